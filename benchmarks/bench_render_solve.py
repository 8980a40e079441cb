"""Benchmark (issue 3 acceptance): render -> ideal 8-bit image -> ``svgs`` pose solve.

The noise-free flux of the Galaxy Nexus frame, scaled linearly so that its brightest
pixel is 255 and rounded to 8 bits (no camera model: no noise, blooming or glare), is fed
to :func:`svgs_sim.svgs.pipeline.solve_image` (the code behind ``svgs solve``) at 1, 5, 10, 20 and
30 m, nominal attitude and a tilted one. Prints position and attitude errors against the
rendered truth. Part of the position error is physics, not solver error: the spots sit
at the flash's image through each cube, shifted from the targets by about half the
flash-to-lens offset (4 mm here), which the solver (like the paper's) does not model.

Run: ``.venv/bin/python benchmarks/bench_render_solve.py``
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from svgs_sim.svgs.frames import pose_from_scenario, rotation_angle_deg, state_to_pose  # noqa: E402
from svgs_sim.svgs.pipeline import solve_image  # noqa: E402


def main():
    from svgs_sim.render import Renderer

    r = Renderer("galaxy-nexus", "svgs-3u")
    print(f"{'range':>6s} {'attitude (r,p,y) deg':>22s} {'ok':>3s} {'pos err (dx, dy, dz) mm':>28s} {'|dpos| mm':>9s} "
          f"{'att err deg':>11s} {'resid px':>8s}")
    for att in ((0.0, 0.0, 0.0), (5.0, -8.0, 10.0)):
        for rng in (1.0, 5.0, 10.0, 20.0, 30.0):
            R, t = pose_from_scenario(rng, roll_deg=att[0], pitch_deg=att[1], yaw_deg=att[2])
            t0 = time.perf_counter()
            res = r.render(R, t, seed=1)
            img = np.round(255.0 * np.clip(res.flux / res.flux.max(), 0, 1)).astype(np.uint8)
            sol = solve_image(img, r.camera, r.pattern)
            dt = time.perf_counter() - t0
            if not sol:
                print(f"{rng:6.1f} {str(att):>22s}  no  {sol.reason}: {sol.message} ({dt:.1f} s)")
                continue
            L_true = -R.T @ t
            Rs, ts = state_to_pose(sol.state)
            L_sol = -Rs.T @ ts
            d = (L_sol - L_true) * 1e3
            print(f"{rng:6.1f} {str(att):>22s} yes {np.array2string(d, precision=2):>28s} {np.linalg.norm(d):9.2f} "
                  f"{float(rotation_angle_deg(Rs, R)):11.4f} {sol.residual_rms_px:8.3f}")


if __name__ == "__main__":
    main()
