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
