"""Scene geometry in double precision: corner cubes, their mounts, the target body.

Everything here is numpy (float64) and mitsuba-free: a :class:`MeshSpec` holds vertices,
triangles and a material name; :mod:`svgs_sim.render.scene` turns the specs into Mitsuba meshes.
The world frame of every scene is the **target frame** (target at the world origin, see
``shared/notes/physics.md`` section 2, pitfall 2), so the vertices are small numbers and
nothing is truncated (pitfall 3). Triangles carry flat face normals only (pitfall 1):
:mod:`svgs_sim.render.scene` builds the meshes without vertex normals.

Corner cube model
-----------------
Local cube frame: vertex at the origin, symmetry axis +z (pointing out of the front face,
towards the viewer), front face at ``z = height_m``. The three reflecting faces are the
planes ``e_i . p = 0`` of an orthonormal triad ``e_i`` with ``sum(e_i) / sqrt(3) = +z``,
cut by the cylinder of radius ``diameter_m / 2`` around the axis (a "circular" cube as
catalogue cubes are). A circular cube covers its whole aperture only if
``height_m >= diameter_m / sqrt(2)`` (the middle of each face reaches that deep).

- ``solid``: N-BK7 glass, dielectric front face and three dielectric back faces (they
  reflect by total internal reflection), the cylindrical side black (ground, in a mount).
- ``hollow``: three mirrors (``mirror_reflectance`` per bounce), no front face.

Each cube sits in a black cylindrical housing with a front lip that shadows the
aperture at oblique incidence. The **reference point** of a cube - the point placed on
the pattern's target position - is its optical vertex as seen from outside: the
physical vertex for a hollow cube, the apparent vertex (``height_m / n`` behind the
front face, paraxial) for a solid one. A retro-reflected spot appears where the
flash's image through the cube is: near the projection of ``2 V - S`` (V reference
point, S the LED), see :mod:`svgs_sim.render.predict`.
"""

from __future__ import annotations

import functools
import hashlib
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from svgs_sim.base.errors import InputError, check_finite, check_finite_positive
from svgs_sim.base.profile_schema import REFLECTOR_MODELS, check_reflector_table

from .materials import check_body, is_mesh_body
from .cubesat import cubesat_3u_meshes
from .earth import in_eclipse
from .constants import DEFAULT_MAX_DEPTH, DEFAULT_MESH_SEGMENTS, nbk7_index

#: Named reflector models (``[reflector] model`` in a pattern file): :data:`REFLECTOR_MODELS`,
#: defined in :mod:`svgs_sim.base.profile_schema` so that :meth:`svgs_sim.svgs.Pattern.load` refuses an unknown
#: model at load.


@dataclass(frozen=True)
class Reflector:
    """A corner-cube retroreflector in its mount.

    Attributes
    ----------
    kind : {"solid", "hollow"}
    diameter_m : float
        Clear aperture diameter (the cylinder that cuts the cube), m.
    height_m : float
        Vertex-to-front-face distance, m. ASSUMPTION for the Edmund cube: 9.5 mm
        (a circular 12.7 mm cube needs >= 8.98 mm; catalogue drawings show about 9.5).
    ior : float or None
        Refractive index of the glass (solid); None: N-BK7 at the band centre.
    mirror_reflectance : float
        Reflectance per mirror bounce (hollow); 1.0 = perfect, ~0.96 silver, ~0.90 Al.
    mount_lip_m : float
        How far the housing's front lip stands in front of the front face, m.
    mount_outer_diameter_m : float
        Outer diameter of the cylindrical housing, m.
    mount_back_m : float
        Housing material behind the cube vertex, m.
    mount_reflectance : float
        Diffuse reflectance of the housing (black anodised aluminium ~0.05).
    clocking_deg : float
        Rotation of the cube about its axis (orientation of the edges), degrees.
    segments : int
        Rim segments per face of the tessellation.
    model : str
        Name, for the truth record.
    """

    kind: str = "solid"
    diameter_m: float = 0.0127
    height_m: float = 0.0095
    ior: float | None = None
    mirror_reflectance: float = 1.0
    mount_lip_m: float = 0.001
    mount_outer_diameter_m: float = 0.019
    mount_back_m: float = 0.001
    mount_reflectance: float = 0.05
    clocking_deg: float = 0.0
    segments: int = DEFAULT_MESH_SEGMENTS
    model: str = "custom"

    def __post_init__(self):
        if self.kind not in ("solid", "hollow"):
            raise InputError(f"reflector.kind: expected 'solid' or 'hollow', got {self.kind!r}")
        for k in ("diameter_m", "height_m", "mount_outer_diameter_m"):
            check_finite_positive(getattr(self, k), f"reflector.{k}")
        for k in ("mount_lip_m", "mount_back_m"):
            check_finite_positive(getattr(self, k), f"reflector.{k}", allow_zero=True)
        for k in ("mirror_reflectance", "mount_reflectance"):
            v = check_finite(getattr(self, k), f"reflector.{k}")
            if not 0.0 <= v <= 1.0:
                raise InputError(f"reflector.{k}: expected a reflectance in [0, 1], got {v!r}")
        check_finite(self.clocking_deg, "reflector.clocking_deg")
        if self.ior is not None and check_finite_positive(self.ior, "reflector.ior") <= 1.0:
            raise InputError(f"reflector.ior: expected > 1 for glass, got {self.ior!r}")
        if self.height_m < self.diameter_m / np.sqrt(2.0) * (1 - 1e-9):
            raise InputError(
                f"reflector.height_m = {self.height_m} m is too short for a circular cube of diameter "
                f"{self.diameter_m} m: the faces would not cover the aperture (need >= D/sqrt(2) = "
                f"{self.diameter_m / np.sqrt(2):.5f} m)"
            )
        if self.mount_outer_diameter_m <= self.diameter_m:
            raise InputError("reflector.mount_outer_diameter_m must exceed diameter_m")
        if int(self.segments) < 4:
            raise InputError(f"reflector.segments: expected >= 4, got {self.segments!r}")

    @property
    def radius_m(self) -> float:
        return 0.5 * self.diameter_m

    def index(self, band_nm=(400.0, 700.0)) -> float:
        """Refractive index used (solid); 1.0 for hollow cubes."""
        if self.kind == "hollow":
            return 1.0
        if self.ior is not None:
            return float(self.ior)
        return float(nbk7_index(0.5 * (band_nm[0] + band_nm[1])))

    def reference_depth_m(self, band_nm=(400.0, 700.0)) -> float:
        """Depth of the reference point (apparent vertex) behind the front face, m."""
        return self.height_m / self.index(band_nm)

    def to_json(self, band_nm=(400.0, 700.0)) -> dict:
        d = asdict(self)
        d["ior_used"] = self.index(band_nm)
        d["reference_depth_m"] = self.reference_depth_m(band_nm)
        return d

    @classmethod
    def resolve(cls, spec=None, pattern=None) -> "Reflector":
        """A :class:`Reflector` from a name, a kind, a dict of overrides, or the pattern.

        Parameters
        ----------
        spec : None, str, dict or Reflector
            None: the pattern's ``[reflector] model`` (default Edmund N-BK7 12.7 mm);
            ``"solid"``/``"hollow"``: that kind with the pattern's diameter; a model name of
            :data:`REFLECTOR_MODELS`; a dict of field overrides (may hold ``"model"`` or
            ``"kind"``).
        pattern : svgs.Pattern, optional
        """
        if isinstance(spec, Reflector):
            return spec
        base = dict(REFLECTOR_MODELS["edmund-nbk7-12.7mm"], model="edmund-nbk7-12.7mm")
        ptab = pattern.reflector.to_dict() if pattern is not None else {}
        try:  # an unknown model is refused, never replaced by the default (a pattern built in code)
            ptab = check_reflector_table(ptab)
        except InputError as exc:
            raise InputError(f"pattern {pattern.name!r}: {exc}") from None
        if "model" in ptab:
            base = dict(REFLECTOR_MODELS[ptab["model"]], model=ptab["model"])
        if "diameter_m" in ptab:
            base["diameter_m"] = float(ptab["diameter_m"])
        over = {}
        if spec is None:
            pass
        elif isinstance(spec, str):
            if spec in REFLECTOR_MODELS:
                base = dict(REFLECTOR_MODELS[spec], model=spec)
            elif spec in ("solid", "hollow"):
                if spec != base["kind"]:
                    base = dict(base, kind=spec, model=f"{spec}-{base['diameter_m'] * 1e3:g}mm")
            else:
                raise InputError(
                    f"reflector: unknown model {spec!r}; expected 'solid', 'hollow' or one of {sorted(REFLECTOR_MODELS)}"
                )
        elif isinstance(spec, dict):
            over = dict(spec)
            m = over.pop("model", None)
            if m is not None:
                if m not in REFLECTOR_MODELS:
                    raise InputError(f"reflector.model: unknown {m!r}; known {sorted(REFLECTOR_MODELS)}")
                base = dict(REFLECTOR_MODELS[m], model=m)
        else:
            raise InputError(f"reflector: expected a name, a dict or a Reflector, got {type(spec).__name__}")
        known = set(cls.__dataclass_fields__)
        bad = set(over) - known
        if bad:
            raise InputError(f"reflector: unknown fields {sorted(bad)}; known {sorted(known)}")
        base.update(over)
        return cls(**base)


@dataclass
class MeshSpec:
    """A triangle mesh in the world (target) frame, float64.

    Attributes
    ----------
    name : str
    vertices_m : ndarray, shape (V, 3)
    faces : ndarray of uint32, shape (F, 3)
        Counter-clockwise seen from the side the face normal points to.
    material : str
        Key into the scene's material table (``"glass"``, ``"mirror"``, ``"black"``, ``"body"``...).
    """

    name: str
    vertices_m: np.ndarray
    faces: np.ndarray
    material: str

    def face_normals(self) -> np.ndarray:
        v = self.vertices_m
        f = self.faces
        n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
        return n / np.linalg.norm(n, axis=1, keepdims=True)

    def transformed(self, R=None, t=None) -> "MeshSpec":
        R = np.eye(3) if R is None else np.asarray(R, float)
        t = np.zeros(3) if t is None else np.asarray(t, float)
        return MeshSpec(self.name, self.vertices_m @ R.T + t, self.faces.copy(), self.material)


# ------------------------------------------------------------------ mesh builders
class _Builder:
    """Accumulates triangles with a requested outward normal direction."""

    def __init__(self):
        self.v: list = []
        self.f: list = []

    def tri(self, a, b, c, normal_hint):
        n = np.cross(np.subtract(b, a), np.subtract(c, a))
        if np.dot(n, normal_hint) < 0:
            b, c = c, b
        i = len(self.v)
        self.v.extend([a, b, c])
        self.f.append([i, i + 1, i + 2])

    def quad(self, a, b, c, d, normal_hint):
        self.tri(a, b, c, normal_hint)
        self.tri(a, c, d, normal_hint)

    def spec(self, name, material) -> MeshSpec:
        return MeshSpec(name, np.asarray(self.v, float), np.asarray(self.f, np.uint32), material)


def cube_triad(clocking_deg: float = 0.0) -> np.ndarray:
    """Unit edge vectors of the cube in its local frame (axis +z).

    Returns
    -------
    E : ndarray, shape (3, 3)
        Row i is edge direction ``e_i``; ``E.sum(0) / sqrt(3) = (0, 0, 1)``.
    """
    a = np.ones(3) / np.sqrt(3.0)
    e1 = np.array([1.0, 0.0, 0.0])
    x = e1 - a * (e1 @ a)
    x /= np.linalg.norm(x)
    y = np.cross(a, x)
    Q = np.stack([x, y, a])  # cube coords -> local coords
    c, s = np.cos(np.radians(clocking_deg)), np.sin(np.radians(clocking_deg))
    Rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return (Rz @ Q @ np.eye(3)).T  # row i = Rz Q e_i


def corner_cube_meshes(refl: Reflector, R_target_cube=None, t_target_cube_m=None, name="cube") -> list[MeshSpec]:
    """Triangle meshes of one mounted corner cube.

    Parameters
    ----------
    refl : Reflector
    R_target_cube : ndarray, shape (3, 3), optional
        Orientation of the cube frame (axis = third column) in the target frame.
    t_target_cube_m : ndarray, shape (3,), optional
        Position of the cube's physical vertex in the target frame, m.
    name : str

    Returns
    -------
    list of MeshSpec
        Solid: ``<name>_glass`` (front + back faces, dielectric), ``<name>_side`` (black
        ground side, seen from inside), ``<name>_mount``. Hollow: ``<name>_mirrors``,
        ``<name>_mount`` (which includes the inner wall).
    """
    E = cube_triad(refl.clocking_deg)
    rho, h = refl.radius_m, refl.height_m
    nseg = int(refl.segments)
    z = np.array([0.0, 0.0, 1.0])
    glass, side, mirrors, mount = _Builder(), _Builder(), _Builder(), _Builder()
    origin = np.zeros(3)

    def u(phi):
        return np.array([np.cos(phi), np.sin(phi), 0.0])

    rim = []  # (phi, back-face rim point) around the full circle
    for i in range(3):
        ei = E[i]
        phi_i = np.arctan2(ei[1], ei[0])
        phis = phi_i + np.pi + np.linspace(-np.pi / 3, np.pi / 3, nseg + 1)
        pts = [rho * u(p) + (-np.sqrt(3.0) * rho * (ei @ u(p))) * z for p in phis]
        for k in range(nseg):
            if refl.kind == "solid":
                glass.tri(origin, pts[k], pts[k + 1], -ei)  # outward of the glass
            else:
                mirrors.tri(origin, pts[k], pts[k + 1], ei)  # towards the cube's inside
        rim.extend(zip(phis[:-1], pts[:-1]))
    rim.sort(key=lambda q: q[0])
    rim.append((rim[0][0] + 2 * np.pi, rim[0][1]))
    centre_front = h * z
    for k in range(len(rim) - 1):
        (p0, c0), (p1, c1) = rim[k], rim[k + 1]
        f0, f1 = rho * u(p0) + h * z, rho * u(p1) + h * z
        radial = u(0.5 * (p0 + p1))
        if refl.kind == "solid":
            glass.tri(centre_front, f0, f1, z)  # front face, normal out of the glass
            side.quad(c0, c1, f1, f0, radial)  # ground side: black seen from inside
        else:
            mount.quad(c0, c1, f1, f0, -radial)  # housing wall, seen from inside
    # housing: inner lip, front ring, outer tube, back
    R_out = 0.5 * refl.mount_outer_diameter_m
    z_front = h + refl.mount_lip_m
    z_back = -refl.mount_back_m
    nring = len(rim) - 1
    for k in range(nring):
        p0, p1 = rim[k][0], rim[k + 1][0]
        radial = u(0.5 * (p0 + p1))
        if refl.mount_lip_m > 0:
            mount.quad(rho * u(p0) + h * z, rho * u(p1) + h * z, rho * u(p1) + z_front * z, rho * u(p0) + z_front * z, -radial)
        mount.quad(rho * u(p0) + z_front * z, rho * u(p1) + z_front * z, R_out * u(p1) + z_front * z, R_out * u(p0) + z_front * z, z)
        mount.quad(R_out * u(p0) + z_back * z, R_out * u(p1) + z_back * z, R_out * u(p1) + z_front * z, R_out * u(p0) + z_front * z, radial)
        mount.tri(z_back * z, R_out * u(p0) + z_back * z, R_out * u(p1) + z_back * z, -z)
    out = []
    if refl.kind == "solid":
        out += [glass.spec(f"{name}_glass", "glass"), side.spec(f"{name}_side", "black")]
    else:
        out += [mirrors.spec(f"{name}_mirrors", "mirror")]
    out.append(mount.spec(f"{name}_mount", "mount"))
    return [m.transformed(R_target_cube, t_target_cube_m) for m in out]


def box_mesh(name, lo, hi, material) -> MeshSpec:
    """Axis-aligned box with outward normals. ``lo``, ``hi``: corners, shape (3,)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    b = _Builder()
    c = 0.5 * (lo + hi)
    for ax in range(3):
        for side in (0, 1):
            n = np.zeros(3)
            n[ax] = 1.0 if side else -1.0
            o1, o2 = [(a) for a in range(3) if a != ax]
            pts = []
            for s1, s2 in ((0, 0), (1, 0), (1, 1), (0, 1)):
                p = np.where(np.arange(3) == ax, hi if side else lo, c).astype(float)
                p[o1] = hi[o1] if s1 else lo[o1]
                p[o2] = hi[o2] if s2 else lo[o2]
                pts.append(p)
            b.quad(*pts, n)
    return b.spec(name, material)


def cylinder_mesh(name, centre_xy, z0, z1, radius, material, segments=32) -> MeshSpec:
    """Closed z-aligned cylinder with outward normals."""
    cx, cy = centre_xy
    b = _Builder()
    ph = np.linspace(0, 2 * np.pi, segments + 1)
    for k in range(segments):
        p0 = np.array([cx + radius * np.cos(ph[k]), cy + radius * np.sin(ph[k])])
        p1 = np.array([cx + radius * np.cos(ph[k + 1]), cy + radius * np.sin(ph[k + 1])])
        radial = np.append(0.5 * (p0 + p1) - [cx, cy], 0.0)
        b.quad(np.append(p0, z0), np.append(p1, z0), np.append(p1, z1), np.append(p0, z1), radial)
        b.tri(np.array([cx, cy, z1]), np.append(p0, z1), np.append(p1, z1), [0, 0, 1.0])
        b.tri(np.array([cx, cy, z0]), np.append(p0, z0), np.append(p1, z0), [0, 0, -1.0])
    return b.spec(name, material)


# ------------------------------------------------------------------ target assembly

class OptionsMixin:
    """``resolve`` (None, a dict of fields or an instance) and ``replace`` for the frozen
    option dataclasses of the scenes (SVGS and ToF)."""

    @classmethod
    def resolve(cls, opts=None):
        """From None (defaults), a dict of fields, or an instance."""
        if opts is None:
            return cls()
        if isinstance(opts, cls):
            return opts
        if isinstance(opts, dict):
            bad = set(opts) - set(cls.__dataclass_fields__)
            if bad:
                raise InputError(f"scene_options: unknown keys {sorted(bad)}; known {sorted(cls.__dataclass_fields__)}")
            return cls(**opts)
        raise InputError(f"scene_options: expected a dict or {cls.__name__}, got {type(opts).__name__}")

    def replace(self, **kw):
        return replace(self, **kw)


@functools.lru_cache(maxsize=8)
def _file_sha1(path: str, mtime_ns: int, size: int) -> str:
    """SHA-1 of a mesh file, read once per version of it (its modification time and size are the
    key: a renderer whose sun moves copies its options every frame)."""
    return hashlib.sha1(Path(path).read_bytes()).hexdigest()


@dataclass(frozen=True)
class SceneOptions(OptionsMixin):
    """Everything about the scene besides camera, pattern, pose and reflector model.

    Attributes
    ----------
    body : {"plate", "3u", "none"} or str
        Target body: a flat plate (the paper's test used a Thorlabs MS12B/M optical
        breadboard), a 3U CubeSat (100 x 340.5 x 100 mm, rails, MLI, body-mounted cells:
        :mod:`svgs_sim.render.cubesat`), nothing (cubes and mounts only), or a mesh file (a path ending
        in ``.ply`` or ``.obj``; metres, target frame: :mod:`svgs_sim.render.body_mesh`).
    body_material : str or None
        A mesh body's surface (:mod:`svgs_sim.render.materials`), for its parts not in
        ``body_materials``.
    body_materials : tuple of (str, str)
        A mesh body's parts and their surfaces.
    body_file_sha1 : str or None
        Set from the mesh file (the renderer's cache key holds it).
    body_reflectance : float
        Diffuse (Lambertian) reflectance of body and boom; dark by default.
    body_thickness_m : float
        Plate thickness (3U: depth of the box), m.
    body_margin_m : float
        Plate margin around the outermost mount, m.
    boom_radius_m : float
        Radius of the boom(s) that carry cubes standing off the face, m.
    distractors : tuple of dict
        Extra bright objects, positions in the target frame:
        ``{"type": "glint", "position_m": [x, y, z], "radius_m": r, "reflectance": 1.0}``
        (a polished metal sphere that mirrors the flash),
        ``{"type": "lamp", "position_m": [...], "radius_m": r, "radiance_w_m2_sr": L}``
        (a glowing sphere, radiance in the camera band).
    focus_distance_m : float or None
        Override of the profile's focus distance; None: the profile's.
    max_depth : int
        Path length limit of the integrator (>= 8 for the cube paths).
    anchor : {"apparent-vertex", "front-face"}
        Which point of a cube sits on the pattern's target position.
    sun_direction_target : tuple of 3 float or None
        Unit vector toward the sun in the target frame (None: no sun, eclipse or the lab). The
        sun is rendered in a pass of its own (:mod:`svgs_sim.render.sun`).
    earth_direction_target : tuple of 3 float or None
        Unit vector toward the Earth's centre in the target frame (None: no Earth); rendered with
        the sun's pass as an environment map (:mod:`svgs_sim.render.earth`), lit by the sun.
    altitude_m : float
        The target's altitude above the Earth, m (the Earth's size and the eclipse).
    earth_albedo : float
        The Earth's Lambertian albedo, 0-1.
    earth_uniform_radiance_w_m2_sr : float or None
        For checks only: the Earth's disk at this uniform band radiance, unlit by the sun.
    """

    body: str = "plate"
    body_reflectance: float = 0.05
    body_thickness_m: float = 0.0127
    body_margin_m: float = 0.012
    boom_radius_m: float = 0.004
    distractors: tuple = ()
    focus_distance_m: float | None = None
    max_depth: int = DEFAULT_MAX_DEPTH
    anchor: str = "apparent-vertex"
    sun_direction_target: tuple | None = None
    earth_direction_target: tuple | None = None
    altitude_m: float = 400e3
    earth_albedo: float = 0.3
    earth_uniform_radiance_w_m2_sr: float | None = None
    body_material: str | None = None
    body_materials: tuple = ()
    body_file_sha1: str | None = None

    @property
    def mesh_body(self) -> bool:
        """Whether the body is a mesh file."""
        return is_mesh_body(self.body)

    def __post_init__(self):
        if isinstance(self.body_materials, dict):
            object.__setattr__(self, "body_materials", tuple(sorted(self.body_materials.items())))
        if check_body(self.body, self.body_material, self.body_materials):
            try:
                st = Path(self.body).stat()
                object.__setattr__(self, "body_file_sha1", _file_sha1(str(self.body), st.st_mtime_ns, st.st_size))
            except OSError as exc:
                raise InputError(f"--body: cannot read {self.body!r}: {exc}") from None
        v = check_finite(self.body_reflectance, "scene_options.body_reflectance")
        if not 0 <= v <= 1:
            raise InputError(f"scene_options.body_reflectance: expected a reflectance in [0, 1], got {v!r}")
        check_finite_positive(self.body_thickness_m, "scene_options.body_thickness_m")
        check_finite_positive(self.body_margin_m, "scene_options.body_margin_m", allow_zero=True)
        check_finite_positive(self.boom_radius_m, "scene_options.boom_radius_m")
        if self.focus_distance_m is not None:
            check_finite_positive(self.focus_distance_m, "scene_options.focus_distance_m")
        if int(self.max_depth) < 8:
            raise InputError(f"scene_options.max_depth: expected >= 8 (cube paths need 7 bounces), got {self.max_depth!r}")
        if self.anchor not in ("apparent-vertex", "front-face"):
            raise InputError(f"scene_options.anchor: expected 'apparent-vertex' or 'front-face', got {self.anchor!r}")
        object.__setattr__(self, "distractors", tuple(_check_distractor(d, i) for i, d in enumerate(self.distractors)))
        for name in ("sun_direction_target", "earth_direction_target"):  # unit 3-vectors or None
            v = getattr(self, name)
            if v is not None:
                d = np.asarray(v, float).reshape(-1)
                if d.shape != (3,) or not np.all(np.isfinite(d)) or abs(np.linalg.norm(d) - 1.0) > 1e-6:
                    raise InputError(f"scene_options.{name}: expected a unit 3-vector or None, got {v!r}")
                object.__setattr__(self, name, tuple(float(x) for x in d))
        check_finite_positive(self.altitude_m, "scene_options.altitude_m")
        a = check_finite(self.earth_albedo, "scene_options.earth_albedo")
        if not 0 <= a <= 1:
            raise InputError(f"scene_options.earth_albedo: expected an albedo in [0, 1], got {a!r}")
        if self.earth_uniform_radiance_w_m2_sr is not None:
            check_finite_positive(self.earth_uniform_radiance_w_m2_sr, "scene_options.earth_uniform_radiance_w_m2_sr")

    @property
    def eclipsed(self) -> bool:
        """Whether the Earth hides the sun from the target (:func:`svgs_sim.render.earth.in_eclipse`)."""
        return (self.sun_direction_target is not None and self.earth_direction_target is not None
                and in_eclipse(self.sun_direction_target, self.earth_direction_target, self.altitude_m))

    @property
    def light_pass(self) -> bool:
        """Whether the scene has a pass of natural light (the sun, or an Earth the sun lights or a
        check lights uniformly)."""
        return self.sun_direction_target is not None or (
            self.earth_direction_target is not None and self.earth_uniform_radiance_w_m2_sr is not None)

    def to_json(self) -> dict:
        d = asdict(self)
        d["distractors"] = [dict(x) for x in self.distractors]
        if d["sun_direction_target"] is None:  # no sun: the record of a dark scene, as before the sun
            del d["sun_direction_target"]
        else:
            d["sun_direction_target"] = list(d["sun_direction_target"])
        if d["earth_direction_target"] is None:  # no Earth: as before the Earth
            for k in ("earth_direction_target", "altitude_m", "earth_albedo", "earth_uniform_radiance_w_m2_sr"):
                del d[k]
        else:
            d["earth_direction_target"] = list(d["earth_direction_target"])
            if d["earth_uniform_radiance_w_m2_sr"] is None:
                del d["earth_uniform_radiance_w_m2_sr"]
        for k in ("body_material", "body_materials", "body_file_sha1"):  # a mesh body's only
            if not d[k]:
                del d[k]
        if "body_materials" in d:
            d["body_materials"] = dict(d["body_materials"])
        return d


def _check_distractor(d, i):
    if not isinstance(d, dict):
        raise InputError(f"scene_options.distractors[{i}]: expected a dict, got {type(d).__name__}")
    kind = d.get("type")
    if kind not in ("glint", "lamp"):
        raise InputError(f"scene_options.distractors[{i}].type: expected 'glint' or 'lamp', got {kind!r}")
    pos = np.asarray(d.get("position_m", None), dtype=float) if d.get("position_m") is not None else None
    if pos is None or pos.shape != (3,) or not np.all(np.isfinite(pos)):
        raise InputError(f"scene_options.distractors[{i}].position_m: expected 3 finite numbers (target frame, m)")
    out = {"type": kind, "position_m": pos.tolist(),
           "radius_m": check_finite_positive(d.get("radius_m", 0.005), f"scene_options.distractors[{i}].radius_m")}
    if kind == "glint":
        r = check_finite(d.get("reflectance", 1.0), f"scene_options.distractors[{i}].reflectance")
        if not 0 <= r <= 1:
            raise InputError(f"scene_options.distractors[{i}].reflectance: expected [0, 1], got {r}")
        out["reflectance"] = r
    else:
        out["radiance_w_m2_sr"] = check_finite_positive(d.get("radiance_w_m2_sr", 1.0), f"scene_options.distractors[{i}].radiance_w_m2_sr")
    extra = set(d) - set(out) - {"type"}
    if extra:
        raise InputError(f"scene_options.distractors[{i}]: unknown keys {sorted(extra)}")
    return out


@dataclass
class TargetGeometry:
    """All meshes of the target plus where each cube is.

    Attributes
    ----------
    meshes : list of MeshSpec
    cube_vertex_m : ndarray, shape (N, 3)
        Physical vertex of each cube, target frame.
    cube_axis : ndarray, shape (N, 3)
        Unit axis of each cube (out of the front face), target frame.
    reference_m : ndarray, shape (N, 3)
        The cubes' reference points (= pattern points), target frame.
    info : dict
        Body extents etc., for the truth record.
    """

    meshes: list
    cube_vertex_m: np.ndarray
    cube_axis: np.ndarray
    reference_m: np.ndarray
    info: dict = field(default_factory=dict)


def build_target(pattern, refl: Reflector, opts: SceneOptions, band_nm=(400.0, 700.0)) -> TargetGeometry:
    """Meshes of the pattern's cubes, mounts, body and booms, in the target frame.

    Parameters
    ----------
    pattern : svgs.Pattern
    refl : Reflector
    opts : SceneOptions
    band_nm : (float, float)
        Camera band, for the glass index at the band centre.

    Returns
    -------
    TargetGeometry
    """
    pts = np.asarray(pattern.points_m, float)
    axis = np.array([0.0, 0.0, 1.0])
    z_ref = refl.height_m - (refl.reference_depth_m(band_nm) if opts.anchor == "apparent-vertex" else 0.0)
    if refl.kind == "hollow" and opts.anchor == "apparent-vertex":
        z_ref = 0.0
    vertices = pts - z_ref * axis
    meshes = []
    for tid, v in zip(pattern.ids, vertices):
        meshes += corner_cube_meshes(refl, np.eye(3), v, name=f"cube{tid}")
    mount_base = vertices[:, 2] - refl.mount_back_m
    z_face = float(mount_base.min())
    R_out = 0.5 * refl.mount_outer_diameter_m
    info = {"face_z_m": z_face, "body": opts.body}
    if opts.mesh_body:
        pass  # the mesh's parts are added by the scene (svgs_sim.render.body_mesh)
    elif opts.body == "3u":
        boom = None
        for tid, p, base in zip(pattern.ids, pts, mount_base):
            if base > z_face + 1e-4 and int(tid) == 3:
                boom = (float(p[0]), float(p[1]), z_face, float(base))
        centre = 0.5 * (pts[:, :2].min(0) + pts[:, :2].max(0))
        meshes += [MeshSpec(*part) for part in cubesat_3u_meshes(z_face, boom, centre)]
        info.update(boom_3u=boom, body_centre_xy_m=centre.tolist(), body_parts=[m.material for m in meshes if m.name.startswith("cubesat_")])
        for tid, v, base in zip(pattern.ids, vertices, mount_base):
            if base > z_face + 1e-4 and int(tid) != 3:
                meshes.append(cylinder_mesh(f"boom{tid}", v[:2], z_face, base, opts.boom_radius_m, "body"))
                info.setdefault("booms", []).append({"target": int(tid), "z0_m": z_face, "z1_m": float(base)})
    elif opts.body != "none":
        lo_xy = pts[:, :2].min(0) - R_out - opts.body_margin_m
        hi_xy = pts[:, :2].max(0) + R_out + opts.body_margin_m
        depth = opts.body_thickness_m
        lo = np.array([lo_xy[0], lo_xy[1], z_face - depth])
        hi = np.array([hi_xy[0], hi_xy[1], z_face])
        meshes.append(box_mesh("body", lo, hi, "body"))
        info.update(body_lo_m=lo.tolist(), body_hi_m=hi.tolist())
        for tid, v, base in zip(pattern.ids, vertices, mount_base):
            if base > z_face + 1e-4:
                meshes.append(cylinder_mesh(f"boom{tid}", v[:2], z_face, base, opts.boom_radius_m, "body"))
                info.setdefault("booms", []).append({"target": int(tid), "z0_m": z_face, "z1_m": float(base)})
    return TargetGeometry(meshes=meshes, cube_vertex_m=vertices, cube_axis=np.tile(axis, (len(pts), 1)),
                          reference_m=pts.copy(), info=info)
