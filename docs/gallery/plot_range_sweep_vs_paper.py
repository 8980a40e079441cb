"""
Does the simulated phone see what the paper saw, range by range?
================================================================

The committed range sweep of the HTC Amaze 4G (``docs/reports/range-sweep-htc-amaze-4g``, made by
the command its README names): the target head-on at each range, rendered, exposed as the phone
did, detected and solved. Against it, the paper's standard deviations (Table 3, from the paper's
own file in the package). The sweep is head-on (no gimbal turns), so its scatter is the sensor's
alone; the paper's includes the stand's settings: read the comparison as a floor, not a match.
Nothing is rendered here: the figure reads the committed CSV.
"""

import csv
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from svgs_sim.assets.papers import svgs_2014_rows

here = Path(__file__).resolve().parent if "__file__" in globals() else Path.cwd()
with open(here.parent / "reports" / "range-sweep-htc-amaze-4g" / "summary.csv", newline="") as fh:
    rows = [{k: (float(v) if v not in ("", None) and k != "failures" else v) for k, v in r.items()} for r in csv.DictReader(fh)]
paper = svgs_2014_rows("htc-amaze-4g", "std")

fig, axes = plt.subplots(1, 2, figsize=(10, 4))
r = np.array([x["range_m"] for x in rows])
axes[0].plot(r, [x["success_rate"] for x in rows], "o-", label="solved")
axes[0].plot(r, [x["merged_rate"] for x in rows], "s--", label="spots merged")
axes[0].set_xlabel("range (m)")
axes[0].set_ylabel("fraction of frames")
axes[0].set_title("success against range (the paper: four spots up to about 6.5 m)", fontsize=9)
axes[0].legend()
for c, mk in (("x_m", "o"), ("y_m", "s"), ("z_m", "^")):
    axes[1].semilogy(r, [x[f"err_std_{c}"] for x in rows], mk + "-", label=f"simulated {c}")
    axes[1].semilogy([p["range_m"] for p in paper], [p[c] for p in paper], mk + ":", color="red", alpha=0.6,
                     label=f"paper Table 3 {c}" if c == "x_m" else None)
axes[1].set_xlabel("range (m)")
axes[1].set_ylabel("standard deviation (m)")
axes[1].set_title("position scatter: head-on sweep (blue) and the paper's (red, dotted)", fontsize=9)
axes[1].legend(fontsize=7)
fig.tight_layout()
plt.show()
