"""Running the ToF study: the runs on the study engine (resumable), their sections, then the
figures, the CSV and the report.

Part of :mod:`svgs_sim.studies.tof_study`.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from svgs_sim.sim.tof_closed_loop import load_scene, make_sensor
from svgs_sim.sim.tof_stability import COLUMNS, paper_statistics, statistics, summary
from svgs_sim.sim.trials import get_trial_kind

from ..execution import ExecutorSpec, plan_trials, run_stored_study
from .design import (
    LONG_CHECKPOINTS,
    PAPER_RANGES_M,
    STOPPING_RULES,
    SWEEP_RANGES_M,
    SWEEP_SCHEMES,
    TofStudyConfig,
    active_pixels_near,
    auto_integration_times,
    design_digest,
    runs_from_rows,
    study_runs,
    study_trials,
)
from .failures import failure_modes
from .figures import plot_mechanisms, plot_series, plot_sweep
from .report import write_csv, write_markdown


def run_study(cfg: TofStudyConfig, out: Path, spec=None, *, store_dir=None, chunk_size=None, argv=(), quiet=False) -> dict:
    """Run (or resume) every run as trials of the ``tof`` kind and write the report; returns the
    numbers (JSON-serialisable).

    Parameters
    ----------
    cfg : TofStudyConfig
    out : str or Path
        Folder of the report and its figures.
    spec : svgs_sim.studies.execution.ExecutorSpec, optional
        How the trials run (default: in this process).
    store_dir : str or Path, optional
        The results store (default ``out / "tof-study"``); a rerun skips the stored trials, a
        changed ``cfg`` is refused.
    chunk_size : int, optional
        Trials per task, at least (:func:`svgs_sim.sim.tof_trial.chunk_frames`: a run stays in one task).
    """
    from svgs_sim.sim.tof_trial import cached_render, chunk_frames


    t_start = time.perf_counter()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    camera, target = load_scene(cfg.camera, cfg.pattern)

    def log(msg):
        if not quiet:
            print(msg, file=sys.stderr, flush=True)

    log("automatic integration times at the paper's ranges (the baseline renders)")
    auto_T = auto_integration_times(cfg)
    runs = study_runs(cfg, auto_T, active_pixels_near(cfg))
    trials = study_trials(runs)
    plan = plan_trials(get_trial_kind("tof"), trials, spec or ExecutorSpec("inline", 1))
    log(plan.describe() + "; frames already in the store are skipped")
    for line in plan.warnings():
        if "--processes" not in line and "--workers" not in line:  # the command said that one already
            log(line)
    manifest = {**cfg.manifest(), "design_sha256": design_digest(runs)}
    store, stats = run_stored_study(get_trial_kind("tof"), trials, Path(store_dir) if store_dir else out / "tof-study",
                                manifest, spec or ExecutorSpec("inline", 1),
                                chunk_size=chunk_frames(max(r[2].frames for r in runs), chunk_size),
                                progress=not quiet, description="ToF study frames")
    rows = store.read_rows()
    done = runs_from_rows(runs, rows)
    res = _sections(runs, done)
    log("failure modes")
    sensor = make_sensor(cfg.scenario(1.0), camera)
    fm = failure_modes(cfg, camera, target, out / "tof_failure_modes.png")
    runs_d, sums = res["runs"], res["sums"]
    plot_series(out / "tof_stability_series.png", runs_d, sums)
    plot_mechanisms(out / "tof_mechanisms.png", sums, res["var_rows"])
    plot_sweep(out / "tof_fig14.png", res["sweep"])
    csv_path = write_csv(out / "tof_stability.csv", sums, res["var_rows"], res["sweep"])
    wall = time.perf_counter() - t_start
    timing = {"wall_s": wall, "n_run": int(getattr(stats, "n_run", len(rows)) if stats is not None else 0),
              "n_frames": len(rows), "trial_s": float(sum(float(r.get("wall_s") or 0.0) for r in rows))}
    base = cached_render(cfg.scenario(PAPER_RANGES_M[0])).renderer
    md = write_markdown(out / "tof_stability.md", camera, target, sensor, base, sums, runs_d, res["var_rows"], res["sweep"],
                        fm, cfg.frames, cfg.variant_frames, cfg.sweep_frames, cfg.seed, argv, timing,
                        stopping=res["stopping"], long=res["long"])
    return {"stability": {str(r): s for r, s in sums.items()}, "stopping_rule": res["stopping"], "long_run": res["long"],
            "mechanisms": [{"label": v["label"], "range_m": v["range_m"], "ratio_to_paper": v["summary"]["ratio_to_paper"],
                            "fluctuation": v["summary"]["fluctuation"], "solved": v["summary"]["solved"]}
                           for v in res["var_rows"]],
            "fig14": res["sweep"], "failure_modes": fm, "wall_s": wall,
            "outputs": {"report": str(md), "csv": str(csv_path), "series": str(out / "tof_stability_series.png"),
                        "mechanisms": str(out / "tof_mechanisms.png"), "fig14": str(out / "tof_fig14.png"),
                        "failure_modes": str(out / "tof_failure_modes.png")}}


def _sections(runs, done) -> dict:
    """The report's sections from the finished runs (in :func:`study_runs` order)."""
    runs_d, sums, var_rows, sweep, long = {}, {}, [], [], None
    stopping_runs: dict = {}
    for (section, label, first, extra), run in zip(runs, done):
        r = first.nominal_range_m
        if section == "baseline":
            runs_d[r], sums[r] = run, summary(run)
        elif section == "mechanism":
            var_rows.append({"label": label, "why": extra, "range_m": r, "summary": summary(run)})
        elif section == "sweep":
            sweep.append(_sweep_row(label, r, run, first.frames))
        elif section == "stopping":
            stopping_runs.setdefault(label, {"pipeline": extra, "runs": {}})["runs"][r] = run
        else:
            long = _long_run(run)
    stopping = []
    for label, pkw in STOPPING_RULES:
        row = {"label": label, "pipeline": pkw, "ratio_to_paper": {}, "iterations_median": {}, "fig14_z_rms_mm": {}}
        for r, tab in zip(PAPER_RANGES_M, ("3", "2")):
            run = runs_d[r] if not pkw else stopping_runs[label]["runs"][r]
            row["ratio_to_paper"][tab] = (sums[r] if not pkw else summary(run))["ratio_to_paper"][tab]
            row["iterations_median"][str(r)] = run["iterations_median"]
        for r in SWEEP_RANGES_M:
            if not pkw:
                sw = next(s for s in sweep if s["scheme"] == SWEEP_SCHEMES[0][0] and s["range_m"] == r)
            else:
                run = stopping_runs[label]["runs"][r]
                sw = _sweep_row(label, r, run, run["frames"])
            row["fig14_z_rms_mm"][str(r)] = sw["rms"]["target_z_cam_mm"] if sw["rms"] else None
        stopping.append(row)
    return {"runs": runs_d, "sums": sums, "var_rows": var_rows, "sweep": sweep, "stopping": stopping, "long": long}


def _long_run(run) -> dict:
    """Fluctuation (max - min) and std of the first N frames of a long run, against Tables 1 and 3."""

    paper = paper_statistics(run["range_mm"])
    C = run["cols"]
    rows = []
    for n in sorted({*(k for k in LONG_CHECKPOINTS if k < C.shape[0]), C.shape[0]}):
        st = statistics(C[:n])
        rows.append({"frames": int(n), "fluctuation": dict(zip(COLUMNS, st["fluctuation"].tolist())),
                     "std": dict(zip(COLUMNS, st["std"].tolist())),
                     "ratio_to_paper": {tab: {c: float(st["fluctuation"][i] / paper[tab]["fluctuation"][c])
                                              for i, c in enumerate(COLUMNS)} for tab in ("1", "3")}})
    return {"frames": run["frames"], "solved": int(C.shape[0]), "failures": dict(run["fails"]), "checkpoints": rows,
            "frames_s": run["frames_s"]}


def _sweep_row(scheme, r, run, frames) -> dict:
    C, tr = run["cols"], run["truth"]
    err = C - tr
    ok = C.shape[0] > 0
    return {"scheme": scheme, "range_m": r, "solved": int(C.shape[0]), "frames": frames,
            "bias": dict(zip(COLUMNS, err.mean(0).tolist())) if ok else None,
            "rms": dict(zip(COLUMNS, np.sqrt((err**2).mean(0)).tolist())) if ok else None,
            "std": dict(zip(COLUMNS, C.std(0).tolist())) if ok else None,
            "rot_err_rms_deg": float(np.sqrt(np.mean(run["rot_err_deg"] ** 2))) if ok else None,
            "integration_time_s": run["integration_time_s"]}
