"""The SVGS sensor of an approach: a pose in, a :class:`Measurement` out, frame after frame
(:class:`ApproachSensor`; the model is described in :mod:`svgs_sim.sim.approach`)."""

from __future__ import annotations

import dataclasses
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from svgs_sim.base.errors import InputError, check_finite
from svgs_sim.base.profiles import load_camera, load_pattern
from svgs_sim.sim.closed_loop import (
    Frame, RenderOptions, Scenario, lab_flux, lab_photon_factor, natural_part, solve_exposure, solver_camera,
)
from svgs_sim.sim.crlb import frame_crlb, frame_windows, window_gradients
from svgs_sim.sim.metrics import match_err_max_px, spot_positions_px, state_error, wrong_lock_px
from svgs_sim.svgs.frames import D_CAM_PHOTO, STATE_KEYS, angles_from_rotation, check_pose, pose_to_state, state_dict
from svgs_sim.svgs.pipeline import camera_threshold

from .stream import ExposureStream, RenderStream, frame_seeds
from .trajectory import VELOCITY_STEP_S, Trajectory

#: PSF draws per shifted image of the per-frame Cramer-Rao bound (:func:`svgs_sim.sim.crlb.frame_crlb`):
#: a quarter of the study default, for a Monte Carlo error of about 1 % on a band in a plot.
CRLB_DRAWS = 1 << 15
#: Reason of a frame whose target the camera cannot see at all (nothing is rendered).
OUT_OF_VIEW = "out_of_view"


@dataclass
class Measurement:
    """One frame of the sensor.

    Attributes
    ----------
    frame : int
    t_s : float
        Timestamp: the exposure midpoint of the centre row, s.
    ok : bool
    reason : str or None
        Why there is no solution (:class:`svgs_sim.svgs.result.SolveResult` reasons).
    truth : dict
        The paper's state at ``t_s`` (:data:`svgs_sim.svgs.frames.STATE_KEYS`, m and deg).
    estimate : dict or None
        The solved state.
    error : dict or None
        ``estimate - truth`` per component (angles wrapped to +-180 deg).
    crlb_std : dict or None
        1-sigma Cramer-Rao bound per component for this frame (:func:`svgs_sim.sim.crlb.frame_crlb`).
    range_m : float
        Distance from the lens to the target origin at ``t_s``.
    exposure_s, iso, metered_level : float
        The frame's settings and what the meter read on it.
    next_exposure_s, next_iso : float
        The auto-exposure's settings for the next frame.
    timings_s : dict
        ``render``, ``optics``, ``expose``, ``solve`` (the sensor's own processing: detect,
        identify, solve), ``crlb``, s.
    n_blobs : int or None
    residual_rms_px : float or None
    p_value : float or None
        The solution's consistency (:func:`svgs_sim.svgs.app.consistency`; also for an ``inconsistent``
        frame, whose ``reason`` says so).
    image : ndarray, uint8 (H, W), or None
        The delivered image (``keep_images=True``).
    detect_image : ndarray, uint8 (H, W), or None
        The image the detector read (``keep_images`` True or ``"detector"``): with
        ``dark_pixels="deferred"`` the delivered bytes over the tiles that can reach the
        threshold and 0 elsewhere (every pixel above :attr:`threshold_u8` as in :attr:`image`),
        otherwise the delivered image itself.
    threshold_u8 : float or None
        The detector's threshold on this frame's 8-bit image (when the sensor keeps images).
    solution : object
        :class:`svgs_sim.svgs.solver.Solution` or the failure result (for overlays).
    blobs_px : ndarray, shape (M, 2), or None
        Every blob the detector found (when the sensor keeps images).
    match_err_max_px : float or None
        For a pose the paper's app would report (solved, or refused only by the consistency test):
        the largest distance of an identified blob from its target's spot, px
        (:func:`svgs_sim.sim.metrics.match_err_max_px`); None otherwise.
    wrong_lock : bool
        That pose locked onto something else: ``match_err_max_px`` beyond
        :func:`svgs_sim.sim.metrics.wrong_lock_px` (a glint or a lit body taken for a target).
    """

    frame: int
    t_s: float
    ok: bool
    reason: str | None
    truth: dict
    estimate: dict | None
    error: dict | None
    crlb_std: dict | None
    range_m: float
    exposure_s: float
    iso: float
    metered_level: float
    next_exposure_s: float
    next_iso: float
    timings_s: dict = field(default_factory=dict)
    n_blobs: int | None = None
    residual_rms_px: float | None = None
    p_value: float | None = None
    image: np.ndarray | None = field(default=None, repr=False)
    solution: object = field(default=None, repr=False)
    blobs_px: np.ndarray | None = field(default=None, repr=False)
    match_err_max_px: float | None = None
    wrong_lock: bool = False
    detect_image: np.ndarray | None = field(default=None, repr=False)
    threshold_u8: float | None = None

    def row(self) -> dict:
        """Flat columns (:data:`MEASUREMENT_COLUMNS`)."""
        out = {"frame": self.frame, "t_s": self.t_s, "range_m": self.range_m}
        for k in STATE_KEYS:
            out[f"true_{k}"] = self.truth[k]
        for prefix, d in (("est", self.estimate), ("err", self.error), ("crlb", self.crlb_std)):
            for k in STATE_KEYS:
                out[f"{prefix}_{k}"] = None if d is None else d.get(k)
        out.update({"ok": int(self.ok), "reason": self.reason or "", "n_blobs": self.n_blobs,
                    "residual_rms_px": self.residual_rms_px, "p_value": self.p_value, "exposure_s": self.exposure_s, "iso": self.iso,
                    "metered_level": self.metered_level, "next_exposure_s": self.next_exposure_s,
                    "next_iso": self.next_iso, "match_err_max_px": self.match_err_max_px,
                    "wrong_lock": int(self.wrong_lock)})
        for k in TIMING_KEYS:
            out[f"{k}_s"] = self.timings_s.get(k)
        return out


#: The stages of a frame's :attr:`Measurement.timings_s`.
TIMING_KEYS = ("render", "optics", "expose", "solve", "crlb")
#: Columns of ``measurements.csv`` (one row per frame); ``solve_s`` is the sensor's processing
#: time (detect, identify, solve) on this machine.
MEASUREMENT_COLUMNS = (("frame", "t_s", "range_m") + tuple(f"true_{k}" for k in STATE_KEYS)
                       + tuple(f"est_{k}" for k in STATE_KEYS) + tuple(f"err_{k}" for k in STATE_KEYS)
                       + tuple(f"crlb_{k}" for k in STATE_KEYS)
                       + ("ok", "reason", "n_blobs", "residual_rms_px", "p_value", "exposure_s", "iso", "metered_level",
                          "next_exposure_s", "next_iso", "match_err_max_px", "wrong_lock")
                       + tuple(f"{k}_s" for k in TIMING_KEYS))


def scenario_from_pose(R_cam_target, t_cam_target_m, base: Scenario) -> Scenario:
    """The target-mounted :class:`~svgs_sim.sim.closed_loop.Scenario` whose pose is ``(R, t)``."""
    R = np.asarray(R_cam_target, float)
    t = np.asarray(t_cam_target_m, float)
    if t[2] <= 0:
        raise InputError(f"pose: the target is behind the camera (t_cam_target_m = {t.tolist()})")
    ang = np.degrees(angles_from_rotation(D_CAM_PHOTO @ R))
    x, y, _ = D_CAM_PHOTO @ t
    return base.replace(mount="target", range_m=float(t[2]), target_x_m=float(x), target_y_m=float(y),
                        roll_deg=float(ang[0]), pitch_deg=float(ang[1]), yaw_deg=float(ang[2]))


class ApproachSensor:
    """The SVGS sensor for a simulation loop: a pose in, a measurement out, frame after frame.

    Parameters
    ----------
    camera : str or svgs.Camera
        A phone profile (name, path, or a camera such as :func:`svgs_sim.camera.phone.preview.binned_camera`).
    pattern : str
        Target pattern.
    seed : int
        Seeds every frame's render and noise (frame ``k`` draws from ``(seed, k)``,
        :func:`svgs_sim.sim.approach.stream.frame_seeds`).
    motion : bool
        Model motion blur and the rolling shutter (see :mod:`svgs_sim.sim.approach`).
    crlb : bool
        Compute each solved frame's Cramer-Rao bound (:data:`CRLB_DRAWS`; 0.3-0.5 s a frame at
        full resolution).
    frame_rate_hz : float, optional
        The rate at which the sensor takes its frames. The phone must deliver a frame per period:
        its auto-exposure's longest exposure is capped at the period, and a manual exposure or a
        rolling-shutter readout longer than the period is refused. The auto-exposure then steps
        ``period / max(1/STREAM_FPS, exposure)`` times between frames. None: free-running, the
        steps counted from the times of consecutive calls.
    keep_images : bool or "detector"
        Keep the images, the threshold, the blobs and the solution in each :class:`Measurement`.
        True: the delivered image and the detector's image (with the default
        ``dark_pixels="deferred"`` the delivered image is made for it: about as long again as
        the frame at full resolution); ``"detector"``: the detector's image only (nothing more
        to make).
    overlap_render : bool
        Render the next frame of a trajectory (``next_pose``, :meth:`along`) in a background
        thread while the phone model works on this one. On by default since the deferred dark
        pixels (issue 40): on the two-core machine it takes a full-resolution frame from about
        0.24 to 0.2 s (``benchmarks/bench_approach.py``); before them it bought little, the
        camera model's full-frame passes then filling both cores. Only a trajectory's frames
        know their next pose (``measure_on(..., next_t_s=)``, :meth:`along`); :meth:`measure`
        renders in place. The numbers do not change.
    overlap_camera : bool
        Meter the frame in a background thread while the exposure is made, detected and solved
        and the bound computed (the single-threaded JPEG, solution and bound leave a core free).
        On by default; the numbers do not change (``tests/test_sim_approach.py``).
    threshold : None, float or str
        The detector's threshold (None: the app's for the camera, :func:`svgs_sim.svgs.pipeline.camera_threshold`).
    base : Scenario, optional
        The lab around the target (backdrop, ambient light) and render quality; default the
        lab of :mod:`svgs_sim.sim.lab`. Its camera fields (lens offsets, overrides, a fixed focus) are
        refused: give the camera itself.
    body : RenderOptions or dict, optional
        The target's body (:class:`svgs_sim.sim.closed_loop.RenderOptions`' ``body``,
        ``body_material``, ``body_materials``: ``"3u"``, a mesh file...); default the renderer's,
        the lab's breadboard.
    dark_pixels : {"deferred", "exact", "fast"}
        How the camera model makes the pixels that cannot reach the detection threshold
        (:meth:`svgs_sim.camera.phone.Exposer.expose`; tiles away from the spots whose expected
        charge keeps them below it but with a chance under 1e-13 a pixel). ``deferred``
        (default): only the other tiles are exposed for the detector, to the exact path's bytes;
        the full image, the exact path's, is made when it is read (``keep_images``): the same
        measurements as ``exact`` unless a dark pixel would have reached the threshold
        (``tests/test_phone_deferred.py``). ``exact``: every pixel now. ``fast``: those pixels by a
        table sampler of the same Poisson law (other numbers, the same statistics:
        ``tests/test_phone_dark_pixels.py``). A frame whose pixels can mostly reach the
        threshold takes the exact path.

    Examples
    --------
    >>> sensor = ApproachSensor("galaxy-nexus", seed=1)            # doctest: +SKIP
    >>> m = sensor.measure(0.0, R_cam_target, t_cam_target_m)      # doctest: +SKIP
    >>> for m in sensor.stream((t, R, t_vec) for ...): ...          # doctest: +SKIP
    """

    def __init__(self, camera="galaxy-nexus", pattern="svgs-3u", *, seed: int = 0, motion: bool = True,
                 crlb: bool = True, keep_images: bool | str = False, threshold=None, base: Scenario | None = None,
                 frame_rate_hz: float | None = None, overlap_render: bool = True, body=None,
                 overlap_camera: bool = True, dark_pixels: str = "deferred"):
        from svgs_sim.camera.phone import DARK_PIXELS, PhoneCamera, PhoneParams

        if dark_pixels not in DARK_PIXELS:
            raise InputError(f"dark_pixels: expected one of {DARK_PIXELS}, got {dark_pixels!r}")
        #: How the camera model makes the dark pixels (``deferred``, ``exact`` or ``fast``).
        self.dark_pixels = dark_pixels

        self.camera = load_camera(camera)
        for t in ("optics", "flash"):
            self.camera.table(t)
        self.pattern = load_pattern(pattern)
        base = base or Scenario()
        if base.camera_overrides or any(base.lens_pp_offset_px) or base.lens_k1 or base.focus_distance_m is not None:
            raise InputError("base: camera_overrides, lens_pp_offset_px, lens_k1 and focus_distance_m belong to the "
                             "camera; give ApproachSensor the camera itself (the lens refocuses on the target)")
        self.base = base.replace(camera=self.camera, pattern=self.pattern)  # the scenario carries the objects
        params, self.frame_rate_hz = self._stream_params(PhoneParams.from_camera(self.camera), frame_rate_hz)
        if int(seed) < 0:
            raise InputError(f"seed: expected a non-negative integer, got {seed!r}")
        self.seed = int(seed)
        self.motion = bool(motion)
        self.crlb = bool(crlb)
        if isinstance(keep_images, str) and keep_images != "detector":
            raise InputError(f"keep_images: expected True, False or 'detector', got {keep_images!r}")
        #: What the measurements keep (True, ``"detector"`` or False).
        self.keep_images = keep_images if isinstance(keep_images, str) else bool(keep_images)
        self.overlap_render = bool(overlap_render)
        self.overlap_camera = bool(overlap_camera)
        self._camera_pool = None
        self._meter_lock = threading.Lock()
        self.threshold = threshold
        self.phone = PhoneCamera(self.camera, params=params)
        self.exposure = ExposureStream(self.phone, self.frame_rate_hz)
        self.body = body if isinstance(body, RenderOptions) else RenderOptions(**(body or {}))  # checked here
        self.renders = RenderStream(self.camera, self.pattern, self.seed, spp=self.base.spp, roi_spp=self.base.roi_spp,
                                    scene_options={**self.base.scene.natural_light(), **self.body.scene_options()})
        self._lab_factor = None
        self.frame_index = 0
        self._last_pose = None

    def _stream_params(self, params, frame_rate_hz):
        """The phone's parameters at a frame rate (its longest exposure capped at the period) and
        the checked rate (None: free-running)."""

        if frame_rate_hz is None:
            return params, None
        f = float(frame_rate_hz)
        if not (np.isfinite(f) and f > 0):
            raise InputError(f"frame_rate_hz: expected a positive frame rate, got {frame_rate_hz!r}")
        period = 1.0 / f
        e, ro = params.exposure, params.sensor.readout_time_s
        if ro > period:
            raise InputError(f"--fps: {f:g} frames/s leaves {period * 1e3:.1f} ms a frame, less than the "
                             f"{self.camera.name} sensor's {ro * 1e3:.0f} ms rolling-shutter readout")
        if e.mode == "manual" and e.exposure_s > period:
            raise InputError(f"--fps: {f:g} frames/s leaves {period * 1e3:.1f} ms a frame, less than the "
                             f"{self.camera.name}'s manual exposure of {e.exposure_s * 1e3:.1f} ms")
        if e.max_exposure_s > period:  # the phone shortens its longest exposure to keep the frame rate
            params = dataclasses.replace(params, exposure=dataclasses.replace(
                e, max_exposure_s=max(period, e.min_exposure_s)))
        return params, f

    # ------------------------------------------------------------------ state
    @property
    def exposure_settings(self):
        """(exposure_s, iso) the next frame will use, or None before the first frame of an
        auto-exposing phone (it then converges on that frame's scene)."""
        return self.exposure.next_settings

    def restore(self, frame_index: int, next_exposure_s: float | None, next_iso: float | None) -> None:
        """Continue a stream at ``frame_index`` with the auto-exposure's stored settings for it
        (a resumed run; ``next_exposure_s``, ``next_iso`` of the last stored frame, which with
        ``frame_rate_hz`` already include the steps between frames)."""
        self.frame_index = int(frame_index)
        self.exposure.restore(next_exposure_s, next_iso)

    def frame_seeds(self, k: int) -> tuple[int, int, int]:
        """Frame ``k``'s seeds ``(render, noise, motion)`` (:func:`svgs_sim.sim.approach.stream.frame_seeds`)."""
        return frame_seeds(self.seed, k)

    def renderer(self):
        """The sensor's one :class:`svgs_sim.render.api.Renderer` (:meth:`RenderStream.renderer`)."""
        return self.renders.renderer()

    def _lab(self, scenario: Scenario) -> tuple[np.ndarray, dict]:
        if self._lab_factor is None:
            self._lab_factor = lab_photon_factor(self.camera)
        return lab_flux(self.camera, scenario, factor=self._lab_factor)

    def targets_px(self, R, t) -> np.ndarray:
        """The pattern's targets projected at a pose, (N, 2) px."""
        return self.camera.project(self.pattern.points_m @ np.asarray(R, float).T + np.asarray(t, float))

    def _in_view(self, R, t) -> bool:
        """Every target in front of the lens and at least one inside the image."""
        p_cam = self.pattern.points_m @ R.T + t
        return bool(np.all(p_cam[:, 2] > 0) and np.any(self.camera.in_image(self.targets_px(R, t))))

    def _velocity_since_last(self, t_s, R, t) -> np.ndarray | None:
        """Image velocity of each target (N, 2) px/s since the previous frame (None on the first)."""
        if self._last_pose is None:
            return None
        t1, R1, tv1 = self._last_pose
        dt = float(t_s) - t1
        if dt <= 0:
            return None
        return (self.targets_px(R, t) - self.targets_px(R1, tv1)) / dt

    def _checked_velocity(self, image_velocity_px_s) -> np.ndarray | None:
        if image_velocity_px_s is None:
            return None
        v = np.asarray(image_velocity_px_s, float)
        if v.shape != (self.pattern.n, 2) or not np.all(np.isfinite(v)):
            raise InputError(f"image_velocity_px_s: expected finite (du/dt, dv/dt) px/s of each of the "
                             f"{self.pattern.n} targets, shape ({self.pattern.n}, 2), got shape {v.shape}")
        return v

    # ------------------------------------------------------------------ measuring
    def measure(self, t_s: float, R_cam_target=None, t_cam_target_m=None, *, image_velocity_px_s=None,
                scenario: Scenario | None = None, next_pose=None) -> Measurement:
        """One frame at time ``t_s`` with the target at ``(R_cam_target, t_cam_target_m)``.

        The steps: the frame's scenario and pose (:meth:`_frame_scenario`), the auto-exposure's
        steps since the last frame, the render (:meth:`_render`), the optics with the motion
        during the exposure (:meth:`_optics`), the exposure, detection and solution
        (:meth:`_expose_and_solve`), the auto-exposure's next step, the bound (:meth:`_crlb`).

        Parameters
        ----------
        t_s : float
            The frame's timestamp, s.
        R_cam_target : array_like, shape (3, 3)
        t_cam_target_m : array_like, shape (3,)
            ``p_cam = R_cam_target @ p_target + t_cam_target_m`` (OpenCV camera frame), m.
        image_velocity_px_s : array_like, shape (N, 2), optional
            Image velocity of each target, px/s (motion blur, rolling shutter); default: the
            velocity since the previous call (none on the first frame).
        scenario : Scenario, optional
            The frame as a scenario (e.g. a stand-mounted trajectory), instead of the pose.
        next_pose : (R_cam_target, t_cam_target_m), optional
            The pose of the next call, when known (a trajectory): its render starts in a
            background thread as soon as this frame's render is done, and overlaps this frame's
            camera model, detection, solution and bound, when the sensor was made with
            ``overlap_render=True`` (ignored otherwise). The numbers do not change: the next
            call uses that render only if its frame and pose match.

        Returns
        -------
        Measurement
        """
        sc, R, t = self._frame_scenario(R_cam_target, t_cam_target_m, scenario)
        t_s = float(check_finite(t_s, "t_s"))
        k = self.frame_index
        self.exposure.catch_up(t_s)
        uv_true = self.targets_px(R, t)
        if not self._in_view(R, t):
            self.renders.drop()
            return self._out_of_view(k, t_s, R, t)
        next_frame = self._next_frame(next_pose)
        vel = self._checked_velocity(image_velocity_px_s)
        _, noise_seed, motion_seed = self.frame_seeds(k)
        timings = {}
        t0 = time.perf_counter()
        frame = self._render(k, sc, R, t, t_s, next_frame)
        timings["render"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        if vel is None:
            vel = self._velocity_since_last(t_s, R, t)
        exposer, settings = self._optics(frame, uv_true, vel, motion_seed)
        timings["optics"] = time.perf_counter() - t0
        ahead = self._ahead(exposer)
        ex, blobs, row = self._expose_and_solve(frame, exposer, settings, noise_seed, timings)
        crlb = self._crlb(frame, exposer, row, timings)  # while the camera thread meters
        self._meter_built(exposer, ahead)
        level = exposer.metered_level(*settings)
        self.exposure.after_frame(t_s, settings, exposer.meter)
        m = self._measurement(k, t_s, R, t, row, crlb, settings, level, timings, ex, blobs)
        m.match_err_max_px = match_err_max_px(row, row["_solution"], spot_positions_px(
            solver_camera(self.camera, ex.detect_image.shape), self.pattern, R, t, frame.truth.get("spots_px_predicted"),
            ex.detect_image.shape[1] / self.camera.width), self.pattern.ids)
        m.wrong_lock = bool(m.match_err_max_px is not None
                            and m.match_err_max_px > wrong_lock_px(self.camera, self.pattern, float(t[2])))
        self.frame_index = k + 1
        self._last_pose = (float(t_s), R, t)
        return m

    def _frame_scenario(self, R_cam_target, t_cam_target_m, scenario: Scenario | None):
        """The frame's scenario (the lab around the target at this range) and pose ``(sc, R, t)``."""

        if scenario is not None:
            sc = scenario.replace(camera=self.base.camera, pattern=self.base.pattern)
            R, t = sc.pose()
            return sc, R, t
        if R_cam_target is None or t_cam_target_m is None:
            raise InputError("measure: give the pose (R_cam_target, t_cam_target_m) or a scenario")
        R, t = check_pose(R_cam_target, t_cam_target_m)
        return scenario_from_pose(R, t, self.base), R, t

    def _next_frame(self, next_pose):
        """The next frame's pose to render in the background (None: no overlap, or not in view)."""

        if next_pose is None or not self.overlap_render:
            return None
        Rn, tn = check_pose(*next_pose)
        return (Rn, tn) if self._in_view(Rn, tn) else None

    def _render(self, k: int, sc: Scenario, R, t, t_s: float, next_frame) -> Frame:
        """Frame ``k`` rendered (or taken from the background thread) with the lab's light around
        it; the next frame's render started when there is one."""
        light = sc.scene.natural_light()  # the frame's sun (a trajectory's sun columns move it)
        res = self.renders.take(k, R, t, light)
        if next_frame is not None:  # the next frame renders while this one goes through the phone (this one's light)
            self.renders.start(k + 1, *next_frame, light)
        lab, info = self._lab(sc)
        truth = dict(res.truth)
        truth.update({"lab": info, "scenario": sc.to_json(), "focus_distance_m": float(np.linalg.norm(t)), "t_s": float(t_s)})
        return Frame(sc, res.flux + lab, truth, 0.0, lab, target_diffuse=res.flux_diffuse, points=res.points,
                     _phone={(True, None, None): self.phone}, lab_unit=(info["radiance_w_m2_sr"], self._lab_factor),
                     natural=natural_part(res))

    def _optics(self, frame: Frame, uv_true: np.ndarray, vel, motion_seed: int):
        """The frame's exposer and its settings ``(exposure_s, iso)``: the stream's, or on its
        first frame the ones the phone settles on; with ``motion``, the spots' samples moved by
        their image velocity ``vel`` over the exposure and the rolling shutter's readout."""
        settings = self.exposure_settings
        exposer = None
        if settings is None:  # the stream's first frame: the phone has settled on this scene
            exposer = frame.exposer()
            e_s, iso, _ = exposer.auto_exposure()
            settings = (e_s, iso)
        if self.motion and vel is not None and frame.points is not None and len(frame.points):
            pts = frame.points
            near = np.argmin((pts.u_px[:, None] - uv_true[None, :, 0]) ** 2
                             + (pts.v_px[:, None] - uv_true[None, :, 1]) ** 2, axis=1)
            frame.points = pts.moved(np.asarray(vel, float)[near], settings[0], self.phone.params.sensor.readout_time_s,
                                     self.camera.height, np.random.default_rng(motion_seed))
            exposer = frame.exposer()
        elif exposer is None:
            exposer = frame.exposer()
        return exposer, settings

    def _ahead(self, exposer):
        """With ``overlap_camera``: the frame's meter (it only reads the optical image), started
        in a background thread while this one exposes, detects, solves and computes the bound (a
        future; None otherwise). The meter is built under the exposer's lock: the main thread
        builds it itself when the thread has not yet begun it (:meth:`_meter_built`).

        (Until the third round of issue 40 the thread first computed the bound's image derivatives
        around the targets' true places; the bound's windows lie around the solved spots, which
        round to other pixels, so 34 of 36 were computed again here: wasted work on a shared core.)"""
        if not self.overlap_camera:
            return None
        if self._camera_pool is None:
            self._camera_pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="svgs-camera")
        lock = self._meter_lock

        def work():
            with lock:
                exposer.meter  # noqa: B018 - the property builds and keeps the meter

        return self._camera_pool.submit(work)

    def _meter_built(self, exposer, ahead) -> None:
        """The frame's meter built (by whichever thread gets to it first) and the background work done."""
        if ahead is not None:
            with self._meter_lock:
                exposer.meter  # noqa: B018
            ahead.result()

    def _expose_and_solve(self, frame: Frame, exposer, settings, noise_seed: int, timings: dict):
        """The exposure, the detection and the SVGS solution (:func:`svgs_sim.sim.closed_loop.solve_exposure`
        against the actual pose): ``(exposure, blobs, row)``; ``timings`` gets ``expose`` and
        ``solve`` (detection included)."""
        from svgs_sim.svgs.detect import detect_blobs

        t0 = time.perf_counter()
        if self.dark_pixels == "exact":
            ex = exposer.expose(seed=noise_seed, exposure_s=settings[0], iso=settings[1])
        else:  # the threshold on the delivered 8-bit image (a string: "auto" or "otsu", then the exact path)
            thr = camera_threshold(np.zeros(1, np.uint8), self.camera, self.threshold)
            ex = exposer.expose(seed=noise_seed, exposure_s=settings[0], iso=settings[1], dark_pixels=self.dark_pixels,
                                threshold_u8=None if isinstance(thr, str) else float(thr))
        timings["expose"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        img = ex.detect_image  # deferred: the lit tiles' bytes (the full image is made only when it is read)
        blobs = detect_blobs(img, threshold=camera_threshold(img, self.camera, self.threshold))
        t_detect = time.perf_counter() - t0
        row = solve_exposure(frame, ex, threshold=self.threshold, solver_camera_profile=self.camera, truth="actual",
                             blobs=blobs)
        timings["solve"] = t_detect + row["solve_s"]
        return ex, blobs, row

    def _crlb(self, frame: Frame, exposer, row: dict, timings: dict) -> dict | None:
        """A solved frame's 1-sigma bound per component (:func:`svgs_sim.sim.crlb.frame_crlb`), when the
        sensor computes it; ``timings`` gets ``crlb``."""
        crlb = None
        t0 = time.perf_counter()
        if self.crlb and row["ok"]:
            if self.overlap_camera:  # half the windows' derivatives on the camera thread (after its meter)
                boxes = frame_windows(exposer, row)
                theirs = self._camera_pool.submit(window_gradients, frame, exposer, boxes[1::2])
                window_gradients(frame, exposer, boxes[0::2])
                theirs.result()
            c = frame_crlb(frame, exposer, row, draws=CRLB_DRAWS)
            crlb = None if c is None else c.get("crlb_std")
        timings["crlb"] = time.perf_counter() - t0 if self.crlb else None
        return crlb

    def _measurement(self, k: int, t_s: float, R, t, row: dict, crlb, settings, level: float, timings: dict, ex,
                     blobs) -> Measurement:
        """The frame's :class:`Measurement`: the truth at the pose, the estimate, its error
        (:func:`svgs_sim.sim.metrics.state_error`, angles wrapped) and the exposure's settings."""
        true_state = pose_to_state(R, t)
        truth_state = state_dict(true_state)
        est = row["state"]
        sol = row["_solution"]
        error = dict(zip(STATE_KEYS, (float(x) for x in state_error(sol.state, true_state)))) if est else None
        nxt = self.exposure_settings
        # frame.flux keeps the unmoved render; the image was made from frame.points (moved)
        return Measurement(
            frame=k, t_s=float(t_s), ok=bool(row["ok"]), reason=row["reason"], truth=truth_state, estimate=est,
            error=error, crlb_std=crlb, range_m=float(t[2]),
            exposure_s=float(settings[0]), iso=float(settings[1]), metered_level=float(level),
            next_exposure_s=float(nxt[0]), next_iso=float(nxt[1]), timings_s=timings, n_blobs=row["n_blobs"],
            residual_rms_px=row["residual_rms_px"], p_value=row.get("p_value"),
            image=ex.image if self.keep_images is True else None, solution=sol if self.keep_images else None,
            blobs_px=blobs.centroid_px if self.keep_images else None,
            detect_image=ex.detect_image if self.keep_images else None,
            threshold_u8=float(blobs.threshold_used) if self.keep_images else None,
        )

    def close(self) -> None:
        """Stop the background threads (a later frame starts them again)."""
        self.renders.close()
        if self._camera_pool is not None:
            self._camera_pool.shutdown(wait=True)
            self._camera_pool = None

    def _out_of_view(self, k: int, t_s: float, R, t) -> Measurement:
        """A dropout: the target is behind the camera or outside its field of view (not rendered;
        the auto-exposure keeps its settings)."""
        nxt = self.exposure_settings or (float("nan"), float("nan"))
        m = Measurement(frame=k, t_s=t_s, ok=False, reason=OUT_OF_VIEW, truth=state_dict(pose_to_state(R, t)),
                        estimate=None, error=None, crlb_std=None, range_m=float(t[2]), exposure_s=float(nxt[0]),
                        iso=float(nxt[1]), metered_level=float("nan"), next_exposure_s=float(nxt[0]),
                        next_iso=float(nxt[1]), timings_s={}, n_blobs=0)
        self.frame_index = k + 1
        self._last_pose = (t_s, R, t)
        return m

    def stream(self, poses):
        """Measurements of poses, one per pose, as they come.

        Parameters
        ----------
        poses : iterable of (t_s, R_cam_target, t_cam_target_m)
            Times (s) and poses (shapes (3, 3) and (3,), m); each frame's image velocity comes
            from the previous pose.

        Yields
        ------
        Measurement
        """
        for t_s, R, t in poses:
            yield self.measure(t_s, R, t)

    def along(self, trajectory: Trajectory, times_s):
        """Measurements along a trajectory.

        Parameters
        ----------
        trajectory : Trajectory
        times_s : array_like, shape (n,)
            Frame times, s; each frame's image velocity from the trajectory itself (central
            difference, :data:`VELOCITY_STEP_S`).

        Yields
        ------
        Measurement
        """
        times = np.asarray(times_s, float)
        try:
            for i, t_s in enumerate(times):
                yield self.measure_on(trajectory, float(t_s), next_t_s=float(times[i + 1]) if i + 1 < len(times)
                                      else None)
        finally:
            self.close()

    def measure_on(self, trajectory: Trajectory, t_s: float, *, next_t_s: float | None = None) -> Measurement:
        """One frame of a trajectory at ``t_s``, the image velocity from the trajectory itself.
        ``next_t_s``: the time of the next frame, whose render then overlaps this frame's camera
        model (see :meth:`measure`)."""
        sc = trajectory.scenario(t_s, self.base)
        nxt = None
        if next_t_s is not None and self.overlap_render:
            nxt = trajectory.scenario(float(next_t_s), self.base).replace(camera=self.base.camera,
                                                                          pattern=self.base.pattern).pose()
        lo = max(t_s - VELOCITY_STEP_S, float(trajectory.t_s[0]))
        hi = min(t_s + VELOCITY_STEP_S, float(trajectory.t_s[-1]))
        vel = None
        if hi > lo:
            vel = (self.targets_px(*trajectory.scenario(hi, self.base).pose())
                   - self.targets_px(*trajectory.scenario(lo, self.base).pose())) / (hi - lo)
        return self.measure(t_s, scenario=sc, image_velocity_px_s=vel, next_pose=nxt)
