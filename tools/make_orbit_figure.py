"""The figure of docs/orbit.md: one Galaxy Nexus frame at 5 m on orbit, sunlit and in eclipse, with
the shipped 3U body and the Earth.

Run::

    python tools/make_orbit_figure.py [--out docs/figures/orbit_sun_vs_eclipse.png]

Renders both frames with ``svgs render-and-solve --environment orbit --body 3u --earth-deg=0,-25``
(``--seed 1``; the Earth's centre 65 deg off the boresight: the target seen against it, its limb 5 deg from the centre) - the sun
at azimuth 90, elevation 45 deg in the first, at 0,-10 (behind the Earth: eclipse) in the second -
into a temporary folder and shows the delivered 8-bit images whole (top) and cropped around the
target (bottom), with each frame's outcome in its title.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

COMMON = ["--body", "3u", "--earth-deg=0,-25"]
CASES = (("sunlit: sun at azimuth 90, elevation 45 deg", ["--sun-deg=90,45"]),
         ("eclipse: the sun (0, -10 deg) behind the Earth", ["--sun-deg=0,-10"]))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default="docs/figures/orbit_sun_vs_eclipse.png")
    args = ap.parse_args()
    import cv2
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from svgs_sim.cli.main import main as svgs

    fig, axes = plt.subplots(2, 2, figsize=(10, 8.2), gridspec_kw={"height_ratios": [0.75, 1]})
    with tempfile.TemporaryDirectory() as tmp:
        for k, (title, extra) in enumerate(CASES):
            out = Path(tmp) / f"case{k}"
            svgs(["render-and-solve", "--camera", "galaxy-nexus", "--range", "5", "--environment", "orbit",
                  *COMMON, *extra, "--seed", "1", "--out", str(out)])
            img = cv2.imread(str(out / "image.png"), cv2.IMREAD_UNCHANGED)
            sol = json.loads((out / "solution.json").read_text())
            truth = json.loads((out / "truth.json").read_text())
            uv = np.asarray(list(truth["targets_px"].values()), float)
            c = uv.mean(0)
            h = int(max(np.ptp(uv[:, 0]), np.ptp(uv[:, 1])) * 1.1) + 40
            x0, y0 = int(c[0]) - h, int(c[1]) - h
            crop = img[max(0, y0):y0 + 2 * h, max(0, x0):x0 + 2 * h]
            outcome = "solved" if sol.get("ok") else f"no solution: {sol.get('reason')}"
            whole = img if img.ndim == 2 else img[..., ::-1]
            axes[0, k].imshow(whole, cmap="gray", vmin=0, vmax=255)
            axes[0, k].add_patch(plt.Rectangle((x0, y0), 2 * h, 2 * h, fill=False, ec="r", lw=0.8))
            axes[0, k].set_title(f"{title}\n{outcome}", fontsize=10)
            axes[1, k].imshow(crop if crop.ndim == 2 else crop[..., ::-1], cmap="gray", vmin=0, vmax=255)
            axes[1, k].set_title("around the target (red box above)", fontsize=9)
            for ax in axes[:, k]:
                ax.set_xticks([])
                ax.set_yticks([])
    fig.suptitle("Galaxy Nexus at 5 m on orbit: the 3U body, the target seen against the Earth (its limb at left), the spots\n"
                 "(svgs render-and-solve --environment orbit --body 3u --earth-deg=0,-25 --seed 1)", fontsize=11)
    fig.tight_layout()
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=110)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
