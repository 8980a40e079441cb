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

``--sampler`` picks the renderer's sample generator (``sobol``, the default, or the earlier
``r2``) and ``--rim-spp-factor`` the factor on ``--spp`` for the pixels on the marker rims
(default the renderer's; 1: uniform), for the before/after comparison (:mod:`svgs_sim.render.tof.camera`).
``--spp`` is the samples per pixel of the traced box (the rim pixels get the factor times more);
the sensor's reference render is the last ``--spp`` entry with a 4x larger factor.

Run: ``.venv/bin/python tools/tof_render_noise.py [--spp 64 256] [--rim-spp-factor 64] [--seeds 6]
[--frames 40] [--range 5.712] [--sampler sobol]``; before issue 23's change:
``--spp 64 1024 4096 --sampler r2 --rim-spp-factor 1``.
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


def _parse_args(argv):
    """The command line."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spp", type=int, nargs="+", default=[64, 256], help="samples per pixel to compare")
    ap.add_argument("--seeds", type=int, default=6, help="render seeds per spp (default 6)")
    ap.add_argument("--frames", type=int, default=40, help="sensor noise draws on one render (default 40)")
    ap.add_argument("--range", type=float, default=5.712, dest="range_m", help="range, m (default 5.712)")
    ap.add_argument("--sampler", default="sobol", help="the renderer's sample generator: sobol (default) or r2")
    ap.add_argument("--rim-spp-factor", type=int, default=None,
                    help="factor on --spp for the marker-rim pixels (default the renderer's; 1: uniform)")
    args = ap.parse_args(argv)
    return args


def main(argv=None):
    args = _parse_args(argv)
    from svgs_sim.camera.amcw import TofSensor
    from svgs_sim.render.tof.camera import DEFAULT_RIM_SPP_FACTOR, TofRenderer
    from svgs_sim.svgs.frames import pose_from_scenario
    from svgs_sim.tof import TofPipeline, load_camera, load_target

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

    factor = DEFAULT_RIM_SPP_FACTOR if args.rim_spp_factor is None else args.rim_spp_factor
    renderers = {}

    def render(spp, seed, rim_factor=factor, warm_up=True):
        key = (spp, rim_factor)
        if key not in renderers:  # one scene per setting; the first render (kernel compilation) not timed
            renderers[key] = TofRenderer(camera, target, spp=spp, modulation_frequency_hz=sensor.modulation_frequency_hz,
                                         sampler=args.sampler, rim_spp_factor=rim_factor)
            if warm_up:
                renderers[key].render(R, t, seed=seed + 1_000_000)
        t0 = time.perf_counter()
        out = renderers[key].render(R, t, seed=seed)
        return out, time.perf_counter() - t0

    top = args.spp[-1]
    ref, _ = render(top, 10_000, 4 * factor, warm_up=False)
    clean_ref = next(sensor.frames(ref, 1, None, noise=False))
    marker = clean_ref.gray > 0.2 * np.nanmax(clean_ref.gray)  # the markers' bright pixels
    noisy = np.array([fr.gray for fr in sensor.frames(ref, args.frames, [99, 1])])
    pix_sensor = np.std(noisy, axis=0, ddof=1)[marker]
    # single frames (each the first of a fresh pipeline, as the render rows), noise seeds [s, 1]
    s_sensor = np.std(np.concatenate([states(ref, [s, 1], 1) for s in range(args.frames)]), axis=0, ddof=1)
    rr = ref.truth["render"]
    print(f"ToF EPC660, tof-8, {args.range_m:g} m head-on, sampler {args.sampler}, rim factor {factor}; sensor: "
          f"{args.frames} single-frame noise draws on one render ({rr['spp']} spp, {rr['rim_spp']} on "
          f"{rr['rim_pixels']} rim pixels)")
    print(f"{'':>10}" + "".join(f"{k:>11}" for k in KEYS))
    print(f"{'sensor':>10}" + "".join(f"{v:>11.4f}" for v in s_sensor))
    for spp in args.spp:
        _report_spp(spp, args.seeds, factor, render, states, sensor, marker, pix_sensor, s_sensor)

def _report_spp(spp: int, n_seeds: int, factor: int, render, states, sensor, marker, pix_sensor, s_sensor) -> None:
    """Print the render noise at ``spp`` samples per pixel against the sensor's noise.

    Parameters
    ----------
    spp : int
        Samples per pixel of the renders.
    n_seeds : int
        Render seeds (one render each).
    factor : int
        The rim pixels' factor on ``spp``.
    render : callable
        ``render(spp, seed) -> (rendered, render_time_s)``.
    states : callable
        ``states(rendered, noise_seed, n, noise=True) -> ndarray, shape (n_solved, 6)``.
    sensor : TofSensor
    marker : ndarray of bool, shape (H, W)
        The markers' bright pixels.
    pix_sensor : ndarray, shape (n_marker_pixels,)
        The sensor noise (gray) of each marker pixel.
    s_sensor : ndarray, shape (6,)
        The sensor noise of the state (:data:`KEYS`).
    """
    rows, times = [], []
    clean, grays = [], []
    for s in range(n_seeds):
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
          + f"   same noise draw ({len(rows)}/{n_seeds} solved, render {np.median(times):.2f} s, "
          f"{spp * factor} spp on the rims)")
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
