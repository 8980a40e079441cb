"""The ToF pipeline's noise-free pose bias, taken apart by switching its inputs to the truth.

Renders the stability run's scene at ``RANGE_M`` (the paper's average pose at 0.697 and 5.712 m,
as ``svgs tof stability``), pushes the noise-free frame through the default pipeline
(:class:`svgs_sim.tof.TofPipeline`), then re-solves the same eight markers with the pipeline's own
steps (weighted SVD, then the paper's line-of-sight iteration with its defaults) on:

- the measured centres and depths (reproduces the pipeline's pose);
- the true projected centres with the measured depths (the centroid's share);
- the measured centres with the true slant ranges (the depth's share);
- both true (must give zero: the frames, intrinsics and truth agree);

each also without the refinement (SVD only) and with Gauss-Newton, and prints each pose error
(the stability run's columns: the markers' centroid in the camera frame, mm, and the paper
state's angles, deg) with the centroid error against the truth.

Usage::

    python tools/tof_bias_mechanism.py 5.712 [--seed 0]

About 10 s a range on 2 cores (one render).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from svgs_sim.sim.metrics import state_error  # noqa: E402
from svgs_sim.sim.tof_closed_loop import noise_free_frame, render  # noqa: E402
from svgs_sim.sim.tof_stability import COLUMNS, pose_columns, reference_point_m, stability_scenario  # noqa: E402
from svgs_sim.svgs.frames import pose_to_state  # noqa: E402
from svgs_sim.tof import PipelineParams, TofPipeline  # noqa: E402
from svgs_sim.tof.camera import line_of_sight  # noqa: E402
from svgs_sim.tof.pose import REFINE_TOL, refine_line_of_sight, weighted_svd_pose  # noqa: E402


def pose_error(tr, R, t) -> np.ndarray:
    """The stability run's columns of (R, t) less the truth's, and the total rotation, deg; shape (7,)."""
    truth = tr.truth_state
    pt = reference_point_m(tr.target, "markers")
    tc = pose_columns(tr.R_cam_target, tr.t_cam_target_m, truth, None, pt)
    e = pose_columns(R, t, truth, state_error(pose_to_state(R, t), truth), pt) - tc
    dR = R @ tr.R_cam_target.T
    return np.append(e, np.degrees(np.arccos(np.clip((np.trace(dR) - 1) / 2, -1, 1))))


def resolve(tr, uv_px, slant_m, depth_std_m, method: str):
    """The pipeline's pose from eight matched markers in catalog order (its ``_solve`` after the
    match, the centre correction already in ``uv_px``). ``method``: ``fixed-point`` (the default),
    ``gauss-newton`` or ``svd``. Returns (R, t)."""
    P, cam, tgt = PipelineParams(), tr.camera, tr.target
    f = float(np.sqrt(cam.fx * cam.fy))
    e = line_of_sight(cam, uv_px)
    sig_perp = P.centroid_sigma_px * slant_m / f
    sig_rho = np.maximum(np.nan_to_num(depth_std_m, nan=1.0), P.depth_sigma_floor_m)
    w = 1 / (sig_perp**2 + sig_rho**2)
    R, t = weighted_svd_pose(tgt.points_m, e * slant_m[:, None], w)
    if method == "svd":
        return R, t
    gn = method == "gauss-newton"
    r = refine_line_of_sight(tgt.points_m, e, R, t, weights=1 / sig_perp**2, slant_range_m=slant_m,
                             depth_weight=float(P.depth_weight), method=method,
                             tol=REFINE_TOL if gn else P.refine_tol_m, max_iter=None if gn else P.refine_max_iter)
    return r.R_cam_target, r.t_cam_target_m


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("range_m", type=float, help="the stability run's range, m (0.697 and 5.712: the paper's poses)")
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args(argv)
    tr = render(stability_scenario(a.range_m, seed=a.seed))
    cam, tgt = tr.camera, tr.target
    R0, t0 = tr.R_cam_target, tr.t_cam_target_m
    faces = tgt.points_m @ R0.T + t0
    uv_true, rho_true = cam.project(faces), np.linalg.norm(faces, axis=1)
    res = TofPipeline(cam, tgt).process(*((fr := noise_free_frame(tr)).gray, fr.depth_m))
    if not res:
        print(f"the noise-free frame does not solve: {res.reason}", file=sys.stderr)
        return 1
    if sorted(res.targets_px) != sorted(int(k) for k in tgt.ids):
        print(f"only markers {sorted(res.targets_px)} were matched; this tool needs all eight", file=sys.stderr)
        return 1
    uv_meas = np.array([res.targets_px[int(k)] for k in tgt.ids], float)
    c = res.candidates  # the measured depths: each marker's nearest candidate
    near = np.linalg.norm(c.uv_px[:, None, :] - uv_true[None], axis=2).argmin(0)
    e_meas = line_of_sight(cam, uv_meas)
    pipe = TofPipeline(cam, tgt)
    rho_meas = c.depth_m[near] if pipe.depth_kind == "radial" else c.depth_m[near] / e_meas[:, 2]
    std = c.depth_std_m[near]
    du = uv_meas - uv_true
    f = float(np.sqrt(cam.fx * cam.fy))
    print(f"range {a.range_m} m, seed {a.seed}: markers {np.round(2 * tgt.radius_m * f / faces[:, 2], 1)} px across; "
          f"centroid error against the true projected centres {np.sqrt(np.mean(np.sum(du**2, 1))):.4f} px RMS "
          f"(max {np.abs(du).max():.4f}); depth error {np.sqrt(np.mean((rho_meas - rho_true)**2)) * 1e3:.3f} mm RMS")
    print(f"pipeline's own pose error: " + " ".join(f"{v:+.4f}" for v in pose_error(tr, res.R_cam_target, res.t_cam_target_m)))
    hdr = " ".join(f"{c_:>16s}" for c_ in (*COLUMNS, "rotation_deg"))
    print(f"{'centres':9s} {'depths':9s} {'solver':13s} {hdr}")
    for cn, uv in (("measured", uv_meas), ("true", uv_true)):
        for dn, rho in (("measured", rho_meas), ("true", rho_true)):
            for method in ("fixed-point", "gauss-newton", "svd"):
                e = pose_error(tr, *resolve(tr, uv, rho, std, method))
                print(f"{cn:9s} {dn:9s} {method:13s} " + " ".join(f"{v:+16.4f}" for v in e))
    return 0


if __name__ == "__main__":
    sys.exit(main())
