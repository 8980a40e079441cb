"""Collinearity solver: exactness on noise-free data, efficiency (Cramer-Rao), OpenCV agreement."""

import cv2
import numpy as np
import pytest

from conftest import random_envelope_poses
from svgs_sim.svgs import InputError, solve_centroids
from svgs_sim.svgs.frames import pose_from_scenario, pose_to_state, rotation_angle_deg


# ------------------------------------------------------------------ reference model
# The paper-state az/el model in plain numpy, independent of the compiled kernel
# (svgs_sim.svgs._lm_kernel), as the reference its covariance is checked against.
def _rotations_and_derivatives(angles):
    """M = R3(psi) R2(theta) R1(phi) and its derivatives, element by element.

    Parameters
    ----------
    angles : ndarray, shape (N, 3)

    Returns
    -------
    M : list of 3 lists of 3 ndarrays, each shape (N, 1)
        ``M[i][j]``, kept as separate arrays (explicit products beat batched 3x3 matmul).
    dM : list of 3 such matrices
        ``dM[a]`` is dM / d angle_a (a = phi, theta, psi).
    """
    c1, s1 = np.cos(angles[:, 0:1]), np.sin(angles[:, 0:1])
    c2, s2 = np.cos(angles[:, 1:2]), np.sin(angles[:, 1:2])
    c3, s3 = np.cos(angles[:, 2:3]), np.sin(angles[:, 2:3])
    s2c3, s2s3, c2c3, c2s3 = s2 * c3, s2 * s3, c2 * c3, c2 * s3
    z = np.zeros_like(c1)
    M = [
        [c2c3, c1 * s3 + s1 * s2c3, s1 * s3 - c1 * s2c3],
        [-c2s3, c1 * c3 - s1 * s2s3, s1 * c3 + c1 * s2s3],
        [s2, -s1 * c2, c1 * c2],
    ]
    d_phi = [
        [z, -s1 * s3 + c1 * s2c3, c1 * s3 + s1 * s2c3],
        [z, -s1 * c3 - c1 * s2s3, c1 * c3 - s1 * s2s3],
        [z, -c1 * c2, -s1 * c2],
    ]
    d_theta = [
        [-s2c3, s1 * c2c3, -c1 * c2c3],
        [s2s3, -s1 * c2s3, c1 * c2s3],
        [c2, s1 * s2, -c1 * s2],
    ]
    d_psi = [
        [-c2s3, M[1][1], M[1][2]],
        [-c2c3, -M[0][1], -M[0][2]],
        [z, z, z],
    ]
    return M, [d_phi, d_theta, d_psi]


def model_azel(state: np.ndarray, points_m: np.ndarray, with_jacobian: bool = True):
    """Predicted azimuth/elevation and their Jacobian with respect to the state.

    Parameters
    ----------
    state : ndarray, shape (N, 6)
    points_m : ndarray, shape (n, 3)
        Target points in the target frame.

    Returns
    -------
    azel : ndarray, shape (N, n, 2)
    J : ndarray, shape (N, n, 2, 6) (only when ``with_jacobian``)
    vz : ndarray, shape (N, n)
        Depth coordinate in the paper camera frame (negative in front of the camera).
    """
    L = state[:, :3]
    M, dM = _rotations_and_derivatives(state[:, 3:])
    d = points_m[None, :, :] - L[:, None, :]  # (N, n, 3)
    dx_, dy_, dz_ = d[..., 0], d[..., 1], d[..., 2]

    def rot(R):  # R as nested element lists applied to d -> three (N, n) arrays
        return [R[i][0] * dx_ + R[i][1] * dy_ + R[i][2] * dz_ for i in range(3)]

    vx, vy, vz = rot(M)
    rho2 = vx * vx + vz * vz
    r2 = rho2 + vy * vy
    azel = np.empty(d.shape[:2] + (2,))
    azel[..., 0] = np.arctan2(vx, -vz)
    azel[..., 1] = np.arcsin(np.clip(vy / np.sqrt(r2), -1.0, 1.0))
    if not with_jacobian:
        return azel, None, vz
    rho = np.sqrt(rho2)
    a_x, a_z = -vz / rho2, vx / rho2  # dAz/dv (dAz/dvy = 0)
    k = -vy / (r2 * rho)
    e_x, e_y, e_z = vx * k, vy * k + 1.0 / rho, vz * k  # dEl/dv
    J = np.empty(d.shape[:2] + (2, 6))
    for j in range(3):  # dv/dL_j = -M[:, :, j]
        mx, my, mz = -M[0][j], -M[1][j], -M[2][j]
        J[..., 0, j] = a_x * mx + a_z * mz
        J[..., 1, j] = e_x * mx + e_y * my + e_z * mz
    for a in range(3):  # dv/dangle_a = dM_a @ d
        wx, wy, wz = rot(dM[a])
        J[..., 0, 3 + a] = a_x * wx + a_z * wz
        J[..., 1, 3 + a] = e_x * wx + e_y * wy + e_z * wz
    return azel, J, vz


def test_noise_free_envelope_10000_poses(nexus, pattern):
    """Every pose of 10,000 over the envelope is recovered to < 1e-6 deg and < 1e-6 m."""
    R, t = random_envelope_poses(10_000, seed=11)
    uv = nexus.project_target(pattern.points_m, R, t)
    assert nexus.in_image(uv).all()
    b = solve_centroids(uv, nexus, pattern)
    assert b.ok.all(), f"failed frames: {np.flatnonzero(~b.ok)[:10]}"
    rot_err = rotation_angle_deg(b.R_cam_target, R)
    pos_err = np.linalg.norm(b.t_cam_target_m - t, axis=1)
    assert rot_err.max() < 1e-6, rot_err.max()
    assert pos_err.max() < 1e-6, pos_err.max()
    assert b.residual_rms_px.max() < 1e-6


def test_noise_free_with_distortion(nexus, pattern):
    cam = nexus.replace(dist=np.array([0.09, -0.2, 4e-4, -2e-4, 0.1]))
    R, t = random_envelope_poses(2000, seed=12)
    uv = cam.project_target(pattern.points_m, R, t)
    b = solve_centroids(uv, cam, pattern)
    assert b.ok.all()
    assert rotation_angle_deg(b.R_cam_target, R).max() < 1e-6
    assert np.abs(b.t_cam_target_m - t).max() < 1e-6


def test_agrees_with_opencv_ap3p_refinelm(nexus, pattern):
    """Noise-free: same pose as OpenCV's AP3P + solvePnPRefineLM; noisy: the two minimise
    almost the same cost (pixel versus whitened az/el residuals), so they agree to a small
    fraction of the Cramer-Rao sigma."""
    R, t = random_envelope_poses(200, seed=13)
    uv = nexus.project_target(pattern.points_m, R, t)
    rng = np.random.default_rng(14)
    noisy = uv + rng.normal(0, 0.3, uv.shape)
    for pts, tol_frac in ((uv, None), (noisy, 0.05)):
        b = solve_centroids(pts, nexus, pattern, sigma_px=0.3)
        assert b.ok.all()
        for k in range(len(pts)):
            ok, rv, tv = cv2.solvePnP(pattern.points_m, pts[k], nexus.K, nexus.dist, flags=cv2.SOLVEPNP_AP3P)
            assert ok
            rv, tv = cv2.solvePnPRefineLM(pattern.points_m, pts[k], nexus.K, nexus.dist, rv, tv)
            R_cv = cv2.Rodrigues(rv)[0]
            if tol_frac is None:
                assert rotation_angle_deg(R_cv, b.R_cam_target[k]) < 1e-6
                assert np.abs(tv[:, 0] - b.t_cam_target_m[k]).max() < 1e-6
            else:
                d_state = pose_to_state(R_cv, tv[:, 0]) - b.state[k]
                sd = np.sqrt(np.diag(b.covariance[k]))
                assert np.all(np.abs(d_state) < tol_frac * sd), np.abs(d_state) / sd


@pytest.mark.parametrize("range_m, sigma_px", [(3.0, 0.05), (10.0, 0.2), (20.0, 0.5), (30.0, 0.3)])
def test_monte_carlo_covariance_matches_crlb(nexus, pattern, range_m, sigma_px):
    """The solver is efficient: the Monte Carlo covariance of 6000 noisy solves matches its
    predicted covariance (the Cramer-Rao bound) within 10 % per component (variance)."""
    R, t = pose_from_scenario(range_m, 0.06 * range_m, -0.04 * range_m, 12, -18, 30)
    truth = pose_to_state(R, t)
    uv = nexus.project_target(pattern.points_m, R, t)
    rng = np.random.default_rng(int(range_m * 100))
    n = 6000
    b = solve_centroids(uv[None] + rng.normal(0, sigma_px, (n, 4, 2)), nexus, pattern, sigma_px=sigma_px)
    assert b.ok.all()
    err = b.state - truth
    var_mc = err.var(0)
    var_crlb = np.diag(solve_centroids(uv, nexus, pattern, sigma_px=sigma_px).covariance)
    ratio = var_mc / var_crlb
    print(f"range {range_m} m sigma {sigma_px} px: var ratio MC/CRLB = {np.round(ratio, 3)}")
    assert np.all(np.abs(ratio - 1) < 0.10), ratio
    # the full matrix too: correlation structure agrees
    c_mc = np.cov(err.T)
    c_cr = solve_centroids(uv, nexus, pattern, sigma_px=sigma_px).covariance
    corr = lambda c: c / np.sqrt(np.outer(np.diag(c), np.diag(c)))  # noqa: E731
    assert np.abs(corr(c_mc) - corr(c_cr)).max() < 0.05


def test_single_frame_result_and_batch_agree(nexus, pattern):
    R, t = pose_from_scenario(7.0, 0.3, 0.2, 5, -5, 10)
    uv = nexus.project_target(pattern.points_m, R, t)
    s = solve_centroids(uv, nexus, pattern)
    assert s and s.ok
    b = solve_centroids(uv[None], nexus, pattern)
    np.testing.assert_allclose(s.state, b.state[0])
    assert set(s.targets_px) == {1, 2, 3, 4}
    d = s.to_json()
    assert d["state"]["z_m"] == pytest.approx(7.0, abs=0.2)
    assert d["ok"] is True


def test_points_that_are_not_the_pattern_fail_with_reason(nexus, pattern):
    rng = np.random.default_rng(5)
    R, t = pose_from_scenario(7.0)
    uv = nexus.project_target(pattern.points_m, R, t)
    uv = uv[[1, 0, 2, 3]]  # targets 1 and 2 swapped: a mirror image of the pattern
    res = solve_centroids(uv + rng.normal(0, 0.01, uv.shape), nexus, pattern)
    assert not res
    assert res.reason in ("diverged", "behind_camera", "behind_target")
    assert res.message


@pytest.mark.parametrize(
    "pts, match",
    [
        (np.zeros((3, 2)), "expected shape"),
        (np.full((4, 2), np.nan), "non-finite"),
        (np.array([[1.0, 1], [1, 1], [5, 5], [9, 1]]), "degenerate"),
        (np.array([[0.0, 0], [1, 1], [2, 2], [3, 3]]), "degenerate"),
        ("abc", "expected"),
    ],
)
def test_bad_points(nexus, pattern, pts, match):
    with pytest.raises(InputError, match=match):
        solve_centroids(pts, nexus, pattern)


def test_kernel_covariance_equals_analytic_paper_state_crlb(nexus, pattern):
    """The covariance the compiled kernel reports (iteration parameters mapped to the paper's
    state) equals (J^T Sigma^-1 J)^-1 built from the analytic paper-state Jacobian."""
    from svgs_sim.svgs.solver import azel_pixel_jacobian

    for range_m in (2.0, 15.0, 35.0):
        R, t = pose_from_scenario(range_m, 0.1 * range_m, 0.05 * range_m, -20, 15, 40)
        uv = nexus.project_target(pattern.points_m, R, t)
        sol = solve_centroids(uv, nexus, pattern, sigma_px=0.25)
        _, J, _ = model_azel(sol.state[None], pattern.points_m)
        Winv = np.linalg.inv(azel_pixel_jacobian(uv, nexus))
        Jw = (Winv @ J[0]).reshape(-1, 6)
        cov = np.linalg.inv(Jw.T @ Jw) * 0.25**2
        np.testing.assert_allclose(sol.covariance, cov, rtol=1e-5, atol=1e-12 * np.abs(cov).max())


def test_model_jacobian_matches_finite_differences(pattern):
    x = np.array([[0.3, -0.2, 5.0, 0.2, -0.3, 0.5]])
    _, J, _ = model_azel(x, pattern.points_m)
    Jn = np.zeros_like(J)
    for p in range(6):
        e = np.zeros(6)
        e[p] = 1e-6
        Jn[..., p] = (model_azel(x + e, pattern.points_m, False)[0] - model_azel(x - e, pattern.points_m, False)[0]) / 2e-6
    np.testing.assert_allclose(J, Jn, atol=1e-8)


def test_the_compiled_measurements_match_the_profile_undistortion_and_finite_differences():
    """Issue 14 item 9: the measurements kernel (undistortion and the analytic whitening
    Jacobian) against the profile's own Newton undistortion and central differences of it."""
    from svgs_sim.base.profiles import Camera
    from svgs_sim.svgs.solver import _measurements, azel_from_normalized

    cam = Camera.load("galaxy-nexus").replace(dist=np.array([0.08, -0.21, 4e-4, -3e-4, 0.12]))
    rng = np.random.default_rng(4)
    pts = rng.uniform([50, 50], [cam.width - 50, cam.height - 50], (3, 4, 2))
    xy, meas, W = _measurements(pts, cam)
    np.testing.assert_allclose(xy, cam.pixels_to_normalized(pts), atol=1e-13)
    np.testing.assert_allclose(meas, azel_from_normalized(cam.pixels_to_normalized(pts)), atol=1e-13)
    h = 1e-3
    G = np.stack([(azel_from_normalized(cam.pixels_to_normalized(pts + e)) - azel_from_normalized(
        cam.pixels_to_normalized(pts - e))) / (2 * h) for e in (np.array([h, 0.0]), np.array([0.0, h]))], -1)
    np.testing.assert_allclose(np.linalg.inv(W), G, rtol=1e-6, atol=1e-12)


def test_one_frame_and_the_same_frame_in_a_batch_give_the_same_pose(nexus, pattern):
    """The single-frame short path (issue 14 item 9) and the batch path agree."""
    from svgs_sim.svgs.frames import pose_from_scenario

    rng = np.random.default_rng(9)
    for k in range(20):
        R, t = pose_from_scenario(rng.uniform(3, 40), rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5),
                                  *rng.uniform(-20, 20, 3))
        uv = nexus.project_target(pattern.points_m, R, t) + rng.normal(0, 0.1, (4, 2))
        one = solve_centroids(uv, nexus, pattern)
        many = solve_centroids(uv[None], nexus, pattern)
        assert bool(one) == bool(many.ok[0])
        if one:
            np.testing.assert_allclose(one.state, many.state[0], rtol=1e-12, atol=1e-12)
            np.testing.assert_allclose(one.covariance, many.covariance[0], rtol=1e-10, atol=1e-18)
            assert one.iterations == many.iterations[0]
