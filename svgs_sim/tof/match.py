"""Matching observed reflectors to the catalogue (paper section 4).

Deterministic annealing / softassign (Gold & Rangarajan 1996, graduated assignment)
    The assignment of observed reflector ``a`` to catalogue reflector ``i`` is a soft
    matrix ``M_ai``. Its energy is rigid-motion invariant: a pair of assignments
    ``(a -> i, b -> j)`` is compatible when the observed distance ``|q_a - q_b|`` equals the
    catalogue distance ``|p_i - p_j|``,
    ``C_aibj = exp(-(d_ab - D_ij)^2 / (2 s_ab^2))`` (the MRF clique potential), and
    ``Q_ai = sum_bj C_aibj M_bj`` is the support of ``a -> i``. From a high temperature
    (``beta0``) the inverse temperature grows geometrically (``beta *= beta_rate``, the
    paper's cooling schedule) to ``beta_f``; at each temperature a few iterations set
    ``M_ai = exp(beta Q_ai)`` and Sinkhorn-normalise rows and columns of ``M`` augmented by a
    slack row and column (value ``exp(beta alpha)``), which absorb spurious observations and
    missing catalogue reflectors. Optional unary compatibility from the marker sizes
    multiplies ``C``. A Hungarian clean-up (``scipy.optimize.linear_sum_assignment``) turns
    ``M`` into a one-to-one assignment.

Verification
    The assignment is checked by a rigid fit (weighted SVD): pairs whose residual exceeds
    the tolerance are dropped one at a time (worst first), then unassigned observations
    that fall on a predicted catalogue position are added. Fewer than 3 consistent pairs is
    a :class:`svgs_sim.svgs.result.Failure` (``no_consistent_set``).

Parameters follow ``shared/notes/physics.md`` section 6: ``beta0 = 0.5``, ``beta_f = 10``,
``beta_rate = 1.075``; 1 inner iteration of 4 warm-started Sinkhorn iterations per temperature
(G&R use 4 and 30 from scratch; with the Sinkhorn scalings carried from step to step this
suffices - same success on the acceptance trials - and keeps the matcher within the frame
budget); annealing stops early once the assignment is crisp. The
slack value ``alpha = 0.8`` (support of about one fully consistent neighbour) is our choice.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment

from svgs_sim.base.errors import InputError
from svgs_sim.svgs.result import Failure

from .pose import is_degenerate, weighted_svd_pose

DEFAULT_SIGMA_M = 0.005
DEFAULT_SLACK = 0.8
DEFAULT_SIZE_TOL = 0.35


@dataclass
class Match:
    """A verified assignment.

    Attributes
    ----------
    cat_of_obs : ndarray of int, shape (M,)
        Catalogue index of each observation, -1 for outliers.
    obs_index, cat_index : ndarray of int, shape (k,)
        The matched pairs.
    R_cam_target, t_cam_target_m : ndarray
        Rigid fit of the pairs.
    residual_m : ndarray, shape (k,)
    soft : ndarray, shape (M + 1, N + 1)
        The final soft assignment (with slack row/column).
    iterations : int
        Annealing steps (temperatures x inner iterations).
    """

    cat_of_obs: np.ndarray
    obs_index: np.ndarray
    cat_index: np.ndarray
    R_cam_target: np.ndarray
    t_cam_target_m: np.ndarray
    residual_m: np.ndarray
    soft: np.ndarray = field(repr=False)
    iterations: int = 0

    ok = True

    def __bool__(self) -> bool:
        return True

    @property
    def n(self) -> int:
        return int(self.obs_index.size)


def _dist(x):
    return np.linalg.norm(x[:, None, :] - x[None, :, :], axis=-1)


def compatibility(obs_m, cat_m, sigma_m=DEFAULT_SIGMA_M, obs_sigma_m=None, unary=None) -> np.ndarray:
    """Pairwise compatibility ``C[a, i, b, j]``, shape (M, N, M, N).

    Parameters
    ----------
    obs_m : ndarray, shape (M, 3)
    cat_m : ndarray, shape (N, 3)
    sigma_m : float
        Distance tolerance floor.
    obs_sigma_m : ndarray, shape (M,), optional
        Position uncertainty of each observation (adds in quadrature).
    unary : ndarray, shape (M, N), optional
        Unary compatibility in [0, 1] (e.g. from marker sizes).
    """
    do = _dist(obs_m)
    dc = _dist(cat_m)
    M, N = do.shape[0], dc.shape[0]
    s2 = np.full((M, M), float(sigma_m) ** 2)
    if obs_sigma_m is not None:
        os2 = np.asarray(obs_sigma_m, float) ** 2
        s2 = s2 + os2[:, None] + os2[None, :]
    diff = do[:, None, :, None] - dc[None, :, None, :]
    C = np.exp(-diff * diff / (2 * s2[:, None, :, None]))
    C[np.arange(M), :, np.arange(M), :] = 0.0
    C[:, np.arange(N), :, np.arange(N)] = 0.0
    if unary is not None:
        u = np.asarray(unary, float)
        C *= u[:, :, None, None] * u[None, None, :, :]
    return C


def _sinkhorn(k, n_iter, tol, r=None, c=None):
    """Alternate row and column normalisation of ``k`` (M + 1, N + 1) except the slack row
    and column, by scaling vectors (``m = diag(r) k diag(c)``).

    ``r`` and ``c`` (updated in place) warm-start the iteration: between annealing steps the
    matrix changes little, so a few iterations from the previous scalings suffice.

    Returns
    -------
    m : ndarray, shape (M + 1, N + 1)
    """
    M, N = k.shape[0] - 1, k.shape[1] - 1
    kr, kc = k[:M], k[:, :N]
    r = np.ones(M + 1) if r is None else r
    c = np.ones(N + 1) if c is None else c
    for it in range(n_iter):
        r[:M] = 1.0 / (kr @ c + 1e-300)
        c[:N] = 1.0 / (r @ kc + 1e-300)
        if it % 4 == 3 and np.abs(r[:M] * (kr @ c) - 1).max() < tol:
            break
    return k * np.outer(r, c)


def softassign(C, *, slack: float = DEFAULT_SLACK, beta0: float = 0.5, beta_f: float = 10.0, beta_rate: float = 1.075,
               inner_iter: int = 1, sinkhorn_iter: int = 4, sinkhorn_tol: float = 1e-3, inner_tol: float = 1e-3,
               crisp: float = 0.9):
    """Graduated assignment with slack (Gold & Rangarajan 1996).

    Parameters
    ----------
    C : ndarray, shape (M, N, M, N)
        Compatibilities.
    slack : float
        ``alpha``: support an assignment needs to beat the slack.
    beta0, beta_f, beta_rate : float
        Annealing schedule of the inverse temperature.
    inner_iter, sinkhorn_iter : int
        Iterations per temperature and Sinkhorn iterations per step (both stop early on
        ``inner_tol`` / ``sinkhorn_tol``); the Sinkhorn scalings are carried from step to
        step (warm start), so few iterations keep the matrix balanced.
    crisp : float
        Stop annealing once every row and column of the assignment has an entry above this
        (the assignment can no longer change).

    Returns
    -------
    soft : ndarray, shape (M + 1, N + 1)
    steps : int
        Annealing steps taken.

    Notes
    -----
    The support ``Q = C M`` is computed from the real part of ``M`` with each row
    renormalised without its slack share; otherwise mass moving to the slack at high
    temperature starves every support and the assignment collapses into the slack when
    few markers are seen.
    """
    M, N = C.shape[0], C.shape[1]
    C2 = C.reshape(M * N, M * N)
    real = np.full(M * N, 1.0 / N)
    m = np.zeros((M + 1, N + 1))
    k = np.zeros((M + 1, N + 1))
    r = np.ones(M + 1)
    c = np.ones(N + 1)
    beta = float(beta0)
    steps = 0
    while beta <= beta_f:
        for _ in range(inner_iter):
            steps += 1
            Q = C2 @ real
            top = max(Q.max(), slack)
            k[:M, :N] = np.exp(beta * (Q - top)).reshape(M, N)
            es = np.exp(beta * (slack - top))
            k[:M, N] = es
            k[M, :N] = es
            m_new = _sinkhorn(k, sinkhorn_iter, sinkhorn_tol, r, c)
            rm = m_new[:M, :N]
            new_real = (rm / (rm.sum(1, keepdims=True) + 1e-300)).ravel()
            change = np.abs(new_real - real).max()
            real, m = new_real, m_new
            if change < inner_tol:
                break
        if m[:M].max(1).min() > crisp and m[:, :N].max(0).min() > crisp:
            break
        beta *= beta_rate
    return m, steps


def match_points(obs_m, cat_m, *, sigma_m: float = DEFAULT_SIGMA_M, obs_sigma_m=None, obs_size=None, cat_size=None,
                 size_tol: float = DEFAULT_SIZE_TOL, slack: float = DEFAULT_SLACK, min_soft: float = 0.3,
                 verify_tol_m: float | None = None, weights=None, **anneal) -> Match | Failure:
    """Match observed 3-D points (camera frame) to catalogue points (target frame).

    Parameters
    ----------
    obs_m : array_like, shape (M, 3)
        Observed reflector positions, camera frame, metres.
    cat_m : array_like, shape (N, 3)
        Catalogue positions, target frame, metres.
    sigma_m : float
        Distance tolerance floor of the compatibility.
    obs_sigma_m : array_like, shape (M,), optional
        Per-observation position uncertainty.
    obs_size, cat_size : array_like, shapes (M,), (N,), optional
        Marker sizes (e.g. diameters); when both given they add a unary compatibility
        ``exp(-(log(obs / cat))^2 / (2 size_tol^2))``.
    min_soft : float
        Hungarian pairs with a soft assignment below this are dropped.
    verify_tol_m : float, optional
        Residual tolerance of the rigid verification; default ``3 sqrt(sigma_m^2 + obs_sigma^2)``
        plus 2 mm.
    weights : array_like, shape (M,), optional
        Weights for the verification fit.
    **anneal
        Passed to :func:`softassign` (``beta0``, ``beta_f``, ``beta_rate``...).

    Returns
    -------
    Match or Failure
        Failure reasons: ``too_few_blobs`` (fewer than 3 observations), ``no_consistent_set``.
    """
    q = np.asarray(obs_m, float)
    p = np.asarray(cat_m, float)
    if q.ndim != 2 or q.shape[1:] != (3,) or p.ndim != 2 or p.shape[1:] != (3,):
        raise InputError(f"obs_m, cat_m: expected shapes (M, 3) and (N, 3), got {q.shape} and {p.shape}")
    if not (np.all(np.isfinite(q)) and np.all(np.isfinite(p))):
        raise InputError("obs_m, cat_m: points must be finite")
    M, N = q.shape[0], p.shape[0]
    if M < 3:
        return Failure("too_few_blobs", f"{M} reflector(s) observed; at least 3 are needed for a pose",
                       {"n_blobs": int(M)})
    osig = np.zeros(M) if obs_sigma_m is None else np.asarray(obs_sigma_m, float)
    w = np.ones(M) if weights is None else np.asarray(weights, float)
    unary = None
    if obs_size is not None and cat_size is not None:
        os_ = np.asarray(obs_size, float)
        cs = np.asarray(cat_size, float)
        with np.errstate(invalid="ignore", divide="ignore"):
            lr = np.log(os_[:, None] / cs[None, :])
        unary = np.where(np.isfinite(lr), np.exp(-lr * lr / (2 * size_tol**2)), 1.0)
    C = compatibility(q, p, sigma_m, osig, unary)
    soft, steps = softassign(C, slack=slack, **anneal)
    rows, cols = linear_sum_assignment(-soft[:M, :N])
    good = soft[rows, cols] >= min_soft
    a, i = rows[good], cols[good]
    tol = (3 * np.sqrt(sigma_m**2 + osig**2) + 0.002) if verify_tol_m is None else np.full(M, float(verify_tol_m))
    res = _verify(q, p, a, i, w, tol, unary, soft[a, i])
    if res is None:
        return Failure("no_consistent_set", "no subset of 3 or more observed reflectors matches the target geometry",
                       {"n_blobs": int(M), "n_soft_pairs": int(a.size)})
    a, i, R, t, r = res
    cat_of_obs = np.full(M, -1, int)
    cat_of_obs[a] = i
    return Match(cat_of_obs, a, i, R, t, r, soft, steps)


def _fit(q, p, a, i, w):
    if a.size < 3 or is_degenerate(p[i]):
        return None
    R, t = weighted_svd_pose(p[i], q[a], w[a])
    return R, t, np.linalg.norm(q[a] - (p[i] @ R.T + t), axis=1)


def _consistent_pairs(q, p, a, i, tol, score):
    """Drop pairs until all pairwise distances agree (rigid-invariant, no least-squares masking):
    repeatedly remove the pair inconsistent with the most others (lowest score on ties)."""
    if a.size == 0:
        return a, i
    keep = np.ones(a.size, bool)
    do = _dist(q[a])
    dc = _dist(p[i])
    bad = np.abs(do - dc) > (tol[a][:, None] + tol[a][None, :])
    while True:
        cnt = (bad & keep[None, :] & keep[:, None]).sum(1)
        if cnt.max() == 0:
            return a[keep], i[keep]
        worst = np.flatnonzero(cnt == cnt.max())
        k = worst[np.argmin(score[worst])]
        keep[k] = False


def _verify(q, p, a, i, w, tol, unary, score=None):
    """Keep the pairs consistent in their distances, check them by a rigid fit (dropping the
    worst residual while any exceeds the tolerance), then add observations found on the
    predicted positions of unassigned catalogue points."""
    score = np.ones(a.size) if score is None else score
    a, i = _consistent_pairs(q, p, a, i, tol, score)
    while True:
        f = _fit(q, p, a, i, w)
        if f is None:
            return None
        R, t, r = f
        bad = r > tol[a]
        if not bad.any():
            break
        k = int(np.argmax(r / tol[a]))
        a, i = np.delete(a, k), np.delete(i, k)
    # completion: unassigned observations that sit on unassigned catalogue points
    free_o = np.setdiff1d(np.arange(q.shape[0]), a)
    free_c = np.setdiff1d(np.arange(p.shape[0]), i)
    if free_o.size and free_c.size:
        pred = p[free_c] @ R.T + t
        d = np.linalg.norm(q[free_o][:, None, :] - pred[None, :, :], axis=-1)
        ok = d <= tol[free_o][:, None]
        if unary is not None:
            ok &= unary[np.ix_(free_o, free_c)] > 0.05
        if ok.any():
            rr, cc = linear_sum_assignment(np.where(ok, d, 1e9))
            sel = ok[rr, cc]
            if sel.any():
                a = np.concatenate([a, free_o[rr[sel]]])
                i = np.concatenate([i, free_c[cc[sel]]])
                f = _fit(q, p, a, i, w)
                R, t, r = f
    order = np.argsort(i)
    return a[order], i[order], R, t, r[order]
