"""The figure of docs/orbit.md: one Galaxy Nexus frame at 5 m on orbit, in eclipse and sunlit.

Run::

    python tools/make_orbit_figure.py [--out docs/figures/orbit_sun_vs_eclipse.png]

Renders both frames with ``svgs render-and-solve --environment orbit`` (``--seed 1``; the sun at
azimuth 90, elevation 60 deg in the second) into a temporary folder and puts the delivered 8-bit
images side by side, cropped around the target, with each frame's outcome in its title.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

CASES = (("eclipse (the flash alone)", []), ("sun at azimuth 90, elevation 60 deg", ["--sun-deg=90,60"]))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default="docs/figures/orbit_sun_vs_eclipse.png")
    args = ap.parse_args()
    import cv2
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from svgs_sim.cli.main import main as svgs

    fig, axes = plt.subplots(1, 2, figsize=(10, 4.6))
    with tempfile.TemporaryDirectory() as tmp:
        for ax, (title, extra) in zip(axes, CASES):
            out = Path(tmp) / ("sun" if extra else "eclipse")
            svgs(["render-and-solve", "--camera", "galaxy-nexus", "--range", "5", "--environment", "orbit",
                  *extra, "--seed", "1", "--out", str(out)])
            img = cv2.imread(str(out / "image.png"), cv2.IMREAD_UNCHANGED)
            sol = json.loads((out / "solution.json").read_text())
            truth = json.loads((out / "truth.json").read_text())
            uv = np.asarray(list(truth["targets_px"].values()), float)
            c = uv.mean(0)
            h = int(max(np.ptp(uv[:, 0]), np.ptp(uv[:, 1])) * 1.1) + 40
            x0, y0 = int(c[0]) - h, int(c[1]) - h
            crop = img[max(0, y0):y0 + 2 * h, max(0, x0):x0 + 2 * h]
            ax.imshow(crop if crop.ndim == 2 else crop[..., ::-1], cmap="gray", vmin=0, vmax=255)
            outcome = "solved" if sol.get("ok") else f"no solution: {sol.get('reason')}"
            ax.set_title(f"{title}\n{outcome}", fontsize=10)
            ax.set_xticks([])
            ax.set_yticks([])
    fig.suptitle("Galaxy Nexus at 5 m on orbit (svgs render-and-solve --environment orbit --seed 1)", fontsize=11)
    fig.tight_layout()
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=110)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
