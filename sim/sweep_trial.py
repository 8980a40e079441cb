"""The ``closed-loop`` trial kind: one exposure of a rendered scenario through the SVGS chain,
with the knobs of the range sweep and the exposure study.

Registers with :mod:`sim.trials`; ``studies.range_sweep`` and ``studies.exposure_study`` build
its scenarios and :func:`studies.execution.run_study` runs them. A trial is
:func:`sim.closed_loop.render_scenario` (Mitsuba, the lab light) followed by
:func:`sim.closed_loop.expose_and_solve` (phone model, detector, solver), exactly the chain of
``svgs render-and-solve``.

Render once, expose many
    The render key is everything that decides the rendered flux: camera, pattern and its
    scale, pose, lab, samples per pixel and the render's own Monte Carlo seed
    (``render_seed``, a scenario parameter, so trials sharing a render agree on it). What acts
    after the render - the noise draw (the trial's seed), a forced exposure or ISO, a
    neutral-density filter over the reflectors (``target_scale``), the detector threshold -
    varies within a render group. A trial's numbers depend only on its scenario and seed,
    whether it runs alone or in a group.

Scenario keys
    Text: ``camera``, ``pattern`` (name or path), ``threshold`` (``auto``, ``otsu`` or a
    level in 8-bit counts). Numbers: :data:`SWEEP_PARAMETERS`. Studies add labels
    (``pose_index``, ``trial``, ``remedy``...) carried into the rows unchanged.
"""

from __future__ import annotations

import functools
import tempfile
from pathlib import Path

import numpy as np

from sim.metrics import (
    ATT_ERR_VEC_DEG,
    ERR_KEYS,
    POS_ERR_NORM_M,
    POS_ERR_VEC_M,
    ROT_ERR_DEG,
)
from sim.trials import GEOMETRIC_PARAMETERS, Parameter, TrialKind, register_trial_kind
from svgs.errors import InputError
from svgs.frames import STATE_KEYS

_POSE = ("range_m", "target_x_m", "target_y_m", "roll_deg", "pitch_deg", "yaw_deg")

SWEEP_PARAMETERS = {
    **{k: GEOMETRIC_PARAMETERS[k] for k in _POSE},
    "backdrop_distance_m": Parameter("backdrop_distance_m", "m", "grey backdrop behind the target (0: none)", 3.0, True,
                                     lower=0.0),
    "ambient_radiance_w_m2_sr": Parameter("ambient_radiance_w_m2_sr", "W m^-2 sr^-1",
                                          "uniform ambient scene radiance from room lights, in band", 0.0, True, lower=0.0),
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
}

SWEEP_OUTPUTS = (
    "ok", "reason", "message", "n_blobs",
    *(f"true_{k}" for k in STATE_KEYS),
    *(f"est_{k}" for k in STATE_KEYS),
    *ERR_KEYS, POS_ERR_NORM_M, ROT_ERR_DEG,
    "residual_rms_px", "exposure_s_used", "iso_used", "expose_s", "solve_s",
)

#: Outputs that are timings (they differ from run to run; every other output is reproducible).
SWEEP_TIMING_OUTPUTS = ("expose_s", "solve_s")


def check_threshold(text) -> str:
    """A ``threshold`` scenario value: ``auto``, ``otsu`` or a non-negative level (as text)."""
    t = "auto" if text is None else str(text).strip()
    if t in ("auto", "otsu"):
        return t
    try:
        v = float(t)
    except ValueError:
        raise InputError(f"--threshold: expected a number, 'auto' or 'otsu', got {text!r}") from None
    if not np.isfinite(v) or v < 0:
        raise InputError(f"--threshold: expected a non-negative finite level, got {text!r}")
    return repr(v)


def _threshold(text):
    t = check_threshold(text)
    return None if t == "auto" else (t if t == "otsu" else float(t))


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


def sweep_scenario(labels: dict | None = None, **values) -> dict:
    """A complete, validated ``closed-loop`` scenario: defaults filled in, domains checked.

    Parameters
    ----------
    labels : dict, optional
        Extra keys carried into the rows unchanged (``pose_index``, ``trial``, ``remedy``...).
    **values
        ``camera`` (required), ``pattern`` (default ``svgs-3u``), ``threshold`` (default
        ``auto``) and :data:`SWEEP_PARAMETERS`; an unknown key is an :class:`InputError`.
    """
    from sim.trials import build_scenario

    threshold = check_threshold(values.pop("threshold", None))
    scen = build_scenario(CLOSED_LOOP, values)
    for k in ("spp", "roi_spp", "render_seed"):
        if scen[k] != int(scen[k]):
            raise InputError(f"{k}: expected an integer, got {scen[k]!r}")
    if scen["roi_spp"] == 0:
        raise InputError("roi_spp: expected >= 1 (or -1: the renderer's default), got 0")
    out = {"camera": scen.pop("camera"), "pattern": scen.pop("pattern"), "threshold": threshold, **scen}
    for k, v in (labels or {}).items():
        if k in out:
            raise InputError(f"scenario label {k!r} clashes with a parameter")
        out[k] = v
    return out


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

    row = expose_and_solve(frame, _exposer(frame, exposers, float(scenario["target_scale"])), seed=int(seed),
                           threshold=_threshold(scenario["threshold"]),
                           exposure_s=scenario["exposure_s"] or None, iso=scenario["iso"] or None)
    out = {k: None for k in SWEEP_OUTPUTS}
    out.update({k: row[k] for k in ("ok", "reason", "message", "n_blobs", "residual_rms_px", "expose_s", "solve_s",
                                    POS_ERR_NORM_M, ROT_ERR_DEG)})
    out["ok"] = bool(row["ok"])
    out["exposure_s_used"], out["iso_used"] = float(row["exposure_s"]), float(row["iso"])
    out.update({f"true_{k}": v for k, v in row["truth_state"].items()})
    if row["state"] is not None:
        out.update({f"est_{k}": v for k, v in row["state"].items()})
        out.update(dict(zip(ERR_KEYS, [*row[POS_ERR_VEC_M], *row[ATT_ERR_VEC_DEG]])))
    if out["message"] is not None:
        out["message"] = " ".join(str(out["message"]).split())  # one line (a CSV field)
    return out


def sweep_trial(scenario: dict, seed: int) -> dict:
    """One closed-loop trial: render (or reuse this worker's last render of the same key), expose, solve.

    Parameters
    ----------
    scenario : dict
        ``camera``, ``pattern``, ``threshold`` and :data:`SWEEP_PARAMETERS` (labels ignored).
    seed : int
        Seeds the exposure's noise draw.

    Returns
    -------
    dict
        :data:`SWEEP_OUTPUTS`: ``ok``, ``reason``, ``message``, ``n_blobs``; ``true_*``,
        ``est_*`` (m, deg; the camera's perspective centre in the target frame and the paper's
        attitude) and the errors of :mod:`sim.metrics` (``err_*``, ``pos_err_norm_m``,
        ``rot_err_deg``; None when unsolved); ``residual_rms_px``; ``exposure_s_used``,
        ``iso_used``; ``expose_s``, ``solve_s`` (wall times).
    """
    frame, exposers = _frame(render_key(scenario))
    return _solve_one(scenario, seed, frame, exposers)


def sweep_group(scenarios, seeds) -> list[dict]:
    """Trials sharing one render key: render once, expose and solve each."""
    frame, exposers = _frame(render_key(scenarios[0]))
    return [_solve_one(s, int(k), frame, exposers) for s, k in zip(scenarios, seeds)]


def _warm_up():
    from render.variant import select_variant

    select_variant()


CLOSED_LOOP = register_trial_kind(TrialKind(
    name="closed-loop",
    run_trial=sweep_trial,
    outputs=SWEEP_OUTPUTS,
    parameters=SWEEP_PARAMETERS,
    text_keys=("camera", "pattern", "threshold"),
    run_group=sweep_group,
    render_key=render_key,
    warm_up=_warm_up,
    description="Mitsuba render of a scenario (pose, lab, pattern scale), exposures through the phone model "
                "(forced exposure, ND filter), SVGS detector and solver",
    module=__name__,
))
