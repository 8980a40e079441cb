"""Basilisk's frames and the paper's: two spacecraft's inertial states -> the SVGS pose and back.

Pure numpy: nothing here needs Basilisk installed (:mod:`svgs_sim.sim.basilisk_svgs` is the module that
runs inside a Basilisk simulation and uses these).

Basilisk's conventions (Schaub & Junkins, *Analytical Mechanics of Space Systems*, 4th ed.,
2018, sec. 3.5; Basilisk's ``RigidBodyKinematics.MRP2C``):

- ``r_BN_N``, ``v_BN_N``: a body frame B's origin relative to the inertial origin N, in inertial
  (N) components, m and m/s (``SCStatesMsgPayload``).
- ``sigma_BN``: the modified Rodrigues parameters of B relative to N. Their direction cosine
  matrix ``[BN] = I + (8 [s]^2 - 4 (1 - s.s) [s]) / (1 + s.s)^2`` (``[s]`` the cross-product
  matrix of ``sigma_BN``) maps N components to B components, ``v_B = [BN] v_N``.
- ``omega_BN_B``: B's angular velocity relative to N, in B components, rad/s.

The sensor's frames on the two bodies (:mod:`svgs_sim.svgs.frames`, ``docs/frames.md``):

- the **camera frame** (OpenCV: x right, y down, z along the boresight) is fixed to the chaser's
  body: a :class:`Mount` gives ``[C B]`` (chaser body components -> camera components) and the
  camera's position in the chaser's body frame;
- the **target frame** (the paper's: origin at the base of the target-3 boom, +z out of the
  pattern's face) is fixed to the target's body by another :class:`Mount`.

Then ``R_cam_target = [C Bc][Bc N][Bt N]^T [T Bt]^T`` and ``t_cam_target_m = [C N] (r_T - r_C)``
(both origins in N), and the paper's state is :func:`svgs_sim.svgs.frames.pose_to_state` of that pose.
:func:`chaser_from_pose` inverts it: the chaser's inertial position and attitude for a given
target state and sensor pose.

Hill frame (Basilisk's ``orbitalMotion.hillFrame``): x radial (out), y along-track (completes),
z along the target's orbit normal; :func:`hill_from_inertial` gives the chaser's position and
velocity relative to the target as seen in the rotating Hill frame (Basilisk's
``orbitalMotion.rv2hill``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from svgs_sim.base.errors import InputError
from svgs_sim.svgs.frames import pose_to_state, state_dict

#: Largest departure of a mount's matrix from a proper rotation.
ROTATION_TOLERANCE = 1e-9


def _vec3(x, name: str) -> np.ndarray:
    a = np.asarray(x, float)
    if a.shape[-1:] != (3,) or not np.all(np.isfinite(a)):
        raise InputError(f"{name}: expected finite 3-vectors, shape (..., 3), got shape {a.shape}")
    return a


def _skew(v: np.ndarray) -> np.ndarray:
    z = np.zeros(v.shape[:-1])
    x, y, w = v[..., 0], v[..., 1], v[..., 2]
    return np.stack([np.stack([z, -w, y], -1), np.stack([w, z, -x], -1), np.stack([-y, x, z], -1)], -2)


def mrp_to_dcm(sigma_BN) -> np.ndarray:
    """Direction cosine matrix of modified Rodrigues parameters.

    Parameters
    ----------
    sigma_BN : array_like, shape (..., 3)
        MRPs of frame B relative to frame N.

    Returns
    -------
    dcm_BN : ndarray, shape (..., 3, 3)
        ``[BN]``: N components -> B components (Schaub & Junkins eq. 3.153).
    """
    s = _vec3(sigma_BN, "sigma_BN")
    S = _skew(s)
    s2 = np.sum(s * s, -1)[..., None, None]
    return np.eye(3) + (8.0 * S @ S - 4.0 * (1.0 - s2) * S) / (1.0 + s2) ** 2


def dcm_to_mrp(dcm_BN) -> np.ndarray:
    """Modified Rodrigues parameters of a direction cosine matrix (the short set, ``|sigma| <= 1``).

    Parameters
    ----------
    dcm_BN : array_like, shape (..., 3, 3)
        A proper rotation ``[BN]``.

    Returns
    -------
    sigma_BN : ndarray, shape (..., 3)
        ``sigma = beta_vec / (1 + beta_0)`` of the Euler parameters with ``beta_0 >= 0``
        (Sheppard's method for the Euler parameters, Schaub & Junkins sec. 3.3).
    """
    C = np.asarray(dcm_BN, float)
    if C.shape[-2:] != (3, 3) or not np.all(np.isfinite(C)):
        raise InputError(f"dcm_BN: expected finite 3x3 matrices, got shape {C.shape}")
    tr = np.trace(C, axis1=-2, axis2=-1)
    b2 = np.stack([(1 + tr) / 4, (1 + 2 * C[..., 0, 0] - tr) / 4, (1 + 2 * C[..., 1, 1] - tr) / 4,
                   (1 + 2 * C[..., 2, 2] - tr) / 4], -1)
    i = np.argmax(b2, -1)
    bi = np.sqrt(np.maximum(np.take_along_axis(b2, i[..., None], -1)[..., 0], 0.0))
    p01 = (C[..., 1, 2] - C[..., 2, 1]) / 4  # b0 b1
    p02 = (C[..., 2, 0] - C[..., 0, 2]) / 4  # b0 b2
    p03 = (C[..., 0, 1] - C[..., 1, 0]) / 4  # b0 b3
    p12 = (C[..., 0, 1] + C[..., 1, 0]) / 4  # b1 b2
    p13 = (C[..., 2, 0] + C[..., 0, 2]) / 4  # b1 b3
    p23 = (C[..., 1, 2] + C[..., 2, 1]) / 4  # b2 b3
    cand = [np.stack([bi, p01 / bi, p02 / bi, p03 / bi], -1), np.stack([p01 / bi, bi, p12 / bi, p13 / bi], -1),
            np.stack([p02 / bi, p12 / bi, bi, p23 / bi], -1), np.stack([p03 / bi, p13 / bi, p23 / bi, bi], -1)]
    beta = np.choose(i[..., None], cand)
    beta = np.where(beta[..., :1] < 0, -beta, beta)
    return beta[..., 1:] / (1.0 + beta[..., :1])


def _check_rotation(R, name: str) -> np.ndarray:
    R = np.asarray(R, float)
    if R.shape != (3, 3) or not np.all(np.isfinite(R)):
        raise InputError(f"{name}: expected a finite 3x3 rotation matrix, got shape {R.shape}")
    if np.max(np.abs(R @ R.T - np.eye(3))) > ROTATION_TOLERANCE or np.linalg.det(R) < 0:
        raise InputError(f"{name}: not a proper rotation (R R^T != I or det < 0)")
    return R


@dataclass(frozen=True)
class Mount:
    """A sensor frame fixed to a spacecraft body.

    Attributes
    ----------
    dcm_frame_body : ndarray, shape (3, 3)
        Body components -> the frame's components (``[C B]`` of the camera, ``[T B]`` of the
        target pattern).
    origin_body_m : ndarray, shape (3,)
        The frame's origin (the camera's perspective centre, the pattern's origin) in the body
        frame, relative to the body frame's origin, m.
    """

    dcm_frame_body: np.ndarray = field(default_factory=lambda: np.eye(3))
    origin_body_m: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def __post_init__(self):
        object.__setattr__(self, "dcm_frame_body", _check_rotation(self.dcm_frame_body, "Mount.dcm_frame_body"))
        o = np.asarray(self.origin_body_m, float)
        if o.shape != (3,) or not np.all(np.isfinite(o)):
            raise InputError(f"Mount.origin_body_m: expected 3 finite numbers (m), got {self.origin_body_m!r}")
        object.__setattr__(self, "origin_body_m", o)

    def frame_in_inertial(self, r_BN_N_m, sigma_BN) -> tuple[np.ndarray, np.ndarray]:
        """The frame's attitude and origin for the body's state.

        Parameters
        ----------
        r_BN_N_m : array_like, shape (3,)
        sigma_BN : array_like, shape (3,)

        Returns
        -------
        dcm_frame_N : ndarray, shape (3, 3)
            Inertial components -> the frame's components.
        r_origin_N_m : ndarray, shape (3,)
            The frame's origin in N, m.
        """
        BN = mrp_to_dcm(sigma_BN)
        r = _vec3(r_BN_N_m, "r_BN_N_m")
        return self.dcm_frame_body @ BN, r + BN.T @ self.origin_body_m


def relative_pose(r_chaser_N_m, sigma_chaser_BN, r_target_N_m, sigma_target_BN, camera: Mount,
                  pattern: Mount) -> tuple[np.ndarray, np.ndarray]:
    """The sensor's pose from the two spacecraft's inertial states.

    Parameters
    ----------
    r_chaser_N_m, r_target_N_m : array_like, shape (3,)
        Body origins in N (Basilisk's ``r_BN_N``), m.
    sigma_chaser_BN, sigma_target_BN : array_like, shape (3,)
        Body attitudes (Basilisk's ``sigma_BN``).
    camera : Mount
        The camera frame on the chaser.
    pattern : Mount
        The target frame on the target.

    Returns
    -------
    R_cam_target : ndarray, shape (3, 3)
    t_cam_target_m : ndarray, shape (3,)
        ``p_cam = R_cam_target @ p_target + t_cam_target_m`` (:mod:`svgs_sim.svgs.frames`).
    """
    CN, r_C = camera.frame_in_inertial(r_chaser_N_m, sigma_chaser_BN)
    TN, r_T = pattern.frame_in_inertial(r_target_N_m, sigma_target_BN)
    return CN @ TN.T, CN @ (r_T - r_C)


def relative_state(r_chaser_N_m, sigma_chaser_BN, r_target_N_m, sigma_target_BN, camera: Mount,
                   pattern: Mount) -> dict:
    """The paper's state (:data:`svgs_sim.svgs.frames.STATE_KEYS`, m and deg) of the two spacecraft's states
    (the arguments of :func:`relative_pose`)."""
    return state_dict(pose_to_state(*relative_pose(r_chaser_N_m, sigma_chaser_BN, r_target_N_m, sigma_target_BN,
                                                   camera, pattern)))


def chaser_from_pose(R_cam_target, t_cam_target_m, r_target_N_m, sigma_target_BN, camera: Mount,
                     pattern: Mount) -> tuple[np.ndarray, np.ndarray]:
    """The chaser's inertial position and attitude that put the sensor at a pose (the inverse of
    :func:`relative_pose`).

    Parameters
    ----------
    R_cam_target : array_like, shape (3, 3)
    t_cam_target_m : array_like, shape (3,)
    r_target_N_m, sigma_target_BN : array_like, shape (3,)
    camera, pattern : Mount

    Returns
    -------
    r_chaser_N_m : ndarray, shape (3,)
    sigma_chaser_BN : ndarray, shape (3,)
    """
    R = _check_rotation(R_cam_target, "R_cam_target")
    t = _vec3(t_cam_target_m, "t_cam_target_m")
    TN, r_T = pattern.frame_in_inertial(r_target_N_m, sigma_target_BN)
    CN = R @ TN
    BN = camera.dcm_frame_body.T @ CN
    r_C = r_T - CN.T @ t
    return r_C - BN.T @ camera.origin_body_m, dcm_to_mrp(BN)


def hill_dcm(r_target_N_m, v_target_N_m_s) -> np.ndarray:
    """``[H N]`` of the target's Hill frame (x radial, y along-track, z orbit normal), shape (3, 3)."""
    r = _vec3(r_target_N_m, "r_target_N_m")
    v = _vec3(v_target_N_m_s, "v_target_N_m_s")
    ir = r / np.linalg.norm(r)
    h = np.cross(r, v)
    ih = h / np.linalg.norm(h)
    return np.array([ir, np.cross(ih, ir), ih])


def hill_from_inertial(r_target_N_m, v_target_N_m_s, r_chaser_N_m, v_chaser_N_m_s) -> tuple[np.ndarray, np.ndarray]:
    """The chaser relative to the target in the target's rotating Hill frame.

    Returns
    -------
    rho_H_m : ndarray, shape (3,)
    rho_dot_H_m_s : ndarray, shape (3,)
        The rate as seen in the rotating frame: ``[HN](v_c - v_t) - omega_HN x rho`` with
        ``omega_HN = |r x v| / r^2`` along the orbit normal (the osculating orbit's true-anomaly
        rate).
    """
    r, v = _vec3(r_target_N_m, "r_target_N_m"), _vec3(v_target_N_m_s, "v_target_N_m_s")
    HN = hill_dcm(r, v)
    w = np.array([0.0, 0.0, np.linalg.norm(np.cross(r, v)) / (r @ r)])
    rho = HN @ (_vec3(r_chaser_N_m, "r_chaser_N_m") - r)
    return rho, HN @ (_vec3(v_chaser_N_m_s, "v_chaser_N_m_s") - v) - np.cross(w, rho)


def inertial_from_hill(r_target_N_m, v_target_N_m_s, rho_H_m, rho_dot_H_m_s) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of :func:`hill_from_inertial`: the chaser's ``(r_N, v_N)``, m and m/s."""
    r, v = _vec3(r_target_N_m, "r_target_N_m"), _vec3(v_target_N_m_s, "v_target_N_m_s")
    HN = hill_dcm(r, v)
    w = np.array([0.0, 0.0, np.linalg.norm(np.cross(r, v)) / (r @ r)])
    rho = _vec3(rho_H_m, "rho_H_m")
    return r + HN.T @ rho, v + HN.T @ (_vec3(rho_dot_H_m_s, "rho_dot_H_m_s") + np.cross(w, rho))


def propagate_body(r_BN_N_m, v_BN_N_m_s, sigma_BN, omega_BN_B_rad_s, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """A body's position and attitude ``dt_s`` later at constant velocity and angular velocity
    (for the image velocity of the spots over a few milliseconds).

    Returns
    -------
    r_BN_N_m : ndarray, shape (3,)
    sigma_BN : ndarray, shape (3,)
        ``[BN](t + dt) = exp(-[omega] dt) [BN](t)`` (Rodrigues' formula; ``d[BN]/dt = -[omega][BN]``).
    """
    w = _vec3(omega_BN_B_rad_s, "omega_BN_B_rad_s")
    a = float(np.linalg.norm(w)) * float(dt_s)
    K = _skew(w / np.linalg.norm(w)) if a > 0 else np.zeros((3, 3))
    E = np.eye(3) - np.sin(a) * K + (1.0 - np.cos(a)) * K @ K
    return _vec3(r_BN_N_m, "r_BN_N_m") + _vec3(v_BN_N_m_s, "v_BN_N_m_s") * float(dt_s), \
        dcm_to_mrp(E @ mrp_to_dcm(sigma_BN))
