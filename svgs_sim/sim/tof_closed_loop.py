"""The ToF closed loop: scenario -> rendered phasors -> AMCW frames -> ToF pipeline -> pose -> errors.

The ToF counterpart of :mod:`svgs_sim.sim.closed_loop`, and the one frame loop of ``svgs tof
render-and-solve`` (:mod:`svgs_sim.cli.tof_render`), the stability runs (:mod:`svgs_sim.sim.tof_stability`,
``svgs tof stability``) and the ToF study (:mod:`svgs_sim.sim.tof_trial`, :mod:`svgs_sim.studies.tof_study`)::

    TofScenario --render--> TofRender --expose--> svgs_sim.camera.amcw.TofFrame --solve--> TofFrameResult

- :class:`TofScenario`: camera, marker target, pose (range along the boresight, lateral
  offsets, the paper's attitude), the renderer's options and the sensor's overrides (each
  optional field None = the profile's or the renderer's default).
- :func:`render`: Mitsuba renders the target once (:class:`svgs_sim.render.tof.camera.TofRenderer`);
  the :class:`TofRender` holds the render, the loaded profiles, the truth and the sensor.
- :func:`expose`: the sensor's noisy frames from one render (one seeded stream, frame ``k``
  the ``k``-th draw; :data:`NOISE_STREAM`).
- :func:`solve_frames`: the frames in sequence through one :class:`svgs_sim.tof.TofPipeline` (its
  temporal median and persistence window carry state from frame to frame); each result
  carries its errors, stated only through :mod:`svgs_sim.sim.metrics`.

Seeds: the render's Monte Carlo seed is :attr:`TofScenario.seed`; the frames' noise is
``numpy.random.default_rng([seed, NOISE_STREAM])`` with the same seed, so every path that
runs a scenario with a seed draws the same frames.
"""

from __future__ import annotations

import functools
import json
import time
from dataclasses import dataclass, replace

import numpy as np

from svgs_sim.base.errors import InputError, SimulationFailure, check_finite
from svgs_sim.base.profile_schema import SHEETINGS, TOF_MATERIALS
from svgs_sim.camera.amcw import TofSensor
from svgs_sim.sim.metrics import no_pose_errors, pose_errors, state_error
from svgs_sim.sim.target_pose import TargetPose
from svgs_sim.svgs.frames import pose_from_scenario, pose_to_state

#: Second entry of the noise stream's seed ``[seed, NOISE_STREAM]`` (the stability runs' since
#: issue 23, kept so the committed ToF report does not move).
NOISE_STREAM = 7
#: The fields of :class:`TofScene` (the renderer's scene options a scenario sets).
SCENE_KEYS = ("marker_material", "sheeting", "distractors")


@dataclass(frozen=True)
class TofScene:
    """What the ToF scene holds around the target besides the pattern's own values: the scene
    part of :class:`TofScenario` (the SVGS scenario's is :class:`svgs_sim.sim.scene.Scene`).

    Attributes
    ----------
    marker_material : str or None
        The markers' surface (:data:`svgs_sim.base.profile_schema.TOF_MATERIALS`); None: the
        pattern's ``[marker] material``.
    sheeting : str or None
        The retroreflective sheeting table (:data:`svgs_sim.base.profile_schema.SHEETINGS`); None:
        the pattern's ``[marker] sheeting``.
    distractors : tuple of dict
        Extra diffuse objects in the target frame (:data:`svgs_sim.render.tof.scene.DISTRACTOR_KINDS`).
    """

    marker_material: str | None = None
    sheeting: str | None = None
    distractors: tuple = ()

    def __post_init__(self):
        for k, choices in (("marker_material", TOF_MATERIALS), ("sheeting", SHEETINGS)):
            v = getattr(self, k)
            if v is not None and v not in choices:
                raise InputError(f"scene.{k}: expected one of {', '.join(choices)} (or None: the pattern's), got {v!r}")
        if not isinstance(self.distractors, (list, tuple)):
            raise InputError(f"scene.distractors: expected a list of objects, got {self.distractors!r}")
        object.__setattr__(self, "distractors", tuple(self.distractors))

    @classmethod
    def from_dict(cls, options) -> "TofScene":
        """The scene of the renderer's option names (a dict or ``(name, value)`` pairs; the
        results store's ``scene`` column read back)."""
        items = dict(options.items() if isinstance(options, dict) else options)
        unknown = sorted(set(items) - set(SCENE_KEYS))
        if unknown:
            raise InputError(f"scene: unknown option(s) {', '.join(map(repr, unknown))}; known: {', '.join(SCENE_KEYS)}")
        return cls(**items)

    def to_dict(self) -> dict:
        """The renderer's ``scene_options`` (only what the scene sets: the pattern's values
        elsewhere), sorted by name."""
        out = {"distractors": list(self.distractors)} if self.distractors else {}
        if self.marker_material is not None:
            out["marker_material"] = self.marker_material
        if self.sheeting is not None:
            out["sheeting"] = self.sheeting
        return dict(sorted(out.items()))


def _optional(value, name: str, kind=float, positive: bool = True, allow_zero: bool = False):
    if value is None:
        return None
    try:
        v = kind(value)
    except (TypeError, ValueError):
        raise InputError(f"{name}: expected a number or None, got {value!r}") from None
    if kind is float and not np.isfinite(v):
        raise InputError(f"{name}: expected a finite number or None, got {value!r}")
    if positive and (v < 0 or (v == 0 and not allow_zero)):
        raise InputError(f"{name}: expected a {'non-negative' if allow_zero else 'positive'} number or None, "
                         f"got {value!r}")
    return v


@dataclass(frozen=True)
class TofScenario(TargetPose):
    """One ToF situation: what is rendered and how the sensor sees it.

    Attributes
    ----------
    camera : str
        ToF camera profile name or path (needs the render tables, :func:`svgs_sim.tof.load_camera`).
    pattern : str
        Marker target name or path (:func:`svgs_sim.tof.load_target`).
    range_m : float
        Along the boresight to the target frame's origin (``tof-8``: the centroid of the marker
        faces, the plate 125 mm behind it), m.
    target_x_m, target_y_m, roll_deg, pitch_deg, yaw_deg : float
        The target's pose besides its range (keyword-only, declared once in
        :class:`svgs_sim.sim.target_pose.TargetPose`): lateral offsets, m, and the paper's attitude, deg.
    seed : int
        The render's Monte Carlo seed, and the noise stream's (``[seed, NOISE_STREAM]``).
    spp, rim_spp_factor : int or None
        Samples per pixel and the factor on them at the marker rims (None: the renderer's).
    max_bounces : int
        1 direct returns, 2-4 with multipath.
    pinhole : bool
        No defocus blur.
    scene : TofScene
        The scene around the target (marker material, sheeting, distractors; default: the
        pattern's). A dict of its fields is taken too.
    ambient_lux, integration_time_s, modulation_frequency_hz : float or None
        Sensor overrides (None: the profile's; integration time None: automatic).
    """

    camera: str = "tof-epc660"
    pattern: str = "tof-8"
    range_m: float = 1.0
    seed: int = 0
    spp: int | None = None
    rim_spp_factor: int | None = None
    max_bounces: int = 1
    pinhole: bool = False
    scene: TofScene = TofScene()
    ambient_lux: float | None = None
    integration_time_s: float | None = None
    modulation_frequency_hz: float | None = None

    def __post_init__(self):
        if isinstance(self.scene, dict):  # the renderer's option names (or a TofScene's fields)
            object.__setattr__(self, "scene", TofScene.from_dict(self.scene))
        if not isinstance(self.scene, TofScene):
            raise InputError(f"scene: expected a TofScene or a dict of its fields, got {self.scene!r}")
        for k in ("range_m", "target_x_m", "target_y_m", "roll_deg", "pitch_deg", "yaw_deg"):
            check_finite(getattr(self, k), k)
        if self.range_m <= 0:
            raise InputError(f"range_m: expected a positive distance in metres, got {self.range_m!r}")
        if isinstance(self.seed, bool) or int(self.seed) != self.seed or self.seed < 0:
            raise InputError(f"seed: expected a non-negative integer, got {self.seed!r}")
        if not 1 <= int(self.max_bounces) <= 4:
            raise InputError(f"max_bounces: expected 1..4, got {self.max_bounces!r}")
        for k in ("spp", "rim_spp_factor"):
            _optional(getattr(self, k), k, int)
        _optional(self.ambient_lux, "ambient_lux", allow_zero=True)
        _optional(self.integration_time_s, "integration_time_s")
        _optional(self.modulation_frequency_hz, "modulation_frequency_hz")

    def pose(self):
        """(R_cam_target (3, 3), t_cam_target_m (3,)) of this scenario (:func:`svgs_sim.svgs.frames.pose_from_scenario`)."""
        return pose_from_scenario(self.range_m, self.target_x_m, self.target_y_m, self.roll_deg, self.pitch_deg,
                                  self.yaw_deg)

    def scene_dict(self) -> dict:
        """:attr:`scene` as the renderer's ``scene_options`` dict."""
        return self.scene.to_dict()

    def render_key(self) -> tuple:
        """What decides the render (hashable): equal keys, equal renders."""
        return (self.camera, self.pattern, float(self.range_m), float(self.target_x_m), float(self.target_y_m),
                float(self.roll_deg), float(self.pitch_deg), float(self.yaw_deg), int(self.seed), self.spp,
                self.rim_spp_factor, int(self.max_bounces), bool(self.pinhole),
                json.dumps(self.scene_dict(), sort_keys=True), self.modulation_frequency_hz)

    @classmethod
    def from_pose_mm(cls, t_cam_target_mm, angles_deg, **kw) -> "TofScenario":
        """The scenario whose pose has the translation ``t_cam_target_mm`` (OpenCV camera frame,
        mm; shape (3,)) and the paper's attitude ``angles_deg`` (roll, pitch, yaw)."""
        t = np.asarray(t_cam_target_mm, float) * 1e-3
        return cls(range_m=float(t[2]), target_x_m=float(t[0]), target_y_m=float(-t[1]),
                   roll_deg=float(angles_deg[0]), pitch_deg=float(angles_deg[1]), yaw_deg=float(angles_deg[2]), **kw)


@functools.lru_cache(maxsize=8)
def load_scene(camera: str, pattern: str):
    """The ToF camera (with its render tables) and the marker target, loaded once per process.

    Returns
    -------
    (svgs_sim.base.profiles.Camera, tof.MarkerTarget)
    """
    from svgs_sim.tof import load_camera, load_target

    return load_camera(camera, render=True), load_target(pattern)


def make_sensor(scenario: TofScenario, camera=None):
    """The scenario's :class:`svgs_sim.camera.amcw.TofSensor` (the profile's with its overrides)."""

    camera = camera if camera is not None else load_scene(scenario.camera, scenario.pattern)[0]
    return TofSensor.from_camera(camera, ambient_lux=scenario.ambient_lux,
                                 modulation_frequency_hz=scenario.modulation_frequency_hz,
                                 integration_time_s=scenario.integration_time_s)


def check_in_view(scenario: TofScenario) -> dict:
    """:func:`svgs_sim.render.tof.camera.check_target_in_view` at the scenario's pose (InputError when
    the target is behind the lens or outside the field of view); checked before any render."""
    from svgs_sim.render.tof.camera import check_target_in_view

    camera, target = load_scene(scenario.camera, scenario.pattern)
    return check_target_in_view(camera, target, *scenario.pose())


@dataclass
class TofRender:
    """One render of a :class:`TofScenario` (render once, expose many).

    Attributes
    ----------
    scenario : TofScenario
    camera, target : the loaded profiles
    renderer : svgs_sim.render.tof.camera.TofRenderer
    rendered : svgs_sim.camera.amcw.RenderedTof
    sensor : svgs_sim.camera.amcw.TofSensor
    R_cam_target : ndarray, shape (3, 3)
    t_cam_target_m : ndarray, shape (3,)
    render_s : float
        Wall time of the render, s.
    """

    scenario: TofScenario
    camera: object
    target: object
    renderer: object
    rendered: object
    sensor: object
    R_cam_target: np.ndarray
    t_cam_target_m: np.ndarray
    render_s: float

    @property
    def truth_state(self) -> np.ndarray:
        """The paper state of the rendered pose, shape (6,) (m, rad)."""
        return pose_to_state(self.R_cam_target, self.t_cam_target_m)

    def with_sensor(self, **overrides) -> "TofRender":
        """The same render seen by the sensor with other settings (``ambient_lux``,
        ``integration_time_s``): nothing is rendered again."""

        if "modulation_frequency_hz" in overrides:
            raise InputError("modulation_frequency_hz: changes the render; make a new scenario")
        sc = replace(self.scenario, **overrides)
        return replace(self, scenario=sc, sensor=self.sensor.replace(**{k: v for k, v in overrides.items()}))


def render(scenario: TofScenario) -> TofRender:
    """Render the scenario once (Mitsuba; the renderer's defaults where the scenario has None)."""
    from svgs_sim.render.tof.camera import TofRenderer

    camera, target = load_scene(scenario.camera, scenario.pattern)
    sensor = make_sensor(scenario, camera)
    R, t = scenario.pose()
    t0 = time.perf_counter()
    renderer = TofRenderer(camera, target, spp=scenario.spp, rim_spp_factor=scenario.rim_spp_factor,
                           max_bounces=int(scenario.max_bounces), scene_options=scenario.scene_dict(),
                           modulation_frequency_hz=sensor.modulation_frequency_hz, pinhole=bool(scenario.pinhole))
    rendered = renderer.render(R, t, seed=int(scenario.seed), modulation_frequency_hz=sensor.modulation_frequency_hz)
    return TofRender(scenario, camera, target, renderer, rendered, sensor, R, t, time.perf_counter() - t0)


def expose(tof_render: TofRender, n_frames: int, start: int = 0):
    """Noisy frames ``start .. n_frames - 1`` of the scenario's noise stream (a generator of
    :class:`svgs_sim.camera.amcw.TofFrame`); frame ``k`` is the same whatever ``start`` is."""
    sc = tof_render.scenario
    for k, fr in enumerate(tof_render.sensor.frames(tof_render.rendered, n_frames, [int(sc.seed), NOISE_STREAM])):
        if k >= start:
            yield fr


def noise_free_frame(tof_render: TofRender):
    """The noise-free frame (:meth:`svgs_sim.camera.amcw.TofSensor.frame` with ``noise=False``)."""
    return tof_render.sensor.frame(tof_render.rendered, noise=False)


def pipeline(tof_render: TofRender, overrides: dict | None = None):
    """A fresh :class:`svgs_sim.tof.TofPipeline` for the render's camera and target."""
    from svgs_sim import tof

    return tof.TofPipeline(tof_render.camera, tof_render.target, **(overrides or {}))


@dataclass
class TofFrameResult:
    """One frame through the pipeline.

    Attributes
    ----------
    frame : int
        Index in the noise stream.
    solution : tof.TofSolution or svgs Failure
        Truthy when solved.
    errors : dict
        :data:`svgs_sim.sim.metrics.POSE_ERROR_KEYS` (None when unsolved).
    state_err : ndarray, shape (6,) or None
        :func:`svgs_sim.sim.metrics.state_error` (m, deg; angles wrapped), None when unsolved.
    saturated_pixels : int
    """

    frame: int
    solution: object
    errors: dict
    state_err: np.ndarray | None
    saturated_pixels: int


def check_measurable(tof_render: TofRender, frame_index: int, tof_frame) -> None:
    """Raise :class:`svgs_sim.base.errors.SimulationFailure` when the simulated frame has no valid depth pixel.

    A frame with no valid depth is a physical failure of the simulation (every pixel saturated,
    or no return above the amplitude threshold), not bad input: ``svgs_sim.tof.pipeline`` would refuse it
    as an input image. The message gives the saturated fraction, the ambient light and the
    integration time.
    """
    d = np.asarray(tof_frame.depth_m)
    with np.errstate(invalid="ignore"):
        if np.any(np.isfinite(d) & (d > 0)):
            return
    n_sat, n = int(np.count_nonzero(tof_frame.saturated)), int(d.size)
    sensor = tof_render.sensor
    light = f"{sensor.ambient_lux:g} lux ambient, {tof_frame.integration_time_s * 1e3:.4g} ms integration"
    if n_sat:
        why = (f"{n_sat} of {n} pixels saturated ({n_sat / n:.0%}) and the rest are below the "
               f"{sensor.min_amplitude_dn:g} LSB amplitude threshold ({light})")
    else:
        why = f"no pixel's return reaches the {sensor.min_amplitude_dn:g} LSB amplitude threshold ({light})"
    raise SimulationFailure(f"simulated frame {frame_index}: no pixel has a valid depth: {why}",
                            "saturated" if n_sat else "no_signal")


def solve(tof_render: TofRender, frame_index: int, tof_frame, pipe) -> TofFrameResult:
    """One frame through ``pipe`` (stateful: call in frame order), with its errors.

    Raises
    ------
    svgs_sim.base.errors.SimulationFailure
        The simulated frame has no valid depth pixel (:func:`check_measurable`).
    """
    check_measurable(tof_render, frame_index, tof_frame)
    res = pipe.process(tof_frame.gray, tof_frame.depth_m)
    truth = tof_render.truth_state
    if res:
        errors = pose_errors(res.state, truth, R_cam_target_est=res.R_cam_target)
        err = state_error(res.state, truth)
    else:
        errors, err = no_pose_errors(), None
    return TofFrameResult(frame_index, res, errors, err, int(tof_frame.saturated.sum()))


def solve_frames(tof_render: TofRender, n_frames: int, overrides: dict | None = None, *, progress=None,
                 keep_frames: int = 0):
    """Draw ``n_frames`` noisy frames and solve them in sequence through one pipeline.

    Parameters
    ----------
    tof_render : TofRender
    n_frames : int
    overrides : dict, optional
        :class:`svgs_sim.tof.PipelineParams` overrides.
    progress : callable, optional
        Called with 1 after each frame.
    keep_frames : int
        Also return the first ``keep_frames`` :class:`svgs_sim.camera.amcw.TofFrame`.

    Returns
    -------
    results : list of TofFrameResult
    kept : list of svgs_sim.camera.amcw.TofFrame
    """
    pipe = pipeline(tof_render, overrides)
    results, kept = [], []
    for k, fr in enumerate(expose(tof_render, n_frames)):
        results.append(solve(tof_render, k, fr, pipe))
        if k < keep_frames:
            kept.append(fr)
        if progress is not None:
            progress(1)
    return results, kept


def pipeline_overrides(persistence: int = 1, max_active_pixels: int | None = None) -> dict:
    """The commands' pipeline options as :class:`svgs_sim.tof.PipelineParams` overrides: a persistence
    window of ``persistence`` frames (a marker kept when seen in half of them, rounded up) and
    the active-set cap."""
    kw = {}
    if persistence > 1:
        kw.update(persistence_window=int(persistence), persistence_min_count=max(1, (int(persistence) + 1) // 2))
    if max_active_pixels is not None:
        kw["max_active_pixels"] = int(max_active_pixels)
    return kw


__all__ = ["NOISE_STREAM", "TofScenario", "TofRender", "TofFrameResult", "load_scene", "make_sensor", "check_in_view",
           "render", "expose", "noise_free_frame", "pipeline", "solve", "solve_frames", "pipeline_overrides"]
