"""``svgs render-and-solve`` and ``svgs range-sweep``: the closed loop from the command line.

No Mitsuba import at module level: the handlers import the renderer when they run.
"""

from __future__ import annotations

import csv
import json
import sys
from pathlib import Path

import numpy as np

from svgs.errors import InputError

POSE_ARGS = (("--x", "x_m", "lateral offset of the target origin, right (m)"),
             ("--y", "y_m", "lateral offset of the target origin, up (m)"),
             ("--roll", "roll_deg", "roll, paper x-y-z sequence (deg)"),
             ("--pitch", "pitch_deg", "pitch (deg)"),
             ("--yaw", "yaw_deg", "yaw (deg)"))


def _scene_args(p, with_range=True):
    p.add_argument("--camera", required=True, help="camera profile name or .toml path (needs [optics] and [flash])")
    p.add_argument("--pattern", default="svgs-3u", help="target pattern (default svgs-3u)")
    if with_range:
        p.add_argument("--range", dest="range_m", type=float, required=True, help="range along the boresight to the target origin (m)")
    for flag, dest, text in POSE_ARGS:
        p.add_argument(flag, dest=dest, type=float, default=0.0, help=text)
    p.add_argument("--spp", type=int, default=None, help="samples per pixel, full frame (default: the renderer's)")
    p.add_argument("--roi-spp", type=int, default=None, help="samples per pixel in the spot windows (default: the renderer's)")
    p.add_argument("--backdrop-m", type=float, default=None,
                   help="distance of a grey backdrop behind the target (m; default 3; 0 = none)")
    p.add_argument("--ambient", type=float, default=0.0,
                   help="ambient scene radiance from room lights, W m^-2 sr^-1 in band (default 0: lights off)")
    p.add_argument("--threshold", default=None, help="detector threshold: a level, 'auto' or 'otsu' (default auto)")
    p.add_argument("--exposure-s", type=float, default=None, help="override the phone's exposure time (s)")
    p.add_argument("--iso", type=float, default=None, help="override the phone's ISO")
    p.add_argument("--seed", type=int, default=0, help="random seed (render and noise); same seed, same numbers")


def _scenario(args, range_m=None):
    from sim.closed_loop import DEFAULT_BACKDROP_DISTANCE_M, Scenario

    back = DEFAULT_BACKDROP_DISTANCE_M if args.backdrop_m is None else (None if args.backdrop_m == 0 else args.backdrop_m)
    return Scenario(
        camera=args.camera, pattern=args.pattern, range_m=args.range_m if range_m is None else range_m,
        x_m=args.x_m, y_m=args.y_m, roll_deg=args.roll_deg, pitch_deg=args.pitch_deg, yaw_deg=args.yaw_deg,
        backdrop_distance_m=back, ambient_radiance_w_m2_sr=args.ambient, spp=args.spp, roi_spp=args.roi_spp,
    )


def _threshold(text):
    from cli.solve import parse_threshold

    return parse_threshold(text)


def _check_camera_renderable(name):
    from svgs import Camera

    cam = Camera.load(name)
    for t in ("optics", "flash"):
        cam.table(t)  # ProfileError naming the missing table
    return cam


def write_outputs(out: Path, frame, row) -> dict:
    """flux.npy, raw.npy, image.png, preview.png, truth.json, solution.json."""
    import cv2

    from render.api import write_preview

    out.mkdir(parents=True, exist_ok=True)
    ex = row["_exposure"]
    np.save(out / "flux.npy", frame.flux.astype(np.float32))
    np.save(out / "raw.npy", ex.raw_dn.astype(np.float32))
    cv2.imwrite(str(out / "image.png"), ex.image)
    write_preview(out / "preview.png", frame.flux)
    truth = dict(frame.truth)
    truth["exposure"] = {"exposure_s": ex.exposure_s, "iso": ex.iso, "gain_dn_per_e": ex.gain_dn_per_e,
                         **{k: v for k, v in ex.info.items() if k != "stages"}, "stages": ex.info.get("stages")}
    (out / "truth.json").write_text(json.dumps(truth, indent=1, default=_json_default))
    sol = {k: v for k, v in row.items() if not k.startswith("_")}
    (out / "solution.json").write_text(json.dumps(sol, indent=1, default=_json_default))
    return {k: str(out / k) for k in ("flux.npy", "raw.npy", "image.png", "preview.png", "truth.json", "solution.json")}


def _json_default(o):
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (np.floating, np.integer, np.bool_)):
        return o.item()
    return str(o)


def cmd_render_and_solve(args) -> int:
    from sim.closed_loop import expose_and_solve, render_scenario

    _check_camera_renderable(args.camera)
    scen = _scenario(args)
    thr = _threshold(args.threshold)
    print(f"rendering {scen.camera} at {scen.range_m:g} m ...", file=sys.stderr)
    frame = render_scenario(scen, seed=args.seed)
    row = expose_and_solve(frame, frame.exposer(), seed=args.seed, threshold=thr, exposure_s=args.exposure_s, iso=args.iso)
    paths = write_outputs(Path(args.out), frame, row) if args.out else {}
    out = {k: v for k, v in row.items() if not k.startswith("_")}
    out["render_s"] = frame.render_s
    out["outputs"] = paths
    if args.json:
        print(json.dumps(out, default=_json_default))
    else:
        t = row["truth_state"]
        print(f"truth:    x {t['x_m']:+.4f} y {t['y_m']:+.4f} z {t['z_m']:+.4f} m   "
              f"roll {t['roll_deg']:+.3f} pitch {t['pitch_deg']:+.3f} yaw {t['yaw_deg']:+.3f} deg")
        print(f"exposure: {row['exposure_s'] * 1e3:.3f} ms at ISO {row['iso']:.0f}; blobs found: {row['n_blobs']}")
        if row["ok"]:
            s = row["state"]
            print(f"solution: x {s['x_m']:+.4f} y {s['y_m']:+.4f} z {s['z_m']:+.4f} m   "
                  f"roll {s['roll_deg']:+.3f} pitch {s['pitch_deg']:+.3f} yaw {s['yaw_deg']:+.3f} deg")
            pe, ae = row["pos_err_m"], row["att_err_deg"]
            print(f"errors:   pos_err_m [{pe[0]:+.4f}, {pe[1]:+.4f}, {pe[2]:+.4f}]   "
                  f"att_err_deg [{ae[0]:+.3f}, {ae[1]:+.3f}, {ae[2]:+.3f}]   residual {row['residual_rms_px']:.3f} px")
        else:
            print(f"NO SOLUTION ({row['reason']}): {row['message']}")
        for k, v in paths.items():
            print(f"wrote {v}")
    return 0 if row["ok"] else 1


def _parse_ranges(text) -> list[float]:
    try:
        vals = [float(x) for x in str(text).split(",") if x.strip()]
    except ValueError:
        raise InputError(f"--ranges: expected comma-separated numbers of metres, got {text!r}") from None
    if not vals:
        raise InputError("--ranges: no range given")
    bad = [v for v in vals if not (np.isfinite(v) and v > 0)]
    if bad:
        raise InputError(f"--ranges: ranges must be positive metres, got {bad}")
    return vals


def sweep(camera, ranges, *, trials=20, poses=1, jitter_deg=1.0, jitter_m=0.01, seed=0, threshold=None,
          base=None, progress=True):
    """Range sweep: at each range, ``poses`` renders (nominal pose plus small seeded
    jitter), each exposed ``trials`` times (noise draws). Returns a list of row dicts."""
    from tqdm import tqdm

    from sim.closed_loop import Scenario, expose_and_solve, render_scenario

    base = base or Scenario(camera=camera)
    rows = []
    total = len(ranges) * poses * trials
    bar = tqdm(total=total, desc="range sweep", unit="trial", disable=not progress, file=sys.stderr)
    for ri, rng_m in enumerate(ranges):
        for pk in range(poses):
            g = np.random.default_rng([seed, ri, pk])
            j = g.normal(0, 1, 5) * ([jitter_m] * 2 + [jitter_deg] * 3) if pk > 0 else np.zeros(5)
            scen = base.replace(camera=camera, range_m=rng_m, x_m=base.x_m + j[0], y_m=base.y_m + j[1],
                                roll_deg=base.roll_deg + j[2], pitch_deg=base.pitch_deg + j[3], yaw_deg=base.yaw_deg + j[4])
            frame = render_scenario(scen, seed=int(g.integers(2**31)))
            exposer = frame.exposer()
            for k in range(trials):
                row = expose_and_solve(frame, exposer, seed=int(g.integers(2**31)), threshold=threshold)
                row = {k2: v for k2, v in row.items() if not k2.startswith("_")}
                row.update({"range_m": rng_m, "pose_index": pk, "trial": k})
                rows.append(row)
                bar.update(1)
    bar.close()
    return rows


def summarise(rows) -> list[dict]:
    """Per-range table: blobs, success rate, merged rate, mean and std of errors."""
    out = []
    for r in sorted({row["range_m"] for row in rows}):
        rr = [x for x in rows if x["range_m"] == r]
        ok = [x for x in rr if x["ok"]]
        reasons = {}
        for x in rr:
            if not x["ok"]:
                reasons[x["reason"]] = reasons.get(x["reason"], 0) + 1
        d = {
            "range_m": r, "trials": len(rr),
            "blobs_median": float(np.median([x["n_blobs"] or 0 for x in rr])),
            "four_blobs_rate": float(np.mean([(x["n_blobs"] or 0) == 4 for x in rr])),
            "success_rate": len(ok) / len(rr),
            "merged_rate": reasons.get("merged_spots", 0) / len(rr),
            "failures": ";".join(f"{k}:{v}" for k, v in sorted(reasons.items())),
            "exposure_s": float(np.median([x["exposure_s"] for x in rr])),
            "iso": float(np.median([x["iso"] for x in rr])),
        }
        for name, key, idx in (("x_m", "pos_err_m", 0), ("y_m", "pos_err_m", 1), ("z_m", "pos_err_m", 2),
                               ("roll_deg", "att_err_deg", 0), ("pitch_deg", "att_err_deg", 1), ("yaw_deg", "att_err_deg", 2)):
            v = np.array([x[key][idx] for x in ok]) if ok else np.array([np.nan])
            d[f"err_mean_{name}"] = float(np.mean(v))
            d[f"err_std_{name}"] = float(np.std(v))
        out.append(d)
    return out


def plot_sweep(table, path, title):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    r = [d["range_m"] for d in table]
    fig, ax = plt.subplots(1, 3, figsize=(14, 4))
    ax[0].plot(r, [d["success_rate"] for d in table], "o-", label="solved")
    ax[0].plot(r, [d["merged_rate"] for d in table], "s--", label="failed: merged spots")
    ax[0].set(xlabel="range (m)", ylabel="fraction of trials", ylim=(-0.05, 1.05), title="success")
    ax[0].legend()
    ax[1].plot(r, [d["blobs_median"] for d in table], "o-")
    ax[1].axhline(4, color="grey", lw=0.5)
    ax[1].set(xlabel="range (m)", ylabel="blobs found (median)", title="blobs",
              ylim=(0, max(6.0, max(d["blobs_median"] for d in table) + 1)))
    for name in ("x_m", "y_m", "z_m"):
        ax[2].plot(r, [abs(d[f"err_mean_{name}"]) + d[f"err_std_{name}"] for d in table], "o-", label=f"|mean|+std {name}")
    ax[2].set(xlabel="range (m)", ylabel="position error (m)", title="errors", yscale="log")
    ax[2].legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def cmd_range_sweep(args) -> int:
    _check_camera_renderable(args.camera)
    ranges = _parse_ranges(args.ranges)
    if args.trials < 1 or args.poses < 1:
        raise InputError(f"--trials and --poses must be >= 1, got {args.trials} and {args.poses}")
    args.range_m = ranges[0]
    base = _scenario(args, range_m=ranges[0])
    rows = sweep(args.camera, ranges, trials=args.trials, poses=args.poses, jitter_deg=args.jitter_deg,
                 jitter_m=args.jitter_m, seed=args.seed, threshold=_threshold(args.threshold), base=base)
    table = summarise(rows)
    out = Path(args.out or f"range-sweep-{Path(str(args.camera)).stem}")
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "summary.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(table[0]))
        w.writeheader()
        w.writerows(table)
    with open(out / "trials.jsonl", "w") as fh:
        for row in rows:
            fh.write(json.dumps(row, default=_json_default) + "\n")
    plot_sweep(table, out / "range_sweep.png", f"{args.camera}: range sweep ({args.trials} trials x {args.poses} pose(s) per range)")
    hdr = f"{'range_m':>8} {'blobs':>5} {'4 blobs':>7} {'solved':>6} {'merged':>6} {'exp_ms':>7} {'iso':>5}  err x/y/z (m, mean+-std)        failures"
    print(hdr)
    for d in table:
        errs = " ".join(f"{d[f'err_mean_{n}']:+.3f}+-{d[f'err_std_{n}']:.3f}" for n in ("x_m", "y_m", "z_m"))
        print(f"{d['range_m']:8.2f} {d['blobs_median']:5.1f} {d['four_blobs_rate']:7.2f} {d['success_rate']:6.2f} "
              f"{d['merged_rate']:6.2f} {d['exposure_s'] * 1e3:7.2f} {d['iso']:5.0f}  {errs}  {d['failures']}")
    print(f"wrote {out / 'summary.csv'}, {out / 'trials.jsonl'}, {out / 'range_sweep.png'}")
    return 0


def register(sub) -> None:
    p = sub.add_parser("render-and-solve", help="render a scenario, expose it with the phone model and solve it",
                       description="Render the target under the phone's flash (Mitsuba), expose the flux with the "
                       "phone camera model, run the SVGS detector and solver on the delivered image, and print "
                       "truth, solution and errors (pos_err_m, att_err_deg). Exit 0 solved, 1 no solution, 2 bad input.")
    _scene_args(p)
    p.add_argument("--out", default=None, help="write flux.npy, raw.npy, image.png, preview.png, truth.json, solution.json here")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_render_and_solve)

    p = sub.add_parser("range-sweep", help="success rate, blobs and errors versus range",
                       description="At each range, render the scenario (nominal pose, or --poses jittered poses) "
                       "and expose it --trials times (noise draws: render once, expose many); print a table of "
                       "blobs found, success rate, merged-spot failures and errors, and write summary.csv, "
                       "trials.jsonl and range_sweep.png.")
    _scene_args(p, with_range=False)
    p.add_argument("--ranges", required=True, help="comma-separated ranges in metres, e.g. 1,2,4,6.5,8,10")
    p.add_argument("--trials", type=int, default=20, help="exposures (noise draws) per rendered pose (default 20)")
    p.add_argument("--poses", type=int, default=1, help="rendered poses per range; beyond the first they are jittered (default 1)")
    p.add_argument("--jitter-deg", type=float, default=1.0, help="attitude jitter of the extra poses, deg (1 sigma)")
    p.add_argument("--jitter-m", type=float, default=0.01, help="lateral jitter of the extra poses, m (1 sigma)")
    p.add_argument("--out", default=None, help="output folder (default range-sweep-CAMERA)")
    p.set_defaults(func=cmd_range_sweep)
