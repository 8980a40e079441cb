"""Compiled Levenberg-Marquardt kernel of the collinearity solver (numba).

One frame at a time, frames in parallel (``prange``). The iteration runs on the target pose
in the camera frame - ``t_cam_target`` and a left rotation increment ``delta``
(``R <- exp([delta]x) R``) - because the paper's state couples attitude and position
through the range lever arm (a curved valley at 30-40 m) while this parametrisation is
nearly linear. Both reach the same minimum; :mod:`svgs_sim.svgs.solver` reports the state and its
Cramer-Rao covariance in the paper's parametrisation.

Measurements are the paper's azimuth/elevation (eqs. 12-13) written in the OpenCV camera
frame: ``Az = atan2(x, z)``, ``El = asin(-y / |v|)``; residuals are whitened by ``W = G^-1``
(``G = d(Az, El)/d(u, v)`` per target), which makes the cost the maximum-likelihood cost
for isotropic Gaussian centroid noise.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..base.distortion import distortion_jacobian, undistort_one


@njit(cache=True, fastmath=False)
def residual_jacobian(R, t, P, meas, W, rw, Jw):
    """Whitened residuals and Jacobian of one frame.

    Parameters
    ----------
    R : (3, 3), t : (3,)
        Target pose in the camera frame.
    P : (n, 3)
        Target points, target frame (m).
    meas : (n, 2)
        Measured Az/El (rad).
    W : (n, 2, 2)
        Whitening matrices (px/rad).
    rw : (2n,) out
        Whitened residual (px), measured minus model.
    Jw : (2n, 6) out
        Whitened Jacobian of the model: columns d/dt (3), d/ddelta (3).

    Returns
    -------
    cost : float
        ``sum(rw**2)`` (px^2).
    """
    n = P.shape[0]
    cost = 0.0
    for i in range(n):
        qx = R[0, 0] * P[i, 0] + R[0, 1] * P[i, 1] + R[0, 2] * P[i, 2]
        qy = R[1, 0] * P[i, 0] + R[1, 1] * P[i, 1] + R[1, 2] * P[i, 2]
        qz = R[2, 0] * P[i, 0] + R[2, 1] * P[i, 1] + R[2, 2] * P[i, 2]
        x, y, z = qx + t[0], qy + t[1], qz + t[2]
        rho2 = x * x + z * z
        r2 = rho2 + y * y
        rho = np.sqrt(rho2)
        az = np.arctan2(x, z)
        s = -y / np.sqrt(r2)
        if s > 1.0:
            s = 1.0
        elif s < -1.0:
            s = -1.0
        el = np.arcsin(s)
        da = meas[i, 0] - az
        da = (da + np.pi) % (2.0 * np.pi) - np.pi
        de = meas[i, 1] - el
        a_x, a_z = z / rho2, -x / rho2
        k = y / (r2 * rho)
        e_x, e_y, e_z = x * k, y * k - 1.0 / rho, z * k
        # rows of d(Az, El)/d(t, delta); dv/ddelta = -[q]x
        ja = (a_x, 0.0, a_z, a_z * qy, a_x * qz - a_z * qx, -a_x * qy)
        je = (e_x, e_y, e_z, -e_y * qz + e_z * qy, e_x * qz - e_z * qx, -e_x * qy + e_y * qx)
        for r in range(2):
            w0, w1 = W[i, r, 0], W[i, r, 1]
            v = w0 * da + w1 * de
            rw[2 * i + r] = v
            cost += v * v
            for p in range(6):
                Jw[2 * i + r, p] = w0 * ja[p] + w1 * je[p]
    return cost


@njit(cache=True)
def _solve6(A, b, lam, out):
    """Solve ``(D^-1 A D^-1 + lam I) (D x) = D^-1 b`` by Cholesky (D = sqrt(diag A)).

    Returns False when the damped, scaled matrix is not positive definite.
    """
    d = np.empty(6)
    for i in range(6):
        d[i] = np.sqrt(A[i, i]) if A[i, i] > 0 else 1.0
    L = np.zeros((6, 6))
    for j in range(6):
        s = A[j, j] / (d[j] * d[j]) + lam
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not s > 0:
            return False
        L[j, j] = np.sqrt(s)
        for i in range(j + 1, 6):
            acc = A[i, j] / (d[i] * d[j])
            for k in range(j):
                acc -= L[i, k] * L[j, k]
            L[i, j] = acc / L[j, j]
    y = np.empty(6)
    for i in range(6):
        acc = b[i] / d[i]
        for j in range(i):
            acc -= L[i, j] * y[j]
        y[i] = acc / L[i, i]
    for i in range(5, -1, -1):
        acc = y[i]
        for j in range(i + 1, 6):
            acc -= L[j, i] * out[j]
        out[i] = acc / L[i, i]
    for i in range(6):
        out[i] /= d[i]
    return True


@njit(cache=True)
def _rotate_left(R, w, out):
    """``out = exp([w]x) @ R`` (Rodrigues), written out: no temporaries, no BLAS."""
    wx, wy, wz = w[0], w[1], w[2]
    th2 = wx * wx + wy * wy + wz * wz
    th = np.sqrt(th2)
    if th < 1e-8:
        a = 1.0 - th2 / 6.0
        b = 0.5 - th2 / 24.0
    else:
        a = np.sin(th) / th
        b = (1.0 - np.cos(th)) / th2
    # E = I + a K + b K^2, K = [w]x, K^2 = w w^T - th2 I
    e00 = 1.0 + b * (wx * wx - th2)
    e11 = 1.0 + b * (wy * wy - th2)
    e22 = 1.0 + b * (wz * wz - th2)
    e01 = -a * wz + b * wx * wy
    e10 = a * wz + b * wx * wy
    e02 = a * wy + b * wx * wz
    e20 = -a * wy + b * wx * wz
    e12 = -a * wx + b * wy * wz
    e21 = a * wx + b * wy * wz
    for j in range(3):
        r0, r1, r2 = R[0, j], R[1, j], R[2, j]
        out[0, j] = e00 * r0 + e01 * r1 + e02 * r2
        out[1, j] = e10 * r0 + e11 * r1 + e12 * r2
        out[2, j] = e20 * r0 + e21 * r1 + e22 * r2


@njit(cache=True)
def paper_state(R, t, out):
    """Paper state ``[X_L, Y_L, Z_L, phi, theta, psi]`` of a pose (see :mod:`svgs_sim.svgs.frames`).

    ``L = -R^T t``; with ``M = diag(1, -1, -1) R``: ``theta = asin(M[2,0])``,
    ``phi = atan2(-M[2,1], M[2,2])``, ``psi = atan2(-M[1,0], M[0,0])``.
    """
    for i in range(3):
        out[i] = -(R[0, i] * t[0] + R[1, i] * t[1] + R[2, i] * t[2])
    s = -R[2, 0]
    if s > 1.0:
        s = 1.0
    elif s < -1.0:
        s = -1.0
    out[4] = np.arcsin(s)
    out[3] = np.arctan2(R[2, 1], -R[2, 2])
    out[5] = np.arctan2(R[1, 0], R[0, 0])


@njit(cache=True)
def covariance_paper(R, t, Jw, out):
    """Unit-noise covariance of the paper state, ``T (Jw^T Jw)^-1 T^T`` (T = dV/dp).

    ``Jw`` is the whitened Jacobian (px per unit of p = (t, delta)); T is the Jacobian of
    the map from the iteration's parameters to the paper's state, by central differences.
    Returns the smallest pivot of the Jacobi-scaled information matrix (0 if singular).

    This function is long (~95 lines) because it is one Numba-compiled kernel: the normal
    matrix, its Cholesky inverse, the central-difference Jacobian and the product run in
    one compiled body on stack-sized 6x6 arrays, which is what the per-frame solver calls;
    its steps are marked by comments.
    """
    m = Jw.shape[0]
    A = np.empty((6, 6))
    for p in range(6):
        for q in range(p, 6):
            acc = 0.0
            for r in range(m):
                acc += Jw[r, p] * Jw[r, q]
            A[p, q] = acc
            A[q, p] = acc
    d = np.empty(6)
    for i in range(6):
        d[i] = np.sqrt(A[i, i]) if A[i, i] > 0 else 1.0
    L = np.zeros((6, 6))
    min_piv = np.inf
    for j in range(6):
        s = A[j, j] / (d[j] * d[j])
        for k in range(j):
            s -= L[j, k] * L[j, k]
        min_piv = min(min_piv, s)
        if not s > 1e-14:
            return 0.0
        L[j, j] = np.sqrt(s)
        for i in range(j + 1, 6):
            acc = A[i, j] / (d[i] * d[j])
            for k in range(j):
                acc -= L[i, k] * L[j, k]
            L[i, j] = acc / L[j, j]
    # inverse of the scaled matrix column by column
    Cs = np.empty((6, 6))
    y = np.empty(6)
    for c in range(6):
        for i in range(6):
            acc = 1.0 if i == c else 0.0
            for j in range(i):
                acc -= L[i, j] * y[j]
            y[i] = acc / L[i, i]
        for i in range(5, -1, -1):
            acc = y[i]
            for j in range(i + 1, 6):
                acc -= L[j, i] * Cs[j, c]
            Cs[i, c] = acc / L[i, i]
    Cp = np.empty((6, 6))
    for i in range(6):
        for j in range(6):
            Cp[i, j] = Cs[i, j] / (d[i] * d[j])
    # T = dV/dp by central differences
    T = np.empty((6, 6))
    Vp = np.empty(6)
    Vm = np.empty(6)
    Rp = np.empty((3, 3))
    tp = np.empty(3)
    w = np.zeros(3)
    scale = max(np.sqrt(t[0] * t[0] + t[1] * t[1] + t[2] * t[2]), 1.0)
    for j in range(6):
        for sgn in (1.0, -1.0):
            for i in range(3):
                tp[i] = t[i]
                w[i] = 0.0
            if j < 3:
                h = 1e-6 * scale
                tp[j] += sgn * h
                Rp[:, :] = R
            else:
                h = 1e-6
                w[j - 3] = sgn * h
                _rotate_left(R, w, Rp)
            if sgn > 0:
                paper_state(Rp, tp, Vp)
            else:
                paper_state(Rp, tp, Vm)
        for i in range(6):
            dv = Vp[i] - Vm[i]
            if i >= 3:
                dv = (dv + np.pi) % (2.0 * np.pi) - np.pi
            T[i, j] = dv / (2.0 * h)
    for i in range(6):
        for j in range(6):
            acc = 0.0
            for a in range(6):
                ta = T[i, a]
                if ta != 0.0:
                    for b in range(6):
                        acc += ta * Cp[a, b] * T[j, b]
            out[i, j] = acc
    return min_piv


@njit(cache=True)
def lm_frame(R, t, P, meas, W, max_iter, step_tol, rw, Jw):
    """Levenberg-Marquardt for one frame, in place on R and t.

    Gauss-Newton first; damping only after a step that did not lower the cost.

    ``rw`` (2n,) and ``Jw`` (2n, 6) receive the whitened residual and Jacobian at the end.

    Returns
    -------
    converged : bool
    iterations : int
    """
    m = 2 * P.shape[0]
    rn = np.empty(m)
    Jn = np.empty((m, 6))
    A = np.empty((6, 6))
    g = np.empty(6)
    dx = np.zeros(6)
    Rn = np.empty((3, 3))
    tn = np.empty(3)
    cost = residual_jacobian(R, t, P, meas, W, rw, Jw)
    lam = 0.0
    it = 0
    while it < max_iter:
        it += 1
        for p in range(6):
            acc = 0.0
            for r in range(m):
                acc += Jw[r, p] * rw[r]
            g[p] = acc
            for q in range(p, 6):
                acc = 0.0
                for r in range(m):
                    acc += Jw[r, p] * Jw[r, q]
                A[p, q] = acc
                A[q, p] = acc
        if not _solve6(A, g, lam + 1e-15, dx):
            lam = max(lam * 10.0, 1e-6)
            if lam > 1e10:
                return False, it
            continue
        pred = 0.0
        for p in range(6):
            pred += g[p] * dx[p]
        for i in range(3):
            tn[i] = t[i] + dx[i]
        _rotate_left(R, dx[3:], Rn)
        cn = residual_jacobian(Rn, tn, P, meas, W, rn, Jn)
        finite = np.isfinite(cn)
        better = finite and cn <= cost
        rng = max(np.sqrt(t[0] * t[0] + t[1] * t[1] + t[2] * t[2]), 1e-3)
        small = (max(abs(dx[0]), abs(dx[1]), abs(dx[2])) <= step_tol * rng) and (
            max(abs(dx[3]), abs(dx[4]), abs(dx[5])) <= step_tol
        )
        flat = better and (cost - cn <= 1e-12 * cost)
        tiny_gain = finite and abs(pred) <= 1e-12 * cost + 1e-30
        if better:
            R[:, :] = Rn
            t[:] = tn
            rw[:] = rn
            Jw[:, :] = Jn
            cost = cn
            lam *= 0.1
        else:
            lam = max(lam * 10.0, 1e-6)
            if lam > 1e10:
                return False, it
        if (better and small) or flat or tiny_gain:
            return True, it
    return False, it


@njit(cache=True)
def _solve_frame(k, R, t, P, meas, W, max_iter, step_tol, active, conv, iters, rw, cov, min_piv):
    """Frame ``k`` of a batch: :func:`lm_frame` then :func:`covariance_paper`, into the outputs."""
    if not active[k]:
        return
    Jw = np.empty((2 * P.shape[0], 6))
    c, it = lm_frame(R[k], t[k], P, meas[k], W[k], max_iter, step_tol, rw[k], Jw)
    conv[k] = c
    iters[k] = it
    if c:
        min_piv[k] = covariance_paper(R[k], t[k], Jw, cov[k])


@njit(cache=True)
def _outputs(N, m):
    return (np.zeros(N, np.bool_), np.zeros(N, np.int64), np.full((N, m), np.nan), np.full((N, 6, 6), np.nan),
            np.zeros(N))


@njit(cache=True, parallel=True)
def lm_batch(R, t, P, meas, W, max_iter, step_tol, active):
    """:func:`lm_frame` over frames in parallel, in place on R (N, 3, 3) and t (N, 3).

    Only frames with ``active[k]`` are iterated.

    Returns
    -------
    converged : (N,) bool
    iterations : (N,) int
    rw : (N, 2n) whitened residuals (px)
    cov : (N, 6, 6) covariance of the paper state for 1 px centroid noise (NaN if not converged)
    min_pivot : (N,) smallest pivot of the scaled information matrix (0: singular)
    """
    N = R.shape[0]
    conv, iters, rw, cov, min_piv = _outputs(N, 2 * P.shape[0])
    for k in prange(N):
        _solve_frame(k, R, t, P, meas, W, max_iter, step_tol, active, conv, iters, rw, cov, min_piv)
    return conv, iters, rw, cov, min_piv


@njit(cache=True)
def lm_batch_serial(R, t, P, meas, W, max_iter, step_tol, active):
    """:func:`lm_batch` without threads: small batches, where waking a thread pool costs
    more than the work."""
    N = R.shape[0]
    conv, iters, rw, cov, min_piv = _outputs(N, 2 * P.shape[0])
    for k in range(N):
        _solve_frame(k, R, t, P, meas, W, max_iter, step_tol, active, conv, iters, rw, cov, min_piv)
    return conv, iters, rw, cov, min_piv


@njit(cache=True)
def posit_batch(xy, P, Bmat, n_iter, R, t):
    """POSIT (DeMenthon & Davis 1995, non-coplanar form) for N frames, in place on R, t.

    Parameters
    ----------
    xy : (N, n, 2)
        Normalised image coordinates (OpenCV camera frame).
    P : (n, 3)
        Target points; ``P[0]`` is the reference point.
    Bmat : (3, n-1)
        Pseudo-inverse of ``P[1:] - P[0]``.
    n_iter : int
    R : (N, 3, 3) out, t : (N, 3) out
        Pose of the target in the camera frame.
    """
    N, n = xy.shape[0], xy.shape[1]
    eps = np.zeros(n - 1)
    I = np.empty(3)
    J = np.empty(3)
    k = np.empty(3)
    for f in range(N):
        x0, y0 = xy[f, 0, 0], xy[f, 0, 1]
        for m in range(n - 1):
            eps[m] = 0.0
        Z0 = 1.0
        bad = False
        for _ in range(n_iter):
            for a in range(3):
                si = 0.0
                sj = 0.0
                for m in range(n - 1):
                    si += Bmat[a, m] * (xy[f, m + 1, 0] * (1.0 + eps[m]) - x0)
                    sj += Bmat[a, m] * (xy[f, m + 1, 1] * (1.0 + eps[m]) - y0)
                I[a] = si
                J[a] = sj
            nI = np.sqrt(I[0] * I[0] + I[1] * I[1] + I[2] * I[2])
            nJ = np.sqrt(J[0] * J[0] + J[1] * J[1] + J[2] * J[2])
            if not (nI > 0 and nJ > 0):  # degenerate image points (coincident): no pose
                bad = True
                break
            for a in range(3):
                I[a] /= nI
                J[a] /= nJ
            k[0] = I[1] * J[2] - I[2] * J[1]
            k[1] = I[2] * J[0] - I[0] * J[2]
            k[2] = I[0] * J[1] - I[1] * J[0]
            nk = np.sqrt(k[0] * k[0] + k[1] * k[1] + k[2] * k[2])
            if not nk > 0:  # I parallel to J (collinear image points): no pose
                bad = True
                break
            for a in range(3):
                k[a] /= nk
            Z0 = 1.0 / np.sqrt(nI * nJ)
            for m in range(n - 1):
                eps[m] = ((P[m + 1, 0] - P[0, 0]) * k[0] + (P[m + 1, 1] - P[0, 1]) * k[1]
                          + (P[m + 1, 2] - P[0, 2]) * k[2]) / Z0
        if bad:  # NaN: the caller's residual is then not finite and the set is not a candidate
            for a in range(3):
                t[f, a] = np.nan
                for b in range(3):
                    R[f, a, b] = np.nan
            continue
        # j = k x i makes the rows orthonormal and right-handed
        R[f, 0, 0], R[f, 0, 1], R[f, 0, 2] = I[0], I[1], I[2]
        R[f, 1, 0] = k[1] * I[2] - k[2] * I[1]
        R[f, 1, 1] = k[2] * I[0] - k[0] * I[2]
        R[f, 1, 2] = k[0] * I[1] - k[1] * I[0]
        R[f, 2, 0], R[f, 2, 1], R[f, 2, 2] = k[0], k[1], k[2]
        for a in range(3):
            t[f, a] = -(R[f, a, 0] * P[0, 0] + R[f, a, 1] * P[0, 1] + R[f, a, 2] * P[0, 2])
        t[f, 0] += x0 * Z0
        t[f, 1] += y0 * Z0
        t[f, 2] += Z0


@njit(cache=True)
def measurements_batch(pts, fx, fy, cx, cy, dist, xy, meas, Winv):
    """Undistortion (Newton, as :meth:`svgs_sim.base.profiles.Camera.undistort_normalized`), the
    azimuth/elevation measurements and their whitening ``W = G^-1`` for N frames of n centroids,
    with the analytic Jacobian ``G = d(Az, El)/d(u, v) = d(Az, El)/d(x, y) (d(xd, yd)/d(x, y))^-1
    diag(1/fx, 1/fy)``. Outputs ``xy`` (N, n, 2), ``meas`` (N, n, 2), ``Winv`` (N, n, 2, 2)."""
    k1, k2, p1, p2, k3 = dist[0], dist[1], dist[2], dist[3], dist[4]
    has = (k1 != 0.0) or (k2 != 0.0) or (p1 != 0.0) or (p2 != 0.0) or (k3 != 0.0)
    N, n = pts.shape[0], pts.shape[1]
    for i in range(N):
        for j in range(n):
            xd = (pts[i, j, 0] - cx) / fx
            yd = (pts[i, j, 1] - cy) / fy
            x, y = xd, yd
            a, b, c, d = 1.0, 0.0, 0.0, 1.0
            if has:
                x, y = undistort_one(xd, yd, k1, k2, p1, p2, k3)
                a, b, d, _ = distortion_jacobian(x, y, k1, k2, p1, p2, k3)
                c = b
            xy[i, j, 0] = x
            xy[i, j, 1] = y
            s2 = x * x + y * y + 1.0
            q = np.sqrt(1.0 + x * x)
            meas[i, j, 0] = np.arctan(x)
            meas[i, j, 1] = np.arcsin(-y / np.sqrt(s2))
            # d(Az, El)/d(x, y)
            e00 = 1.0 / (q * q)
            e10 = x * y / (q * s2)
            e11 = -q / s2
            # (d(xd, yd)/d(x, y))^-1 diag(1/fx, 1/fy)
            det = a * d - b * c
            m00, m01 = d / det / fx, -b / det / fy
            m10, m11 = -c / det / fx, a / det / fy
            g00 = e00 * m00
            g01 = e00 * m01
            g10 = e10 * m00 + e11 * m10
            g11 = e10 * m01 + e11 * m11
            dg = g00 * g11 - g01 * g10
            Winv[i, j, 0, 0] = g11 / dg
            Winv[i, j, 0, 1] = -g01 / dg
            Winv[i, j, 1, 0] = -g10 / dg
            Winv[i, j, 1, 1] = g00 / dg


@njit(cache=True)
def check_points_batch(pts, bad):
    """Per frame: 1 a non-finite centroid, 2 coincident or collinear centroids, else 0."""
    N, n = pts.shape[0], pts.shape[1]
    for i in range(N):
        bad[i] = 0
        for j in range(n):
            if not (np.isfinite(pts[i, j, 0]) and np.isfinite(pts[i, j, 1])):
                bad[i] = 1
        if bad[i]:
            continue
        mx, my = 0.0, 0.0
        for j in range(n):
            mx += pts[i, j, 0]
            my += pts[i, j, 1]
        mx /= n
        my /= n
        sxx, syy, sxy = 0.0, 0.0, 0.0
        for j in range(n):
            dx, dy = pts[i, j, 0] - mx, pts[i, j, 1] - my
            sxx += dx * dx
            syy += dy * dy
            sxy += dx * dy
            for k in range(j + 1, n):
                ex, ey = pts[i, j, 0] - pts[i, k, 0], pts[i, j, 1] - pts[i, k, 1]
                if np.sqrt(ex * ex + ey * ey) < 1e-6:
                    bad[i] = 2
        half_tr, det = 0.5 * (sxx + syy), sxx * syy - sxy * sxy
        disc = np.sqrt(max(half_tr * half_tr - det, 0.0))
        if (half_tr - disc) < 1e-18 * max(half_tr + disc, 1e-300):
            bad[i] = 2
