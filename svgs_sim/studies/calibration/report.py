"""The calibration study's report: CSV tables, ``summary.json``, a self-contained
``report.html`` (:class:`svgs_sim.studies.report.Report`) and the text summary the CLI prints.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from svgs_sim.base.errors import InputError
from svgs_sim.base.profiles import DISTORTION_KEYS
from svgs_sim.studies.execution import library_versions
from svgs_sim.studies.report import Report, write_csv

from .common import (
    GEOMETRIC_CENTROID_NOISE_PX,
    POSE_SPREAD,
    REPORT_RANGES_M,
    STATE_COLS,
    row_at,
)
from .figures import fig_convergence, fig_focal, fig_pose, fig_table4
from .table4 import table4_conclusion

#: Columns of ``calibration_convergence.csv``.
CONVERGENCE_CSV_COLUMNS = ["n_views", "subset", "fx_px", "fy_px", "cx_px", "cy_px", *DISTORTION_KEYS, "fx_error_pct",
                           "fy_error_pct", "pp_error_u_px", "pp_error_v_px", "pp_error_norm_px", "map_rms_px",
                           "map_max_px", "map_rot_rms_px", "map_rot_max_px", "rms_px", "std_fx_px", "std_cx_px", "views"]
#: Columns of ``focal_method.csv``.
FOCAL_CSV_COLUMNS = ["ranges", "n_ranges", "added_noise_px", "n_estimates", "mean_err_pct", "rms_err_pct",
                     "max_abs_err_pct", "reported_sigma_pct", "chi2_per_dof"]
#: Columns of ``pose_errors.csv``.
POSE_CSV_COLUMNS = ["group", "case", "range_m", "noise_px", "n_poses", "n_failed", *STATE_COLS, "mean_z_m", "pos_err_norm_m",
                    "pos_err_max_m", "pos_err_rel_pct", "rot_err_deg"]
#: Columns of ``cameras.csv``.
CAMERA_CSV_COLUMNS = ["camera", "width", "height", "fx", "fy", "cx", "cy", *DISTORTION_KEYS]


def _columns(rows) -> list:
    return list(dict.fromkeys(k for r in rows for k in r))


def focal_frame_rows(result) -> list[dict]:
    """Per focal range: the frame's description and its centroid scatter."""
    return [{**info, **nz} for info, nz in zip(result.focal_frames.info, result.centroid_noise)]


def study_summary(result) -> dict:
    """What ``summary.json`` holds: configuration, key numbers, board set, timings, Table 4."""
    t4 = result.table4
    return {"config": result.config, "key_numbers": result.key_numbers(), "board_set": result.board_set_info,
            "timings_s": result.timings_s, "table4_exponents": t4.get("exponents", {}),
            "table4_conclusion": table4_conclusion(result)}


def write_tables(result, out: Path) -> dict:
    """Write the CSV tables and ``summary.json`` into ``out``; name -> path."""

    files = {}
    files["calibration_convergence"] = write_csv(out / "calibration_convergence.csv", CONVERGENCE_CSV_COLUMNS,
                                                 result.convergence_rows)
    sum_cols = list(result.convergence[0]) if result.convergence else []
    files["calibration_convergence_summary"] = write_csv(out / "calibration_convergence_summary.csv", sum_cols,
                                                         result.convergence)
    files["focal_method"] = write_csv(out / "focal_method.csv", FOCAL_CSV_COLUMNS, result.focal_rows)
    fr_rows = focal_frame_rows(result)
    files["focal_frames"] = write_csv(out / "focal_frames.csv", _columns(fr_rows), fr_rows)
    files["pose_errors"] = write_csv(out / "pose_errors.csv", POSE_CSV_COLUMNS, result.pose_rows)
    t4 = result.table4
    if t4.get("rows"):
        t4_cols = ["range_m", "component", "paper_mean_error", *t4["cases"]]
        files["table4_comparison"] = write_csv(out / "table4_comparison.csv", t4_cols, t4["rows"])
    files["cameras"] = write_csv(out / "cameras.csv", CAMERA_CSV_COLUMNS,
                                 [{"camera": k, **v} for k, v in result.believed.items()])
    files["summary"] = out / "summary.json"
    with open(files["summary"], "w", encoding="utf-8") as fh:
        json.dump(study_summary(result), fh, indent=1, default=float)
    return files


def _section_setup(rep, result) -> None:
    c = result.config
    rep.paragraph(
        f"The profile '{c['camera']}' is the nominal camera a paper-style calibration believes. The study's true "
        f"camera adds a principal-point offset of {c['true_pp_offset_px']} px and distortion {c['true_dist']} "
        "(k1, k2, p1, p2, k3) - ASSUMPTIONS standing for a real phone's unknown lens (one sigma of the spreads "
        "'svgs campaign --calibration paper' draws). Every image of the study is made with the true camera.")
    cams = [{"camera": k, **v} for k, v in result.believed.items()]
    rep.table(CAMERA_CSV_COLUMNS, cams, caption="Cameras: the truth, the nominal profile, and what each calibration believes",
              digits=6)
    bi = result.board_set_info
    rep.bullets([f"{k}: {v}" for k, v in bi.items() if k not in ("render", "skipped")]
                + [f"skipped views: {', '.join(bi.get('skipped', [])) or 'none'}"]
                + ([f"render: {json.dumps(bi['render'])}"] if "render" in bi else [])
                + [f"pose study: {c['poses_per_range']} poses per range (the first facing the camera on the boresight; "
                   f"others roll/pitch/yaw within +-{POSE_SPREAD['roll_deg']:g}/{POSE_SPREAD['pitch_deg']:g}/"
                   f"{POSE_SPREAD['yaw_deg']:g} deg, lateral offsets within {100 * POSE_SPREAD['lateral_fraction']:g} % "
                   "of the range; ASSUMPTION: the paper does not list its test attitudes)",
                   f"timings (s): {json.dumps({k: round(v, 1) for k, v in result.timings_s.items()})}"])


def _section_convergence(rep, result) -> None:
    c = result.config
    sum_cols = list(result.convergence[0]) if result.convergence else []
    rep.heading("1. Full calibration from N views: convergence to the truth")
    rep.paragraph(
        "OpenCV calibration (fx, fy, cx, cy, k1, k2, p1, p2, k3, no constraints) from N views of the board, N in "
        f"{c['views_list']}; the first subset is views 0..N-1, the others random. Mapping error: over a pixel grid, "
        "how far the estimated camera puts each ray the true camera sees there (calibration.mapping_error_px); "
        "'after best rotation' removes the small camera rotation that absorbs most of a principal-point error "
        "(which the solver sees as an attitude bias instead).")
    rep.figure(fig_convergence(result), "Errors of the recovered intrinsics versus the number of views.")
    rep.table(sum_cols, result.convergence, caption="Per N: mean and worst absolute errors over the subsets")
    rep.table(CONVERGENCE_CSV_COLUMNS[:-1], result.convergence_rows, caption="Every calibration", digits=4)


def _section_focal(rep, result) -> None:
    c = result.config
    fr_rows = focal_frame_rows(result)
    rep.heading("2. The paper's focal-length method on images of the target")
    rep.paragraph(
        ("Images of the SVGS target facing the camera at each range, rendered (svgs_sim.sim.closed_loop.render_scenario: "
         "corner cubes under the phone's flash, the phone's auto-exposure, noise and ISP), "
         f"{c['focal_exposures']} exposures per range; spots found by svgs_sim.svgs.detect and labelled by svgs_sim.svgs.identify with "
         "the nominal camera."
         if not c["geometric"] else
         f"Projected target points with Gaussian noise ({GEOMETRIC_CENTROID_NOISE_PX} px) - no render.")
        + " calibration.estimate_focal then fits the focal length with the nominal camera's principal point and no "
        "distortion, as the paper's method would. Ranges are exact (a range error scales f by the same factor).")
    rep.table(_columns(fr_rows), fr_rows, caption="Focal frames: identification, exposure and centroid scatter per range")
    rep.figure(fig_focal(result), "Left: RMS focal length error versus ranges used and centroid noise added. Right: "
               "each image's own estimate (1 sigma) and the combined estimate (the focal-only calibration).")
    rep.table(FOCAL_CSV_COLUMNS, result.focal_rows, caption="Focal method: error against the true fx (%)")
    fe = result.focal_estimate
    fk = 100.0 * (fe.per_image_f_px / result.camera_true.fx - 1.0)
    scat = [r["exposure_scatter_px"] for r in result.centroid_noise if np.isfinite(r["exposure_scatter_px"])]
    base = np.ptp(result.focal_frames.truth_px[:, :, 1], axis=1)  # targets 1-2 baseline, px
    rng_idx = [int(np.argmin(np.abs(result.focal_frames.ranges_m - r))) for r in fe.ranges_m]
    rep.paragraph(
        f"Per-image estimates scatter by {np.sqrt(np.mean(fk**2)):.2f} % RMS about the truth; on the long baseline "
        f"that is {np.sqrt(np.mean((fk / 100.0 * base[rng_idx]) ** 2)):.2f} px RMS of spacing error per frame, while "
        f"repeated exposures of one frame scatter by only {np.mean(scat) if scat else float('nan'):.3f} px per axis: "
        "the centroids carry per-frame errors that exposing again does not average out (in a render: the sampled "
        "spot image and the spot's shape at the phone's exposure; on a real phone: the spot itself). The spots sit "
        "'offset_from_truth_px' from the targets' projections, falling as 1/range - the parallax of the flash LED "
        "beside the lens, the same for every spot, so spacings and the focal length do not see it.")
    rep.preformatted(fe.summary())


def _section_pose(rep, result) -> None:
    rep.heading("3. Pose error caused by calibration error (centroid level, no noise)")
    rep.paragraph(
        "Centroids projected with the true camera are solved (svgs.solve_centroids) with a camera wrong in one way, "
        "or with what each calibration found; the errors are biases (no noise), mean over the poses at each range.")
    cases = list(dict.fromkeys(r["case"] for r in result.pose_rows if r["noise_px"] == 0))
    single = [k for k in cases if k != "exact" and not k.startswith(("focal-only", "full"))]
    rep.figure(fig_pose(result, single), "Single calibration errors: position and attitude error versus range.")
    calib = [k for k in cases if k.startswith(("focal-only", "full"))]
    rep.figure(fig_pose(result, calib), "The calibrations: focal-only (the paper's) versus full (OpenCV, N views).")
    tab = []
    for case in cases:
        if case == "exact":
            continue
        row = {"case": case}
        for rng in REPORT_RANGES_M:
            r = row_at(result.pose_rows, case, rng)
            if r and "pos_err_norm_m" in r:
                row[f"{rng:g} m: position (m)"] = r["pos_err_norm_m"]
                row[f"{rng:g} m: Z bias (m)"] = r["mean_z_m"]
                row[f"{rng:g} m: attitude (deg)"] = r["rot_err_deg"]
        tab.append(row)
    tcols = ["case"] + [f"{rng:g} m: {q}" for rng in REPORT_RANGES_M for q in ("position (m)", "Z bias (m)", "attitude (deg)")]
    rep.table(tcols, tab, caption="Pose error from calibration error alone at 5, 10, 20 and 30 m (mean over poses)")
    noisy = []
    for r in result.pose_rows:
        if r["noise_px"] > 0 and r["range_m"] in REPORT_RANGES_M and "pos_err_norm_m" in r:
            noisy.append(r)
    rep.table(["case", "noise_px", "range_m", *STATE_COLS, "pos_err_norm_m", "rot_err_deg"], noisy,
              caption="With centroid noise: exact intrinsics versus the two calibrations (mean absolute errors)")


def _section_table4(rep, result) -> None:
    t4 = result.table4
    tm = (t4.get("tables") or ["Table 4"])[0]
    rep.heading(f"4. Could calibration error explain the growth of error with range in the paper's {tm}?")
    rep.figure(fig_table4(result), f"The paper's {tm} mean errors beside the calibration biases (no noise) and "
               "the noise floor (exact intrinsics with centroid noise).")
    if t4.get("exponents"):
        ecols = ["source", *STATE_COLS]
        rep.table(ecols, [{"source": k, **v} for k, v in t4["exponents"].items()],
                  caption="Growth exponent p of error ~ range^p (log-log least squares over the ranges)", digits=2)
    if t4.get("rows"):
        rep.table(["range_m", "component", "paper_mean_error", *t4["cases"]], t4["rows"],
                  caption=f"{tm} (mean error) beside the study's mean absolute errors at the paper's ranges")
    for s in table4_conclusion(result):
        rep.paragraph(s)


def write_report(result, out_dir, command: str | None = None) -> dict:
    """Write ``report.html`` (self-contained), the CSV tables and ``summary.json`` into ``out_dir``.

    Parameters
    ----------
    result : svgs_sim.studies.calibration.StudyResult
    out_dir : str or Path
    command : str, optional
        The command line shown in the report.

    Returns
    -------
    dict
        Name -> path of each file written.
    """

    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {str(out)!r} exists and is not a folder")
    out.mkdir(parents=True, exist_ok=True)
    c = result.config
    files = write_tables(result, out)
    mode = "geometric images (no render)" if c["geometric"] else "rendered images (Mitsuba + phone model)"
    rep = Report(f"Calibration study: {c['camera']} - {mode}", command, library_versions())
    rep.heading("Summary")
    rep.preformatted(summary_text(result))
    _section_setup(rep, result)
    _section_convergence(rep, result)
    _section_focal(rep, result)
    _section_pose(rep, result)
    _section_table4(rep, result)
    files["report"] = rep.write(out / "report.html")
    return {k: str(v) for k, v in files.items()}


def summary_text(result) -> str:
    """The short text summary ``svgs calibrate study`` prints."""
    c, tr = result.config, result.camera_true
    kn = result.key_numbers()
    lines = [
        f"calibration study: camera {c['camera']} ({'geometric images, no render' if c['geometric'] else 'rendered'}); "
        f"true camera: principal point offset {c['true_pp_offset_px']} px, distortion + {c['true_dist']}",
        f"1) full calibration ({result.board_set_info['board']}), worst of {c['subsets']} subsets per N:",
    ]
    for r in result.convergence:
        lines.append(
            f"   N = {r['n_views']:3d}: |fx err| <= {r['fx_error_pct_max_abs']:.3f} %, "
            f"|fy err| <= {r['fy_error_pct_max_abs']:.3f} %, "
            f"pp err <= {r['pp_error_norm_px_max']:.2f} px, "
            f"mapping error (after rotation) RMS <= {r['map_rot_rms_px_max']:.3f} px "
            f"(raw {r['map_rms_px_mean']:.3f} px)")
    ok = (kn["fx_error_pct_max_abs"] <= 0.2 and kn["fy_error_pct_max_abs"] <= 0.2 and kn["pp_error_norm_px_max"] <= 1.0
          and kn["map_rot_rms_px_max"] < 0.1)
    lines.append(f"   acceptance at N = {kn['n_views_max']} (fx, fy within 0.2 %, pp within 1 px, mapping < 0.1 px): "
                 f"{'met' if ok else 'NOT met'}")
    fe = result.focal_estimate
    err = kn["focal_only_error_pct"]
    lines.append(f"2) paper's focal method ({len(fe.per_image)} images, {min(fe.ranges_m):g}-{max(fe.ranges_m):g} m): "
                 f"f = {fe.f_px:.2f} +- {fe.sigma_f_px:.2f} px, true fx {tr.fx:.2f} px: error {err:+.3f} % "
                 f"({'within' if abs(err) <= 1 else 'NOT within'} 1 %)")
    worst = max(result.focal_rows, key=lambda r: r["rms_err_pct"])
    lines.append(f"   fewer ranges / noisier centroids: RMS error up to {worst['rms_err_pct']:.2f} % "
                 f"({worst['ranges']}, +{worst['added_noise_px']:g} px noise)")
    full = f"full calibration ({c['views_list'][-1]} views)"
    lines.append("3) pose error from calibration alone (no noise), mean over poses: position m / attitude deg")
    for rng in REPORT_RANGES_M:
        a = row_at(result.pose_rows, "focal-only calibration (paper)", rng)
        b = row_at(result.pose_rows, full, rng)
        if a and b and "pos_err_norm_m" in a and "pos_err_norm_m" in b:
            lines.append(f"   {rng:4g} m: focal-only {a['pos_err_norm_m']:.3f} m / {a['rot_err_deg']:.2f} deg;  "
                         f"{full} {b['pos_err_norm_m']:.4f} m / {b['rot_err_deg']:.3f} deg")
    lines.append(f"{(result.table4.get('tables') or ['Paper'])[0]}: " + table4_conclusion(result)[-1])
    return "\n".join(lines)

