"""Benchmark (issue 2a): collinearity solver latency and batched throughput against OpenCV.

Peer: OpenCV ``solvePnP(SOLVEPNP_AP3P)`` followed by ``solvePnPRefineLM``, called once per
frame (the standard way to get a maximum-likelihood P4P pose from OpenCV), on the same noisy
centroids. Prints our figure, the peer's, and the ratio. Target: batched throughput >= 10x
OpenCV's per-call throughput.

Run: ``.venv/bin/python benchmarks/bench_solver.py [--frames 100000]``
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from svgs_sim.svgs import Camera, Pattern, solve_centroids  # noqa: E402
from svgs_sim.svgs.frames import pose_from_scenario, sample_envelope_scenario  # noqa: E402


def envelope_points(n, seed, cam, pat, sigma_px=0.1):
    rng = np.random.default_rng(seed)
    Rs, ts = [], []
    for _ in range(n):
        R, t = pose_from_scenario(**sample_envelope_scenario(rng))
        Rs.append(R)
        ts.append(t)
    uv = cam.project_target(pat.points_m, np.array(Rs), np.array(ts))
    return uv + rng.normal(0, sigma_px, uv.shape)


def opencv_solve(pat, cam, pts):
    ok, rv, tv = cv2.solvePnP(pat.points_m, pts, cam.K, cam.dist, flags=cv2.SOLVEPNP_AP3P)
    return cv2.solvePnPRefineLM(pat.points_m, pts, cam.K, cam.dist, rv, tv)


def run(cam, pat, args, label):
    """Single-frame latency and batched throughput, ours against OpenCV's, on one camera."""
    pts = envelope_points(args.frames, 0, cam, pat)
    ours, peer = [], []
    for k in range(args.single):
        t0 = time.perf_counter()
        solve_centroids(pts[k], cam, pat)
        t1 = time.perf_counter()
        opencv_solve(pat, cam, pts[k])
        t2 = time.perf_counter()
        ours.append(t1 - t0)
        peer.append(t2 - t1)
    lat_ours, lat_peer = statistics.median(ours) * 1e6, statistics.median(peer) * 1e6
    solve_centroids(pts[: args.chunk], cam, pat)  # warm-up
    t0 = time.perf_counter()
    n_ok = 0
    for a in range(0, args.frames, args.chunk):
        n_ok += int(solve_centroids(pts[a : a + args.chunk], cam, pat).ok.sum())
    t_batch = time.perf_counter() - t0
    n_peer = min(args.frames, 20_000)
    t0 = time.perf_counter()
    for k in range(n_peer):
        opencv_solve(pat, cam, pts[k])
    t_peer = time.perf_counter() - t0
    thr_ours, thr_peer = args.frames / t_batch, n_peer / t_peer
    print(f"[{label}] single-frame latency (median of {args.single}): ours {lat_ours:.1f} us, "
          f"OpenCV AP3P+RefineLM {lat_peer:.1f} us, ratio ours/peer {lat_ours / lat_peer:.2f} (target <= 1)")
    print(f"[{label}] batched throughput ({args.frames} frames, chunks of {args.chunk}, {n_ok} solved): ours "
          f"{thr_ours:,.0f} frames/s, OpenCV per call {thr_peer:,.0f} frames/s, ratio {thr_ours / thr_peer:.1f}x "
          "(target >= 10x)")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=100_000, help="frames in the batched run (default 1e5)")
    ap.add_argument("--single", type=int, default=2000, help="frames timed one call at a time (default 2000)")
    ap.add_argument("--chunk", type=int, default=8192, help="batch chunk size (default 8192)")
    args = ap.parse_args(argv)
    cam, pat = Camera.load("galaxy-nexus"), Pattern.load("svgs-3u")
    run(cam, pat, args, "galaxy-nexus, no distortion")
    # the same camera with the Brown-Conrady terms of a typical phone lens (k1-k3 and tangential)
    dcam = cam.replace(dist=np.array([0.08, -0.21, 4e-4, -3e-4, 0.12]))
    run(dcam, pat, args, "galaxy-nexus with k1..k3, p1, p2")


if __name__ == "__main__":
    main()
