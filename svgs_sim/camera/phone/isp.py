"""Phone image processing: auto-exposure, tone curve, 8-bit output, downscale, noise
reduction, sharpening, JPEG.

Auto-exposure as Android 4-era phones did it: meter the scene (mean, centre-weighted or
spot), then choose the exposure time first and the ISO second so that the metered linear
level reaches ``target_level * 2^compensation_ev``, within the phone's limits. The metered
level is computed from the noise-free signal with full-well clipping, from a weighted
histogram of the per-pixel signal in 4096 log bins (exact to within one bin).
"""

from __future__ import annotations

import functools
import math
from concurrent.futures import ThreadPoolExecutor

import cv2
import numpy as np
from numba import njit, prange

from svgs_sim.base.errors import InputError
from svgs_sim.camera.phone.params import ExposureParams, SensorParams, check_grid_offset, check_subsampling
from svgs_sim.camera.tonemap import gamma_u8


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


#: Pixel chunks the meter's histogram is built over (each in pixel order, then added in chunk
#: order: the same sums whatever the number of threads).
METER_CHUNKS = 64


@njit(parallel=True, cache=True)
def _meter_range(x, a, b, c, n_chunks):
    """Smallest and largest positive ``r = (a x + b) / c`` over ``x`` (flat), and whether any is."""
    n = x.size
    mins = np.full(n_chunks, np.inf)
    maxs = np.full(n_chunks, -np.inf)
    for j in prange(n_chunks):
        lo, hi = np.inf, -np.inf
        for i in range(j * n // n_chunks, (j + 1) * n // n_chunks):
            r = (a * x[i] + b) / c
            if r > 0.0:
                if r < lo:
                    lo = r
                if r > hi:
                    hi = r
        mins[j] = lo
        maxs[j] = hi
    return mins.min(), maxs.max()


@njit(parallel=True, cache=True)
def _meter_bins(x, a, b, c, w, w_const, lo, hi, n_bins, n_chunks, w_bin, wr_bin, w_zero):
    """Add ``w`` and ``w * r`` of every pixel (``r = (a x + b) / c``; ``w`` per pixel, or
    ``w_const`` for all when ``w`` is empty) into its bin of ``log r`` over ``[lo, hi]`` (the ends
    clipped), one histogram per chunk of pixels (rows of ``w_bin``, ``wr_bin``), in pixel order;
    the weight of pixels with ``r <= 0`` into ``w_zero`` per chunk."""
    n = x.size
    const = w.size == 0
    scale = n_bins / (hi - lo)
    for j in prange(n_chunks):
        for i in range(j * n // n_chunks, (j + 1) * n // n_chunks):
            r = (a * x[i] + b) / c
            wi = w_const if const else w[i]
            if r <= 0.0:
                w_zero[j] += wi
                continue
            k = int((math.log(r) - lo) * scale)
            if k < 0:
                k = 0
            elif k > n_bins - 1:
                k = n_bins - 1
            w_bin[j, k] += wi
            wr_bin[j, k] += wi * r


@njit(cache=True)
def _bin_of(x, a, b, c, lo, scale, n_bins):
    """The log bin of ``r = (a x + b) / c`` (``r > 0``), as :func:`_meter_bins` computes it."""
    r = (a * x + b) / c
    k = int((math.log(r) - lo) * scale)
    if k < 0:
        k = 0
    elif k > n_bins - 1:
        k = n_bins - 1
    return k


@njit(cache=True)
def _bin_tables(b_lo, b_hi, shift, a, b, c, lo, scale, n_bins):
    """The tables of :func:`_meter_bins_f32`: the bin of the first float32 of each cell of
    ``2^shift`` bit patterns over ``[b_lo, b_hi]`` (non-negative float32 bit patterns, whose order
    is their values'), and the first bit pattern of each bin (bisection; the bin is a
    non-decreasing function of the pattern)."""
    buf = np.zeros(1, np.int32)
    val = buf.view(np.float32)
    c0 = b_lo >> shift
    n_cells = (b_hi >> shift) - c0 + 1
    cell_bin = np.empty(n_cells, np.int32)
    for i in range(n_cells):
        buf[0] = max((c0 + i) << shift, b_lo)
        cell_bin[i] = _bin_of(np.float64(val[0]), a, b, c, lo, scale, n_bins)
    first = np.full(n_bins + 1, b_hi + 1, np.int64)  # bins above the last pixel's: never reached
    buf[0] = b_lo
    k_lo = _bin_of(np.float64(val[0]), a, b, c, lo, scale, n_bins)
    buf[0] = b_hi
    k_hi = _bin_of(np.float64(val[0]), a, b, c, lo, scale, n_bins)
    for k in range(k_lo + 1, k_hi + 1):  # the smallest pattern in [b_lo, b_hi] whose bin is >= k
        lo_b, hi_b = b_lo, b_hi
        while lo_b < hi_b:
            mid = (lo_b + hi_b) // 2
            buf[0] = mid
            if _bin_of(np.float64(val[0]), a, b, c, lo, scale, n_bins) >= k:
                hi_b = mid
            else:
                lo_b = mid + 1
        first[k] = lo_b
    return cell_bin, first


@njit(parallel=True, cache=True)
def _meter_bins_f32(x, bits, a, b, c, w, w_const, shift, c0, cell_bin, first, n_bins, n_chunks, w_bin, wr_bin):
    """:func:`_meter_bins` for a float32 image whose every ``r`` is positive, without a
    logarithm per pixel: the bin from the tables of :func:`_bin_tables` (a cell's first bin,
    then up while the pattern reaches the next bin's first). The same bins, the same sums in
    the same order (``tests/test_phone_meter.py``)."""
    n = x.size
    const = w.size == 0
    for j in prange(n_chunks):
        for i in range(j * n // n_chunks, (j + 1) * n // n_chunks):
            bi = np.int64(bits[i])
            k = cell_bin[(bi >> shift) - c0]
            while bi >= first[k + 1]:
                k += 1
            r = (a * x[i] + b) / c
            wi = w_const if const else w[i]
            w_bin[j, k] += wi
            wr_bin[j, k] += wi * r


#: Float32 bit patterns per cell of the meter's bin table (:func:`_bin_tables`): 2^15, 256 cells
#: an octave.
METER_CELL_SHIFT = 15


class ExposureSolver:
    """Metered level as a function of the exposure product, from one noise-free signal map.

    Parameters
    ----------
    rate : ndarray, shape (H, W)
        Linear signal per unit exposure product ``S = t * ISO / base_ISO`` (fraction of
        the ADC's white level per second at base ISO), noise-free.
    weights : ndarray, shape (H, W)
        Metering weights, summing to 1.

    :meth:`from_flux` meters a flux image directly (the rate computed pixel by pixel in the
    same pass, no full-frame temporaries).
    """

    def __init__(self, rate: np.ndarray, weights: np.ndarray, n_bins: int = 4096):
        r = np.ascontiguousarray(rate, np.float64).ravel()
        w = np.ascontiguousarray(weights, np.float64).ravel()
        self._build(r, 1.0, 0.0, 1.0, w, 0.0, n_bins)

    @classmethod
    def from_flux(cls, flux_ph_s: np.ndarray, sensor: SensorParams, metering: str, n_bins: int = 4096):
        """The meter of a noise-free flux image (photons/s/px, after the optics): the rate
        ``(qe flux + dark) / full_well`` per pixel, the metering weights of ``metering``.

        Parameters
        ----------
        flux_ph_s : ndarray, shape (H, W), float32 or float64
        sensor : SensorParams
        metering : {"mean", "center_weighted", "spot"}
        n_bins : int

        Returns
        -------
        ExposureSolver
        """
        f = np.ascontiguousarray(flux_ph_s)
        if f.dtype not in (np.float32, np.float64):
            f = f.astype(np.float64)
        self = cls.__new__(cls)
        if metering == "mean":  # the same weight everywhere: no weight map
            w, w_const = np.zeros(0), 1.0 / f.size
        else:
            w, w_const = np.ascontiguousarray(metering_weights(f.shape, metering)).ravel(), 0.0
        self._build(f.ravel(), float(sensor.qe), float(sensor.dark_current_e_s), float(sensor.full_well_e), w,
                    w_const, n_bins)
        return self

    def _build(self, x, a, b, c, w, w_const, n_bins):
        """The histogram of ``r = (a x + b) / c`` in ``n_bins`` log bins, weighted by ``w`` (or
        ``w_const`` each when ``w`` is empty)."""
        if self._build_f32(x, a, b, c, w, w_const, n_bins):
            return
        rmin, rmax = _meter_range(x, a, b, c, METER_CHUNKS)
        if not np.isfinite(rmin):  # no positive signal
            self.edges = None
            self.w_zero = float(w.sum()) if w.size else w_const * x.size
            return
        lo, hi = np.log(rmin), np.log(rmax)
        if hi - lo < 1e-9:
            hi = lo + 1e-9
        edges = np.linspace(lo, hi, n_bins + 1)
        w_bin = np.zeros((METER_CHUNKS, n_bins))
        wr_bin = np.zeros((METER_CHUNKS, n_bins))
        w_zero = np.zeros(METER_CHUNKS)
        _meter_bins(x, a, b, c, w, w_const, float(lo), float(hi), int(n_bins), METER_CHUNKS, w_bin, wr_bin, w_zero)
        self._finish(edges, w_bin, wr_bin, w_zero)

    def _build_f32(self, x, a, b, c, w, w_const, n_bins) -> bool:
        """:meth:`_build` for a float32 image of non-negative values whose every ``r`` is positive
        (a flux with dark current), without a logarithm per pixel (:func:`_meter_bins_f32`): the
        same histogram to the bit. False (nothing done) for any other input.

        ``r`` is a non-decreasing function of ``x``, and ``x`` of its bit pattern: the range is the
        smallest and largest pattern's ``r`` (what :func:`_meter_range` finds), and each bin a
        run of patterns."""
        if x.dtype != np.float32 or not (a > 0 and c > 0) or x.size < 4096:
            return False
        bits = x.view(np.int32)
        b_lo, b_hi = int(bits.min()), int(bits.max())
        if b_lo < 0:  # a negative value (or -0.0): the general path
            return False
        xs = np.array([b_lo, b_hi], np.int32).view(np.float32).astype(np.float64)
        rmin, rmax = (a * xs + b) / c
        if not rmin > 0:
            return False
        lo, hi = np.log(rmin), np.log(rmax)
        if hi - lo < 1e-9:
            hi = lo + 1e-9
        edges = np.linspace(lo, hi, n_bins + 1)
        scale = n_bins / (hi - lo)
        shift = METER_CELL_SHIFT
        cell_bin, first = _bin_tables(b_lo, b_hi, shift, float(a), float(b), float(c), float(lo), float(scale),
                                      int(n_bins))
        w_bin = np.zeros((METER_CHUNKS, n_bins))
        wr_bin = np.zeros((METER_CHUNKS, n_bins))
        _meter_bins_f32(x, bits, float(a), float(b), float(c), w, w_const, shift, b_lo >> shift, cell_bin, first,
                        int(n_bins), METER_CHUNKS, w_bin, wr_bin)
        self._finish(edges, w_bin, wr_bin, np.zeros(METER_CHUNKS))
        return True

    def _finish(self, edges, w_bin, wr_bin, w_zero):
        """The histogram's chunks summed, the edges and the running sums :meth:`level` reads."""
        self.w_bin = w_bin.sum(axis=0)
        self.wr_bin = wr_bin.sum(axis=0)
        self.w_zero = float(w_zero.sum())
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
        solver = ExposureSolver.from_flux(flux_ph_s, sensor, exp.metering)
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


#: OpenCV's chroma sampling flag for each colour :data:`svgs_sim.camera.phone.params.JPEG_SUBSAMPLING`.
_JPEG_SAMPLING = {"4:4:4": cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444, "4:2:0": cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420}


def jpeg_roundtrip(image: np.ndarray, quality: int, subsampling: str = "gray", grid_offset_px=(0, 0)) -> np.ndarray:
    """Encode as a baseline JPEG and decode again (OpenCV's libjpeg; IJG quality scaling).

    Parameters
    ----------
    image : ndarray, uint8, shape (H, W) or (H, W, 3)
        A grey image (``subsampling="gray"``), or a colour one in OpenCV's BGR order, coded in
        YCbCr (JFIF: full-range BT.601) with full (``"4:4:4"``) or 2 x 2 subsampled
        (``"4:2:0"``) chroma and decoded with libjpeg's default (smooth) chroma upsampling.
    quality : int
        1-100.
    subsampling : {"gray", "4:4:4", "4:2:0"}
    grid_offset_px : (int, int)
        ``(x, y)``, 0-15: image pixel ``(u, v)`` is coded at ``(u + x, v + y)`` of the block
        grid (the image is padded by edge replication on the left and top, coded, decoded and
        cropped back): the phase of the 8 x 8 blocks (16 x 16 MCUs at 4:2:0) against what the
        image shows.

    Returns
    -------
    ndarray, uint8, the shape of ``image``
    """

    img = np.asarray(image)
    try:
        q = float(quality)
    except (TypeError, ValueError):
        raise InputError(f"quality: expected a whole number 1-100, got {quality!r}") from None
    if not (q.is_integer() and 1 <= q <= 100):
        raise InputError(f"quality: expected a whole number 1-100, got {quality!r}")
    sub = check_subsampling(subsampling, "subsampling")
    ox, oy = check_grid_offset(grid_offset_px, "grid_offset_px")
    if img.dtype != np.uint8:
        raise InputError(f"image: expected uint8, got {img.dtype}")
    if (sub == "gray") != (img.ndim == 2) or (img.ndim == 3 and img.shape[2] != 3) or img.ndim not in (2, 3):
        raise InputError(f"image: shape {img.shape} does not fit subsampling {sub!r} (gray: (H, W); colour: (H, W, 3))")
    if ox or oy:
        img = cv2.copyMakeBorder(img, oy, 0, ox, 0, cv2.BORDER_REPLICATE)
    params = [cv2.IMWRITE_JPEG_QUALITY, int(q)]
    if sub != "gray":
        params += [cv2.IMWRITE_JPEG_SAMPLING_FACTOR, _JPEG_SAMPLING[sub]]
    n = _jpeg_strips(img.shape[0])
    if n == 1:
        out = _jpeg_code(img, params, sub)
    else:  # bands of MCU rows, each coded with one MCU row of its neighbours', on two threads
        H = img.shape[0]
        cuts = [0] + [(H * i // n) // JPEG_MCU_PX * JPEG_MCU_PX for i in range(1, n)] + [H]

        def band(i):
            a, b = cuts[i], cuts[i + 1]
            a0 = max(0, a - JPEG_MCU_PX)
            return _jpeg_code(img[a0:min(H, b + JPEG_MCU_PX)], params, sub)[a - a0:a - a0 + b - a]

        out = np.concatenate(list(_jpeg_pool().map(band, range(n))), axis=0)
    return np.ascontiguousarray(out[oy:, ox:])


#: Rows of a JPEG's largest minimum coded unit (4:2:0): the bands of :func:`jpeg_roundtrip` start and
#: end on multiples of it, and each is coded with one more of them on either side.
JPEG_MCU_PX = 16
#: Images of at least this many rows are coded in two bands on two threads (:func:`jpeg_roundtrip`).
JPEG_BAND_MIN_ROWS = 512
_JPEG_POOL = []


def _jpeg_strips(rows: int) -> int:
    """How many bands :func:`jpeg_roundtrip` codes an image of ``rows`` rows in."""
    return 2 if rows >= JPEG_BAND_MIN_ROWS else 1


def _jpeg_pool() -> ThreadPoolExecutor:
    if not _JPEG_POOL:
        _JPEG_POOL.append(ThreadPoolExecutor(max_workers=2, thread_name_prefix="svgs-jpeg"))
    return _JPEG_POOL[0]


def _jpeg_code(img: np.ndarray, params: list, sub: str) -> np.ndarray:
    """One encode and decode through OpenCV's libjpeg.

    A band of whole MCU rows decodes to the same bytes as those rows of the whole image, except
    within one MCU row of its cut edges (the decoder's smooth chroma upsampling reads the chroma
    row beyond; everything else of baseline JPEG is per block, and the DC prediction is
    lossless): ``tests/test_phone_image_path.py`` checks the bands against the whole image."""
    ok, buf = cv2.imencode(".jpg", np.ascontiguousarray(img), params)
    if not ok:  # pragma: no cover - OpenCV always encodes uint8 images
        raise RuntimeError("JPEG encoding failed")
    return cv2.imdecode(buf, cv2.IMREAD_UNCHANGED if sub == "gray" else cv2.IMREAD_COLOR)


#: Luminance weights of OpenCV's BGR channel order (ITU-R BT.601).
LUMA_BGR = np.array([0.114, 0.587, 0.299], np.float32)


def luma(image: np.ndarray) -> np.ndarray:
    """The BT.601 luma of a BGR image (what the app reads from a colour picture).

    Parameters
    ----------
    image : ndarray, shape (H, W, 3)
        uint8 (rounded, OpenCV's ``COLOR_BGR2GRAY``) or float (0-255 scale, not rounded).

    Returns
    -------
    ndarray, shape (H, W): uint8, or float32 for a float image
    """
    if image.dtype == np.uint8:
        return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    return np.tensordot(np.asarray(image, np.float32), LUMA_BGR, axes=([2], [0])).astype(np.float32)


def noise_reduction(image: np.ndarray, sigma_px: float, range_sigma: float = 0.0) -> np.ndarray:
    """The ISP's noise reduction: each channel filtered on its own (OpenCV).

    ``range_sigma == 0``: a Gaussian of standard deviation ``sigma_px`` (``cv2.GaussianBlur``,
    kernel to 4 sigma, edges replicated). ``range_sigma > 0``: a bilateral filter
    (``cv2.bilateralFilter``), spatial sigma ``sigma_px`` over a disk of radius ``ceil(4 sigma)``,
    range sigma ``range_sigma`` in the image's units: it smooths the noise of flat regions and
    keeps edges such as a spot's rim.

    Parameters
    ----------
    image : ndarray, float32, shape (H, W) or (H, W, C)
        A linear image (fraction of white).
    sigma_px : float
        > 0.
    range_sigma : float
        >= 0.

    Returns
    -------
    ndarray, float32, the shape of ``image``
    """
    if not (np.isfinite(sigma_px) and sigma_px > 0):
        raise InputError(f"sigma_px: expected a positive number of pixels, got {sigma_px!r}")
    if not (np.isfinite(range_sigma) and range_sigma >= 0):
        raise InputError(f"range_sigma: expected a non-negative number, got {range_sigma!r}")
    img = np.ascontiguousarray(image, np.float32)
    planes = [img] if img.ndim == 2 else [np.ascontiguousarray(img[..., k]) for k in range(img.shape[2])]
    out = []
    for pl in planes:
        if range_sigma == 0:
            out.append(cv2.GaussianBlur(pl, (0, 0), float(sigma_px), borderType=cv2.BORDER_REPLICATE))
        else:
            d = 2 * int(np.ceil(4.0 * sigma_px)) + 1
            out.append(cv2.bilateralFilter(pl, d, float(range_sigma), float(sigma_px), borderType=cv2.BORDER_REPLICATE))
    return out[0] if img.ndim == 2 else np.stack(out, axis=-1)


def unsharp_mask(image: np.ndarray, amount: float, sigma_px: float) -> np.ndarray:
    """Unsharp masking, ``out = in + amount (in - G_sigma * in)`` (``cv2.GaussianBlur``, kernel
    to 4 sigma, edges replicated), not clipped.

    Parameters
    ----------
    image : ndarray, float32, shape (H, W)
    amount : float
        >= 0.
    sigma_px : float
        > 0.

    Returns
    -------
    ndarray, float32, shape (H, W)
    """
    if not (np.isfinite(amount) and amount >= 0):
        raise InputError(f"amount: expected a non-negative number, got {amount!r}")
    if not (np.isfinite(sigma_px) and sigma_px > 0):
        raise InputError(f"sigma_px: expected a positive number of pixels, got {sigma_px!r}")
    img = np.ascontiguousarray(image, np.float32)
    blur = cv2.GaussianBlur(img, (0, 0), float(sigma_px), borderType=cv2.BORDER_REPLICATE)
    return (img + np.float32(amount) * (img - blur)).astype(np.float32)
