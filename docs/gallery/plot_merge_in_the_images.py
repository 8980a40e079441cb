"""
Where do the Amaze 4G's spots merge, and how thin is the margin?
================================================================

The paper: the HTC Amaze 4G kept four separate spots "up to about 6.5 meter". In the simulation
the phone's auto-exposure lifts the lit lab to mid-grey and the flash's spots bloom; the gap
between two neighbouring spots falls under the app's brightness threshold, and two blobs become
one. The committed merge-range study (``docs/reports/merge-range-htc-amaze-4g``) measured the
margin: the darkest pixel on the line between two spots, below the threshold (positive: still
apart). Each other line moves one physical parameter to the end of its plausible range.
Nothing is rendered here: the figure reads the committed ``summary.json``.
"""

import json
from pathlib import Path

import matplotlib.pyplot as plt

here = Path(__file__).resolve().parent if "__file__" in globals() else Path.cwd()
s = json.loads((here.parent / "reports" / "merge-range-htc-amaze-4g" / "summary.json").read_text())

fig, ax = plt.subplots(figsize=(8, 4.5))
for case in s["cases"]:
    nominal = case["case"] == "nominal"
    if not nominal and case["parameter"] not in ("ambient_radiance_w_m2_sr", "threshold", "glare_veiling_fraction"):
        continue
    ax.plot(s["ranges_m"], case["margin_dn"], "k-" if nominal else "--", lw=2.5 if nominal else 1,
            label=("nominal (the fitted lab light)" if nominal else f"{case['parameter']} = {case['value']:g}")
            + f": merge at {case['merge_range_m']:.3g} m" + ("" if case["bound"] == "inside" else f" ({case['bound']})"))
ax.axhline(0.0, color="red", lw=0.8)
ax.axvline(6.5, color="grey", ls=":", lw=1)
ax.text(6.55, ax.get_ylim()[1] * 0.9, "paper: 6.5 m", fontsize=8, color="grey")
ax.set_xlabel("range (m)")
ax.set_ylabel("margin below the threshold (DN)")
ax.set_title("The merge: positive margin = four spots; the nominal line crosses zero where they merge", fontsize=9)
ax.legend(fontsize=7)
fig.tight_layout()
plt.show()

# %%
# The same merge in the images the phone delivered: the committed head-on range sweep's crops of
# the target (``docs/reports/range-sweep-htc-amaze-4g/overlays.png``), the detected blobs circled.
# Past the merge the two upper spots are one blob.
img = plt.imread(here.parent / "reports" / "range-sweep-htc-amaze-4g" / "overlays.png")
fig, ax = plt.subplots(figsize=(10, 10 * img.shape[0] / img.shape[1]))
ax.imshow(img)
ax.axis("off")
fig.tight_layout()
plt.show()
