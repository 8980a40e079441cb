"""The calibration study end to end (``svgs calibrate study``): inputs, trials, results.

:func:`run_calibration_study` makes the study's inputs once - the board set and its
detections, the focal frames - and keeps them in the study folder; then runs the three
parts' trials (:mod:`svgs_sim.studies.calibration.trials`) through :func:`svgs_sim.studies.execution.run_study`
on the chosen executor, each part into a :class:`svgs_sim.studies.store.ResultStore`::

    OUT/trials/convergence/  manifest.json, results.csv, board_detections.npz
    OUT/trials/focal/        manifest.json, results.csv, focal_frames.npz
    OUT/trials/pose/         manifest.json, results.csv

A rerun with the same ``OUT`` and parameters resumes: it reuses the inputs and runs only
the trials not yet stored; other parameters are refused with the list of differences.
The numbers do not depend on the executor (see :mod:`svgs_sim.studies.calibration.trials`).

``geometric=True`` replaces the renders by :func:`svgs_sim.calibration.synthesize_views` (boards)
and projected, noisy centroids (pattern): no Mitsuba, seconds instead of minutes (tests,
quick looks). Nothing here imports Mitsuba at import time.
"""

from __future__ import annotations

import contextlib
import json
import shutil
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from svgs_sim.base.errors import InputError, SimulationFailure, check_finite_positive
from svgs_sim.base.profiles import Camera, DISTORTION_KEYS, Pattern, load_camera, load_pattern
from svgs_sim.calibration import Board, synthesize_views
from svgs_sim.calibration.synthetic import sample_board_poses
from svgs_sim.sim.boards import BoardSet, render_board_set
from svgs_sim.studies.execution import (
    DEFAULT_CHUNK_SIZE,
    Trial,
    check_executor,
    executor_spec,
    open_executor,
    run_study,
)
from svgs_sim.studies.seeding import trial_seed
from svgs_sim.studies.store import ResultStore

from .common import (
    DEFAULT_BOARD,
    DEFAULT_FLOOR_NOISE_PX,
    DEFAULT_FOCAL_EXPOSURES,
    DEFAULT_FOCAL_RANGES_M,
    DEFAULT_FOCAL_TRIALS,
    DEFAULT_NOISE_LEVELS_PX,
    DEFAULT_POSE_RANGES_M,
    DEFAULT_POSES_PER_RANGE,
    DEFAULT_SUBSETS,
    DEFAULT_TRUE_DIST,
    DEFAULT_TRUE_PP_OFFSET_PX,
    DEFAULT_VIEWS_LIST,
    POSE_SPREAD,
    cam_json,
    profile_dict,
    spawn_seeds,
    true_camera,
)
from .convergence import (
    ERROR_COLUMNS,
    check_views_list,
    convergence_subsets,
    convergence_summary,
    detect_all,
    load_detections,
    save_detections,
    upgrade_stored_columns,
)
from .focal import (
    FOCAL_COLUMNS,
    FocalFrames,
    centroid_noise,
    check_focal_frames,
    focal_cases,
    focal_frames_geometric,
    focal_frames_rendered,
    focal_only_estimate,
)
from .plan import part_plan, study_plan
from .pose import SUMMARY_COLUMNS, error_cases, pose_seeds
from .table4 import paper_phone, table4_comparison
from .trials import KINDS, SCENARIO_KEYS, convergence_scenario, focal_scenario, pose_scenario


@dataclass
class StudyResult:
    """Everything :func:`run_calibration_study` measured (tables as lists of dict rows)."""

    config: dict
    camera_nominal: Camera
    camera_true: Camera
    board_set_info: dict
    convergence_rows: list
    convergence: list
    focal_frames: FocalFrames | None
    centroid_noise: list
    focal_rows: list
    focal_estimate: object
    pose_rows: list
    table4: dict
    believed: dict
    timings_s: dict
    run_stats: dict = field(default_factory=dict)

    def key_numbers(self) -> dict:
        """The acceptance numbers, flat."""
        conv = self.convergence[-1] if self.convergence else {}
        best = [r for r in self.convergence_rows if r["n_views"] == conv.get("n_views")]
        fe = self.focal_estimate
        return {
            "n_views_max": conv.get("n_views"),
            "fx_error_pct_max_abs": conv.get("fx_error_pct_max_abs"),
            "fy_error_pct_max_abs": conv.get("fy_error_pct_max_abs"),
            "pp_error_norm_px_max": conv.get("pp_error_norm_px_max"),
            "map_rot_rms_px_max": conv.get("map_rot_rms_px_max"),
            "map_rms_px_mean": conv.get("map_rms_px_mean"),
            "rms_reprojection_px": best[0]["rms_px"] if best else None,
            "focal_only_f_px": float(fe.f_px) if fe is not None else None,
            "focal_only_error_pct": (100.0 * (fe.f_px / self.camera_true.fx - 1.0) if fe is not None else None),
        }


@dataclass
class _Setup:
    """The study's checked parameters and part seeds."""

    nominal: Camera
    camera_true: Camera
    pattern: Pattern
    pattern_ref: str
    board: Board
    config: dict
    seeds: dict


def _pattern_ref(pattern, loaded: Pattern) -> str:
    """How trial scenarios name the pattern (a name or the path as given; never resolved)."""
    if isinstance(pattern, (str, Path)):
        return str(pattern)
    try:
        load_pattern(loaded.name)
        return loaded.name
    except InputError:
        from .trials import input_path

        return input_path(loaded.source)


def _setup(camera, *, views_list=DEFAULT_VIEWS_LIST, seed=0, board=None, subsets=DEFAULT_SUBSETS, spp=16,
           geometric=False, true_pp_offset_px=DEFAULT_TRUE_PP_OFFSET_PX, true_dist=DEFAULT_TRUE_DIST,
           focal_ranges_m=DEFAULT_FOCAL_RANGES_M, focal_exposures=DEFAULT_FOCAL_EXPOSURES,
           noise_levels_px=DEFAULT_NOISE_LEVELS_PX, pose_ranges_m=DEFAULT_POSE_RANGES_M,
           poses_per_range=DEFAULT_POSES_PER_RANGE, floor_noise_px=DEFAULT_FLOOR_NOISE_PX, pattern="svgs-3u") -> _Setup:
    """Load and check the parameters (:class:`InputError` before any work); the defaults are
    :func:`run_calibration_study`'s."""
    nominal = load_camera(camera)
    pat = load_pattern(pattern)
    board = board or Board(*DEFAULT_BOARD)
    cam_true = true_camera(nominal, true_pp_offset_px, true_dist)
    vl = tuple(sorted({int(v) for v in views_list}))
    if not vl or vl[0] < 3:
        raise InputError(f"--views-list: every number of views must be at least 3, got {list(views_list)}")
    fr = tuple(float(r) for r in focal_ranges_m)
    if len(fr) < 1 or min(fr) <= float(pat.points_m[:, 2].max()):
        raise InputError(f"--focal-ranges: expected positive ranges beyond the pattern's depth, got {list(focal_ranges_m)}")
    if any(float(r) <= 0 for r in pose_ranges_m):
        raise InputError(f"pose ranges: expected positive ranges, got {list(pose_ranges_m)}")
    check_finite_positive(cam_true.fx, "true focal length")
    config = {
        "camera": nominal.name, "views_list": list(vl), "seed": int(seed), "board": board.describe(),
        "subsets": int(subsets), "spp": int(spp), "geometric": bool(geometric),
        "true_pp_offset_px": [float(x) for x in true_pp_offset_px], "true_dist": [float(x) for x in true_dist],
        "focal_ranges_m": list(fr), "focal_exposures": int(focal_exposures),
        "noise_levels_px": [float(x) for x in noise_levels_px], "pose_ranges_m": [float(x) for x in pose_ranges_m],
        "poses_per_range": int(poses_per_range), "floor_noise_px": [float(x) for x in floor_noise_px],
        "pattern": pat.name, "pose_spread": dict(POSE_SPREAD),
    }
    seeds = dict(zip(("board_set", "convergence", "focal_frames", "focal_study", "pose"), spawn_seeds(seed, 5)))
    _check_board_poses(board, cam_true, vl[-1], seeds["board_set"], true_pp_offset_px, true_dist)
    return _Setup(nominal, cam_true, pat, _pattern_ref(pattern, pat), board, config, seeds)


def _check_board_poses(board: Board, cam_true: Camera, n_views: int, seed: int, pp_offset_px, dist) -> None:
    """Draw the board set's poses as the study will (the same seed): :class:`InputError` naming the
    options when the true camera leaves no pose with the whole board in its image - before any
    store or render."""

    try:
        sample_board_poses(board, cam_true, n_views, seed=seed)
    except InputError:
        raise InputError(
            f"--true-dist {','.join(f'{float(x):g}' for x in dist)} / --true-pp-offset-px "
            f"{' '.join(f'{float(x):g}' for x in pp_offset_px)}: the true camera bends or shifts its "
            f"{cam_true.width} x {cam_true.height} px image so far that no pose keeps the whole board "
            f"({board.describe()}) inside it; give a smaller distortion or offset") from None


def manifest(setup: _Setup) -> dict:
    """What decides the study's numbers (the stores refuse to resume with anything else)."""
    return {"command": "calibrate study", **setup.config, "board_json": setup.board.to_json(),
            "camera_true": profile_dict(setup.camera_true), "pattern_points_m": setup.pattern.points_m.tolist(),
            "focal_trials": DEFAULT_FOCAL_TRIALS}


# --------------------------------------------------------------------------- inputs
def _delivered(cam: Camera, like: Camera) -> Camera:
    return cam if (cam.width, cam.height) == (like.width, like.height) else cam.scaled(like.width, like.height)


def _geometric_board_set(s: _Setup, n_views: int, say=None):
    seed = s.seeds["board_set"]
    R, t = sample_board_poses(s.board, s.camera_true, n_views, seed=seed)
    t0 = time.perf_counter()

    def tell(msg):  # a line per view: at full resolution a view takes seconds
        if say is not None:
            say(f"  board set: {msg} ({time.perf_counter() - t0:.0f} s)")

    images = list(synthesize_views(s.board, s.camera_true, R, t, oversample=3, blur_px=0.6, noise_dn=1.5, seed=seed + 1,
                                   progress=tell))
    info = {"source": "geometric (calibration.synthesize_views: blur 0.6 px, noise 1.5 DN)", "n_views": n_views}
    return images, [f"view_{k:03d}" for k in range(n_views)], s.camera_true, info


def _rendered_board_set(s: _Setup, n_views: int, board_set_dir, say):

    if board_set_dir is not None and (Path(board_set_dir) / "truth.json").is_file():
        bs = BoardSet.load(board_set_dir)
        if (len(bs) < n_views or bs.board.to_json() != s.board.to_json()
                or profile_dict(bs.camera) != profile_dict(_delivered(s.camera_true, bs.camera))):
            raise InputError(f"{str(board_set_dir)!r} holds a board set of another camera profile, board or "
                             f"size ({len(bs)} views of {bs.board.describe()}); use another --cache folder")
        say(f"board set: reusing {len(bs)} views from {board_set_dir}")
        bs.images, bs.names = bs.images[:n_views], bs.names[:n_views]
        bs.truth["views"] = bs.truth["views"][:n_views]
    else:
        bs = render_board_set(s.camera_true, s.board, n_views, seed=s.seeds["board_set"], spp=s.config["spp"],
                              out_dir=board_set_dir, progress=lambda m: say("board " + m))
    v = bs.truth["views"]
    info = {"source": "rendered (svgs_sim.sim.boards: Mitsuba, phone model)", "n_views": n_views,
            "render_s_mean": float(np.mean([x["timings_s"]["render_s"] for x in v])),
            "exposure_ms_mean": 1e3 * float(np.mean([x["exposure_s"] for x in v])),
            "distance_m_range": [float(min(x["distance_m"] for x in v)), float(max(x["distance_m"] for x in v))],
            "render": bs.truth["render"]}
    return bs.images, bs.names, bs.camera, info


def board_detections(s: _Setup, path: Path, board_set_dir, say, timings: dict):
    """The board set's detections: from ``path`` if a run left them, else made and saved there.

    Returns
    -------
    (Detections, Camera, dict)
        Detections, the camera that made the images, the set's description.
    """

    if path.is_file():
        det, camera, info = load_detections(path)
        say(f"board set: reusing the detections of {info['n_views']} views in {path.parent}")
        return det, camera, info
    t0 = time.perf_counter()
    n_views = s.config["views_list"][-1]
    if s.config["geometric"]:
        say(f"board set: drawing {n_views} geometric views at {s.camera_true.width}x{s.camera_true.height} px ...")
        images, names, camera, info = _geometric_board_set(s, n_views, say)
        say(f"board set: {n_views} geometric views in {time.perf_counter() - t0:.1f} s")
    else:
        images, names, camera, info = _rendered_board_set(s, n_views, board_set_dir, say)
    info["board"] = s.board.describe()
    timings["board_set_s"] = time.perf_counter() - t0
    say(f"detecting the board in {len(images)} views (OpenCV) ...")
    det = detect_all(images, s.board, names)
    info["found"] = len(det)
    info["skipped"] = [f"{n}: {f.message}" for n, f in det.skipped]
    say(f"board found in {len(det)} of {len(images)} views")
    save_detections(path, det, camera, info)
    return det, camera, info


def focal_frames(s: _Setup, path: Path, cache, say) -> FocalFrames:
    """The focal frames: from ``path`` if a run left them, else from ``cache`` or made; saved to ``path``."""

    fr, exposures = s.config["focal_ranges_m"], s.config["focal_exposures"]
    for src in (path, None if (s.config["geometric"] or cache is None) else Path(cache)):
        if src is not None and src.is_file():
            frames = FocalFrames.load(src)
            if (frames.ranges_m.tolist() != list(fr) or frames.centroids_px.shape[1] != int(exposures)
                    or (not s.config["geometric"] and frames.camera != profile_dict(s.camera_true))):
                raise InputError(f"{str(src)!r} holds focal frames of another camera profile, ranges or exposures; "
                                 "use another --cache folder")
            say(f"focal frames: reusing {src}")
            break
    else:
        if s.config["geometric"]:
            frames = focal_frames_geometric(s.camera_true, s.pattern, fr, exposures=exposures,
                                            seed=s.seeds["focal_frames"])
        else:
            frames = focal_frames_rendered(s.camera_true, s.nominal, s.pattern, fr, exposures=exposures,
                                           seed=s.seeds["focal_frames"], progress=say)
            frames.camera = profile_dict(s.camera_true)
            if cache is not None:
                frames.save(cache)
    if not path.is_file():
        frames.save(path)
    return frames


# --------------------------------------------------------------------------- running the trials
class _Runner:
    """Opens the stores (holding their locks) and, on first need, the executor."""

    PARTS = ("convergence", "focal", "pose")

    def __init__(self, out: Path, manifest_: dict, spec, chunk_size, show_progress: bool):


        self.spec, self.chunk_size, self.show_progress = spec, chunk_size, show_progress
        self.stack = contextlib.ExitStack()
        self.executor = None
        self.stats = {}
        self.stores = {}
        upgrade_stored_columns(out / "trials" / "convergence")  # stored under the names before issue 25
        for part in self.PARTS:
            cols = KINDS[part].columns(SCENARIO_KEYS[part])
            self.stores[part] = ResultStore(out / "trials" / part, manifest_, cols)
        try:
            for st in self.stores.values():
                self.stack.enter_context(st)
        except BaseException:
            self.stack.close()
            raise

    def folder(self, part: str) -> Path:
        return self.stores[part].dir

    def run(self, part: str, trials: list, description: str) -> list[dict]:
        """Run the part's trials not yet stored; all its rows, by trial id."""


        store = self.stores[part]
        if any(t.trial_id not in store.done_ids for t in trials):
            if self.show_progress:  # the part's plan (trials, estimate) before it runs

                plan = part_plan(part, trials, self.spec, done_ids=store.done_ids)
                print(f"{description}: {plan.describe()}", file=sys.stderr, flush=True)
            if self.executor is None:
                self.executor = self.stack.enter_context(open_executor(self.spec))
            self.stats[part] = run_study(
                KINDS[part], trials, store, self.executor, chunk_size=self.chunk_size or DEFAULT_CHUNK_SIZE,
                n_workers=max(1, self.spec.n_workers), progress=self.show_progress, description=description,
                spec=self.spec)
        wanted = {t.trial_id for t in trials}
        return [r for r in store.read_rows() if r["trial_id"] in wanted]

    def close(self) -> None:
        self.stack.close()


def _convergence_part(s: _Setup, runner: _Runner, det, camera, timings: dict):
    """Run the calibrations; (rows, summary, full-calibration cameras by N)."""


    t0 = time.perf_counter()
    vl = check_views_list(det, camera, s.config["views_list"])
    inputs = runner.folder("convergence") / "board_detections.npz"
    cases = convergence_subsets(len(det), vl, s.config["subsets"], s.seeds["convergence"])
    trials = [Trial(i, convergence_scenario(n, k, idx, inputs), trial_seed(s.seeds["convergence"], i))
              for i, (n, k, idx) in enumerate(cases)]
    rows = [{"n_views": r["n_views"], "subset": r["subset"],
             **{k: np.nan if r[k] is None else r[k] for k in ERROR_COLUMNS}, "views": r["views"]}
            for r in runner.run("convergence", trials, "calibrations")]
    w, h = det.image_size
    cams = {r["n_views"]: Camera(name=f"full-{r['n_views']}", width=int(w), height=int(h), fx=r["fx_px"], fy=r["fy_px"],
                                 cx=r["cx_px"], cy=r["cy_px"], dist=np.array([r[k] for k in DISTORTION_KEYS]))
            for r in rows if r["subset"] == 0}
    timings["calibration_s"] = timings.get("calibration_s", 0.0) + time.perf_counter() - t0
    return rows, convergence_summary(rows), cams


def _focal_part(s: _Setup, runner: _Runner, frames: FocalFrames):
    """Run the focal-method cases; (rows, focal-only estimate)."""


    check_focal_frames(frames)
    inputs = runner.folder("focal") / "focal_frames.npz"
    cases = focal_cases(frames, None, s.config["noise_levels_px"], DEFAULT_FOCAL_TRIALS)
    seed = s.seeds["focal_study"]
    trials = [Trial(i, focal_scenario(c, inputs, s.nominal, s.pattern_ref, s.camera_true.fx), seed)
              for i, c in enumerate(cases)]
    rows = []
    for r in runner.run("focal", trials, "focal-method cases"):
        if r["n_estimates"] is None:
            continue
        row = {k: r[k] for k in FOCAL_COLUMNS}
        row["chi2_per_dof"] = float("nan") if row["chi2_per_dof"] is None else row["chi2_per_dof"]
        rows.append(row)
    return rows, focal_only_estimate(frames, s.nominal, s.pattern)


def believed_cameras(s: _Setup, f_est, full_cams: dict, image_camera: Camera) -> dict:
    """Case name -> camera of the two calibrations: focal-only (the paper's) and full (per N)."""
    nominal = s.nominal
    focal_only = nominal.replace(name="focal-only", fx=float(f_est.f_px), fy=float(f_est.f_px * f_est.aspect))
    believed = {"focal-only calibration (paper)": focal_only}
    for n, cam in full_cams.items():
        believed[f"full calibration ({n} views)"] = cam
    ct = s.camera_true
    if image_camera is not ct and (image_camera.width, image_camera.height) != (ct.width, ct.height):
        # the ISP downscaled: the calibrations describe the delivered images; the pose study
        # runs at the sensor's resolution
        for k in list(believed):
            if k.startswith("full"):
                believed[k] = believed[k].scaled(ct.width, ct.height)
    return believed


def _pose_part(s: _Setup, runner: _Runner, believed: dict):
    """Run the pose-error cells: every case without noise, then the floor cases with noise."""


    c, ct = s.config, s.camera_true
    full_max = f"full calibration ({c['views_list'][-1]} views)"
    floor = {"exact": ct, "focal-only calibration (paper)": believed["focal-only calibration (paper)"],
             full_max: believed[full_max]}
    groups = [("calibration bias (no noise)", 0.0, {**error_cases(ct), **believed})]
    groups += [(f"with centroid noise {sig:g} px", float(sig), floor) for sig in c["floor_noise_px"]]
    s_pose, s_noise = pose_seeds(s.seeds["pose"])
    trials = []
    for group, noise, cases in groups:
        for case, cam in cases.items():
            for i, r in enumerate(c["pose_ranges_m"]):
                sc = pose_scenario(case, group, r, i, noise, c["poses_per_range"], s_pose, s.pattern_ref, ct, cam)
                trials.append(Trial(len(trials), sc, s_noise))
    rows = [{"case": r["case"], "group": r["group"], "range_m": r["range_m"], "noise_px": r["noise_px"],
             **{k: r[k] for k in SUMMARY_COLUMNS if r[k] is not None}}
            for r in runner.run("pose", trials, "pose-error cells")]
    return rows, floor


def _stored_timings(out: Path, rebuild_timings: dict) -> dict:
    """The timings of the run that computed the stored trials, when this one computed none (a
    report rebuilt from its stores): the previous ``summary.json``'s ``timings_s`` with this
    rebuild's total as ``rebuild_s``. Without a previous summary, this run's own timings."""

    try:
        previous = json.loads((out / "summary.json").read_text()).get("timings_s") or {}
    except (OSError, ValueError, AttributeError):
        previous = {}
    if not previous:
        return rebuild_timings
    return {**{k: float(v) for k, v in previous.items() if k != "rebuild_s"},
            "rebuild_s": float(sum(rebuild_timings.values()))}


def _run_parts(s, runner, board_set_dir, focal_cache, say, timings: dict) -> tuple:
    """The three parts of the study in order: convergence, focal-only calibration, pose error.

    Parameters
    ----------
    s : _Setup
        The checked study set-up.
    runner : _Runner
        Runs and stores the trials.
    board_set_dir, focal_cache : str or Path or None
        See :func:`run_calibration_study`.
    say : callable
        Called with lines of progress text.
    timings : dict
        Wall times (s) of the parts; filled in place (``focal_s``, ``pose_s``, and the board
        and convergence times).

    Returns
    -------
    tuple
        ``(set_info, conv_rows, conv, frames, focal_rows, f_est, believed, pose_rows, floor)``.
    """
    det, img_camera, set_info = board_detections(s, runner.folder("convergence") / "board_detections.npz",
                                                 board_set_dir, say, timings)
    conv_rows, conv, full_cams = _convergence_part(s, runner, det, img_camera, timings)
    t0 = time.perf_counter()
    frames = focal_frames(s, runner.folder("focal") / "focal_frames.npz", focal_cache, say)
    focal_rows, f_est = _focal_part(s, runner, frames)
    timings["focal_s"] = time.perf_counter() - t0
    say(f"focal-only calibration: f = {f_est.f_px:.2f} px (true fx {s.camera_true.fx:.2f} px)")
    t0 = time.perf_counter()
    believed = believed_cameras(s, f_est, full_cams, img_camera)
    pose_rows, floor = _pose_part(s, runner, believed)
    timings["pose_s"] = time.perf_counter() - t0
    return set_info, conv_rows, conv, frames, focal_rows, f_est, believed, pose_rows, floor


# --------------------------------------------------------------------------- the study
def plan_calibration_study(camera, out_dir, *, spec=None, board_set_dir=None, focal_cache=None, **study):
    """The study's plan (:func:`svgs_sim.studies.calibration.plan.study_plan`): the checks of
    :func:`run_calibration_study` (:class:`InputError`), then the counts and the estimate;
    nothing is made or written. What a rerun would reuse (the detections and focal frames in
    ``out_dir``, the board set in ``board_set_dir``, the frames in ``focal_cache``) costs nothing.

    Parameters
    ----------
    camera, out_dir, board_set_dir, focal_cache
        As :func:`run_calibration_study`.
    spec : svgs_sim.studies.execution.ExecutorSpec, optional
        Where the trials would run (default: in this process).
    **study
        The study's parameters as :func:`run_calibration_study` takes them (``views_list``,
        ``seed``, ``board``, ``subsets``, ``spp``, ``geometric``, ...).

    Returns
    -------
    svgs_sim.studies.calibration.plan.CalibrationStudyPlan
    """


    s = _setup(camera, **study)
    trials = Path(out_dir) / "trials"
    kept = {"detections": (trials / "convergence" / "board_detections.npz").is_file(),
            "views": (not s.config["geometric"] and board_set_dir is not None
                      and (Path(board_set_dir) / "truth.json").is_file()),
            "focal_frames": (trials / "focal" / "focal_frames.npz").is_file()
            or (not s.config["geometric"] and focal_cache is not None and Path(focal_cache).is_file())}
    ct = s.camera_true
    return study_plan(s.config, ct.width, ct.height, len(error_cases(ct)), spec or executor_spec(processes=0),
                      convergence_seed=s.seeds["convergence"], kept=kept)


def run_calibration_study(camera, out_dir, *, views_list=DEFAULT_VIEWS_LIST, seed: int = 0, board: Board | None = None,
                          subsets: int = DEFAULT_SUBSETS, spp: int = 16, geometric: bool = False,
                          true_pp_offset_px=DEFAULT_TRUE_PP_OFFSET_PX, true_dist=DEFAULT_TRUE_DIST,
                          focal_ranges_m=DEFAULT_FOCAL_RANGES_M, focal_exposures: int = DEFAULT_FOCAL_EXPOSURES,
                          noise_levels_px=DEFAULT_NOISE_LEVELS_PX, pose_ranges_m=DEFAULT_POSE_RANGES_M,
                          poses_per_range: int = DEFAULT_POSES_PER_RANGE, floor_noise_px=DEFAULT_FLOOR_NOISE_PX,
                          pattern="svgs-3u", board_set_dir=None, focal_cache=None, spec=None, chunk_size=None,
                          show_progress: bool = False, progress=None) -> StudyResult:
    """Run the three parts (see :mod:`svgs_sim.studies.calibration`) with their trials stored in ``out_dir``.

    Parameters
    ----------
    camera : str, path or Camera
        The nominal camera profile.
    out_dir : str or Path
        The study folder (``trials/`` inside it; a rerun resumes).
    views_list : sequence of int
        Numbers of views for the convergence part; the set has ``max(views_list)`` views.
    seed : int
    board : Board, optional
        Default :data:`~svgs_sim.studies.calibration.common.DEFAULT_BOARD`.
    subsets : int
    spp : int
        Board render samples per pixel.
    geometric : bool
        No Mitsuba: geometric board images and projected centroids.
    true_pp_offset_px, true_dist
        The real camera's difference from the profile (:func:`true_camera`).
    focal_ranges_m : sequence of float
    focal_exposures : int
    noise_levels_px : sequence of float
    pose_ranges_m : sequence of float
    poses_per_range : int
    floor_noise_px : sequence of float
        Centroid noise of the noise-floor runs.
    pattern : str or Pattern
    board_set_dir : str or Path, optional
        Keep the rendered board set there; a set already there (same camera, board, at
        least ``max(views_list)`` views) is reused instead of rendered.
    focal_cache : str or Path, optional
        ``.npz`` file keeping the focal frames' centroids; reused when it exists.
    spec : svgs_sim.studies.execution.ExecutorSpec, optional
        Where the trials run (default: in this process).
    chunk_size : int, optional
        Trials per task.
    show_progress : bool
        Progress bars on stderr.
    progress : callable, optional
        Called with lines of text.

    Returns
    -------
    StudyResult
    """


    say = progress or (lambda m: None)
    s = _setup(camera, views_list=views_list, seed=seed, board=board, subsets=subsets, spp=spp, geometric=geometric,
               true_pp_offset_px=true_pp_offset_px, true_dist=true_dist, focal_ranges_m=focal_ranges_m,
               focal_exposures=focal_exposures, noise_levels_px=noise_levels_px, pose_ranges_m=pose_ranges_m,
               poses_per_range=poses_per_range, floor_noise_px=floor_noise_px, pattern=pattern)
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {str(out)!r} exists and is not a folder")
    spec = spec or executor_spec(processes=0)
    check_executor(spec)  # Dask importable, scheduler reachable: before any work
    made = not (out / "trials").exists()
    runner = _Runner(out, manifest(s), spec, chunk_size, show_progress)
    timings = {}
    try:
        set_info, conv_rows, conv, frames, focal_rows, f_est, believed, pose_rows, floor = _run_parts(
            s, runner, board_set_dir, focal_cache, say, timings)
    except (InputError, SimulationFailure):
        runner.close()
        if made:
            # refused (e.g. the board found in fewer views than asked, no focal frame identified),
            # or the simulated physics left nothing to measure (a black board render): nothing is
            # left. Its stores could serve only a rerun with these inputs, which is refused again;
            # a corrected rerun would be refused for other parameters, and a kept detections cache
            # would be reused by it. An interrupt (not a refusal) keeps the trials.
            shutil.rmtree(out / "trials", ignore_errors=True)
        raise
    finally:
        runner.close()
    t4 = table4_comparison([r for r in pose_rows if r["case"] in floor and not (r["case"] == "exact" and r["noise_px"] == 0)],
                           phone=paper_phone(s.nominal.key))

    cams = {k: cam_json(c) for k, c in {**believed, "true": s.camera_true, "nominal": s.nominal}.items()}
    if not runner.stats:
        timings = _stored_timings(out, timings)
    return StudyResult(s.config, s.nominal, s.camera_true, set_info, conv_rows, conv, frames, centroid_noise(frames),
                       focal_rows, f_est, pose_rows, t4, cams, timings, runner.stats)
