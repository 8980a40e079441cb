"""
How large is the error of an approach, against what the sensor could do?
========================================================================

The committed approach of the Galaxy Nexus from 30 m to 1 m (``docs/reports/approach-galaxy-nexus``,
made by the command its ``report.md`` names): every frame rendered, exposed with the phone's own
exposure, solved. Its position error beside the Cramer-Rao bound of the frame (the best an
unbiased estimator could do with that image's noise). Where the error sits far above the bound,
something other than noise makes it (the calibration, the pose's weak mode).
Nothing is rendered here: the figure reads the committed ``measurements.csv``.
"""

import csv
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

here = Path(__file__).resolve().parent if "__file__" in globals() else Path.cwd()
with open(here.parent / "reports" / "approach-galaxy-nexus" / "measurements.csv", newline="") as fh:
    rows = [r for r in csv.DictReader(fh) if r["ok"] in ("1", "True")]
r = np.array([float(x["range_m"]) for x in rows])

fig, axes = plt.subplots(1, 3, figsize=(12, 3.8), sharex=True)
for ax, c in zip(axes, ("x_m", "y_m", "z_m")):
    err = np.abs([float(x[f"err_{c}"]) for x in rows])
    crlb = np.array([float(x[f"crlb_{c}"]) for x in rows])
    ax.semilogy(r, err, ".", ms=3, label="|error|")
    ax.semilogy(r, crlb, "-", color="k", lw=1, label="CRLB 1-sigma")
    ax.set_xlabel("range (m)")
    ax.set_title(c, fontsize=9)
    ax.invert_xaxis()
axes[0].set_ylabel("m")
axes[0].legend(fontsize=8)
fig.suptitle(f"Galaxy Nexus approach: {len(rows)} solved frames, position error against the Cramer-Rao bound",
             fontsize=10)
fig.tight_layout()
plt.show()
