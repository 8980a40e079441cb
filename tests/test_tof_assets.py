"""The ToF camera profile and the eight-marker target (issue 7, item 2)."""

import itertools

import numpy as np
import pytest

from svgs_sim.base.errors import ProfileError
from svgs_sim.base.profiles import Camera, Pattern
from svgs_sim.tof.camera import line_of_sight, load_camera, load_target, points_from_depth


def test_epc660_profile_matches_the_paper_optics():
    cam = load_camera("tof-epc660")
    assert (cam.width, cam.height) == (320, 240)
    # paper: 6.5 mm lens, 52.4 x 40.6 deg field of view; EPC660: 20 um pixels
    hfov = 2 * np.degrees(np.arctan(cam.width / 2 / cam.fx))
    vfov = 2 * np.degrees(np.arctan(cam.height / 2 / cam.fy))
    assert hfov == pytest.approx(52.4, abs=0.1)
    assert vfov == pytest.approx(40.6, abs=0.1)
    tof = cam.table("tof")
    assert cam.table("optics").focal_length_m / tof.pixel_pitch_m == pytest.approx(cam.fx)
    # unambiguous range c / (2 f) covers the paper's 15 m operating range
    assert 299_792_458.0 / (2 * tof.modulation_frequency_hz) == pytest.approx(15.0, rel=0.01)
    assert tof.depth_kind == "radial"
    assert cam.table("illumination").divergence_full_angle_deg == 90.0
    assert tof.wavelength_m == pytest.approx(850e-9)


def test_every_number_of_the_profile_is_sourced_or_assumed():
    path = Camera.load("tof-epc660").source
    with open(path, encoding="utf-8") as fh:
        lines = fh.read().splitlines()
    for line in lines:
        s = line.strip()
        value = s.split("=", 1)[1].split("#")[0].strip() if "=" in s and not s.startswith("#") else ""
        if value and not value.startswith('"') and any(ch.isdigit() for ch in value):
            key = s.split("=")[0].strip()
            if key in ("width", "height", "k1", "k2", "p1", "p2", "k3"):
                continue  # sourced in [sources]
            assert "#" in s, f"unsourced number in tof-epc660.toml: {s!r}"


def test_tof8_target_has_the_paper_sizes_and_standoffs():
    tgt = load_target("tof-8")
    assert tgt.ids.tolist() == list(range(1, 9))
    np.testing.assert_allclose(tgt.diameter_m, [0.035] * 4 + [0.080] * 4)
    stand = dict(zip(tgt.ids.tolist(), tgt.standoff_m))
    assert {k for k, v in stand.items() if v == pytest.approx(0.100)} == {1, 3, 4, 7}
    assert {k for k, v in stand.items() if v == pytest.approx(0.150)} == {2, 5, 6, 8}
    np.testing.assert_allclose(tgt.points_m[:, 2], tgt.standoff_m)
    # the SVGS loader reads the same file
    assert Pattern.load("tof-8").n == 8
    # every marker lies on the plate
    w, h = tgt.plate["width_m"], tgt.plate["height_m"]
    assert np.all(np.abs(tgt.points_m[:, 0]) + tgt.radius_m <= w / 2)
    assert np.all(np.abs(tgt.points_m[:, 1]) + tgt.radius_m <= h / 2)


def test_tof8_layout_has_no_distance_symmetry():
    """No relabelling of 6 markers preserves their distances (matching stays unambiguous
    with two markers missing), nor of 4 markers to 5 mm."""
    P = load_target().points_m
    D = np.linalg.norm(P[:, None] - P[None], axis=-1)
    for k, margin in ((6, 0.035), (4, 0.005)):
        perms = np.array(list(itertools.permutations(range(8), k)))
        Dp = D[perms[:, :, None], perms[:, None, :]]
        worst = np.inf
        for sub in itertools.combinations(range(8), k):
            sub = np.array(sub)
            err = np.abs(Dp - D[np.ix_(sub, sub)]).max(axis=(1, 2))
            err[np.all(perms == sub, axis=1)] = np.inf
            worst = min(worst, err.min())
        assert worst > margin, (k, worst)


def test_target_without_diameters_is_a_profile_error(tmp_path):
    p = tmp_path / "bad.toml"
    p.write_text("name='bad'\n" + "".join(
        f"[[target]]\nid={i}\nx_m={x}\ny_m={y}\nz_m=0.0\n" for i, (x, y) in enumerate([(0, 0), (1, 0), (0, 1), (1, 1)], 1)))
    with pytest.raises(ProfileError, match="diameter_m"):
        load_target(str(p))


def test_points_from_radial_depth_and_z_depth_agree():
    cam = load_camera()
    p = np.array([[0.3, -0.2, 2.0], [-0.5, 0.4, 1.0]])
    uv = cam.project(p)
    np.testing.assert_allclose(points_from_depth(cam, uv, np.linalg.norm(p, axis=1)), p, atol=1e-12)
    np.testing.assert_allclose(points_from_depth(cam, uv, p[:, 2], kind="z"), p, atol=1e-12)
    e = line_of_sight(cam, uv)
    np.testing.assert_allclose(np.linalg.norm(e, axis=1), 1.0)
