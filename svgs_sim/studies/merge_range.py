"""Which physical parameters move the range at which a phone's spots merge, and by how much.

The design question of the Amaze 4G's headline failure (Becker, Howard & Rakoczy 2014: solutions
"up to about 6.5 meter range", beyond which "the four bright spots ... merged"): what in the
lens, the flash, the target and the exposure sets that range?

Method (one parameter at a time, on the rendered chain)
    The phone faces the target on the test stand (roll and pitch 0.5 deg, off the exact facing
    at which an uncoated cube's front-face glint reaches the lens), at every range of a grid;
    each render is exposed ``exposures`` times through the phone model (its own auto-exposure)
    and the detector's threshold is applied. The **merge margin** of an exposure is the
    threshold minus the darkest level between the closest spots
    (:func:`svgs_sim.sim.render_trial.merge_margin_dn`): positive, the spots are separate blobs;
    negative, the binary image joins them. The **merge range** is where the mean margin first
    crosses zero (linear interpolation between the grid's ranges). It is found for the phone as
    profiled (nominal) and with each parameter at the low and the high end of its physical range,
    the others nominal; the same noise seeds at every range and case (common random numbers), and
    parameters acting after the render share the nominal render.

Parameters (:data:`PHYSICS`: the range and where it comes from)
    the glare's veiling fraction and wing exponent, the exposure (compensation in EV on what the
    phone's auto-exposure picks), the flash LED's offset from the lens, the cubes' spacing (the
    pattern scaled), the f-number, the app's brightness threshold and the lab's light.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from svgs_sim.base.errors import InputError
from svgs_sim.base.profiles import load_camera
from svgs_sim.sim.render_trial import RENDER, render_trial_scenario
from svgs_sim.svgs.app import settings

from .campaign import log_run, run_log
from .execution import Trial, library_versions, run_stored_study
from .report import Report, write_csv
from .seeding import check_seed, trial_seed

#: name -> (low, high, what the range is and where it comes from). The nominal value is the
#: profile's (the render kind's default for the parameter).
PHYSICS = {
    "glare_veiling_fraction": (0.01, 0.08, "share of the light in the lens' veiling-glare wings: 1-8 %, the span of "
                               "veiling glare indices of compact camera lenses (ISO 9358 measures; recalled, ASSUMPTION); "
                               "the profiles' prior is 3 %"),
    "glare_wing_exponent": (2.0, 3.5, "the wings' power law r^-n: n = 2-3.5, from surface-scatter (n ~ 2-3) to steeper "
                            "ghost-dominated falls (ASSUMPTION); prior 2.5"),
    "exposure_compensation_ev": (-2.0, 0.0, "an exposure lock or compensation the app could set: 1/4 of the "
                                 "auto-exposure's time to the auto-exposure itself (the Amaze's auto-exposure is at its "
                                 "longest time, 1/15 s, in the fitted lab)"),
    "led_offset_scale": (0.5, 1.3, "the flash LED 0.5-1.3x its profiled offset from the lens (the Amaze's: 9 mm): "
                         "4.5-11.7 mm, the span of phone designs; beyond ~12.7 mm (the cube's aperture diameter) the "
                         "return misses the lens"),
    "pattern_scale": (0.8, 1.5, "the cubes' spacing 0.8-1.5x the 3U pattern's (27.5 cm tall); wider than a 3U face "
                      "needs booms"),
    "f_number": (2.0, 2.8, "phone camera lenses of 2011-2012: f/2.0 to f/2.8 (the Amaze's f/2.2)"),
    "threshold": (170.0, 250.0, "the app's brightness threshold on the 8-bit image (an app setting, not a camera "
                  "value: assets/app/svgs-app.toml, 200 for the Amaze, ASSUMED): from just above the lit lab the "
                  "auto-exposure holds at mid-grey (its brightest per cent at ~155 counts) to just below white; "
                  "without LOW:HIGH, 0.85-1.25x the camera's app value within the app's plausible range"),
    "ambient_radiance_w_m2_sr": (0.014, 0.056, "the lab's light, half to twice the value fitted to the merge with "
                                 "the windowed centroid and the automatic threshold (0.028 W m^-2 sr^-1, "
                                 "assets/labs/fitted/msfc-frl.toml, whose plausible range is 0-0.2): through the "
                                 "auto-exposure it sets how far the spots are over full well"),
}
#: The paper's last range with solutions, per phone (Becker, Howard & Rakoczy 2014: the Amaze 4G
#: "only provided effective state calculations up to about a 6.5 meter range"; beyond it the spots
#: merged). Marked on the figures; not used by any computation.
PAPER_LAST_SOLVED_M = {"htc-amaze-4g": 6.5}
DEFAULT_RANGES_M = (3.0, 4.0, 5.0, 5.5, 6.0, 6.5, 7.0, 7.5, 8.0, 9.0, 10.0, 12.0)
#: The stand's attitude: off the exact facing, at which the on-axis cube's front-face glint
#: reaches the lens (a 0.1 deg window).
ATTITUDE_DEG = {"roll_deg": 0.5, "pitch_deg": 0.5, "yaw_deg": 0.0}


@dataclass(frozen=True)
class MergeRangeConfig:
    """What the study computes (its manifest)."""

    camera: str
    ranges_m: tuple = DEFAULT_RANGES_M
    parameters: tuple = tuple(PHYSICS)
    bounds: dict = field(default_factory=lambda: {k: v[:2] for k, v in PHYSICS.items()})
    exposures: int = 2
    seed: int = 0
    pattern: str = "svgs-3u"

    def cases(self) -> list[tuple[str, str, float | None]]:
        """``(case, parameter, value)``: the nominal one, then each parameter low and high."""
        out = [("nominal", "", None)]
        for p in self.parameters:
            lo, hi = self.bounds[p]
            out += [(f"{p}=low", p, float(lo)), (f"{p}=high", p, float(hi))]
        return out

    def manifest(self) -> dict:
        return {"study": "merge-range", "camera": self.camera, "pattern": self.pattern,
                "ranges_m": [float(r) for r in self.ranges_m], "parameters": list(self.parameters),
                "bounds": {k: [float(x) for x in self.bounds[k]] for k in self.parameters},
                "exposures": int(self.exposures), "seed": int(self.seed), "attitude_deg": ATTITUDE_DEG}


def make_config(camera: str, *, ranges_m=None, vary=None, exposures: int = 2, seed: int = 0,
                pattern: str = "svgs-3u") -> MergeRangeConfig:
    """A validated :class:`MergeRangeConfig` (:class:`InputError` on bad input, before any work).

    Parameters
    ----------
    vary : sequence of str, optional
        ``NAME`` (its :data:`PHYSICS` range) or ``NAME=LOW:HIGH``; default every parameter of
        :data:`PHYSICS`.
    """

    render_trial_scenario(camera=camera, pattern=pattern)  # the camera and pattern exist
    rs = []
    for r in (DEFAULT_RANGES_M if ranges_m is None else ranges_m):
        rs.append(RENDER.parameters["rail_m"].check(r, "--ranges"))  # rail positions on the stand
    if len(rs) < 2 or sorted(rs) != rs or len(set(rs)) != len(rs):
        raise InputError(f"--ranges: expected at least two increasing ranges, got {rs}")
    if isinstance(exposures, bool) or not isinstance(exposures, (int, np.integer)) or exposures < 1:
        raise InputError(f"--exposures: expected a positive integer, got {exposures!r}")
    names, bounds = [], {}
    for text in (vary or list(PHYSICS)):
        name, _, rng = str(text).partition("=")
        name = name.strip()
        if name not in PHYSICS:
            raise InputError(f"--vary: {name!r} is not one of the physical parameters: {', '.join(PHYSICS)}")
        if name in names:
            raise InputError(f"--vary: {name} given twice")
        lo, hi = PHYSICS[name][:2]
        if name == "threshold" and not rng:  # around this camera's app setting, within its plausible range

            app = settings()
            t = app.threshold_for(load_camera(camera).key)
            lo, hi = max(app.threshold_range_dn[0], 0.85 * t), min(app.threshold_range_dn[1], 1.25 * t)
        if rng:
            try:
                lo, hi = (float(x) for x in rng.split(":"))
            except ValueError:
                raise InputError(f"--vary: expected NAME or NAME=LOW:HIGH, got {text!r}") from None
        if not lo < hi:
            raise InputError(f"--vary {name}: expected LOW < HIGH, got {lo:g}:{hi:g}")
        for v in (lo, hi):
            render_trial_scenario(camera=camera, pattern=pattern, **{name: v})  # the parameter's own domain
        names.append(name)
        bounds[name] = (float(lo), float(hi))
    return MergeRangeConfig(camera=camera, ranges_m=tuple(rs), parameters=tuple(names), bounds=bounds,
                            exposures=int(exposures), seed=check_seed(seed), pattern=pattern)


def merge_range_trials(config: MergeRangeConfig) -> list:
    """Every trial: case x range x exposure, the noise seed shared by a (range, exposure) over cases."""


    trials, i = [], 0
    for case, param, value in config.cases():
        for ri, r in enumerate(config.ranges_m):
            for e in range(config.exposures):
                values = {"camera": config.camera, "pattern": config.pattern, "rail_m": r, "mount": "stand", **ATTITUDE_DEG}
                if param:
                    values[param] = value
                scen = render_trial_scenario(labels={"case": case, "parameter": param or "nominal",
                                                     "value": float("nan") if value is None else value,
                                                     "exposure_index": e}, **values)
                trials.append(Trial(i, scen, trial_seed(config.seed, ri * config.exposures + e)))
                i += 1
    return trials


def crossing(ranges_m, margins) -> tuple[float, str]:
    """Where the margin first goes from >= 0 to < 0 (linear interpolation), and how it is bounded:
    ``("inside")``, ``below`` (negative at the first range: the merge range is below the grid) or
    ``above`` (never negative: beyond the grid)."""
    r = np.asarray(ranges_m, float)
    m = np.asarray(margins, float)
    if not np.isfinite(m[0]) or m[0] < 0:
        return float(r[0]), "below"
    for k in range(1, len(r)):
        if np.isfinite(m[k]) and m[k] < 0:
            a, b = m[k - 1], m[k]
            return float(r[k - 1] + (r[k] - r[k - 1]) * a / (a - b)), "inside"
    return float(r[-1]), "above"


def analyse(table: dict, config: MergeRangeConfig) -> list[dict]:
    """Per case: the mean margin and the solved fraction per range, the merge range.

    Returns
    -------
    list of dict
        ``case``, ``parameter``, ``value``, ``margin_dn`` (per range), ``solved`` (per range),
        ``reasons`` (per range: {reason: n}), ``merge_range_m``, ``bound``.
    """
    out = []
    cases = np.array([str(c) for c in table["case"]])
    for case, param, value in config.cases():
        sel = cases == case
        margins, solved, reasons = [], [], []
        for r in config.ranges_m:
            m = sel & (table["rail_m"] == r)  # the stand's rail position (the study's ranges)
            v = np.asarray(table["merge_margin_dn"][m], float)
            margins.append(float(np.mean(v)) if v.size and np.all(np.isfinite(v)) else float("nan"))
            ok = table["ok"][m] == 1
            solved.append(float(ok.mean()) if m.any() else float("nan"))
            rs = {}
            for x in table["reason"][m][~ok]:
                rs[str(x)] = rs.get(str(x), 0) + 1
            reasons.append(rs)
        r_star, bound = crossing(config.ranges_m, margins)
        out.append({"case": case, "parameter": param or "nominal", "value": value, "margin_dn": margins,
                    "solved": solved, "reasons": reasons, "merge_range_m": r_star, "bound": bound})
    return out


def effects(cases: list[dict], config: MergeRangeConfig) -> list[dict]:
    """Per parameter: the merge range at its low and high value, the nominal's, and the span,
    largest span first."""
    nominal = cases[0]
    by = {c["case"]: c for c in cases}
    out = []
    for p in config.parameters:
        lo, hi = by[f"{p}=low"], by[f"{p}=high"]
        out.append({"parameter": p, "low": config.bounds[p][0], "high": config.bounds[p][1],
                    "merge_range_low_m": lo["merge_range_m"], "bound_low": lo["bound"],
                    "merge_range_high_m": hi["merge_range_m"], "bound_high": hi["bound"],
                    "nominal_m": nominal["merge_range_m"],
                    "span_m": abs(hi["merge_range_m"] - lo["merge_range_m"])})
    return sorted(out, key=lambda e: -e["span_m"])


def format_merge_range(r: float, bound: str) -> str:
    """A merge range as printed: ``< r`` / ``> r`` when it lies beyond the ranges tried (``bound``
    ``below`` / ``above``), otherwise ``r`` in metres to 2 decimals."""
    return f"< {r:g}" if bound == "below" else f"> {r:g}" if bound == "above" else f"{r:.2f}"


def tornado_figure(eff: list[dict], config: MergeRangeConfig):
    from matplotlib.figure import Figure

    fig = Figure(figsize=(8.5, 0.55 * len(eff) + 1.6))
    ax = fig.subplots()
    nom = eff[0]["nominal_m"] if eff else float("nan")
    for k, e in enumerate(reversed(eff)):
        lo, hi = e["merge_range_low_m"], e["merge_range_high_m"]
        ax.barh(k, lo - nom, left=nom, color="C0", height=0.6, label="low end" if k == 0 else None)
        ax.barh(k, hi - nom, left=nom, color="C3", height=0.6, alpha=0.8, label="high end" if k == 0 else None)
        ax.text(min(lo, hi) - 0.05, k, f"{format_merge_range(lo, e['bound_low'])} | {format_merge_range(hi, e['bound_high'])} m", ha="right",
                va="center", fontsize=7)
    ax.axvline(nom, color="k", lw=1)
    paper = PAPER_LAST_SOLVED_M.get(config.camera)
    if paper is not None:
        ax.axvspan(paper, config.ranges_m[-1] + 0.5, color="0.85", zorder=0,
                   label=f"paper: solved to ~{paper:g} m, merged beyond")
    ax.set_yticks(range(len(eff)), [f"{e['parameter']}\n{e['low']:g} .. {e['high']:g}" for e in reversed(eff)],
                  fontsize=7)
    ax.set_xlabel("range at which the spots merge (m)")
    ax.set_xlim(config.ranges_m[0] - 1.5, config.ranges_m[-1] + 0.5)
    ax.legend(fontsize=7, loc="lower right")
    ax.grid(alpha=0.3, axis="x")
    ax.set_title(f"{config.camera}: the merge range with each parameter at the low / high end of its range "
                 f"(nominal {nom:.2f} m)", fontsize=9)
    fig.tight_layout()
    return fig


def margin_figure(cases: list[dict], config: MergeRangeConfig):
    from matplotlib.figure import Figure

    n = len(config.parameters)
    cols = 3
    rows = max(1, math.ceil(n / cols))
    fig = Figure(figsize=(11, 3.0 * rows))
    axes = np.atleast_1d(fig.subplots(rows, cols)).ravel()
    by = {c["case"]: c for c in cases}
    for ax, p in zip(axes, config.parameters):
        for case, style, color in (("nominal", "-", "k"), (f"{p}=low", "--", "C0"), (f"{p}=high", "--", "C3")):
            c = by[case]
            label = "nominal" if case == "nominal" else f"{c['value']:g}"
            ax.plot(config.ranges_m, c["margin_dn"], style, color=color, marker="o", ms=3, label=label)
        ax.axhline(0, color="0.5", lw=0.8)
        if config.camera in PAPER_LAST_SOLVED_M:
            ax.axvline(PAPER_LAST_SOLVED_M[config.camera], color="0.4", ls=":", lw=1)
        ax.set_title(p, fontsize=8)
        ax.set_xlabel("range (m)")
        ax.set_ylabel("merge margin (counts)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    for ax in axes[n:]:
        ax.set_visible(False)
    fig.suptitle(f"{config.camera}: detector threshold minus the darkest level between the closest spots "
                 "(negative: merged)", fontsize=9)
    fig.tight_layout()
    return fig


def write_report(out_dir, config: MergeRangeConfig, cases: list[dict], eff: list[dict], *, command: str,
                 versions: dict, wall_s: float | None) -> Path:

    out_dir = Path(out_dir)
    write_csv(out_dir / "merge_ranges.csv", ["parameter", "low", "high", "merge_range_low_m", "bound_low",
                                             "merge_range_high_m", "bound_high", "nominal_m", "span_m"], eff)
    rep = Report(f"What moves the range at which the {config.camera}'s spots merge", command, versions)
    nom = cases[0]
    rep.paragraph(
        f"The phone as profiled merges its spots at {format_merge_range(nom['merge_range_m'], nom['bound'])} m (the paper: solutions "
        "'up to about 6.5 meter range', merged beyond). One parameter at a time, at the low and the high end of its "
        "physical range, the others as profiled; the rendered chain (Mitsuba, the phone model with its "
        f"auto-exposure, the SVGS detector's threshold), {config.exposures} exposures per render, ranges "
        f"{', '.join(f'{r:g}' for r in config.ranges_m)} m, the phone facing the target on the stand (roll and pitch "
        "0.5 deg). The detector is the paper's (the app's fixed brightness threshold, the blobs' weighted centroids; "
        "svgs_sim.svgs.app)." + (f" Wall time {wall_s:.0f} s." if wall_s else "")
        + (f" The paper's onset is marked on the figures (grey: beyond its last solved range, "
           f"{PAPER_LAST_SOLVED_M[config.camera]:g} m)." if config.camera in PAPER_LAST_SOLVED_M else ""))
    rep.heading("Answer")
    lines = []
    for e in eff:
        lines.append(f"{e['parameter']} {e['low']:g} -> {e['high']:g}: merge range {format_merge_range(e['merge_range_low_m'], e['bound_low'])}"
                     f" -> {format_merge_range(e['merge_range_high_m'], e['bound_high'])} m (span {e['span_m']:.2f} m)")
    rep.bullets(lines)
    rep.figure(tornado_figure(eff, config), "The merge range with each parameter at its low (blue) and high (red) "
               "end, around the phone as profiled (black line); a bound at the grid's edge is written < or >.")
    rep.heading("Parameters and their ranges")
    rep.table(["parameter", "low", "high", "why this range"],
              [[p, config.bounds[p][0], config.bounds[p][1], PHYSICS[p][2]] for p in config.parameters],
              text_columns=["why this range"], digits=4)
    rep.heading("Merge margin against range")
    rep.figure(margin_figure(cases, config), "Mean merge margin over the exposures (the detector's threshold minus "
               "the darkest level on the segments between the spots; below zero the binary image joins them).")
    rep.table(["case", "merge range (m)", *[f"{r:g} m solved" for r in config.ranges_m]],
              [[c["case"], format_merge_range(c["merge_range_m"], c["bound"]), *c["solved"]] for c in cases],
              text_columns=["case", "merge range (m)"], caption="Solved fraction of the exposures per range")
    rep.paragraph(
        "How to read this. The margin is measured in the delivered image's counts at the detector's own threshold, so "
        "it compares the two things that decide merging: how bright the light between two spots is (their diffraction "
        "halos, the glare wings, the exposure) and where the detector cuts. A parameter with a short bar can be "
        "chosen freely for the merge range; the longest bars are the design levers. The ranges are one at a time: "
        "interactions are not shown (a sensitivity study gives them: svgs sensitivity --trial-kind render "
        "--method morris over the same parameters and range_m, output merge_margin_dn).", "note")
    return rep.write(out_dir / "report.html")


def run_merge_range(config: MergeRangeConfig, out_dir, spec, *, chunk_size=None, progress: bool = True,
                    command: str = ""):
    """Run (or resume) the study into ``out_dir`` and write its report.

    Returns
    -------
    (cases, effects, stats, report_path)
    """


    trials = merge_range_trials(config)
    store, stats = run_stored_study(RENDER, trials, out_dir, config.manifest(), spec, chunk_size=chunk_size,
                                    progress=progress, description=f"merge range {config.camera}")
    log_run(out_dir, "rendered trials", stats)
    table = store.read_table()
    cases = analyse(table, config)
    eff = effects(cases, config)
    wall = sum(x["elapsed_s"] for x in run_log(out_dir)) or None
    path = write_report(out_dir, config, cases, eff, command=command, versions=library_versions(), wall_s=wall)
    return cases, eff, stats, path
