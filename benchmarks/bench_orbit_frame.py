"""Benchmark (issue 38 item 10): a sunlit full-resolution frame with the Earth in view against
today's dark frame, both rendered warm in one run.

Ours: the Galaxy Nexus at 5 m on orbit with the shipped 3U body, the sun at azimuth 90, elevation
45 deg and the Earth's limb in the frame (``--earth-deg=0,-25``): the flash's pass plus the natural
light's pass (the sun's disk, the body's sunlit faces, the Earth as a closed-form environment map,
over the full frame because the Earth is in view). Peer: the same pose in the dark lab's orbit
(``--environment orbit``, eclipse, no Earth: the flash's pass alone), the frame the paper's chain
renders today. Both at the renderer's defaults (4 spp background, 64 spp windows). Target: ours at
most 2x the peer's median wall time.

Run: ``.venv/bin/python benchmarks/bench_orbit_frame.py [--frames 5]``
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from svgs_sim.svgs.frames import pose_from_scenario  # noqa: E402


def _median_s(renderer, poses) -> float:
    renderer.render(*poses[0], seed=0)  # warm: kernels compiled
    times = []
    for k, pose in enumerate(poses[1:], 1):
        t0 = time.perf_counter()
        renderer.render(*pose, seed=k)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=5)
    ap.add_argument("--camera", default="galaxy-nexus")
    ap.add_argument("--range", type=float, default=5.0)
    args = ap.parse_args(argv)
    from svgs_sim.render import Renderer
    from svgs_sim.render.sun import sun_direction_target

    poses = [pose_from_scenario(args.range, roll_deg=1.0 + 0.1 * k, pitch_deg=-1.0, yaw_deg=0.5 * k)
             for k in range(args.frames + 1)]
    dark = Renderer(args.camera, "svgs-3u", scene_options={"body": "3u"})
    lit = Renderer(args.camera, "svgs-3u", scene_options={
        "body": "3u", "sun_direction_target": tuple(sun_direction_target(90.0, 45.0)),
        "earth_direction_target": tuple(sun_direction_target(0.0, -25.0))})
    t_peer = _median_s(dark, poses)
    t_ours = _median_s(lit, poses)
    res = lit.render(*poses[1], seed=1)
    print(f"frame: {args.camera} {lit.camera.width}x{lit.camera.height} at {args.range:g} m, 3U body; "
          f"Earth in view: {res.truth['earth']['in_view']}; natural-light pass: {res.timings_s.get('sun_tiles')}")
    print(f"ours (sun + Earth, median of {args.frames}): {t_ours:.2f} s")
    print(f"peer (dark, the flash alone, same run):   {t_peer:.2f} s")
    print(f"ratio ours/peer: {t_ours / t_peer:.2f} (target <= 2)")


if __name__ == "__main__":
    main()
