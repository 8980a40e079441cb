"""A target body from a mesh file (``svgs render --body FILE.ply --body-material NAME``).

The file's coordinates are metres in the target frame (the pattern's: x, y in the pattern plane,
+z its face normal toward a head-on camera). trimesh reads it (``.ply`` or ``.obj``); a file of
several parts (an ``.obj`` with groups) keeps them apart, so each part may have a surface of its
own (``--body-materials FILE.toml``: ``part = "surface"``; a part not named there takes
``--body-material``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from svgs_sim.base.errors import InputError

from .geometry import MeshSpec
from .materials import PREFIX, surface

def _parts(path: Path) -> dict:
    """Part name -> (vertices (V, 3), faces (F, 3)) of a mesh file."""
    try:
        import trimesh
    except ImportError:
        raise InputError("--body FILE: mesh bodies need trimesh: pip install -e \".[orbit]\"") from None
    try:
        loaded = trimesh.load(str(path), process=False)
    except Exception as exc:  # trimesh raises many kinds for a bad file
        raise InputError(f"--body: {str(path)!r} is not a readable .ply/.obj mesh ({type(exc).__name__}: {exc})") from None
    geoms = loaded.geometry if hasattr(loaded, "geometry") else {path.stem: loaded}
    out = {}
    for name, g in geoms.items():
        v, f = np.asarray(getattr(g, "vertices", ()), float), np.asarray(getattr(g, "faces", ()), np.int64)
        if v.ndim != 2 or v.shape[1:] != (3,) or f.ndim != 2 or f.shape[1:] != (3,) or len(f) == 0:
            continue
        if not np.all(np.isfinite(v)):
            raise InputError(f"--body: {str(path)!r} part {name!r} has vertices that are not finite numbers")
        out[str(name)] = (v, f)
    if not out:
        raise InputError(f"--body: {str(path)!r} holds no triangle")
    return out


def body_meshes(path, material: str | None, materials: dict | None = None) -> list[MeshSpec]:
    """The MeshSpecs of a mesh body, each part with its library surface.

    Parameters
    ----------
    path : str or Path
        A ``.ply`` or ``.obj`` file, metres in the target frame.
    material : str or None
        The surface of every part not in ``materials`` (:mod:`svgs_sim.render.materials`).
    materials : dict, optional
        Part name -> surface name.

    Returns
    -------
    list of MeshSpec
        One per part, vertices not shared between triangles (the renderer's flat normals).
    """
    path = Path(path)
    materials = dict(materials or {})
    parts = _parts(path)
    unknown = sorted(set(materials) - set(parts))
    if unknown:
        raise InputError(f"--body-materials: {str(path)!r} has no part {', '.join(map(repr, unknown))}; its parts: "
                         f"{', '.join(map(repr, parts))}")
    out = []
    for k, (name, (v, f)) in enumerate(parts.items()):
        surf = materials.get(name, material)
        if surf is None:
            raise InputError(f"--body-material: part {name!r} of {str(path)!r} has no surface (give --body-material "
                             "NAME, or name it in --body-materials)")
        surface(surf)  # InputError naming the library's surfaces
        tri = v[f]  # (F, 3, 3): the vertices unshared
        area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
        tri = tri[area > 1e-14]  # degenerate triangles have no normal
        if len(tri) == 0:
            continue
        out.append(MeshSpec(f"bodymesh{k}", tri.reshape(-1, 3), np.arange(3 * len(tri), dtype=np.uint32).reshape(-1, 3),
                            PREFIX + surf))
    return out
