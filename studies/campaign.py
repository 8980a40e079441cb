"""The 2014 MSFC Flight Robotics Lab campaign of Becker, Howard & Rakoczy, simulated.

Test set-up (paper, "Test Setup")
    The phone sits on the Sensor Mount: a 3-axis gimbal (roll and pitch +/-25 deg, yaw
    +/-45 deg) on a 1-axis translation stage (+/-15 cm along the line between the mounts),
    carried on a cart along a rail to each test range. The Target Mount stays fixed.

Simulated campaign
    At each of the paper's ranges for the phone (Amaze 4G: 1, 2, 3, 4, 6.5 m; Galaxy Nexus:
    5, 10, 15, 20, 30 m) run ``trials`` trials; trial ``i`` draws its gimbal attitude
    uniformly in the envelope and its stage position uniformly in +/-15 cm (its own stream,
    :func:`studies.seeding.design_rng`). The attitude is the paper's relative attitude
    (roll, pitch, yaw = phi, theta, psi) with the target origin on the boresight
    (:func:`svgs.frames.pose_from_scenario`): the campaign measured the target in view.

Statistics (paper Tables 2-5)
    The paper does not define "mean error". It is computed three ways per component: |mean e|
    (the magnitude of the signed mean, the verdicts' headline reading), mean |e| and RMS
    (:data:`studies.error_budget.HEADLINE_REASON` says why the headline is |mean e|); the
    standard deviation is that of the signed error (ddof = 1). Each is put beside the paper's
    numbers (``assets/data/svgs_2014_results.csv``) with the simulated/paper ratio. The
    Cramer-Rao bound per range is the median over trials of the solver's 1-sigma bound for the
    trial's centroid noise.

The honest count
    :func:`fitted_values_table` lists every fitted value (and chosen app setting) that applies
    to the campaign, what it was fitted to and the cells of Tables 2-5 it consumes
    (:data:`FIT_USES`); consumed cells get the verdict ``fitted`` and are not counted as
    reproduced. Counts are given under each reading (:func:`honest_counts`). A cell outside 2x
    is explained only by a source measured by switching it off (the error budget), otherwise it
    is ``unexplained`` with its size (:func:`studies.error_budget.cell_verdicts`).
    :func:`rebuild_report` (``python -m studies.campaign rebuild DIR``) rewrites a finished
    campaign's report and tables from its stored results without running a trial.

Calibration practice (``calibration="paper"``)
    The paper calibrated only "a rough approximation of each camera's focal length" from
    images at known ranges and assumed nothing about the principal point and distortion.
    With ``paper``, one calibration is made per campaign (seeded) and used by the solver in
    every trial: the focal length by simulating that procedure (:func:`paper_calibration_error`:
    images at the campaign's ranges, ranges from a hand-held range finder with an ASSUMED
    2 cm 1-sigma error, :func:`calibration.focal.estimate_focal`), the principal point and k1
    off by draws from ASSUMED spreads (15 px per axis, 0.03).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from svgs.errors import InputError

from .error_budget import HEADLINE_READING, MEAN_READINGS, READING_LABELS
from .seeding import check_seed, design_rng, study_rng, trial_seed
from assets.papers import svgs_2014_results
from sim.trials import build_scenario, get_trial_kind
from svgs.frames import STATE_KEYS

#: The paper's Sensor Mount envelope.
GIMBAL_ROLL_DEG = 25.0
GIMBAL_PITCH_DEG = 25.0
GIMBAL_YAW_DEG = 45.0
STAGE_HALF_TRAVEL_M = 0.15

#: The ranges of the paper's Tables 2-5, per phone profile.
PAPER_RANGES_M = {"htc-amaze-4g": (1.0, 2.0, 3.0, 4.0, 6.5), "galaxy-nexus": (5.0, 10.0, 15.0, 20.0, 30.0)}

#: ASSUMED 1-sigma differences between the paper's assumed camera (principal point at the image
#: centre, no distortion) and the real lens. Not sourced: typical of phone cameras of 2011
#: (principal points within ~1 % of the width of the centre, mild barrel distortion).
PAPER_CALIBRATION_SPREAD = {"pp_error_u_px": 15.0, "pp_error_v_px": 15.0, "k1_error": 0.03}
CALIBRATION_KEYS = ("focal_error_frac", "pp_error_u_px", "pp_error_v_px", "k1_error")


COMPONENT_LABELS = {"x_m": "X (m)", "y_m": "Y (m)", "z_m": "Z (m)",
                    "roll_deg": "roll (deg)", "pitch_deg": "pitch (deg)", "yaw_deg": "yaw (deg)"}
SHORT = {"x_m": "X", "y_m": "Y", "z_m": "Z", "roll_deg": "roll", "pitch_deg": "pitch", "yaw_deg": "yaw"}


@dataclass(frozen=True)
class CampaignConfig:
    """What a campaign computes (its manifest); how it runs is not part of it."""

    camera: str
    ranges_m: tuple
    trials_per_range: int = 200
    seed: int = 0
    sigma_px: float = 0.1
    trial_kind: str = "geometric"
    pattern: str = "svgs-3u"
    calibration: str = "exact"
    calibration_error: dict = field(default_factory=dict)
    merge_px: float = 0.0
    exposures_per_render: int = 4
    misalignment_deg: tuple = (0.0, 0.0, 0.0)
    lens: dict = field(default_factory=dict)
    budget: bool = False
    lab_errors: dict = field(default_factory=dict)
    calibration_info: dict = field(default_factory=dict, compare=False)

    def lab_error(self, key: str) -> float:
        """One of the lab's error sources (:data:`sim.lab.ERROR_KEYS`; 0: absent)."""
        return float(self.lab_errors.get(key, 0.0))

    @property
    def poses_per_range(self) -> int:
        """Distinct stand settings (renders) per range: ``ceil(trials_per_range / exposures_per_render)``."""
        return -(-self.trials_per_range // self.exposures_per_render)

    def manifest(self) -> dict:
        return {
            "study": "campaign",
            "camera": self.camera,
            "pattern": self.pattern,
            "ranges_m": [float(r) for r in self.ranges_m],
            "trials_per_range": int(self.trials_per_range),
            "seed": int(self.seed),
            "sigma_px": float(self.sigma_px),
            "trial_kind": self.trial_kind,
            "calibration": self.calibration,
            "calibration_error": {k: float(v) for k, v in sorted(self.calibration_error.items())},
            "merge_px": float(self.merge_px),
            "envelope": {"roll_deg": GIMBAL_ROLL_DEG, "pitch_deg": GIMBAL_PITCH_DEG, "yaw_deg": GIMBAL_YAW_DEG,
                         "stage_m": STAGE_HALF_TRAVEL_M, "in_view": "sim.stand.sample_in_view"},
            "exposures_per_render": int(self.exposures_per_render),
            "misalignment_deg": [float(x) for x in self.misalignment_deg],
            "lens": {k: float(v) for k, v in sorted(self.lens.items())},
            "budget": bool(self.budget),
            "lab_errors": {k: float(v) for k, v in sorted(self.lab_errors.items())},
        }


def paper_calibration_error(camera, pattern, ranges_m, sigma_px: float, seed: int,
                            range_sigma_m: float | None = None) -> dict:
    """One calibration as the paper made it, simulated (seeded, once per campaign).

    Focal length: the paper's procedure - one image of the target facing the camera at each
    test range, the range measured with a hand-held laser range finder (1-sigma
    ``range_sigma_m``, default :func:`sim.lab.lab_errors`' ``rangefinder_sigma_m``; the paper leaves it blank), the focal
    length fitted to the spot spacings (:func:`calibration.focal.estimate_focal`) from
    centroids with ``sigma_px`` noise. Principal point and k1: the paper assumed the image
    centre and no distortion; the real lens differs by draws from
    :data:`PAPER_CALIBRATION_SPREAD` (ASSUMED spreads).

    Returns
    -------
    dict
        ``focal_error_frac``, ``pp_error_u_px``, ``pp_error_v_px``, ``k1_error``.
    """
    from calibration.focal import estimate_focal
    from svgs.frames import pose_from_scenario

    from svgs.profiles import load_pattern as _pattern

    if range_sigma_m is None:
        from sim.lab import lab_errors

        range_sigma_m = lab_errors()["rangefinder_sigma_m"]
    pat = _pattern(pattern)
    rng = study_rng(seed, 0)
    images, measured = [], []
    for r in ranges_m:
        R, t = pose_from_scenario(r)
        uv = camera.project_target(pat.points_m, R, t)
        images.append(uv + sigma_px * rng.standard_normal(uv.shape))
        measured.append(r + range_sigma_m * rng.standard_normal())
    est = estimate_focal(images, measured, camera, pat, centroid_sigma_px=max(sigma_px, 1e-3),
                         range_sigma_m=max(range_sigma_m, 1e-4))
    err = {"focal_error_frac": float(est.f_px / camera.fx - 1.0)}
    for k in ("pp_error_u_px", "pp_error_v_px", "k1_error"):
        err[k] = float(rng.normal(0.0, PAPER_CALIBRATION_SPREAD[k]))
    return err


def paper_lens(seed: int) -> dict:
    """The true lens of a campaign with the paper's calibration practice: how its principal point
    and radial distortion differ from what the paper assumed (image centre, no distortion),
    drawn once per campaign from :data:`PAPER_CALIBRATION_SPREAD` (ASSUMED spreads).

    Returns
    -------
    dict
        ``lens_pp_u_px``, ``lens_pp_v_px`` (px), ``lens_k1``.
    """
    rng = study_rng(seed, 1)
    return {"lens_pp_u_px": float(rng.normal(0.0, PAPER_CALIBRATION_SPREAD["pp_error_u_px"])),
            "lens_pp_v_px": float(rng.normal(0.0, PAPER_CALIBRATION_SPREAD["pp_error_v_px"])),
            "lens_k1": float(rng.normal(0.0, PAPER_CALIBRATION_SPREAD["k1_error"]))}


def _count_option(value, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise InputError(f"{name}: expected a positive integer, got {value!r}")
    return int(value)


def make_config(camera: str, *, ranges_m=None, trials_per_range: int = 200, seed: int = 0, sigma_px: float = 0.1,
                trial_kind: str = "render", pattern: str = "svgs-3u", calibration: str = "paper",
                calibration_error: dict | None = None, merge_px: float = 0.0, exposures_per_render: int = 4,
                misalignment_deg=None, budget: bool = False, lab_errors: bool = True) -> CampaignConfig:
    """A validated :class:`CampaignConfig` (:class:`InputError` on bad input).

    Parameters
    ----------
    camera : str
        Camera profile name or path.
    ranges_m : sequence of float, optional
        Test ranges (the stand's rail positions); default the paper's for that phone
        (required for other cameras).
    trials_per_range : int
        Trials per range: ``ceil(trials / exposures_per_render)`` stand settings, each
        rendered once and exposed ``exposures_per_render`` times.
    trial_kind : {"render", "geometric"}
        ``render`` (default): Mitsuba render -> phone model -> SVGS; ``geometric``: the
        pattern projected with ``sigma_px`` of Gaussian centroid noise (fast).
    calibration : {"paper", "exact"}
        ``paper`` (default): the paper's practice - the true lens has a principal-point offset
        and a radial distortion (:func:`paper_lens`), the solver assumes the image centre, no
        distortion and a focal length estimated by the paper's method (from rendered frames
        for the render kind, :func:`rendered_paper_calibration`, in :func:`run_campaign`).
        ``exact``: the solver knows the camera, unless ``calibration_error`` says otherwise.
    calibration_error : dict, optional
        Explicit errors (``focal_error_frac``, ``pp_error_u_px``, ``pp_error_v_px``,
        ``k1_error``) for ``exact``.
    exposures_per_render : int
        Exposures (noise draws) per stand setting.
    misalignment_deg : sequence of 3 float, optional
        The phone's (roll, pitch, yaw) in its holder (:class:`sim.stand.TestStand`), deg.
        Default: the lab's for this phone (:func:`sim.lab.stand_misalignment_deg`: 2 deg of yaw
        for the Galaxy Nexus, fitted to Table 4; 0 for others).
    budget : bool
        Also run the error-budget variants (render kind; :mod:`studies.error_budget`).
    lab_errors : bool
        The lab's error sources (default; :func:`sim.lab.lab_errors`, sourced): each stand
        setting's gimbal and stage errors, the rail position recorded from the rangefinder
        (whose readings also feed the paper's focal calibration) and, for the render kind, the
        air's turbulence. False: a perfect stand, exact ranges and still air.
    """
    from sim.lab import lab_errors as _lab_errors
    from sim.stand import TestStand
    from svgs.profiles import load_camera as _camera

    cam = _camera(camera)
    kind = get_trial_kind(trial_kind)
    if kind.name not in ("render", "geometric"):
        raise InputError(f"--trial-kind: the campaign runs 'render' or 'geometric' trials, got {trial_kind!r}")
    if ranges_m is None:
        if cam.name not in PAPER_RANGES_M:
            raise InputError(f"--ranges: camera {cam.name!r} is not one of the paper's phones "
                             f"({', '.join(PAPER_RANGES_M)}); give the test ranges")
        ranges_m = PAPER_RANGES_M[cam.name]
    rs = []
    for r in ranges_m:
        rs.append(kind.parameters["range_m"].check(r, "--ranges"))
    if not rs:
        raise InputError("--ranges: no ranges given")
    if len(set(rs)) != len(rs):
        raise InputError(f"--ranges: repeated range in {rs}")
    trials_per_range = _count_option(trials_per_range, "--trials")
    exposures_per_render = _count_option(exposures_per_render, "--exposures-per-render")
    if "sigma_px" in kind.parameters:
        kind.parameters["sigma_px"].check(sigma_px, "--sigma-px")
    if calibration not in ("exact", "paper"):
        raise InputError(f"--calibration: expected 'exact' or 'paper', got {calibration!r}")
    if misalignment_deg is None:
        from sim.lab import stand_misalignment_deg

        misalignment_deg = stand_misalignment_deg(cam.name)
    mis = tuple(float(x) for x in misalignment_deg)
    TestStand(misalignment_deg=mis)  # InputError beyond +/-10 deg
    if budget and kind.name != "render":
        raise InputError("--budget: the error budget switches sources of the rendered chain off; use --trial-kind render")
    err = dict(calibration_error or {})
    unknown = sorted(set(err) - set(CALIBRATION_KEYS))
    if unknown:
        raise InputError(f"calibration error: unknown key(s) {unknown}; known: {', '.join(CALIBRATION_KEYS)}")
    lens = {}
    if calibration == "paper":
        if any(v != 0 for v in err.values()):
            raise InputError("--calibration paper draws the calibration error itself; drop the explicit error options")
        if kind.name == "render":
            # the lens differs from the assumed one; the focal length comes from rendered frames (run_campaign)
            lens = paper_lens(check_seed(seed))
            err = {"focal_error_frac": 0.0, "pp_error_u_px": -lens["lens_pp_u_px"],
                   "pp_error_v_px": -lens["lens_pp_v_px"], "k1_error": -lens["lens_k1"]}
        else:
            err = paper_calibration_error(cam, pattern, rs, float(sigma_px), check_seed(seed),
                                          range_sigma_m=None if lab_errors else 0.0)
    for k, v in err.items():
        if k not in kind.parameters:
            if v != 0:
                raise InputError(f"trial kind {kind.name!r} cannot model a calibration error ({k})")
            continue
        kind.parameters[k].check(v, k)
    err = {k: float(v) for k, v in err.items() if k in kind.parameters}
    return CampaignConfig(camera=camera, ranges_m=tuple(rs), trials_per_range=trials_per_range,
                          seed=check_seed(seed), sigma_px=float(sigma_px), trial_kind=kind.name, pattern=pattern,
                          calibration=calibration, calibration_error=err, merge_px=float(merge_px),
                          exposures_per_render=exposures_per_render, misalignment_deg=mis, lens=lens,
                          budget=bool(budget), lab_errors=_campaign_lab_errors(_lab_errors(), kind.name, lab_errors))


def _campaign_lab_errors(errors: dict, kind: str, on: bool) -> dict:
    """The lab's error sources a campaign applies: all of them (turbulence for the render kind
    only: the geometric kind has no spots to move), or none."""
    if not on:
        return {}
    out = {k: float(v) for k, v in errors.items() if v > 0}
    if kind != "render":
        out.pop("turbulence_cn2_m23", None)
    return out


def rangefinder_readings(config: CampaignConfig) -> list[float]:
    """The ranges the lab recorded with its hand-held rangefinder, one per test range (the rail
    positions' truth and the paper's focal calibration; 1-sigma the lab's
    ``rangefinder_sigma_m``, seeded: ``study_rng(seed, 2)``)."""
    rng = study_rng(config.seed, 2)
    sig = config.lab_error("rangefinder_sigma_m")
    return [float(r + sig * rng.standard_normal()) for r in config.ranges_m]


#: Design streams of the stand's errors (apart from the settings' streams).
STAND_ERROR_STREAM = 500_000_000


def stand_errors(config: CampaignConfig, ri: int, j: int, readings: list[float] | None = None) -> dict:
    """Setting ``j`` of range ``ri``: the gimbal's and the stage's errors, each uniform within
    +/- the lab's accuracy (an accuracy specification bounds the error at any position; which
    error a position has is fixed but unknown, so across settings it is a draw), and the rail
    position's error (the recorded range minus the true one, common to a range's settings).

    Returns
    -------
    dict
        ``range_m`` (the recorded range) and the scenario's ``stand_err_*`` and ``rail_err_m``.
        ``readings``: :func:`rangefinder_readings` when the caller has them.
    """
    g, st = config.lab_error("gimbal_accuracy_deg"), config.lab_error("stage_accuracy_m")
    rng = design_rng(config.seed, STAND_ERROR_STREAM + ri * POSE_STRIDE + j)
    e = rng.uniform(-1.0, 1.0, 4)
    recorded = (rangefinder_readings(config) if readings is None else readings)[ri]
    return {"range_m": recorded, "rail_err_m": float(config.ranges_m[ri] - recorded),
            "stand_err_roll_deg": float(g * e[0]), "stand_err_pitch_deg": float(g * e[1]),
            "stand_err_yaw_deg": float(g * e[2]), "stand_err_stage_m": float(st * e[3])}


def rendered_paper_calibration(config: CampaignConfig, out_dir=None, progress=None) -> CampaignConfig:
    """The paper's focal-length calibration simulated on rendered frames; returns the config
    with the solver's ``focal_error_frac`` set (and ``calibration_info``).

    One image of the target facing the phone at each of the campaign's ranges, through the
    true lens (:attr:`CampaignConfig.lens`), exposed as the phone does; the spots detected and
    identified with the assumed camera (image centre, no distortion); each range as a
    hand-held laser range finder gives it (:func:`rangefinder_readings`, the readings that are also the
    rail positions' truth);
    :func:`calibration.focal.estimate_focal` on those. Kept in ``out_dir/calibration.json``
    (a rerun reuses it when the campaign's configuration is the same).
    """
    import dataclasses
    import json

    from calibration.focal import estimate_focal
    from svgs.profiles import load_camera as _camera, load_pattern as _pattern
    from studies.calibration.focal import focal_frames_rendered

    if config.trial_kind != "render" or config.calibration != "paper":
        return config
    sig = config.lab_error("rangefinder_sigma_m")
    key = {"camera": config.camera, "pattern": config.pattern, "ranges_m": list(config.ranges_m),
           "seed": config.seed, "lens": config.lens, "range_sigma_m": sig}
    path = Path(out_dir) / "calibration.json" if out_dir is not None else None
    info = None
    if path is not None and path.is_file():
        try:
            saved = json.loads(path.read_text())
            info = saved["result"] if saved.get("key") == key else None
        except (ValueError, KeyError, TypeError):
            info = None
    if info is None:
        cam, pat = _camera(config.camera), _pattern(config.pattern)
        lens = config.lens
        true = cam.replace(name=f"{cam.name}-true-lens", cx=cam.cx + lens["lens_pp_u_px"], cy=cam.cy + lens["lens_pp_v_px"],
                           dist=cam.dist + np.array([lens["lens_k1"], 0.0, 0.0, 0.0, 0.0]))
        frames = focal_frames_rendered(true, cam, pat, config.ranges_m, exposures=1, seed=config.seed,
                                       progress=progress)
        measured = rangefinder_readings(config)
        imgs, rngs, used = [], [], []
        for k, r in enumerate(config.ranges_m):
            c = frames.centroids_px[k, 0]
            if np.all(np.isfinite(c)):
                imgs.append(c)
                rngs.append(measured[k])
                used.append(float(r))
        if not imgs:
            raise InputError("calibration: no rendered calibration frame had its four targets identified "
                             f"({frames.info}); the paper's focal-length method needs at least one")
        est = estimate_focal(imgs, rngs, cam, pat, range_sigma_m=max(sig, 1e-4))
        info = {"f_px": float(est.f_px), "f_sigma_px": float(est.sigma_f_px),
                "f_true_px": float(cam.fx), "focal_error_frac": float(est.f_px / cam.fx - 1.0),
                "ranges_used_m": used, "ranges_measured_m": rngs, "frames": frames.info}
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(json.dumps({"key": key, "result": info}, indent=1, default=float))
    err = dict(config.calibration_error)
    err["focal_error_frac"] = info["focal_error_frac"]
    return dataclasses.replace(config, calibration_error=err, calibration_info=info)


#: Design streams per range (a range's stand settings never depend on the number of trials).
POSE_STRIDE = 1_000_000


def campaign_poses(config: CampaignConfig) -> list[list[dict]]:
    """The stand settings of every range: ``poses[ri][j]`` (``stage_m``, ``roll_deg``,
    ``pitch_deg``, ``yaw_deg``), drawn uniformly over the Sensor Mount's envelope and kept when
    the phone sees every target (:func:`sim.stand.sample_in_view`; pose ``j`` of range ``ri``
    from its own stream ``design_rng(seed, ri * POSE_STRIDE + j)``)."""
    from sim.stand import TestStand, sample_in_view
    from svgs.profiles import load_camera as _camera, load_pattern as _pattern

    cam, pat = _camera(config.camera), _pattern(config.pattern)
    stand = TestStand(misalignment_deg=tuple(config.misalignment_deg))
    out = []
    for ri, r in enumerate(config.ranges_m):
        row = []
        for j in range(config.poses_per_range):
            (setting,), _ = sample_in_view(design_rng(config.seed, ri * POSE_STRIDE + j), cam, pat, r, 1, stand=stand)
            row.append(setting)
        out.append(row)
    return out


def campaign_trials(config: CampaignConfig, *, variants: bool = True) -> list:
    """Every trial of the campaign.

    Baseline trial ``i = range_index * trials_per_range + k``: stand setting ``k //
    exposures_per_render`` of that range (:func:`campaign_poses`), exposure ``k %
    exposures_per_render``. With ``config.budget`` (and ``variants``), the error-budget variants
    follow (:func:`studies.error_budget.variant_trials`): the same settings and noise seeds with
    one source switched off, ids from ``len(baseline) * (v + 1)``.

    Returns
    -------
    list of :class:`studies.execution.Trial`
    """
    from .execution import Trial

    kind = get_trial_kind(config.trial_kind)
    trials = []
    n, K = config.trials_per_range, config.exposures_per_render
    fixed = {"camera": config.camera, "pattern": config.pattern, **config.calibration_error, "stand": 1.0,
             **{f"misalign_{a}_deg": float(v) for a, v in zip(("roll", "pitch", "yaw"), config.misalignment_deg)}}
    if kind.name == "render":
        fixed.update(config.lens)
        if config.lab_error("turbulence_cn2_m23") > 0:
            fixed["turbulence_cn2"] = config.lab_error("turbulence_cn2_m23")
    if "sigma_px" in kind.parameters:
        fixed["sigma_px"] = config.sigma_px
    if config.merge_px and "merge_px" in kind.parameters:
        fixed["merge_px"] = config.merge_px
    poses = campaign_poses(config)
    readings = rangefinder_readings(config)
    for ri, r in enumerate(config.ranges_m):
        for k in range(n):
            i = ri * n + k
            j, e = divmod(k, K)
            lab = stand_errors(config, ri, j, readings) if config.lab_errors else {"range_m": r}
            scen = build_scenario(kind, {**fixed, **poses[ri][j], **lab},
                                  labels={"nominal_range_m": float(r), "pose_index": j, "exposure_index": e,
                                          "variant": "baseline"})
            trials.append(Trial(i, scen, trial_seed(config.seed, i)))
    if config.budget and variants:
        from .error_budget import variant_trials

        trials += variant_trials(trials, config)
    return trials


# --------------------------------------------------------------------------- fitted values (the honest count)
@dataclass(frozen=True)
class FitUse:
    """How one fitted or chosen value enters a campaign, and which cells of Tables 2-5 it consumes.

    Attributes
    ----------
    cameras : tuple of str or None
        The camera profiles it applies to; None: every campaign its file serves (a camera's own
        overlay, the lab's light).
    consumes : tuple of (str, str)
        ``(statistic, component)`` pairs (statistic ``mean_error`` | ``std``) it was fitted to, at
        every range of the campaign the paper has a row for; ``()``: it was fitted to something
        that is not a table cell.
    condition : str
        ``"always"``, or ``"misalignment_yaw"``: only when the campaign's holder yaw
        (:attr:`CampaignConfig.misalignment_deg`) is the fitted value (a campaign run with
        ``--misalignment-deg 0,0,0`` does not use it and consumes nothing).
    effect : dict
        Camera profile name -> what the value does to that campaign's statistics (``"*"``: others).
    """

    cameras: tuple | None
    consumes: tuple
    condition: str
    effect: dict


_REACH = ("fitted to the Galaxy Nexus's reach (solutions from 5 to 30 m in Tables 4-5, 'approaching 40 meters' "
          "in the text): a claim about which ranges solve, not a table cell, so it consumes none. It sets every "
          "Galaxy Nexus statistic through the spots' brightness and size: read the Nexus's cells as conditional on it")
#: The consumption rules: fitted key (``[[fit]] key`` of ``assets/cameras/fitted/<camera>.toml`` or
#: ``assets/labs/fitted/msfc-frl.toml``; ``threshold.by_camera`` for the app's threshold) -> :class:`FitUse`.
#: Why these and no others: a value consumes a cell when the cell's number was the target of its fit -
#: then matching it is the fit working, not a prediction. The holder's 2 deg yaw was fitted to the yaw
#: mean error of Table 4 at all five ranges, so those five cells are its data (under every reading of
#: "mean error"); the yaw std cells (Table 5) only told the fit that the offset is constant, and a
#: constant rotation moves no scatter, so they stay predictions. The Galaxy Nexus's manual exposure and
#: the lab's ambient light were fitted to claims of the paper's text (the reach, the merging range),
#: which are not cells; they are listed because every statistic of their phone depends on them.
FIT_USES = {
    "stand.galaxy_nexus_misalignment_yaw_deg": FitUse(
        ("galaxy-nexus",), (("mean_error", "yaw_deg"),), "misalignment_yaw",
        {"*": "fitted to Table 4's yaw mean error at every range: those cells are its data, shown as fitted and "
              "not counted as reproduced; the yaw std cells (Table 5) stay predictions (a constant rotation "
              "moves no scatter)"}),
    "exposure.mode": FitUse(None, (), "always", {"*": _REACH}),
    "exposure.exposure_s": FitUse(None, (), "always", {"*": _REACH}),
    "exposure.iso": FitUse(None, (), "always", {"*": _REACH}),
    "lab.ambient_radiance_w_m2_sr": FitUse(
        None, (), "always",
        {"htc-amaze-4g": "fitted to the Amaze 4G's merging range (four spots 'up to about 6.5 meter', text): it "
                         "consumes no table cell directly, but it sets the Amaze's auto-exposure and so every "
                         "Amaze statistic",
         "galaxy-nexus": "fitted to the Amaze 4G's merging range (text): consumes no cell; the Galaxy Nexus's fixed "
                         "manual exposure hardly sees it (about 5 e- per pixel at 0.5 ms)",
         "*": "fitted to the Amaze 4G's merging range (text): consumes no cell; it sets the exposure of a phone on "
              "auto-exposure"}),
    "threshold.by_camera": FitUse(
        None, (), "always",
        {"*": "a setting of the app chosen once per phone, not fitted to any cell (the file says which cells, if "
              "any, under 'consumes')"}),
}
#: The rule of a fitted key :data:`FIT_USES` does not list.
UNKNOWN_FIT_USE = FitUse(None, (), "always", {"*": "no consumption rule recorded (studies.campaign.FIT_USES): "
                                                   "what it was fitted to must be checked by hand"})
#: The SVGS app's settings (``[threshold]``, ``[threshold.by_camera]``), when the file exists.
APP_SETTINGS_FILE = Path(__file__).resolve().parent.parent / "assets" / "app" / "svgs-app.toml"


def _fit_use(key: str, phone: str) -> FitUse | None:
    """The rule of a fitted key for a phone; None when it does not apply to that phone (another
    phone's holder misalignment)."""
    use = FIT_USES.get(key)
    if use is None and key.startswith("stand.") and key.endswith("_misalignment_yaw_deg"):
        # any phone's holder yaw is fitted like the Galaxy Nexus's: to its own yaw mean error
        use = FitUse((key[len("stand."):-len("_misalignment_yaw_deg")].replace("_", "-"),),
                     FIT_USES["stand.galaxy_nexus_misalignment_yaw_deg"].consumes, "misalignment_yaw",
                     {"*": "fitted to the phone's yaw mean error at every range: those cells are shown as fitted"})
    use = use or UNKNOWN_FIT_USE
    return use if use.cameras is None or phone in use.cameras else None


def _rel(path) -> str:
    root = Path(__file__).resolve().parent.parent
    try:
        return str(Path(path).resolve().relative_to(root))
    except ValueError:
        return str(path)


def _paper_ranges(config: CampaignConfig) -> list[float]:
    from svgs.profiles import load_camera as _camera

    phone = _camera(config.camera).name
    paper = svgs_2014_results()
    return [float(r) for r in config.ranges_m if (phone, "mean_error", float(r)) in paper]


def _consumed(pairs, config: CampaignConfig) -> list[tuple]:
    """``(statistic, range_m, component)`` of ``pairs`` (``(statistic, component)`` at every paper range,
    or explicit ``(statistic, range_m, component)``)."""
    out = []
    for p in pairs:
        if len(p) == 3:
            out.append((str(p[0]), float(p[1]), str(p[2])))
        else:
            out += [(str(p[0]), r, str(p[1])) for r in _paper_ranges(config)]
    return out


def _fit_row(key, entry: dict, source: str, use: FitUse, config: CampaignConfig, phone: str, status: str,
             in_campaign=None) -> dict:
    used = True
    if use.condition == "misalignment_yaw":
        used = float(config.misalignment_deg[2]) == float(entry["value"]) != 0.0
        in_campaign = f"yaw {config.misalignment_deg[2]:g} deg"
    effect = use.effect.get(phone, use.effect.get("*", ""))
    if not used:
        status = f"{status}, not used"
        effect = (f"not used by this campaign (its holder misalignment is "
                  f"{', '.join(f'{x:g}' for x in config.misalignment_deg)} deg): consumes nothing")
    return {"key": key, "value": entry["value"], "prior": entry.get("prior"), "status": status, "source": source,
            "fitted_to": entry.get("fitted_to", ""), "range": entry.get("range"),
            "range_source": entry.get("range_source", ""), "effect": effect, "in_campaign": in_campaign,
            "consumes": _consumed(use.consumes, config) if used else []}


def fitted_values_table(config: CampaignConfig, table: dict | None = None) -> list[dict]:
    """Every fitted value (and chosen app setting) that applies to a campaign, and the cells it consumes.

    Reads the camera's fitted overlay (``assets/cameras/fitted/<camera>.toml``, through
    :meth:`svgs.profiles.Camera.load`), the lab's (``assets/labs/fitted/msfc-frl.toml``, through
    :func:`svgs.profiles.read_fitted_overlay`) and, when it exists, the app's threshold for the
    camera (``assets/app/svgs-app.toml``: a *chosen* setting, consuming the cells its
    ``[threshold] consumes`` lists, none otherwise). What each consumes is :data:`FIT_USES`.

    Parameters
    ----------
    config : CampaignConfig
    table : dict, optional
        The campaign's rows; when given, ``in_campaign`` holds the values the trials used where
        they record them (the lab's light).

    Returns
    -------
    list of dict
        ``key``, ``value``, ``prior`` (the unfitted value, or None), ``status`` (``fitted``,
        ``fitted, not used``, ``chosen``), ``source`` (file), ``fitted_to``, ``range``,
        ``range_source``, ``effect`` (text), ``in_campaign``, ``consumes``: list of
        ``(statistic, range_m, component)``.
    """
    import tomllib

    from sim.lab import DEFAULT_LAB
    from svgs.profiles import load_camera as _camera
    from svgs.profiles import apply_fitted, fitted_overlay_path, read_fitted_overlay

    cam = _camera(config.camera)
    phone = cam.name
    rows = []
    for key, entry in (cam.tables.get("fitted") or {}).items():
        use = _fit_use(key, phone)
        if use is not None:
            rows.append(_fit_row(key, entry, f"assets/cameras/{entry.get('overlay', 'fitted/' + phone + '.toml')}", use,
                                 config, phone, "fitted"))
    lab_path = Path(__file__).resolve().parent.parent / "assets" / "labs" / f"{DEFAULT_LAB}.toml"
    overlay = fitted_overlay_path(lab_path)
    if overlay is not None:
        base = tomllib.loads(lab_path.read_text())
        record = apply_fitted(base, read_fitted_overlay(overlay, base))["fitted"]
        for key, entry in record.items():
            use = _fit_use(key, phone)
            if use is None:
                continue
            inc = None
            col = key.split(".", 1)[1]
            if table is not None and key.startswith("lab.") and col in table:
                vals = np.unique(np.asarray(table[col], float)[np.isfinite(np.asarray(table[col], float))])
                inc = ", ".join(f"{v:g}" for v in vals) if vals.size else None
            rows.append(_fit_row(key, entry, _rel(overlay), use, config, phone, "fitted", inc))
    if APP_SETTINGS_FILE.is_file():
        th = tomllib.loads(APP_SETTINGS_FILE.read_text()).get("threshold") or {}
        by = th.get("by_camera") or {}
        if phone in by or "default_dn" in th:
            use = FIT_USES["threshold.by_camera"]
            if th.get("consumes"):
                use = FitUse(None, tuple(tuple(x) for x in th["consumes"]), "always",
                             {"*": "a chosen app setting; the file lists the cells it consumes"})
            key = "threshold.by_camera" if phone in by else "threshold.default_dn"
            value = by.get(phone, th.get("default_dn"))
            entry = {"value": value, "range": th.get("range_dn"), "range_source": th.get("source", ""),
                     "fitted_to": f"not fitted: chosen for this phone's set-up (status {th.get('status', 'not given')}; "
                                  f"the default's source: {th.get('source', 'not given')})"}
            inc = None
            if table is not None and "threshold" in table:
                vals = np.unique(np.asarray(table["threshold"], float))
                inc = ("threshold scenario value " + ", ".join(f"{v:g}" for v in vals)
                       + (" (0: the app's setting; in results made before assets/app/svgs-app.toml existed, 0 was "
                          "the automatic threshold)" if 0.0 in vals else ""))
            rows.append(_fit_row(f"{key}[{phone}]" if phone in by else key, entry, _rel(APP_SETTINGS_FILE), use,
                                 config, phone, "chosen", inc))
    return rows


def fitted_cells(rows: list[dict]) -> dict:
    """``(statistic, range_m, component) -> key`` of every cell the values of
    :func:`fitted_values_table` consume (several keys joined by ``+``)."""
    out = {}
    for r in rows:
        for cell in r["consumes"]:
            out[cell] = f"{out[cell]}+{r['key']}" if cell in out else r["key"]
    return out


def misalignment_text(config: CampaignConfig, rows: list[dict] | None = None) -> str:
    """The holder misalignment as printed in reports: ``0, 0, 2 (yaw fitted: <key> to <what>)``."""
    txt = ", ".join(f"{x:g}" for x in config.misalignment_deg)
    rows = fitted_values_table(config) if rows is None else rows
    fit = [r for r in rows if r["key"].endswith("_misalignment_yaw_deg") and r["status"] == "fitted"]
    if fit:
        return f"{txt} (yaw FITTED: {fit[0]['key']} = {fit[0]['value']:g} deg, {fit[0]['source']}, to Table 4's yaw mean error)"
    return txt


def paper_table(camera_name: str, statistic: str) -> str:
    """The paper's table of a phone's cells: Tables 2-3 for the Amaze 4G, 4-5 for the Galaxy Nexus."""
    first = {"htc-amaze-4g": 2, "galaxy-nexus": 4}.get(camera_name)
    return f"Table {first + (statistic == 'std')}" if first else ""


def _consumes_text(cells: list) -> str:
    if not cells:
        return "no table cell"
    by = {}
    for stat, r, c in cells:
        by.setdefault((stat, c), []).append(r)
    return "; ".join(f"{'mean error' if s == 'mean_error' else s} {SHORT.get(c, c)} at "
                     f"{', '.join(f'{r:g}' for r in sorted(rs))} m" for (s, c), rs in by.items())


def honest_counts(verdicts: list[dict]) -> dict:
    """Counts of the paper's cells under each reading of the mean error.

    Every cell of Tables 2-5 (verdicts other than ``no_paper_value``); ``fitted`` cells are
    left out of ``predicted``; ``within_2x``, ``below``, ``above``, ``no_solution`` count the
    predicted cells, ``measured`` and ``unexplained`` the explanations of those outside 2x. The
    std cells have one reading and count alike under all three.

    Returns
    -------
    dict
        reading (:data:`studies.error_budget.MEAN_READINGS`) -> ``{"cells", "fitted",
        "predicted", "within_2x", "below", "above", "no_solution", "measured", "unexplained",
        "by_statistic": {"mean_error" | "std": {same keys}}}``.
    """
    def count(vs, reading):
        out = {"cells": len(vs), "fitted": 0, "predicted": 0, "within_2x": 0, "below": 0, "above": 0,
               "no_solution": 0, "measured": 0, "unexplained": 0}
        for v in vs:
            verdict, expl = v[f"verdict_{reading}"], v[f"explanation_{reading}"]
            out[verdict] = out.get(verdict, 0) + 1
            if verdict != "fitted":
                out["predicted"] += 1
            if expl:
                out["measured" if expl.startswith("measured") else "unexplained"] += 1
        return out

    cells = [v for v in verdicts if v["verdict"] != "no_paper_value"]
    res = {}
    for x in MEAN_READINGS:
        res[x] = count(cells, x)
        res[x]["by_statistic"] = {st: count([v for v in cells if v["statistic"] == st], x) for st in ("mean_error", "std")}
    return res


def honest_count_object(config: CampaignConfig, rows: list[dict], verdicts: list[dict]) -> dict:
    """What ``DIR/honest_count.json`` holds (and ``summary.json``'s ``honest_count``): the fitted
    values, the reading the verdicts use and why, and the counts under each reading."""
    from .error_budget import HEADLINE_REASON, READING_MEANINGS

    return {"headline_reading": HEADLINE_READING, "headline_reason": HEADLINE_REASON,
            "readings": {x: READING_MEANINGS[x] for x in (*MEAN_READINGS, "std")},
            "fitted_values": [{**r, "consumes": [{"statistic": s, "range_m": rr, "component": c}
                                                 for s, rr, c in r["consumes"]]} for r in rows],
            "counts": honest_counts(verdicts)}


def read_honest_count(out_dir) -> dict | None:
    """``DIR/honest_count.json`` of a campaign report (None when absent): for ``summary.json``."""
    import json

    p = Path(out_dir) / "honest_count.json"
    try:
        return json.loads(p.read_text())
    except (OSError, ValueError):
        return None


# --------------------------------------------------------------------------- statistics
def summarize(table: dict, config: CampaignConfig, paper: dict | None = None) -> list[dict]:
    """Per-range statistics beside the paper's.

    Parameters
    ----------
    table : dict of column -> ndarray
        The campaign's rows (:meth:`ResultStore.read_table`); only the baseline's are used
        (``variant`` ``baseline``, or no ``variant`` column).

    Returns
    -------
    list of dict, one per range
        ``range_m``, ``n``, ``n_ok``, ``success_rate``, ``reasons`` (dict), and per component
        ``c``: the three readings of the paper's "mean error" (:data:`studies.error_budget.MEAN_READINGS`)
        ``abs_mean_<c>`` (|mean e|, the headline), ``mean_abs_<c>`` (mean |e|) and ``rms_<c>``
        (sqrt(mean e^2)), each with its ratio to the paper's mean error ``ratio_abs_mean_<c>``,
        ``ratio_mean_abs_<c>`` (also as ``ratio_mean_<c>``, its older name), ``ratio_rms_<c>``;
        ``bias_<c>`` (signed mean), ``std_<c>`` (ddof = 1), ``crlb_<c>``, ``paper_mean_<c>``,
        ``paper_std_<c>``, ``ratio_std_<c>``. ``crlb_<c>`` is the median over the solved trials
        of the bound from the simulated sensor (``crlb_sensor_<c>``, rendered trials) or, for
        geometric trials, of the solver's bound at ``sigma_px``. Units: those of the component
        (m or deg); ratios dimensionless.
    """
    from svgs.profiles import load_camera as _camera

    paper = svgs_2014_results() if paper is None else paper
    phone = _camera(config.camera).name
    out = []
    if "variant" in table:
        base = np.array([str(v) == "baseline" for v in table["variant"]])
    else:
        base = np.ones(len(table["ok"]), bool)
    for r in config.ranges_m:
        sel = base & (table["nominal_range_m"] == r)
        ok = sel & (table["ok"] == 1)
        reasons = {}
        for x in table["reason"][sel & ~(table["ok"] == 1)]:
            key = str(x) if x is not None and x == x else "unknown"
            reasons[key] = reasons.get(key, 0) + 1
        row = {"range_m": float(r), "n": int(sel.sum()), "n_ok": int(ok.sum()),
               "success_rate": float(ok.sum() / sel.sum()) if sel.any() else float("nan"), "reasons": reasons}
        pm = paper.get((phone, "mean_error", float(r)))
        ps = paper.get((phone, "std", float(r)))
        for c in STATE_KEYS:
            e = table[f"err_{c}"][ok]
            row[f"mean_abs_{c}"] = float(np.mean(np.abs(e))) if e.size else float("nan")
            row[f"bias_{c}"] = float(np.mean(e)) if e.size else float("nan")
            row[f"abs_mean_{c}"] = abs(row[f"bias_{c}"])
            row[f"rms_{c}"] = float(np.sqrt(np.mean(e**2))) if e.size else float("nan")
            row[f"std_{c}"] = float(np.std(e, ddof=1)) if e.size > 1 else float("nan")
            cr = table[f"crlb_sensor_{c}"][ok] if f"crlb_sensor_{c}" in table else table[f"crlb_{c}"][ok]
            cr = cr[np.isfinite(cr)]
            row[f"crlb_{c}"] = float(np.median(cr)) if cr.size else float("nan")
            row[f"paper_mean_{c}"] = pm[c] if pm else float("nan")
            row[f"paper_std_{c}"] = ps[c] if ps else float("nan")
            for x in MEAN_READINGS:
                row[f"ratio_{x}_{c}"] = row[f"{x}_{c}"] / pm[c] if pm and pm[c] > 0 else float("nan")
            row[f"ratio_mean_{c}"] = row[f"ratio_mean_abs_{c}"]
            row[f"ratio_std_{c}"] = row[f"std_{c}"] / ps[c] if ps and ps[c] > 0 else float("nan")
        out.append(row)
    return out


#: The statistics of ``summary.csv`` that are cells of the paper's tables: statistic -> (summary key prefix,
#: the paper's key prefix, the column of :func:`studies.error_budget.cell_verdicts` that judges it under that
#: reading; the std's one reading is its ``verdict``).
SUMMARY_CELL_STATISTICS = {"abs_mean_error": ("abs_mean", "paper_mean", "verdict_abs_mean"),
                           "mean_abs_error": ("mean_abs", "paper_mean", "verdict_mean_abs"),
                           "rms_error": ("rms", "paper_mean", "verdict_rms"),
                           "std": ("std", "paper_std", "verdict")}
SUMMARY_COLUMNS = ("range_m", "component", "statistic", "simulated", "paper", "ratio", "verdict", "explanation")


def summary_long_rows(summary: list[dict], verdicts: list[dict] | None = None) -> list[dict]:
    """The summary as long-form rows for ``summary.csv`` (:data:`SUMMARY_COLUMNS`).

    Statistics per range and component: ``abs_mean_error`` (|mean e|, the verdicts' headline
    reading of the paper's "mean error"), ``mean_abs_error`` (mean |e|), ``rms_error`` (each
    against the paper's mean error), ``std`` (against the paper's std), ``bias`` (signed mean),
    ``crlb_std``; per range ``success_rate`` (component ``all``). With ``verdicts``
    (:func:`studies.error_budget.cell_verdicts`) the paper's cells carry their verdict under
    that reading (``fitted`` for a cell a fitted value consumed) and explanation.
    """
    index = {(v["range_m"], v["component"], v["statistic"]): v for v in verdicts or ()}
    rows = []
    for s in summary:
        for c in STATE_KEYS:
            for stat, (key, pkey, vcol) in SUMMARY_CELL_STATISTICS.items():
                v = index.get((s["range_m"], c, "std" if stat == "std" else "mean_error"))
                rows.append({"range_m": s["range_m"], "component": c, "statistic": stat, "simulated": s[f"{key}_{c}"],
                             "paper": s[f"{pkey}_{c}"], "ratio": s[f"ratio_{'std' if stat == 'std' else key}_{c}"],
                             "verdict": v[vcol] if v else None,
                             "explanation": (v[vcol.replace("verdict", "explanation")] or None) if v else None})
            rows.append({"range_m": s["range_m"], "component": c, "statistic": "bias",
                         "simulated": s[f"bias_{c}"], "paper": None, "ratio": None})
            rows.append({"range_m": s["range_m"], "component": c, "statistic": "crlb_std",
                         "simulated": s[f"crlb_{c}"], "paper": None, "ratio": None})
        rows.append({"range_m": s["range_m"], "component": "all", "statistic": "success_rate",
                     "simulated": s["success_rate"], "paper": None, "ratio": None})
    return rows


def explain(summary: list[dict], config: CampaignConfig) -> list[str]:
    """Sentences on which error source dominates at each range (from the numbers).

    Centroid noise alone gives the Cramer-Rao bound; a wrong calibration adds a bias and a
    pose-dependent scatter; what neither explains (simulated/paper ratio well below 1) comes
    from sources this trial kind does not model.
    """
    lines = []
    for s in summary:
        if s["n_ok"] < 2:
            lines.append(f"{s['range_m']:g} m: only {s['n_ok']} solved trial(s) of {s['n']}; "
                         f"failures: {s['reasons'] or 'none'}.")
            continue
        parts = []
        for group, comps in (("position", STATE_KEYS[:3]), ("attitude", STATE_KEYS[3:])):
            std = np.array([s[f"std_{c}"] for c in comps])
            crlb = np.array([s[f"crlb_{c}"] for c in comps])
            crlb = np.where(crlb > 0, crlb, np.nan)
            bias = np.abs([s[f"bias_{c}"] for c in comps])
            excess = np.sqrt(np.maximum(std**2 - crlb**2, 0.0))
            # everything in units of the centroid-noise bound, median over the group's components
            share = {"centroid noise": 1.0,
                     "calibration bias": float(np.nanmedian(bias / crlb)),
                     "pose-dependent calibration error": float(np.nanmedian(excess / crlb))}
            if not all(np.isfinite(v) for v in share.values()):
                parts.append(f"{group}: no centroid noise, errors from the calibration only")
                continue
            src = max(share, key=share.get)
            detail = ", ".join(f"{k} {v:.2g}" for k, v in share.items() if k != "centroid noise")
            ratio = [s[f"ratio_std_{c}"] for c in comps]
            ratio = [x for x in ratio if x == x]
            rtxt = f"; simulated/paper std {np.median(ratio):.2f}" if ratio else ""
            parts.append(f"{group}: {src} dominates (in units of the noise bound: {detail}){rtxt}")
        lines.append(f"{s['range_m']:g} m: " + "; ".join(parts) + ".")
    return lines


# --------------------------------------------------------------------------- figures
def _range_groups(ranges):
    """Split ranges as the paper's figures did (Amaze 1-3 / 4-8 m, Nexus 5-15 / 20-30 m)."""
    rs = list(ranges)
    h = math.ceil(len(rs) / 2)
    return [g for g in (rs[:h], rs[h:]) if g]


def histogram_figures(table: dict, config: CampaignConfig):
    """Figures 6-13 of the paper: error histograms per component, two range groups.

    Yields
    ------
    (Figure, caption)
    """
    from matplotlib.figure import Figure

    ok = table["ok"] == 1
    for grp in _range_groups(config.ranges_m):
        label = f"{grp[0]:g}-{grp[-1]:g} m" if len(grp) > 1 else f"{grp[0]:g} m"
        for title, comps in (("Position error", STATE_KEYS[:3]), ("Attitude error", STATE_KEYS[3:])):
            fig = Figure(figsize=(11, 3.2))
            axes = fig.subplots(1, 3)
            for ax, c in zip(axes, comps):
                data = [table[f"err_{c}"][ok & (table["nominal_range_m"] == r)] for r in grp]
                allv = np.concatenate(data) if data else np.array([])
                if allv.size:
                    lim = np.percentile(np.abs(allv), 99.5) or 1.0
                    bins = np.linspace(-lim, lim, 41)
                    for r, d in zip(grp, data):
                        ax.hist(np.clip(d, -lim, lim), bins=bins, histtype="step", linewidth=1.4, label=f"{r:g} m")
                ax.set_xlabel(f"{SHORT[c]} error ({c.split('_')[1]})")
                ax.set_ylabel("trials")
                ax.grid(alpha=0.3)
            axes[0].legend(fontsize=8)
            fig.suptitle(f"{config.camera}: {title.lower()} ({label})")
            yield fig, f"{title} histograms, {label} (like the paper's Figures 6-13)."


def crlb_figure(summary: list[dict], config: CampaignConfig):
    """Simulated std, Cramer-Rao bound and the paper's std (and mean |error|) versus range."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(12, 6.5))
    axes = fig.subplots(2, 3).ravel()
    r = np.array([s["range_m"] for s in summary])
    for ax, c in zip(axes, STATE_KEYS):
        ax.plot(r, [s[f"crlb_{c}"] for s in summary], "k-", label="Cramer-Rao 1-sigma")
        ax.plot(r, [s[f"std_{c}"] for s in summary], "o-", color="C0", label="simulated std")
        ax.plot(r, [s[f"mean_abs_{c}"] for s in summary], "o--", color="C0", alpha=0.6, label="simulated mean |err|")
        ps = [s[f"paper_std_{c}"] for s in summary]
        if np.any(np.isfinite(ps)):
            ax.plot(r, ps, "s-", color="C3", label="paper std")
            ax.plot(r, [s[f"paper_mean_{c}"] for s in summary], "s--", color="C3", alpha=0.6, label="paper mean error")
        ax.set_yscale("log")
        ax.set_xlabel("range (m)")
        ax.set_ylabel(COMPONENT_LABELS[c])
        ax.grid(alpha=0.3, which="both")
    axes[0].legend(fontsize=7)
    fig.suptitle(f"{config.camera}: errors versus range, beside the Cramer-Rao bound and the paper")
    fig.tight_layout()
    return fig


# --------------------------------------------------------------------------- report
def _side_by_side(summary, stat_sim, stat_paper, stat_ratio, comps=STATE_KEYS, crlb: bool = False):
    cols = ["range (m)"]
    for c in comps:
        cols += [f"{SHORT[c]} sim", f"{SHORT[c]} paper", f"{SHORT[c]} ratio"] + ([f"{SHORT[c]} CRLB"] if crlb else [])
    rows = []
    for s in summary:
        row = [s["range_m"]]
        for c in comps:
            row += [s[f"{stat_sim}_{c}"], s[f"{stat_paper}_{c}"], s[f"{stat_ratio}_{c}"]] + ([s[f"crlb_{c}"]] if crlb else [])
        rows.append(row)
    return cols, rows


def run_log(out_dir) -> list[dict]:
    """The runs a campaign folder has seen (``DIR/runs.json``): trials run, wall time, executor."""
    import json

    p = Path(out_dir) / "runs.json"
    try:
        return list(json.loads(p.read_text()))
    except (OSError, ValueError, TypeError):
        return []


def _log_run(out_dir, part: str, stats) -> None:
    import json

    if stats is None:
        return
    log = run_log(out_dir)
    log.append({"part": part, "trials_run": stats.n_run, "elapsed_s": round(stats.elapsed_s, 2),
                "executor": stats.executor})
    (Path(out_dir) / "runs.json").write_text(json.dumps(log, indent=1))


def sample_image_figure(config: CampaignConfig, trials: list, table: dict):
    """One delivered image per range (the first stand setting, its first exposure), cropped to the
    target, with the true target projections (circles) and the solved targets (crosses)."""
    from matplotlib.figure import Figure

    from sim.closed_loop import solve_exposure, solver_camera
    from sim.render_trial import rendered_frame
    from sim.trials import camera_with_calibration_errors
    from svgs.profiles import Pattern

    pat = Pattern.load(config.pattern)
    firsts = {}
    for t in trials:
        sc = t.scenario
        if sc.get("variant") == "baseline" and sc["pose_index"] == 0 and sc["exposure_index"] == 0:
            firsts.setdefault(sc["nominal_range_m"], t)
    n = len(config.ranges_m)
    fig = Figure(figsize=(3.0 * n, 3.4))
    axes = np.atleast_1d(fig.subplots(1, n))
    for ax, r in zip(axes, config.ranges_m):
        t = firsts.get(r)
        ax.set_xticks([])
        ax.set_yticks([])
        if t is None:
            continue
        frame = rendered_frame(t.scenario)
        ex = frame.exposer().expose(seed=int(t.seed))
        img = ex.image
        cam_img = solver_camera(frame.camera, img.shape)
        R, tt = frame.scenario.pose()
        uv = cam_img.project_target(pat.points_m, R, tt)
        row = solve_exposure(frame, ex, solver_camera_profile=camera_with_calibration_errors(frame.camera, t.scenario))
        lo, hi = uv.min(0), uv.max(0)
        pad = max(12.0, 0.6 * float(np.max(hi - lo)))
        x0, x1 = int(max(0, lo[0] - pad)), int(min(img.shape[1], hi[0] + pad))
        y0, y1 = int(max(0, lo[1] - pad)), int(min(img.shape[0], hi[1] + pad))
        ax.imshow(img[y0:y1, x0:x1], cmap="gray", vmin=0, vmax=255, extent=(x0 - 0.5, x1 - 0.5, y1 - 0.5, y0 - 0.5))
        ax.plot(uv[:, 0], uv[:, 1], "o", mfc="none", mec="C0", ms=9, label="true targets")
        sol = row["_solution"]
        if sol:
            found = np.array([sol.targets_px[i] for i in pat.ids], float)
            ax.plot(found[:, 0], found[:, 1], "+", color="C3", ms=9, label="solved")
        ax.set_title(f"{r:g} m: {'solved' if sol else sol.reason}\n{ex.exposure_s * 1e3:.3g} ms, ISO {ex.iso:.0f}",
                     fontsize=8)
    axes[0].legend(fontsize=6, loc="lower left")
    fig.suptitle(f"{config.camera}: delivered images (8-bit), the first stand setting of each range", fontsize=9)
    fig.tight_layout()
    return fig


def campaign_verdicts(config: CampaignConfig, summary: list[dict], budget: dict | None = None,
                      rows: list[dict] | None = None) -> list[dict]:
    """Every cell of Tables 2-5 judged (:func:`studies.error_budget.cell_verdicts`), the cells the
    fitted values consume (:func:`fitted_values_table`) as ``fitted``, each with its ``table``
    (``Table 2`` ... ``Table 5``)."""
    from svgs.profiles import load_camera as _camera

    from .error_budget import cell_verdicts

    rows = fitted_values_table(config) if rows is None else rows
    b = budget or {}
    verdicts = cell_verdicts(summary, b.get("attribution"), b.get("variant_stats"), b.get("centroids"),
                             fitted_cells=fitted_cells(rows))
    phone = _camera(config.camera).name
    return [{**v, "table": paper_table(phone, v["statistic"])} for v in verdicts]


def _carried_figure(html_text: str, heading: str) -> str | None:
    """The first ``<figure>`` after ``<h2>heading</h2>`` of an earlier report (None if none)."""
    import html as _html

    h = f"<h2>{_html.escape(heading)}</h2>"
    i = html_text.find(h)
    if i < 0:
        return None
    j = html_text.find("<figure>", i)
    k = html_text.find("</figure>", j)
    nxt = html_text.find("<h2>", i + len(h))
    if j < 0 or k < 0 or (0 <= nxt < j):
        return None
    return html_text[j:k + len("</figure>")]


def _honest_count_section(rep, config: CampaignConfig, rows: list[dict], verdicts: list[dict], counts: dict) -> None:
    from .error_budget import HEADLINE_REASON, READING_MEANINGS

    rep.heading("The honest count: fitted values and the cells they consume")
    h = counts[HEADLINE_READING]
    rep.paragraph(
        f"Under the headline reading of the paper's mean error ({READING_LABELS[HEADLINE_READING]}): "
        f"{h['within_2x']} of {h['predicted']} predicted cells of Tables 2-5 within 2x of the paper, {h['below']} below, "
        f"{h['above']} above, {h['no_solution']} without a solution; {h['fitted']} of the {h['cells']} cells are fitted "
        f"(a value was fitted to them) and are not counted. Of the {h['below'] + h['above']} outside 2x, "
        f"{h['measured']} are explained by a mechanism measured by switching it off in the simulation (the error "
        f"budget), {h['unexplained']} are unexplained.")
    rep.paragraph(
        "Every value of the simulation that was fitted to a result of the paper (or chosen for it), what it was fitted "
        "to, and the cells of Tables 2-5 it consumes: a consumed cell was the target of the fit, so matching it is not "
        "a prediction. Values fitted to a claim of the paper's text (a reach, a merging range) consume no cell, but "
        "the statistics that depend on them are conditional on them (the 'effect' column).", "note")
    rep.table(["key", "value", "status", "file", "fitted to", "cells consumed", "effect on this campaign",
               "in the trials"],
              [[r["key"], r["value"] if isinstance(r["value"], str) else f"{r['value']:g}"
                + (f" (prior {r['prior']:g})" if isinstance(r["prior"], (int, float)) else
                   f" (prior {r['prior']})" if r["prior"] is not None else ""),
                r["status"], r["source"], r["fitted_to"], _consumes_text(r["consumes"]), r["effect"],
                r["in_campaign"]] for r in rows],
              caption="Fitted values and chosen settings that apply to this campaign",
              text_columns=["value", "status", "file", "fitted to", "cells consumed", "effect on this campaign",
                            "in the trials"])
    rep.paragraph("The paper's mean error is read three ways: " + "; ".join(READING_MEANINGS[x] for x in MEAN_READINGS)
                  + f". The verdicts use {READING_LABELS[HEADLINE_READING]}. Why: " + HEADLINE_REASON, "note")
    cols = ["reading", "predicted", "within 2x", "below", "above", "no solution", "fitted (not counted)",
            "outside 2x: measured", "outside 2x: unexplained"]
    trows = []
    for x in MEAN_READINGS:
        for scope, k in (("all cells", None), ("mean error", "mean_error"), ("std", "std")):
            c = counts[x] if k is None else counts[x]["by_statistic"][k]
            if k == "std" and x != MEAN_READINGS[0]:
                continue  # one reading: the same under all three
            label = (f"{READING_LABELS[x]}{' (headline)' if x == HEADLINE_READING else ''}: {scope}" if k != "std"
                     else "std (one reading): std")
            trows.append([label, c["predicted"], c["within_2x"], c["below"], c["above"], c["no_solution"],
                          c["fitted"], c["measured"], c["unexplained"]])
    tables = sorted({v["table"] for v in verdicts if v["table"]})
    rep.table(cols, trows, text_columns=["reading"],
              caption="Cells of " + (" and ".join(tables) if tables else "the paper's tables")
              + " under each reading of the mean error (counts over predicted cells: all cells less the fitted ones)")


def _mean_error_section(rep, summary, crlb_note: str) -> None:
    rep.heading("Mean error (paper Tables 2 and 4), three readings")
    rep.paragraph(
        f"{READING_LABELS[HEADLINE_READING]} (the headline reading: the magnitude of the signed mean error), mean |e| "
        "and RMS per component of the relative state (the camera's position in the target frame, m; the paper's "
        "roll/pitch/yaw, deg), each beside the paper's mean error with the simulated/paper ratio, and the CRLB 1-sigma ("
        + crlb_note + ").", "note")
    for grp, comps in (("position", STATE_KEYS[:3]), ("attitude", STATE_KEYS[3:])):
        cols, rows = _side_by_side(summary, "abs_mean", "paper_mean", "ratio_abs_mean", comps, crlb=True)
        rep.table(cols, rows, caption=f"Mean error, {grp}, read as {READING_LABELS[HEADLINE_READING]}: "
                                      "simulated | paper | ratio | CRLB")
    for grp, comps in (("position", STATE_KEYS[:3]), ("attitude", STATE_KEYS[3:])):
        cols = ["range (m)"]
        for c in comps:
            cols += [f"{SHORT[c]} paper", f"{SHORT[c]} |mean e|", f"{SHORT[c]} mean |e|", f"{SHORT[c]} RMS"]
        rows = [[s["range_m"]] + [x for c in comps for x in (s[f"paper_mean_{c}"], s[f"abs_mean_{c}"],
                                                             s[f"mean_abs_{c}"], s[f"rms_{c}"])] for s in summary]
        rep.table(cols, rows, caption=f"Mean error, {grp}: the paper's beside the three simulated readings")


def _cells_section(rep, verdicts: list[dict], budget) -> None:
    rep.heading("Every cell of Tables 2-5")
    rep.paragraph(
        "A cell outside 2x is explained only by a mechanism whose size was measured by switching it off in the "
        "simulation (the error budget: 'measured:<source>' when switching that source off brings the cell within 2x). "
        "Otherwise it is unexplained, with the size of the gap. A cell below the paper's is always unexplained: "
        "switching a modelled source off only removes error, so the test had errors that no modelled source makes. "
        + ("" if budget is not None else "This campaign ran no error budget (--budget): no source is measured. "), "note")
    eq = {}
    for v in verdicts:
        if v["verdict"] == "below" and np.isfinite(v["sigma_equivalent_px"]):
            eq.setdefault(v["range_m"], []).append(v["sigma_equivalent_px"])
    if eq and budget is not None:
        rep.paragraph(
            "What it would take (not an explanation): the random centroid noise that would add the std cells' gaps in "
            "quadrature (the geometric trial on the same settings, whose errors scale with its noise), median "
            + ", ".join(f"{np.median(x):.2g} px at {r:g} m" for r, x in sorted(eq.items()))
            + " per axis, against the rendered sensor's own scatter of "
            + ", ".join(f"{c['scatter_px']:.2g}" for c in budget["centroids"]) + " px. No source of that size is "
            "modelled or measured. Candidates the simulation leaves out (none measured, so none counted as an "
            "explanation): the air's turbulence over the path and the stand's vibration, the phone's own image "
            "processing beyond the modelled tone curve and JPEG (sharpening, noise reduction, video compression), "
            "and the lab's truth (the gimbal's angles and the range finder are taken as exact). The mean-error "
            f"gaps under {READING_LABELS[HEADLINE_READING]} are biases, which random noise cannot make.", "note")
    rep.table(["range (m)", "component", "table", "reading", "simulated", "paper", "ratio", "verdict", "explanation",
               "why"],
              [[v["range_m"], v["component"], v["table"], READING_LABELS[v["reading"]], v["simulated"], v["paper"],
                v["ratio"], v["verdict"], v["explanation"], v["text"]]
               for v in verdicts if v["verdict"] not in ("within_2x", "no_paper_value")],
              text_columns=["component", "table", "reading", "verdict", "explanation", "why"],
              caption="Cells outside 2x of the paper, and the fitted cells")


def write_campaign_report(out_dir, config: CampaignConfig, table: dict, summary: list[dict], *, command: str,
                          versions: dict, stats=None, budget: dict | None = None, trials: list | None = None,
                          sample_figure_html: str | None = None) -> Path:
    """``DIR/report.html``, ``DIR/summary.csv``, ``DIR/verdicts.csv`` and ``DIR/honest_count.json``
    (and with a budget ``DIR/budget.csv``) for a finished campaign.

    ``trials`` (rendered): the sample images are rendered again; without them
    ``sample_figure_html`` (that figure of an earlier report, :func:`rebuild_report`) is kept.
    """
    import json

    from .error_budget import VERDICT_COLUMNS
    from .report import Report, write_csv

    out_dir = Path(out_dir)
    rows = fitted_values_table(config, table)
    verdicts = campaign_verdicts(config, summary, budget, rows)
    counts = honest_counts(verdicts)
    write_csv(out_dir / "summary.csv", list(SUMMARY_COLUMNS), summary_long_rows(summary, verdicts))
    write_csv(out_dir / "verdicts.csv", ["table", *VERDICT_COLUMNS], verdicts)
    (out_dir / "honest_count.json").write_text(json.dumps(_finite(honest_count_object(config, rows, verdicts)), indent=1,
                                                          allow_nan=False) + "\n")
    n = int(np.sum([s["n"] for s in summary]))
    n_ok = int(np.sum([s["n_ok"] for s in summary]))
    rendered = config.trial_kind == "render"
    rep = Report(f"SVGS test campaign simulated: {config.camera} ({config.trial_kind} trials)", command, versions)
    log = run_log(out_dir)
    wall = sum(x["elapsed_s"] for x in log)
    rep.paragraph(
        f"{n} trials over {len(config.ranges_m)} ranges ({', '.join(f'{r:g}' for r in config.ranges_m)} m), "
        f"{n_ok} solved ({100.0 * n_ok / max(n, 1):.1f} %): {config.poses_per_range} stand settings per range, "
        f"{config.exposures_per_render} exposures of each. As on the MSFC Flight Robotics Lab stand of Becker, Howard & "
        "Rakoczy (2014), the target stays fixed and the phone is turned by the Sensor Mount's gimbal (roll and pitch "
        f"+/-{GIMBAL_ROLL_DEG:g} deg, yaw +/-{GIMBAL_YAW_DEG:g} deg about the line of sight) on the translation stage "
        f"(+/-{100 * STAGE_HALF_TRAVEL_M:g} cm) at each rail position (sim.stand); each setting is drawn uniformly over "
        "that envelope and kept when the phone sees all four targets."
        + (f" Wall time of the trials: {wall:.0f} s over {len(log)} run(s) ({', '.join(sorted({x['executor'] for x in log}))})."
           if log else ""))
    _honest_count_section(rep, config, rows, verdicts, counts)
    rep.heading("Set-up")
    setup = [("camera", config.camera), ("pattern", config.pattern), ("trial kind", config.trial_kind),
             ("trials per range", config.trials_per_range), ("stand settings (renders) per range", config.poses_per_range),
             ("exposures per setting", config.exposures_per_render), ("seed", config.seed),
             ("calibration practice", config.calibration),
             ("phone misalignment in its holder (roll, pitch, yaw), deg", misalignment_text(config, rows))]
    if not rendered:
        setup.append(("centroid noise sigma_px", config.sigma_px))
    setup += [(f"true lens: {k}", v) for k, v in config.lens.items()]
    setup += [(f"solver calibration error: {k}", v) for k, v in config.calibration_error.items()]
    ci = config.calibration_info
    if ci:
        setup += [("paper's focal calibration: f estimated (px)", ci["f_px"]), ("... its 1-sigma (px)", ci["f_sigma_px"]),
                  ("... true fx (px)", ci["f_true_px"]),
                  ("... ranges used (m)", ", ".join(f"{x:g}" for x in ci["ranges_used_m"])),
                  ("... as the range finder gave them (m)", ", ".join(f"{x:.3f}" for x in ci["ranges_measured_m"]))]
    for x in log:
        setup.append((f"run: {x['part']}", f"{x['trials_run']} trials in {x['elapsed_s']:.0f} s ({x['executor']})"))
    rep.table(["setting", "value"], setup, text_columns=["value"], digits=4)
    crlb_note = ("the Cramer-Rao bound from the simulated sensor (shot, read and quantisation noise at the exposure used; "
                 "sim.crlb), median over the solved trials" if rendered else
                 f"the solver's Cramer-Rao bound for {config.sigma_px:g} px centroid noise, median over the solved trials")
    _mean_error_section(rep, summary, crlb_note)
    rep.heading("Standard deviation (paper Tables 3 and 5)")
    rep.paragraph("Standard deviation of the signed error per component of the relative state (the camera's position "
                  "in the target frame, m; the paper's roll/pitch/yaw, deg): simulated, the paper's, simulated/paper and "
                  "the CRLB 1-sigma (" + crlb_note + ").", "note")
    for grp, comps in (("position", STATE_KEYS[:3]), ("attitude", STATE_KEYS[3:])):
        cols, trows = _side_by_side(summary, "std", "paper_std", "ratio_std", comps, crlb=True)
        rep.table(cols, trows, caption=f"Standard deviation, {grp}: simulated | paper | ratio | CRLB")
    rep.heading("Bias and efficiency")
    cols = ["range (m)"] + [f"{SHORT[c]} bias" for c in STATE_KEYS]
    rep.table(cols, [[s["range_m"]] + [s[f"bias_{c}"] for c in STATE_KEYS] for s in summary],
              caption="Signed mean error (bias) per component")
    cols = ["range (m)"] + [f"{SHORT[c]} std/CRLB" for c in STATE_KEYS]
    rep.table(cols, [[s["range_m"]] + [s[f"std_{c}"] / s[f"crlb_{c}"] if s[f"crlb_{c}"] > 0 else float("nan")
                                       for c in STATE_KEYS] for s in summary],
              caption="Simulated standard deviation over the Cramer-Rao bound (1: an efficient estimate)")
    rep.table(["range (m)", "trials", "solved", "success rate", "failures by reason"],
              [[s["range_m"], s["n"], s["n_ok"], s["success_rate"],
                ", ".join(f"{k}: {v}" for k, v in sorted(s["reasons"].items())) or "none"] for s in summary],
              caption="Success rate", text_columns=["failures by reason"])
    if budget is not None:
        _budget_sections(rep, out_dir, config, summary, budget)
    _cells_section(rep, verdicts, budget)
    rep.heading("Errors versus range")
    rep.figure(crlb_figure(summary, config), "Simulated standard deviation and mean |error| (blue), the paper's "
               "(red) and the Cramer-Rao bound (black), per component, versus range.")
    if rendered and trials is not None:
        rep.heading("What the phone saw")
        rep.figure(sample_image_figure(config, trials, table), "The delivered 8-bit image of the first stand setting "
                   "at each range, cropped to the target: the true target positions (circles) and the solved "
                   "targets (crosses).")
    elif rendered and sample_figure_html:
        rep.heading("What the phone saw")
        rep.paragraph("Carried over from the report this one was rebuilt from (the images are not rendered again).",
                      "note")
        rep._parts.append(sample_figure_html)  # the earlier report's embedded PNG, verbatim
    rep.heading("Error histograms (paper Figures 6-13)")
    base_table = table
    if "variant" in table:
        keep = np.array([str(v) == "baseline" for v in table["variant"]])
        base_table = {k: np.asarray(v)[keep] for k, v in table.items()}
    for fig, cap in histogram_figures(base_table, config):
        rep.figure(fig, cap)
    if not rendered:
        rep.heading("What dominates the error at each range")
        rep.bullets(explain(summary, config))
        rep.paragraph(
            "How to read this. With centroid noise alone the solver is efficient: the simulated scatter sits on the "
            "Cramer-Rao bound. A wrong calibration used by the solver adds a bias and, because the gimbal attitude "
            "changes from trial to trial, a pose-dependent scatter. The geometric trial gives every spot the same "
            "isotropic sigma_px; the rendered campaign (the default trial kind) makes the spots and measures what "
            "each error source contributes (its error budget). These are inferences from the numbers, not "
            "measurements by switching a source off: they explain no cell of the tables.")
    return rep.write(out_dir / "report.html")


def _finite(obj):
    """``obj`` in plain JSON types (:func:`studies.store._jsonable`) with NaN and infinite floats as
    None (strict JSON)."""
    from .store import _jsonable

    def fin(o):
        if isinstance(o, dict):
            return {k: fin(v) for k, v in o.items()}
        if isinstance(o, list):
            return [fin(v) for v in o]
        return (o if np.isfinite(o) else None) if isinstance(o, float) else o

    return fin(_jsonable(obj))


def _budget_sections(rep, out_dir, config, summary, budget) -> None:
    from .error_budget import SOURCE_LABELS, VARIANTS, applicable_variants, budget_figure, budget_rows_for_csv
    from .report import write_csv

    cols, rows = budget_rows_for_csv(budget["attribution"])
    write_csv(out_dir / "budget.csv", cols, rows)
    rep.heading("Error budget")
    rep.paragraph(
        "The campaign rerun on the same stand settings and noise seeds with one error source removed at a time. "
        "A source's contribution is the part of the baseline statistic that goes when it goes, in quadrature "
        "(sqrt(baseline^2 - without^2)); the floor is the error with all of them removed (what the retro spots' "
        "formation, the optics and the pattern's geometry give by themselves: the flash-to-lens parallax, the "
        "spots' pixel sampling); 'random centroid noise' is the geometric trial on the same settings at the "
        "centroid scatter measured on the rendered exposures (not a removal: that source alone).", "note")
    ran = {v.name for v in applicable_variants(config.camera, config.lab_errors)}
    rep.bullets([f"{v.name}: {v.meaning}" + ("" if v.all_exposures else " (the first exposure of each setting)")
                 for v in VARIANTS if v.name in ran])
    cs = budget["centroids"]
    rep.table(["range (m)", "scatter over exposures (px)", "common offset (px)", "differential offset (px)",
               "sensor CRLB (px)", "settings"],
              [[c["range_m"], c["scatter_px"], c["common_offset_px"], c["differential_offset_px"], c["crlb_px"],
                c["settings"]] for c in cs],
              caption="Measured centroids against the targets' true projections (through the true lens, at the "
                      "actual pose), medians over the stand settings")
    names = [n for n in ("floor", "perfect_calibration", "no_sensor_noise", "no_glare", "no_quantisation",
                         "no_misalignment", "no_jpeg", "no_chroma_subsampling", "no_cfa", "no_noise_reduction",
                         "no_sharpening", "no_stand_error", "no_rail_error", "no_turbulence", "geometric")
             if n in ("floor", "geometric") or any(n in b for b in budget["attribution"])]
    for grp, comps in (("position", STATE_KEYS[:3]), ("attitude", STATE_KEYS[3:])):
        tcols = ["range (m)", "component", "RMS error"] + [SOURCE_LABELS[n] for n in names] + ["interaction"]
        trows = [[b["range_m"], b["component"], b["baseline"]] + [b.get(n, float("nan")) for n in names]
                 + [b["interaction"]] for b in budget["attribution"] if b["statistic"] == "rms" and b["component"] in comps]
        rep.table(tcols, trows, caption=f"Error budget, {grp}: RMS error and each source's contribution in quadrature",
                  text_columns=["component"])
    rep.figure(budget_figure(budget["attribution"], config.ranges_m, config.camera),
               "Each source's share of the mean square error per component and range (stacked; the floor in grey, "
               "what the sources do not explain on their own - their interaction - in light grey).")


def print_summary(summary: list[dict], config: CampaignConfig, file=None) -> None:
    """A short table on stdout: per range, success and std simulated vs paper; then the cells of
    Tables 2-5 within 2x under each reading of the mean error, fitted cells left out."""
    import sys

    f = file or sys.stdout
    rows = fitted_values_table(config)
    print(f"campaign {config.camera}: {config.trials_per_range} trials per range, sigma_px {config.sigma_px:g}, "
          f"calibration {config.calibration}, holder misalignment {misalignment_text(config, rows)}", file=f)
    hdr = f"{'range_m':>8} {'ok':>6} " + " ".join(f"{SHORT[c] + ' std':>10} {'/paper':>7}" for c in STATE_KEYS)
    print(hdr, file=f)
    for s in summary:
        cells = " ".join(f"{s[f'std_{c}']:10.3g} {s[f'ratio_std_{c}']:7.2f}" for c in STATE_KEYS)
        print(f"{s['range_m']:8g} {s['n_ok']:>3}/{s['n']:<3}{cells}".replace("nan", "  -"), file=f)
    counts = honest_counts(campaign_verdicts(config, summary, None, rows))
    if counts[HEADLINE_READING]["cells"]:
        print("cells within 2x of the paper (fitted cells not counted): " + "; ".join(
            f"{READING_LABELS[x]}{' (headline)' if x == HEADLINE_READING else ''} {counts[x]['within_2x']} of "
            f"{counts[x]['predicted']}" for x in MEAN_READINGS) + f"; {counts[HEADLINE_READING]['fitted']} fitted", file=f)


def run_campaign(config: CampaignConfig, out_dir, spec, *, chunk_size=None, progress: bool = True,
                 command: str = "", out=None):
    """Run (or resume) a campaign into ``out_dir`` and write its report.

    With the paper's calibration practice on rendered trials, the focal length is first
    estimated from rendered frames (:func:`rendered_paper_calibration`). With ``config.budget``
    the variants run in the same store, then the geometric trial at the measured centroid
    scatter in ``DIR/budget-geometric``.

    Returns
    -------
    (summary, stats, report_path, config)
        ``config`` with the calibration filled in.
    """
    import sys

    from .execution import check_executor, library_versions, run_stored_study

    check_executor(spec)  # before the calibration renders: an unreachable cluster is bad input, not lost work
    kind = get_trial_kind(config.trial_kind)
    out_dir = Path(out_dir)
    say = (lambda m: print(m, file=sys.stderr)) if progress else None
    config = rendered_paper_calibration(config, out_dir, progress=say)
    trials = campaign_trials(config)
    store, stats = run_stored_study(kind, trials, out_dir, config.manifest(), spec, chunk_size=chunk_size,
                                    progress=progress, description=f"campaign {config.camera}")
    _log_run(out_dir, "rendered trials" if kind.name == "render" else "trials", stats)
    table = store.read_table()
    summary = summarize(table, config)
    budget = None
    if config.budget:
        budget = run_budget_geometric(config, trials, table, out_dir, progress=progress)
    path = write_campaign_report(out_dir, config, table, summary, command=command, versions=library_versions(),
                                 stats=stats, budget=budget, trials=trials)
    return summary, stats, path, config


def run_budget_geometric(config: CampaignConfig, trials: list, table: dict, out_dir, *, progress: bool = True) -> dict:
    """The error budget of a finished rendered campaign: the measured centroids, the geometric
    trial at their scatter (``DIR/budget-geometric``, in this process: milliseconds a trial), the
    variants' statistics and the attribution (:mod:`studies.error_budget`)."""
    from sim.trials import GEOMETRIC

    from .error_budget import attribute, centroid_statistics, geometric_trials, variant_statistics
    from .execution import ExecutorSpec, run_stored_study

    cents = centroid_statistics(table, config.ranges_m)
    base = [t for t in trials if t.scenario.get("variant") == "baseline"]
    gtrials = geometric_trials(base, config, cents)
    manifest = {"study": "campaign-budget-geometric", "campaign": config.manifest(),
                "sigma_px": {f"{c['range_m']:g}": c["scatter_px"] for c in cents}}
    gstore, gstats = run_stored_study(GEOMETRIC, gtrials, Path(out_dir) / "budget-geometric", manifest,
                                      ExecutorSpec("inline", 0), progress=progress, description="budget: geometric")
    _log_run(out_dir, "budget: geometric trials", gstats)
    vs = variant_statistics(table, config.ranges_m, gstore.read_table())
    return {"centroids": cents, "variant_stats": vs, "attribution": attribute(vs, config.ranges_m)}


# --------------------------------------------------------------------------- rebuilding a report
def config_from_manifest(out_dir) -> CampaignConfig:
    """The :class:`CampaignConfig` a campaign folder's ``manifest.json`` records (with
    ``calibration_info`` from ``calibration.json`` when there is one); nothing is recomputed."""
    import json

    out_dir = Path(out_dir)
    try:
        m = json.loads((out_dir / "manifest.json").read_text())["parameters"]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise InputError(f"{out_dir}: no campaign manifest.json ({exc})") from None
    if m.get("study") != "campaign":
        raise InputError(f"{out_dir}: manifest.json is a {m.get('study')!r} study, not a campaign")
    info = {}
    try:
        info = json.loads((out_dir / "calibration.json").read_text())["result"]
    except (OSError, ValueError, KeyError, TypeError):
        pass
    return CampaignConfig(camera=m["camera"], ranges_m=tuple(float(r) for r in m["ranges_m"]),
                          trials_per_range=int(m["trials_per_range"]), seed=int(m["seed"]),
                          sigma_px=float(m["sigma_px"]), trial_kind=m["trial_kind"], pattern=m["pattern"],
                          calibration=m["calibration"], calibration_error=dict(m["calibration_error"]),
                          merge_px=float(m["merge_px"]), exposures_per_render=int(m["exposures_per_render"]),
                          misalignment_deg=tuple(float(x) for x in m["misalignment_deg"]), lens=dict(m["lens"]),
                          budget=bool(m["budget"]), lab_errors=dict(m.get("lab_errors") or {}), calibration_info=info)


def rebuild_report(out_dir, *, command: str | None = None) -> Path:
    """Rewrite a finished campaign's report and tables from its stored results; no trial runs.

    Reads ``DIR/manifest.json``, ``DIR/calibration.json``, ``DIR/results.csv`` and (with a
    budget) ``DIR/budget-geometric/results.csv``; writes ``report.html``, ``summary.csv``,
    ``verdicts.csv``, ``honest_count.json`` (and ``budget.csv``) and updates ``summary.json``
    where there is one (per range the three readings of the mean error and their ratios, and
    ``honest_count``). The sample images are not rendered: that figure is carried over from the
    folder's earlier ``report.html``. Unlike rerunning ``svgs campaign``, this never starts a
    trial, even when the trial code has changed since the results were made.

    Parameters
    ----------
    out_dir : str or Path
        A campaign folder (rebuilt in place: copy it first to keep the original).
    command : str, optional
        The command line for the report's provenance (default: the earlier report's, with a
        note of the rebuild).

    Returns
    -------
    Path
        ``DIR/report.html``.
    """
    import html as _html
    import json
    import re

    from .error_budget import attribute, centroid_statistics, variant_statistics
    from .execution import library_versions
    from .store import read_table

    out_dir = Path(out_dir)
    config = config_from_manifest(out_dir)
    table = read_table(out_dir / "results.csv")
    summary = summarize(table, config)
    budget = None
    if config.budget:
        gpath = out_dir / "budget-geometric" / "results.csv"
        cents = centroid_statistics(table, config.ranges_m)
        vs = variant_statistics(table, config.ranges_m, read_table(gpath) if gpath.is_file() else None)
        budget = {"centroids": cents, "variant_stats": vs, "attribution": attribute(vs, config.ranges_m)}
    old = (out_dir / "report.html").read_text(encoding="utf-8") if (out_dir / "report.html").is_file() else ""
    if command is None:
        m = re.search(r"Command:</p><pre>(.*?)</pre>", old, re.S)
        command = ((_html.unescape(m.group(1)) + "\n") if m else "") + (
            f"# report rebuilt from the stored results: python -m studies.campaign rebuild {out_dir}")
    path = write_campaign_report(out_dir, config, table, summary, command=command, versions=library_versions(),
                                 budget=budget, sample_figure_html=_carried_figure(old, "What the phone saw"))
    sj = out_dir / "summary.json"
    if sj.is_file():
        obj = json.loads(sj.read_text())
        by = {s["range_m"]: s for s in summary}
        for r in obj.get("ranges", []):
            s = by.get(r["range_m"])
            if s is None:
                continue
            for x in MEAN_READINGS:
                r[f"{x}_error"] = {c: s[f"{x}_{c}"] for c in STATE_KEYS}
            r.setdefault("ratio", {}).update({f"{x}_error": {c: s[f"ratio_{x}_{c}"] for c in STATE_KEYS}
                                              for x in MEAN_READINGS})
        obj["misalignment"] = misalignment_text(config)
        obj["honest_count"] = read_honest_count(out_dir)
        obj.setdefault("outputs", {}).update({"verdicts_csv": str(out_dir / "verdicts.csv"),
                                              "honest_count_json": str(out_dir / "honest_count.json")})
        sj.write_text(json.dumps(_finite(obj), indent=1, allow_nan=False) + "\n")
    return path


def _main(argv=None) -> int:
    """``python -m studies.campaign rebuild DIR [DIR ...]``: :func:`rebuild_report` on each folder."""
    import argparse

    p = argparse.ArgumentParser(prog="python -m studies.campaign",
                                description="Rebuild campaign reports from their stored results (no trial runs).")
    sub = p.add_subparsers(dest="what", required=True)
    r = sub.add_parser("rebuild", help="rewrite report.html, summary.csv, verdicts.csv, honest_count.json and "
                                       "summary.json of campaign folders in place (copy them first to keep them)")
    r.add_argument("dirs", nargs="+", metavar="DIR")
    args = p.parse_args(argv)
    for d in args.dirs:
        path = rebuild_report(d)
        counts = read_honest_count(d)["counts"]
        print(f"{path}: " + "; ".join(f"{READING_LABELS[x]} {counts[x]['within_2x']} of {counts[x]['predicted']} "
                                      f"within 2x" for x in MEAN_READINGS) + f" ({counts[HEADLINE_READING]['fitted']} fitted)")
    return 0


if __name__ == "__main__":
    raise SystemExit(_main())
