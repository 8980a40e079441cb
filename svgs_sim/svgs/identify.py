"""Target identification: choose the pattern's targets among the blobs and label them.

The paper (section "SVGS Algorithms") selects four blobs at a time and applies "basic geometric
alignment checks derived from the known orientation of the targets" until the targets are
found and labelled. Here the checks are derived from the pattern file and the operating
envelope, not hard-coded for ``svgs-3u``:

1. **Gates from the envelope.** Poses are sampled over the envelope (with a margin) and the
   pattern projected (normalised, undistorted coordinates). Take the pattern's longest
   baseline ``(a, b)`` (targets 1 and 2 of ``svgs-3u``). Any image point ``z`` expressed
   relative to that baseline as the complex ratio ``w = (z - z_a) / (z_b - z_a)`` is free of
   the image translation, scale and in-image rotation (the yaw); what remains - the
   foreshortening by roll and pitch, the boom's parallax, perspective - is a small region per
   other target, summarised as an ellipse (mean, covariance, and the largest Mahalanobis
   radius of the samples). The sign of ``Im(w)`` carries the handedness, which tells ``a``
   from ``b``. The baseline's length in pixels is gated by the envelope's range.
2. **Candidates.** For every ordered pair of blobs that passes the baseline gate, the other
   blobs are mapped to ``w`` and tested against each target's ellipse, enlarged for the
   centroid tolerance (``tolerance_px`` relative to the baseline length). Every combination
   of distinct blobs in the regions is a candidate, scored by its summed normalised
   Mahalanobis distance.
3. **Verification.** Candidates are ranked by the reprojection residual of a POSIT pose
   (vectorised over all candidates, cheap); those within a loose gate, at most
   ``max_verify`` of them, are solved in one batch with
   :func:`svgs_sim.svgs.solver.solve_centroids`. A candidate is consistent when its RMS reprojection
   residual is at most ``max_residual_px`` and its pose lies in the envelope (with
   margins). The consistent candidate with the lowest residual wins; candidates that fit
   about as well are told apart by how alike their blobs are (flux, area), because the
   boom target's position is nearly free in the pose fit (it mostly sets roll and pitch)
   and a distractor where it could be fits as well as the target itself.

Failures (falsy :class:`svgs_sim.svgs.result.Failure`): ``no_blobs``; ``too_few_blobs``;
``merged_spots`` when there are fewer blobs than targets and one blob is much larger or
holds most of the light (the spots have run into each other); ``no_consistent_set``.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from ..base.errors import InputError
from ..base.profiles import Camera, Pattern, load_camera, load_pattern
from .envelope import PAPER_ENVELOPE, Envelope, incidence_deg, physical_envelope
from .frames import D_CAM_PHOTO, angles_from_rotation, rotation_from_angles
from .result import Failure
from .solver import posit, solve_centroids

# ------------------------------------------------------------------ defaults (one place)
#: Poses sampled to build the geometric gates (plus the envelope's corners).
GATE_SAMPLES = 6000
#: Margin added to the envelope for the gates: degrees on each angle, fraction on the
#: lateral offset, factor on the range limits.
GATE_MARGIN_DEG = 5.0
GATE_MARGIN_LATERAL = 0.05
GATE_MARGIN_RANGE = 1.25
#: Centroid tolerance in the gates, px (covers noise, blending and lens-model error).
TOLERANCE_PX = 2.0
#: Candidate sets kept after the geometric gates (best scores first).
MAX_CANDIDATES = 5000
#: Candidates are ranked by the reprojection residual of a POSIT pose (cheap, vectorised);
#: those above max(POSIT_GATE_FACTOR * max_residual_px, POSIT_GATE_MIN_PX) are dropped.
POSIT_GATE_FACTOR = 4.0
POSIT_GATE_MIN_PX = 8.0
#: POSIT iterations for the ranking.
POSIT_ITER = 20
#: Consistent sets whose residuals are within this (px) or twice the best one's are told
#: apart by how alike their blobs are (flux, area) rather than by the residual alone.
TIE_RESIDUAL_PX = 0.3
#: Candidates verified with the solver (best POSIT residuals first).
MAX_VERIFY = 6
#: When none verifies, the best this many are solved again with the solver's restarts.
RETRY_VERIFY = 2
#: Blobs considered at most (the brightest).
MAX_BLOBS = 30
#: Largest RMS reprojection residual of a consistent set, px.
MAX_RESIDUAL_PX = 2.0
#: Margin on the envelope when judging a verified pose (degrees, lateral fraction, range factor).
POSE_MARGIN_DEG = 15.0
POSE_MARGIN_LATERAL = 0.15
POSE_MARGIN_RANGE = 2.0
#: Merged-spot test: a blob this many times the area of a typical single spot...
MERGE_AREA_RATIO = 1.8
#: ...or holding this fraction of the light while being at least 1.5 times its area...
MERGE_FLUX_FRACTION = 0.6
#: ...or, when it is the only blob, at least this large (px).
MERGE_MIN_AREA_PX = 40


@dataclass
class Identification:
    """The pattern's targets found among the blobs: truthy.

    Attributes
    ----------
    points_px : ndarray, shape (n, 2)
        Target centroids ``(u, v)``, ordered by pattern id.
    blob_index : ndarray of int, shape (n,)
        Index of each target's blob in the input blobs/points.
    ids : ndarray of int, shape (n,)
        Pattern ids (ascending).
    residual_rms_px : float
        RMS reprojection residual of the verifying solve (NaN without verification).
    solution : Solution or None
        The verifying solve (the pose), when ``verify`` was on.
    n_blobs, n_pairs, n_candidates, n_verified : int
        Blobs considered, ordered blob pairs that passed the baseline gate, candidate sets
        that passed the geometric gates, candidate sets solved.
    score : float
        Geometric score of the chosen set (mean squared normalised gate distance).
    outside_test_envelope : bool
        The verifying pose lies outside the paper's test envelope (:data:`PAPER_ENVELOPE`):
        inside the sensor's physical envelope, where the paper did not test it.
    """

    points_px: np.ndarray
    blob_index: np.ndarray
    ids: np.ndarray
    residual_rms_px: float = float("nan")
    solution: object = None
    n_blobs: int = 0
    n_pairs: int = 0
    n_candidates: int = 0
    n_verified: int = 0
    score: float = float("nan")
    details: dict = field(default_factory=dict)
    outside_test_envelope: bool = False

    ok = True
    reason = None

    def __bool__(self) -> bool:
        return True

    @property
    def targets_px(self) -> dict:
        """Target id -> ``[u, v]``."""
        return {int(i): [float(x) for x in p] for i, p in zip(self.ids, self.points_px)}

    def to_json(self) -> dict:
        return {
            "ok": True,
            "reason": None,
            "targets_px": {str(k): v for k, v in self.targets_px.items()},
            "blob_index": [int(i) for i in self.blob_index],
            "residual_rms_px": None if self.residual_rms_px != self.residual_rms_px else float(self.residual_rms_px),
            "n_blobs": self.n_blobs,
            "n_pairs": self.n_pairs,
            "n_candidates": self.n_candidates,
            "n_verified": self.n_verified,
            "outside_test_envelope": bool(self.outside_test_envelope),
        }


# ------------------------------------------------------------------ geometric model
@dataclass(frozen=True)
class _Gates:
    a: int  # pattern index of baseline start
    b: int  # pattern index of baseline end
    others: tuple  # pattern indices of the other targets
    mean: np.ndarray  # (K, 2) ellipse centres in w
    whiten: np.ndarray  # (K, 2, 2) C^-1/2
    radius: np.ndarray  # (K,) largest Mahalanobis radius of the samples
    inv_sqrt_lmin: np.ndarray  # (K,) 1/sqrt(smallest eigenvalue of C)
    base_min: float  # baseline length limits, normalised units
    base_max: float


def _envelope_poses(env: Envelope, n: int, seed: int = 0):
    """Poses over an (inflated) envelope: random draws plus all corners. R (m,3,3), t (m,3).

    An envelope with :attr:`Envelope.max_incidence_deg` is drawn by rejection (the attitude box,
    then the face normal within the acceptance plus :data:`GATE_MARGIN_DEG` of the line of sight;
    its box corners lie outside it, so none are added)."""
    if env.max_incidence_deg is not None:
        return _incidence_poses(env, n, seed)
    rng = np.random.default_rng(seed)
    lo, hi = env.range_interval_m[0] / GATE_MARGIN_RANGE, env.range_interval_m[1] * GATE_MARGIN_RANGE
    lat = env.lateral_fraction + GATE_MARGIN_LATERAL
    am = np.array([env.roll_deg, env.pitch_deg, env.yaw_deg]) + GATE_MARGIN_DEG
    r = np.exp(rng.uniform(np.log(lo), np.log(hi), n))
    f = rng.uniform(-1, 1, (n, 5))
    corners = np.array(list(itertools.product([-1.0, 1.0], repeat=6)))
    rc = np.where(corners[:, 0] < 0, lo, hi)
    r = np.concatenate([r, rc])
    f = np.concatenate([f, corners[:, 1:]])
    return _poses(r, f, lat, am)


def _poses(r, f, lat, am):
    """Poses from ranges ``r`` (m,) and unit draws ``f`` (m, 5): lateral offsets (fraction ``lat``
    of the range) and roll, pitch, yaw (``am`` degrees)."""
    off = f[:, :2] * lat * r[:, None]
    ang = np.deg2rad(f[:, 2:] * am)
    R = D_CAM_PHOTO @ rotation_from_angles(ang[:, 0], ang[:, 1], ang[:, 2])
    t = (D_CAM_PHOTO @ np.stack([off[:, 0], off[:, 1], -r], 1).T).T
    return R, t


def _incidence_poses(env: Envelope, n: int, seed: int):
    """``n`` poses of an envelope with an incidence limit, by rejection; a fifth of them at its
    nearest or farthest range (the gates' extremes)."""
    rng = np.random.default_rng(seed)
    lo, hi = env.range_interval_m[0] / GATE_MARGIN_RANGE, env.range_interval_m[1] * GATE_MARGIN_RANGE
    lat = env.lateral_fraction + GATE_MARGIN_LATERAL
    am = np.minimum(np.array([env.roll_deg, env.pitch_deg, env.yaw_deg]) + GATE_MARGIN_DEG, 180.0)
    Rs, ts, have = [], [], 0
    while have < n:
        m = 4 * n
        r = np.exp(rng.uniform(np.log(lo), np.log(hi), m))
        r[rng.uniform(size=m) < 0.2] = np.where(rng.uniform(size=m) < 0.5, lo, hi)[:1]
        R, t = _poses(r, rng.uniform(-1, 1, (m, 5)), lat, am)
        keep = incidence_deg(R, t) <= env.max_incidence_deg + GATE_MARGIN_DEG
        Rs.append(R[keep]), ts.append(t[keep])
        have += int(keep.sum())
    return np.concatenate(Rs)[:n], np.concatenate(ts)[:n]


@lru_cache(maxsize=32)
def _gates_cached(points_key: bytes, n: int, env: Envelope) -> _Gates:
    P = np.frombuffer(points_key, dtype=np.float64).reshape(n, 3)
    d = np.linalg.norm(P[:, None] - P[None], axis=-1)
    a, b = np.unravel_index(np.argmax(d), d.shape)
    a, b = int(min(a, b)), int(max(a, b))
    others = tuple(k for k in range(n) if k not in (a, b))
    R, t = _envelope_poses(env, GATE_SAMPLES)
    pc = np.einsum("kij,nj->kni", R, P) + t[:, None]
    ok = np.all(pc[..., 2] > 1e-6, axis=1)
    pc = pc[ok]
    z = pc[..., 0] / pc[..., 2] + 1j * pc[..., 1] / pc[..., 2]
    base = z[:, b] - z[:, a]
    w = (z[:, others] - z[:, [a]]) / base[:, None]  # (m, K)
    W = np.stack([w.real, w.imag], -1)  # (m, K, 2)
    mean = W.mean(0)
    whiten, radius, inv_sqrt_lmin = [], [], []
    for k in range(len(others)):
        C = np.cov(W[:, k].T) + np.eye(2) * 1e-10
        lam, V = np.linalg.eigh(C)
        Wk = V @ np.diag(1.0 / np.sqrt(lam)) @ V.T
        u = (W[:, k] - mean[k]) @ Wk.T
        whiten.append(Wk)
        radius.append(float(np.sqrt(np.max(np.sum(u * u, 1)))))
        inv_sqrt_lmin.append(1.0 / np.sqrt(lam[0]))
    L = np.abs(base)
    return _Gates(a, b, others, mean, np.array(whiten), np.array(radius), np.array(inv_sqrt_lmin),
                  float(L.min()), float(L.max()))


def pattern_gates(pattern: Pattern, envelope: Envelope = PAPER_ENVELOPE) -> _Gates:
    """The geometric gates of a pattern over an envelope (cached)."""
    P = np.ascontiguousarray(pattern.points_m, dtype=np.float64)
    return _gates_cached(P.tobytes(), P.shape[0], envelope)


# ------------------------------------------------------------------ helpers
def _as_points(blobs_or_points):
    """(points (N, 2), blobs or None)."""
    from .detect import Blobs

    if isinstance(blobs_or_points, Blobs):
        return np.asarray(blobs_or_points.centroid_px, float).reshape(-1, 2), blobs_or_points
    try:
        pts = np.asarray(blobs_or_points, dtype=float)
    except (TypeError, ValueError):
        raise InputError(
            f"blobs_or_points: expected Blobs or an (N, 2) array of pixels, got {type(blobs_or_points).__name__}"
        ) from None
    if pts.size == 0:
        return np.zeros((0, 2)), None
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise InputError(f"blobs_or_points: expected shape (N, 2), got {pts.shape}")
    if not np.all(np.isfinite(pts)):
        raise InputError("blobs_or_points: contains NaN or infinite coordinates")
    return pts, None


def _merged_failure(blobs, n_targets: int, single_spot_area_px):
    """A merged_spots Failure when fewer blobs than targets look like run-together spots, else None."""
    if blobs is None or len(blobs) == 0:
        return None
    area = np.asarray(blobs.area_px, float)
    flux = np.asarray(blobs.flux, float)
    big = int(np.argmax(area))
    others = np.delete(area, big)
    if single_spot_area_px is not None:
        ref = float(single_spot_area_px)
    elif others.size:
        ref = float(np.median(others))
    else:
        ref = None
    total = float(flux.sum())
    share = float(flux[big] / total) if total > 0 else 0.0
    why = None
    if ref is not None and area[big] >= MERGE_AREA_RATIO * ref:
        why = f"blob {big} covers {int(area[big])} px, {area[big] / ref:.1f} times a single spot (~{ref:.0f} px)"
    elif ref is not None and others.size and share >= MERGE_FLUX_FRACTION and area[big] >= 1.5 * ref:
        why = (f"blob {big} holds {100 * share:.0f} % of the light and is {area[big] / ref:.1f} times "
               "a single spot's area")
    elif ref is None and area[big] >= MERGE_MIN_AREA_PX:
        why = (f"the only blob covers {int(area[big])} px (a single spot is expected to be smaller than "
               f"{MERGE_MIN_AREA_PX} px)")
    if why is None:
        return None
    sat = float(blobs.saturated_fraction[big])
    return Failure(
        "merged_spots",
        f"only {len(blobs)} blob(s) for {n_targets} targets: the target spots merged ({why}"
        + (f", {100 * sat:.0f} % saturated" if sat > 0 else "")
        + "); at this range the spots run into each other - reduce the exposure or gain, raise the threshold, "
        "or come closer",
        {"n_blobs": len(blobs), "merged_blob": big, "merged_area_px": int(area[big]),
         "single_spot_area_px": ref, "flux_fraction": share, "saturated_fraction": sat},
    )


def _merge_hint(blobs, idx_all) -> tuple[str, dict]:
    """Message suffix and details naming a blob that looks like merged spots, if any."""
    if blobs is None or len(idx_all) < 2:
        return "", {}
    area = np.asarray(blobs.area_px, float)[idx_all]
    big = int(np.argmax(area))
    ref = float(np.median(np.delete(area, big)))
    if ref > 0 and area[big] >= MERGE_AREA_RATIO * ref:
        k = int(idx_all[big])
        return (f"; blob {k} covers {area[big]:.0f} px, {area[big] / ref:.1f} times the median blob - "
                "target spots may have merged"), {"possibly_merged_blob": k}
    return "", {}


def _pose_in_envelope(R, t, env: Envelope, margin_deg, margin_lateral, margin_range):
    """Boolean (N,) - verified poses inside the envelope with margins (:meth:`Envelope.contains`)."""
    return env.contains(R, t, margin_deg=margin_deg, margin_lateral=margin_lateral, margin_range=margin_range)


def outside_test_envelope(R_cam_target, t_cam_target_m) -> bool:
    """Whether a pose lies outside the paper's test envelope (:data:`PAPER_ENVELOPE`, no margin):
    solved, but where the paper did not test the sensor."""
    return not PAPER_ENVELOPE.contains(R_cam_target, t_cam_target_m)


# ------------------------------------------------------------------ main entry
def identify(
    blobs_or_points,
    camera,
    pattern="svgs-3u",
    *,
    verify: bool = True,
    envelope: Envelope | None = None,
    tolerance_px: float = TOLERANCE_PX,
    max_blobs: int = MAX_BLOBS,
    max_verify: int = MAX_VERIFY,
    max_residual_px: float = MAX_RESIDUAL_PX,
    pose_margin_deg: float = POSE_MARGIN_DEG,
    single_spot_area_px=None,
    sigma_px: float = 0.1,
):
    """Find and label the pattern's targets among blobs.

    Parameters
    ----------
    blobs_or_points : Blobs or array_like, shape (N, 2)
        Detected blobs (:func:`svgs_sim.svgs.detect.detect_blobs`, brightest first) or bare centroids
        in pixels (then the merged-spot diagnosis is not available).
    camera : Camera or str
    pattern : Pattern or str
    verify : bool
        Solve the best candidates and keep the consistent one with the smallest residual
        (default). Without it the best geometric score wins (no solve).
    envelope : Envelope, optional
        Envelope the gates and the verified-pose check are built for; default the sensor's
        physical one (:func:`svgs_sim.svgs.envelope.physical_envelope`: the cubes' acceptance,
        the field of view, the range limits). :data:`PAPER_ENVELOPE` gives the paper's test
        envelope (the gates of earlier versions). A pose outside the paper's test envelope is
        returned with :attr:`Identification.outside_test_envelope` set.
    tolerance_px : float
        Centroid tolerance of the geometric gates, px.
    max_blobs : int
        At most this many blobs (the brightest) are considered.
    max_verify : int
        At most this many candidate sets are solved.
    max_residual_px : float
        Largest RMS reprojection residual of a consistent set, px.
    pose_margin_deg : float
        Margin on the envelope's angles when judging a verified pose (the range and
        lateral margins are :data:`POSE_MARGIN_RANGE`, :data:`POSE_MARGIN_LATERAL`).
    single_spot_area_px : float, optional
        Expected area of one target spot, for the merged-spot diagnosis; by default the
        median area of the other blobs.
    sigma_px : float
        Centroid noise for the covariance of the verifying solution.

    Returns
    -------
    Identification or Failure
        Failure reasons: ``no_blobs``, ``too_few_blobs``, ``merged_spots``,
        ``no_consistent_set``.
    """
    camera = load_camera(camera)
    pattern = load_pattern(pattern)
    if envelope is None:
        envelope = physical_envelope(camera, pattern)
    _check_options(tolerance_px, max_residual_px, max_blobs, max_verify)
    pts, blobs = _as_points(blobs_or_points)
    n_t = pattern.n
    n_all = pts.shape[0]
    if (too_few := _count_failure(n_all, blobs, n_t, single_spot_area_px)) is not None:
        return too_few
    # brightest first (Blobs are sorted by flux); keep at most max_blobs
    idx_all = np.arange(n_all)[:max_blobs]
    pts = pts[idx_all]
    N = pts.shape[0]
    sets, scores, n_pairs = _candidate_sets(pts, camera, pattern_gates(pattern, envelope), n_t, tolerance_px)
    n_cand = int(sets.shape[0])
    diag = {"n_blobs": n_all, "n_pairs": n_pairs, "n_candidates": n_cand}
    hint, hint_d = _merge_hint(blobs, idx_all)
    if n_cand == 0:
        return Failure(
            "no_consistent_set",
            f"no {n_t} of {_blobs_phrase(N, n_all)} match the {pattern.name!r} pattern's geometry over the "
            "envelope" + hint,
            {**diag, "n_verified": 0, **hint_d},
        )
    order = np.argsort(scores, kind="stable")[:MAX_CANDIDATES]
    sets, scores = sets[order], scores[order]
    if not verify:
        sel = sets[0]
        return Identification(pts[sel], idx_all[sel], pattern.ids.copy(), n_blobs=n_all, n_pairs=n_pairs,
                              n_candidates=n_cand, n_verified=0, score=float(scores[0]))

    return _verified_identification(pts, idx_all, blobs, sets, scores, camera, pattern, diag, hint, hint_d,
                                    sigma_px=sigma_px, max_residual_px=max_residual_px, max_verify=max_verify,
                                    envelope=envelope, pose_margin_deg=pose_margin_deg)


def _verified_identification(pts, idx_all, blobs, sets, scores, camera, pattern, diag: dict, hint: str, hint_d: dict,
                             *, sigma_px: float, max_residual_px: float, max_verify: int, envelope: Envelope,
                             pose_margin_deg: float):
    """The verifying step of :func:`identify`: solve the best candidate sets and keep the consistent one.

    Parameters
    ----------
    pts : ndarray, shape (N, 2)
        The considered blobs' centroids, px (brightest first).
    idx_all : ndarray of int, shape (N,)
        Their indices among all blobs.
    blobs : Blobs or None
        The detected blobs (None for bare centroids).
    sets : ndarray of int, shape (n_sets, n_targets)
        Candidate sets (indices into ``pts``), best geometric score first.
    scores : ndarray, shape (n_sets,)
        Their geometric scores.
    camera : Camera
    pattern : Pattern
    diag : dict
        ``n_blobs``, ``n_pairs``, ``n_candidates`` (before the candidates were capped).
    hint : str
        The merged-spot hint appended to failure messages ("" for none).
    hint_d : dict
        The hint's diagnostics.
    sigma_px, max_residual_px, max_verify, envelope, pose_margin_deg
        See :func:`identify`.

    Returns
    -------
    Identification or Failure
    """
    N = pts.shape[0]
    n_all, n_pairs, n_cand = diag["n_blobs"], diag["n_pairs"], diag["n_candidates"]
    pres, rank = _posit_rank(pts, sets, camera, pattern, max_residual_px, max_verify)
    if rank.size == 0:
        return Failure(
            "no_consistent_set",
            f"{n_cand} candidate set(s) of {_blobs_phrase(N, n_all)} fit the pattern's layout, but no pose "
            f"reproduces any of them (best approximate residual {float(np.min(pres)):.3g} px)" + hint,
            {**diag, "n_verified": 0, **hint_d},
        )
    n_ver = int(rank.size)
    vsets, batch, good = _solve_candidates(pts, sets[rank], camera, pattern, sigma_px, max_residual_px, envelope,
                                           pose_margin_deg)
    res = np.asarray(batch.residual_rms_px, float)
    if not np.any(good):
        return _unverified_failure(res, n_cand, N, n_ver, max_residual_px, hint, diag, hint_d)
    best = _pick(vsets, res, good, blobs, idx_all)
    return _identification(pts, idx_all, pattern, vsets, batch, good, best, float(scores[rank[best]]),
                           float(pres[rank[best]]), n_blobs=n_all, n_pairs=n_pairs, n_candidates=n_cand,
                           n_verified=n_ver)


def _unverified_failure(res, n_cand: int, N: int, n_ver: int, max_residual_px: float, hint: str, diag: dict,
                        hint_d: dict):
    """The Failure when no solved candidate set is consistent (``res``: their RMS residuals, px)."""
    best = float(np.nanmin(res)) if np.any(np.isfinite(res)) else None
    return Failure(
        "no_consistent_set",
        f"{n_cand} candidate set(s) of {_blobs_phrase(N, diag['n_blobs'])} fit the pattern's layout, but none of "
        f"the {n_ver} solved reproduces it within {max_residual_px:g} px inside the envelope"
        + (f" (best RMS residual {best:.3g} px)" if best is not None else "") + hint,
        {**diag, "n_verified": n_ver, "best_residual_px": best, **hint_d},
    )


def _posit_rank(pts, sets, camera, pattern, max_residual_px, max_verify):
    """Candidate sets ranked by the residual of a cheap pose fit (POSIT, vectorised).

    Returns
    -------
    pres : ndarray, shape (M,)
        POSIT reprojection residual of each set, px (inf when no pose).
    rank : ndarray of int, shape (<= max_verify,)
        Indices of the sets worth solving, best first.
    """
    from ._lm_kernel import check_points_batch  # numba: compiled kernels load on first use, as the solver's

    pres = _posit_residual(pts[sets], camera, pattern)
    flags = np.empty(len(sets), np.int64)
    check_points_batch(np.ascontiguousarray(pts[sets], dtype=np.float64), flags)
    pres[flags != 0] = np.inf  # coincident or collinear blobs (sunlit clutter): no pose, not worth solving
    rank = np.argsort(pres, kind="stable")
    rank = rank[pres[rank] <= max(POSIT_GATE_FACTOR * max_residual_px, POSIT_GATE_MIN_PX)][:max_verify]
    return pres, rank


def _identification(pts, idx_all, pattern, vsets, batch, good, best, score, posit_residual_px,
                    **counts) -> Identification:
    """The :class:`Identification` of the chosen set ``vsets[best]`` with its solution."""
    res = np.asarray(batch.residual_rms_px, float)
    sel = vsets[best]
    sol = batch[best]
    sol.targets_px = {int(i): pts[sel[k]].tolist() for k, i in enumerate(pattern.ids)}
    sol.n_blobs = counts["n_blobs"]
    sol.outside_test_envelope = outside_test_envelope(sol.R_cam_target, sol.t_cam_target_m)
    ok_res = np.sort(res[good])
    return Identification(
        pts[sel], idx_all[sel], pattern.ids.copy(), residual_rms_px=float(res[best]), solution=sol, score=score,
        outside_test_envelope=sol.outside_test_envelope,
        details={"n_consistent": int(good.sum()), "second_residual_px": float(ok_res[1]) if ok_res.size > 1 else None,
                 "posit_residual_px": posit_residual_px},
        **counts,
    )


def _check_options(tolerance_px, max_residual_px, max_blobs, max_verify) -> None:
    """Raise :class:`InputError` for a non-positive pixel tolerance or count."""
    for nm, v in (("tolerance_px", tolerance_px), ("max_residual_px", max_residual_px)):
        if not (isinstance(v, (int, float, np.floating, np.integer)) and np.isfinite(v) and v > 0):
            raise InputError(f"{nm}: expected a positive number of pixels, got {v!r}")
    for nm, v in (("max_blobs", max_blobs), ("max_verify", max_verify)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
            raise InputError(f"{nm}: expected a positive integer, got {v!r}")


def _blobs_phrase(n_used: int, n_found: int) -> str:
    """"the 12 blobs", or "the 30 brightest of the 40 blobs found" when ``max_blobs`` kept fewer."""
    if n_used >= n_found:
        return f"the {n_found} blobs"
    return f"the {n_used} brightest of the {n_found} blobs found (max_blobs {n_used})"


def _threshold_phrase(blobs) -> str:
    """" above the threshold 250" from a :class:`~svgs_sim.svgs.detect.Blobs`' level (empty without one)."""
    t = getattr(blobs, "threshold_used", None)
    return f" above the threshold {float(t):g}" if t is not None and np.isfinite(t) else " above the threshold"


def _scale_hint(blobs) -> str:
    """A hint when the image's brightest value lies below a threshold above 1: a float image scaled
    0-1 against a threshold in 8-bit counts (empty otherwise)."""
    top, t = float(getattr(blobs, "image_max", float("nan"))), getattr(blobs, "threshold_used", None)
    if t is None or not (np.isfinite(top) and np.isfinite(t)) or not (top <= 1.0 < float(t)):
        return ""
    return (f"; the image's brightest value is {top:g}: an image scaled 0-1 against a threshold in counts? "
            "Give it in the camera's counts (0-255 for 8 bits) or a threshold on its scale (--threshold)")


def _count_failure(n_all: int, blobs, n_t: int, single_spot_area_px):
    """The Failure of a frame with no blob or fewer blobs than targets, else None."""
    base = {"n_blobs": n_all}
    if n_all == 0:
        return Failure("no_blobs", f"no bright blob was found (nothing{_threshold_phrase(blobs)} passed the size "
                       f"and shape gates){_scale_hint(blobs)}", base)
    if n_all < n_t:
        merged = _merged_failure(blobs, n_t, single_spot_area_px)
        if merged is not None:
            return merged
        return Failure("too_few_blobs", f"found {n_all} blob(s) where the pattern has {n_t} targets", base)
    return None


def _candidate_sets(pts: np.ndarray, camera: Camera, g: _Gates, n_t: int, tolerance_px: float):
    """Blob sets that pass the pattern's geometric gates.

    Every ordered blob pair within the baseline's length range is tried as the base targets
    ``(a, b)``; the other targets' blobs must fall inside their gates in the pair's frame.

    Parameters
    ----------
    pts : ndarray, shape (N, 2)
        Blob centroids, pixels.
    g : _Gates
        :func:`pattern_gates` of the pattern.

    Returns
    -------
    sets : ndarray of int, shape (M, n_t)
        Blob index of each target, in pattern order.
    scores : ndarray, shape (M,)
        Mean squared normalised gate distance (smaller is better).
    n_pairs : int
        Base pairs tried.
    """
    N = pts.shape[0]
    K = len(g.others)
    # undistorted normalised coordinates, scaled by fx to work in ideal pixels
    z = camera.pixels_to_normalized(pts)
    z = (z[:, 0] + 1j * z[:, 1]) * camera.fx
    ii, jj = np.nonzero(~np.eye(N, dtype=bool))  # ordered pairs (i -> a, j -> b)
    L = np.abs(z[jj] - z[ii])
    keep = (L >= g.base_min * camera.fx) & (L <= g.base_max * camera.fx)
    ii, jj, L = ii[keep], jj[keep], L[keep]
    n_pairs = int(ii.size)
    sets = np.zeros((0, n_t), int)
    scores = np.zeros(0)
    if not n_pairs:
        return sets, scores, n_pairs
    w = (z[None, :] - z[ii, None]) / (z[jj] - z[ii])[:, None]  # (p, N)
    Wv = np.stack([w.real, w.imag], -1)  # (p, N, 2)
    dist = np.empty((n_pairs, N, K))
    lim = np.empty((n_pairs, K))
    for k in range(K):
        u = (Wv - g.mean[k]) @ g.whiten[k].T
        dist[:, :, k] = np.sqrt(np.sum(u * u, -1))
        lim[:, k] = g.radius[k] + 3.0 * tolerance_px / L * g.inv_sqrt_lmin[k]
    inside = dist <= lim[:, None, :]
    rows = np.arange(n_pairs)
    inside[rows, ii, :] = False
    inside[rows, jj, :] = False
    # vectorised join: partial sets (pair, blob for others[0], blob for others[1], ...)
    part_p = np.flatnonzero(np.all(inside.any(1), axis=1))
    part_sel = np.zeros((part_p.size, 0), int)
    part_d2 = np.zeros(part_p.size)
    for k in range(K):
        r_, c_ = np.nonzero(inside[part_p, :, k])
        new_p = part_p[r_]
        new_sel = np.concatenate([part_sel[r_], c_[:, None]], 1)
        new_d2 = part_d2[r_] + (dist[new_p, c_, k] / g.radius[k]) ** 2
        if k:  # distinct blobs
            distinct = np.all(new_sel[:, :-1] != c_[:, None], axis=1)
            new_p, new_sel, new_d2 = new_p[distinct], new_sel[distinct], new_d2[distinct]
        part_p, part_sel, part_d2 = new_p, new_sel, new_d2
    if part_p.size:
        sets = np.empty((part_p.size, n_t), int)
        sets[:, g.a], sets[:, g.b] = ii[part_p], jj[part_p]
        sets[:, list(g.others)] = part_sel
        scores = part_d2 / K
    return sets, scores, n_pairs


def _solve_candidates(pts, vsets, camera, pattern, sigma_px, max_residual_px, envelope, pose_margin_deg):
    """Solve the candidate sets to verify; keep the consistent solutions.

    Solves without the solver's retries first (cheap) and retries the best
    :data:`RETRY_VERIFY` only if none is consistent.

    Returns
    -------
    vsets : ndarray of int, shape (M, n)
        The sets solved (the retried ones when the retry found a consistent set).
    batch : BatchSolution
    good : ndarray of bool, shape (M,)
        Consistent: solved, within ``max_residual_px`` and inside the envelope.
    """

    batch = solve_centroids(pts[vsets], camera, pattern, sigma_px=sigma_px, max_residual_px=np.inf)
    good = _consistent(batch, max_residual_px, envelope, pose_margin_deg)
    if not np.any(good):
        m = min(RETRY_VERIFY, int(vsets.shape[0]))
        retry = solve_centroids(pts[vsets[:m]], camera, pattern, sigma_px=sigma_px, max_residual_px=max_residual_px)
        g2 = _consistent(retry, max_residual_px, envelope, pose_margin_deg)
        if np.any(g2):
            vsets, batch, good = vsets[:m], retry, g2
    return vsets, batch, good

def _pick(vsets, res, good, blobs, idx_all) -> int:
    """Index of the chosen set among the consistent ones.

    The lowest residual wins, except that sets fitting about as well (within
    :data:`TIE_RESIDUAL_PX` or twice the best residual) are ranked by photometric
    uniformity when blob measurements are available: the targets are identical
    retroreflectors at nearly the same range, so their fluxes and areas agree, while a
    distractor that happens to sit where a target could be (the boom target's position is
    nearly free in the pose fit: it mostly sets roll and pitch) usually differs.
    """
    gi = np.flatnonzero(good)
    best = int(gi[np.argmin(res[gi])])
    if blobs is None or gi.size < 2:
        return best
    tie = gi[res[gi] <= max(2.0 * res[best], res[best] + TIE_RESIDUAL_PX)]
    if tie.size < 2:
        return best
    b = idx_all[vsets[tie]]  # (T, n) blob indices
    lf = np.log(np.maximum(np.asarray(blobs.flux, float)[b], 1e-12))
    la = np.log(np.maximum(np.asarray(blobs.area_px, float)[b], 1.0))
    cost = lf.std(1) + la.std(1)
    return int(tie[np.argmin(cost)])


def _posit_residual(sets_px: np.ndarray, camera: Camera, pattern: Pattern) -> np.ndarray:
    """RMS reprojection residual (px) of POSIT poses for candidate sets (M, n, 2) -> (M,)."""

    xy = camera.pixels_to_normalized(sets_px)
    with np.errstate(all="ignore"):
        R, t = posit(xy, pattern.points_m, n_iter=POSIT_ITER)
        pc = np.einsum("kij,nj->kni", R, pattern.points_m) + t[:, None]
        front = np.all(pc[..., 2] > 0, axis=1)
        proj = np.stack([pc[..., 0] / pc[..., 2], pc[..., 1] / pc[..., 2]], -1)
        d = (proj - xy) * camera.fx
        res = np.sqrt(np.mean(np.sum(d * d, -1), -1))
    res[~front | ~np.isfinite(res)] = np.inf
    return res


def _consistent(batch, max_residual_px, envelope, pose_margin_deg) -> np.ndarray:
    res = np.asarray(batch.residual_rms_px, float)
    good = np.asarray(batch.ok, bool) & (res <= max_residual_px)
    if np.any(good):
        gi = np.flatnonzero(good)
        good[gi] &= _pose_in_envelope(batch.R_cam_target[gi], batch.t_cam_target_m[gi], envelope, pose_margin_deg,
                                      POSE_MARGIN_LATERAL, POSE_MARGIN_RANGE)
    return good


__all__ = ["identify", "Identification", "Envelope", "PAPER_ENVELOPE", "pattern_gates", "outside_test_envelope"]
