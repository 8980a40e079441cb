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
    "Mean error" is taken as the mean *absolute* error per component (the paper's means are
    all positive, and a signed mean over a symmetric gimbal envelope would be near zero); the
    standard deviation is that of the signed error (ddof = 1). Both are put beside the
    paper's numbers (``assets/data/svgs_2014_results.csv``) with the simulated/paper ratio.
    The Cramer-Rao bound per range is the median over trials of the solver's 1-sigma bound
    for the trial's centroid noise.

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
#: ASSUMED 1-sigma error of a range measured with the paper's hand-held laser range finder to
#: the target plane and the phone's perspective centre ("(insert accuracy)" in the paper).
PAPER_RANGE_SIGMA_M = 0.02
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
                         "stage_m": STAGE_HALF_TRAVEL_M},
        }


def paper_calibration_error(camera, pattern, ranges_m, sigma_px: float, seed: int) -> dict:
    """One calibration as the paper made it, simulated (seeded, once per campaign).

    Focal length: the paper's procedure - one image of the target facing the camera at each
    test range, the range measured with a hand-held laser range finder (1-sigma
    :data:`PAPER_RANGE_SIGMA_M`, ASSUMED: the paper leaves the accuracy blank), the focal
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

    from sim.trials import _pattern

    pat = _pattern(pattern)
    rng = study_rng(seed, 0)
    images, measured = [], []
    for r in ranges_m:
        R, t = pose_from_scenario(r)
        uv = camera.project_target(pat.points_m, R, t)
        images.append(uv + sigma_px * rng.standard_normal(uv.shape))
        measured.append(r + PAPER_RANGE_SIGMA_M * rng.standard_normal())
    est = estimate_focal(images, measured, camera, pat, centroid_sigma_px=max(sigma_px, 1e-3),
                         range_sigma_m=PAPER_RANGE_SIGMA_M)
    err = {"focal_error_frac": float(est.f_px / camera.fx - 1.0)}
    for k in ("pp_error_u_px", "pp_error_v_px", "k1_error"):
        err[k] = float(rng.normal(0.0, PAPER_CALIBRATION_SPREAD[k]))
    return err


def make_config(camera: str, *, ranges_m=None, trials_per_range: int = 200, seed: int = 0, sigma_px: float = 0.1,
                trial_kind: str = "geometric", pattern: str = "svgs-3u", calibration: str = "exact",
                calibration_error: dict | None = None, merge_px: float = 0.0) -> CampaignConfig:
    """A validated :class:`CampaignConfig` (:class:`InputError` on bad input).

    Parameters
    ----------
    camera : str
        Camera profile name or path.
    ranges_m : sequence of float, optional
        Test ranges; default the paper's for that phone (required for other cameras).
    calibration : {"exact", "paper"}
        ``exact``: the solver knows the camera exactly unless ``calibration_error`` says
        otherwise; ``paper``: draw one calibration error per campaign from
        :data:`PAPER_CALIBRATION_SPREAD`.
    calibration_error : dict, optional
        Explicit errors (``focal_error_frac``, ``pp_error_u_px``, ``pp_error_v_px``,
        ``k1_error``) for ``exact``.
    """
    from sim.trials import _camera

    cam = _camera(camera)
    kind = get_trial_kind(trial_kind)
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
    if isinstance(trials_per_range, bool) or not isinstance(trials_per_range, (int, np.integer)) or trials_per_range < 1:
        raise InputError(f"--trials: expected a positive integer, got {trials_per_range!r}")
    if "sigma_px" in kind.parameters:
        kind.parameters["sigma_px"].check(sigma_px, "--sigma-px")
    if calibration not in ("exact", "paper"):
        raise InputError(f"--calibration: expected 'exact' or 'paper', got {calibration!r}")
    err = dict(calibration_error or {})
    unknown = sorted(set(err) - set(CALIBRATION_KEYS))
    if unknown:
        raise InputError(f"calibration error: unknown key(s) {unknown}; known: {', '.join(CALIBRATION_KEYS)}")
    if calibration == "paper":
        if any(v != 0 for v in err.values()):
            raise InputError("--calibration paper draws the calibration error itself; drop the explicit error options")
        err = paper_calibration_error(cam, pattern, rs, float(sigma_px), check_seed(seed))
    for k, v in err.items():
        if k not in kind.parameters:
            if v != 0:
                raise InputError(f"trial kind {kind.name!r} cannot model a calibration error ({k})")
            continue
        kind.parameters[k].check(v, k)
    err = {k: float(v) for k, v in err.items() if k in kind.parameters}
    return CampaignConfig(camera=camera, ranges_m=tuple(rs), trials_per_range=int(trials_per_range),
                          seed=check_seed(seed), sigma_px=float(sigma_px), trial_kind=kind.name, pattern=pattern,
                          calibration=calibration, calibration_error=err, merge_px=float(merge_px))


def campaign_trials(config: CampaignConfig) -> list:
    """Every trial of the campaign: trial ``i = range_index * trials_per_range + k``.

    Returns
    -------
    list of :class:`studies.execution.Trial`
    """
    from .execution import Trial

    kind = get_trial_kind(config.trial_kind)
    trials = []
    n = config.trials_per_range
    fixed = {"camera": config.camera, "pattern": config.pattern, **config.calibration_error}
    if "sigma_px" in kind.parameters:
        fixed["sigma_px"] = config.sigma_px
    if config.merge_px and "merge_px" in kind.parameters:
        fixed["merge_px"] = config.merge_px
    for ri, r in enumerate(config.ranges_m):
        for k in range(n):
            i = ri * n + k
            rng = design_rng(config.seed, i)
            roll, pitch, yaw = (rng.uniform(-GIMBAL_ROLL_DEG, GIMBAL_ROLL_DEG), rng.uniform(-GIMBAL_PITCH_DEG, GIMBAL_PITCH_DEG),
                                rng.uniform(-GIMBAL_YAW_DEG, GIMBAL_YAW_DEG))
            stage = rng.uniform(-STAGE_HALF_TRAVEL_M, STAGE_HALF_TRAVEL_M)
            scen = build_scenario(kind, {**fixed, "range_m": r + stage, "roll_deg": roll, "pitch_deg": pitch,
                                         "yaw_deg": yaw}, labels={"nominal_range_m": float(r)})
            trials.append(Trial(i, scen, trial_seed(config.seed, i)))
    return trials


# --------------------------------------------------------------------------- statistics
def summarize(table: dict, config: CampaignConfig, paper: dict | None = None) -> list[dict]:
    """Per-range statistics beside the paper's.

    Parameters
    ----------
    table : dict of column -> ndarray
        The campaign's rows (:meth:`ResultStore.read_table`).

    Returns
    -------
    list of dict, one per range
        ``range_m``, ``n``, ``n_ok``, ``success_rate``, ``reasons`` (dict), and per component
        ``c``: ``mean_abs_<c>``, ``bias_<c>``, ``std_<c>``, ``crlb_<c>``, ``paper_mean_<c>``,
        ``paper_std_<c>``, ``ratio_mean_<c>``, ``ratio_std_<c>``.
    """
    from sim.trials import _camera

    paper = svgs_2014_results() if paper is None else paper
    phone = _camera(config.camera).name
    out = []
    for r in config.ranges_m:
        sel = table["nominal_range_m"] == r
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
            row[f"std_{c}"] = float(np.std(e, ddof=1)) if e.size > 1 else float("nan")
            row[f"crlb_{c}"] = float(np.median(table[f"crlb_{c}"][ok])) if e.size else float("nan")
            row[f"paper_mean_{c}"] = pm[c] if pm else float("nan")
            row[f"paper_std_{c}"] = ps[c] if ps else float("nan")
            row[f"ratio_mean_{c}"] = row[f"mean_abs_{c}"] / pm[c] if pm and pm[c] > 0 else float("nan")
            row[f"ratio_std_{c}"] = row[f"std_{c}"] / ps[c] if ps and ps[c] > 0 else float("nan")
        out.append(row)
    return out


def summary_long_rows(summary: list[dict]) -> list[dict]:
    """The summary as long-form rows (range, component, statistic, simulated, paper, ratio) for CSV."""
    rows = []
    for s in summary:
        for c in STATE_KEYS:
            rows.append({"range_m": s["range_m"], "component": c, "statistic": "mean_abs_error",
                         "simulated": s[f"mean_abs_{c}"], "paper": s[f"paper_mean_{c}"], "ratio": s[f"ratio_mean_{c}"]})
            rows.append({"range_m": s["range_m"], "component": c, "statistic": "std",
                         "simulated": s[f"std_{c}"], "paper": s[f"paper_std_{c}"], "ratio": s[f"ratio_std_{c}"]})
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
def _side_by_side(summary, stat_sim, stat_paper, stat_ratio):
    cols = ["range (m)"]
    for c in STATE_KEYS:
        cols += [f"{SHORT[c]} sim", f"{SHORT[c]} paper", f"{SHORT[c]} ratio"]
    rows = []
    for s in summary:
        row = [s["range_m"]]
        for c in STATE_KEYS:
            row += [s[f"{stat_sim}_{c}"], s[f"{stat_paper}_{c}"], s[f"{stat_ratio}_{c}"]]
        rows.append(row)
    return cols, rows


def write_campaign_report(out_dir, config: CampaignConfig, table: dict, summary: list[dict], *, command: str,
                          versions: dict, stats=None) -> Path:
    """``DIR/report.html`` and ``DIR/summary.csv`` for a finished campaign."""
    from .report import Report, write_csv

    out_dir = Path(out_dir)
    write_csv(out_dir / "summary.csv", ["range_m", "component", "statistic", "simulated", "paper", "ratio"],
              summary_long_rows(summary))
    n = int(np.sum([s["n"] for s in summary]))
    n_ok = int(np.sum([s["n_ok"] for s in summary]))
    rep = Report(f"SVGS test campaign simulated: {config.camera} ({config.trial_kind} trials)", command, versions)
    rep.paragraph(
        f"{n} trials over {len(config.ranges_m)} ranges ({', '.join(f'{r:g}' for r in config.ranges_m)} m), "
        f"{n_ok} solved ({100.0 * n_ok / max(n, 1):.1f} %). Each trial draws the Sensor Mount's gimbal attitude "
        f"uniformly in roll/pitch +/-{GIMBAL_ROLL_DEG:g} deg and yaw +/-{GIMBAL_YAW_DEG:g} deg and the translation "
        f"stage in +/-{100 * STAGE_HALF_TRAVEL_M:g} cm, as in the MSFC Flight Robotics Lab tests of Becker, Howard & "
        "Rakoczy (2014)."
    )
    rep.heading("Set-up")
    setup = [("camera", config.camera), ("pattern", config.pattern), ("trial kind", config.trial_kind),
             ("trials per range", config.trials_per_range), ("seed", config.seed),
             ("centroid noise sigma_px", config.sigma_px), ("calibration practice", config.calibration)]
    setup += [(f"solver calibration error: {k}", v) for k, v in config.calibration_error.items()]
    if stats is not None:
        setup += [("executor (last run)", stats.executor), ("trials run in the last run", stats.n_run),
                  ("wall time of the last run (s)", round(stats.elapsed_s, 2))]
    rep.table(["setting", "value"], setup, text_columns=["value"], digits=4)
    rep.heading("Mean error (paper Tables 2 and 4)")
    rep.paragraph("Mean absolute error per component of the relative state (position of the camera in the target "
                  "frame, m; paper roll/pitch/yaw, deg): simulated, the paper's, and simulated/paper.", "note")
    cols, rows = _side_by_side(summary, "mean_abs", "paper_mean", "ratio_mean")
    rep.table(cols, rows, caption="Mean |error|: simulated | paper | ratio")
    rep.heading("Standard deviation (paper Tables 3 and 5)")
    cols, rows = _side_by_side(summary, "std", "paper_std", "ratio_std")
    rep.table(cols, rows, caption="Standard deviation of the error: simulated | paper | ratio")
    rep.heading("Cramer-Rao bound per range")
    rep.paragraph(f"Median over trials of the solver's 1-sigma Cramer-Rao bound for {config.sigma_px:g} px centroid "
                  "noise, beside the simulated standard deviation and the signed mean (bias).", "note")
    cols = ["range (m)"] + [f"{SHORT[c]} CRLB" for c in STATE_KEYS] + [f"{SHORT[c]} std/CRLB" for c in STATE_KEYS] \
        + [f"{SHORT[c]} bias" for c in STATE_KEYS]
    rows = [[s["range_m"]] + [s[f"crlb_{c}"] for c in STATE_KEYS]
            + [s[f"std_{c}"] / s[f"crlb_{c}"] if s[f"crlb_{c}"] > 0 else float("nan") for c in STATE_KEYS]
            + [s[f"bias_{c}"] for c in STATE_KEYS] for s in summary]
    rep.table(cols, rows, caption="Cramer-Rao 1-sigma, efficiency (std/CRLB) and bias")
    rep.table(["range (m)", "trials", "solved", "success rate", "failures by reason"],
              [[s["range_m"], s["n"], s["n_ok"], s["success_rate"],
                ", ".join(f"{k}: {v}" for k, v in sorted(s["reasons"].items())) or "none"] for s in summary],
              caption="Success rate", text_columns=["failures by reason"])
    rep.heading("Errors versus range")
    rep.figure(crlb_figure(summary, config), "Simulated standard deviation and mean |error| (blue), the paper's "
               "(red) and the Cramer-Rao bound (black), per component, versus range.")
    rep.heading("Error histograms (paper Figures 6-13)")
    for fig, cap in histogram_figures(table, config):
        rep.figure(fig, cap)
    rep.heading("What dominates the error at each range")
    rep.bullets(explain(summary, config))
    rep.paragraph(
        "How to read this. With centroid noise alone the solver is efficient: the simulated scatter sits on the "
        "Cramer-Rao bound, which grows as range squared for the position (the camera's position in the target "
        "frame is coupled to roll and pitch through the lever arm of the range) and linearly for the angles. A wrong "
        "calibration used by the solver (focal length, principal point, distortion) adds a bias and, because the "
        "gimbal attitude changes from trial to trial, a pose-dependent scatter; the paper's rough focal-length "
        "calibration is such a source. Where the simulated/paper ratio stays well below one, the paper's errors "
        "contain sources this trial kind does not model: the lab truth itself (a hand-held laser range finder for "
        "gross range, the cart on the rail, the alignment of the gimbal zero to the target frame - constant offsets "
        "such as the paper's ~2 deg yaw mean error on the Galaxy Nexus at every range), spot shape, blooming and "
        "thresholding in the real images (the render-and-solve trial models those), and the phone's image "
        "processing. Where the ratio is above one, the simulation's noise or envelope is larger than the test's for "
        "that component: the trial gives every spot the same isotropic sigma_px, and the paper does not say that "
        "every range used the whole gimbal envelope."
    )
    return rep.write(out_dir / "report.html")


def print_summary(summary: list[dict], config: CampaignConfig, file=None) -> None:
    """A short table on stdout: per range, success and std simulated vs paper."""
    import sys

    f = file or sys.stdout
    print(f"campaign {config.camera}: {config.trials_per_range} trials per range, sigma_px {config.sigma_px:g}, "
          f"calibration {config.calibration}", file=f)
    hdr = f"{'range_m':>8} {'ok':>6} " + " ".join(f"{SHORT[c] + ' std':>10} {'/paper':>7}" for c in STATE_KEYS)
    print(hdr, file=f)
    for s in summary:
        cells = " ".join(f"{s[f'std_{c}']:10.3g} {s[f'ratio_std_{c}']:7.2f}" for c in STATE_KEYS)
        print(f"{s['range_m']:8g} {s['n_ok']:>3}/{s['n']:<3}{cells}".replace("nan", "  -"), file=f)


def run_campaign(config: CampaignConfig, out_dir, spec, *, chunk_size=None, progress: bool = True,
                 command: str = "", out=None):
    """Run (or resume) a campaign into ``out_dir`` and write its report.

    Returns
    -------
    (summary, stats, report_path)
    """
    from .execution import library_versions, run_stored_study

    kind = get_trial_kind(config.trial_kind)
    trials = campaign_trials(config)
    store, stats = run_stored_study(kind, trials, out_dir, config.manifest(), spec, chunk_size=chunk_size,
                                    progress=progress, description=f"campaign {config.camera}")
    table = store.read_table()
    summary = summarize(table, config)
    path = write_campaign_report(out_dir, config, table, summary, command=command, versions=library_versions(),
                                 stats=stats)
    return summary, stats, path
