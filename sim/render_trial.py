"""The ``render`` trial kind for studies: Mitsuba render -> phone exposure -> SVGS solve.

Registers with :mod:`sim.trials`, so ``svgs campaign --trial-kind render`` and
``svgs sensitivity --trial-kind render`` run the full physical chain. Trials that share
the geometry (camera, pattern, pose, lab) share one render (``render_key``/``run_group``):
render once, expose many. Each trial's numbers depend only on its scenario and seed.
"""

from __future__ import annotations

import functools

import numpy as np

from sim.metrics import state_m_deg
from sim.trials import (
    GEOMETRIC_OUTPUTS,
    GEOMETRIC_PARAMETERS,
    Parameter,
    TrialKind,
    camera_with_calibration_errors,
    estimate_outputs,
    register_trial_kind,
)
from svgs.frames import STATE_KEYS

_POSE = ("range_m", "target_x_m", "target_y_m", "roll_deg", "pitch_deg", "yaw_deg")

RENDER_PARAMETERS = {
    **{k: GEOMETRIC_PARAMETERS[k] for k in _POSE},
    "backdrop_distance_m": Parameter("backdrop_distance_m", "m", "grey backdrop behind the target (0: none)", 3.0, True,
                                     lower=0.0),
    "ambient_radiance_w_m2_sr": Parameter("ambient_radiance_w_m2_sr", "W m^-2 sr^-1",
                                          "uniform ambient scene radiance from room lights, in band", 0.0, True, lower=0.0),
    "exposure_s": Parameter("exposure_s", "s", "exposure time forced on the phone (0: the profile's mode)", 0.0, False,
                            lower=0.0, upper=60.0),
    "iso": Parameter("iso", "ISO", "sensitivity forced on the phone (0: the profile's mode)", 0.0, False, lower=0.0),
    "threshold": Parameter("threshold", "DN", "detector threshold in 8-bit counts (0: automatic)", 0.0, False,
                           lower=0.0, upper=255.0),
    **{k: GEOMETRIC_PARAMETERS[k] for k in ("focal_error_frac", "pp_error_u_px", "pp_error_v_px", "k1_error")},
}

RENDER_OUTPUTS = (*GEOMETRIC_OUTPUTS, "n_blobs", "exposure_s_used", "iso_used")


def render_key(scenario: dict):
    return tuple(scenario[k] for k in ("camera", "pattern", *_POSE, "backdrop_distance_m", "ambient_radiance_w_m2_sr"))


@functools.lru_cache(maxsize=2)
def _frame(key):
    from sim.closed_loop import Scenario, render_scenario

    camera, pattern, rng, x, y, roll, pitch, yaw, back, amb = key
    scen = Scenario(camera=camera, pattern=pattern, range_m=rng, target_x_m=x, target_y_m=y, roll_deg=roll,
                    pitch_deg=pitch, yaw_deg=yaw, backdrop_distance_m=back if back > 0 else None,
                    ambient_radiance_w_m2_sr=amb)
    # the render's own Monte Carlo seed is part of the geometry key, so it is fixed
    frame = render_scenario(scen, seed=0)
    return frame, frame.exposer()


def _solve_one(scenario: dict, seed: int, frame, exposer) -> dict:
    from svgs.frames import pose_to_state
    from svgs.profiles import Pattern

    from sim.closed_loop import expose_and_solve

    cam = frame.camera
    row = expose_and_solve(
        frame, exposer, seed=seed,
        threshold=scenario["threshold"] if scenario["threshold"] > 0 else None,
        exposure_s=scenario["exposure_s"] or None, iso=scenario["iso"] or None,
        solver_camera_profile=camera_with_calibration_errors(cam, scenario),
    )
    out = {k: None for k in RENDER_OUTPUTS}
    R, t = frame.scenario.pose()
    st = pose_to_state(R, t)
    out.update({f"true_{k}": float(v) for k, v in zip(STATE_KEYS, state_m_deg(st))})
    uv = cam.project_target(Pattern.load(scenario["pattern"]).points_m, R, t)
    d = np.linalg.norm(uv[:, None] - uv[None], axis=-1) + np.eye(len(uv)) * 1e12
    out["min_separation_px"] = float(d.min())
    out.update({"ok": row["ok"], "reason": row["reason"], "n_blobs": row["n_blobs"],
                "exposure_s_used": row["exposure_s"], "iso_used": row["iso"]})
    sol = row["_solution"]
    if row["ok"]:
        out.update(estimate_outputs(sol, st))  # CRLB for the solver's default 0.1 px
    return out


def render_trial(scenario: dict, seed: int) -> dict:
    """One render-and-solve trial (renders, or reuses the worker's last render of the same geometry)."""
    frame, exposer = _frame(render_key(scenario))
    return _solve_one(scenario, seed, frame, exposer)


def render_group(scenarios, seeds) -> list[dict]:
    """Trials sharing one render key: render once, expose and solve each."""
    frame, exposer = _frame(render_key(scenarios[0]))
    return [_solve_one(s, int(k), frame, exposer) for s, k in zip(scenarios, seeds)]


def _warm_up():
    from render.variant import select_variant

    select_variant()


RENDER = register_trial_kind(TrialKind(
    name="render",
    run_trial=render_trial,
    outputs=RENDER_OUTPUTS,
    parameters=RENDER_PARAMETERS,
    run_group=render_group,
    render_key=render_key,
    warm_up=_warm_up,
    description="Mitsuba render of the target under the flash, phone camera model, SVGS detector and solver",
    module=__name__,
))
