"""The ToF camera profile and the eight-marker target (issue 7, item 2)."""

import importlib.util
import itertools
import tomllib

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


def _tof8_file() -> dict:
    """assets/patterns/tof-8.toml as written (not through the loaders)."""
    with open(Pattern.load("tof-8").source, "rb") as fh:
        return tomllib.load(fh)


def test_tof8_target_has_the_paper_sizes_and_standoffs():
    tgt = load_target("tof-8")
    assert tgt.ids.tolist() == list(range(1, 9))
    np.testing.assert_allclose(tgt.diameter_m, [0.035] * 4 + [0.080] * 4)
    stand = dict(zip(tgt.ids.tolist(), tgt.standoff_m))
    assert {k for k, v in stand.items() if v == pytest.approx(0.100)} == {1, 3, 4, 7}
    assert {k for k, v in stand.items() if v == pytest.approx(0.150)} == {2, 5, 6, 8}
    # the SVGS loader reads the same file
    assert Pattern.load("tof-8").n == 8
    # every marker lies on the plate (in-plane, about the plate's centre)
    pc = np.asarray(_tof8_file()["plate"]["centre_m"])
    w, h = tgt.plate["width_m"], tgt.plate["height_m"]
    assert np.all(np.abs(tgt.points_m[:, 0] - pc[0]) + tgt.radius_m <= w / 2)
    assert np.all(np.abs(tgt.points_m[:, 1] - pc[1]) + tgt.radius_m <= h / 2)


def test_tof8_origin_is_the_marker_faces_centroid_and_the_plate_sits_at_the_standoffs():
    """The target frame's origin is the centroid of the eight marker faces (the paper's reported
    point, within ~3.5 cm of it along the line of sight by its Table 2); the plate's front face,
    ``[plate] centre_m``, lies a standoff behind every face: the paper's 100 / 150 mm."""
    raw = _tof8_file()
    P = np.array([[t["x_m"], t["y_m"], t["z_m"]] for t in raw["target"]])
    np.testing.assert_allclose(P.mean(0), 0.0, atol=1e-12)
    pc = np.asarray(raw["plate"]["centre_m"])
    for t in raw["target"]:
        assert t["z_m"] - t["standoff_m"] == pytest.approx(pc[2], abs=1e-12), t["id"]
        assert t["standoff_m"] == (0.100 if t["id"] in (1, 3, 4, 7) else 0.150)  # the paper's section 2.1
    # the mean standoff: half the faces 100 mm, half 150 mm above the plate
    assert pc[2] == pytest.approx(-0.125, abs=1e-12)
    tgt = load_target("tof-8")
    np.testing.assert_allclose(tgt.plate_centre_m, pc, atol=0)
    np.testing.assert_allclose(tgt.points_m[:, 2] - tgt.standoff_m, pc[2], atol=1e-12)


def test_the_scene_geometry_puts_the_plate_at_its_centre_and_the_posts_on_it():
    """TofGeometry (numpy; what the renderer builds its shapes from and bounds its window with):
    the plate's front face at ``[plate] centre_m``, its back a thickness behind, the bounding box
    from the plate's back to the nearest marker face."""
    from svgs_sim.render.tof.scene import TofSceneOptions, resolve_geometry

    tgt = load_target("tof-8")
    pc = np.asarray(_tof8_file()["plate"]["centre_m"])
    geo = resolve_geometry(tgt, TofSceneOptions())
    np.testing.assert_array_equal(geo.plate_centre_m, pc)
    C = geo.corners_m()
    w, h = geo.plate_size_m
    r = tgt.radius_m.max()  # the box takes the largest marker's radius round every face
    np.testing.assert_allclose(C.min(0), [min(pc[0] - w / 2, tgt.points_m[:, 0].min() - r),
                                          min(pc[1] - h / 2, tgt.points_m[:, 1].min() - r),
                                          pc[2] - geo.plate_thickness_m], atol=1e-15)
    np.testing.assert_allclose(C.max(0), [max(pc[0] + w / 2, tgt.points_m[:, 0].max() + r),
                                          max(pc[1] + h / 2, tgt.points_m[:, 1].max() + r),
                                          tgt.points_m[:, 2].max()], atol=1e-15)
    # a bare plate on the origin (the renderer's flat-plate tests)
    bare = resolve_geometry(tgt, TofSceneOptions(markers=False, plate_centre_m=(0, 0, 0)))
    assert bare.plate_centre_m == (0.0, 0.0, 0.0) and bare.corners_m()[:, 2].max() == 0.0


@pytest.mark.render
def test_the_mitsuba_scene_has_the_plate_face_at_its_centre_and_posts_from_it():
    """The loaded Mitsuba shapes: the plate's box ends at z = [plate] centre_m z (its front face)
    centred on the key's x, y; each post runs from that face to its puck's back."""
    if importlib.util.find_spec("mitsuba") is None:  # not imported here: select_variant picks the LLVM first
        pytest.skip("Mitsuba is not installed (the 'render' extra)")
    from svgs_sim.render.tof.scene import TofSceneOptions, build_tof_scene
    from svgs_sim.render.variant import select_variant

    select_variant()
    tgt = load_target("tof-8")
    pc = np.asarray(_tof8_file()["plate"]["centre_m"])
    scene, geo = build_tof_scene(tgt, TofSceneOptions())
    shapes = {s.id(): s for s in scene.shapes()}
    bb = shapes["plate"].bbox()
    lo, hi = np.array(bb.min, float), np.array(bb.max, float)
    w, h = geo.plate_size_m
    np.testing.assert_allclose(hi, pc + [w / 2, h / 2, 0.0], atol=1e-6)
    np.testing.assert_allclose(lo, pc - [w / 2, h / 2, geo.plate_thickness_m], atol=1e-6)
    for i, (c, rp) in enumerate(zip(tgt.points_m, geo.post_radius_m)):
        pb = shapes[f"post{i}"].bbox()
        assert float(pb.min[2]) == pytest.approx(pc[2], abs=1e-6)
        assert float(pb.max[2]) == pytest.approx(c[2] - geo.marker_thickness_m, abs=1e-6)
        assert float(pb.min[0] + pb.max[0]) / 2 == pytest.approx(c[0], abs=1e-6)
        face = shapes[f"marker{i}_face"].bbox()
        assert float(face.max[2]) == pytest.approx(c[2], abs=1e-6)


#: The paper's average positions (Zhu et al. 2022, Table 1 at 697 mm and Table 2 at 5712 mm), mm,
#: typed from the paper: x, y, z of the target in the ToF frame.
PAPER_AVERAGE_MM = {0.697: (2.193, -10.457, 697.604), 5.712: (5.097, -2.381, 5712.362)}


@pytest.mark.parametrize("range_m", sorted(PAPER_AVERAGE_MM))
def test_the_stability_truth_is_the_papers_average_position(range_m):
    """The truth of ``svgs tof stability --range 0.697 / 5.712`` (reported at the marker faces'
    centroid, the default) is the paper's average position within 10 mm in every component; the
    scenario's range_m is the boresight distance to the target frame's origin."""
    from svgs_sim.sim.tof_stability import COLUMNS, pose_columns, reference_point_m, stability_scenario
    from svgs_sim.svgs.frames import pose_to_state

    sc = stability_scenario(range_m)
    R, t = sc.pose()
    tgt = load_target(sc.pattern)
    cols = dict(zip(COLUMNS, pose_columns(R, t, pose_to_state(R, t), None, reference_point_m(tgt, "markers"))))
    got = np.array([cols["target_x_cam_mm"], cols["target_y_cam_mm"], cols["target_z_cam_mm"]])
    assert np.all(np.abs(got - PAPER_AVERAGE_MM[range_m]) < 10.0), got
    assert sc.range_m == pytest.approx(t[2])  # range_m: the boresight distance to the origin
    # the markers' centroid reported is the origin the pose places (the marker faces' centroid)
    np.testing.assert_allclose(R @ tgt.points_m.mean(0) + t, t, atol=1e-12)
    # the plate's front face, 125 mm behind along the plate normal, is the other reference
    plate = pose_columns(R, t, pose_to_state(R, t), None, reference_point_m(tgt, "plate"))[:3]
    assert np.linalg.norm(plate - got) == pytest.approx(np.linalg.norm([22.5, 0.625, 125.0]), abs=1e-9)


def test_moving_the_frame_does_not_move_the_target():
    """The same physical target in the old frame (origin on the plate's face, the layout as first
    drawn) at pose (R, t) and in tof-8's frame at (R, t + R c), c the old frame's marker centroid:
    the same marker faces in the camera and the same projected centres (the truth targets_px),
    the same plate."""
    from svgs_sim.render.tof.camera import marker_truth
    from svgs_sim.render.tof.scene import TofSceneOptions, resolve_geometry
    from svgs_sim.svgs.frames import pose_from_scenario

    old_xy_mm = {1: (30, 125), 2: (30, 30), 3: (100, 30), 4: (180, 30), 5: (-140, 90), 6: (-140, -100),
                 7: (-20, -100), 8: (140, -110)}
    stand_mm = {1: 100, 2: 150, 3: 100, 4: 100, 5: 150, 6: 150, 7: 100, 8: 150}
    old = Pattern(name="tof-8-plate-frame", ids=np.arange(1, 9),
                  points_m=np.array([[*old_xy_mm[i], stand_mm[i]] for i in range(1, 9)], float) * 1e-3,
                  tables={"plate": {"width_m": 0.40, "height_m": 0.32, "thickness_m": 0.005, "albedo": 0.04}},
                  target_sizes_m=tuple((0.035 if i <= 4 else 0.080, None) for i in range(1, 9)))
    new = load_target("tof-8")
    old_t = load_target(old)
    np.testing.assert_allclose(old_t.standoff_m, new.standoff_m)  # default standoff: z_m less the plate's z (0)
    c = old.points_m.mean(0)
    np.testing.assert_allclose(new.points_m, old.points_m - c, atol=1e-15)
    cam = load_camera()
    for R, t in (pose_from_scenario(0.9, 0.05, -0.03, 5.0, -8.0, 20.0), pose_from_scenario(5.712, 0.0, 0.0, 3.8, 1.3, -2.1)):
        a, b = marker_truth(cam, old_t, R, t), marker_truth(cam, new, R, t + R @ c)
        np.testing.assert_allclose(b["centres_cam_m"], a["centres_cam_m"], atol=1e-12)
        np.testing.assert_allclose(b["centres_px"], a["centres_px"], atol=1e-9)
        g_old = resolve_geometry(old_t, TofSceneOptions())
        g_new = resolve_geometry(new, TofSceneOptions())
        np.testing.assert_allclose(R @ np.asarray(g_new.plate_centre_m) + t + R @ c,
                                   R @ np.asarray(g_old.plate_centre_m) + t, atol=1e-12)
        np.testing.assert_allclose(g_new.corners_m() @ R.T + t + R @ c, g_old.corners_m() @ R.T + t, atol=1e-12)


def test_a_standoff_the_plate_contradicts_is_a_profile_error(tmp_path):
    """The post joins the plate's face and the puck: a standoff other than the face's height above
    [plate] centre_m, or a face behind the plate, is refused when the target is loaded."""
    raw = _tof8_file()

    def write(name, edit):
        import copy

        import tomli_w

        d = copy.deepcopy(raw)
        edit(d)
        p = tmp_path / name
        p.write_bytes(tomli_w.dumps(d).encode())
        return str(p)

    def shift_plate(d):
        d["plate"]["centre_m"][2] = -0.100

    def face_behind(d):
        d["plate"]["centre_m"][2] = 0.05
        for t in d["target"]:
            del t["standoff_m"]

    with pytest.raises(ProfileError, match=r"standoff_m = 0\.1 .*\[plate\] centre_m"):
        load_target(write("shifted.toml", shift_plate))
    with pytest.raises(ProfileError, match="behind the plate"):
        load_target(write("behind.toml", face_behind))

    def no_standoffs(d):
        for t in d["target"]:
            del t["standoff_m"]

    tgt = load_target(write("defaults.toml", no_standoffs))  # the default standoff: z_m less the plate's z
    np.testing.assert_allclose(tgt.standoff_m, load_target("tof-8").standoff_m, atol=1e-12)


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
