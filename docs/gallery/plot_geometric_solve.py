"""
A geometric solve: centroids to the 6-DOF state
===============================================

The SVGS collinearity solver on centroids projected through the Galaxy Nexus's camera model
from a known pose, with seeded Gaussian centroid noise of 0.1 px per axis. No image, no
renderer: the solver alone, against the pose the points were projected from, beside its
Cramer-Rao bound (the ``std`` of the solution).
"""

import matplotlib.pyplot as plt
import numpy as np

from svgs_sim import svgs

camera = svgs.Camera.load("galaxy-nexus")
pattern = svgs.Pattern.load("svgs-3u")

# the target 10 m along the boresight, 0.3 m right, 0.2 m down, turned a little
R_cam_target, t_cam_target_m = svgs.pose_from_scenario(10.0, 0.3, -0.2, roll_deg=5, pitch_deg=-3, yaw_deg=10)
truth = svgs.pose_to_state(R_cam_target, t_cam_target_m)

sigma_px = 0.1
rng = np.random.default_rng(1)  # seeded: the same numbers at every build
exact_px = camera.project_target(pattern.points_m, R_cam_target, t_cam_target_m)
points_px = exact_px + rng.normal(0.0, sigma_px, exact_px.shape)

solution = svgs.solve_centroids(points_px, camera, pattern, sigma_px=sigma_px)
print(f"solved: {bool(solution)}, RMS residual {solution.residual_rms_px:.3f} px")
names = ["x_m", "y_m", "z_m", "roll_rad", "pitch_rad", "yaw_rad"]
for name, true, est, std in zip(names, truth, solution.state, solution.std):
    print(f"{name:10s} truth {true:+.5f}  solved {est:+.5f}  error {est - true:+.2e}  CRLB std {std:.1e}")

# %%
# The centroids in the image (the target spans a few tens of pixels at 10 m)
fig, ax = plt.subplots(figsize=(5, 4))
ax.plot(exact_px[:, 0], exact_px[:, 1], "o", mfc="none", label="projected (truth)")
ax.plot(points_px[:, 0], points_px[:, 1], "+", label="with 0.1 px noise")
ax.invert_yaxis()
ax.set_xlabel("u (px)")
ax.set_ylabel("v (px)")
ax.set_aspect("equal")
ax.legend()
ax.set_title("SVGS 3U target, Galaxy Nexus, 10 m")
fig.tight_layout()
