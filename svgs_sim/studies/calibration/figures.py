"""The calibration study's figures (matplotlib ``Figure`` objects, no pyplot state).

Each takes a :class:`svgs_sim.studies.calibration.StudyResult`.
"""

from __future__ import annotations

import numpy as np


def fig_convergence(result):
    """Errors of the recovered intrinsics versus the number of views (three panels)."""
    from matplotlib.figure import Figure

    rows = result.convergence_rows
    fig = Figure(figsize=(13, 3.8))
    axs = fig.subplots(1, 3)
    n = np.array([r["n_views"] for r in rows])
    summ = result.convergence
    ns = [r["n_views"] for r in summ]
    for ax in axs:
        ax.set_xscale("log")
        ax.set_xticks([], minor=True)
        ax.set_xticks(ns, [str(x) for x in ns])
        ax.set_xlabel("views calibrated from")
        ax.grid(alpha=0.3)
    axs[0].scatter(n * 0.97, [abs(r["fx_error_pct"]) for r in rows], s=14, label="|fx error|")
    axs[0].scatter(n * 1.03, [abs(r["fy_error_pct"]) for r in rows], s=14, marker="s", label="|fy error|")
    axs[0].plot(ns, [r["fx_error_pct_mean_abs"] for r in summ], "-", lw=1)
    axs[0].axhline(0.2, color="r", ls="--", lw=1, label="0.2 % acceptance")
    axs[0].set_ylabel("focal length error (%)")
    axs[0].legend(fontsize=8)
    axs[1].scatter(n, [r["pp_error_norm_px"] for r in rows], s=14)
    axs[1].plot(ns, [r["pp_error_norm_px_mean"] for r in summ], "-", lw=1)
    axs[1].axhline(1.0, color="r", ls="--", lw=1, label="1 px acceptance")
    axs[1].set_ylabel("principal point error (px)")
    axs[1].legend(fontsize=8)
    axs[2].scatter(n * 0.97, [r["map_rot_rms_px"] for r in rows], s=14, label="after best rotation")
    axs[2].scatter(n * 1.03, [r["map_rms_px"] for r in rows], s=14, marker="^", label="raw (incl. principal point)")
    axs[2].axhline(0.1, color="r", ls="--", lw=1, label="0.1 px acceptance")
    axs[2].set_yscale("log")
    axs[2].set_ylabel("mapping error over the image, RMS (px)")
    axs[2].legend(fontsize=8)
    fig.tight_layout()
    return fig


def fig_focal(result):
    """RMS focal error versus ranges used and noise added; each image's estimate and the combined one."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 3.8))
    axs = fig.subplots(1, 2)
    names = list(dict.fromkeys(r["ranges"] for r in result.focal_rows))
    for nme in names:
        rs = [r for r in result.focal_rows if r["ranges"] == nme]
        x = [max(r["added_noise_px"], 0.02) for r in rs]
        axs[0].plot(x, [r["rms_err_pct"] for r in rs], "o-", ms=4, label=nme)
    axs[0].set_xscale("log")
    axs[0].set_yscale("log")
    axs[0].axhline(1.0, color="r", ls="--", lw=1)
    axs[0].set_xlabel("centroid noise added (px per axis; 0 plotted at 0.02)")
    axs[0].set_ylabel("RMS focal length error (%)")
    axs[0].legend(fontsize=7)
    axs[0].grid(alpha=0.3, which="both")
    fe = result.focal_estimate
    axs[1].errorbar(fe.ranges_m, 100 * (fe.per_image_f_px / result.camera_true.fx - 1),
                    yerr=[100 * p.sigma_f_px / result.camera_true.fx for p in fe.per_image], fmt="o", ms=4,
                    label="each image alone")
    axs[1].axhline(100 * (fe.f_px / result.camera_true.fx - 1), color="k", lw=1, label="combined estimate")
    axs[1].axhline(0, color="grey", lw=0.8, ls=":")
    axs[1].set_xlabel("range (m)")
    axs[1].set_ylabel("focal length error (%)")
    axs[1].legend(fontsize=8)
    axs[1].grid(alpha=0.3)
    fig.tight_layout()
    return fig


def fig_pose(result, cases):
    """Position and attitude error versus range for ``cases`` (no noise), log-log."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(12, 4.2))
    axs = fig.subplots(1, 2)
    for case in cases:
        rs = [r for r in result.pose_rows if r["case"] == case and r["noise_px"] == 0 and "pos_err_norm_m" in r]
        if not rs:
            continue
        x = [r["range_m"] for r in rs]
        axs[0].plot(x, [max(r["pos_err_norm_m"], 1e-6) for r in rs], "o-", ms=3, label=case)
        axs[1].plot(x, [max(r["rot_err_deg"], 1e-5) for r in rs], "o-", ms=3, label=case)
    for ax, lab in zip(axs, ("position error, mean (m)", "attitude error, mean rotation angle (deg)")):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("range (m)")
        ax.set_ylabel(lab)
        ax.grid(alpha=0.3, which="both")
    axs[1].legend(fontsize=7, loc="center left", bbox_to_anchor=(1.02, 0.5))
    fig.tight_layout()
    return fig


def fig_table4(result):
    """The paper's Table 4 mean errors beside the calibration biases and the noise floor."""
    from matplotlib.figure import Figure

    paper = result.table4.get("paper", [])
    tm = (result.table4.get("tables") or ["Table"])[0]
    fig = Figure(figsize=(12, 4.2))
    axs = fig.subplots(1, 2)
    if paper:
        pr = [p["range_m"] for p in paper]
        for c, m in (("x_m", "o"), ("y_m", "s"), ("z_m", "^")):
            axs[0].plot(pr, [p[c] for p in paper], "k" + m + "-", ms=5, lw=1, label=f"paper {tm} {c[0].upper()}")
        for c, m in (("roll_deg", "o"), ("pitch_deg", "s"), ("yaw_deg", "^")):
            axs[1].plot(pr, [p[c] for p in paper], "k" + m + "-", ms=5, lw=1, label=f"paper {tm} {c.split('_')[0]}")
    full = f"full calibration ({result.config['views_list'][-1]} views)"
    for case, noise, style in (("focal-only calibration (paper)", 0.0, "C0"), (full, 0.0, "C2"),
                               *(("exact", s, f"C{3 + i}") for i, s in enumerate(result.config["floor_noise_px"]))):
        rs = [r for r in result.pose_rows if r["case"] == case and r["noise_px"] == noise and "pos_err_norm_m" in r]
        if not rs:
            continue
        lab = case if noise == 0 else f"exact intrinsics, {noise:g} px noise"
        x = [r["range_m"] for r in rs]
        axs[0].plot(x, [max(r["z_m"], 1e-6) for r in rs], "--", color=style, label=f"{lab}: Z")
        axs[0].plot(x, [max(r["x_m"], 1e-6) for r in rs], ":", color=style, label=f"{lab}: X")
        axs[1].plot(x, [max(r["roll_deg"], 1e-5) for r in rs], "--", color=style, label=f"{lab}: roll")
    for ax, lab in zip(axs, ("mean absolute position error (m)", "mean absolute attitude error (deg)")):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("range (m)")
        ax.set_ylabel(lab)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=6.5)
    fig.tight_layout()
    return fig
