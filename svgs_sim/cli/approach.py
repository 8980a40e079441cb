"""``svgs approach``: a docking approach simulated frame by frame.

Registered in :data:`svgs_sim.cli.main.COMMANDS`; nothing heavy at module level. Every frame is rendered,
exposed through the phone (its auto-exposure carried over from the previous frame), detected and
solved (:class:`svgs_sim.sim.approach.ApproachSensor`); the run is a resumable study in ``--out``
(:mod:`svgs_sim.studies.approach`): ``measurements.csv``, a video, ``approach.png`` and ``summary.json``.

Exit codes: 0 done (at least one frame solved), 1 no frame solved, 2 bad input (checked before
any rendering: the trajectory file, its poses against the camera's field of view, the frame
count, the output folder, a stored run with other parameters).
"""

from __future__ import annotations

import argparse
import sys

from svgs_sim.cli.exit_codes import EXIT_NO_SOLUTION, EXIT_OK
from svgs_sim.base.errors import InputError, number_items


def _floats(text: str, n: int, flag: str) -> tuple:
    return tuple(number_items(text, flag, count=n))


def register(sub) -> None:
    p = sub.add_parser(
        "approach",
        help="a docking approach frame by frame: measurements against truth, video and error plot",
        description="Simulate the SVGS sensor along an approach: per frame render, expose (the phone's "
        "auto-exposure carried over from the previous frame), detect, identify and solve, with motion blur and "
        "the rolling shutter of the moving target. Either a trajectory file (CSV: t_s and the paper's state "
        "x_m,y_m,z_m,roll_deg,pitch_deg,yaw_deg, or the test stand's rail_m,stage_m,roll_deg,pitch_deg,yaw_deg; "
        "interpolated linearly; on orbit optional columns sun_azimuth_deg,sun_elevation_deg give the sun per row) or a straight approach --from R0 --to R1 --duration S along the boresight. "
        "Writes DIR/measurements.csv (one row per frame: t_s, truth, estimate, error, 1-sigma CRLB, ok, reason, "
        "settings, where the time went), DIR/approach.mp4 (overlays; mp4v, or approach.avi with MJPG), "
        "DIR/approach.png and DIR/summary.json. A killed run continues where it stopped when rerun with the same "
        "arguments. Exit 0 done, 1 no frame solved, 2 bad input.",
    )
    p.add_argument("--camera", default="galaxy-nexus", help="phone camera profile name or .toml path (default galaxy-nexus)")
    p.add_argument("--pattern", default="svgs-3u", help="target pattern name or .toml path (default svgs-3u)")
    p.add_argument("--trajectory", default=None, metavar="FILE.csv", help="trajectory file (instead of --from/--to/--duration; default: none)")
    p.add_argument("--from", dest="from_m", type=float, default=None, help="straight approach: start range, m (no default; with --to, --duration)")
    p.add_argument("--to", dest="to_m", type=float, default=None, help="straight approach: end range, m (no default; with --from, --duration)")
    p.add_argument("--duration", dest="duration_s", type=float, default=None, help="straight approach: duration, s (no default; with --from, --to)")
    p.add_argument("--lateral", default="0,0", metavar="X,Y",
                   help="straight approach: the target's lateral offset at the start, m (right, up; nulled linearly "
                        "by the end; default 0,0)")
    p.add_argument("--attitude", default="0,0,0", metavar="ROLL,PITCH,YAW",
                   help="straight approach: the target's attitude at the start, deg (the paper's angles; nulled "
                        "linearly; default 0,0,0)")
    p.add_argument("--fps", type=float, required=True, help="frames per second of the sensor, Hz; the run renders duration x fps frames, ~0.4-0.9 s each at full "
                        "resolution, ~0.2-0.3 s with --preview")
    p.add_argument("--seed", type=int, default=0, help="seed of every render and noise draw (default 0)")
    p.add_argument("--preview", action="store_true",
                   help="image through the phone's 640 x 480 preview stream (binned sensor) instead of full resolution")
    p.add_argument("--no-motion", action="store_true", help="no motion blur and no rolling shutter (a static target per frame)")
    p.add_argument("--no-crlb", action="store_true", help="skip the per-frame Cramer-Rao bound (about 0.1-0.3 s a frame)")
    p.add_argument("--threshold", default=None,
                   help="detector threshold: 'app' (the app's brightness threshold for the camera, "
                        "assets/app/svgs-app.toml; the default), a level in 8-bit counts, 'auto' or 'otsu'")
    from svgs_sim.sim.scene import add_scene_options  # the scene around the target: --environment, --backdrop-m, --ambient
    from svgs_sim.cli.render import body_args

    add_scene_options(p)
    body_args(p)
    p.add_argument("--out", required=True, help="output folder (a rerun with the same arguments resumes it)")
    p.add_argument("--overlap-render", action=argparse.BooleanOptionalAction, default=True,
                   help="render the next frame in a background thread while the phone model works on this one "
                        "(default on; the same numbers; docs/approach.md#speed)")
    p.add_argument("--no-video", action="store_true",
                   help="write no frame pictures and no video: the fastest run (a little faster than the default "
                        "video); the same numbers (docs/approach.md#speed)")
    p.add_argument("--video-image", choices=("detector", "delivered"), default=None,
                   help="what the video's pictures show: 'detector' (the default): the pixels above the detection "
                        "threshold, the rest black, made without the full image; 'delivered': the whole delivered "
                        "image, which costs the full image every frame (about twice the time; docs/approach.md#speed)")
    p.add_argument("--fast-dark-pixels", action="store_true",
                   help="draw the shot noise of the pixels that cannot reach the detection threshold (away from the "
                        "spots) with a cheaper sampler of the same Poisson law: other noise draws than the default, "
                        "the same statistics; the exact path for a frame mostly bright (docs/performance.md, Issue 40)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object on stdout")
    p.set_defaults(func=cmd_approach)


def config_from_args(args) -> dict:
    """The approach's parameters from ``args`` (the trajectory read and checked; the rest is
    checked by :func:`svgs_sim.studies.approach.check_config` before any work, and the profile's kind by
    :mod:`svgs_sim.cli.validate`)."""
    from svgs_sim.sim.approach import Trajectory
    from svgs_sim.sim.approach.trajectory import SUN_COLUMNS
    from svgs_sim.sim.scene import scene_from_args
    from svgs_sim.studies.approach import make_config

    straight = [a is not None for a in (args.from_m, args.to_m, args.duration_s)]
    if args.trajectory is not None and any(straight):
        raise InputError("--trajectory: give either a trajectory file or --from/--to/--duration, not both")
    if args.trajectory is None and not all(straight):
        raise InputError("--from/--to/--duration: a straight approach needs all three (or give --trajectory FILE)")
    if args.trajectory is not None:
        traj = Trajectory.load(args.trajectory)
    else:
        traj = Trajectory.straight(args.from_m, args.to_m, args.duration_s,
                                   lateral_m=_floats(args.lateral, 2, "--lateral"),
                                   attitude_deg=_floats(args.attitude, 3, "--attitude"))
    scene = scene_from_args(args)
    if traj.sun_deg is not None:  # the file's sun, frame by frame
        if scene.sun_azimuth_deg is not None:
            raise InputError(f"--sun-deg: the trajectory {args.trajectory!r} gives the sun per row ({', '.join(SUN_COLUMNS)}); "
                             "give one or the other")
        if scene.environment != "orbit":
            raise InputError(f"--trajectory {args.trajectory!r}: its columns {', '.join(SUN_COLUMNS)} light the target on "
                             "orbit only (give --environment orbit)")
    from svgs_sim.cli.render import body_options

    return make_config(args.camera, traj, args.fps, seed=args.seed, preview=args.preview, motion=not args.no_motion,
                       crlb=not args.no_crlb, pattern=args.pattern, threshold=args.threshold, scene=scene,
                       body=body_options(args), dark_pixels="fast" if args.fast_dark_pixels else "deferred")


def print_summary(s: dict, file=None) -> None:
    file = sys.stdout if file is None else file  # looked up at call time (--json redirects it)
    print(f"{s['camera']}{' (preview)' if s['preview'] else ''}: {s['solved']}/{s['frames']} frames solved "
          f"({100 * s['solved_fraction']:.0f} %); {s['trajectory']}", file=file)
    if s["failures"]:
        print(f"  failures: {', '.join(f'{k} {v}' for k, v in sorted(s['failures'].items()))}", file=file)
    if s.get("wrong_locks"):
        print(f"  WRONG LOCKS: {s['wrong_locks']} frames reported a pose with a blob off its target's spot", file=file)
    print(f"  {'range bin, m':>14s} {'frames':>6s} {'solved':>6s}" + "".join(
        f" {'rms ' + k:>15s}" for k in ("x_m", "y_m", "z_m", "roll_deg", "pitch_deg", "yaw_deg")), file=file)
    for b in s["rms_by_range"]:
        lo, hi = b["range_m"]
        label = f"{lo:g}-{hi:g}" if hi is not None else f"> {lo:g}"
        vals = "".join(f" {b[f'rms_err_{k}']:15.4f}" if b[f"rms_err_{k}"] is not None else f" {'-':>15s}"
                       for k in ("x_m", "y_m", "z_m", "roll_deg", "pitch_deg", "yaw_deg"))
        print(f"  {label:>14s} {b['frames']:6d} {b['solved']:6d}{vals}", file=file)
    t = s["timing"]
    parts = ", ".join(f"{k[5:-2]} {t[k]:.2f} s" for k in t if k.startswith("mean_") and k != "mean_frame_s" and t[k] is not None)
    print(f"  per frame: {parts}; {t['mean_frame_s']:.2f} s = {t['frames_per_s']:.2f} frames/s on this machine", file=file)
    wpf = s.get("run", {}).get("wall_per_frame_s")
    if wpf:  # what the stages leave out: the background threads' waits, the pictures, the store
        print(f"  wall clock: {wpf:.2f} s a frame after the first ({1 / wpf:.2f} frames/s), "
              f"{s['run']['wall_s']:.1f} s in all", file=file)
    o = s["outputs"]
    print(f"  wrote {o['measurements']}, {o['plot']}, {o['video']} ({o['video_codec']})", file=file)


def _exact(x: float) -> str:
    """A number as the shortest text that reads back to the same float (``30``, ``0.2``)."""
    return str(int(x)) if float(x).is_integer() and abs(x) < 1e15 else repr(float(x))


def command_line(args) -> str:
    """The ``svgs approach`` command line of ``args`` (for the report), the output folder as given."""
    from shlex import quote

    parts = ["svgs approach", f"--camera {quote(args.camera)}"]
    if args.pattern != "svgs-3u":
        parts.append(f"--pattern {quote(args.pattern)}")
    if args.trajectory:
        parts.append(f"--trajectory {quote(args.trajectory)}")
    else:  # repr-exact numbers: the command rebuilds the same study
        parts.append(f"--from {_exact(args.from_m)} --to {_exact(args.to_m)} --duration {_exact(args.duration_s)}")
        if args.lateral != "0,0":
            parts.append(f"--lateral {quote(args.lateral)}")
        if args.attitude != "0,0,0":
            parts.append(f"--attitude {quote(args.attitude)}")
    parts.append(f"--fps {_exact(args.fps)}")
    parts += [f"--seed {args.seed}"] if args.seed else []
    parts += [f for f, on in (("--preview", args.preview), ("--no-motion", args.no_motion), ("--no-crlb", args.no_crlb),
                              ("--fast-dark-pixels", getattr(args, "fast_dark_pixels", False)),
                              ("--no-video", getattr(args, "no_video", False))) if on]
    if getattr(args, "video_image", None) == "delivered":
        parts.append("--video-image delivered")
    if args.threshold not in (None, "app"):
        parts.append(f"--threshold {quote(str(args.threshold))}")
    from svgs_sim.sim.scene import scene_option_words

    parts += scene_option_words(args)
    for flag, v in (("--body", args.body), ("--body-material", args.body_material),
                    ("--body-materials", args.body_materials)):
        if v is not None:
            parts.append(f"{flag} {quote(str(v))}")
    parts.append(f"--out {quote(args.out)}")
    return " ".join(parts)


def cmd_approach(args) -> int:
    from svgs_sim.cli.json_out import emit, text_to_stderr
    from svgs_sim.studies.approach import run_approach

    from svgs_sim.cli.outdir import output_folder

    cfg = config_from_args(args)
    if args.no_video and args.video_image is not None:
        raise InputError(f"--video-image {args.video_image}: there are no pictures with --no-video; give one or the other")
    with output_folder(args.out), text_to_stderr(args.json):  # --out made and probed before any work
        s = run_approach(cfg, args.out, progress=not args.no_progress, command=command_line(args),
                         overlap_render=args.overlap_render, video=not args.no_video,
                         video_image=args.video_image or "detector")
        print_summary(s)
    emit(s, args.json)
    return EXIT_OK if s["solved"] > 0 else EXIT_NO_SOLUTION
