"""Candidate reflector blobs (paper section 3.2).

A blob is a contiguous (8-connected) region of the filtered active set whose

1. gray values are all above the low gray threshold and at least one is above the high one;
2. filtered intensities are all above the low filtered threshold and at least one above the
   high one;
3. pixel count lies between ``min_pixels`` and ``max_pixels``, and whose eccentricity is at
   most ``max_eccentricity``.

Criteria 1 and 2 are hysteresis thresholds, i.e. morphological reconstruction of the
"high" pixels inside the "low" mask (the paper's four binary images): the low thresholds
are those of the active set (every active pixel passes them), so reconstruction reduces to
labelling the active mask (8-connected, ``cv2.connectedComponents``) and keeping the components whose maxima pass the high
thresholds (tested equal to ``skimage.morphology.reconstruction``). Criterion 3 is the
connected-component analysis, with moments from ``np.bincount``.

ASSUMPTION (values not legible in the paper): high gray threshold 0.5 x frame maximum; high
filtered threshold 0.2 x largest response; 3 <= pixels <= 8000; eccentricity <= 0.92
(a circle tilted by up to ~67 deg).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from .active import ActiveSet

DEFAULT_HIGH_GRAY_REL = 0.5
DEFAULT_HIGH_FILTERED_REL = 0.2
DEFAULT_MIN_PIXELS = 3
DEFAULT_MAX_PIXELS = 8000
DEFAULT_MAX_ECCENTRICITY = 0.92

@dataclass
class Blobs:
    """Candidate blobs, as arrays over blobs (``n``) and over member pixels.

    Attributes
    ----------
    n_pixels : ndarray of int, shape (n,)
    centroid_px : ndarray, shape (n, 2)
        Unweighted centroid ``(u, v)``.
    cov_px2 : ndarray, shape (n, 2, 2)
        Second central moments of the member pixels (each pixel a unit square).
    eccentricity : ndarray, shape (n,)
    bbox : ndarray of int, shape (n, 4)
        ``(u0, v0, u1, v1)``, inclusive.
    peak_gray, peak_filtered : ndarray, shape (n,)
    rows, cols : ndarray of intp, shape (m,)
        Member pixels of all blobs, grouped by blob.
    blob_of_pixel : ndarray of intp, shape (m,)
        Blob index (0..n-1) of each member pixel.
    gray, filtered : ndarray, shape (m,)
        Member pixels' raw gray and filtered intensities.
    rejected : dict
        Count of rejected components per reason.
    rejected_bbox : ndarray of int, shape (k, 4)
        Boxes of components rejected by the size/shape gates (for ellipse supplementing).
    rejected_rows, rejected_cols : list of ndarray
        Their member pixels.
    """

    n_pixels: np.ndarray
    centroid_px: np.ndarray
    cov_px2: np.ndarray
    eccentricity: np.ndarray
    bbox: np.ndarray
    peak_gray: np.ndarray
    peak_filtered: np.ndarray
    rows: np.ndarray
    cols: np.ndarray
    blob_of_pixel: np.ndarray
    gray: np.ndarray
    filtered: np.ndarray
    rejected: dict = field(default_factory=dict)
    rejected_bbox: np.ndarray = field(default_factory=lambda: np.zeros((0, 4), int))
    rejected_rows: list = field(default_factory=list)
    rejected_cols: list = field(default_factory=list)

    @property
    def n(self) -> int:
        return int(self.n_pixels.size)

    def mask(self, shape) -> np.ndarray:
        """Boolean image of all member pixels."""
        m = np.zeros(shape, bool)
        m[self.rows, self.cols] = True
        return m


def _moments(lab, rows, cols, nlab):
    """Count, centroid, covariance per label (labels 0..nlab-1) via bincount."""
    cnt = np.bincount(lab, minlength=nlab).astype(float)
    x = cols.astype(float)
    y = rows.astype(float)
    sx = np.bincount(lab, x, nlab)
    sy = np.bincount(lab, y, nlab)
    sxx = np.bincount(lab, x * x, nlab)
    syy = np.bincount(lab, y * y, nlab)
    sxy = np.bincount(lab, x * y, nlab)
    with np.errstate(invalid="ignore", divide="ignore"):
        mx, my = sx / cnt, sy / cnt
        cxx = sxx / cnt - mx * mx + 1.0 / 12.0
        cyy = syy / cnt - my * my + 1.0 / 12.0
        cxy = sxy / cnt - mx * my
    cov = np.stack([np.stack([cxx, cxy], -1), np.stack([cxy, cyy], -1)], -2)
    return cnt, np.stack([mx, my], -1), cov


def eccentricity_from_cov(cov) -> np.ndarray:
    """``sqrt(1 - l_min / l_max)`` of covariance matrices, shape (..., 2, 2) -> (...)."""
    cov = np.asarray(cov, float)
    a, b, c = cov[..., 0, 0], cov[..., 1, 1], cov[..., 0, 1]
    tr2 = (a + b) / 2
    d = np.sqrt(((a - b) / 2) ** 2 + c * c)
    lmax, lmin = tr2 + d, tr2 - d
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.sqrt(np.clip(1 - lmin / lmax, 0, 1))


def _no_blobs() -> Blobs:
    """A :class:`Blobs` with no blob (an empty active set)."""
    return Blobs(np.zeros(0, int), np.zeros((0, 2)), np.zeros((0, 2, 2)), np.zeros(0), np.zeros((0, 4), int),
                 np.zeros(0), np.zeros(0), np.zeros(0, np.intp), np.zeros(0, np.intp), np.zeros(0, np.intp),
                 np.zeros(0), np.zeros(0))


def _gates(pg, pf, cnt, ecc, hg: float, hf: float, min_pixels: int, max_pixels: int, max_eccentricity: float):
    """The hysteresis, size and eccentricity gates of :func:`find_blobs`, per connected component.

    Parameters
    ----------
    pg, pf : ndarray, shape (n_labels,)
        Peak gray and peak filtered intensity of each component.
    cnt : ndarray, shape (n_labels,)
        Pixel count of each component.
    ecc : ndarray, shape (n_labels,)
        Eccentricity of each component.
    hg, hf : float
        High thresholds on the peak gray and the peak filtered intensity.
    min_pixels, max_pixels : int
    max_eccentricity : float

    Returns
    -------
    keep : ndarray of bool, shape (n_labels,)
        Components that pass every gate.
    gate_rej : ndarray of bool, shape (n_labels,)
        Components above the high thresholds and ``min_pixels`` that a size or shape gate rejected.
    rejected : dict
        Counts of components rejected by each gate (``below_high_thresholds``, ``size``, ``eccentricity``).
    """
    rejected = {}
    hyst = (pg > hg) & (pf > hf)
    rejected["below_high_thresholds"] = int(np.sum(~hyst))
    size_ok = (cnt >= min_pixels) & (cnt <= max_pixels)
    shape_ok = ecc <= max_eccentricity
    rejected["size"] = int(np.sum(hyst & ~size_ok))
    rejected["eccentricity"] = int(np.sum(hyst & size_ok & ~shape_ok))
    keep = hyst & size_ok & shape_ok
    gate_rej = hyst & ~(size_ok & shape_ok) & (cnt >= min_pixels)
    return keep, gate_rej, rejected


def find_blobs(
    active: ActiveSet,
    filtered,
    *,
    high_gray: float | None = None,
    high_filtered: float | None = None,
    high_gray_rel: float = DEFAULT_HIGH_GRAY_REL,
    high_filtered_rel: float = DEFAULT_HIGH_FILTERED_REL,
    min_pixels: int = DEFAULT_MIN_PIXELS,
    max_pixels: int = DEFAULT_MAX_PIXELS,
    max_eccentricity: float = DEFAULT_MAX_ECCENTRICITY,
) -> Blobs:
    """Hysteresis + connected components with size and eccentricity gates.

    Parameters
    ----------
    active : ActiveSet
        The filtered active set (every pixel already passes the low thresholds).
    filtered : array_like, shape (active.n,)
        Filtered intensity of each active pixel.
    high_gray, high_filtered : float, optional
        Absolute high thresholds; default ``high_gray_rel * active.gray_max`` and
        ``high_filtered_rel * max(filtered)``.
    min_pixels, max_pixels : int
    max_eccentricity : float

    Returns
    -------
    Blobs
        Ordered by decreasing peak filtered intensity.
    """
    f = np.asarray(filtered, np.float32)
    H, W = active.shape
    if active.n == 0:
        return _no_blobs()
    hg = high_gray_rel * active.gray_max if high_gray is None else float(high_gray)
    hf = high_filtered_rel * float(max(f.max(), 0.0)) if high_filtered is None else float(high_filtered)
    mask = np.zeros((H, W), bool)
    mask[active.rows, active.cols] = True
    nlab, labels = cv2.connectedComponents(mask.view(np.uint8), connectivity=8, ltype=cv2.CV_32S)
    nlab -= 1  # label 0 is the background
    lab = labels[active.rows, active.cols] - 1
    # per-label reductions on the pixels sorted by label (every label has >= 1 pixel)
    srt = np.argsort(lab, kind="stable")
    starts = np.searchsorted(lab[srt], np.arange(nlab))
    pg = np.maximum.reduceat(active.gray[srt], starts)
    pf = np.maximum.reduceat(f[srt], starts)
    cnt, cen, cov = _moments(lab, active.rows, active.cols, nlab)
    ecc = eccentricity_from_cov(cov)
    keep, gate_rej, rejected = _gates(pg, pf, cnt, ecc, hg, hf, min_pixels, max_pixels, max_eccentricity)
    # bounding boxes per label
    cs, rs = active.cols[srt], active.rows[srt]
    u0, u1 = np.minimum.reduceat(cs, starts), np.maximum.reduceat(cs, starts)
    v0, v1 = np.minimum.reduceat(rs, starts), np.maximum.reduceat(rs, starts)
    bbox = np.stack([u0, v0, u1, v1], -1)
    kept = np.flatnonzero(keep)
    kept = kept[np.argsort(-pf[kept], kind="stable")]
    new_id = np.full(nlab, -1, np.intp)
    new_id[kept] = np.arange(kept.size)
    member = new_id[lab] >= 0
    order = np.argsort(new_id[lab][member], kind="stable")
    sel = np.flatnonzero(member)[order]
    rej = np.flatnonzero(gate_rej)
    ends = np.append(starts[1:], lab.size)
    rej_rows = [rs[starts[k]:ends[k]] for k in rej]
    rej_cols = [cs[starts[k]:ends[k]] for k in rej]
    return Blobs(
        n_pixels=cnt[kept].astype(int),
        centroid_px=cen[kept],
        cov_px2=cov[kept],
        eccentricity=ecc[kept],
        bbox=bbox[kept],
        peak_gray=pg[kept],
        peak_filtered=pf[kept],
        rows=active.rows[sel],
        cols=active.cols[sel],
        blob_of_pixel=new_id[lab[sel]],
        gray=active.gray[sel],
        filtered=f[sel],
        rejected=rejected,
        rejected_bbox=bbox[rej],
        rejected_rows=rej_rows,
        rejected_cols=rej_cols,
    )


def blobs_from_mask(mask, gray, filtered_image=None, *, min_pixels: int = DEFAULT_MIN_PIXELS,
                    max_pixels: int = DEFAULT_MAX_PIXELS) -> Blobs:
    """Blobs of a given pixel mask (used after the persistence check), no hysteresis.

    Parameters
    ----------
    mask : ndarray of bool, shape (H, W)
    gray : ndarray, shape (H, W)
        Intensity image used for the blob statistics (e.g. the mean over frames).
    filtered_image : ndarray, shape (H, W), optional
    """
    rows, cols = np.nonzero(mask)
    g = np.asarray(gray, np.float32)[rows, cols]
    f = np.zeros_like(g) if filtered_image is None else np.asarray(filtered_image, np.float32)[rows, cols]
    a = ActiveSet(rows, cols, g, mask.shape, 0.0, rows.size, float(g.max()) if g.size else 0.0, 0.0, 0.0)
    return find_blobs(a, f, high_gray=-np.inf, high_filtered=-np.inf, min_pixels=min_pixels,
                      max_pixels=max_pixels, max_eccentricity=1.0)
