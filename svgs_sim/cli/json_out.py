"""``--json`` of the study commands: one JSON object on stdout, the text on stderr.

With ``--json`` a study command runs under :func:`text_to_stderr` (its tables, status lines
and progress go to stderr), then :func:`emit` prints exactly one JSON object on stdout and
writes the same object as ``summary.json`` in the study folder. :func:`clean` turns numpy
values into plain numbers and NaN or infinity into ``null``. :data:`SCHEMAS` documents each
command's object (``docs/cli.md`` shows them; ``tools/make_cli_doc.py``).

Light: imports only the standard library, numpy and :mod:`svgs_sim.base.jsonable` (a ``cli`` module is
imported to build the parser).
"""

from __future__ import annotations

import contextlib
import json
import sys
from pathlib import Path

from svgs_sim.base.jsonable import to_jsonable


def clean(obj):
    """``obj`` with numpy values as Python ones, tuples as lists, NaN/inf as None (JSON-safe):
    :func:`svgs_sim.base.jsonable.to_jsonable` with ``nonfinite="null"``."""
    return to_jsonable(obj, nonfinite="null")


def dumps(obj, **kw) -> str:
    """``json.dumps`` of :func:`clean` ``(obj)`` (strict JSON: no NaN)."""
    return json.dumps(clean(obj), allow_nan=False, **kw)


@contextlib.contextmanager
def text_to_stderr(enabled: bool):
    """While ``enabled``, what the command prints on stdout goes to stderr instead."""
    if not enabled:
        yield
        return
    with contextlib.redirect_stdout(sys.stderr):
        yield


def run_info(stats, n_trials: int) -> dict:
    """The ``run`` object: ``trials_run``, ``already_done``, ``elapsed_s``, ``executor``.

    ``stats`` is a :class:`svgs_sim.studies.execution.RunStats`, or None when all ``n_trials`` were
    already stored (then ``elapsed_s`` and ``executor`` are null)."""
    if stats is None:
        return {"trials_run": 0, "already_done": int(n_trials), "elapsed_s": None, "executor": None}
    return {"trials_run": int(stats.n_run), "already_done": int(stats.n_already_done),
            "elapsed_s": float(stats.elapsed_s), "executor": str(stats.executor)}


def failures_from_text(text) -> dict:
    """``{"reason": n}`` from a ``reason:n;reason:n`` cell (empty: no failure)."""
    out = {}
    for part in str(text or "").split(";"):
        if part.strip():
            k, _, n = part.rpartition(":")
            out[k] = int(n)
    return out


def emit(obj: dict, enabled: bool, out_dir=None) -> dict:
    """Write ``obj`` as ``out_dir/summary.json`` (when ``out_dir`` is given) and, when ``enabled``,
    print it on stdout as one line of JSON. Returns the cleaned object."""
    obj = clean(obj)
    if out_dir is not None:
        Path(out_dir, "summary.json").write_text(json.dumps(obj, indent=1, allow_nan=False) + "\n", encoding="utf-8")
    if enabled:
        print(json.dumps(obj, allow_nan=False), file=sys.stdout)
        sys.stdout.flush()
    return obj


_STATE = '{"x_m", "y_m", "z_m", "roll_deg", "pitch_deg", "yaw_deg"}'
_RUN = ('"run": {"trials_run": int, "already_done": int,\n'
        '        "elapsed_s": float | null, "executor": str | null}   # null: every trial was already stored')

_SOLUTION = f"""\
{{"ok": bool, "reason": str | null,          # reason: a code of svgs_sim.svgs.result.REASONS when unsolved
 "state": {_STATE} | null,   # paper state (m, deg)
 "R_cam_target": [[float x3] x3] | null, "t_cam_target_m": [float x3] | null,
 "targets_px": {{target: [u, v]}}, "n_blobs": int, "residual_rms_px": float | null,
 "chi2": float | null, "dof": int | null, "p_value": float | null,   # the consistency test (svgs_sim.svgs.app),
 "consistency_sigma_px": float | null, "alpha": float | null, "consistent": bool | null  # also for reason inconsistent"""
_ERRORS = ('"pos_err_vec_m": [float x3] | null, "att_err_vec_deg": [float x3] | null,\n'
           ' "pos_err_norm_m": float | null, "rot_err_deg": float | null')

_DETECTOR = ('"detector": {"camera_key": str | null, "threshold": float | str,   # 8-bit DN for the app\'s\n'
             '              "threshold_source": str,   # "app by_camera[KEY]", "app default" or "given"\n'
             '              "fitted_overlay": str | null}')   # the camera's overlay (fitted/KEY.toml)

#: The JSON object of each command's ``--json`` (for the study commands also DIR/summary.json), as
#: shown in docs/cli.md after the command's help.
SCHEMAS = {
    "svgs solve": f"""\
{_SOLUTION},
 {_DETECTOR},
 # solved: "iterations": int, "crlb_std": {{...state keys}}, "crlb_sigma_px": float,
 #   "outside_test_envelope": bool   # the pose lies outside the paper's test envelope (inside the physical one)
 # unsolved: "message": str, "details": {{...}}}}""",
    "svgs render": """\
{"out": {"flux", "truth", "preview", "raw", "image": path,    # raw, image: unless --no-expose
         "flux_diffuse", "points": path},                     # guided method: the film before the PSF
 "variant": str, "total_flux_photons_per_s": float, "targets_px": {target: [u, v]},
 "timings_s": {stage: float}}""",
    "svgs doctor": """\
{"ok": bool, "usable": bool, "python": str, "platform": str, "versions": {package: str | null},
 "llvm_candidates": [{"path", "major", "origin", "usable"}], "llvm_chosen": str | null,
 "llvm_min_major": int, "variant": {...} , "warning": str,   # or "error": str when unusable
 ...}                                                         # the backend's report""",
    "svgs render-and-solve": f"""\
{{"ok": bool, "reason": str | null, "message": str | null, "n_blobs": int,
 "outside_test_envelope": bool | null,         # solved outside the paper's test envelope (inside the physical one)
 "identified_px": {{target: [u, v]}} | null,   # the identified blobs (solved or inconsistent), delivered image px
 "sun_in_view": bool, "saturated_px": int,      # on orbit with --sun-deg only: the sun's disk in the image, full-scale px
 "truth_state": {_STATE}, "state": {{...}} | null,
 "exposure_s": float, "iso": float, "expose_s": float, "solve_s": float, "render_s": float,
 "residual_rms_px": float | null, "chi2": float | null, "chi2_dof": int | null,
 "p_value": float | null,                      # the consistency test (svgs_sim.svgs.app); reason "inconsistent" below alpha
 {_ERRORS},
 {_DETECTOR},
 "crlb": {{"centroid_sigma_px": float, "per_spot_sigma_px": {{target: [su, sv]}},
          "crlb_std": {{...state keys, m and deg}}}} | null,   # Cramer-Rao 1-sigma from the simulated sensor
 "outputs": {{file: path}}}}                  # with --out""",
    "svgs calibrate focal": """\
{"ok": true, "camera": str, "fx_px_before": float, "f_px": float, "sigma_f_px": float,
 "sigma_f_noise_px": float, "sigma_f_range_px": float, "centroid_sigma_px": float,
 "residual_sigma_px": float | null, "residual_rms_px": float, "dof": int,
 "consistency_chi2": float | null, "aspect": float, "iterations": int,
 "warnings": [str],   # images that disagree (chi2 p < 1 %: a wrong --range?), sigma_f > 5 %
 "per_image": [{...}], "skipped": [{"image", "reason"}], "out": path | null}""",
    "svgs calibrate board": """\
{"ok": true, "board": {"kind", "cols", "rows", "spacing_mm", ...}, "image_size": [w, h],
 "fx_px", "fy_px", "cx_px", "cy_px": float, "dist": {"k1", "k2", "p1", "p2", "k3"},
 "std": {...}, "rms_px": float, "constraints": {...}, "n_views": int,
 "per_view": [{"image", "rms_px", "n_points"}], "skipped": [{"image", "reason", "message"}],
 "warnings": [str], "out": path | null}""",
    "svgs calibrate render-board": """\
{"ok": true, "out": path, "n_views": int, "board": {"kind", "cols", "rows", "spacing_mm", ...},
 "intrinsics": {...}, "distortion": {"k1", "k2", "p1", "p2", "k3"}}""",
    "svgs tof solve": f"""\
{_SOLUTION},
 "n_frames": int, ...}}                      # the other keys as 'svgs solve'""",
    "svgs tof render-and-solve": f"""\
{_SOLUTION}, "n_frames": int,
 "truth_state": {_STATE}, {_ERRORS},
 "n_solved": int, "frame_statistics": {{"mean", "std", "min", "max", "fluctuation", "bias", "mean_abs_error", "rms", ...}},
 "integration_time_s": float, "ambient_lux": float, "modulation_frequency_hz": float,
 "render_s": float, "frames_s": float, "outputs": {{file: path}}}}""",
    "svgs tof stability": """\
{"range_m": float, "frames": int, "solved": int,
 "average", "maximum", "minimum", "fluctuation", "std", "truth":
     {"target_x_cam_mm", "target_y_cam_mm", "target_z_cam_mm", "roll_deg", "pitch_deg", "yaw_deg": float | null},
 "paper": {table: {statistic: {column: float}}},   # Tables 1 and 3 at 0.697 m, 2 at 5.712 m; {} elsewhere
 "ratio_to_paper": {table: {column: float}},       # our fluctuation / the paper's
 "within_2x": {table: {column: bool}},
 "failures": {reason: int}, "integration_time_s": float, "max_amplitude_lsb": float,
 "saturated_pixels": int, "rot_err_median_deg": float | null, "reference": "markers" | "plate",
 "noise_free": {"ok": bool, "centroid_err_rms_px", "centroid_err_max_px": float,   # the noise-free frame
                "pose_error": {column: float}},                                     # (the bias part)
 "spp": int, "rim_spp": int,                         # samples per pixel; on the marker rims
 "render_s": float, "frames_s": float,
 "outputs": {"frames", "summary", "plot": path}}     # with --out""",
    "svgs tof study": """\
{"stability": {range_m: <svgs tof stability object>},
 "mechanisms": [{"label": str, "range_m": float, "ratio_to_paper": {table: {column: float}},
                 "fluctuation": {column: float}, "solved": int}],
 "fig14": [{"range_m": float, "solved": int, "frames": int, "bias", "rms", "std": {column: float},
            "rot_err_rms_deg": float, "integration_time_s": float}],
 "failure_modes": {"flying_pixels_1m", "multipath_1m", "ambient_1m", ...}, "wall_s": float,
 "outputs": {"report", "csv", "series", "mechanisms", "fig14", "failure_modes": path}}""",
    "svgs sensor-model build": """\
{"ok": true, "camera": str, "nodes": int, "frames": int,
 "solved": int, "gross_errors": int, "wrong_locks": int,   # over every node's frames (solved: the core)
 "dropouts": {reason: int},
 "envelope": {"range_m": [lo, hi], "off_axis_deg_max": float, "attitude_deg_max": float},
 "outputs": {"table", "frames", "figure": path}}""",
    "svgs sensor-model validate": """\
{"camera": str, "frames": int, "seed": int, "command": str,
 "envelope": {"range_m": [lo, hi], "off_axis_deg_max": float, "attitude_deg_max": float},
 "outcomes": {outcome: {"observed": int, "model_mean": float,      # solved, gross_error, wrong_lock, reasons
                        "model_interval90": [lo, hi], "within": bool}},
 "errors": {state key: {"n_rendered": int, "ks_p": float, "scatter_ratio": float,
                        "scatter_ratio_interval90": [lo, hi],
                        "bands": [{"range_m": [lo, hi], "n_rendered": int, "ks_p": float}]}},
 "outcomes_within": bool, "ks_min_p": float | null}""",
    "svgs approach": f"""\
{{"camera": str, "preview": bool, "fps": float, "seed": int, "trajectory": str,
 "frames": int, "solved": int, "solved_fraction": float,
 "failures": {{reason: int}},                     # reasons of svgs_sim.svgs.result.REASONS
 "wrong_locks": int,                             # poses reported with a blob off its target's spot
 "solved_range_m": [float, float] | null,        # nearest and farthest solved frame
 "rms_by_range": [{{"range_m": [lo, hi | null], "frames": int, "solved": int,
                   "rms_err_<k>", "mean_err_<k>", "rms_crlb_<k>": float | null}}],   # k in {_STATE}
 "timing": {{"mean_render_s", "mean_optics_s", "mean_expose_s", "mean_solve_s",   # frames after the first
            "mean_crlb_s",                                  # over the solved frames
            "mean_frame_s", "frames_per_s": float | null}},
 "run": {{"frames_run": int, "frames_reused": int, "wall_s": float,
         "wall_per_frame_s": float | null}},   # wall time a frame after the first, pictures included
 "outputs": {{"measurements", "plot", "report", "video": path | null, "video_codec": str, "video_fps": float}}}}""",
    "svgs range-sweep": f"""\
{{"camera": str, "pattern": str, "trials_per_pose": int, "poses": int,
 "ranges": [{{"range_m": float, "trials": int, "solved": int, "success_rate": float,
             "failures": {{reason: int}},        # unsolved trials by reason
             "blobs_median": float, "four_blobs_rate": float, "merged_rate": float,
             "exposure_s": float, "iso": float,  # medians over the trials
             "bias": {_STATE},   # solved trials, mean of estimate - truth (m, deg)
             "std": {{...same keys}}}}],          # null where no trial solved
 "outputs": {{"summary_csv", "trials_jsonl", "plot", "overlays", "results_csv", "summary_json": path}},
 {_RUN}}}""",
    "svgs exposure-study": f"""\
{{"camera": str, "trials": int, "ranges_m": [float], "success_level": float,
 "remedies": [{{"remedy": str, "max_range_95_m": float | null,
               "ranges": [{{"range_m": float, "trials": int, "solved": int, "success_rate": float,
                           "failures": {{reason: int}}}}]}}],
 "outputs": {{"summary_csv", "summary_md", "trials_csv", "plot", "results_csv", "summary_json": path}},
 {_RUN}}}""",
    "svgs campaign": f"""\
{{"trial_kind": "render" | "geometric", "camera": str, "trials_per_range": int,
 "exposures_per_render": int, "stand_settings_per_range": int,
 "sigma_px": float | null,                                  # geometric trials only
 "calibration": "exact" | "paper", "calibration_error": {{name: float}},   # the solver's, relative to the true lens
 "true_lens": {{"lens_pp_u_px", "lens_pp_v_px", "lens_k1": float}},         # rendered, paper practice; else {{}}
 "focal_calibration": {{"f_px", "f_sigma_px", "f_true_px", "focal_error_frac": float,
                       "ranges_used_m", "ranges_measured_m": [float], "frames": [...]}} | null,
 "misalignment_deg": [roll, pitch, yaw], "budget": bool,
 "ranges": [{{"range_m": float, "trials": int,
             "solved": int, "success_rate": float,   # the paper's app: every solution reported
             "refused_by_consistency_test": int,     # of those, refused by the (optional) consistency test
             "failures": {{reason: int}},
             "mean_abs_error": {_STATE},   # three readings of the paper's "mean error" (not predictable,
             "abs_bias": {{...}}, "rms": {{...}},   # not scored): mean |e|, |mean e|, RMS
             "bias": {{...}}, "std": {{...}},
             "crlb_std": {{...}},                      # median Cramer-Rao bound of the solved trials
             "paper": {{"mean_error": {{...}} | null, "std": {{...}} | null}},   # Tables 2-5; null: no row
             "ratio": {{"mean_abs_error": {{...}}, "std": {{...}},                # simulated / paper
                       "abs_bias": {{...}}, "rms": {{...}}}}}}],
 "honest_count": {{...}} | null,    # DIR/honest_count.json: fitted cells, the std cells' counts
 "outputs": {{"results_csv", "summary_csv", "report", "summary_json": path}},
 {_RUN}}}""",
    "svgs sensitivity": f"""\
{{"camera": str, "method": "sobol" | "morris", "trial_kind": str, "n": int, "n_trials": int,
 "parameters": [{{"name": str, "low": float, "high": float, "unit": str, "needs_render": bool}}],
 "fixed": {{name: float}}, "failure_fraction": float, "render_groups": int,
 "indices": {{output: [{{"parameter": str,          # output: pos_err_norm_m, rot_err_deg, success (+ merge_margin_dn: render)
                       "S1", "S1_low", "S1_high", "ST", "ST_low", "ST_high": float}}]}},  # sobol
          # morris: "mu_star", "mu_star_low", "mu_star_high", "mu", "sigma"
 "ranking": {{output: [[parameter, ST or mu_star], ...]}},   # largest first
 "outputs": {{"results_csv", "indices_csv", "report", "summary_json": path}},
 {_RUN}}}""",
    "svgs merge-range": f"""\
{{"camera": str, "ranges_m": [float], "exposures": int,
 "nominal": {{"merge_range_m": float, "bound": "inside" | "below" | "above"}},   # below/above: beyond the grid
 "cases": [{{"case": str, "parameter": str, "value": float | null, "merge_range_m": float, "bound": str,
            "margin_dn": [float], "solved": [float]}}],      # per range of the grid
 "effects": [{{"parameter", "low", "high", "merge_range_low_m", "merge_range_high_m", "nominal_m", "span_m"}}],
 "outputs": {{"results_csv", "merge_ranges_csv", "report", "summary_json": path}},
 {_RUN}}}""",
    "svgs sun-study": """\
{"camera": str, "pattern": str, "trials_per_cell": int, "pose": str, "wrong_lock_px": str,
 "body": "plate" | "3u" | "none", "body_description": str,
 "earth": {"azimuth_deg", "elevation_deg", "altitude_km": float, "albedos": [float]} | null,
 "cells": [{"range_m": float, "earth_albedo": float,   # earth_albedo with the Earth only
            "sun_azimuth_deg": float, "sun_elevation_deg": float,
            "phase_angle_deg": float,       # target->sun against target->camera (head-on)
            "trials": int, "solved": int, "wrong_lock": int, "wrong_lock_flagged": int,
            "wrong_lock_paper_gates": int,   # the same images with the paper's test-envelope gates
            "reasons": {reason: int},        # solved + wrong_lock + sum(reasons) == trials
            "mechanisms": {"sun_in_fov", "lit_body", "glint", "saturation", "earth_background": int}}],
 "outputs": {"results_csv", "figure", "readme", "summary_json": path},
 "run": {"trials_run": int, "trials": int}}""",
    "svgs calibrate study": """\
{"config": {...},                  # every option of the study
 "key_numbers": {...},             # e.g. n_views_max, focal_only_error_pct
 "board_set": {...}, "timings_s": {part: float},
 "table4_exponents": {...}, "table4_conclusion": [str],
 "outputs": {name: path},          # report, summary, the CSV tables
 "run": {part: {"trials_run", "already_done", "elapsed_s", "executor"}}}   # parts run this time""",
}
