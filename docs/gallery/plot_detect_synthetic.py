"""
The detector on a synthetic image
=================================

An 8-bit frame of the Galaxy Nexus's size with Gaussian spots drawn (pixel-integrated) at the
target's projected centroids, read noise and one bright distractor, all seeded. The SVGS
detector (the app's brightness threshold, the blobs' centroids), the target identification
and the solver recover the pose: :func:`svgs_sim.svgs.solve_image` end to end.
"""

import matplotlib.pyplot as plt
import numpy as np
from scipy.special import erf

from svgs_sim import svgs

camera = svgs.Camera.load("galaxy-nexus")
pattern = svgs.Pattern.load("svgs-3u")
R_cam_target, t_cam_target_m = svgs.pose_from_scenario(8.0, -0.2, 0.1, roll_deg=-4, pitch_deg=6, yaw_deg=3)
truth = svgs.pose_to_state(R_cam_target, t_cam_target_m)
centres_px = camera.project_target(pattern.points_m, R_cam_target, t_cam_target_m)


def add_spot(image, u, v, sigma_px, peak_dn):
    """Add a pixel-integrated Gaussian spot centred at (u, v) (pixel centres at integers)."""
    r = int(np.ceil(7 * sigma_px)) + 1
    u0, v0 = int(np.floor(u)) - r, int(np.floor(v)) - r
    cols = np.arange(u0, u0 + 2 * r + 2)
    rows = np.arange(v0, v0 + 2 * r + 2)
    s = np.sqrt(2.0) * sigma_px
    fu = 0.5 * (erf((cols + 0.5 - u) / s) - erf((cols - 0.5 - u) / s))
    fv = 0.5 * (erf((rows + 0.5 - v) / s) - erf((rows - 0.5 - v) / s))
    image[v0:v0 + len(rows), u0:u0 + len(cols)] += peak_dn * 2 * np.pi * sigma_px**2 * np.outer(fv, fu)


rng = np.random.default_rng(7)  # seeded: the same image at every build
frame = np.full((camera.height, camera.width), 12.0)
for u, v in centres_px:
    add_spot(frame, u, v, sigma_px=1.5, peak_dn=200.0)
add_spot(frame, 400.0, 300.0, sigma_px=1.5, peak_dn=220.0)  # a glint away from the target
frame += rng.normal(0.0, 2.0, frame.shape)
image = np.clip(np.rint(frame), 0, 255).astype(np.uint8)

result = svgs.solve_image(image, camera, pattern)
print(f"blobs found: {result.n_blobs}, threshold {result.threshold_used:.0f} DN")
print("errors (solved - truth):", np.array2string(result.state - truth, precision=4))

# %%
# The target's region of the frame, the detected target centroids marked
u_lo, v_lo = (centres_px.min(0) - 40).astype(int)
u_hi, v_hi = (centres_px.max(0) + 40).astype(int)
fig, ax = plt.subplots(figsize=(5, 4))
ax.imshow(image[v_lo:v_hi, u_lo:u_hi], cmap="gray", extent=(u_lo - 0.5, u_hi - 0.5, v_hi - 0.5, v_lo - 0.5))
found = np.array(list(result.targets_px.values()))
ax.plot(found[:, 0], found[:, 1], "r+", ms=12, label="identified targets")
ax.set_xlabel("u (px)")
ax.set_ylabel("v (px)")
ax.legend(loc="lower right")
fig.tight_layout()
