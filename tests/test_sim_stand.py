"""The test stand as a kinematic chain (issue 12, item 1): geometry checked against projections
and plain vector algebra, not against the chain's own code."""

import numpy as np
import pytest

from sim.stand import TestStand, sample_in_view, targets_in_view
from svgs.errors import InputError
from svgs.frames import pose_from_scenario, pose_to_state


def _camera_position(R, t):
    return -R.T @ t


def _target_image(camera, R, t):
    return camera.project((t)[None, :])[0]  # the target origin's image


def test_zero_setting_is_the_nominal_pose():
    R, t = TestStand().pose(10.0)
    R0, t0 = pose_from_scenario(10.0)
    assert np.allclose(R, R0) and np.allclose(t, t0)


def test_yaw_about_the_perspective_centre_moves_the_image_by_f_tan_yaw(nexus):
    stand = TestStand(pivot_to_camera_m=(0.0, 0.0, 0.0))
    for yaw in (5.0, -12.0, 20.0):
        R, t = stand.pose(10.0, yaw_deg=yaw)
        u, v = _target_image(nexus, R, t)
        # the boresight turned right by yaw: the target moves left by fx tan(yaw)
        assert u - nexus.cx == pytest.approx(-nexus.fx * np.tan(np.deg2rad(yaw)), abs=1e-6)
        assert v == pytest.approx(nexus.cy, abs=1e-6)
        # the camera did not move; the range to the target origin is unchanged
        assert np.allclose(_camera_position(R, t), _camera_position(*pose_from_scenario(10.0)))
    R, t = stand.pose(10.0, pitch_deg=8.0)
    u, v = _target_image(nexus, R, t)
    assert v - nexus.cy == pytest.approx(nexus.fy * np.tan(np.deg2rad(8.0)), abs=1e-6)  # boresight up: target down
    R, t = stand.pose(10.0, roll_deg=30.0)
    assert np.allclose(_target_image(nexus, R, t), (nexus.cx, nexus.cy))  # roll about the boresight


def test_a_pivot_behind_the_lens_moves_the_camera_on_a_circle():
    d = 0.05
    stand = TestStand(pivot_to_camera_m=(0.0, 0.0, d))
    p0 = _camera_position(*stand.pose(10.0))
    for yaw in (10.0, -30.0):
        p = _camera_position(*stand.pose(10.0, yaw_deg=yaw))
        # the perspective centre stays d from the fixed pivot and moves by the chord 2 d sin(yaw / 2)
        assert np.linalg.norm(p - p0) == pytest.approx(2 * d * np.sin(np.deg2rad(abs(yaw)) / 2), rel=1e-9)


def test_the_stage_moves_along_the_rail():
    stand = TestStand()
    p0 = _camera_position(*stand.pose(10.0))
    p1 = _camera_position(*stand.pose(10.0, stage_m=0.12))
    assert np.linalg.norm(p1) - np.linalg.norm(p0) == pytest.approx(0.12, abs=1e-12)
    assert np.allclose(np.cross(p1, p0), 0.0, atol=1e-12)  # along the same line through the target


def test_misalignment_is_a_constant_rotation_of_the_truth():
    """A 2 deg yaw of the phone in its holder turns every truth attitude by the same 2 deg,
    whatever the gimbal does."""
    plain, tilted = TestStand(), TestStand(misalignment_deg=(2.0, 0.0, 0.0))
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
    # +/-45 deg of yaw exceed the +/-27.9 deg half-field: about 60 % of the uniform draws are lost
    half_fov = np.degrees(np.arctan(nexus.cx / nexus.fx))
    assert half_fov == pytest.approx(27.9, abs=0.1)
    assert 0.3 < info["kept_fraction"] < 0.75
    # with roll, an off-axis target can sit towards a corner: the diagonal half-field bounds the yaw
    half_diag = np.degrees(np.arctan(np.hypot(nexus.cx, nexus.cy) / nexus.fx))
    assert max(abs(x) for x in info["yaw_span_deg"]) < half_diag


def test_bad_stand_input_is_refused(nexus, pattern):
    with pytest.raises(InputError, match="axis_order"):
        TestStand(axis_order="pitch-yaw-roll")
    with pytest.raises(InputError, match="misalignment_deg"):
        TestStand(misalignment_deg=(45.0, 0.0, 0.0))
    with pytest.raises(InputError, match="keep the target in view"):
        sample_in_view(np.random.default_rng(0), nexus, pattern, 10.0, 5,
                       limits_deg={"roll_deg": 0.0, "pitch_deg": 0.0, "yaw_deg": 89.0}, max_draws=5)


def test_scenario_on_the_stand_turns_the_phone():
    from sim.closed_loop import Scenario

    s = Scenario(range_m=10.0, pitch_deg=8.0, yaw_deg=10.0, roll_deg=10.0, mount="stand", stage_m=0.05)
    R, t = s.pose()
    R2, t2 = TestStand().pose(10.0, stage_m=0.05, roll_deg=10.0, pitch_deg=8.0, yaw_deg=10.0)
    assert np.allclose(R, R2) and np.allclose(t, t2)
    with pytest.raises(InputError, match="no lateral stage"):
        Scenario(range_m=10.0, target_x_m=0.2, mount="stand")
    with pytest.raises(InputError, match="only the test stand"):
        Scenario(range_m=10.0, stage_m=0.1)
    with pytest.raises(InputError, match="mount"):
        Scenario(range_m=10.0, mount="tripod")


@pytest.mark.render
def test_render_and_solve_on_the_stand(capsys):
    """The phone turned on the gimbal (the cubes keep facing the rail, so they keep returning
    light) is solved, and the truth is the stand's."""
    import json

    from cli.main import main

    rc = main(["render-and-solve", "--camera", "galaxy-nexus", "--range", "10", "--mount", "stand", "--pitch", "8",
               "--yaw", "10", "--roll", "10", "--json"])
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert rc == 0 and out["ok"] and out["n_blobs"] == 4
    truth = TestStand().state(10.0, roll_deg=10.0, pitch_deg=8.0, yaw_deg=10.0)
    assert out["truth_state"]["z_m"] == pytest.approx(truth[2])
    assert np.abs(out["pos_err_vec_m"]).max() < 0.1 and np.abs(out["att_err_vec_deg"]).max() < 1.0
    assert main(["render-and-solve", "--camera", "galaxy-nexus", "--range", "10", "--mount", "stand", "--x", "0.2"]) == 2
