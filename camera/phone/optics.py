"""Lens point-spread function: diffraction + aberration core, power-law glare wings, ghosts.

PSF = (1 - eta) * core + eta * wings (+ ghosts, which take their share from the core):

- **core**: a Gaussian of variance ``sigma_airy^2 + sigma_ab^2`` px^2, with
  ``sigma_airy = 0.42 lambda N / pitch`` (the Gaussian that best fits the Airy disk of an
  f/N lens) at the band's mean wavelength, and ``sigma_ab`` the lens' aberration blur;
- **wings** (veiling glare, ISO 9358): ``w(r) ~ (1 + (r / r_c)^2)^(-alpha / 2)`` out to
  ``wing_radius_px``, normalised to unit sum; share ``eta = veiling_fraction``;
- **ghosts**: images of the scene scaled by ``scale`` about the principal point (negative:
  mirrored through it), blurred, each with a share ``fraction``.

Scaling to full-resolution frames: the core is a separable blur at full resolution; the
wings are smooth, so they are convolved by FFT on a grid binned by ``s`` (chosen so that
grid has at most ~0.5 Mpx) and spread back by bilinear interpolation. Energy is conserved
except what the wings carry off the frame.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
from scipy.signal import fftconvolve

from camera.phone.params import GlareParams

#: Coarse grid size for the wing convolution, pixels.
WING_GRID_PX = 1 << 19


def core_sigma_px(f_number: float, band_nm, pitch_m: float, aberration_sigma_px: float) -> float:
    """Standard deviation (px) of the Gaussian core of the PSF."""
    lam_m = 0.5 * (band_nm[0] + band_nm[1]) * 1e-9
    s_airy = 0.42 * lam_m * f_number / pitch_m
    return math.sqrt(s_airy**2 + aberration_sigma_px**2)


def wing_kernel(glare: GlareParams, step_px: int) -> np.ndarray:
    """The wing PSF sampled on a grid of ``step_px`` full-resolution pixels, unit sum."""
    rmax = int(math.ceil(glare.wing_radius_px / step_px))
    y, x = np.mgrid[-rmax : rmax + 1, -rmax : rmax + 1] * float(step_px)
    r2 = x * x + y * y
    k = (1.0 + r2 / glare.wing_core_px**2) ** (-glare.wing_exponent / 2.0)
    k[r2 > glare.wing_radius_px**2] = 0.0
    return (k / k.sum()).astype(np.float64)


def apply_psf(flux: np.ndarray, glare: GlareParams, sigma_core_px: float, principal_point=None) -> np.ndarray:
    """Convolve a flux image (any linear unit per pixel) with the lens PSF.

    Parameters
    ----------
    flux : ndarray, shape (H, W)
    glare : GlareParams
    sigma_core_px : float
        From :func:`core_sigma_px`.
    principal_point : (cx, cy), optional
        Centre of the ghost images (default: image centre).

    Returns
    -------
    ndarray, float32, shape (H, W)
    """
    f = np.ascontiguousarray(flux, np.float32)
    H, W = f.shape
    eta = glare.veiling_fraction
    ghost_share = sum(g[0] for g in glare.ghosts)
    core_share = 1.0 - eta - ghost_share
    if sigma_core_px > 0:
        out = cv2.GaussianBlur(f, (0, 0), sigmaX=sigma_core_px, sigmaY=sigma_core_px, borderType=cv2.BORDER_CONSTANT)
    else:
        out = f.copy()
    out *= core_share
    if eta > 0:
        s = max(1, int(math.ceil(math.sqrt(H * W / WING_GRID_PX))))
        Hc, Wc = -(-H // s), -(-W // s)
        pad = np.zeros((Hc * s, Wc * s), np.float32)
        pad[:H, :W] = f
        coarse = pad.reshape(Hc, s, Wc, s).sum(axis=(1, 3), dtype=np.float64)  # sum-pool: energy kept
        wc = fftconvolve(coarse, wing_kernel(glare, s), mode="same")
        # spread each coarse pixel's energy back over its s x s fine pixels, smoothly
        fine = cv2.resize(wc.astype(np.float32), (Wc * s, Hc * s), interpolation=cv2.INTER_LINEAR) / (s * s)
        out += eta * fine[:H, :W]
    if glare.ghosts:
        cx, cy = principal_point if principal_point is not None else ((W - 1) / 2.0, (H - 1) / 2.0)
        for frac, scale, blur in glare.ghosts:
            A = np.array([[scale, 0.0, cx * (1 - scale)], [0.0, scale, cy * (1 - scale)]], np.float32)
            g = cv2.warpAffine(f, A, (W, H), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
            g /= scale * scale  # warpAffine samples: keep the energy
            if blur > 0:
                g = cv2.GaussianBlur(g, (0, 0), sigmaX=blur, sigmaY=blur, borderType=cv2.BORDER_CONSTANT)
            out += frac * g
    return out
