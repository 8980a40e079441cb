"""Candidate reflector centroids, depths and penalty scores (paper section 3.4).

For each blob:

- weighted centroid ``sum(w x) / sum(w)`` (paper eq. 18) with the paper's ``w = gray - background``
  or (default) coverage weights over the blob and its one-pixel rim (:func:`coverage_centroids`),
  which remove the bias that the illumination gradient across a large marker gives the
  intensity weighting;
- depth: mean of the member pixels' (temporally filtered) depths (paper eq. 19), weighted by
  ``gray - background`` and after rejecting samples more than 3 robust sigmas from the blob median - mixed
  ("flying") pixels on the rim, which AMCW phasor mixing puts between the marker and the
  plate, weigh little and the far-off ones are dropped (deviation from the paper's plain mean);
- an image conic: a sub-pixel ellipse fit (:func:`svgs_sim.tof.ellipse.fit_ellipse_subpixel`) for
  blobs of at least ``ellipse_min_pixels``, else the uniform-ellipse conic of the blob's
  second moments; with a good fit the centre is the mean of the weighted centroid and the
  ellipse centre (paper: "the mean values of ... and detected ellipse centroids");
- a penalty score from size, shape and intensity; candidates with a score above
  ``max_penalty`` or a box larger than ``max_box_px`` are dropped (paper: ``P < P_max``,
  ``w < W_max``, ``h < H_max``).

The projected-circle-centre correction needs the plate normal and is applied after a first
pose (see :mod:`svgs_sim.tof.pipeline`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from svgs_sim.base.errors import InputError
from svgs_sim.base.profiles import Camera

from .blobs import Blobs
from .ellipse import EllipseFit, detect_ellipse_arcs, fit_ellipse_subpixel

#: ASSUMPTION: blobs of at least this many pixels get a sub-pixel ellipse fit (~9 px across).
DEFAULT_ELLIPSE_MIN_PIXELS = 60
#: ASSUMPTION: a blob whose pixel count differs from its moment ellipse's area by more than
#: this fraction is not a clean filled ellipse (its contour gets checked).
DEFAULT_FILL_TOL = 0.06
#: ASSUMPTION: an ellipse fit is good when its RMS Sampson distance is at most this.
DEFAULT_MAX_FIT_RMS_PX = 0.35
#: ASSUMPTION: the paper's P_max, W_max, H_max.
DEFAULT_MAX_PENALTY = 1.5
DEFAULT_MAX_BOX_PX = 160


@dataclass
class Candidates:
    """Candidate reflectors measured in one frame.

    Attributes
    ----------
    uv_px : ndarray, shape (n, 2)
        Centre estimate (before the projected-circle-centre correction).
    conic : ndarray, shape (n, 3, 3)
        Image conic of each marker (fit or moments).
    depth_m : ndarray, shape (n,)
        Blob depth (NaN when the blob has no valid depth pixel).
    depth_std_m : ndarray, shape (n,)
        Standard error of the blob depth (robust spread / sqrt(count)).
    n_depth : ndarray of int, shape (n,)
    n_pixels : ndarray of int, shape (n,)
    eccentricity : ndarray, shape (n,)
    semi_major_px : ndarray, shape (n,)
    penalty : ndarray, shape (n,)
    fit_rms_px : ndarray, shape (n,)
        RMS of the ellipse fit (NaN without a fit).
    source : ndarray of str, shape (n,)
        ``"blob"`` or ``"ellipse"`` (supplemented by ellipse detection).
    """

    uv_px: np.ndarray
    conic: np.ndarray
    depth_m: np.ndarray
    depth_std_m: np.ndarray
    n_depth: np.ndarray
    n_pixels: np.ndarray
    eccentricity: np.ndarray
    semi_major_px: np.ndarray
    penalty: np.ndarray
    fit_rms_px: np.ndarray
    source: np.ndarray
    notes: dict = field(default_factory=dict)

    @property
    def n(self) -> int:
        return int(self.uv_px.shape[0])

    def subset(self, keep) -> "Candidates":
        return Candidates(self.uv_px[keep], self.conic[keep], self.depth_m[keep], self.depth_std_m[keep],
                          self.n_depth[keep], self.n_pixels[keep], self.eccentricity[keep], self.semi_major_px[keep],
                          self.penalty[keep], self.fit_rms_px[keep], self.source[keep], dict(self.notes))

    def diameter_m(self, camera: Camera) -> np.ndarray:
        """Marker diameter implied by the image size and depth: ``2 a rho / f`` (approx.)."""
        return 2 * self.semi_major_px * self.depth_m / np.sqrt(camera.fx * camera.fy)


def _median(x) -> float:
    """Median by partition (faster than np.median on small arrays)."""
    n = x.size
    k = n // 2
    part = np.partition(x, (k - 1, k) if n % 2 == 0 and n > 1 else k)
    return float(part[k] if n % 2 else 0.5 * (part[k - 1] + part[k]))


def blob_depth(d, w, k_sigma: float = 3.0, floor_m: float = 1e-3) -> tuple[float, float, int]:
    """Robust weighted mean depth of one blob's samples.

    Parameters
    ----------
    d : ndarray, shape (m,)
        Depth samples (NaN = invalid).
    w : ndarray, shape (m,)
        Non-negative weights.

    Returns
    -------
    depth_m, std_err_m : float
        NaN when no valid sample.
    n : int
        Samples used.
    """
    ok = np.isfinite(d)
    if not ok.any():
        return np.nan, np.nan, 0
    d, w = d[ok], w[ok]
    med = _median(d)
    sig = 1.4826 * _median(np.abs(d - med))
    sel = np.abs(d - med) <= max(k_sigma * sig, floor_m)
    d, w = d[sel], w[sel]
    if w.sum() <= 0:
        w = np.ones_like(d)
    mean = float(np.sum(w * d) / np.sum(w))
    n = int(d.size)
    spread = float(np.sqrt(np.sum(w * (d - mean) ** 2) / np.sum(w))) if n > 1 else sig
    return mean, max(spread, 1e-4) / np.sqrt(n), n


def _penalty(ecc, n_pixels, cov, peak, peak_max):
    lam = np.linalg.eigvalsh(cov)
    area = np.pi * 4 * np.sqrt(np.clip(lam[..., 0], 1e-12, None) * lam[..., 1])
    fill = n_pixels / area
    return ecc**2 + np.abs(1 - fill) + (1 - peak / max(peak_max, 1e-12))


def _group_slices(groups, n_groups: int):
    """Order that sorts ``groups`` (stable) and the slice bounds of each group."""
    groups = np.asarray(groups)
    if groups.size > 1 and np.any(groups[1:] < groups[:-1]):
        order = np.argsort(groups, kind="stable")
    else:
        order = None
    g = groups if order is None else groups[order]
    bounds = np.searchsorted(g, np.arange(n_groups + 1))
    return order, bounds


def _grouped_quantile(values, groups, n_groups: int, q: float) -> np.ndarray:
    """Per-group quantile (lower, by rank) of ``values`` grouped by ``groups`` (0..n-1); NaN
    for empty groups."""
    order, bounds = _group_slices(groups, n_groups)
    v = np.asarray(values, float) if order is None else np.asarray(values, float)[order]
    out = np.full(n_groups, np.nan)
    for i in range(n_groups):
        x = v[bounds[i]:bounds[i + 1]]
        if x.size:
            k = int(q * (x.size - 1))
            out[i] = np.partition(x, k)[k]
    return out


def _grouped_median(values, groups, n_groups: int) -> np.ndarray:
    """Per-group median; NaN when empty."""
    order, bounds = _group_slices(groups, n_groups)
    v = np.asarray(values, float) if order is None else np.asarray(values, float)[order]
    out = np.full(n_groups, np.nan)
    for i in range(n_groups):
        x = v[bounds[i]:bounds[i + 1]]
        if x.size:
            out[i] = _median(x)
    return out


def _neighbour_labels(labels, size: int):
    """Largest and smallest non-zero label within a ``size x size`` window (0 / big if none)."""
    import cv2

    k = np.ones((size, size), np.uint8)
    big = np.uint16(65535)
    hi = cv2.dilate(labels, k)
    lo = cv2.erode(np.where(labels == 0, big, labels).astype(np.uint16), k)
    return hi, lo


def _pixels_of_both(mask, hi, lo):
    """Pixels of ``mask`` with the blob index ``hi - 1``, repeated with ``lo - 1`` where a
    second blob is near (``lo != hi``)."""
    rr, cc = np.nonzero(mask)
    h = hi[rr, cc].astype(np.intp)
    lw = lo[rr, cc].astype(np.intp)
    two = (lw != h) & (lw < 65535)
    return (np.concatenate([rr, rr[two]]), np.concatenate([cc, cc[two]]),
            np.concatenate([h, lw[two]]) - 1)


def coverage_centroids(gray, blobs: Blobs, background: float, local_background: bool = True,
                       min_plane_pixels: int = 20, interior_frac: float = 0.7) -> np.ndarray:
    """Coverage-weighted centroids of all blobs at once, each blob including its one-pixel rim.

    Each blob's pixels plus its one-pixel rim (pixels next to this blob only) are weighted by
    ``clip((gray - b_i) / I_i(u, v), 0, 1)``: ``b_i`` the local background (median of the ring
    2-3 px around the blob, next to no other blob), ``I_i`` the marker's own intensity: a plane
    ``a + b u + c v`` fitted to the interior pixels (signal above ``interior_frac`` of the 90th
    percentile) when the blob has at least ``min_plane_pixels`` pixels, else the 90th
    percentile. The rim holds the marker's partly covered edge pixels that fell below the
    active-set threshold; leaving them out truncates the blob unevenly and biases small blobs.

    Returns
    -------
    uv_px : ndarray, shape (n, 2)
    """
    n = blobs.n
    if n == 0:
        return np.zeros((0, 2))
    if n > 65000:
        raise InputError("too many blobs for the label image")
    H, W = gray.shape
    # work in the box holding all blobs and their 3-px surroundings
    r0, c0 = max(int(blobs.rows.min()) - 4, 0), max(int(blobs.cols.min()) - 4, 0)
    r1, c1 = min(int(blobs.rows.max()) + 5, H), min(int(blobs.cols.max()) + 5, W)
    g = np.asarray(gray, np.float32)[r0:r1, c0:c1]
    labels = np.zeros((r1 - r0, c1 - c0), np.uint16)
    labels[blobs.rows - r0, blobs.cols - c0] = (blobs.blob_of_pixel + 1).astype(np.uint16)
    hi1, lo1 = _neighbour_labels(labels, 3)
    bg = np.full(n, float(background))
    if local_background:
        hi3, lo3 = _neighbour_labels(labels, 7)
        rr, cc, lab = _pixels_of_both((hi1 == 0) & (hi3 > 0), hi3, lo3)
        cnt = np.bincount(lab, minlength=n)
        med = _grouped_median(g[rr, cc].astype(float), lab, n)
        use = (cnt >= 8) & (med > bg)
        bg[use] = med[use]
    # marker intensity model from the members
    mb = blobs.blob_of_pixel
    sig_m = blobs.gray.astype(float) - bg[mb]
    p90 = _grouped_quantile(sig_m, mb, n, 0.9)
    inner = sig_m >= interior_frac * p90[mb]
    u = blobs.cols.astype(float)
    v = blobs.rows.astype(float)
    ii = mb[inner]
    S = [np.bincount(ii, x, n) for x in (np.ones(int(inner.sum())), u[inner], v[inner], u[inner] ** 2,
                                         u[inner] * v[inner], v[inner] ** 2, sig_m[inner], u[inner] * sig_m[inner],
                                         v[inner] * sig_m[inner])]
    s0, su, sv, suu, suv, svv, ss, sus, svs = S
    A = np.stack([np.stack([s0, su, sv], -1), np.stack([su, suu, suv], -1), np.stack([sv, suv, svv], -1)], -2)
    b = np.stack([ss, sus, svs], -1)
    plane_ok = (blobs.n_pixels >= min_plane_pixels) & (s0 >= 6) & (np.abs(np.linalg.det(A)) > 1e-9)
    coef = np.zeros((n, 3))
    coef[:, 0] = p90
    if plane_ok.any():
        coef[plane_ok] = np.linalg.solve(A[plane_ok], b[plane_ok][..., None])[..., 0]
    # weights on members + rim (a rim pixel between two blobs counts for both)
    rr, cc, lab_r = _pixels_of_both((labels == 0) & (hi1 > 0), hi1, lo1)
    all_lab = np.concatenate([mb, lab_r])
    all_u = np.concatenate([u, cc.astype(float) + c0])
    all_v = np.concatenate([v, rr.astype(float) + r0])
    all_g = np.concatenate([blobs.gray.astype(float), g[rr, cc].astype(float)])
    model = coef[all_lab, 0] + coef[all_lab, 1] * all_u + coef[all_lab, 2] * all_v
    model = np.where(model > 0.5 * p90[all_lab], model, p90[all_lab])
    with np.errstate(invalid="ignore", divide="ignore"):
        w = np.clip((all_g - bg[all_lab]) / model, 0.0, 1.0)
    w = np.nan_to_num(w)
    sw = np.bincount(all_lab, w, n)
    out = np.stack([np.bincount(all_lab, w * all_u, n), np.bincount(all_lab, w * all_v, n)], -1)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = out / sw[:, None]
    bad = ~(sw > 0)
    out[bad] = blobs.centroid_px[bad]
    return out


def blob_depths(depth_samples, weights, groups, n_groups: int, k_sigma: float = 3.0, floor_m: float = 1e-3):
    """Vectorised :func:`blob_depth` over all blobs.

    Returns
    -------
    depth_m, std_err_m : ndarray, shape (n,)
    n_used : ndarray of int, shape (n,)
    """
    d = np.asarray(depth_samples, float)
    ok = np.isfinite(d)
    d, w, gr = d[ok], np.asarray(weights, float)[ok], groups[ok]
    med = _grouped_median(d, gr, n_groups)
    mad = _grouped_median(np.abs(d - med[gr]), gr, n_groups)
    tol = np.maximum(k_sigma * 1.4826 * np.nan_to_num(mad), floor_m)
    sel = np.abs(d - med[gr]) <= tol[gr]
    d, w, gr = d[sel], w[sel], gr[sel]
    n_used = np.bincount(gr, minlength=n_groups)
    sw = np.bincount(gr, w, n_groups)
    w = np.where(sw[gr] > 0, w, 1.0)
    sw = np.bincount(gr, w, n_groups)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.bincount(gr, w * d, n_groups) / sw
        var = np.bincount(gr, w * (d - mean[gr]) ** 2, n_groups) / sw
    spread = np.where(n_used > 1, np.sqrt(np.maximum(var, 0)), 1.4826 * np.nan_to_num(mad))
    err = np.maximum(spread, 1e-4) / np.sqrt(np.maximum(n_used, 1))
    mean[n_used == 0] = np.nan
    err[n_used == 0] = np.nan
    return mean, err, n_used


def measure_candidates(
    blobs: Blobs,
    gray,
    depth_m,
    background: float = 0.0,
    *,
    expected: int | None = None,
    ellipse_min_pixels: int = DEFAULT_ELLIPSE_MIN_PIXELS,
    max_fit_rms_px: float = DEFAULT_MAX_FIT_RMS_PX,
    max_penalty: float = DEFAULT_MAX_PENALTY,
    max_box_px: int = DEFAULT_MAX_BOX_PX,
    supplement: bool = True,
    weighting: str = "coverage",
    ellipse_fit: str = "auto",
    fill_tol: float = DEFAULT_FILL_TOL,
) -> Candidates:
    """Centroids, depths, conics and penalties of the candidate blobs.

    Parameters
    ----------
    blobs : Blobs
    gray : ndarray, shape (H, W)
        Intensity image the centroids are weighted with (raw or persistence mean).
    depth_m : ndarray, shape (H, W)
        Depth image (temporally filtered), NaN where invalid.
    background : float
        Background gray level subtracted from the weights.
    expected : int, optional
        Number of markers on the target. When the count differs, ellipse detection confirms
        (drops blobs whose contour is not an ellipse, if too many) or supplements (searches
        the components rejected by the gates for elliptical arcs, if too few).
    ellipse_min_pixels, max_fit_rms_px, max_penalty, max_box_px : see module constants
    supplement : bool
        Allow the edge-following ellipse detection: it supplements missing markers (count too
        low) and repairs blobs whose contour is not an ellipse (a glint or a neighbour glued to
        a marker) by taking the marker's centre from its elliptical arcs.
    ellipse_fit : {"auto", "always", "never"}
        When blobs of at least ``ellipse_min_pixels`` get the sub-pixel ellipse fit:
        ``"always"``; ``"auto"`` (default) when the blob count differs from ``expected`` (the
        paper's rule, section 3.3), or for blobs whose pixel count differs from the area of
        their moment ellipse by more than ``fill_tol`` or that touch the image border;
        ``"never"``. A fitted blob's centre is the mean of its centroid and the ellipse centre.
    fill_tol : float
        See ``ellipse_fit``.
    weighting : {"coverage", "intensity"}
        Centroid weights: ``"intensity"`` is the paper's ``w = gray - background``;
        ``"coverage"`` (default) weighs each pixel of the blob and of its one-pixel rim by
        its estimated coverage (:func:`coverage_centroids`): interior pixels weigh alike and
        only edge pixels weigh by how much of them the marker covers. The intensity weighting pulls the centroid towards
        the brighter side of a marker whose illumination falls off across it
        (``cos i / r^2``): by 0.2-0.5 px for an 80 mm marker at 0.7 m in our noise-free
        synthetic frames.

    Returns
    -------
    Candidates
    """
    gray = np.asarray(gray, np.float32)
    depth = np.asarray(depth_m, np.float32)
    w_all = np.clip(blobs.gray - background, 0, None).astype(float)
    uvw = _weighted_centroids(gray, blobs, background, weighting, w_all)
    d_all = depth[blobs.rows, blobs.cols]
    m = _moment_measures(blobs, uvw, d_all, w_all)
    if ellipse_fit not in ("auto", "always", "never"):
        raise InputError(f"ellipse_fit: expected 'auto', 'always' or 'never', got {ellipse_fit!r}")
    fit_me = _blobs_to_fit(blobs, gray.shape, ellipse_fit, expected, ellipse_min_pixels, fill_tol)
    _fit_ellipses(m, gray, blobs, fit_me, uvw, d_all, w_all, background, max_fit_rms_px, supplement)
    pen, ok, notes = _gate(blobs, gray.shape, m, expected, max_penalty, max_box_px)
    cands = Candidates(m["uv"][ok], m["conics"][ok], m["dep"][ok], m["dstd"][ok], m["nd"][ok], blobs.n_pixels[ok],
                       blobs.eccentricity[ok], m["semi"][ok], pen[ok], m["rms"][ok], m["source"][ok], notes)
    if supplement and expected is not None and cands.n < expected and len(blobs.rejected_rows):
        extra = _supplement(blobs, gray, depth, background, cands.uv_px, max_fit_rms_px)
        if extra is not None and extra.n:
            cands = _concat(cands, extra)
            cands.notes["supplemented"] = int(extra.n)
    return cands


def _weighted_centroids(gray, blobs: Blobs, background: float, weighting: str, w_all) -> np.ndarray:
    """Blob centroids, shape (n, 2): coverage-weighted or the paper's intensity weighting.

    ``w_all`` (shape (m,)) holds the member pixels' ``gray - background``, clipped at 0.
    """
    n = blobs.n
    if weighting == "coverage":
        return coverage_centroids(gray, blobs, background)
    if weighting == "intensity":
        sw = np.bincount(blobs.blob_of_pixel, w_all, n)
        su = np.bincount(blobs.blob_of_pixel, w_all * blobs.cols, n)
        sv = np.bincount(blobs.blob_of_pixel, w_all * blobs.rows, n)
        with np.errstate(invalid="ignore", divide="ignore"):
            uvw = np.stack([su / sw, sv / sw], -1)
        bad_w = ~(sw > 0)
        uvw[bad_w] = blobs.centroid_px[bad_w]
        return uvw
    raise InputError(f"weighting: expected 'coverage' or 'intensity', got {weighting!r}")


def _moment_measures(blobs: Blobs, uvw, d_all, w_all) -> dict:
    """Per-blob measurements before any ellipse fit: the centroid, the blob depth and the
    uniform-ellipse conic and semi-major axis of the blob's second moments.

    Returns
    -------
    dict of ndarray
        ``uv`` (n, 2), ``conics`` (n, 3, 3), ``dep``, ``dstd``, ``nd``, ``rms`` (NaN: no fit
        yet), ``semi`` (n,), and the flags ``confirmed``, ``fitted`` and ``source`` (n,).
    """
    n = blobs.n
    m = {
        "uv": uvw.copy(),
        "conics": np.empty((n, 3, 3)),
        "dep": np.full(n, np.nan),
        "dstd": np.full(n, np.nan),
        "nd": np.zeros(n, int),
        "rms": np.full(n, np.nan),
        "semi": np.empty(n),
        "confirmed": np.ones(n, bool),
        "fitted": np.zeros(n, bool),
        "source": np.array(["blob"] * n, dtype=object),
    }
    if n:
        m["dep"], m["dstd"], m["nd"] = blob_depths(d_all, w_all, blobs.blob_of_pixel, n)
        A = np.linalg.inv(4.0 * blobs.cov_px2)
        conics = m["conics"]
        conics[:, :2, :2] = A
        conics[:, :2, 2] = conics[:, 2, :2] = -np.einsum("nij,nj->ni", A, uvw)
        conics[:, 2, 2] = np.einsum("ni,nij,nj->n", uvw, A, uvw) - 1.0
        m["semi"] = 2 * np.sqrt(np.maximum(np.linalg.eigvalsh(blobs.cov_px2)[:, 1], 0.0))
    return m


def _at_border(blobs: Blobs, shape) -> np.ndarray:
    """Boolean (n,): the blob's box touches the image border."""
    H, W = shape
    bb = blobs.bbox
    return (bb[:, 0] <= 0) | (bb[:, 1] <= 0) | (bb[:, 2] >= W - 1) | (bb[:, 3] >= H - 1)


def _blobs_to_fit(blobs: Blobs, shape, ellipse_fit: str, expected, ellipse_min_pixels: int, fill_tol: float):
    """Boolean (n,): the blobs that get the sub-pixel ellipse fit (see :func:`measure_candidates`)."""
    n = blobs.n
    fit_me = blobs.n_pixels >= ellipse_min_pixels
    if ellipse_fit == "never":
        fit_me[:] = False
    elif ellipse_fit == "auto" and n and (expected is None or n == expected):
        # the paper runs ellipse detection when the count is wrong; we also run it on blobs
        # that do not look like a filled ellipse (fill ratio of the moment ellipse off by more
        # than fill_tol: a glint or neighbour glued to a marker) or that touch the border
        lam = np.linalg.eigvalsh(blobs.cov_px2)
        fill = blobs.n_pixels / (4 * np.pi * np.sqrt(np.clip(lam[:, 0], 1e-12, None) * lam[:, 1]))
        fit_me &= (np.abs(1 - fill) > fill_tol) | _at_border(blobs, shape)
    return fit_me


def _fit_ellipses(m: dict, gray, blobs: Blobs, fit_me, uvw, d_all, w_all, background: float,
                  max_fit_rms_px: float, supplement: bool) -> None:
    """Sub-pixel ellipse fits of the blobs in ``fit_me``, updating the measurements ``m`` in place.

    A good fit (RMS at most ``max_fit_rms_px``, coverage >= 0.9) gives the conic and moves the
    centre to the mean of the centroid and the ellipse centre; otherwise the blob's elliptical
    arcs, if found (``supplement``), give its centre, conic and depth; else it is unconfirmed.
    """
    starts = np.searchsorted(blobs.blob_of_pixel, np.arange(blobs.n + 1))
    member = None
    for i in np.flatnonzero(fit_me):
        s, e = starts[i], starts[i + 1]
        if member is None:
            member = np.zeros(gray.shape, bool)
        member[blobs.rows[s:e], blobs.cols[s:e]] = True
        g = blobs.gray[s:e]
        k = int(0.9 * (g.size - 1))
        level = background + 0.5 * (float(np.partition(g, k)[k]) - background)
        fit = fit_ellipse_subpixel(gray, tuple(blobs.bbox[i]), level, member)
        if fit is not None:
            m["rms"][i] = fit.rms_px
        if fit is not None and fit.rms_px <= max_fit_rms_px and fit.coverage >= 0.9:
            m["fitted"][i] = True
            m["uv"][i] = 0.5 * (uvw[i] + fit.center_px)
            m["conics"][i] = fit.conic
            m["semi"][i] = fit.axes_px[0]
        else:
            # not an ellipse (a glint or a neighbour glued to it, a clipped marker):
            # look for the marker's elliptical arcs and, if found, take its centre from them
            repaired = _repair(gray, blobs.bbox[i], level, member, max_fit_rms_px) if supplement else None
            if repaired is not None:
                m["uv"][i], m["conics"][i] = repaired.center_px, repaired.conic
                m["semi"][i], m["rms"][i] = repaired.axes_px[0], repaired.rms_px
                x = np.stack([blobs.cols[s:e], blobs.rows[s:e], np.ones(e - s)], 1)
                inside = np.einsum("ij,jk,ik->i", x, repaired.conic, x) < 0
                if inside.sum() >= 3:
                    m["dep"][i], m["dstd"][i], m["nd"][i] = blob_depth(d_all[s:e][inside], w_all[s:e][inside])
                m["source"][i] = "ellipse"
            else:
                m["confirmed"][i] = False
        member[blobs.rows[s:e], blobs.cols[s:e]] = False


def _gate(blobs: Blobs, shape, m: dict, expected, max_penalty: float, max_box_px: int):
    """Penalty scores and the candidates kept (paper: ``P < P_max``, ``w < W_max``, ``h < H_max``).

    Also drops blobs cut by the image border without a closed ellipse or found arcs, and -
    when there are more than ``expected`` - the blobs whose contour failed the ellipse test.

    Returns
    -------
    penalty : ndarray, shape (n,)
    ok : ndarray of bool, shape (n,)
    notes : dict
        Counts of the blobs dropped by each rule.
    """
    n = blobs.n
    peak_max = float(blobs.peak_gray.max()) if n else 1.0
    pen = _penalty(blobs.eccentricity, blobs.n_pixels, blobs.cov_px2, blobs.peak_gray, peak_max) if n else np.zeros(0)
    box = (blobs.bbox[:, 2:] - blobs.bbox[:, :2] + 1) if n else np.zeros((0, 2), int)
    ok = (pen <= max_penalty) & np.all(box <= max_box_px, axis=1)
    notes = {"dropped_penalty": int(np.sum(~ok))}
    if n:
        # a marker cut by the image border has a biased centroid: keep a blob touching the
        # border only if its contour closed into a good ellipse or its arcs were found
        cut = _at_border(blobs, shape) & ~m["fitted"] & (m["source"] != "ellipse")
        if cut.any():
            notes["dropped_at_border"] = int(np.sum(ok & cut))
            ok &= ~cut
    confirmed = m["confirmed"]
    if expected is not None and int(np.sum(ok)) > expected and not confirmed.all():
        # confirm: drop blobs whose contour failed the ellipse test
        notes["dropped_unconfirmed"] = int(np.sum(ok & ~confirmed))
        ok &= confirmed
    return pen, ok, notes

def _inside_image(f: EllipseFit, shape, margin: float = 0.5) -> bool:
    """True if the whole ellipse lies inside the image (a marker cut by the border gives arcs
    whose fit is unreliable)."""
    H, W = shape
    a, b = f.axes_px
    c, s_ = np.cos(f.angle_rad), np.sin(f.angle_rad)
    hu = np.sqrt((a * c) ** 2 + (b * s_) ** 2)
    hv = np.sqrt((a * s_) ** 2 + (b * c) ** 2)
    u, v = f.center_px
    return bool(u - hu >= margin - 0.5 and v - hv >= margin - 0.5 and u + hu <= W - 0.5 - margin
                and v + hv <= H - 0.5 - margin)


def _repair(gray, bbox, level, member, max_fit_rms_px) -> EllipseFit | None:
    """The best elliptical-arc fit centred inside a blob that is not an ellipse, or None."""
    fits = detect_ellipse_arcs(gray, tuple(bbox), level, max_rms_px=max_fit_rms_px, min_coverage=0.5)
    best = None
    for f in fits:
        if not _inside_image(f, gray.shape):
            continue
        c = np.round(f.center_px).astype(int)
        if not (0 <= c[1] < member.shape[0] and 0 <= c[0] < member.shape[1] and member[c[1], c[0]]):
            continue
        if best is None or f.coverage * f.n_points > best.coverage * best.n_points:
            best = f
    return best


def _supplement(blobs: Blobs, gray, depth, background, existing_uv, max_fit_rms_px) -> Candidates | None:
    """Elliptical arcs in the components rejected by the gates (merged or clipped markers)."""
    rows_out = []
    for bbox, rr, cc in zip(blobs.rejected_bbox, blobs.rejected_rows, blobs.rejected_cols):
        g = gray[rr, cc]
        level = background + 0.5 * (float(np.percentile(g, 90)) - background)
        fits: list[EllipseFit] = detect_ellipse_arcs(gray, tuple(bbox), level, max_rms_px=max_fit_rms_px)
        for f in fits:
            c = f.center_px
            if not _inside_image(f, gray.shape):
                continue
            if existing_uv.shape[0] and np.min(np.linalg.norm(existing_uv - c, axis=1)) < 2.0:
                continue
            if any(np.linalg.norm(r[0] - c) < 2.0 for r in rows_out):
                continue
            x = np.stack([cc, rr, np.ones_like(cc)], 1).astype(float)
            inside = np.einsum("ij,jk,ik->i", x, f.conic, x) < 0
            if inside.sum() < 3:
                continue
            w = np.clip(g[inside] - background, 0, None).astype(float)
            dm, ds, nd = blob_depth(depth[rr[inside], cc[inside]].astype(float), w)
            rows_out.append((c, f.conic, dm, ds, nd, int(inside.sum()), float(np.sqrt(1 - (f.axes_px[1] / f.axes_px[0]) ** 2)),
                             float(f.axes_px[0]), f.rms_px))
    if not rows_out:
        return None
    r = list(zip(*rows_out))
    k = len(rows_out)
    return Candidates(np.array(r[0]), np.array(r[1]), np.array(r[2]), np.array(r[3]), np.array(r[4], int),
                      np.array(r[5], int), np.array(r[6]), np.array(r[7]), np.zeros(k), np.array(r[8]),
                      np.array(["ellipse"] * k, dtype=object))


def _concat(a: Candidates, b: Candidates) -> Candidates:
    return Candidates(*(np.concatenate([getattr(a, f), getattr(b, f)]) for f in (
        "uv_px", "conic", "depth_m", "depth_std_m", "n_depth", "n_pixels", "eccentricity", "semi_major_px",
        "penalty", "fit_rms_px", "source")), notes=dict(a.notes))
