"""The range sweep: success rate, blobs found and pose errors versus range, from full renders.

Scenarios (:func:`range_sweep_trials`)
    At each range ``r_i`` of the sweep, ``poses`` rendered poses: pose 0 is the nominal pose
    (the scenario's lateral offsets and attitude), poses ``1 ..`` add seeded Gaussian jitter
    (``jitter_m`` on the target's lateral offsets, ``jitter_deg`` on roll, pitch and yaw, 1 sigma). Each pose is
    rendered once and exposed ``trials`` times (noise draws): render once, expose many. Trial
    ``i = (i_range * poses + i_pose) * trials + k``; the trials of one pose form one render
    group of the ``render`` trial kind (:mod:`svgs_sim.sim.render_trial`).

Seeds (:mod:`svgs_sim.studies.seeding`)
    Trial ``i`` exposes with :func:`~svgs_sim.studies.seeding.trial_seed` ``(seed, i)``. A pose's
    jitter and its render's Monte Carlo seed are drawn from the design stream
    (:func:`~svgs_sim.studies.seeding.design_rng`) of the pose's first trial. Numbers therefore do not
    depend on the executor, the worker count, the task packing or on a resumed run.

Outputs in the study directory
    ``manifest.json`` and ``results.csv`` (the resumable store, one row per trial),
    ``trials.jsonl`` (one JSON record per trial in the layout of
    :func:`svgs_sim.sim.closed_loop.expose_and_solve`, plus ``range_m``, ``pose_index``, ``trial``;
    read by ``tools/compare_paper.py``), ``summary.csv`` and ``range_sweep.png``.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from svgs_sim.base.errors import InputError
from svgs_sim.base.image_files import write_image
from svgs_sim.sim.metrics import ATT_ERR_VEC_DEG, POS_ERR_NORM_M, POS_ERR_VEC_M, ROT_ERR_DEG
from svgs_sim.sim.render_trial import (
    RenderScenario,
    check_threshold,
    render_trial_scenario,
    threshold_parameter,
    trial_picture,
)
from svgs_sim.sim.scene import Scene
from svgs_sim.sim.target_pose import TargetPose
from svgs_sim.svgs.frames import STATE_KEYS
from svgs_sim.svgs.overlay import render_overlay
from svgs_sim.svgs.pipeline import camera_threshold

from .execution import Trial
from .seeding import check_seed, design_rng, trial_seed
from .tail import run_rendered_study, write_dict_csv

#: The render options a sweep may force (None: the renderer's or the phone's own).
_ROW_OPTIONS = ("spp", "roi_spp", "exposure_s", "iso")

#: Pose keys of the scenario that a pose's jitter moves, with the jitter option that scales each.
JITTER_KEYS = (("target_x_m", "jitter_m"), ("target_y_m", "jitter_m"), ("roll_deg", "jitter_deg"), ("pitch_deg", "jitter_deg"),
               ("yaw_deg", "jitter_deg"))


@dataclass(frozen=True)
class RangeSweepConfig(TargetPose):
    """What a range sweep computes (its manifest); how it runs is not part of it.

    Attributes
    ----------
    camera, pattern : str
    ranges_m : tuple of float
    trials : int
        Exposures (noise draws) per rendered pose.
    poses : int
        Rendered poses per range (beyond the first, jittered).
    jitter_deg, jitter_m : float
        1-sigma jitter of the extra poses.
    seed : int
    threshold : str
        ``app`` (the app's brightness threshold for the camera, :mod:`svgs_sim.svgs.app`; default),
        ``auto``, ``otsu`` or a level.
    target_x_m, target_y_m, roll_deg, pitch_deg, yaw_deg : float
        The nominal pose besides the range (keyword-only, :class:`svgs_sim.sim.target_pose.TargetPose`).
    scene : svgs_sim.sim.scene.Scene
        The scene around the target (default: the paper's lab).
    spp, roi_spp : int or None
        Samples per pixel of the full frame and the spot windows (None: the renderer's).
    exposure_s : float or None
        Exposure time forced on the phone, s (None: its auto-exposure).
    iso : float or None
        ISO forced on the phone (None: its auto-exposure).
    """

    camera: str
    ranges_m: tuple
    trials: int = 20
    poses: int = 1
    jitter_deg: float = 1.0
    jitter_m: float = 0.01
    seed: int = 0
    pattern: str = "svgs-3u"
    threshold: str = "app"
    scene: Scene = field(default_factory=Scene)
    spp: int | None = None
    roi_spp: int | None = None
    exposure_s: float | None = None
    iso: float | None = None

    def manifest(self) -> dict:
        """The results store's manifest: the fields as a render trial's row writes them (the
        scene's parameters flat, None as the row's code), so a study folder of 0.1 resumes."""
        d = {k: v for k, v in asdict(self).items() if k != "scene"}
        d["ranges_m"] = [float(r) for r in self.ranges_m]
        at = list(d).index("spp")
        row = self.row_options()
        items = list(d.items())
        items[at:] = [*self.scene.row_values().items(), *((k, row[k]) for k in _ROW_OPTIONS)]
        return {"study": "range-sweep", "trial_kind": "render", **dict(items)}

    def row_options(self) -> dict:
        """``spp``, ``roi_spp``, ``exposure_s`` and ``iso`` as a render trial's row writes them
        (the results store's codec: None as -1 or 0)."""

        out = {k: RenderScenario.row_code(k, getattr(self, k)) for k in _ROW_OPTIONS}
        return {**out, "spp": int(out["spp"]), "roi_spp": int(out["roi_spp"])}

    @property
    def n_trials(self) -> int:
        return len(self.ranges_m) * self.poses * self.trials


def _count(value, flag: str) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise InputError(f"{flag}: expected a positive integer, got {value!r}")
    return int(value)


def _nonneg(value, flag: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{flag}: expected a number, got {value!r}") from None
    if not np.isfinite(v) or v < 0:
        raise InputError(f"{flag}: expected a non-negative number, got {value!r}")
    return v


def make_config(camera: str, ranges_m, *, trials: int = 20, poses: int = 1, jitter_deg: float = 1.0,
                jitter_m: float = 0.01, seed: int = 0, **options) -> RangeSweepConfig:
    """A validated :class:`RangeSweepConfig` (:class:`InputError` naming the option on bad input).

    Parameters
    ----------
    camera : str
        Camera profile name or path (needs ``[optics]`` and ``[flash]``).
    ranges_m : sequence of float
        Positive, distinct ranges.
    **options
        Other :class:`RangeSweepConfig` fields (pattern, threshold, nominal pose, ``scene``,
        samples per pixel, forced exposure; None: the default).
    """

    if "threshold" in options:
        options["threshold"] = check_threshold(options["threshold"])
    if not isinstance(options.get("scene", Scene()), Scene):
        raise InputError(f"scene: expected a svgs_sim.sim.scene.Scene, got {options['scene']!r}")
    rs = [float(r) for r in ranges_m]
    if not rs:
        raise InputError("--ranges: no range given")
    if len(set(rs)) != len(rs):
        raise InputError(f"--ranges: repeated range in {rs}")
    cfg = RangeSweepConfig(camera=str(camera), ranges_m=tuple(rs), trials=_count(trials, "--trials"),
                           poses=_count(poses, "--poses"), jitter_deg=_nonneg(jitter_deg, "--jitter-deg"),
                           jitter_m=_nonneg(jitter_m, "--jitter-m"), seed=check_seed(seed), **options)
    for r in rs:  # validates every scenario value now, before any work (InputError)
        render_trial_scenario(**_fixed(cfg), range_m=r)
    return cfg


def _fixed(cfg: RangeSweepConfig) -> dict:

    keys = ("camera", "pattern", "target_x_m", "target_y_m", "roll_deg", "pitch_deg", "yaw_deg")
    return {**{k: getattr(cfg, k) for k in keys}, **cfg.scene.row_values(), **cfg.row_options(),
            "threshold": threshold_parameter(cfg.threshold)}


def range_sweep_trials(cfg: RangeSweepConfig) -> list:
    """Every trial of the sweep (see the module docstring).

    Returns
    -------
    list of :class:`svgs_sim.studies.execution.Trial`
    """


    trials = []
    base = _fixed(cfg)
    for ri, r in enumerate(cfg.ranges_m):
        for pk in range(cfg.poses):
            first = (ri * cfg.poses + pk) * cfg.trials
            rng = design_rng(cfg.seed, first)
            z = rng.standard_normal(len(JITTER_KEYS))
            pose = dict(base)
            if pk > 0:
                for (key, scale), zi in zip(JITTER_KEYS, z):
                    pose[key] = base[key] + zi * getattr(cfg, scale)
            render_seed = int(rng.integers(2**31))
            for k in range(cfg.trials):
                i = first + k
                scen = render_trial_scenario(**pose, range_m=r, render_seed=render_seed,
                                      labels={"pose_index": pk, "trial": k})
                trials.append(Trial(i, scen, trial_seed(cfg.seed, i)))
    return trials


# --------------------------------------------------------------------------- records and summary
def trial_records(rows: list[dict]) -> list[dict]:
    """The stored rows as the JSON records of ``trials.jsonl``.

    Each record has the keys of :func:`svgs_sim.sim.closed_loop.expose_and_solve` (``ok``, ``reason``,
    ``message``, ``n_blobs``, ``truth_state``, ``exposure_s``, ``iso``, ``expose_s``,
    ``solve_s``, ``state``, ``residual_rms_px`` and the errors of :mod:`svgs_sim.sim.metrics`:
    ``pos_err_vec_m``, ``att_err_vec_deg``, ``pos_err_norm_m``, ``rot_err_deg``) and the
    sweep's ``range_m``, ``pose_index``, ``trial``, ``trial_id``, ``seed``.

    Parameters
    ----------
    rows : list of dict
        :meth:`svgs_sim.studies.store.ResultStore.read_rows`, sorted by ``trial_id``.
    """

    out = []
    for r in rows:
        ok = bool(r["ok"])
        rec = {"ok": ok, "reason": r["reason"], "message": r["message"], "n_blobs": r["n_blobs"],
               "truth_state": {k: r[f"true_{k}"] for k in STATE_KEYS},
               "exposure_s": r["exposure_s_used"], "iso": r["iso_used"], "expose_s": r["expose_s"],
               "solve_s": r["solve_s"],
               "state": {k: r[f"est_{k}"] for k in STATE_KEYS} if ok else None,
               "residual_rms_px": r["residual_rms_px"],
               POS_ERR_VEC_M: [r[f"err_{k}"] for k in STATE_KEYS[:3]] if ok else None,
               ATT_ERR_VEC_DEG: [r[f"err_{k}"] for k in STATE_KEYS[3:]] if ok else None,
               POS_ERR_NORM_M: r[POS_ERR_NORM_M], ROT_ERR_DEG: r[ROT_ERR_DEG],
               "range_m": r["range_m"], "pose_index": r["pose_index"], "trial": r["trial"],
               "trial_id": r["trial_id"], "seed": r["seed"]}
        out.append(rec)
    return out


def summarise(records) -> list[dict]:
    """Per-range table: blobs, success rate, merged rate, mean and std of the error components.

    Parameters
    ----------
    records : list of dict
        :func:`trial_records`.
    """

    out = []
    for r in sorted({row["range_m"] for row in records}):
        rr = [x for x in records if x["range_m"] == r]
        ok = [x for x in rr if x["ok"]]
        reasons = {}
        for x in rr:
            if not x["ok"]:
                reasons[x["reason"]] = reasons.get(x["reason"], 0) + 1
        d = {
            "range_m": r, "trials": len(rr),
            "blobs_median": float(np.median([x["n_blobs"] or 0 for x in rr])),
            "four_blobs_rate": float(np.mean([(x["n_blobs"] or 0) == 4 for x in rr])),
            "success_rate": len(ok) / len(rr),
            "merged_rate": reasons.get("merged_spots", 0) / len(rr),
            "failures": ";".join(f"{k}:{v}" for k, v in sorted(reasons.items())),
            "exposure_s": float(np.median([x["exposure_s"] for x in rr])),
            "iso": float(np.median([x["iso"] for x in rr])),
        }
        for idx, name in enumerate(STATE_KEYS):
            key, j = (POS_ERR_VEC_M, idx) if idx < 3 else (ATT_ERR_VEC_DEG, idx - 3)
            v = np.array([x[key][j] for x in ok]) if ok else np.array([np.nan])
            d[f"err_mean_{name}"] = float(np.mean(v))
            d[f"err_std_{name}"] = float(np.std(v))
        out.append(d)
    return out


def plot_sweep(table, path, title) -> None:
    """``range_sweep.png``: success and merged rates, blobs found, |mean| + std of the position error."""
    from matplotlib.figure import Figure

    r = [d["range_m"] for d in table]
    fig = Figure(figsize=(14, 4))
    ax = fig.subplots(1, 3)
    ax[0].plot(r, [d["success_rate"] for d in table], "o-", label="solved")
    ax[0].plot(r, [d["merged_rate"] for d in table], "s--", label="failed: merged spots")
    ax[0].set(xlabel="range (m)", ylabel="fraction of trials", ylim=(-0.05, 1.05), title="success")
    ax[0].legend()
    ax[1].plot(r, [d["blobs_median"] for d in table], "o-")
    ax[1].axhline(4, color="grey", lw=0.5)
    ax[1].set(xlabel="range (m)", ylabel="blobs found (median)", title="blobs",
              ylim=(0, max(6.0, max(d["blobs_median"] for d in table) + 1)))
    for name in ("x_m", "y_m", "z_m"):
        ax[2].plot(r, [abs(d[f"err_mean_{name}"]) + d[f"err_std_{name}"] for d in table], "o-", label=f"|mean|+std {name}")
    ax[2].set(xlabel="range (m)", ylabel="position error (m)", title="errors", yscale="log")
    ax[2].legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def format_table(table) -> list[str]:
    """The per-range table as printed by ``svgs range-sweep``."""
    lines = [(f"{'range_m':>8} {'blobs':>5} {'4 blobs':>7} {'solved':>6} {'merged':>6} {'exp_ms':>7} {'iso':>5}  "
              "err x/y/z (m, mean+-std)        failures")]
    for d in table:
        errs = " ".join(f"{d[f'err_mean_{n}']:+.3f}+-{d[f'err_std_{n}']:.3f}" for n in ("x_m", "y_m", "z_m"))
        lines.append(f"{d['range_m']:8.2f} {d['blobs_median']:5.1f} {d['four_blobs_rate']:7.2f} {d['success_rate']:6.2f} "
                     f"{d['merged_rate']:6.2f} {d['exposure_s'] * 1e3:7.2f} {d['iso']:5.0f}  {errs}  {d['failures']}")
    return lines


def write_outputs(out_dir, cfg: RangeSweepConfig, rows: list[dict]) -> tuple[list[dict], list[dict]]:
    """``trials.jsonl``, ``summary.csv`` and ``range_sweep.png`` from the stored rows, and
    ``overlays.png`` (it renders each range's first trial again) unless the folder's one is newer
    than its results: a rerun of a finished sweep re-renders nothing.

    Returns
    -------
    (records, table)
    """
    out_dir = Path(out_dir)
    records = trial_records(rows)
    table = summarise(records)
    write_dict_csv(out_dir / "summary.csv", table)
    with open(out_dir / "trials.jsonl", "w", encoding="utf-8") as fh:
        fh.writelines(json.dumps(rec) + "\n" for rec in records)
    plot_sweep(table, out_dir / "range_sweep.png",
               f"{cfg.camera}: range sweep ({cfg.trials} trials x {cfg.poses} pose(s) per range)")
    overlays, results = out_dir / "overlays.png", out_dir / "results.csv"
    if not (overlays.exists() and results.exists() and overlays.stat().st_mtime >= results.stat().st_mtime):
        sample_overlays(overlays, cfg)
    return records, table


def sample_overlays(path, cfg: RangeSweepConfig, panel_px: int = 420) -> str:
    """``overlays.png``: at each range, what the sensor saw in the sweep's first trial (the nominal
    pose, its first exposure) - the detected blobs, the target labels and the solution's
    reprojection (:func:`svgs_sim.svgs.overlay.render_overlay`), re-made from the trial's own seeds."""
    import cv2

    from svgs_sim.svgs.detect import detect_blobs

    trials = range_sweep_trials(cfg)
    firsts = {}
    for t in trials:
        if t.scenario["pose_index"] == 0 and t.scenario["trial"] == 0:
            firsts.setdefault(t.scenario["range_m"], t)
    panels = []
    for r in cfg.ranges_m:
        t = firsts[r]
        pic = trial_picture(t.scenario, int(t.seed))
        sol, cam, pat = pic["row"]["_solution"], pic["camera"], pic["pattern"]

        blobs = detect_blobs(pic["image"], threshold=camera_threshold(pic["image"], cam, pic["threshold"]))
        targets = {str(k): v for k, v in sol.targets_px.items()} if sol else {}
        reproj = ({str(int(i)): uv for i, uv in zip(pat.ids, cam.project_target(pat.points_m, sol.R_cam_target,
                                                                                 sol.t_cam_target_m))} if sol else {})
        title = f"{r:g} m: " + (f"solved, {sol.residual_rms_px:.3f} px" if sol else f"{sol.reason}") + f", {len(blobs)} blobs"
        img = render_overlay(pic["image"], blobs_px=blobs.centroid_px, targets_px=targets, reprojected_px=reproj,
                             title=title, size_px=panel_px)
        panels.append(cv2.resize(img, (panel_px, int(round(img.shape[0] * panel_px / img.shape[1])))))
    h = max(p.shape[0] for p in panels)
    panels = [np.vstack([p, np.zeros((h - p.shape[0], panel_px, 3), np.uint8)]) for p in panels]
    ncols = min(4, len(panels))
    rows = []
    for i in range(0, len(panels), ncols):
        row = panels[i:i + ncols]
        row += [np.zeros_like(panels[0])] * (ncols - len(row))
        rows.append(np.hstack(row))
    write_image(path, np.vstack(rows))
    return str(path)


def run_range_sweep(cfg: RangeSweepConfig, out_dir, spec, *, chunk_size=None, progress: bool = True):
    """Run (or resume) a range sweep into ``out_dir`` and write its outputs.

    Parameters
    ----------
    cfg : RangeSweepConfig
    out_dir : str or Path
        Study directory; a rerun skips the finished trials, a changed ``cfg`` is refused.
    spec : svgs_sim.studies.execution.ExecutorSpec
    chunk_size : int, optional
        Trials per task (a pose's render group is kept whole).

    Returns
    -------
    (table, stats)
        The per-range summary and the :class:`~svgs_sim.studies.execution.RunStats` (None if every
        trial was already done).
    """
    (_, table), stats = run_rendered_study(range_sweep_trials(cfg), out_dir, cfg.manifest(), spec,
                                           lambda rows: write_outputs(out_dir, cfg, rows),
                                           description=f"range sweep {cfg.camera}", chunk_size=chunk_size,
                                           progress=progress)
    return table, stats
