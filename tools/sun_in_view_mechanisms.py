"""What saturates a frame with the sun in view: one render, exposed with the camera model as
shipped, without blooming (plain clipping at full well), without the glare wings, and without both;
each solved with the paper's chain (docs/orbit.md, "The sun in the field of view").

Usage::

    python tools/sun_in_view_mechanisms.py [--camera galaxy-nexus] [--range 5] [--sun-deg=0,-87] [--seed 0]

prints, per variant, the outcome and the pixels at full scale (about 1 minute on 2 cores).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from svgs_sim.base.profiles import load_camera  # noqa: E402
from svgs_sim.camera.phone import ALL_STAGES  # noqa: E402
from svgs_sim.sim.closed_loop import Scenario, expose_and_solve, render_scenario  # noqa: E402
from svgs_sim.sim.scene import Scene  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--camera", default="galaxy-nexus")
    ap.add_argument("--range", type=float, default=5.0)
    ap.add_argument("--sun-deg", default="0,-87")
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args(argv)
    az, el = (float(x) for x in a.sun_deg.split(","))
    sc = Scenario(camera=load_camera(a.camera), range_m=a.range,
                  scene=Scene(environment="orbit", sun_azimuth_deg=az, sun_elevation_deg=el))
    frame = render_scenario(sc, seed=a.seed)
    no_bloom = tuple(s for s in ALL_STAGES if s != "bloom")
    for label, stages, glare in (("as shipped", None, True), ("blooming off", no_bloom, True),
                                 ("glare off", None, False), ("both off", no_bloom, False)):
        row = expose_and_solve(frame, frame.exposer(stages=stages, glare=glare), seed=a.seed, truth="actual",
                               stages=stages)
        img = row["_exposure"].image
        gray = img if img.ndim == 2 else img.max(axis=2)
        outcome = "solved" if row["ok"] else row["reason"]
        print(f"{label:13s} {outcome:14s} blobs {row['n_blobs']}, {int((gray >= 255).sum())} px at full scale")
    return 0


if __name__ == "__main__":
    sys.exit(main())
