"""The paper's focal-length method inside the calibration study (svgs_sim.studies.calibration.focal_study).

Projected centroids (no render) with seeded noise; the rendered path is checked by a slow test
on two Galaxy Nexus frames.
"""

import importlib.util

import numpy as np
import pytest

from svgs_sim.studies.calibration import (
    FocalFrames,
    default_range_sets,
    focal_frames_geometric,
    focal_study,
    true_camera,
)
from svgs_sim.base.profiles import Camera


@pytest.fixture(scope="module")
def nominal():
    return Camera.load("galaxy-nexus")


def test_exact_on_noise_free_projections(nominal, pattern):
    frames = focal_frames_geometric(nominal, pattern, [1.0, 4.0, 10.0], exposures=2, noise_px=1e-9, seed=1)
    rows, est = focal_study(frames, nominal, pattern, nominal.fx, noise_levels_px=(0.0,))
    assert est.f_px == pytest.approx(nominal.fx, rel=1e-6)
    assert all(abs(r["mean_err_pct"]) < 1e-4 for r in rows)


def test_error_grows_with_fewer_ranges_and_noisier_centroids(nominal, pattern):
    ranges = [float(r) for r in range(1, 11)]
    frames = focal_frames_geometric(nominal, pattern, ranges, exposures=4, noise_px=0.05, seed=2)
    rows, est = focal_study(frames, nominal, pattern, nominal.fx, noise_levels_px=(0.0, 0.3, 1.0), trials=10, seed=3)
    by = {(r["ranges"], r["added_noise_px"]): r for r in rows}
    names = [n for n, _ in default_range_sets(ranges)]
    assert names[0].startswith("all 10") and names[-1] == "10 m only"
    for sig in (0.3, 1.0):
        assert by[("10 m only", sig)]["rms_err_pct"] > 3 * by[(names[0], sig)]["rms_err_pct"]
    for name in names:
        assert by[(name, 1.0)]["rms_err_pct"] > by[(name, 0.0)]["rms_err_pct"]
    # all ten ranges: within 0.1 % even with 0.3 px of added noise; the method's own sigma is honest
    assert by[(names[0], 0.3)]["rms_err_pct"] < 0.1
    assert by[(names[0], 1.0)]["rms_err_pct"] == pytest.approx(by[(names[0], 1.0)]["reported_sigma_pct"], rel=0.5)
    assert abs(est.f_px / nominal.fx - 1) < 5e-4


def test_ignored_lens_errors_bias_the_focal_only_estimate(nominal, pattern):
    # the real lens has k1 = 0.03 and a shifted principal point; the method believes the nominal
    # camera: f comes out slightly long (pincushion magnifies off-axis spots), well within 1 %
    cam = true_camera(nominal, (15.0, -15.0), (0.03, 0, 0, 0, 0))
    frames = focal_frames_geometric(cam, pattern, [float(r) for r in range(1, 11)], exposures=1, noise_px=1e-9, seed=4)
    _, est = focal_study(frames, nominal, pattern, cam.fx, noise_levels_px=(0.0,))
    err = est.f_px / cam.fx - 1
    assert 2e-4 < err < 5e-3
    assert est.consistency_chi2 > 0  # the ranges disagree: a model error, visible in chi2


def test_focal_frames_cache_round_trip(tmp_path, nominal, pattern):
    frames = focal_frames_geometric(nominal, pattern, [2.0, 5.0], exposures=3, seed=5)
    frames.centroids_px[1, 2] = np.nan  # one exposure not identified
    frames.camera = {"intrinsics": {"fx": 2450.0}, "exposure": {"mode": "manual"}}
    frames.save(tmp_path / "f.npz")
    again = FocalFrames.load(tmp_path / "f.npz")
    assert np.array_equal(again.centroids_px, frames.centroids_px, equal_nan=True)
    assert again.info == frames.info and again.rendered is False and again.camera == frames.camera
    assert again.ok().tolist() == [[True, True, True], [True, True, False]]
    from svgs_sim.base.errors import InputError

    (tmp_path / "bad.npz").write_bytes(b"not a zip")
    with pytest.raises(InputError, match="not a focal-frames cache"):
        FocalFrames.load(tmp_path / "bad.npz")


@pytest.mark.slow
@pytest.mark.render
@pytest.mark.skipif(importlib.util.find_spec("mitsuba") is None, reason="Mitsuba is not installed")
def test_rendered_frames_recover_the_focal_length(nominal, pattern):
    # two rendered Galaxy Nexus frames (corner cubes, flash, phone exposure, detection,
    # identification) - the focal-only estimate within 1 % of the truth
    from svgs_sim.studies.calibration import focal_frames_rendered

    cam = true_camera(nominal, (0.0, 0.0), (0.0, 0, 0, 0, 0))
    frames = focal_frames_rendered(cam, nominal, pattern, [2.0, 5.0], exposures=1, seed=1)
    assert frames.ok().all()
    _, est = focal_study(frames, nominal, pattern, cam.fx, noise_levels_px=(0.0,))
    assert abs(est.f_px / cam.fx - 1) < 0.01
