"""The ``render`` trial kind: Mitsuba render -> phone exposure -> SVGS solve.

Registers with :mod:`sim.trials`, so ``svgs campaign --trial-kind render`` and
``svgs sensitivity --trial-kind render`` run the full physical chain, and
``studies.range_sweep`` and ``studies.exposure_study`` build its scenarios (with
:func:`render_trial_scenario`). A trial is :func:`sim.closed_loop.render_scenario` (Mitsuba, the
lab light) followed by :func:`sim.closed_loop.expose_and_solve` (phone model, detector,
solver), exactly the chain of ``svgs render-and-solve``.

Render once, expose many
    The render key is everything that decides the rendered flux: camera, pattern and its
    scale, pose, lab, samples per pixel and the render's own Monte Carlo seed
    (``render_seed``, a scenario parameter, so trials sharing a render agree on it). What acts
    after the render - the noise draw (the trial's seed), a forced exposure or ISO, a
    neutral-density filter over the reflectors (``target_scale``), the detector threshold,
    the calibration the solver uses - varies within a render group. A trial's numbers depend
    only on its scenario and seed, whether it runs alone or in a group.

Scenario keys
    Text: ``camera``, ``pattern`` (name or path). Numbers: :data:`RENDER_PARAMETERS` (the
    defaults are a render with seed 0 of the pattern as it is, no ND filter, the renderer's
    samples per pixel, the phone's auto-exposure, the automatic threshold and the exact
    calibration). Studies add labels (``nominal_range_m``, ``pose_index``, ``trial``,
    ``remedy``...) carried into the rows unchanged.
"""

from __future__ import annotations

import functools
import tempfile
from pathlib import Path

import numpy as np

from sim.closed_loop import DEFAULT_AMBIENT_RADIANCE_W_M2_SR, DEFAULT_BACKDROP_DISTANCE_M
from sim.metrics import (
    ATT_ERR_VEC_DEG,
    ERR_KEYS,
    POS_ERR_NORM_M,
    POS_ERR_VEC_M,
    ROT_ERR_DEG,
)
from sim.trials import (
    GEOMETRIC_PARAMETERS,
    Parameter,
    TrialKind,
    build_scenario,
    camera_with_calibration_errors,
    register_trial_kind,
)
from svgs.errors import InputError
from svgs.frames import STATE_KEYS

_POSE = ("range_m", "target_x_m", "target_y_m", "roll_deg", "pitch_deg", "yaw_deg")

#: ``threshold`` values that are not levels (the parameter is numeric, so a sensitivity study can vary it).
THRESHOLD_AUTO, THRESHOLD_OTSU = 0.0, -1.0

RENDER_PARAMETERS = {
    **{k: GEOMETRIC_PARAMETERS[k] for k in _POSE},
    "backdrop_distance_m": Parameter("backdrop_distance_m", "m", "grey backdrop behind the target (0: none)",
                                     DEFAULT_BACKDROP_DISTANCE_M, True,
                                     lower=0.0),
    "ambient_radiance_w_m2_sr": Parameter("ambient_radiance_w_m2_sr", "W m^-2 sr^-1",
                                          "uniform ambient scene radiance from room lights, in band (default: the lab's, sim.lab)",
                                          DEFAULT_AMBIENT_RADIANCE_W_M2_SR, True, lower=0.0),
    "spp": Parameter("spp", "1", "samples per pixel of the full frame (-1: the renderer's default)", -1.0, True,
                     lower=-1.0),
    "roi_spp": Parameter("roi_spp", "1", "samples per pixel in the spot windows (-1: the renderer's default)", -1.0,
                         True, lower=-1.0),
    "render_seed": Parameter("render_seed", "1", "seed of the render's Monte Carlo sampling", 0.0, True, lower=0.0),
    "pattern_scale": Parameter("pattern_scale", "1", "the pattern scaled about its origin by this factor (a wider target)",
                               1.0, True, lower=0.0, upper=10.0, lower_open=True),
    "target_scale": Parameter("target_scale", "1", "multiplies the target's flux, not the lab's (an ND filter of "
                              "transmission T over every reflector: T**2)", 1.0, False, lower=0.0, upper=1.0,
                              lower_open=True),
    "exposure_s": Parameter("exposure_s", "s", "exposure time forced on the phone (0: the phone's auto-exposure)", 0.0,
                            False, lower=0.0, upper=60.0),
    "iso": Parameter("iso", "ISO", "sensitivity forced on the phone (0: the phone's auto-exposure)", 0.0, False,
                     lower=0.0),
    "threshold": Parameter("threshold", "DN", "detector threshold in 8-bit counts (0: automatic, -1: Otsu's)", 0.0,
                           False, lower=-1.0, upper=255.0),
    **{k: GEOMETRIC_PARAMETERS[k] for k in ("focal_error_frac", "pp_error_u_px", "pp_error_v_px", "k1_error")},
}

RENDER_OUTPUTS = (
    "ok", "reason", "message", "n_blobs",
    *(f"true_{k}" for k in STATE_KEYS),
    *(f"est_{k}" for k in STATE_KEYS),
    *ERR_KEYS, POS_ERR_NORM_M, ROT_ERR_DEG,
    "residual_rms_px", "min_separation_px",
    *(f"crlb_{k}" for k in STATE_KEYS),
    "exposure_s_used", "iso_used", "expose_s", "solve_s",
)

#: Outputs that are timings (they differ from run to run; every other output is reproducible).
RENDER_TIMING_OUTPUTS = ("expose_s", "solve_s")


def check_threshold(text) -> str:
    """A threshold option: ``auto``, ``otsu`` or a positive level (as text); :class:`InputError` otherwise."""
    from svgs.detect import parse_threshold

    v = parse_threshold("auto" if text is None else str(text).strip())
    return v if isinstance(v, str) else repr(v)


def threshold_parameter(text) -> float:
    """The ``threshold`` scenario value of a threshold option (``auto``: 0, ``otsu``: -1, a level: itself)."""
    t = check_threshold(text)
    return THRESHOLD_AUTO if t == "auto" else THRESHOLD_OTSU if t == "otsu" else float(t)


def _threshold(value: float):
    """The detector's ``threshold`` argument of a scenario value."""
    v = float(value)
    return None if v == THRESHOLD_AUTO else "otsu" if v < 0 else v


def scaled_pattern_file(pattern, factor: float, folder) -> str:
    """Write the pattern scaled by ``factor`` about its origin as a TOML file; returns its path.

    Parameters
    ----------
    pattern : str
        Pattern name or path.
    factor : float
        Scale of every target position.
    folder : str or Path
        Where to write ``<name>-x<factor>.toml``.
    """
    import tomli_w

    from svgs.profiles import Pattern

    pat = Pattern.load(pattern)
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{pat.name}-x{factor:g}.toml"
    data = {"name": f"{pat.name}-x{factor:g}", **{k: v for k, v in pat.tables.items()},
            "target": [{"id": int(i), "x_m": float(p[0] * factor), "y_m": float(p[1] * factor), "z_m": float(p[2] * factor)}
                       for i, p in zip(pat.ids, pat.points_m)]}
    with open(path, "wb") as fh:
        tomli_w.dump(data, fh)
    return str(path)


@functools.lru_cache(maxsize=1)
def _pattern_dir() -> str:
    return tempfile.mkdtemp(prefix="svgs-patterns-")


@functools.lru_cache(maxsize=16)
def _scaled_pattern(pattern: str, factor: float) -> str:
    """The pattern to render: the name itself, or a scaled copy in this process's temp folder."""
    if factor == 1.0:
        return pattern
    import hashlib

    sub = hashlib.sha1(pattern.encode()).hexdigest()[:12]  # patterns of one name from different paths
    return scaled_pattern_file(pattern, factor, Path(_pattern_dir()) / sub)


def render_trial_scenario(labels: dict | None = None, **values) -> dict:
    """A complete, validated ``render`` scenario: defaults filled in, domains checked.

    :func:`sim.trials.build_scenario` plus the integer parameters checked.

    Parameters
    ----------
    labels : dict, optional
        Extra keys carried into the rows unchanged (``pose_index``, ``trial``, ``remedy``...).
    **values
        ``camera`` (required), ``pattern`` (default ``svgs-3u``) and :data:`RENDER_PARAMETERS`
        (``threshold`` as a number; see :func:`threshold_parameter`); an unknown key is an
        :class:`InputError`.
    """
    scen = build_scenario(RENDER, values, labels)
    for k in ("spp", "roi_spp", "render_seed"):
        if scen[k] != int(scen[k]):
            raise InputError(f"{k}: expected an integer, got {scen[k]!r}")
    if scen["roi_spp"] == 0:
        raise InputError("roi_spp: expected >= 1 (or -1: the renderer's default), got 0")
    return scen


def render_key(scenario: dict):
    """What decides the rendered flux (see the module docstring)."""
    return tuple(scenario[k] for k in ("camera", "pattern", "pattern_scale", *_POSE, "backdrop_distance_m",
                                       "ambient_radiance_w_m2_sr", "spp", "roi_spp", "render_seed"))


@functools.lru_cache(maxsize=2)
def _frame(key):
    from sim.closed_loop import Scenario, render_scenario

    camera, pattern, scale, rng, x, y, roll, pitch, yaw, back, amb, spp, roi_spp, seed = key
    scen = Scenario(camera=camera, pattern=_scaled_pattern(pattern, float(scale)), range_m=rng, target_x_m=x, target_y_m=y,
                    roll_deg=roll, pitch_deg=pitch, yaw_deg=yaw, backdrop_distance_m=back if back > 0 else None,
                    ambient_radiance_w_m2_sr=amb, spp=None if spp < 0 else int(spp),
                    roi_spp=None if roi_spp < 0 else int(roi_spp))
    return render_scenario(scen, seed=int(seed)), {}


def _exposer(frame, exposers: dict, target_scale: float):
    if target_scale not in exposers:
        exposers[target_scale] = frame.exposer(target_scale=target_scale)
    return exposers[target_scale]


def _solve_one(scenario: dict, seed: int, frame, exposers: dict) -> dict:
    from sim.closed_loop import expose_and_solve
    from sim.metrics import state_m_deg
    from svgs.profiles import Pattern

    cam = frame.camera
    row = expose_and_solve(frame, _exposer(frame, exposers, float(scenario["target_scale"])), seed=int(seed),
                           threshold=_threshold(scenario["threshold"]),
                           exposure_s=scenario["exposure_s"] or None, iso=scenario["iso"] or None,
                           solver_camera_profile=camera_with_calibration_errors(cam, scenario))
    out = {k: None for k in RENDER_OUTPUTS}
    out.update({k: row[k] for k in ("ok", "reason", "message", "n_blobs", "residual_rms_px", "expose_s", "solve_s",
                                    POS_ERR_NORM_M, ROT_ERR_DEG)})
    out["ok"] = bool(row["ok"])
    out["exposure_s_used"], out["iso_used"] = float(row["exposure_s"]), float(row["iso"])
    out.update({f"true_{k}": v for k, v in row["truth_state"].items()})
    R, t = frame.scenario.pose()
    uv = cam.project_target(Pattern.load(frame.scenario.pattern).points_m, R, t)
    d = np.linalg.norm(uv[:, None] - uv[None], axis=-1) + np.eye(len(uv)) * 1e12
    out["min_separation_px"] = float(d.min())
    if row["state"] is not None:
        sol = row["_solution"]
        out.update({f"est_{k}": v for k, v in row["state"].items()})
        out.update(dict(zip(ERR_KEYS, [*row[POS_ERR_VEC_M], *row[ATT_ERR_VEC_DEG]])))
        # Cramer-Rao 1-sigma for the solver's default centroid noise (0.1 px)
        crlb = state_m_deg(np.sqrt(np.diag(sol.covariance)))
        out.update({f"crlb_{k}": float(v) for k, v in zip(STATE_KEYS, crlb)})
    if out["message"] is not None:
        out["message"] = " ".join(str(out["message"]).split())  # one line (a CSV field)
    return out


def render_trial(scenario: dict, seed: int) -> dict:
    """One rendered trial: render (or reuse this worker's last render of the same key), expose, solve.

    Parameters
    ----------
    scenario : dict
        ``camera``, ``pattern`` and :data:`RENDER_PARAMETERS` (labels ignored).
    seed : int
        Seeds the exposure's noise draw.

    Returns
    -------
    dict
        :data:`RENDER_OUTPUTS`: ``ok``, ``reason``, ``message``, ``n_blobs``; ``true_*``,
        ``est_*`` (m, deg; the camera's perspective centre in the target frame and the paper's
        attitude) and the errors of :mod:`sim.metrics` (``err_*``, ``pos_err_norm_m``,
        ``rot_err_deg``; None when unsolved); ``residual_rms_px``; ``min_separation_px``
        (closest pair of true image points); ``crlb_*`` (Cramer-Rao 1-sigma for 0.1 px
        centroid noise, at the estimate); ``exposure_s_used``, ``iso_used``; ``expose_s``,
        ``solve_s`` (wall times).
    """
    frame, exposers = _frame(render_key(scenario))
    return _solve_one(scenario, seed, frame, exposers)


def render_group(scenarios, seeds) -> list[dict]:
    """Trials sharing one render key: render once, expose and solve each."""
    frame, exposers = _frame(render_key(scenarios[0]))
    return [_solve_one(s, int(k), frame, exposers) for s, k in zip(scenarios, seeds)]


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
    description="Mitsuba render of the target under the flash (pose, lab, pattern scale), exposures through the "
                "phone model (forced exposure, ND filter), SVGS detector and solver (with calibration errors)",
    module=__name__,
))
