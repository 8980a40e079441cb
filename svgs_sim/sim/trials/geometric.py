"""The built-in ``geometric`` trial kind: the pattern projected through the camera at the scenario's
pose, seeded Gaussian centroid noise, the solver with a (possibly wrong) calibration; truth,
estimate, errors and the Cramer-Rao bound.

Part of :mod:`svgs_sim.sim.trials`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from svgs_sim.base.errors import InputError
from svgs_sim.base.limits import RANGE_LIMIT_M, bounds
from svgs_sim.base.profiles import Camera, load_camera, load_pattern
from svgs_sim.sim.metrics import ERR_KEYS, POS_ERR_NORM_M, ROT_ERR_DEG, error_columns, state_m_deg
from svgs_sim.sim.trials.registry import Parameter, TrialKind, register_trial_kind
from svgs_sim.sim.trials.scenario import PoseKey, PoseScenario, build_scenario, camera_with_calibration_errors
from svgs_sim.svgs.envelope import ATTITUDE_LIMITS_DEG
from svgs_sim.svgs.frames import STATE_KEYS, pose_from_scenario, pose_to_state
from svgs_sim.svgs.solver import solve_centroids

# Every numeric parameter of every kind has a physical lower and upper bound (a test walks the
# registry): the CLI's for the same quantity (svgs_sim.base.limits, one table), the sensor's envelope, or
# the parameter's own (a switch 0-1, an error a calibration could have).
GEOMETRIC_PARAMETERS = {
    p.name: p
    for p in (
        Parameter("range_m", "m", "distance from the camera to the target origin along the boresight (stand = 0 "
                  "only; a stand trial gives rail_m)", 10.0, True, lower=0.0, upper=RANGE_LIMIT_M, lower_open=True,
                  optional=True),
        Parameter("rail_m", "m", "the gimbal pivot's position on the test stand's rail, the distance the lab "
                  "recorded (stand = 1 only, where it is required)", None, True, lower=0.0, upper=RANGE_LIMIT_M,
                  lower_open=True, optional=True),
        Parameter("target_x_m", "m", "lateral offset of the target origin from the boresight, camera right", 0.0, True,
                  **bounds("target_x_m")),
        Parameter("target_y_m", "m", "lateral offset of the target origin from the boresight, camera up", 0.0, True,
                  **bounds("target_y_m")),
        Parameter("roll_deg", "deg", "relative attitude, rotation about the target x axis (paper phi)", 0.0, True,
                  lower=-ATTITUDE_LIMITS_DEG["roll_deg"], upper=ATTITUDE_LIMITS_DEG["roll_deg"]),
        Parameter("pitch_deg", "deg", "relative attitude, rotation about the target y axis (paper theta)", 0.0, True,
                  lower=-ATTITUDE_LIMITS_DEG["pitch_deg"], upper=ATTITUDE_LIMITS_DEG["pitch_deg"]),
        Parameter("yaw_deg", "deg", "relative attitude, rotation about the target z axis (paper psi)", 0.0, True,
                  lower=-ATTITUDE_LIMITS_DEG["yaw_deg"], upper=ATTITUDE_LIMITS_DEG["yaw_deg"]),
        Parameter("sigma_px", "px", "1-sigma Gaussian centroid noise per image axis", 0.1, False,
                  **bounds("sigma_px")),
        Parameter("focal_error_frac", "1", "relative error of the focal length the solver uses (fx and fy scaled by 1 + e)",
                  0.0, False, **bounds("focal_error_frac")),
        Parameter("pp_error_u_px", "px", "error of the principal point cx the solver uses", 0.0, False,
                  **bounds("true_pp_offset_px")),
        Parameter("pp_error_v_px", "px", "error of the principal point cy the solver uses", 0.0, False,
                  **bounds("true_pp_offset_px")),
        Parameter("k1_error", "1", "error of the radial distortion k1 the solver uses (the lens has the profile's k1)",
                  0.0, False, **bounds("k1_error")),
        Parameter("merge_px", "px", "spots closer than this in the image merge into one (0: never)", 0.0, True,
                  **bounds("merge_px")),
        # the paper's test stand (svgs_sim.sim.stand): the gimbal turns the phone, the target stays still
        Parameter("stand", "1", "1: the angles turn the phone on the test stand's gimbal about its pivot, rail_m gives "
                  "the rail position (svgs_sim.sim.stand.TestStand); 0: they turn the target in front of the camera, "
                  "range_m away", 0.0, True,
                  lower=0.0, upper=1.0),
        Parameter("stage_m", "m", "the stand's translation stage along the rail, positive away from the target "
                  "(stand = 1 only)", 0.0, True, **bounds("stage_m")),
        Parameter("misalign_yaw_deg", "deg", "the phone's yaw in its holder on the stand (stand = 1 only)", 0.0, True,
                  lower=-10.0, upper=10.0),
        Parameter("misalign_pitch_deg", "deg", "the phone's pitch in its holder on the stand (stand = 1 only)", 0.0,
                  True, lower=-10.0, upper=10.0),
        Parameter("misalign_roll_deg", "deg", "the phone's roll in its holder on the stand (stand = 1 only)", 0.0, True,
                  lower=-10.0, upper=10.0),
        Parameter("truth_actual", "1", "0: errors against the pose the lab commanded (the stand's setting); 1: against "
                  "the pose with the phone's misalignment in its holder included", 0.0, False, lower=0.0,
                  upper=1.0),
        # the stand's errors at this setting (svgs_sim.sim.closed_loop.Scenario.stand_error; the lab's, svgs_sim.sim.lab)
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


@dataclass(frozen=True, eq=False)
class GeometricScenario(PoseScenario):
    """A ``geometric`` trial's scenario (:data:`GEOMETRIC_PARAMETERS`; see
    :class:`TrialScenario` for the row view).

    Attributes
    ----------
    sigma_px : float
        1-sigma Gaussian centroid noise per image axis, px.
    merge_px : float
        Spots closer than this in the image merge (0: never).
    """

    sigma_px: float = 0.1
    merge_px: float = 0.0

    KIND: ClassVar[str] = "geometric"


def geometric_scenario(labels: dict | None = None, **values) -> GeometricScenario:
    """A complete, validated geometric scenario (see :func:`build_scenario`)."""
    return build_scenario(GEOMETRIC, values, labels)


GEOMETRIC_OUTPUTS = (
    "ok", "reason",
    *(f"true_{k}" for k in STATE_KEYS),
    *(f"est_{k}" for k in STATE_KEYS),
    *ERR_KEYS,
    POS_ERR_NORM_M, ROT_ERR_DEG, "residual_rms_px", "min_separation_px",
    *(f"crlb_{k}" for k in STATE_KEYS),
)


def _geometric_render(scenario: GeometricScenario):
    """The geometric "render": the pattern's true image points through the true camera.

    Returns
    -------
    uv_px : ndarray, shape (n, 2)
    depth_ok : bool
        All points in front of the camera.
    state_true : ndarray, shape (6,)
    """

    cam, pat = load_camera(scenario.camera), load_pattern(scenario.pattern)
    (R, t), (R_truth, t_truth) = scenario.poses()
    p_cam = pat.points_m @ R.T + t
    depth_ok = bool(np.all(p_cam[:, 2] > 0))
    uv = cam.project(p_cam)
    return uv, depth_ok, pose_to_state(R_truth, t_truth)


def _geometric_expose_solve(scenario: GeometricScenario, seed: int, rendered) -> dict:

    uv_true, depth_ok, state_true = rendered
    cam, pat = load_camera(scenario.camera), load_pattern(scenario.pattern)
    rng = np.random.default_rng(seed)
    uv = uv_true + scenario.sigma_px * rng.standard_normal(uv_true.shape)
    out = {k: None for k in GEOMETRIC_OUTPUTS}
    out.update({f"true_{k}": float(v) for k, v in zip(STATE_KEYS, state_m_deg(state_true))})
    d = np.linalg.norm(uv_true[:, None] - uv_true[None], axis=-1) + np.eye(len(uv_true)) * 1e12
    out["min_separation_px"] = float(d.min())
    reason = None
    if not depth_ok or not np.all(cam.in_image(uv_true)):
        reason = "too_few_blobs"  # a target outside the image: the detector sees fewer than four spots
    elif scenario.merge_px > 0 and d.min() < scenario.merge_px:
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
        out.update(estimate_outputs(sol, state_true, crlb_scale=scenario.sigma_px))
    return out


def estimate_outputs(sol, state_true, crlb_scale: float = 1.0) -> dict:
    """The ``est_*``, ``err_*``, ``crlb_*``, ``pos_err_norm_m``, ``rot_err_deg`` and
    ``residual_rms_px`` outputs of a solved trial (errors from :mod:`svgs_sim.sim.metrics`).

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


def geometric_trial(scenario: GeometricScenario | Mapping, seed: int) -> dict:
    """One geometric trial: project, add centroid noise, solve with the solver's calibration.

    Parameters
    ----------
    scenario : GeometricScenario or mapping
        See :func:`geometric_scenario` (camera, pattern, pose, ``sigma_px``, calibration
        errors, ``merge_px``); a mapping of row values is read with
        :meth:`TrialScenario.from_row`.
    seed : int
        Seeds the centroid noise.

    Returns
    -------
    dict
        :data:`GEOMETRIC_OUTPUTS`: ``ok``, ``reason`` (a :data:`svgs_sim.svgs.result.REASONS` code or
        None), ``true_*``/``est_*``/``err_*`` for x, y, z (m; the camera's perspective centre in
        the target frame) and roll, pitch, yaw (deg; paper angles, errors wrapped to
        [-180, 180)), ``pos_err_norm_m`` (norm of the position error), ``rot_err_deg``
        (rotation angle between solved and true attitude; see :mod:`svgs_sim.sim.metrics`), ``residual_rms_px``, ``min_separation_px`` (closest pair of true
        image points) and ``crlb_*`` (Cramer-Rao 1-sigma for ``sigma_px``, at the estimate).
    """
    scenario = GeometricScenario.from_row(scenario)
    return _geometric_expose_solve(scenario, seed, _geometric_render(scenario))


def geometric_group(scenarios: list, seeds: list) -> list[dict]:
    """Trials sharing one projection (same :func:`geometric_render_key`): project once."""
    scenarios = [GeometricScenario.from_row(s) for s in scenarios]
    rendered = _geometric_render(scenarios[0])
    return [_geometric_expose_solve(s, seed, rendered) for s, seed in zip(scenarios, seeds)]


def geometric_render_key(scenario) -> PoseKey:
    """What decides the geometric "render": camera, pattern, pose (and the truth it is judged by)."""
    return PoseKey.of(GeometricScenario.from_row(scenario))


def geometric_warm_up() -> None:
    """Load the compiled solver (numba, cached on disk after the first compilation)."""

    cam = Camera(name="warm-up", width=1000, height=1000, fx=1000.0, fy=1000.0, cx=499.5, cy=499.5)
    pat = load_pattern("svgs-3u")
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
    scenario_type=GeometricScenario,
))
