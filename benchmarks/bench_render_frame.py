"""Benchmark (issue 3): one full-resolution Galaxy Nexus frame at 10 m, warm.

Renders the default scene (3U pattern on its plate, solid N-BK7 cubes, guided method:
background tiles at 4 spp, 32 px windows at 256 spp, 65536 guided samples per spot)
``--frames`` times at slightly different poses (a sweep: parameters updated in place)
after one warm-up frame, and prints the median wall time and its parts. Peer: the same
frame rendered whole (``full_frame=True``) at the same background spp - the naive way.
Target: <= 2 s median on the 2-core development machine.

Run: ``.venv/bin/python benchmarks/bench_render_frame.py [--frames 7]``
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


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=7)
    ap.add_argument("--camera", default="galaxy-nexus")
    ap.add_argument("--range", type=float, default=10.0)
    args = ap.parse_args(argv)
    from svgs_sim.render import Renderer

    t0 = time.perf_counter()
    r = Renderer(args.camera, "svgs-3u")
    t_load = time.perf_counter() - t0
    poses = [pose_from_scenario(args.range, roll_deg=1.0 + 0.1 * k, pitch_deg=-1.0, yaw_deg=0.5 * k) for k in range(args.frames + 1)]
    t0 = time.perf_counter()
    r.render(*poses[0], seed=0)
    t_first = time.perf_counter() - t0
    times, parts = [], []
    for k in range(1, args.frames + 1):
        t0 = time.perf_counter()
        res = r.render(*poses[k], seed=k)
        times.append(time.perf_counter() - t0)
        parts.append(res.timings_s)
    med = statistics.median(times)
    keys = [k for k in parts[0] if isinstance(parts[0][k], float)]
    part_med = {k: statistics.median(p[k] for p in parts) for k in keys}
    # peer: the whole frame at the same background spp
    r.render(*poses[0], seed=0, full_frame=True)
    peer = []
    for k in range(1, 4):
        t0 = time.perf_counter()
        r.render(*poses[k], seed=k, full_frame=True)
        peer.append(time.perf_counter() - t0)
    print(f"{args.camera} {r.camera.width}x{r.camera.height} at {args.range:g} m, variant {r.variant.name}: "
          f"load {t_load:.2f} s, first frame {t_first:.2f} s (compiles)")
    print(f"warm frame: median {med:.3f} s over {len(times)} frames (min {min(times):.3f}, max {max(times):.3f}); "
          f"target <= 2 s: {'met' if med <= 2.0 else 'NOT met'}")
    print("  parts (median): " + ", ".join(f"{k} {v:.3f} s" for k, v in part_med.items()))
    print(f"peer (whole frame at {r.spp} spp + spots): median {statistics.median(peer):.3f} s, "
          f"ratio peer/ours {statistics.median(peer) / med:.1f}x")
    print(f"total flux {res.flux.sum(dtype=np.float64):.4g} photons/s")
    # image formation of the rendered film (once per render): lens PSF on the points and the
    # diffuse light, pixel integration, Bayer mosaic - what Exposer(...) costs before exposing
    from svgs_sim.camera.phone import PhoneCamera

    phone = PhoneCamera(args.camera)
    flux, points = res.film()
    opt = []
    for k in range(3):
        t0 = time.perf_counter()
        phone.optics(flux, points, seed=k)
        opt.append(time.perf_counter() - t0)
    mono = []
    for k in range(3):
        t0 = time.perf_counter()
        phone.optics(flux, points, seed=k, cfa=False)
        mono.append(time.perf_counter() - t0)
    n = 0 if points is None else len(points)
    print(f"optical image ({n} spot samples; Airy PSF by Monte Carlo convolution, pixel integration): "
          f"colour (Bayer, 3 channels) median {statistics.median(opt):.3f} s, mono {statistics.median(mono):.3f} s; "
          f"render + colour optical image {med + statistics.median(opt):.3f} s (target <= 2 s: "
          f"{'met' if med + statistics.median(opt) <= 2.0 else 'NOT met'})")


if __name__ == "__main__":
    main()
