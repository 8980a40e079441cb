"""The image sensor in electrons: EMVA 1288 linear model with charge-conserving blooming.

Order of operations (ISETCam's ``sensorCompute``, plus a charge spill it lacks):

1. expected photo-electrons ``mu_e = QE * flux * t * (1 + PRNU)``;
2. shot noise ``Poisson(mu_e)``, dark current ``Poisson(mu_dark * t)``, DSNU (fixed offset, e-);
3. full-well clipping with **charge-conserving blooming**: the charge above full well is
   drained with probability ``anti_blooming_drain``; the rest spills into the nearest pixels
   that still have room (isotropically or along the column), so that
   ``sum(before) = sum(after) + drained + charge spilled off the frame``;
4. read noise ``N(0, sigma_d^2)`` (e-), system gain ``K = (white - black) / full_well * ISO /
   base_ISO`` (DN/e-), black level, ADC clipping to ``[0, 2^bits - 1]`` and rounding.

The fixed patterns (PRNU, DSNU) depend on the camera's ``serial`` only, never on the frame.
Per-frame noise comes from a counter-based generator (SplitMix64 of the seed, the noise
source and the pixel index): the same seed gives the same frame whatever the number of
threads. Shot noise is exact Poisson (inversion) below 25 e- and the normal approximation
N(mu, mu) above, as in ISETCam's ``noiseShot``; mean and variance are exact either way.
"""

from __future__ import annotations

import functools

import cv2
import numpy as np

from numba import njit, prange

from svgs_sim.camera.phone.params import SensorParams


def fixed_patterns(params: SensorParams, shape) -> tuple[np.ndarray, np.ndarray]:
    """PRNU gain map (1 + prnu * N(0,1)) and DSNU offset map (e-), fixed by ``serial``.

    The same sensor's patterns are the same on every frame: they are drawn once per
    ``(params, shape)`` and kept (read-only) for the process' later frames.

    Returns
    -------
    prnu_gain : ndarray, float32, shape (H, W)
    dsnu_e : ndarray, float32, shape (H, W)
        Zero-mean (a constant dark offset belongs to the black level).
    """
    return _fixed_patterns(params, tuple(int(n) for n in shape))


@functools.lru_cache(maxsize=4)
def _fixed_patterns(params: SensorParams, shape: tuple) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng([int(params.serial), 1288])
    prnu = (1.0 + params.prnu * rng.standard_normal(shape, dtype=np.float32)).astype(np.float32)
    dsnu = (params.dsnu_e * rng.standard_normal(shape, dtype=np.float32)).astype(np.float32)
    prnu.setflags(write=False)
    dsnu.setflags(write=False)
    return prnu, dsnu


@njit(cache=True, inline="always")
def _uniform(key, counter):
    """Counter-based uniform in (0, 1): SplitMix64 of (key, counter). Same (key, counter),
    same number - whatever thread draws it."""
    z = key + (counter + np.uint64(1)) * np.uint64(0x9E3779B97F4A7C15)
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    z = z ^ (z >> np.uint64(31))
    return (float(z >> np.uint64(11)) + 0.5) * (1.0 / 9007199254740992.0)


@njit(cache=True, inline="always")
def _normal(key, counter):
    """Standard normal from two counter-based uniforms (Box-Muller)."""
    u1 = _uniform(key, np.uint64(2) * counter)
    u2 = _uniform(key, np.uint64(2) * counter + np.uint64(1))
    return np.sqrt(-2.0 * np.log(u1)) * np.cos(6.283185307179586 * u2)


#: 1 / k for the Poisson inversion (k < 201).
_INV_K = np.concatenate([[0.0], 1.0 / np.arange(1, 201, dtype=np.float64)])


@njit(cache=True, inline="always")
def _poisson(lam, key, counter):
    """Poisson(lam): exact inversion below POISSON_GAUSS_LAMBDA, else the normal
    approximation N(lam, lam) rounded (as ISETCam's noiseShot does above 25 e-)."""
    if lam <= 0.0:
        return 0.0
    if lam < 25.0:
        u = _uniform(key, np.uint64(2) * counter)
        if u <= 1.0 - lam:  # then u <= exp(-lam) = P(0): zero, without the exponential
            return 0.0
        p = np.exp(-lam)
        F = p
        k = 0
        while u > F and k < 200:
            k += 1
            p *= lam * _INV_K[k]  # 1 / k from a table: a multiply, not a division
            F += p
        return float(k)
    x = np.floor(lam + np.sqrt(lam) * _normal(key, counter) + 0.5)
    return x if x > 0.0 else 0.0


def _key(seed: int, stream: int) -> np.uint64:
    return np.uint64((np.uint64(int(seed) & 0xFFFFFFFF) << np.uint64(20)) ^ np.uint64(stream * 0x5851F42D))


@njit(parallel=True, cache=True)
def _charge_kernel(flux, scale, prnu, use_prnu, dark_e, dsnu, key_shot, key_dark, shot, dark, r0, c0, width, out):
    """Expected photo-electrons ``scale * flux * prnu`` (scale = QE x exposure time), Poisson
    shot + dark noise and DSNU; every pixel draws from its own counter: its index in the full
    frame (``width`` px wide) whose rows ``r0 ..`` and columns ``c0 ..`` these arrays hold."""
    H, W = flux.shape
    for r in prange(H):
        for c in range(W):
            idx = np.uint64((r + r0) * width + c + c0)
            m = scale * flux[r, c]
            if use_prnu:
                m *= prnu[r, c]
            if shot and dark:  # a sum of Poisson variables is Poisson: one draw
                e = _poisson(m + dark_e, key_shot, idx)
            elif shot:
                e = _poisson(m, key_shot, idx)
            elif dark:
                e = m + _poisson(dark_e, key_dark, idx)
            else:
                e = m
            out[r, c] = e + dsnu[r, c]


#: Read noise uses normal quantiles at 2^16 equiprobable levels (inverse CDF of the
#: normal, scipy.special.ndtri), four per 64-bit counter-based draw: exact to the
#: discretisation (the tails stop at 4.3 sigma), and ~10x cheaper than Box-Muller.
_NORMAL_LEVELS = None


def normal_levels() -> np.ndarray:
    global _NORMAL_LEVELS
    if _NORMAL_LEVELS is None:
        from scipy.special import ndtri

        _NORMAL_LEVELS = ndtri((np.arange(65536) + 0.5) / 65536).astype(np.float32)
    return _NORMAL_LEVELS


@njit(cache=True, inline="always")
def _bits(key, counter):
    """64 counter-based random bits (SplitMix64 of (key, counter))."""
    z = key + (counter + np.uint64(1)) * np.uint64(0x9E3779B97F4A7C15)
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


@njit(parallel=True, cache=True)
def _readout_kernel(e, read_sigma, gain, black, white, key, read, quantise, lut, levels, r0, c0, width, out, out8):
    """Read noise, gain, black level, ADC clip and rounding (DN, float32), and the 8-bit
    image through the tone LUT when quantising (one pass). The draws are counted in the full
    frame (``width`` px wide; these arrays hold its rows ``r0 ..`` and columns ``c0 ..``, ``c0`` a
    multiple of 4)."""
    H, W = e.shape
    nl = lut.shape[0]
    blocks = (width + 3) // 4
    for r in prange(H):
        z = np.uint64(0)
        for c in range(W):
            x = e[r, c]
            if read:
                j = c & 3
                if j == 0:
                    z = _bits(key, np.uint64((r + r0) * blocks + ((c + c0) >> 2)))
                x += read_sigma * levels[(z >> np.uint64(16 * j)) & np.uint64(0xFFFF)]
            y = gain * x + black
            if quantise:
                y = np.floor(y + 0.5)
                if y < 0.0:
                    y = 0.0
                elif y > white:
                    y = white
                k = int(y)
                out8[r, c] = lut[k if k < nl else nl - 1]
            out[r, c] = y


def bloom(e: np.ndarray, full_well_e: float, drain: float, direction: str = "isotropic", *, rings: str = "fast"):
    """Clip at full well and spill the excess charge into neighbouring pixels, in place.

    Each connected region above full well keeps ``full_well_e`` per pixel; a fraction
    ``drain`` of its excess is removed (anti-blooming drain), the rest fills the rings of
    pixels around the region in order of distance (8-neighbour rings for ``isotropic``, up
    and down the columns for ``column``), each pixel up to full well; the last ring is filled
    in proportion to its room.

    Parameters
    ----------
    e : ndarray, float32, shape (H, W)
        Electrons per pixel; modified in place.
    full_well_e : float
    drain : float
        Anti-blooming drain fraction in [0, 1].
    direction : {"isotropic", "column"}
    rings : {"fast", "dilation"}
        ``fast``: rings from a distance transform in large windows, and a frame with no pixel
        below full well recognised; ``dilation``: the definition, one dilation per ring and
        region (slow on a frame the sun fills; the same bits).

    Returns
    -------
    dict
        ``drained_e`` (removed by the drain), ``lost_e`` (spilled off the frame),
        ``regions`` (number of saturated regions), ``bloomed_px`` (pixels filled by spill).
    """
    stats = {"drained_e": 0.0, "lost_e": 0.0, "regions": 0, "bloomed_px": 0}
    H, W = e.shape
    # rows and columns holding saturated pixels (cheap reductions), then work in that box
    rows = np.flatnonzero(e.max(axis=1) > full_well_e)
    if rows.size == 0:
        return stats
    cols = np.flatnonzero(e[rows[0] : rows[-1] + 1].max(axis=0) > full_well_e)
    ry0, ry1, rx0, rx1 = rows[0], rows[-1] + 1, cols[0], cols[-1] + 1
    over = np.zeros((H, W), np.uint8)
    over[ry0:ry1, rx0:rx1] = e[ry0:ry1, rx0:rx1] > full_well_e
    sub_over = over[ry0:ry1, rx0:rx1]
    n, sub_labels, box, _ = cv2.connectedComponentsWithStats(sub_over, connectivity=8)
    labels = np.zeros((H, W), np.int32)
    labels[ry0:ry1, rx0:rx1] = sub_labels
    box = box.copy()
    box[:, 0] += rx0
    box[:, 1] += ry0
    stats["regions"] = n - 1
    kernel = np.ones((3, 3), np.uint8) if direction == "isotropic" else np.ones((3, 1), np.uint8)
    # excess per region, then clip everything at full well
    sub_e = e[ry0:ry1, rx0:rx1]
    excess = np.bincount(sub_labels.ravel(), weights=np.maximum(sub_e - full_well_e, 0).ravel(), minlength=n)
    np.minimum(sub_e, full_well_e, out=sub_e)
    order = np.argsort(-excess[1:]) + 1
    if rings not in ("fast", "dilation"):
        raise ValueError(f"rings: expected 'fast' or 'dilation', got {rings!r}")
    fill = _fill_rings if rings == "fast" else _fill_rings_by_dilation
    frame_full = False  # no pixel below full well: every later region's spill leaves the frame
    for lab in order:
        q = float(excess[lab])
        stats["drained_e"] += q * drain
        q *= 1.0 - drain
        if frame_full:  # what the rings would give: each adds nothing, all of q is lost off the frame
            stats["lost_e"] += q
            continue
        x, y, w, h, _ = box[lab]
        pad = int(np.sqrt(q / (np.pi * full_well_e) + w * h)) + 4
        while True:
            x0, y0 = max(0, x - pad), max(0, y - pad)
            x1, y1 = min(W, x + w + pad), min(H, y + h + pad)
            sub = e[y0:y1, x0:x1]
            region = (labels[y0:y1, x0:x1] == lab).astype(np.uint8)
            trial = sub.copy()
            rem, filled, touched_edge = fill(trial, region, q, full_well_e, kernel)
            at_frame_edge = (x0 == 0 and touched_edge[0]) or (y0 == 0 and touched_edge[1]) or (
                x1 == W and touched_edge[2]) or (y1 == H and touched_edge[3])
            window_edge = any(touched_edge) and not at_frame_edge
            if rem > 0 and window_edge and (x0 > 0 or y0 > 0 or x1 < W or y1 < H):
                pad *= 2
                continue
            sub[...] = trial
            stats["lost_e"] += rem
            stats["bloomed_px"] += filled
            if rem > 0 and rings == "fast":
                frame_full = not bool((e < full_well_e).any())
            break
    return stats


def _ring_distance(region, column: bool) -> np.ndarray:
    """Ring index of each pixel around ``region``: the number of dilations by the 3 x 3 square
    (chessboard distance) or, for ``column``, by the 3 x 1 column (the distance along the column)
    that first reaches it; region pixels 0, pixels no dilation reaches (``column``: other
    columns) a value above every ring.

    Parameters
    ----------
    region : ndarray, uint8, shape (h, w)
        Non-zero inside the region.

    Returns
    -------
    ndarray, int32, shape (h, w)
    """
    h, w = region.shape
    if not column:
        d = cv2.distanceTransform((region == 0).astype(np.uint8), cv2.DIST_C, 3)
        return d.astype(np.int32)
    far = h + w + 1  # above any distance along a column
    rows = np.arange(h, dtype=np.int32)[:, None]
    inside = region > 0
    above = np.maximum.accumulate(np.where(inside, rows, -far), axis=0)  # nearest region row at or above
    below = np.minimum.accumulate(np.where(inside, rows, 2 * far)[::-1], axis=0)[::-1]  # at or below
    return np.minimum(np.minimum(rows - above, below - rows), far).astype(np.int32)


#: Windows up to this many pixels grow their rings by dilation, one per ring (cheaper for the small
#: spots of most frames); larger ones take them from a distance transform. Both give the same bits.
RING_DILATION_MAX_PX = 4096


def _fill_rings(sub, region, q, fw, kernel):
    """Fill rings around ``region`` in ``sub`` with charge ``q``. Returns (left over, filled px,
    (left, top, right, bottom) whether the growing region reached that side of the window).

    Ring ``k`` is what the ``k``-th dilation of ``region`` by ``kernel`` (3 x 3: isotropic; 3 x 1:
    along the column) adds. Each ring in turn is filled to full well while the charge lasts; the
    last in proportion to its room. The rings come from one distance transform and one stable
    sort, not one dilation each: a frame full to the brim (the sun at a long exposure) otherwise
    costs a full-window dilation for each of thousands of rings, for each saturated region. The
    arithmetic is the ring-by-ring one (the same pixels in the same order, float32), so the
    result is the same to the bit (tests/test_phone_model.py holds the ring-by-ring reference).
    """
    h, w = sub.shape
    if h * w <= RING_DILATION_MAX_PX:
        return _fill_rings_by_dilation(sub, region, q, fw, kernel)
    column = kernel.shape[1] == 1
    if not sub.flags.c_contiguous:
        raise ValueError("_fill_rings fills a C-contiguous window in place")
    room_all = np.maximum(fw - sub, 0.0)
    has_room = bool((room_all > 0).any())
    if q > 0 and not column and not has_room:  # no room: the rings grow over the whole window
        return q, 0, (True, True, True, True)
    d = _ring_distance(region, column)
    reach = int(h + w + 1) if column else None
    flat = sub.reshape(-1)  # a view
    last = int(d[d < reach].max()) if column else int(d.max())

    def edges(upto):
        m = d <= upto
        return (bool(m[:, 0].any()), bool(m[0, :].any()), bool(m[:, w - 1].any()), bool(m[h - 1, :].any()))

    if q <= 0:
        return max(q, 0.0), 0, edges(0)
    if not has_room:  # nothing takes charge: every ring passes with cap 0, the window fills up
        return q, 0, edges(last)
    dflat = d.reshape(-1)
    key = dflat.astype(np.uint16) if last < 65535 and (reach is None or reach < 65536) else dflat
    order = np.argsort(key, kind="stable")  # raster order inside each ring, as a boolean mask takes it
    counts = np.bincount(np.minimum(dflat, last + 1), minlength=last + 2)  # rings 0..last, then the unreached
    bounds = np.concatenate([[0], np.cumsum(counts)])
    room_sorted = room_all.reshape(-1)[order]
    filled = 0
    k = 0
    for k in range(1, last + 1):
        a, b = int(bounds[k]), int(bounds[k + 1])
        idx = order[a:b]
        room = room_sorted[a:b]
        cap = float(room.sum())
        if cap >= q and cap > 0:
            flat[idx] += (room * (q / cap)).astype(sub.dtype)
            filled += int(np.count_nonzero(room))
            q = 0.0
            break
        flat[idx] = np.maximum(flat[idx], fw)
        filled += int(np.count_nonzero(room))
        q -= cap
    return max(q, 0.0), filled, edges(k)


def _fill_rings_by_dilation(sub, region, q, fw, kernel):
    """:func:`_fill_rings`, one dilation of ``region`` by ``kernel`` per ring."""
    filled = 0
    h, w = sub.shape
    while q > 0:
        grown = cv2.dilate(region, kernel)
        ring = (grown > 0) & (region == 0)
        if not ring.any():
            break
        room = np.maximum(fw - sub[ring], 0.0)
        cap = float(room.sum())
        if cap >= q and cap > 0:
            sub[ring] += (room * (q / cap)).astype(sub.dtype)
            filled += int(np.count_nonzero(room))
            q = 0.0
        else:
            sub[ring] = np.maximum(sub[ring], fw)
            filled += int(np.count_nonzero(room))
            q -= cap
        region = grown
    edge = (bool(region[:, 0].any()), bool(region[0, :].any()), bool(region[:, w - 1].any()), bool(region[h - 1, :].any()))
    return max(q, 0.0), filled, edge


def electrons(flux, params: SensorParams, exposure_s: float, prnu, dsnu, seed: int, *, shot=True, dark=True, fpn=True,
              origin=(0, 0), full_width: int | None = None):
    """Stages 1-2: expected photo-electrons ``QE * flux * t * PRNU``, shot and dark noise, DSNU.

    Parameters
    ----------
    flux : ndarray, float32, shape (H, W)
        Photons per second per pixel reaching the sensor (after the optics).
    exposure_s : float
    prnu, dsnu : ndarray, float32, shape (H, W)
        Fixed patterns (:func:`fixed_patterns`); ignored unless ``fpn``.
    origin : (int, int)
        ``(row, column)`` of ``flux[0, 0]`` in the full frame: a crop draws the same numbers as
        the same pixels of the full frame.
    full_width : int, optional
        The full frame's width, px (default ``W``: the arrays are the frame).

    Returns
    -------
    ndarray, float32, shape (H, W)
        Electrons per pixel.
    """
    out = np.empty(flux.shape, np.float32)
    dsnu_use = dsnu if fpn else np.zeros(flux.shape, np.float32)
    _charge_kernel(np.ascontiguousarray(flux, np.float32), float(params.qe * exposure_s), prnu, bool(fpn),
                   float(params.dark_current_e_s * exposure_s), dsnu_use, _key(seed, 1), _key(seed, 2),
                   bool(shot), bool(dark), int(origin[0]), int(origin[1]),
                   int(flux.shape[1] if full_width is None else full_width), out)
    return out


def readout(e, params: SensorParams, iso: float, seed: int, *, read=True, adc=True, lut=None, origin=(0, 0),
            full_width: int | None = None):
    """Stage 4: read noise, gain, black level and ADC.

    ``origin`` (row, column; the column a multiple of 4) and ``full_width`` place a crop ``e``
    in the full frame: it draws the read noise of those pixels of the frame.

    Returns
    -------
    raw_dn : ndarray, float32, shape (H, W)
        DN (integers when ``adc``).
    image : ndarray, uint8, shape (H, W) or None
        ``lut[raw_dn]`` when ``adc`` and a tone LUT is given (one pass over the frame).
    """
    if int(origin[1]) % 4:
        raise ValueError(f"origin: a crop's first column must be a multiple of 4 (the read noise's draws), got {origin}")
    out = np.empty(e.shape, np.float32)
    want8 = bool(adc) and lut is not None
    # the kernel writes the 8-bit image whenever it quantises (no bounds checks in numba):
    # it gets a full-size one then, with a one-entry LUT when no tone LUT is given
    out8 = np.empty(e.shape if adc else (1, 1), np.uint8)
    lut_arr = np.ascontiguousarray(lut if lut is not None else np.zeros(1, np.uint8), np.uint8)
    _readout_kernel(np.ascontiguousarray(e, np.float32), float(params.read_noise_e), float(params.gain_dn_per_e(iso)),
                    float(params.black_level_dn), float(params.white_dn), _key(seed, 3),
                    bool(read), bool(adc), lut_arr, normal_levels(), int(origin[0]), int(origin[1]),
                    int(e.shape[1] if full_width is None else full_width), out, out8)
    return out, (out8 if want8 else None)


# ---------------------------------------------------------------------------------------------
# Dark pixels (an option, off by default): a cheaper exact Poisson sampler for the pixels whose
# expected charge keeps them far below the detection threshold.

#: Step of the expected-charge levels of the dark pixels' Poisson tables, e-.
DARK_TABLE_STEP_E = 1.0 / 16.0
#: The highest expected charge a dark pixel may have, e- (below ``POISSON_GAUSS_LAMBDA`` = 25 e-,
#: where the exact path's sampler is exact Poisson inversion too: both draw the same law).
DARK_TABLE_MAX_E = 24.0
#: Counts per level in the tables: ``P(Poisson(24) > 64) < 1e-11`` (below the draws' 2^-32), the mass beyond on the last.
DARK_TABLE_KMAX = 64
#: Guide bins per level (``u`` in bin ``b`` starts the search at the smallest count whose CDF passes ``b / bins``).
_GUIDE_BITS = 6
DARK_GUIDE_BINS = 1 << _GUIDE_BITS


@functools.lru_cache(maxsize=1)
def dark_poisson_tables() -> tuple[np.ndarray, np.ndarray]:
    """The dark pixels' Poisson tables: the CDF of ``Poisson(q * DARK_TABLE_STEP_E)`` for each
    level ``q`` (0 ... ``DARK_TABLE_MAX_E / DARK_TABLE_STEP_E`` + 1) in units of 2^-32, and its
    guide table.

    Returns
    -------
    cdf : ndarray, int64, shape (levels, DARK_TABLE_KMAX + 1)
        ``round(2^32 P(N <= k))``; the last column 2^32 (the mass beyond ``DARK_TABLE_KMAX``,
        below 1e-11, put there).
    guide : ndarray, int32, shape (levels, DARK_GUIDE_BINS)
        The smallest ``k`` with ``cdf[q, k] > b 2^32 / DARK_GUIDE_BINS``: the search's start
        for a 32-bit draw in bin ``b``.
    """
    from scipy.stats import poisson

    lam = np.arange(int(round(DARK_TABLE_MAX_E / DARK_TABLE_STEP_E)) + 2) * DARK_TABLE_STEP_E
    k = np.arange(DARK_TABLE_KMAX + 1)
    cdf = np.rint(poisson.cdf(k[None, :], lam[:, None]) * 2.0 ** 32).astype(np.int64)
    cdf[:, -1] = 1 << 32
    edges = np.arange(DARK_GUIDE_BINS, dtype=np.int64) << (32 - _GUIDE_BITS)
    guide = np.stack([np.searchsorted(row, edges, side="right") for row in cdf]).astype(np.int32)
    cdf.setflags(write=False)
    guide.setflags(write=False)
    return cdf, guide


@njit(cache=True, inline="always")
def _poisson_dark(lam, key, counter, cdf, guide):
    """Poisson(lam) for ``0 <= lam < DARK_TABLE_MAX_E``, exact in law to 2^-32: the sum of
    Poisson(``q * step``) by inversion of the integer CDF table (guide table, no exponential,
    no float conversion) and Poisson of the remainder ``r < step`` by inversion (zero for
    ``u2 <= 1 - r``, without an exponential). The two draws are the 32-bit halves of one
    counter-based draw (``2 * counter``, the exact sampler's counter): outcomes rarer than
    2^-32 (2.3e-10) a pixel are not resolved."""
    if lam <= 0.0:
        return 0.0
    x = lam * (1.0 / DARK_TABLE_STEP_E)
    q = int(x)
    r = (x - q) * DARK_TABLE_STEP_E
    z = _bits(key, np.uint64(2) * counter)
    hi = np.int64(z >> np.uint64(32))
    k = guide[q, hi >> (32 - _GUIDE_BITS)]
    while hi >= cdf[q, k]:
        k += 1
    lo = np.int64(z & np.uint64(0xFFFFFFFF))
    if lo >= (1.0 - r) * 4294967296.0:  # rare (probability r <= step): the remainder's inversion
        u2 = (lo + 0.5) * (1.0 / 4294967296.0)
        p = np.exp(-r)
        F = p
        j = 0
        while u2 > F and j < 40:
            j += 1
            p *= r * _INV_K[j]
            F += p
        k += j
    return float(k)


@njit(parallel=True, cache=True)
def _charge_kernel_dark(flux, scale, prnu, use_prnu, dark_e, dsnu, key_shot, dark_tile, tile, cdf, guide, out):
    """:func:`_charge_kernel` with shot and dark noise on, the pixels of the dark tiles
    (``dark_tile[r // tile, c // tile]``) drawn by :func:`_poisson_dark`; the others exactly as
    :func:`_charge_kernel` draws them (the same counters: the same bits)."""
    H, W = flux.shape
    for r in prange(H):
        tr = r // tile
        for c in range(W):
            idx = np.uint64(r * W + c)
            m = scale * flux[r, c]
            if use_prnu:
                m *= prnu[r, c]
            lam = m + dark_e
            if dark_tile[tr, c // tile] and lam < DARK_TABLE_MAX_E:  # the guard: a table level always exists
                e = _poisson_dark(lam, key_shot, idx, cdf, guide)
            else:
                e = _poisson(lam, key_shot, idx)
            out[r, c] = e + dsnu[r, c]


@njit(parallel=True, cache=True)
def _tile_max_kernel(a, tile, out):
    """Largest value of each ``tile x tile`` block of ``a`` (the last row and column of blocks partial)."""
    H, W = a.shape
    th, tw = out.shape
    for i in prange(th):
        for j in range(tw):
            m = -np.inf
            for r in range(i * tile, min(H, (i + 1) * tile)):
                for c in range(j * tile, min(W, (j + 1) * tile)):
                    if a[r, c] > m:
                        m = a[r, c]
            out[i, j] = m


def tile_max(a: np.ndarray, tile: int) -> np.ndarray:
    """The largest value of each ``tile x tile`` block of a float32 image.

    Parameters
    ----------
    a : ndarray, float32, shape (H, W)
    tile : int
        Block side, px.

    Returns
    -------
    ndarray, float64, shape (ceil(H / tile), ceil(W / tile))
    """
    H, W = a.shape
    out = np.empty((-(-H // tile), -(-W // tile)))
    _tile_max_kernel(np.ascontiguousarray(a, np.float32), int(tile), out)
    return out


def dark_charge_limit(e_reach: float, params: SensorParams, dsnu_max_e: float, tail_p: float) -> float:
    """The largest expected charge (e-) of a pixel that reaches ``e_reach`` e- (signal, dark
    current, DSNU and read noise together) with probability below ``tail_p`` at most, capped at
    :data:`DARK_TABLE_MAX_E`.

    The bound is hard in the fixed and read parts: DSNU at most ``dsnu_max_e`` (the frame's
    largest), read noise at most its largest quantile (4.33 sigma, :func:`normal_levels`); the
    Poisson count ``N`` must then reach ``n = ceil(e_reach - dsnu_max_e - 4.33 sigma_read)``, and
    ``P(N >= n) < tail_p`` is solved for the mean by bisection (``P`` grows with the mean).

    Parameters
    ----------
    e_reach : float
        Charge, e-, at and above which a pixel could reach the detection threshold.
    params : SensorParams
    dsnu_max_e : float
        Largest DSNU of the frame, e-.
    tail_p : float
        Per-pixel probability allowed.

    Returns
    -------
    float
        e- (0 when no expected charge is safe).
    """
    from scipy.stats import poisson

    read_max = float(params.read_noise_e) * float(np.abs(normal_levels()).max())
    n = int(np.ceil(e_reach - dsnu_max_e - read_max))
    if n <= 0 or poisson.sf(n - 1, 1e-9) >= tail_p:
        return 0.0
    if poisson.sf(n - 1, DARK_TABLE_MAX_E) < tail_p:
        return DARK_TABLE_MAX_E
    lo, hi = 1e-9, DARK_TABLE_MAX_E
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if poisson.sf(n - 1, mid) < tail_p else (lo, mid)
    return lo


def electrons_dark(flux, params: SensorParams, exposure_s: float, prnu, dsnu, seed: int, dark_tile, tile: int, *,
                   fpn=True):
    """:func:`electrons` with shot and dark noise on, the pixels of the dark tiles drawn by the
    tables' sampler (the same Poisson law; other variates), the others to the bit as
    :func:`electrons` draws them.

    Parameters
    ----------
    flux : ndarray, float32, shape (H, W)
        Photons per second per pixel (after the optics).
    exposure_s : float
        s.
    prnu, dsnu : ndarray, float32, shape (H, W)
        Fixed patterns; ignored unless ``fpn``.
    seed : int
    dark_tile : ndarray, bool or uint8, shape (ceil(H / tile), ceil(W / tile))
        The dark tiles (every pixel of them below :data:`DARK_TABLE_MAX_E` expected e-).
    tile : int
        Tile side, px.

    Returns
    -------
    ndarray, float32, shape (H, W)
        Electrons per pixel.
    """
    out = np.empty(flux.shape, np.float32)
    dsnu_use = dsnu if fpn else np.zeros(flux.shape, np.float32)
    cdf, guide = dark_poisson_tables()
    _charge_kernel_dark(np.ascontiguousarray(flux, np.float32), float(params.qe * exposure_s), prnu, bool(fpn),
                        float(params.dark_current_e_s * exposure_s), dsnu_use, _key(seed, 1),
                        np.ascontiguousarray(dark_tile, np.uint8), int(tile), cdf, guide, out)
    return out
