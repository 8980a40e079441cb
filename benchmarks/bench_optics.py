"""Benchmark (issue 23): one rendered frame with the deterministic optics and the analytic
bound against the Monte Carlo optics and bound they replace, measured in the same run.

A warm full-resolution Galaxy Nexus frame at 10 m (the demo's pose): render (Mitsuba, warm),
optics (the lens PSF on the diffuse light and the points, glare, CFA), expose + detect +
identify + solve, and the centroid Cramer-Rao bound. Ours: ``point_method="grid"`` and
``frame_crlb`` analytic; peer: ``point_method="monte-carlo"`` (2^20 PSF draws per channel) and
the bound from Monte Carlo central differences (the path before issue 23). Prints the median
per stage of both, their ratio, the bound each gives, and the goal (a frame within 0.3 s).

Run: ``.venv/bin/python benchmarks/bench_optics.py [--frames 3]``
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

GOAL_FRAME_S = 0.3


def one_frame(scen, seed: int, method: str):
    from svgs_sim.sim.closed_loop import expose_and_solve, render_scenario
    from svgs_sim.sim.crlb import centroid_crlb_px

    t0 = time.perf_counter()
    fr = render_scenario(scen, seed=seed)
    t1 = time.perf_counter()
    fr.phone().point_method = "grid" if method == "analytic" else "monte-carlo"
    ex = fr.exposer()
    t2 = time.perf_counter()
    row = expose_and_solve(fr, ex, seed=seed)
    t3 = time.perf_counter()
    assert row["ok"], row["reason"]
    sol = row["_solution"]
    spots = [sol.targets_px[i] for i in sol.targets_px]
    sig = centroid_crlb_px(fr, ex, row["_exposure"], spots, method=method)
    t4 = time.perf_counter()
    rms = float((sig**2).mean() ** 0.5)
    return {"render": t1 - t0, "optics": t2 - t1, "expose+solve": t3 - t2, "crlb": t4 - t3, "total": t4 - t0,
            "crlb_px": rms}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=3, help="frames timed per path (default 3)")
    args = ap.parse_args(argv)
    from svgs_sim.sim.closed_loop import Scenario

    scen = Scenario(camera="galaxy-nexus", range_m=10.0, roll_deg=5, pitch_deg=-3, yaw_deg=10)
    one_frame(scen, 0, "analytic")  # warm-up: scene build, JIT, kernels
    one_frame(scen, 0, "monte-carlo")
    res = {m: [one_frame(scen, k + 1, m) for k in range(args.frames)] for m in ("analytic", "monte-carlo")}
    med = {m: {k: statistics.median(r[k] for r in rows) for k in rows[0]} for m, rows in res.items()}
    print(f"Galaxy Nexus 2592x1944, 10 m, warm, median of {args.frames} frames per path")
    print(f"{'stage':<14}{'ours (grid, analytic) s':>26}{'peer (Monte Carlo) s':>24}{'peer/ours':>11}")
    for k in ("render", "optics", "expose+solve", "crlb", "total"):
        a, b = med["analytic"][k], med["monte-carlo"][k]
        print(f"{k:<14}{a:>26.3f}{b:>24.3f}{b / a:>11.2f}")
    a, b = med["analytic"]["crlb_px"], med["monte-carlo"]["crlb_px"]
    print(f"centroid CRLB (RMS of the spots), px: ours {a:.5f}, peer {b:.5f}, ratio {a / b:.4f}")
    share = med["analytic"]["crlb"] / med["analytic"]["total"]
    print(f"bound's share of the frame: {share:.1%} (goal <= 10 %: {'met' if share <= 0.10 else 'not met'})")
    tot = med["analytic"]["total"]
    print(f"frame: {tot:.3f} s (goal <= {GOAL_FRAME_S} s: {'met' if tot <= GOAL_FRAME_S else 'not met'})")


if __name__ == "__main__":
    main()
