"""``svgs render-and-solve`` and ``svgs range-sweep``: the closed loop from the command line.

No Mitsuba import at module level: the handlers import the renderer when they run.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from svgs_sim.base.image_files import write_image
from svgs_sim.base.limits import check_focus_beyond_focal_length
from svgs_sim.cli.json_out import failures_from_text, run_info
from svgs_sim.cli.solve import json_default

#: (flag, dest, help). ``--x``/``--y`` set the target's lateral offset (Scenario.target_x_m,
#: target_y_m), not the camera position ``x_m``/``y_m`` of the solved state.
POSE_ARGS = (("--x", "target_x_m", "lateral offset of the target origin from the boresight, camera right (m; default 0)"),
             ("--y", "target_y_m", "lateral offset of the target origin from the boresight, camera up (m; default 0)"),
             ("--roll", "roll_deg", "roll, paper x-y-z sequence (deg; default 0)"),
             ("--pitch", "pitch_deg", "pitch (deg; default 0)"),
             ("--yaw", "yaw_deg", "yaw (deg; default 0)"))


def state_line(state: dict) -> str:
    """One line of a paper state (``x_m``... ``yaw_deg``) for the terminal: metres to 0.1 mm, degrees
    to 0.001 deg."""
    return (f"x {state['x_m']:+.4f} y {state['y_m']:+.4f} z {state['z_m']:+.4f} m   roll {state['roll_deg']:+.3f} "
            f"pitch {state['pitch_deg']:+.3f} yaw {state['yaw_deg']:+.3f} deg")


def add_focus_arg(p) -> None:
    """``--focus-m``, shared by ``svgs render`` and ``render-and-solve`` (one focus rule)."""
    p.add_argument("--focus-m", dest="focus_m", type=float, default=None,
                   help="distance the lens is focused at, m (default: the target's distance - the phone's autofocus "
                   "locks on it; svgs render and render-and-solve form the same image)")


def scenario_args(p, with_range=True, with_threshold=True) -> None:
    """The options of a rendered scenario, declared once for ``svgs render``, ``render-and-solve``
    and ``range-sweep``: camera, pattern, range, pose, samples per pixel, the scene
    (:func:`svgs_sim.sim.scene.add_scene_options`), focus, the detector's threshold, a forced
    exposure and the seed; :func:`scenario_from_args` builds the scenario of them."""
    from svgs_sim.sim.scene import add_scene_options  # not at module level: `svgs solve` loads no sim code

    p.add_argument("--camera", required=True, help="camera profile name or .toml path (needs [optics] and [flash])")
    p.add_argument("--pattern", default="svgs-3u", help="target pattern name or .toml path (default svgs-3u)")
    if with_range:
        p.add_argument("--range", dest="range_m", type=float, required=True, help="range along the boresight to the target origin (m)")
    for flag, dest, text in POSE_ARGS:
        p.add_argument(flag, dest=dest, type=float, default=0.0, help=text)
    p.add_argument("--spp", type=int, default=None, help="samples per pixel, full frame (default 4; the background is dark and diffuse)")
    p.add_argument("--roi-spp", type=int, default=None, help="samples per pixel in the windows around the spots "
                   "(default 64, the guided method's; 4096 with svgs render --method path)")
    add_scene_options(p)  # --backdrop-m, --ambient: the scene around the target (svgs_sim.sim.scene)
    add_focus_arg(p)
    if with_threshold:
        p.add_argument("--threshold", default=None, help="detector threshold: 'app' (the app's brightness threshold for the camera, assets/app/svgs-app.toml; the default), a level in image counts, 'auto' or 'otsu'")
    p.add_argument("--exposure-s", type=float, default=None, help="exposure time, s (default: the phone's automatic exposure)")
    p.add_argument("--iso", type=float, default=None, help="ISO, ISO 12232 arithmetic speed (default: the phone's automatic ISO)")
    p.add_argument("--seed", type=int, default=0, help="random seed (render and noise); same seed, same numbers (default 0)")


def scenario_from_args(args, range_m=None):
    """The :class:`svgs_sim.sim.closed_loop.Scenario` of a rendering command's options (the pose,
    the scene, samples per pixel, focus; the stand with ``--mount stand``)."""
    from svgs_sim.sim.closed_loop import Scenario
    from svgs_sim.sim.scene import scene_from_args

    focus = getattr(args, "focus_m", None)
    if focus is not None:  # a thin lens focused inside its focal length forms no real image: refuse before the render
        from svgs_sim.base.profiles import load_camera

        check_focus_beyond_focal_length(focus, load_camera(args.camera).table("optics").focal_length_m, "--focus-m")
    distance = args.range_m if range_m is None else range_m
    # on the test stand (--mount stand) --range is the gimbal's rail position
    where = {"rail_m": distance} if getattr(args, "mount", "target") == "stand" else {"range_m": distance}
    return Scenario(
        camera=args.camera, pattern=args.pattern, **where,
        target_x_m=args.target_x_m, target_y_m=args.target_y_m, roll_deg=args.roll_deg, pitch_deg=args.pitch_deg, yaw_deg=args.yaw_deg,
        scene=scene_from_args(args), spp=args.spp, roi_spp=args.roi_spp,
        focus_distance_m=getattr(args, "focus_m", None),
        **({"mount": args.mount, "stage_m": args.stage_m} if hasattr(args, "mount") else {}),
    )


def _threshold(text):
    from svgs_sim.svgs.detect import parse_threshold

    return parse_threshold(text)


def check_camera_renderable(name):
    """The camera profile ``name``, refused (ProfileError naming the table) without ``[optics]``
    or ``[flash]``, before any heavy import."""
    from svgs_sim.base.profiles import load_camera

    cam = load_camera(name)
    for t in ("optics", "flash"):
        cam.table(t)  # ProfileError naming the missing table
    return cam


def write_outputs(out: Path, frame, row, crlb=None, threshold=None) -> dict:
    """flux.npy, raw.npy, image.png, preview.png, overlay.png, truth.json, solution.json."""
    from svgs_sim.render.api import write_preview

    out.mkdir(parents=True, exist_ok=True)
    ex = row["_exposure"]
    np.save(out / "flux.npy", frame.flux.astype(np.float32))
    np.save(out / "raw.npy", ex.raw_dn.astype(np.float32))
    write_image(out / "image.png", ex.image)
    write_preview(out / "preview.png", frame.flux)
    truth = dict(frame.truth)
    truth["exposure"] = {"exposure_s": ex.exposure_s, "iso": ex.iso, "gain_dn_per_e": ex.gain_dn_per_e,
                         **{k: v for k, v in ex.info.items() if k != "stages"}, "stages": ex.info.get("stages")}
    (out / "truth.json").write_text(json.dumps(truth, indent=1, default=json_default), encoding="utf-8")
    sol = {k: v for k, v in row.items() if not k.startswith("_")}
    (out / "solution.json").write_text(json.dumps(sol, indent=1, default=json_default), encoding="utf-8")
    from svgs_sim.cli.solve import write_solution_overlay

    spots = (crlb or {}).get("per_spot_sigma_px")
    result = row["_solution"]
    title = None
    if result:
        t = row["truth_state"]
        title = (f"SOLVED at {frame.truth.get('range_m', float('nan')):.3g} m: residual {result.residual_rms_px:.3f} px; "
                 f"truth roll/pitch/yaw {t['roll_deg']:+.2f}/{t['pitch_deg']:+.2f}/{t['yaw_deg']:+.2f} deg")
    from svgs_sim.sim.closed_loop import solver_camera

    write_solution_overlay(out / "overlay.png", ex.image, solver_camera(frame.camera, ex.image.shape),
                           frame.pattern, result, threshold,
                           sigma_px=spots, sigma_label="CRLB 1-sigma (the simulated sensor)" if spots else None, title=title,
                           notes=error_notes(row, crlb, frame.truth, frame.pattern))
    return {k: str(out / k) for k in ("flux.npy", "raw.npy", "image.png", "preview.png", "overlay.png", "truth.json",
                                       "solution.json")}


def cmd_render_and_solve(args) -> int:
    from svgs_sim.cli.outdir import output_folder_if

    check_camera_renderable(args.camera)
    scen = scenario_from_args(args)
    thr = _threshold(args.threshold)
    from svgs_sim.cli.render import body_options
    from svgs_sim.sim.closed_loop import RenderOptions

    options = RenderOptions(**body_options(args))  # the body checked before the render
    with output_folder_if(args.out):  # made and probed before the render; removed again if refused
        return _render_and_solve(args, scen, thr, options)


def sun_in_view_note(frame, row: dict) -> dict:
    """On orbit: ``sun_in_view`` (the sun's disk projects into the image), ``saturated_px`` (pixels
    of the delivered image at full scale) and, for a frame without a solution with the sun in view,
    the message extended by why (the sun's glare and blooming; docs/orbit.md). Empty in the lab."""
    sun = frame.truth.get("sun")
    if not sun:
        return {}
    img = row["_exposure"].image
    gray = img if img.ndim == 2 else img.max(axis=2)
    full = np.iinfo(img.dtype).max if np.issubdtype(img.dtype, np.integer) else 1.0  # the image's full scale
    sat = int(np.sum(gray >= full))
    out = {"sun_in_view": bool(sun.get("in_view")), "saturated_px": sat}
    if sun.get("in_view") and not row["ok"]:
        out["message"] = (f"{row['message']}; the sun is in the field of view and {sat} px "
                          f"({100.0 * sat / gray.size:.1f} % of the frame) are at full scale: its glare and blooming "
                          "cover the spots (docs/orbit.md)")
    return out


def _render_and_solve(args, scen, thr, options=None) -> int:
    """``svgs render-and-solve`` once its inputs are checked and ``--out`` is ready."""
    import time

    from svgs_sim.sim.closed_loop import expose_and_solve, render_scenario

    t0 = time.perf_counter()
    from svgs_sim.cli.render import render_cost_warning
    from svgs_sim.render.constants import DEFAULT_ROI_SPP, DEFAULT_SPP

    warn = render_cost_warning(scen.camera.width, scen.camera.height, scen.spp or DEFAULT_SPP,
                               scen.roi_spp or DEFAULT_ROI_SPP, int(scen.pattern.n))
    if warn:
        print(f"svgs render-and-solve: {warn}", file=sys.stderr, flush=True)
    print(f"rendering {scen.camera.name} at {scen.distance_m:g} m (Mitsuba) ...", file=sys.stderr, flush=True)
    from svgs_sim.sim.crlb import frame_crlb
    from svgs_sim.sim import hard_stop

    with hard_stop.scope():  # Ctrl-C stops the render within a second (nothing is written yet)
        frame = render_scenario(scen, seed=args.seed, options=options)
        print(f"  rendered in {time.perf_counter() - t0:.1f} s; exposing (phone camera model) and solving ...",
              file=sys.stderr, flush=True)
        exposer = frame.exposer()
        row = expose_and_solve(frame, exposer, seed=args.seed, threshold=thr, exposure_s=args.exposure_s, iso=args.iso)
        if row["ok"]:
            print("  the Cramer-Rao bound of the simulated sensor ...", file=sys.stderr, flush=True)
        crlb = frame_crlb(frame, exposer, row)
    paths = write_outputs(Path(args.out), frame, row, crlb, thr) if args.out else {}
    from svgs_sim.svgs.pipeline import describe_detector, detector_settings

    out = {k: v for k, v in row.items() if not k.startswith("_")}
    out.update(sun_in_view_note(frame, row))
    out["detector"] = detector_settings(frame.camera, thr)
    out["crlb"] = crlb
    out["render_s"] = frame.render_s
    out["outputs"] = paths
    if args.json:
        print(json.dumps(out, default=json_default))
    else:
        t = row["truth_state"]
        print(f"truth:    {state_line(t)}")
        print(f"exposure: {row['exposure_s'] * 1e3:.3f} ms at ISO {row['iso']:.0f}; blobs found: {row['n_blobs']}")
        print(describe_detector(out["detector"]))
        if row["ok"]:
            print_state_table(row, crlb)
            if row.get("outside_test_envelope"):
                from svgs_sim.svgs.envelope import OUTSIDE_TEST_ENVELOPE_NOTE

                print(f"note: {OUTSIDE_TEST_ENVELOPE_NOTE}")
            note = bound_line(row, crlb, frame.truth, frame.pattern)
            if note:
                print(note)
        else:
            print(f"NO SOLUTION ({row['reason']}): {out['message']}")
        for k, v in paths.items():
            print(f"wrote {v}")
    return 0 if row["ok"] else 1


def _parse_ranges(text) -> list[float]:
    from svgs_sim.cli.validate import parse_range_list

    return parse_range_list(text, "--ranges")


def range_sweep_json(cfg, table, stats, out: Path) -> dict:
    """The object of ``svgs range-sweep --json`` (:data:`svgs_sim.cli.json_out.SCHEMAS`)."""
    from svgs_sim.svgs.frames import STATE_KEYS

    ranges = []
    for d in table:
        fails = failures_from_text(d["failures"])
        ranges.append({"range_m": d["range_m"], "trials": d["trials"], "solved": d["trials"] - sum(fails.values()),
                       "success_rate": d["success_rate"], "failures": fails,
                       **{k: d[k] for k in ("blobs_median", "four_blobs_rate", "merged_rate", "exposure_s", "iso")},
                       "bias": {k: d[f"err_mean_{k}"] for k in STATE_KEYS},
                       "std": {k: d[f"err_std_{k}"] for k in STATE_KEYS}})
    outputs = {"summary_csv": out / "summary.csv", "trials_jsonl": out / "trials.jsonl", "plot": out / "range_sweep.png",
               "overlays": out / "overlays.png",
               "results_csv": out / "results.csv", "summary_json": out / "summary.json"}
    return {"camera": cfg.camera, "pattern": cfg.pattern, "trials_per_pose": cfg.trials, "poses": cfg.poses,
            "ranges": ranges, "outputs": outputs, "run": run_info(stats, cfg.n_trials)}


def cmd_range_sweep(args) -> int:
    from svgs_sim.cli.json_out import emit, text_to_stderr
    from svgs_sim.cli.studies import announce_plan, executor_from_args, print_run_stats
    from svgs_sim.sim.scene import scene_from_args
    from svgs_sim.studies.range_sweep import format_table, make_config, run_range_sweep

    check_camera_renderable(args.camera)
    ranges = _parse_ranges(args.ranges)
    spec = executor_from_args(args)
    scene = {"pattern": args.pattern, "threshold": _threshold(args.threshold), "target_x_m": args.target_x_m,
             "target_y_m": args.target_y_m, "roll_deg": args.roll_deg, "pitch_deg": args.pitch_deg,
             "yaw_deg": args.yaw_deg, "scene": scene_from_args(args), "spp": args.spp, "roi_spp": args.roi_spp,
             "exposure_s": args.exposure_s or None, "iso": args.iso or None}
    cfg = make_config(args.camera, ranges, trials=args.trials, poses=args.poses, jitter_deg=args.jitter_deg,
                      jitter_m=args.jitter_m, seed=args.seed, **scene)
    from svgs_sim.cli.outdir import output_folder

    out = Path(args.out or f"range-sweep-{Path(str(args.camera)).stem}")
    if announce_plan(args, "render", cfg.n_trials, len(cfg.ranges_m) * cfg.poses, spec, manifest=cfg.manifest(),
                     out=out):
        return 0
    with output_folder(out), text_to_stderr(args.json):
        table, stats = run_range_sweep(cfg, out, spec, chunk_size=args.chunk_size, progress=not args.no_progress)
        print("\n".join(format_table(table)))
        print_run_stats(stats)
        print(f"wrote {out / 'summary.csv'}, {out / 'trials.jsonl'}, {out / 'range_sweep.png'}, {out / 'summary.json'} "
              f"(results: {out / 'results.csv'})")
    emit(range_sweep_json(cfg, table, stats, out), args.json, out)
    return 0


def register(sub) -> None:
    from svgs_sim.cli.studies import add_executor_options

    p = sub.add_parser("render-and-solve", help="render a scenario, expose it with the phone model and solve it",
                       description="Render the target under the phone's flash (Mitsuba), expose the flux with the "
                       "phone camera model, run the SVGS detector and solver on the delivered image, and print "
                       "truth, solution and errors (pos_err_vec_m, att_err_vec_deg). Exit 0 solved, 1 no solution, 2 bad input.")
    scenario_args(p)
    from svgs_sim.cli.render import body_args

    body_args(p)
    p.add_argument("--mount", choices=("target", "stand"), default="target",
                   help="what --roll/--pitch/--yaw turn: 'target' (default: the target's attitude in front of the "
                   "camera) or 'stand' (the paper's test stand: the target fixed, the phone turned by the gimbal "
                   "about its pivot - roll and pitch tilt it about its horizontal and vertical axes, yaw turns it about "
                   "the line of sight, as the paper names the attitude; --range is the rail position, no --x/--y)")
    p.add_argument("--stage-m", dest="stage_m", type=float, default=0.0,
                   help="the stand's translation stage along the rail, m (+/-0.15 on the paper's stand; --mount stand; default 0)")
    p.add_argument("--out", default=None, help="write flux.npy, raw.npy, image.png, preview.png, truth.json, solution.json here (default: none, nothing written)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_render_and_solve)

    p = sub.add_parser("range-sweep", help="success rate, blobs and errors versus range",
                       description="At each range, render the scenario (nominal pose, or --poses jittered poses) "
                       "and expose it --trials times (noise draws: render once, expose many); print a table of "
                       "blobs found, success rate, merged-spot failures and errors, and write summary.csv, "
                       "trials.jsonl, range_sweep.png and summary.json. Trials are stored as they finish (results.csv, "
                       "manifest.json): rerunning the same command resumes; other options are refused.")
    scenario_args(p, with_range=False)
    p.add_argument("--ranges", required=True, help="comma-separated ranges in metres, e.g. 1,2,4,6.5,8,10; each costs one render per pose (~1-4 s) "
                   "plus --trials exposures (~0.15-0.35 s each)")
    p.add_argument("--trials", type=int, default=20, help="exposures (noise draws) per rendered pose (default 20)")
    p.add_argument("--poses", type=int, default=1, help="rendered poses per range; beyond the first they are jittered (default 1)")
    p.add_argument("--jitter-deg", type=float, default=1.0, help="attitude jitter of the extra poses, deg (1 sigma; default %(default)s)")
    p.add_argument("--jitter-m", type=float, default=0.01, help="lateral jitter of the extra poses, m (1 sigma; default %(default)s)")
    p.add_argument("--out", default=None, help="output folder (default range-sweep-CAMERA); rerun with the same "
                   "options to resume an interrupted sweep")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout (the table goes to stderr); "
                   "the same object is written to summary.json")
    add_executor_options(p, plan_only=True)
    p.set_defaults(func=cmd_range_sweep)


def print_state_table(row, crlb) -> None:
    """Truth, solution, error and the Cramer-Rao 1-sigma of each state component: an error
    many sigmas wide is bias, one within a sigma or two is noise."""
    from svgs_sim.svgs.frames import STATE_KEYS

    t, s = row["truth_state"], row["state"]
    err = list(row["pos_err_vec_m"]) + list(row["att_err_vec_deg"])
    bound = (crlb or {}).get("crlb_std")
    print(f"{'':10s} {'truth':>10s} {'solved':>10s} {'error':>10s} {'CRLB 1-sigma':>13s} {'error/CRLB':>10s}")
    for k, e in zip(STATE_KEYS, err):
        b = bound[k] if bound else None
        fmt = "{:+10.4f}" if k.endswith("_m") else "{:+10.3f}"
        bs = ("{:13.4f}" if k.endswith("_m") else "{:13.3f}").format(b) if b is not None else f"{'-':>13s}"
        ratio = f"{e / b:+10.1f}" if b else f"{'-':>10s}"
        print(f"{k:10s} {fmt.format(t[k])} {fmt.format(s[k])} {fmt.format(e)} {bs} {ratio}")
    if crlb and crlb.get("centroid_sigma_px") is not None:
        print(f"residual {row['residual_rms_px']:.3f} px; CRLB from the simulated sensor: centroid sigma "
              f"{crlb['centroid_sigma_px']:.4f} px RMS over the spots (shot, read and 8-bit quantisation noise at "
              f"this exposure; saturated pixels carry no information)")
    else:
        print(f"residual {row['residual_rms_px']:.3f} px")
    if row.get("p_value") is not None:
        print(f"consistency: chi2 {row['chi2']:.3g} with {row['chi2_dof']} degrees of freedom, p = {row['p_value']:.2g} "
              "(against the app's stated centroid accuracy, svgs_sim.svgs.app; below its alpha the frame is 'inconsistent')")


def state_errors(row) -> dict:
    """State key -> error (estimate - truth) of a solved row: metres and degrees."""
    from svgs_sim.svgs.frames import STATE_KEYS

    return dict(zip(STATE_KEYS, list(row["pos_err_vec_m"]) + list(row["att_err_vec_deg"])))


def bound_line(row, crlb, truth: dict, pattern) -> str | None:
    """One line when an error of a solved frame is far above its CRLB
    (:data:`svgs_sim.studies.diagnosis.FAR_ABOVE_BOUND`), with the likely why: the head-on glint when the
    renderer sampled a front-face glint for this frame, else a bias the bound does not hold.
    None when every error is within it (or the bound is unknown)."""
    from svgs_sim.studies.diagnosis import bound_note, glint_targets_of_truth

    if not row.get("ok") or not (crlb or {}).get("crlb_std"):
        return None
    return bound_note(state_errors(row), crlb["crlb_std"], glint_targets_of_truth(truth, pattern))


def error_notes(row, crlb, truth: dict, pattern) -> list[str]:
    """The overlay's text panel: per state component the truth, the error against it and
    error/CRLB (tab-separated cells), and :func:`bound_line`; empty for a failure."""
    from svgs_sim.svgs.frames import STATE_KEYS

    if not row.get("ok"):
        return []
    bound = (crlb or {}).get("crlb_std") or {}
    err = state_errors(row)
    lines = ["\t".join(("component", "truth", "error", "CRLB 1-sigma", "error/CRLB"))]
    for k in STATE_KEYS:
        f = "{:+.4f}" if k.endswith("_m") else "{:+.3f}"
        b = bound.get(k)
        lines.append("\t".join((k, f.format(row["truth_state"][k]), f.format(err[k]),
                                 "-" if b is None else f.format(b).lstrip("+"),
                                 f"{err[k] / b:+.1f}" if b else "-")))
    note = bound_line(row, crlb, truth, pattern)
    if note:
        lines.append(note)
    return lines
