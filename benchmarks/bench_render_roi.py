"""Benchmark (issue 3): region-of-interest speed-up at equal centroid precision.

Two comparisons on the full-resolution Galaxy Nexus frame, 3U target:

1. **ROI versus full frame, brute force** (``method="path"``: the LED as a disk area
   emitter, spots path traced), 5 m. The windows at ``S`` spp estimate each spot pixel
   exactly as a full-frame render at ``S`` spp does (same sampler, same pixel integral;
   ``tests/test_render_scene.py`` checks they agree), so the centroid precision is equal
   by construction; the full frame at ``S`` spp is timed at two low spp and extrapolated
   linearly (its cost is proportional to spp), as rendering 5 Mpx at 4096 spp would take
   hours here.
2. **Guided estimator versus brute-force windows**, 10 m: the centroid scatter over seeds
   of each, and the brute-force spp that would match the guided scatter (scatter ~ 1/sqrt(spp)).

Prints each speed-up; target >= 20x at equal centroid precision.

Run: ``.venv/bin/python benchmarks/bench_render_roi.py [--seeds 6]``
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from svgs_sim.svgs.frames import pose_from_scenario  # noqa: E402


def centroid(flux, c, half=4):
    cu, cv = (int(round(x)) for x in c)
    sub = flux[cv - half:cv + half + 1, cu - half:cu + half + 1].astype(np.float64)
    v, u = np.mgrid[cv - half:cv + half + 1, cu - half:cu + half + 1]
    return np.array([(sub * u).sum() / sub.sum(), (sub * v).sum() / sub.sum()])


def scatter(renderer, pose, seeds, **kw):
    """Per-coordinate centroid scatter (px, pooled over targets) and median time."""
    pred = renderer.predicted_centroids_px(*pose)
    cs, ts = [], []
    renderer.render(*pose, seed=10_000, **kw)  # warm
    for s in range(seeds):
        t0 = time.perf_counter()
        res = renderer.render(*pose, seed=s, **kw)
        ts.append(time.perf_counter() - t0)
        cs.append([centroid(res.flux, p) for p in pred])
    cs = np.array(cs)  # (seeds, targets, 2)
    sd = float(np.sqrt(np.mean(np.var(cs, axis=0, ddof=1))))
    bias = float(np.abs(cs.mean(0) - pred).max())
    return sd, bias, statistics.median(ts)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=6)
    ap.add_argument("--roi-spp", type=int, default=4096)
    args = ap.parse_args(argv)
    from svgs_sim.render import Renderer

    # 1. brute force: windows versus whole frame
    S = args.roi_spp
    rp = Renderer("galaxy-nexus", "svgs-3u", method="path", spp=4, roi_spp=S)
    pose5 = pose_from_scenario(5.0, roll_deg=1.0, pitch_deg=-1.0, yaw_deg=1.0)
    sd_roi5, bias_roi5, t_roi5 = scatter(rp, pose5, args.seeds)
    full_t = {}
    for spp in (4, 16):
        rp.render(*pose5, seed=1, spp=spp, full_frame=True)
        t0 = time.perf_counter()
        rp.render(*pose5, seed=2, spp=spp, full_frame=True)
        full_t[spp] = time.perf_counter() - t0
    slope = (full_t[16] - full_t[4]) / 12.0
    t_full_S = full_t[16] + slope * (S - 16)
    print(f"[1] brute force, 5 m, {S} spp in 32 px windows + 4 spp background tiles: {t_roi5:.2f} s/frame, "
          f"centroid scatter {sd_roi5:.4f} px (bias vs geometric optics {bias_roi5:.4f} px)")
    print(f"    whole frame: {full_t[4]:.2f} s at 4 spp, {full_t[16]:.2f} s at 16 spp -> {t_full_S:.0f} s at {S} spp "
          f"(linear extrapolation); ROI speed-up at equal precision {t_full_S / t_roi5:.0f}x (target >= 20x)")

    # 2. guided versus brute-force windows at 10 m
    pose10 = pose_from_scenario(10.0, roll_deg=1.0, pitch_deg=-1.0, yaw_deg=1.0)
    sd_b, bias_b, t_b = scatter(rp, pose10, args.seeds)
    rg = Renderer("galaxy-nexus", "svgs-3u")
    sd_g, bias_g, t_g = scatter(rg, pose10, args.seeds)
    spp_needed = S * (sd_b / sd_g) ** 2
    t_needed = t_b * spp_needed / S
    print(f"[2] 10 m: brute-force windows at {S} spp: scatter {sd_b:.4f} px, bias {bias_b:.4f} px, {t_b:.2f} s; "
          f"guided (default): scatter {sd_g:.4f} px, bias {bias_g:.4f} px, {t_g:.2f} s")
    print(f"    brute force would need ~{spp_needed:.3g} spp ({t_needed:.0f} s) for the guided scatter: "
          f"speed-up {t_needed / t_g:.0f}x; versus a whole brute-force frame at that spp "
          f"~{(full_t[16] + slope * (spp_needed - 16)) / t_g:.3g}x")


if __name__ == "__main__":
    main()
