"""Negative Laplacian-of-Gaussian filtering on the active set (paper section 3.1.2).

``F = nLoG * I`` with the scale-normalised kernel ``nLoG = -sigma^2 (d2/dx2 + d2/dy2) G_sigma``,
evaluated only at the active pixels (the paper's computational saving): each active pixel's
``k x k`` neighbourhood is gathered from the (reflect-padded) raw gray image and dotted with
the kernel. The kernel is made zero-sum, so a flat region gives 0; a bright blob of radius
``~sigma sqrt(2)`` gives its largest response at its centre, a larger blob responds
positively just inside its rim and about zero in its interior.

The filtered-intensity threshold keeps active pixels with ``F > threshold_rel * max(F)``
and orders them by decreasing ``F``. ASSUMPTION (the paper's values are not legible):
``sigma = 1.0 px``; ``threshold_rel = -0.1``, i.e. the threshold rejects only the dark
side of edges (pixels whose response is clearly negative) and keeps the ~0-response
interior of large markers, which a positive threshold would hollow out.
"""

from __future__ import annotations

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from svgs_sim.base.errors import InputError

from .active import ActiveSet

#: ASSUMPTION: nLoG scale in pixels.
DEFAULT_SIGMA_PX = 1.0
#: Above this (active pixels x kernel size) / (frame pixels x kernel width), the filter is
#: evaluated on the whole frame with OpenCV and read at the active pixels (same values).
FULL_FRAME_FRACTION = 0.5
#: ASSUMPTION: filtered-intensity threshold as a fraction of the largest response.
DEFAULT_FILTERED_THRESHOLD_REL = -0.1


def nlog_kernel(sigma_px: float = DEFAULT_SIGMA_PX, radius_px: int | None = None) -> np.ndarray:
    """Scale-normalised negative LoG kernel, zero-sum.

    Parameters
    ----------
    sigma_px : float
    radius_px : int, optional
        Half-width; default ``ceil(3 sigma)``.

    Returns
    -------
    kernel : ndarray of float32, shape (2 r + 1, 2 r + 1)
        ``(2 - rho^2 / sigma^2) G(rho)`` sampled at integer offsets, mean removed.
    """
    if not (np.isfinite(sigma_px) and sigma_px > 0):
        raise InputError(f"sigma_px: expected a positive number of pixels, got {sigma_px!r}")
    r = int(np.ceil(3 * sigma_px)) if radius_px is None else int(radius_px)
    y, x = np.mgrid[-r:r + 1, -r:r + 1].astype(float)
    q = (x * x + y * y) / (sigma_px * sigma_px)
    k = (2.0 - q) * np.exp(-q / 2) / (2 * np.pi * sigma_px * sigma_px)
    k -= k.mean()
    return k.astype(np.float32)


def nlog_at(gray, rows, cols, sigma_px: float = DEFAULT_SIGMA_PX) -> np.ndarray:
    """nLoG response at the given pixels only.

    Parameters
    ----------
    gray : array_like, shape (H, W)
    rows, cols : array_like of int, shape (n,)
    sigma_px : float

    Returns
    -------
    F : ndarray of float32, shape (n,)
        Equal to ``cv2.filter2D(gray, -1, nlog_kernel(sigma), borderType=BORDER_REFLECT_101)``
        at those pixels.
    """
    g = np.asarray(gray, np.float32)
    kern = nlog_kernel(sigma_px)
    r = kern.shape[0] // 2
    rows = np.asarray(rows, np.intp)
    cols = np.asarray(cols, np.intp)
    if rows.size == 0:
        return np.zeros(0, np.float32)
    if rows.size * kern.size > FULL_FRAME_FRACTION * g.size * kern.shape[0]:
        # many active pixels: OpenCV's whole-frame (separable-speed) filter is cheaper in numpy
        # than gathering every window; the values at the active pixels are the same
        return nlog_image(g, sigma_px)[rows, cols]
    pad = np.pad(g, r, mode="reflect")
    win = sliding_window_view(pad, kern.shape)
    return win[rows, cols].reshape(rows.size, -1) @ kern.ravel()


def nlog_image(gray, sigma_px: float = DEFAULT_SIGMA_PX) -> np.ndarray:
    """nLoG of the whole image (reference for tests and figures), shape (H, W)."""
    import cv2

    return cv2.filter2D(np.asarray(gray, np.float32), -1, nlog_kernel(sigma_px), borderType=cv2.BORDER_REFLECT_101)


def filtered_threshold(filtered, threshold_rel: float = DEFAULT_FILTERED_THRESHOLD_REL) -> tuple[np.ndarray, float]:
    """Filtered-intensity threshold.

    Parameters
    ----------
    filtered : array_like, shape (n,)
    threshold_rel : float
        Threshold as a fraction of ``max(filtered)`` (may be negative).

    Returns
    -------
    order : ndarray of intp, shape (m,)
        Indices of the kept pixels, by decreasing filtered intensity.
    threshold : float
    """
    f = np.asarray(filtered)
    if f.size == 0:
        return np.zeros(0, np.intp), 0.0
    thr = float(threshold_rel) * float(max(f.max(), 0.0))
    keep = np.flatnonzero(f > thr)
    return keep[np.argsort(-f[keep])], thr


def filter_active_set(gray, active: ActiveSet, sigma_px: float = DEFAULT_SIGMA_PX,
                      threshold_rel: float = DEFAULT_FILTERED_THRESHOLD_REL) -> tuple[ActiveSet, np.ndarray, float]:
    """nLoG on the active set, then the filtered-intensity threshold.

    Returns
    -------
    active : ActiveSet
        The kept pixels, by decreasing filtered intensity.
    filtered : ndarray, shape (m,)
        Their filtered intensities.
    threshold : float
    """
    f = nlog_at(gray, active.rows, active.cols, sigma_px)
    order, thr = filtered_threshold(f, threshold_rel)
    return active.subset(order), f[order], thr
