"""Running a campaign (or resuming it) into its folder, its error budget's geometric trials, and
rebuilding a finished campaign's report from its stored results (``python -m svgs_sim.studies.campaign
rebuild DIR``)."""

from __future__ import annotations

import argparse
import html as _html
import json
import re
import sys
from pathlib import Path

from svgs_sim.base.errors import InputError
from svgs_sim.sim.trials import GEOMETRIC, get_trial_kind
from svgs_sim.svgs.frames import STATE_KEYS

from ..error_budget import (
    HEADLINE_READING,
    MEAN_READINGS,
    attribute,
    centroid_statistics,
    geometric_trials,
    variant_statistics,
)
from ..execution import ExecutorSpec, check_executor, library_versions, run_stored_study
from ..store import check_resumable, read_table
from .design import CampaignConfig, campaign_trials
from .folder import config_from_manifest, finite_json, log_run, read_honest_count
from .honest_count import misalignment_text
from .html_report import carried_figure, write_campaign_report
from .paper_calibration import rendered_paper_calibration, save_paper_calibration
from .statistics import READING_OUTPUT_NAMES, RENAMED_STATISTICS, summarize


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


    check_executor(spec)  # before the calibration renders: an unreachable cluster is bad input, not lost work
    kind = get_trial_kind(config.trial_kind)
    out_dir = Path(out_dir)
    say = (lambda m: print(m, file=sys.stderr)) if progress else None
    paper = config.trial_kind == "render" and config.calibration == "paper"
    if paper:
        # before the calibration renders: the design (stand settings in view, scenarios; designed
        # again below with the calibrated focal length, the same seeded settings) and a stored
        # campaign in the folder with other parameters (all but the focal length still to come)
        campaign_trials(config, variants=False)
        check_resumable(out_dir, config.manifest(), ignore=("calibration_error",))
    # calibration.json is only read here: written once the store has taken this campaign
    config = rendered_paper_calibration(config, out_dir, progress=say, save=False)
    trials = campaign_trials(config)
    try:
        store, stats = run_stored_study(kind, trials, out_dir, config.manifest(), spec, chunk_size=chunk_size,
                                        progress=progress, description=f"campaign {config.camera}")
    except InputError:
        _keep_calibration(config, out_dir, refused=True)
        raise
    except BaseException:
        _keep_calibration(config, out_dir)  # interrupted: the renders kept for the rerun
        raise
    _keep_calibration(config, out_dir)
    log_run(out_dir, "rendered trials" if kind.name == "render" else "trials", stats)
    table = store.read_table()
    summary = summarize(table, config)
    budget = None
    if config.budget:
        budget = run_budget_geometric(config, trials, table, out_dir, progress=progress)
    path = write_campaign_report(out_dir, config, table, summary, command=command, versions=library_versions(),
                                 stats=stats, budget=budget, trials=trials)
    return summary, stats, path, config


def _keep_calibration(config: CampaignConfig, out_dir: Path, *, refused: bool = False) -> None:
    """Keep the rendered calibration (``calibration.json``) for a rerun - unless the folder holds
    another campaign's store, whose files a run never changes, or (``refused``) holds no store of
    this campaign: a refused run leaves the folder as it was (a store it made without a row
    removed itself)."""
    if not config.calibration_info:
        return
    try:
        ours = check_resumable(out_dir, config.manifest())
    except InputError:
        return
    if ours or not refused:
        save_paper_calibration(config, out_dir)


def run_budget_geometric(config: CampaignConfig, trials: list, table: dict, out_dir, *, progress: bool = True) -> dict:
    """The error budget of a finished rendered campaign: the measured centroids, the geometric
    trial at their scatter (``DIR/budget-geometric``, in this process: milliseconds a trial), the
    variants' statistics and the attribution (:mod:`svgs_sim.studies.error_budget`)."""


    cents = centroid_statistics(table, config.ranges_m)
    base = [t for t in trials if t.scenario.get("variant") == "baseline"]
    gtrials = geometric_trials(base, config, cents)
    manifest = {"study": "campaign-budget-geometric", "campaign": config.manifest(),
                "sigma_px": {f"{c['range_m']:g}": c["scatter_px"] for c in cents}}
    gstore, gstats = run_stored_study(GEOMETRIC, gtrials, Path(out_dir) / "budget-geometric", manifest,
                                      ExecutorSpec("inline", 0), progress=progress, description="budget: geometric")
    log_run(out_dir, "budget: geometric trials", gstats)
    vs = variant_statistics(table, config.ranges_m, gstore.read_table())
    return {"centroids": cents, "variant_stats": vs, "attribution": attribute(vs, config.ranges_m)}


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
        earlier = "\n".join(x for x in _html.unescape(m.group(1)).splitlines()
                            if not x.startswith("# report rebuilt")) if m else ""  # one note, however many rebuilds
        command = ((earlier + "\n") if earlier else "") + (
            f"# report rebuilt from the stored results: python -m svgs_sim.studies.campaign rebuild {out_dir}")
    path = write_campaign_report(out_dir, config, table, summary, command=command, versions=library_versions(),
                                 budget=budget, sample_figure_html=carried_figure(old, "What the phone saw"))
    sj = out_dir / "summary.json"
    if sj.is_file():
        obj = json.loads(sj.read_text())
        by = {s["range_m"]: s for s in summary}
        for r in obj.get("ranges", []):
            s = by.get(r["range_m"])
            if s is None:
                continue
            for old in RENAMED_STATISTICS:  # the names before the renaming
                r.pop(old, None)
                r.get("ratio", {}).pop(old, None)
            r.get("ratio", {}).pop("mean_error", None)  # the ratio of mean |e|: now mean_abs_error
            # the paper's app: every solution reported; the consistency test's refusals beside it
            r.update({"solved": s["n_ok"], "success_rate": s["success_rate"],
                      "refused_by_consistency_test": s["n_rejected_consistency"],
                      "failures": dict(sorted(s["reasons"].items())),
                      "mean_abs_error": {c: s[f"mean_abs_{c}"] for c in STATE_KEYS},
                      "bias": {c: s[f"bias_{c}"] for c in STATE_KEYS}, "std": {c: s[f"std_{c}"] for c in STATE_KEYS},
                      "crlb_std": {c: s[f"crlb_{c}"] for c in STATE_KEYS}})
            r.setdefault("ratio", {})["std"] = {c: s[f"ratio_std_{c}"] for c in STATE_KEYS}
            for x in MEAN_READINGS:
                r[READING_OUTPUT_NAMES[x]] = {c: s[f"{x}_{c}"] for c in STATE_KEYS}
            r.setdefault("ratio", {}).update({READING_OUTPUT_NAMES[x]: {c: s[f"ratio_{x}_{c}"] for c in STATE_KEYS}
                                              for x in MEAN_READINGS})
        obj["misalignment"] = misalignment_text(config)
        obj["honest_count"] = read_honest_count(out_dir)
        obj.setdefault("outputs", {}).update({"verdicts_csv": str(out_dir / "verdicts.csv"),
                                              "honest_count_json": str(out_dir / "honest_count.json")})
        sj.write_text(json.dumps(finite_json(obj), indent=1, allow_nan=False) + "\n", encoding="utf-8")
    return path


def main(argv=None) -> int:
    """``python -m svgs_sim.studies.campaign rebuild DIR [DIR ...]``: :func:`rebuild_report` on each folder."""

    p = argparse.ArgumentParser(prog="python -m svgs_sim.studies.campaign",
                                description="Rebuild campaign reports from their stored results (no trial runs).")
    sub = p.add_subparsers(dest="what", required=True)
    r = sub.add_parser("rebuild", help="rewrite report.html, summary.csv, verdicts.csv, honest_count.json and "
                                       "summary.json of campaign folders in place (copy them first to keep them)")
    r.add_argument("dirs", nargs="+", metavar="DIR")
    args = p.parse_args(argv)
    for d in args.dirs:
        path = rebuild_report(d)
        c = read_honest_count(d)["counts"][HEADLINE_READING]["by_statistic"]
        print(f"{path}: std cells {c['std']['within_2x']} of {c['std']['predicted']} within 2x "
              f"({c['std']['fitted']} fitted); {c['mean_error']['not_predictable']} mean-error cells not predictable")
    return 0
