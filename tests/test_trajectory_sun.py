"""A trajectory file's sun per row (issue 38 item 7): read, checked, interpolated and set on each
frame's scene; the references are geometric (the bisector of two directions, a unit vector from
its azimuth and elevation), not the code's own output."""

import numpy as np
import pytest

from svgs_sim.cli.main import main
from svgs_sim.sim.approach import Trajectory
from svgs_sim.sim.closed_loop import Scenario
from svgs_sim.sim.scene import Scene
from svgs_sim.svgs import InputError

HEAD = "t_s,x_m,y_m,z_m,roll_deg,pitch_deg,yaw_deg"


def _file(tmp_path, rows, sun=True):
    head = HEAD + (",sun_azimuth_deg,sun_elevation_deg" if sun else "")
    p = tmp_path / "t.csv"
    p.write_text(head + "\n" + "\n".join(rows) + "\n")
    return str(p)


def test_the_sun_between_rows_lies_on_the_great_circle(tmp_path):
    # az 0 and az 90 on the horizon: halfway in time the chord's midpoint points at az 45, el 0;
    # a quarter of the way, the chord point (0.75, 0.25, 0) points at atan(1/3)
    t = Trajectory.load(_file(tmp_path, ["0,0,0,5,0,0,0,0,0", "4,0,0,3,0,0,0,90,0"]))
    assert t.sun_at(2.0) == pytest.approx((45.0, 0.0), abs=1e-9)
    assert t.sun_at(1.0)[0] == pytest.approx(np.degrees(np.arctan2(0.25, 0.75)), abs=1e-9)
    assert t.sun_at(-5.0) == pytest.approx((0.0, 0.0), abs=1e-9)  # clamped to the span
    # a row's elevation comes back at the row; over the pole the azimuth is the row's
    t2 = Trajectory.load(_file(tmp_path, ["0,0,0,5,0,0,0,30,60", "4,0,0,3,0,0,0,30,-20"]))
    assert t2.sun_at(0.0) == pytest.approx((30.0, 60.0), abs=1e-9)
    assert t2.sun_at(4.0) == pytest.approx((30.0, -20.0), abs=1e-9)
    assert t2.sun_at(2.0)[0] == pytest.approx(30.0, abs=1e-9)  # along a meridian: elevation 20, the bisector
    assert t2.sun_at(2.0)[1] == pytest.approx(20.0, abs=1e-9)


def test_each_frame_s_scene_takes_the_row_s_sun(tmp_path):
    t = Trajectory.load(_file(tmp_path, ["0,0,0,5,0,0,0,0,0", "4,0,0,3,0,0,0,90,0"]))
    base = Scenario(scene=Scene(environment="orbit", earth_azimuth_deg=0.0, earth_elevation_deg=-60.0))
    sc = t.scenario(2.0, base)
    c = np.sqrt(0.5)
    assert sc.scene.sun_direction_target == pytest.approx((c, c, 0.0), abs=1e-12)
    assert sc.scene.earth_direction_target == base.scene.earth_direction_target  # the rest of the scene is kept
    assert sc.range_m == pytest.approx(4.0)
    # a file without the columns leaves the base's sun alone
    t0 = Trajectory.load(_file(tmp_path, ["0,0,0,5,0,0,0", "4,0,0,3,0,0,0"], sun=False))
    assert t0.sun_deg is None and t0.scenario(1.0, base).scene == base.scene
    # the study's manifest carries the columns and reads them back
    assert Trajectory.from_json(t.to_json()).sun_at(1.0) == t.sun_at(1.0)
    assert "sun_deg" not in t0.to_json()


@pytest.mark.parametrize("rows,head,message", [
    (["0,0,0,5,0,0,0,0", "1,0,0,4,0,0,0,0"], HEAD + ",sun_azimuth_deg", "needs both columns"),
    (["0,0,0,5,0,0,0,0,95", "1,0,0,4,0,0,0,0,0"], None, "outside -90 to 90"),
    (["0,0,0,5,0,0,0,0,0", "1,0,0,4,0,0,0,120,0"], None, "turns 120 deg"),
    (["0,0,0,5,0,0,0,0,0", "1,0,0,4,0,0,0,x,0"], None, "column sun_azimuth_deg"),
])
def test_bad_sun_columns_are_refused_naming_the_line(tmp_path, rows, head, message):
    p = tmp_path / "t.csv"
    p.write_text((head or HEAD + ",sun_azimuth_deg,sun_elevation_deg") + "\n" + "\n".join(rows) + "\n")
    with pytest.raises(InputError, match=message):
        Trajectory.load(str(p))


@pytest.mark.parametrize("extra,message", [
    ([], "on orbit only"),
    (["--environment", "orbit", "--sun-deg", "0,10"], "one or the other"),
])
def test_the_command_refuses_a_sun_it_cannot_use_before_any_work(tmp_path, capsys, extra, message):
    traj = _file(tmp_path, ["0,0,0,5,0,0,0,0,0", "4,0,0,3,0,0,0,90,0"])
    out = tmp_path / "never"
    assert main(["approach", "--camera", "galaxy-nexus", "--trajectory", traj, "--fps", "1", *extra,
                 "--out", str(out)]) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.render
def test_the_stream_renders_each_frame_under_its_own_sun(small_camera, tmp_path):
    """An orbit approach whose sun turns between rows: frame 1 of the stream (its renderer built
    under frame 0's sun, then moved by ``set_natural_light``) is the frame the isolated chain
    renders from scratch under the interpolated sun, image for image; and the sun shows (the frame
    differs from the same frame in eclipse)."""
    from svgs_sim.sim.approach import ApproachSensor
    from svgs_sim.sim.closed_loop import expose_and_solve, render_scenario

    traj = Trajectory.load(_file(tmp_path, ["0,0,0,6,0,3,-5,0,30", "2,0,0,4,0,0,0,90,30"]))
    base = Scenario(scene=Scene(environment="orbit"))
    sensor = ApproachSensor(small_camera, seed=5, motion=False, crlb=False, keep_images=True, base=base)
    sensor.measure_on(traj, 0.0)
    m1 = sensor.measure_on(traj, 1.0)
    rs, ns, _ = sensor.frame_seeds(1)
    sc = traj.scenario(1.0, Scenario(camera=small_camera, scene=base.scene))
    assert sc.scene.sun_azimuth_deg == pytest.approx(45.0) and sc.scene.sun_elevation_deg > 30.0
    frame = render_scenario(sc, seed=rs)
    row = expose_and_solve(frame, frame.exposer(), seed=ns, exposure_s=m1.exposure_s, iso=m1.iso, truth="actual")
    np.testing.assert_array_equal(row["_exposure"].image, m1.image)
    dark = render_scenario(sc.replace(scene=base.scene), seed=rs)
    lit_photons, dark_photons = float(frame.flux.sum()), float(dark.flux.sum())
    assert lit_photons > 1.5 * dark_photons, (lit_photons, dark_photons)


@pytest.mark.render
def test_the_stream_renders_the_body_it_is_given(small_camera, tmp_path):
    """``svgs approach --body 3u``: the stream's frame is the isolated chain's with the same body
    (image for image), and not the default breadboard's."""
    from svgs_sim.sim.approach import ApproachSensor
    from svgs_sim.sim.closed_loop import RenderOptions, expose_and_solve, render_scenario

    traj = Trajectory.load(_file(tmp_path, ["0,0,0,6,0,3,-5,45,30", "2,0,0,4,0,0,0,90,30"]))
    base = Scenario(scene=Scene(environment="orbit"))
    sensor = ApproachSensor(small_camera, seed=5, motion=False, crlb=False, keep_images=True, base=base,
                            body={"body": "3u"})
    m0 = sensor.measure_on(traj, 0.0)
    rs, ns, _ = sensor.frame_seeds(0)
    sc = traj.scenario(0.0, Scenario(camera=small_camera, scene=base.scene))
    frame = render_scenario(sc, seed=rs, options=RenderOptions(body="3u"))
    row = expose_and_solve(frame, frame.exposer(), seed=ns, exposure_s=m0.exposure_s, iso=m0.iso, truth="actual")
    np.testing.assert_array_equal(row["_exposure"].image, m0.image)
    plate = render_scenario(sc, seed=rs)
    assert not np.array_equal(plate.flux, frame.flux)
