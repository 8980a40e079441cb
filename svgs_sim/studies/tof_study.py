"""The committed ToF report (``svgs tof study``): the paper's stability runs, what moves them, the
accuracy-versus-distance sweep of its Fig. 14 and the failure modes.

Writes into ``out``: ``tof_stability.md`` (the report), ``tof_stability.csv`` (every
statistic of every run, the paper's rows beside them), ``tof_stability_series.png``,
``tof_mechanisms.png``, ``tof_fig14.png`` and ``tof_failure_modes.png``.
"""

from __future__ import annotations

import csv
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from svgs_sim.sim.tof_stability import COLUMNS, summary

#: Short names of the columns in the report's sentences.
SHORT_NAMES = dict(zip(COLUMNS, ("x", "y", "z", "roll", "pitch", "yaw")))
#: The paper's two ranges (m).
PAPER_RANGES_M = (0.697, 5.712)
#: Ranges of the Fig. 14 sweep (m).
SWEEP_RANGES_M = tuple(float(r) for r in range(1, 11))
#: Pose schemes of the sweep: the paper's literal line-of-sight iteration (the default), its converged
#: optimum (Gauss-Newton, the former default) and the maximum-likelihood depth blend.
GN = {"refine_method": "gauss-newton"}
SWEEP_SCHEMES = (("paper (fixed point, default)", {}), ("converged optimum (Gauss-Newton)", GN),
                 ("ML depth blend", {**GN, "depth_weight": None}))
#: The stopping rule's sensitivity: (label, pipeline overrides); the default is 1e-6 m / rad, 500 iterations.
#: The default's row ({}) is the baseline's runs and sweep, not run again.
STOPPING_RULES = tuple((f"tol {tol:g}, cap 500", {"refine_tol_m": tol} if tol != 1e-6 else {})
                       for tol in (1e-3, 1e-4, 1e-5, 1e-6, 1e-7)) + \
    (("tol 1e-06, cap 100", {"refine_max_iter": 100}), ("tol 1e-06, cap 2000", {"refine_max_iter": 2000}))
#: Frame counts at which the long run's fluctuation is reported.
LONG_CHECKPOINTS = (200, 1000, 3000, 10000)
#: The paper's headline accuracy (abstract): 0.13 deg and 2 mm.
PAPER_ACCURACY = {"deg": 0.13, "mm": 2.0}
#: The paper's Fig. 14 text (section 6.5): the range (z) error beyond 5 m, mm.
PAPER_FIG14_Z_MM = 2.5


def _variants(frames_auto_T_far: float, frames_auto_T_near: float):
    """(label, ranges, renderer kwargs, sensor kwargs, pipeline kwargs, reference, what it tests)."""
    both = PAPER_RANGES_M
    near = (PAPER_RANGES_M[0],)
    far = (PAPER_RANGES_M[1],)
    v = [
        ("converged optimum (Gauss-Newton)", both, {}, {}, GN, "markers",
         "the literal iteration's fixed point (the former default): range from the pattern's apparent size"),
        ("reference point: plate centre", both, {}, {}, {}, "plate",
         "the position columns at the target frame's origin, 125 mm behind the marker faces"),
        ("ML depth blending (depth_weight None)", both, {}, {}, {**GN, "depth_weight": None}, "markers",
         "the pipeline's maximum-likelihood blend of the depths with an assumed 0.05 px centroid sigma"),
        ("no recursive median of depth", both, {}, {}, {"temporal_median": False}, "markers",
         "the paper's recursive time-domain median of the depth image (section 3.1.2) switched off"),
        ("centroid weighting: intensity", both, {}, {}, {"centroid_weighting": "intensity"}, "markers",
         "the paper's intensity-weighted centroid over all of a marker's pixels (~1000 per marker at 0.7 m)"),
        ("integration time 1/4 of automatic", near, {}, {"integration_time_s": frames_auto_T_near / 4}, {}, "markers",
         "a quarter of the automatic setting: 4x fewer photo-electrons (shot noise x2)"),
        ("integration time 1/4 of automatic", far, {}, {"integration_time_s": frames_auto_T_far / 4}, {}, "markers",
         "a quarter of the automatic setting: 4x fewer photo-electrons (shot noise x2)"),
        ("persistence window 10 frames", both, {}, {}, {"persistence_window": 10, "persistence_min_count": 5}, "markers",
         "the paper's temporal filter (section 3.4), 0.26 s at 39 fps"),
        ("persistence window 39 frames", both, {}, {}, {"persistence_window": 39, "persistence_min_count": 20}, "markers",
         "1 s at the datasheet's 39 fps"),
        ("Lambertian white markers (albedo 0.85)", both, {"scene_options": {"marker_material": "lambertian"}}, {}, {},
         "markers", "the previous model: white paint instead of sheeting"),
        ("sheeting EN 12899-1 RA1", both, {"scene_options": {"sheeting": "en12899-ra1-white"}}, {}, {}, "markers",
         "engineering-grade glass beads"),
        ("sheeting 3M 983 (microprismatic)", both, {"scene_options": {"sheeting": "3m-983-diamond-grade-white"}}, {}, {},
         "markers", "full-cube prisms (typical values; extrapolated beyond 0.5 deg)"),
        ("fixed integration time (5.7 m setting)", both, {}, {"integration_time_s": frames_auto_T_far}, {}, "markers",
         "one integration time for both ranges: the near markers saturate"),
        ("ambient 10 klux", both, {}, {"ambient_lux": 10000.0}, {}, "markers", "the paper's high light environment"),
        ("multipath (2 bounces)", both, {"max_bounces": 2}, {}, {}, "markers", "diffuse inter-reflections plate <-> markers"),
    ]
    for cap in (7600, 7300, 7000, 6500):
        v.append((f"active-set cap N_max = {cap} px", near, {}, {}, {"max_active_pixels": cap}, "markers",
                  "the paper's cap on the active pixel set (section 3.1), dimmest discarded first"))
    return v


def _fmt(v, d=3):
    return "nan" if v is None or not np.isfinite(v) else f"{v:.{d}f}"


@dataclass(frozen=True)
class TofStudyConfig:
    """What the ToF study computes (its manifest); how it runs is not part of it.

    Attributes
    ----------
    camera, pattern : str
        ToF camera profile and marker target (names or paths).
    frames, variant_frames, sweep_frames, long_frames : int
        Frames of the stability runs, of each mechanism and stopping-rule run, per range of the
        Fig. 14 sweep, and of the long run (0: none).
    seed : int
        Every run's render seed and noise stream (:mod:`svgs_sim.sim.tof_trial`).
    spp, rim_spp_factor : int or None
        The renders' samples per pixel and the factor at the marker rims (None: the renderer's).
    ambient_lux : float or None
        The sensor's ambient light (None: the profile's).
    scene : tuple of (str, value)
        Scene options of every render (``marker_material``, ``sheeting``).
    """

    camera: str = "tof-epc660"
    pattern: str = "tof-8"
    frames: int = 500
    variant_frames: int = 200
    sweep_frames: int = 40
    long_frames: int = 3000
    seed: int = 0
    spp: int | None = None
    rim_spp_factor: int | None = None
    ambient_lux: float | None = None
    scene: tuple = ()

    def manifest(self) -> dict:
        d = asdict(self)
        d["scene"] = dict(self.scene)
        return {"study": "tof-study", "trial_kind": "tof", **d}

    def scenario(self, range_m: float, *, scene: dict | None = None, max_bounces: int = 1, **sensor):
        """The stability scenario at ``range_m`` with this study's render and sensor settings."""
        from svgs_sim.sim.tof_stability import stability_scenario

        so = {**dict(self.scene), **(scene or {})}
        kw = {"ambient_lux": self.ambient_lux, **sensor}
        return stability_scenario(range_m, camera=self.camera, pattern=self.pattern, seed=self.seed, spp=self.spp,
                                  rim_spp_factor=self.rim_spp_factor, max_bounces=max_bounces,
                                  scene_options=tuple(so.items()), **kw)


def auto_integration_times(cfg: TofStudyConfig) -> dict:
    """The automatic integration time at the paper's two ranges (s; the baseline renders'
    noise-free frames): the mechanism runs at a quarter of it and at the far range's."""
    from svgs_sim.sim.tof_closed_loop import noise_free_frame
    from svgs_sim.sim.tof_trial import cached_render

    return {r: float(noise_free_frame(cached_render(cfg.scenario(r))).integration_time_s) for r in PAPER_RANGES_M}


def study_runs(cfg: TofStudyConfig, auto_T: dict) -> list:
    """Every run of the study, in trial order: ``(section, label, TofTrialScenario of frame 0, extra)``.

    ``section``: ``baseline``, ``mechanism``, ``sweep``, ``stopping`` or ``long``; ``extra``:
    the mechanism's explanation, the sweep's scheme or the stopping rule's overrides.
    """
    from svgs_sim.sim.tof_trial import TofTrialScenario

    def run(r, frames, label, pipeline=None, reference="markers", scenario=None):
        sc = scenario if scenario is not None else cfg.scenario(r)
        return TofTrialScenario(sc, float(r), int(frames), 0, tuple((pipeline or {}).items()), reference, label)

    out = [("baseline", f"baseline @ {r}", run(r, cfg.frames, f"baseline @ {r}"), None) for r in PAPER_RANGES_M]
    for label, ranges, rkw, skw, pkw, ref, why in _variants(auto_T[PAPER_RANGES_M[1]], auto_T[PAPER_RANGES_M[0]]):
        for r in ranges:
            sc = cfg.scenario(r, scene=rkw.get("scene_options"), max_bounces=rkw.get("max_bounces", 1), **skw)
            name = f"mechanism {label} @ {r}"
            out.append(("mechanism", label, run(r, cfg.variant_frames, name, pkw, ref, sc), why))
    for scheme, pkw in SWEEP_SCHEMES:
        for r in SWEEP_RANGES_M:
            out.append(("sweep", scheme, run(r, cfg.sweep_frames, f"sweep {scheme} @ {r}", pkw), None))
    for label, pkw in STOPPING_RULES:
        if not pkw:  # the default: the baseline runs and the sweep above
            continue
        for r in (*PAPER_RANGES_M, *SWEEP_RANGES_M):
            n = cfg.variant_frames if r in PAPER_RANGES_M else cfg.sweep_frames
            out.append(("stopping", label, run(r, n, f"stopping {label} @ {r}", pkw), pkw))
    if cfg.long_frames:
        r = PAPER_RANGES_M[0]
        out.append(("long", "long run", run(r, cfg.long_frames, f"long run @ {r}"), None))
    return out


def study_trials(runs) -> list:
    """The study engine's trials: every frame of every run, ids in run order, each with its run's seed."""
    from dataclasses import replace

    from .execution import Trial

    trials = []
    for _, _, first, _ in runs:
        for k in range(first.frames):
            trials.append(Trial(len(trials), replace(first, frame=k), int(first.scenario.seed)))
    return trials


def runs_from_rows(runs, rows) -> list:
    """The stored rows back as the stability runs of :func:`svgs_sim.sim.tof_stability.assemble_run`, one per run."""
    from svgs_sim.sim.tof_stability import COLUMNS, RUN_INFO_KEYS, assemble_run

    by_label: dict = {}
    for r in rows:
        by_label.setdefault(r["run"], []).append(r)
    out = []
    for _, _, first, _ in runs:
        rr = sorted(by_label[first.run], key=lambda x: x["frame"])
        frame_rows = [{"frame": int(x["frame"]), "ok": bool(x["ok"]), "reason": x["reason"], "n_blobs": x["n_blobs"],
                       "iterations": x["iterations"], **{c: x[f"col_{c}"] for c in COLUMNS}, "rot_err_deg": x["rot_err_deg"],
                       "saturated_pixels": x["saturated_pixels"]} for x in rr]
        info = {k: rr[0][k] for k in RUN_INFO_KEYS}
        info["nf_ok"] = bool(info["nf_ok"])
        out.append(assemble_run(first.nominal_range_m, frame_rows, info, frames=first.frames, reference=first.reference,
                                frames_s=float(sum(x["wall_s"] for x in rr))))
    return out


def run_study(cfg: TofStudyConfig, out: Path, spec=None, *, store_dir=None, chunk_size=None, argv=(), quiet=False) -> dict:
    """Run (or resume) every run as trials of the ``tof`` kind and write the report; returns the
    numbers (JSON-serialisable).

    Parameters
    ----------
    cfg : TofStudyConfig
    out : str or Path
        Folder of the report and its figures.
    spec : svgs_sim.studies.execution.ExecutorSpec, optional
        How the trials run (default: in this process).
    store_dir : str or Path, optional
        The results store (default ``out / "tof-study"``); a rerun skips the stored trials, a
        changed ``cfg`` is refused.
    chunk_size : int, optional
        Trials per task, at least (:func:`svgs_sim.sim.tof_trial.chunk_frames`: a run stays in one task).
    """
    from svgs_sim.sim.tof_closed_loop import load_scene, make_sensor
    from svgs_sim.sim.trials import get_trial_kind
    from svgs_sim.sim.tof_trial import cached_render, chunk_frames

    from .execution import ExecutorSpec, plan_trials, run_stored_study

    t_start = time.perf_counter()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    camera, target = load_scene(cfg.camera, cfg.pattern)

    def log(msg):
        if not quiet:
            print(msg, file=sys.stderr, flush=True)

    log("automatic integration times at the paper's ranges (the baseline renders)")
    auto_T = auto_integration_times(cfg)
    runs = study_runs(cfg, auto_T)
    trials = study_trials(runs)
    plan = plan_trials(get_trial_kind("tof"), trials, spec or ExecutorSpec("inline", 1))
    log(plan.describe() + "; frames already in the store are skipped")
    for line in plan.warnings():
        if "--processes" not in line and "--workers" not in line:  # the command said that one already
            log(line)
    store, stats = run_stored_study(get_trial_kind("tof"), trials, Path(store_dir) if store_dir else out / "tof-study",
                                cfg.manifest(), spec or ExecutorSpec("inline", 1),
                                chunk_size=chunk_frames(max(r[2].frames for r in runs), chunk_size),
                                progress=not quiet, description="ToF study frames")
    rows = store.read_rows()
    done = runs_from_rows(runs, rows)
    res = _sections(runs, done)
    log("failure modes")
    sensor = make_sensor(cfg.scenario(1.0), camera)
    fm = failure_modes(cfg, camera, target, out / "tof_failure_modes.png")
    runs_d, sums = res["runs"], res["sums"]
    plot_series(out / "tof_stability_series.png", runs_d, sums)
    plot_mechanisms(out / "tof_mechanisms.png", sums, res["var_rows"])
    plot_sweep(out / "tof_fig14.png", res["sweep"])
    csv_path = write_csv(out / "tof_stability.csv", sums, res["var_rows"], res["sweep"])
    wall = time.perf_counter() - t_start
    timing = {"wall_s": wall, "n_run": int(getattr(stats, "n_run", len(rows)) if stats is not None else 0),
              "n_frames": len(rows), "trial_s": float(sum(float(r.get("wall_s") or 0.0) for r in rows))}
    base = cached_render(cfg.scenario(PAPER_RANGES_M[0])).renderer
    md = write_markdown(out / "tof_stability.md", camera, target, sensor, base, sums, runs_d, res["var_rows"], res["sweep"],
                        fm, cfg.frames, cfg.variant_frames, cfg.sweep_frames, cfg.seed, argv, timing,
                        stopping=res["stopping"], long=res["long"])
    return {"stability": {str(r): s for r, s in sums.items()}, "stopping_rule": res["stopping"], "long_run": res["long"],
            "mechanisms": [{"label": v["label"], "range_m": v["range_m"], "ratio_to_paper": v["summary"]["ratio_to_paper"],
                            "fluctuation": v["summary"]["fluctuation"], "solved": v["summary"]["solved"]}
                           for v in res["var_rows"]],
            "fig14": res["sweep"], "failure_modes": fm, "wall_s": wall,
            "outputs": {"report": str(md), "csv": str(csv_path), "series": str(out / "tof_stability_series.png"),
                        "mechanisms": str(out / "tof_mechanisms.png"), "fig14": str(out / "tof_fig14.png"),
                        "failure_modes": str(out / "tof_failure_modes.png")}}


def _sections(runs, done) -> dict:
    """The report's sections from the finished runs (in :func:`study_runs` order)."""
    runs_d, sums, var_rows, sweep, long = {}, {}, [], [], None
    stopping_runs: dict = {}
    for (section, label, first, extra), run in zip(runs, done):
        r = first.nominal_range_m
        if section == "baseline":
            runs_d[r], sums[r] = run, summary(run)
        elif section == "mechanism":
            var_rows.append({"label": label, "why": extra, "range_m": r, "summary": summary(run)})
        elif section == "sweep":
            sweep.append(_sweep_row(label, r, run, first.frames))
        elif section == "stopping":
            stopping_runs.setdefault(label, {"pipeline": extra, "runs": {}})["runs"][r] = run
        else:
            long = _long_run(run)
    stopping = []
    for label, pkw in STOPPING_RULES:
        row = {"label": label, "pipeline": pkw, "ratio_to_paper": {}, "iterations_median": {}, "fig14_z_rms_mm": {}}
        for r, tab in zip(PAPER_RANGES_M, ("3", "2")):
            run = runs_d[r] if not pkw else stopping_runs[label]["runs"][r]
            row["ratio_to_paper"][tab] = (sums[r] if not pkw else summary(run))["ratio_to_paper"][tab]
            row["iterations_median"][str(r)] = run["iterations_median"]
        for r in SWEEP_RANGES_M:
            if not pkw:
                sw = next(s for s in sweep if s["scheme"] == SWEEP_SCHEMES[0][0] and s["range_m"] == r)
            else:
                run = stopping_runs[label]["runs"][r]
                sw = _sweep_row(label, r, run, run["frames"])
            row["fig14_z_rms_mm"][str(r)] = sw["rms"]["target_z_cam_mm"] if sw["rms"] else None
        stopping.append(row)
    return {"runs": runs_d, "sums": sums, "var_rows": var_rows, "sweep": sweep, "stopping": stopping, "long": long}


def _long_run(run) -> dict:
    """Fluctuation (max - min) and std of the first N frames of a long run, against Tables 1 and 3."""
    from svgs_sim.sim.tof_stability import paper_statistics, statistics

    paper = paper_statistics(run["range_mm"])
    C = run["cols"]
    rows = []
    for n in sorted({*(k for k in LONG_CHECKPOINTS if k < C.shape[0]), C.shape[0]}):
        st = statistics(C[:n])
        rows.append({"frames": int(n), "fluctuation": dict(zip(COLUMNS, st["fluctuation"].tolist())),
                     "std": dict(zip(COLUMNS, st["std"].tolist())),
                     "ratio_to_paper": {tab: {c: float(st["fluctuation"][i] / paper[tab]["fluctuation"][c])
                                              for i, c in enumerate(COLUMNS)} for tab in ("1", "3")}})
    return {"frames": run["frames"], "solved": int(C.shape[0]), "failures": dict(run["fails"]), "checkpoints": rows,
            "frames_s": run["frames_s"]}


def _sweep_row(scheme, r, run, frames) -> dict:
    C, tr = run["cols"], run["truth"]
    err = C - tr
    ok = C.shape[0] > 0
    return {"scheme": scheme, "range_m": r, "solved": int(C.shape[0]), "frames": frames,
            "bias": dict(zip(COLUMNS, err.mean(0).tolist())) if ok else None,
            "rms": dict(zip(COLUMNS, np.sqrt((err**2).mean(0)).tolist())) if ok else None,
            "std": dict(zip(COLUMNS, C.std(0).tolist())) if ok else None,
            "rot_err_rms_deg": float(np.sqrt(np.mean(run["rot_err_deg"] ** 2))) if ok else None,
            "integration_time_s": run["integration_time_s"]}


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
    from svgs_sim.sim.tof_closed_loop import noise_free_frame, pipeline, render, solve

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


def plot_series(path, runs, sums) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(6, 2, figsize=(11, 11), sharex="col")
    for j, r in enumerate(PAPER_RANGES_M):
        run, s = runs[r], sums[r]
        k = np.array([row["frame"] for row in run["frame_rows"] if row["ok"]])
        for i, c in enumerate(COLUMNS):
            ax = axes[i, j]
            ax.plot(k, run["cols"][:, i], lw=0.5)
            for n, (tab, st) in enumerate(sorted(s["paper"].items())):
                if "fluctuation" in st:
                    h = 0.5 * st["fluctuation"][c]
                    ax.axhspan(s["average"][c] - h, s["average"][c] + h, color=f"C{n + 1}", alpha=0.15,
                               label=f"paper T{tab} range")
            ax.set_ylabel(c, fontsize=8)
            if i == 0:
                ax.set_title(f"{r} m: {s['solved']}/{s['frames']} solved")
                ax.legend(fontsize=6, loc="upper right")
        axes[-1, j].set_xlabel("frame")
    fig.suptitle("Stability runs (bands: the paper's fluctuation ranges, drawn about our mean)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def plot_mechanisms(path, sums, var_rows) -> None:
    """Fluctuation / paper (log colour, 0.5-2 is the band) per run and component, at both ranges."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    fig, axes = plt.subplots(1, 2, figsize=(15, 6.5), gridspec_kw={"wspace": 0.75})
    for ax, r, tab in zip(axes, PAPER_RANGES_M, ("3", "2")):
        labels = ["baseline"] + [v["label"] for v in var_rows if v["range_m"] == r]
        rows = [sums[r]] + [v["summary"] for v in var_rows if v["range_m"] == r]
        M = np.array([[s["ratio_to_paper"].get(tab, {}).get(c) or np.nan for c in COLUMNS] for s in rows], float)
        im = ax.imshow(M, cmap="RdBu_r", norm=LogNorm(vmin=0.01, vmax=100), aspect="auto")
        for (i, j), v in np.ndenumerate(M):
            ok = 0.5 <= v <= 2
            ax.text(j, i, "nan" if not np.isfinite(v) else f"{v:.2g}", ha="center", va="center", fontsize=7,
                    fontweight="bold" if ok else "normal")
        ax.set_xticks(range(6), COLUMNS, rotation=30, fontsize=8)
        ax.set_yticks(range(len(labels)), labels, fontsize=7)
        ax.set_title(f"{r} m: fluctuation / paper Table {tab} (bold: within 2x)", fontsize=9)
    fig.colorbar(im, ax=axes, fraction=0.025)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)


def plot_sweep(path, sweep) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(12, 4.3))
    for k, (scheme, _) in enumerate(SWEEP_SCHEMES):
        rows = [s for s in sweep if s["scheme"] == scheme]
        r = np.array([s["range_m"] for s in rows])
        ls = ("-", "--", ":")[k]
        for j, c in enumerate(COLUMNS[:3]):
            axes[0].plot(r, [s["rms"][c] if s["rms"] else np.nan for s in rows], "o" + ls, ms=3,
                         color=f"C{j}", label=f"{c} ({scheme})")
        for j, c in enumerate(COLUMNS[3:]):
            axes[1].plot(r, [s["rms"][c] if s["rms"] else np.nan for s in rows], "o" + ls, ms=3,
                         color=f"C{j + 3}", label=f"{c} ({scheme})")
    axes[0].axhline(PAPER_ACCURACY["mm"], color="k", ls=":", lw=0.8, label="paper: 2 mm")
    axes[1].axhline(PAPER_ACCURACY["deg"], color="k", ls=":", lw=0.8, label="paper: 0.13 deg")
    axes[0].plot([5, 10], [PAPER_FIG14_Z_MM] * 2, color="k", lw=2, alpha=0.4, label="paper: z 2.5 mm beyond 5 m")
    for ax, unit in zip(axes, ("mm", "deg")):
        ax.set_xlabel("range, m")
        ax.set_ylabel(f"single-frame RMS error, {unit}")
        ax.set_yscale("log")
        ax.legend(fontsize=6, ncol=2)
    fig.suptitle("Accuracy against distance (the paper's Fig. 14), target head-on: solid = the paper's literal "
                 "line-of-sight iteration (default), dashed = its converged optimum, dotted = depths blended in", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_csv(path, sums, var_rows, sweep) -> Path:
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(["run", "range_m", "statistic", *COLUMNS])
        for r, s in sums.items():
            for k in ("truth", "average", "maximum", "minimum", "fluctuation", "std"):
                w.writerow(["baseline", r, k, *[_fmt(s[k][c], 4) for c in COLUMNS]])
            for tab, st in sorted(s["paper"].items()):
                for k, d in st.items():
                    w.writerow([f"paper table {tab}", r, k, *[d[c] for c in COLUMNS]])
        for v in var_rows:
            s = v["summary"]
            for k in ("fluctuation", "std"):
                w.writerow([v["label"], v["range_m"], k, *[_fmt(s[k][c], 4) for c in COLUMNS]])
        for s in sweep:
            if s["rms"]:
                w.writerow([f"fig14 sweep, {s['scheme']}", s["range_m"], "rms",
                            *[_fmt(s["rms"][c], 4) for c in COLUMNS]])
    return Path(path)


def _ratio_cells(ratios) -> str:
    return " | ".join(("**" + _fmt(v, 2) + "**") if v is not None and 0.5 <= v <= 2 else _fmt(v, 2) for v in ratios)


def stopping_section(stopping, sweep_frames, variant_frames) -> list[str]:
    """The stopping rule's table: Tables 3 and 2 and the Fig. 14 range error per rule."""
    far_r = [r for r in SWEEP_RANGES_M if r >= 5]
    L = ["## The refinement and its stopping rule", "",
         "The paper's section 5.2 iterates `q_i = e_i e_i^T (R_k p_i + t_k)` and the SVD until the change drops "
         "below a threshold it does not state. With the SVD's centroid translation each step moves the range only "
         "by ~(pattern size / range)^2 of the way to the line-of-sight optimum (~7e-4 at 5.7 m), so a literal "
         "iteration stopped by a change threshold keeps most of the measured (centroid-depth) range at long range, "
         "while its converged optimum (what Gauss-Newton reaches) takes the range from the pattern's apparent size. "
         "The default stops when one step changes the translation by < 1e-6 m and the rotation by < 1e-6 rad "
         "(the tables' last printed digits: 0.001 mm and 0.001 deg = 1.7e-5 rad), at most 500 iterations (the "
         "module's cap since issue 13); neither is in the paper, so the rows below give the sensitivity "
         f"({variant_frames} frames per paper range, {sweep_frames} per sweep range; the same renders and noise "
         "draws as above; the default's row is the baseline runs and the Fig. 14 sweep).", "",
         "| stopping rule | iterations 0.697 / 5.712 m | T3 ratios x, y, z, roll, pitch, yaw | T2 ratios x, y, z, roll, pitch, yaw | "
         + " | ".join(f"z RMS {r:g} m" for r in far_r) + " |", "|---|---|---|---|" + "---|" * len(far_r)]
    for row in stopping:
        it = row["iterations_median"]
        L.append(f"| {row['label']}{' (default)' if row['label'] == 'tol 1e-06, cap 500' else ''} | "
                 + " / ".join(_fmt(v, 0) for v in it.values()) + " | "
                 + ", ".join(_fmt(v, 2) for v in row["ratio_to_paper"]["3"].values()) + " | "
                 + ", ".join(_fmt(v, 2) for v in row["ratio_to_paper"]["2"].values()) + " | "
                 + " | ".join(_fmt(row["fig14_z_rms_mm"][str(r)], 1) for r in far_r) + " |")
    L += ["", f"The paper: z error {PAPER_FIG14_Z_MM} mm beyond 5 m (Fig. 14 text).", ""]
    return L


def long_section(long, near) -> list[str]:
    if not long:
        return []
    L = [f"## The long run: {long['frames']} frames at {near * 1e3:.0f} mm against Table 1's ~6000 s", "",
         f"`svgs tof stability --range {near} --frames {long['frames']} --seed 0` draws fresh sensor noise for each frame "
         "from one render (no motion, no drift: no source found for the EPC660's or the emitters' temperature "
         "coefficient of depth, so none is modelled). Solved "
         f"{long['solved']}/{long['frames']} (failures: {long['failures'] or 'none'}). Fluctuation (max - min) of the "
         "first N frames over the paper's:", "",
         "| frames | table | " + " | ".join(COLUMNS) + " |", "|---|---|" + "---|" * 6]
    for cp in long["checkpoints"]:
        for tab in ("1", "3"):
            L.append(f"| {cp['frames']} | T{tab} | " + _ratio_cells(cp["ratio_to_paper"][tab].values()) + " |")
    last = long["checkpoints"][-1]
    n_paper = 6000 * 39
    e200, elast, epaper = (expected_range_sigma(n) for n in (200, last["frames"], n_paper))
    L += ["", f"Standard deviation over all {last['frames']} frames: "
          + ", ".join(f"{c} {_fmt(v, 4)}" for c, v in last["std"].items()) + ". For independent Gaussian noise the "
          f"expected range (max - min) of N draws is {e200:.2f} sigma for 200, {elast:.2f} sigma for {last['frames']} and "
          f"{epaper:.2f} sigma for {n_paper:,} (6000 s at the datasheet's 39 fps; the paper's output rate is not "
          f"stated): a run as long as the paper's widens the 200-frame fluctuation by {epaper / e200:.1f}x at most.", ""]
    return L


def expected_range_sigma(n: int) -> float:
    """Expected range (max - min) of ``n`` independent standard normal draws,
    ``int 1 - Phi(x)^n - (1 - Phi(x))^n dx``."""
    from scipy.integrate import quad
    from scipy.stats import norm

    f = lambda x: 1.0 - np.exp(n * norm.logcdf(x)) - np.exp(n * norm.logsf(x))  # noqa: E731
    return float(quad(f, -12, 12, limit=400, points=[-3, 0, 3])[0])


def write_markdown(path, camera, target, sensor, renderer, sums, runs, var_rows, sweep, fm, frames, variant_frames,
                   sweep_frames, seed, argv, timing, stopping=None, long=None) -> Path:
    """``tof_stability.md``: the report, section by section from the numbers (each section a
    function of its own, in the order the report reads)."""
    L = _header_lines(camera, target, sensor, renderer, seed, argv, timing)
    L += _stability_lines(sums, runs, frames, seed)
    L += _mechanism_lines(sums, var_rows, variant_frames)
    L += findings(sums, var_rows)
    L += stopping_section(stopping or [], sweep_frames, variant_frames)
    L += long_section(long, PAPER_RANGES_M[0])
    L += _sweep_lines(sweep, sweep_frames)
    L += _failure_lines(fm)
    Path(path).write_text("\n".join(L))
    return Path(path)




def _header_lines(camera, target, sensor, renderer, seed, argv, timing) -> list[str]:
    """The report's title, provenance, the simulated sensor and target, and the columns."""
    ill = renderer.illumination
    sheet = renderer.geometry.materials
    L = ["# The ToF sensor re-enacted: Zhu et al. 2022, Tables 1-3 and Fig. 14", "",
         "Generated by `svgs " + " ".join(argv or ["tof", "study"]) + f"` on this 2-core machine: {timing['n_frames']} "
         f"frames whose trials took {timing['trial_s'] / 60:.1f} min (each trial's wall time, summed; render once per pose, "
         "then noisy frames through one `svgs_sim.tof.TofPipeline` per run). This invocation computed "
         f"{timing['n_run']} of them, read the rest from its resumable store, and took {timing['wall_s'] / 60:.1f} min.", "",
         f"Camera `{camera.name}` (Espros EPC660 as its datasheet specifies it: {sensor.modulation_frequency_hz / 1e6:g} MHz, "
         f"demodulation contrast {sensor.demodulation_contrast:g}, QE {sensor.quantum_efficiency:g}, "
         f"{sensor.gain_e_per_lsb:.1f} e-/LSB from the TOF sensitivity, automatic integration time "
         f"{sensor.integration_time_min_s * 1e9:.0f} ns - {sensor.integration_time_max_s * 1e3:g} ms, ambient "
         f"{sensor.ambient_lux:g} lux), target `{target.pattern.name}` with marker faces of "
         f"**{sheet['marker']}** `{sheet.get('sheeting')}`, {ill.n_emitters} emitters of "
         f"{ill.peak_intensity_w_sr:g} W/sr on a {ill.ring_radius_m * 1e3:g} mm ring; {renderer.spp} spp, "
         f"{renderer.spp * renderer.rim_spp_factor} on the marker rims ({renderer.sampler} sampler), seed {seed}. "
         "Where each figure comes from: `docs/tof.md`. Pipeline: the defaults of `svgs_sim.tof.PipelineParams` - the paper's "
         "literal line-of-sight iteration (section 5.2) from the SVD of the centroid-depth points, stopped when one step "
         "changes the pose by < 1e-6 m / 1e-6 rad or after 500 iterations (below: its sensitivity).", "",
         "Columns: the paper's Tables 1-3 in its order. target_x_cam_mm, target_y_cam_mm, target_z_cam_mm: the "
         "centroid of the eight marker faces in the camera frame (OpenCV axes; not the state's x_m, y_m, z_m, the "
         "camera in the target frame; the paper gives no target frame; its Table 2 - its pitch fluctuating 0.52 deg, "
         "x only 0.19 mm - puts its reference point within ~2 cm of that centroid along the boresight; the "
         "plate-centre variant below shows the difference); roll_deg, pitch_deg, yaw_deg: the paper state's angles, "
         "which the paper calls pitch, yaw, roll (our roll is the rotation about the line of sight). Fluctuation = "
         "maximum - minimum over the run, as the paper's tables.", ""]
    return L


def _stability_lines(sums, runs, frames, seed) -> list[str]:
    """One section per paper range: the stability table against Tables 1-3 and single-frame accuracy."""
    L = []
    tabs = {PAPER_RANGES_M[0]: ("1", "3"), PAPER_RANGES_M[1]: ("2",)}
    for r in PAPER_RANGES_M:
        s, run = sums[r], runs[r]
        L += [f"## {r * 1e3:.0f} mm: `svgs tof stability --range {r} --frames {frames} --seed {seed}`", "",
              f"Solved {s['solved']}/{s['frames']} frames (failures: {s['failures'] or 'none'}); integration time "
              f"{s['integration_time_s'] * 1e6:.2f} us per DCS; brightest amplitude {s['max_amplitude_lsb']:.0f} LSB; "
              f"saturated pixels {s['saturated_pixels']}; render {run['render_s']:.1f} s, frames + pipeline "
              f"{run['frames_s']:.1f} s.", "",
              "| statistic | " + " | ".join(COLUMNS) + " |", "|---|" + "---|" * 6,
              "| truth | " + " | ".join(_fmt(s["truth"][c]) for c in COLUMNS) + " |"]
        for k in ("average", "maximum", "minimum", "fluctuation", "std"):
            L.append(f"| sim {k} | " + " | ".join(_fmt(s[k][c]) for c in COLUMNS) + " |")
        for tab in tabs[r]:
            st = s["paper"].get(tab, {})
            if "fluctuation" in st:
                L.append(f"| **paper T{tab} fluctuation** | " + " | ".join(_fmt(st["fluctuation"][c]) for c in COLUMNS) + " |")
                L.append(f"| ratio sim / T{tab} | " + " | ".join(
                    ("**" + _fmt(v, 2) + "**") if v is not None and 0.5 <= v <= 2 else _fmt(v, 2)
                    for v in s["ratio_to_paper"][tab].values()) + " |")
        err = run["cols"] - run["truth"]
        if err.size:
            rms = np.sqrt((err**2).mean(0))
            rot = float(np.sqrt(np.mean(run["rot_err_deg"] ** 2)))
            ok_pos = bool(np.all(rms[:3] <= PAPER_ACCURACY["mm"]))
            ok_rot = rot <= PAPER_ACCURACY["deg"]
            nf = s.get("noise_free") or {}
            nf_txt = (f" The noise-free frame: centroids {_fmt(nf['centroid_err_rms_px'])} px RMS ({_fmt(nf['centroid_err_max_px'])} "
                      "max) from the projected face centres (the paper: 0.06 px), pose error "
                      + ", ".join(f"{c} {_fmt(v)}" for c, v in nf["pose_error"].items())
                      + " - the bias part of the single-frame error.") if nf.get("ok") else ""
            L += ["", "Single frames against the truth (the paper's headline 2 mm and 0.13 deg): RMS error "
                  + ", ".join(f"{c} {_fmt(v)}" for c, v in zip(COLUMNS, rms)) + f"; rotation angle RMS {_fmt(rot)} deg - "
                  + ("position within 2 mm" if ok_pos else "position NOT within 2 mm") + ", "
                  + ("rotation within 0.13 deg." if ok_rot else "rotation NOT within 0.13 deg.") + nf_txt]
        L.append("")
    return L


def _mechanism_lines(sums, var_rows, variant_frames) -> list[str]:
    """The mechanisms table: each one-change rerun's fluctuation over the paper's."""
    L = []
    L += ["![stability series](tof_stability_series.png)", "",
          "## What moves the figures (the mechanisms, measured)", "",
          f"Each row reruns the stability run with one change ({variant_frames} frames); the numbers are the "
          "fluctuation range over the paper's (Table 3 at 697 mm, Table 2 at 5712 mm); **bold** within 2x.", "",
          "| run | what it tests | range | " + " | ".join(COLUMNS) + " | solved |", "|---|---|---|" + "---|" * 7]
    for r, tab in zip(PAPER_RANGES_M, ("3", "2")):
        L.append(f"| baseline | the model above | {r} | " + " | ".join(
            ("**" + _fmt(v, 2) + "**") if v is not None and 0.5 <= v <= 2 else _fmt(v, 2)
            for v in sums[r]["ratio_to_paper"][tab].values()) + f" | {sums[r]['solved']}/{sums[r]['frames']} |")
    for v in var_rows:
        tab = "3" if v["range_m"] == PAPER_RANGES_M[0] else "2"
        s = v["summary"]
        L.append(f"| {v['label']} | {v['why']} | {v['range_m']} | " + " | ".join(
            ("**" + _fmt(x, 2) + "**") if x is not None and 0.5 <= x <= 2 else _fmt(x, 2)
            for x in s["ratio_to_paper"][tab].values()) + f" | {s['solved']}/{s['frames']} |")
    L += ["", "![mechanisms](tof_mechanisms.png)", ""]
    return L


def _sweep_lines(sweep, sweep_frames) -> list[str]:
    """Accuracy against distance (the paper's Fig. 14): the table, one finding per scheme and the discussion."""
    L = []
    L += ["## Accuracy against distance (the paper's Fig. 14)", "",
          f"Target head-on at 1-10 m, {sweep_frames} frames per range; RMS error of single frames against the truth.", "",
          "| scheme | range m | solved | " + " | ".join(f"{c} RMS" for c in COLUMNS) + " | rotation RMS deg | z RMS / paper's 2.5 mm | integration us |",
          "|---|---|---|" + "---|" * 9]
    for s in sweep:
        e = s["rms"] or {}
        zr = e.get("target_z_cam_mm") / PAPER_FIG14_Z_MM if e and s["range_m"] >= 5 else None
        L.append(f"| {s['scheme']} | {s['range_m']:g} | {s['solved']}/{s['frames']} | " + " | ".join(_fmt(e.get(c)) for c in COLUMNS)
                 + f" | {_fmt(s['rot_err_rms_deg'])} | {_ratio_cells([zr]) if zr is not None else '-'} | {s['integration_time_s'] * 1e6:.2f} |")
    L.append("")
    for scheme, _ in SWEEP_SCHEMES:
        rows = [s for s in sweep if s["scheme"] == scheme and s["rms"]]
        within = [s["range_m"] for s in rows if max(s["rms"][c] for c in COLUMNS[:3]) <= 2.0
                  and s["rot_err_rms_deg"] <= PAPER_ACCURACY["deg"]]
        zmax = max(rows, key=lambda s: s["rms"]["target_z_cam_mm"]) if rows else None
        L.append(f"- {scheme}: single frames meet the paper's headline accuracy (2 mm and 0.13 deg, every position "
                 f"component and the total rotation) at {', '.join(f'{x:g}' for x in within) or 'no'} m; the largest "
                 f"range error is {_fmt(zmax['rms']['target_z_cam_mm'], 1) if zmax else 'nan'} mm RMS at "
                 f"{zmax['range_m'] if zmax else 'nan'} m (bias {_fmt(zmax['bias']['target_z_cam_mm'], 1) if zmax else 'nan'} mm).")
    L += ["", "The paper's Fig. 14 text: beyond 5 m its range error is 2.5 mm (larger below 5 m, which it puts down to "
          "the target's calibration and installation); its pitch and yaw accuracy is not analysed (coupled by the "
          "turntable). In the converged optimum the range comes from the pattern's apparent size, so the "
          "centroid biases of 2-5 px blobs (defocus at the 1 m focus, the small markers merging with their "
          "neighbours beyond ~8 m) become a range bias that grows with range; the literal iteration, stopped by its "
          "threshold, keeps most of the measured range at long range (its error is then the depth noise and the "
          "part of the iteration that did run); blending the depths in by maximum likelihood removes the bias "
          "but brings the depth noise into the tilt.", "",
          "![Fig. 14 sweep](tof_fig14.png)", "",
          "## Failure modes", ""]
    return L


def _failure_lines(fm) -> list[str]:
    """Failure modes at 1 m: flying pixels, multipath (plate, wall), ambient light."""
    L = []
    fp, mp, amb = fm["flying_pixels_1m"], fm["multipath_1m"], fm["ambient_1m"]
    L += [f"- **Flying pixels** at the marker rims (1 m, noise-free): {fp['count']} pixels whose phasor depth lies "
          "between the marker face and the plate behind it (per marker: "
          + ", ".join(f"{k}: {v}" for k, v in fp["per_marker"].items()) + "). The retroreflective face outshines the "
          "plate ~100x, so most rim pixels take the face's depth: the flying pixels are the outer rims of the large markers.",
          f"- **Multipath** from the plate (2 bounces against 1, at 1 m): marker depths change by "
          f"{_fmt(mp['marker_depth_change_mm_median'], 3)} mm (median; largest {_fmt(mp['marker_depth_change_mm_max'], 2)} mm), plate depths by "
          f"{_fmt(mp['plate_depth_change_mm_median'], 3)} mm (95th percentile |change| "
          f"{_fmt(mp['plate_depth_change_mm_p95'], 2)} mm): the black plate (albedo 0.04) and the marker faces, which "
          "face the same way, exchange little light. Noise-free pose, direct returns: "
          + ", ".join(f"{k} {_fmt(v)}" for k, v in fm['pose_noise_free_direct'].items() if k != 'failed')
          + "; with multipath: " + ", ".join(f"{k} {_fmt(v)}" for k, v in fm['pose_noise_free_multipath'].items() if k != 'failed') + ".",
          f"- **Multipath from a white wall** (albedo 0.8, 0.3 m tall, beside the markers, 2 bounces against 1): "
          f"marker depths change by {_fmt(fm['multipath_wall_1m']['marker_depth_change_mm_median'], 3)} mm (median; largest "
          f"{_fmt(fm['multipath_wall_1m']['marker_depth_change_mm_max'], 2)} mm), plate pixels by up to "
          f"{_fmt(fm['multipath_wall_1m']['plate_depth_change_mm_p95'], 2)} mm (95th percentile); noise-free pose with "
          "the wall, direct: " + ", ".join(f"{k} {_fmt(v)}" for k, v in fm['pose_noise_free_wall_direct'].items() if k != 'failed')
          + "; with multipath: " + ", ".join(f"{k} {_fmt(v)}" for k, v in fm['pose_noise_free_wall_multipath'].items() if k != 'failed') + ".",
          f"- **Ambient light** at 1 m: per-pixel depth noise of the marker pixels "
          f"{_fmt(amb['1000']['marker_depth_std_mm'], 2)} mm at 1000 lux and {_fmt(amb['10000']['marker_depth_std_mm'], 2)} mm "
          f"at 10 klux; of the plate pixels {_fmt(amb['1000']['plate_depth_std_mm'], 1)} and "
          f"{_fmt(amb['10000']['plate_depth_std_mm'], 1)} mm (valid fraction {_fmt(amb['1000']['plate_valid_fraction'], 2)} and "
          f"{_fmt(amb['10000']['plate_valid_fraction'], 2)}). The stability runs at 10 klux are in the mechanism table.", "",
          "![failure modes](tof_failure_modes.png)", ""]
    return L

def findings(sums, var_rows) -> list[str]:
    """The measured conclusions, from the numbers (no hard-coded verdicts)."""
    near, far = PAPER_RANGES_M

    def count(s, tab):
        return sum(1 for v in s["ratio_to_paper"][tab].values() if v is not None and 0.5 <= v <= 2)

    L = ["### Findings", ""]
    L.append(f"- At {far * 1e3:.0f} mm the baseline has {count(sums[far], '2')} of 6 components within 2x of Table 2 "
             f"in single frames; at {near * 1e3:.0f} mm {count(sums[near], '3')} of 6 of Table 3 (median ratio "
             f"{np.median([v for v in sums[near]['ratio_to_paper']['3'].values() if v is not None]):.2g}): the simulation is "
             "much quieter at the near range, where the paper's sensor was noisier than at the far one.")
    caps = [v for v in var_rows if v["label"].startswith("active-set cap")]
    if caps:
        parts = []
        for v in caps:
            rr = [x for x in v["summary"]["ratio_to_paper"]["3"].values() if x is not None]
            parts.append(f"{v['label'].split('= ')[1]}: {min(rr):.2g}-{max(rr):.2g}x ({count(v['summary'], '3')}/6 within 2x)")
        L.append("- **The near range's noise is the paper's active-set cap** (section 3.1: the active set is limited "
                 "to N_max pixels, the dimmest discarded first). At 0.7 m the eight retroreflective faces fill ~8000 "
                 "pixels above the threshold with a flat top, so a cap below that drops pixels chosen by the noise, "
                 "frame by frame, and the centroids jitter; at 5.7 m the markers cover ~100 pixels and no cap of that "
                 "kind binds. Ratios to Table 3 against N_max: " + "; ".join(parts) + ". The paper's N_max is not "
                 "legible in our copy, so it is not fitted: the default keeps the pipeline's 12000 (never binding) and "
                 "`--max-active-pixels` sets it.")
    def one(prefix, r):
        return next((v["summary"] for v in var_rows if v["label"].startswith(prefix) and v["range_m"] == r), None)

    def cells(sm, tab):
        return ", ".join(f"{SHORT_NAMES[c]} {_fmt(sm['ratio_to_paper'][tab][c], 2)}" for c in COLUMNS)

    gn, ml = one("converged optimum", far), one("ML depth", far)
    if gn and ml:
        L.append(f"- **Refinement scheme at {far * 1e3:.0f} mm** (Table 2 ratios): the literal iteration (default) "
                 f"{cells(sums[far], '2')}; its converged optimum {cells(gn, '2')}; the ML depth blend {cells(ml, '2')} "
                 f"({count(sums[far], '2')}, {count(gn, '2')} and {count(ml, '2')} of 6 within 2x). The ML blend weights "
                 "the depths with an assumed 0.05 px centroid sigma, 25-100x too much for these datasheet-limited depths.")
    for prefix, what in (("no recursive median", "The recursive median of depth (section 3.1.2) switched off"),
                         ("centroid weighting: intensity", "The paper's intensity-weighted centroid (many pixels per marker)"),
                         ("integration time 1/4", "A quarter of the automatic integration time")):
        a, b = one(prefix, near), one(prefix, far)
        if a and b:
            L.append(f"- **{what}**: Table 3 ratios at {near * 1e3:.0f} mm {cells(a, '3')} (baseline "
                     f"{cells(sums[near], '3')}); Table 2 ratios at {far * 1e3:.0f} mm {cells(b, '2')}.")
    ref = [v for v in var_rows if v["label"].startswith("reference point") and v["range_m"] == far]
    if ref:
        L.append(f"- **Reference point**: at the plate centre x and y fluctuate {_fmt(ref[0]['summary']['ratio_to_paper']['2']['target_x_cam_mm'], 1)}x "
                 f"and {_fmt(ref[0]['summary']['ratio_to_paper']['2']['target_y_cam_mm'], 1)}x the paper's at 5.7 m - the tilt noise "
                 "times the 125 mm lever - which is why the marker centroid is reported.")
    lam = [v for v in var_rows if v["label"].startswith("Lambertian") and v["range_m"] == far]
    if lam:
        L.append(f"- **Marker material**: white paint at 5.7 m returns ~1000x less than the sheeting; the integration "
                 f"time then hits its 1 ms limit and the fluctuation is {_fmt(np.median([x for x in lam[0]['summary']['ratio_to_paper']['2'].values() if x is not None]), 2)}x "
                 "the paper's (median over components). With sheeting the automatic integration time keeps the brightest "
                 "pixel at ~1000 LSB at both ranges, so the sheeting class hardly matters for the noise.")
    return L + [""]


__all__ = ["run_study", "PAPER_RANGES_M", "SWEEP_RANGES_M"]
