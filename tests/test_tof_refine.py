"""The paper's line-of-sight iteration (section 5.2) against independent references: an analytic
planar ring (what one step does to the range, where the stopping rule leaves it) and a brute-force
SciPy minimisation of the objective whose minimum is its fixed point."""

import numpy as np
import pytest
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from svgs_sim.svgs.frames import rotation_angle_deg
from svgs_sim.tof.camera import load_target
from svgs_sim.tof.pipeline import PipelineParams
from svgs_sim.tof.pose import REFINE_MAX_ITER, REFINE_TOL_PAPER_M, refine_line_of_sight, weighted_svd_pose
from synth_tof import random_pose


def _ring(r_m, n=8):
    a = 2 * np.pi * np.arange(n) / n
    return np.stack([r_m * np.cos(a), r_m * np.sin(a), np.zeros(n)], 1)


@pytest.mark.parametrize("Z, r, dZ", [(0.7, 0.15, 0.004), (5.7, 0.15, 0.003), (10.0, 0.1, -0.01)])
def test_one_step_moves_the_range_by_the_analytic_fraction(Z, r, dZ):
    """Planar ring of radius r facing the camera at range Z, exact lines of sight, start at the
    right attitude but Z + dZ. Projecting x_i = (r cos a, r sin a, Z + dZ) onto e_i = (r cos a,
    r sin a, Z) / sqrt(r^2 + Z^2) gives depth Z + dZ Z^2 / (r^2 + Z^2) for every point, so the
    SVD's centroid translation keeps the fraction Z^2 / (r^2 + Z^2) of the range error."""
    p = _ring(r)
    x = p + [0, 0, Z]
    e = x / np.linalg.norm(x, axis=1, keepdims=True)
    one = refine_line_of_sight(p, e, np.eye(3), np.array([0, 0, Z + dZ]), method="fixed-point", max_iter=1, tol=0)
    keep = Z**2 / (r**2 + Z**2)
    assert one.t_cam_target_m[2] == pytest.approx(Z + dZ * keep, abs=1e-12)
    assert np.abs(one.t_cam_target_m[:2]).max() < 1e-12
    assert rotation_angle_deg(one.R_cam_target, np.eye(3)) < 1e-9


@pytest.mark.parametrize("Z, dZ", [(0.7, 0.004), (5.7, 0.003)])
def test_the_stopping_rule_leaves_the_range_where_the_geometric_series_says(Z, dZ):
    """Step k changes the range by dZ keep^(k-1) (1 - keep); the iteration stops at the first step
    below the threshold (or at the cap), leaving the error dZ keep^K."""
    r = 0.15
    p = _ring(r)
    x = p + [0, 0, Z]
    e = x / np.linalg.norm(x, axis=1, keepdims=True)
    keep = Z**2 / (r**2 + Z**2)
    tol, cap = REFINE_TOL_PAPER_M, REFINE_MAX_ITER
    steps = abs(dZ) * keep ** np.arange(cap) * (1 - keep)
    K = int(np.argmax(steps < tol)) + 1 if np.any(steps < tol) else cap
    res = refine_line_of_sight(p, e, np.eye(3), np.array([0, 0, Z + dZ]), method="fixed-point", tol=tol, max_iter=cap)
    assert res.iterations == K
    assert res.t_cam_target_m[2] - Z == pytest.approx(dZ * keep**K, rel=1e-9)
    if Z > 5:  # at long range the literal scheme keeps most of the starting (measured) range
        assert abs(res.t_cam_target_m[2] - Z) > 0.5 * abs(dZ)
    else:  # at 0.7 m it converges to the line-of-sight optimum
        assert abs(res.t_cam_target_m[2] - Z) < 0.01 * abs(dZ)


def test_the_converged_fixed_point_is_the_brute_force_minimum():
    """With noisy lines of sight the fixed point (run to convergence) and Gauss-Newton both reach the
    minimum of sum_i w_i |(I - e_i e_i^T)(R p_i + t)|^2 that SciPy's least_squares finds from the truth."""
    target = load_target("tof-8")
    rng = np.random.default_rng(3)
    for _ in range(3):
        R, t = random_pose(rng, range_m=(0.7, 1.5))
        x = target.points_m @ R.T + t
        e = x / np.linalg.norm(x, axis=1, keepdims=True)
        e = e + rng.normal(0, 2e-4, e.shape)  # ~0.06 px of line-of-sight noise at 325 px focal length
        e /= np.linalg.norm(e, axis=1, keepdims=True)
        w = rng.uniform(0.5, 2.0, target.n)
        rho = np.linalg.norm(x, axis=1) + rng.normal(0, 0.005, target.n)
        R0, t0 = weighted_svd_pose(target.points_m, e * rho[:, None], w)

        def resid(v):
            xx = target.points_m @ Rotation.from_rotvec(v[:3]).as_matrix().T + v[3:]
            perp = xx - e * np.einsum("ij,ij->i", e, xx)[:, None]
            return (np.sqrt(w)[:, None] * perp).ravel()

        ref = least_squares(resid, np.concatenate([Rotation.from_matrix(R).as_rotvec(), t]), xtol=1e-15, ftol=1e-15,
                            gtol=1e-15)
        R_ref, t_ref = Rotation.from_rotvec(ref.x[:3]).as_matrix(), ref.x[3:]
        fp = refine_line_of_sight(target.points_m, e, R0, t0, weights=w, method="fixed-point", tol=1e-13,
                                  max_iter=200000)
        gn = refine_line_of_sight(target.points_m, e, R0, t0, weights=w, method="gauss-newton")
        for sol in (fp, gn):
            assert sol.converged
            assert np.abs(sol.t_cam_target_m - t_ref).max() < 1e-8
            assert rotation_angle_deg(sol.R_cam_target, R_ref) < 1e-6


def test_pipeline_default_is_the_literal_iteration_and_the_others_are_options():
    P = PipelineParams()
    assert P.refine_method == "fixed-point" and P.depth_weight == 0.0
    assert P.refine_tol_m == REFINE_TOL_PAPER_M and P.refine_max_iter == REFINE_MAX_ITER
    assert P.replace(refine_method="gauss-newton").refine_method == "gauss-newton"
