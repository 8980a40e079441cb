"""What the parts of the calibration study share: defaults, the true camera, number lists,
study-level seeds and cameras written as flat scenario columns.

The true camera. A profile such as ``galaxy-nexus`` states the paper-style *nominal*
camera: principal point at the image centre, no distortion (ASSUMPTION in the profile).
A real phone differs; the study's true camera is the profile plus a principal-point offset
and distortion (:func:`true_camera`; defaults :data:`DEFAULT_TRUE_PP_OFFSET_PX`,
:data:`DEFAULT_TRUE_DIST`, ASSUMPTIONS).
"""

from __future__ import annotations

import json

import numpy as np

from svgs_sim.base.errors import InputError, number_items
from svgs_sim.base.profiles import DISTORTION_KEYS, Camera
from svgs_sim.svgs.frames import STATE_KEYS

#: Numbers of views the convergence study calibrates from.
DEFAULT_VIEWS_LIST = (5, 10, 20, 40)
#: Subsets of views per N (the first is views 0..N-1; the others drawn at random).
DEFAULT_SUBSETS = 3
#: Default board of the rendered sets: OpenCV's 9 x 6 chessboard with 100 mm squares
#: (1.2 x 0.9 m with its margin), large enough to sit near the phones' fixed focus (1.8 m)
#: while filling half the frame.
DEFAULT_BOARD = ("chessboard", 9, 6, 0.100)
#: The real camera's principal point minus the nominal one, px. ASSUMPTION: one sigma of the
#: spread ``svgs campaign --calibration paper`` draws (15 px per axis, docs/studies.md):
#: lens-to-sensor centring of phone modules leaves offsets of tens of pixels; no
#: measurement of the Galaxy Nexus was found.
DEFAULT_TRUE_PP_OFFSET_PX = (15.0, -15.0)
#: The real camera's distortion added to the profile's (k1, k2, p1, p2, k3). ASSUMPTION: one
#: sigma of the campaign's k1 spread (0.03: +1.3 % radial scale at the image corners of a
#: 2592 x 1944, f = 2450 px camera); not measured for the Galaxy Nexus.
DEFAULT_TRUE_DIST = (0.03, 0.0, 0.0, 0.0, 0.0)
#: Ranges of the focal-length images (the paper: "a succession of images ... from a known
#: range"; the issue: 1-10 m).
DEFAULT_FOCAL_RANGES_M = tuple(float(r) for r in range(1, 11))
#: Exposures per rendered focal frame (render once, expose many).
DEFAULT_FOCAL_EXPOSURES = 4
#: Centroid noise added in the focal study, px per axis.
DEFAULT_NOISE_LEVELS_PX = (0.0, 0.1, 0.3, 1.0)
#: Noise draws per exposure and range set in the focal study (1 when no noise is added).
DEFAULT_FOCAL_TRIALS = 8
#: Ranges of the pose-error study, m.
DEFAULT_POSE_RANGES_M = (1.0, 2.0, 3.0, 5.0, 7.5, 10.0, 15.0, 20.0, 25.0, 30.0, 35.0, 40.0)
#: Ranges at which the report compares focal-only and full calibrations (the paper's Table 4).
REPORT_RANGES_M = (5.0, 10.0, 20.0, 30.0)
#: Poses per range in the pose study and their spread. ASSUMPTION: the paper does not list
#: its test attitudes; roll and pitch +-15 deg, yaw +-30 deg, the target within 3 % of the
#: range of the boresight.
DEFAULT_POSES_PER_RANGE = 16
POSE_SPREAD = {"roll_deg": 15.0, "pitch_deg": 15.0, "yaw_deg": 30.0, "lateral_fraction": 0.03}
#: Centroid noise of the noise-floor runs, px per axis.
DEFAULT_FLOOR_NOISE_PX = (0.1, 0.3)
#: Centroid noise of the geometric (no-render) focal frames, px per axis.
GEOMETRIC_CENTROID_NOISE_PX = 0.1
#: Pose error components (paper state: m, m, m, deg, deg, deg).
STATE_COLS = STATE_KEYS  # the paper's state keys (svgs_sim.svgs.frames)
#: The flat scenario columns of a camera's geometry (see :func:`camera_columns`).
CAMERA_FIELDS = ("width_px", "height_px", "fx_px", "fy_px", "cx_px", "cy_px", *DISTORTION_KEYS)


def parse_number_list(text, name: str, *, integer: bool = False, minimum=None) -> tuple:
    """``"5,10,20"`` -> ``(5, 10, 20)``; raises :class:`InputError` naming ``name``."""
    if isinstance(text, (list, tuple)):
        items = list(text)
    else:
        items = number_items(text, name) if str(text).strip() else []
    if not items:
        raise InputError(f"{name}: expected a comma-separated list of numbers, got {text!r}")
    out = []
    for s in items:
        try:
            v = float(s)
        except (TypeError, ValueError):
            raise InputError(f"{name}: {s!r} is not a number (expected e.g. '5,10,20')") from None
        if not np.isfinite(v):
            raise InputError(f"{name}: {s!r} is not finite")
        if integer:
            if v != int(v):
                raise InputError(f"{name}: {s!r} is not a whole number")
            v = int(v)
        if minimum is not None and v < minimum:
            raise InputError(f"{name}: {s!r} is below the minimum {minimum}")
        out.append(v)
    return tuple(out)


def true_camera(nominal: Camera, pp_offset_px=DEFAULT_TRUE_PP_OFFSET_PX, dist_delta=DEFAULT_TRUE_DIST) -> Camera:
    """The study's real camera: the nominal profile plus a principal-point offset and distortion.

    Parameters
    ----------
    nominal : Camera
    pp_offset_px : (float, float)
        Added to ``(cx, cy)``.
    dist_delta : sequence of 5 float
        Added to ``(k1, k2, p1, p2, k3)``.

    Returns
    -------
    Camera
        Named ``<nominal>-true``.
    """
    off = np.asarray(pp_offset_px, float).reshape(-1)
    dd = np.asarray(dist_delta, float).reshape(-1)
    if off.shape != (2,) or not np.all(np.isfinite(off)):
        raise InputError(f"true principal-point offset: expected two finite numbers (px), got {pp_offset_px!r}")
    if dd.shape != (5,) or not np.all(np.isfinite(dd)):
        raise InputError(f"true distortion: expected 5 finite numbers k1,k2,p1,p2,k3, got {dist_delta!r}")
    cx, cy = nominal.cx + off[0], nominal.cy + off[1]
    if not (0 <= cx <= nominal.width - 1 and 0 <= cy <= nominal.height - 1):
        raise InputError(f"true principal point ({cx:g}, {cy:g}) lies outside the {nominal.width} x {nominal.height} image")
    return nominal.replace(name=f"{nominal.name}-true", cx=float(cx), cy=float(cy), dist=np.asarray(nominal.dist) + dd)


def spawn_seeds(seed: int, n: int) -> list[int]:
    """``n`` integer seeds of the study's parts: the first word of each child of
    ``SeedSequence(seed)`` (the same for any executor; they fix the study's numbers)."""
    return [int(s.generate_state(1)[0]) for s in np.random.SeedSequence(int(seed)).spawn(n)]


def camera_columns(prefix: str, camera: Camera) -> dict:
    """A camera's geometry as flat scenario columns ``<prefix>width_px`` ... ``<prefix>k3``.

    Floats are stored exactly (the results store writes ``repr``), so
    :func:`camera_from_columns` rebuilds the same projection in a worker.
    """
    vals = (int(camera.width), int(camera.height), float(camera.fx), float(camera.fy), float(camera.cx),
            float(camera.cy), *(float(v) for v in camera.dist))
    return {f"{prefix}{k}": v for k, v in zip(CAMERA_FIELDS, vals)}


def camera_from_columns(prefix: str, scenario: dict, name: str = "") -> Camera:
    """The camera :func:`camera_columns` wrote (geometry only: no sensor or optics tables)."""
    g = {k: scenario[f"{prefix}{k}"] for k in CAMERA_FIELDS}
    return Camera(name=name or prefix.rstrip("_"), width=int(g["width_px"]), height=int(g["height_px"]),
                  fx=float(g["fx_px"]), fy=float(g["fy_px"]), cx=float(g["cx_px"]), cy=float(g["cy_px"]),
                  dist=np.array([float(g[k]) for k in DISTORTION_KEYS]))


def cam_json(c: Camera) -> dict:
    """A camera's geometry for ``cameras.csv`` and the report."""
    return {"width": c.width, "height": c.height, "fx": c.fx, "fy": c.fy, "cx": c.cx, "cy": c.cy,
            **{k: float(v) for k, v in zip(DISTORTION_KEYS, c.dist)}}


def profile_dict(c: Camera) -> dict:
    """A camera's whole profile (JSON round-trip, name left out): what a cache must match."""

    d = json.loads(json.dumps(c.to_dict(), default=float))
    d.pop("name", None)
    return d


def row_at(rows, case, range_m, noise_px=0.0):
    """The pose-error row of ``case`` at ``range_m`` and ``noise_px`` (None if absent)."""
    for r in rows:
        if r["case"] == case and r["range_m"] == float(range_m) and r["noise_px"] == float(noise_px):
            return r
    return None
