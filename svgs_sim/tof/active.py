"""Active pixel set from the raw gray threshold (paper section 3.1.1).

Pixels brighter than a threshold ``T_g`` are kept; when more than ``max_pixels`` pass, the
dimmest are discarded first. Everything downstream (nLoG filtering, blobs, centroids) works
on this small set only.

The threshold is ``T_g = max(threshold_rel * gray_max, noise floor)``: ``gray_max`` is the
frame's brightest value (paper: a fraction of the maximum gray value; the fraction is not
legible in our copy - ASSUMPTION: 0.3), and the noise floor ``median + noise_k * sigma``
(robust sigma from the MAD of a pixel subsample) keeps an all-dark frame from turning its
noise into active pixels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from svgs_sim.base.errors import InputError

#: ASSUMPTION: fraction of the frame maximum used as the raw gray threshold.
DEFAULT_THRESHOLD_REL = 0.3
#: ASSUMPTION: cap on the active set (about 16 % of a 320 x 240 frame: the eight markers of
#: tof-8 at 0.7 m cover ~8200 pixels above the threshold; a cap that trims their rims,
#: dimmest first, biases the centroids towards the lit side).
DEFAULT_MAX_PIXELS = 12000
#: Noise floor: threshold at least median + NOISE_K robust sigmas.
DEFAULT_NOISE_K = 6.0


@dataclass
class ActiveSet:
    """The active pixel set.

    Attributes
    ----------
    rows, cols : ndarray of intp, shape (n,)
        Pixel coordinates (row = v, col = u) of the active pixels.
    gray : ndarray, shape (n,)
        Raw gray value of each active pixel.
    shape : tuple of int
        ``(H, W)`` of the frame.
    threshold : float
        The raw gray threshold used.
    n_above : int
        Pixels above the threshold before the cap.
    gray_max : float
        Frame maximum the relative threshold refers to.
    background : float
        Robust background level (median of a subsample).
    noise_sigma : float
        Robust noise sigma (1.4826 MAD of a subsample).
    """

    rows: np.ndarray
    cols: np.ndarray
    gray: np.ndarray
    shape: tuple
    threshold: float
    n_above: int
    gray_max: float
    background: float
    noise_sigma: float

    @property
    def n(self) -> int:
        return int(self.rows.size)

    def mask(self) -> np.ndarray:
        """Boolean image of the set, shape ``(H, W)``."""
        m = np.zeros(self.shape, bool)
        m[self.rows, self.cols] = True
        return m

    def subset(self, keep: np.ndarray) -> "ActiveSet":
        """The set restricted to ``keep`` (bool (n,) or indices)."""
        return ActiveSet(self.rows[keep], self.cols[keep], self.gray[keep], self.shape, self.threshold,
                         self.n_above, self.gray_max, self.background, self.noise_sigma)


def robust_background(gray: np.ndarray, step: int = 4) -> tuple[float, float]:
    """Background level and noise sigma from a strided subsample (median, 1.4826 MAD).

    Parameters
    ----------
    gray : ndarray, shape (H, W)
    step : int
        Subsampling stride in both axes.

    Returns
    -------
    background, sigma : float
    """
    sub = np.asarray(gray[::step, ::step], np.float32).ravel()
    if sub.size == 0:
        return 0.0, 0.0
    med = float(np.median(sub))
    mad = float(np.median(np.abs(sub - med)))
    return med, 1.4826 * mad


def active_pixel_set(
    gray,
    threshold_rel: float = DEFAULT_THRESHOLD_REL,
    max_pixels: int = DEFAULT_MAX_PIXELS,
    *,
    threshold: float | None = None,
    gray_max: float | None = None,
    noise_k: float = DEFAULT_NOISE_K,
) -> ActiveSet:
    """Threshold the raw gray image into the active pixel set, capped at ``max_pixels``.

    Parameters
    ----------
    gray : array_like, shape (H, W)
        Raw gray (amplitude) image, any real dtype, finite.
    threshold_rel : float
        Threshold as a fraction of ``gray_max``.
    max_pixels : int
        Maximum size of the set; the dimmest pixels are discarded first.
    threshold : float, optional
        Absolute threshold in gray counts; overrides ``threshold_rel`` and the noise floor.
    gray_max : float, optional
        Full-scale value the relative threshold refers to (default: the frame maximum).
    noise_k : float
        The threshold is at least ``background + noise_k * sigma``.

    Returns
    -------
    ActiveSet
        Pixels ordered by decreasing gray value when capped, else in raster order.
    """
    g = np.asarray(gray)
    if g.ndim != 2:
        raise InputError(f"gray: expected a 2-D image, got shape {g.shape}")
    if not (0 < threshold_rel <= 1):
        raise InputError(f"threshold_rel: expected a fraction in (0, 1], got {threshold_rel!r}")
    if int(max_pixels) < 1:
        raise InputError(f"max_pixels: expected a positive count, got {max_pixels!r}")
    g = g.astype(np.float32, copy=False)
    background, sigma = robust_background(g)
    gmax = float(g.max()) if gray_max is None else float(gray_max)
    if threshold is None:
        thr = max(threshold_rel * gmax, background + noise_k * sigma)
    else:
        thr = float(threshold)
    flat = g.ravel()
    idx = np.flatnonzero(flat > thr)
    n_above = int(idx.size)
    if n_above > max_pixels:
        vals = flat[idx]
        keep = np.argpartition(-vals, max_pixels - 1)[:max_pixels]
        keep = keep[np.argsort(-vals[keep], kind="stable")]
        idx = idx[keep]
    rows, cols = np.divmod(idx, g.shape[1])
    return ActiveSet(rows, cols, flat[idx], g.shape, float(thr), n_above, gmax, background, sigma)
