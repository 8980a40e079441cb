"""``svgs sensor-model build`` and ``svgs sensor-model validate``: the statistical sensor's table from
rendered frames, and its check against rendered frames that were not used to build it
(:mod:`svgs_sim.studies.sensor_model`, :class:`svgs_sim.sim.statistical_sensor.StatisticalSensor`).

Registered in :data:`svgs_sim.cli.main.COMMANDS`; nothing heavy at module level. Exit codes: 0 done,
1 (validate) the held-out frames are outside the model's intervals, 2 bad input (checked before any
rendering), 3 a file could not be written.
"""

from __future__ import annotations

import shlex
import sys
from pathlib import Path

from svgs_sim.base.errors import InputError, number_items
from svgs_sim.cli.exit_codes import EXIT_NO_SOLUTION, EXIT_OK

#: Seconds a full-resolution frame of the sensor takes on one core of the 2-core reference machine
#: (render, camera model, detection, solution, bound; ``benchmarks/bench_approach.py``), for the plan.
FRAME_COST_S = 0.5


def register(sub) -> None:
    from svgs_sim.cli.studies import add_executor_options
    from svgs_sim.studies.sensor_model import SensorModelConfig

    d = SensorModelConfig("galaxy-nexus")
    b = sub.add_parser(
        "build", help="the statistical sensor's table: bias, covariance and dropouts over range and off-axis angle",
        description="Render frames of the docking loop's sensor (full resolution, the phone's auto-exposure carried "
        "from frame to frame, the app's threshold, the per-frame CRLB) at each node of a grid over range and off-axis "
        "angle, with the attitude drawn within +-ATTITUDE_DEG, and keep per node the error's bias and covariance, the "
        "median bound and the dropouts by reason. Writes OUT/sensor_model.json (the table the statistical sensor and "
        "basilisk_docking.py --sensor-model read), OUT/frames.csv and OUT/sensor_model.png. A killed build continues "
        "where it stopped when rerun with the same arguments.")
    b.add_argument("--camera", required=True, help="phone camera profile name or .toml path")
    b.add_argument("--pattern", default="svgs-3u", help="target pattern (default svgs-3u)")
    b.add_argument("--ranges", default=",".join(f"{r:g}" for r in d.ranges_m), metavar="R1,R2,...",
                   help=f"the nodes' ranges along the boresight, m, increasing (default {','.join(f'{r:g}' for r in d.ranges_m)})")
    b.add_argument("--off-axis-deg", default=",".join(f"{a:g}" for a in d.off_axis_deg), metavar="A1,A2,...",
                   help="the nodes' off-axis angles of the target, deg, from 0, increasing (default "
                        f"{','.join(f'{a:g}' for a in d.off_axis_deg)})")
    b.add_argument("--frames-per-node", type=int, default=d.frames_per_node,
                   help=f"rendered frames at each node (default {d.frames_per_node})")
    b.add_argument("--attitude-deg", type=float, default=d.attitude_deg,
                   help=f"each frame's roll, pitch and yaw uniform within +-this, deg (the envelope; default {d.attitude_deg:g})")
    b.add_argument("--fps", type=float, default=d.frame_rate_hz,
                   help=f"the phone's frame rate, frames/s (its auto-exposure's steps; default {d.frame_rate_hz:g})")
    b.add_argument("--seed", type=int, default=0, help="seed of every pose, render and noise draw (default 0)")
    b.add_argument("--out", required=True, help="output folder (a rerun with the same arguments resumes it)")
    b.add_argument("--json", action="store_true", help="print the summary as one JSON object on stdout")
    add_executor_options(b, plan_only=True)
    b.set_defaults(func=cmd_build)
    v = sub.add_parser(
        "validate", help="the statistical sensor against held-out rendered frames: KS tests, scatter, dropouts",
        description="Render FRAMES held-out frames at poses drawn inside a table's envelope (log-uniform range, "
        "uniform off-axis angle and attitude) from a seed of their own, and compare them with the statistical "
        "sensor at the same poses: per component a two-sample Kolmogorov-Smirnov test of the errors, the errors' "
        "scatter in units of the model's with a 90 % interval, and each outcome's count (solved, wrong lock, "
        "dropouts by reason) against the model's 90 % interval. Writes OUT/validation.json, OUT/validation.csv and "
        "OUT/validation.png. Exit 0 when every outcome count is inside its interval and no KS p-value is below "
        "0.01, 1 otherwise.")
    v.add_argument("--model", required=True, help="sensor_model.json of svgs sensor-model build (or its folder)")
    v.add_argument("--frames", type=int, default=200, help="held-out frames to render (default 200)")
    v.add_argument("--seed", type=int, default=1, help="seed of the held-out poses, renders and noise (default 1)")
    v.add_argument("--out", required=True, help="output folder (default: none; a rerun with the same arguments resumes it)")
    v.add_argument("--json", action="store_true", help="print the validation as one JSON object on stdout")
    add_executor_options(v, plan_only=True)
    v.set_defaults(func=cmd_validate)


def _plan(args, spec, n_frames: int, what: str) -> bool:
    """Print the plan on stderr; True under ``--plan-only`` (nothing runs)."""
    from svgs_sim.cli.studies import plan_only_checks, print_plan_json
    from svgs_sim.studies.execution import cpu_cores

    if args.chunk_size is not None:
        raise InputError("--chunk-size: a sensor model's task is one node (or 8 held-out frames); it takes no chunk size")
    workers = spec.n_workers if spec.n_workers else 1
    est_s = n_frames * FRAME_COST_S / max(1, min(workers, cpu_cores()))
    print(f"plan: {what}: {n_frames} rendered frames, about {est_s / 60:.0f} min on {workers} "
          f"process{'es' if workers != 1 else ''} ({FRAME_COST_S:g} s a frame a core)", file=sys.stderr, flush=True)
    if not getattr(args, "plan_only", False):
        return False
    plan_only_checks(args, spec)
    if args.json:
        print_plan_json({"frames": n_frames, "estimate_s": est_s, "workers": workers})
    return True


def config_from_args(args):
    from svgs_sim.studies.sensor_model import SensorModelConfig

    return SensorModelConfig(args.camera, args.pattern, tuple(number_items(args.ranges, "--ranges")),
                             tuple(number_items(args.off_axis_deg, "--off-axis-deg")), args.frames_per_node,
                             args.attitude_deg, args.fps, args.seed)


def cmd_build(args) -> int:
    from svgs_sim.cli.json_out import emit, text_to_stderr
    from svgs_sim.cli.outdir import output_folder
    from svgs_sim.cli.studies import executor_from_args, executor_argv
    from svgs_sim.studies.sensor_model import build_sensor_model, check_build_folder

    spec = executor_from_args(args)
    cfg = config_from_args(args)
    check_build_folder(cfg, args.out)
    argv = ["svgs", "sensor-model", "build", "--camera", args.camera, "--ranges", args.ranges,
            "--off-axis-deg", args.off_axis_deg, "--frames-per-node", str(cfg.frames_per_node),
            "--attitude-deg", f"{cfg.attitude_deg:g}", "--fps", f"{cfg.frame_rate_hz:g}", "--seed", str(cfg.seed),
            "--out", args.out] + executor_argv(args)
    if args.pattern != "svgs-3u":
        argv[5:5] = ["--pattern", args.pattern]
    if _plan(args, spec, cfg.n_frames(), f"sensor model of {cfg.camera}, {len(cfg.nodes())} nodes"):
        return EXIT_OK
    with output_folder(args.out), text_to_stderr(args.json):
        s = build_sensor_model(cfg, args.out, spec, progress=not args.no_progress, command=shlex.join(argv))
        drops = ", ".join(f"{k} {v}" for k, v in sorted(s["dropouts"].items())) or "none"
        print(f"{cfg.camera}: {s['frames']} frames at {s['nodes']} nodes: {s['solved']} solved in the core, "
              f"{s['gross_errors']} gross errors, {s['wrong_locks']} wrong locks, dropouts: {drops}")
        print(f"  table: {s['outputs']['table']}  frames: {s['outputs']['frames']}  figure: {s['outputs']['figure']}")
    emit(s, args.json)
    return EXIT_OK


def cmd_validate(args) -> int:
    from svgs_sim.cli.json_out import emit, text_to_stderr
    from svgs_sim.cli.outdir import output_folder
    from svgs_sim.cli.studies import executor_from_args, executor_argv
    from svgs_sim.sim.statistical_sensor import SensorTable
    from svgs_sim.studies.sensor_model import check_validation_folder, validate_sensor_model

    spec = executor_from_args(args)
    check_validation_folder(SensorTable.load(args.model), args.out, args.frames, args.seed)  # before any work
    if _plan(args, spec, args.frames, "sensor model validation"):
        return EXIT_OK
    argv = ["svgs", "sensor-model", "validate", "--model", args.model, "--frames", str(args.frames),
            "--seed", str(args.seed), "--out", args.out] + executor_argv(args)
    with output_folder(args.out), text_to_stderr(args.json):
        res = validate_sensor_model(args.model, args.out, frames=args.frames, seed=args.seed, spec=spec,
                                    progress=not args.no_progress, command=shlex.join(argv))
        print_validation(res)
        print(f"  wrote {Path(args.out) / 'validation.json'}, validation.csv, validation.png")
    emit(res, args.json)
    ok = res["outcomes_within"] and (res["ks_min_p"] is None or res["ks_min_p"] >= 0.01)
    return EXIT_OK if ok else EXIT_NO_SOLUTION


def print_validation(res: dict, file=None) -> None:
    file = sys.stdout if file is None else file
    print(f"{res['camera']}: {res['frames']} held-out rendered frames", file=file)
    for k, v in res["outcomes"].items():
        lo, hi = v["model_interval90"]
        print(f"  {k:>22s}: {v['observed']:4d} rendered, model {v['model_mean']:.1f} (90 %: {lo}-{hi})"
              f"{'' if v['within'] else '  OUTSIDE'}", file=file)
    for k, v in res["errors"].items():
        if "ks_p" not in v:
            print(f"  {k:>10s}: {v['n_rendered']} solved frames, too few to test", file=file)
            continue
        lo, hi = v["scatter_ratio_interval90"]
        print(f"  {k:>10s}: KS p {v['ks_p']:.3f}, scatter x{v['scatter_ratio']:.2f} of the model's (90 %: {lo:.2f}-"
              f"{hi:.2f}), {v['n_rendered']} solved", file=file)
