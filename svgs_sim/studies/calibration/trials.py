"""The calibration study's trial kinds, run by :func:`svgs_sim.studies.execution.run_study`.

``calibration-convergence``
    One OpenCV calibration from a subset of the board views (:mod:`.convergence`). The
    scenario names the views (``view_indices``) and the detections file in the study
    folder (``inputs``); the trial draws no random numbers.
``calibration-focal``
    One (range set, added noise) case of the paper's focal method (:mod:`svgs_sim.studies.calibration.focal`) on the
    focal frames file in the study folder.
``calibration-pose``
    One (believed camera, noise level, range) cell of the pose-error study (:mod:`svgs_sim.studies.calibration.pose`):
    the true and the believed camera are scenario columns (``true_*``, ``solver_*``).

Seeds. The study's parts each read one random stream whose seed is derived from the study
seed (:func:`svgs_sim.studies.calibration.common.spawn_seeds`, the same on every executor); a trial
of the focal or pose kind carries that stream's seed and skips to its own part of it
(``noise_skip``; ``range_index``), so its numbers do not depend on which worker runs it,
on the worker count or on which trials ran before a resume, and equal those of the whole
study computed in one process. The cases of both kinds share their stream on purpose:
every believed camera is tried on the same poses and the same noise (common random
numbers), so differences between cases are the calibrations', not the draws'.

Input files are named in the scenario relative to the working directory; workers (local
processes, a Dask ``LocalCluster``) must see them at the same place.
"""

from __future__ import annotations

import functools
import os

import numpy as np

from svgs_sim.base.profiles import load_pattern
from svgs_sim.sim.trials import TrialKind, geometric_warm_up, register_trial_kind

from .common import CAMERA_FIELDS, camera_columns, camera_from_columns
from .convergence import ERROR_COLUMNS, calibrate_subset, load_detections
from .focal import FOCAL_COLUMNS, FocalFrames, focal_case
from .pose import (
    SUMMARY_COLUMNS,
    pose_errors_batch,
    range_noise,
    range_poses,
    range_summary,
)


def _stamp(path: str) -> tuple:
    st = os.stat(path)
    return (path, st.st_mtime_ns, st.st_size)


@functools.lru_cache(maxsize=4)
def _detections(stamp: tuple):
    return load_detections(stamp[0])


@functools.lru_cache(maxsize=4)
def _frames(stamp: tuple) -> FocalFrames:
    return FocalFrames.load(stamp[0])


@functools.lru_cache(maxsize=8)
def _pattern(name: str):

    return load_pattern(name)


def indices_text(idx) -> str:
    """View or range indices as a scenario text column: ``"0 3 7"``."""
    return " ".join(str(int(i)) for i in idx)


def parse_indices(text) -> list[int]:
    """Inverse of :func:`indices_text` (a single index may come back from a CSV as an int)."""
    return [int(x) for x in str(text).split()]


def input_path(path) -> str:
    """How a scenario names an input file: relative to the working directory."""
    return os.path.relpath(os.fspath(path))


# --------------------------------------------------------------------------- convergence
def convergence_trial(scenario: dict, seed: int) -> dict:
    """Calibrate from the views ``view_indices`` of the detections in ``inputs``.

    Returns
    -------
    dict
        :data:`CONVERGENCE_OUTPUTS`: :func:`.convergence.calibration_errors` and ``views``.
    """
    det, camera, _ = _detections(_stamp(scenario["inputs"]))
    row, _ = calibrate_subset(det, parse_indices(scenario["view_indices"]), camera)
    return row


CONVERGENCE_OUTPUTS = (*ERROR_COLUMNS, "views")

CONVERGENCE = register_trial_kind(TrialKind(
    name="calibration-convergence",
    run_trial=convergence_trial,
    outputs=CONVERGENCE_OUTPUTS,
    parameters={},
    text_keys=("view_indices", "inputs"),
    description="OpenCV calibration from a subset of detected board views, judged against the true camera",
))


def convergence_scenario(n_views: int, subset: int, idx, inputs) -> dict:
    """The scenario of one calibration (``inputs``: the detections file)."""
    return {"n_views": int(n_views), "subset": int(subset), "view_indices": indices_text(idx),
            "inputs": input_path(inputs)}


# --------------------------------------------------------------------------- focal method
FOCAL_OUTPUTS = tuple(c for c in FOCAL_COLUMNS if c not in ("ranges", "added_noise_px"))


def focal_trial(scenario: dict, seed: int) -> dict:
    """One case of the focal study on the frames in ``inputs``; empty outputs if no exposure
    has all the set's ranges."""
    frames = _frames(_stamp(scenario["inputs"]))
    case = {**scenario, "range_indices": parse_indices(scenario["range_indices"])}
    row = focal_case(frames, case, camera_from_columns("solver_", scenario), _pattern(scenario["pattern"]),
                     float(scenario["f_true_px"]), seed)
    return {k: None for k in FOCAL_OUTPUTS} if row is None else {k: row[k] for k in FOCAL_OUTPUTS}


FOCAL = register_trial_kind(TrialKind(
    name="calibration-focal",
    run_trial=focal_trial,
    outputs=FOCAL_OUTPUTS,
    parameters={},
    text_keys=("ranges", "range_indices", "inputs", "pattern"),
    description="the paper's focal-length method on a set of ranges with added centroid noise",
))


def focal_scenario(case: dict, inputs, believed, pattern: str, f_true_px: float) -> dict:
    """The scenario of one :func:`.focal.focal_cases` case."""
    return {"ranges": case["ranges"], "range_indices": indices_text(case["range_indices"]),
            "added_noise_px": float(case["added_noise_px"]), "n_trials": int(case["n_trials"]),
            "noise_skip": int(case["noise_skip"]), "inputs": input_path(inputs), "pattern": str(pattern),
            "f_true_px": float(f_true_px), **camera_columns("solver_", believed)}


# --------------------------------------------------------------------------- pose errors
def pose_trial(scenario: dict, seed: int) -> dict:
    """The poses at one range solved with the believed camera; mean errors.

    ``seed`` seeds the study's centroid-noise stream (used when ``noise_px`` > 0).
    """
    pattern = _pattern(scenario["pattern"])
    n, i, r = int(scenario["poses_per_range"]), int(scenario["range_index"]), float(scenario["range_m"])
    R, t = range_poses(r, i, n, seed=int(scenario["pose_seed"]))
    noise_px = float(scenario["noise_px"])
    noise = range_noise(noise_px, (n, pattern.n, 2), i * n, seed=seed) if noise_px > 0 else None
    res = pose_errors_batch(camera_from_columns("true_", scenario, "true"),
                            camera_from_columns("solver_", scenario, "believed"), pattern, R, t, noise=noise)
    row = range_summary(res, np.ones(n, bool), r)
    return {k: row.get(k) for k in SUMMARY_COLUMNS}


def _warm_solver() -> None:

    geometric_warm_up()


POSE = register_trial_kind(TrialKind(
    name="calibration-pose",
    run_trial=pose_trial,
    outputs=SUMMARY_COLUMNS,
    parameters={},
    text_keys=("case", "group", "pattern"),
    warm_up=_warm_solver,
    description="projected centroids solved with a believed (mis-calibrated) camera; mean pose error per range",
))


def pose_scenario(case: str, group: str, range_m: float, range_index: int, noise_px: float, poses_per_range: int,
                  pose_seed: int, pattern: str, camera_true, believed) -> dict:
    """The scenario of one (case, noise, range) cell."""
    return {"case": str(case), "group": str(group), "range_m": float(range_m), "noise_px": float(noise_px),
            "range_index": int(range_index), "poses_per_range": int(poses_per_range), "pose_seed": int(pose_seed),
            "pattern": str(pattern), **camera_columns("true_", camera_true), **camera_columns("solver_", believed)}


#: The kinds by study part.
KINDS = {"convergence": CONVERGENCE, "focal": FOCAL, "pose": POSE}
#: Scenario keys (columns) of each part's trials, in the order the scenario functions write them.
SCENARIO_KEYS = {
    "convergence": ("n_views", "subset", "view_indices", "inputs"),
    "focal": ("ranges", "range_indices", "added_noise_px", "n_trials", "noise_skip", "inputs", "pattern", "f_true_px",
              *(f"solver_{k}" for k in CAMERA_FIELDS)),
    "pose": ("case", "group", "range_m", "noise_px", "range_index", "poses_per_range", "pose_seed", "pattern",
             *(f"true_{k}" for k in CAMERA_FIELDS), *(f"solver_{k}" for k in CAMERA_FIELDS)),
}

__all__ = ["CONVERGENCE", "FOCAL", "KINDS", "POSE", "SCENARIO_KEYS", "convergence_scenario", "focal_scenario",
           "pose_scenario"]
