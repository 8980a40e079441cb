"""The surfaces a target's body is made of: a library of BSDFs in the camera band
(``assets/materials/surfaces.toml``, each value with its source or marked ASSUMPTION).

>>> sorted(surface_names())
['anodised-aluminium', 'lambertian-white', 'mli', 'solar-cell', 'white-paint']
>>> surface("white-paint")["reflectance"]
0.88
"""

from __future__ import annotations

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
