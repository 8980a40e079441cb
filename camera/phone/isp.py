"""Phone image processing: auto-exposure, tone curve, 8-bit output, downscale, JPEG.

Auto-exposure as Android 4-era phones did it: meter the scene (mean, centre-weighted or
spot), then choose the exposure time first and the ISO second so that the metered linear
level reaches ``target_level * 2^compensation_ev``, within the phone's limits. The metered
level is computed from the noise-free signal with full-well clipping, from a weighted
histogram of the per-pixel signal in 4096 log bins (exact to within one bin).
"""

from __future__ import annotations

import functools
import math

import cv2
import numpy as np
from numba import njit

from svgs.errors import InputError

from camera.phone.params import ExposureParams, SensorParams
from camera.tonemap import gamma_u8


def metering_weights(shape, mode: str) -> np.ndarray:
    """Metering weight map (sums to 1), float64, shape (H, W); read-only (one map per shape and
    mode is kept: a stream meters every frame with it)."""
    return _metering_weights(tuple(int(x) for x in shape), str(mode))


@functools.lru_cache(maxsize=8)
def _metering_weights(shape, mode: str) -> np.ndarray:
    w = _metering_weights_uncached(shape, mode)
    w.setflags(write=False)
    return w


def _metering_weights_uncached(shape, mode: str) -> np.ndarray:
    H, W = shape
    if mode == "mean":
        return np.full(shape, 1.0 / (H * W))
    y, x = np.mgrid[0:H, 0:W]
    r2 = ((x - (W - 1) / 2) / W) ** 2 + ((y - (H - 1) / 2) / H) ** 2
    if mode == "center_weighted":
        w = np.exp(-r2 / (2 * 0.2**2))  # ~60 % of the weight in the central third
    elif mode == "spot":
        w = (r2 <= 0.05**2).astype(float)  # central disk, ~1 % of the frame
    else:
        raise InputError(f"metering: unknown mode {mode!r}")
    return w / w.sum()


@njit(cache=True)
def _log_bins(r, w, lo, hi, n_bins, w_bin, wr_bin):
    """Add ``w`` and ``w * r`` of every pixel into its bin of ``log r`` over ``[lo, hi]``
    (``n_bins`` bins, the ends clipped), in pixel order; ``r > 0`` everywhere."""
    for i in range(r.size):
        ri = r[i]
        k = int((math.log(ri) - lo) / (hi - lo) * n_bins)
        if k < 0:
            k = 0
        elif k > n_bins - 1:
            k = n_bins - 1
        w_bin[k] += w[i]
        wr_bin[k] += w[i] * ri


class ExposureSolver:
    """Metered level as a function of the exposure product, from one noise-free signal map.

    Parameters
    ----------
    rate : ndarray, shape (H, W)
        Linear signal per unit exposure product ``S = t * ISO / base_ISO`` (fraction of
        the ADC's white level per second at base ISO), noise-free.
    weights : ndarray, shape (H, W)
        Metering weights, summing to 1.
    """

    def __init__(self, rate: np.ndarray, weights: np.ndarray, n_bins: int = 4096):
        r = np.ascontiguousarray(rate, np.float64).ravel()
        w = np.ascontiguousarray(weights, np.float64).ravel()
        pos = r > 0
        if pos.all():  # the usual case (dark current): no copies
            self.w_zero = 0.0
        else:
            self.w_zero = float(w[~pos].sum())
            r, w = r[pos], w[pos]
        if r.size == 0:
            self.edges = None
            return
        lo, hi = np.log(r.min()), np.log(r.max())
        if hi - lo < 1e-9:
            hi = lo + 1e-9
        edges = np.linspace(lo, hi, n_bins + 1)
        # one pass over the pixels: the same bins and sums (in pixel order) as
        # np.bincount(idx, weights=...) of idx = clip(((log r - lo) / (hi - lo) * n).astype(int))
        self.w_bin = np.zeros(n_bins)
        self.wr_bin = np.zeros(n_bins)
        _log_bins(r, w, float(lo), float(hi), int(n_bins), self.w_bin, self.wr_bin)
        self.edges = np.exp(edges)
        # suffix sums: weight above bin k (clipped) and prefix sums of w*r below (linear)
        self.w_above = np.concatenate([np.cumsum(self.w_bin[::-1])[::-1], [0.0]])
        self.wr_below = np.concatenate([[0.0], np.cumsum(self.wr_bin)])

    def level(self, S: float) -> float:
        """Metered linear level (0..1) at exposure product ``S``."""
        if self.edges is None or S <= 0:
            return 0.0
        # bins whose lower edge is above 1/S clip; the bin straddling 1/S counts linearly
        k = int(np.searchsorted(self.edges, 1.0 / S, side="right")) - 1
        k = min(max(k, 0), len(self.w_bin))
        clipped = self.w_above[k + 1] if k + 1 < len(self.w_above) else 0.0
        linear = S * self.wr_below[k + 1] if k + 1 < len(self.wr_below) else S * self.wr_below[-1]
        return float(min(clipped + linear, 1.0))

    def solve(self, target: float, S_min: float, S_max: float) -> float:
        """Exposure product that meters ``target``, clamped to [S_min, S_max]."""
        if self.level(S_max) <= target:
            return S_max
        if self.level(S_min) >= target:
            return S_min
        a, b = math.log(S_min), math.log(S_max)
        for _ in range(60):
            m = 0.5 * (a + b)
            if self.level(math.exp(m)) < target:
                a = m
            else:
                b = m
        return math.exp(0.5 * (a + b))


def split_exposure(S: float, exp: ExposureParams, base_iso: float) -> tuple[float, float]:
    """Exposure time first, then ISO: (exposure_s, iso) giving the product ``S``."""
    t = min(max(S * base_iso / exp.min_iso, exp.min_exposure_s), exp.max_exposure_s)
    iso = min(max(S * base_iso / t, exp.min_iso), exp.max_iso)
    return t, iso


def metered_target(exp: ExposureParams) -> float:
    """The linear level the auto-exposure aims at: ``target_level * 2^compensation_ev`` (at most 1)."""
    return min(exp.target_level * 2.0**exp.compensation_ev, 1.0)


def exposure_limits(sensor: SensorParams, exp: ExposureParams) -> tuple[float, float]:
    """Smallest and largest exposure product ``t * ISO / base_ISO`` the phone allows."""
    return exp.min_exposure_s * exp.min_iso / sensor.base_iso, exp.max_exposure_s * exp.max_iso / sensor.base_iso


def auto_exposure(flux_ph_s: np.ndarray, sensor: SensorParams, exp: ExposureParams, solver: ExposureSolver | None = None):
    """Auto-exposure on a noise-free flux image (photons/s/px, after the optics).

    Returns
    -------
    exposure_s : float
    iso : float
    info : dict
        ``metered_level``, ``target_level``, ``limited`` (True when the phone's limits stopped
        it short of the target), ``exposure_product``.
    """
    if solver is None:
        rate = (sensor.qe * flux_ph_s + sensor.dark_current_e_s) / sensor.full_well_e  # fraction of white per s at base ISO
        solver = ExposureSolver(rate, metering_weights(flux_ph_s.shape, exp.metering))
    target = metered_target(exp)
    S = solver.solve(target, *exposure_limits(sensor, exp))
    t, iso = split_exposure(S, exp, sensor.base_iso)
    lvl = solver.level(t * iso / sensor.base_iso)
    return t, iso, {
        "metered_level": lvl,
        "target_level": target,
        "limited": bool(abs(lvl - target) > 0.01 * target),
        "exposure_product": t * iso / sensor.base_iso,
    }


#: Share of the metered error, in log exposure, that the phone's auto-exposure corrects per
#: frame when it runs on a stream (ASSUMPTION: phone 3A loops settle in a few frames rather than
#: jumping to the new level; 0.5 leaves 10 % of a step change after 3.3 frames).
AE_STREAM_GAIN = 0.5


def next_exposure(exposure_s: float, iso: float, metered_level: float, sensor: SensorParams, exp: ExposureParams,
                  gain: float = AE_STREAM_GAIN) -> tuple[float, float]:
    """The auto-exposure's settings for the next frame of a stream, from this frame's.

    The metered level of the frame just taken (``metered_level``, 0..1, at ``exposure_s`` and
    ``iso``) is compared with the target; the exposure product moves by ``gain`` of the error
    in log units, ``S' = S (target / level)^gain``, within the phone's limits, and is split into
    time first, then ISO (:func:`split_exposure`).

    Returns
    -------
    exposure_s, iso : float
    """
    S = float(exposure_s) * float(iso) / sensor.base_iso
    target = metered_target(exp)
    S_min, S_max = exposure_limits(sensor, exp)
    if metered_level <= 0:
        S_next = S_max
    else:
        S_next = S * (target / float(metered_level)) ** float(gain)
    S_next = min(max(S_next, S_min), S_max)
    return split_exposure(S_next, exp, sensor.base_iso)


def stream_exposure(exposure_s: float, iso: float, level_of_product, sensor: SensorParams, exp: ExposureParams,
                    steps: int, gain: float = AE_STREAM_GAIN) -> tuple[float, float]:
    """``steps`` frames of the stream's auto-exposure loop (:func:`next_exposure`) on one scene.

    Parameters
    ----------
    exposure_s, iso : float
        The settings of the frame the loop starts from.
    level_of_product : callable
        The scene's metered level (0..1) at an exposure product ``S = t ISO / base_ISO``
        (:meth:`ExposureSolver.level`).
    steps : int
        Stream frames (>= 0).

    Returns
    -------
    exposure_s, iso : float
    """
    t, g = float(exposure_s), float(iso)
    for _ in range(int(steps)):
        t, g = next_exposure(t, g, level_of_product(t * g / sensor.base_iso), sensor, exp, gain)
    return t, g


def tone_lut(sensor: SensorParams, gamma: float, tone: bool) -> np.ndarray:
    """Raw DN (0..2^bits-1) -> 8-bit output, as a lookup table of uint8."""
    dn = np.arange(int(sensor.white_dn) + 1, dtype=np.float64)
    lin = np.clip((dn - sensor.black_level_dn) / (sensor.white_dn - sensor.black_level_dn), 0.0, 1.0)
    return gamma_u8(lin, gamma if tone else 0.0)


def downscale(image: np.ndarray, width: int, height: int) -> np.ndarray:
    """Area-averaging downscale to (width, height) (what a preview stream does)."""
    return cv2.resize(image, (int(width), int(height)), interpolation=cv2.INTER_AREA)


def jpeg_roundtrip(image: np.ndarray, quality: int) -> np.ndarray:
    """Encode as JPEG at ``quality`` and decode again (OpenCV)."""
    ok, buf = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:  # pragma: no cover - OpenCV always encodes uint8 grey
        raise RuntimeError("JPEG encoding failed")
    return cv2.imdecode(buf, cv2.IMREAD_UNCHANGED)
