"""The campaign's statistics per range beside the paper's (Tables 2-5), as ``summary.csv``'s long
rows, and what dominates the error at each range."""

from __future__ import annotations

import numpy as np

from svgs_sim.assets.papers import svgs_2014_results
from svgs_sim.base.profiles import load_camera
from svgs_sim.svgs.frames import STATE_KEYS

from ..error_budget import MEAN_ABS_PER_STD, MEAN_READINGS, consistency_rejected_mask, reported_mask
from .design import CampaignConfig


def summarize(table: dict, config: CampaignConfig, paper: dict | None = None) -> list[dict]:
    """Per-range statistics beside the paper's.

    Parameters
    ----------
    table : dict of column -> ndarray
        The campaign's rows (:meth:`ResultStore.read_table`); only the baseline's are used
        (``variant`` ``baseline``, or no ``variant`` column), and of those the ones the paper's app
        would have reported (:func:`svgs_sim.studies.error_budget.reported_mask`: every solution; the
        consistency test is an option the paper did not have).

    Returns
    -------
    list of dict, one per range
        ``range_m``, ``n``, ``n_ok`` (reported), ``success_rate`` (reported / n), ``reasons``
        (dict, of the unreported), ``n_rejected_consistency`` (reported solutions the consistency
        test would refuse), ``success_rate_with_consistency_test``, and per component
        ``c``: the three readings of the paper's "mean error" (:data:`svgs_sim.studies.error_budget.MEAN_READINGS`)
        ``abs_mean_<c>`` (|mean e|, the headline), ``mean_abs_<c>`` (mean |e|) and ``rms_<c>``
        (sqrt(mean e^2)), each with its ratio to the paper's mean error ``ratio_abs_mean_<c>``,
        ``ratio_mean_abs_<c>``, ``ratio_rms_<c>``;
        ``bias_<c>`` (signed mean), ``std_<c>`` (ddof = 1), ``crlb_<c>``, ``paper_mean_<c>``,
        ``paper_std_<c>``, ``ratio_std_<c>``, ``mean_floor_<c>`` (0.80 ``std_<c>``: mean |e| of a
        zero-mean normal error, the floor the scatter puts under the paper's mean error),
        ``std_with_test_<c>`` (the std of the solutions the consistency test keeps). ``crlb_<c>`` is the median over the solved trials
        of the bound from the simulated sensor (``crlb_sensor_<c>``, rendered trials) or, for
        geometric trials, of the solver's bound at ``sigma_px``. Units: those of the component
        (m or deg); ratios dimensionless.
    """

    paper = svgs_2014_results() if paper is None else paper
    phone = load_camera(config.camera).key
    out = []
    if "variant" in table:
        base = np.array([str(v) == "baseline" for v in table["variant"]])
    else:
        base = np.ones(len(table["ok"]), bool)
    reported = reported_mask(table)
    rejected = consistency_rejected_mask(table)
    for r in config.ranges_m:
        sel = base & (table["nominal_range_m"] == r)
        ok = sel & reported
        reasons = {}
        for x in table["reason"][sel & ~reported]:
            key = str(x) if x is not None and x == x else "unknown"
            reasons[key] = reasons.get(key, 0) + 1
        n_rej = int((sel & rejected).sum())
        row = {"range_m": float(r), "n": int(sel.sum()), "n_ok": int(ok.sum()),
               "success_rate": float(ok.sum() / sel.sum()) if sel.any() else float("nan"), "reasons": reasons,
               "n_rejected_consistency": n_rej,
               "success_rate_with_consistency_test": float((ok.sum() - n_rej) / sel.sum()) if sel.any() else float("nan")}
        pm = paper.get((phone, "mean_error", float(r)))
        ps = paper.get((phone, "std", float(r)))
        for c in STATE_KEYS:
            e = table[f"err_{c}"][ok]
            row[f"mean_abs_{c}"] = float(np.mean(np.abs(e))) if e.size else float("nan")
            row[f"bias_{c}"] = float(np.mean(e)) if e.size else float("nan")
            row[f"abs_mean_{c}"] = abs(row[f"bias_{c}"])
            row[f"rms_{c}"] = float(np.sqrt(np.mean(e**2))) if e.size else float("nan")
            row[f"std_{c}"] = float(np.std(e, ddof=1)) if e.size > 1 else float("nan")
            # the floor the scatter alone puts under the paper's mean |e| (a zero-mean normal error)
            row[f"mean_floor_{c}"] = MEAN_ABS_PER_STD * row[f"std_{c}"]
            # the same statistics with the consistency test applied (what the option would cost)
            ek = table[f"err_{c}"][ok & ~rejected]
            row[f"std_with_test_{c}"] = float(np.std(ek, ddof=1)) if ek.size > 1 else float("nan")
            cr = table[f"crlb_sensor_{c}"][ok] if f"crlb_sensor_{c}" in table else table[f"crlb_{c}"][ok]
            cr = cr[np.isfinite(cr)]
            row[f"crlb_{c}"] = float(np.median(cr)) if cr.size else float("nan")
            row[f"paper_mean_{c}"] = pm[c] if pm else float("nan")
            row[f"paper_std_{c}"] = ps[c] if ps else float("nan")
            for x in MEAN_READINGS:
                row[f"ratio_{x}_{c}"] = row[f"{x}_{c}"] / pm[c] if pm and pm[c] > 0 else float("nan")
            row[f"ratio_std_{c}"] = row[f"std_{c}"] / ps[c] if ps and ps[c] > 0 else float("nan")
        out.append(row)
    return out


#: The statistics of ``summary.csv`` that are cells of the paper's tables: statistic -> (summary key prefix,
#: the paper's key prefix, the column of :func:`svgs_sim.studies.error_budget.cell_verdicts` that judges it under that
#: reading; the std's one reading is its ``verdict``).
#: The output name of each reading of the paper's "mean error" (:data:`svgs_sim.studies.error_budget.MEAN_READINGS`):
#: ``summary.csv``'s statistic and ``summary.json``'s key, one name for one thing (``abs_bias``:
#: |mean e|; ``mean_abs_error``: mean |e|; ``rms``: sqrt(mean e^2)).
READING_OUTPUT_NAMES = {"abs_mean": "abs_bias", "mean_abs": "mean_abs_error", "rms": "rms"}
#: ``summary.csv`` statistics and ``summary.json`` keys of campaigns made before the renaming ->
#: their names now (``tools/compare_summaries.py`` reads both).
RENAMED_STATISTICS = {"abs_mean_error": "abs_bias", "rms_error": "rms"}
SUMMARY_CELL_STATISTICS = {"abs_bias": ("abs_mean", "paper_mean", "verdict_abs_mean"),
                           "mean_abs_error": ("mean_abs", "paper_mean", "verdict_mean_abs"),
                           "rms": ("rms", "paper_mean", "verdict_rms"),
                           "std": ("std", "paper_std", "verdict")}


SUMMARY_COLUMNS = ("range_m", "component", "statistic", "simulated", "paper", "ratio", "verdict", "explanation")


def summary_long_rows(summary: list[dict], verdicts: list[dict] | None = None) -> list[dict]:
    """The summary as long-form rows for ``summary.csv`` (:data:`SUMMARY_COLUMNS`).

    Statistics per range and component: ``abs_bias`` (|mean e|, the verdicts' headline
    reading of the paper's "mean error"), ``mean_abs_error`` (mean |e|), ``rms`` (each
    against the paper's mean error), ``std`` (against the paper's std), ``bias`` (signed mean),
    ``crlb_std``; per range ``success_rate`` (component ``all``). With ``verdicts``
    (:func:`svgs_sim.studies.error_budget.cell_verdicts`) the paper's cells carry their verdict under
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
