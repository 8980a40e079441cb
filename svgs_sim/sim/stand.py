"""The paper's test stand as a kinematic chain: the phone on a gimbal, the target fixed.

Becker, Howard & Rakoczy (2014), MSFC Flight Robotics Laboratory: the target pattern sat on a
fixed Target Mount; the SVGS phone sat on the Sensor Mount, "a 3-axis rotation motorized
gimbal mounted on a 1-axis motorized translation stage", +/-25 deg roll and pitch, +/-45 deg
yaw, the stage +/-15 cm "on an axis aligned in the direction between the Sensor and Target
Mounts", the whole on a cart on a rail along the lab. So the *phone* turns, about the
gimbal's pivot, and the target stays still - unlike :func:`svgs_sim.svgs.frames.pose_from_scenario`,
which sets the target's attitude in front of the camera.

The chain, target (world) frame first (ASSUMPTIONS marked; each is a parameter of
:class:`TestStand`):

1. **Rail**: along the line from the target origin to the camera's nominal position (the
   camera facing the target, the pattern's own attitude zero: :func:`pose_from_scenario` at
   zero angles). The cart puts the gimbal's pivot at ``rail_m`` plus the stage's
   ``stage_m`` (positive: away from the target) along it.
2. **Gimbal**, named as the paper names the relative attitude (its roll, pitch, yaw = phi,
   theta, psi; :mod:`svgs_sim.svgs.frames`): ``roll`` turns the camera about its horizontal axis,
   ``pitch`` about its vertical axis, ``yaw`` about its boresight - the right-hand rule about
   the OpenCV camera axes +x (right), -y (up) and -z, signs chosen so that each gimbal angle
   alone is the same angle of the truth state. Why the paper's yaw is the rotation about the
   line of sight (ASSUMPTION, argued from the paper's own numbers): its yaw error has by far
   the smallest scatter at every range (Nexus 0.04-0.26 deg against roll 0.39-1.5 and pitch
   0.24-0.72, Table 5), which is what a camera gives for the in-plane rotation of a pattern and
   not for the out-of-plane tilts; and the +/-45 deg it gives the yaw axis would put the target
   outside a +/-28 deg field of view if yaw turned the boresight, yet the paper reports solutions
   over the whole envelope. The order of the axes, outer to inner (ASSUMPTION,
   ``axis_order``): pitch (a pan about the vertical), then roll (a tilt), then yaw about the
   boresight - the usual build of a pan-tilt-roll head.
3. **Pivot to perspective centre** (ASSUMPTION, ``pivot_to_camera_m``): the camera's
   perspective centre relative to the pivot in the camera frame, default 3 cm in front of it
   along the boresight (a phone clamped to a gimbal plate, the lens ahead of the axes).
4. **Installation misalignment** (``misalignment_deg``, default 0): the phone's rotation in
   its holder (roll, pitch, yaw about the same axes), innermost. The paper's near-constant
   2 deg yaw error at every range for the Galaxy Nexus (Table 4, with a yaw scatter of only
   0.04-0.26 deg, Table 5) looks like one: a phone clamped 2 deg rotated about its lens axis.
   It is an error of the truth, not of the sensor: the image is made at the actual pose and
   the lab's truth is the commanded one.

Truth states come out of the chain in the paper's convention (:func:`svgs_sim.svgs.frames.pose_to_state`).

The field of view cuts the gimbal's envelope: +/-25 deg of roll (the tilt about the
horizontal axis) exceeds the Galaxy Nexus' +/-21.6 deg vertical half-field (the Amaze's
+/-24.9 deg) and +/-25 deg of pitch comes close to its +/-27.9 deg horizontal one, so a phone
turned that far no longer sees the whole target. :func:`sample_in_view` draws the gimbal
uniformly over its envelope and keeps the draws in which every target projects inside the
image with a margin (rejection): the attitudes the paper could have recorded solutions for.
Its ``info`` says what fraction was kept and the roll span that remains.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from svgs_sim.base.errors import InputError
from svgs_sim.svgs.frames import pose_from_scenario, pose_to_state

#: The paper's Sensor Mount envelope (Becker, Howard & Rakoczy 2014, "SVGS testing").
GIMBAL_LIMITS_DEG = {"roll_deg": 25.0, "pitch_deg": 25.0, "yaw_deg": 45.0}
STAGE_LIMIT_M = 0.15
AXIS_ORDERS = ("pitch-roll-yaw", "roll-pitch-yaw")


def _axis_rotation(axis: str, angle_deg: float) -> np.ndarray:
    """Rotation (camera frame, active) about a camera axis by the stand's sign convention:
    ``roll`` about +x, ``pitch`` about -y (up), ``yaw`` about -z, so that each angle alone is
    the same angle of the paper's truth state."""
    a = np.deg2rad(float(angle_deg))
    c, s = np.cos(a), np.sin(a)
    if axis == "roll":  # about +x: positive turns the boresight up (towards -y)
        return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
    if axis == "pitch":  # about -y (up): positive turns the boresight to the camera's left (-x)
        return np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])
    if axis == "yaw":  # about -z: the image turns about the boresight
        return np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    raise ValueError(axis)


@dataclass(frozen=True)
class TestStand:
    """The FRL stand's geometry (see the module docstring for the chain and its ASSUMPTIONS).

    Attributes
    ----------
    pivot_to_camera_m : tuple of float
        The camera's perspective centre relative to the gimbal pivot, camera frame (OpenCV
        axes), m.
    axis_order : str
        ``"pitch-roll-yaw"`` (outer to inner, default) or ``"roll-pitch-yaw"``.
    misalignment_deg : tuple of float
        The phone's (roll, pitch, yaw) in its holder, deg (the gimbal's axes).
    """

    __test__ = False  # not a pytest class, whatever its name

    pivot_to_camera_m: tuple = (0.0, 0.0, 0.03)
    axis_order: str = "pitch-roll-yaw"
    misalignment_deg: tuple = (0.0, 0.0, 0.0)

    def __post_init__(self):
        o = np.asarray(self.pivot_to_camera_m, float)
        if o.shape != (3,) or not np.all(np.isfinite(o)) or np.linalg.norm(o) > 1.0:
            raise InputError(f"pivot_to_camera_m: expected 3 finite numbers within 1 m, got {self.pivot_to_camera_m!r}")
        if self.axis_order not in AXIS_ORDERS:
            raise InputError(f"axis_order: expected one of {AXIS_ORDERS}, got {self.axis_order!r}")
        m = np.asarray(self.misalignment_deg, float)
        if m.shape != (3,) or not np.all(np.isfinite(m)) or np.any(np.abs(m) > 10.0):
            raise InputError(f"misalignment_deg: expected (roll, pitch, yaw) within +/-10 deg, got {self.misalignment_deg!r}")

    def to_json(self) -> dict:
        d = asdict(self)
        return {k: list(v) if isinstance(v, tuple) else v for k, v in d.items()}

    def gimbal_rotation(self, roll_deg: float, pitch_deg: float, yaw_deg: float) -> np.ndarray:
        """``R_nominal-camera_camera`` of the gimbal at these angles (misalignment included), (3, 3)."""
        g = {"roll": roll_deg, "pitch": pitch_deg, "yaw": yaw_deg}
        names = self.axis_order.split("-")
        R = np.eye(3)
        for n in names:  # outer first: R = R_outer @ R_middle @ R_inner
            R = R @ _axis_rotation(n, g[n])
        mr, mp, my = self.misalignment_deg
        return R @ _axis_rotation("pitch", mp) @ _axis_rotation("roll", mr) @ _axis_rotation("yaw", my)

    def pose(self, rail_m: float, *, stage_m: float = 0.0, roll_deg: float = 0.0, pitch_deg: float = 0.0,
             yaw_deg: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """The camera's pose for a stand setting.

        Parameters
        ----------
        rail_m : float
            Rail position: the pivot's distance from the target origin with the stage at 0, m.
        stage_m : float
            Translation stage, m, positive away from the target (+/-0.15 m on the paper's stand).
        roll_deg, pitch_deg, yaw_deg : float
            Gimbal angles, deg.

        Returns
        -------
        R_cam_target : ndarray, shape (3, 3)
        t_cam_target_m : ndarray, shape (3,)
            ``p_cam = R_cam_target @ p_target + t_cam_target_m``.
        """
        for name, v in (("stage_m", stage_m), ("roll_deg", roll_deg), ("pitch_deg", pitch_deg), ("yaw_deg", yaw_deg)):
            if not np.isfinite(float(v)):
                raise InputError(f"{name}: expected a finite number, got {v!r}")
        o = np.asarray(self.pivot_to_camera_m, float)
        R0, t0 = pose_from_scenario(rail_m)  # nominal: the camera faces the target along the rail
        R_t_c0 = R0.T  # target <- nominal camera
        p_c0 = -R0.T @ t0  # nominal camera position, target frame
        rail = p_c0 / np.linalg.norm(p_c0)  # from the target towards the camera
        # the pivot: where the nominal camera's pivot is (camera at rail_m), moved by the stage
        pivot = p_c0 - R_t_c0 @ o + rail * float(stage_m)
        R_t_c = R_t_c0 @ self.gimbal_rotation(roll_deg, pitch_deg, yaw_deg)
        p_c = pivot + R_t_c @ o
        R = R_t_c.T
        return R, -R @ p_c

    def state(self, rail_m: float, **setting) -> np.ndarray:
        """The truth state (paper convention, :func:`svgs_sim.svgs.frames.pose_to_state`) of a setting
        (``rail_m``: the rail position, m)."""
        return pose_to_state(*self.pose(rail_m, **setting))


def targets_in_view(camera, pattern, R, t, margin_frac: float = 0.02) -> bool:
    """Whether every target lies in front of the camera and projects inside the image, at
    least ``margin_frac`` of the width/height from its edges."""
    p = pattern.points_m @ R.T + t
    if np.any(p[:, 2] <= 0):
        return False
    uv = camera.project(p)
    mx, my = margin_frac * camera.width, margin_frac * camera.height
    return bool(np.all((uv[:, 0] >= mx) & (uv[:, 0] <= camera.width - 1 - mx)
                       & (uv[:, 1] >= my) & (uv[:, 1] <= camera.height - 1 - my)))


def sample_in_view(rng: np.random.Generator, camera, pattern, rail_m: float, n: int, *,
                   stand: TestStand | None = None, limits_deg: dict | None = None,
                   stage_limit_m: float = STAGE_LIMIT_M, margin_frac: float = 0.02, max_draws: int | None = None):
    """Draw ``n`` stand settings uniformly over the gimbal's envelope, keeping those in which
    the camera sees every target.

    Parameters
    ----------
    rng : numpy.random.Generator
        Seeded: the same seed gives the same settings.
    camera : svgs.Camera
    pattern : svgs.Pattern
    rail_m : float
        The rail position, m.
    n : int
    stand : TestStand, optional
    limits_deg : dict, optional
        Half-ranges of ``roll_deg``, ``pitch_deg``, ``yaw_deg`` (default: the paper's, 25/25/45).
    stage_limit_m : float
    margin_frac : float
        See :func:`targets_in_view`.
    max_draws : int, optional
        Give up after this many draws (default ``200 n``): InputError naming the envelope.

    Returns
    -------
    settings : list of dict
        ``stage_m``, ``roll_deg``, ``pitch_deg``, ``yaw_deg`` of each kept draw.
    info : dict
        ``draws``, ``kept``, ``kept_fraction``, ``roll_span_deg`` and ``pitch_span_deg`` (min, max
        of the kept angles),
        the limits used.
    """
    stand = stand or TestStand()
    lim = dict(GIMBAL_LIMITS_DEG if limits_deg is None else limits_deg)
    n = int(n)
    if n < 1:
        raise InputError(f"n: expected at least 1 setting, got {n}")
    max_draws = 200 * n if max_draws is None else int(max_draws)
    out, draws = [], 0
    while len(out) < n:
        if draws >= max_draws:
            raise InputError(
                f"sample_in_view: only {len(out)} of {n} settings keep the target in view after {draws} draws "
                f"at the rail position {rail_m:g} m over roll/pitch/yaw +/-{lim['roll_deg']:g}/{lim['pitch_deg']:g}/{lim['yaw_deg']:g} deg")
        draws += 1
        s = {"stage_m": float(rng.uniform(-stage_limit_m, stage_limit_m)),
             **{k: float(rng.uniform(-lim[k], lim[k])) for k in ("roll_deg", "pitch_deg", "yaw_deg")}}
        R, t = stand.pose(rail_m, **s)
        if targets_in_view(camera, pattern, R, t, margin_frac):
            out.append(s)
    span = {f"{k}_span_deg": [min(s[f"{k}_deg"] for s in out), max(s[f"{k}_deg"] for s in out)] for k in ("roll", "pitch")}
    return out, {"draws": draws, "kept": len(out), "kept_fraction": len(out) / draws,
                 **span, "limits_deg": lim, "stage_limit_m": stage_limit_m,
                 "margin_frac": margin_frac}
