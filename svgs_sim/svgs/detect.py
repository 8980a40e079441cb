"""Blob detector: threshold, connected components, per-blob centroid and shape (paper Fig. 3).

The steps
    1. Colour -> luminance (Rec. 601 weights, RGB channel order as :func:`svgs_sim.svgs.load_image`
       returns it); 8/16-bit and float images are kept in their type.
    2. Threshold: a fixed level (the app's, by default), Otsu, or automatic (``"auto"``): the
       background level (median) plus ``k`` robust sigmas (1.4826 x MAD for float images,
       the histogram-interpolated inter-quartile range / 1.349 for 8/16-bit ones, whose
       MAD is quantised to whole DN), both estimated on a regular subsample of the frame,
       with two floors - a sigma of at least half a DN for integer images, and
       ``peak_fraction`` of the frame's brightest value above the background (so that noise-free dark frames and saturated spots are handled).
       Otsu splits the histogram into two populations of comparable size and is a poor
       choice for a dark frame with a few small spots (it lands inside the noise); it is
       offered for completeness.
    3. Connected components (8-connectivity). On a multi-megapixel frame OpenCV's labelling
       with statistics is slow (~40 ms at 8 MP), so components are first found on an 8x8
       block-OR image and then labelled in full resolution only inside those regions.
    4. Size gate on the component area, then per blob: background (median of a ring around
       the blob), background-subtracted flux, peak, saturated fraction, second-moment shape
       (eccentricity, with each pixel counted as a unit square) and roundness
       ``4 pi A / P^2`` (``P`` the outer contour through pixel centres plus ``pi``, the
       perimeter of the pixel squares' outline for a convex blob); shape gates.
    5. Centroid (``centroid``; default the app's, :mod:`svgs_sim.svgs.app`: ``"weighted"``):

       - ``"weighted"`` (the paper's rule, default): the intensity-weighted centroid of the
         blob's own thresholded pixels, background subtracted (``"component"`` is another name);
       - ``"binary"``: the unweighted centroid of the blob's pixels (the binary image's blob);
       - ``"window"``: a Gaussian-weighted iterative centroid (SExtractor's XWIN) on
         background-subtracted intensities in a window around the blob, *deblended*: every
         other blob's thresholded pixels are masked, as SExtractor's windowed measurements
         mask the other objects of the segmentation map, and the window's reach is at most
         half the distance to the nearest other blob (never below the smallest window's, 6 px
         at sigma 0.8 px), so it does not reach into a neighbour (its sub-threshold halo gets a
         weight below ``exp(-8)``). Unbiased by the threshold
         truncating the spot's wings; an option,
         not the paper's rule (``docs/detector.md``, "What a better centroid buys").

The default threshold is the app's "specified brightness threshold value" (Becker, Howard &
Rakoczy 2014) on the 8-bit image: ``threshold=None`` takes :func:`svgs_sim.svgs.app.settings`'
``threshold_dn`` (scaled by 257 for a 16-bit image; a float image is taken in 8-bit units, as
the camera model delivers it); :func:`svgs_sim.svgs.pipeline.solve_image` takes the value of the
camera's test set-up. ``threshold="auto"`` is the automatic rule of step 2.

Pixel convention: OpenCV's, pixel centres at integer coordinates; ``centroid_px`` holds
``(u, v)`` = (column, row).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import cv2
import numpy as np

from ..base.errors import InputError
from .app import CENTROIDS, settings

# ------------------------------------------------------------------ defaults (one place)
#: Automatic threshold: background + AUTO_K_SIGMA robust sigmas...
AUTO_K_SIGMA = 6.0
#: ...and at least this fraction of (brightest pixel - background) above the background.
#: 0.3 in 8-bit gamma-encoded counts is ~7 % of the peak in linear signal: the spots stay
#: compact, so neighbours at 5-6 px (the 3U pattern at 40 m) stay apart.
AUTO_PEAK_FRACTION = 0.3
#: Pixels sampled for the background statistics (regular subsample of the frame).
BACKGROUND_SAMPLES = 100_000
#: Smallest blob kept, px (single hot pixels and pairs are rejected).
MIN_AREA_PX = 3
#: Largest blob kept, px (a 160 px diameter disc); bigger regions are background glare.
MAX_AREA_PX = 20_000
#: Largest eccentricity kept (0 = circle, 1 = line); a 1 x 5 px streak has 0.98.
MAX_ECCENTRICITY = 0.97
#: Smallest roundness 4 pi A / P^2 kept (1 = disc).
MIN_ROUNDNESS = 0.3
#: Shape gates apply to blobs at least this large (smaller blobs have no meaningful shape).
SHAPE_GATE_MIN_AREA_PX = 12
#: Most blobs measured per frame (the largest by area are kept); guards noisy frames.
MAX_BLOBS = 256
#: Block size of the coarse labelling pass.
COARSE_BLOCK_PX = 8
#: Coarse regions above which the detector labels the full frame in one call instead.
COARSE_MAX_REGIONS = 400
#: Windowed centroid: iterations, convergence (px), smallest Gaussian window sigma (px).
WIN_MAX_ITER = 20
WIN_TOL_PX = 1e-4
WIN_MIN_SIGMA_PX = 0.8


GATES = ("min_area", "max_area", "eccentricity", "roundness", "max_blobs")


@dataclass
class Blobs:
    """Blobs found in an image, sorted by flux (brightest first).

    Attributes
    ----------
    centroid_px : ndarray, shape (N, 2)
        ``(u, v)`` centroids, pixels (OpenCV convention: pixel centres at integers).
    area_px : ndarray of int, shape (N,)
        Pixels above the threshold in the blob.
    bbox : ndarray of int, shape (N, 4)
        ``(x, y, width, height)`` of the thresholded pixels, px.
    peak : ndarray, shape (N,)
        Brightest pixel value (image units, background included).
    saturated_fraction : ndarray, shape (N,)
        Fraction of the blob's pixels at or above the saturation level.
    eccentricity : ndarray, shape (N,)
        From the second moments of the blob's pixels (unit squares): 0 for a disc.
    roundness : ndarray, shape (N,)
        ``4 pi area / perimeter^2``, clipped to [0, 1]; 1 for a disc.
    flux : ndarray, shape (N,)
        Sum of background-subtracted values over the blob's pixels (image units).
    background : ndarray, shape (N,)
        Local background level subtracted for each blob.
    threshold_used : float
        The binarisation level (pixels strictly above it are foreground).
    background_level, noise_sigma : float
        Frame background (median) and robust noise sigma, image units (see
        :func:`background_stats`).
    saturation_level : float
        Level counted as saturated (``inf`` when none applies).
    rejected : dict
        Number of components dropped by each gate (``min_area``, ``max_area``,
        ``eccentricity``, ``roundness``, ``max_blobs``).
    n_components : int
        Connected components above the threshold before gating.
    image_shape : tuple
        ``(H, W)`` of the image.
    image_max : float
        The brightest grey value of a floating-point image (NaN for an integer one): says what
        scale an image without a blob was given in.
    """

    centroid_px: np.ndarray
    area_px: np.ndarray
    bbox: np.ndarray
    peak: np.ndarray
    saturated_fraction: np.ndarray
    eccentricity: np.ndarray
    roundness: np.ndarray
    flux: np.ndarray
    background: np.ndarray
    threshold_used: float = float("nan")
    background_level: float = float("nan")
    noise_sigma: float = float("nan")
    saturation_level: float = float("inf")
    rejected: dict = field(default_factory=lambda: {g: 0 for g in GATES})
    n_components: int = 0
    image_shape: tuple = (0, 0)
    image_max: float = float("nan")

    _ARRAYS = ("centroid_px", "area_px", "bbox", "peak", "saturated_fraction", "eccentricity", "roundness", "flux",
               "background")

    def __len__(self) -> int:
        return int(self.centroid_px.shape[0])

    def subset(self, index) -> "Blobs":
        """The blobs selected by an index array or boolean mask (same metadata)."""
        kw = {k: getattr(self, k)[index] for k in self._ARRAYS}
        return Blobs(**kw, threshold_used=self.threshold_used, background_level=self.background_level,
                     noise_sigma=self.noise_sigma, saturation_level=self.saturation_level,
                     rejected=dict(self.rejected), n_components=self.n_components, image_shape=self.image_shape,
                     image_max=self.image_max)

    @classmethod
    def empty(cls, **meta) -> "Blobs":
        """A well-shaped empty result."""
        return cls(
            centroid_px=np.zeros((0, 2)), area_px=np.zeros(0, int), bbox=np.zeros((0, 4), int), peak=np.zeros(0),
            saturated_fraction=np.zeros(0), eccentricity=np.zeros(0), roundness=np.zeros(0), flux=np.zeros(0),
            background=np.zeros(0), **meta,
        )

    def to_json(self) -> dict:
        """Per-blob lists and the metadata, JSON-serialisable."""
        d = {k: np.asarray(getattr(self, k)).tolist() for k in self._ARRAYS}
        d.update(threshold_used=float(self.threshold_used), background_level=float(self.background_level),
                 noise_sigma=float(self.noise_sigma), rejected=dict(self.rejected),
                 n_components=int(self.n_components), n_blobs=len(self))
        return d


# ------------------------------------------------------------------ input
def to_gray(image, *, name: str = "image") -> np.ndarray:
    """Check an image and return its luminance as a 2-D array.

    Parameters
    ----------
    image : array_like, shape (H, W), (H, W, 1), (H, W, 3) or (H, W, 4)
        Grey or RGB(A) image; unsigned/signed integer or float. Alpha is ignored.
    name : str
        Name used in error messages.

    Returns
    -------
    gray : ndarray, shape (H, W)
        uint8 and uint16 stay as they are (colour is converted with rounding); other
        integer types become float32; float32/float64 stay.

    Raises
    ------
    InputError
        Wrong number of dimensions or channels, empty, non-numeric, or non-finite values.
    """
    try:
        img = np.asarray(image)
    except Exception:  # noqa: BLE001 - anything that is not an array is bad input
        raise InputError(f"{name}: expected a numeric array, got {type(image).__name__}") from None
    if img.dtype == bool or not (np.issubdtype(img.dtype, np.integer) or np.issubdtype(img.dtype, np.floating)):
        raise InputError(f"{name}: expected an integer or float image, got dtype {img.dtype}")
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[..., 0]
    if img.ndim not in (2, 3) or (img.ndim == 3 and img.shape[2] not in (3, 4)):
        raise InputError(f"{name}: expected shape (H, W) or (H, W, 3), got {img.shape}")
    if img.size == 0:
        raise InputError(f"{name}: empty array of shape {img.shape}")
    if img.dtype not in (np.uint8, np.uint16, np.float32, np.float64):
        img = img.astype(np.float32)
    if img.dtype == np.float64 and img.ndim == 3:
        img = img.astype(np.float32)
    if np.issubdtype(img.dtype, np.floating):
        # cheap test first: sum is finite unless a value is NaN/inf (or the sum overflows)
        if not np.isfinite(img.sum()) and not np.all(np.isfinite(img)):
            raise InputError(f"{name}: contains NaN or infinite values")
    if img.ndim == 3:
        if img.shape[2] == 4:
            img = img[..., :3]
        img = cv2.cvtColor(np.ascontiguousarray(img), cv2.COLOR_RGB2GRAY)
    return np.ascontiguousarray(img)


def _default_saturation(dtype) -> float:
    if np.issubdtype(dtype, np.integer):
        return float(np.iinfo(dtype).max)
    return float("inf")


# ------------------------------------------------------------------ threshold
def background_stats(gray: np.ndarray, samples: int = BACKGROUND_SAMPLES) -> tuple[float, float]:
    """Background level (median) and robust noise sigma from a subsample.

    Float images: median and 1.4826 x MAD. 8/16-bit images: median and inter-quartile
    range / 1.349 interpolated in the histogram (robust to quantisation).

    Parameters
    ----------
    gray : ndarray, shape (H, W)
    samples : int
        About this many pixels are used (a regular grid).

    Returns
    -------
    background, sigma : float
        Image units.
    """
    H, W = gray.shape
    step = max(1, int(np.sqrt(H * W / max(samples, 1))))
    s = np.ascontiguousarray(gray[step // 2::step, step // 2::step]).ravel()
    if s.dtype in (np.uint8, np.uint16):
        # integer samples: quantiles interpolated in the histogram (each value spread over
        # its unit bin), sigma from the inter-quartile range - the MAD of quantised noise
        # of a few DN is itself quantised to whole DN
        hist = np.bincount(s, minlength=2)
        c = np.cumsum(hist)

        def q(f):
            target = f * c[-1]
            v = int(np.searchsorted(c, target))
            below = c[v - 1] if v > 0 else 0
            return v - 0.5 + (target - below) / max(hist[v], 1)

        med = q(0.5)
        return float(med), float((q(0.75) - q(0.25)) / 1.3490)
    s = s.astype(np.float32)
    med = float(np.median(s))
    mad = float(np.median(np.abs(s - med)))
    return med, 1.4826 * mad


def auto_threshold(gray: np.ndarray, *, k_sigma: float = AUTO_K_SIGMA, peak_fraction: float = AUTO_PEAK_FRACTION):
    """The automatic threshold (see the module notes).

    Returns
    -------
    threshold, background, sigma : float
    """
    bg, sigma = background_stats(gray)
    if np.issubdtype(gray.dtype, np.integer):
        sigma = max(sigma, 0.5)
    _, vmax, _, _ = cv2.minMaxLoc(gray)
    floor = peak_fraction * max(vmax - bg, 0.0)
    level = bg + max(k_sigma * sigma, floor)
    if not sigma > 0 and not floor > 0:  # a constant float frame: nothing is above it
        level = bg
    return float(level), bg, sigma


def _otsu(gray: np.ndarray) -> float:
    if gray.dtype == np.uint8:
        t, _ = cv2.threshold(gray, 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
        return float(t)
    from skimage.filters import threshold_otsu

    H, W = gray.shape
    step = max(1, int(np.sqrt(H * W / BACKGROUND_SAMPLES)))
    s = np.asarray(gray[::step, ::step], np.float64)
    if np.ptp(s) == 0:
        return float(s.flat[0])
    return float(threshold_otsu(s))


def parse_threshold(text):
    """A ``--threshold`` option: None, ``'app'``, ``'auto'``, ``'otsu'`` or a non-negative level.

    Parameters
    ----------
    text : str or None
        ``app`` (the app's threshold; same as None), ``auto``, ``otsu`` or a number (image counts).

    Returns
    -------
    None, str or float
        What :func:`detect_blobs` takes as ``threshold``.

    Raises
    ------
    InputError
        Not a number, negative or not finite.
    """
    if text is None or text in ("auto", "otsu"):
        return text
    if text == "app":
        return None
    try:
        v = float(text)
    except ValueError:
        raise InputError(f"--threshold: expected a number, 'app', 'auto' or 'otsu', got {text!r}") from None
    if not np.isfinite(v) or v < 0:
        raise InputError(f"--threshold: expected a non-negative finite level, got {text!r}")
    return v


def app_level(dtype, threshold_dn: float | None = None) -> float:
    """The app's brightness threshold (8-bit DN) as a level of an image of ``dtype``.

    Parameters
    ----------
    dtype : numpy dtype
        The image's type: uint8 and float images take the 8-bit value as it is (the camera model's
        float images are in 8-bit units), uint16 ones scale it by 257.
    threshold_dn : float, optional
        Default: :func:`svgs_sim.svgs.app.settings`' ``threshold_dn``.

    Returns
    -------
    float
        The level in the image's units.
    """

    t = settings().threshold_dn if threshold_dn is None else float(threshold_dn)
    return t * 257.0 if np.dtype(dtype) == np.uint16 else t


def _resolve_threshold(gray, threshold, k_sigma, peak_fraction):
    if isinstance(threshold, str) and threshold == "auto":
        return auto_threshold(gray, k_sigma=k_sigma, peak_fraction=peak_fraction)
    bg, sigma = background_stats(gray)
    if threshold is None or (isinstance(threshold, str) and threshold == "app"):
        if np.issubdtype(gray.dtype, np.floating) and 0 < float(gray.max()) <= 1.0:

            warnings.warn("a float image with values in [0, 1]: the app's brightness threshold is in 8-bit counts "
                          "(0-255), so no pixel passes it; scale the image to 0-255 or pass threshold='auto' or a "
                          "level", stacklevel=3)
        return app_level(gray.dtype), bg, sigma
    if isinstance(threshold, str):
        if threshold == "otsu":
            return _otsu(gray), bg, sigma
        raise InputError(f"threshold: expected a number, 'app', 'auto' or 'otsu', got {threshold!r}")
    if isinstance(threshold, bool):
        raise InputError(f"threshold: expected a number, 'app', 'auto' or 'otsu', got {threshold!r}")
    try:
        t = float(threshold)
    except (TypeError, ValueError):
        raise InputError(f"threshold: expected a number, 'app', 'auto' or 'otsu', got {threshold!r}") from None
    if not np.isfinite(t):
        raise InputError(f"threshold: expected a finite level, got {threshold!r}")
    return t, bg, sigma


def _check_level_below_full_scale(level: float, dtype) -> None:
    """Refuse a level no pixel of an integer image can pass (foreground is strictly above it)."""
    if np.issubdtype(dtype, np.integer):
        top = int(np.iinfo(dtype).max)
        if level >= top:
            bits = 8 * np.dtype(dtype).itemsize
            raise InputError(f"threshold: {level:g} is at or above the largest value of this {bits}-bit image "
                             f"({top}, a saturated pixel); no pixel can pass it - give a level below {top}")


# ------------------------------------------------------------------ components
def _components(binary: np.ndarray, block: int = COARSE_BLOCK_PX):
    """Connected components (8-connectivity) of a 0/255 uint8 image.

    Returns a list of ``(labels, stats, x0, y0)``: labels of a sub-image whose top-left pixel
    is ``(x0, y0)`` and OpenCV's stats rows (label 0, the background, excluded) in that
    sub-image's coordinates.
    """
    H, W = binary.shape
    if cv2.countNonZero(binary) == 0:
        return []
    # block-OR image: OR over each block's rows with numpy (SIMD), then over its columns
    Hb, Wb = -(-H // block), -(-W // block)
    H8 = (H // block) * block
    r1 = binary[:H8].reshape(H // block, block, W).max(1)
    if H8 < H:
        r1 = np.concatenate([r1, binary[H8:].max(0, keepdims=True)], 0)
    if Wb * block != W:
        r1 = cv2.copyMakeBorder(r1, 0, 0, 0, Wb * block - W, cv2.BORDER_CONSTANT, value=0)
    # INTER_AREA with an integer factor averages each block: > 0 iff a pixel is set
    coarse = cv2.resize(r1, (Wb, Hb), interpolation=cv2.INTER_AREA)
    n, _, cstats, _ = cv2.connectedComponentsWithStats(coarse, connectivity=8, ltype=cv2.CV_32S)
    if n - 1 > COARSE_MAX_REGIONS:
        n, labels, stats, _ = cv2.connectedComponentsWithStats(binary, connectivity=8, ltype=cv2.CV_32S)
        return [(labels, stats[1:], 0, 0)]
    out = []
    for cx, cy, cw, ch, _ in cstats[1:]:
        x0, y0 = cx * block, cy * block
        x1, y1 = min((cx + cw) * block, W), min((cy + ch) * block, H)
        sub = binary[y0:y1, x0:x1]
        m, labels, stats, _ = cv2.connectedComponentsWithStats(sub, connectivity=8, ltype=cv2.CV_32S)
        if m > 1:
            out.append((labels, stats[1:], x0, y0))
    return out


# ------------------------------------------------------------------ per-blob measurement
def _shape(mask: np.ndarray, area: int):
    """Eccentricity (pixels as unit squares) and roundness of a blob mask."""
    ys, xs = np.nonzero(mask)
    xs = xs.astype(np.float64)
    ys = ys.astype(np.float64)
    cxx = xs.var() + 1.0 / 12.0
    cyy = ys.var() + 1.0 / 12.0
    cxy = np.mean((xs - xs.mean()) * (ys - ys.mean()))
    tr, det = cxx + cyy, cxx * cyy - cxy * cxy
    disc = np.sqrt(max(tr * tr / 4.0 - det, 0.0))
    l1, l2 = tr / 2.0 + disc, tr / 2.0 - disc
    ecc = float(np.sqrt(max(1.0 - l2 / l1, 0.0)))
    contours, _ = cv2.findContours(mask.view(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    perim = sum(cv2.arcLength(c, True) for c in contours) + np.pi
    roundness = float(min(1.0, 4.0 * np.pi * area / perim**2))
    return ecc, roundness


def _ring_background(gray, x0, y0, w, h, pad, fallback):
    """Median of the ring of width ``pad`` around a bounding box (image border clipped)."""
    H, W = gray.shape
    X0, Y0, X1, Y1 = max(x0 - pad, 0), max(y0 - pad, 0), min(x0 + w + pad, W), min(y0 + h + pad, H)
    win = gray[Y0:Y1, X0:X1]
    parts = [win[: y0 - Y0].ravel(), win[y0 + h - Y0:].ravel(),
             win[y0 - Y0: y0 + h - Y0, : x0 - X0].ravel(), win[y0 - Y0: y0 + h - Y0, x0 + w - X0:].ravel()]
    ring = np.concatenate(parts)
    if ring.size < 8:
        return fallback
    return float(np.median(ring))


def windowed_centroid(gray, u0, v0, sigma_w, background, *, foreground=None, own=None, max_iter=WIN_MAX_ITER,
                      tol_px=WIN_TOL_PX):
    """Gaussian-weighted iterative centroid around ``(u0, v0)``.

    Iterates ``x <- x + 2 sum(w I (x_i - x)) / sum(w I)`` with ``w`` a Gaussian of sigma
    ``sigma_w`` centred on ``x`` and ``I`` the background-subtracted values in a window of
    half-width ``4 sigma_w + 2`` px. The factor 2 makes one step exact for a Gaussian spot
    of sigma ``sigma_w``; the fixed point is the centre of any symmetric spot.

    ``foreground`` (the frame's binary image, nonzero above the threshold, shape (H, W)) masks
    every foreground pixel of the window (its value taken as 0) except this blob's own, ``own =
    (mask, x0, y0)`` (its component's mask and that mask's top-left pixel): the window takes in
    no other blob's thresholded light, as SExtractor's windowed measurements mask the other
    objects of its segmentation map.

    Returns
    -------
    (u, v) : tuple of float, or None if the iteration failed (no positive signal, or it
        walked out of the window).
    """
    H, W = gray.shape
    r = int(np.ceil(4.0 * sigma_w)) + 2
    iu, iv = int(round(u0)), int(round(v0))
    X0, X1 = max(iu - r, 0), min(iu + r + 1, W)
    Y0, Y1 = max(iv - r, 0), min(iv + r + 1, H)
    I = gray[Y0:Y1, X0:X1].astype(np.float64) - background
    xs = np.arange(X0, X1, dtype=np.float64)
    ys = np.arange(Y0, Y1, dtype=np.float64)
    if foreground is not None:
        other = foreground[Y0:Y1, X0:X1] > 0
        if own is not None:
            m, mx0, my0 = own
            ys0, ys1 = max(Y0, my0), min(Y1, my0 + m.shape[0])
            xs0, xs1 = max(X0, mx0), min(X1, mx0 + m.shape[1])
            if ys1 > ys0 and xs1 > xs0:
                other[ys0 - Y0:ys1 - Y0, xs0 - X0:xs1 - X0] &= ~m[ys0 - my0:ys1 - my0, xs0 - mx0:xs1 - mx0]
        I = np.where(other, 0.0, I)
    u, v = float(u0), float(v0)
    k = -0.5 / (sigma_w * sigma_w)
    for _ in range(max_iter):
        dx, dy = xs - u, ys - v
        gx, gy = np.exp(k * dx * dx), np.exp(k * dy * dy)
        row = gy @ I  # (nx,)
        col = I @ gx  # (ny,)
        s = row @ gx
        if not s > 0:
            return None
        du = 2.0 * (row @ (gx * dx)) / s
        dv = 2.0 * (col @ (gy * dy)) / s
        u += du
        v += dv
        if abs(u - u0) > r - 1 or abs(v - v0) > r - 1:
            return None
        if abs(du) < tol_px and abs(dv) < tol_px:
            break
    return u, v


# ------------------------------------------------------------------ main entry
def detect_blobs(
    image,
    *,
    threshold=None,
    min_area_px: int = MIN_AREA_PX,
    max_area_px: int = MAX_AREA_PX,
    max_eccentricity: float = MAX_ECCENTRICITY,
    min_roundness: float = MIN_ROUNDNESS,
    shape_gate_min_area_px: int = SHAPE_GATE_MIN_AREA_PX,
    max_blobs: int = MAX_BLOBS,
    saturation_level=None,
    centroid: str | None = None,
    k_sigma: float = AUTO_K_SIGMA,
    peak_fraction: float = AUTO_PEAK_FRACTION,
) -> Blobs:
    """Find bright blobs and measure them.

    Parameters
    ----------
    image : array_like, shape (H, W) or (H, W, 3)
        uint8, uint16 or float image, grey or RGB.
    threshold : None, "app", "auto", "otsu" or float
        Binarisation level in image units (pixels strictly above it are foreground).
        ``None`` or ``"app"``: the app's brightness threshold (:func:`svgs_sim.svgs.app.settings`, ``threshold_dn``
        on the 8-bit scale; x257 for 16-bit images). ``"auto"``: background + ``k_sigma``
        robust sigmas, at least ``peak_fraction`` of the brightest value above background.
    min_area_px, max_area_px : int
        Size gate on the number of thresholded pixels (defaults 3 and 20000).
    max_eccentricity : float
        Shape gate (default 0.97: drops streaks and glints longer than about 1 x 5 px).
    min_roundness : float
        Shape gate on ``4 pi A / P^2`` (default 0.3: drops ragged, branched regions).
    shape_gate_min_area_px : int
        The shape gates only judge blobs at least this large (default 12 px).
    max_blobs : int
        At most this many blobs are measured; the largest are kept (default 256).
    saturation_level : float, optional
        Values at or above it count as saturated; default the integer type's maximum
        (none for float images).
    centroid : {"weighted", "binary", "window"}, optional
        The intensity-weighted centroid of each blob's own pixels (the paper's rule, the app's
        default), their unweighted centroid, or the deblended Gaussian-windowed centroid (see
        the module notes). ``"component"`` is another name of ``"weighted"``.
    k_sigma, peak_fraction : float
        Parameters of the automatic threshold.

    Returns
    -------
    Blobs
        Sorted by flux, brightest first; empty (well-shaped) when nothing passes.

    Raises
    ------
    InputError
        For a bad ``image`` (see :func:`to_gray`) or bad options.
    """
    gray = to_gray(image)
    centroid = _check_options(centroid, min_area_px, max_area_px, max_blobs)
    sat = _default_saturation(gray.dtype) if saturation_level is None else float(saturation_level)
    level, bg, sigma = _resolve_threshold(gray, threshold, k_sigma, peak_fraction)
    _check_level_below_full_scale(level, np.asarray(image).dtype)
    meta = dict(threshold_used=level, background_level=bg, noise_sigma=sigma, saturation_level=sat,
                image_shape=tuple(gray.shape),
                image_max=float(np.max(gray)) if gray.size and np.issubdtype(np.asarray(image).dtype, np.floating)
                else float("nan"))
    binary = _binarise(gray, level)
    if binary is None:
        return Blobs.empty(**meta)
    rejected = {g: 0 for g in GATES}
    cand, n_components = _size_gated_candidates(binary, min_area_px, max_area_px, max_blobs, rejected)
    rows = []
    for c in cand:
        row = _measure_candidate(gray, c, bg, sat, centroid, max_eccentricity, min_roundness,
                                 shape_gate_min_area_px, rejected)
        if row is not None:
            rows.append(row)
    if centroid == "window":
        _deblended_windows(gray, binary, rows)
    meta.update(rejected=rejected, n_components=n_components)
    return _blobs_from_rows(rows, meta)


def _check_options(centroid, min_area_px, max_area_px, max_blobs) -> str:
    """The centroid rule (the app's default for None; ``"component"`` -> ``"weighted"``); raise
    :class:`InputError` for a bad one or a non-positive integer gate."""

    if centroid is None:
        centroid = settings().centroid
    if centroid == "component":
        centroid = "weighted"
    if centroid not in CENTROIDS:
        raise InputError(f"centroid: expected one of {', '.join(CENTROIDS)}, got {centroid!r}")
    for nm, v in (("min_area_px", min_area_px), ("max_area_px", max_area_px), ("max_blobs", max_blobs)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
            raise InputError(f"{nm}: expected a positive integer, got {v!r}")
    return centroid


def _binarise(gray: np.ndarray, level: float):
    """Foreground mask (uint8 0/255, shape (H, W)): pixels strictly above ``level``; None when
    no pixel of an integer image can exceed it."""
    if np.issubdtype(gray.dtype, np.integer):
        top = np.iinfo(gray.dtype).max
        if level >= top:
            return None
        lev = np.floor(level) if level >= 0 else -1
        return cv2.compare(gray, float(lev), cv2.CMP_GT) if level >= 0 else np.full(gray.shape, 255, np.uint8)
    return cv2.compare(gray, float(level), cv2.CMP_GT)


def _size_gated_candidates(binary: np.ndarray, min_area_px: int, max_area_px: int, max_blobs: int,
                           rejected: dict) -> tuple[list, int]:
    """Connected components that pass the size gates, the ``max_blobs`` largest.

    Returns
    -------
    cand : list of tuple
        ``(area, x, y, w, h, labels, lab, lx0, ly0)`` in image coordinates.
    n_components : int
        Components found before the gates. ``rejected`` counts the gated ones.
    """
    cand = []
    n_components = 0
    for labels, stats, ox, oy in _components(binary):
        n_components += len(stats)
        areas = stats[:, cv2.CC_STAT_AREA]
        small = areas < min_area_px
        big = areas > max_area_px
        rejected["min_area"] += int(small.sum())
        rejected["max_area"] += int(big.sum())
        for j in np.flatnonzero(~small & ~big):
            x, y, w, h, a = stats[j]
            cand.append((int(a), int(x) + ox, int(y) + oy, int(w), int(h), labels, j + 1, ox, oy))
    if len(cand) > max_blobs:
        cand.sort(key=lambda c: -c[0])
        rejected["max_blobs"] = len(cand) - max_blobs
        cand = cand[:max_blobs]
    return cand, n_components


def _measure_candidate(gray, cand, bg, sat, centroid, max_eccentricity, min_roundness, shape_gate_min_area_px,
                       rejected: dict):
    """Shape gates and measurements of one candidate component.

    Returns
    -------
    tuple or None
        ``(u, v, area, x, y, w, h, peak, saturated_fraction, eccentricity, roundness, flux,
        background, window_sigma, (mask, x, y))``: the centroid is the weighted (or binary) one,
        ``window_sigma`` the windowed centroid's Gaussian sigma (px; 0 unless ``centroid`` is
        ``"window"``) and ``(mask, x, y)`` the component's mask and its top-left pixel (for the
        deblending); None when a shape gate rejects it (counted in ``rejected``).
    """
    a, x, y, w, h, labels, lab, ox, oy = cand
    mask = labels[y - oy: y - oy + h, x - ox: x - ox + w] == lab
    vals = gray[y: y + h, x: x + w]
    ecc, rnd = _shape(mask, a)
    if a >= shape_gate_min_area_px:
        if ecc > max_eccentricity:
            rejected["eccentricity"] += 1
            return None
        if rnd < min_roundness:
            rejected["roundness"] += 1
            return None
    pad = max(2, int(round(0.5 * np.sqrt(a))))
    bgl = _ring_background(gray, x, y, w, h, pad, bg)
    v = vals[mask].astype(np.float64)
    I = np.clip(v - bgl, 0.0, None)
    flux = float(I.sum())
    peak = float(v.max())
    satf = float(np.count_nonzero(v >= sat)) / a
    yy, xx = np.nonzero(mask)
    if flux > 0 and centroid != "binary":
        uc = float((I * xx).sum() / flux) + x
        vc = float((I * yy).sum() / flux) + y
    else:
        uc, vc = float(xx.mean()) + x, float(yy.mean()) + y
    sw = 0.0
    if centroid == "window" and flux > 0:
        half = 0.5 * (peak - bgl)
        a_half = max(int(np.count_nonzero(v - bgl >= half)), 1)
        fwhm = 2.0 * np.sqrt(a_half / np.pi)
        sw = max(fwhm / 2.3548, WIN_MIN_SIGMA_PX)
    return (uc, vc, a, x, y, w, h, peak, satf, ecc, rnd, flux, bgl, sw, (mask, x, y))


def _deblended_windows(gray, binary, rows: list) -> None:
    """Replace each row's centroid by its windowed centroid (in place), deblended: every other
    blob's thresholded pixels masked (``binary`` is the frame's foreground, 0/255), and the
    window's reach (``4 sigma + 2``) at most half the distance to the nearest other blob (sigma
    never below :data:`WIN_MIN_SIGMA_PX`), so the Gaussian weights a neighbour's sub-threshold halo
    by less than ``exp(-8)``."""
    c = np.array([(r[0], r[1]) for r in rows], np.float64)
    for i, r in enumerate(rows):
        if not r[13] > 0:
            continue
        sw = r[13]
        if len(rows) > 1:  # the window stays on this blob's side: its reach at most half-way to the nearest blob
            d_nn = float(np.sqrt(np.min(np.sum((np.delete(c, i, axis=0) - c[i]) ** 2, axis=1))))
            sw = max(min(sw, (0.5 * d_nn - 2.0) / 4.0), WIN_MIN_SIGMA_PX)
        res = windowed_centroid(gray, r[0], r[1], sw, r[12], foreground=binary, own=r[14])
        if res is not None:
            rows[i] = (res[0], res[1], *r[2:])


def _blobs_from_rows(rows: list, meta: dict) -> Blobs:
    """:class:`Blobs` from the measured rows (see :func:`_measure_candidate`), brightest first."""
    if not rows:
        return Blobs.empty(**meta)
    r = np.array([row[:14] for row in rows], dtype=np.float64)
    order = np.argsort(-r[:, 11], kind="stable")
    r = r[order]
    return Blobs(
        centroid_px=r[:, 0:2].copy(),
        area_px=r[:, 2].astype(int),
        bbox=r[:, 3:7].astype(int),
        peak=r[:, 7].copy(),
        saturated_fraction=r[:, 8].copy(),
        eccentricity=r[:, 9].copy(),
        roundness=r[:, 10].copy(),
        flux=r[:, 11].copy(),
        background=r[:, 12].copy(),
        **meta,
    )

__all__ = ["Blobs", "detect_blobs", "to_gray", "auto_threshold", "app_level", "background_stats", "windowed_centroid",
           "GATES"]
