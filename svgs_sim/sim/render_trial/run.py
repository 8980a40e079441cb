"""What a ``render`` trial computes: the frame rendered once per :class:`RenderKey` (cached), its
exposures through the phone's image path, the detector and the solver, the errors; the kind's
registration.

Part of :mod:`svgs_sim.sim.render_trial`.
"""

from __future__ import annotations

import dataclasses
import functools
import time
from collections import OrderedDict

import numpy as np

from svgs_sim.camera.rendered import PointFlux
from svgs_sim.render.optics import Optics
from svgs_sim.render.variant import select_variant
from svgs_sim.sim.closed_loop import render_scenario, solve_exposure, solver_camera
from svgs_sim.sim.crlb import centroid_crlb_px, pose_crlb
from svgs_sim.sim.metrics import (
    ATT_ERR_VEC_DEG, ERR_KEYS, POS_ERR_NORM_M, POS_ERR_VEC_M, ROT_ERR_DEG, match_err_max_px, spot_positions_px,
    pose_errors, spot_radius_px, state_m_deg,
)
from svgs_sim.sim.render_trial.scenario import (
    RENDER_OUTPUTS,
    RENDER_PARAMETERS,
    SOURCE_SWITCHES,
    RenderKey,
    RenderScenario,
    render_key,
)
from svgs_sim.sim.trials import TrialKind, camera_with_calibration_errors, register_trial_kind
from svgs_sim.sim.turbulence import image_shifts_px
from svgs_sim.svgs.app import consistency
from svgs_sim.svgs.frames import STATE_KEYS
from svgs_sim.svgs.envelope import PAPER_ENVELOPE
from svgs_sim.svgs.pipeline import solve_image


def merge_margin_dn(image: np.ndarray, targets_px: np.ndarray, threshold: float, step_px: float = 0.25) -> float:
    """How far the spots are from merging at the detector's threshold, image counts.

    For every pair of targets the darkest level of the image along the segment between their
    true positions (bilinear, ``step_px`` apart) is their saddle; ``threshold - saddle`` is the
    pair's margin: positive, the two spots are separate blobs at that threshold; negative, the
    binary image joins them (along that line). Returns the smallest margin over the pairs.

    Parameters
    ----------
    image : ndarray, shape (H, W)
        The delivered image (8-bit or float counts).
    targets_px : ndarray, shape (N, 2)
        True target positions in that image, px.
    threshold : float
        The detector's binarisation level, counts.
    """
    import cv2

    g = np.asarray(image, np.float32)
    if g.ndim == 3:
        g = g.mean(axis=2)
    out = np.inf
    n = len(targets_px)
    for a in range(n):
        for b in range(a + 1, n):
            p, q = np.asarray(targets_px[a], float), np.asarray(targets_px[b], float)
            m = max(2, int(np.ceil(np.linalg.norm(q - p) / step_px)))
            s = np.linspace(0.0, 1.0, m + 1)[1:-1]
            xy = p[None] + s[:, None] * (q - p)[None]
            vals = cv2.remap(g, xy[:, 0].astype(np.float32).reshape(1, -1), xy[:, 1].astype(np.float32).reshape(1, -1),
                             cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)
            out = min(out, float(threshold - vals.min()))
    return float(out)


@functools.lru_cache(maxsize=2)
def _frame(key: RenderKey):

    return render_scenario(key.scenario(), seed=key.render_seed), {}


def rendered_frame(scenario):
    """The rendered frame of a ``render`` scenario (:class:`svgs_sim.sim.closed_loop.Frame`), from this
    process's render cache: the trials of one render group share it."""
    return _frame(render_key(scenario))[0]


def _glare_key(scenario: RenderScenario) -> tuple:
    """What decides the exposer of a trial (after the render): ND filter, the lens' glare and the
    colour filter array."""
    return (scenario.target_scale, scenario.glare, scenario.glare_veiling_fraction, scenario.glare_wing_exponent,
            scenario.cfa)


def _exposer(frame, cache: dict, key: tuple):
    k = ("exposer", *key)
    if k not in cache:
        ts, glare, veil, expo, cfa = key
        cache[k] = frame.exposer(exposure_stages({"cfa": cfa}), target_scale=ts, glare=glare, veiling_fraction=veil,
                                 wing_exponent=expo)
    return cache[k]


def exposure_stages(scenario) -> tuple:
    """The exposure's stages: every stage, less those the error-budget switches turn off (absent
    switches: on). ``scenario``: a mapping of row values (a scenario's row view)."""
    from svgs_sim.camera.phone import ALL_STAGES, NOISE_STAGES

    off = set()
    if not scenario.get("sensor_noise", 1):
        off |= set(NOISE_STAGES)
    if not scenario.get("quantise", 1):
        off |= {"u8", "jpeg"}
    off |= {k for k in ("cfa", "nr", "sharpen", "chroma", "jpeg") if not scenario.get(k, 1)}
    return tuple(s for s in ALL_STAGES if s not in off)


def exposure_isp(exposer, scenario: RenderScenario) -> tuple:
    """``(isp, demosaic)`` of a trial's exposure: the profile's ``[isp]`` with the scenario's JPEG
    quality and block-grid offset, and its demosaic (None: the profile's)."""
    scenario = RenderScenario.from_row(scenario)
    isp = exposer.phone.params.isp
    q = scenario.jpeg_quality
    ox, oy = isp.jpeg_grid_offset_px
    du, dv = scenario.jpeg_grid_offset_u_px, scenario.jpeg_grid_offset_v_px
    new = dataclasses.replace(isp, jpeg_quality=isp.jpeg_quality if q is None else q,
                              jpeg_grid_offset_px=((ox + du) % 16, (oy + dv) % 16))
    return (isp if new == isp else new), scenario.demosaic


def _sensor_centroid_sigma(frame, exposer, row, cache: dict, key, spots_px) -> float | None:
    """The simulated sensor's centroid bound (RMS over the spots, px; :func:`svgs_sim.sim.crlb.centroid_crlb_px`)
    at the targets' true positions, once per exposer and exposure setting: it depends on the
    render and the exposure, not on the noise draw (so not on which trial of a group asks first).
    None when a spot carries no information."""

    k = ("crlb", *key, row["exposure_s"], row["iso"])
    if k not in cache:
        sig = centroid_crlb_px(frame, exposer, row["_exposure"], spots_px)
        cache[k] = float(np.sqrt(np.mean(sig**2))) if np.all(np.isfinite(sig)) else None
    return cache[k]


#: Exposures kept per render group, so that variants judged differently (the solver's
#: calibration, the truth) reuse the same image instead of exposing it again.
_EXPOSURE_CACHE = 12


def turbulent_points(frame, cn2_m23: float, seed: int):
    """The frame's retro-spot samples as one exposure through the lab's air sees them: each
    spot's samples moved by a frozen draw of its angle of arrival (:mod:`svgs_sim.sim.turbulence`; the
    phone's entrance pupil, the spots at the actual pose), seeded by the exposure's seed on a
    stream of its own (the sensor noise's draw unchanged). A sample belongs to the spot whose
    true image point is nearest.

    Returns
    -------
    points : svgs_sim.camera.rendered.PointFlux
    shifts_px : ndarray, shape (N, 2)
        Each target's image motion ``(du, dv)``, px.
    """

    cam = frame.camera
    R, t = frame.scenario.pose()
    pat = frame.pattern
    p_cam = pat.points_m @ R.T + t
    aperture_m = 2.0 * Optics.from_camera(cam).aperture_radius_m  # the entrance pupil's diameter
    rng = np.random.default_rng([int(seed), 0x7475726E])  # "turn": the air's own stream
    shifts = image_shifts_px(p_cam, cam.fx, aperture_m, float(cn2_m23), rng)
    uv = cam.project_target(pat.points_m, R, t)
    pts = frame.points
    near = np.argmin((pts.u_px[:, None] - uv[None, :, 0]) ** 2 + (pts.v_px[:, None] - uv[None, :, 1]) ** 2, axis=1)
    return PointFlux(pts.u_px + shifts[near, 0], pts.v_px + shifts[near, 1], pts.rate_ph_s), shifts


def _exposure_exposer(frame, exposers: dict, gkey, scenario: RenderScenario, seed: int):
    """The exposer of one exposure: the render group's, or - through turbulent air - one made
    for this exposure's moved spots (its optics redone)."""
    exposer = _exposer(frame, exposers, gkey)
    cn2 = scenario.turbulence_cn2
    if cn2 == 0 or frame.points is None:
        return exposer
    pts, _ = turbulent_points(frame, cn2, seed)
    ts, glare, veil, expo, cfa = gkey
    return dataclasses.replace(frame, points=pts).exposer(exposure_stages({"cfa": cfa}), target_scale=ts, glare=glare,
                                                         veiling_fraction=veil, wing_exponent=expo)


def _exposure(frame, exposers: dict, key, scenario: RenderScenario, seed: int):
    """The exposure of ``(render, seed, stages, setting, air)``, made once per render group."""


    store = exposers.setdefault("exposures", OrderedDict())
    ev = scenario.exposure_compensation_ev
    isp, demosaic = exposure_isp(_exposer(frame, exposers, key), scenario)
    cn2 = scenario.turbulence_cn2
    k = (key, int(seed), exposure_stages(scenario), scenario.exposure_s, scenario.iso, ev, isp, demosaic, cn2)
    if k in store:
        store.move_to_end(k)
        return store[k], 0.0
    t0 = time.perf_counter()
    exposer = _exposure_exposer(frame, exposers, key, scenario, seed)
    t_s, iso = scenario.exposure_s, scenario.iso
    if ev != 0:  # exposure compensation: the time the phone would choose, times 2^EV
        t_s, iso, _ = exposer.settings(t_s, iso)
        t_s *= 2.0 ** ev
    ex = exposer.expose(seed=int(seed), exposure_s=t_s, iso=iso, stages=exposure_stages(scenario), isp=isp, demosaic=demosaic)
    dt = time.perf_counter() - t0
    store[k] = ex
    while len(store) > _EXPOSURE_CACHE:
        store.popitem(last=False)
    return ex, dt


def _is_baseline(scenario: RenderScenario) -> bool:
    """Every error-budget switch on (the default; the sensor bound is computed for these only)."""
    return all(getattr(scenario, k) for k in SOURCE_SWITCHES)


def _centroid_columns(out: dict, found_px, cam, row: dict, pat, R, t) -> None:
    """The centroids' error: identified centroids ``found_px`` (shape (N, 2), the pattern's order)
    against the targets' true projections (the true lens, the actual pose), in the delivered
    image's pixels: ``centroid_err_rms_px`` and ``cen_du_px_k``, ``cen_dv_px_k`` of the first four."""
    uv_img = solver_camera(cam, row["_exposure"].image.shape).project_target(pat.points_m, R, t)
    d = np.asarray(found_px, float) - uv_img
    out["centroid_err_rms_px"] = float(np.sqrt(np.mean(d ** 2)))
    for k, (du, dv) in enumerate(d[:4]):
        out[f"cen_du_px_{k}"], out[f"cen_dv_px_{k}"] = float(du), float(dv)


def _state_array(state: dict) -> np.ndarray:
    """A state keyed by :data:`svgs_sim.svgs.frames.STATE_KEYS` (m, deg) as the paper state (m, rad), shape (6,)."""
    v = np.array([float(state[k]) for k in STATE_KEYS])
    v[3:] = np.radians(v[3:])
    return v


def _solve_one(scenario: RenderScenario, seed: int, frame, exposers: dict) -> dict:

    cam = frame.camera  # the true lens
    gkey = _glare_key(scenario)
    exposer = _exposer(frame, exposers, gkey)
    ex, expose_s = _exposure(frame, exposers, gkey, scenario, seed)
    row = solve_exposure(frame, ex, threshold=scenario.threshold,
                         solver_camera_profile=camera_with_calibration_errors(cam, scenario),
                         truth=scenario.truth)
    row["expose_s"] = expose_s
    out = {k: None for k in RENDER_OUTPUTS}
    out.update({k: row[k] for k in ("ok", "reason", "message", "n_blobs", "residual_rms_px", "chi2", "chi2_dof",
                                    "p_value", "expose_s", "solve_s", POS_ERR_NORM_M, ROT_ERR_DEG)})
    out["ok"] = bool(row["ok"])
    out["outside_test_envelope"] = row["outside_test_envelope"]
    out["exposure_s_used"], out["iso_used"] = float(row["exposure_s"]), float(row["iso"])
    out.update({f"true_{k}": v for k, v in row["truth_state"].items()})
    R, t = frame.scenario.pose()
    pat = frame.pattern
    uv = cam.project_target(pat.points_m, R, t)
    d = np.linalg.norm(uv[:, None] - uv[None], axis=-1) + np.eye(len(uv)) * 1e12
    out["min_separation_px"] = float(d.min())
    sol = row["_solution"]
    level = sol.threshold_used if sol else sol.details.get("threshold_used")
    if level is not None:
        img = ex.image
        out["merge_margin_dn"] = merge_margin_dn(img, solver_camera(cam, img.shape).project_target(pat.points_m, R, t),
                                                 float(level))
    if row["state"] is not None:
        out.update({f"est_{k}": v for k, v in row["state"].items()})
        out.update(dict(zip(ERR_KEYS, [*row[POS_ERR_VEC_M], *row[ATT_ERR_VEC_DEG]])))
        # Cramer-Rao 1-sigma for the solver's default centroid noise (0.1 px)
        crlb = state_m_deg(np.sqrt(np.diag(sol.covariance)))
        out.update({f"crlb_{k}": float(v) for k, v in zip(STATE_KEYS, crlb)})
        _centroid_columns(out, np.array([sol.targets_px[i] for i in pat.ids], float), cam, row, pat, R, t)
        # the bound from the simulated sensor at this exposure (svgs_sim.sim.crlb)
        rms = (_sensor_centroid_sigma(frame, exposer, row, exposers, gkey, uv) if _is_baseline(scenario) and
               frame.points is not None else None)
        if rms is not None:

            out["crlb_centroid_px"] = rms
            # the consistency test against the sensor's bound alone (what the residual would be
            # judged by if the centroids were as good as the CRLB): reported, not applied

            out["p_value_crlb"] = consistency(sol.residual_rms_px, len(pat.ids), sigma_px=rms).p_value
            out.update({f"crlb_sensor_{k}": float(v) for k, v in pose_crlb(sol, rms).items()})
    elif row["reason"] == "inconsistent" and "state" in sol.details:
        # the pose the paper's app would have reported (it had no consistency test): kept beside
        # ok 0 / reason inconsistent, so that a study can score the app as published
        out.update({f"est_{k}": float(v) for k, v in sol.details["state"].items()})
        e = pose_errors(_state_array(sol.details["state"]), _state_array(row["truth_state"]))
        out.update(dict(zip(ERR_KEYS, [*e[POS_ERR_VEC_M], *e[ATT_ERR_VEC_DEG]])))
        targets = sol.details.get("targets_px") or {}
        if all(str(i) in targets for i in pat.ids):
            _centroid_columns(out, np.array([targets[str(i)] for i in pat.ids], float), cam, row, pat, R, t)
    _clutter(out, row, sol, cam, pat, R, t, level, frame.truth.get("spots_px_predicted"))
    if scenario.scene.environment == "orbit":
        _paper_gates(out, row, scenario, cam, pat, R, t, frame.truth.get("spots_px_predicted"))
    if out["message"] is not None:
        out["message"] = " ".join(str(out["message"]).split())  # one line (a CSV field)
    return out


#: Pixels this far beyond a target's spot (its cube's image radius) are "away from the targets", px.
STRAY_MARGIN_PX = 10.0


def _clutter(out: dict, row: dict, sol, cam, pat, R, t, level, spots_px=None) -> None:
    """What else the sensor saw, for the on-orbit studies: ``match_err_max_px`` (the largest distance
    of an identified blob from its target's spot, px - the renderer's predicted spot centroid, which
    the flash's offset from the lens moves off the target's projection by a few pixels at close range
    - for a solution the app would report: solved, or refused only by the consistency test; else
    None), ``stray_px`` (pixels at or above the detector's threshold away from every target's spot:
    a lit body, a glint, the sun) and ``stray_saturated_px`` (those at full scale)."""
    img = row["_exposure"].image
    uv = spot_positions_px(solver_camera(cam, img.shape), pat, R, t, spots_px, img.shape[1] / cam.width)
    out["match_err_max_px"] = match_err_max_px(row, sol, uv, pat.ids)
    if level is None:
        return
    gray = img if img.ndim == 2 else img.max(axis=2)
    v, u = np.nonzero(gray >= float(level))
    z = (np.asarray(pat.points_m, float) @ np.asarray(R, float).T + t)[:, 2]
    radius = spot_radius_px(cam, pat, z) * (img.shape[1] / cam.width) + STRAY_MARGIN_PX
    if u.size:
        d = np.hypot(u[:, None] - uv[None, :, 0], v[:, None] - uv[None, :, 1]) - radius[None, :]
        away = np.all(d > 0, axis=1)
        out["stray_px"] = int(away.sum())
        full = 255 if img.dtype == np.uint8 else float(np.max(gray))
        out["stray_saturated_px"] = int(np.sum(gray[v[away], u[away]] >= full))
    else:
        out["stray_px"] = out["stray_saturated_px"] = 0


def _paper_gates(out: dict, row: dict, scenario, cam, pat, R, t, spots_px=None) -> None:
    """The same image solved with the identification's gates of earlier versions (the paper's test
    envelope, :data:`svgs_sim.svgs.envelope.PAPER_ENVELOPE`) instead of the physical envelope, for the
    on-orbit studies' wrong locks before and after: ``paper_gates_reported`` (a pose the app would
    report: solved, or refused only by the consistency test) and ``paper_gates_match_err_max_px``
    (as ``match_err_max_px``)."""
    img = row["_exposure"].image
    scam = camera_with_calibration_errors(cam, scenario)
    sol = solve_image(img, solver_camera(scam, img.shape), pat, threshold=scenario.threshold,
                      identify_options={"envelope": PAPER_ENVELOPE})
    alt = {"state": sol.state_dict if sol else None, "reason": None if sol else sol.reason, "_exposure": row["_exposure"]}
    tmp = {"match_err_max_px": None}
    _clutter(tmp, alt, sol, cam, pat, R, t, None, spots_px)
    out["paper_gates_reported"] = bool(sol) or sol.reason == "inconsistent"
    out["paper_gates_match_err_max_px"] = tmp["match_err_max_px"]


def trial_picture(scenario, seed: int) -> dict:
    """What one trial's sensor saw, for pictures (``overlay.png`` panels of the study reports):
    the same render, exposure and solve as :func:`render_trial` (same seeds, same numbers).

    Returns
    -------
    dict
        ``image`` (the delivered image), ``camera`` (the solver's, at the image's size),
        ``pattern``, ``threshold`` and ``row`` (:func:`svgs_sim.sim.closed_loop.solve_exposure`'s row,
        ``_solution`` included).
    """

    scenario = RenderScenario.from_row(scenario)
    frame, exposers = _frame(RenderKey.of(scenario))
    gkey = _glare_key(scenario)
    ex, _ = _exposure(frame, exposers, gkey, scenario, seed)
    cam_solver = camera_with_calibration_errors(frame.camera, scenario)
    thr = scenario.threshold
    row = solve_exposure(frame, ex, threshold=thr, solver_camera_profile=cam_solver, truth=scenario.truth)
    return {"image": ex.image, "camera": solver_camera(cam_solver, ex.image.shape),
            "pattern": frame.pattern, "threshold": thr, "row": row}


def render_trial(scenario, seed: int) -> dict:
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
        attitude) and the errors of :mod:`svgs_sim.sim.metrics` (``err_*``, ``pos_err_norm_m``,
        ``rot_err_deg``; None when unsolved); ``residual_rms_px``; ``min_separation_px``
        (closest pair of true image points); ``merge_margin_dn`` (the detector's threshold minus
        the darkest level between the targets, image counts: negative, the spots join;
        :func:`merge_margin_dn`); ``crlb_*`` (Cramer-Rao 1-sigma for 0.1 px centroid noise, at
        the estimate); ``cen_du_px_k``, ``cen_dv_px_k``, ``centroid_err_rms_px`` (the identified
        centroids of the first four targets minus their true projections, px, in the delivered
        image); ``crlb_centroid_px``, ``crlb_sensor_*`` (the simulated sensor's centroid bound at
        the targets' true positions and the pose bound at this trial's solution, :mod:`svgs_sim.sim.crlb`;
        with every error source on only); ``exposure_s_used``,
        ``iso_used``; ``expose_s``, ``solve_s`` (wall times).
    """
    scenario = RenderScenario.from_row(scenario)
    frame, exposers = _frame(RenderKey.of(scenario))
    return _solve_one(scenario, seed, frame, exposers)


def _exposure_order(scenario: RenderScenario, seed: int) -> tuple:
    """What decides a trial's exposure within its render group (:func:`_exposure`'s key, less
    the exposer's own): trials that judge one image differently (the solver's calibration, the
    truth) sort together, so each exposure is made once however many variants share it."""
    return (repr(_glare_key(scenario)), int(seed), exposure_stages(scenario), scenario["exposure_s"], scenario["iso"],
            scenario["exposure_compensation_ev"], scenario["jpeg_quality"], scenario["jpeg_grid_offset_u_px"],
            scenario["jpeg_grid_offset_v_px"], scenario["demosaic"], scenario["turbulence_cn2"])


def render_group(scenarios, seeds) -> list[dict]:
    """Trials sharing one render key: render once, expose and solve each (in the order that
    shares exposures, :func:`_exposure_order`; the rows come back in the given order - a trial's
    numbers depend only on its scenario and seed)."""
    scenarios = [RenderScenario.from_row(s) for s in scenarios]
    frame, exposers = _frame(RenderKey.of(scenarios[0]))
    order = sorted(range(len(scenarios)), key=lambda i: _exposure_order(scenarios[i], seeds[i]))
    out = [None] * len(scenarios)
    for i in order:
        out[i] = _solve_one(scenarios[i], int(seeds[i]), frame, exposers)
    return out


def _warm_up():

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
    scenario_type=RenderScenario,
))
