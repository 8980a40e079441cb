"""ToF camera geometry and the marker target: profile loaders and lines of sight.

The ToF camera's geometry is a :class:`svgs_sim.base.profiles.Camera` (pinhole + OpenCV distortion);
its ``[tof]`` table says what the depth image holds. The marker target is a
:class:`svgs_sim.base.profiles.Pattern` whose ``[[target]]`` tables also give each marker's
``diameter_m`` and ``standoff_m``.

Depth convention
    ``depth_kind = "radial"`` (default, what an AMCW camera measures): the distance from the
    optical centre along the pixel's line of sight, so a marker seen at unit line of sight
    ``e`` and depth ``rho`` sits at ``p_cam = rho * e``. ``depth_kind = "z"``: the coordinate
    along the boresight, ``p_cam = z * (xn, yn, 1)``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from svgs_sim.base.errors import InputError, ProfileError
from svgs_sim.base.profile_schema import DEPTH_KINDS, TARGET_KEYS, TOF_CAMERA_TABLES
from svgs_sim.base.profiles import Camera, Pattern, load_pattern
from svgs_sim.base.profiles import load_camera as load_profile

#: Default ToF camera profile (``assets/cameras/tof-epc660.toml``).
DEFAULT_CAMERA = "tof-epc660"
#: Default marker target (``assets/patterns/tof-8.toml``).
DEFAULT_PATTERN = "tof-8"
#: The ToF sensor's range envelope, m: the paper's design range 0.27-15 m (section 2.2), within
#: the 15 m unambiguous range of its 10 MHz modulation (``--range``, range lists, sensitivity bounds).
DESIGN_RANGE_M = (0.27, 15.0)
#: How far a marker's ``standoff_m`` may differ from its face's height above the plate, m
#: (``z_m`` less the plate's ``z``; rounding of the file's decimals).
STANDOFF_TOLERANCE_M = 1e-6


#: Tables that only a phone (SVGS) camera profile has.
PHONE_TABLES = ("flash", "cfa", "isp", "glare", "exposure")
#: What the ToF renderer and pixel model read from a profile.
RENDER_TABLES = ("tof", "optics", "illumination", "noise")


def load_camera(name_or_path=DEFAULT_CAMERA, *, render: bool = False) -> Camera:
    """Load a ToF camera profile (by name or path).

    A geometry-only profile (``[intrinsics]``, optional ``[distortion]`` and ``[tof]``) is
    accepted for solving real frames; ``render=True`` also needs the tables the renderer and
    the pixel model read (:data:`RENDER_TABLES`).

    Returns
    -------
    Camera

    Raises
    ------
    ProfileError
        A value of the profile refused when it is loaded (:meth:`svgs_sim.base.profiles.Camera.load`
        checks ``[tof]``, ``[noise]``, ``[illumination]`` with the rest); a phone profile (it has
        a ``[flash]``/``[cfa]``... table: an SVGS camera, not a ToF one), or ``render=True`` and
        a table missing.
    """
    cam = load_profile(name_or_path)
    phone = [t for t in PHONE_TABLES if cam.has(t)]
    if phone:
        raise ProfileError(f"camera {cam.name!r} is a phone (SVGS) profile (it has [{phone[0]}]), not a ToF camera; "
                           f"ToF commands need a ToF profile such as {DEFAULT_CAMERA!r}")
    if render:
        missing = [t for t in RENDER_TABLES if not cam.has(t)]
        if missing:
            raise ProfileError(f"camera {cam.name!r}: rendering the ToF camera needs the table(s) "
                               f"{['[' + m + ']' for m in missing]} (see {DEFAULT_CAMERA!r})")
    return cam


def depth_kind(camera: Camera) -> str:
    """What the camera's depth image holds: ``"radial"`` (default) or ``"z"``
    (:data:`svgs_sim.base.profile_schema.DEPTH_KINDS`; checked by the profile's entry, for cameras
    built in code: a loaded profile passed the check already)."""
    kind = camera.tof.given("depth_kind", "radial")
    try:
        return TOF_CAMERA_TABLES["tof"]["depth_kind"].check(kind, f"camera {camera.name!r}: [tof] depth_kind")
    except InputError as exc:
        raise ProfileError(str(exc)) from None


def line_of_sight(camera: Camera, uv_px) -> np.ndarray:
    """Unit line-of-sight vectors in the OpenCV camera frame (paper eq. 9).

    Parameters
    ----------
    camera : Camera
    uv_px : array_like, shape (..., 2)
        Pixel coordinates (distorted, as measured).

    Returns
    -------
    e_cam : ndarray, shape (..., 3)
        Unit vectors, z > 0.
    """
    xy = camera.pixels_to_normalized(np.asarray(uv_px, float))
    v = np.concatenate([xy, np.ones(xy.shape[:-1] + (1,))], -1)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def points_from_depth(camera: Camera, uv_px, depth_m, kind: str | None = None) -> np.ndarray:
    """3-D points in the camera frame from pixel positions and depths (paper eq. 8).

    Parameters
    ----------
    camera : Camera
    uv_px : array_like, shape (..., 2)
    depth_m : array_like, shape (...)
        Radial range or z depth (see ``kind``), metres.
    kind : {"radial", "z"}, optional
        Default: the camera's ``tof.depth_kind``.

    Returns
    -------
    p_cam_m : ndarray, shape (..., 3)
    """
    kind = depth_kind(camera) if kind is None else kind
    if kind not in DEPTH_KINDS:
        raise InputError(f"kind: expected one of {DEPTH_KINDS}, got {kind!r}")
    d = np.asarray(depth_m, float)[..., None]
    if kind == "radial":
        return line_of_sight(camera, uv_px) * d
    xy = camera.pixels_to_normalized(np.asarray(uv_px, float))
    return np.concatenate([xy, np.ones(xy.shape[:-1] + (1,))], -1) * d


@dataclass(frozen=True)
class MarkerTarget:
    """The ToF marker target: a pattern plus each marker's size and standoff.

    Attributes
    ----------
    pattern : Pattern
        Marker ids and face centres in the target frame, metres.
    diameter_m : ndarray, shape (N,)
    standoff_m : ndarray, shape (N,)
        Height of each marker face above the plate's front face.
    normal_target : ndarray, shape (3,)
        Unit normal of the marker faces (and the plate) in the target frame.
    plate : dict
        The ``[plate]`` table (``width_m``, ``height_m``, ``albedo``...), may be empty.
    marker : dict
        The ``[marker]`` table, may be empty.
    """

    pattern: Pattern
    diameter_m: np.ndarray
    standoff_m: np.ndarray
    normal_target: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))
    plate: dict = field(default_factory=dict)
    marker: dict = field(default_factory=dict)

    @property
    def n(self) -> int:
        return self.pattern.n

    @property
    def ids(self) -> np.ndarray:
        return self.pattern.ids

    @property
    def points_m(self) -> np.ndarray:
        return self.pattern.points_m

    @property
    def radius_m(self) -> np.ndarray:
        return self.diameter_m / 2.0

    @property
    def plate_centre_m(self) -> np.ndarray:
        """The centre of the plate's front face in the target frame, shape (3,): the pattern's
        ``[plate] centre_m``, else the origin (a pattern whose frame has its origin on the plate)."""
        return plate_centre_m(self.plate)


def plate_centre_m(plate) -> np.ndarray:
    """``[plate] centre_m`` of a ``[plate]`` table (dict, may be empty) as an array (3,); (0, 0, 0) when absent."""
    c = (plate or {}).get("centre_m")
    return np.zeros(3) if c is None else np.asarray(c, float).reshape(3)


def load_target(name_or_path=DEFAULT_PATTERN) -> MarkerTarget:
    """Load a marker target: a pattern TOML with ``diameter_m`` per ``[[target]]``.

    ``standoff_m`` defaults to the marker's ``z_m`` less the plate's ``z`` (``[plate] centre_m``,
    default the origin: the height of the face above the plate's front face). A pattern without
    per-target diameters may give one in a ``[marker]`` or ``[reflector]`` table (``diameter_m``).

    Raises
    ------
    ProfileError
        A value of the pattern refused when it is loaded (:meth:`svgs_sim.base.profiles.Pattern.load`
        checks every ``[[target]]``, ``[plate]``, ``[marker]`` and ``[reflector]`` value); a
        marker without a diameter, or a diameter out of range (a pattern built in code); a
        marker face behind the plate's front face, or a ``standoff_m`` that is not the face's
        height above it (the post joins the plate and the marker).
    """
    if isinstance(name_or_path, MarkerTarget):
        return name_or_path
    pattern = load_pattern(name_or_path)
    default_d = pattern.marker.diameter_m
    if default_d is None:
        default_d = pattern.reflector.diameter_m
    plate_z = float(plate_centre_m(pattern.plate.to_dict())[2])
    diam, stand = [], []
    for spec in pattern.targets:
        tid = spec.id
        d = default_d if spec.diameter_m is None else spec.diameter_m
        if d is None:
            raise ProfileError(f"pattern {pattern.name!r}: target {tid} has no diameter_m (and no [marker] diameter_m)")
        try:  # a loaded file passed this check already; a pattern built in code may not have
            diam.append(TARGET_KEYS["diameter_m"].check(d, f"pattern {pattern.name!r}: target {tid} diameter_m"))
        except InputError as exc:
            raise ProfileError(str(exc)) from None
        height = float(spec.z_m) - plate_z
        where = f"target pattern {pattern.source or pattern.name!r}: target {tid}"
        if height < 0:
            raise ProfileError(f"{where}: its face (z_m = {spec.z_m:g}) lies behind the plate's front face "
                               f"(z = {plate_z:g} m, [plate] centre_m)")
        if spec.standoff_m is not None and abs(float(spec.standoff_m) - height) > STANDOFF_TOLERANCE_M:
            raise ProfileError(f"{where}: standoff_m = {spec.standoff_m:g} but its face stands {height:g} m above "
                               f"the plate (z_m = {spec.z_m:g}, [plate] centre_m z = {plate_z:g})")
        stand.append(height if spec.standoff_m is None else float(spec.standoff_m))
    return MarkerTarget(
        pattern=pattern,
        diameter_m=np.asarray(diam),
        standoff_m=np.asarray(stand),
        plate=pattern.plate.to_dict(),
        marker=pattern.marker.to_dict(),
    )
