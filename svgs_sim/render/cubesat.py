"""The shipped 3U CubeSat body (``svgs render --body 3u``), generated here (numpy; each part a
surface of :mod:`svgs_sim.render.materials`). ``tools/make_3u_body.py`` writes it as an ``.obj``
(``svgs_sim/assets/bodies/cubesat-3u.obj``, to look at or to start a mesh body of one's own from).

The model, metres in the target frame (x, y in the pattern plane, +z the face normal toward a
head-on camera; the pattern file's origin at the base of target 3's boom):

- **Envelope**: 100 x 340.5 x 100 mm, long along the target's y (CubeSat Design Specification rev. 14:
  a 3U is 100.0 x 100.0 x 340.5 mm; its four rails run along the long edges, at least 8.5 mm wide).
  The pattern face is one 100 x 340.5 mm side; its plane is the one the cube mounts sit on (the
  renderer's ``face_z_m``); the body reaches 100 mm behind it.
- **Where the pattern sits**: the svgs-3u pattern spans 87.5 mm across (x: targets 1, 2, 3 at 0,
  target 4 at 87.5 mm) and 275 mm along (y: targets 1 and 2 at +/-137.5 mm); with the 19 mm mounts
  it is 106.5 mm wide, 6.5 mm more than the face. The face is centred on the pattern across
  (x from -6.25 to 93.75 mm) and along: the mounts of targets 1, 2 and 3 stand on one rail, target
  4's on the other, each overhanging the rail's outer edge by 3.25 mm (a flight pattern would move
  its cubes 3.25 mm inward or use 12.5 mm mounts; the paper's Table 1 positions are kept).
- **Parts** (each its own surface): ``rails`` (four 8.5 x 8.5 mm rails, anodised aluminium),
  ``face`` (the pattern face between the rails: an MLI blanket), ``solar_x_pos`` and ``solar_x_neg``
  (the two sides next to the pattern face, body-mounted cells under cover glass), ``solar_back``
  (the side opposite the pattern), ``ends`` (the two 100 x 100 mm ends, anodised aluminium) and
  ``boom`` (target 3's boom: a 4 mm radius rod from the face to the cube's mount, as the
  renderer's plate body has it, anodised aluminium).

Every optical value is the surface library's (``assets/materials/surfaces.toml``: each sourced or
marked ASSUMPTION); the part-to-surface choice is an ASSUMPTION of a typical 3U (MLI on the face
that carries the pattern, cells on the other three long sides).
"""

from __future__ import annotations

import numpy as np

from .materials import PREFIX

SIZE_X_M, SIZE_Y_M, DEPTH_M = 0.100, 0.3405, 0.100  # CubeSat Design Specification rev. 14, 3U
RAIL_M = 0.0085  # the rails' minimum width (CDS rev. 14)
BOOM_RADIUS_M = 0.004  # svgs_sim.render.geometry.SceneOptions.boom_radius_m
SURFACES = {"rails": "anodised-aluminium", "face": "mli", "solar_x_pos": "solar-cell", "solar_x_neg": "solar-cell",
            "solar_back": "solar-cell", "ends": "anodised-aluminium", "boom": "anodised-aluminium"}


def _quad(a, b, c, d):
    """Two triangles of the quad a-b-c-d (counter-clockwise seen from outside)."""
    return [(a, b, c), (a, c, d)]


def box(lo, hi) -> list:
    """Outward triangles of an axis-aligned box, each a tuple of three (3,) points."""
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    p = {k: np.array(v, float) for k, v in {
        "000": (x0, y0, z0), "100": (x1, y0, z0), "010": (x0, y1, z0), "110": (x1, y1, z0),
        "001": (x0, y0, z1), "101": (x1, y0, z1), "011": (x0, y1, z1), "111": (x1, y1, z1)}.items()}
    tris = []
    for q in (("000", "010", "110", "100"), ("001", "101", "111", "011"), ("000", "100", "101", "001"),
              ("010", "011", "111", "110"), ("000", "001", "011", "010"), ("100", "110", "111", "101")):
        tris += _quad(*(p[k] for k in q))
    return tris


def rect(centre, u, v) -> list:
    """A rectangle ``centre +/- u +/- v`` facing ``u x v``."""
    c, u, v = (np.asarray(a, float) for a in (centre, u, v))
    return _quad(c - u - v, c + u - v, c + u + v, c - u + v)


def cylinder(x, y, z0, z1, r, n=24) -> list:
    """A closed cylinder along z."""
    a = np.linspace(0, 2 * np.pi, n + 1)
    ring = [np.array([x + r * np.cos(t), y + r * np.sin(t)]) for t in a]
    tris = []
    for k in range(n):
        p0, p1 = ring[k], ring[k + 1]
        tris += _quad(np.r_[p0, z0], np.r_[p1, z0], np.r_[p1, z1], np.r_[p0, z1])
        tris.append((np.r_[x, y, z1], np.r_[p0, z1], np.r_[p1, z1]))
        tris.append((np.r_[x, y, z0], np.r_[p1, z0], np.r_[p0, z0]))
    return tris


def parts(face_z_m: float, boom, centre_xy_m=(0.04375, 0.0)) -> dict:
    """Part name -> triangles. ``boom``: ``(x, y, z0, z1)`` of target 3's boom, or None;
    ``centre_xy_m``: the face's centre (svgs-3u: the middle of its targets, x 0..87.5 mm)."""
    cx, cy = (float(c) for c in centre_xy_m)
    x0, x1 = cx - SIZE_X_M / 2, cx + SIZE_X_M / 2
    y0, y1 = cy - SIZE_Y_M / 2, cy + SIZE_Y_M / 2
    z1 = face_z_m
    z0 = z1 - DEPTH_M
    r = RAIL_M
    rails = []
    for xa, za in ((x0, z0), (x1 - r, z0), (x0, z1 - r), (x1 - r, z1 - r)):
        rails += box((xa, y0, za), (xa + r, y1, za + r))
    xc, yc, zc = 0.5 * (x0 + x1), 0.5 * (y0 + y1), 0.5 * (z0 + z1)
    hx, hy, hz = 0.5 * SIZE_X_M - r, 0.5 * SIZE_Y_M, 0.5 * DEPTH_M - r
    out = {
        "rails": rails,
        "face": rect((xc, yc, z1), (hx, 0, 0), (0, hy, 0)),
        "solar_x_pos": rect((x1, yc, zc), (0, hy, 0), (0, 0, hz)),
        "solar_x_neg": rect((x0, yc, zc), (0, 0, hz), (0, hy, 0)),
        "solar_back": rect((xc, yc, z0), (0, hy, 0), (hx, 0, 0)),
        "ends": rect((xc, y1, zc), (0, 0, hz + r), (hx + r, 0, 0)) + rect((xc, y0, zc), (hx + r, 0, 0), (0, 0, hz + r)),
    }
    if boom is not None:
        out["boom"] = cylinder(*boom, BOOM_RADIUS_M)
    return out


def cubesat_3u_meshes(face_z_m: float, boom, centre_xy_m=(0.04375, 0.0)) -> list:
    """The body's parts, each with its library surface: the fields of a
    :class:`svgs_sim.render.geometry.MeshSpec` (which :func:`svgs_sim.render.geometry.build_target` makes of them).

    Parameters
    ----------
    face_z_m : float
        The pattern face's plane (the mounts' base), target frame, m.
    boom : tuple of float or None
        ``(x_m, y_m, z0_m, z1_m)`` of target 3's boom (None: no boom).
    centre_xy_m : (float, float)
        The pattern face's centre in the pattern plane, m.

    Returns
    -------
    list of (name, vertices (V, 3), faces (F, 3) uint32, material ``surface:NAME``)
    """
    out = []
    for name, tris in parts(face_z_m, boom, centre_xy_m).items():
        v = np.asarray(tris, float).reshape(-1, 3)
        out.append((f"cubesat_{name}", v, np.arange(len(v), dtype=np.uint32).reshape(-1, 3), PREFIX + SURFACES[name]))
    return out
