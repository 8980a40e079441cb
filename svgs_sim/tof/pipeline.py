"""The ToF pose pipeline: gray + depth frames -> pose (Zhu et al. 2022, sections 3-5).

Stages (each a function of its own module, usable alone)::

    validate -> temporal median of depth (svgs_sim.tof.temporal) -> active pixel set (svgs_sim.tof.active)
    -> nLoG on the active set + filtered threshold (svgs_sim.tof.log_filter)
    -> hysteresis blobs + size/eccentricity gates (svgs_sim.tof.blobs) -> persistence counter (svgs_sim.tof.temporal)
    -> centroids, ellipse confirmation/supplement, depth, penalty (svgs_sim.tof.centroid, svgs_sim.tof.ellipse)
    -> 3-D points from line of sight and depth (svgs_sim.tof.camera)
    -> deterministic-annealing matching with slack (svgs_sim.tof.match)
    -> weighted SVD (svgs_sim.tof.pose) -> projected-circle-centre correction (svgs_sim.tof.ellipse)
    -> iterative line-of-sight refinement (svgs_sim.tof.pose)

:class:`TofPipeline` holds the per-sequence state (temporal median, persistence counter);
:func:`solve_frame` runs one frame pair from scratch. Results are :class:`TofSolution`
(truthy) or :class:`svgs_sim.svgs.result.Failure` (falsy, with a reason).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, fields, replace

import numpy as np

from svgs_sim.base.errors import InputError
from svgs_sim.svgs.frames import pose_to_state
from svgs_sim.base.profiles import Camera
from svgs_sim.svgs.result import Failure, Solved

from . import active as _active
from . import blobs as _blobs
from . import centroid as _centroid
from . import log_filter as _log
from . import match as _match
from .camera import DEFAULT_CAMERA, DEFAULT_PATTERN, depth_kind, line_of_sight, load_camera, load_target
from .ellipse import centre_correction_px, project_circle_conics
from .pose import REFINE_MAX_ITER, REFINE_TOL, REFINE_TOL_PAPER_M, is_degenerate, refine_line_of_sight, weighted_svd_pose
from .temporal import PersistenceCounter, RecursiveMedianDepth

STAGES = ("validate", "temporal_median", "active_set", "nlog_filter", "blobs", "persistence", "centroids",
          "match", "pose")


@dataclass(frozen=True)
class PipelineParams:
    """Pipeline settings. Defaults are ASSUMPTIONS where the paper's values are not legible;
    see each stage's module for what the parameter means.
    """

    threshold_rel: float = _active.DEFAULT_THRESHOLD_REL
    max_active_pixels: int = _active.DEFAULT_MAX_PIXELS
    noise_k: float = _active.DEFAULT_NOISE_K
    sigma_px: float = _log.DEFAULT_SIGMA_PX
    filtered_threshold_rel: float = _log.DEFAULT_FILTERED_THRESHOLD_REL
    high_gray_rel: float = _blobs.DEFAULT_HIGH_GRAY_REL
    high_filtered_rel: float = _blobs.DEFAULT_HIGH_FILTERED_REL
    min_blob_pixels: int = _blobs.DEFAULT_MIN_PIXELS
    max_blob_pixels: int = _blobs.DEFAULT_MAX_PIXELS
    max_eccentricity: float = _blobs.DEFAULT_MAX_ECCENTRICITY
    ellipse_min_pixels: int = _centroid.DEFAULT_ELLIPSE_MIN_PIXELS
    max_fit_rms_px: float = _centroid.DEFAULT_MAX_FIT_RMS_PX
    max_penalty: float = _centroid.DEFAULT_MAX_PENALTY
    max_box_px: int = _centroid.DEFAULT_MAX_BOX_PX
    ellipse_supplement: bool = True
    ellipse_fit: str = "auto"
    centroid_weighting: str = "coverage"
    temporal_median: bool = True
    persistence_window: int = 1
    persistence_min_count: int = 1
    match_sigma_m: float = _match.DEFAULT_SIGMA_M
    match_slack: float = _match.DEFAULT_SLACK
    use_marker_sizes: bool = True
    centre_correction: bool = True
    refine: bool = True
    refine_method: str = "fixed-point"  # the paper's literal iteration (section 5.2); "gauss-newton": its converged optimum
    refine_tol_m: float = REFINE_TOL_PAPER_M  # fixed point: stop when t changes < tol (m) and R < tol (rad) in one step
    refine_max_iter: int = REFINE_MAX_ITER
    centroid_sigma_px: float = 0.05
    depth_sigma_floor_m: float = 0.002
    depth_weight: float | None = 0.0  # 0: the paper's scheme (section 5.2); None: sigma_perp^2 / sigma_rho^2 per marker
    max_residual_px: float = 3.0

    def replace(self, **kw) -> "PipelineParams":
        unknown = set(kw) - {f.name for f in fields(self)}
        if unknown:
            raise InputError(f"unknown pipeline parameter(s): {sorted(unknown)}")
        return replace(self, **kw)


@dataclass
class TofSolution(Solved):
    """A solved ToF pose: truthy.

    Attributes
    ----------
    state : ndarray, shape (6,)
        Paper state ``[X_L_m, Y_L_m, Z_L_m, phi_rad, theta_rad, psi_rad]`` (svgs_sim.svgs.frames).
    R_cam_target : ndarray, shape (3, 3)
    t_cam_target_m : ndarray, shape (3,)
    targets_px : dict
        Marker id -> ``[u, v]`` measured (corrected) centre of each matched marker.
    targets_slant_range_m : dict
        Marker id -> measured slant range (along the marker's line of sight), m.
    n_blobs : int
        Candidate reflectors found.
    residual_rms_px : float
        RMS reprojection residual of the matched markers.
    residual_rms_m : float
        RMS 3-D residual between measured marker points and the model.
    iterations : int
        Line-of-sight refinement iterations.
    timings_s : dict
        Seconds per stage (see :data:`STAGES`).
    candidates : object
        The :class:`svgs_sim.tof.centroid.Candidates` (diagnostics).
    """

    state: np.ndarray
    R_cam_target: np.ndarray
    t_cam_target_m: np.ndarray
    targets_px: dict
    targets_slant_range_m: dict
    n_blobs: int
    residual_rms_px: float
    residual_rms_m: float
    iterations: int
    timings_s: dict = field(default_factory=dict)
    candidates: object = field(default=None, repr=False)

    def to_json(self) -> dict:
        """The JSON object of ``svgs tof solve --json`` (same keys as ``svgs solve``)."""
        return {
            "ok": True,
            "reason": None,
            "state": self.state_dict,
            "R_cam_target": np.asarray(self.R_cam_target).tolist(),
            "t_cam_target_m": np.asarray(self.t_cam_target_m).tolist(),
            "targets_px": {str(k): [float(x) for x in v] for k, v in self.targets_px.items()},
            "n_blobs": int(self.n_blobs),
            "residual_rms_px": float(self.residual_rms_px),
            "iterations": int(self.iterations),
            "targets_slant_range_m": {str(k): float(v) for k, v in self.targets_slant_range_m.items()},
            "residual_rms_m": float(self.residual_rms_m),
            "timings_s": {k: float(v) for k, v in self.timings_s.items()},
        }


def validate_frames(gray, depth_m, camera: Camera | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Check a gray + depth pair; return float32 copies with invalid depth as NaN.

    Parameters
    ----------
    gray : array_like, shape (H, W) (or (H, W, 3): channels are averaged)
    depth_m : array_like, shape (H, W)
        Metres; NaN, inf and 0 mark invalid pixels.
    camera : Camera, optional
        When given, the frames must have its size.

    Raises
    ------
    InputError
        Not 2-D, sizes differ (from each other or the camera), gray not finite, negative
        depth, or no valid depth pixel at all.
    """
    g = np.asarray(gray)
    d = np.asarray(depth_m)
    if g.ndim == 3 and g.shape[2] in (3, 4):
        g = g[..., :3].astype(np.float32).mean(-1)
    if g.ndim != 2 or g.size == 0:
        raise InputError(f"gray: expected a 2-D image, got shape {g.shape}")
    if d.ndim != 2 or d.size == 0:
        raise InputError(f"depth: expected a 2-D image, got shape {d.shape}")
    if not (np.issubdtype(g.dtype, np.number) and np.issubdtype(d.dtype, np.number)):
        raise InputError(f"gray, depth: expected numeric images, got {g.dtype} and {d.dtype}")
    if g.shape != d.shape:
        raise InputError(f"gray and depth have different sizes: gray {g.shape[1]}x{g.shape[0]}, depth {d.shape[1]}x{d.shape[0]} (W x H)")
    if camera is not None and g.shape != (camera.height, camera.width):
        raise InputError(f"gray/depth: frames are {g.shape[1]}x{g.shape[0]} but camera {camera.name!r} is "
                         f"{camera.width}x{camera.height}")
    g = g.astype(np.float32)
    if not np.all(np.isfinite(g)):
        raise InputError("gray: contains NaN or infinite values")
    d = d.astype(np.float32)
    with np.errstate(invalid="ignore"):
        if np.any(d < 0):
            raise InputError("depth: contains negative values (expected metres; 0 or NaN mark invalid pixels)")
        valid = np.isfinite(d) & (d > 0)
    if not valid.any():
        raise InputError("depth: no valid pixel (all NaN, infinite or 0)")
    return g, np.where(valid, d, np.nan).astype(np.float32)


class TofPipeline:
    """Stateful ToF pose pipeline for a sequence of frame pairs.

    Parameters
    ----------
    camera : str, Path or Camera
        ToF camera profile (default ``tof-epc660``).
    target : str, Path or MarkerTarget
        Marker target (default ``tof-8``).
    params : PipelineParams, optional
    **overrides
        Individual :class:`PipelineParams` fields.
    """

    def __init__(self, camera=DEFAULT_CAMERA, target=DEFAULT_PATTERN, params: PipelineParams | None = None, **overrides):
        self.camera = camera if isinstance(camera, Camera) else load_camera(camera)
        self.target = load_target(target)
        self.params = (params or PipelineParams()).replace(**overrides) if overrides else (params or PipelineParams())
        self.depth_kind = depth_kind(self.camera)
        self.reset()

    def reset(self) -> None:
        """Forget the sequence (temporal median and persistence state)."""
        self.median = RecursiveMedianDepth()
        self.persistence = PersistenceCounter(self.params.persistence_window, self.params.persistence_min_count)
        self.frames = 0

    # ------------------------------------------------------------------ one frame
    def process(self, gray, depth_m):
        """Run the pipeline on one frame pair.

        Parameters
        ----------
        gray : array_like, shape (H, W)
            Gray (amplitude) image, any scale.
        depth_m : array_like, shape (H, W)
            Depth in metres (NaN / 0 invalid), radial unless the profile says ``z``.

        Returns
        -------
        TofSolution or Failure
        """
        P = self.params
        T = {}
        tic = time.perf_counter()

        def lap(name):
            nonlocal tic
            now = time.perf_counter()
            T[name] = T.get(name, 0.0) + now - tic
            tic = now

        g, d = validate_frames(gray, depth_m, self.camera)
        lap("validate")
        self.frames += 1
        if P.temporal_median:
            d = self.median.update(d)
        lap("temporal_median")
        act = _active.active_pixel_set(g, P.threshold_rel, P.max_active_pixels, noise_k=P.noise_k)
        lap("active_set")
        if act.n == 0:
            return Failure("no_blobs", "no pixel is brighter than the raw gray threshold (all-dark frame?)",
                           {"n_blobs": 0, "threshold": act.threshold, "timings_s": T})
        act_f, F, _ = _log.filter_active_set(g, act, P.sigma_px, P.filtered_threshold_rel)
        lap("nlog_filter")
        bl = _blobs.find_blobs(act_f, F, high_gray_rel=P.high_gray_rel, high_filtered_rel=P.high_filtered_rel,
                               min_pixels=P.min_blob_pixels, max_pixels=P.max_blob_pixels,
                               max_eccentricity=P.max_eccentricity)
        lap("blobs")
        g_c, d_c = g, d
        if P.persistence_window > 1:
            keep, g_c, d_c, _ = self.persistence.update(bl.mask(g.shape), g, d)
            bl = _blobs.blobs_from_mask(keep, g_c, min_pixels=P.min_blob_pixels, max_pixels=P.max_blob_pixels)
            g_c = np.where(keep, g_c, act.background).astype(np.float32)
        lap("persistence")
        if bl.n == 0 and not len(bl.rejected_rows):
            return Failure("no_blobs", "no bright blob passed the thresholds and the size/shape gates",
                           {"n_blobs": 0, "rejected": bl.rejected, "timings_s": T})
        cands = _centroid.measure_candidates(
            bl, g_c, d_c, act.background, expected=self.target.n, ellipse_min_pixels=P.ellipse_min_pixels,
            max_fit_rms_px=P.max_fit_rms_px, max_penalty=P.max_penalty, max_box_px=P.max_box_px,
            supplement=P.ellipse_supplement, weighting=P.centroid_weighting, ellipse_fit=P.ellipse_fit,
        )
        n_found = cands.n
        cands = cands.subset(np.isfinite(cands.depth_m) & (cands.depth_m > 0))
        lap("centroids")
        if cands.n < 3:
            return Failure("too_few_blobs", f"{cands.n} candidate reflector(s) with valid depth; at least 3 are needed",
                           {"n_blobs": int(n_found), "n_with_depth": int(cands.n), "timings_s": T})
        res = self._solve(cands, T, lap)
        return res

    def _solve(self, cands, T, lap):
        P, cam, tgt = self.params, self.camera, self.target
        f = float(np.sqrt(cam.fx * cam.fy))
        e = line_of_sight(cam, cands.uv_px)
        rho = self._to_range(cands.depth_m, e)
        q = e * rho[:, None]
        sig_perp = P.centroid_sigma_px * rho / f
        sig_rho = np.maximum(np.nan_to_num(cands.depth_std_m, nan=1.0), P.depth_sigma_floor_m)
        obs_sigma = np.sqrt(sig_perp**2 + sig_rho**2)
        sizes = cands.diameter_m(cam) if P.use_marker_sizes else None
        m = _match.match_points(q, tgt.points_m, sigma_m=P.match_sigma_m, obs_sigma_m=obs_sigma,
                                obs_size=sizes, cat_size=tgt.diameter_m if sizes is not None else None,
                                slack=P.match_slack, weights=1 / obs_sigma**2)
        lap("match")
        if not m:
            m.details.update({"n_blobs": int(cands.n), "timings_s": T})
            return m
        a, i = m.obs_index, m.cat_index
        pts = tgt.points_m[i]
        if is_degenerate(pts):
            return Failure("degenerate", "the matched markers are collinear; the pose is not constrained",
                           {"n_blobs": int(cands.n), "matched_ids": tgt.ids[i].tolist(), "timings_s": T})
        uv = cands.uv_px[a].copy()
        R, t = weighted_svd_pose(pts, q[a], 1 / obs_sigma[a] ** 2)
        lam = (sig_perp[a] ** 2 / sig_rho[a] ** 2).clip(0, 1) if P.depth_weight is None else float(P.depth_weight)
        iters = 0
        if P.centre_correction:
            # the shift depends on the pose only weakly (it is itself ~0.1 px): one pass from
            # the SVD pose is enough
            uv = cands.uv_px[a] + self._centre_shift(R, t, i)
        e_a = line_of_sight(cam, uv)
        rho_a = self._to_range(cands.depth_m[a], e_a)
        if P.refine:
            gn = P.refine_method == "gauss-newton"
            r = refine_line_of_sight(pts, e_a, R, t, weights=1 / sig_perp[a] ** 2, slant_range_m=rho_a, depth_weight=lam,
                                     method=P.refine_method, tol=REFINE_TOL if gn else P.refine_tol_m,
                                     max_iter=None if gn else P.refine_max_iter)
            R, t, iters = r.R_cam_target, r.t_cam_target_m, r.iterations
        else:
            R, t = weighted_svd_pose(pts, e_a * rho_a[:, None], 1 / obs_sigma[a] ** 2)
        lap("pose")
        x = pts @ R.T + t
        if np.any(x[:, 2] <= 0) or t[2] <= 0:
            return Failure("behind_camera", "the solution puts the target behind the camera", {"n_blobs": int(cands.n)})
        res_px = cam.project(x) - uv
        rms_px = float(np.sqrt(np.mean(np.sum(res_px**2, axis=1))))
        rms_m = float(np.sqrt(np.mean(np.sum((x - e_a * rho_a[:, None]) ** 2, axis=1))))
        if not np.isfinite(rms_px) or rms_px > P.max_residual_px:
            return Failure("no_consistent_set", f"reprojection residual {rms_px:.3g} px exceeds {P.max_residual_px} px",
                           {"n_blobs": int(cands.n), "residual_rms_px": rms_px, "timings_s": T})
        ids = tgt.ids[i]
        return TofSolution(
            state=pose_to_state(R, t), R_cam_target=R, t_cam_target_m=t,
            targets_px={int(k): uv[n].tolist() for n, k in enumerate(ids)},
            targets_slant_range_m={int(k): float(rho_a[n]) for n, k in enumerate(ids)},
            n_blobs=int(cands.n), residual_rms_px=rms_px, residual_rms_m=rms_m, iterations=int(iters),
            timings_s=dict(T), candidates=cands,
        )

    def _to_range(self, depth, e):
        """Depth values -> ranges along the lines of sight ``e`` (shape (n, 3))."""
        depth = np.asarray(depth, float)
        return depth if self.depth_kind == "radial" else depth / e[:, 2]

    def _centre_shift(self, R, t, cat_index) -> np.ndarray:
        """Projected-circle-centre correction of each matched marker from the current pose:
        pole of the vanishing line minus ellipse centre of the predicted marker conic."""
        K = self.camera.K
        n = R[:, 2]
        c = self.target.points_m[cat_index] @ R.T + t
        C = project_circle_conics(K, c, n, self.target.radius_m[cat_index])
        return centre_correction_px(C, K, np.broadcast_to(n, c.shape))


def solve_frame(gray, depth_m, camera=DEFAULT_CAMERA, target=DEFAULT_PATTERN, params: PipelineParams | None = None,
                **overrides):
    """Solve one gray + depth frame pair from scratch (see :class:`TofPipeline`).

    Returns
    -------
    TofSolution or Failure
    """
    return TofPipeline(camera, target, params, **overrides).process(gray, depth_m)

