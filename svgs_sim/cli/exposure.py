"""``svgs exposure-study``: what would have extended a phone's range (the paper's remedies).

The paper: "Possible remedies for this issue could include replacing the corner cubes with
reflectors with a lower return brightness or increasing the spacing between the
reflectors." This study renders the scenario over a set of ranges and, for each remedy,
exposes and solves ``--trials`` noise draws per range:

- ``baseline``: the profile as it is;
- ``exposure=T``: a fixed exposure of T seconds at base ISO (if the phone had allowed it);
- ``nd=OD``: a neutral-density filter of optical density OD over every reflector (the
  return passes it twice: the spots' flux scales by 10^(-2 OD)); render once, expose many;
- ``spacing=K``: the pattern scaled by K about its origin (a wider target; re-rendered).

It reports the success rate per range and remedy, the largest range at which >= 95 % of
trials solve, a CSV, a plot and a Markdown table.
"""

from __future__ import annotations

from pathlib import Path

from svgs_sim.base.errors import InputError


def exposure_study_json(cfg, stats, out: Path) -> dict:
    """The object of ``svgs exposure-study --json`` (:data:`svgs_sim.cli.json_out.SCHEMAS`), from the stored rows."""
    from svgs_sim.cli.json_out import run_info
    from svgs_sim.studies.exposure_study import SUCCESS_LEVEL, summarise, trial_table
    from svgs_sim.studies.store import RESULTS, read_rows

    tt = trial_table(read_rows(out / RESULTS))
    remedies = []
    for d in summarise(tt, cfg.remedies, list(cfg.ranges_m)):
        per = []
        for r in cfg.ranges_m:
            rr = [x for x in tt if x["remedy"] == d["remedy"] and x["range_m"] == r]
            fails = {}
            for x in rr:
                if not x["ok"]:
                    fails[str(x["reason"])] = fails.get(str(x["reason"]), 0) + 1
            per.append({"range_m": r, "trials": len(rr), "solved": sum(bool(x["ok"]) for x in rr),
                        "success_rate": d[f"{r:g} m"], "failures": dict(sorted(fails.items()))})
        remedies.append({"remedy": d["remedy"], "max_range_95_m": d["max_range_95_m"], "ranges": per})
    outputs = {"summary_csv": out / "summary.csv", "summary_md": out / "summary.md", "trials_csv": out / "trials.csv",
               "plot": out / "remedies.png", "results_csv": out / RESULTS, "summary_json": out / "summary.json"}
    return {"camera": cfg.camera, "trials": cfg.trials, "ranges_m": list(cfg.ranges_m), "success_level": SUCCESS_LEVEL,
            "remedies": remedies, "outputs": outputs, "run": run_info(stats, cfg.n_trials)}


def cmd_exposure_study(args) -> int:
    from svgs_sim.cli.json_out import emit, text_to_stderr
    from svgs_sim.cli.sim import check_camera_renderable, _parse_ranges
    from svgs_sim.cli.studies import announce_plan, executor_from_args, print_run_stats
    from svgs_sim.studies.exposure_study import make_config, run_exposure_study

    check_camera_renderable(args.camera)
    ranges = _parse_ranges(args.ranges)
    spec = executor_from_args(args)
    if args.trials < 1:
        raise InputError(f"--trials must be >= 1, got {args.trials}")
    cfg = make_config(args.camera, ranges, args.remedy, trials=args.trials, seed=args.seed)
    from svgs_sim.cli.outdir import output_folder

    out = Path(args.out or f"exposure-study-{Path(str(args.camera)).stem}")
    if announce_plan(args, "render", cfg.n_trials, len(cfg.ranges_m) * len(cfg.remedies), spec,
                     manifest=cfg.manifest(), out=out):
        return 0
    with output_folder(out), text_to_stderr(args.json):  # --out made and probed before any work
        lines, stats = run_exposure_study(cfg, out, spec, chunk_size=args.chunk_size, progress=not args.no_progress)
        print("\n".join(lines))
        print_run_stats(stats)
        print(f"wrote {out / 'summary.csv'}, {out / 'summary.md'}, {out / 'trials.csv'}, {out / 'remedies.png'}, "
              f"{out / 'summary.json'} (results: {out / 'results.csv'})")
    emit(exposure_study_json(cfg, stats, out), args.json, out)
    return 0


def register(sub) -> None:
    from svgs_sim.cli.studies import add_executor_options

    p = sub.add_parser("exposure-study", help="which remedy (exposure, ND filter, spacing) extends the range",
                       description=__doc__.split("\n\n")[1].replace("\n", " ") + " Writes summary.csv, summary.md, "
                       "trials.csv, remedies.png and summary.json; trials are stored as they finish (results.csv, manifest.json), so "
                       "rerunning the same command resumes.")
    p.add_argument("--camera", required=True, help="camera profile (needs [optics] and [flash])")
    p.add_argument("--ranges", default="2,4,6.5,8,10,15,20,30", help="comma-separated ranges, m (default %(default)s)")
    p.add_argument("--remedy", action="append", default=None,
                   help="baseline | exposure=SECONDS | nd=OD | spacing=FACTOR (repeat; default: a standard set)")
    p.add_argument("--trials", type=int, default=5, help="noise draws per range and remedy (default 5; each range and remedy costs one render, ~1-4 s, and "
                   "each draw an exposure, ~0.15-0.35 s)")
    p.add_argument("--seed", type=int, default=0, help="seed of the renders and the noise draws (default 0)")
    p.add_argument("--out", default=None, help="output folder (default exposure-study-CAMERA); rerun with the "
                   "same options to resume an interrupted study")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout (the table goes to stderr); "
                   "the same object is written to summary.json")
    add_executor_options(p, plan_only=True)
    p.set_defaults(func=cmd_exposure_study)
