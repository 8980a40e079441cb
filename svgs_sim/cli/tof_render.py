"""``svgs tof render-and-solve``: render the ToF camera once, draw N noisy frames, solve each.

Registered in the ``tof`` group of :data:`svgs_sim.cli.main.COMMANDS`. No
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

from svgs_sim.base.errors import InputError, check_finite, check_finite_positive
from svgs_sim.base.image_files import write_image
from svgs_sim.svgs.frames import STATE_KEYS

from svgs_sim.cli.exit_codes import EXIT_NO_SOLUTION, EXIT_OK
from svgs_sim.cli.sim import POSE_ARGS, state_line
from svgs_sim.cli.solve import json_default

#: Frames written by ``--out`` at most (gray.npy / depth.npy stacks).
MAX_SAVED_FRAMES = 200

def add_scene_args(p) -> None:
    """The options of the ToF commands that render: ``--camera``, ``--pattern``, ``--spp`` and
    ``--rim-spp-factor`` (shared with :mod:`svgs_sim.cli.tof_stability`)."""
    p.add_argument("--camera", default="tof-epc660", help="ToF camera profile name or .toml path (default tof-epc660)")
    p.add_argument("--pattern", default="tof-8", help="marker target name or .toml path (default tof-8)")
    p.add_argument("--spp", type=int, default=None,
                   help="samples per pixel of the render (power of two; default 256); the pixels on the marker "
                        "faces' rims get --rim-spp-factor times more")
    p.add_argument("--rim-spp-factor", type=int, default=None,
                   help="factor on --spp for the marker-rim pixels (power of two; default 64, i.e. 16384 samples "
                        "there; 1: the same spp everywhere)")


#: Keys of :func:`frame_statistics`.
FRAME_STATISTICS = ("mean", "std", "min", "max", "fluctuation", "bias", "mean_abs_error", "rms")


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
                   help="range along the boresight to the target frame's origin (tof-8: the marker faces' centroid), m")
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
                        "truth.json, solution.json and preview.png here (default: none, nothing written)")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=cmd_render_and_solve)


def _check_args(args):
    r = check_finite(args.range_m, "--range")
    if r <= 0:
        raise InputError(f"--range: expected a positive distance in metres, got {args.range_m!r}")
    for flag, dest, _ in POSE_ARGS:
        check_finite(getattr(args, dest), flag)
    from svgs_sim.sim.tof_stability import check_frames

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
    """Statistics of the solved states over a run, in the state's units (m, deg).

    Parameters
    ----------
    states : ndarray, shape (K, 6)
        Solved paper states (radians for the angles).
    truth_state : ndarray, shape (6,)

    Returns
    -------
    dict
        ``mean``, ``std``, ``min``, ``max``, ``fluctuation`` (max - min) of the states (angles
        unwrapped next to the truth: the truth plus :func:`svgs_sim.sim.metrics.state_error`), ``bias``
        (mean of the signed errors, = mean - truth), ``mean_abs_error`` and ``rms`` (of the
        errors), each keyed by ``x_m, ..., yaw_deg``; empty dicts when K == 0.
    """
    from svgs_sim.sim.metrics import state_error, state_m_deg

    S = np.asarray(states, float).reshape(-1, 6)
    out = {k: {} for k in FRAME_STATISTICS}
    if S.shape[0] == 0:
        return out
    err = state_error(S, truth_state)  # (K, 6) m, deg; angles wrapped
    V = state_m_deg(truth_state) + err
    stats = {"mean": V.mean(0), "std": V.std(0), "min": V.min(0), "max": V.max(0), "fluctuation": V.max(0) - V.min(0),
             "bias": err.mean(0), "mean_abs_error": np.abs(err).mean(0), "rms": np.sqrt((err**2).mean(0))}
    for name, v in stats.items():
        out[name] = {k: float(x) for k, x in zip(STATE_KEYS, v)}
    return out


def frame_rows(results) -> list:
    """Per frame of :func:`svgs_sim.sim.tof_closed_loop.solve_frames`: ``frame, ok, reason, n_blobs, state``
    (paper keys) or None, ``residual_rms_px`` and the :data:`svgs_sim.sim.metrics.POSE_ERROR_KEYS`."""
    rows = []
    for r in results:
        res = r.solution
        row = {"frame": r.frame, "ok": bool(res), "reason": None if res else res.reason,
               "n_blobs": res.n_blobs if res else res.details.get("n_blobs"),
               "state": res.state_dict if res else None,
               "residual_rms_px": float(res.residual_rms_px) if res else None, **r.errors}
        rows.append(row)
    return rows


def write_preview(path, gray, depth_m) -> None:
    """Gray (square-root scaled) beside depth (near = bright), 8-bit PNG."""
    from svgs_sim.camera.tonemap import depth_stretch, encode_u8, sqrt_stretch

    write_image(path, encode_u8(np.hstack([sqrt_stretch(gray), depth_stretch(depth_m)])))


def scenario_from_args(args):
    """The command's :class:`svgs_sim.sim.tof_closed_loop.TofScenario` (checked: in view, profiles load)."""
    from svgs_sim.sim.tof_closed_loop import TofScenario, check_in_view

    sc = TofScenario(camera=args.camera, pattern=args.pattern, range_m=args.range_m, target_x_m=args.target_x_m,
                     target_y_m=args.target_y_m, roll_deg=args.roll_deg, pitch_deg=args.pitch_deg, yaw_deg=args.yaw_deg,
                     seed=args.seed, spp=args.spp, rim_spp_factor=args.rim_spp_factor, max_bounces=args.bounces,
                     pinhole=args.pinhole, ambient_lux=args.ambient_lux, integration_time_s=args.integration_time_s,
                     modulation_frequency_hz=args.modulation_frequency_hz)
    check_in_view(sc)
    return sc


def cmd_render_and_solve(args) -> int:
    _check_args(args)
    sc = scenario_from_args(args)
    from svgs_sim.cli.outdir import output_folder_if

    with output_folder_if(args.out):  # made and probed before the render; removed again if refused
        return _render_and_solve(args, sc)


def _render_and_solve(args, sc) -> int:
    """``svgs tof render-and-solve`` once its inputs are checked and ``--out`` is ready."""
    from svgs_sim.svgs.frames import state_dict
    from svgs_sim.cli.tof import print_solution, solution_json

    from svgs_sim.sim.metrics import POSE_ERROR_KEYS
    from svgs_sim.sim.tof_closed_loop import pipeline_overrides, render, solve_frames
    from svgs_sim.studies.progress import progress_bar

    if not args.json:
        print(f"rendering {sc.camera} / {sc.pattern} at {args.range_m:g} m ...", file=sys.stderr)
    from svgs_sim.sim import hard_stop

    with hard_stop.scope():  # Ctrl-C stops the render within a second (nothing is written yet)
        tof_render = render(sc)
    sensor, rendered, render_s = tof_render.sensor, tof_render.rendered, tof_render.render_s
    truth_state = tof_render.truth_state
    t0 = time.perf_counter()
    keep = min(args.frames, MAX_SAVED_FRAMES) if args.out else 0
    with progress_bar(args.frames, "frames", enabled=args.frames > 20 and (not args.json or sys.stderr.isatty()),
                      unit="frame") as bar:
        results, kept = solve_frames(tof_render, args.frames, pipeline_overrides(args.persistence), progress=bar.update,
                                     keep_frames=keep)
    frames_s = time.perf_counter() - t0
    rows = frame_rows(results)
    last = results[-1].solution
    states = np.array([r.solution.state for r in results if r.solution]).reshape(-1, 6)
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
        print(f"truth: {state_line(s)}")
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
            fl, me = stats["fluctuation"], stats["bias"]
            print("  over the frames: fluctuation (max - min) " + ", ".join(f"{k} {fl[k]:.4g}" for k in STATE_KEYS))
            print("                   bias (mean error)       " + ", ".join(f"{k} {me[k]:+.4g}" for k in STATE_KEYS))
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
    (out / "truth.json").write_text(json.dumps(rendered.truth, indent=1, default=json_default), encoding="utf-8")
    (out / "solution.json").write_text(json.dumps(summary, indent=1, default=json_default), encoding="utf-8")
    with open(out / "frames.csv", "w", newline="", encoding="utf-8") as fh:
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
