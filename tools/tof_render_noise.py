"""How much the ToF render's Monte Carlo noise moves a single frame's pose, against the
sensor's own frame-to-frame noise (issue 23, deliverable 3).

The scene of ``svgs tof render-and-solve --range 5.712`` (EPC660 camera, the eight-marker
target, head-on). Two scatters of a single frame's state, per component:

- *render*: ``--seeds`` render seeds at a given samples-per-pixel, each exposed with the same
  sensor noise draw (seed ``[0, 1]``), so only the render differs;
- *sensor*: one render at the highest spp, ``--frames`` noise draws (what the hardware's own
  shot, read and ambient noise give a single frame).

Their ratio per spp (goal: the render's at most a third of the sensor's), and the render time.

Run: ``.venv/bin/python tools/tof_render_noise.py [--spp 64 256 1024] [--seeds 6] [--frames 40]``
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

KEYS = ("x_m", "y_m", "z_m", "roll_deg", "pitch_deg", "yaw_deg")
GOAL_RATIO = 1.0 / 3.0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spp", type=int, nargs="+", default=[64, 256, 1024], help="samples per pixel to compare")
    ap.add_argument("--seeds", type=int, default=6, help="render seeds per spp (default 6)")
    ap.add_argument("--frames", type=int, default=40, help="sensor noise draws on one render (default 40)")
    ap.add_argument("--range", type=float, default=5.712, dest="range_m", help="range, m (default 5.712)")
    args = ap.parse_args(argv)
    from camera.amcw import TofSensor
    from render.tof.camera import TofRenderer
    from svgs.frames import pose_from_scenario
    from tof import TofPipeline, load_camera, load_target

    camera = load_camera("tof-epc660", render=True)
    target = load_target("tof-8")
    R, t = pose_from_scenario(args.range_m, 0.0, 0.0, 0.0, 0.0, 0.0)
    sensor = TofSensor.from_camera(camera)
    pipe = TofPipeline(camera, target)

    def states(rendered, seed, n):
        out = []
        for fr in sensor.frames(rendered, n, seed):
            res = pipe.process(fr.gray, fr.depth_m)
            if res:
                d = res.state_dict
                out.append([d[k] for k in KEYS])
        return np.array(out).reshape(-1, 6)

    def render(spp, seed):
        r = TofRenderer(camera, target, spp=spp, modulation_frequency_hz=sensor.modulation_frequency_hz)
        t0 = time.perf_counter()
        out = r.render(R, t, seed=seed)
        return out, time.perf_counter() - t0

    top = max(args.spp)
    ref, _ = render(top, 10_000)
    s_sensor = np.std(states(ref, [0, 1], args.frames), axis=0, ddof=1)
    print(f"ToF EPC660, tof-8, {args.range_m:g} m head-on; sensor: {args.frames} noise draws on one {top}-spp render")
    print(f"{'':>10}" + "".join(f"{k:>11}" for k in KEYS))
    print(f"{'sensor':>10}" + "".join(f"{v:>11.4f}" for v in s_sensor))
    for spp in args.spp:
        rows, times = [], []
        for s in range(args.seeds):
            rendered, dt = render(spp, s)
            times.append(dt)
            st = states(rendered, [0, 1], 1)
            if len(st):
                rows.append(st[0])
        s_render = np.std(np.array(rows), axis=0, ddof=1)
        ratio = s_render / s_sensor
        print(f"{'render':>6}{spp:>4d}" + "".join(f"{v:>11.4f}" for v in s_render)
              + f"   ({len(rows)}/{args.seeds} solved, render {np.median(times):.2f} s)")
        worst = float(np.max(ratio))
        print(f"{'ratio':>10}" + "".join(f"{v:>11.2f}" for v in ratio)
              + f"   worst {worst:.2f}: {'met' if worst <= GOAL_RATIO else 'not met'} (goal <= {GOAL_RATIO:.2f})")


if __name__ == "__main__":
    main()
