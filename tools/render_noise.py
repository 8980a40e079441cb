"""How much Monte Carlo noise the guided spot estimator leaves on the spots' positions,
against the sensor's own centroid Cramer-Rao bound (issue 23, deliverable 3).

The scene of the demo (Galaxy Nexus, 10 m, roll 5, pitch -3, yaw 10 deg, the lab's light),
rendered with ``--seeds`` render seeds at each number of guided samples per virtual source
(``svgs_sim.render.constants.DEFAULT_SPOT_SAMPLES`` is the default). For every spot, the centroid of
its samples (their radiance-weighted film position: what the deterministic optics carry to
the image unchanged) is taken per seed; the scatter across seeds is the render's noise on
that spot, px per axis. It is printed beside the frame's centroid CRLB (the shot, read and
quantisation noise of one exposure, ``svgs_sim.sim.crlb``) with their ratio and the render time.

Run: ``.venv/bin/python tools/render_noise.py [--seeds 8] [--samples 65536 262144]``
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

GOAL_RATIO = 1.0 / 3.0


def spot_centroids(points, shape):
    """Radiance-weighted centroid of each spot's samples (spots: connected groups of the
    pixels the samples fall in, 2 px apart at most), sorted by u: ndarray (N, 2), px."""
    from scipy import ndimage

    H, W = shape
    ui = np.clip(np.floor(points.u_px + 0.5).astype(int), 0, W - 1)
    vi = np.clip(np.floor(points.v_px + 0.5).astype(int), 0, H - 1)
    occ = np.zeros((H, W), bool)
    occ[vi, ui] = True
    lab, n = ndimage.label(ndimage.binary_dilation(occ, iterations=2), np.ones((3, 3), int))
    lp = lab[vi, ui]
    w = points.rate_ph_s
    sw = np.bincount(lp, weights=w, minlength=n + 1)[1:]
    su = np.bincount(lp, weights=w * points.u_px, minlength=n + 1)[1:]
    sv = np.bincount(lp, weights=w * points.v_px, minlength=n + 1)[1:]
    keep = sw > 1e-3 * sw.max()  # the retro spots (glints far fainter are left out)
    return np.array(sorted(zip(su[keep] / sw[keep], sv[keep] / sw[keep])))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=8, help="render seeds per sample count (default 8)")
    ap.add_argument("--samples", type=int, nargs="+", default=None,
                    help="guided samples per virtual source to compare (default: the default, 4x and 16x it)")
    ap.add_argument("--range", type=float, default=10.0, dest="range_m", help="range, m (default 10)")
    ap.add_argument("--camera", default="galaxy-nexus", help="phone profile (default galaxy-nexus)")
    ap.add_argument("--sampler", nargs="+", default=None, choices=("sobol", "kronecker", "independent"),
                    help="how the guided samples are placed (svgs_sim.render.spots; default: the renderer's default)")
    args = ap.parse_args(argv)
    from svgs_sim.render import render_flux
    from svgs_sim.render.constants import DEFAULT_SPOT_SAMPLER, DEFAULT_SPOT_SAMPLES
    from svgs_sim.sim.closed_loop import Scenario, expose_and_solve, render_scenario
    from svgs_sim.sim.crlb import centroid_crlb_px
    from svgs_sim.base.profiles import Pattern

    scen = Scenario(camera=args.camera, range_m=args.range_m, roll_deg=5, pitch_deg=-3, yaw_deg=10)
    fr = render_scenario(scen, seed=0)
    ex = fr.exposer()
    row = expose_and_solve(fr, ex, seed=0)
    sol = row["_solution"]
    crlb = centroid_crlb_px(fr, ex, row["_exposure"], [sol.targets_px[i] for i in sol.targets_px])
    crlb_rms = float(np.sqrt(np.mean(crlb**2)))
    camera = scen.camera_profile()
    pattern = Pattern.load(scen.pattern)
    R, t = scen.pose()
    shape = (camera.height, camera.width)
    samples = args.samples or [DEFAULT_SPOT_SAMPLES, 4 * DEFAULT_SPOT_SAMPLES, 16 * DEFAULT_SPOT_SAMPLES]
    print(f"{args.camera}, {args.range_m:g} m, demo pose; {args.seeds} render seeds per row")
    print(f"sensor centroid CRLB (RMS over spots, per axis): {crlb_rms:.5f} px")
    print(f"{'sampler':>12}{'samples/source':>15}{'render s':>10}{'scatter px':>12}{'scatter/CRLB':>14}  goal <= {GOAL_RATIO:.2f}")
    for sampler, n in [(sm, n) for sm in (args.sampler or [DEFAULT_SPOT_SAMPLER]) for n in samples]:
        cents, times = [], []
        render_flux(camera, pattern, R, t, seed=1000, spot_samples=int(n), spot_sampler=sampler,
                    scene_options={"focus_distance_m": float(np.linalg.norm(t))})  # warm-up (kernel)
        for s in range(args.seeds):
            t0 = time.perf_counter()
            res = render_flux(camera, pattern, R, t, seed=s, spot_samples=int(n), spot_sampler=sampler,
                              scene_options={"focus_distance_m": float(np.linalg.norm(t))})
            times.append(time.perf_counter() - t0)
            cents.append(spot_centroids(res.points, shape))
        c = np.array(cents)  # (seeds, spots, 2)
        scatter = float(np.sqrt(np.mean(np.var(c, axis=0, ddof=1))))
        ratio = scatter / crlb_rms
        print(f"{sampler:>12}{n:>15d}{np.median(times):>10.3f}{scatter:>12.5f}{ratio:>14.2f}  {'met' if ratio <= GOAL_RATIO else 'not met'}")


if __name__ == "__main__":
    main()
