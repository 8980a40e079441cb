"""``svgs tof stability`` (the paper's stability runs) and ``svgs tof study`` (the committed report).

Registered in the ``tof`` group of :data:`svgs_sim.cli.main.COMMANDS`; no Mitsuba import at module
level. ``stability`` renders once at a range, draws N noisy frames and prints the paper's
statistics per component beside its Tables 1-3; ``study`` regenerates
``docs/reports/tof_stability.md`` (both ranges, the mechanisms, the accuracy-versus-distance
sweep of the paper's Fig. 14 and the failure modes).

Exit codes: 0 done (at least one frame solved), 1 no frame solved, 2 bad input (checked before
any rendering: range, frames, profiles, output folder).
"""

from __future__ import annotations

import csv
import json
import sys
from pathlib import Path

import numpy as np

from svgs_sim.base.errors import InputError, check_finite
from svgs_sim.base.profile_schema import TOF_MATERIALS
from svgs_sim.tof.camera import DESIGN_RANGE_M

from svgs_sim.cli.exit_codes import EXIT_NO_SOLUTION, EXIT_OK
from svgs_sim.cli.solve import json_default
from svgs_sim.cli.studies import add_executor_options
from svgs_sim.cli.tof_render import add_scene_args

#: Ranges the stability run accepts (m): the paper's design range 0.27-15 m (section 2.2) within
#: the 15 m unambiguous range of the 10 MHz modulation.
RANGE_LIMITS_M = DESIGN_RANGE_M  # svgs_sim.tof.camera: one envelope with --range elsewhere


def _common(p) -> None:
    p.add_argument("--seed", type=int, default=0, help="seed of the render and the frames' noise (default 0)")
    add_scene_args(p)
    p.add_argument("--ambient-lux", type=float, default=None,
                   help="ambient illuminance (default: the profile's 1000 lux, the paper's normal light)")
    p.add_argument("--marker-material", choices=TOF_MATERIALS, default=None,
                   help="marker faces (default: the pattern's, retroreflective sheeting for tof-8)")
    p.add_argument("--sheeting", default=None,
                   help="sheeting table of the retroreflective markers (default: the pattern's, en12899-ra2-white)")


def register(group) -> None:
    """Add ``stability`` and ``study`` to the ``svgs tof`` group's sub-parsers."""
    p = group.add_parser(
        "stability",
        help="the paper's stability run: one render, N noisy frames, statistics beside Tables 1-3",
        description="Render the ToF target once at --range (the paper's average pose at 0.697 and 5.712 m, "
        "head-on elsewhere), draw N noisy frames from it and run them in sequence through the ToF pipeline. "
        "Prints the average, maximum, minimum, fluctuation range (max - min) and standard deviation of each "
        "component in the paper's order - target_x_cam_mm, target_y_cam_mm, target_z_cam_mm (the target's "
        "reference point in the camera frame), roll_deg, pitch_deg, yaw_deg (the state's angles; the paper's "
        "pitch, yaw, roll) - beside the paper's Tables 1-3. Exit 0 done, 1 no frame solved, 2 bad input.",
    )
    p.add_argument("--range", dest="range_m", type=float, required=True,
                   help=f"range to the target, m ({RANGE_LIMITS_M[0]}-{RANGE_LIMITS_M[1]}); 0.697 and 5.712 "
                        "are the paper's")
    p.add_argument("--frames", type=int, default=200, help="noisy frames (default 200; at most 20000, ~50 ms each)")
    _common(p)
    p.add_argument("--persistence", type=int, default=1, metavar="W",
                   help="the pipeline's persistence window: frames averaged (paper section 3.4; default 1)")
    p.add_argument("--max-active-pixels", type=int, default=None, metavar="N",
                   help="cap of the active pixel set, dimmest discarded first (paper section 3.1, N_max; "
                        "default: the pipeline's 12000, which the target never reaches)")
    p.add_argument("--reference", choices=("markers", "plate"), default="markers",
                   help="point reported as x, y, z: the marker faces' centroid (default; tof-8's origin) or the centre of the "
                        "plate's front face")
    p.add_argument("--bounces", type=int, default=1, help="1 = direct returns (default), 2-4 = with multipath")
    p.add_argument("--out", default=None, help="write frames.csv, summary.json and stability.png here (default: none, nothing written)")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=cmd_stability)

    q = group.add_parser(
        "study",
        help="regenerate the ToF report: stability at both ranges, mechanisms, Fig. 14 sweep, failure modes",
        description="The committed ToF report (docs/reports/tof_stability.md): the stability runs at the paper's "
        "two ranges beside Tables 1-3, what moves them (the paper's active-set cap and persistence window, the "
        "marker material, the reference point, ambient light, the recursive median, the centroid weighting, the "
        "integration time), the refinement's stopping rule, a long run at 697 mm, accuracy against distance over "
        "1-10 m (the paper's Fig. 14) and the failure modes (flying pixels, multipath, 10 klux).",
    )
    q.add_argument("--frames", type=int, default=200, help="frames per stability run (default 200, as the issue's acceptance)")
    q.add_argument("--variant-frames", type=int, default=200, help="frames per mechanism run (default 200)")
    q.add_argument("--sweep-frames", type=int, default=40, help="frames per range of the Fig. 14 sweep (default 40)")
    q.add_argument("--long-frames", type=int, default=3000,
                   help="frames of the long run at 697 mm against Table 1's ~6000 s (default 3000; 0 skips it)")
    _common(q)
    q.add_argument("--out", default=None,
                   help=f"folder of tof_stability.md and its figures (default {DEFAULT_STUDY_OUT}, or {DEFAULT_STUDY_OUT}-2, "
                   "-3... when it holds a finished report: a rerun never overwrites one unless --out names it; the "
                   "committed report: --out docs/reports)")
    q.add_argument("--store", default=None, metavar="DIR",
                   help="the study's results store (resumable: a rerun skips the stored frames; default OUT/tof-study)")
    add_executor_options(q)
    q.add_argument("--json", action="store_true", help="print the report's numbers as one JSON object")
    q.set_defaults(func=cmd_study)


def _check_common(args) -> None:
    """What :mod:`svgs_sim.cli.validate` (run before every command) does not check already."""
    if args.sheeting is not None:
        from svgs_sim.render.tof.retro import load_sheeting

        load_sheeting(args.sheeting)


def scene_options(args) -> dict:
    return {k: v for k, v in (("marker_material", args.marker_material), ("sheeting", args.sheeting)) if v is not None}


def check_stability_args(args):
    """Everything checked before rendering; returns the run's :class:`svgs_sim.sim.tof_closed_loop.TofScenario`."""
    from svgs_sim.sim.tof_closed_loop import TofScene, check_in_view
    from svgs_sim.sim.tof_stability import check_frames, stability_scenario

    from svgs_sim.cli.outdir import check_output_folder


    r = check_finite(args.range_m, "--range")
    lo, hi = RANGE_LIMITS_M
    if not lo <= r <= hi:
        raise InputError(f"--range: expected {lo}-{hi} m (the paper's design range, inside the 15 m unambiguous "
                         f"range of the 10 MHz modulation), got {args.range_m!r}")
    check_frames(args.frames)
    _check_common(args)
    if not 1 <= args.bounces <= 4:
        raise InputError(f"--bounces: expected 1..4, got {args.bounces}")
    if args.out:
        check_output_folder(args.out)
    sc = stability_scenario(r, camera=args.camera, pattern=args.pattern, seed=args.seed, spp=args.spp,
                            rim_spp_factor=args.rim_spp_factor, max_bounces=args.bounces,
                            scene=TofScene.from_dict(scene_options(args)), ambient_lux=args.ambient_lux)
    check_in_view(sc)
    return sc


def pipeline_overrides(args) -> dict:
    """``--persistence`` and ``--max-active-pixels`` (:func:`svgs_sim.sim.tof_closed_loop.pipeline_overrides`)."""
    from svgs_sim.sim.tof_closed_loop import pipeline_overrides as overrides

    return overrides(args.persistence, args.max_active_pixels)


def print_summary(s: dict, file=None) -> None:
    """The statistics table beside the paper's (text), on ``file`` (None: the current ``sys.stdout``,
    looked up at the call: a default bound at import kept a stream that may since have closed)."""
    from svgs_sim.sim.tof_stability import COLUMNS

    file = sys.stdout if file is None else file

    w = max(11, max(len(c) for c in COLUMNS) + 2)  # every name with room to spare: the columns stay apart
    print(f"range {s['range_m']:g} m: solved {s['solved']}/{s['frames']} frames; integration time "
          f"{s['integration_time_s'] * 1e6:.2f} us per DCS, brightest amplitude {s['max_amplitude_lsb']:.0f} LSB, "
          f"reference point: {s['reference']}", file=file)
    if s["failures"]:
        print(f"  failures: {s['failures']}", file=file)
    print(" " * 24 + "".join(f"{c:>{w}s}" for c in COLUMNS), file=file)

    def row(label, d):
        print(f"{label:24s}" + "".join(f"{(d[c] if d[c] is not None else float('nan')):{w}.3f}" for c in COLUMNS), file=file)

    row("truth", s["truth"])
    for k in ("average", "maximum", "minimum", "fluctuation", "std"):
        row(f"sim {k}", s[k])
    for tab, stats in s["paper"].items():
        if "fluctuation" in stats:
            row(f"paper T{tab} fluctuation", stats["fluctuation"])
            print(f"{'  ratio sim / T' + tab:24s}" + "".join(
                f"{(v if v is not None else float('nan')):{w}.2f}" for v in s["ratio_to_paper"][tab].values()), file=file)
    if not s["paper"]:
        print("  (no paper figures at this range: the paper's stability runs are at 0.697 and 5.712 m)", file=file)


def write_stability_outputs(out: Path, run: dict, s: dict) -> dict:
    """frames.csv, summary.json and stability.png."""
    from svgs_sim.sim.tof_stability import COLUMNS

    out.mkdir(parents=True, exist_ok=True)
    with open(out / "frames.csv", "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(["frame", "ok", "reason", *COLUMNS])
        for r in run["frame_rows"]:
            w.writerow([r["frame"], int(r["ok"]), r["reason"] or "", *["" if r[c] is None else f"{r[c]:.6f}" for c in COLUMNS]])
    (out / "summary.json").write_text(json.dumps(s, indent=1, default=json_default), encoding="utf-8")
    plot_stability(out / "stability.png", run, s)
    return {"frames": str(out / "frames.csv"), "summary": str(out / "summary.json"), "plot": str(out / "stability.png")}


def plot_stability(path, run: dict, s: dict) -> None:
    """Each component against the frame index, with the paper's fluctuation range drawn about our mean."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from svgs_sim.sim.tof_stability import COLUMNS

    fig, axes = plt.subplots(3, 2, figsize=(10, 7), sharex=True)
    k = np.array([r["frame"] for r in run["frame_rows"] if r["ok"]])
    for i, (ax, c) in enumerate(zip(axes.T.ravel(), COLUMNS)):
        if run["cols"].shape[0]:
            ax.plot(k, run["cols"][:, i], lw=0.6, color="C0", label="simulated")
            ax.axhline(s["truth"][c], color="k", lw=0.8, ls=":", label="truth")
            for j, (tab, stats) in enumerate(s["paper"].items()):
                if "fluctuation" in stats:
                    half = 0.5 * stats["fluctuation"][c]
                    m = s["average"][c]
                    ax.axhspan(m - half, m + half, color=f"C{j + 1}", alpha=0.15,
                               label=f"paper T{tab} fluctuation range (about our mean)")
        ax.set_ylabel(c)
    axes[-1, 0].set_xlabel("frame")
    axes[-1, 1].set_xlabel("frame")
    axes[0, 0].legend(fontsize=7, loc="upper right")
    fig.suptitle(f"svgs tof stability --range {s['range_m']:g}: {s['solved']}/{s['frames']} frames solved")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def cmd_stability(args) -> int:
    from svgs_sim.cli.outdir import output_folder_if

    sc = check_stability_args(args)
    with output_folder_if(args.out):  # made and probed before the render; removed again if refused
        return _stability(args, sc)


def _stability(args, sc) -> int:
    """``svgs tof stability`` once its inputs are checked and ``--out`` is ready."""
    from svgs_sim.sim.tof_closed_loop import render
    from svgs_sim.sim.tof_stability import run_stability, summary
    from svgs_sim.studies.progress import progress_bar

    if not args.json:
        print(f"rendering {sc.camera} / {sc.pattern} at {args.range_m:g} m ...", file=sys.stderr)
    tof_render = render(sc)
    with progress_bar(args.frames, "frames", enabled=not args.json or sys.stderr.isatty(), unit="frame") as bar:
        run = run_stability(tof_render, args.range_m, args.frames, pipeline=pipeline_overrides(args),
                            reference=args.reference, progress=bar.update)
    s = summary(run)
    if args.out:
        s["outputs"] = write_stability_outputs(Path(args.out), run, s)
    if args.json:
        print(json.dumps(s, default=json_default))
    else:
        print_summary(s)
        for v in (s.get("outputs") or {}).values():
            print(f"wrote {v}")
    return EXIT_OK if s["solved"] else EXIT_NO_SOLUTION


#: ``svgs tof study``'s folder when ``--out`` is not given (never docs/reports: the committed report
#: is rewritten only when asked for).
DEFAULT_STUDY_OUT = "tof-study"
#: The file whose presence marks a finished study.
STUDY_REPORT = "tof_stability.md"


def default_study_out(base: str = DEFAULT_STUDY_OUT, *, say: bool = True) -> str:
    """``base``, or the first of ``base-2``, ``base-3``... that holds no finished report
    (:data:`STUDY_REPORT`): an unfinished one is resumed, a finished one is kept. Says on
    stderr when it picks a new name."""
    k, name = 1, base
    while (Path(name) / STUDY_REPORT).exists():
        k += 1
        name = f"{base}-{k}"
    if say and name != base:
        print(f"svgs tof study: {base}/ holds a finished report ({STUDY_REPORT}); writing to {name}/ instead "
              f"(--out {base} rewrites it)", file=sys.stderr)
    return name


def cmd_study(args) -> int:
    from svgs_sim.sim.tof_closed_loop import load_scene
    from svgs_sim.sim.tof_stability import check_frames
    from svgs_sim.studies.tof_study import TofStudyConfig, run_study

    from svgs_sim.cli.outdir import check_output_folder, output_folder, output_folder_if
    from svgs_sim.cli.studies import executor_from_args, warn_processes

    longs = (("--long-frames", args.long_frames),) if args.long_frames else ()
    for flag, v in (("--frames", args.frames), ("--variant-frames", args.variant_frames), ("--sweep-frames", args.sweep_frames),
                    *longs):
        try:
            check_frames(v)
        except InputError as exc:
            raise InputError(str(exc).replace("--frames", flag)) from None
    _check_common(args)
    spec = executor_from_args(args)
    warn_processes(spec)
    out_arg = args.out if args.out is not None else default_study_out()
    if args.store:
        check_output_folder(args.store, "--store")  # at once (the layer checks --out), nothing made
    load_scene(args.camera, args.pattern)  # a bad profile is refused before any work
    cfg = TofStudyConfig(camera=args.camera, pattern=args.pattern, frames=args.frames, variant_frames=args.variant_frames,
                         sweep_frames=args.sweep_frames, long_frames=args.long_frames, seed=args.seed, spp=args.spp,
                         rim_spp_factor=args.rim_spp_factor, ambient_lux=args.ambient_lux,
                         scene=tuple(scene_options(args).items()))
    # both folders made and probed before any work; removed again if the run is refused
    with output_folder(out_arg) as out, output_folder_if(args.store, "--store"):
        res = run_study(cfg, out, spec, store_dir=args.store, chunk_size=args.chunk_size, argv=sys.argv[1:],
                        quiet=args.json or args.no_progress)
    if args.json:
        print(json.dumps(res, default=json_default))
    else:
        for v in res["outputs"].values():
            print(f"wrote {v}")
    return EXIT_OK


if __name__ == "__main__":  # ``python -m svgs_sim.cli.tof_stability ARGS`` = ``svgs tof stability ARGS``
    from svgs_sim.cli.main import main

    raise SystemExit(main(["tof", "stability", *sys.argv[1:]]))
