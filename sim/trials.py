"""Trial kinds: what one trial of a study computes, registered by name.

A trial kind is a top-level (picklable) function ``run_trial(scenario: dict, seed: int) ->
dict`` plus a description of its inputs and outputs. Studies (campaign, sensitivity, range
sweeps) only build scenarios and hand them, with per-trial seeds (:mod:`studies.seeding`),
to an executor (:mod:`studies.execution`); they never call a renderer or solver themselves.
So the render-and-solve trial plugs in with :func:`register_trial_kind` and every study runs
on it unchanged.

Render once, expose many
    A kind may declare ``render_key(scenario) -> hashable``: trials with equal keys need the
    same expensive render (same geometry, camera, pattern, flash...), differing only in what
    happens after it (noise draw, exposure, centroiding, calibration used by the solver).
    The runner packs such trials into one task and calls ``run_group(scenarios, seeds)``,
    which renders once and exposes/solves each trial. ``run_group`` must return exactly the
    rows ``run_trial`` would (a trial's numbers never depend on its companions).

The built-in kind ``geometric`` projects the pattern through the camera at the scenario's
pose, adds seeded Gaussian centroid noise, optionally gives the solver a wrong calibration
(focal length, principal point, radial distortion), solves with
:func:`svgs.solve_centroids` and records truth, estimate, errors and the Cramer-Rao bound.
Its "render" (the projection) is grouped the same way, so the mechanism is exercised today.
"""

from __future__ import annotations

import functools
import importlib
from dataclasses import dataclass, field
from typing import Callable, Hashable, Mapping

import numpy as np

from sim.metrics import ERR_KEYS, POS_ERR_NORM_M, ROT_ERR_DEG, error_columns, state_m_deg
from svgs.errors import InputError
from svgs.frames import STATE_KEYS

#: Modules that may register more trial kinds; imported when an unknown name is asked for
#: (a module that is not installed is skipped). The render-and-solve trial of the campaign,
#: the sensitivity study, the range sweep and the exposure study registers itself from
#: ``sim.render_trial``. Studies run the trials with :func:`studies.execution.run_task`.
KIND_MODULES = ("sim.render_trial", "sim.tof_trial")

#: Columns every study row has besides the scenario and the kind's outputs.
ID_COLUMNS = ("trial_id", "seed")
TIMING_COLUMNS = ("wall_s", "cpu_s")


@dataclass(frozen=True)
class Parameter:
    """A scenario parameter a study may set or vary.

    Attributes
    ----------
    name : str
        Scenario key (units in the name).
    unit : str
    meaning : str
        One sentence for reports and ``--help``.
    default : float
    needs_render : bool
        True if changing it changes the rendered flux (geometry, optics, flash); False if
        it acts after the render (noise, exposure, detector, calibration used by the solver),
        so trials differing only in it can share one render.
    lower, upper : float or None
        Physical domain (inclusive unless ``*_open``).
    """

    name: str
    unit: str
    meaning: str
    default: float
    needs_render: bool
    lower: float | None = None
    upper: float | None = None
    lower_open: bool = False

    def check(self, value, what: str = "") -> float:
        """``float(value)`` if it lies in the domain, else :class:`InputError`."""
        label = what or self.name
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise InputError(f"{label}: expected a number ({self.unit}), got {value!r}") from None
        if not np.isfinite(v):
            raise InputError(f"{label}: expected a finite number ({self.unit}), got {value!r}")
        if self.lower is not None and (v < self.lower or (self.lower_open and v == self.lower)):
            op = ">" if self.lower_open else ">="
            raise InputError(f"{label}: {self.name} must be {op} {self.lower:g} {self.unit} ({self.meaning}), got {v:g}")
        if self.upper is not None and v > self.upper:
            raise InputError(f"{label}: {self.name} must be <= {self.upper:g} {self.unit} ({self.meaning}), got {v:g}")
        return v


@dataclass(frozen=True)
class TrialKind:
    """A registered kind of trial.

    Attributes
    ----------
    name : str
    run_trial : callable
        ``run_trial(scenario: dict, seed: int) -> dict`` (top-level, picklable). The dict
        holds the kind's ``outputs``.
    outputs : tuple of str
        Output columns, in order.
    parameters : mapping of str -> Parameter
        Numeric scenario parameters (for validation and sensitivity studies).
    text_keys : tuple of str
        Non-numeric scenario keys (camera, pattern...).
    run_group : callable, optional
        ``run_group(scenarios, seeds) -> list[dict]`` for trials sharing one render key.
    render_key : callable, optional
        ``render_key(scenario) -> hashable``.
    warm_up : callable, optional
        Called once per worker process (JIT compilation, caches).
    description : str
    module : str
        Module that registers the kind; workers import it to find the kind.
    """

    name: str
    run_trial: Callable[[dict, int], dict]
    outputs: tuple
    parameters: Mapping[str, Parameter]
    text_keys: tuple = ("camera", "pattern")
    run_group: Callable | None = None
    render_key: Callable[[dict], Hashable] | None = None
    warm_up: Callable | None = None
    description: str = ""
    module: str = field(default="")

    @property
    def ref(self) -> tuple[str, str]:
        return (self.module or self.run_trial.__module__, self.name)

    def columns(self, scenario_keys) -> list[str]:
        """All columns of a study of this kind whose scenarios have ``scenario_keys``."""
        clash = set(scenario_keys) & (set(self.outputs) | set(ID_COLUMNS) | set(TIMING_COLUMNS))
        if clash:
            raise ValueError(f"scenario keys {sorted(clash)} clash with output columns")
        return [*ID_COLUMNS, *scenario_keys, *self.outputs, *TIMING_COLUMNS]


_REGISTRY: dict[str, TrialKind] = {}


def register_trial_kind(kind: TrialKind) -> TrialKind:
    """Register (or replace) a trial kind under ``kind.name``."""
    if not kind.module:
        kind = TrialKind(**{**kind.__dict__, "module": kind.run_trial.__module__})
    _REGISTRY[kind.name] = kind
    return kind


def known_trial_kinds() -> list[str]:
    """Names of the registered trial kinds (the built-in ones of :data:`KIND_MODULES` included)."""
    _import_kind_modules()
    return sorted(_REGISTRY)


def _import_kind_modules() -> None:
    for m in KIND_MODULES:
        try:
            importlib.import_module(m)
        except ModuleNotFoundError as exc:
            if exc.name and (exc.name == m or m.startswith(exc.name + ".")):
                continue
            raise


def get_trial_kind(name: str) -> TrialKind:
    """The trial kind called ``name`` (:class:`InputError` listing the known ones)."""
    if name not in _REGISTRY and name not in known_trial_kinds():
        raise InputError(f"--trial-kind: unknown trial kind {name!r}; known: {', '.join(known_trial_kinds())}")
    return _REGISTRY[name]


# --------------------------------------------------------------------------- geometric trial
GEOMETRIC_PARAMETERS = {
    p.name: p
    for p in (
        Parameter("range_m", "m", "distance from the camera to the target origin along the boresight", 10.0, True,
                  lower=0.0, lower_open=True),
        Parameter("target_x_m", "m", "lateral offset of the target origin from the boresight, camera right", 0.0, True),
        Parameter("target_y_m", "m", "lateral offset of the target origin from the boresight, camera up", 0.0, True),
        Parameter("roll_deg", "deg", "relative attitude, rotation about the target x axis (paper phi)", 0.0, True,
                  lower=-90.0, upper=90.0),
        Parameter("pitch_deg", "deg", "relative attitude, rotation about the target y axis (paper theta)", 0.0, True,
                  lower=-90.0, upper=90.0),
        Parameter("yaw_deg", "deg", "relative attitude, rotation about the target z axis (paper psi)", 0.0, True,
                  lower=-180.0, upper=180.0),
        Parameter("sigma_px", "px", "1-sigma Gaussian centroid noise per image axis", 0.1, False, lower=0.0),
        Parameter("focal_error_frac", "1", "relative error of the focal length the solver uses (fx and fy scaled by 1 + e)",
                  0.0, False, lower=-0.5, upper=0.5),
        Parameter("pp_error_u_px", "px", "error of the principal point cx the solver uses", 0.0, False),
        Parameter("pp_error_v_px", "px", "error of the principal point cy the solver uses", 0.0, False),
        Parameter("k1_error", "1", "error of the radial distortion k1 the solver uses (the lens has the profile's k1)",
                  0.0, False, lower=-1.0, upper=1.0),
        Parameter("merge_px", "px", "spots closer than this in the image merge into one (0: never)", 0.0, True,
                  lower=0.0),
        # the paper's test stand (sim.stand): the gimbal turns the phone, the target stays still
        Parameter("stand", "1", "1: the angles turn the phone on the test stand's gimbal about its pivot, range_m is "
                  "the rail position (sim.stand.TestStand); 0: they turn the target in front of the camera", 0.0, True,
                  lower=0.0, upper=1.0),
        Parameter("stage_m", "m", "the stand's translation stage along the rail, positive away from the target "
                  "(stand = 1 only)", 0.0, True, lower=-1.0, upper=1.0),
        Parameter("misalign_yaw_deg", "deg", "the phone's yaw in its holder on the stand (stand = 1 only)", 0.0, True,
                  lower=-10.0, upper=10.0),
        Parameter("misalign_pitch_deg", "deg", "the phone's pitch in its holder on the stand (stand = 1 only)", 0.0,
                  True, lower=-10.0, upper=10.0),
        Parameter("misalign_roll_deg", "deg", "the phone's roll in its holder on the stand (stand = 1 only)", 0.0, True,
                  lower=-10.0, upper=10.0),
        Parameter("truth_actual", "1", "0: errors against the pose the lab commanded (the stand's setting); 1: against "
                  "the pose with the phone's misalignment in its holder included", 0.0, False, lower=0.0,
                  upper=1.0),
        # the stand's errors at this setting (sim.closed_loop.Scenario.stand_error; the lab's, sim.lab)
        Parameter("stand_err_roll_deg", "deg", "the gimbal's actual roll minus the commanded (stand = 1 only)", 0.0,
                  True, lower=-5.0, upper=5.0),
        Parameter("stand_err_pitch_deg", "deg", "the gimbal's actual pitch minus the commanded (stand = 1 only)", 0.0,
                  True, lower=-5.0, upper=5.0),
        Parameter("stand_err_yaw_deg", "deg", "the gimbal's actual yaw minus the commanded (stand = 1 only)", 0.0,
                  True, lower=-5.0, upper=5.0),
        Parameter("stand_err_stage_m", "m", "the translation stage's actual position minus the commanded (stand = 1 "
                  "only)", 0.0, True, lower=-1.0, upper=1.0),
        Parameter("rail_err_m", "m", "the rail position's actual minus the recorded one (the range the lab measured "
                  "with its rangefinder; stand = 1 only)", 0.0, True, lower=-1.0, upper=1.0),
        Parameter("truth_stand", "1", "1: errors against the pose with the gimbal's and the stage's errors "
                  "included (they are then no error); 0: against the commanded setting", 0.0, False, lower=0.0,
                  upper=1.0),
        Parameter("truth_rail", "1", "1: errors against the pose with the rail position's error included; 0: "
                  "against the recorded range", 0.0, False, lower=0.0, upper=1.0),
    )
}

#: Scenario keys of the pose (the geometric kind's render key; the render kind adds its own).
POSE_KEYS = ("range_m", "target_x_m", "target_y_m", "roll_deg", "pitch_deg", "yaw_deg", "stand", "stage_m",
             "misalign_yaw_deg", "misalign_pitch_deg", "misalign_roll_deg", "stand_err_roll_deg",
             "stand_err_pitch_deg", "stand_err_yaw_deg", "stand_err_stage_m", "rail_err_m")
#: The truth's switches: which of the truth errors the errors are taken against.
TRUTH_KEYS = ("truth_actual", "truth_stand", "truth_rail")


def scenario_pose_kwargs(scenario: Mapping) -> dict:
    """The :class:`sim.closed_loop.Scenario` pose fields of a trial scenario."""
    flag = scenario.get("stand", 0.0)
    if flag not in (0.0, 1.0):
        raise InputError(f"stand: expected 0 (target turned) or 1 (phone on the stand's gimbal), got {flag!r}")
    kw = {k: float(scenario[k]) for k in ("range_m", "target_x_m", "target_y_m", "roll_deg", "pitch_deg", "yaw_deg")}
    kw["mount"] = "stand" if flag == 1.0 else "target"
    kw["stage_m"] = float(scenario.get("stage_m", 0.0))
    kw["misalignment_deg"] = tuple(float(scenario.get(f"misalign_{a}_deg", 0.0)) for a in ("roll", "pitch", "yaw"))
    kw["stand_error"] = tuple(float(scenario.get(k, 0.0)) for k in ("stand_err_roll_deg", "stand_err_pitch_deg",
                                                                     "stand_err_yaw_deg", "stand_err_stage_m",
                                                                     "rail_err_m"))
    return kw


def truth_flags(scenario: Mapping) -> tuple:
    """``(misalignment, stand, rail)``: which truth errors a trial's truth includes
    (:meth:`sim.closed_loop.Scenario.truth_pose`), from its :data:`TRUTH_KEYS`."""
    return tuple(bool(scenario.get(k, 0.0)) for k in TRUTH_KEYS)


def scenario_poses(scenario: Mapping):
    """``(R, t)`` actual and ``(R, t)`` of the truth the errors are taken against
    (:data:`TRUTH_KEYS`), of a trial scenario (:class:`sim.closed_loop.Scenario`'s poses)."""
    from sim.closed_loop import Scenario

    sc = Scenario(camera=str(scenario["camera"]), **scenario_pose_kwargs(scenario))
    return sc.pose(), sc.truth_pose(*truth_flags(scenario))

GEOMETRIC_OUTPUTS = (
    "ok", "reason",
    *(f"true_{k}" for k in STATE_KEYS),
    *(f"est_{k}" for k in STATE_KEYS),
    *ERR_KEYS,
    POS_ERR_NORM_M, ROT_ERR_DEG, "residual_rms_px", "min_separation_px",
    *(f"crlb_{k}" for k in STATE_KEYS),
)


def _camera(name: str):
    from svgs.profiles import load_camera

    return load_camera(name)


def _pattern(name: str):
    from svgs.profiles import load_pattern

    return load_pattern(name)


def camera_with_calibration_errors(camera, scenario: Mapping):
    """The camera the solver believes: ``camera`` with the scenario's calibration errors.

    Parameters
    ----------
    camera : svgs.profiles.Camera
        The true camera.
    scenario : mapping
        ``focal_error_frac`` (fx and fy scaled by ``1 + e``), ``pp_error_u_px``,
        ``pp_error_v_px`` (added to cx, cy), ``k1_error`` (added to the radial k1).

    Returns
    -------
    svgs.profiles.Camera
    """
    return camera.replace(
        fx=camera.fx * (1.0 + scenario["focal_error_frac"]),
        fy=camera.fy * (1.0 + scenario["focal_error_frac"]),
        cx=camera.cx + scenario["pp_error_u_px"],
        cy=camera.cy + scenario["pp_error_v_px"],
        dist=camera.dist + np.array([scenario["k1_error"], 0.0, 0.0, 0.0, 0.0]),
    )


def build_scenario(kind: TrialKind, values: dict, labels: dict | None = None) -> dict:
    """A complete, validated scenario of ``kind``: defaults filled in, domains checked.

    Parameters
    ----------
    kind : TrialKind
    values : dict
        Text keys (``camera`` required, ``pattern`` default ``svgs-3u``) and numeric
        parameters of ``kind``; an unknown key is an :class:`InputError`.
    labels : dict, optional
        Extra keys carried into the rows unchanged (e.g. ``nominal_range_m``).
    """
    values = dict(values)
    if "camera" not in values:
        raise InputError(f"{kind.name} scenario: 'camera' is required")
    out = {"camera": str(values.pop("camera")), "pattern": str(values.pop("pattern", "svgs-3u"))}
    _camera(out["camera"])  # InputError for an unknown profile, now rather than in a worker
    _pattern(out["pattern"])
    unknown = sorted(set(values) - set(kind.parameters))
    if unknown:
        raise InputError(f"trial kind {kind.name!r} has no parameter {', '.join(map(repr, unknown))}; "
                         f"known: {', '.join(kind.parameters)}")
    for name, p in kind.parameters.items():
        out[name] = p.check(values.get(name, p.default))
    if "stand" in out:  # the pose fields together (stand and lateral offsets, misalignment without a stand)
        from sim.closed_loop import Scenario

        Scenario(camera=out["camera"], **scenario_pose_kwargs(out))
    for k, v in (labels or {}).items():
        if k in out:
            raise InputError(f"scenario label {k!r} clashes with a parameter")
        out[k] = v
    return out


def geometric_scenario(labels: dict | None = None, **values) -> dict:
    """A complete, validated geometric scenario (see :func:`build_scenario`)."""
    return build_scenario(GEOMETRIC, values, labels)


def _geometric_render(scenario: dict):
    """The geometric "render": the pattern's true image points through the true camera.

    Returns
    -------
    uv_px : ndarray, shape (n, 2)
    depth_ok : bool
        All points in front of the camera.
    state_true : ndarray, shape (6,)
    """
    from svgs.frames import pose_to_state

    cam, pat = _camera(scenario["camera"]), _pattern(scenario["pattern"])
    (R, t), (R_truth, t_truth) = scenario_poses(scenario)
    p_cam = pat.points_m @ R.T + t
    depth_ok = bool(np.all(p_cam[:, 2] > 0))
    uv = cam.project(p_cam)
    return uv, depth_ok, pose_to_state(R_truth, t_truth)


def _geometric_expose_solve(scenario: dict, seed: int, rendered) -> dict:
    from svgs.solver import solve_centroids

    uv_true, depth_ok, state_true = rendered
    cam, pat = _camera(scenario["camera"]), _pattern(scenario["pattern"])
    rng = np.random.default_rng(seed)
    uv = uv_true + scenario["sigma_px"] * rng.standard_normal(uv_true.shape)
    out = {k: None for k in GEOMETRIC_OUTPUTS}
    out.update({f"true_{k}": float(v) for k, v in zip(STATE_KEYS, state_m_deg(state_true))})
    d = np.linalg.norm(uv_true[:, None] - uv_true[None], axis=-1) + np.eye(len(uv_true)) * 1e12
    out["min_separation_px"] = float(d.min())
    reason = None
    if not depth_ok or not np.all(cam.in_image(uv_true)):
        reason = "too_few_blobs"  # a target outside the image: the detector sees fewer than four spots
    elif scenario["merge_px"] > 0 and d.min() < scenario["merge_px"]:
        reason = "merged_spots"
    if reason is None:
        solver_cam = camera_with_calibration_errors(cam, scenario)
        try:
            sol = solve_centroids(uv, solver_cam, pat, sigma_px=1.0)
        except InputError:  # a degenerate image (e.g. all points on one line)
            sol = None
            reason = "degenerate"
        if sol is not None and not sol:
            reason = sol.reason
    out["ok"] = reason is None
    out["reason"] = reason
    if reason is None:
        out.update(estimate_outputs(sol, state_true, crlb_scale=scenario["sigma_px"]))
    return out


def estimate_outputs(sol, state_true, crlb_scale: float = 1.0) -> dict:
    """The ``est_*``, ``err_*``, ``crlb_*``, ``pos_err_norm_m``, ``rot_err_deg`` and
    ``residual_rms_px`` outputs of a solved trial (errors from :mod:`sim.metrics`).

    Parameters
    ----------
    sol : svgs.Solution
    state_true : ndarray, shape (6,)
        The true paper state (m, rad).
    crlb_scale : float
        Multiplies the solution's 1-sigma bound (its covariance is for ``sol.sigma_px``).
    """
    crlb = state_m_deg(np.sqrt(np.diag(sol.covariance)) * crlb_scale)
    out = {f"est_{k}": float(v) for k, v in zip(STATE_KEYS, state_m_deg(sol.state))}
    out.update(error_columns(sol.state, state_true, R_cam_target_est=sol.R_cam_target))
    out.update({f"crlb_{k}": float(v) for k, v in zip(STATE_KEYS, crlb)})
    out["residual_rms_px"] = float(sol.residual_rms_px)
    return out


def geometric_trial(scenario: dict, seed: int) -> dict:
    """One geometric trial: project, add centroid noise, solve with the solver's calibration.

    Parameters
    ----------
    scenario : dict
        See :func:`geometric_scenario` (camera, pattern, pose, ``sigma_px``, calibration
        errors, ``merge_px``).
    seed : int
        Seeds the centroid noise.

    Returns
    -------
    dict
        :data:`GEOMETRIC_OUTPUTS`: ``ok``, ``reason`` (a :data:`svgs.result.REASONS` code or
        None), ``true_*``/``est_*``/``err_*`` for x, y, z (m; the camera's perspective centre in
        the target frame) and roll, pitch, yaw (deg; paper angles, errors wrapped to
        [-180, 180)), ``pos_err_norm_m`` (norm of the position error), ``rot_err_deg``
        (rotation angle between solved and true attitude; see :mod:`sim.metrics`), ``residual_rms_px``, ``min_separation_px`` (closest pair of true
        image points) and ``crlb_*`` (Cramer-Rao 1-sigma for ``sigma_px``, at the estimate).
    """
    return _geometric_expose_solve(scenario, seed, _geometric_render(scenario))


def geometric_group(scenarios: list, seeds: list) -> list[dict]:
    """Trials sharing one projection (same :func:`geometric_render_key`): project once."""
    rendered = _geometric_render(scenarios[0])
    return [_geometric_expose_solve(s, seed, rendered) for s, seed in zip(scenarios, seeds)]


def geometric_render_key(scenario: dict):
    """What decides the geometric "render": camera, pattern, pose (and the truth it is judged by)."""
    return (scenario["camera"], scenario["pattern"],
            *(scenario.get(k, GEOMETRIC_PARAMETERS[k].default) for k in (*POSE_KEYS, *TRUTH_KEYS)))


def geometric_warm_up() -> None:
    """Load the compiled solver (numba, cached on disk after the first compilation)."""
    from svgs.frames import pose_from_scenario
    from svgs.profiles import Camera, Pattern
    from svgs.solver import solve_centroids

    cam = Camera(name="warm-up", width=1000, height=1000, fx=1000.0, fy=1000.0, cx=499.5, cy=499.5)
    pat = Pattern.load("svgs-3u")
    R, t = pose_from_scenario(5.0, 0.0, 0.0, 5.0, -5.0, 10.0)
    solve_centroids(cam.project_target(pat.points_m, R, t), cam, pat)


GEOMETRIC = register_trial_kind(TrialKind(
    name="geometric",
    run_trial=geometric_trial,
    outputs=GEOMETRIC_OUTPUTS,
    parameters=GEOMETRIC_PARAMETERS,
    run_group=geometric_group,
    render_key=geometric_render_key,
    warm_up=geometric_warm_up,
    description="pattern projected through the camera, Gaussian centroid noise, solver with a (possibly wrong) calibration",
))
