"""Part 2 of the calibration study: the paper's focal-length method on images of the target.

The target faces the camera at known ranges: rendered (:func:`focal_frames_rendered`:
:func:`svgs_sim.sim.closed_loop.render_scenario`, the phone's exposure, detection and
identification) or projected with noise (:func:`focal_frames_geometric`). Then
:func:`svgs_sim.calibration.estimate_focal` runs on subsets of the ranges with added centroid noise
(:func:`focal_cases`, :func:`focal_case`); each (range set, noise level) is one trial of the
kind ``calibration-focal`` (:mod:`svgs_sim.studies.calibration.trials`). The estimate from one image
per range is the focal-only calibration (:func:`focal_only_estimate`).
"""

from __future__ import annotations

import json
import os
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from svgs_sim.base.errors import InputError, check_finite_positive
from svgs_sim.base.profiles import Camera, Pattern
from svgs_sim.calibration import estimate_focal
from svgs_sim.sim.closed_loop import Scenario, render_scenario
from svgs_sim.svgs.frames import pose_from_scenario
from svgs_sim.svgs.identify import identify
from svgs_sim.svgs.pipeline import camera_threshold

from .common import (
    DEFAULT_FOCAL_EXPOSURES,
    DEFAULT_FOCAL_TRIALS,
    DEFAULT_NOISE_LEVELS_PX,
    GEOMETRIC_CENTROID_NOISE_PX,
    spawn_seeds,
)

#: Output columns of one (range set, noise level) case, in order.
FOCAL_COLUMNS = ("ranges", "n_ranges", "added_noise_px", "n_estimates", "mean_err_pct", "rms_err_pct",
                 "max_abs_err_pct", "reported_sigma_pct", "chi2_per_dof")
#: Nominal centroid noise given to a single image (one image leaves 1 dof), px.
SINGLE_IMAGE_SIGMA_PX = 0.05


@dataclass
class FocalFrames:
    """Labelled centroids of the target facing the camera at known ranges.

    Attributes
    ----------
    ranges_m : ndarray, shape (K,)
    centroids_px : ndarray, shape (K, E, N, 2)
        Per range and exposure, the centroids ordered by target id (NaN: not identified).
    truth_px : ndarray, shape (K, N, 2)
        True projections of the targets (the pattern points through the true camera).
    info : list of dict
        Per range: render time, exposure, failures.
    rendered : bool
    camera : dict
        The true camera's profile (:meth:`svgs_sim.svgs.Camera.to_dict`, name left out) the frames
        were made with; a cache is reused only for the same profile.
    """

    ranges_m: np.ndarray
    centroids_px: np.ndarray
    truth_px: np.ndarray
    info: list = field(default_factory=list)
    rendered: bool = True
    camera: dict = field(default_factory=dict)

    def ok(self) -> np.ndarray:
        """(K, E) bool: identified."""
        return np.all(np.isfinite(self.centroids_px), axis=(2, 3))

    def save(self, path) -> None:
        """Write the frames to an ``.npz`` file (info as JSON); a temporary file renamed, so a
        killed run leaves no partial file."""

        path = Path(path)
        tmp = path.with_name(path.name + ".tmp.npz")
        np.savez(tmp, ranges_m=self.ranges_m, centroids_px=self.centroids_px, truth_px=self.truth_px,
                 info=np.array(json.dumps(self.info)), rendered=np.array(self.rendered),
                 camera=np.array(json.dumps(self.camera)))
        os.replace(tmp, path)

    @classmethod
    def load(cls, path) -> FocalFrames:

        try:
            with np.load(path, allow_pickle=False) as z:
                return cls(z["ranges_m"], z["centroids_px"], z["truth_px"], json.loads(str(z["info"])), bool(z["rendered"]),
                           json.loads(str(z["camera"])) if "camera" in z.files else {})
        except (OSError, KeyError, ValueError) as exc:
            raise InputError(f"{str(path)!r}: not a focal-frames cache ({exc})") from None


def focal_frames_geometric(camera_true: Camera, pattern: Pattern, ranges_m, *, exposures: int = DEFAULT_FOCAL_EXPOSURES,
                           noise_px: float = GEOMETRIC_CENTROID_NOISE_PX, seed: int = 0) -> FocalFrames:
    """Projected centroids with Gaussian noise (the no-render stand-in)."""

    rng = np.random.default_rng(seed)
    r = np.asarray(ranges_m, float)
    truth = np.array([camera_true.project_target(pattern.points_m, *pose_from_scenario(x)) for x in r])
    cents = truth[:, None] + rng.normal(0.0, noise_px, (len(r), int(exposures)) + truth.shape[1:])
    info = [{"range_m": float(x), "source": f"projection + N(0, {noise_px} px)"} for x in r]
    return FocalFrames(r, cents, truth, info, rendered=False)


def _identified_points(image, believed: Camera, pattern: Pattern):
    """Detect and identify the targets in one image with the believed camera.

    Returns
    -------
    ndarray, shape (N, 2), or Failure
        Full-resolution pixels (an image the ISP downscaled is mapped back).
    """
    from svgs_sim.svgs.detect import detect_blobs

    h, w = image.shape[:2]
    cam_b = believed if (w, h) == (believed.width, believed.height) else believed.scaled(w, h)

    ident = identify(detect_blobs(image, threshold=camera_threshold(image, cam_b)), cam_b, pattern)
    if not ident:
        return ident
    pts = np.asarray(ident.points_px, float)
    if cam_b is not believed:  # back to full-resolution pixels
        pts = (pts + 0.5) * np.array([believed.width / w, believed.height / h]) - 0.5
    return pts


def focal_frames_rendered(camera_true: Camera, believed: Camera, pattern: Pattern, ranges_m, *,
                          exposures: int = DEFAULT_FOCAL_EXPOSURES, seed: int = 0, workdir=None,
                          progress=None) -> FocalFrames:
    """Render the target facing the camera at each range and expose it ``exposures`` times.

    Each frame is :func:`svgs_sim.sim.closed_loop.render_scenario` (Mitsuba: the corner cubes under
    the flash, the profile's phone model with its auto-exposure); the targets are found with
    :func:`svgs_sim.svgs.detect.detect_blobs` and labelled by :func:`svgs_sim.svgs.identify.identify` using
    the ``believed`` (nominal) camera, as a user of the focal method would.

    Parameters
    ----------
    camera_true : Camera
        The camera the images are rendered with.
    believed : Camera
        The camera identification uses.
    pattern : Pattern
    ranges_m : sequence of float
    exposures : int
    seed : int
    workdir : str or Path, optional
        Where the true camera's profile is written for the renderer (default: a
        temporary folder).
    progress : callable, optional

    Returns
    -------
    FocalFrames
    """


    r = np.asarray(ranges_m, float)
    E = int(exposures)
    cents = np.full((len(r), E, pattern.n, 2), np.nan)
    truth = np.array([camera_true.project_target(pattern.points_m, *pose_from_scenario(x)) for x in r])
    info = []
    seeds = spawn_seeds(seed, len(r))
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(workdir or tmp) / f"{camera_true.name}.toml"
        camera_true.save(path)
        for k, x in enumerate(r):
            sc = Scenario(camera=str(path), pattern=pattern.source or pattern.name, range_m=float(x))
            t0 = time.perf_counter()
            frame = render_scenario(sc, seed=seeds[k])
            t_render = time.perf_counter() - t0
            ex = frame.exposer()
            reasons, settings = [], None
            for e, e_seed in enumerate(spawn_seeds(seeds[k] + 1, E)):
                shot = ex.expose(seed=e_seed)
                settings = (shot.exposure_s, shot.iso)
                pts = _identified_points(shot.image, believed, pattern)
                if isinstance(pts, np.ndarray):
                    cents[k, e] = pts
                else:
                    reasons.append(pts.reason)
            info.append({"range_m": float(x), "render_s": round(t_render, 2), "exposure_s": settings[0],
                         "iso": settings[1], "identified": E - len(reasons), "failures": ", ".join(reasons)})
            if progress is not None:
                progress(f"focal frame {k + 1}/{len(r)}: {x:g} m rendered in {t_render:.1f} s, "
                         f"targets identified in {E - len(reasons)}/{E} exposures")
    return FocalFrames(r, cents, truth, info, rendered=True)


def centroid_noise(frames: FocalFrames) -> list[dict]:
    """Per range: centroid scatter over the exposures of one frame (px per axis) and the mean
    offset of the centroids from the targets' projections (px; the flash LED's parallax moves
    every spot alike)."""
    out = []
    for k, x in enumerate(frames.ranges_m):
        c = frames.centroids_px[k]
        ok = np.all(np.isfinite(c), axis=(1, 2))
        row = {"range_m": float(x), "exposures_identified": int(ok.sum())}
        if ok.sum() >= 2:
            cc = c[ok]
            row["exposure_scatter_px"] = float(np.sqrt(np.mean(np.var(cc, axis=0, ddof=1))))
        else:
            row["exposure_scatter_px"] = float("nan")
        if ok.any():
            row["offset_from_truth_px"] = float(np.sqrt(np.mean(np.sum((c[ok].mean(0) - frames.truth_px[k]) ** 2, -1))))
        else:
            row["offset_from_truth_px"] = float("nan")
        out.append(row)
    return out


def default_range_sets(ranges_m) -> list[tuple[str, tuple]]:
    """Subsets of the focal ranges: all, three spread, two far, one far, and the nearest three."""
    r = sorted(float(x) for x in ranges_m)
    sets = [(f"all {len(r)} ({r[0]:g}-{r[-1]:g} m)", tuple(r))]
    if len(r) >= 3:
        spread = (r[0], r[len(r) // 2], r[-1])
        sets.append((" + ".join(f"{x:g}" for x in spread) + " m", spread))
        sets.append((f"{r[0]:g}-{r[2]:g} m (near 3)", tuple(r[:3])))
    if len(r) >= 2:
        sets.append((" + ".join(f"{x:g}" for x in r[-2:]) + " m (far 2)", tuple(r[-2:])))
    sets.append((f"{r[-1]:g} m only", (r[-1],)))
    seen, out = set(), []
    for name, s in sets:
        if s not in seen:
            seen.add(s)
            out.append((name, s))
    return out


def check_focal_frames(frames: FocalFrames) -> None:
    """:class:`InputError` if the targets were identified in none of the frames."""
    if not frames.ok().any(axis=1).any():
        raise InputError("focal study: the targets were identified in none of the focal frames")


def focal_cases(frames: FocalFrames, range_sets=None, noise_levels_px=DEFAULT_NOISE_LEVELS_PX,
                trials: int = DEFAULT_FOCAL_TRIALS) -> list[dict]:
    """The cases of the focal study: each range set with each added noise level.

    All cases draw their noise from one stream (a generator seeded with the study's focal
    seed), case after case; ``noise_skip`` is the number of normal deviates the cases
    before this one draw, so a case computed alone, in any process, draws the same numbers.

    Returns
    -------
    list of dict
        ``ranges`` (the set's name), ``range_indices`` (tuple of int into
        ``frames.ranges_m``), ``added_noise_px``, ``n_trials`` (noise draws per exposure) and
        ``noise_skip``.
    """
    sets = default_range_sets(frames.ranges_m) if range_sets is None else list(range_sets)
    ok = frames.ok()
    per_image = int(np.prod(frames.centroids_px.shape[2:]))
    out, skip = [], 0
    for name, rs in sets:
        idx = tuple(int(np.argmin(np.abs(frames.ranges_m - r))) for r in rs)
        n_exp = int(np.sum(np.all(ok[list(idx)], axis=0)))
        for sig in noise_levels_px:
            n_trials = 1 if sig == 0 else int(trials)
            out.append({"ranges": name, "range_indices": idx, "added_noise_px": float(sig), "n_trials": n_trials,
                        "noise_skip": skip})
            if sig > 0:
                skip += n_exp * n_trials * len(idx) * per_image
    return out


def focal_case(frames: FocalFrames, case: dict, believed: Camera, pattern: Pattern, f_true_px: float,
               seed: int = 0) -> dict | None:
    """One case of :func:`focal_cases`: the focal method's error over exposures and noise draws.

    Every exposure index in which all the set's ranges were identified (one image per range,
    as a user would take) gives ``n_trials`` estimates (:func:`svgs_sim.calibration.estimate_focal`
    with the believed camera: its principal point and distortion, here the nominal ones).

    Returns
    -------
    dict or None
        :data:`FOCAL_COLUMNS`, in percent of the true fx; ``reported_sigma_pct`` is the mean
        of the method's own 1-sigma, ``chi2_per_dof`` its mean consistency. None if no
        exposure has all the set's ranges.
    """

    idx, sig = list(case["range_indices"]), float(case["added_noise_px"])
    ok, ranges = frames.ok(), frames.ranges_m
    rng = np.random.default_rng(seed)
    rng.standard_normal(int(case["noise_skip"]))  # the draws of the cases before this one
    if len(idx) == 1:  # one image leaves 1 dof: give it the noise (or a nominal one)
        kw = {"centroid_sigma_px": sig if sig > 0 else SINGLE_IMAGE_SIGMA_PX}
    else:
        kw = {}
    errs, sigmas, chi = [], [], []
    for e in range(frames.centroids_px.shape[1]):
        if not all(ok[k, e] for k in idx):
            continue
        for _ in range(int(case["n_trials"])):
            cs = [frames.centroids_px[k, e] + (rng.normal(0.0, sig, frames.centroids_px[k, e].shape) if sig > 0 else 0.0)
                  for k in idx]
            est = estimate_focal(cs, ranges[idx], believed, pattern, **kw)
            errs.append(100.0 * (est.f_px / f_true_px - 1.0))
            sigmas.append(100.0 * est.sigma_f_px / f_true_px)
            if len(idx) > 1:
                chi.append(est.consistency_chi2 / (len(idx) - 1))
    if not errs:
        return None
    e = np.asarray(errs)
    return {
        "ranges": case["ranges"], "n_ranges": len(idx), "added_noise_px": sig, "n_estimates": int(e.size),
        "mean_err_pct": float(e.mean()), "rms_err_pct": float(np.sqrt(np.mean(e**2))),
        "max_abs_err_pct": float(np.abs(e).max()), "reported_sigma_pct": float(np.mean(sigmas)),
        "chi2_per_dof": float(np.mean(chi)) if chi else float("nan"),
    }


def focal_only_estimate(frames: FocalFrames, believed: Camera, pattern: Pattern):
    """The focal-only calibration: all ranges, one image per range (the first identified
    exposure), no added noise.

    Returns
    -------
    calibration.FocalEstimate
    """

    ok = frames.ok()
    cs, rr = [], []
    for k in range(len(frames.ranges_m)):
        es = np.flatnonzero(ok[k])
        if es.size:
            cs.append(frames.centroids_px[k, es[0]])
            rr.append(frames.ranges_m[k])
    kw = {"centroid_sigma_px": SINGLE_IMAGE_SIGMA_PX} if len(cs) == 1 else {}
    return estimate_focal(cs, rr, believed, pattern, names=[f"{r:g} m" for r in rr], **kw)


def focal_study(frames: FocalFrames, believed: Camera, pattern: Pattern, f_true_px: float, *, range_sets=None,
                noise_levels_px=DEFAULT_NOISE_LEVELS_PX, trials: int = DEFAULT_FOCAL_TRIALS, seed: int = 0):
    """Error of the paper's focal-length method versus ranges used and centroid noise (in this process).

    Parameters
    ----------
    frames : FocalFrames
    believed : Camera
    pattern : Pattern
    f_true_px : float
        The true fx.
    range_sets : list of (str, tuple), optional
        Default :func:`default_range_sets`.
    noise_levels_px : sequence of float
        Gaussian noise added to the centroids, px per axis.
    trials : int
        Noise draws per exposure (1 when no noise is added).
    seed : int

    Returns
    -------
    rows : list of dict
        One per case with an estimate (:func:`focal_case`).
    estimate : FocalEstimate
        :func:`focal_only_estimate`.
    """
    f_true_px = check_finite_positive(f_true_px, "true focal length")
    check_focal_frames(frames)
    rows = [focal_case(frames, c, believed, pattern, f_true_px, seed)
            for c in focal_cases(frames, range_sets, noise_levels_px, trials)]
    return [r for r in rows if r is not None], focal_only_estimate(frames, believed, pattern)
