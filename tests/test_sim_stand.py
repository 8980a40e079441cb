"""The test stand as a kinematic chain (issue 12, item 1): geometry checked against projections
and plain vector algebra, not against the chain's own code."""

import numpy as np
import pytest

from svgs_sim.sim.stand import TestStand, sample_in_view, targets_in_view
from svgs_sim.base.errors import InputError
from svgs_sim.svgs.frames import pose_from_scenario, pose_to_state
from svgs_sim.base.profiles import Pattern


def _camera_position(R, t):
    return -R.T @ t


def _target_image(camera, R, t):
    return camera.project((t)[None, :])[0]  # the target origin's image


def test_zero_setting_is_the_nominal_pose():
    R, t = TestStand().pose(10.0)
    R0, t0 = pose_from_scenario(10.0)
    assert np.allclose(R, R0) and np.allclose(t, t0)


def test_gimbal_angles_about_the_perspective_centre_move_the_image_as_a_pinhole_predicts(nexus):
    """Each gimbal angle alone, the pivot at the perspective centre: pitch (a pan) moves the
    target by fx tan(pitch) sideways, roll (a tilt) by fy tan(roll) vertically, yaw turns the
    image about the boresight; the camera itself does not move."""
    stand = TestStand(pivot_to_camera_m=(0.0, 0.0, 0.0))
    for a in (5.0, -12.0, 20.0):
        R, t = stand.pose(10.0, pitch_deg=a)
        u, v = _target_image(nexus, R, t)
        # the boresight turned left by a: the target moves right by fx tan(a)
        assert u - nexus.cx == pytest.approx(nexus.fx * np.tan(np.deg2rad(a)), abs=1e-6)
        assert v == pytest.approx(nexus.cy, abs=1e-6)
        assert np.allclose(_camera_position(R, t), _camera_position(*pose_from_scenario(10.0)))
        R, t = stand.pose(10.0, roll_deg=a)
        u, v = _target_image(nexus, R, t)
        assert v - nexus.cy == pytest.approx(nexus.fy * np.tan(np.deg2rad(a)), abs=1e-6)  # boresight up: target down
        assert u == pytest.approx(nexus.cx, abs=1e-6)
    # yaw about the boresight: a point off the axis turns about the image centre by the yaw angle
    pat = Pattern.load("svgs-3u")
    uv0 = nexus.project_target(pat.points_m, *stand.pose(10.0))
    uv1 = nexus.project_target(pat.points_m, *stand.pose(10.0, yaw_deg=30.0))
    c = np.array([nexus.cx, nexus.cy])
    off = np.linalg.norm(uv0 - c, axis=1) > 1.0  # the target at the pattern's origin sits on the axis
    assert off.sum() >= 3
    uv0, uv1 = uv0[off], uv1[off]
    a0 = np.arctan2(*(uv0 - c).T[::-1])
    a1 = np.arctan2(*(uv1 - c).T[::-1])
    d = np.degrees(np.angle(np.exp(1j * (a1 - a0))))
    assert np.allclose(np.abs(d), 30.0, atol=1e-6) and np.allclose(d, d[0], atol=1e-6)
    assert np.allclose(np.linalg.norm(uv1 - c, axis=1), np.linalg.norm(uv0 - c, axis=1), atol=1e-6)


def test_each_gimbal_angle_alone_is_the_same_angle_of_the_truth_state():
    """The gimbal is named as the paper names the attitude: roll, pitch, yaw alone give the same
    roll, pitch, yaw of the truth state (svgs_sim.svgs.frames)."""
    stand = TestStand()
    s0 = stand.state(10.0)
    for i, k in enumerate(("roll_deg", "pitch_deg", "yaw_deg")):
        d = np.degrees(stand.state(10.0, **{k: 7.0})[3:] - s0[3:])
        assert d[i] == pytest.approx(7.0, abs=1e-9)
        assert np.allclose(np.delete(d, i), 0.0, atol=1e-9)
        m = [0.0, 0.0, 0.0]
        m[i] = -1.5
        d = np.degrees(TestStand(misalignment_deg=tuple(m)).state(10.0)[3:] - s0[3:])
        assert d[i] == pytest.approx(-1.5, abs=1e-9)


def test_a_pivot_behind_the_lens_moves_the_camera_on_a_circle():
    d = 0.05
    stand = TestStand(pivot_to_camera_m=(0.0, 0.0, d))
    p0 = _camera_position(*stand.pose(10.0))
    for a in (10.0, -30.0):
        p = _camera_position(*stand.pose(10.0, pitch_deg=a))
        # the perspective centre stays d from the fixed pivot and moves by the chord 2 d sin(a / 2)
        assert np.linalg.norm(p - p0) == pytest.approx(2 * d * np.sin(np.deg2rad(abs(a)) / 2), rel=1e-9)


def test_the_stage_moves_along_the_rail():
    stand = TestStand()
    p0 = _camera_position(*stand.pose(10.0))
    p1 = _camera_position(*stand.pose(10.0, stage_m=0.12))
    assert np.linalg.norm(p1) - np.linalg.norm(p0) == pytest.approx(0.12, abs=1e-12)
    assert np.allclose(np.cross(p1, p0), 0.0, atol=1e-12)  # along the same line through the target


def test_misalignment_is_a_constant_rotation_of_the_truth():
    """A 2 deg yaw of the phone in its holder (about its lens axis) turns every truth attitude by
    the same 2 deg, whatever the gimbal does."""
    plain, tilted = TestStand(), TestStand(misalignment_deg=(0.0, 0.0, 2.0))
    for s in ({}, {"yaw_deg": 15.0}, {"pitch_deg": -10.0, "roll_deg": 5.0}):
        Ra, _ = plain.pose(10.0, **s)
        Rb, _ = tilted.pose(10.0, **s)
        ang = np.degrees(np.arccos(np.clip((np.trace(Ra @ Rb.T) - 1) / 2, -1, 1)))
        assert ang == pytest.approx(2.0, abs=1e-9)


def test_truth_states_are_the_papers():
    R, t = TestStand().pose(12.0, yaw_deg=10.0, stage_m=-0.1)
    s = TestStand().state(12.0, yaw_deg=10.0, stage_m=-0.1)
    assert np.allclose(s, pose_to_state(R, t))


def test_draws_keep_the_target_in_view_and_repeat(nexus, pattern):
    a, info = sample_in_view(np.random.default_rng(3), nexus, pattern, 10.0, 40)
    b, _ = sample_in_view(np.random.default_rng(3), nexus, pattern, 10.0, 40)
    assert a == b and len(a) == 40
    stand = TestStand()
    assert all(targets_in_view(nexus, pattern, *stand.pose(10.0, **s)) for s in a)
    # +/-25 deg of roll (a tilt about the horizontal axis) exceed the +/-21.6 deg vertical half-field
    half_v = np.degrees(np.arctan(nexus.cy / nexus.fy))
    assert half_v == pytest.approx(21.6, abs=0.1)
    assert not targets_in_view(nexus, pattern, *stand.pose(10.0, roll_deg=24.0))
    assert targets_in_view(nexus, pattern, *stand.pose(10.0, roll_deg=18.0))
    # ...unless the yaw about the boresight turns that offset towards the wider horizontal field
    assert targets_in_view(nexus, pattern, *stand.pose(10.0, roll_deg=24.0, yaw_deg=40.0))
    assert 0.5 < info["kept_fraction"] < 0.95
    # yaw about the boresight never takes the target out of view
    assert all(targets_in_view(nexus, pattern, *stand.pose(10.0, yaw_deg=y)) for y in (-45.0, 45.0))


def test_bad_stand_input_is_refused(nexus, pattern):
    with pytest.raises(InputError, match="axis_order"):
        TestStand(axis_order="pitch-yaw-roll")
    with pytest.raises(InputError, match="misalignment_deg"):
        TestStand(misalignment_deg=(45.0, 0.0, 0.0))
    with pytest.raises(InputError, match="keep the target in view"):
        sample_in_view(np.random.default_rng(0), nexus, pattern, 10.0, 5,
                       limits_deg={"roll_deg": 0.0, "pitch_deg": 89.0, "yaw_deg": 0.0}, max_draws=5)


def test_scenario_on_the_stand_turns_the_phone():
    from svgs_sim.sim.closed_loop import Scenario

    s = Scenario(rail_m=10.0, pitch_deg=8.0, yaw_deg=10.0, roll_deg=10.0, mount="stand", stage_m=0.05)
    R, t = s.pose()
    R2, t2 = TestStand().pose(10.0, stage_m=0.05, roll_deg=10.0, pitch_deg=8.0, yaw_deg=10.0)
    assert np.allclose(R, R2) and np.allclose(t, t2)
    with pytest.raises(InputError, match="no lateral stage"):
        Scenario(rail_m=10.0, target_x_m=0.2, mount="stand")
    with pytest.raises(InputError, match="only the test stand"):
        Scenario(range_m=10.0, stage_m=0.1)
    with pytest.raises(InputError, match="mount"):
        Scenario(range_m=10.0, mount="tripod")


@pytest.mark.render
def test_render_and_solve_on_the_stand(capsys):
    """The phone turned on the gimbal (the cubes keep facing the rail, so they keep returning
    light) is solved, and the truth is the stand's."""
    import json

    from svgs_sim.cli.main import main

    rc = main(["render-and-solve", "--camera", "galaxy-nexus", "--range", "10", "--mount", "stand", "--pitch", "8",
               "--yaw", "10", "--roll", "10", "--json"])
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert rc == 0 and out["ok"] and out["n_blobs"] == 4
    truth = TestStand().state(10.0, roll_deg=10.0, pitch_deg=8.0, yaw_deg=10.0)
    assert out["truth_state"]["z_m"] == pytest.approx(truth[2])
    # within the paper's own errors at 10 m (Table 4, Galaxy Nexus: mean 0.10 / 0.16 / 0.13 m, 0.7 / 1.0 / 1.8 deg)
    assert np.all(np.abs(out["pos_err_vec_m"]) < [0.2, 0.32, 0.26]), out["pos_err_vec_m"]
    assert np.all(np.abs(out["att_err_vec_deg"]) < [1.4, 2.0, 3.6]), out["att_err_vec_deg"]
    assert main(["render-and-solve", "--camera", "galaxy-nexus", "--range", "10", "--mount", "stand", "--x", "0.2"]) == 2
