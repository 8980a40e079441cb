"""Benchmark of the ToF renderer (render/tof): render time per pose and spp, and the cost of
drawing one noisy 4-tap frame, at the paper's two stability ranges.

Usage::

    python benchmarks/bench_tof_render.py [--spp 16,64,256] [--frames 50]
"""

from __future__ import annotations

import argparse
import os
import time


from svgs_sim.camera.amcw import TofSensor
from svgs_sim.render.tof import TofRenderer
from svgs_sim.svgs.frames import pose_from_scenario

SCENARIOS = {"697 mm": (0.697, 0.0022, -0.0105, -0.38, -2.65, -2.53),
             "5712 mm": (5.712, 0.0051, -0.0024, 3.82, 1.32, -2.05)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--spp", default="16,64,256")
    ap.add_argument("--frames", type=int, default=50)
    args = ap.parse_args(argv)
    spps = [int(x) for x in args.spp.split(",")]
    t0 = time.perf_counter()
    r = TofRenderer(spp=spps[0])
    print(f"ToF renderer: {r.variant.name}, scene load {time.perf_counter() - t0:.2f} s; load average "
          f"{' '.join(f'{x:.1f}' for x in os.getloadavg())}")
    sensor = TofSensor.from_camera(r.camera)
    for name, sc in SCENARIOS.items():
        R, t = pose_from_scenario(*sc)
        r.render(R, t, spp=spps[0])  # warm-up: kernel compilation
        for spp in spps:
            t0 = time.perf_counter()
            rd = r.render(R, t, spp=spp, seed=1)
            dt = time.perf_counter() - t0
            x0, y0, w, h = rd.truth["render"]["window"]
            print(f"{name}: {spp:4d} spp, window {w}x{h} px: {dt:.2f} s ({w * h * spp / dt / 1e6:.2f} M samples/s)")
        t0 = time.perf_counter()
        for k, _ in enumerate(sensor.frames(rd, args.frames, seed=1)):
            pass
        dt = (time.perf_counter() - t0) / args.frames
        print(f"{name}: one noisy 320x240 frame (4 taps, Poisson + read noise, ADC): {dt * 1e3:.1f} ms")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
