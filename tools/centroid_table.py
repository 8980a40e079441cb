"""What a better centroid buys: the paper's blob centroid against the other rules, on both phones.

For each phone and range the target is rendered once (Mitsuba, the stand's attitude 0.5 deg off
the exact facing), exposed ``--exposures`` times through the phone model (its own exposure), and
every exposure is detected at the app's threshold with each centroid rule
(:data:`svgs_sim.svgs.app.CENTROIDS`), identified and solved. Per rule and range it prints

- the solved fraction (consistent solutions) and the failures,
- the mean |x| and |pitch| errors against the truth (the pose the image was made at),
- the centroids' RMS error against the targets' true projections, px (the rendered cubes' apparent
  centres sit a few px from the pattern points at 1 m, ~12/R px, which every rule shares),
- the centroids' scatter over the noise draws, px (RMS over targets and axes of each target's
  standard deviation), and the CRLB efficiency ``CRLB^2 / scatter^2`` (1: the bound is reached)
  with the simulated sensor's bound at the true positions (:func:`svgs_sim.sim.crlb.centroid_crlb_px`).

Usage::

    python tools/centroid_table.py [--exposures 8] [--out docs/centroid_rules.md]

Writes a markdown table (stdout, or ``--out``).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

RANGES = {"htc-amaze-4g": (1.0, 2.0, 4.0, 6.5), "galaxy-nexus": (5.0, 10.0, 20.0, 30.0)}


def measure(camera: str, range_m: float, exposures: int, seed: int = 0) -> list[dict]:
    from svgs_sim.sim.closed_loop import Scenario, render_scenario, solver_camera
    from svgs_sim.sim.crlb import centroid_crlb_px
    from svgs_sim.svgs.app import CENTROIDS
    from svgs_sim.svgs.detect import detect_blobs
    from svgs_sim.svgs.frames import pose_to_state
    from svgs_sim.svgs.pipeline import camera_threshold, solve_image
    from svgs_sim.base.profiles import Pattern

    sc = Scenario(camera=camera, range_m=range_m, roll_deg=0.5, pitch_deg=0.5)
    frame = render_scenario(sc, seed=seed)
    exposer = frame.exposer()
    pat = Pattern.load(sc.pattern)
    R, t = sc.pose()
    truth = pose_to_state(R, t)
    per = {c: {"ok": 0, "fail": {}, "err": [], "cen": []} for c in CENTROIDS}
    crlb = None
    for e in range(exposures):
        ex = exposer.expose(seed=seed * 1000 + e)
        cam = solver_camera(frame.camera, ex.image.shape)
        uv = cam.project_target(pat.points_m, R, t)
        if crlb is None:
            s = centroid_crlb_px(frame, exposer, ex, uv)
            crlb = float(np.sqrt(np.mean(s[np.isfinite(s)] ** 2))) if np.isfinite(s).any() else float("nan")
        thr = camera_threshold(ex.image, cam)
        for c in CENTROIDS:
            b = detect_blobs(ex.image, threshold=thr, centroid=c)
            sol = solve_image(ex.image, cam, pat, blobs=b)
            d = per[c]
            if sol:
                d["ok"] += 1
                err = sol.state - truth
                d["err"].append([err[0], np.degrees(err[4])])
                d["cen"].append(np.array([sol.targets_px[i] for i in pat.ids]) - uv)
            else:
                d["fail"][sol.reason] = d["fail"].get(sol.reason, 0) + 1
    rows = []
    for c in CENTROIDS:
        d = per[c]
        err = np.array(d["err"]) if d["err"] else np.full((1, 2), np.nan)
        cen = np.array(d["cen"]) if d["cen"] else np.full((1, 4, 2), np.nan)
        scatter = float(np.sqrt(np.mean(np.std(cen, axis=0) ** 2))) if len(d["cen"]) > 1 else float("nan")
        rows.append({"camera": camera, "range_m": range_m, "centroid": c, "solved": f"{d['ok']}/{exposures}",
                     "failures": ", ".join(f"{k}: {v}" for k, v in d["fail"].items()) or "-",
                     "mean_abs_x_m": float(np.mean(np.abs(err[:, 0]))),
                     "mean_abs_pitch_deg": float(np.mean(np.abs(err[:, 1]))),
                     "centroid_rms_px": float(np.sqrt(np.nanmean(np.sum(cen ** 2, axis=-1)))),
                     "scatter_px": scatter, "crlb_px": crlb,
                     "efficiency": crlb ** 2 / scatter ** 2 if scatter > 0 else float("nan")})
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--exposures", type=int, default=8, help="noise draws per render (default 8)")
    ap.add_argument("--out", default=None, help="write the markdown table here")
    args = ap.parse_args(argv)
    if args.exposures < 2:
        print("--exposures: at least 2 (the scatter needs two draws)", file=sys.stderr)
        return 2
    t0 = time.perf_counter()
    rows = []
    for cam, ranges in RANGES.items():
        for r in ranges:
            print(f"{cam} at {r:g} m ...", file=sys.stderr, flush=True)
            rows += measure(cam, r, args.exposures)
    head = ("| phone | range m | centroid | solved | failures | mean abs x m | mean abs pitch deg | centroid RMS err px "
            "| scatter px | CRLB px | CRLB efficiency |")
    lines = [head, "|" + "---|" * 11]
    for d in rows:
        lines.append(f"| {d['camera']} | {d['range_m']:g} | {d['centroid']} | {d['solved']} | {d['failures']} | "
                     f"{d['mean_abs_x_m']:.3f} | {d['mean_abs_pitch_deg']:.2f} | {d['centroid_rms_px']:.2f} | "
                     f"{d['scatter_px']:.4f} | {d['crlb_px']:.4f} | {d['efficiency']:.2f} |")
    text = "\n".join(lines) + "\n"
    text += (f"\n{args.exposures} noise draws per render, the stand 0.5 deg off the exact facing; "
             f"`python tools/centroid_table.py --exposures {args.exposures}` ({time.perf_counter() - t0:.0f} s).\n")
    if args.out:
        Path(args.out).write_text(text)
        print(f"wrote {args.out}", file=sys.stderr)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
