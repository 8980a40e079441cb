"""The campaign's report: ``report.html`` with its tables (``summary.csv``, ``verdicts.csv``,
``honest_count.json``, ``budget.csv``), and the short table on stdout."""

from __future__ import annotations

import html as _html
import json
import sys
from pathlib import Path

import numpy as np

from svgs_sim.base.profiles import load_camera
from svgs_sim.svgs.frames import STATE_KEYS

from ..error_budget import (
    HEADLINE_READING,
    HEADLINE_REASON,
    NOT_PREDICTABLE_REASON,
    READING_LABELS,
    REMOVAL_NAMES,
    SOURCE_LABELS,
    VARIANTS,
    VERDICT_COLUMNS,
    applicable_variants,
    budget_figure,
    budget_rows_for_csv,
)
from ..report import Report, write_csv
from .design import GIMBAL_ROLL_DEG, GIMBAL_YAW_DEG, SHORT, STAGE_HALF_TRAVEL_M, CampaignConfig
from .figures import crlb_figure, histogram_figures, sample_image_figure, weak_mode_figure
from .folder import finite_json, run_log
from .honest_count import (
    campaign_verdicts,
    consumes_text,
    fitted_values_table,
    honest_count_object,
    honest_counts,
    misalignment_text,
)
from .statistics import SUMMARY_COLUMNS, explain, summary_long_rows


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


def carried_figure(html_text: str, heading: str) -> str | None:
    """The first ``<figure>`` after ``<h2>heading</h2>`` of an earlier report (None if none)."""

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

    rep.heading("The honest count: fitted values and the cells they consume")
    h = counts[HEADLINE_READING]["by_statistic"]["std"]
    m = counts[HEADLINE_READING]["by_statistic"]["mean_error"]
    rep.paragraph(
        f"Standard deviations (Tables 3 and 5): {h['within_2x']} of {h['predicted']} predicted cells within 2x of the "
        f"paper, {h['below']} below, {h['above']} above, {h['no_solution']} without a solution"
        + (f"; {h['fitted']} fitted and not counted" if h["fitted"] else "")
        + f". Of the {h['below'] + h['above']} outside 2x, {h['measured']} are explained by a mechanism measured by "
        f"switching it off in the simulation (the error budget), {h['unexplained']} are unexplained. The "
        f"{m['cells']} mean-error cells (Tables 2 and 4) are not predictable and are in no count "
        "(the section on them below says why).")
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
                r["status"], r["source"], r["fitted_to"], consumes_text(r["consumes"]), r["effect"],
                r["in_campaign"]] for r in rows],
              caption="Fitted values and chosen settings that apply to this campaign",
              text_columns=["value", "status", "file", "fitted to", "cells consumed", "effect on this campaign",
                            "in the trials"])
    tables = sorted({v["table"] for v in verdicts if v["table"]})
    c = counts[HEADLINE_READING]
    rep.table(["cells", "predicted", "within 2x", "below", "above", "no solution", "fitted (not counted)",
               "not predictable (not counted)", "outside 2x: measured", "outside 2x: unexplained"],
              [[scope, x["predicted"], x["within_2x"], x["below"], x["above"], x["no_solution"], x["fitted"],
                x["not_predictable"], x["measured"], x["unexplained"]]
               for scope, x in (("std (Tables 3, 5)", h), ("mean error (Tables 2, 4)", m), ("all", c))],
              text_columns=["cells"],
              caption="Cells of " + (" and ".join(tables) if tables else "the paper's tables"))


def _mean_error_section(rep, summary, crlb_note: str, table: dict, config: CampaignConfig) -> None:
    rep.heading("Mean error (paper Tables 2 and 4): not predictable")
    rep.paragraph(NOT_PREDICTABLE_REASON + " " + HEADLINE_REASON, "note")
    for grp, comps in (("position", STATE_KEYS[:3]), ("attitude", STATE_KEYS[3:])):
        cols = ["range (m)"]
        for c in comps:
            cols += [f"{SHORT[c]} paper", f"{SHORT[c]} floor 0.80 std", f"{SHORT[c]} bias", f"{SHORT[c]} mean |e|"]
        rows = [[s["range_m"]] + [x for c in comps for x in (s[f"paper_mean_{c}"], s[f"mean_floor_{c}"],
                                                             s[f"bias_{c}"], s[f"mean_abs_{c}"])] for s in summary]
        rep.table(cols, rows, caption=f"Mean error, {grp}: the paper's beside the floor the simulated scatter puts "
                                      "under it, the simulated signed bias and the simulated mean |e| (not scored)")
    for grp, comps in (("position", STATE_KEYS[:3]), ("attitude", STATE_KEYS[3:])):
        cols = ["range (m)"]
        for c in comps:
            cols += [f"{SHORT[c]} |mean e|", f"{SHORT[c]} RMS"]
        rows = [[s["range_m"]] + [x for c in comps for x in (s[f"abs_mean_{c}"], s[f"rms_{c}"])] for s in summary]
        rep.table(cols, rows, caption=f"Mean error, {grp}: the other two readings, simulated")
    phone = load_camera(config.camera).key
    fig, st = weak_mode_figure(table, config, phone)
    rep.figure(fig, "The weak mode: per reported trial the X error against R tan(pitch error) and the Y error "
                    "against R tan(roll error), R the true range; the paper's mean errors (Tables 2/4) as red squares. "
                    + "; ".join(f"{SHORT[p]}: correlation {v['corr']:+.2f}, slope {v['slope']:+.2f} over {v['n']} "
                                f"trials; the paper's {SHORT[p]} / (R tan {SHORT[v['angle']]}) "
                                + ", ".join(f"{r:g} m {x:.2f}" for r, x in v["paper_ratio"])
                                for p, v in st.items()) + ".", tight=False)


def _consistency_section(rep, summary) -> None:
    rep.heading("The paper's app and the consistency test")
    rep.paragraph(
        "The statistics above are those of the paper's algorithm as published: every solution is reported. "
        "The consistency test (svgs_sim.svgs.app.consistency: the residual against 0.25 px of centroid noise, "
        "alpha 1e-3; an option the paper does not describe) would have refused the solutions counted here; "
        "the table gives what the option would have cost each range.", "note")
    cols = ["range (m)", "trials", "reported (the paper's app)", "refused by the test", "left with the test"]
    cols += [f"{SHORT[c]} std / with the test" for c in STATE_KEYS]
    rows = []
    for s in summary:
        rows.append([s["range_m"], s["n"], s["n_ok"], s["n_rejected_consistency"], s["n_ok"] - s["n_rejected_consistency"]]
                    + [f"{s[f'std_{c}']:.3g} / {s[f'std_with_test_{c}']:.3g}" for c in STATE_KEYS])
    rep.table(cols, rows, text_columns=[f"{SHORT[c]} std / with the test" for c in STATE_KEYS],
              caption="Reported solutions and the consistency test's refusals per range; std with every solution / "
                      "with only those the test keeps")


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
            "", "note")
    rep.table(["range (m)", "component", "table", "reading", "simulated", "paper", "ratio", "verdict", "explanation",
               "why"],
              [[v["range_m"], v["component"], v["table"], READING_LABELS[v["reading"]], v["simulated"], v["paper"],
                v["ratio"], v["verdict"], v["explanation"], v["text"]]
               for v in verdicts if v["verdict"] not in ("within_2x", "no_paper_value", "not_predictable")],
              text_columns=["component", "table", "reading", "verdict", "explanation", "why"],
              caption="Standard-deviation cells outside 2x of the paper, and the fitted cells")


def write_campaign_tables(out_dir, config: CampaignConfig, table: dict, summary: list[dict],
                          budget: dict | None = None) -> tuple[list[dict], list[dict], dict]:
    """``DIR/summary.csv``, ``DIR/verdicts.csv`` and ``DIR/honest_count.json`` of a finished campaign.

    Returns
    -------
    (rows, verdicts, counts)
        The fitted values (:func:`fitted_values_table`), the cells' verdicts
        (:func:`campaign_verdicts`) and their counts (:func:`honest_counts`).
    """


    out_dir = Path(out_dir)
    rows = fitted_values_table(config, table)
    verdicts = campaign_verdicts(config, summary, budget, rows)
    counts = honest_counts(verdicts)
    write_csv(out_dir / "summary.csv", list(SUMMARY_COLUMNS), summary_long_rows(summary, verdicts))
    write_csv(out_dir / "verdicts.csv", ["table", *VERDICT_COLUMNS], verdicts)
    (out_dir / "honest_count.json").write_text(json.dumps(finite_json(honest_count_object(config, rows, verdicts)), indent=1,
                                                          allow_nan=False) + "\n", encoding="utf-8")
    return rows, verdicts, counts


def _overview_paragraph(rep, config: CampaignConfig, summary: list[dict], log: list[dict]) -> None:
    n = int(np.sum([s["n"] for s in summary]))
    n_ok = int(np.sum([s["n_ok"] for s in summary]))
    wall = sum(x["elapsed_s"] for x in log)
    rep.paragraph(
        f"{n} trials over {len(config.ranges_m)} ranges ({', '.join(f'{r:g}' for r in config.ranges_m)} m), "
        f"{n_ok} solutions reported ({100.0 * n_ok / max(n, 1):.1f} %; the paper's app reported every solution, "
        f"{int(np.sum([s.get('n_rejected_consistency', 0) for s in summary]))} of them the consistency test would "
        f"refuse): {config.poses_per_range} stand settings per range, "
        f"{config.exposures_per_render} exposures of each. As on the MSFC Flight Robotics Lab stand of Becker, Howard & "
        "Rakoczy (2014), the target stays fixed and the phone is turned by the Sensor Mount's gimbal (roll and pitch "
        f"+/-{GIMBAL_ROLL_DEG:g} deg, yaw +/-{GIMBAL_YAW_DEG:g} deg about the line of sight) on the translation stage "
        f"(+/-{100 * STAGE_HALF_TRAVEL_M:g} cm) at each rail position (svgs_sim.sim.stand); each setting is drawn uniformly over "
        "that envelope and kept when the phone sees all four targets."
        + (f" Wall time of the trials: {wall:.0f} s over {len(log)} run(s) ({', '.join(sorted({x['executor'] for x in log}))})."
           if log else ""))


def _setup_section(rep, config: CampaignConfig, rows: list[dict], log: list[dict]) -> None:
    rendered = config.trial_kind == "render"
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


def _std_bias_sections(rep, summary: list[dict], crlb_note: str) -> None:
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
    rep.table(["range (m)", "trials", "reported", "success rate", "failures by reason"],
              [[s["range_m"], s["n"], s["n_ok"], s["success_rate"],
                ", ".join(f"{k}: {v}" for k, v in sorted(s["reasons"].items())) or "none"] for s in summary],
              caption="Success rate: solutions the paper's app would report (the consistency test's refusals are "
                      "in the table of the app and the test)", text_columns=["failures by reason"])


def _figure_sections(rep, config: CampaignConfig, table: dict, summary: list[dict], trials: list | None,
                     sample_figure_html: str | None) -> None:
    rendered = config.trial_kind == "render"
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
        rep.figure(fig, cap, tight=False)


def _explain_section(rep, config: CampaignConfig, summary: list[dict]) -> None:
    rep.heading("What dominates the error at each range")
    rep.bullets(explain(summary, config))
    rep.paragraph(
        "How to read this. With centroid noise alone the solver is efficient: the simulated scatter sits on the "
        "Cramer-Rao bound. A wrong calibration used by the solver adds a bias and, because the gimbal attitude "
        "changes from trial to trial, a pose-dependent scatter. The geometric trial gives every spot the same "
        "isotropic sigma_px; the rendered campaign (the default trial kind) makes the spots and measures what "
        "each error source contributes (its error budget). These are inferences from the numbers, not "
        "measurements by switching a source off: they explain no cell of the tables.")


def write_campaign_report(out_dir, config: CampaignConfig, table: dict, summary: list[dict], *, command: str,
                          versions: dict, stats=None, budget: dict | None = None, trials: list | None = None,
                          sample_figure_html: str | None = None) -> Path:
    """``DIR/report.html``, ``DIR/summary.csv``, ``DIR/verdicts.csv`` and ``DIR/honest_count.json``
    (and with a budget ``DIR/budget.csv``) for a finished campaign.

    ``trials`` (rendered): the sample images are rendered again; without them
    ``sample_figure_html`` (that figure of an earlier report, :func:`rebuild_report`) is kept.
    """

    out_dir = Path(out_dir)
    rows, verdicts, counts = write_campaign_tables(out_dir, config, table, summary, budget)
    rendered = config.trial_kind == "render"
    rep = Report(f"SVGS test campaign simulated: {config.camera} ({config.trial_kind} trials)", command, versions)
    log = run_log(out_dir)
    _overview_paragraph(rep, config, summary, log)
    h = counts[HEADLINE_READING]["by_statistic"]
    rep.paragraph(
        f"Result: {h['std']['within_2x']} of {h['std']['predicted']} standard-deviation cells of the paper's "
        f"{' and '.join(sorted({v['table'] for v in verdicts if v['statistic'] == 'std' and v['table']})) or 'tables'} "
        f"within 2x ({h['std']['below']} below, {h['std']['above']} above; {h['std']['measured']} of those outside with a "
        f"measured mechanism); the {h['mean_error']['cells']} mean-error cells are not predictable and are not counted. "
        "The comparison comes first below; the fitted values, the set-up and the provenance follow it.", "result")
    crlb_note = ("the Cramer-Rao bound from the simulated sensor (shot, read and quantisation noise at the exposure used; "
                 "svgs_sim.sim.crlb), median over the solved trials" if rendered else
                 f"the solver's Cramer-Rao bound for {config.sigma_px:g} px centroid noise, median over the solved trials")
    rep.figure(crlb_figure(summary, config), "Simulated standard deviation and mean |error| (blue), the paper's "
               "(red) and the Cramer-Rao bound (black), per component, versus range.", tight=False)
    _std_bias_sections(rep, summary, crlb_note)
    _consistency_section(rep, summary)
    _mean_error_section(rep, summary, crlb_note, table, config)
    if budget is not None:
        _budget_sections(rep, out_dir, config, summary, budget)
    _cells_section(rep, verdicts, budget)
    _figure_sections(rep, config, table, summary, trials, sample_figure_html)
    if not rendered:
        _explain_section(rep, config, summary)
    _honest_count_section(rep, config, rows, verdicts, counts)
    _setup_section(rep, config, rows, log)
    return rep.write(out_dir / "report.html")


def _budget_sections(rep, out_dir, config, summary, budget) -> None:

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
    names = [n for n in ("floor", *REMOVAL_NAMES, "geometric")
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
    """A short table on stdout: per range, the reported solutions and std simulated vs paper; then
    the std cells of Tables 3 and 5 within 2x (fitted cells left out; the mean-error cells of
    Tables 2 and 4 are not predictable and are not counted)."""

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
        c = counts[HEADLINE_READING]["by_statistic"]["std"]
        m = counts[HEADLINE_READING]["by_statistic"]["mean_error"]
        print(f"std cells (Tables 3, 5) within 2x of the paper: {c['within_2x']} of {c['predicted']}"
              + (f" ({c['fitted']} fitted, not counted)" if c["fitted"] else "")
              + f"; {m['cells']} mean-error cells (Tables 2, 4) not predictable, not counted", file=f)
