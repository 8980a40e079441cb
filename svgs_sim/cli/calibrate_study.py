"""``svgs calibrate render-board`` and ``svgs calibrate study`` (issue 5, items 3-4).

Registered in the ``calibrate`` group of :data:`svgs_sim.cli.main.COMMANDS`. Nothing here
imports Mitsuba: the handlers import :mod:`render` when they run. Exit codes: 0 done, 2 bad
input (:class:`svgs_sim.base.errors.InputError`, printed without a traceback by ``svgs_sim.cli.main.main``).
"""

from __future__ import annotations

import shlex
import sys
from pathlib import Path

import numpy as np

from svgs_sim.base.errors import InputError


def register(sub) -> None:
    """Add ``render-board`` and ``study`` to the ``svgs calibrate`` group's sub-parsers."""
    _add_render_board(sub)
    _add_study(sub)


def _board_options(p, required: bool) -> None:
    from svgs_sim.calibration.boards import BOARD_KINDS, DEFAULT_DICTIONARY

    kw = {"required": True} if required else {}
    p.add_argument("--board", choices=BOARD_KINDS, default=None if required else "chessboard", **kw,
                   help="board kind" + ("" if required else " (default chessboard)"))
    p.add_argument("--cols", type=int, default=None if required else 9, **kw,
                   help="features per row: chessboard inner corners, ChArUco squares, circles" + ("" if required else " (default 9)"))
    p.add_argument("--rows", type=int, default=None if required else 6, **kw,
                   help="features per column (as --cols)" + ("" if required else " (default 6)"))
    p.add_argument("--spacing-mm", type=float, default=None if required else 100.0, **kw,
                   help="square side or circle spacing, mm" + ("" if required else " (default 100)"))
    p.add_argument("--marker-mm", type=float, default=None, help="ChArUco marker side, mm (default 0.7 x spacing)")
    p.add_argument("--dictionary", default=DEFAULT_DICTIONARY, help=f"ChArUco dictionary (default {DEFAULT_DICTIONARY})")


def _make_board(args):
    from svgs_sim.calibration.boards import Board

    if args.spacing_mm is None or not np.isfinite(args.spacing_mm) or args.spacing_mm <= 0:
        raise InputError(f"--spacing-mm: expected a positive size in mm, got {args.spacing_mm}")
    if args.marker_mm is not None and not (np.isfinite(args.marker_mm) and args.marker_mm > 0):
        raise InputError(f"--marker-mm: expected a positive size in mm, got {args.marker_mm}")
    return Board(args.board, args.cols, args.rows, args.spacing_mm * 1e-3,
                 marker_m=None if args.marker_mm is None else args.marker_mm * 1e-3, dictionary=args.dictionary)


def _camera(args):
    """The camera profile, resized with --width/--height (the same field of view)."""
    from svgs_sim.base.profiles import load_camera

    cam = load_camera(args.camera)
    if (args.width is None) != (args.height is None):
        raise InputError("--width and --height go together")
    if args.width is not None:
        if args.width < 16 or args.height < 16:
            raise InputError(f"--width/--height: expected at least 16 px, got {args.width} x {args.height}")
        scaled = cam.scaled(args.width, args.height).replace(name=f"{cam.name}-{args.width}x{args.height}")
        warn_non_square(cam, scaled, f"svgs calibrate {getattr(args, 'calibrate_command', '') or 'render-board'}")
        cam = scaled
    return cam


#: Relative change of the pixel aspect (fx / fy) that --width/--height may make without a warning
#: (rounding a size to whole pixels changes it by well under 1 %).
ASPECT_TOLERANCE = 0.01


def warn_non_square(camera, scaled, prog: str, file=None) -> bool:
    """Say on stderr (one line) when a resize changes the pixel aspect ratio fx / fy.

    Parameters
    ----------
    camera, scaled : svgs.Camera
        The profile and the profile resized to ``--width x --height``.
    prog : str
        The command, for the line's prefix.

    Returns
    -------
    bool
        Whether the warning was printed (the aspect moved by more than :data:`ASPECT_TOLERANCE`).
    """
    before, after = camera.fx / camera.fy, scaled.fx / scaled.fy
    if abs(after / before - 1.0) <= ASPECT_TOLERANCE:
        return False
    h_square = camera.height * scaled.width / camera.width
    print(f"{prog}: warning: --width/--height {scaled.width} x {scaled.height} px does not keep the profile's "
          f"{camera.width} x {camera.height} px shape: the pixels become non-square (fx {scaled.fx:.1f} px, fy "
          f"{scaled.fy:.1f} px, fx/fy {after:.3g} instead of {before:.3g}); for square pixels give --height "
          f"{h_square:.0f} with --width {scaled.width}", file=sys.stderr if file is None else file, flush=True)
    return True


def _size_options(p) -> None:
    p.add_argument("--width", type=int, default=None, metavar="W",
                   help="render at this width, px, instead of the profile's (same field of view; with --height; default: the "
                        "profile's)")
    p.add_argument("--height", type=int, default=None, metavar="H", help="render at this height, px (with --width; default: the profile's)")


def _positive_int(v, name):
    if v is None or v < 1:
        raise InputError(f"{name}: expected a positive integer, got {v}")
    return int(v)


# --------------------------------------------------------------------------- render-board
def _add_render_board(sub) -> None:
    from svgs_sim.sim.boards import DEFAULT_BOARD_SPP, DEFAULT_EXPOSURE_FILL

    p = sub.add_parser(
        "render-board",
        help="render a calibration set: board images through Mitsuba and the phone model, with the truth",
        description="Render N images of a calibration board through the camera profile's exact model (focal "
        "lengths, principal point, Brown-Conrady distortion, thin lens) with Mitsuba - a printed board lit by a "
        "room's uniform light in front of a grey wall, at poses covering the field of view - then through the "
        "phone camera model (lens PSF, noise, ADC, tone curve) at a manual exposure that puts the paper at "
        "--exposure-fill of full well. Writes DIR/view_NNN.png, DIR/truth.json (true intrinsics, board poses, "
        "true feature positions, exposures) and DIR/camera_true.toml. Board conventions as 'svgs calibrate board'.",
    )
    p.add_argument("--camera", required=True, help="camera profile name or .toml path (needs [optics])")
    _board_options(p, required=True)
    p.add_argument("--views", required=True, type=int, metavar="N", help="number of views")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--seed", type=int, default=0, help="seed of the poses, renders and noise (default 0)")
    p.add_argument("--spp", type=int, default=DEFAULT_BOARD_SPP, help=f"samples per pixel (default {DEFAULT_BOARD_SPP})")
    p.add_argument("--pinhole", action="store_true", help="pinhole camera (no defocus) instead of the profile's thin lens")
    p.add_argument("--exposure-fill", type=float, default=DEFAULT_EXPOSURE_FILL,
                   help=f"paper level as a fraction of full well (default {DEFAULT_EXPOSURE_FILL})")
    _size_options(p)
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=cmd_render_board)


def cmd_render_board(args) -> int:
    import json

    board = _make_board(args)
    cam = _camera(args)
    n = _positive_int(args.views, "--views")
    spp = _positive_int(args.spp, "--spp")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {str(out)!r} exists and is not a folder")
    if out.is_dir() and (out / "truth.json").exists():
        raise InputError(f"--out {str(out)!r} already holds a rendered set (truth.json); choose an empty folder")
    from svgs_sim.cli.outdir import output_folder
    from svgs_sim.sim.boards import render_board_set

    progress = None if args.json else (lambda s: print(s, file=sys.stderr))
    with output_folder(out):  # made and probed before the renders; removed again if refused
        bs = render_board_set(cam, board, n, seed=args.seed, spp=spp, pinhole=args.pinhole,
                              exposure_fill=args.exposure_fill, out_dir=out, progress=progress)
    c = bs.camera
    if args.json:
        print(json.dumps({"ok": True, "out": str(out), "n_views": len(bs), "board": board.to_json(),
                          "intrinsics": bs.truth["intrinsics"], "distortion": bs.truth["distortion"]}))
    else:
        print(f"rendered {len(bs)} views of {board.describe()} through {c.name!r} into {out}/")
        print(f"true intrinsics ({c.width} x {c.height} px): fx {c.fx:.3f}, fy {c.fy:.3f}, cx {c.cx:.3f}, cy {c.cy:.3f} px; "
              "distortion " + ", ".join(f"{k} {v:+.6g}" for k, v in bs.truth["distortion"].items()))
        print(f"calibrate with: svgs calibrate board {out} --board {board.kind} --cols {board.cols} --rows {board.rows} "
              f"--spacing-mm {board.spacing_m * 1e3:g}")
    return 0


# --------------------------------------------------------------------------- study
def _add_study(sub) -> None:
    from svgs_sim.studies.calibration.common import (
        DEFAULT_FOCAL_EXPOSURES,
        DEFAULT_POSES_PER_RANGE,
        DEFAULT_SUBSETS,
        DEFAULT_TRUE_DIST,
        DEFAULT_TRUE_PP_OFFSET_PX,
        DEFAULT_VIEWS_LIST,
    )

    p = sub.add_parser(
        "study",
        help="calibration studies: convergence of a full calibration, the focal method, pose error from calibration error",
        description="(1) Render a board set and calibrate it from N views for each N (--views-list): errors of "
        "fx, fy, principal point and the mapping over the image against the truth. (2) Render the SVGS target "
        "facing the camera at known ranges and run the paper's focal-length method, with fewer ranges and "
        "added centroid noise. (3) Solve projected centroids with wrong intrinsics - focal length, principal "
        "point, distortion, the focal-only calibration, the full calibrations - and report pose error versus "
        "range (1-40 m), beside the paper's Table 4. The true camera is the profile plus --true-pp-offset-px "
        "and --true-dist (ASSUMED real-lens differences; '0 0' and '0,0,0,0,0' take the profile as the truth). "
        "Writes DIR/report.html (self-contained), CSV tables and summary.json; prints a short summary. The trials of "
        "the three parts run on the executor chosen as for 'svgs campaign' and are stored in DIR/trials/ as they "
        "finish: rerun the same command to resume an interrupted study.",
    )
    p.add_argument("--camera", required=True, help="nominal camera profile (name or .toml path)")
    p.add_argument("--out", default=None, metavar="DIR", help="report folder (default calibration-study-CAMERA)")
    p.add_argument("--views-list", default=",".join(str(v) for v in DEFAULT_VIEWS_LIST), metavar="N1,N2,...",
                   help="numbers of views to calibrate from (default %(default)s); the set has the largest")
    p.add_argument("--seed", type=int, default=0, help="study seed (default 0)")
    _board_options(p, required=False)
    p.add_argument("--subsets", type=int, default=DEFAULT_SUBSETS, help=f"subsets of views per N (default {DEFAULT_SUBSETS})")
    p.add_argument("--spp", type=int, default=16, help="board render samples per pixel (default 16)")
    p.add_argument("--true-pp-offset-px", type=float, nargs=2, default=list(DEFAULT_TRUE_PP_OFFSET_PX),
                   metavar=("DU", "DV"), help="true principal point minus the profile's, px (default %(default)s)")
    p.add_argument("--true-dist", default=",".join(f"{v:g}" for v in DEFAULT_TRUE_DIST), metavar="K1,K2,P1,P2,K3",
                   help="true distortion minus the profile's (default %(default)s)")
    p.add_argument("--focal-ranges", default="1,2,3,4,5,6,7,8,9,10", metavar="R1,R2,...",
                   help="ranges of the focal-method images, m (default %(default)s)")
    p.add_argument("--focal-exposures", type=int, default=DEFAULT_FOCAL_EXPOSURES,
                   help=f"exposures per focal image (default {DEFAULT_FOCAL_EXPOSURES})")
    p.add_argument("--pose-ranges", default="1,2,3,5,7.5,10,15,20,25,30,35,40", metavar="R1,R2,...",
                   help="ranges of the pose-error study, m (default %(default)s)")
    p.add_argument("--poses-per-range", type=int, default=DEFAULT_POSES_PER_RANGE,
                   help=f"poses per range in the pose study (default {DEFAULT_POSES_PER_RANGE})")
    p.add_argument("--pattern", default="svgs-3u", help="target pattern (default svgs-3u)")
    p.add_argument("--geometric", action="store_true",
                   help="no Mitsuba: geometric board images and projected centroids; still minutes with the "
                        "defaults (each of the 40 full-size board views took 5-10 s on a busy 2-core machine); a "
                        "smaller --views-list and --width/--height make a quick look")
    p.add_argument("--cache", default=None, metavar="DIR",
                   help="keep the rendered board set and focal frames here, and reuse them on a rerun (default: none, "
                        "rendered again each run)")
    _size_options(p)
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout (the summary goes to stderr): "
                   "DIR/summary.json")
    from svgs_sim.cli.studies import add_executor_options

    add_executor_options(p, plan_only=True)
    p.set_defaults(func=cmd_study)


def cmd_study(args) -> int:
    import json

    from svgs_sim.cli.json_out import emit, run_info, text_to_stderr
    from svgs_sim.cli.studies import executor_from_args, print_run_stats
    from svgs_sim.studies.calibration import (
        parse_number_list,
        plan_calibration_study,
        run_calibration_study,
        summary_text,
        write_report,
    )

    board = _make_board(args)
    cam = _camera(args)
    views = parse_number_list(args.views_list, "--views-list", integer=True, minimum=3)
    true_dist = parse_number_list(args.true_dist, "--true-dist")
    if len(true_dist) != 5:
        raise InputError(f"--true-dist: expected 5 numbers k1,k2,p1,p2,k3, got {len(true_dist)}")
    focal_ranges = parse_number_list(args.focal_ranges, "--focal-ranges", minimum=0.1)
    pose_ranges = parse_number_list(args.pose_ranges, "--pose-ranges", minimum=0.1)
    subsets = _positive_int(args.subsets, "--subsets")
    exposures = _positive_int(args.focal_exposures, "--focal-exposures")
    ppr = _positive_int(args.poses_per_range, "--poses-per-range")
    spp = _positive_int(args.spp, "--spp")
    from svgs_sim.cli.outdir import output_folder, output_folder_if

    out = Path(args.out or f"calibration-study-{cam.name}")
    cache = Path(args.cache) if args.cache else None
    spec = executor_from_args(args)
    say = lambda s: print(s, file=sys.stderr)
    study = dict(views_list=views, seed=args.seed, board=board, subsets=subsets, spp=spp, geometric=args.geometric,
                 true_pp_offset_px=tuple(args.true_pp_offset_px), true_dist=true_dist, focal_ranges_m=focal_ranges,
                 focal_exposures=exposures, pose_ranges_m=pose_ranges, poses_per_range=ppr, pattern=args.pattern)
    kept = dict(board_set_dir=None if cache is None else cache / "board-set",
                focal_cache=None if cache is None else cache / "focal_frames.npz")
    # the checks and the plan (counts, estimate, warnings) before any work
    plan = plan_calibration_study(cam, out, spec=spec, **kept, **study)
    for line in plan.lines():
        say(line)
    if args.plan_only:
        from svgs_sim.cli.studies import plan_only_checks, print_plan_json

        plan_only_checks(args, spec)
        if args.json:
            print_plan_json(plan.to_json())
        return 0
    # both made and probed before any work; removed again if refused (the study removes its trials then)
    with output_folder(out), output_folder_if(cache, "--cache"):
        res = run_calibration_study(cam, out, **study, **kept, progress=say, spec=spec, chunk_size=args.chunk_size,
                                    show_progress=not args.no_progress)
    command = _study_command(args)
    files = write_report(res, out, command=command)
    with text_to_stderr(args.json):
        print(summary_text(res))
        for part, st in res.run_stats.items():
            print_run_stats(st, label=part)
        if not res.run_stats:
            print_run_stats(None, "report")
        print(f"wrote {files['report']}, {files['summary']} and "
              f"{len([k for k in files if k not in ('report', 'summary')])} CSV tables in {out}/")
    # summary.json (svgs_sim.studies.calibration.report.study_summary), extended with the files and the runs
    summary = json.loads(Path(files["summary"]).read_text())
    summary["outputs"] = files
    summary["run"] = {part: run_info(st, 0) for part, st in res.run_stats.items()}
    emit(summary, args.json, out)
    return 0


def _study_command(args) -> str:
    """The command line that reproduces this study (every option spelled out)."""
    parts = ["svgs", "calibrate", "study", "--camera", args.camera]
    if args.out:
        parts += ["--out", args.out]
    parts += ["--views-list", args.views_list, "--seed", str(args.seed), "--board", args.board, "--cols", str(args.cols),
              "--rows", str(args.rows), "--spacing-mm", f"{args.spacing_mm:g}", "--subsets", str(args.subsets),
              "--spp", str(args.spp), "--true-pp-offset-px", *[f"{v:g}" for v in args.true_pp_offset_px],
              "--true-dist", args.true_dist, "--focal-ranges", args.focal_ranges,
              "--focal-exposures", str(args.focal_exposures), "--pose-ranges", args.pose_ranges,
              "--poses-per-range", str(args.poses_per_range), "--pattern", args.pattern]
    if args.marker_mm is not None:
        parts += ["--marker-mm", f"{args.marker_mm:g}"]
    if args.width is not None:
        parts += ["--width", str(args.width), "--height", str(args.height)]
    if args.geometric:
        parts.append("--geometric")
    from svgs_sim.cli.studies import executor_argv

    return " ".join(shlex.quote(p) for p in parts + executor_argv(args))


__all__ = ["cmd_render_board", "cmd_study", "register"]
