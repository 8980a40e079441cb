import numpy as np
import pytest

from svgs_sim.base.errors import InputError
from svgs_sim.svgs.frames import (
    angles_from_rotation,
    pose_from_scenario,
    pose_to_state,
    rotation_angle_deg,
    rotation_from_angles,
    state_to_pose,
)


def test_angles_roundtrip_and_orthonormal():
    rng = np.random.default_rng(0)
    ang = rng.uniform([-np.pi, -1.5, -np.pi], [np.pi, 1.5, np.pi], (500, 3))
    M = rotation_from_angles(ang[:, 0], ang[:, 1], ang[:, 2])
    np.testing.assert_allclose(M @ np.swapaxes(M, 1, 2), np.broadcast_to(np.eye(3), M.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(M), 1.0, atol=1e-12)
    np.testing.assert_allclose(angles_from_rotation(M), ang, atol=1e-10)


def test_sequence_is_x_then_y_then_z_frame_rotations():
    # A pure roll of +90 deg about x maps the target's +y axis onto the camera's -z axis
    # (photogrammetric passive rotation: p_photo = M p_target).
    M = rotation_from_angles(np.pi / 2, 0.0, 0.0)
    np.testing.assert_allclose(M @ [0, 1, 0], [0, 0, -1], atol=1e-15)
    # M = R3(psi) R2(theta) R1(phi): compare with explicit products
    a, b, c = 0.1, -0.2, 0.3
    M = rotation_from_angles(a, b, c)
    Mx = rotation_from_angles(a, 0, 0)
    My = rotation_from_angles(0, b, 0)
    Mz = rotation_from_angles(0, 0, c)
    np.testing.assert_allclose(M, Mz @ My @ Mx, atol=1e-15)


def test_state_pose_roundtrip():
    rng = np.random.default_rng(1)
    st = np.column_stack([rng.normal(0, 3, (200, 3)), rng.uniform(-1, 1, (200, 3))])
    R, t = state_to_pose(st)
    np.testing.assert_allclose(pose_to_state(R, t), st, atol=1e-12)


def test_nominal_geometry_matches_the_paper():
    """At zero attitude the camera sits on the target's +z axis looking back at it:
    target 1 (+y) appears above the image centre, target 4 (+x) to the right, and
    target 3 (on the boom, +z) is closer to the camera than the plate."""
    R, t = pose_from_scenario(5.0)
    np.testing.assert_allclose(pose_to_state(R, t), [0, 0, 5, 0, 0, 0], atol=1e-12)
    p1 = R @ [0, 0.1375, 0] + t
    p3 = R @ [0, 0, 0.05] + t
    p4 = R @ [0.0875, 0, 0] + t
    assert p1[1] < 0  # OpenCV y down: negative is up
    assert p4[0] > 0
    assert p3[2] < t[2]


def test_scenario_offsets_and_errors():
    R, t = pose_from_scenario(10.0, target_x_m=0.5, target_y_m=0.3, yaw_deg=20)
    # target origin at (x, y, -range) in the paper camera frame = (x, -y, range) in OpenCV
    np.testing.assert_allclose(t, [0.5, -0.3, 10.0])
    with pytest.raises(InputError, match="range_m"):
        pose_from_scenario(-1.0)
    with pytest.raises(InputError, match="roll_deg"):
        pose_from_scenario(1.0, roll_deg=float("nan"))


def test_rotation_angle_small_and_large():
    R = rotation_from_angles(0.0, 0.0, 1e-9)
    assert abs(rotation_angle_deg(R, np.eye(3)) - np.degrees(1e-9)) < 1e-15
    R = rotation_from_angles(0.0, 0.0, 2.0)
    assert abs(rotation_angle_deg(R, np.eye(3)) - np.degrees(2.0)) < 1e-9
