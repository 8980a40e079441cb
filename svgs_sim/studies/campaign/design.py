"""The campaign's configuration and trial design: the Sensor Mount's envelope, the paper's ranges,
:class:`CampaignConfig` (:func:`make_config` validates it), the stand settings, the lab's stand
errors and every trial."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from svgs_sim.base.errors import InputError
from svgs_sim.base.profiles import load_camera, load_pattern
from svgs_sim.sim.lab import lab_errors as _lab_errors
from svgs_sim.sim.lab import stand_misalignment_deg
from svgs_sim.sim.stand import TestStand, sample_in_view
from svgs_sim.sim.trials import build_scenario, get_trial_kind

from ..error_budget import variant_trials
from ..execution import Trial
from ..seeding import check_seed, design_rng, trial_seed
from .paper_calibration import CALIBRATION_KEYS, paper_calibration_error, paper_lens, rangefinder_readings

#: The paper's Sensor Mount envelope.
GIMBAL_ROLL_DEG = 25.0


GIMBAL_PITCH_DEG = 25.0


GIMBAL_YAW_DEG = 45.0


STAGE_HALF_TRAVEL_M = 0.15


#: The ranges of the paper's Tables 2-5, per phone profile.
PAPER_RANGES_M = {"htc-amaze-4g": (1.0, 2.0, 3.0, 4.0, 6.5), "galaxy-nexus": (5.0, 10.0, 15.0, 20.0, 30.0)}


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
        """One of the lab's error sources (:data:`svgs_sim.sim.lab.ERROR_KEYS`; 0: absent)."""
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
                         "stage_m": STAGE_HALF_TRAVEL_M, "in_view": "sim.stand.sample_in_view"},  # a label stored in manifests: unchanged, so older campaigns resume
            "exposures_per_render": int(self.exposures_per_render),
            "misalignment_deg": [float(x) for x in self.misalignment_deg],
            "lens": {k: float(v) for k, v in sorted(self.lens.items())},
            "budget": bool(self.budget),
            "lab_errors": {k: float(v) for k, v in sorted(self.lab_errors.items())},
        }


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
        The phone's (roll, pitch, yaw) in its holder (:class:`svgs_sim.sim.stand.TestStand`), deg.
        Default: the lab's for this phone (:func:`svgs_sim.sim.lab.stand_misalignment_deg`: 2 deg of yaw
        for the Galaxy Nexus, fitted to Table 4; 0 for others).
    budget : bool
        Also run the error-budget variants (render kind; :mod:`svgs_sim.studies.error_budget`).
    lab_errors : bool
        The lab's error sources (default; :func:`svgs_sim.sim.lab.lab_errors`, sourced): each stand
        setting's gimbal and stage errors, the rail position recorded from the rangefinder
        (whose readings also feed the paper's focal calibration) and, for the render kind, the
        air's turbulence. False: a perfect stand, exact ranges and still air.
    """

    cam = load_camera(camera)
    kind = get_trial_kind(trial_kind)
    if kind.name not in ("render", "geometric"):
        raise InputError(f"--trial-kind: the campaign runs 'render' or 'geometric' trials, got {trial_kind!r}")
    rs = _check_ranges_m(ranges_m, cam.key, kind)
    trials_per_range = _count_option(trials_per_range, "--trials")
    exposures_per_render = _count_option(exposures_per_render, "--exposures-per-render")
    if "sigma_px" in kind.parameters:
        kind.parameters["sigma_px"].check(sigma_px, "--sigma-px")
    if calibration not in ("exact", "paper"):
        raise InputError(f"--calibration: expected 'exact' or 'paper', got {calibration!r}")
    if misalignment_deg is None:

        misalignment_deg = stand_misalignment_deg(cam.key)
    mis = tuple(float(x) for x in misalignment_deg)
    TestStand(misalignment_deg=mis)  # InputError beyond +/-10 deg
    if budget and kind.name != "render":
        raise InputError("--budget: the error budget switches sources of the rendered chain off; use --trial-kind render")
    err, lens = _calibration_error(calibration, calibration_error, kind, cam, pattern, rs, sigma_px, seed,
                                   lab_errors)
    return CampaignConfig(camera=camera, ranges_m=tuple(rs), trials_per_range=trials_per_range,
                          seed=check_seed(seed), sigma_px=float(sigma_px), trial_kind=kind.name, pattern=pattern,
                          calibration=calibration, calibration_error=err, merge_px=float(merge_px),
                          exposures_per_render=exposures_per_render, misalignment_deg=mis, lens=lens,
                          budget=bool(budget), lab_errors=_campaign_lab_errors(_lab_errors(), kind.name, lab_errors))


def _check_ranges_m(ranges_m, camera_key: str | None, kind) -> list[float]:
    """The campaign's test ranges (the stand's rail positions), checked against the trial kind's
    ``rail_m`` parameter.

    Parameters
    ----------
    ranges_m : sequence of float or None
        Test ranges (m); None: the paper's for the camera ``camera_key``.
    camera_key : str or None
        The loaded camera's key (:attr:`svgs_sim.base.profiles.Camera.key`, to look up
        :data:`PAPER_RANGES_M`).
    kind : TrialKind
        The trial kind whose ``rail_m`` parameter checks each range.

    Returns
    -------
    list of float, shape (n_ranges,)
        The checked ranges (m), in the given order; :class:`InputError` when empty or repeated.
    """
    if ranges_m is None:
        if camera_key not in PAPER_RANGES_M:
            raise InputError(f"--ranges: camera key {camera_key!r} is not one of the paper's phones "
                             f"({', '.join(PAPER_RANGES_M)}); give the test ranges")
        ranges_m = PAPER_RANGES_M[camera_key]
    rs = []
    for r in ranges_m:
        rs.append(kind.parameters["rail_m"].check(r, "--ranges"))
    if not rs:
        raise InputError("--ranges: no ranges given")
    if len(set(rs)) != len(rs):
        raise InputError(f"--ranges: repeated range in {rs}")
    return rs


def _calibration_error(calibration: str, calibration_error: dict | None, kind, cam, pattern: str,
                       rs: list, sigma_px: float, seed: int, lab_errors: bool) -> tuple[dict, dict]:
    """The solver's calibration error and the true lens of a campaign (see :func:`make_config`).

    Parameters
    ----------
    calibration : {"paper", "exact"}
        ``paper``: drawn from the paper's practice (:func:`paper_lens` for the render kind,
        :func:`paper_calibration_error` otherwise); ``exact``: ``calibration_error`` as given.
    calibration_error : dict or None
        Explicit errors (keys of :data:`CALIBRATION_KEYS`) for ``exact``.
    kind : TrialKind
        The trial kind, whose parameters check each error.
    cam : Camera
        The loaded camera profile.
    pattern : str
        Pattern profile name.
    rs : list of float, shape (n_ranges,)
        The checked test ranges (m).
    sigma_px : float
        Centroid noise (px) of the geometric kind.
    seed : int
        The campaign's seed (checked here).
    lab_errors : bool
        Whether the rangefinder's error feeds the paper's focal calibration.

    Returns
    -------
    err : dict
        The calibration errors the trial kind models (float values).
    lens : dict
        The true lens (:func:`paper_lens`) for the paper calibration of the render kind, else empty.
    """
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
    return err, lens


def _campaign_lab_errors(errors: dict, kind: str, on: bool) -> dict:
    """The lab's error sources a campaign applies: all of them (turbulence for the render kind
    only: the geometric kind has no spots to move), or none."""
    if not on:
        return {}
    out = {k: float(v) for k, v in errors.items() if v > 0}
    if kind != "render":
        out.pop("turbulence_cn2_m23", None)
    return out


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
        ``rail_m`` (the recorded rail position) and the scenario's ``stand_err_*`` and ``rail_err_m``.
        ``readings``: :func:`rangefinder_readings` when the caller has them.
    """
    g, st = config.lab_error("gimbal_accuracy_deg"), config.lab_error("stage_accuracy_m")
    rng = design_rng(config.seed, STAND_ERROR_STREAM + ri * POSE_STRIDE + j)
    e = rng.uniform(-1.0, 1.0, 4)
    recorded = (rangefinder_readings(config) if readings is None else readings)[ri]
    return {"rail_m": recorded, "rail_err_m": float(config.ranges_m[ri] - recorded),
            "stand_err_roll_deg": float(g * e[0]), "stand_err_pitch_deg": float(g * e[1]),
            "stand_err_yaw_deg": float(g * e[2]), "stand_err_stage_m": float(st * e[3])}


#: Design streams per range (a range's stand settings never depend on the number of trials).
POSE_STRIDE = 1_000_000


def campaign_poses(config: CampaignConfig) -> list[list[dict]]:
    """The stand settings of every range: ``poses[ri][j]`` (``stage_m``, ``roll_deg``,
    ``pitch_deg``, ``yaw_deg``), drawn uniformly over the Sensor Mount's envelope and kept when
    the phone sees every target (:func:`svgs_sim.sim.stand.sample_in_view`; pose ``j`` of range ``ri``
    from its own stream ``design_rng(seed, ri * POSE_STRIDE + j)``)."""

    cam, pat = load_camera(config.camera), load_pattern(config.pattern)
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
    follow (:func:`svgs_sim.studies.error_budget.variant_trials`): the same settings and noise seeds with
    one source switched off, ids from ``len(baseline) * (v + 1)``.

    Returns
    -------
    list of :class:`svgs_sim.studies.execution.Trial`
    """

    kind = get_trial_kind(config.trial_kind)
    trials = []
    n, K = config.trials_per_range, config.exposures_per_render
    fixed = {"camera": config.camera, "pattern": config.pattern, **config.calibration_error, "mount": "stand",
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
            lab = stand_errors(config, ri, j, readings) if config.lab_errors else {"rail_m": r}
            scen = build_scenario(kind, {**fixed, **poses[ri][j], **lab},
                                  labels={"nominal_range_m": float(r), "pose_index": j, "exposure_index": e,
                                          "variant": "baseline"})
            trials.append(Trial(i, scen, trial_seed(config.seed, i)))
    if config.budget and variants:

        trials += variant_trials(trials, config)
    return trials
