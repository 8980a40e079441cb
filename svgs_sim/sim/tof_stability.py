"""The ToF paper's stability runs (Zhu et al. 2022, Tables 1-3) on the rendered camera.

Render the target once at a pose, draw N noisy frames from that render and run them in
sequence through one :class:`svgs_sim.tof.TofPipeline` - the frame loop of :mod:`svgs_sim.sim.tof_closed_loop`;
the statistics of the solved poses per component are the paper's (average, maximum, minimum,
fluctuation range = maximum - minimum) plus the standard deviation. ``svgs tof stability``
(:mod:`svgs_sim.cli.tof_stability`; also ``python -m svgs_sim.cli.tof_stability``) is the command; the ToF
study runs the same frames as trials of the ``tof`` kind (:mod:`svgs_sim.sim.tof_trial`).

Columns (:data:`COLUMNS`; the paper's Tables 1-3 in its order)
    ``target_x_cam_mm, target_y_cam_mm, target_z_cam_mm``: the target's reference point in the
    camera frame (OpenCV axes: x right, y down, z along the boresight; not the state's
    ``x_m, y_m, z_m``, which are the camera in the target frame); ``roll_deg, pitch_deg,
    yaw_deg``: the paper state's angles (:func:`svgs_sim.svgs.frames.pose_to_state`: an x-y-z
    sequence, roll about the target's x axis, pitch about its y axis, yaw about its z axis, the
    plate normal), unwrapped next to the truth. The paper calls them pitch, yaw, roll
    (:data:`PAPER_COLUMNS`): its "pitch" is our roll (about the horizontal x axis), its "yaw" our
    pitch (about the vertical y axis) and its "roll" our yaw, the rotation about the line of sight
    (the boresight, at the near head-on poses of its tables). Its roll is the angle it measures
    best (section 6.4: "high precision appears in the roll angle measurements") and the one its
    Table 2 has the smallest scatter in (0.116 deg, against 0.518 and 0.294), as our yaw.

Reference point and target frame (ASSUMPTION argued from the paper)
    The paper's measurement model (section 2.3) is ``r_i = R p_i + t`` with ``t`` "the position
    of the origin of the target frame with respect to the ToF frame": its tables report the
    catalog frame's origin, which it does not place. Its experiment (section 6.1) aligns "the
    center of the target" with the ToF and knows "the center distance from the camera". Its
    Table 2 (5712 mm) bounds where that origin lies: a point ``h`` in front of or behind the
    rotation's centre (for an SVD fit of the marker points, their centroid) along the line of
    sight moves across it by ``h x tan(angle)``; its y
    fluctuates 0.321 mm while its pitch (about x) fluctuates 0.518 deg, so
    ``h <= 0.321 / tan(0.518 deg) = 35.5 mm`` (its x, 0.185 mm, against its yaw, 0.294 deg, about
    y: 36.1 mm). The reported point lies within ~3.5 cm of the marker faces' centroid along the
    line of sight, not at the plate 125 mm behind it. So the target frame of ``tof-8``
    (``assets/patterns/tof-8.toml``) has its origin at the centroid of the eight marker faces (the
    plate's front face at ``[plate] centre_m``, 125 mm behind), and the pose this module places
    and the pipeline solves is that origin's: ``range_m`` is the boresight distance to it.
    ``reference="markers"`` (default) reports the centroid of the eight marker faces (the origin
    of ``tof-8``); ``"plate"`` the centre of the plate's front face, whose x and y pick up the tilt
    noise.

Scenarios
    At the paper's two ranges (697 and 5712 mm, within 5 mm) the truth is the paper's average
    pose of Table 1 / Table 2 (its target origin at the paper's average x, y, z) and the paper's
    statistics are attached; this takes the real sensor's mean error as small (the paper gives
    no truth for these runs, only its measured averages). At any other range the target faces the
    camera on the boresight and no paper figures are attached.
"""

from __future__ import annotations

import time

import numpy as np

from svgs_sim.assets.papers import tof_2022_stability
from svgs_sim.base.errors import InputError
from svgs_sim.sim.metrics import ROT_ERR_DEG, state_m_deg
from svgs_sim.sim.tof_closed_loop import TofScenario, noise_free_frame, pipeline, solve, solve_frames

#: Our columns, in the paper's order (see the module docstring).
COLUMNS = ("target_x_cam_mm", "target_y_cam_mm", "target_z_cam_mm", "roll_deg", "pitch_deg", "yaw_deg")
#: The paper's names of the same columns, position by position (its "pitch" is our roll, about x;
#: its "roll" our yaw, about the line of sight).
PAPER_COLUMNS = ("x_mm", "y_mm", "z_mm", "pitch_deg", "yaw_deg", "roll_deg")
#: Statistics of the paper's tables (and ours), plus the standard deviation (ours only).
STATISTICS = ("average", "maximum", "minimum", "fluctuation")
#: The paper's average poses (Table 1 at 697 mm, Table 2 at 5712 mm): t (mm, the target origin in the OpenCV
#: camera frame) and (roll, pitch, yaw) deg of our state (the paper's pitch, yaw, roll).
SCENARIOS = {
    697: {"tables": ("1", "3"), "t_mm": (2.193, -10.457, 697.604), "angles_deg": (-0.382, -2.653, -2.528)},
    5712: {"tables": ("2",), "t_mm": (5.097, -2.381, 5712.362), "angles_deg": (3.823, 1.324, -2.053)},
}
#: Most frames one stability run draws (about 50 ms each on one core: ~17 min).
MAX_FRAMES = 20000
#: Reference points of the position columns.
REFERENCES = ("markers", "plate")


def paper_range_mm(range_m: float):
    """The paper's range (697 or 5712, mm) within 5 mm of ``range_m``, else None."""
    r_mm = float(range_m) * 1e3
    return next((key for key in SCENARIOS if abs(r_mm - key) <= 5.0), None)


def stability_scenario(range_m: float, **kw):
    """The stability run's scenario at ``range_m``: the paper's average pose within 5 mm of its
    two ranges, else head-on on the boresight.

    Parameters
    ----------
    range_m : float
    **kw
        Other :class:`svgs_sim.sim.tof_closed_loop.TofScenario` fields (camera, pattern, seed, spp...).

    Returns
    -------
    svgs_sim.sim.tof_closed_loop.TofScenario
    """

    key = paper_range_mm(range_m)
    if key is not None:
        return TofScenario.from_pose_mm(SCENARIOS[key]["t_mm"], SCENARIOS[key]["angles_deg"], **kw)
    return TofScenario(range_m=float(range_m), **kw)


def paper_tables(range_m: float) -> tuple:
    """The paper's table ids at ``range_m`` (empty off its ranges)."""
    key = paper_range_mm(range_m)
    return SCENARIOS[key]["tables"] if key is not None else ()


def reference_point_m(target, reference: str = "markers") -> np.ndarray:
    """The reported point in the target frame, shape (3,): the marker faces' centroid (``tof-8``:
    its origin) or the centre of the plate's front face (``target.plate_centre_m``)."""
    if reference not in REFERENCES:
        raise InputError(f"reference: expected one of {REFERENCES}, got {reference!r}")
    if reference == "markers":
        return np.asarray(target.points_m, float).mean(0)
    return np.asarray(target.plate_centre_m, float)


def pose_columns(R, t, truth_state, state_err_m_deg=None, point_m=None) -> np.ndarray:
    """The six :data:`COLUMNS` of one pose, shape (6,): the point (mm) and the angles (deg).

    Parameters
    ----------
    R, t : R_cam_target (3, 3), t_cam_target_m (3,)
        The pose whose reference point is reported.
    truth_state : (6,)
        The true paper state (m, rad).
    state_err_m_deg : (6,), optional
        :func:`svgs_sim.sim.metrics.state_error` of the pose against the truth; the angles are the
        truth's plus its wrapped angle errors (None: the truth's angles).
    point_m : (3,), optional
        Reported point in the target frame (default the origin).
    """

    p = np.zeros(3) if point_m is None else np.asarray(point_m, float)
    pos = np.asarray(R, float) @ p + np.asarray(t, float)
    err = np.zeros(3) if state_err_m_deg is None else np.asarray(state_err_m_deg, float)[3:]
    # (truth + (err + 180)) - 180: the association these columns have had since issue 23 (the
    # wrapped difference added before its -180), kept so the committed report does not move by
    # 1e-14 deg; err + 180 is exact for |err| < 90 deg
    ang = (state_m_deg(truth_state)[3:] + (err + 180.0)) - 180.0
    return np.concatenate([pos * 1e3, ang])


def statistics(cols) -> dict:
    """average / maximum / minimum / fluctuation / std per column of ``cols`` (K, 6); NaN when K == 0."""
    C = np.asarray(cols, float).reshape(-1, 6)
    if C.shape[0] == 0:
        nan = np.full(6, np.nan)
        return {k: nan for k in (*STATISTICS, "std")}
    return {"average": C.mean(0), "maximum": C.max(0), "minimum": C.min(0), "fluctuation": C.max(0) - C.min(0),
            "std": C.std(0)}


def paper_statistics(range_mm) -> dict:
    """The paper's tables at a range: ``{table_id: {statistic: {column: value}}}`` under our
    :data:`COLUMNS` (empty off its ranges)."""

    if range_mm is None:
        return {}
    out = {}
    for row in tof_2022_stability():
        if int(row["range_mm"]) == int(range_mm):
            out.setdefault(row["table"], {})[row["statistic"]] = {c: float(row[pc]) for c, pc in zip(COLUMNS, PAPER_COLUMNS)}
    return out


def frame_row(result, tof_render, point_m) -> dict:
    """One solved (or failed) frame as a row: ``frame, ok, reason, n_blobs, iterations``, the
    :data:`COLUMNS` (None when unsolved), ``rot_err_deg`` (:mod:`svgs_sim.sim.metrics`) and
    ``saturated_pixels``.

    Parameters
    ----------
    result : svgs_sim.sim.tof_closed_loop.TofFrameResult
    tof_render : svgs_sim.sim.tof_closed_loop.TofRender
    point_m : (3,)
        :func:`reference_point_m`.
    """

    res = result.solution
    row = {"frame": result.frame, "ok": bool(res), "reason": None if res else res.reason,
           "n_blobs": res.n_blobs if res else res.details.get("n_blobs"),
           "iterations": int(res.iterations) if res else None}
    if res:
        c = pose_columns(res.R_cam_target, res.t_cam_target_m, tof_render.truth_state, result.state_err, point_m)
        row.update(dict(zip(COLUMNS, c.tolist())))
    else:
        row.update({c: None for c in COLUMNS})
    row.update({"rot_err_deg": result.errors[ROT_ERR_DEG], "saturated_pixels": result.saturated_pixels})
    return row


#: Keys of :func:`run_info` (the run-level values, the same for every frame of a run).
RUN_INFO_KEYS = ("integration_time_used_s", "max_amplitude_lsb", "spp_used", "rim_spp_used", "render_s",
                 *(f"truth_{c}" for c in COLUMNS), "nf_ok", "nf_reason", "nf_centroid_err_rms_px",
                 "nf_centroid_err_max_px", *(f"nf_err_{c}" for c in COLUMNS))


def run_info(tof_render, overrides, point_m) -> dict:
    """The run-level values of a stability run (:data:`RUN_INFO_KEYS`): the noise-free frame's
    integration time (automatic or the sensor's) and brightest amplitude, the render's sample counts and time, the truth's
    columns and the noise-free frame through the pipeline (``nf_*``: the centroid errors against
    the projected face centres, px, and the pose error per column - the bias part of the
    single-frame error)."""

    clean = noise_free_frame(tof_render)
    truth = tof_render.truth_state
    R, t = tof_render.R_cam_target, tof_render.t_cam_target_m
    tc = pose_columns(R, t, truth, None, point_m)
    rr = tof_render.rendered.truth["render"]
    info = {"integration_time_used_s": float(clean.integration_time_s), "max_amplitude_lsb": float(np.max(clean.amplitude_dn)),
            "spp_used": rr["spp"], "rim_spp_used": rr.get("rim_spp"), "render_s": float(tof_render.render_s),
            **{f"truth_{c}": float(v) for c, v in zip(COLUMNS, tc)},
            "nf_ok": False, "nf_reason": None, "nf_centroid_err_rms_px": None, "nf_centroid_err_max_px": None,
            **{f"nf_err_{c}": None for c in COLUMNS}}
    nf = solve(tof_render, 0, clean, pipeline(tof_render, overrides))
    res = nf.solution
    if not res:
        info["nf_reason"] = res.reason
        return info
    truth_px = tof_render.rendered.truth["targets_px"]
    e = np.array([np.hypot(*(np.asarray(res.targets_px[k]) - np.asarray(truth_px[str(k)]))) for k in sorted(res.targets_px)])
    err = pose_columns(res.R_cam_target, res.t_cam_target_m, truth, nf.state_err, point_m) - tc
    info.update({"nf_ok": True, "nf_centroid_err_rms_px": float(np.sqrt(np.mean(e**2))),
                 "nf_centroid_err_max_px": float(e.max()), **{f"nf_err_{c}": float(v) for c, v in zip(COLUMNS, err)}})
    return info


def assemble_run(range_m: float, rows: list, info: dict, *, frames: int, reference: str, frames_s: float) -> dict:
    """A stability run from its frame rows (:func:`frame_row`, in frame order) and its
    :func:`run_info` - the same dict whether the frames ran here or as stored trials.

    Returns
    -------
    dict
        ``range_m``, ``range_mm``, ``tables``, ``truth`` (6,), ``cols`` (K, 6) of the solved
        frames, ``frame_rows``, ``fails`` (reason -> count), ``rot_err_deg`` (K,),
        ``integration_time_s``, ``saturated_pixels`` (first frame), ``max_amplitude_lsb``
        (noise-free), ``noise_free``, ``render_s``, ``frames_s``, ``frames``, ``spp``,
        ``rim_spp``, ``reference``, ``iterations_median``.
    """
    ok = [r for r in rows if r["ok"]]
    fails = {}
    for r in rows:
        if not r["ok"]:
            fails[r["reason"]] = fails.get(r["reason"], 0) + 1
    if info["nf_ok"]:
        noise_free = {"ok": True, "centroid_err_rms_px": info["nf_centroid_err_rms_px"],
                      "centroid_err_max_px": info["nf_centroid_err_max_px"],
                      "pose_error": {c: info[f"nf_err_{c}"] for c in COLUMNS}}
    else:
        noise_free = {"ok": False, "reason": info["nf_reason"]}
    iters = [r["iterations"] for r in ok]
    return {"range_m": float(range_m), "range_mm": paper_range_mm(range_m), "tables": list(paper_tables(range_m)),
            "truth": np.array([info[f"truth_{c}"] for c in COLUMNS], float),
            "cols": np.array([[r[c] for c in COLUMNS] for r in ok], float).reshape(-1, 6), "frame_rows": rows,
            "fails": fails, "rot_err_deg": np.array([r["rot_err_deg"] for r in ok], float),
            "integration_time_s": info["integration_time_used_s"],
            "saturated_pixels": int(rows[0]["saturated_pixels"]) if rows else None,
            "max_amplitude_lsb": info["max_amplitude_lsb"], "render_s": info["render_s"], "frames_s": frames_s,
            "frames": int(frames), "spp": info["spp_used"], "rim_spp": info["rim_spp_used"], "reference": reference,
            "noise_free": noise_free, "iterations_median": float(np.median(iters)) if iters else None}


def run_stability(tof_render, range_m: float, frames: int, *, pipeline: dict | None = None, reference: str = "markers",
                  progress=None) -> dict:
    """Draw ``frames`` noisy frames from one render of the stability scenario and solve them in sequence.

    Parameters
    ----------
    tof_render : svgs_sim.sim.tof_closed_loop.TofRender
        :func:`svgs_sim.sim.tof_closed_loop.render` of :func:`stability_scenario` at ``range_m``.
    range_m : float
        The run's nominal range (selects the paper's tables).
    frames : int
        1 .. :data:`MAX_FRAMES`.
    pipeline : dict, optional
        :class:`svgs_sim.tof.pipeline.PipelineParams` overrides (``persistence_window``, ``max_active_pixels``...).
    reference : {"markers", "plate"}
    progress : callable, optional
        Called with 1 after each frame (a progress bar's ``update``).

    Returns
    -------
    dict
        :func:`assemble_run`.
    """

    frames = check_frames(frames)
    pt = reference_point_m(tof_render.target, reference)
    info = run_info(tof_render, pipeline, pt)
    t0 = time.perf_counter()
    results, _ = solve_frames(tof_render, frames, pipeline, progress=progress)
    rows = [frame_row(r, tof_render, pt) for r in results]
    return assemble_run(range_m, rows, info, frames=frames, reference=reference, frames_s=time.perf_counter() - t0)


def check_frames(frames) -> int:
    """``frames`` as an int in 1 .. :data:`MAX_FRAMES`, else :class:`InputError`."""
    try:
        n = int(frames)
    except (TypeError, ValueError):
        raise InputError(f"--frames: expected a whole number of frames, got {frames!r}") from None
    if n != frames or not 1 <= n <= MAX_FRAMES:
        raise InputError(f"--frames: expected 1..{MAX_FRAMES} frames (one frame takes ~50 ms; {MAX_FRAMES} about "
                         f"17 min), got {frames!r}")
    return n


def summary(run: dict) -> dict:
    """The JSON summary of a run (the ``--json`` schema of ``svgs tof stability``).

    Returns
    -------
    dict
        ``range_m, frames, solved, average, maximum, minimum, fluctuation, std`` (each
        ``{column: value}``), ``truth``, ``paper`` (``{table: {statistic: {column: value}}}``,
        empty off the paper's ranges), ``ratio_to_paper`` (our fluctuation / the paper's, per
        table), ``within_2x`` (per table, per column), ``failures``, ``integration_time_s``,
        ``reference``, ``render_s``, ``frames_s``.
    """
    st = statistics(run["cols"])
    paper = paper_statistics(run["range_mm"])

    def d(v):
        return {c: (None if not np.isfinite(x) else float(x)) for c, x in zip(COLUMNS, v)}

    out = {"range_m": run["range_m"], "frames": run["frames"], "solved": int(run["cols"].shape[0])}
    out.update({k: d(st[k]) for k in (*STATISTICS, "std")})
    out.update({"truth": d(run["truth"]), "paper": paper, "ratio_to_paper": {}, "within_2x": {}})
    for tab, stats in paper.items():
        fl = stats.get("fluctuation")
        if fl:
            ratio = {c: (out["fluctuation"][c] / fl[c] if out["fluctuation"][c] is not None and fl[c] > 0 else None)
                     for c in COLUMNS}
            out["ratio_to_paper"][tab] = ratio
            out["within_2x"][tab] = {c: (r is not None and 0.5 <= r <= 2.0) for c, r in ratio.items()}
    out.update({"failures": dict(run["fails"]), "integration_time_s": run["integration_time_s"],
                "max_amplitude_lsb": run["max_amplitude_lsb"], "saturated_pixels": run["saturated_pixels"],
                "rot_err_median_deg": float(np.median(run["rot_err_deg"])) if run["rot_err_deg"].size else None,
                "noise_free": run["noise_free"],
                "reference": run["reference"], "spp": run["spp"], "rim_spp": run["rim_spp"], "render_s": run["render_s"],
                "frames_s": run["frames_s"]})
    return out
