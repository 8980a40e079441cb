"""How much the ToF render's Monte Carlo noise moves a single frame's pose, against the
sensor's own frame-to-frame noise (issue 23, deliverable 3).

The scene of ``svgs tof render-and-solve --range 5.712`` (EPC660 camera, the eight-marker
target, head-on). Two scatters of a single frame's state, per component:

- *render*: ``--seeds`` render seeds at a given samples-per-pixel, each solved as a noise-free
  frame (the sensor's expected values: only the render differs), and, for comparison, each
  exposed with the same sensor noise draw (seed ``[0, 1]``: the render's change then also moves
  which pixels the noise pushes over the pipeline's thresholds);
- *sensor*: one render at the highest spp, ``--frames`` noise draws, each the first frame of a
  fresh pipeline (what the hardware's own shot, read and ambient noise give a single frame).

The ratio of the noise-free scatter to the sensor's per spp (goal: at most a third), the same
per pixel of the markers in the gray image (the render's scatter across seeds of the expected
image against the sensor's noise), and the render time. The pose scatter of noise-free frames
does not fall as 1/sqrt(spp) at high spp: the pipeline thresholds, so an edge pixel crossing
the threshold moves a centroid by a step (the same happens under the sensor's own noise).

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

    def states(rendered, seed, n, noise=True):
        pipe = TofPipeline(camera, target)  # a fresh pipeline: no state carried between renders
        out = []
        for fr in sensor.frames(rendered, n, seed, noise=noise):
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
    clean_ref = next(sensor.frames(ref, 1, None, noise=False))
    marker = clean_ref.gray > 0.2 * np.nanmax(clean_ref.gray)  # the markers' bright pixels
    noisy = np.array([fr.gray for fr in sensor.frames(ref, args.frames, [99, 1])])
    pix_sensor = np.std(noisy, axis=0, ddof=1)[marker]
    # single frames (each the first of a fresh pipeline, as the render rows), noise seeds [s, 1]
    s_sensor = np.std(np.concatenate([states(ref, [s, 1], 1) for s in range(args.frames)]), axis=0, ddof=1)
    print(f"ToF EPC660, tof-8, {args.range_m:g} m head-on; sensor: {args.frames} single-frame noise draws on one {top}-spp render")
    print(f"{'':>10}" + "".join(f"{k:>11}" for k in KEYS))
    print(f"{'sensor':>10}" + "".join(f"{v:>11.4f}" for v in s_sensor))
    for spp in args.spp:
        rows, times = [], []
        clean, grays = [], []
        for s in range(args.seeds):
            rendered, dt = render(spp, s)
            times.append(dt)
            grays.append(next(sensor.frames(rendered, 1, None, noise=False)).gray)
            st = states(rendered, [0, 1], 1)
            if len(st):
                rows.append(st[0])
            st = states(rendered, None, 1, noise=False)
            if len(st):
                clean.append(st[0])
        s_render = np.std(np.array(rows), axis=0, ddof=1)
        s_clean = np.std(np.array(clean), axis=0, ddof=1)
        print(f"{'render':>6}{spp:>4d}" + "".join(f"{v:>11.4f}" for v in s_render)
              + f"   same noise draw ({len(rows)}/{args.seeds} solved, render {np.median(times):.2f} s)")
        print(f"{'':>10}" + "".join(f"{v:>11.4f}" for v in s_clean) + f"   noise-free frames ({len(clean)} solved)")
        pix_render = np.std(np.array(grays), axis=0, ddof=1)[marker]
        print(f"{'':>10}  per marker pixel (gray): render noise / sensor noise, median "
              f"{np.median(pix_render / pix_sensor):.3f}, 90th percentile {np.percentile(pix_render / pix_sensor, 90):.3f}"
              f" ({marker.sum()} pixels)")
        ratio = s_clean / s_sensor
        worst = float(np.max(ratio))
        print(f"{'ratio':>10}" + "".join(f"{v:>11.2f}" for v in ratio)
              + f"   noise-free / sensor, worst {worst:.2f}: {'met' if worst <= GOAL_RATIO else 'not met'} "
              f"(goal <= {GOAL_RATIO:.2f})")


if __name__ == "__main__":
    main()
