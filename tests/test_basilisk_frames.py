"""Basilisk's frames -> the paper's state and back (svgs_sim.sim.basilisk_frames).

References the code did not produce: hand-computed poses and MRPs, and - where the ``basilisk``
extra is installed - Basilisk's own ``RigidBodyKinematics`` and ``orbitalMotion``.
"""

import numpy as np
import pytest

from svgs_sim.base.errors import InputError
from svgs_sim.svgs.frames import rotation_angle_deg

from svgs_sim.sim.basilisk_frames import (
    Mount,
    chaser_from_pose,
    dcm_to_mrp,
    hill_from_inertial,
    inertial_from_hill,
    mrp_to_dcm,
    propagate_body,
    relative_pose,
    relative_state,
)

D = np.diag([1.0, -1.0, -1.0])


def _random_rotations(rng, n):
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    return np.stack([np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
                     np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
                     np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1)], -2)


def test_mrp_of_a_rotation_about_one_axis_by_hand():
    # sigma = e tan(theta/4): theta = 90 deg about z is a frame rotation R3(90 deg)
    C = mrp_to_dcm([0.0, 0.0, np.tan(np.pi / 8)])
    np.testing.assert_allclose(C, [[0, 1, 0], [-1, 0, 0], [0, 0, 1]], atol=1e-15)
    # 180 deg about x: sigma = (1, 0, 0), [BN] = diag(1, -1, -1)
    np.testing.assert_allclose(mrp_to_dcm([1.0, 0.0, 0.0]), D, atol=1e-15)
    # 60 deg about y: R2(60 deg) = [[c, 0, -s], [0, 1, 0], [s, 0, c]]
    c, s = 0.5, np.sqrt(3) / 2
    np.testing.assert_allclose(mrp_to_dcm([0.0, np.tan(np.pi / 12), 0.0]), [[c, 0, -s], [0, 1, 0], [s, 0, c]],
                               atol=1e-15)
    np.testing.assert_allclose(dcm_to_mrp([[c, 0, -s], [0, 1, 0], [s, 0, c]]), [0, np.tan(np.pi / 12), 0], atol=1e-15)


def test_mrp_round_trip_short_set():
    rng = np.random.default_rng(3)
    R = _random_rotations(rng, 400)
    s = dcm_to_mrp(R)
    assert np.all(np.linalg.norm(s, axis=1) <= 1 + 1e-12)
    np.testing.assert_allclose(mrp_to_dcm(s), R, atol=1e-12)


def test_mrp_matches_basilisk():
    rbk = pytest.importorskip("Basilisk.utilities.RigidBodyKinematics", reason="the basilisk extra is not installed")
    rng = np.random.default_rng(4)
    for R in _random_rotations(rng, 50):
        s = dcm_to_mrp(R)
        np.testing.assert_allclose(mrp_to_dcm(s), rbk.MRP2C(s), atol=1e-13)
        np.testing.assert_allclose(s, rbk.C2MRP(R), atol=1e-12)


def test_relative_pose_hand_computed():
    # Target at the origin with N's axes, pattern frame = body frame. The chaser 5 m up +z_N,
    # its camera (= body) turned 180 deg about x, so it looks down -z_N at the pattern.
    ident = Mount()
    R, t = relative_pose([0, 0, 5.0], [1.0, 0, 0], [0, 0, 0], [0, 0, 0], ident, ident)
    np.testing.assert_allclose(R, D, atol=1e-15)
    np.testing.assert_allclose(t, [0, 0, 5.0], atol=1e-15)
    st = relative_state([0, 0, 5.0], [1.0, 0, 0], [0, 0, 0], [0, 0, 0], ident, ident)
    np.testing.assert_allclose([st[k] for k in st], [0, 0, 5, 0, 0, 0], atol=1e-12)
    # The target yawed +90 deg about z_N, the chaser at (1, 0, 5): in the target frame
    # (x_T = y_N, y_T = -x_N) the camera sits at (0, -1, 5), and the paper's yaw is -90 deg.
    st = relative_state([1.0, 0, 5.0], [1.0, 0, 0], [0, 0, 0], [0, 0, np.tan(np.pi / 8)], ident, ident)
    np.testing.assert_allclose([st[k] for k in st], [0, -1, 5, 0, 0, -90], atol=1e-12)


def test_relative_pose_with_mount_offsets_by_hand():
    # The pattern 0.05 m out along the target's -y face, its +z along -y_B (x_T = x_B, y_T = z_B);
    # the camera 0.1 m along the chaser's +y, boresight along +y_B (x_C = x_B, y_C = -z_B).
    pattern = Mount([[1, 0, 0], [0, 0, 1], [0, -1, 0]], [0, -0.05, 0])
    camera = Mount([[1, 0, 0], [0, 0, -1], [0, 1, 0]], [0, 0.1, 0])
    # both bodies with N's axes, the chaser 10 m along -y_N and 0.2 m along +x_N
    R, t = relative_pose([0.2, -10.0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0], camera, pattern)
    # the target's origin is 10 - 0.1 - 0.05 = 9.85 m along the boresight, 0.2 m to the camera's -x
    np.testing.assert_allclose(t, [-0.2, 0, 9.85], atol=1e-14)
    np.testing.assert_allclose(R, D, atol=1e-15)  # zero relative attitude: the paper's camera axes = target axes
    st = relative_state([0.2, -10.0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0], camera, pattern)
    np.testing.assert_allclose([st[k] for k in st], [0.2, 0, 9.85, 0, 0, 0], atol=1e-12)


def test_chaser_from_pose_round_trip():
    rng = np.random.default_rng(5)
    for _ in range(30):
        Rc, Rt = _random_rotations(rng, 2)
        camera = Mount(Rc, rng.normal(0, 0.2, 3))
        pattern = Mount(Rt, rng.normal(0, 0.2, 3))
        r_t = rng.normal(0, 7e6, 3)
        s_t = dcm_to_mrp(_random_rotations(rng, 1)[0])
        r_c = r_t + rng.normal(0, 20, 3)
        s_c = dcm_to_mrp(_random_rotations(rng, 1)[0])
        R, t = relative_pose(r_c, s_c, r_t, s_t, camera, pattern)
        r2, s2 = chaser_from_pose(R, t, r_t, s_t, camera, pattern)
        np.testing.assert_allclose(r2, r_c, atol=1e-8)  # 7000 km positions: 1e-8 m is ~1e-15 relative
        assert rotation_angle_deg(mrp_to_dcm(s2), mrp_to_dcm(s_c)) < 1e-10
        R2, t2 = relative_pose(r2, s2, r_t, s_t, camera, pattern)
        np.testing.assert_allclose(R2, R, atol=1e-12)
        np.testing.assert_allclose(t2, t, atol=1e-8)


def test_hill_round_trip_and_circular_orbit_by_hand():
    mu = 3.986004418e14
    a = 6378137.0 + 400e3
    n = np.sqrt(mu / a**3)
    r_t, v_t = np.array([a, 0, 0]), np.array([0, n * a, 0])
    # a chaser 30 m behind on the same circular orbit: (0, -30, 0) in Hill, at rest there
    th = -30.0 / a
    r_c = a * np.array([np.cos(th), np.sin(th), 0])
    v_c = n * a * np.array([-np.sin(th), np.cos(th), 0])
    rho, rho_dot = hill_from_inertial(r_t, v_t, r_c, v_c)
    np.testing.assert_allclose(rho, [a * (np.cos(th) - 1), -a * np.sin(-th), 0], atol=1e-9)
    np.testing.assert_allclose(rho[1], -30.0, atol=1e-6)
    np.testing.assert_allclose(rho_dot, 0.0, atol=1e-9)
    r2, v2 = inertial_from_hill(r_t, v_t, rho, rho_dot)
    np.testing.assert_allclose(r2, r_c, atol=1e-8)
    np.testing.assert_allclose(v2, v_c, atol=1e-11)


def test_hill_matches_basilisk():
    om = pytest.importorskip("Basilisk.utilities.orbitalMotion", reason="the basilisk extra is not installed")
    rng = np.random.default_rng(6)
    for _ in range(10):
        r_t, v_t = rng.normal(0, 7e6, 3), rng.normal(0, 7e3, 3)
        r_c, v_c = r_t + rng.normal(0, 30, 3), v_t + rng.normal(0, 0.1, 3)
        rho, rd = hill_from_inertial(r_t, v_t, r_c, v_c)
        rho_b, rd_b = om.rv2hill(r_t, v_t, r_c, v_c)
        np.testing.assert_allclose(rho, rho_b, atol=1e-8)
        np.testing.assert_allclose(rd, rd_b, atol=1e-11)


def test_propagate_body_spin_by_hand():
    # spinning at 0.1 rad/s about body z for 2 s: [BN] becomes R3(0.2 rad) [BN]
    r, s = propagate_body([1.0, 2, 3], [0.1, 0, 0.0], [0, 0, 0], [0, 0, 0.1], 2.0)
    np.testing.assert_allclose(r, [1.2, 2, 3.0], atol=1e-15)
    c, si = np.cos(0.2), np.sin(0.2)
    np.testing.assert_allclose(mrp_to_dcm(s), [[c, si, 0], [-si, c, 0], [0, 0, 1]], atol=1e-14)


def test_bad_input_names_the_input():
    with pytest.raises(InputError, match="dcm_frame_body"):
        Mount(np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(InputError, match="origin_body_m"):
        Mount(np.eye(3), [0, np.nan, 0])
    with pytest.raises(InputError, match="sigma_BN"):
        mrp_to_dcm([0.1, 0.2])
