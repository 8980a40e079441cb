"""The Brown-Conrady lens distortion inverted by Newton's method: compiled kernels (numba, cached
on disk) shared by :meth:`svgs_sim.base.profiles.Camera.undistort_normalized` and the collinearity
solver's measurement kernel (:func:`svgs_sim.svgs._lm_kernel.measurements_batch`).

Normalised coordinates ``x = (u - cx) / fx``, ``y = (v - cy) / fy``; coefficients ``(k1, k2, p1, p2,
k3)`` in OpenCV's order.
"""

from __future__ import annotations

from numba import njit, prange


@njit(cache=True)
def distortion_jacobian(x, y, k1, k2, p1, p2, k3):
    """``d(xd, yd)/d(x, y)`` of the Brown-Conrady model at ``(x, y)``: ``(a, b, d)`` of the
    symmetric 2x2 ``[[a, b], [b, d]]``, and the radial factor."""
    r2 = x * x + y * y
    rad = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    drad = 2.0 * (k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2))
    a = rad + x * x * drad + 2.0 * p1 * y + 6.0 * p2 * x
    b = x * y * drad + 2.0 * p1 * x + 2.0 * p2 * y
    d = rad + y * y * drad + 6.0 * p1 * y + 2.0 * p2 * x
    return a, b, d, rad


@njit(cache=True)
def undistort_one(x0, y0, k1, k2, p1, p2, k3):
    """Newton's method on the distortion model, at most 20 steps, until the residual < 1e-15."""
    x, y = x0, y0
    for _ in range(20):
        a, b, d, rad = distortion_jacobian(x, y, k1, k2, p1, p2, k3)
        r2 = x * x + y * y
        fx_ = x * rad + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x) - x0
        fy_ = y * rad + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y - y0
        det = a * d - b * b
        x -= (d * fx_ - b * fy_) / det
        y -= (-b * fx_ + a * fy_) / det
        if max(abs(fx_), abs(fy_)) < 1e-15:
            break
    return x, y


@njit(cache=True, parallel=True)
def undistort_points(xd, dist, out):
    """Invert the Brown-Conrady distortion of normalised points ``xd`` (M, 2) by Newton's
    method, per point until the residual is below 1e-15 (at most 20 steps); ``out`` (M, 2)."""
    k1, k2, p1, p2, k3 = dist[0], dist[1], dist[2], dist[3], dist[4]
    for i in prange(xd.shape[0]):
        x, y = undistort_one(xd[i, 0], xd[i, 1], k1, k2, p1, p2, k3)
        out[i, 0] = x
        out[i, 1] = y
