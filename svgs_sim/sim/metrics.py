"""Pose errors: the one function that computes them and the one set of names they go by.

Every row, JSON record and CSV column that reports how far a solved pose is from the truth
uses these names, so one word means one thing:

``pos_err_vec_m``
    The camera-position error ``[dX_L, dY_L, dZ_L]`` in the target frame (paper state,
    estimate minus truth), m; a 3-vector (JSON rows).
``att_err_vec_deg``
    The attitude error per paper angle ``[droll, dpitch, dyaw]``, wrapped to [-180, 180),
    deg; a 3-vector (JSON rows).
``pos_err_norm_m``
    The norm of ``pos_err_vec_m``, m.
``rot_err_deg``
    The angle of the relative rotation between the solved and true attitude, deg (>= 0;
    not the norm of ``att_err_vec_deg``).
``err_x_m`` ... ``err_yaw_deg``
    The six components of the state error as flat CSV columns (:data:`ERR_KEYS`), m and deg.

The state keys themselves (``x_m`` ... ``yaw_deg``: the camera's position in the target
frame and the paper's attitude) are :data:`svgs_sim.svgs.frames.STATE_KEYS`.
"""

from __future__ import annotations

import numpy as np

from svgs_sim.svgs.frames import STATE_KEYS, rotation_angle_deg, state_to_pose

POS_ERR_VEC_M = "pos_err_vec_m"
ATT_ERR_VEC_DEG = "att_err_vec_deg"
POS_ERR_NORM_M = "pos_err_norm_m"
ROT_ERR_DEG = "rot_err_deg"

#: The keys of :func:`pose_errors`, in order.
POSE_ERROR_KEYS = (POS_ERR_VEC_M, ATT_ERR_VEC_DEG, POS_ERR_NORM_M, ROT_ERR_DEG)
#: Per-component state-error columns ``err_x_m`` ... ``err_yaw_deg`` (m, deg).
ERR_KEYS = tuple(f"err_{k}" for k in STATE_KEYS)
#: The scalar error columns of a study row.
SCALAR_ERROR_KEYS = (POS_ERR_NORM_M, ROT_ERR_DEG)


def state_m_deg(state) -> np.ndarray:
    """A paper state in the units of :data:`svgs_sim.svgs.frames.STATE_KEYS` (m and deg).

    Parameters
    ----------
    state : array_like, shape (..., 6)
        ``[X_L_m, Y_L_m, Z_L_m, phi_rad, theta_rad, psi_rad]``.

    Returns
    -------
    ndarray, shape (..., 6)
        ``[X_L_m, Y_L_m, Z_L_m, roll_deg, pitch_deg, yaw_deg]``.
    """
    s = np.asarray(state, float)
    return np.concatenate([s[..., :3], np.degrees(s[..., 3:])], -1)


def state_error(est_state, true_state) -> np.ndarray:
    """Estimate minus truth of a paper state, in m and deg, angles wrapped to [-180, 180).

    Parameters
    ----------
    est_state, true_state : array_like, shape (..., 6)
        Paper states (m, rad).

    Returns
    -------
    ndarray, shape (..., 6)
        ``[dX_L_m, dY_L_m, dZ_L_m, droll_deg, dpitch_deg, dyaw_deg]``.
    """
    err = state_m_deg(est_state) - state_m_deg(true_state)
    err[..., 3:] = (err[..., 3:] + 180.0) % 360.0 - 180.0
    return err


def pose_errors(est_state, true_state, *, R_cam_target_est=None) -> dict:
    """The errors of a solved paper state against the truth, under :data:`POSE_ERROR_KEYS`.

    Parameters
    ----------
    est_state, true_state : array_like, shape (6,)
        Paper states (m, rad).
    R_cam_target_est : array_like, shape (3, 3), optional
        The solver's rotation, if it has one (else built from ``est_state``); the true
        rotation is built from ``true_state``.

    Returns
    -------
    dict
        ``pos_err_vec_m`` (list of 3 floats, m), ``att_err_vec_deg`` (list of 3 floats,
        deg), ``pos_err_norm_m`` (float, m), ``rot_err_deg`` (float, deg).
    """
    err = state_error(est_state, true_state)
    R_est = state_to_pose(est_state)[0] if R_cam_target_est is None else np.asarray(R_cam_target_est, float)
    R_true = state_to_pose(true_state)[0]
    return {
        POS_ERR_VEC_M: err[:3].tolist(),
        ATT_ERR_VEC_DEG: err[3:].tolist(),
        POS_ERR_NORM_M: float(np.linalg.norm(err[:3])),
        ROT_ERR_DEG: float(rotation_angle_deg(R_est, R_true)),
    }


def error_columns(est_state, true_state, *, R_cam_target_est=None) -> dict:
    """The flat error columns of a study row: ``err_x_m`` ... ``err_yaw_deg``,
    ``pos_err_norm_m``, ``rot_err_deg`` (floats; see :func:`pose_errors`)."""
    e = pose_errors(est_state, true_state, R_cam_target_est=R_cam_target_est)
    out = {k: float(v) for k, v in zip(ERR_KEYS, e[POS_ERR_VEC_M] + e[ATT_ERR_VEC_DEG])}
    out.update({k: e[k] for k in SCALAR_ERROR_KEYS})
    return out


def no_pose_errors() -> dict:
    """:data:`POSE_ERROR_KEYS` set to None (an unsolved frame)."""
    return {k: None for k in POSE_ERROR_KEYS}


# ----------------------------------------------------------------------------- locks on the right spots
#: A wrong lock: an identified blob farther than this from its target's spot, px (or than the
#: spot's image radius, where that is larger: :func:`wrong_lock_px`).
WRONG_LOCK_PX = 3.0
#: The cube aperture the spot radius is taken from where the pattern gives no target sizes, m (1 in).
STRAY_CUBE_DIAMETER_M = 0.0254


def spot_radius_px(camera, pattern, depth_m):
    """The image radius of a target's cube aperture at ``depth_m`` along the boresight, px (the
    pattern's largest target diameter, else :data:`STRAY_CUBE_DIAMETER_M`); ``depth_m`` may be an array."""
    sizes = [d for d, _ in pattern.target_sizes_m if d is not None]
    diam = max(sizes) if sizes else STRAY_CUBE_DIAMETER_M
    return np.sqrt(camera.fx * camera.fy) * 0.5 * diam / np.asarray(depth_m, float)


def wrong_lock_px(camera, pattern, range_m: float) -> float:
    """The distance beyond which an identified blob is not its target's spot, px (:data:`WRONG_LOCK_PX`)."""
    return max(WRONG_LOCK_PX, float(spot_radius_px(camera, pattern, float(range_m))))


def spot_positions_px(image_camera, pattern, R_cam_target, t_cam_target_m, spots_px=None, scale: float = 1.0):
    """Where each target's spot lies in the delivered image, px.

    Parameters
    ----------
    image_camera : svgs.Camera
        The delivered image's camera geometry (projects the targets where there are no spots).
    pattern : svgs.Pattern
    R_cam_target : array_like, shape (3, 3)
    t_cam_target_m : array_like, shape (3,)
    spots_px : dict, optional
        The renderer's predicted spot centroids, target id (str) -> (u, v) full-frame px (the
        flash's offset from the lens moves them a few px off the targets' projection at close range).
    scale : float
        The delivered image's width over the full frame's (with ``spots_px``).

    Returns
    -------
    ndarray, shape (N, 2)
        In the pattern's target order.
    """
    if spots_px is not None:
        return np.array([spots_px[str(int(i))] for i in pattern.ids], float) * float(scale)
    return image_camera.project_target(pattern.points_m, R_cam_target, t_cam_target_m)


def match_err_max_px(row: dict, solution, spots_uv_px, target_ids) -> float | None:
    """The largest distance of an identified blob from its target's spot, px, for a solution the
    paper's app would report (solved, or refused only by the consistency test); None otherwise.

    Parameters
    ----------
    row : dict
        The frame's row (``state`` None when unsolved, ``reason``).
    solution : svgs.Solution or failure result
        With ``targets_px`` (solved) or ``details["targets_px"]`` (inconsistent).
    spots_uv_px : ndarray, shape (N, 2)
        :func:`spot_positions_px`.
    target_ids : array_like, shape (N,)
        The pattern's target ids, in the order of ``spots_uv_px``.
    """
    targets = None
    if row["state"] is not None and solution:
        targets = solution.targets_px
    elif row.get("reason") == "inconsistent" and solution is not None and "targets_px" in getattr(solution, "details", {}):
        targets = solution.details["targets_px"]
    if targets is None:
        return None
    found = {int(k): v for k, v in targets.items()}
    uv = np.array([found[int(i)] for i in target_ids], float)
    return float(np.max(np.linalg.norm(uv - np.asarray(spots_uv_px, float), axis=1)))
