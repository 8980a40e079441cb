"""An approach simulated frame by frame: trajectories and a sensor that measures along them.

The SVGS sensor in a GNC loop sees one frame after another. :class:`ApproachSensor` is that
sensor for a simulation loop: give it the pose at each frame time and it renders the target
(Mitsuba), exposes it through the phone (its auto-exposure carried over from the previous frame,
as a phone's camera runs on a stream), detects, identifies and solves, and returns a
:class:`Measurement` (the estimate, the truth, the 1-sigma Cramer-Rao bound, ``ok`` and the
reason, and where the time went). :class:`Trajectory` gives the poses: a straight approach, or a
CSV file.

Motion during a frame. A phone's CMOS sensor exposes its rows one after another (a rolling
shutter, ``[sensor] readout_time_s``: 30 ms top to bottom, ASSUMPTION) and each row for the
exposure time. Both are modelled on the spots, which carry the measurement: every point sample
of the render (:class:`camera.rendered.PointFlux`) is moved by its spot's image velocity times
its arrival time (:meth:`~camera.rendered.PointFlux.moved`), the time measured from the frame's
timestamp, the exposure midpoint of the centre row. The image velocity comes from the
trajectory (the projected targets at ``t +- 1 ms``). The target body and the lab (a uniform
backdrop, ambient light) are not moved: the body's light is ~1e-7 of the spots' and a uniform
field does not change when it moves.

The sensor keeps what a real one keeps from frame to frame: one renderer (the scene built once,
the lens refocused on the target each frame, as the phones' autofocus), one sensor (its fixed
pattern noise), the auto-exposure state. The numbers of a frame are those of
:func:`sim.closed_loop.render_scenario` and :func:`sim.closed_loop.expose_and_solve` for the same
scenario, seeds and exposure (``tests/test_sim_approach.py``).
"""

from __future__ import annotations

import csv
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from svgs.errors import InputError, check_finite
from svgs.frames import D_CAM_PHOTO, STATE_KEYS, angles_from_rotation, pose_to_state, state_dict, state_to_pose
from svgs.profiles import Camera, Pattern

from sim.closed_loop import Frame, Scenario, lab_flux, lab_photon_factor, solve_exposure

#: Columns of a trajectory file in the paper's state: the camera position in the target frame
#: and the paper's attitude (x-y-z sequence).
STATE_COLUMNS = STATE_KEYS
#: Columns of a trajectory file in the test stand's chain (:class:`sim.stand.TestStand`): the
#: gimbal pivot's rail position, the translation stage and the gimbal angles.
STAND_COLUMNS = ("rail_m", "stage_m", "roll_deg", "pitch_deg", "yaw_deg")
#: Internal form of a target-mounted trajectory: :class:`sim.closed_loop.Scenario`'s fields.
TARGET_FIELDS = ("range_m", "target_x_m", "target_y_m", "roll_deg", "pitch_deg", "yaw_deg")
#: Internal form of a stand trajectory.
STAND_FIELDS = ("range_m", "stage_m", "roll_deg", "pitch_deg", "yaw_deg")
#: Time step of the central difference that gives the image velocity of the spots, s.
VELOCITY_STEP_S = 1e-3
#: Most frames one approach may have.
MAX_FRAMES = 100000
#: PSF draws per shifted image of the per-frame Cramer-Rao bound (:func:`sim.crlb.frame_crlb`):
#: a quarter of the study default, for a Monte Carlo error of about 1 % on a band in a plot.
CRLB_DRAWS = 1 << 15
#: The phone's preview stream rate when the exposure allows it, frames/s: its auto-exposure loop
#: steps once per stream frame, whether or not the sensor processes that frame (ASSUMPTION:
#: Android phones of 2011 streamed preview at up to 30 frames/s, and at 1/exposure when longer).
STREAM_FPS = 30.0
#: Most auto-exposure steps between two measurements (the loop has long settled by then).
MAX_AE_STEPS = 200
#: Reason of a frame whose target the camera cannot see at all (nothing is rendered).
OUT_OF_VIEW = "out_of_view"
#: A pose is visible when every target projects this far inside the image, px.
VISIBILITY_MARGIN_PX = 2.0


# ----------------------------------------------------------------------------- trajectories
@dataclass(frozen=True)
class Trajectory:
    """Poses against time, interpolated linearly between knots.

    Attributes
    ----------
    t_s : ndarray, shape (N,)
        Knot times, s, strictly increasing.
    values : ndarray, shape (N, K)
        At each knot, the :data:`TARGET_FIELDS` (``mount="target"``: the target's position in
        the camera's frame and the paper's attitude) or the :data:`STAND_FIELDS`
        (``mount="stand"``).
    mount : {"target", "stand"}
    source : str
        Where it came from (a file, or the generator's parameters).
    """

    t_s: np.ndarray
    values: np.ndarray
    mount: str = "target"
    source: str = ""

    def __post_init__(self):
        t = np.asarray(self.t_s, float)
        v = np.asarray(self.values, float)
        object.__setattr__(self, "t_s", t)
        object.__setattr__(self, "values", v)
        if self.mount not in ("target", "stand"):
            raise InputError(f"trajectory: mount must be 'target' or 'stand', got {self.mount!r}")
        if t.ndim != 1 or t.size < 2 or v.shape != (t.size, len(self.fields)):
            raise InputError(f"trajectory: expected at least 2 knots of {len(self.fields)} values, got times "
                             f"{t.shape} and values {v.shape}")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(v))):
            raise InputError("trajectory: times and values must be finite")
        if np.any(np.diff(t) <= 0):
            raise InputError("trajectory: knot times t_s must increase strictly")

    @property
    def fields(self) -> tuple:
        return TARGET_FIELDS if self.mount == "target" else STAND_FIELDS

    @property
    def duration_s(self) -> float:
        return float(self.t_s[-1] - self.t_s[0])

    def at(self, t_s: float) -> dict:
        """The Scenario fields at a time, interpolated linearly between the knots.

        Parameters
        ----------
        t_s : float
            Time, s (clamped to the trajectory's span).

        Returns
        -------
        dict
            :attr:`fields` -> value (m, deg).
        """
        t = float(np.clip(t_s, self.t_s[0], self.t_s[-1]))
        return {k: float(np.interp(t, self.t_s, self.values[:, j])) for j, k in enumerate(self.fields)}

    def scenario(self, t_s: float, base: Scenario) -> Scenario:
        """``base`` (camera, lab, ...) at this trajectory's pose at time ``t_s`` (s): a
        :class:`~sim.closed_loop.Scenario` with this trajectory's mount."""
        return base.replace(mount=self.mount, **self.at(t_s))

    def frame_times(self, fps: float) -> np.ndarray:
        """Frame timestamps ``t0 + k / fps`` within the span.

        Parameters
        ----------
        fps : float
            Frames per second (> 0).

        Returns
        -------
        ndarray, shape (n,)
            Times, s; at most :data:`MAX_FRAMES`.
        """
        fps = float(fps)
        if not np.isfinite(fps) or fps <= 0:
            raise InputError(f"--fps: expected a positive frame rate, got {fps!r}")
        n = int(np.floor(self.duration_s * fps + 1e-9)) + 1
        if n > MAX_FRAMES:
            raise InputError(f"--fps: {n} frames over {self.duration_s:g} s; at most {MAX_FRAMES}")
        return self.t_s[0] + np.arange(n) / fps

    def to_json(self) -> dict:
        """The knots as JSON-ready lists (the study's manifest: a changed file is a changed study)."""
        return {"mount": self.mount, "fields": list(self.fields), "t_s": self.t_s.tolist(),
                "values": self.values.tolist(), "source": self.source}

    # ------------------------------------------------------------------ constructors
    @classmethod
    def straight(cls, from_m: float, to_m: float, duration_s: float, *, lateral_m=(0.0, 0.0),
                 attitude_deg=(0.0, 0.0, 0.0)) -> "Trajectory":
        """A straight approach along the boresight from ``from_m`` to ``to_m`` over ``duration_s``.

        ``lateral_m`` (x right, y up, m) and ``attitude_deg`` (the paper's roll, pitch, yaw) are
        the target's offsets at the start; they are nulled linearly along the way, as a docking
        approach lines up on the docking axis.
        """
        for name, v in (("--from", from_m), ("--to", to_m), ("--duration", duration_s)):
            if not np.isfinite(float(v)) or float(v) <= 0:
                raise InputError(f"{name}: expected a positive number, got {v!r}")
        lat = [float(x) for x in lateral_m]
        att = [float(x) for x in attitude_deg]
        if len(lat) != 2 or len(att) != 3 or not np.all(np.isfinite(lat + att)):
            raise InputError(f"lateral_m/attitude_deg: expected (x, y) m and (roll, pitch, yaw) deg, got {lateral_m!r}, "
                             f"{attitude_deg!r}")
        start = [float(from_m), *lat, *att]
        end = [float(to_m), 0.0, 0.0, 0.0, 0.0, 0.0]
        src = (f"straight approach {float(from_m):g} -> {float(to_m):g} m in {float(duration_s):g} s, lateral {lat} m, "
               f"attitude {att} deg at the start, nulled linearly")
        return cls(np.array([0.0, float(duration_s)]), np.array([start, end]), "target", src)

    @classmethod
    def load(cls, path) -> "Trajectory":
        """Read a trajectory CSV: ``t_s`` and either the paper's state (:data:`STATE_COLUMNS`) or
        the test stand's chain (:data:`STAND_COLUMNS`) per row. Every problem is an
        :class:`~svgs.errors.InputError` naming the file, the row and the column."""
        p = Path(path)
        where = f"--trajectory {str(path)!r}"
        if not p.is_file():
            raise InputError(f"{where}: no such file")
        try:
            text = p.read_text(encoding="utf-8-sig")  # a byte-order mark (spreadsheets write one) is not a column
        except (OSError, UnicodeDecodeError) as exc:
            raise InputError(f"{where}: cannot read it as text ({exc})") from None
        kept = [(n, line) for n, line in enumerate(text.splitlines(), start=1)
                if line.strip() and not line.lstrip().startswith("#")]
        line_no = [n for n, _ in kept]  # the file's own line numbers, for the messages
        rows = list(csv.reader(line for _, line in kept))
        if not rows:
            raise InputError(f"{where}: empty file; expected a header with t_s and "
                             f"{', '.join(STATE_COLUMNS)} (paper state) or {', '.join(STAND_COLUMNS)} (test stand)")
        header = [h.strip() for h in rows[0]]
        if "t_s" not in header:
            raise InputError(f"{where}: no t_s column in the header {header}")
        if set(STATE_COLUMNS) <= set(header):
            mount, cols = "target", STATE_COLUMNS
        elif set(STAND_COLUMNS) <= set(header):
            mount, cols = "stand", STAND_COLUMNS
        else:
            raise InputError(f"{where}: the header {header} has neither the paper state ({', '.join(STATE_COLUMNS)}) "
                             f"nor the test stand's chain ({', '.join(STAND_COLUMNS)})")
        idx = [header.index(c) for c in ("t_s", *cols)]
        data = []
        for i, row in enumerate(rows[1:], start=1):
            n = line_no[i]
            if len(row) != len(header):
                raise InputError(f"{where}: line {n} has {len(row)} fields, the header {len(header)}")
            vals = []
            for j, c in zip(idx, ("t_s", *cols)):
                try:
                    x = float(row[j])
                except ValueError:
                    raise InputError(f"{where}: line {n}, column {c}: {row[j]!r} is not a number") from None
                if not np.isfinite(x):
                    raise InputError(f"{where}: line {n}, column {c}: {row[j]!r} is not finite")
                vals.append(x)
            data.append(vals)
        if len(data) < 2:
            raise InputError(f"{where}: expected at least 2 rows of poses, got {len(data)}")
        a = np.array(data)
        rows_line = line_no[1:]
        dt = np.diff(a[:, 0])
        if np.any(dt <= 0):
            k = int(np.argmax(dt <= 0))
            raise InputError(f"{where}: t_s must increase strictly; line {rows_line[k + 1]} (t_s = {a[k + 1, 0]:g}) "
                             f"follows t_s = {a[k, 0]:g}")
        # angles: the shorter way round between rows (yaw 179 -> -179 is a 2 deg turn, not 358)
        ang = [1 + cols.index(c) for c in ("roll_deg", "pitch_deg", "yaw_deg")]
        a[:, ang] = np.degrees(np.unwrap(np.radians(a[:, ang]), axis=0))
        if mount == "stand":
            values = a[:, 1:]
        else:  # paper state -> the target's position in the camera frame (Scenario's fields)
            R, t = state_to_pose(np.column_stack([a[:, 1:4], np.deg2rad(a[:, 4:7])]))
            if np.any(t[:, 2] <= 0):
                k = int(np.argmax(t[:, 2] <= 0))
                raise InputError(f"{where}: line {rows_line[k]}: the target is behind the camera (range along the "
                                 f"boresight {t[k, 2]:.3g} m)")
            xyz = t @ D_CAM_PHOTO  # D t: (target_x, target_y, -range) in the paper's camera frame
            values = np.column_stack([t[:, 2], xyz[:, 0], xyz[:, 1], a[:, 4:7]])
        return cls(a[:, 0], values, mount, str(path))


def check_visible(trajectory: Trajectory, times_s, camera, pattern, base: Scenario | None = None) -> None:
    """Refuse a trajectory on which the camera cannot see the whole pattern at some frame.

    Parameters
    ----------
    trajectory : Trajectory
    times_s : array_like, shape (n,)
        The frame times, s.
    camera : svgs.Camera or str
        The camera the frames are made through.
    pattern : svgs.Pattern or str
    base : Scenario, optional
        The scenario the trajectory's poses are set in.

    Raises
    ------
    InputError
        Naming the first frame time whose pose puts a target behind the camera or outside the
        image (with :data:`VISIBILITY_MARGIN_PX`), shows the camera the back of the target (its
        reflectors face the target's +z), or is a stand setting the stand cannot take.
    """
    cam = Camera.load(camera)
    pat = Pattern.load(pattern)
    base = base or Scenario(camera=cam, pattern=pat)
    for t in np.asarray(times_s, float):
        try:
            sc = trajectory.scenario(t, base)
            R, tv = sc.pose()
        except InputError as exc:
            raise InputError(f"trajectory ({trajectory.source}) at t = {t:g} s: {exc}") from None
        p = pat.points_m @ R.T + tv
        facing = float(-(R[:, 2] @ tv) / np.linalg.norm(tv))  # cos(target +z, direction to the camera)
        if facing <= 0:
            raise InputError(f"trajectory ({trajectory.source}) at t = {t:g} s: the camera sees the back of the target "
                             f"({np.degrees(np.arccos(np.clip(facing, -1, 1))):.0f} deg from its face normal); its "
                             "reflectors return no light there")
        if np.any(p[:, 2] <= 0.05):
            raise InputError(f"trajectory ({trajectory.source}) at t = {t:g} s: a target is behind (or at) the lens")
        uv = cam.project(p)
        m = VISIBILITY_MARGIN_PX
        bad = ~((uv[:, 0] >= m) & (uv[:, 0] <= cam.width - 1 - m) & (uv[:, 1] >= m) & (uv[:, 1] <= cam.height - 1 - m))
        if np.any(bad):
            ids = [int(i) for i in np.asarray(pat.ids)[bad]]
            raise InputError(f"trajectory ({trajectory.source}) at t = {t:g} s: target(s) {ids} fall outside the "
                             f"{cam.width} x {cam.height} image (at {np.round(uv[bad], 1).tolist()} px); the camera "
                             "cannot see the whole pattern there")


# ----------------------------------------------------------------------------- the sensor
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
        Why there is no solution (:class:`svgs.result.SolveResult` reasons).
    truth : dict
        The paper's state at ``t_s`` (:data:`svgs.frames.STATE_KEYS`, m and deg).
    estimate : dict or None
        The solved state.
    error : dict or None
        ``estimate - truth`` per component (angles wrapped to +-180 deg).
    crlb_std : dict or None
        1-sigma Cramer-Rao bound per component for this frame (:func:`sim.crlb.frame_crlb`).
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
        The solution's consistency (:func:`svgs.app.consistency`; also for an ``inconsistent``
        frame, whose ``reason`` says so).
    image : ndarray or None
        The delivered image (when the sensor keeps images).
    solution : object
        :class:`svgs.solver.Solution` or the failure result (for overlays).
    blobs_px : ndarray, shape (M, 2), or None
        Every blob the detector found (when the sensor keeps images).
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
                    "next_iso": self.next_iso})
        for k in TIMING_KEYS:
            out[f"{k}_s"] = self.timings_s.get(k)
        return out


TIMING_KEYS = ("render", "optics", "expose", "solve", "crlb")
#: Columns of ``measurements.csv`` (one row per frame); ``solve_s`` is the sensor's processing
#: time (detect, identify, solve) on this machine.
MEASUREMENT_COLUMNS = (("frame", "t_s", "range_m") + tuple(f"true_{k}" for k in STATE_KEYS)
                       + tuple(f"est_{k}" for k in STATE_KEYS) + tuple(f"err_{k}" for k in STATE_KEYS)
                       + tuple(f"crlb_{k}" for k in STATE_KEYS)
                       + ("ok", "reason", "n_blobs", "residual_rms_px", "p_value", "exposure_s", "iso", "metered_level",
                          "next_exposure_s", "next_iso") + tuple(f"{k}_s" for k in TIMING_KEYS))


def state_error(estimate: dict, truth: dict) -> dict:
    """``estimate - truth`` per state component, angles wrapped to [-180, 180) deg."""
    out = {}
    for k in STATE_KEYS:
        d = float(estimate[k]) - float(truth[k])
        if k.endswith("_deg"):
            d = (d + 180.0) % 360.0 - 180.0
        out[k] = d
    return out


def scenario_from_pose(R_cam_target, t_cam_target_m, base: Scenario) -> Scenario:
    """The target-mounted :class:`~sim.closed_loop.Scenario` whose pose is ``(R, t)``."""
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
        A phone profile (name, path, or a camera such as :func:`camera.phone.preview.binned_camera`).
    pattern : str
        Target pattern.
    seed : int
        Seeds every frame's render and noise (frame ``k`` draws from ``(seed, k)``).
    motion : bool
        Model motion blur and the rolling shutter (see the module docstring).
    crlb : bool
        Compute each solved frame's Cramer-Rao bound (:data:`CRLB_DRAWS`; 0.3-0.5 s a frame at
        full resolution).
    frame_rate_hz : float, optional
        The rate at which the sensor takes its frames. The phone must deliver a frame per period:
        its auto-exposure's longest exposure is capped at the period, and a manual exposure or a
        rolling-shutter readout longer than the period is refused. The auto-exposure then steps
        ``period / max(1/STREAM_FPS, exposure)`` times between frames. None: free-running, the
        steps counted from the times of consecutive calls.
    keep_images : bool
        Keep the delivered image, the blobs and the solution in each :class:`Measurement`.
    overlap_render : bool
        Render the next frame of a trajectory (``next_pose``, :meth:`along`) in a background
        thread while the phone model works on this one. Off by default: on the two-core machine
        it bought nothing (Mitsuba's threads and the camera model's then share the two cores;
        ``benchmarks/bench_approach.py``); with more cores it may. The numbers do not change.
    threshold : None, float or str
        The detector's threshold (None: the app's for the camera, :func:`svgs.pipeline.camera_threshold`).
    base : Scenario, optional
        The lab around the target (backdrop, ambient light) and render quality; default the
        lab of :mod:`sim.lab`. Its camera fields (lens offsets, overrides, a fixed focus) are
        refused: give the camera itself.

    Examples
    --------
    >>> sensor = ApproachSensor("galaxy-nexus", seed=1)            # doctest: +SKIP
    >>> m = sensor.measure(0.0, R_cam_target, t_cam_target_m)      # doctest: +SKIP
    >>> for m in sensor.stream((t, R, t_vec) for ...): ...          # doctest: +SKIP
    """

    def __init__(self, camera="galaxy-nexus", pattern="svgs-3u", *, seed: int = 0, motion: bool = True,
                 crlb: bool = True, keep_images: bool = False, threshold=None, base: Scenario | None = None,
                 frame_rate_hz: float | None = None, overlap_render: bool = False):
        import dataclasses

        from camera.phone import PhoneCamera, PhoneParams

        self.camera = Camera.load(camera)
        for t in ("optics", "flash"):
            self.camera.table(t)
        self.pattern = Pattern.load(pattern)
        base = base or Scenario()
        if base.camera_overrides or any(base.lens_pp_offset_px) or base.lens_k1 or base.focus_distance_m is not None:
            raise InputError("base: camera_overrides, lens_pp_offset_px, lens_k1 and focus_distance_m belong to the "
                             "camera; give ApproachSensor the camera itself (the lens refocuses on the target)")
        self.base = base.replace(camera=self.camera, pattern=self.pattern)  # the scenario carries the objects
        params = PhoneParams.from_camera(self.camera)
        self.frame_rate_hz = None
        if frame_rate_hz is not None:
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
            self.frame_rate_hz = f
        if int(seed) < 0:
            raise InputError(f"seed: expected a non-negative integer, got {seed!r}")
        self.seed = int(seed)
        self.motion = bool(motion)
        self.crlb = bool(crlb)
        self.keep_images = bool(keep_images)
        self.overlap_render = bool(overlap_render)
        self.threshold = threshold
        self.phone = PhoneCamera(self.camera, params=params)
        self._renderer = None
        self._meter = None  # (t_s, exposure_s, iso, meter) of the last frame, free-running mode
        self._lab_factor = None
        self.frame_index = 0
        self._settings = None  # (exposure_s, iso) for the next frame; None: converge on it
        self._last_pose = None
        self._pool = None  # the background render thread (next_pose)
        self._pending = None  # ((frame, R bytes, t bytes), future) of the render in flight

    # ------------------------------------------------------------------ state
    @property
    def exposure_settings(self):
        """(exposure_s, iso) the next frame will use, or None before the first frame of an
        auto-exposing phone (it then converges on that frame's scene)."""
        p = self.phone.params.exposure
        if p.mode == "manual":
            return (p.exposure_s, p.iso)
        return self._settings

    def restore(self, frame_index: int, next_exposure_s: float | None, next_iso: float | None) -> None:
        """Continue a stream at ``frame_index`` with the auto-exposure's stored settings for it
        (a resumed run; ``next_exposure_s``, ``next_iso`` of the last stored frame, which with
        ``frame_rate_hz`` already include the steps between frames)."""
        self.frame_index = int(frame_index)
        self._settings = None if next_exposure_s is None else (float(next_exposure_s), float(next_iso))
        self._meter = None

    def _ae_steps(self, dt_s: float, exposure_s: float) -> int:
        """Auto-exposure steps the phone's stream makes in ``dt_s`` at ``exposure_s``."""
        period = max(1.0 / STREAM_FPS, float(exposure_s))
        return int(np.clip(np.floor(float(dt_s) / period + 1e-9), 1, MAX_AE_STEPS))

    def _advance_exposure(self, meter, exposure_s: float, iso: float, steps: int) -> tuple[float, float]:
        from camera.phone.isp import stream_exposure

        p = self.phone.params
        return stream_exposure(exposure_s, iso, meter.level, p.sensor, p.exposure, steps)

    def _frame_seeds(self, k: int) -> tuple[int, int, int]:
        s = np.random.SeedSequence([self.seed, int(k)]).generate_state(3, dtype=np.uint32)
        return int(s[0]), int(s[1]), int(s[2])

    def renderer(self):
        if self._renderer is None:
            from render.api import Renderer

            kw = {k: int(getattr(self.base, k)) for k in ("spp", "roi_spp") if getattr(self.base, k) is not None}
            self._renderer = Renderer(self.camera, self.pattern, scene_options={"focus_distance_m": 1.0}, **kw)
        return self._renderer

    def _lab(self, scenario: Scenario) -> tuple[np.ndarray, dict]:
        if self._lab_factor is None:
            self._lab_factor = lab_photon_factor(self.camera)
        return lab_flux(self.camera, scenario, factor=self._lab_factor)

    def targets_px(self, R, t) -> np.ndarray:
        """The pattern's targets projected at a pose, (N, 2) px."""
        return self.camera.project(self.pattern.points_m @ np.asarray(R, float).T + np.asarray(t, float))

    def _velocity_since_last(self, t_s, R, t) -> np.ndarray | None:
        """Image velocity of each target (N, 2) px/s since the previous frame (None on the first)."""
        if self._last_pose is None:
            return None
        t1, R1, tv1 = self._last_pose
        dt = float(t_s) - t1
        if dt <= 0:
            return None
        return (self.targets_px(R, t) - self.targets_px(R1, tv1)) / dt

    # ------------------------------------------------------------------ measuring
    def measure(self, t_s: float, R_cam_target=None, t_cam_target_m=None, *, image_velocity_px_s=None,
                scenario: Scenario | None = None, next_pose=None) -> Measurement:
        """One frame at time ``t_s`` with the target at ``(R_cam_target, t_cam_target_m)``.

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
        from svgs.frames import check_pose

        if scenario is not None:
            sc = scenario.replace(camera=self.base.camera, pattern=self.base.pattern)
            R, t = sc.pose()
        else:
            if R_cam_target is None or t_cam_target_m is None:
                raise InputError("measure: give the pose (R_cam_target, t_cam_target_m) or a scenario")
            R, t = check_pose(R_cam_target, t_cam_target_m)
            sc = scenario_from_pose(R, t, self.base)
        t_s = float(check_finite(t_s, "t_s"))
        k = self.frame_index
        auto = self.phone.params.exposure.mode == "auto"
        if auto and self._meter is not None:  # free-running: the steps the stream made since the last call
            t_prev, e_prev, iso_prev, meter = self._meter
            self._settings = self._advance_exposure(meter, e_prev, iso_prev,
                                                    self._ae_steps(max(t_s - t_prev, 0.0), e_prev))
            self._meter = None
        uv_true = self.targets_px(R, t)
        p_cam = self.pattern.points_m @ R.T + t
        if np.any(p_cam[:, 2] <= 0) or not np.any(self.camera.in_image(uv_true)):
            self._drop_render()
            return self._out_of_view(k, t_s, R, t)
        next_frame = None
        if next_pose is not None and self.overlap_render:
            Rn, tn = check_pose(*next_pose)
            pn = self.pattern.points_m @ Rn.T + tn
            if np.all(pn[:, 2] > 0) and np.any(self.camera.in_image(self.targets_px(Rn, tn))):
                next_frame = (Rn, tn)
        if image_velocity_px_s is not None:
            image_velocity_px_s = np.asarray(image_velocity_px_s, float)
            if image_velocity_px_s.shape != (self.pattern.n, 2) or not np.all(np.isfinite(image_velocity_px_s)):
                raise InputError(f"image_velocity_px_s: expected finite (du/dt, dv/dt) px/s of each of the "
                                 f"{self.pattern.n} targets, shape ({self.pattern.n}, 2), got shape "
                                 f"{image_velocity_px_s.shape}")
        render_seed_k, noise_seed, motion_seed = self._frame_seeds(k)
        timings = {}
        t0 = time.perf_counter()
        res = self._take_render(k, R, t)
        if next_frame is not None:  # the next frame renders while this one goes through the phone
            self._start_render(k + 1, *next_frame)
        lab, info = self._lab(sc)
        truth = dict(res.truth)
        truth.update({"lab": info, "scenario": sc.to_json(), "focus_distance_m": float(np.linalg.norm(t)), "t_s": float(t_s)})
        frame = Frame(sc, res.flux + lab, truth, 0.0, lab, target_diffuse=res.flux_diffuse, points=res.points,
                      _phone={(True, None, None): self.phone},
                      lab_unit=(info["radiance_w_m2_sr"], self._lab_factor))
        timings["render"] = time.perf_counter() - t0

        t0 = time.perf_counter()
        settings = self.exposure_settings
        exposer = None
        if settings is None:  # the stream's first frame: the phone has settled on this scene
            exposer = frame.exposer()
            e_s, iso, _ = exposer.auto_exposure()
            settings = (e_s, iso)
        vel = image_velocity_px_s if image_velocity_px_s is not None else self._velocity_since_last(t_s, R, t)
        if self.motion and vel is not None and frame.points is not None and len(frame.points):
            pts = frame.points
            near = np.argmin((pts.u_px[:, None] - uv_true[None, :, 0]) ** 2
                             + (pts.v_px[:, None] - uv_true[None, :, 1]) ** 2, axis=1)
            frame.points = pts.moved(np.asarray(vel, float)[near], settings[0], self.phone.params.sensor.readout_time_s,
                                     self.camera.height, np.random.default_rng(motion_seed))
            exposer = frame.exposer()
        elif exposer is None:
            exposer = frame.exposer()
        timings["optics"] = time.perf_counter() - t0

        t0 = time.perf_counter()
        ex = exposer.expose(seed=noise_seed, exposure_s=settings[0], iso=settings[1])
        timings["expose"] = time.perf_counter() - t0
        from svgs.detect import detect_blobs
        from svgs.pipeline import camera_threshold

        t0 = time.perf_counter()
        blobs = detect_blobs(ex.image, threshold=camera_threshold(ex.image, self.camera, self.threshold))
        t_detect = time.perf_counter() - t0
        row = solve_exposure(frame, ex, threshold=self.threshold, solver_camera_profile=self.camera, truth="actual",
                             blobs=blobs)
        timings["solve"] = t_detect + row["solve_s"]
        level = exposer.metered_level(*settings)
        if auto:  # the stream's loop runs on: to the next frame with a frame rate, one step otherwise
            steps = self._ae_steps(1.0 / self.frame_rate_hz, settings[0]) if self.frame_rate_hz else 1
            self._settings = self._advance_exposure(exposer.meter, settings[0], settings[1], steps)
            self._meter = None if self.frame_rate_hz else (t_s, settings[0], settings[1], exposer.meter)
        nxt = self.exposure_settings
        crlb = None
        t0 = time.perf_counter()
        if self.crlb and row["ok"]:
            from sim.crlb import frame_crlb

            c = frame_crlb(frame, exposer, row, draws=CRLB_DRAWS)
            crlb = None if c is None else c.get("crlb_std")
        timings["crlb"] = time.perf_counter() - t0 if self.crlb else None

        truth_state = state_dict(pose_to_state(R, t))
        est = row["state"]
        # frame.flux keeps the unmoved render; the image was made from frame.points (moved)
        sol = row["_solution"]
        m = Measurement(
            frame=k, t_s=float(t_s), ok=bool(row["ok"]), reason=row["reason"], truth=truth_state, estimate=est,
            error=state_error(est, truth_state) if est else None, crlb_std=crlb, range_m=float(t[2]),
            exposure_s=float(settings[0]), iso=float(settings[1]), metered_level=float(level),
            next_exposure_s=float(nxt[0]), next_iso=float(nxt[1]), timings_s=timings, n_blobs=row["n_blobs"],
            residual_rms_px=row["residual_rms_px"], p_value=row.get("p_value"),
            image=ex.image if self.keep_images else None, solution=sol if self.keep_images else None,
            blobs_px=blobs.centroid_px if self.keep_images else None,
        )
        self.frame_index = k + 1
        self._last_pose = (float(t_s), R, t)
        return m

    # ------------------------------------------------------------------ renders, overlapped
    def _render_now(self, k: int, R, t):
        r = self.renderer()
        r.set_focus_distance(float(np.linalg.norm(t)))
        return r.render(R, t, seed=self._frame_seeds(k)[0])

    def _start_render(self, k: int, R, t) -> None:
        """Render frame ``k`` at ``(R, t)`` in the background thread (one at a time)."""
        from concurrent.futures import ThreadPoolExecutor

        self._drop_render()
        if self._pool is None:
            self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="svgs-render")
        key = (int(k), np.asarray(R, float).tobytes(), np.asarray(t, float).tobytes())
        self._pending = (key, self._pool.submit(self._render_now, k, R, t))

    def _take_render(self, k: int, R, t):
        """Frame ``k``'s render: the background one if it is that frame's, else rendered now."""
        if self._pending is not None:
            key, fut = self._pending
            self._pending = None
            res = fut.result()  # wait for it (and the renderer) in any case; errors surface here
            if key == (int(k), np.asarray(R, float).tobytes(), np.asarray(t, float).tobytes()):
                return res
        return self._render_now(k, R, t)

    def _drop_render(self) -> None:
        if self._pending is not None:
            _, fut = self._pending
            self._pending = None
            fut.result()

    def close(self) -> None:
        """Stop the background render thread (a later frame starts it again)."""
        self._drop_render()
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None

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
