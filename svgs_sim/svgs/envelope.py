"""Where the sensor is asked to work: the paper's test envelope (:data:`PAPER_ENVELOPE`, the
identification's gates and its verified-pose check, :mod:`svgs_sim.svgs.identify`) and the
simulator's envelope (:func:`range_envelope_m`, :data:`ATTITUDE_LIMITS_DEG`): the ranges and
attitudes every command, range list, trajectory file and sensitivity bound is checked against."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..base.errors import InputError
from ..base.profiles import load_camera, load_pattern


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
    """

    range_interval_m: tuple = (1.0, 40.0)
    roll_deg: float = 25.0
    pitch_deg: float = 25.0
    yaw_deg: float = 45.0
    lateral_fraction: float = 0.6


#: The paper's test envelope: range 1-40 m, roll/pitch +/-25 deg, yaw +/-45 deg, the target anywhere
#: in the field of view (lateral offsets up to 60 % of the range).
PAPER_ENVELOPE = Envelope()

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
    P = np.asarray(pat.points_m, float)[:, :2]
    span = float(max(np.linalg.norm(a - b) for a in P for b in P))
    f = float(np.sqrt(cam.fx * cam.fy))
    return f * span / (MAX_FILL * min(cam.width, cam.height)), f * span / MIN_SPAN_PX


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
