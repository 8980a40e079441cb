"""The ToF paper's stability runs (Zhu et al. 2022, Tables 1-3) on the rendered camera.

Render the target once at a pose, draw N noisy frames from that render
(:class:`camera.amcw.TofSensor`) and run them in sequence through one
:class:`tof.TofPipeline`; the statistics of the solved poses per component are the paper's
(average, maximum, minimum, fluctuation range = maximum - minimum) plus the standard
deviation. ``svgs tof stability`` (:mod:`cli.tof_stability`; also ``python -m
cli.tof_stability``) is the command: it replaces the former ``python -m render.tof.stability``.

Columns (the paper's axes)
    ``x_mm, y_mm, z_mm``: the target's reference point in the camera frame (OpenCV axes:
    x right, y down, z along the boresight); ``pitch_deg, yaw_deg, roll_deg``: the paper's
    names for our paper-state angles (roll, pitch, yaw) (:func:`svgs.frames.pose_to_state`)
    - its roll is the rotation about the line of sight, the one its Table 2 has the smallest
    scatter in, as ours.

Reference point (ASSUMPTION argued from the paper's numbers)
    The paper gives no target frame. Its Table 2 has a pitch fluctuation of 0.52 deg but an x
    fluctuation of only 0.19 mm: a point ``h`` in front of or behind the rotation's centre
    would move by ``h x 0.52 deg``, so its reference point lies within ~2 cm of the centre of
    the marker faces along the boresight. ``reference="markers"`` (default) reports the
    centroid of the eight marker faces; ``"plate"`` the target frame's origin (the plate
    centre, 125 mm behind it), whose x and y pick up the tilt noise.

Scenarios
    At the paper's two ranges (697 and 5712 mm, within 5 mm) the truth is the paper's average
    pose of Table 1 / Table 2 and the paper's statistics are attached; at any other range the
    target faces the camera on the boresight and no paper figures are attached.
"""

from __future__ import annotations

import time

import numpy as np

from svgs.errors import InputError

#: The paper's column names, in its order.
COLUMNS = ("x_mm", "y_mm", "z_mm", "pitch_deg", "yaw_deg", "roll_deg")
#: Statistics of the paper's tables (and ours), plus the standard deviation (ours only).
STATISTICS = ("average", "maximum", "minimum", "fluctuation")
#: The paper's average poses (Table 1 at 697 mm, Table 2 at 5712 mm): t (mm) and (pitch, yaw, roll) deg.
SCENARIOS = {
    697: {"tables": ("1", "3"), "t_mm": (2.193, -10.457, 697.604), "angles_deg": (-0.382, -2.653, -2.528)},
    5712: {"tables": ("2",), "t_mm": (5.097, -2.381, 5712.362), "angles_deg": (3.823, 1.324, -2.053)},
}
#: Most frames one stability run draws (about 50 ms each on one core: ~17 min).
MAX_FRAMES = 20000
#: Reference points of the position columns.
REFERENCES = ("markers", "plate")


def scenario_for_range(range_m: float) -> dict:
    """The scenario at ``range_m``: the paper's average pose within 5 mm of its two ranges, else
    head-on on the boresight.

    Returns
    -------
    dict
        ``range_mm`` (int or None), ``tables`` (paper table ids, may be empty),
        ``R_cam_target`` (3, 3), ``t_cam_target_m`` (3,).
    """
    from svgs.frames import pose_from_scenario

    r_mm = float(range_m) * 1e3
    for key, sc in SCENARIOS.items():
        if abs(r_mm - key) <= 5.0:
            R, _ = pose_from_scenario(1.0, 0.0, 0.0, *sc["angles_deg"])
            return {"range_mm": key, "tables": sc["tables"], "R_cam_target": R,
                    "t_cam_target_m": np.asarray(sc["t_mm"], float) * 1e-3}
    R, t = pose_from_scenario(float(range_m))
    return {"range_mm": None, "tables": (), "R_cam_target": R, "t_cam_target_m": np.asarray(t, float)}


def reference_point_m(target, reference: str = "markers") -> np.ndarray:
    """The reported point in the target frame, shape (3,): the marker faces' centroid or the origin."""
    if reference not in REFERENCES:
        raise InputError(f"reference: expected one of {REFERENCES}, got {reference!r}")
    return np.asarray(target.points_m, float).mean(0) if reference == "markers" else np.zeros(3)


def pose_columns(R, t, R_ref=None, point_m=None) -> np.ndarray:
    """The paper's six columns of one pose, shape (6,): the point (mm) and (pitch, yaw, roll) deg.

    Parameters
    ----------
    R, t : R_cam_target (3, 3), t_cam_target_m (3,)
    R_ref : (3, 3), optional
        Angles are unwrapped next to this pose's.
    point_m : (3,), optional
        Reported point in the target frame (default the origin).
    """
    from svgs.frames import pose_to_state

    p = np.zeros(3) if point_m is None else np.asarray(point_m, float)
    pos = np.asarray(R, float) @ p + np.asarray(t, float)
    ang = np.degrees(pose_to_state(R, t)[3:])
    if R_ref is not None:
        ref = np.degrees(pose_to_state(R_ref, t)[3:])
        ang = ref + (ang - ref + 180.0) % 360.0 - 180.0
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
    """The paper's tables at a range: ``{table_id: {statistic: {column: value}}}`` (empty off its ranges)."""
    from assets.papers import tof_2022_stability

    if range_mm is None:
        return {}
    out = {}
    for row in tof_2022_stability():
        if int(row["range_mm"]) == int(range_mm):
            out.setdefault(row["table"], {})[row["statistic"]] = {c: float(row[c]) for c in COLUMNS}
    return out


def run_stability(renderer, sensor, range_m: float, frames: int, *, seed: int = 0, pipeline: dict | None = None,
                  reference: str = "markers", progress=None, rendered=None) -> dict:
    """Render once at the scenario of ``range_m``, draw ``frames`` noisy frames, solve them in sequence.

    Parameters
    ----------
    renderer : render.tof.camera.TofRenderer
    sensor : camera.amcw.TofSensor
    range_m : float
    frames : int
        1 .. :data:`MAX_FRAMES`.
    seed : int
        Seed of the render and (with ``7``) of the frames' noise.
    pipeline : dict, optional
        :class:`tof.pipeline.PipelineParams` overrides (``persistence_window``, ``max_active_pixels``...).
    reference : {"markers", "plate"}
    progress : callable, optional
        Called with 1 after each frame (a progress bar's ``update``).
    rendered : camera.amcw.RenderedTof, optional
        This renderer's render of the scenario at ``seed`` and the sensor's frequency, from an
        earlier run (the ``rendered`` of its result): reused instead of rendering again.

    Returns
    -------
    dict
        ``range_m``, ``scenario`` (without arrays), ``truth`` (6,), ``cols`` (K, 6) of the solved
        frames, ``frame_rows`` (per frame: ``frame, ok, reason`` and the columns or None),
        ``fails`` (reason -> count), ``rot_err_deg`` (K,), ``integration_time_s``,
        ``saturated_pixels`` (first frame), ``max_amplitude_lsb`` (noise-free), ``noise_free``
        (the noise-free frame's centroid errors and pose error), ``render_s``, ``frames_s``,
        ``spp``, ``rim_spp`` (the samples per pixel on the marker rims), ``reference``,
        ``iterations_median`` (line-of-sight refinement iterations, median over solved frames),
        ``rendered``.
    """
    import tof
    from svgs.frames import rotation_angle_deg

    frames = check_frames(frames)
    sc = scenario_for_range(range_m)
    R, t = sc["R_cam_target"], sc["t_cam_target_m"]
    pt = reference_point_m(renderer.target, reference)
    t0 = time.perf_counter()
    if rendered is None:
        rendered = renderer.render(R, t, seed=seed, modulation_frequency_hz=sensor.modulation_frequency_hz)
    render_s = time.perf_counter() - t0
    clean = sensor.frame(rendered, noise=False)
    noise_free = _noise_free(renderer, rendered, clean, pipeline, R, t, pt)
    pipe = tof.TofPipeline(renderer.camera, renderer.target, **(pipeline or {}))
    cols, rows, rot, fails, iters = [], [], [], {}, []
    sat0 = None
    t0 = time.perf_counter()
    for k, fr in enumerate(sensor.frames(rendered, frames, [seed, 7])):
        if sat0 is None:
            sat0 = int(fr.saturated.sum())
        res = pipe.process(fr.gray, fr.depth_m)
        if res:
            c = pose_columns(res.R_cam_target, res.t_cam_target_m, R, pt)
            cols.append(c)
            rot.append(float(rotation_angle_deg(res.R_cam_target, R)))
            iters.append(res.iterations)
            rows.append({"frame": k, "ok": True, "reason": None, **dict(zip(COLUMNS, c.tolist()))})
        else:
            fails[res.reason] = fails.get(res.reason, 0) + 1
            rows.append({"frame": k, "ok": False, "reason": res.reason, **{c: None for c in COLUMNS}})
        if progress is not None:
            progress(1)
    frames_s = time.perf_counter() - t0
    return {"range_m": float(range_m), "range_mm": sc["range_mm"], "tables": list(sc["tables"]),
            "truth": pose_columns(R, t, R, pt), "cols": np.array(cols).reshape(-1, 6), "frame_rows": rows,
            "fails": fails, "rot_err_deg": np.array(rot), "integration_time_s": float(clean.integration_time_s),
            "saturated_pixels": sat0, "max_amplitude_lsb": float(np.max(clean.amplitude_dn)),
            "render_s": render_s, "frames_s": frames_s, "frames": frames,
            "spp": rendered.truth["render"]["spp"], "rim_spp": rendered.truth["render"].get("rim_spp"),
            "reference": reference, "noise_free": noise_free,
            "iterations_median": float(np.median(iters)) if iters else None,
            "rendered": rendered}


def _noise_free(renderer, rendered, clean, pipeline, R, t, pt) -> dict:
    """The noise-free frame through the pipeline: the centroid errors against the projected face
    centres (px) and the pose error per column (the bias part of the single-frame error)."""
    import tof

    res = tof.TofPipeline(renderer.camera, renderer.target, **(pipeline or {})).process(clean.gray, clean.depth_m)
    if not res:
        return {"ok": False, "reason": res.reason}
    truth_px = rendered.truth["targets_px"]
    e = np.array([np.hypot(*(np.asarray(res.targets_px[k]) - np.asarray(truth_px[str(k)]))) for k in sorted(res.targets_px)])
    err = pose_columns(res.R_cam_target, res.t_cam_target_m, R, pt) - pose_columns(R, t, R, pt)
    return {"ok": True, "centroid_err_rms_px": float(np.sqrt(np.mean(e**2))), "centroid_err_max_px": float(e.max()),
            "pose_error": dict(zip(COLUMNS, err.tolist()))}


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
