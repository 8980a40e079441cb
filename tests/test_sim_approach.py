"""svgs approach: trajectories checked on input, the sensor frame by frame, motion, the preview
stream, the command's outputs and its resumption.

The physics references are analytic: a uniform smear's centroid and variance, a rolling
shutter's row delay, the photons of a binned pixel, the auto-exposure's fixed point from the
metering solver. The sensor's frame is checked against the isolated-pose chain
(:func:`svgs_sim.sim.closed_loop.render_scenario` + :func:`svgs_sim.sim.closed_loop.expose_and_solve`), which it
must equal: keeping the renderer, the sensor and the exposure between frames is a saving of
time, never a change of numbers. Rendered tests use the Galaxy Nexus scaled to 648 x 486."""

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from svgs_sim.cli.main import main
from svgs_sim.sim.approach import ApproachSensor, Trajectory, check_visible, scenario_from_pose
from svgs_sim.sim.closed_loop import Scenario
from svgs_sim.sim.scene import Scene
from svgs_sim.svgs import Camera, InputError


def _rows(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def _write(path, text):
    path.write_text(text)
    return str(path)


# ----------------------------------------------------------------------------- trajectory files
BAD_FILES = [
    ("", "empty file"),
    ("x_m,y_m,z_m,roll_deg,pitch_deg,yaw_deg\n0,0,10,0,0,0\n", "no t_s column"),
    ("t_s,a,b\n0,1,2\n1,1,2\n", "neither the paper state"),
    ("t_s,x_m,y_m,z_m,roll_deg,pitch_deg,yaw_deg\n0,0,0,10,0,0,0\n", "at least 2 rows"),
    ("t_s,x_m,y_m,z_m,roll_deg,pitch_deg,yaw_deg\n0,0,0,10,0,0,0\n1,0,0,abc,0,0,0\n", "line 3, column z_m"),
    ("t_s,x_m,y_m,z_m,roll_deg,pitch_deg,yaw_deg\n0,0,0,10,0,0,0\n1,0,0,nan,0,0,0\n", "not finite"),
    ("t_s,x_m,y_m,z_m,roll_deg,pitch_deg,yaw_deg\n0,0,0,10,0,0,0\n0,0,0,9,0,0,0\n", "increase strictly"),
    ("t_s,x_m,y_m,z_m,roll_deg,pitch_deg,yaw_deg\n0,0,0,10,0,0,0\n1,0,0,9,0,0\n", "line 3 has 6 fields"),
    # the camera 10 m on the target's far side: the target faces away, its origin behind the camera
    ("t_s,x_m,y_m,z_m,roll_deg,pitch_deg,yaw_deg\n0,0,0,10,0,0,0\n1,0,0,-10,0,0,0\n", "behind the camera"),
]


@pytest.mark.parametrize("text,message", BAD_FILES)
def test_bad_trajectory_files_are_refused_naming_the_problem(tmp_path, text, message):
    with pytest.raises(InputError, match=message):
        Trajectory.load(_write(tmp_path / "t.csv", text))


def test_messages_give_the_file_line_past_comments_and_a_byte_order_mark(tmp_path):
    text = "\ufeff# an approach\nt_s,x_m,y_m,z_m,roll_deg,pitch_deg,yaw_deg\n\n# knots\n0,0,0,10,0,0,0\n1,0,0,x,0,0,0\n"
    with pytest.raises(InputError, match="line 6, column z_m"):
        Trajectory.load(_write(tmp_path / "t.csv", text))


def test_angles_take_the_short_way_between_rows(tmp_path):
    text = "t_s,x_m,y_m,z_m,roll_deg,pitch_deg,yaw_deg\n0,0,0,10,0,0,179\n1,0,0,10,0,0,-179\n"
    traj = Trajectory.load(_write(tmp_path / "t.csv", text))
    assert traj.at(0.5)["yaw_deg"] == pytest.approx(180.0)


def test_a_trajectory_showing_the_target_s_back_is_refused(nexus, pattern):
    traj = Trajectory(np.array([0.0, 5.0]), np.array([[10.0, 0, 0, 0, 170.0, 0], [5.0, 0, 0, 0, 0, 0]]), "target")
    with pytest.raises(InputError, match="back of the target"):
        check_visible(traj, [0.0], nexus, pattern)


def test_frame_rate_limits_the_exposure_and_the_readout():
    """A frame period shorter than the readout or a manual exposure is refused; the auto-exposure's
    longest exposure is cut to the period."""
    with pytest.raises(InputError, match="rolling-shutter readout"):
        ApproachSensor("htc-amaze-4g", frame_rate_hz=40.0)
    s = ApproachSensor("htc-amaze-4g", frame_rate_hz=20.0)
    assert s.phone.params.exposure.max_exposure_s == pytest.approx(0.05)
    assert ApproachSensor("htc-amaze-4g", frame_rate_hz=1.0).phone.params.exposure.max_exposure_s == pytest.approx(0.0667)


def test_a_pose_out_of_view_is_a_dropout_not_an_error(nexus):
    """In a user's loop a target that leaves the field of view gives ok=False, reason out_of_view
    (nothing rendered), and the stream goes on."""
    from svgs_sim.svgs.frames import pose_from_scenario

    s = ApproachSensor("galaxy-nexus")
    R, t = pose_from_scenario(5.0, 20.0, 0.0)  # 20 m to the side at 5 m
    m = s.measure(0.0, R, t)
    assert not m.ok and m.reason == "out_of_view" and m.estimate is None and s.frame_index == 1
    with pytest.raises(InputError, match="image_velocity_px_s"):
        s.measure(1.0, *pose_from_scenario(5.0), image_velocity_px_s=[1.0, 2.0])


def test_missing_trajectory_file(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        Trajectory.load(tmp_path / "nope.csv")


def test_state_file_gives_the_paper_pose_at_its_knots(tmp_path):
    """A paper-state row is the camera's position in the target frame: its pose is
    svgs_sim.svgs.frames.state_to_pose's, whatever the interpolation between knots."""
    from svgs_sim.svgs.frames import state_to_pose

    rows = [(0.0, 0.1, -0.2, 12.0, 2.0, -3.0, 5.0), (4.0, 0.0, 0.05, 6.0, 0.0, 1.0, 0.0)]
    text = "t_s,x_m,y_m,z_m,roll_deg,pitch_deg,yaw_deg\n" + "".join(",".join(map(str, r)) + "\n" for r in rows)
    traj = Trajectory.load(_write(tmp_path / "s.csv", text))
    assert traj.mount == "target"
    for r in rows:
        R, t = traj.scenario(r[0], Scenario()).pose()
        R0, t0 = state_to_pose(np.array([*r[1:4], *np.deg2rad(r[4:7])]))
        np.testing.assert_allclose(R, R0, atol=1e-12)
        np.testing.assert_allclose(t, t0, atol=1e-12)


def test_stand_file_uses_the_test_stand_chain(tmp_path):
    from svgs_sim.sim.stand import TestStand

    text = "t_s,rail_m,stage_m,roll_deg,pitch_deg,yaw_deg\n0,10,0.1,0,5,-10\n2,8,0,0,0,0\n"
    traj = Trajectory.load(_write(tmp_path / "s.csv", text))
    assert traj.mount == "stand"
    R, t = traj.scenario(0.0, Scenario()).pose()
    R0, t0 = TestStand().pose(10.0, stage_m=0.1, roll_deg=0.0, pitch_deg=5.0, yaw_deg=-10.0)
    np.testing.assert_allclose(R, R0)
    np.testing.assert_allclose(t, t0)
    mid = traj.at(1.0)
    assert mid["rail_m"] == pytest.approx(9.0) and mid["yaw_deg"] == pytest.approx(-5.0)


def test_scenario_from_pose_round_trips(nexus):
    from svgs_sim.svgs.frames import pose_from_scenario

    R, t = pose_from_scenario(7.0, 0.2, -0.3, 4.0, -6.0, 20.0)
    sc = scenario_from_pose(R, t, Scenario())
    R2, t2 = sc.pose()
    np.testing.assert_allclose(R2, R, atol=1e-12)
    np.testing.assert_allclose(t2, t, atol=1e-12)


def test_poses_the_camera_cannot_see_are_refused(nexus, pattern):
    traj = Trajectory.straight(10.0, 2.0, 4.0, lateral_m=(6.0, 0.0))  # 6 m off the boresight at 10 m: out of view (5.3 m)
    with pytest.raises(InputError, match=r"at t = 0 s: target\(s\) .* fall outside"):
        check_visible(traj, traj.frame_times(1.0), nexus, pattern)
    check_visible(Trajectory.straight(10.0, 2.0, 4.0), np.arange(5.0), nexus, pattern)


def test_frame_times_and_their_limit():
    traj = Trajectory.straight(20.0, 5.0, 10.0)
    np.testing.assert_allclose(traj.frame_times(1.0), np.arange(11.0))
    with pytest.raises(InputError, match="at most"):
        traj.frame_times(1e5)


# ----------------------------------------------------------------------------- motion (analytic)
def test_global_shutter_smear_is_uniform_about_the_timestamp():
    """A spot moving at v px/s exposed for T s: the samples spread uniformly over v*T about the
    spot's position at the timestamp (mean unchanged, variance (vT)^2/12)."""
    from svgs_sim.camera.rendered import PointFlux

    n = 200000
    pts = PointFlux(np.full(n, 100.0), np.full(n, 50.0), np.ones(n))
    moved = pts.moved(np.array([400.0, -100.0]), 0.01, 0.0, 101, np.random.default_rng(1))
    du, dv = moved.u_px - 100.0, moved.v_px - 50.0
    assert abs(du.mean()) < 4.0 * 4.0 / np.sqrt(12 * n) * 3 and abs(dv.mean()) < 0.01
    assert du.var() == pytest.approx(4.0**2 / 12, rel=0.02) and dv.var() == pytest.approx(1.0**2 / 12, rel=0.02)
    assert du.min() >= -2.0 and du.max() <= 2.0


def test_rolling_shutter_delays_rows_by_the_readout():
    """Zero exposure: a sample on row v is taken (v - (H - 1) / 2) / H * readout after the centre row."""
    from svgs_sim.camera.rendered import PointFlux

    H, readout, vel = 1000, 0.03, 50.0
    rows = np.array([0.0, 499.5, 999.0])
    pts = PointFlux(np.zeros(3), rows, np.ones(3))
    moved = pts.moved(np.array([vel, 0.0]), 0.0, readout, H, np.random.default_rng(0))
    np.testing.assert_allclose(moved.u_px, vel * (rows - 499.5) / H * readout, atol=1e-12)
    np.testing.assert_allclose(moved.v_px, rows)


# ----------------------------------------------------------------------------- preview and exposure
def test_binned_preview_collects_the_photons_of_its_pixels():
    """The preview's pixel gets the light of s^2 picture pixels (same radiance, same lens): the lab
    flux summed over the frame is the same in both streams."""
    from svgs_sim.camera.phone.preview import binned_camera
    from svgs_sim.sim.closed_loop import lab_flux

    full = Camera.load("galaxy-nexus")
    prev = binned_camera(full, 648, 486)
    sc = Scenario(scene=Scene(backdrop_distance_m=None, ambient_radiance_w_m2_sr=0.01))
    a, _ = lab_flux(full, sc)
    b, _ = lab_flux(prev, sc)
    assert b.sum() == pytest.approx(a.sum(), rel=0.01)
    assert b.mean() == pytest.approx(16.0 * a.mean(), rel=0.01)
    with pytest.raises(InputError, match="aspect ratio"):
        binned_camera(full, 640, 640)


def test_binned_preview_takes_its_phone_s_app_threshold(tmp_path):
    """The preview stream is the same phone running the same app: the detector's threshold is the
    phone's (assets/app/svgs-app.toml: 64 for the Galaxy Nexus, 200 for the Amaze), not the default
    for unknown cameras, also after the preview profile went through a file."""
    from svgs_sim.camera.phone.preview import binned_camera
    from svgs_sim.svgs.app import settings
    from svgs_sim.svgs.pipeline import camera_threshold

    img = np.zeros((4, 4), np.uint8)
    for name in ("galaxy-nexus", "htc-amaze-4g"):
        prev = binned_camera(name)
        want = settings().threshold_for(name)
        assert want != settings().threshold_dn
        assert camera_threshold(img, prev) == want
        path = prev.save(tmp_path / f"{prev.name}.toml")
        assert camera_threshold(img, str(path)) == want


def test_stream_auto_exposure_step_response():
    """Linear regime (nothing clips): each step takes ``gain`` of the log error away, so after k
    steps the error is (1 - gain)^k of the start's, whatever the scene."""
    from svgs_sim.camera.phone.isp import AE_STREAM_GAIN, stream_exposure
    from svgs_sim.camera.phone.params import ExposureParams, SensorParams

    sensor = SensorParams()
    exp = ExposureParams(target_level=0.18, min_exposure_s=1e-6, max_exposure_s=10.0, min_iso=100.0, max_iso=100.0)
    c = 3.7  # level per unit exposure product: level = c S
    S_star = 0.18 / c
    for k in (1, 2, 5):
        t, _ = stream_exposure(0.4 * S_star, 100.0, lambda S: c * S, sensor, exp, k)
        assert np.log(t / S_star) == pytest.approx((1 - AE_STREAM_GAIN) ** k * np.log(0.4), rel=1e-9)


def test_stream_auto_exposure_settles_where_the_one_shot_does():
    """The carried-over exposure converges on a static scene to the phone's one-shot solution
    (svgs_sim.camera.phone.isp.ExposureSolver.solve), from a start 8x too long."""
    from svgs_sim.camera.phone.isp import ExposureSolver, exposure_limits, next_exposure, split_exposure
    from svgs_sim.camera.phone.params import ExposureParams, SensorParams

    sensor = SensorParams()
    exp = ExposureParams(metering="mean", target_level=0.18)
    rng = np.random.default_rng(2)
    rate = rng.lognormal(0.0, 1.0, (60, 80)) * 20.0  # fraction of white per second at base ISO
    solver = ExposureSolver(rate, np.full(rate.shape, 1.0 / rate.size))
    S_star = solver.solve(0.18, *exposure_limits(sensor, exp))
    t, iso = split_exposure(8 * S_star, exp, sensor.base_iso)
    for _ in range(30):
        t, iso = next_exposure(t, iso, solver.level(t * iso / sensor.base_iso), sensor, exp)
    assert t * iso / sensor.base_iso == pytest.approx(S_star, rel=1e-3)


# ----------------------------------------------------------------------------- rendered
@pytest.mark.render
def test_sensor_frame_equals_the_isolated_pose_chain(small_camera):
    """Frame 0 of a stream (no motion) is render_scenario + expose_and_solve with the same seeds
    and exposure: the kept renderer, sensor and lab factor change no number."""
    from svgs_sim.sim.closed_loop import expose_and_solve, render_scenario

    traj = Trajectory.straight(6.0, 4.0, 2.0, attitude_deg=(0.0, 3.0, -5.0))
    sensor = ApproachSensor(small_camera, seed=5, motion=False, crlb=False, keep_images=True)
    m0 = sensor.measure_on(traj, 0.0)
    m1 = sensor.measure_on(traj, 1.0)
    rs, ns, _ = sensor.frame_seeds(1)
    sc = traj.scenario(1.0, Scenario(camera=small_camera))
    frame = render_scenario(sc, seed=rs)
    row = expose_and_solve(frame, frame.exposer(), seed=ns, exposure_s=m1.exposure_s, iso=m1.iso, truth="actual")
    np.testing.assert_array_equal(row["_exposure"].image, m1.image)
    assert m0.ok and m1.ok and row["ok"]
    for k, v in row["state"].items():
        assert m1.estimate[k] == pytest.approx(v, abs=1e-12)


@pytest.mark.render
def test_overlapped_render_changes_no_number(small_camera):
    """With the next frame rendered in the background thread (next_t_s), every frame is the
    frame rendered in sequence; a pose that differs from the one prefetched is rendered anew."""
    traj = Trajectory.straight(6.0, 4.0, 2.0, attitude_deg=(0.0, 3.0, -5.0))
    times = [0.0, 0.5, 1.0]
    seq = ApproachSensor(small_camera, seed=5, motion=True, crlb=False, keep_images=True, overlap_render=False)
    ov = ApproachSensor(small_camera, seed=5, motion=True, crlb=False, keep_images=True, overlap_render=True)
    a = [seq.measure_on(traj, t) for t in times]
    b = list(ov.along(traj, times))
    assert not ov.renders.running  # along() closes its thread
    for ma, mb in zip(a, b):
        assert ma.ok and mb.ok
        np.testing.assert_array_equal(ma.image, mb.image)
    # a wrong guess of the next pose: the prefetched render is not used
    wrong = ApproachSensor(small_camera, seed=5, motion=True, crlb=False, keep_images=True, overlap_render=True)
    wrong.measure_on(traj, 0.0, next_t_s=2.0)
    m1 = wrong.measure_on(traj, 0.5)
    wrong.close()
    np.testing.assert_array_equal(m1.image, a[1].image)


@pytest.fixture(scope="module")
def small_auto_camera(tmp_path_factory):
    """The small Galaxy Nexus without its fitted manual exposure: the prior's auto-exposure."""
    path = tmp_path_factory.mktemp("cam") / "nexus-small-auto.toml"
    Camera.load("galaxy-nexus", fitted=False).scaled(648, 486).replace(name="nexus-small-auto", key="nexus-small-auto").save(path)
    return str(path)


@pytest.mark.render
@pytest.mark.parametrize("exposure", ["manual", "auto"])
def test_approach_command_writes_its_outputs_and_resumes(small_camera, small_auto_camera, tmp_path, capsys, exposure):
    """With a manual exposure (the fitted Nexus) and an auto-exposure carried over from frame to
    frame (the prior's): outputs, and a killed run resumed with the same numbers."""
    cam, r0, r1 = (small_camera, "8", "5") if exposure == "manual" else (small_auto_camera, "2.5", "1.5")
    out = tmp_path / "run"
    argv = ["approach", "--camera", cam, "--from", r0, "--to", r1, "--duration", "2", "--fps", "1",
            "--out", str(out), "--json", "--no-progress"]
    if exposure == "auto":  # the auto-exposure lifts the lab to mid-grey: the app's threshold for such a set-up
        argv += ["--threshold", "200"]  # (the Amaze 4G's, assets/app/svgs-app.toml), not the default for others
    assert main(argv) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["frames"] == 3 and s["solved"] >= (2 if exposure == "manual" else 1) and s["run"]["frames_run"] == 3
    assert 0 < s["run"]["wall_per_frame_s"] < s["run"]["wall_s"]  # the frames after the first, by the clock
    rows = _rows(out / "measurements.csv")
    assert [float(r["t_s"]) for r in rows] == [0.0, 1.0, 2.0]
    assert {"true_z_m", "est_z_m", "err_yaw_deg", "crlb_yaw_deg", "ok", "reason", "solve_s"} <= set(rows[0])
    solved = [r for r in rows if r["ok"] == "1"]
    assert all(float(r["crlb_z_m"]) > 0 for r in solved)
    for a, b in zip(rows, rows[1:]):  # each frame takes the settings the previous one left
        assert (a["next_exposure_s"], a["next_iso"]) == (b["exposure_s"], b["iso"])
    if exposure == "auto":
        assert float(rows[0]["metered_level"]) == pytest.approx(0.18, rel=0.02)  # the first frame has settled
    assert (out / "approach.png").stat().st_size > 0 and s["outputs"]["video"] and s["outputs"]["video_codec"]
    import cv2

    cap = cv2.VideoCapture(s["outputs"]["video"])
    assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == 3
    cap.release()
    assert (out / "frames" / "video_image.txt").read_text().strip() == "detector"
    assert "--video-image" not in (out / "report.md").read_text()  # the default is not written out

    # a run killed after frame 1: the rerun makes frame 2 only, with the same numbers (here with
    # --no-video: no picture of it, no video, and the same numbers)
    res = out / "results.csv"
    lines = res.read_text().splitlines(keepends=True)
    res.write_text("".join(lines[:-1]))
    (out / "frames" / "00002.jpg").unlink()
    # pictures of the other image, or pictures asked for without a video: refused before any work
    for extra, message in ((["--video-image", "delivered"], "show the detector image"),
                           (["--no-video", "--video-image", "delivered"], "no pictures with --no-video")):
        assert main(argv + extra) == 2
        assert message in capsys.readouterr().err
        assert not (out / "frames" / "00002.jpg").exists() and len(_rows(res)) == 2
    assert main(argv + ["--no-video"]) == 0
    s2 = json.loads(capsys.readouterr().out)
    assert s2["run"] == {**s2["run"], "frames_run": 1, "frames_reused": 2}
    assert not (out / "frames" / "00002.jpg").exists() and s2["outputs"]["video"] is None
    assert not Path(s["outputs"]["video"]).exists()  # the first run's video, of other frames, is gone
    assert "1 of 3 frames run without pictures" in s2["outputs"]["video_codec"]
    rows2 = _rows(out / "measurements.csv")
    timing = {c for c in rows[0] if c.endswith("_s") and c != "t_s" and c not in ("exposure_s", "next_exposure_s")}
    assert [{k: v for k, v in r.items() if k not in timing} for r in rows2] == \
        [{k: v for k, v in r.items() if k not in timing} for r in rows]

    # other parameters into the same folder: refused before any work
    assert main(argv[:-4] + ["--fps", "2", "--out", str(out), "--no-progress"]) == 2
    assert "differ" in capsys.readouterr().err


@pytest.mark.parametrize("extra,message", [
    (["--trajectory", "T", "--from", "5"], "not both"),
    (["--from", "5", "--to", "2"], "needs all three"),
    (["--from", "5", "--to", "2", "--duration", "1", "--lateral", "1"], "--lateral"),
    (["--from", "5", "--to", "2", "--duration", "1", "--fps", "1e6"], "at most"),
    (["--from", "5", "--to", "2", "--duration", "1", "--lateral", "4,0"], "outside"),
    (["--from", "-5", "--to", "2", "--duration", "1"], "--from"),
    (["--from", "5", "--to", "2", "--duration", "0"], "--duration"),
    (["--from", "5", "--to", "2", "--duration", "1", "--fps", "40"], "rolling-shutter readout"),
    (["--from", "5", "--to", "2", "--duration", "1", "--attitude", "0,170,0"], "-90 to 90 deg"),
])
def test_approach_bad_input_exits_2_before_any_work(tmp_path, capsys, extra, message):
    out = tmp_path / "never"
    traj = _write(tmp_path / "T", "t_s,x_m\n0,1\n")
    extra = [traj if a == "T" else a for a in extra]
    fps = [] if "--fps" in extra else ["--fps", "1"]
    assert main(["approach", "--camera", "galaxy-nexus", *extra, *fps, "--out", str(out)]) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_approach_bad_trajectory_file_exits_2(tmp_path, capsys):
    bad = _write(tmp_path / "t.csv", BAD_FILES[6][0])
    out = tmp_path / "never"
    assert main(["approach", "--trajectory", bad, "--fps", "1", "--out", str(out)]) == 2
    assert "increase strictly" in capsys.readouterr().err and not out.exists()


@pytest.mark.render
def test_a_pattern_file_is_solved_with_its_own_geometry(small_camera, tmp_path):
    """A pattern given as a .toml path (not a bundled name) is the one the solver uses."""
    from svgs_sim.base.profiles import Pattern
    from svgs_sim.svgs.frames import pose_from_scenario

    src = Pattern.load("svgs-3u").source
    from pathlib import Path

    text = Path(src).read_text().replace('name = "svgs-3u"', 'name = "my-3u"')
    path = _write(tmp_path / "my-3u.toml", text)
    m = ApproachSensor(small_camera, pattern=path, crlb=False).measure(0.0, *pose_from_scenario(6.0, pitch_deg=2.0))
    assert m.ok, m.reason


@pytest.mark.render
@pytest.mark.parametrize("cam", ["small_camera", "small_auto_camera"])
def test_issue40_camera_path_changes_no_number(cam, request, monkeypatch):
    """Issue 40's camera path (the meter without per-pixel logarithms, the JPEG in bands on two
    threads, the meter and half the bound's derivatives in a background thread) gives every number
    and image of the path before it (the reference, run with those switched off)."""
    from svgs_sim.camera.phone import isp

    camera = request.getfixturevalue(cam)
    traj = Trajectory.straight(6.0, 4.0, 2.0, attitude_deg=(0.0, 3.0, -5.0))
    times = [0.0, 0.7, 1.4]
    monkeypatch.setattr(isp, "JPEG_BAND_MIN_ROWS", 64)  # the small frame coded in bands too
    new = ApproachSensor(camera, seed=9, motion=True, keep_images=True)
    a = [new.measure_on(traj, t) for t in times]
    new.close()
    monkeypatch.setattr(isp, "JPEG_BAND_MIN_ROWS", 1 << 30)
    monkeypatch.setattr(isp.ExposureSolver, "_build_f32", lambda self, *args: False)
    old = ApproachSensor(camera, seed=9, motion=True, keep_images=True, overlap_camera=False)
    b = [old.measure_on(traj, t) for t in times]
    assert cam != "small_camera" or any(m.crlb_std is not None for m in a)  # a solved frame with its bound
    for ma, mb in zip(a, b):
        np.testing.assert_array_equal(ma.image, mb.image)
        ra, rb = ma.row(), mb.row()
        assert {k: v for k, v in ra.items() if not k.endswith("_s") or k in ("t_s", "exposure_s", "next_exposure_s")} \
            == {k: v for k, v in rb.items() if not k.endswith("_s") or k in ("t_s", "exposure_s", "next_exposure_s")}


def test_the_video_image_of_stored_pictures_binds_a_rerun(tmp_path):
    """The pictures stored say which image a continued run must show: the record, or for pictures
    from before the choice existed (no record) the delivered image; a record without pictures (a
    run stopped before its first picture) binds nothing. A finished run is checked too (its
    report's command must say what its pictures show), without writing a record."""
    from svgs_sim.base.errors import InputError
    from svgs_sim.studies.approach import VIDEO_IMAGE_FILE, _check_video_image

    frames = tmp_path / "frames"
    frames.mkdir()
    _check_video_image(frames, "detector", record=False)
    assert not (frames / VIDEO_IMAGE_FILE).exists()
    _check_video_image(frames, "detector")
    _check_video_image(frames, "delivered")  # no picture yet: the record is replaced
    assert (frames / VIDEO_IMAGE_FILE).read_text().strip() == "delivered"
    (frames / "00000.jpg").write_bytes(b"x")
    with pytest.raises(InputError, match="show the delivered image"):
        _check_video_image(frames, "detector", record=False)
    (frames / VIDEO_IMAGE_FILE).unlink()  # pictures of an older run: the delivered image
    with pytest.raises(InputError, match="continue with --video-image delivered"):
        _check_video_image(frames, "detector")
    _check_video_image(frames, "delivered")


@pytest.mark.parametrize("dtype,threshold,black", [(np.uint8, 64.5, 64.0), (np.uint8, 64.0, 64.0),
                                                   (np.float32, 64.5, 64.5)])
def test_the_detector_picture_shows_what_the_detector_keeps(dtype, threshold, black, monkeypatch):
    """A video frame of the detector's image: black up to the threshold (its floor for an integer
    image, the level itself for a float one, as the detector compares), every pixel the detector
    keeps (strictly above the level, :func:`svgs_sim.svgs.detect.detect_blobs`) shown."""
    from types import SimpleNamespace

    from svgs_sim.studies import approach
    from svgs_sim.svgs.detect import detect_blobs

    img = np.zeros((120, 160), dtype)
    img[50:53, 70:73] = np.array([[60, 64, 65], [64.2, 64.8, 70], [200, 90, 63]], dtype)
    m = SimpleNamespace(solution=None, image=None, detect_image=img, threshold_u8=threshold,
                        blobs_px=np.array([[71.0, 51.0]]))
    shown = []
    real = approach.render_overlay

    def spy(image, **kw):
        shown.append(kw["black_level"])
        return real(image, **kw)

    monkeypatch.setattr(approach, "render_overlay", spy)
    pic = approach._overlay(m, None, None, "t")
    assert shown == [black] and pic.shape == approach.VIDEO_SIZE_PX[::-1] + (3,)
    from svgs_sim.svgs.overlay import _display_u8

    disp = _display_u8(img, (60, 40, 90, 65), black)
    kept = detect_blobs(img, threshold=threshold, min_area_px=1, max_eccentricity=1.0, min_roundness=0.0).area_px
    assert int((disp > 0).sum()) == int(np.sum(kept)) == int((img > threshold).sum())
