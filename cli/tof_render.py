"""``svgs tof render-and-solve``: render the ToF camera once, draw N noisy frames, solve each.

Registered in the ``tof`` group of :data:`cli.main.COMMANDS`. No
Mitsuba import at module level: the handler imports the renderer when it runs.

Exit codes (as ``svgs solve``): 0 the last frame solved, 1 no solution (reason printed),
2 bad input (negative range, target outside the field of view, unknown profile...).
"""

from __future__ import annotations

import csv
import json
import sys
import time
from pathlib import Path

import numpy as np

from svgs.errors import InputError, check_finite, check_finite_positive
from svgs.frames import STATE_KEYS

from cli.exit_codes import EXIT_NO_SOLUTION, EXIT_OK
from cli.solve import json_default

#: Frames written by ``--out`` at most (gray.npy / depth.npy stacks).
MAX_SAVED_FRAMES = 200

#: (flag, dest, help). ``--x``/``--y`` set the target's lateral offset (not the camera
#: position ``x_m``/``y_m`` of the solved state).
POSE_ARGS = (("--x", "target_x_m", "lateral offset of the target origin from the boresight, camera right (m)"),
             ("--y", "target_y_m", "lateral offset of the target origin from the boresight, camera up (m)"),
             ("--roll", "roll_deg", "roll, paper x-y-z sequence (deg)"),
             ("--pitch", "pitch_deg", "pitch (deg)"),
             ("--yaw", "yaw_deg", "yaw (deg)"))


def add_scene_args(p) -> None:
    """The options of the ToF commands that render: ``--camera``, ``--pattern``, ``--spp`` and
    ``--rim-spp-factor`` (shared with :mod:`cli.tof_stability`)."""
    p.add_argument("--camera", default="tof-epc660", help="ToF camera profile name or .toml path (default tof-epc660)")
    p.add_argument("--pattern", default="tof-8", help="marker target name or .toml path (default tof-8)")
    p.add_argument("--spp", type=int, default=None,
                   help="samples per pixel of the render (power of two; default 256); the pixels on the marker "
                        "faces' rims get --rim-spp-factor times more")
    p.add_argument("--rim-spp-factor", type=int, default=None,
                   help="factor on --spp for the marker-rim pixels (power of two; default 64, i.e. 16384 samples "
                        "there; 1: the same spp everywhere)")


def register(group) -> None:
    """Add ``render-and-solve`` to the ``svgs tof`` group's sub-parsers."""
    p = group.add_parser(
        "render-and-solve",
        help="render the ToF camera (Mitsuba), draw noisy frames and solve them",
        description="Render the marker target seen by the ToF camera once (AMCW phasors per pixel), draw N "
        "noisy 4-tap frames (shot, read and ambient noise), run each gray + depth pair through the ToF "
        "pipeline (one stateful sequence) and print the last frame's solution and errors plus statistics "
        "over the frames. Exit 0 solved, 1 no solution, 2 bad input.",
    )
    p.add_argument("--range", dest="range_m", type=float, required=True,
                   help="range along the boresight to the target origin (plate centre), m")
    for flag, dest, text in POSE_ARGS:
        p.add_argument(flag, dest=dest, type=float, default=0.0, help=text)
    p.add_argument("--frames", type=int, default=1,
                   help="noisy frames drawn from the one render (default 1; at most 20000, ~50 ms each)")
    p.add_argument("--seed", type=int, default=0, help="seed of the render and the noise (default 0)")
    add_scene_args(p)
    p.add_argument("--bounces", type=int, default=1, help="1 = direct returns (default), 2-4 = with multipath")
    p.add_argument("--ambient-lux", type=float, default=None,
                   help="ambient illuminance (default: the profile's, 1000 lux = the paper's normal light)")
    p.add_argument("--integration-time-s", type=float, default=None,
                   help="integration time per depth frame (default: automatic)")
    p.add_argument("--modulation-frequency-hz", type=float, default=None,
                   help="AMCW modulation frequency (default: the profile's)")
    p.add_argument("--persistence", type=int, default=1, metavar="N",
                   help="persistence window of the pipeline in frames (default 1)")
    p.add_argument("--pinhole", action="store_true", help="no defocus blur (trace through the lens centre)")
    p.add_argument("--out", default=None,
                   help=f"write gray.npy, depth.npy (first {MAX_SAVED_FRAMES} frames), rendered.npz, frames.csv, "
                        "truth.json, solution.json and preview.png here")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=cmd_render_and_solve)


def _check_args(args):
    r = check_finite(args.range_m, "--range")
    if r <= 0:
        raise InputError(f"--range: expected a positive distance in metres, got {args.range_m!r}")
    for flag, dest, _ in POSE_ARGS:
        check_finite(getattr(args, dest), flag)
    from sim.tof_stability import check_frames

    check_frames(args.frames)  # 1..20000 (~50 ms each)
    if args.spp is not None and args.spp < 1:
        raise InputError(f"--spp: expected a positive number of samples per pixel, got {args.spp}")
    if not 1 <= args.bounces <= 4:
        raise InputError(f"--bounces: expected 1..4, got {args.bounces}")
    if args.persistence < 1:
        raise InputError(f"--persistence: expected a positive number of frames, got {args.persistence}")
    if args.ambient_lux is not None:
        check_finite_positive(args.ambient_lux, "--ambient-lux", allow_zero=True)
    if args.integration_time_s is not None:
        check_finite_positive(args.integration_time_s, "--integration-time-s")
    if args.modulation_frequency_hz is not None:
        check_finite_positive(args.modulation_frequency_hz, "--modulation-frequency-hz")


def frame_statistics(states, truth_state) -> dict:
    """Statistics of the solved states over a run.

    Parameters
    ----------
    states : ndarray, shape (K, 6)
        Solved paper states (radians for the angles).
    truth_state : ndarray, shape (6,)

    Returns
    -------
    dict
        ``mean``, ``std``, ``min``, ``max``, ``fluctuation`` (max - min) and ``mean_error``
        (mean - truth), each keyed by ``x_m, ..., yaw_deg``; empty dicts when K == 0.
    """
    S = np.asarray(states, float).reshape(-1, 6)
    out = {k: {} for k in ("mean", "std", "min", "max", "fluctuation", "mean_error")}
    if S.shape[0] == 0:
        return out
    tr = np.asarray(truth_state, float).copy()
    S = S.copy()
    S[:, 3:] = tr[3:] + (S[:, 3:] - tr[3:] + np.pi) % (2 * np.pi) - np.pi  # unwrap around the truth
    conv = np.array([1, 1, 1, *([180 / np.pi] * 3)])
    S, tr = S * conv, tr * conv
    stats = {"mean": S.mean(0), "std": S.std(0), "min": S.min(0), "max": S.max(0),
             "fluctuation": S.max(0) - S.min(0), "mean_error": S.mean(0) - tr}
    for name, v in stats.items():
        out[name] = {k: float(x) for k, x in zip(STATE_KEYS, v)}
    return out


def run_frames(rendered, sensor, pipe, n_frames: int, seed, truth_state, keep_frames: int = 0, progress=None):
    """Draw ``n_frames`` noisy frames from one render and solve them in sequence.

    Returns
    -------
    rows : list of dict
        Per frame: ``frame, ok, reason, state (paper keys) or None, residual_rms_px, n_blobs``
        and the :data:`sim.metrics.POSE_ERROR_KEYS` (None when unsolved).
    last : TofSolution or Failure
    kept : list of TofFrame
        The first ``keep_frames`` frames.
    states : ndarray, shape (K, 6)
        Solved states.
    """
    from sim.metrics import no_pose_errors, pose_errors

    rows, kept, states, last = [], [], [], None
    for k, fr in enumerate(sensor.frames(rendered, n_frames, seed)):
        res = pipe.process(fr.gray, fr.depth_m)
        last = res
        row = {"frame": k, "ok": bool(res), "reason": None if res else res.reason,
               "n_blobs": res.n_blobs if res else res.details.get("n_blobs")}
        if res:
            states.append(res.state)
            row.update({"state": res.state_dict, "residual_rms_px": float(res.residual_rms_px),
                        **pose_errors(res.state, truth_state)})
        else:
            row.update({"state": None, "residual_rms_px": None, **no_pose_errors()})
        rows.append(row)
        if k < keep_frames:
            kept.append(fr)
        if progress is not None:
            progress(1)
    return rows, last, kept, np.array(states).reshape(-1, 6)


def write_preview(path, gray, depth_m) -> None:
    """Gray (square-root scaled) beside depth (near = bright), 8-bit PNG."""
    import cv2

    from camera.tonemap import depth_stretch, encode_u8, sqrt_stretch

    cv2.imwrite(str(path), encode_u8(np.hstack([sqrt_stretch(gray), depth_stretch(depth_m)])))


def cmd_render_and_solve(args) -> int:
    from svgs.frames import pose_from_scenario, pose_to_state, state_dict
    from tof import TofPipeline, load_camera, load_target
    from cli.tof import print_solution, solution_json

    from render.tof.camera import check_target_in_view
    from camera.amcw import TofSensor
    from sim.metrics import POSE_ERROR_KEYS

    _check_args(args)
    camera = load_camera(args.camera, render=True)
    target = load_target(args.pattern)
    R, t = pose_from_scenario(args.range_m, args.target_x_m, args.target_y_m, args.roll_deg, args.pitch_deg, args.yaw_deg)
    check_target_in_view(camera, target, R, t)
    sensor = TofSensor.from_camera(camera, ambient_lux=args.ambient_lux, modulation_frequency_hz=args.modulation_frequency_hz,
                                   integration_time_s=args.integration_time_s)
    from render.tof.camera import TofRenderer

    if not args.json:
        print(f"rendering {camera.name} / {target.pattern.name} at {args.range_m:g} m ...", file=sys.stderr)
    t0 = time.perf_counter()
    renderer = TofRenderer(camera, target, spp=args.spp, rim_spp_factor=args.rim_spp_factor, max_bounces=args.bounces,
                           modulation_frequency_hz=sensor.modulation_frequency_hz, pinhole=args.pinhole)
    rendered = renderer.render(R, t, seed=args.seed)
    render_s = time.perf_counter() - t0
    truth_state = pose_to_state(R, t)
    pipe = TofPipeline(camera, target, persistence_window=args.persistence,
                       persistence_min_count=max(1, (args.persistence + 1) // 2))
    t0 = time.perf_counter()
    keep = min(args.frames, MAX_SAVED_FRAMES) if args.out else 0
    from studies.progress import progress_bar

    with progress_bar(args.frames, "frames", enabled=args.frames > 20 and (not args.json or sys.stderr.isatty()),
                      unit="frame") as bar:
        rows, last, kept, states = run_frames(rendered, sensor, pipe, args.frames, [args.seed, 1], truth_state, keep,
                                              progress=bar.update)
    frames_s = time.perf_counter() - t0
    stats = frame_statistics(states, truth_state)
    T = sensor.integration_time_s or sensor.auto_integration_time(rendered)
    out = solution_json(last, args.frames)
    lr = rows[-1]
    out.update({
        "truth_state": state_dict(truth_state),
        **{k: lr[k] for k in POSE_ERROR_KEYS},
        "n_solved": int(states.shape[0]),
        "frame_statistics": stats,
        "integration_time_s": float(T),
        "ambient_lux": sensor.ambient_lux,
        "modulation_frequency_hz": sensor.modulation_frequency_hz,
        "render_s": render_s, "frames_s": frames_s,
        "outputs": {},
    })
    if args.out:
        out["outputs"] = write_outputs(Path(args.out), rendered, kept, rows, out)
    if args.json:
        print(json.dumps(out, default=json_default))
    else:
        s = out["truth_state"]
        print(f"truth: x {s['x_m']:+.4f} y {s['y_m']:+.4f} z {s['z_m']:+.4f} m   roll {s['roll_deg']:+.3f} "
              f"pitch {s['pitch_deg']:+.3f} yaw {s['yaw_deg']:+.3f} deg")
        rr = rendered.truth["render"]
        print(f"render {render_s:.2f} s ({rr['spp']} spp, {rr['rim_spp']} on {rr['rim_pixels']} marker-rim pixels); "
              f"{args.frames} frame(s) at "
              f"{T * 1e3:.3f} ms integration, {sensor.ambient_lux:g} lux ambient; solved {out['n_solved']}/{args.frames}")
        print_solution(last)
        if last:
            pe, ae = out["pos_err_vec_m"], out["att_err_vec_deg"]
            print(f"  errors (last frame): pos_err_vec_m [{pe[0]:+.4f}, {pe[1]:+.4f}, {pe[2]:+.4f}]  "
                  f"att_err_vec_deg [{ae[0]:+.3f}, {ae[1]:+.3f}, {ae[2]:+.3f}]")
        if out["n_solved"] > 1:
            fl, me = stats["fluctuation"], stats["mean_error"]
            print("  over the frames: fluctuation (max - min) " + ", ".join(f"{k} {fl[k]:.4g}" for k in STATE_KEYS))
            print("                   mean error              " + ", ".join(f"{k} {me[k]:+.4g}" for k in STATE_KEYS))
        for v in out["outputs"].values():
            print(f"wrote {v}")
    return EXIT_OK if last else EXIT_NO_SOLUTION


def write_outputs(out: Path, rendered, kept, rows, summary) -> dict:
    """Frames, render, per-frame table, truth and solution into ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    paths = {}
    if kept:
        np.save(out / "gray.npy", np.stack([f.gray for f in kept]))
        np.save(out / "depth.npy", np.stack([f.depth_m for f in kept]))
        write_preview(out / "preview.png", kept[-1].gray, kept[-1].depth_m)
        paths.update(gray=str(out / "gray.npy"), depth=str(out / "depth.npy"), preview=str(out / "preview.png"))
    rendered.save(out / "rendered.npz")
    (out / "truth.json").write_text(json.dumps(rendered.truth, indent=1, default=json_default))
    (out / "solution.json").write_text(json.dumps(summary, indent=1, default=json_default))
    with open(out / "frames.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["frame", "ok", "reason", "n_blobs", *STATE_KEYS, "residual_rms_px", "rot_err_deg"])
        for r in rows:
            st = r["state"] or {}
            w.writerow([r["frame"], int(r["ok"]), r["reason"] or "", r["n_blobs"],
                        *[st.get(k, "") for k in STATE_KEYS], r["residual_rms_px"] if r["residual_rms_px"] is not None else "",
                        r["rot_err_deg"] if r["rot_err_deg"] is not None else ""])
    paths.update(rendered=str(out / "rendered.npz"), truth=str(out / "truth.json"),
                 solution=str(out / "solution.json"), frames=str(out / "frames.csv"))
    return paths
