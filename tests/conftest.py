"""Shared fixtures. Paths are relative to this file, never to the working directory."""

from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"


@pytest.fixture(scope="session")
def nexus():
    from svgs import Camera

    return Camera.load("galaxy-nexus", fitted=False)  # geometry for model tests: no fitted values


@pytest.fixture(scope="session")
def pattern():
    from svgs import Pattern

    return Pattern.load("svgs-3u")


def random_envelope_poses(n, seed, range_m=(1.0, 40.0)):
    """Poses drawn over the paper's test envelope: range log-uniform, roll/pitch +/-25 deg,
    yaw +/-45 deg, lateral offsets up to +/-15 % of range. Returns (R (n,3,3), t (n,3))."""
    from svgs.frames import pose_from_scenario, sample_envelope_scenario

    rng = np.random.default_rng(seed)
    Rs, ts = [], []
    for _ in range(n):
        R, t = pose_from_scenario(**sample_envelope_scenario(rng, range_m=range_m))
        Rs.append(R)
        ts.append(t)
    return np.array(Rs), np.array(ts)
