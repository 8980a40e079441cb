"""Tone mapping to 8 bits - one home for the phone's tone curve and the people-facing previews.

- :func:`gamma_u8`: the phone ISP's tone curve (linear 0..1 -> ``x^(1/gamma)`` -> 8 bits),
  used for the tone LUT and for float-DN frames (:mod:`svgs_sim.camera.phone`).
- :func:`log_stretch`: the flux preview (``preview.png`` of ``svgs render``): log scale between
  the 1st percentile of the lit pixels and the maximum (spots are ~1e7 x the background).
- :func:`sqrt_stretch`, :func:`depth_stretch`: the ToF preview (gray beside depth).
- :func:`encode_u8`: 0..1 -> uint8 (rounded), the last step of each.

numpy only.
"""

from __future__ import annotations

import numpy as np


def encode_u8(x) -> np.ndarray:
    """Values in 0..1 -> uint8 0..255, rounded to nearest (no clipping: callers clip).

    Parameters
    ----------
    x : array_like, any shape

    Returns
    -------
    ndarray of uint8, same shape
    """
    return np.round(np.asarray(x) * 255.0).astype(np.uint8)


def gamma_u8(linear, gamma: float) -> np.ndarray:
    """The tone curve ``linear^(1/gamma)`` in 8 bits (``gamma <= 0``: linear 8-bit).

    Parameters
    ----------
    linear : array_like
        Linear signal, already clipped to 0..1.
    gamma : float
    """
    lin = np.asarray(linear)
    return encode_u8(lin ** (1.0 / gamma) if gamma > 0 else lin)


def log_stretch(values) -> np.ndarray:
    """Log scale of a non-negative image between the 1st percentile of its positive values
    (at least 1e-9 of the maximum) and its maximum, as 0..1 (all zeros: zeros).

    Parameters
    ----------
    values : array_like, shape (H, W)

    Returns
    -------
    ndarray of float64, shape (H, W)
    """
    f = np.asarray(values, np.float64)
    pos = f[f > 0]
    if pos.size == 0:
        return np.zeros(f.shape)
    lo = max(np.percentile(pos, 1.0), pos.max() * 1e-9)
    hi = pos.max()
    return np.log(np.clip(f, lo, hi) / lo) / max(np.log(hi / lo), 1e-12)


def sqrt_stretch(values) -> np.ndarray:
    """``sqrt(x / max)`` clipped to 0..1 (the ToF gray preview), float64."""
    g = np.asarray(values, float)
    return np.sqrt(np.clip(g / max(float(g.max()), 1e-12), 0, 1))


def depth_stretch(depth_m) -> np.ndarray:
    """Depth as 0..1, near = bright, between its 1st and 99th percentile; 0 where not finite."""
    d = np.asarray(depth_m, float)
    ok = np.isfinite(d)
    b = np.zeros_like(d)
    if ok.any():
        lo, hi = np.percentile(d[ok], [1, 99])
        b[ok] = 1.0 - np.clip((d[ok] - lo) / max(hi - lo, 1e-9), 0, 1)
    return b
