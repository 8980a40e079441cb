"""Part 3 of the calibration study: pose error caused by calibration error (centroid level).

Centroids projected with the true camera at poses over ranges (:func:`study_poses`) are
solved (:func:`svgs_sim.svgs.solver.solve_centroids`) with a believed camera - wrong in one way
(:func:`error_cases`) or what a calibration found - and the errors are averaged per range
(:func:`range_summary`). Each (case, noise level, range) is one trial of the kind
``calibration-pose`` (:mod:`svgs_sim.studies.calibration.trials`), which computes its range's poses
alone (:func:`range_poses`, :func:`range_noise`) and draws exactly the numbers of the whole
study's streams.
"""

from __future__ import annotations

import numpy as np

from svgs_sim.base.profiles import Camera, Pattern
from svgs_sim.sim.metrics import state_error
from svgs_sim.svgs.frames import pose_from_scenario, pose_to_state, rotation_angle_deg
from svgs_sim.svgs.solver import solve_centroids

from .common import (
    DEFAULT_POSE_RANGES_M,
    DEFAULT_POSES_PER_RANGE,
    POSE_SPREAD,
    STATE_COLS,
    spawn_seeds,
)

#: Output columns of one (case, noise, range) summary, besides the labels.
SUMMARY_COLUMNS = ("n_poses", "n_failed", *STATE_COLS, "mean_z_m", "pos_err_norm_m", "pos_err_max_m", "pos_err_rel_pct",
                   "rot_err_deg")
#: Uniform draws per drawn pose (lateral x, y; roll, pitch, yaw).
_DRAWS_PER_POSE = 5


def _draw_pose(r: float, rng, sp: dict):

    lat = sp["lateral_fraction"] * r
    return pose_from_scenario(r, rng.uniform(-lat, lat), rng.uniform(-lat, lat),
                              rng.uniform(-sp["roll_deg"], sp["roll_deg"]),
                              rng.uniform(-sp["pitch_deg"], sp["pitch_deg"]),
                              rng.uniform(-sp["yaw_deg"], sp["yaw_deg"]))


def study_poses(ranges_m, poses_per_range: int = DEFAULT_POSES_PER_RANGE, *, seed: int = 0, spread=None):
    """Poses per range: the first faces the camera on the boresight, the rest drawn.

    One generator seeded with ``seed`` draws the poses range after range.

    Returns
    -------
    ranges : ndarray, shape (M,)
    R_cam_target : ndarray, shape (M, 3, 3)
    t_cam_target_m : ndarray, shape (M, 3)
    """

    sp = dict(POSE_SPREAD if spread is None else spread)
    rng = np.random.default_rng(seed)
    rr, Rs, ts = [], [], []
    for r in ranges_m:
        for j in range(int(poses_per_range)):
            R, t = pose_from_scenario(r) if j == 0 else _draw_pose(r, rng, sp)
            rr.append(float(r))
            Rs.append(R)
            ts.append(t)
    return np.array(rr), np.array(Rs), np.array(ts)


def range_poses(range_m: float, range_index: int, poses_per_range: int, *, seed: int = 0, spread=None):
    """The poses :func:`study_poses` draws at its ``range_index``-th range, computed alone.

    Returns
    -------
    R_cam_target : ndarray, shape (poses_per_range, 3, 3)
    t_cam_target_m : ndarray, shape (poses_per_range, 3)
    """

    sp = dict(POSE_SPREAD if spread is None else spread)
    n = int(poses_per_range)
    rng = np.random.default_rng(seed)
    rng.random(int(range_index) * max(0, n - 1) * _DRAWS_PER_POSE)  # the earlier ranges' draws
    poses = [pose_from_scenario(range_m) if j == 0 else _draw_pose(range_m, rng, sp) for j in range(n)]
    return np.array([p[0] for p in poses]), np.array([p[1] for p in poses])


def range_noise(noise_px: float, shape, first_pose: int, seed: int = 0) -> np.ndarray:
    """Poses ``first_pose ...`` of the centroid noise one generator seeded with ``seed`` draws
    for the whole study, ``normal(0, noise_px, (M, N, 2))``.

    Parameters
    ----------
    shape : (int, int, int)
        (poses, points, 2) of this part.
    """
    rng = np.random.default_rng(seed)
    rng.standard_normal(int(first_pose) * int(np.prod(shape[1:])))
    return rng.normal(0.0, noise_px, shape)


def pose_errors_batch(camera_true: Camera, believed: Camera, pattern: Pattern, R, t, *, noise_px: float = 0.0,
                      seed: int = 0, noise=None) -> dict:
    """Solve projected centroids with the believed camera; per-pose errors.

    Parameters
    ----------
    camera_true, believed : Camera
    pattern : Pattern
    R : ndarray, shape (M, 3, 3)
    t : ndarray, shape (M, 3)
    noise_px : float
        Gaussian centroid noise, px per axis (the same draws for every believed camera
        with the same seed).
    seed : int
    noise : ndarray, shape (M, N, 2), optional
        The noise to add instead of drawing it.

    Returns
    -------
    dict of ndarray
        ``ok`` (M,), ``d_state`` (M, 6) solved minus true state (m, m, m, deg, deg, deg;
        angles wrapped: :func:`svgs_sim.sim.metrics.state_error`), ``pos_err_norm_m`` (M,) norm,
        ``rot_err_deg`` (M,) angle of the relative rotation, ``in_image`` (M,).
    """

    P = pattern.points_m
    p_cam = np.einsum("mij,nj->mni", R, P) + t[:, None, :]
    uv = camera_true.project(p_cam.reshape(-1, 3)).reshape(p_cam.shape[0], P.shape[0], 2)
    inside = np.all(camera_true.in_image(uv.reshape(-1, 2)).reshape(uv.shape[:2]), axis=1)
    if noise is not None:
        uv = uv + noise
    elif noise_px > 0:
        uv = uv + np.random.default_rng(seed).normal(0.0, noise_px, uv.shape)
    sol = solve_centroids(uv, believed, pattern)
    truth = pose_to_state(R, t)
    d = state_error(sol.state, truth)
    rot = np.full(len(R), np.nan)
    okm = np.asarray(sol.ok, bool)
    if okm.any():
        rot[okm] = rotation_angle_deg(sol.R_cam_target[okm], R[okm])
    return {"ok": okm & inside, "d_state": d, "pos_err_norm_m": np.linalg.norm(d[:, :3], axis=1), "rot_err_deg": rot,
            "in_image": inside}


def range_summary(res: dict, mask, range_m: float) -> dict:
    """Mean errors over the poses ``mask`` of :func:`pose_errors_batch`'s result at one range.

    Returns
    -------
    dict
        ``n_poses`` (in the image), ``n_failed``; where any pose was solved, the mean
        absolute error per state component (``x_m`` ... ``yaw_deg``), ``mean_z_m`` (signed:
        the range bias), ``pos_err_norm_m`` (mean norm), ``pos_err_max_m``, ``pos_err_rel_pct``
        (mean norm / range) and ``rot_err_deg`` (mean).
    """
    m = mask & res["in_image"]
    ok = m & res["ok"]
    row = {"n_poses": int(m.sum()), "n_failed": int((m & ~res["ok"]).sum())}
    if ok.any():
        d = res["d_state"][ok]
        row.update({k: float(np.mean(np.abs(d[:, i]))) for i, k in enumerate(STATE_COLS)})
        row["mean_z_m"] = float(np.mean(d[:, 2]))
        row["pos_err_norm_m"] = float(np.mean(res["pos_err_norm_m"][ok]))
        row["pos_err_max_m"] = float(np.max(res["pos_err_norm_m"][ok]))
        row["pos_err_rel_pct"] = 100.0 * row["pos_err_norm_m"] / float(range_m)
        row["rot_err_deg"] = float(np.nanmean(res["rot_err_deg"][ok]))
    return row


def pose_error_study(camera_true: Camera, believed: dict, pattern: Pattern, ranges_m=DEFAULT_POSE_RANGES_M, *,
                     poses_per_range: int = DEFAULT_POSES_PER_RANGE, noise_px: float = 0.0, seed: int = 0,
                     spread=None, group: str = "") -> list[dict]:
    """Pose error versus range for each believed camera (in this process).

    Parameters
    ----------
    camera_true : Camera
    believed : dict
        Case name -> the Camera the solver uses.
    pattern : Pattern
    ranges_m : sequence of float
    poses_per_range : int
    noise_px : float
        Centroid noise (0: the pure calibration bias).
    seed : int
        Poses and noise (identical for every case): :func:`pose_seeds`.
    spread : dict, optional
        Pose spread (default :data:`POSE_SPREAD`).
    group : str
        Label stored in each row.

    Returns
    -------
    list of dict
        Per case and range: ``case``, ``group``, ``range_m``, ``noise_px`` and
        :func:`range_summary`.
    """
    s_pose, s_noise = pose_seeds(seed)
    rr, R, t = study_poses(ranges_m, poses_per_range, seed=s_pose, spread=spread)
    rows = []
    for case, cam in believed.items():
        res = pose_errors_batch(camera_true, cam, pattern, R, t, noise_px=noise_px, seed=s_noise)
        for r in ranges_m:
            rows.append({"case": case, "group": group, "range_m": float(r), "noise_px": float(noise_px),
                         **range_summary(res, rr == float(r), r)})
    return rows


def pose_seeds(seed: int) -> tuple[int, int]:
    """(pose seed, noise seed) of a pose-error study seeded with ``seed``."""
    s_pose, s_noise = spawn_seeds(seed, 2)
    return s_pose, s_noise


def error_cases(camera_true: Camera, *, focal_pct=(0.1, 0.5, 1.0, 2.0), pp_px=(5.0, 20.0, 50.0),
                k1=(0.01, 0.05, 0.1)) -> dict:
    """Believed cameras that are the true one wrong in one way.

    Returns
    -------
    dict
        ``"exact"``; ``"focal +p %"`` (fx and fy scaled); ``"principal point +d px (u)"``;
        ``"k1 error +e"`` (the believed k1 too small by e).
    """
    out = {"exact": camera_true}
    for p in focal_pct:
        s = 1.0 + p / 100.0
        out[f"focal +{p:g} %"] = camera_true.replace(fx=camera_true.fx * s, fy=camera_true.fy * s)
    for d in pp_px:
        out[f"principal point +{d:g} px (u)"] = camera_true.replace(cx=camera_true.cx + d)
    for e in k1:
        dist = np.asarray(camera_true.dist, float).copy()
        dist[0] -= e
        out[f"k1 error {e:g}"] = camera_true.replace(dist=dist)
    return out
