"""The surfaces a target's body is made of: a library of BSDFs in the camera band
(``assets/materials/surfaces.toml``, each value with its source or marked ASSUMPTION).

>>> sorted(surface_names())
['anodised-aluminium', 'lambertian-white', 'mli', 'solar-cell', 'white-paint']
>>> surface("white-paint")["reflectance"]
0.88
"""

from __future__ import annotations

from pathlib import Path

from svgs_sim.assets import ASSETS_DIR
from svgs_sim.base.errors import InputError, ProfileError
from svgs_sim.base.profiles import cached, read_toml

SURFACES_FILE = ASSETS_DIR / "materials" / "surfaces.toml"
#: Each BSDF model and the values it takes (all in [0, 1] except ``int_ior``, 1 to 3).
MODELS = {"diffuse": ("reflectance",), "plastic": ("diffuse_reflectance", "int_ior"),
          "roughconductor": ("specular_reflectance", "alpha")}
#: The prefix of a library surface's key in the scene's material table (a MeshSpec's material).
PREFIX = "surface:"


def _load() -> dict:
    data = read_toml(SURFACES_FILE, "surface library")
    out = {}
    for i, s in enumerate(data.get("surface", [])):
        where = f"{SURFACES_FILE.name} surface {i + 1}"
        name, model = s.get("name"), s.get("model")
        if not isinstance(name, str) or model not in MODELS or not isinstance(s.get("source"), str):
            raise ProfileError(f"{where}: needs a name, a model ({', '.join(MODELS)}) and a source")
        for key in MODELS[model]:
            v = s.get(key)
            hi = 3.0 if key == "int_ior" else 1.0
            lo = 1.0 if key == "int_ior" else 0.0
            if not isinstance(v, (int, float)) or not lo <= float(v) <= hi:
                raise ProfileError(f"{where} ({name}): {key} must be a number from {lo:g} to {hi:g}, got {v!r}")
        out[name] = dict(s)
    return out


def surfaces() -> dict:
    """Surface name -> its table (``model``, the model's values, ``source``), read once."""
    return cached("surfaces", (str(SURFACES_FILE),), (SURFACES_FILE,), _load)


def surface_names() -> list[str]:
    return list(surfaces())


def surface(name: str) -> dict:
    """The table of the library surface ``name`` (InputError naming the known ones)."""
    lib = surfaces()
    if name not in lib:
        raise InputError(f"--body-material: unknown surface {name!r}; the library "
                         f"(svgs_sim/assets/materials/surfaces.toml) has {', '.join(sorted(lib))}")
    return lib[name]


#: File name endings read as a mesh body (:mod:`svgs_sim.render.body_mesh`).
MESH_SUFFIXES = (".ply", ".obj")


def is_mesh_body(body) -> bool:
    """Whether a ``--body`` value names a mesh file (by its ending) rather than a built-in body."""
    return isinstance(body, str) and body.lower().endswith(MESH_SUFFIXES)


def check_body(body, body_material=None, body_materials=(), builtin=("plate", "3u", "none")) -> bool:
    """A body and its surfaces, checked before any work (InputError naming the option): one of
    ``builtin``, or an existing ``.ply``/``.obj`` file with a library surface for every part
    (``body_material``, and ``body_materials``: (part, surface) pairs). Returns whether it is a mesh."""
    if is_mesh_body(body):
        if not Path(body).is_file():
            raise InputError(f"--body: mesh file {body!r} does not exist")
        if body_material is None and not body_materials:
            raise InputError(f"--body-material: the mesh body {body!r} needs a surface (one of the library's, "
                             "svgs_sim/assets/materials/surfaces.toml), or --body-materials FILE.toml")
        for name in [body_material, *(m for _, m in body_materials)]:
            if name is not None:
                surface(name)
        return True
    if body not in builtin:
        raise InputError(f"--body: expected {', '.join(repr(b) for b in builtin if b is not None)} or a mesh file "
                         f"ending in .ply or .obj, got {body!r}")
    if body_material is not None or body_materials:
        raise InputError("--body-material: only a mesh body (--body FILE.ply or FILE.obj) takes a surface")
    return False


def bsdf_dict(name: str) -> dict:
    """The Mitsuba BSDF dictionary of the library surface ``name``."""
    s = surface(name)
    u = lambda v: {"type": "uniform", "value": float(v)}  # noqa: E731
    if s["model"] == "diffuse":
        return {"type": "diffuse", "reflectance": u(s["reflectance"])}
    if s["model"] == "plastic":
        return {"type": "plastic", "diffuse_reflectance": u(s["diffuse_reflectance"]), "int_ior": float(s["int_ior"]),
                "ext_ior": 1.0, "nonlinear": False}
    return {"type": "roughconductor", "material": "none", "distribution": "ggx", "alpha": float(s["alpha"]),
            "specular_reflectance": u(s["specular_reflectance"])}
