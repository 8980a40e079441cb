"""Benchmark (issue 3): the radiometric acceptance numbers, printed as a table.

Rendered / geometric-optics ratios (the same set-ups as ``tests/test_render_radiometry.py``,
several seeds each, mean +- standard deviation):

- single cube, lens in the footprint (LED 4 mm from the lens), hollow and solid N-BK7,
  at 1, 5, 20 and 40 m: ``sum(L * Omega_pix * cos) / (factor * I / |2V - S|^2)``;
- the same with the LED 16 mm from the lens (beyond the footprint);
- brute-force path tracing of the hollow cube at 1 m (the reference method);
(The Lambertian plate check is in the tests only.)

Run: ``.venv/bin/python benchmarks/bench_render_radiometry.py [--seeds 4]``
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import test_render_radiometry as T  # noqa: E402  (the test set-ups)

from svgs_sim.render.predict import retro_irradiance_w_m2  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=4)
    args = ap.parse_args(argv)
    from svgs_sim.render.api import Renderer

    t0 = time.perf_counter()
    print("single cube, LED 4 mm from the lens (inside the footprint): rendered / predicted")
    for kind in ("hollow", "solid"):
        r = Renderer(T._camera(), T.SINGLE, reflector=kind, scene_options={"body": "none"}, spp=4, roi_spp=16,
                     spot_samples=1 << 17)
        for rng in (1.0, 5.0, 20.0, 40.0):
            S = r.flash.led_offsets_m[0]
            R, t = T._pose_facing(S, rng)
            Ep = retro_irradiance_w_m2(T.I_W_SR, S, r.target.reference_m[0] @ R.T + t, r.reflector)
            v = [T._irradiance(r.render(R, t, seed=s), r.camera) / Ep for s in range(args.seeds)]
            print(f"  {kind:6s} {rng:5.1f} m: {np.mean(v):.4f} +- {np.std(v, ddof=1):.4f}")
    r = Renderer(T._camera(offset_m=0.016), T.SINGLE, reflector="solid", scene_options={"body": "none"}, spp=4,
                 roi_spp=16, spot_samples=1 << 16)
    for rng in (1.0, 40.0):
        S = r.flash.led_offsets_m[0]
        R, t = T._pose_facing(S, rng)
        Ep = retro_irradiance_w_m2(T.I_W_SR, S, r.target.reference_m[0] @ R.T + t, r.reflector)
        print(f"LED 16 mm from the lens (beyond the footprint), solid, {rng:g} m: "
              f"{T._irradiance(r.render(R, t, seed=0), r.camera) / Ep:.2e} of the in-footprint value")
    r = Renderer(T._camera(), T.SINGLE, reflector="hollow", scene_options={"body": "none"}, spp=4, roi_spp=4096,
                 method="path")
    S = r.flash.led_offsets_m[0]
    R, t = T._pose_facing(S, 1.0)
    Ep = retro_irradiance_w_m2(T.I_W_SR, S, r.target.reference_m[0] @ R.T + t, r.reflector)
    v = [T._irradiance(r.render(R, t, seed=s), r.camera) / Ep for s in range(args.seeds)]
    print(f"brute-force path tracing (4096 spp windows), hollow, 1 m: {np.mean(v):.4f} +- {np.std(v, ddof=1):.4f}")
    print(f"({time.perf_counter() - t0:.0f} s)")


if __name__ == "__main__":
    main()
