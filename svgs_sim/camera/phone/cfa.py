"""The colour filter array: a Bayer mosaic over the pixels, and the ISP's demosaic to luminance.

The phones' sensors are colour sensors: each pixel sits under a red, green or blue filter
(a Bayer mosaic, :data:`svgs_sim.camera.phone.params.CFA_PATTERNS`). A retro spot one or two pixels
wide is sampled by that mosaic, and the ISP's demosaic interpolates the missing colours from
the neighbours before the app thresholds the luminance, so both move the spot's centroid
(``docs/pixel-phase.md``).

Model (ASSUMPTIONS, documented in each profile's ``[sources]``):

- each channel collects ``response[c]`` times the mono model's photoelectrons from the flash's
  white light (``[cfa] response``, R, G, B), its optical image drawn with the Airy pattern at
  the channel's mean wavelength (``[cfa] wavelength_nm``);
- the ISP removes the black level, white-balances (divides each channel by its response, so
  white light gives equal R, G, B), demosaics with OpenCV (``cv2.demosaicing``: bilinear,
  edge-aware or VNG) and takes the luminance ``Y = 0.299 R + 0.587 G + 0.114 B`` (ITU-R
  BT.601, OpenCV's ``COLOR_BGR2GRAY``), which the tone curve then encodes to 8 bits.
"""

from __future__ import annotations

import functools

import cv2
import numpy as np
from numba import njit, prange

from svgs_sim.camera.phone.params import CfaParams

#: OpenCV's code for each layout (OpenCV names a Bayer pattern by the second row's colours).
_CV_CODES = {"RGGB": "BG", "BGGR": "RG", "GRBG": "GB", "GBRG": "GR"}
_COLOURS = {"R": 0, "G": 1, "B": 2}
#: Luminance weights (R, G, B), ITU-R BT.601.
LUMA = (0.299, 0.587, 0.114)


#: Width of the colour filters' edges, nm: each edge is a logistic step of this scale (10-90 %
#: over 4.4 times it, 40 nm). ASSUMPTION, as the edges' places (:func:`filter_transmission`):
#: phone Bayer filters cross over within a few tens of nm (published transmission curves,
#: recalled, not measured for these sensors). A light's channel weights (:func:`light_weights`)
#: move by under 3 % for 5-15 nm (tested).
FILTER_EDGE_NM = 9.0


def filter_transmission(cfa: CfaParams, wavelength_nm, edge_nm: float = FILTER_EDGE_NM) -> np.ndarray:
    """The colour filters' relative transmission, float64 (3, n) (R, G, B).

    The filters share the band out (they sum to 1 at every wavelength, as the mono model counts
    every in-band photon): blue below, green between and red above two edges, logistic steps of
    scale ``edge_nm`` at the midpoints of the channels' mean wavelengths (``[cfa] wavelength_nm``;
    497.5 and 567.5 nm for 600, 535, 460). ASSUMPTION (:data:`FILTER_EDGE_NM`); under the flash
    (``render/optics.py WHITE_LED``) these filters' photon-weighted mean wavelengths are 604, 539 and
    459 nm, the profile's 600, 535 and 460 within 4 nm.
    """
    wl = np.asarray(wavelength_nm, np.float64)
    r, g, b = (float(x) for x in cfa.wavelength_nm)
    step_bg = 1.0 / (1.0 + np.exp(-(wl - 0.5 * (b + g)) / float(edge_nm)))  # 0 -> 1 from blue to green
    step_gr = 1.0 / (1.0 + np.exp(-(wl - 0.5 * (g + r)) / float(edge_nm)))  # 0 -> 1 from green to red
    return np.stack([step_gr, step_bg - step_gr, 1.0 - step_bg])


def light_weights(cfa: CfaParams, wavelength_nm, photons_light, photons_reference,
                  edge_nm: float = FILTER_EDGE_NM) -> np.ndarray:
    """Each channel's response to a light of another colour, relative to its response to the
    reference light (the flash) for the same in-band photons.

    ``[cfa] response`` is what each channel collects from the flash per mono photon; a light of
    another spectrum (the sun, the Earth's light) gives channel ``c``

    ``w_c = (int N_l T_c / int N_l) / (int N_r T_c / int N_r)``

    times that (``N`` photons per nm over the band, ``T_c`` the filter,
    :func:`filter_transmission`): the camera model multiplies that light's part of each pixel
    of colour ``c`` by ``w_c``. The reference itself gives ``(1, 1, 1)``.

    Parameters
    ----------
    cfa : CfaParams
    wavelength_nm : array_like, shape (n,)
        The grid over the band, nm.
    photons_light, photons_reference : array_like, shape (n,)
        Photon spectral densities (any scale each) on that grid.
    edge_nm : float
        The filters' edge scale (:data:`FILTER_EDGE_NM`).

    Returns
    -------
    ndarray, float64, shape (3,)
        ``w_R, w_G, w_B``.
    """
    wl = np.asarray(wavelength_nm, np.float64)
    t = filter_transmission(cfa, wl, edge_nm)
    shares = []
    for n in (photons_light, photons_reference):
        n = np.asarray(n, np.float64)
        if n.shape != wl.shape or not np.all(np.isfinite(n)) or n.min() < 0 or not np.trapezoid(n, wl) > 0:
            raise ValueError("light_weights: expected finite, non-negative photon spectra on the grid, not all zero")
        shares.append(np.trapezoid(t * n, wl, axis=1) / np.trapezoid(n, wl))
    return shares[0] / shares[1]


def channel_map(pattern: str, shape) -> np.ndarray:
    """Colour index (0 R, 1 G, 2 B) of every pixel, uint8 (H, W); read-only (cached)."""
    return _channel_map(str(pattern), int(shape[0]), int(shape[1]))


@functools.lru_cache(maxsize=8)
def _channel_map(pattern: str, H: int, W: int) -> np.ndarray:
    block = np.array([[_COLOURS[pattern[0]], _COLOURS[pattern[1]]], [_COLOURS[pattern[2]], _COLOURS[pattern[3]]]],
                     np.uint8)
    out = np.tile(block, (-(-H // 2), -(-W // 2)))[:H, :W].copy()
    out.setflags(write=False)
    return out


def response_map(cfa: CfaParams, shape) -> np.ndarray:
    """Each pixel's channel response (relative to the mono qe), float32 (H, W); read-only
    (cached: a frame's optics and its bound use it for every exposure)."""
    return _response_map(tuple(float(r) for r in cfa.response), str(cfa.pattern), int(shape[0]), int(shape[1]))


@functools.lru_cache(maxsize=8)
def _response_map(response: tuple, pattern: str, H: int, W: int) -> np.ndarray:
    out = np.asarray(response, np.float32)[_channel_map(pattern, H, W)]
    out.setflags(write=False)
    return out


def natural_response_map(cfa, excess, shape) -> np.ndarray:
    """Each pixel's response to light of another colour beyond the flash's: ``response[c] *
    excess[c]`` for a pixel of colour ``c``, float32 (H, W); read-only (cached)."""
    resp = tuple(float(r) * float(e) for r, e in zip(cfa.response, excess))
    return _response_map(resp, str(cfa.pattern), int(shape[0]), int(shape[1]))


def demosaic_code(cfa: CfaParams, method: str | None = None) -> int:
    """The ``cv2.cvtColor`` code that demosaics this layout to BGR with ``method`` (default the
    profile's ``[cfa] demosaic``; :data:`svgs_sim.camera.phone.params.DEMOSAIC_METHODS`)."""
    suffix = {"bilinear": "", "edge_aware": "_EA", "vng": "_VNG"}[cfa.demosaic if method is None else method]
    return getattr(cv2, f"COLOR_Bayer{_CV_CODES[cfa.pattern]}2BGR{suffix}")


def demosaic(raw: np.ndarray, cfa: CfaParams, white_dn: float, method: str | None = None) -> np.ndarray:
    """OpenCV's demosaic of a uint16 mosaic to BGR.

    Parameters
    ----------
    raw : ndarray, uint16, shape (H, W)
        The mosaic (DN).
    cfa : CfaParams
    white_dn : float
        The ADC's white level (VNG takes 8-bit input only: the top 8 bits of the ADC's range go
        through it and are scaled back).
    method : str, optional
        ``"bilinear"``, ``"edge_aware"`` or ``"vng"``; default the profile's ``[cfa] demosaic``.

    Returns
    -------
    ndarray, shape (H, W, 3): uint16 (float32 for VNG), DN
    """
    m = cfa.demosaic if method is None else method
    if m == "vng":
        shift = max(0, int(np.ceil(np.log2(white_dn + 1))) - 8)
        return cv2.cvtColor((raw >> shift).astype(np.uint8), demosaic_code(cfa, m)).astype(np.float32) * (1 << shift)
    return cv2.cvtColor(raw, demosaic_code(cfa, m))


def linear_bgr(raw_dn: np.ndarray, cfa: CfaParams, black_dn: float, white_dn: float,
               method: str | None = None) -> np.ndarray:
    """The ISP from the raw mosaic to white-balanced linear colour: demosaic, black level, white
    balance, each channel clipped to white.

    Parameters
    ----------
    raw_dn : ndarray, shape (H, W)
        ADC output (DN) of the mosaic.
    cfa : CfaParams
    black_dn, white_dn : float
    method : str, optional
        The demosaic (default the profile's).

    Returns
    -------
    ndarray, float32, shape (H, W, 3)
        B, G, R (OpenCV's order) as fractions of white, in [0, 1].
    """
    raw = np.clip(np.rint(raw_dn), 0, 65535).astype(np.uint16)
    bgr = demosaic(raw, cfa, white_dn, method).astype(np.float32)
    span = float(white_dn - black_dn)
    for c_bgr, c in ((2, 0), (1, 1), (0, 2)):  # BGR planes -> R, G, B
        ch = bgr[..., c_bgr]
        ch -= black_dn
        ch /= span * cfa.response[c]
        np.clip(ch, 0.0, 1.0, out=ch)
    return bgr


def luminance(raw_dn: np.ndarray, cfa: CfaParams, black_dn: float, white_dn: float,
              method: str | None = None) -> np.ndarray:
    """The ISP from the raw mosaic to linear luminance.

    Parameters
    ----------
    raw_dn : ndarray, shape (H, W)
        ADC output (DN) of the mosaic.
    cfa : CfaParams
    black_dn, white_dn : float
    method : str, optional
        The demosaic (default the profile's).

    Returns
    -------
    ndarray, float32, shape (H, W)
        Luminance as a fraction of white, in [0, 1] (a channel that white balance lifts above
        white is clipped there, as an ISP does).
    """
    bgr = linear_bgr(raw_dn, cfa, black_dn, white_dn, method)
    out = np.zeros(bgr.shape[:2], np.float32)
    for c_bgr, c in ((2, 0), (1, 1), (0, 2)):  # BGR planes -> R, G, B
        out += np.float32(LUMA[c]) * bgr[..., c_bgr]
    return out


@njit(parallel=True, cache=True)
def _plane_lut_kernel(bgr, luts, out):
    """Per pixel and channel: that channel's table at the pixel's DN (clamped to the table)."""
    H, W = out.shape[0], out.shape[1]
    n = luts.shape[1]
    for r in prange(H):
        for c in range(W):
            for k in range(3):
                v = bgr[r, c, k]
                out[r, c, k] = luts[k, v if v < n else n - 1]


def tone_bgr(raw_dn: np.ndarray, cfa: CfaParams, black_dn: float, white_dn: float, gamma: float,
             method: str | None = None, u8: bool = False) -> np.ndarray:
    """The ISP from the raw mosaic to a toned colour image: demosaic, black level, white balance,
    each channel clipped to white, then the tone curve on each channel (what a colour ISP hands
    to its YCbCr encoder).

    Parameters
    ----------
    raw_dn : ndarray, shape (H, W)
    cfa : CfaParams
    black_dn, white_dn : float
    gamma : float
        ``out = 255 lin^(1/gamma)`` (0: linear).
    method : str, optional
        The demosaic (default the profile's).
    u8 : bool
        Rounded to 8 bits (else float32, not rounded).

    Returns
    -------
    ndarray, shape (H, W, 3)
        B, G, R on the 0-255 scale: float32, or uint8 with ``u8``.
    """
    raw = np.clip(np.rint(raw_dn), 0, 65535).astype(np.uint16)
    bgr = demosaic(raw, cfa, white_dn, method)
    bgr16 = bgr if bgr.dtype == np.uint16 else np.clip(np.rint(bgr), 0, 65535).astype(np.uint16)
    span = float(white_dn - black_dn)
    dn = np.arange(int(white_dn) + 1, dtype=np.float64)
    luts = np.empty((3, dn.size))
    for c_bgr, c in ((2, 0), (1, 1), (0, 2)):
        lin = np.clip((dn - black_dn) / (span * cfa.response[c]), 0.0, 1.0)
        luts[c_bgr] = 255.0 * (lin ** (1.0 / gamma) if gamma > 0 else lin)
    if u8:
        luts, out = np.rint(luts).astype(np.uint8), np.empty(bgr16.shape, np.uint8)
    else:
        luts, out = luts.astype(np.float32), np.empty(bgr16.shape, np.float32)
    _plane_lut_kernel(np.ascontiguousarray(bgr16), luts, out)
    return out


@njit(parallel=True, cache=True)
def _luma_tone_kernel(bgr, plane_luts, lut, out8):
    """Per pixel: the three planes' white-balanced, clipped, luminance-weighted values from
    their tables (in DN of luminance), summed, then the tone LUT."""
    H, W = out8.shape
    nl = lut.shape[0]
    npl = plane_luts.shape[1]
    for r in prange(H):
        for c in range(W):
            y = 0.0
            for k in range(3):
                v = bgr[r, c, k]
                y += plane_luts[k, v if v < npl else npl - 1]
            i = int(y + 0.5)
            out8[r, c] = lut[i if i < nl else nl - 1]


def tone_image(raw_dn: np.ndarray, cfa: CfaParams, black_dn: float, white_dn: float, lut: np.ndarray,
               method: str | None = None) -> np.ndarray:
    """The ISP from the raw mosaic to the 8-bit image in one pass after OpenCV's demosaic
    (``method``, default the profile's): :func:`luminance` followed by the tone LUT (indexed by
    DN, as the mono path's).

    Returns
    -------
    ndarray, uint8, shape (H, W)
    """
    raw = raw_dn.astype(np.uint16)  # the ADC's output: whole DN in [0, white]
    bgr = demosaic(raw, cfa, white_dn, method)
    span = float(white_dn - black_dn)
    dn = np.arange(int(white_dn) + 1, dtype=np.float64)
    planes = np.empty((3, dn.size))
    for k, c in enumerate((2, 1, 0)):  # BGR planes -> R, G, B response and weight
        planes[k] = LUMA[c] * np.clip((dn - black_dn) / (span * cfa.response[c]), 0.0, 1.0) * span
    planes[0] += black_dn  # the sum is then a DN index into the tone LUT
    out8 = np.empty(raw.shape, np.uint8)
    bgr16 = bgr if bgr.dtype == np.uint16 else np.clip(np.rint(bgr), 0, 65535).astype(np.uint16)
    _luma_tone_kernel(bgr16, planes, np.ascontiguousarray(lut, np.uint8), out8)
    return out8
