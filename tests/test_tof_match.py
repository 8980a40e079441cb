"""Matching by deterministic annealing, weighted SVD pose, line-of-sight refinement."""

import numpy as np
import pytest

from svgs_sim.base.errors import InputError
from svgs_sim.svgs.frames import rotation_angle_deg
from svgs_sim.tof.camera import load_target
from svgs_sim.tof.match import compatibility, match_points, softassign
from svgs_sim.tof.pose import is_degenerate, refine_line_of_sight, weighted_svd_pose
from synth_tof import random_pose, synth_marker_points


@pytest.fixture(scope="module")
def target():
    return load_target("tof-8")


@pytest.mark.slow
def test_matching_acceptance_1000_trials(target):
    """Acceptance: noise-free 3-D marker sets with 0-2 missing and 0-4 spurious points, random
    poses (0.7-6 m, +-25 deg tilt, any roll): the assignment is exactly right (every inlier to
    its marker, every spurious point rejected) in >= 99 % of 1,000 trials."""
    rng = np.random.default_rng(20240607)
    n, ok = 1000, 0
    for _ in range(n):
        R, t = random_pose(rng)
        obs, truth = synth_marker_points(target.points_m, R, t, n_missing=int(rng.integers(0, 3)),
                                         n_spurious=int(rng.integers(0, 5)), rng=rng)
        m = match_points(obs, target.points_m)
        ok += bool(m) and np.array_equal(m.cat_of_obs, truth)
    assert ok / n >= 0.99, f"matching correct in {ok} of {n} trials"


def test_matching_with_depth_noise_and_sizes(target):
    """5 mm of 3-D noise: still matched; marker sizes (35 / 80 mm) as a unary cue."""
    rng = np.random.default_rng(5)
    good = 0
    for _ in range(100):
        R, t = random_pose(rng)
        obs, truth = synth_marker_points(target.points_m, R, t, n_missing=1, n_spurious=2, noise_m=0.005, rng=rng)
        size = np.where(truth >= 0, target.diameter_m[np.maximum(truth, 0)], 0.05) * rng.uniform(0.9, 1.1, truth.size)
        m = match_points(obs, target.points_m, obs_sigma_m=np.full(len(obs), 0.007), obs_size=size,
                         cat_size=target.diameter_m)
        good += bool(m) and np.array_equal(m.cat_of_obs[truth >= 0], truth[truth >= 0])
    assert good >= 97


def test_softassign_is_doubly_stochastic_with_slack(target):
    rng = np.random.default_rng(6)
    R, t = random_pose(rng)
    obs, truth = synth_marker_points(target.points_m, R, t, n_missing=2, n_spurious=3, rng=rng)
    soft, steps = softassign(compatibility(obs, target.points_m), sinkhorn_iter=200, crisp=2.0)
    M, N = obs.shape[0], target.n
    np.testing.assert_allclose(soft[:M].sum(1), 1, atol=0.01)
    np.testing.assert_allclose(soft[:, :N].sum(0), 1, atol=0.01)
    inl = np.flatnonzero(truth >= 0)
    assert np.all(soft[inl, truth[inl]] > 0.9)  # the true markers win, crisply
    assert 0 < steps
    m = match_points(obs, target.points_m)
    assert np.array_equal(m.cat_of_obs, truth)  # spurious points end in the slack


def test_too_few_observations_fail_with_a_reason(target):
    m = match_points(target.points_m[:2], target.points_m)
    assert not m and m.reason == "too_few_blobs"
    rng = np.random.default_rng(7)
    junk = rng.uniform(-1, 1, (5, 3)) + [0, 0, 3]
    m = match_points(junk, target.points_m)
    assert not m and m.reason in ("no_consistent_set",)


def test_weighted_svd_is_exact_on_noise_free_points(target):
    """Acceptance: SVD pose exact to 1e-9 on noise-free matched points."""
    rng = np.random.default_rng(8)
    for _ in range(200):
        R, t = random_pose(rng, max_tilt_deg=80)
        q = target.points_m @ R.T + t
        w = rng.uniform(0.1, 10, target.n)
        R2, t2 = weighted_svd_pose(target.points_m, q, w)
        assert np.abs(R2 - R).max() < 1e-9 and np.abs(t2 - t).max() < 1e-9
        assert np.linalg.det(R2) == pytest.approx(1.0)


def test_weighted_svd_never_returns_a_reflection():
    rng = np.random.default_rng(9)
    p = rng.normal(size=(6, 3))
    q = p * [1, 1, -1]  # a mirror image: the best proper rotation, not the reflection
    R, t = weighted_svd_pose(p, q)
    assert np.linalg.det(R) == pytest.approx(1.0)
    # weights matter: a down-weighted outlier barely moves the fit
    R0, t0 = np.eye(3), np.zeros(3)
    q = p.copy()
    q[0] += [0.5, 0, 0]
    w = np.ones(6)
    w[0] = 1e-9
    R1, t1 = weighted_svd_pose(p, q, w)
    assert np.abs(R1 - R0).max() < 1e-8 and np.abs(t1 - t0).max() < 1e-8


def test_svd_rejects_degenerate_input():
    with pytest.raises(InputError, match="non-collinear"):
        weighted_svd_pose(np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0.0]]), np.zeros((3, 3)))
    with pytest.raises(InputError, match="shape"):
        weighted_svd_pose(np.zeros((4, 2)), np.zeros((4, 2)))
    assert is_degenerate(np.zeros((2, 3)))


def test_line_of_sight_refinement_fixes_depth_errors(target):
    """The paper's reprojection iteration: with exact lines of sight and 1 cm depth errors,
    the refined pose is exact; Gauss-Newton and the literal fixed-point iteration agree."""
    rng = np.random.default_rng(10)
    for k in range(10):
        R, t = random_pose(rng, range_m=(0.7, 3.0))
        x = target.points_m @ R.T + t
        e = x / np.linalg.norm(x, axis=1, keepdims=True)
        rho = np.linalg.norm(x, axis=1) + rng.normal(0, 0.01, target.n)
        R0, t0 = weighted_svd_pose(target.points_m, e * rho[:, None])
        assert np.abs(target.points_m @ R0.T + t0 - x).max() > 1e-3  # the SVD pose misplaces the markers
        gn = refine_line_of_sight(target.points_m, e, R0, t0)
        assert gn.converged and gn.iterations < 15
        assert np.abs(gn.t_cam_target_m - t).max() < 1e-9 and rotation_angle_deg(gn.R_cam_target, R) < 1e-7
        if k < 2:  # the literal iteration converges linearly: slow, so only twice
            fp = refine_line_of_sight(target.points_m, e, R0, t0, method="fixed-point", max_iter=20000)
            assert np.abs(fp.t_cam_target_m - t).max() < 1e-6
    # with a depth weight the fixed point blends the ranges back in: both methods agree
    lam = np.full(target.n, 0.2)
    a = refine_line_of_sight(target.points_m, e, R0, t0, slant_range_m=rho, depth_weight=lam)
    b = refine_line_of_sight(target.points_m, e, R0, t0, slant_range_m=rho, depth_weight=lam, method="fixed-point",
                             max_iter=20000, tol=1e-13)
    assert np.abs(a.t_cam_target_m - b.t_cam_target_m).max() < 1e-8
    with pytest.raises(InputError, match="range_m"):
        refine_line_of_sight(target.points_m, e, R0, t0, depth_weight=0.5)
