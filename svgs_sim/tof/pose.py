"""Pose from matched 3-D points (paper section 5).

Weighted SVD (paper eqs. 38-46, Kabsch/Umeyama without scale)
    ``min_{R,t} sum_i w_i |q_i - (R p_i + t)|^2`` over rotations (``det R = +1``): centre both
    sets on their weighted centroids, ``H = sum_i w_i (p_i - p_bar)(q_i - q_bar)^T = U S V^T``,
    ``R = V diag(1, 1, det(V U^T)) U^T`` (the diagonal sign forbids reflections),
    ``t = q_bar - R p_bar``.

Line-of-sight refinement (paper section 5.2)
    The centroid gives the line of sight ``e_i`` much more precisely than the depth gives
    the range. Each iteration replaces the measurements by the current pose's expected
    points moved onto the observed lines of sight, ``q_i = e_i e_i^T (R_k p_i + t_k)``, and
    solves the SVD again, until the pose changes by less than a tolerance. This is the
    paper's scheme. With ``depth_weight = 0`` its fixed point is the object-space collinearity
    optimum, whose range comes from the pattern's apparent size; but with the SVD's centroid
    translation one step moves the range only by ~(r / Z)^2 of the way there (pattern radius r,
    range Z: a ring keeps exactly ``Z^2 / (r^2 + Z^2)`` of a range error), so stopped by a
    change threshold at long range it keeps most of the starting (measured) range. The
    pipeline's default is this literal iteration (``REFINE_TOL_PAPER_M``, ``REFINE_MAX_ITER``);
    ``method="gauss-newton"`` reaches the optimum itself. ``depth_weight`` lambda_i blends the
    measured range back in, ``q_i = e_i [(1 - l_i) e_i^T (R_k p_i + t_k) + l_i rho_i]``;
    the fixed point is then the minimum of ``sum_i w_i (|P_perp x_i|^2 + l_i (e_i^T x_i - rho_i)^2)``,
    i.e. maximum likelihood with ``l_i = sigma_perp_i^2 / sigma_rho_i^2`` and
    ``w_i = 1 / sigma_perp_i^2``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from svgs_sim.base.errors import InputError

#: Default convergence tolerances (metres, radians) and iteration cap of the refinement.
REFINE_TOL = 1e-10
REFINE_MAX_ITER = 500
#: Stopping threshold of the paper's literal fixed-point iteration (pipeline default; see docs/tof.md).
REFINE_TOL_PAPER_M = 1e-6


def _check_points(p, name, n=None):
    p = np.asarray(p, float)
    if p.ndim != 2 or p.shape[1] != 3:
        raise InputError(f"{name}: expected shape (N, 3), got {p.shape}")
    if n is not None and p.shape[0] != n:
        raise InputError(f"{name}: expected {n} points, got {p.shape[0]}")
    if not np.all(np.isfinite(p)):
        raise InputError(f"{name}: points must be finite")
    return p


def is_degenerate(points_m, weights=None, rel_tol: float = 1e-6) -> bool:
    """True if fewer than 3 points (with positive weight) or all (nearly) collinear."""
    p = np.asarray(points_m, float)
    if weights is not None:
        p = p[np.asarray(weights) > 0]
    if p.shape[0] < 3:
        return True
    s = np.linalg.svd(p - p.mean(0), compute_uv=False)
    return bool(s[1] <= rel_tol * max(s[0], 1e-300))


def weighted_svd_pose(points_target_m, points_cam_m, weights=None) -> tuple[np.ndarray, np.ndarray]:
    """Rigid transform ``q = R p + t`` by weighted SVD, no reflections.

    Parameters
    ----------
    points_target_m : array_like, shape (N, 3)
        Catalogue points ``p_i`` (target frame).
    points_cam_m : array_like, shape (N, 3)
        Measured points ``q_i`` (camera frame).
    weights : array_like, shape (N,), optional
        Non-negative weights (default 1).

    Returns
    -------
    R_cam_target : ndarray, shape (3, 3)
    t_cam_target_m : ndarray, shape (3,)

    Raises
    ------
    InputError
        Bad shapes, non-finite values, fewer than 3 weighted points or collinear points.
    """
    p = _check_points(points_target_m, "points_target_m")
    q = _check_points(points_cam_m, "points_cam_m", p.shape[0])
    w = np.ones(p.shape[0]) if weights is None else np.asarray(weights, float)
    if w.shape != (p.shape[0],) or not np.all(np.isfinite(w)) or np.any(w < 0):
        raise InputError(f"weights: expected {p.shape[0]} finite non-negative weights")
    if is_degenerate(p, w):
        raise InputError("points_target_m: need at least 3 non-collinear points with positive weight")
    return _kabsch(p, q, w)


def _kabsch(p, q, w) -> tuple[np.ndarray, np.ndarray]:
    """:func:`weighted_svd_pose` without the input checks (the refinement's inner loop)."""
    w = w / w.sum()
    pb, qb = w @ p, w @ q
    H = (p - pb).T @ ((q - qb) * w[:, None])
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0
    R = Vt.T @ np.diag([1.0, 1.0, d]) @ U.T
    return R, qb - R @ pb


@dataclass
class Refinement:
    """Result of :func:`refine_line_of_sight`.

    Attributes
    ----------
    R_cam_target : ndarray, shape (3, 3)
    t_cam_target_m : ndarray, shape (3,)
    iterations : int
    converged : bool
    """

    R_cam_target: np.ndarray
    t_cam_target_m: np.ndarray
    iterations: int
    converged: bool


def _rotvec_to_matrix(w):
    th = np.linalg.norm(w)
    if th < 1e-300:
        return np.eye(3)
    k = w / th
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(th) * K + (1 - np.cos(th)) * (K @ K)


def refine_line_of_sight(points_target_m, los_cam, R0, t0, *, weights=None, slant_range_m=None, depth_weight=0.0,
                         method: str = "gauss-newton", tol: float = REFINE_TOL,
                         max_iter: int | None = None) -> Refinement:
    """Iterative line-of-sight reprojection refinement (paper section 5.2).

    Parameters
    ----------
    points_target_m : array_like, shape (N, 3)
    los_cam : array_like, shape (N, 3)
        Observed unit lines of sight ``e_i`` (camera frame).
    R0, t0 : array_like, shapes (3, 3), (3,)
        Starting pose (the SVD solution).
    weights : array_like, shape (N,), optional
    slant_range_m : array_like, shape (N,), optional
        Measured slant ranges ``rho_i`` along the lines of sight (needed when ``depth_weight > 0``).
    depth_weight : float or array_like, shape (N,)
        ``lambda_i`` in [0, 1]; 0 is the paper's scheme.
    method : {"gauss-newton", "fixed-point"}
        ``"fixed-point"`` iterates the paper's reprojection + SVD literally (linear
        convergence, slow at long range where the depth direction is weakly constrained);
        ``"gauss-newton"`` minimises the same objective (module notes) with Gauss-Newton
        steps on the rotation vector and translation, reaching the same fixed point in a few
        iterations.
    tol : float
        Stop when the translation changes by less than ``tol`` metres and the rotation by
        less than ``tol`` radians.
    max_iter : int, optional
        Default 50 (Gauss-Newton) or 500 (fixed point).

    Returns
    -------
    Refinement
    """
    p = _check_points(points_target_m, "points_target_m")
    e = _check_points(los_cam, "los_cam", p.shape[0])
    e = e / np.linalg.norm(e, axis=1, keepdims=True)
    n = p.shape[0]
    lam = np.broadcast_to(np.asarray(depth_weight, float), (n,))
    if np.any(lam < 0) or np.any(lam > 1):
        raise InputError("depth_weight: expected values in [0, 1]")
    if np.any(lam > 0):
        if slant_range_m is None:
            raise InputError("slant_range_m: needed when depth_weight > 0")
        rho = np.asarray(slant_range_m, float)
    else:
        rho = np.zeros(n)
    w = np.ones(n) if weights is None else np.asarray(weights, float)
    if method not in ("gauss-newton", "fixed-point"):
        raise InputError(f"method: expected 'gauss-newton' or 'fixed-point', got {method!r}")
    R, t = np.asarray(R0, float), np.asarray(t0, float)
    converged = False
    it = 0
    if method == "fixed-point":
        weighted_svd_pose(p, p, w)  # the checks (shapes, weights, degeneracy), once
        for it in range(1, (max_iter or REFINE_MAX_ITER) + 1):
            x = p @ R.T + t
            s = np.einsum("ij,ij->i", e, x)
            q = e * ((1 - lam) * s + lam * rho)[:, None]
            R1, t1 = _kabsch(p, q, w)
            dR = np.linalg.norm(R1 - R)
            dt = np.linalg.norm(t1 - t)
            R, t = R1, t1
            if dR < tol and dt < tol:
                converged = True
                break
        return Refinement(R, t, it, converged)
    # Gauss-Newton on r_i = sqrt(w_i) (A_i x_i - sqrt(l_i) rho_i e_i), A_i = I - (1 - sqrt(l_i)) e_i e_i^T
    sl = np.sqrt(lam)
    A = np.eye(3)[None] - (1 - sl)[:, None, None] * np.einsum("ni,nj->nij", e, e)
    sw = np.sqrt(w)[:, None, None]
    b = (sl * rho)[:, None] * e
    for it in range(1, (max_iter or 50) + 1):
        y = p @ R.T  # rotated points
        x = y + t
        r = np.einsum("nij,nj->ni", A, x) - b
        # d x / d(omega) = -[y]_x, d x / d t = I
        J = np.zeros((n, 3, 6))
        J[:, 0, 1], J[:, 0, 2] = y[:, 2], -y[:, 1]
        J[:, 1, 0], J[:, 1, 2] = -y[:, 2], y[:, 0]
        J[:, 2, 0], J[:, 2, 1] = y[:, 1], -y[:, 0]
        J[:, :, 3:] = np.eye(3)
        AJ = sw * np.einsum("nij,njk->nik", A, J)
        rw = sw[:, :, 0] * r
        Hm = np.einsum("nik,nil->kl", AJ, AJ)
        g = np.einsum("nik,ni->k", AJ, rw)
        try:
            delta = -np.linalg.solve(Hm, g)
        except np.linalg.LinAlgError:
            break
        R = _rotvec_to_matrix(delta[:3]) @ R
        t = t + delta[3:]
        if np.linalg.norm(delta[:3]) < tol and np.linalg.norm(delta[3:]) < tol:
            converged = True
            break
    return Refinement(R, t, it, converged)

