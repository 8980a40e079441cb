"""svgs_sim.sim.metrics: the one pose-error function, against hand-computed errors."""

import numpy as np
import pytest

from svgs_sim.sim.metrics import ERR_KEYS, POSE_ERROR_KEYS, error_columns, no_pose_errors, pose_errors, state_error


def test_names_say_what_they_are():
    assert POSE_ERROR_KEYS == ("pos_err_vec_m", "att_err_vec_deg", "pos_err_norm_m", "rot_err_deg")
    assert ERR_KEYS == ("err_x_m", "err_y_m", "err_z_m", "err_roll_deg", "err_pitch_deg", "err_yaw_deg")
    assert no_pose_errors() == dict.fromkeys(POSE_ERROR_KEYS)


def test_position_vector_and_norm():
    # a 3-4-12 offset: norm 13 exactly
    e = pose_errors([3.0, 4.0, 22.0, 0.1, -0.2, 0.3], [0.0, 0.0, 10.0, 0.1, -0.2, 0.3])
    assert e["pos_err_vec_m"] == pytest.approx([3.0, 4.0, 12.0])
    assert e["pos_err_norm_m"] == pytest.approx(13.0)
    assert e["att_err_vec_deg"] == pytest.approx([0.0, 0.0, 0.0], abs=1e-12)
    assert e["rot_err_deg"] == pytest.approx(0.0, abs=1e-6)


@pytest.mark.parametrize("axis", [3, 4, 5])
def test_single_axis_rotation_angle_is_the_angle_difference(axis):
    # with the other two angles zero, roll, pitch or yaw alone rotates about one axis:
    # the relative rotation angle is the difference of the angles
    true = np.zeros(6)
    true[2] = 5.0
    est = true.copy()
    est[axis] = np.radians(7.0)
    e = pose_errors(est, true)
    assert e["att_err_vec_deg"][axis - 3] == pytest.approx(7.0)
    assert e["rot_err_deg"] == pytest.approx(7.0)


def test_angles_wrap_across_180():
    d = state_error([0, 0, 1, np.radians(179.0), 0, np.radians(-170.0)],
                    [0, 0, 1, np.radians(-179.0), 0, np.radians(170.0)])
    assert d[3] == pytest.approx(-2.0)
    assert d[5] == pytest.approx(20.0)


def test_flat_columns_match_the_vectors():
    est, true = [0.1, -0.2, 9.7, 0.01, 0.02, -0.03], [0.0, 0.0, 10.0, 0.0, 0.0, 0.0]
    c = error_columns(est, true)
    assert [c[k] for k in ERR_KEYS] == pytest.approx([0.1, -0.2, -0.3, *np.degrees([0.01, 0.02, -0.03])])
    assert c["pos_err_norm_m"] == pytest.approx(np.sqrt(0.01 + 0.04 + 0.09))
