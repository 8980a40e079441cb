"""The ToF marker target as Mitsuba geometry: a black plate, eight white circular markers on
black posts at their standoffs, optional distractors.

Everything is built in the **target frame** (the world frame of the scene, as in
:mod:`svgs_sim.render.scene`): the plate's front face is centred on the pattern's ``[plate] centre_m``
(``tof-8``: 125 mm behind the origin, the marker faces' centroid; a pattern without the key: the
origin, its front face ``z = 0``), parallel to the ``x-y`` plane; the markers' white faces are exact
analytic disks (Mitsuba ``disk``: their images are exact ellipses, no tessellation) at their
``(x_m, y_m, z_m)``, facing ``+z``. Each marker is a puck of ``marker_thickness_m`` with a black
side wall and back (only the face is white: a white rim would add a sliver to the image of a
tilted marker and move its centroid off the projected circle centre), carried by a black
cylindrical post (``[marker] post_diameter_ratio`` of the pattern) from the plate's front face to the puck.
All materials are Lambertian (Mitsuba ``diffuse``), reflectances at 850 nm from the pattern's
``[plate]`` / ``[marker]`` tables unless overridden.

:class:`TofSceneOptions` is numpy-only; :func:`build_tof_scene` imports Mitsuba and needs a
variant chosen by :func:`svgs_sim.render.variant.select_variant` first.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from svgs_sim.base.errors import InputError, check_finite_positive
from svgs_sim.base.profile_schema import REFLECTANCE, TOF_MATERIALS, TOF_PATTERN_TABLES, check_table
from svgs_sim.tof.camera import plate_centre_m

from ..geometry import OptionsMixin
from .retro import bsdf_dict, load_sheeting, register_bsdf

#: Distractor kinds: ``sphere`` (``position_m``, ``radius_m``) and ``box`` (``lo_m``, ``hi_m``
#: corners, axis-aligned in the target frame); both take ``albedo`` (Lambertian, default 0.8).
DISTRACTOR_KINDS = ("sphere", "box")
#: Surface materials: ``retroreflective`` (a sheeting table of :mod:`svgs_sim.render.tof.retro`) or
#: ``lambertian`` (the pattern's ``[marker] material`` choices, :mod:`svgs_sim.base.profile_schema`).
MATERIALS = TOF_MATERIALS
#: The pattern's ``[plate]`` and ``[marker]`` entries, which the options of the same meaning share.
_PLATE, _MARKER = TOF_PATTERN_TABLES["plate"], TOF_PATTERN_TABLES["marker"]


def _reflectance(v, name):
    return REFLECTANCE.check(v, name)


def _check_distractor(d, i) -> dict:
    where = f"scene_options.distractors[{i}]"
    if not isinstance(d, dict) or d.get("type") not in DISTRACTOR_KINDS:
        raise InputError(f"{where}: expected a dict with type in {DISTRACTOR_KINDS}, got {d!r}")
    out = {"type": d["type"], "albedo": _reflectance(d.get("albedo", 0.8), f"{where}.albedo")}
    if d["type"] == "sphere":
        try:
            p = np.asarray(d["position_m"], float).reshape(3)
        except (KeyError, TypeError, ValueError):
            raise InputError(f"{where}.position_m: expected [x, y, z] metres") from None
        if not np.all(np.isfinite(p)):
            raise InputError(f"{where}.position_m: expected finite metres, got {d['position_m']!r}")
        out.update(position_m=p.tolist(), radius_m=float(check_finite_positive(d.get("radius_m"), f"{where}.radius_m")))
    else:
        try:
            lo = np.asarray(d["lo_m"], float).reshape(3)
            hi = np.asarray(d["hi_m"], float).reshape(3)
        except (KeyError, TypeError, ValueError):
            raise InputError(f"{where}: a box needs lo_m and hi_m, [x, y, z] metres each") from None
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(hi > lo)):
            raise InputError(f"{where}: expected finite corners with hi_m > lo_m, got {d['lo_m']!r}, {d['hi_m']!r}")
        out.update(lo_m=lo.tolist(), hi_m=hi.tolist())
    return out


@dataclass(frozen=True)
class TofSceneOptions(OptionsMixin):
    """What the ToF scene holds besides the pose.

    Attributes
    ----------
    markers : bool
        Draw the markers (faces, pucks, posts); False leaves the bare plate (tests).
    posts : bool
        Draw the posts under the markers.
    plate_albedo, marker_albedo : float or None
        Lambertian reflectances; None: the pattern's ``[plate]`` / ``[marker]`` albedo
        (0.04 / 0.85, ASSUMPTIONS of ``tof-8``).
    dark_albedo : float or None
        Reflectance of the marker side walls, backs and posts; None: the plate's.
    plate_size_m : (float, float) or None
        Plate width and height; None: the pattern's ``[plate]`` table.
    plate_thickness_m : float or None
        None: the pattern's ``[plate] thickness_m`` (5 mm).
    plate_centre_m : (float, float, float) or None
        The centre of the plate's front face in the target frame, m; None: the pattern's
        ``[plate] centre_m`` (the origin where the pattern gives none). ``(0, 0, 0)`` puts a bare
        plate (``markers=False``) on the origin, at the pose's range.
    marker_thickness_m : float
        Thickness of each marker puck (ASSUMPTION: 3 mm; the paper gives none).
    post_diameter_ratio : float or None
        Post diameter / marker diameter; None: the pattern's ``[marker]`` value (0.5).
    distractors : tuple of dict
        Extra diffuse objects in the target frame, see :data:`DISTRACTOR_KINDS`.
    marker_material : str or None
        One of :data:`MATERIALS`; None: the pattern's ``[marker] material`` (``tof-8``:
        retroreflective; lambertian when the pattern names none).
    sheeting : str or None
        Sheeting table of retroreflective surfaces; None: the pattern's ``[marker] sheeting``.
    plate_material : str
        The plate's material (default lambertian; retroreflective for radiometry tests).
    """

    markers: bool = True
    posts: bool = True
    plate_albedo: float | None = None
    marker_albedo: float | None = None
    dark_albedo: float | None = None
    plate_size_m: tuple | None = None
    plate_thickness_m: float | None = None
    plate_centre_m: tuple | None = None
    marker_thickness_m: float = 0.003
    post_diameter_ratio: float | None = None
    distractors: tuple = field(default_factory=tuple)
    marker_material: str | None = None
    sheeting: str | None = None
    plate_material: str = "lambertian"

    def __post_init__(self):
        for k in ("marker_material", "plate_material"):
            v = getattr(self, k)
            if v is not None:
                _MARKER["material"].check(v, f"scene_options.{k}")
        if self.sheeting is not None:

            load_sheeting(self.sheeting)
        for k in ("plate_albedo", "marker_albedo", "dark_albedo"):
            v = getattr(self, k)
            if v is not None:
                object.__setattr__(self, k, _reflectance(v, f"scene_options.{k}"))
        if self.plate_size_m is not None:
            try:
                w, h = (float(x) for x in self.plate_size_m)
            except (TypeError, ValueError):
                raise InputError(f"scene_options.plate_size_m: expected (width, height) metres, got {self.plate_size_m!r}") from None
            object.__setattr__(self, "plate_size_m", (_PLATE["width_m"].check(w, "scene_options.plate_size_m[0]"),
                                                      _PLATE["height_m"].check(h, "scene_options.plate_size_m[1]")))
        if self.plate_thickness_m is not None:
            _PLATE["thickness_m"].check(self.plate_thickness_m, "scene_options.plate_thickness_m")
        if self.plate_centre_m is not None:
            object.__setattr__(self, "plate_centre_m", tuple(float(x) for x in _PLATE["centre_m"].check(
                list(self.plate_centre_m) if isinstance(self.plate_centre_m, (list, tuple, np.ndarray)) else self.plate_centre_m,
                "scene_options.plate_centre_m")))
        check_finite_positive(self.marker_thickness_m, "scene_options.marker_thickness_m")
        if self.post_diameter_ratio is not None:
            _MARKER["post_diameter_ratio"].check(self.post_diameter_ratio, "scene_options.post_diameter_ratio")
        object.__setattr__(self, "distractors", tuple(_check_distractor(d, i) for i, d in enumerate(self.distractors)))

    def to_json(self) -> dict:
        d = asdict(self)
        d["distractors"] = [dict(x) for x in self.distractors]
        d["plate_size_m"] = list(self.plate_size_m) if self.plate_size_m else None
        d["plate_centre_m"] = list(self.plate_centre_m) if self.plate_centre_m is not None else None
        return d


@dataclass(frozen=True)
class TofGeometry:
    """Resolved dimensions and reflectances of the scene (numpy, for the truth record).

    Attributes
    ----------
    plate_size_m : (float, float)
    plate_thickness_m : float
    albedo : dict
        ``plate``, ``marker``, ``dark``.
    marker_centres_m : ndarray, shape (N, 3)
        Marker face centres, target frame.
    marker_radius_m : ndarray, shape (N,)
    post_radius_m : ndarray, shape (N,)
    marker_thickness_m : float
    materials : dict
        ``marker`` and ``plate``: one of :data:`MATERIALS`; ``sheeting``: the table name (or None).
    plate_centre_m : (float, float, float)
        The centre of the plate's front face, target frame (the plate lies behind it, the posts
        run from it to the pucks).
    """

    plate_size_m: tuple
    plate_thickness_m: float
    albedo: dict
    marker_centres_m: np.ndarray
    marker_radius_m: np.ndarray
    post_radius_m: np.ndarray
    marker_thickness_m: float
    materials: dict = field(default_factory=lambda: {"marker": "lambertian", "plate": "lambertian", "sheeting": None})
    plate_centre_m: tuple = (0.0, 0.0, 0.0)

    def to_json(self) -> dict:
        sheet = None
        if self.materials.get("sheeting"):

            sheet = load_sheeting(self.materials["sheeting"]).to_json()
        return {
            "plate_size_m": list(self.plate_size_m), "plate_thickness_m": self.plate_thickness_m,
            "plate_centre_m": list(self.plate_centre_m),
            "albedo": dict(self.albedo), "marker_thickness_m": self.marker_thickness_m,
            "marker_radius_m": self.marker_radius_m.tolist(), "post_radius_m": self.post_radius_m.tolist(),
            "materials": dict(self.materials),
            "materials_note": (f"marker faces {self.materials['marker']}, plate {self.materials['plate']}; marker "
                               "sides/backs and posts Lambertian dark"),
            "sheeting": sheet,
        }

    def corners_m(self) -> np.ndarray:
        """Corners of the bounding box of plate and markers, target frame, shape (8, 3)."""
        w, h = self.plate_size_m
        r = self.marker_radius_m.max() if self.marker_radius_m.size else 0.0
        c = self.marker_centres_m
        pc = np.asarray(self.plate_centre_m, float)
        lo = pc + [-w / 2, -h / 2, -self.plate_thickness_m]
        hi = pc + [w / 2, h / 2, 0.0]
        if c.size:
            lo = np.minimum(lo, c.min(0) - [r, r, 0.0])
            hi = np.maximum(hi, c.max(0) + [r, r, 0.0])
        return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])


def resolve_geometry(target, opts: TofSceneOptions) -> TofGeometry:
    """Dimensions and reflectances from the marker target and the options.

    Parameters
    ----------
    target : tof.MarkerTarget
    opts : TofSceneOptions

    Raises
    ------
    InputError
        No plate size anywhere, or a marker face nearer the plate's front face than its puck thickness.
    """
    # the pattern's tables, by its own entries (a loaded pattern passed them; a target built in code may not have)
    try:
        plate, marker = check_table("plate", target.plate or {}), check_table("marker", target.marker or {})
    except InputError as exc:
        raise InputError(f"pattern {target.pattern.name!r}: {exc}") from None
    if opts.plate_size_m is not None:
        size = opts.plate_size_m
    elif "width_m" in plate and "height_m" in plate:
        size = (float(plate["width_m"]), float(plate["height_m"]))
    else:
        raise InputError(f"pattern {target.pattern.name!r}: [plate] width_m/height_m missing and no plate_size_m given")
    thick = float(opts.plate_thickness_m if opts.plate_thickness_m is not None else plate.get("thickness_m", 0.005))
    centre = tuple(float(x) for x in (opts.plate_centre_m if opts.plate_centre_m is not None else plate_centre_m(plate)))
    a_plate = opts.plate_albedo if opts.plate_albedo is not None else plate.get("albedo", 0.04)
    a_marker = opts.marker_albedo if opts.marker_albedo is not None else marker.get("albedo", 0.85)
    a_dark = opts.dark_albedo if opts.dark_albedo is not None else a_plate
    ratio = opts.post_diameter_ratio if opts.post_diameter_ratio is not None else float(marker.get("post_diameter_ratio", 0.5))
    m_mat = opts.marker_material if opts.marker_material is not None else marker.get("material", "lambertian")
    sheeting = opts.sheeting if opts.sheeting is not None else marker.get("sheeting")
    if "retroreflective" in (m_mat, opts.plate_material):

        if not sheeting:
            raise InputError(f"pattern {target.pattern.name!r}: a retroreflective surface needs a sheeting "
                             "([marker] sheeting or scene_options.sheeting)")
        load_sheeting(str(sheeting))
    else:
        sheeting = None
    if opts.markers:
        centres = np.asarray(target.points_m, float)
        radius = np.asarray(target.radius_m, float)
        low = centres[:, 2] - opts.marker_thickness_m
        if np.any(low < centre[2]):
            raise InputError(f"marker_thickness_m {opts.marker_thickness_m} exceeds a marker's height above the plate "
                             f"({centres[:, 2].min() - centre[2]:.4f} m)")
    else:
        centres, radius = np.zeros((0, 3)), np.zeros(0)
    return TofGeometry(plate_size_m=tuple(size), plate_thickness_m=thick,
                       albedo={"plate": a_plate, "marker": a_marker, "dark": a_dark},
                       marker_centres_m=centres, marker_radius_m=radius, post_radius_m=radius * ratio,
                       marker_thickness_m=float(opts.marker_thickness_m),
                       materials={"marker": m_mat, "plate": opts.plate_material, "sheeting": sheeting},
                       plate_centre_m=centre)


def scene_dict(geom: TofGeometry, opts: TofSceneOptions) -> dict:
    """The Mitsuba scene dictionary (no sensor, no emitter: the ToF integrator of
    :mod:`svgs_sim.render.tof.camera` generates its own rays and samples its own light source).

    Shape names: ``plate``, ``marker<i>_face``, ``marker<i>_side``, ``marker<i>_back``,
    ``post<i>``, ``distractor<i>`` (``i`` = index in the pattern, from 0).
    """
    import mitsuba as mi

    T = mi.ScalarTransform4f

    def diffuse(a):
        return {"type": "diffuse", "reflectance": {"type": "uniform", "value": float(a)}}

    def material(kind, albedo):
        if kind == "retroreflective":

            register_bsdf()
            return bsdf_dict(geom.materials["sheeting"])
        return diffuse(albedo)

    w, h = geom.plate_size_m
    th = geom.plate_thickness_m
    px, py, pz = (float(x) for x in geom.plate_centre_m)
    d = {"type": "scene",
         "plate": {"type": "cube", "to_world": T().translate([px, py, pz - th / 2]).scale([w / 2, h / 2, th / 2]),
                   "bsdf": material(geom.materials["plate"], geom.albedo["plate"])}}
    t_m = geom.marker_thickness_m
    for i, (c, r, rp) in enumerate(zip(geom.marker_centres_m, geom.marker_radius_m, geom.post_radius_m)):
        c = [float(x) for x in c]
        back = [c[0], c[1], c[2] - t_m]
        d[f"marker{i}_face"] = {"type": "disk", "to_world": T().translate(c).scale([float(r), float(r), 1.0]),
                                "bsdf": material(geom.materials["marker"], geom.albedo["marker"])}
        d[f"marker{i}_side"] = {"type": "cylinder", "p0": back, "p1": c, "radius": float(r),
                                "bsdf": diffuse(geom.albedo["dark"])}
        d[f"marker{i}_back"] = {"type": "disk",
                                "to_world": T().translate(back).rotate([1.0, 0.0, 0.0], 180.0).scale([float(r), float(r), 1.0]),
                                "bsdf": diffuse(geom.albedo["dark"])}
        if opts.posts and back[2] > pz and rp > 0:
            d[f"post{i}"] = {"type": "cylinder", "p0": [c[0], c[1], pz], "p1": back, "radius": float(rp),
                             "bsdf": diffuse(geom.albedo["dark"])}
    for i, dd in enumerate(opts.distractors):
        if dd["type"] == "sphere":
            d[f"distractor{i}"] = {"type": "sphere", "center": dd["position_m"], "radius": dd["radius_m"],
                                   "bsdf": diffuse(dd["albedo"])}
        else:
            lo, hi = np.asarray(dd["lo_m"]), np.asarray(dd["hi_m"])
            d[f"distractor{i}"] = {"type": "cube",
                                   "to_world": T().translate(((lo + hi) / 2).tolist()).scale(((hi - lo) / 2).tolist()),
                                   "bsdf": diffuse(dd["albedo"])}
    return d


def build_tof_scene(target, options=None):
    """Load the ToF scene.

    Parameters
    ----------
    target : tof.MarkerTarget
    options : None, dict or TofSceneOptions

    Returns
    -------
    scene : mi.Scene
    geometry : TofGeometry
    """
    import mitsuba as mi

    opts = TofSceneOptions.resolve(options)
    geom = resolve_geometry(target, opts)
    return mi.load_dict(scene_dict(geom, opts)), geom
