"""Frames and angle conventions - the one home for them.

See ``docs/frames.md`` for the full description with figures in words. In short:

Target frame (paper, "Target Pattern And Coordinate System")
    Origin at the base of the target-3 boom; +y from target 2 to target 1; +z from the
    origin towards target 3 (out of the target face, towards the sensor in the nominal
    set-up); +x completes the right-handed triad (towards target 4).

Paper camera frame ("image frame", photogrammetric)
    Origin at the perspective centre L; at zero attitude its axes are parallel to the
    target frame's; x right, y up in the image, z *backwards* (the camera looks along -z).

OpenCV camera frame (``cam``)
    x right, y down, z along the boresight. ``p_cam = R_cam_target @ p_target + t_cam_target``.
    The two camera frames differ by ``D = diag(1, -1, -1)``: ``p_cam = D @ p_photo``.

State vector V = [X_L, Y_L, Z_L, phi, theta, psi] (paper eq. 6)
    ``X_L, Y_L, Z_L`` (m): the perspective centre in the target frame (paper eq. 1).
    ``phi, theta, psi`` (rad internally, degrees at the user interface as roll, pitch,
    yaw): an x-y-z sequence of frame rotations, ``M = R3(psi) @ R2(theta) @ R1(phi)``,
    where ``Ri(a)`` are the passive (frame) rotations of photogrammetry
    (Moffitt & Mikhail 1980), ``p_photo = M @ (p_target - L)``.

Hence ``R_cam_target = D @ M`` and ``t_cam_target = -D @ M @ L``.
"""

from __future__ import annotations

import numpy as np

from ..base.errors import InputError

#: Conversion between the paper's camera frame and OpenCV's: ``p_cam = D @ p_photo``.
D_CAM_PHOTO = np.diag([1.0, -1.0, -1.0])


def _r1(a):
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([o, z, z], -1), np.stack([z, c, s], -1), np.stack([z, -s, c], -1)], -2)


def _r2(a):
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([c, z, -s], -1), np.stack([z, o, z], -1), np.stack([s, z, c], -1)], -2)


def _r3(a):
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([c, s, z], -1), np.stack([-s, c, z], -1), np.stack([z, z, o], -1)], -2)


def rotation_from_angles(phi_rad, theta_rad, psi_rad) -> np.ndarray:
    """Direction-cosine matrix M (target frame -> paper camera frame).

    Parameters
    ----------
    phi_rad, theta_rad, psi_rad : float or array_like, shape (...)
        Rotations about x, y, z (roll, pitch, yaw), radians.

    Returns
    -------
    M : ndarray, shape (..., 3, 3)
        ``M = R3(psi) @ R2(theta) @ R1(phi)``.
    """
    phi, theta, psi = np.broadcast_arrays(
        np.asarray(phi_rad, float), np.asarray(theta_rad, float), np.asarray(psi_rad, float)
    )
    return _r3(psi) @ _r2(theta) @ _r1(phi)


def angles_from_rotation(M: np.ndarray) -> np.ndarray:
    """Inverse of :func:`rotation_from_angles`.

    Parameters
    ----------
    M : ndarray, shape (..., 3, 3)

    Returns
    -------
    angles_rad : ndarray, shape (..., 3)
        ``[phi, theta, psi]`` with theta in [-pi/2, pi/2].
    """
    M = np.asarray(M, float)
    theta = np.arcsin(np.clip(M[..., 2, 0], -1.0, 1.0))
    phi = np.arctan2(-M[..., 2, 1], M[..., 2, 2])
    psi = np.arctan2(-M[..., 1, 0], M[..., 0, 0])
    return np.stack([phi, theta, psi], -1)


def state_to_pose(state) -> tuple[np.ndarray, np.ndarray]:
    """Paper state -> OpenCV pose.

    Parameters
    ----------
    state : array_like, shape (..., 6)
        ``[X_L_m, Y_L_m, Z_L_m, phi_rad, theta_rad, psi_rad]``.

    Returns
    -------
    R_cam_target : ndarray, shape (..., 3, 3)
    t_cam_target_m : ndarray, shape (..., 3)
    """
    state = np.asarray(state, float)
    if state.shape[-1] != 6:
        raise InputError(f"state: expected shape (..., 6), got {state.shape}")
    M = rotation_from_angles(state[..., 3], state[..., 4], state[..., 5])
    R = D_CAM_PHOTO @ M
    t = -np.einsum("...ij,...j->...i", R, state[..., :3])
    return R, t


def pose_to_state(R_cam_target, t_cam_target_m) -> np.ndarray:
    """OpenCV pose -> paper state.

    Parameters
    ----------
    R_cam_target : array_like, shape (..., 3, 3)
    t_cam_target_m : array_like, shape (..., 3)

    Returns
    -------
    state : ndarray, shape (..., 6)
        ``[X_L_m, Y_L_m, Z_L_m, phi_rad, theta_rad, psi_rad]``.
    """
    R = np.asarray(R_cam_target, float)
    t = np.asarray(t_cam_target_m, float)
    M = D_CAM_PHOTO @ R
    L = -np.einsum("...ji,...j->...i", R, t)
    return np.concatenate([L, angles_from_rotation(M)], -1)


def pose_from_scenario(range_m, target_x_m=0.0, target_y_m=0.0, roll_deg=0.0, pitch_deg=0.0, yaw_deg=0.0):
    """Pose from the scenario parameters used by the CLI (``svgs render --range ...``).

    The target origin sits at ``(target_x_m, target_y_m, -range_m)`` in the paper's camera
    frame (x right, y up, looking along -z), i.e. ``range_m`` is measured along the boresight
    and ``target_x_m``/``target_y_m`` are lateral offsets of the target origin (not the
    camera position ``x_m, y_m`` of the paper's state); the attitude is the paper's
    (roll, pitch, yaw) = (phi, theta, psi) in degrees.

    Returns
    -------
    R_cam_target : ndarray, shape (3, 3)
    t_cam_target_m : ndarray, shape (3,)
    """
    rng = float(range_m)
    if not np.isfinite(rng) or rng <= 0:
        raise InputError(f"range_m: expected a positive finite range in metres, got {range_m!r}")
    for name, v in (("target_x_m", target_x_m), ("target_y_m", target_y_m), ("roll_deg", roll_deg), ("pitch_deg", pitch_deg), ("yaw_deg", yaw_deg)):
        if not np.isfinite(float(v)):
            raise InputError(f"{name}: expected a finite number, got {v!r}")
    M = rotation_from_angles(*np.deg2rad([roll_deg, pitch_deg, yaw_deg]))
    R = D_CAM_PHOTO @ M
    t = D_CAM_PHOTO @ np.array([float(target_x_m), float(target_y_m), -rng])
    return R, t


def check_pose(R_cam_target, t_cam_target_m):
    """A finite proper rotation (3, 3) and a finite translation (3,), else :class:`InputError`.

    Returns
    -------
    R_cam_target : ndarray, shape (3, 3)
    t_cam_target_m : ndarray, shape (3,)
    """
    R = np.asarray(R_cam_target, float)
    t = np.asarray(t_cam_target_m, float)
    if R.shape != (3, 3) or not np.all(np.isfinite(R)):
        raise InputError(f"R_cam_target: expected a finite 3x3 rotation matrix, got shape {R.shape}")
    if np.max(np.abs(R @ R.T - np.eye(3))) > 1e-6 or np.linalg.det(R) < 0:
        raise InputError("R_cam_target: not a proper rotation (R R^T != I or det < 0)")
    if t.shape != (3,) or not np.all(np.isfinite(t)):
        raise InputError(f"t_cam_target_m: expected 3 finite numbers (m), got {t!r}")
    return R, t


#: The paper's state vector as named keys, in order: the camera's position in the target
#: frame (m) and the x-y-z attitude sequence (deg). The one definition; JSON and CSV use it.
STATE_KEYS = ("x_m", "y_m", "z_m", "roll_deg", "pitch_deg", "yaw_deg")


def state_dict(state) -> dict:
    """The state as the JSON keys of ``svgs solve --json`` (metres and degrees).

    Parameters
    ----------
    state : array_like, shape (6,)
    """
    s = np.asarray(state, float)
    values = (*s[:3], *np.degrees(s[3:6]))
    return {k: float(v) for k, v in zip(STATE_KEYS, values)}


def rotation_angle_deg(R_a, R_b) -> np.ndarray:
    """Angle of the rotation ``R_a @ R_b.T`` in degrees (the attitude error between two poses).

    Parameters
    ----------
    R_a, R_b : array_like, shape (..., 3, 3)
    """
    dR = np.asarray(R_a) @ np.swapaxes(np.asarray(R_b), -1, -2)
    c = (np.trace(dR, axis1=-2, axis2=-1) - 1.0) / 2.0
    # arccos is ill-conditioned near 0: use the skew part as well
    s = 0.5 * np.linalg.norm(
        np.stack([dR[..., 2, 1] - dR[..., 1, 2], dR[..., 0, 2] - dR[..., 2, 0], dR[..., 1, 0] - dR[..., 0, 1]], -1), axis=-1
    )
    return np.degrees(np.arctan2(s, c))


def sample_envelope_scenario(rng, *, range_interval_m=(1.0, 40.0), roll_deg=25.0, pitch_deg=25.0, yaw_deg=45.0,
                             lateral_fraction=0.15) -> dict:
    """One pose drawn over a test envelope (default: the paper's, "Test Setup"), as the
    keyword arguments of :func:`pose_from_scenario`.

    Range log-uniform in ``range_interval_m``; lateral offsets of the target origin uniform up to
    +/-``lateral_fraction`` of the range; roll and pitch uniform in +/-``roll_deg``,
    +/-``pitch_deg``, yaw in +/-``yaw_deg``. Six scalar draws from ``rng``, in the order
    range, x, y, roll, pitch, yaw (the one envelope sampler of tests and benchmarks; the
    identification gates draw their own inflated envelope, :mod:`svgs_sim.svgs.identify`).

    Parameters
    ----------
    rng : numpy.random.Generator
    range_interval_m : (float, float)
        Nearest and farthest range along the boresight, m.
    roll_deg, pitch_deg, yaw_deg : float
        Largest absolute attitude angles, deg.
    lateral_fraction : float
        Largest lateral offset as a fraction of the range.

    Returns
    -------
    dict
        ``range_m, target_x_m, target_y_m, roll_deg, pitch_deg, yaw_deg``: the arguments of
        :func:`pose_from_scenario`.
    """
    r = float(np.exp(rng.uniform(np.log(range_interval_m[0]), np.log(range_interval_m[1]))))
    return {
        "range_m": r,
        "target_x_m": float(rng.uniform(-lateral_fraction, lateral_fraction) * r),
        "target_y_m": float(rng.uniform(-lateral_fraction, lateral_fraction) * r),
        "roll_deg": float(rng.uniform(-roll_deg, roll_deg)),
        "pitch_deg": float(rng.uniform(-pitch_deg, pitch_deg)),
        "yaw_deg": float(rng.uniform(-yaw_deg, yaw_deg)),
    }
