"""The shipped 3U CubeSat body (``--body 3u``) against the CubeSat Design Specification (rev. 14:
100.0 x 100.0 x 340.5 mm, rails at least 8.5 mm wide along the long edges) and the paper's Table 1
(the pattern it carries)."""

from __future__ import annotations

import numpy as np
import pytest

from svgs_sim.base.profiles import load_pattern
from svgs_sim.render.geometry import Reflector, SceneOptions, build_target
from svgs_sim.render.materials import PREFIX, surface


@pytest.fixture(scope="module")
def target():
    pat = load_pattern("svgs-3u")
    return build_target(pat, Reflector.resolve(None, pat), SceneOptions.resolve({"body": "3u"}))


def _parts(target):
    return {m.name.removeprefix("cubesat_"): m for m in target.meshes if m.name.startswith("cubesat_")}


def test_the_body_is_a_3u_long_along_y_behind_the_pattern_face(target):
    P = _parts(target)
    v = np.concatenate([m.vertices_m for m in P.values() if m.name != "cubesat_boom"])
    size = v.max(0) - v.min(0)
    assert size == pytest.approx([0.100, 0.3405, 0.100], abs=1e-9)
    z_face = target.info["face_z_m"]
    assert v[:, 2].max() == pytest.approx(z_face) and v[:, 2].min() == pytest.approx(z_face - 0.100)
    rails = P["rails"].vertices_m
    assert rails[:, 0].min() == pytest.approx(v[:, 0].min())
    # four rails, 8.5 mm square, 340.5 mm long: 4 boxes of 12 triangles
    assert len(P["rails"].faces) == 48
    assert {"face", "solar_x_pos", "solar_x_neg", "solar_back", "ends", "boom"} <= set(P)


def test_the_pattern_overhangs_the_100_mm_face_by_its_mounts(target):
    """Table 1: targets 1, 2, 3 at x = 0 and target 4 at x = 87.5 mm; the mounts are 19 mm across, so
    the pattern is 106.5 mm wide on a 100 mm face: 3.25 mm over each long edge."""
    pat = load_pattern("svgs-3u")
    x = pat.points_m[:, 0]
    v = np.concatenate([m.vertices_m for m in _parts(target).values()])
    r_mount = 0.5 * Reflector.resolve(None, pat).mount_outer_diameter_m
    assert r_mount == pytest.approx(0.0095)
    assert (x.min() - r_mount) - v[:, 0].min() == pytest.approx(-0.00325, abs=1e-9)
    assert (x.max() + r_mount) - v[:, 0].max() == pytest.approx(0.00325, abs=1e-9)
    assert v[:, 1].min() < pat.points_m[:, 1].min() - r_mount and v[:, 1].max() > pat.points_m[:, 1].max() + r_mount


def test_every_part_faces_outward_and_has_a_library_surface(target):
    P = _parts(target)
    body = np.concatenate([m.vertices_m for n, m in P.items() if n != "boom"])
    centre = 0.5 * (body.min(0) + body.max(0))
    for name, m in P.items():
        surface(m.material.removeprefix(PREFIX))  # refuses a name the library lacks
        tri = m.vertices_m[m.faces]
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        c = tri.mean(1)
        if name == "rails":  # four closed boxes: each faces out of its own centre
            ref = np.repeat(tri.reshape(4, 12 * 3, 3).mean(1), 12, axis=0)
        elif name == "boom":
            ref = np.r_[target.info["boom_3u"][:2], c[:, 2].mean()][None]
        else:
            ref = centre
        assert np.all(np.einsum("ij,ij->i", n, c - ref) > 0), name
    assert P["face"].material == PREFIX + "mli" and P["solar_back"].material == PREFIX + "solar-cell"


def test_the_shipped_obj_is_the_model(tmp_path):
    """``tools/make_3u_body.py`` writes the same model as the renderer builds (vertex for vertex)."""
    import importlib.util
    from pathlib import Path

    tool = Path(__file__).resolve().parents[1] / "tools" / "make_3u_body.py"
    spec = importlib.util.spec_from_file_location("make_3u_body", tool)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    obj, _ = mod.write(tmp_path)
    shipped = Path(__file__).resolve().parents[1] / "svgs_sim" / "assets" / "bodies" / "cubesat-3u.obj"
    assert obj.read_text() == shipped.read_text()
