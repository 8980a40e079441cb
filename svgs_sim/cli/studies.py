"""``svgs campaign`` and ``svgs sensitivity``: studies from the command line.

Discovered by :mod:`svgs_sim.cli.main` (``register(subparsers)``). Nothing heavy is imported until a
handler runs. Exit codes: 0 done, 2 bad input (an :class:`~svgs_sim.base.errors.InputError`, raised
before any trial runs).
"""

from __future__ import annotations

import re
import shlex
import sys
from pathlib import Path

from svgs_sim.base.errors import InputError, number_items


def print_run_stats(stats, rebuilt: str = "outputs", label: str = "") -> None:
    """One line on what a study run did: trials run, time, executor, trials already stored.

    Parameters
    ----------
    stats : svgs_sim.studies.execution.RunStats or None
        None when every trial was already stored.
    rebuilt : str
        What was rebuilt from the stored results in that case ("outputs", "report").
    label : str
        Prefix (a study part's name).
    """
    pre = f"{label}: " if label else ""
    if stats is None:
        print(f"{pre}all trials were already done; {rebuilt} rebuilt from the stored results")
        return
    print(f"{pre}ran {stats.n_run} trial(s) in {stats.elapsed_s:.1f} s ({stats.rate_text}, "
          f"{stats.executor}); {stats.n_already_done} were already done")


def add_executor_options(p, *, plan_only: bool = False) -> None:
    """The executor options of every study command (``--processes``/``--workers``/``--scheduler``,
    ``--chunk-size``, ``--no-progress``); read them back with :func:`executor_from_args`. With
    ``plan_only``, also ``--plan-only`` (the handler calls :func:`announce_plan`)."""
    g = p.add_argument_group("where the trials run (choose one; default: a local process pool, one process per core)")
    x = g.add_mutually_exclusive_group()
    x.add_argument("--processes", type=int, default=None, metavar="N",
                   help="local process pool of N processes (0: run in this process; default: one per core)")
    x.add_argument("--workers", type=int, default=None, metavar="N",
                   help="start a Dask LocalCluster of N worker processes (needs the 'dask' extra; default: none)")
    x.add_argument("--scheduler", default=None, metavar="ADDR",
                   help="run on an existing Dask cluster, e.g. tcp://10.0.0.5:8786 (needs the 'dask' extra; default: none)")
    g.add_argument("--chunk-size", type=int, default=None, metavar="N",
                   help="trials per task (default 16); trials sharing a render stay together")
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    if plan_only:
        p.add_argument("--plan-only", action="store_true",
                       help="print the study's plan (trials, renders, estimated time) on stderr and exit: nothing "
                       "runs and nothing is written")


def announce_plan(args, kind: str, n_trials: int, n_renders: int, spec, *, note: str = "", manifest=None,
                  out=None, ignore=()) -> bool:
    """Print a study's plan on stderr before any work (:func:`svgs_sim.studies.execution.plan_study`:
    trials, renders, the estimate from the cost table, a warning above an hour and when
    ``--processes``/``--workers`` exceeds the cores).

    Parameters
    ----------
    args : argparse.Namespace
        The command's options (``--plan-only`` where the command has it).
    kind : str
        Trial kind.
    n_trials, n_renders : int
        The study's trials and renders (distinct render keys), from its configuration.
    spec : svgs_sim.studies.execution.ExecutorSpec
    note : str
        Said after the counts.
    manifest, out, ignore
        The study's store parameters (``config.manifest()``), its folder (default ``args.out``) and
        the parameters decided by work still to come: ``--plan-only`` refuses a folder holding
        another study's store, as the run would (:func:`svgs_sim.studies.store.check_resumable`).

    Returns
    -------
    bool
        True when ``--plan-only`` was given: the handler returns 0 without running.
    """
    from svgs_sim.studies.execution import plan_study

    plan = plan_study(kind, n_trials, n_renders, spec, note=note)
    for line in plan.lines():
        print(line, file=sys.stderr, flush=True)
    if not getattr(args, "plan_only", False):
        return False
    plan_only_checks(args, spec, manifest=manifest, out=out, ignore=ignore)
    if getattr(args, "json", False):
        print_plan_json(plan.to_json())
    return True


def plan_only_checks(args, spec, *, manifest=None, out=None, ignore=()) -> None:
    """What a run checks before its work and ``--plan-only`` would otherwise skip: the executor
    (Dask importable, the scheduler reachable) and the output folder (not someone else's files a
    study would overwrite). The arguments themselves were checked before (svgs_sim.cli.validate)."""
    from svgs_sim.studies.execution import check_executor
    from svgs_sim.studies.store import check_resumable, refuse_foreign_outputs

    check_executor(spec)
    out = out or getattr(args, "out", None)
    if out and manifest is not None:  # another study's store or someone's files: refused, as the run does
        check_resumable(out, manifest, ignore=ignore)  # (refuse_foreign_outputs where it holds no store)
    elif out:
        refuse_foreign_outputs(out)


def print_plan_json(plan: dict) -> None:
    """``--plan-only --json``: ``{"ok": true, "plan_only": true, "plan": {...}}`` on stdout."""
    from svgs_sim.cli.json_out import dumps

    print(dumps({"ok": True, "plan_only": True, "plan": plan}), file=sys.stdout, flush=True)


def warn_processes(spec) -> None:
    """Print the plan's warning when ``--processes``/``--workers`` exceeds the cores (for a
    study without a count-based plan)."""
    from svgs_sim.studies.execution import plan_study

    for line in plan_study("render", 0, 0, spec).warnings():
        print(line, file=sys.stderr, flush=True)


def executor_from_args(args):
    """The validated :class:`svgs_sim.studies.execution.ExecutorSpec` of :func:`add_executor_options`'s
    options (:class:`InputError` for a bad ``--chunk-size`` too)."""
    from svgs_sim.studies.execution import executor_spec

    spec = executor_spec(args.processes, args.workers, args.scheduler)
    if args.chunk_size is not None and args.chunk_size < 1:
        raise InputError(f"--chunk-size: expected a positive integer, got {args.chunk_size}")
    return spec


def executor_argv(args) -> list[str]:
    """The executor options of ``args`` as command-line words (for a report's command line)."""
    out = []
    for flag, v in (("--processes", args.processes), ("--workers", args.workers), ("--scheduler", args.scheduler),
                    ("--chunk-size", args.chunk_size)):
        if v is not None:
            out += [flag, str(v)]
    return out


def register(sub) -> None:
    """Add the study subcommands (``campaign``, ``sensitivity``, ``merge-range``) to ``sub``.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The subparsers of the ``svgs`` command.
    """
    _register_campaign(sub)
    _register_sensitivity(sub)
    _register_merge_range(sub)
    _register_sun_study(sub)


def _register_campaign(sub) -> None:
    """Add the ``campaign`` subcommand to ``sub``."""
    p = sub.add_parser(
        "campaign",
        help="simulate the paper's MSFC test campaign and compare with its Tables 2-5",
        description="Simulate the 2014 MSFC Flight Robotics Lab campaign for one phone through the rendered chain "
        "(Mitsuba render, phone camera model, SVGS detector and solver): the phone on the test stand's gimbal (roll and "
        "pitch +/-25 deg, yaw +/-45 deg about the line of sight, attitudes kept when the phone sees the target), the "
        "translation stage +/-15 cm, at the paper's ranges, each setting rendered once and exposed several times; the "
        "paper's calibration practice (a focal length estimated from rendered frames at range-finder ranges, the "
        "principal point assumed at the image centre, no distortion). Writes DIR/results.csv (one row per trial, "
        "resumable: rerun the same command to finish an interrupted run), DIR/summary.csv, DIR/summary.json and a "
        "self-contained DIR/report.html with Tables 2-5 beside the paper's (the app as published: every solution "
        "reported, the consistency test's refusals beside it; the standard deviations scored, the mean errors shown "
        "with the floor their scatter implies but not scored), the Cramer-Rao bound, histograms, sample images and, "
        "with --budget, the error budget.",
    )
    p.add_argument("--camera", required=True, help="camera profile (htc-amaze-4g, galaxy-nexus, or a .toml path)")
    p.add_argument("--trials", type=int, default=200, metavar="N", help="trials per range (default 200); a rendered trial costs ~1-2 s of one core (docs/performance.md), "
                   "a geometric one ~1 ms")
    p.add_argument("--exposures-per-render", type=int, default=4, metavar="K",
                   help="exposures (noise draws) of each rendered stand setting (default 4): trials/K settings per range")
    p.add_argument("--ranges", default=None, metavar="R1,R2,...",
                   help="test ranges in m (default: the paper's for the phone)")
    p.add_argument("--out", default=None, metavar="DIR", help="study directory (default runs/campaign-CAMERA)")
    p.add_argument("--seed", type=int, default=0, help="study seed (default 0)")
    p.add_argument("--trial-kind", choices=("render", "geometric"), default="render",
                   help="render (default): the rendered chain; geometric: the pattern projected with --sigma-px of "
                   "Gaussian centroid noise (fast)")
    p.add_argument("--sigma-px", type=float, default=0.1, help="centroid noise of the geometric trial, px per axis "
                   "(default 0.1)")
    p.add_argument("--pattern", default="svgs-3u", help="target pattern (default svgs-3u)")
    p.add_argument("--calibration", choices=("exact", "paper"), default="paper",
                   help="calibration the solver uses: the paper's practice (default; one per campaign, see "
                   "docs/studies.md) or exact (the solver knows the lens, unless the error options below say otherwise)")
    p.add_argument("--misalignment-deg", default=None, metavar="R,P,Y",
                   help="the phone's roll, pitch, yaw in its holder on the stand, deg (default: the lab's, "
                   "assets/labs/msfc-frl.toml: 0,0,2 for the Galaxy Nexus, fitted to Table 4's yaw; 0,0,0 otherwise)")
    p.add_argument("--budget", action="store_true",
                   help="also run the error budget: the campaign with one error source removed at a time (render trials)")
    p.add_argument("--still-lab", action="store_true",
                   help="a perfect lab: no gimbal or stage positioning error, exact recorded ranges, still air "
                   "(default: the lab's sourced errors, assets/labs/msfc-frl.toml [errors]; docs/studies.md)")
    p.add_argument("--focal-error-frac", type=float, default=0.0, help="solver's focal-length error, a fraction of f (default 0: exact)")
    p.add_argument("--pp-error-px", default="0,0", metavar="DU,DV", help="solver's principal-point error, px (default 0,0)")
    p.add_argument("--k1-error", type=float, default=0.0, help="solver's radial distortion k1 error, dimensionless (normalised image coordinates; default 0)")
    p.add_argument("--merge-px", type=float, default=0.0,
                   help="spots closer than this many px merge (geometric trial; default 0: never)")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout (the table goes to stderr); "
                   "the same object is written to DIR/summary.json")
    add_executor_options(p, plan_only=True)
    p.set_defaults(func=cmd_campaign)


def _register_sensitivity(sub) -> None:
    """Add the ``sensitivity`` subcommand to ``sub``."""
    s = sub.add_parser(
        "sensitivity",
        help="global sensitivity (Sobol or Morris) of pose error and success to scenario parameters",
        description="Vary parameters uniformly in LOW:HIGH and compute first-order and total Sobol' indices (or Morris "
        "mu*) with confidence intervals for the position error, attitude error and success. Writes DIR/results.csv "
        "(resumable), DIR/indices.csv, DIR/summary.json and DIR/report.html.",
    )
    s.add_argument("--camera", required=True, help="camera profile")
    s.add_argument("--vary", action="append", default=[], metavar="PARAM=LOW:HIGH",
                   help="a varied parameter, uniform in LOW:HIGH in the parameter's unit (repeat; at least one; default: none); "
                        "see docs/studies.md for the names and units")
    s.add_argument("--fixed", action="append", default=[], metavar="PARAM=VALUE",
                   help="hold a parameter at VALUE, in its unit, or at a choice's word (f_number=profile, "
                        "threshold=otsu; repeat; default: the trial kind's nominal values)")
    s.add_argument("--method", choices=("sobol", "morris"), default="sobol",
                   help="sobol: first-order and total indices (n (d + 2) trials); morris: elementary effects, mu* "
                        "(n (d + 1) trials, cheaper for screening); default %(default)s")
    s.add_argument("--n", type=int, default=256,
                   help="base samples (Sobol: a power of two, n (d + 2) trials) or trajectories (Morris: n (d + 1)); default "
                        "%(default)s. A geometric trial costs ~1 ms, a rendered one ~1-4 s of one core")
    s.add_argument("--out", default=None, metavar="DIR", help="study directory (default runs/sensitivity-CAMERA)")
    s.add_argument("--seed", type=int, default=0, help="study seed: the sample design and every trial's draws (default 0)")
    s.add_argument("--trial-kind", default="geometric",
                   help="trial kind: geometric (projected centroids with noise, ~1 ms a trial), render (the rendered "
                        "chain, ~1-4 s a trial) or tof; default %(default)s")
    s.add_argument("--pattern", default="svgs-3u", help="target pattern name or .toml path (default %(default)s)")
    s.add_argument("--json", action="store_true", help="print one JSON object on stdout (the rankings go to stderr); "
                   "the same object is written to DIR/summary.json")
    add_executor_options(s, plan_only=True)
    s.set_defaults(func=cmd_sensitivity)


def _register_merge_range(sub) -> None:
    """Add the ``merge-range`` subcommand to ``sub``."""
    m = sub.add_parser(
        "merge-range",
        help="which physical parameters move the range at which the spots merge, and by how much",
        description="The rendered chain at a grid of ranges, the phone facing the target on the stand: the merge "
        "margin (the detector's threshold minus the darkest level between the closest spots) and the range where it "
        "crosses zero, for the phone as profiled and with each physical parameter (glare veiling fraction and "
        "exponent, exposure compensation, LED offset, cube spacing, f-number) at the low and the high end of its "
        "range. Writes DIR/results.csv (resumable), DIR/merge_ranges.csv, DIR/summary.json and DIR/report.html "
        "(a tornado chart and the margin curves).",
    )
    m.add_argument("--camera", required=True, help="camera profile (e.g. htc-amaze-4g)")
    m.add_argument("--ranges", default=None, metavar="R1,R2,...",
                   help="increasing ranges of the grid, m (default 3,4,5,5.5,6,6.5,7,7.5,8,9,10,12)")
    m.add_argument("--vary", action="append", default=[], metavar="NAME[=LOW:HIGH]",
                   help="a physical parameter and its range (default: all, each over its documented range; see "
                   "docs/studies.md)")
    m.add_argument("--exposures", type=int, default=2, metavar="K", help="exposures per render (default 2); each case costs one render per range (~1-4 s) and an exposure "
                   "~0.35 s")
    m.add_argument("--out", default=None, metavar="DIR", help="study directory (default runs/merge-range-CAMERA)")
    m.add_argument("--seed", type=int, default=0, help="seed of the renders and the noise (default 0)")
    m.add_argument("--pattern", default="svgs-3u", help="target pattern name or .toml path (default %(default)s)")
    m.add_argument("--json", action="store_true", help="print one JSON object on stdout; also DIR/summary.json")
    add_executor_options(m, plan_only=True)
    m.set_defaults(func=cmd_merge_range)


#: A list of numbers that may start with a minus (``-60,0,60``): a value, not an option.
NEGATIVE_LIST = re.compile(r"^-\d*\.?\d+([eE][-+]?\d+)?(,-?\d*\.?\d+([eE][-+]?\d+)?)*$")


def allow_negative_lists(parser) -> None:
    """Let ``parser`` take ``--opt -60,0,60`` (argparse reads a word starting with a minus as an
    option unless it looks like a negative number; a list of them now does too)."""
    parser._negative_number_matcher = NEGATIVE_LIST


def _register_sun_study(sub) -> None:
    """Add the ``sun-study`` subcommand to ``sub``."""
    p = sub.add_parser(
        "sun-study",
        help="on orbit: at which ranges and sun directions SVGS holds lock, loses it, or locks onto a glint",
        description="Rendered trials on orbit (--environment orbit) over a grid of ranges and sun directions in the "
        "target frame, TRIALS per cell, each pose drawn over the paper's test envelope (roll, pitch uniform in +/-25 "
        "deg, yaw in +/-45 deg, the target on the boresight). Each trial is solved, a wrong lock (a pose the paper's "
        "app would report with an identified blob that is not its target's spot) or a failure by its reason; the "
        "mechanisms (sun in the field of view, a lit body, a glint, saturation, the Earth behind) are counted per "
        "cell. With --earth-deg, --earth-albedos adds the Earth's albedo as an axis of the grid. Writes "
        "DIR/results.csv (resumable), DIR/summary.json (the cells) and DIR/sun_study.png. Negative values work as "
        "they are: --sun-elevations-deg -60,0,60. Exit 0 done, 2 bad input.",
    )
    p.add_argument("--camera", required=True, help="camera profile (galaxy-nexus, htc-amaze-4g, or a .toml path)")
    p.add_argument("--ranges", required=True, metavar="R1,R2,...", help="boresight distances, m")
    p.add_argument("--sun-azimuths-deg", required=True, metavar="A1,A2,...",
                   help="sun azimuths in the target frame, from +x toward +y, deg")
    p.add_argument("--sun-elevations-deg", required=True, metavar="E1,E2,...",
                   help="sun elevations from the pattern plane toward +z (the face normal), deg")
    p.add_argument("--trials", type=int, required=True, metavar="N", help="trials per cell (each a render, ~1-2 s of one core)")
    p.add_argument("--out", required=True, metavar="DIR", help="study directory (a rerun with the same arguments resumes it)")
    p.add_argument("--seed", type=int, default=0, help="study seed (default 0)")
    p.add_argument("--pattern", default="svgs-3u", help="target pattern name or .toml path (default %(default)s)")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout; also DIR/summary.json")
    p.add_argument("--earth-deg", default=None, metavar="AZ,EL",
                   help="the Earth in every trial: the direction toward its centre in the target frame, deg (as "
                   "svgs render --earth-deg); default: none")
    from svgs_sim.sim.scene import Scene

    q = Scene.quantities()
    a = p.add_argument("--altitude-km", type=float, default=Scene.__dataclass_fields__["altitude_km"].default,
                       help=q["altitude_km"].help)
    a.bounds = (q["altitude_km"].lower, q["altitude_km"].upper, q["altitude_km"].unit)  # the scene quantity's domain
    p.add_argument("--earth-albedos", default=None, metavar="A1,A2,...",
                   help="with --earth-deg: the Earth's Lambertian albedos, an axis of the grid (default 0.3, its Bond "
                   "albedo; 0.05 open ocean, 0.8 a bright cloud deck: --earth-albedos 0.05,0.3,0.8)")
    p.add_argument("--body", default="plate", choices=("plate", "3u", "none"),
                   help="the target's body in every trial: the lab's breadboard (plate, the default), the shipped 3U "
                   "cubesat (3u: rails, MLI, body-mounted cells under cover glass) or none")
    add_executor_options(p, plan_only=True)
    allow_negative_lists(p)
    p.set_defaults(func=cmd_sun_study)


def _numbers(text, flag) -> list[float]:
    return number_items(text, flag)


def cmd_sun_study(args) -> int:
    from svgs_sim.cli.json_out import emit, text_to_stderr
    from svgs_sim.cli.outdir import output_folder
    from svgs_sim.studies.sun_study import make_config, run_sun_study

    spec = executor_from_args(args)
    earth = None
    if args.earth_deg is not None:
        ae = _numbers(args.earth_deg, "--earth-deg")
        if len(ae) != 2:
            raise InputError(f"--earth-deg: expected AZ,EL (two numbers), got {args.earth_deg!r}")
        earth = (*ae, args.altitude_km)
    elif args.altitude_km != 400.0 or args.earth_albedos is not None:
        raise InputError("--altitude-km, --earth-albedos: the Earth's; give them with --earth-deg AZ,EL")
    albedos = None if args.earth_albedos is None else _numbers(args.earth_albedos, "--earth-albedos")
    config = make_config(args.camera, _numbers(args.ranges, "--ranges"), _numbers(args.sun_azimuths_deg, "--sun-azimuths-deg"),
                         _numbers(args.sun_elevations_deg, "--sun-elevations-deg"), args.trials, seed=args.seed,
                         pattern=args.pattern, earth=earth, earth_albedos=albedos, body=args.body)
    out = Path(args.out)
    lists = {k: ",".join(f"{x:g}" for x in v) for k, v in (("--ranges", config.ranges_m),
                                                             ("--sun-azimuths-deg", config.azimuths_deg),
                                                             ("--sun-elevations-deg", config.elevations_deg))}
    argv = ["svgs", "sun-study", "--camera", config.camera] + [w for k, v in lists.items() for w in (f"{k}={v}",)] + [
        "--trials", str(config.trials), "--out", str(out), "--seed", str(config.seed), "--pattern", config.pattern,
        *([f"--earth-deg={config.earth[0]:g},{config.earth[1]:g}", "--altitude-km", f"{config.earth[2]:g}",
           "--earth-albedos=" + ",".join(f"{b:g}" for b in config.earth_albedos)] if config.earth else []),
        *(["--body", config.body] if config.body != "plate" else []),
        *executor_argv(args)]
    if announce_plan(args, "render", config.n_trials, config.n_trials, spec, manifest=config.manifest()):
        return 0
    with output_folder(out), text_to_stderr(args.json):  # --out made and probed before any work
        s = run_sun_study(config, out, spec, chunk_size=args.chunk_size, progress=not args.no_progress,
                          command=shlex.join(argv))
        tot = {k: sum(c[k] for c in s["cells"])
               for k in ("trials", "solved", "wrong_lock", "wrong_lock_flagged", "wrong_lock_paper_gates")}
        print(f"{config.camera} on orbit: {tot['solved']} of {tot['trials']} trials solved, {tot['wrong_lock']} wrong "
              f"lock(s) ({tot['wrong_lock_flagged']} flagged by the consistency test; {tot['wrong_lock_paper_gates']} "
              f"with the paper's test-envelope gates), over {len(s['cells'])} cells")
        for r in config.ranges_m:
            cs = [c for c in s["cells"] if c["range_m"] == r]
            n = sum(c["trials"] for c in cs)
            print(f"  {r:g} m: solved {sum(c['solved'] for c in cs)}/{n}, wrong locks {sum(c['wrong_lock'] for c in cs)}")
        print(f"results: {out}/results.csv  summary: {out}/summary.json  figure: {out}/sun_study.png")
    obj = {k: s[k] for k in ("camera", "pattern", "trials_per_cell", "pose", "wrong_lock_px", "body", "body_description",
                             "earth", "cells", "outputs")}
    obj["run"] = s["run"]
    emit(obj, args.json, out)
    return 0


def _ranges(text):
    from svgs_sim.cli.validate import parse_range_list

    return None if text is None else parse_range_list(text, "--ranges")


def _triple(text, flag):
    return tuple(number_items(text, f"{flag} (roll, pitch, yaw in deg)", count=3))


def _pp(text):
    du, dv = number_items(text, "--pp-error-px (DU,DV in px)", count=2)
    return du, dv


def _safe(name: str) -> str:
    import re

    return re.sub(r"[^A-Za-z0-9_.-]+", "_", Path(name).stem)


def cmd_campaign(args) -> int:
    from svgs_sim.cli.json_out import emit, text_to_stderr
    from svgs_sim.studies.campaign import make_config, print_summary, run_campaign
    from svgs_sim.studies.execution import executor_spec

    spec = executor_spec(args.processes, args.workers, args.scheduler)
    du, dv = _pp(args.pp_error_px)
    err = {"focal_error_frac": args.focal_error_frac, "pp_error_u_px": du, "pp_error_v_px": dv, "k1_error": args.k1_error}
    if args.calibration == "exact":
        err = {k: v for k, v in err.items() if v != 0}
    mis = None if args.misalignment_deg is None else _triple(args.misalignment_deg, "--misalignment-deg")
    config = make_config(args.camera, ranges_m=_ranges(args.ranges), trials_per_range=args.trials, seed=args.seed,
                         sigma_px=args.sigma_px, trial_kind=args.trial_kind, pattern=args.pattern,
                         calibration=args.calibration, calibration_error=err, merge_px=args.merge_px,
                         exposures_per_render=args.exposures_per_render, misalignment_deg=mis, budget=args.budget,
                         lab_errors=not args.still_lab)
    if args.chunk_size is not None and args.chunk_size < 1:
        raise InputError(f"--chunk-size: expected a positive integer, got {args.chunk_size}")
    out = args.out or f"runs/campaign-{_safe(args.camera)}"
    argv = ["svgs", "campaign", "--camera", args.camera, "--trials", str(args.trials),
            "--exposures-per-render", str(args.exposures_per_render),
            "--ranges", ",".join(f"{r:g}" for r in config.ranges_m), "--out", out, "--seed", str(args.seed),
            "--trial-kind", args.trial_kind, "--pattern", args.pattern, "--calibration", args.calibration,
            "--misalignment-deg", ",".join(f"{x:g}" for x in config.misalignment_deg)]
    if args.trial_kind == "geometric":
        argv += ["--sigma-px", repr(args.sigma_px)]
    if args.budget:
        argv += ["--budget"]
    if args.still_lab:
        argv += ["--still-lab"]
    if args.calibration == "exact":
        argv += ["--focal-error-frac", repr(args.focal_error_frac), "--pp-error-px", f"{du!r},{dv!r}",
                 "--k1-error", repr(args.k1_error)]
    if args.merge_px:
        argv += ["--merge-px", repr(args.merge_px)]
    argv += executor_argv(args)
    k = len(config.ranges_m)
    if announce_plan(args, config.trial_kind, k * config.trials_per_range,
                     k * config.poses_per_range if config.trial_kind == "render" else 0, spec,
                     note="; ".join(n for n, on in (
                         ("without the error budget's variants", config.budget),
                         ("the rendered focal calibration first",
                          config.trial_kind == "render" and config.calibration == "paper")) if on),
                     manifest=config.manifest(), out=out, ignore=("calibration_error",)):
        return 0
    from svgs_sim.cli.outdir import output_folder

    with output_folder(out), text_to_stderr(args.json):  # --out made and probed before any work
        summary, stats, path, config = run_campaign(config, out, spec, chunk_size=args.chunk_size,
                                                    progress=not args.no_progress, command=shlex.join(argv))
        print_summary(summary, config)
        print_run_stats(stats, "report")
        print(f"results: {out}/results.csv  summary: {out}/summary.csv, {out}/summary.json  report: {path}")
    emit(campaign_json(config, summary, stats, out, path), args.json, out)
    return 0


def cmd_merge_range(args) -> int:
    from svgs_sim.cli.json_out import emit, run_info, text_to_stderr
    from svgs_sim.studies.merge_range import format_merge_range, make_config, run_merge_range

    spec = executor_from_args(args)
    config = make_config(args.camera, ranges_m=_ranges(args.ranges), vary=args.vary or None, exposures=args.exposures,
                         seed=args.seed, pattern=args.pattern)
    out = Path(args.out or f"runs/merge-range-{_safe(args.camera)}")
    argv = ["svgs", "merge-range", "--camera", args.camera, "--ranges", ",".join(f"{r:g}" for r in config.ranges_m)]
    for p in config.parameters:
        lo, hi = config.bounds[p]
        argv += ["--vary", f"{p}={lo:g}:{hi:g}"]
    argv += ["--exposures", str(config.exposures), "--out", str(out), "--seed", str(config.seed),
             "--pattern", config.pattern] + executor_argv(args)
    n_cases = len(config.cases())
    if announce_plan(args, "render", n_cases * len(config.ranges_m) * config.exposures,
                     n_cases * len(config.ranges_m), spec, manifest=config.manifest(), out=out):
        return 0
    from svgs_sim.cli.outdir import output_folder

    with output_folder(out), text_to_stderr(args.json):  # --out made and probed before any work
        cases, eff, stats, path = run_merge_range(config, out, spec, chunk_size=args.chunk_size,
                                                  progress=not args.no_progress, command=shlex.join(argv))
        nom = cases[0]
        print(f"{config.camera}: the spots merge at {format_merge_range(nom['merge_range_m'], nom['bound'])} m as profiled")
        for e in eff:
            print(f"  {e['parameter']:26s} {e['low']:g} -> {e['high']:g}: {format_merge_range(e['merge_range_low_m'], e['bound_low'])}"
                  f" -> {format_merge_range(e['merge_range_high_m'], e['bound_high'])} m (span {e['span_m']:.2f} m)")
        print_run_stats(stats, "report")
        print(f"results: {out}/results.csv  merge ranges: {out}/merge_ranges.csv  report: {path}")
    obj = {"camera": config.camera, "ranges_m": list(config.ranges_m), "exposures": config.exposures,
           "nominal": {"merge_range_m": nom["merge_range_m"], "bound": nom["bound"]},
           "cases": [{k: c[k] for k in ("case", "parameter", "value", "merge_range_m", "bound", "margin_dn", "solved")}
                     for c in cases],
           "effects": eff,
           "outputs": {"results_csv": out / "results.csv", "merge_ranges_csv": out / "merge_ranges.csv",
                       "report": path, "summary_json": out / "summary.json"},
           "run": run_info(stats, len(cases) * len(config.ranges_m) * config.exposures)}
    emit(obj, args.json, out)
    return 0


def cmd_sensitivity(args) -> int:
    from svgs_sim.cli.json_out import emit, text_to_stderr
    from svgs_sim.studies.execution import executor_spec
    from svgs_sim.studies.sensitivity import analysed_outputs, make_config, ranking, run_sensitivity

    spec = executor_spec(args.processes, args.workers, args.scheduler)
    config = make_config(args.camera, args.vary, fixed=args.fixed, method=args.method, n=args.n, seed=args.seed,
                         trial_kind=args.trial_kind, pattern=args.pattern)
    if args.chunk_size is not None and args.chunk_size < 1:
        raise InputError(f"--chunk-size: expected a positive integer, got {args.chunk_size}")
    out = args.out or f"runs/sensitivity-{_safe(args.camera)}"
    argv = ["svgs", "sensitivity", "--camera", args.camera]
    for v in args.vary:
        argv += ["--vary", v]
    for v in args.fixed:
        argv += ["--fixed", v]
    argv += ["--method", args.method, "--n", str(args.n), "--out", out, "--seed", str(args.seed),
             "--trial-kind", args.trial_kind, "--pattern", config.pattern] + executor_argv(args)
    if config.trial_kind == "tof":  # every trial is a run of its own: one render each
        renders = config.n_trials
    else:
        renders = config.n_trials if config.trial_kind == "render" and any(v.needs_render for v in config.varied) else (
            1 if config.trial_kind == "render" else 0)
    if announce_plan(args, config.trial_kind, config.n_trials, renders, spec,
                     note=f"{args.method} over {len(config.varied)} parameter(s)"
                     + ("; renders at most" if renders > 1 else ""), manifest=config.manifest(), out=out):
        return 0
    from svgs_sim.cli.outdir import output_folder

    with output_folder(out), text_to_stderr(args.json):  # --out made and probed before any work
        result, stats, path, n_groups = run_sensitivity(config, out, spec, chunk_size=args.chunk_size,
                                                        progress=not args.no_progress, command=shlex.join(argv))
        label = "ST" if args.method == "sobol" else "mu*"
        for k in analysed_outputs(config):
            rk = ranking(result, config, k)
            print(f"{k:14s} ranked by {label}: " + ", ".join(f"{n} {s:.3f}" for n, s in rk))
        print(f"failed trials: {100 * result['failure_fraction']:.1f} %; renders needed: {n_groups} of "
              f"{config.n_trials} trials")
        if stats is not None:
            print(f"ran {stats.n_run} trial(s) in {stats.elapsed_s:.1f} s ({stats.executor})")
        print(f"results: {out}/results.csv  indices: {out}/indices.csv, {out}/summary.json  report: {path}")
    emit(sensitivity_json(config, result, stats, out, path, n_groups), args.json, out)
    return 0


def _state(row: dict, prefix: str) -> dict | None:
    """``{component: row[prefix + component]}``; None when every value is NaN (no paper row)."""
    import numpy as np

    from svgs_sim.svgs.frames import STATE_KEYS

    d = {c: row[f"{prefix}{c}"] for c in STATE_KEYS}
    return None if all(v is None or np.isnan(v) for v in d.values()) else d


def campaign_json(config, summary, stats, out, report) -> dict:
    """The object of ``svgs campaign --json`` (:data:`svgs_sim.cli.json_out.SCHEMAS`), from
    :func:`svgs_sim.studies.campaign.summarize` (which reads the paper's tables with :mod:`svgs_sim.assets.papers`)."""
    from svgs_sim.cli.json_out import run_info

    ranges = []
    for s in summary:
        ranges.append({"range_m": s["range_m"], "trials": s["n"], "solved": s["n_ok"], "success_rate": s["success_rate"],
                       "refused_by_consistency_test": s["n_rejected_consistency"],
                       "failures": dict(sorted(s["reasons"].items())), "mean_abs_error": _state(s, "mean_abs_") or {},
                       "abs_bias": _state(s, "abs_mean_") or {}, "rms": _state(s, "rms_") or {},
                       "bias": _state(s, "bias_") or {}, "std": _state(s, "std_") or {},
                       "crlb_std": _state(s, "crlb_") or {},
                       "paper": {"mean_error": _state(s, "paper_mean_"), "std": _state(s, "paper_std_")},
                       "ratio": {"mean_abs_error": _state(s, "ratio_mean_abs_"), "std": _state(s, "ratio_std_"),
                                 "abs_bias": _state(s, "ratio_abs_mean_"), "rms": _state(s, "ratio_rms_")}})
    out = Path(out)
    from svgs_sim.studies.campaign import read_honest_count

    return {"trial_kind": config.trial_kind, "camera": config.camera, "trials_per_range": config.trials_per_range,
            "exposures_per_render": config.exposures_per_render, "stand_settings_per_range": config.poses_per_range,
            "sigma_px": config.sigma_px if config.trial_kind == "geometric" else None, "calibration": config.calibration,
            "calibration_error": dict(sorted(config.calibration_error.items())),
            "true_lens": dict(sorted(config.lens.items())), "focal_calibration": config.calibration_info or None,
            "misalignment_deg": list(config.misalignment_deg), "budget": bool(config.budget), "ranges": ranges,
            "honest_count": read_honest_count(out),
            "outputs": {"results_csv": out / "results.csv", "summary_csv": out / "summary.csv", "report": report,
                        "summary_json": out / "summary.json"},
            "run": run_info(stats, len(config.ranges_m) * config.trials_per_range)}


def sensitivity_json(config, result, stats, out, report, n_groups) -> dict:
    """The object of ``svgs sensitivity --json`` (:data:`svgs_sim.cli.json_out.SCHEMAS`): the rows of
    ``indices.csv`` per output, the rankings and the run."""
    from svgs_sim.cli.json_out import run_info
    from svgs_sim.studies.sensitivity import analysed_outputs, index_rows, ranking

    names = [v.name for v in config.varied]
    rows = index_rows(result, config, names)
    out = Path(out)
    return {"camera": config.camera, "method": config.method, "trial_kind": config.trial_kind, "n": config.n,
            "n_trials": config.n_trials,
            "parameters": [{"name": v.name, "low": v.low, "high": v.high, "unit": v.unit, "needs_render": v.needs_render}
                           for v in config.varied],
            "fixed": dict(config.fixed), "failure_fraction": result["failure_fraction"], "render_groups": n_groups,
            "indices": {k: [{c: v for c, v in r.items() if c != "output"} for r in rows if r["output"] == k]
                        for k in analysed_outputs(config)},
            "ranking": {k: [list(x) for x in ranking(result, config, k)] for k in analysed_outputs(config)},
            "outputs": {"results_csv": out / "results.csv", "indices_csv": out / "indices.csv", "report": report,
                        "summary_json": out / "summary.json"},
            "run": run_info(stats, config.n_trials)}
