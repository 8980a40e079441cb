"""The campaign's figures: error histograms (the paper's Figures 6-13), errors versus range
beside the Cramer-Rao bound, and the delivered images."""

from __future__ import annotations

import math

import numpy as np

from svgs_sim.base.profiles import load_pattern
from svgs_sim.sim.closed_loop import solve_exposure, solver_camera
from svgs_sim.sim.render_trial import rendered_frame
from svgs_sim.sim.trials import camera_with_calibration_errors
from svgs_sim.svgs.frames import STATE_KEYS

from .design import COMPONENT_LABELS, SHORT, CampaignConfig


def _range_groups(ranges):
    """Split ranges as the paper's figures did (Amaze 1-3 / 4-8 m, Nexus 5-15 / 20-30 m)."""
    rs = list(ranges)
    h = math.ceil(len(rs) / 2)
    return [g for g in (rs[:h], rs[h:]) if g]


def histogram_figures(table: dict, config: CampaignConfig):
    """Figures 6-13 of the paper: error histograms per component, two range groups.

    Yields
    ------
    (Figure, caption)
    """
    from matplotlib.figure import Figure

    ok = table["ok"] == 1
    for grp in _range_groups(config.ranges_m):
        label = f"{grp[0]:g}-{grp[-1]:g} m" if len(grp) > 1 else f"{grp[0]:g} m"
        for title, comps in (("Position error", STATE_KEYS[:3]), ("Attitude error", STATE_KEYS[3:])):
            fig = Figure(figsize=(11, 3.2))
            axes = fig.subplots(1, 3)
            for ax, c in zip(axes, comps):
                data = [table[f"err_{c}"][ok & (table["nominal_range_m"] == r)] for r in grp]
                allv = np.concatenate(data) if data else np.array([])
                if allv.size:
                    lim = np.percentile(np.abs(allv), 99.5) or 1.0
                    bins = np.linspace(-lim, lim, 41)
                    for r, d in zip(grp, data):
                        ax.hist(np.clip(d, -lim, lim), bins=bins, histtype="step", linewidth=1.4, label=f"{r:g} m")
                ax.set_xlabel(f"{SHORT[c]} error ({c.split('_')[1]})")
                ax.set_ylabel("trials")
                ax.grid(alpha=0.3)
            axes[0].legend(fontsize=8)
            fig.suptitle(f"{config.camera}: {title.lower()} ({label})")
            yield fig, f"{title} histograms, {label} (like the paper's Figures 6-13)."


def crlb_figure(summary: list[dict], config: CampaignConfig):
    """Simulated std, Cramer-Rao bound and the paper's std (and mean |error|) versus range."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(12, 6.5))
    axes = fig.subplots(2, 3).ravel()
    r = np.array([s["range_m"] for s in summary])
    for ax, c in zip(axes, STATE_KEYS):
        ax.plot(r, [s[f"crlb_{c}"] for s in summary], "k-", label="Cramer-Rao 1-sigma")
        ax.plot(r, [s[f"std_{c}"] for s in summary], "o-", color="C0", label="simulated std")
        ax.plot(r, [s[f"mean_abs_{c}"] for s in summary], "o--", color="C0", alpha=0.6, label="simulated mean |err|")
        ps = [s[f"paper_std_{c}"] for s in summary]
        if np.any(np.isfinite(ps)):
            ax.plot(r, ps, "s-", color="C3", label="paper std")
            ax.plot(r, [s[f"paper_mean_{c}"] for s in summary], "s--", color="C3", alpha=0.6, label="paper mean error")
        ax.set_yscale("log")
        ax.set_xlabel("range (m)")
        ax.set_ylabel(COMPONENT_LABELS[c])
        ax.grid(alpha=0.3, which="both")
    axes[0].legend(fontsize=7)
    fig.suptitle(f"{config.camera}: errors versus range, beside the Cramer-Rao bound and the paper")
    fig.tight_layout()
    return fig


def sample_image_figure(config: CampaignConfig, trials: list, table: dict):
    """One delivered image per range (the first stand setting, its first exposure), cropped to the
    target, with the true target projections (circles) and the solved targets (crosses)."""
    from matplotlib.figure import Figure


    pat = load_pattern(config.pattern)
    firsts = {}
    for t in trials:
        sc = t.scenario
        if sc.get("variant") == "baseline" and sc["pose_index"] == 0 and sc["exposure_index"] == 0:
            firsts.setdefault(sc["nominal_range_m"], t)
    n = len(config.ranges_m)
    fig = Figure(figsize=(3.0 * n, 3.4))
    axes = np.atleast_1d(fig.subplots(1, n))
    for ax, r in zip(axes, config.ranges_m):
        t = firsts.get(r)
        ax.set_xticks([])
        ax.set_yticks([])
        if t is None:
            continue
        frame = rendered_frame(t.scenario)
        ex = frame.exposer().expose(seed=int(t.seed))
        img = ex.image
        cam_img = solver_camera(frame.camera, img.shape)
        R, tt = frame.scenario.pose()
        uv = cam_img.project_target(pat.points_m, R, tt)
        row = solve_exposure(frame, ex, solver_camera_profile=camera_with_calibration_errors(frame.camera, t.scenario))
        lo, hi = uv.min(0), uv.max(0)
        pad = max(12.0, 0.6 * float(np.max(hi - lo)))
        x0, x1 = int(max(0, lo[0] - pad)), int(min(img.shape[1], hi[0] + pad))
        y0, y1 = int(max(0, lo[1] - pad)), int(min(img.shape[0], hi[1] + pad))
        ax.imshow(img[y0:y1, x0:x1], cmap="gray", vmin=0, vmax=255, extent=(x0 - 0.5, x1 - 0.5, y1 - 0.5, y0 - 0.5))
        ax.plot(uv[:, 0], uv[:, 1], "o", mfc="none", mec="C0", ms=9, label="true targets")
        sol = row["_solution"]
        if sol:
            found = np.array([sol.targets_px[i] for i in pat.ids], float)
            ax.plot(found[:, 0], found[:, 1], "+", color="C3", ms=9, label="solved")
        ax.set_title(f"{r:g} m: {'solved' if sol else sol.reason}\n{ex.exposure_s * 1e3:.3g} ms, ISO {ex.iso:.0f}",
                     fontsize=8)
    axes[0].legend(fontsize=6, loc="lower left")
    fig.suptitle(f"{config.camera}: delivered images (8-bit), the first stand setting of each range", fontsize=9)
    fig.tight_layout()
    return fig
