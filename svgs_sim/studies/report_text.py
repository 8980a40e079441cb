"""The result numbers of the README's and the docs' prose, written from the committed reports' data.

A page marks each generated passage::

    <!-- generated: NAME -->
    ... text this module writes from the data ...
    <!-- /generated: NAME -->

and :data:`BLOCKS` holds, per ``NAME``, the function that writes it from the files under
``docs/reports/`` (CSV and JSON the report commands made). ``python -m svgs_sim.studies.report_text``
rewrites every passage in place (and the front page's figure, :data:`FRONT_FIGURE`); ``--check`` writes nothing and exits 1 listing the passages whose
text differs from what the data give (a number typed by hand, or a report regenerated without its
prose). The test suite runs the check (``tests/test_report_text.py``), so a stale number fails it.
Hand-written commentary around the passages quotes no result number.
"""

from __future__ import annotations

import argparse
import csv
import difflib
import json
import re
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np

from svgs_sim.assets.papers import svgs_2014_results

from .campaign.design import SHORT
from .campaign.figures import weak_mode_statistics
from .mechanisms import cell_mechanisms, mechanisms_markdown
from .store import read_table
from .tof_study.design import PAPER_FIG14_Z_MM

#: The pages that carry generated passages, relative to the repository root.
PAGES = ("README.md", "docs/index.md", "docs/studies.md", "docs/tof.md", "docs/orbit.md", "docs/basilisk.md",
         "docs/approach.md", "docs/sensor-model.md", "docs/reports/montecarlo-docking/README.md")
#: The command that writes them (quoted in each passage's page).
COMMAND = "python -m svgs_sim.studies.report_text"
BLOCK_RE = re.compile(r"(<!-- generated: (?P<name>[\w.-]+) -->\n)(?P<body>.*?)(<!-- /generated: (?P=name) -->)", re.S)
PHONES = ("galaxy-nexus", "htc-amaze-4g")
PHONE_NAMES = {"galaxy-nexus": "Galaxy Nexus", "htc-amaze-4g": "HTC Amaze 4G"}


def _campaign(root: Path, phone: str) -> Path:
    return root / "docs" / "reports" / f"campaign-{phone}"


def _json(path: Path) -> dict:
    return json.loads(path.read_text(encoding="utf-8"))


def _number(text: str):
    try:
        return float(text)
    except ValueError:
        return text


def _verdicts(root: Path, phone: str) -> list[dict]:
    """``verdicts.csv`` of a campaign, numbers as floats (empty fields as ``""``)."""
    with open(_campaign(root, phone) / "verdicts.csv", newline="", encoding="utf-8") as fh:
        return [{k: _number(v) for k, v in row.items()} for row in csv.DictReader(fh)]


def _summary(root: Path, phone: str) -> list[dict]:
    return _json(_campaign(root, phone) / "summary.json")["ranges"]


# --------------------------------------------------------------------------- the passages
def merge_range(root: Path) -> str:
    """The Amaze 4G's merging range, its margin at 6.5 m and its sensitivity to the lab's light."""
    d = _json(root / "docs" / "reports" / "merge-range-htc-amaze-4g" / "summary.json")
    nom = d["cases"][0]
    i65 = d["ranges_m"].index(6.5)
    light = {c["value"]: c for c in d["cases"] if c["parameter"] == "ambient_radiance_w_m2_sr"}
    lo, hi = light[min(light)], light[max(light)]

    def where(c):
        return {"inside": f"{c['merge_range_m']:.3g} m", "above": f"beyond {c['merge_range_m']:g} m",
                "below": f"below {c['merge_range_m']:g} m"}[c["bound"]]

    return (f"With the fitted light the Amaze's spots merge at {nom['merge_range_m']:.3g} m; the margin is thin ({nom['margin_dn'][i65]:.2g} DN of "
            f"the app's threshold at 6.5 m), and {lo['value']:g} or {hi['value']:g} W m^-2 sr^-1 of light (the sweep's "
            f"low and high ends around the fitted value) moves the merge to {where(lo)} or {where(hi)} "
            f"(`docs/reports/merge-range-htc-amaze-4g/summary.json`).\n")


def campaign_counts(root: Path) -> str:
    """Per phone: the std cells within 2x, below, above, their explanations; the mean cells not scored."""
    lines = []
    for ph in PHONES:
        c = _json(_campaign(root, ph) / "honest_count.json")["counts"]
        h = next(iter(c.values()))["by_statistic"]
        s, m = h["std"], h["mean_error"]
        lines.append(f"- {PHONE_NAMES[ph]}: {s['within_2x']} of {s['predicted']} standard-deviation cells within 2x "
                     f"of the paper ({s['below']} below, {s['above']} above; of those outside, {s['measured']} with "
                     f"a measured mechanism, {s['unexplained']} unexplained); its {m['not_predictable']} mean-error "
                     "cells are not predictable and are in no count.")
    return "\n".join(lines) + "\n"


def campaign_std_cells(root: Path) -> str:
    """Every std cell outside 2x, per phone, with its verdict."""
    lines = ["| phone | range (m) | component | simulated / paper | verdict | explanation |", "|---|---|---|---|---|---|"]
    for ph in PHONES:
        for v in _verdicts(root, ph):
            if v["statistic"] == "std" and v["verdict"] not in ("within_2x", "no_paper_value"):
                lines.append(f"| {PHONE_NAMES[ph]} | {v['range_m']:g} | {SHORT[v['component']]} | {v['ratio']:.2f} | "
                             f"{v['verdict']} | {v['explanation'] or ''} |")
    return "\n".join(lines) + "\n"


def campaign_consistency(root: Path) -> str:
    """Per phone and range: the solutions the paper's app reports and those the consistency test refuses."""
    lines = ["| phone | range (m) | trials | reported (the paper's app) | refused by the consistency test |",
             "|---|---|---|---|---|"]
    for ph in PHONES:
        for r in _summary(root, ph):
            lines.append(f"| {PHONE_NAMES[ph]} | {r['range_m']:g} | {r['trials']} | {r['solved']} | "
                         f"{r.get('refused_by_consistency_test', 0)} |")
    return "\n".join(lines) + "\n"


def campaign_mean_cells(root: Path) -> str:
    """The mean-error cells beside the floor the simulated scatter implies and the simulated bias."""
    lines = []
    for ph in PHONES:
        vs = [v for v in _verdicts(root, ph) if v["statistic"] == "mean_error" and v["verdict"] == "not_predictable"]
        over = np.array([v["paper"] / v["floor_from_std"] for v in vs if v["floor_from_std"] > 0])
        bias = np.array([abs(v["bias"]) / v["paper"] for v in vs])
        lines.append(f"- {PHONE_NAMES[ph]}: the paper's mean errors are {np.min(over):.2g}-{np.max(over):.2g} times "
                     f"the floor 0.80 std of the simulated scatter (median {np.median(over):.2g}); the simulated "
                     f"signed biases are {np.min(bias):.2g}-{np.max(bias):.2g} of the paper's values "
                     f"(median {np.median(bias):.2g}).")
    return "\n".join(lines) + "\n"


def weak_mode(root: Path) -> str:
    """The correlation and slope of x on R tan(pitch) and y on R tan(roll), simulated and the paper's."""
    paper = svgs_2014_results()
    lines = []
    for ph in PHONES:
        st = weak_mode_statistics(read_table(_campaign(root, ph) / "results.csv"), ph, paper)
        parts = []
        for pos, v in st.items():
            pr = [x for _, x in v["paper_ratio"]]
            parts.append(f"{SHORT[pos]} against R tan({SHORT[v['angle']]}): correlation {v['corr']:+.2f}, slope "
                         f"{v['slope']:+.2f} over {v['n']} trials; the paper's {SHORT[pos]} / (R tan "
                         f"{SHORT[v['angle']]}) {min(pr):.2f}-{max(pr):.2f}")
        lines.append(f"- {PHONE_NAMES[ph]}: " + "; ".join(parts) + ".")
    return "\n".join(lines) + "\n"


def _tof_rows(root: Path) -> dict:
    """``docs/reports/tof_stability.csv``: ``(run, range_m, statistic) -> [6 values]`` in its column order."""
    with open(root / "docs" / "reports" / "tof_stability.csv", newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    cols = [c for c in rows[0] if c not in ("run", "range_m", "statistic")]
    return {(r["run"], float(r["range_m"]), r["statistic"]): np.array([float(r[c]) for c in cols]) for r in rows}


def _tof_ratios(t: dict):
    """The baseline's fluctuation over the paper's Table 2 (5712 mm) and Table 3 (697 mm), shape (6,)
    each, and the Fig. 14 sweep's z RMS beyond 5 m as sorted ``(range_m, mm)`` pairs."""
    fl = "fluctuation"
    r2 = t[("baseline", 5.712, fl)] / t[("paper table 2", 5.712, fl)]
    r3 = t[("baseline", 0.697, fl)] / t[("paper table 3", 0.697, fl)]
    z = sorted((r, v[2]) for (run, r, st), v in t.items()
               if run == "fig14 sweep, paper (fixed point, default)" and st == "rms" and r >= 5.0)
    return r2, r3, z


def tof_tables(root: Path) -> str:
    """The ToF study's Tables 1-3 ratios and its Fig. 14 range error, from ``tof_stability.csv``."""
    t = _tof_rows(root)
    r2, r3, z = _tof_ratios(t)
    gn = t[("converged optimum (Gauss-Newton)", 5.712, "fluctuation")] / t[("paper table 2", 5.712, "fluctuation")]
    r1 = t[("baseline", 0.697, "fluctuation")] / t[("paper table 1", 0.697, "fluctuation")]
    within = sum(0.5 <= x / PAPER_FIG14_Z_MM <= 2.0 for _, x in z)
    std2 = t[("baseline", 5.712, "std")]

    def f(v):
        return ", ".join(f"{x:.2f}" for x in v)

    return (f"- **One configuration for Tables 2, 3 and Fig. 14** (`svgs_sim.tof.PipelineParams()` defaults): Table 2 "
            f"(5712 mm) ratios {f(r2)} (x, y, z, roll, pitch, yaw): {sum(0.5 <= x <= 2 for x in r2)} of 6 within 2x; "
            f"z (std {std2[2]:.1f} mm) is {r2[2]:.1f}x the paper's. The converged optimum (Gauss-Newton) gives "
            f"{f(gn)}. Table 3 (697 mm) {r3.min():.2f}-{r3.max():.2f}x; Table 1 {r1.min():.2f}-{r1.max():.2f}x. Fig. 14 "
            f"range error beyond 5 m {', '.join(f'{x:.1f}' for _, x in z)} mm RMS at {z[0][0]:g}-{z[-1][0]:g} m = "
            f"{', '.join(f'{x / PAPER_FIG14_Z_MM:.2f}' for _, x in z)}x the paper's {PAPER_FIG14_Z_MM:g} mm: {within} of "
            f"{len(z)} ranges within 2x.\n")


def tof_headline(root: Path) -> str:
    """The ToF sensor's headline against the paper's Tables 1-3 and Fig. 14 (the front page)."""
    r2, r3, z = _tof_ratios(_tof_rows(root))
    within = sum(0.5 <= x / PAPER_FIG14_Z_MM <= 2.0 for _, x in z)
    return (f"- Range error beyond 5 m (Fig. 14): {within} of {len(z)} ranges within 2x of the paper's "
            f"{PAPER_FIG14_Z_MM:g} mm.\n"
            f"- Fluctuations at 5712 mm (Table 2): {sum(0.5 <= x <= 2 for x in r2)} of 6 within 2x "
            f"({r2.min():.2f}-{r2.max():.2f}x).\n"
            f"- Fluctuations at 697 mm (Table 3): {r3.min():.2f}-{r3.max():.2f}x the paper's: the simulated sensor is "
            f"far quieter there than the one measured, a gap measured but not closed ([ToF](tof.md)).\n")


def sun_studies(root: Path) -> str:
    """The committed on-orbit availability studies, per study and phone: trials solved (with the sun
    above and below the pattern plane), wrong locks (those the consistency test flags) and the wrong
    locks the paper's gates would have made, from each study's ``summary.json``."""
    rows = ["| study | phone | solved | sun on the face (el > 0) | sun behind (el < 0) | wrong locks (flagged) "
            "| with the paper's gates |", "|---|---|---|---|---|---|---|"]
    for study, what in (("sun-study", "grid, the lab's breadboard"), ("sun-study-3u", "grid, the shipped 3U body"),
                        ("sun-study-albedo", "the Earth behind, three albedos")):
        for ph in PHONES:
            path = root / "docs" / "reports" / f"{study}-{ph}" / "summary.json"
            if not path.is_file():
                continue
            cells = _json(path)["cells"]

            def tally(sel, key):
                return sum(c[key] for c in cells if sel(c))

            n, ok = tally(lambda c: True, "trials"), tally(lambda c: True, "solved")
            up_n, up = tally(lambda c: c["sun_elevation_deg"] > 0, "trials"), tally(lambda c: c["sun_elevation_deg"] > 0, "solved")
            dn_n, dn = tally(lambda c: c["sun_elevation_deg"] < 0, "trials"), tally(lambda c: c["sun_elevation_deg"] < 0, "solved")
            rows.append(f"| {what} | {PHONE_NAMES[ph]} | {ok}/{n} | {up}/{up_n} | {dn}/{dn_n} | "
                        f"{tally(lambda c: True, 'wrong_lock')} ({tally(lambda c: True, 'wrong_lock_flagged')}) | "
                        f"{tally(lambda c: True, 'wrong_lock_paper_gates')} |")
    return "\n".join(rows) + "\n"


def basilisk_results(root: Path) -> str:
    """The committed docking run (``docs/figures/basilisk_docking.json``): per sensor the arrival, the
    delta-v, the frames solved and accepted with the dropouts, the final and navigation errors."""
    d = _json(root / "docs" / "figures" / "basilisk_docking.json")
    rows = ["| sensor | arrived | delta-v | frames solved / accepted | final error against the goal (x, y, z) | "
            "navigation error at arrival (x, y, z) |", "|---|---|---|---|---|---|"]
    for key, name in (("ideal", "ideal"), *((ph, PHONE_NAMES[ph]) for ph in PHONES if ph in d)):
        r = d[key]
        drop = ", ".join(f"{n} `{k}`" for k, n in r["dropouts_by_reason"].items())
        mm = lambda v: "(" + ", ".join(f"{round(1000 * x, 1) or 0.0:.1f}" for x in v) + ") mm"  # noqa: E731
        rows.append(f"| {name} | {'%g s' % r['time_s'] if r['arrived'] else 'no'} | {100 * r['delta_v_m_s']:.2f} cm/s | "
                    f"{r['frames_solved']} / {r['frames_accepted']}{f' ({drop})' if drop else ''} | "
                    f"{mm(r['final_position_error_m'])} | {mm(r['final_navigation_error_m'])} |")
    for ph in PHONES:
        c = d.get(ph, {}).get("cost_vs_ideal")
        if c:
            rows.append("")
            rows.append(f"- {PHONE_NAMES[ph]} against the ideal sensor: delta-v {100 * c['delta_v_m_s']:+.2f} cm/s "
                        f"({100 * c['delta_v_m_s'] / d['ideal']['delta_v_m_s']:+.1f} %), time "
                        f"{'n/a' if c['time_s'] is None else '%+g s' % c['time_s']}, final error "
                        f"{1000 * c['final_position_error_norm_m']:+.1f} mm; first solution at "
                        f"{d[ph]['first_solved_range_m']:.1f} m.")
    walls = ", ".join(f"{d[k]['wall_s']:g} s for {'the ideal run' if k == 'ideal' else PHONE_NAMES[k]}" for k in d)
    return ("\n".join(rows) + f"\n\nRun at {d['galaxy-nexus']['sensor_rate_hz']:g} frames/s with a "
            f"{d['galaxy-nexus']['latency_s']:g} s latency; wall time (a timing, of this machine): {walls}.\n")


def approach_results(root: Path) -> str:
    """The committed approaches (``docs/reports/approach-<phone>/summary.json``): frames solved, the
    ranges they span, the failures, and per range bin the RMS x and pitch errors beside the CRLB."""
    lines = []
    for ph in PHONES:
        d = _json(root / "docs" / "reports" / f"approach-{ph}" / "summary.json")
        fails = ", ".join(f"{n} `{k}`" for k, n in d["failures"].items()) or "none"
        lo, hi = d["solved_range_m"]
        lines += [f"**{PHONE_NAMES[ph]}**: {d['solved']} of {d['frames']} frames solved, from {hi:g} m down to {lo:g} m; "
                  f"failures: {fails}.", "",
                  "| range bin (m) | frames solved | RMS x error (m) | x CRLB (m) | RMS pitch error (deg) | pitch CRLB (deg) |",
                  "|---|---|---|---|---|---|"]
        for b in d["rms_by_range"]:
            if not b["solved"]:
                continue
            a, z = b["range_m"]
            lines.append(f"| [{a:g}, {z:g}) | {b['solved']} / {b['frames']} | {b['rms_err_x_m']:.3g} | {b['rms_crlb_x_m']:.2g} | "
                         f"{b['rms_err_pitch_deg']:.3g} | {b['rms_crlb_pitch_deg']:.2g} |")
        lines.append("")
    return "\n".join(lines)


#: The ToF study's runs that are not mechanisms switched on or off (the paper's rows, the sweeps).
_TOF_NOT_VARIANTS = ("baseline", "paper table", "fig14 sweep", "long run")


def tof_mechanisms(root: Path) -> str:
    """Each mechanism the ToF study switched alone (``tof_stability.csv``): its fluctuation over the
    paper's (Table 3 at 697 mm, Table 2 at 5712 mm), the range of the six ratios and how many are
    within 2x, beside the baseline's."""
    t = _tof_rows(root)
    paper = {0.697: t[("paper table 3", 0.697, "fluctuation")], 5.712: t[("paper table 2", 5.712, "fluctuation")]}
    runs = []
    for (run, r, st) in t:
        if st == "fluctuation" and r in paper and run not in runs and not run.startswith(_TOF_NOT_VARIANTS[1:]):
            runs.append(run)
    lines = ["| run | 697 mm: ratios (within 2x) | 5712 mm: ratios (within 2x) |", "|---|---|---|"]
    for run in ["baseline", *[x for x in runs if x != "baseline"]]:
        cells = []
        for r in (0.697, 5.712):
            v = t.get((run, r, "fluctuation"))
            if v is None:
                cells.append("-")
                continue
            q = v / paper[r]
            cells.append(f"{q.min():.2f}-{q.max():.2f}x ({int(np.sum((q >= 0.5) & (q <= 2)))} of 6)")
        lines.append(f"| {run} | {cells[0]} | {cells[1]} |")
    return "\n".join(lines) + "\n"


def sun_albedo(root: Path) -> str:
    """The Earth behind the target at three albedos (``sun-study-albedo-<phone>/summary.json``): per
    phone and albedo the trials solved and the wrong locks, and with the sun on the face (el > 0)
    and 15 deg below the pattern plane."""
    lines = ["| phone | albedo | solved | wrong locks | solved, sun on the face | wrong locks, sun 15 deg below |",
             "|---|---|---|---|---|---|"]
    for ph in PHONES:
        path = root / "docs" / "reports" / f"sun-study-albedo-{ph}" / "summary.json"
        if not path.is_file():
            continue
        cells = _json(path)["cells"]
        for a in sorted({c["earth_albedo"] for c in cells}):
            cs = [c for c in cells if c["earth_albedo"] == a]
            up = [c for c in cs if c["sun_elevation_deg"] > 0]
            low = [c for c in cs if c["sun_elevation_deg"] == -15.0]
            lines.append(f"| {PHONE_NAMES[ph]} | {a:g} | {sum(c['solved'] for c in cs)}/{sum(c['trials'] for c in cs)} | "
                         f"{sum(c['wrong_lock'] for c in cs)} | {sum(c['solved'] for c in up)}/{sum(c['trials'] for c in up)} | "
                         f"{sum(c['wrong_lock'] for c in low)} |")
    return "\n".join(lines) + "\n"


def sun_3u_detail(root: Path) -> str:
    """The shipped 3U body's study (``sun-study-3u-<phone>/summary.json``): per phone, by the sun's
    elevation, the trials solved and the wrong locks; the failures by reason and what the trials saw
    (the mechanisms' counts)."""
    lines = []
    for ph in PHONES:
        path = root / "docs" / "reports" / f"sun-study-3u-{ph}" / "summary.json"
        if not path.is_file():
            continue
        cells = _json(path)["cells"]
        by_el = []
        for el in sorted({c["sun_elevation_deg"] for c in cells}):
            cs = [c for c in cells if c["sun_elevation_deg"] == el]
            by_el.append(f"{el:+g} deg: {sum(c['solved'] for c in cs)}/{sum(c['trials'] for c in cs)} solved, "
                         f"{sum(c['wrong_lock'] for c in cs)} wrong locks")
        reasons, mech = {}, {}
        for c in cells:
            for k, n in c["reasons"].items():
                reasons[k] = reasons.get(k, 0) + n
            for k, n in c["mechanisms"].items():
                mech[k] = mech.get(k, 0) + n
        lines.append(f"- {PHONE_NAMES[ph]}, by the sun's elevation over the pattern plane: " + "; ".join(by_el) + ". "
                     "Failures: " + (", ".join(f"{n} `{k}`" for k, n in sorted(reasons.items(), key=lambda x: -x[1]))
                                     or "none") + ". Trials with " + ", ".join(f"`{k}` {n}" for k, n in mech.items() if n)
                     + f" (of {sum(c['trials'] for c in cells)}).")
    return "\n".join(lines) + "\n"


def sensor_model_validation(root: Path) -> str:
    """The statistical sensors against their held-out rendered frames
    (``docs/reports/sensor-model-<phone>/validation/validation.json``): per phone each outcome's count
    against the model's 90 % interval, and per component the KS tests and the scatter ratio."""
    out = []
    for ph in PHONES:
        path = root / "docs" / "reports" / f"sensor-model-{ph}" / "validation" / "validation.json"
        if not path.is_file():
            continue
        v = _json(path)
        env = v["envelope"]
        out.append(f"**{PHONE_NAMES[ph]}**: {v['frames']} held-out frames (seed {v['seed']}) over "
                   f"{env['range_m'][0]:g}-{env['range_m'][1]:g} m, 0-{env['off_axis_deg_max']:g} deg off axis, "
                   f"attitude within +-{env['attitude_deg_max']:g} deg.\n")
        out.append("| outcome | rendered | model: mean (90 % interval) | |\n|---|---|---|---|")
        for k, o in v["outcomes"].items():
            out.append(f"| `{k}` | {o['observed']} | {o['model_mean']:.1f} ({o['model_interval90'][0]}-"
                       f"{o['model_interval90'][1]}) | {'within' if o['within'] else '**outside**'} |")
        out.append("")
        out.append("| component | solved frames | KS p, all ranges | KS p by third of the log-range (near, mid, far) | "
                   "scatter / model's (90 %) |\n|---|---|---|---|---|")
        for k, e in v["errors"].items():
            if "ks_p" not in e:
                out.append(f"| {k} | {e['n_rendered']} | too few | | |")
                continue
            bands = ", ".join(f"{b['ks_p']:.2g}" for b in e.get("bands", []))
            lo, hi = e["scatter_ratio_interval90"]
            out.append(f"| {k} | {e['n_rendered']} | {e['ks_p']:.2g} | {bands} | {e['scatter_ratio']:.2f} "
                       f"({lo:.2f}-{hi:.2f}) |")
        out.append("")
    return "\n".join(out)


#: The committed Monte Carlo (examples/basilisk_docking.py --monte-carlo ... --statistical-runs ...).
MONTE_CARLO = Path("docs") / "reports" / "montecarlo-docking" / "montecarlo.json"


def _mc_row(name: str, runs: list, p: dict) -> str:
    def q(key, scale, fmt):
        d = p[key]
        return "/".join("-" if d[s] is None else format(scale * d[s], fmt) for s in ("p50", "p90"))

    arrived = sum(r["arrival_error_m"] is not None for r in runs)
    return (f"| {name} | {len(runs)} | {arrived} | {q('arrival_error_m', 100, '.2f')} | "
            f"{q('arrival_time_s', 1, '.0f')} | {q('delta_v_m_s', 100, '.2f')} | {q('dropouts', 1, '.0f')} | "
            f"{sum(r['wrong_locks'] or 0 for r in runs)} |")


def monte_carlo(root: Path) -> str:
    """The committed docking Monte Carlo: per phone the ideal sensor, the rendered sensor, the statistical
    sensor on the rendered runs' seeds and on all its runs (p50/p90 of each quantity), and the KS test of
    the rendered runs against the statistical ones, with the runs done of those asked for."""
    from scipy.stats import ks_2samp

    d = _json(root / MONTE_CARLO)
    done = ", ".join(f"{k} {v['runs_done']} of {v['runs_requested']}"
                     + (f" ({v['runs_refused']} refused by the sensor model: the pose left its table's envelope)"
                        if v.get("runs_refused") else "") for k, v in d["sensors"].items())
    rows = [f"From {d['start_state'][2]:g} m at {d['sensor_rate_hz']:g} frames/s; the ideal sensor on all "
            f"{len(d['ideal_runs'])} seeds. Runs done: {done}"
            f"{'' if d['complete'] else ' (the Monte Carlo is not complete: rerunning its command flies the rest)'}. "
            "Each cell: p50/p90.\n",
            "| sensor | runs | arrived | arrival error, cm | arrival time, s | delta-v, cm/s | dropouts | wrong locks |",
            "|---|---|---|---|---|---|---|---|",
            _mc_row("ideal", d["ideal_runs"], d["ideal_percentiles"])]
    notes = []
    for ph in PHONES:
        r, s = d["sensors"].get(ph), d["sensors"].get(f"{ph} (statistical)")
        if s and not (r and r["runs"]):  # no rendered run done yet: the statistical sensor alone
            rows.append(_mc_row(f"{PHONE_NAMES[ph]}, statistical", s["runs"], s["percentiles"]))
            notes.append(f"- {PHONE_NAMES[ph]}: no rendered run done yet, so no comparison.")
            continue
        if not (r and s):
            continue
        seeds = {x["seed"] for x in r["runs"]}
        same = [x for x in s["runs"] if x["seed"] in seeds]
        rows.append(_mc_row(f"{PHONE_NAMES[ph]}, rendered", r["runs"], r["percentiles"]))
        rows.append(_mc_row(f"{PHONE_NAMES[ph]}, statistical, the same {len(same)} seeds", same,
                            s["percentiles_on_rendered_seeds"]))
        rows.append(_mc_row(f"{PHONE_NAMES[ph]}, statistical", s["runs"], s["percentiles"]))
        tests = []
        for key, label in (("delta_v_m_s", "delta-v"), ("arrival_error_m", "arrival error"), ("dropouts", "dropouts")):
            a = [x[key] for x in r["runs"] if x[key] is not None]
            b = [x[key] for x in s["runs"] if x[key] is not None]
            if len(a) >= 3 and len(b) >= 3 and len(set(a) | set(b)) > 1:
                tests.append(f"{label} p = {ks_2samp(a, b).pvalue:.2g}")
        by_seed = {x["seed"]: x["delta_v_m_s"] for x in same if x["delta_v_m_s"] is not None}
        dv = np.array([x["delta_v_m_s"] - by_seed[x["seed"]] for x in r["runs"]
                       if x["seed"] in by_seed and x["delta_v_m_s"] is not None])
        paired = (f"{100 * dv.mean():+.3f} +- {100 * dv.std(ddof=1) / np.sqrt(dv.size):.3f} cm/s (mean +- its standard "
                  "error)" if dv.size >= 2 else "too few runs")
        notes.append(f"- {PHONE_NAMES[ph]}: the {len(r['runs'])} rendered runs against the {len(s['runs'])} statistical "
                     f"runs, two-sample KS: {', '.join(tests) or 'no test (too few values)'}; delta-v, rendered minus "
                     f"statistical on the same seeds: {paired}.")
    return "\n".join(rows) + "\n\n" + "\n".join(notes) + "\n"

def _mechanisms(phone: str) -> Callable[[Path], str]:
    def block(root: Path) -> str:
        rows = cell_mechanisms(read_table(_campaign(root, phone) / "results.csv"), phone)
        return mechanisms_markdown(rows, phone)
    block.__doc__ = f"The mechanisms of the {PHONE_NAMES[phone]}'s std cells outside 2x (svgs_sim.studies.mechanisms)."
    return block


#: Passage name -> the function that writes it from the data under ``root``.
BLOCKS: dict[str, Callable[[Path], str]] = {
    "merge-range": merge_range,
    "campaign-counts": campaign_counts,
    "campaign-std-cells": campaign_std_cells,
    "campaign-consistency": campaign_consistency,
    "campaign-mean-cells": campaign_mean_cells,
    "weak-mode": weak_mode,
    "tof-tables": tof_tables,
    "tof-headline": tof_headline,
    "sun-studies": sun_studies,
    "basilisk-results": basilisk_results,
    "approach-results": approach_results,
    "tof-mechanisms": tof_mechanisms,
    "sun-albedo": sun_albedo,
    "sun-3u-detail": sun_3u_detail,
    "sensor-model-validation": sensor_model_validation,
    "monte-carlo": monte_carlo,
    **{f"mechanisms-{ph}": _mechanisms(ph) for ph in PHONES},
}


# --------------------------------------------------------------------------- the front page's figure
#: The front page's figure (docs/index.md), written by :func:`main` beside the passages.
FRONT_FIGURE = Path("docs") / "figures" / "paper_vs_simulation.png"


def front_figure(root: Path):
    """Every std cell of Tables 3 and 5: the simulated standard deviation against the paper's, per phone,
    log-log, with the 2x band; from the campaigns' ``verdicts.csv``.

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10, 4.4))
    axes = fig.subplots(1, 2)
    markers = dict(zip(("x_m", "y_m", "z_m", "roll_deg", "pitch_deg", "yaw_deg"), "os^DvP"))
    for ax, ph in zip(axes, PHONES):
        cells = [v for v in _verdicts(root, ph) if v["statistic"] == "std" and v["verdict"] != "no_paper_value"]
        within = sum(v["verdict"] == "within_2x" for v in cells)
        for c, mk in markers.items():
            pts = np.array([(v["paper"], v["simulated"]) for v in cells if v["component"] == c])
            if pts.size:
                ax.loglog(*pts.T, mk, ms=6, alpha=0.8, label=SHORT[c] + (" (m)" if c.endswith("_m") else " (deg)"))
        lo = min(min(v["paper"], v["simulated"]) for v in cells) / 2
        hi = max(max(v["paper"], v["simulated"]) for v in cells) * 2
        xs = np.array([lo, hi])
        ax.fill_between(xs, xs / 2, xs * 2, color="green", alpha=0.12, label="within 2x")
        ax.plot(xs, xs, "k-", lw=0.8)
        ax.set_xlim(lo, hi)
        ax.set_ylim(lo, hi)
        ax.set_xlabel("the paper's standard deviation (Tables 3, 5)")
        ax.set_ylabel("simulated standard deviation")
        ax.set_title(f"{PHONE_NAMES[ph]}: {within} of {len(cells)} cells within 2x", fontsize=11)
        ax.grid(alpha=0.3, which="both")
    axes[0].legend(fontsize=8, loc="upper left")
    fig.suptitle("The simulated SVGS against the paper's measured scatter (every cell; the mean errors are not "
                 "predictable and not shown)", fontsize=10)
    fig.tight_layout()
    return fig


# --------------------------------------------------------------------------- filling and checking
def fill(text: str, root: Path, cache: dict | None = None) -> str:
    """``text`` with every generated passage rewritten from the data.

    Raises
    ------
    KeyError
        A passage names no function of :data:`BLOCKS`.
    """
    cache = {} if cache is None else cache

    def sub(m):
        name = m.group("name")
        if name not in BLOCKS:
            raise KeyError(f"generated passage {name!r}: no such passage (svgs_sim.studies.report_text.BLOCKS)")
        if name not in cache:
            cache[name] = BLOCKS[name](root)
        return m.group(1) + cache[name] + m.group(4)

    return BLOCK_RE.sub(sub, text)


def stale(root: Path, pages=PAGES) -> list[str]:
    """The unified diffs of the pages whose generated passages differ from the data (empty: none)."""
    out, cache = [], {}
    for p in pages:
        path = Path(root) / p
        old = path.read_text(encoding="utf-8")
        new = fill(old, Path(root), cache)
        if new != old:
            out.append("".join(difflib.unified_diff(old.splitlines(True), new.splitlines(True), p, p + " (from the data)")))
    return out


def main(argv=None) -> int:
    """``python -m svgs_sim.studies.report_text [--check] [--root DIR]``."""
    ap = argparse.ArgumentParser(prog=COMMAND, description="Rewrite the generated passages of the README and the "
                                 "docs from the committed reports' data (--check: only compare).")
    ap.add_argument("--check", action="store_true", help="write nothing; exit 1 and print the differences if any")
    ap.add_argument("--root", default=".", help="the repository root (default: the current folder)")
    a = ap.parse_args(argv)
    root = Path(a.root)
    missing = [p for p in PAGES if not (root / p).is_file()]
    if missing:
        print(f"--root: {root} has no {', '.join(missing)} (not the repository root)", file=sys.stderr)
        return 2
    if a.check:
        diffs = stale(root)
        print("".join(diffs) if diffs else "every generated passage matches its data", end="" if diffs else "\n")
        return 1 if diffs else 0
    cache = {}
    for p in PAGES:
        path = root / p
        old = path.read_text(encoding="utf-8")
        new = fill(old, root, cache)
        if new != old:
            path.write_text(new, encoding="utf-8")
            print(f"{p}: rewritten")
    (root / FRONT_FIGURE).parent.mkdir(parents=True, exist_ok=True)
    front_figure(root).savefig(root / FRONT_FIGURE, dpi=110)
    print(f"{FRONT_FIGURE}: written")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())


__all__ = ["BLOCKS", "BLOCK_RE", "COMMAND", "FRONT_FIGURE", "PAGES", "fill", "front_figure", "main", "stale"]
