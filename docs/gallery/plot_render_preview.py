"""
One render at preview size
==========================

Mitsuba ray-traces the SVGS 3U target's corner-cube retroreflectors under the phone's flash
(:func:`svgs_sim.render.api.render_flux`): the photon flux reaching each pixel, here for the Galaxy
Nexus's camera scaled to a 648 x 486 preview stream, the target 6 m away. The CPU variant
(LLVM) renders it in seconds; the truth records where each target's spot centre lies.
"""

import matplotlib.pyplot as plt
import numpy as np

from svgs_sim import svgs
from svgs_sim.render.api import render_flux

camera = svgs.Camera.load("galaxy-nexus").scaled(648, 486)
R_cam_target, t_cam_target_m = svgs.pose_from_scenario(6.0, 0.1, 0.05, roll_deg=3, pitch_deg=-2, yaw_deg=8)
frame = render_flux(camera, "svgs-3u", R_cam_target, t_cam_target_m, seed=0)

flux = frame.flux  # photons per second reaching each pixel, shape (486, 648)
print(f"flux: shape {flux.shape}, peak {flux.max():.3g}, total {flux.sum():.3g}")
print("render timings (s):", {k: round(v, 2) for k, v in frame.timings_s.items()})

# %%
# The flux on a log scale around the target, the projected target centres marked
targets_px = camera.project_target(svgs.Pattern.load("svgs-3u").points_m, R_cam_target, t_cam_target_m)
u_lo, v_lo = (targets_px.min(0) - 25).astype(int)
u_hi, v_hi = (targets_px.max(0) + 25).astype(int)
crop = flux[v_lo:v_hi, u_lo:u_hi]
fig, ax = plt.subplots(figsize=(5, 4))
im = ax.imshow(np.log10(crop + crop.max() * 1e-6), cmap="magma",
               extent=(u_lo - 0.5, u_hi - 0.5, v_hi - 0.5, v_lo - 0.5))
ax.plot(targets_px[:, 0], targets_px[:, 1], "c+", ms=10, label="projected target centres")
fig.colorbar(im, label="log10 flux")
ax.set_xlabel("u (px)")
ax.set_ylabel("v (px)")
ax.legend(loc="lower right")
fig.tight_layout()
