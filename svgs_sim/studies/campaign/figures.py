"""The campaign's figures: error histograms (the paper's Figures 6-13), errors versus range
beside the Cramer-Rao bound, and the delivered images."""

from __future__ import annotations

import math

import numpy as np

from svgs_sim.assets.papers import svgs_2014_results
from svgs_sim.base.profiles import load_pattern
from svgs_sim.sim.closed_loop import solve_exposure, solver_camera
from svgs_sim.sim.render_trial import rendered_frame
from svgs_sim.sim.trials import camera_with_calibration_errors
from svgs_sim.svgs.frames import STATE_KEYS

from ..error_budget import reported_mask
from .design import COMPONENT_LABELS, SHORT, CampaignConfig


#: Fixed margins (``Figure.subplots_adjust``) of the report's histogram, bound and weak-mode
#: figures, which the report embeds uncropped (``Report.figure(tight=False)``): matplotlib's
#: tight layout and tight crop took about a third of a 3-trial campaign's report (issue 40).
HISTOGRAM_MARGINS = {"left": 0.06, "right": 0.99, "bottom": 0.16, "top": 0.86, "wspace": 0.25}
CRLB_MARGINS = {"left": 0.06, "right": 0.99, "bottom": 0.08, "top": 0.91, "wspace": 0.3, "hspace": 0.3}
WEAK_MODE_MARGINS = {"left": 0.07, "right": 0.99, "bottom": 0.13, "top": 0.86, "wspace": 0.22}


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

    ok = reported_mask(table)
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
            fig.subplots_adjust(**HISTOGRAM_MARGINS)
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
    fig.subplots_adjust(**CRLB_MARGINS)
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


#: The weak mode's pairs (issue 39): a turn about the target's y axis (pitch) moves x, about x (roll) moves y.
WEAK_MODE_PAIRS = (("x_m", "pitch_deg"), ("y_m", "roll_deg"))


def _baseline_reported_and_range(table: dict):
    """The baseline's reported trials (mask, shape (rows,)) and every row's true range, m (the norm of
    ``true_x_m``, ``true_y_m``, ``true_z_m``)."""
    keep = reported_mask(table)
    if "variant" in table:
        keep &= np.array([str(v) == "baseline" for v in table["variant"]])
    R = np.linalg.norm(np.stack([np.asarray(table[f"true_{k}"], float) for k in ("x_m", "y_m", "z_m")], 1), axis=1)
    return keep, R


def weak_mode_statistics(table: dict, camera_key: str, paper: dict | None = None) -> dict:
    """How closely the position errors follow the weak mode of a narrow-field four-point solve
    (slide sideways by d, turn by d/R): x against R tan(pitch error), y against R tan(roll error).

    Parameters
    ----------
    table : dict of column -> ndarray
        A campaign's rows; the baseline's reported trials are used
        (:func:`svgs_sim.studies.error_budget.reported_mask`). R is the true range, m (the norm of
        ``true_x_m``, ``true_y_m``, ``true_z_m``).
    camera_key : str
        The phone (the paper's Tables 2 and 4 rows, by range).
    paper : dict, optional
        :func:`svgs_sim.assets.papers.svgs_2014_results`.

    Returns
    -------
    dict
        Per pair ``"x_m"`` / ``"y_m"``: ``corr`` (Pearson, simulated trials), ``slope`` (least
        squares through the origin of the position error on R tan(angle error)), ``n``, and
        ``paper_ratio`` (list of (range_m, the paper's mean position error / (R tan(its mean angle
        error))), one per range it has).
    """
    paper = svgs_2014_results() if paper is None else paper
    keep, R = _baseline_reported_and_range(table)
    out = {}
    for pos, ang in WEAK_MODE_PAIRS:
        e = np.asarray(table[f"err_{pos}"], float)[keep]
        w = (R * np.tan(np.radians(np.asarray(table[f"err_{ang}"], float))))[keep]
        good = np.isfinite(e) & np.isfinite(w)
        e, w = e[good], w[good]
        corr = float(np.corrcoef(e, w)[0, 1]) if e.size > 2 else float("nan")
        slope = float(np.dot(e, w) / np.dot(w, w)) if e.size and np.dot(w, w) > 0 else float("nan")
        pr = []
        for (ph, st, r), vals in sorted(paper.items()):
            if ph == camera_key and st == "mean_error":
                d = r * np.tan(np.radians(vals[ang]))
                pr.append((float(r), float(vals[pos] / d) if d > 0 else float("nan")))
        out[pos] = {"angle": ang, "corr": corr, "slope": slope, "n": int(e.size), "paper_ratio": pr}
    return out


def weak_mode_figure(table: dict, config: CampaignConfig, camera_key: str, paper: dict | None = None):
    """The weak mode (issue 39): per simulated trial the x error against R tan(pitch error) and
    the y error against R tan(roll error), coloured by range, with the paper's Table 2/4 means
    (magnitudes) as red squares; the line of slope 1 (dashed) and -1 (dotted) for reference.

    Returns
    -------
    (Figure, dict)
        The figure and :func:`weak_mode_statistics`.
    """
    from matplotlib.figure import Figure
    paper = svgs_2014_results() if paper is None else paper
    st = weak_mode_statistics(table, camera_key, paper)
    keep, R = _baseline_reported_and_range(table)
    fig = Figure(figsize=(10, 4.2))
    axes = fig.subplots(1, 2)
    for ax, (pos, ang) in zip(axes, WEAK_MODE_PAIRS):
        for r in config.ranges_m:
            m = keep & (np.asarray(table["nominal_range_m"], float) == r)
            w = R[m] * np.tan(np.radians(np.asarray(table[f"err_{ang}"], float)[m]))
            ax.plot(w, np.asarray(table[f"err_{pos}"], float)[m], ".", ms=3, alpha=0.6, label=f"{r:g} m (sim.)")
        pw = [(r * np.tan(np.radians(v[ang])), v[pos]) for (ph, s_, r), v in paper.items()
              if ph == camera_key and s_ == "mean_error"]
        if pw:
            ax.plot(*np.array(pw).T, "s", color="red", ms=6, label="paper, Tables 2/4 (means)")
        lim = max(np.nanmax(np.abs(ax.get_xlim())), np.nanmax(np.abs(ax.get_ylim())))
        ax.plot([-lim, lim], [-lim, lim], "k--", lw=0.8)
        ax.plot([-lim, lim], [lim, -lim], "k:", lw=0.8)
        ax.set_xlabel(f"R tan({SHORT[ang]} error) (m)")
        ax.set_ylabel(f"{SHORT[pos]} error (m)")
        ax.set_title(f"{SHORT[pos]} vs R tan({SHORT[ang]}): corr {st[pos]['corr']:+.2f}, slope {st[pos]['slope']:+.2f}",
                     fontsize=10)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7)
    fig.suptitle(f"{config.camera}: the weak mode of the four-point solve (slide by d, turn by d/R)")
    fig.subplots_adjust(**WEAK_MODE_MARGINS)
    return fig, st
