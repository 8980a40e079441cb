"""Lens point-spread function: diffraction + aberration core, power-law glare wings, ghosts.

PSF = (1 - eta - sum ghosts) * core + eta * wings (+ ghosts):

- **core** (:class:`svgs_sim.camera.phone.psf.CorePSF`): the Airy pattern of the f/N aperture at the
  band's middle wavelength convolved with the aberration Gaussian ``sigma_ab``. Point samples
  (:class:`svgs_sim.camera.rendered.PointFlux`, the retro spots) go through it by a deterministic
  convolution on a sub-pixel grid with exact pixel-area integration (the expectation of the
  earlier Monte Carlo convolution, kept as ``method="monte-carlo"``); pixel images (the diffuse light) by the
  pixel-integrated kernel. Light that reaches the film as a pixel image and as points is never
  blurred twice: each part takes one path.
- **wings** (veiling glare, ISO 9358): ``w(r) ~ (1 + (r / r_c)^2)^(-alpha / 2)`` out to
  ``wing_radius_px``, normalised to unit sum; share ``eta = veiling_fraction``;
- **ghosts**: images of the scene scaled by ``scale`` about the principal point (negative:
  mirrored through it), blurred, each with a share ``fraction``.

The wings are smooth, so they are convolved by FFT on a grid binned by ``s`` (chosen so that
grid has at most ~0.5 Mpx). The binning and the spreading back are a pair of linear
(tent) interpolations, and points enter bilinearly: each keeps a spot's first moment exactly,
so the wings broaden a spot but never move its centroid (before, a sum-pool and a bilinear
spread moved it by up to ``s / 2`` times the wing share). Energy is conserved except what
leaves the frame.
"""

from __future__ import annotations

import functools
import math

import cv2
import numpy as np
from numba import njit, prange

from svgs_sim.camera.backend import get_backend
from svgs_sim.camera.phone.params import GlareParams
from svgs_sim.camera.phone.psf import CorePSF, support_box
from svgs_sim.camera.rendered import bilinear_splat

#: Coarse grid size for the wing convolution, pixels.
WING_GRID_PX = 1 << 19


def core_sigma_px(f_number: float, band_nm, pitch_m: float, aberration_sigma_px: float) -> float:
    """Standard deviation (px) of the Gaussian that best fits the PSF core (0.42 lambda N for
    the Airy disk at the band's middle, in quadrature with the aberration): for summaries and
    the Cramer-Rao bound; the image itself is formed with the Airy pattern (:func:`core_psf`)."""
    return core_psf(f_number, band_nm, pitch_m, aberration_sigma_px).sigma_equivalent_px


def core_psf(f_number: float, band_nm, pitch_m: float, aberration_sigma_px: float, wavelength_nm=None) -> CorePSF:
    """The core PSF: Airy at ``wavelength_nm`` (default: the band's middle) (x) aberration."""
    lam = 0.5 * (band_nm[0] + band_nm[1]) if wavelength_nm is None else float(wavelength_nm)
    return CorePSF.from_optics(f_number, lam, pitch_m, aberration_sigma_px)


def wing_kernel(glare: GlareParams, step_px: int) -> np.ndarray:
    """The wing PSF sampled on a grid of ``step_px`` full-resolution pixels, unit sum."""
    rmax = int(math.ceil(glare.wing_radius_px / step_px))
    y, x = np.mgrid[-rmax : rmax + 1, -rmax : rmax + 1] * float(step_px)
    r2 = x * x + y * y
    k = (1.0 + r2 / glare.wing_core_px**2) ** (-glare.wing_exponent / 2.0)
    k[r2 > glare.wing_radius_px**2] = 0.0
    return (k / k.sum()).astype(np.float64)


def tent_matrix(n: int, s: int):
    """Linear (tent) interpolation weights between ``n`` fine samples and ``ceil(n / s)``
    coarse ones centred at ``k s + (s - 1) / 2``: sparse, shape (n_coarse, n).

    Each fine sample's weights sum to 1 and reproduce its position (first moment) exactly;
    at the two ends the weight that would fall outside goes to the end cell.
    """
    from scipy.sparse import csr_matrix

    nc = -(-n // s)
    x = np.arange(n, dtype=float)
    t = (x - (s - 1) / 2.0) / s
    k0 = np.floor(t)
    f = t - k0
    k0 = k0.astype(int)
    rows = np.concatenate([np.clip(k0, 0, nc - 1), np.clip(k0 + 1, 0, nc - 1)])
    cols = np.concatenate([np.arange(n), np.arange(n)])
    data = np.concatenate([1.0 - f, f])
    return csr_matrix((data, (rows, cols)), shape=(nc, n))


def wing_step(shape) -> int:
    """The binning ``s`` of the wings' coarse grid for a frame of ``shape`` (at most
    :data:`WING_GRID_PX` coarse pixels)."""
    H, W = shape
    return max(1, int(math.ceil(math.sqrt(H * W / WING_GRID_PX))))


def wings_coarse(flux, glare: GlareParams, points=None, backend=None):
    """The wing PSF (unit sum) applied to a pixel image and point samples, on its coarse grid.

    The light the wings spread (the image plus the points' bilinear image) is tent-binned
    over the box that holds it only (the binning of zeros is zero), convolved by FFT, and
    returned with its binning for :func:`wings` or :func:`compose` to spread back.

    Parameters
    ----------
    flux : ndarray, shape (H, W)
    glare : GlareParams
    points : svgs_sim.camera.rendered.PointFlux, optional
    backend : str or svgs_sim.camera.backend.Backend, optional

    Returns
    -------
    wc : ndarray, float64, shape (ceil(H / s), ceil(W / s))
        Per fine pixel (the full-resolution image itself when ``s == 1``).
    s : int
    """

    be = get_backend(backend)
    f = np.asarray(flux)
    H, W = f.shape
    s = wing_step((H, W))
    if s == 1:
        return be.fft_convolve_same(glare_source(f, points), wing_kernel(glare, 1)), 1
    pbox = _points_box(points, H, W)
    boxes = [b for b in (support_box(f, 0), pbox) if b is not None]
    Ay, Ax = _tent_pair(H, W, s)
    if not boxes:
        return np.zeros((Ay.shape[0], Ax.shape[0])), s
    y0, y1 = min(b[0] for b in boxes), max(b[1] for b in boxes)
    x0, x1 = min(b[2] for b in boxes), max(b[3] for b in boxes)
    sub = np.array(f[y0:y1, x0:x1], np.float64)
    if pbox is not None:
        py0, py1, px0, px1 = pbox
        sub[py0 - y0:py1 - y0, px0 - x0:px1 - x0] += bilinear_splat(
            points.u_px, points.v_px, points.rate_ph_s, px0, py0, px1 - px0, py1 - py0)
    coarse = (Ax[:, x0:x1] @ (Ay[:, y0:y1] @ sub).T).T  # (Hc, Wc)
    return be.fft_convolve_same(coarse, wing_kernel(glare, s)) / float(s * s), s


def _points_box(points, H: int, W: int):
    """The box ``(y0, y1, x0, x1)`` of the points' bilinear image, or None."""
    if points is None or len(points) == 0:
        return None
    x0 = max(0, int(np.floor(points.u_px.min())))
    y0 = max(0, int(np.floor(points.v_px.min())))
    x1 = min(W, int(np.floor(points.u_px.max())) + 2)
    y1 = min(H, int(np.floor(points.v_px.max())) + 2)
    return (y0, y1, x0, x1) if (x1 > x0 and y1 > y0) else None


@njit(cache=True, inline="always")
def _spread_index(i, s, n):
    """Where fine pixel ``i`` reads a coarse grid of ``n`` cells of ``s`` pixels: the two cells
    and the weight of the second (coarse coordinate ``(i + 1/2) / s - 1/2``, clamped at the ends)."""
    t = (i + 0.5) / s - 0.5
    i0 = int(np.floor(t))
    f = t - i0
    if i0 < 0:
        i0, f = 0, 0.0
    if i0 >= n - 1:
        i0, f = n - 1, 0.0
    return i0, (i0 + 1 if i0 + 1 < n else i0), f


@njit(parallel=True, cache=True)
def _compose_kernel(core, share, wc, s, eta, bg, scale, use_bg, resp, wc2, resp2, use2, out):
    """``out = resp * (share * core + eta * up(wc) + scale * bg) + resp2 * eta * up(wc2)`` (float32
    out): the optical image's parts summed in one pass; ``up`` is the linear spreading of a coarse
    wing image back to full resolution (fine x reads coarse (x + 1/2) / s - 1/2, clamped at the
    ends, the tent binning's transpose, as ``cv2.resize``'s INTER_LINEAR on an s-fold grid); the
    second wing image (``use2``) is light of another colour, with its own per-pixel response."""
    H, W = core.shape
    Hc, Wc = wc.shape
    cx0 = np.empty(W, np.int64)
    cx1 = np.empty(W, np.int64)
    cfx = np.empty(W, np.float64)
    for c in range(W):
        cx0[c], cx1[c], cfx[c] = _spread_index(c, s, Wc)
    for r in prange(H):
        y0, y1, fy = _spread_index(r, s, Hc)
        for c in range(W):
            x0, x1, fx = cx0[c], cx1[c], cfx[c]
            w = ((1.0 - fy) * ((1.0 - fx) * wc[y0, x0] + fx * wc[y0, x1])
                 + fy * ((1.0 - fx) * wc[y1, x0] + fx * wc[y1, x1]))
            v = core[r, c] * share + eta * w
            if use_bg:
                v += scale * bg[r, c]
            v *= resp[r, c]
            if use2:
                w2 = ((1.0 - fy) * ((1.0 - fx) * wc2[y0, x0] + fx * wc2[y0, x1])
                      + fy * ((1.0 - fx) * wc2[y1, x0] + fx * wc2[y1, x1]))
                v += eta * w2 * resp2[r, c]
            out[r, c] = v


def compose(core, share: float, wc, s: int, eta: float, resp, background=None, extra=None) -> np.ndarray:
    """The optical image from its parts in one pass (:func:`_compose_kernel`): the core image
    (float64 (H, W)) times its share, the wings' coarse image ``wc`` of binning ``s``
    (:func:`wings_coarse`) times ``eta``, ``background = (scale, image)`` (float64 (H, W)) and
    the per-pixel response ``resp`` (float32 (H, W)); ``extra = (wc2, resp2)``: a second coarse
    wing image (the same binning) with its own per-pixel response, added. Returns float32 (H, W)."""
    H, W = core.shape
    out = np.empty((H, W), np.float32)
    if s == 1:
        wc = np.ascontiguousarray(wc, np.float64)
    if background is None:
        scale, bg, use_bg = 0.0, np.zeros((1, 1)), False
    else:
        scale, bg, use_bg = float(background[0]), background[1], True
    if extra is None:
        wc2, resp2, use2 = np.zeros((1, 1)), np.zeros((1, 1), np.float32), False
    else:
        wc2, resp2, use2 = np.ascontiguousarray(extra[0], np.float64), np.ascontiguousarray(extra[1], np.float32), True
        if wc2.shape != np.shape(wc) or resp2.shape != (H, W):
            raise ValueError("compose: the extra wing image must match the first, its response the core")
    _compose_kernel(np.ascontiguousarray(core, np.float64), float(share), np.ascontiguousarray(wc, np.float64),
                    int(s), float(eta), bg, scale, use_bg, np.ascontiguousarray(resp, np.float32), wc2, resp2, use2,
                    out)
    return out


def wings(image, glare: GlareParams, backend=None) -> np.ndarray:
    """The wing PSF applied to a pixel image (unit-sum kernel; multiply by the share), float64.

    Coarse grid: tent binning, FFT convolution (:func:`wings_coarse`), tent spreading back
    (first moments kept; the spreading is the tent binning's transpose, a linear interpolation,
    done by ``cv2.resize``). ``backend``: the array backend of the FFT convolution
    (:mod:`svgs_sim.camera.backend`)."""
    f = np.asarray(image, np.float64)
    H, W = f.shape
    wc, s = wings_coarse(f, glare, backend=backend)
    if s == 1:
        return wc
    # the transpose of the tent binning: fine x reads coarse (x - (s - 1) / 2) / s, linearly,
    # clamped at the ends - cv2.resize's INTER_LINEAR on an exact s-fold grid, cropped
    Hc, Wc = wc.shape
    fine = cv2.resize(wc, (Wc * s, Hc * s), interpolation=cv2.INTER_LINEAR)
    return fine[:H, :W]


@functools.lru_cache(maxsize=4)
def _tent_pair(H: int, W: int, s: int):
    return tent_matrix(H, s), tent_matrix(W, s)


#: How point samples are convolved with the core PSF: ``"grid"`` (deterministic,
#: :meth:`CorePSF.splat`, the default) or ``"monte-carlo"`` (:meth:`CorePSF.splat_monte_carlo`,
#: the earlier path, kept as the reference the grid is tested against).
POINT_METHODS = ("grid", "monte-carlo")


def core_image(flux, core, points=None, rng: np.random.Generator | None = None, *,
               min_draws: int | None = None, method: str = "grid", backend=None) -> np.ndarray:
    """The core PSF applied to a pixel image and to point samples, integrated over pixels
    (unit share; float64 (H, W)). ``core``: a :class:`CorePSF`, or a float (a Gaussian core of
    that sigma, px, on the pixel image and the points binned: the earlier order, for
    comparisons). ``method``: one of :data:`POINT_METHODS`; ``rng`` and ``min_draws`` (the
    points' PSF draws in all) apply to ``"monte-carlo"`` only."""
    if method not in POINT_METHODS:
        raise ValueError(f"method: expected one of {POINT_METHODS}, got {method!r}")
    f = np.ascontiguousarray(flux, np.float32)
    H, W = f.shape
    has_points = points is not None and len(points) > 0
    if isinstance(core, CorePSF):
        # the convolution of an empty image is empty (point-only images: the CRLB, the tests)
        out = core.convolve(f, backend=backend).astype(np.float64) if f.any() else np.zeros((H, W))
        if has_points:
            if method == "grid":
                out += core.splat(points.u_px, points.v_px, points.rate_ph_s, (H, W))
            else:
                rng = np.random.default_rng(0) if rng is None else rng
                kw = {} if min_draws is None else {"min_draws": int(min_draws)}
                out += core.splat_monte_carlo(points.u_px, points.v_px, points.rate_ph_s, (H, W), rng, **kw)
        return out
    sig = float(core)
    g = f + points.binned((H, W)).astype(np.float32) if has_points else f
    return (cv2.GaussianBlur(g, (0, 0), sigmaX=sig, sigmaY=sig, borderType=cv2.BORDER_CONSTANT)
            if sig > 0 else g.copy()).astype(np.float64)


def glare_source(flux, points=None) -> np.ndarray:
    """The light the glare spreads: the pixel image plus the points' bilinear image (over
    their bounding box), float64 (H, W)."""
    whole = np.array(flux, np.float64)
    H, W = whole.shape
    box = _points_box(points, H, W)
    if box is not None:
        y0, y1, x0, x1 = box
        whole[y0:y1, x0:x1] += bilinear_splat(points.u_px, points.v_px, points.rate_ph_s, x0, y0, x1 - x0, y1 - y0)
    return whole


def glare_image(flux, glare: GlareParams, principal_point=None, points=None, backend=None) -> np.ndarray | None:
    """The glare wings and ghosts of a pixel image and point samples, with their shares
    (float64 (H, W)); None when the lens has neither."""
    eta = glare.veiling_fraction
    if eta <= 0 and not glare.ghosts:
        return None
    whole = glare_source(flux, points)
    H, W = whole.shape
    if eta > 0:
        out = wings(whole, glare, backend)
        out *= eta
    else:
        out = np.zeros((H, W))
    if glare.ghosts:
        cx, cy = principal_point if principal_point is not None else ((W - 1) / 2.0, (H - 1) / 2.0)
        w32 = whole.astype(np.float32)
        for frac, scale, blur in glare.ghosts:
            A = np.array([[scale, 0.0, cx * (1 - scale)], [0.0, scale, cy * (1 - scale)]], np.float32)
            g = cv2.warpAffine(w32, A, (W, H), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
            g /= scale * scale  # warpAffine samples: keep the energy
            if blur > 0:
                g = cv2.GaussianBlur(g, (0, 0), sigmaX=blur, sigmaY=blur, borderType=cv2.BORDER_CONSTANT)
            out += frac * g
    return out


def core_share(glare: GlareParams) -> float:
    """Share of the light in the PSF's core (the rest is in the wings and ghosts)."""
    return 1.0 - glare.veiling_fraction - sum(g[0] for g in glare.ghosts)


def apply_psf(flux: np.ndarray, glare: GlareParams, core, principal_point=None, *, points=None,
              rng: np.random.Generator | None = None, method: str = "grid", backend=None) -> np.ndarray:
    """The optical image: a flux image (and point samples) through the lens PSF, integrated
    over pixels.

    Parameters
    ----------
    flux : ndarray, shape (H, W)
        Light already integrated over pixels (any linear unit per pixel; the diffuse part).
    glare : GlareParams
    core : CorePSF or float
        The core PSF (:func:`core_psf`); a float is a Gaussian core of that sigma (px), kept
        for comparisons with the earlier model.
    principal_point : (cx, cy), optional
        Centre of the ghost images (default: image centre).
    points : svgs_sim.camera.rendered.PointFlux, optional
        Light at exact sub-pixel film positions (the same unit per sample).
    rng : numpy.random.Generator, optional
        Draws of the Monte Carlo convolution of the points (``method="monte-carlo"``; default
        seed 0).
    method : str
        How the points meet the core PSF (:data:`POINT_METHODS`; default the deterministic grid).
    backend : str or svgs_sim.camera.backend.Backend, optional
        Array backend of the convolutions (default: the CPU, or ``$SVGS_ARRAY_BACKEND``).

    Returns
    -------
    ndarray, float32, shape (H, W)
    """
    out = core_share(glare) * core_image(flux, core, points, rng, method=method, backend=backend)
    g = glare_image(flux, glare, principal_point, points, backend)
    if g is not None:
        out += g
    return out.astype(np.float32)
