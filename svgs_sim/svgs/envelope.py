"""Where the sensor is asked to work: the paper's test envelope (:data:`PAPER_ENVELOPE`: a pose
outside it is solved but flagged ``outside_test_envelope``), the sensor's physical envelope
(:func:`physical_envelope`: the identification's gates and its verified-pose check,
:mod:`svgs_sim.svgs.identify`) and the simulator's envelope (:func:`range_envelope_m`, :data:`ATTITUDE_LIMITS_DEG`): the ranges and
attitudes every command, range list, trajectory file and sensitivity bound is checked against."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..base.errors import InputError
from ..base.profiles import load_camera, load_pattern
from .frames import D_CAM_PHOTO, angles_from_rotation


@dataclass(frozen=True)
class Envelope:
    """Operating envelope (paper, "Test Setup"): where identification must work.

    Attributes
    ----------
    range_interval_m : tuple of float
        Nearest and farthest range of the target along the boresight, metres.
    roll_deg, pitch_deg, yaw_deg : float
        Largest absolute attitude angles (paper's phi, theta, psi), degrees.
    lateral_fraction : float
        Largest lateral offset of the target origin as a fraction of the range. On the
        paper's stand the gimbal turns the *phone* (yaw +/-45 deg), so the target may sit
        anywhere in the field of view: 0.6 is tan(31 deg), the half-field of the wider of
        the paper's phones (the Amaze 4G's +/-31.8 deg horizontal). It was 0.15 (a target
        offset in front of a fixed camera), which refused every stand attitude turned more
        than ~16 deg off axis (``no_consistent_set``).
    max_incidence_deg : float or None
        Largest angle between the target's face normal (+z) and the line of sight from the
        target to the camera, degrees; ``None``: no limit beyond the roll and pitch ones. The
        physical envelope sets it to the cubes' acceptance, beyond which they return no light
        to the lens.
    """

    range_interval_m: tuple = (1.0, 40.0)
    roll_deg: float = 25.0
    pitch_deg: float = 25.0
    yaw_deg: float = 45.0
    lateral_fraction: float = 0.6
    max_incidence_deg: float | None = None

    def contains(self, R_cam_target, t_cam_target_m, *, margin_deg: float = 0.0, margin_lateral: float = 0.0,
                 margin_range: float = 1.0) -> np.ndarray:
        """Whether poses lie in the envelope (with margins).

        Parameters
        ----------
        R_cam_target : array_like, shape (N, 3, 3) or (3, 3)
            Target-to-camera rotations (OpenCV camera frame: x right, y down, z along the boresight).
        t_cam_target_m : array_like, shape (N, 3) or (3,)
            The target origin in the camera frame, m.
        margin_deg : float
            Added to every angle limit (roll, pitch, yaw, incidence), degrees.
        margin_lateral : float
            Added to :attr:`lateral_fraction`.
        margin_range : float
            The range interval is widened to ``[near / margin_range, far * margin_range]``.

        Returns
        -------
        ndarray of bool, shape (N,) (or a bool for one pose)
        """
        R = np.asarray(R_cam_target, float)
        t = np.asarray(t_cam_target_m, float)
        one = R.ndim == 2
        R, t = R.reshape(-1, 3, 3), t.reshape(-1, 3)
        ang = np.degrees(angles_from_rotation(D_CAM_PHOTO @ R))  # (N, 3) roll, pitch, yaw
        lim = np.array([self.roll_deg, self.pitch_deg, self.yaw_deg]) + margin_deg
        ok = np.all(np.abs(ang) <= lim, axis=1)
        rng = t[:, 2]
        ok &= (rng >= self.range_interval_m[0] / margin_range) & (rng <= self.range_interval_m[1] * margin_range)
        lat = np.max(np.abs(t[:, :2]), axis=1) / np.maximum(rng, 1e-9)
        ok &= lat <= self.lateral_fraction + margin_lateral
        if self.max_incidence_deg is not None:
            ok &= incidence_deg(R, t) <= self.max_incidence_deg + margin_deg
        return bool(ok[0]) if one else ok


def incidence_deg(R_cam_target, t_cam_target_m) -> np.ndarray:
    """Angle between the target's face normal (its +z) and the line of sight from the target's
    origin to the camera, degrees.

    Parameters
    ----------
    R_cam_target : array_like, shape (N, 3, 3)
    t_cam_target_m : array_like, shape (N, 3)

    Returns
    -------
    ndarray, shape (N,)
    """
    R = np.asarray(R_cam_target, float).reshape(-1, 3, 3)
    t = np.asarray(t_cam_target_m, float).reshape(-1, 3)
    los = -t / np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-12)
    return np.degrees(np.arccos(np.clip(np.einsum("ni,ni->n", R[:, :, 2], los), -1.0, 1.0)))


#: The paper's test envelope: range 1-40 m, roll/pitch +/-25 deg, yaw +/-45 deg, the target anywhere
#: in the field of view (lateral offsets up to 60 % of the range).
PAPER_ENVELOPE = Envelope()

#: What the command line says of a solution flagged ``outside_test_envelope``.
OUTSIDE_TEST_ENVELOPE_NOTE = ("this pose lies outside the paper's test envelope (range 1-40 m, roll and pitch 25 deg, "
                              "yaw 45 deg): inside the sensor's physical envelope, where the paper did not test it")

#: The phone sensor's far limit: beyond the range where the pattern spans this many pixels its
#: four spots merge into one blob (no identification is possible).
MIN_SPAN_PX = 4.0
#: The phone sensor's near limit: closer than the range where the pattern spans this many times
#: the shorter side of the frame (the whole pattern is then far outside the image).
MAX_FILL = 4.0
#: Largest absolute attitude angles the simulator takes, degrees (the paper's x-y-z sequence):
#: roll and pitch turn the target's face away from the camera beyond 90 deg (its reflectors
#: then return no light); yaw, a turn about the boresight, is one turn at +/-180 deg. The
#: paper's test envelope (:data:`PAPER_ENVELOPE`) lies inside.
ATTITUDE_LIMITS_DEG = {"roll_deg": 90.0, "pitch_deg": 90.0, "yaw_deg": 180.0}


def range_envelope_m(camera, pattern="svgs-3u") -> tuple[float, float]:
    """The ranges along the boresight the simulator takes for a camera and a pattern: one
    definition for ``--range``, range lists, trajectory files and sensitivity bounds.

    Parameters
    ----------
    camera : Camera or str
    pattern : Pattern or str

    Returns
    -------
    (near_m, far_m) : tuple of float
        ``near_m``: the pattern's widest span is :data:`MAX_FILL` times the shorter side of the
        frame; ``far_m``: it spans :data:`MIN_SPAN_PX` pixels (its spots merge into one).
    """
    cam, pat = load_camera(camera), load_pattern(pattern)
    span, f = _span_m(pat), float(np.sqrt(cam.fx * cam.fy))
    return f * span / (MAX_FILL * min(cam.width, cam.height)), f * span / MIN_SPAN_PX


def _span_m(pattern) -> float:
    """The pattern's widest span in its plane, m."""
    P = np.asarray(pattern.points_m, float)[:, :2]
    return float(max(np.linalg.norm(a - b) for a in P for b in P))


def field_of_view_fraction(camera) -> float:
    """The largest lateral offset over range that still lies in the image: the largest ``|x|``
    or ``|y|`` (normalised, undistorted) over the frame's edge pixels (corners and edge midpoints).

    Parameters
    ----------
    camera : Camera or str

    Returns
    -------
    float
        ``max(|X| / Z, |Y| / Z)`` of a point on the frame's border (the metric of
        :attr:`Envelope.lateral_fraction`).
    """
    cam = load_camera(camera)
    w, h = cam.width - 0.5, cam.height - 0.5
    edge = np.array([[-0.5, -0.5], [w, -0.5], [-0.5, h], [w, h], [cam.cx, -0.5], [cam.cx, h], [-0.5, cam.cy],
                     [w, cam.cy]], float)
    return float(np.max(np.abs(cam.pixels_to_normalized(edge))))


def physical_envelope(camera, pattern="svgs-3u") -> Envelope:
    """Where the sensor can see its targets at all: the identification's gates and its
    verified-pose check are built from it (:func:`svgs_sim.svgs.identify.identify`).

    - **Range**: from where the pattern's widest span fills the frame's diagonal (closer, all
      four targets cannot be in the image at once) to where it spans :data:`MIN_SPAN_PX`
      pixels (farther, its spots merge into one blob; :func:`range_envelope_m`).
    - **Field of view**: the target origin anywhere in the frame (:func:`field_of_view_fraction`).
    - **Attitude**: the face normal within the cubes' acceptance of the line of sight (the
      pattern file's ``[reflector] acceptance_deg``: the largest incidence at which the
      renderer's cubes still return the flash to the lens of a shipped phone,
      ``tools/reflector_acceptance.py``); any turn about the boresight. A pattern without an
      acceptance is limited by :data:`ATTITUDE_LIMITS_DEG` only.

    Parameters
    ----------
    camera : Camera or str
    pattern : Pattern or str

    Returns
    -------
    Envelope
    """
    cam, pat = load_camera(camera), load_pattern(pattern)
    near = float(np.sqrt(cam.fx * cam.fy)) * _span_m(pat) / float(np.hypot(cam.width, cam.height))
    far = range_envelope_m(cam, pat)[1]
    acc = getattr(pat.reflector, "acceptance_deg", None)
    return Envelope(range_interval_m=(near, far), roll_deg=ATTITUDE_LIMITS_DEG["roll_deg"],
                    pitch_deg=ATTITUDE_LIMITS_DEG["pitch_deg"], yaw_deg=ATTITUDE_LIMITS_DEG["yaw_deg"],
                    lateral_fraction=field_of_view_fraction(cam),
                    max_incidence_deg=None if acc is None else float(acc))


def check_range_m(values, camera, pattern="svgs-3u", what: str = "--range") -> list[float]:
    """``values`` (m) as floats if every one lies in :func:`range_envelope_m`, else :class:`InputError`.

    Parameters
    ----------
    values : float or sequence of float
        Ranges along the boresight, m.
    camera, pattern : Camera/Pattern or str
    what : str
        The input's name for the message (an option, a file and line, a ``--vary`` bound).

    Raises
    ------
    InputError
        A value that is not a finite number, or outside the envelope; the message names
        ``what``, the value and the allowed range with its reason.
    """
    vals = [float(v) for v in np.atleast_1d(np.asarray(values, float))]
    cam, pat = load_camera(camera), load_pattern(pattern)
    near, far = range_envelope_m(cam, pat)
    for v in vals:
        if not np.isfinite(v) or v <= 0:
            raise InputError(f"{what}: expected a range of {near:.2f}-{far:.0f} m, got {v!r}")
        if v > far:
            raise InputError(f"{what}: {v:g} m is beyond {far:.0f} m, where the {pat.name} pattern spans fewer than "
                             f"{MIN_SPAN_PX:g} px on {cam.name} and its spots merge into one (allowed "
                             f"{near:.2f}-{far:.0f} m)")
        if v < near:
            raise InputError(f"{what}: {v:g} m is closer than {near:.2f} m, where the {pat.name} pattern spans more "
                             f"than {MAX_FILL:g}x the shorter side of the {cam.name} frame (allowed "
                             f"{near:.2f}-{far:.0f} m)")
    return vals


def check_attitude_deg(name: str, value, what: str | None = None) -> float:
    """``value`` (deg) as a float if it lies within :data:`ATTITUDE_LIMITS_DEG` of ``name``.

    Parameters
    ----------
    name : {"roll_deg", "pitch_deg", "yaw_deg"}
    value : float
    what : str, optional
        The input's name for the message (default ``name``).

    Raises
    ------
    InputError
    """
    lim = ATTITUDE_LIMITS_DEG[name]
    v = float(value)
    if not (np.isfinite(v) and -lim <= v <= lim):
        raise InputError(f"{what or name}: expected {-lim:g} to {lim:g} deg, got {value!r}")
    return v
