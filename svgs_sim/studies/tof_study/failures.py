"""The failure modes the ToF study demonstrates: flying pixels at a marker's edge, multipath off a
wall beside the target, 10 klux of ambient light (and their figure).

Part of :mod:`svgs_sim.studies.tof_study`.
"""

from __future__ import annotations

import numpy as np

from svgs_sim.sim.tof_closed_loop import noise_free_frame, pipeline, render, solve


def _depth_change(ra, rb) -> dict:
    """Depth change (mm) of the marker pixels (amplitude above 0.3 of the brightest) and of the
    other lit pixels between two renders of the same pose."""
    dd = (rb.depth_m - ra.depth_m) * 1e3
    amp = np.abs(ra.phasor_radiance)
    bright = amp > 0.3 * amp.max()
    plate = np.isfinite(dd) & ~bright & (amp > 0)
    return {"marker_depth_change_mm_median": float(np.nanmedian(dd[bright])),
            "marker_depth_change_mm_max": float(np.nanmax(np.abs(dd[bright]))),
            "plate_depth_change_mm_median": float(np.nanmedian(dd[plate])),
            "plate_depth_change_mm_p95": float(np.nanpercentile(np.abs(dd[plate]), 95))}


def _flying_pixels(camera, target, r1) -> tuple:
    """Rim pixels of the noise-free render ``r1`` whose phasor depth lies more than 5 mm from both
    the marker face and the plate behind it: (mask (H, W), count per marker)."""
    d1 = r1.depth_m
    ids = [str(int(i)) for i in target.ids]
    face_r = {k: v for k, v in r1.truth["targets_slant_range_m"].items()}
    mixed = np.zeros(d1.shape, bool)
    H, W = d1.shape
    vv, uu = np.mgrid[0:H, 0:W]
    rim_counts = {}
    for k, rad in zip(ids, target.radius_m):
        c = np.asarray(r1.truth["targets_px"][k])
        rr_px = rad * camera.fx / face_r[k]
        dist = np.hypot(uu - c[0], vv - c[1])
        ring = (dist > rr_px - 1.5) & (dist < rr_px + 1.5) & np.isfinite(d1)
        # the plate behind the marker rim lies ~ standoff further away
        far = face_r[k] + float(target.standoff_m[ids.index(k)])
        m = ring & (d1 > face_r[k] + 0.005) & (d1 < far - 0.005)
        mixed |= m
        rim_counts[k] = int(m.sum())
    return mixed, rim_counts


#: A bright wall standing out of the plate beside the markers (a part of the spacecraft).
WALL = {"type": "box", "lo_m": [0.205, -0.16, 0.0], "hi_m": [0.215, 0.16, 0.30], "albedo": 0.8}


def failure_modes(cfg, camera, target, png_path) -> dict:
    """Flying pixels at the marker rims, multipath from the plate and from a wall, 10 klux: measured
    at 1 m head-on (renders of :mod:`svgs_sim.sim.tof_closed_loop` with the study's settings)."""

    res = {}
    one, two = (render(cfg.scenario(1.0, max_bounces=b)) for b in (1, 2))
    w1, w2 = (render(cfg.scenario(1.0, scene={"distractors": [WALL]}, max_bounces=b)) for b in (1, 2))
    r1, r2, rw1, rw2 = one.rendered, two.rendered, w1.rendered, w2.rendered
    mixed, rim_counts = _flying_pixels(camera, target, r1)
    res["flying_pixels_1m"] = {"count": int(mixed.sum()), "per_marker": rim_counts,
                               "note": "noise-free depth more than 5 mm from both the marker face and the plate behind it"}
    # multipath: depth change of marker and plate pixels with a second bounce
    res["multipath_1m"] = _depth_change(r1, r2)
    res["multipath_wall_1m"] = {**_depth_change(rw1, rw2), "wall": WALL}
    d1 = r1.depth_m
    ddw = (rw2.depth_m - rw1.depth_m) * 1e3
    amp = np.abs(r1.phasor_radiance)
    bright = amp > 0.3 * amp.max()
    plate = np.isfinite(d1) & ~bright & (amp > 0)
    # pose change from multipath (noise-free)
    for label, tr in (("direct", one), ("multipath", two), ("wall_direct", w1), ("wall_multipath", w2)):
        sol = solve(tr, 0, noise_free_frame(tr), pipeline(tr)).solution
        res[f"pose_noise_free_{label}"] = ({f"target_{a}_cam_mm": float(sol.t_cam_target_m[i] * 1e3) for i, a in enumerate("xyz")}
                                           if sol else {"failed": sol.reason})
    amb = {}
    for lux in (1000.0, 10000.0):
        sen = one.sensor.replace(ambient_lux=lux)
        d = np.stack([f.depth_m for f in sen.frames(r1, 30, [cfg.seed, 3])]).astype(float)  # per-pixel depth noise
        sel = bright & np.all(np.isfinite(d), axis=0)
        sel_plate = plate & np.all(np.isfinite(d), axis=0)
        amb[str(int(lux))] = {"marker_depth_std_mm": float(np.median(np.std(d[:, sel], axis=0)) * 1e3) if sel.any() else None,
                              "plate_depth_std_mm": float(np.median(np.std(d[:, sel_plate], axis=0)) * 1e3) if sel_plate.any() else None,
                              "plate_valid_fraction": float(np.mean(np.isfinite(d[:, plate]))) if plate.any() else None}
    res["ambient_1m"] = amb
    _plot_failure_modes(png_path, r1, d1, mixed, ddw, amb)
    return res


def _plot_failure_modes(png_path, r1, d1, mixed, ddw, amb) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 3, figsize=(13, 4.2))
    c6 = np.asarray(r1.truth["targets_px"]["7"])
    x0, x1 = int(c6[0] - 30), int(c6[0] + 30)
    y0, y1 = int(c6[1] - 30), int(c6[1] + 30)
    im = ax[0].imshow(d1[y0:y1, x0:x1], cmap="viridis", interpolation="nearest")
    yy, xx = np.nonzero(mixed[y0:y1, x0:x1])
    ax[0].plot(xx, yy, "r.", ms=3, label="flying pixels")
    ax[0].set_title("depth at 1 m around marker 7 (m)\nred: between face and plate")
    ax[0].legend(fontsize=7, loc="lower right")
    fig.colorbar(im, ax=ax[0], fraction=0.046)
    lim = max(1.0, float(np.nanpercentile(np.abs(ddw[np.isfinite(ddw)]), 99)))
    im = ax[1].imshow(np.clip(ddw, -lim, lim), cmap="coolwarm", vmin=-lim, vmax=lim, interpolation="nearest")
    ax[1].set_title("multipath, white wall beside the markers:\ndepth(2 bounces) - depth(1), mm", fontsize=9)
    fig.colorbar(im, ax=ax[1], fraction=0.046)
    labels = list(amb)
    w = 0.35
    xs = np.arange(2)
    for j, lux in enumerate(labels):
        ax[2].bar(xs + (j - 0.5) * w, [amb[lux]["marker_depth_std_mm"] or 0, amb[lux]["plate_depth_std_mm"] or 0], w,
                  label=f"{lux} lux")
    ax[2].set_xticks(xs, ["marker pixels", "plate pixels"])
    ax[2].set_ylabel("per-pixel depth noise, mm (median)")
    ax[2].set_yscale("log")
    ax[2].set_title("ambient light at 1 m")
    ax[2].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(png_path, dpi=110)
    plt.close(fig)
