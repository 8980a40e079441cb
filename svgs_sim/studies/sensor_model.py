"""The statistical sensor's table, built from rendered frames, and its validation against rendered
frames that were not used to build it (``svgs sensor-model build`` and ``svgs sensor-model validate``).

Build (:func:`build_sensor_model`)
    At each node (a range of :attr:`SensorModelConfig.ranges_m` and an off-axis angle of
    :attr:`SensorModelConfig.off_axis_deg`) one :class:`svgs_sim.sim.approach.ApproachSensor` (the
    docking loop's sensor: full resolution, the phone's auto-exposure carried from frame to frame at
    ``frame_rate_hz``, the app's threshold, the per-frame bound) takes ``frames_per_node`` static frames,
    each at a seeded azimuth of the off-axis offset and a seeded attitude drawn uniformly within
    ``+-attitude_deg`` per angle. Each node's frames are one task of the project's executors and are
    kept in ``nodes/`` as they finish: a killed build continues where it stopped when rerun with the
    same arguments (other arguments are refused). The table (:class:`svgs_sim.sim.statistical_sensor.SensorTable`)
    is written as ``sensor_model.json``, the frames as ``frames.csv``, the figure as ``sensor_model.png``.

Validate (:func:`validate_sensor_model`)
    ``frames`` poses drawn uniformly inside the table's envelope (log-uniform in range) from a seed
    other than the build's, rendered the same way in tasks of :data:`VALIDATION_CHUNK` frames, and
    compared with the statistical sensor at the same poses: per component a two-sample
    Kolmogorov-Smirnov test of the rendered errors against the model's draws (all ranges, and each
    third of the log-range), the rendered errors' scatter in units of the model's (``(e - bias) / std``,
    1 if the model is right, with a 90 % chi-square interval), and the dropout count by reason against
    the model's 90 % interval (the model's outcomes drawn for the same poses 4000 times).
    Writes ``validation.json``, ``validation.csv`` (the rendered frames) and ``validation.png``.
"""

from __future__ import annotations

import csv
import json
import os
import sys
from concurrent.futures import as_completed
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from svgs_sim.base.errors import InputError
from svgs_sim.base.profiles import load_camera
from svgs_sim.sim.approach import ApproachSensor
from svgs_sim.sim.statistical_sensor import (
    GROSS_ERROR, GROSS_ERROR_SIGMA, MIN_SOLVED_FOR_STATISTICS, WRONG_LOCK, OutsideEnvelope, SensorTable, pose_coordinates,
)
from svgs_sim.svgs.frames import STATE_KEYS, pose_from_scenario

from .execution import open_executor
from .progress import progress_bar
from .seeding import check_seed

#: The build's parameters file in its folder.
MANIFEST_NAME = "sensor_model_manifest.json"
#: Frames per validation task.
VALIDATION_CHUNK = 8
#: Draws of the model's outcomes for the dropout intervals.
OUTCOME_DRAWS = 4000
#: Draws from the model per validation frame for the two-sample tests.
MODEL_DRAWS_PER_FRAME = 20
#: Columns of ``frames.csv`` and ``validation.csv``.
FRAME_COLUMNS = (("node", "frame", "range_m", "off_axis_deg", "azimuth_deg") + tuple(f"true_{k}" for k in STATE_KEYS)
                 + ("ok", "reason", "wrong_lock") + tuple(f"err_{k}" for k in STATE_KEYS)
                 + tuple(f"crlb_{k}" for k in STATE_KEYS) + ("n_blobs", "exposure_s", "frame_s"))


@dataclass(frozen=True)
class SensorModelConfig:
    """What a sensor model's build computes (its manifest).

    Attributes
    ----------
    camera, pattern : str
    ranges_m : tuple of float
        The nodes' ranges (depth along the boresight), increasing, m.
    off_axis_deg : tuple of float
        The nodes' off-axis angles, increasing from 0, deg.
    frames_per_node : int
    attitude_deg : float
        Each frame's roll, pitch and yaw are drawn uniformly within +-this, deg.
    frame_rate_hz : float
        The phone's frame rate (its auto-exposure's steps between frames; the longest exposure).
    seed : int
    """

    camera: str
    pattern: str = "svgs-3u"
    ranges_m: tuple = (0.8, 1.0, 1.3, 1.7, 2.2, 3.0, 4.0, 5.5, 7.5, 10.0, 13.0, 17.0, 22.0, 28.0, 34.0)
    off_axis_deg: tuple = (0.0, 5.0, 10.0)
    frames_per_node: int = 30
    attitude_deg: float = 8.0
    frame_rate_hz: float = 2.0
    seed: int = 0

    def __post_init__(self):
        r = np.asarray(self.ranges_m, float)
        a = np.asarray(self.off_axis_deg, float)
        if r.size < 1 or not np.all(np.isfinite(r)) or np.any(r <= 0) or np.any(np.diff(r) <= 0):
            raise InputError(f"--ranges: expected increasing positive ranges, m, got {list(self.ranges_m)}")
        if a.size < 1 or not np.all(np.isfinite(a)) or a[0] != 0 or np.any(np.diff(a) <= 0) or a[-1] >= 30:
            raise InputError(f"--off-axis-deg: expected increasing angles from 0 and below 30 deg, got "
                             f"{list(self.off_axis_deg)}")
        if not 2 <= int(self.frames_per_node) <= 10000:
            raise InputError(f"--frames-per-node: expected 2-10000, got {self.frames_per_node!r}")
        if not (np.isfinite(self.attitude_deg) and 0 <= self.attitude_deg <= 45):
            raise InputError(f"--attitude-deg: expected 0-45 deg, got {self.attitude_deg!r}")
        if not (np.isfinite(self.frame_rate_hz) and 0 < self.frame_rate_hz <= 60):
            raise InputError(f"--fps: expected a frame rate above 0 and at most 60 frames/s, got {self.frame_rate_hz!r}")
        check_seed(self.seed)
        object.__setattr__(self, "ranges_m", tuple(float(x) for x in r))
        object.__setattr__(self, "off_axis_deg", tuple(float(x) for x in a))

    def nodes(self) -> list[tuple[int, int]]:
        return [(i, j) for i in range(len(self.ranges_m)) for j in range(len(self.off_axis_deg))]

    def n_frames(self) -> int:
        return len(self.nodes()) * self.frames_per_node


def pose_at(range_m: float, off_axis_deg: float, azimuth_deg: float, attitude_deg) -> tuple[np.ndarray, np.ndarray]:
    """``(R_cam_target, t_cam_target_m)`` of a frame: the target at ``range_m`` along the boresight,
    offset by ``off_axis_deg`` towards ``azimuth_deg``, turned by ``attitude_deg`` (roll, pitch, yaw)."""
    lateral = range_m * np.tan(np.radians(off_axis_deg))
    return pose_from_scenario(range_m, lateral * np.cos(np.radians(azimuth_deg)),
                              lateral * np.sin(np.radians(azimuth_deg)), *attitude_deg)


def measure_poses(task: dict) -> list[dict]:
    """One task: an :class:`~svgs_sim.sim.approach.ApproachSensor` takes a frame at each of the task's
    poses (``task["poses"]``: ``(range_m, off_axis_deg, azimuth_deg, roll, pitch, yaw)``), one after
    another at the frame rate. Returns the frames' rows (:data:`FRAME_COLUMNS`)."""
    sensor = ApproachSensor(task["camera"], task["pattern"], seed=task["seed"], motion=False,
                            frame_rate_hz=task["frame_rate_hz"])
    rows = []
    try:
        for k, (rng_m, off, az, *att) in enumerate(task["poses"]):
            R, t = pose_at(rng_m, off, az, att)
            m = sensor.measure(k / task["frame_rate_hz"], R, t, image_velocity_px_s=np.zeros((sensor.pattern.n, 2)))
            row = {"node": task["node"], "frame": k, "range_m": float(t[2]),
                   "off_axis_deg": pose_coordinates(R, t)[1], "azimuth_deg": az}
            row.update({f"true_{key}": m.truth[key] for key in STATE_KEYS})
            row.update({"ok": int(m.ok), "reason": m.reason or "", "wrong_lock": int(m.wrong_lock)})
            for prefix, d in (("err", m.error), ("crlb", m.crlb_std)):
                row.update({f"{prefix}_{key}": (None if d is None else d.get(key)) for key in STATE_KEYS})
            row.update({"n_blobs": m.n_blobs, "exposure_s": m.exposure_s,
                        "frame_s": float(sum(v or 0.0 for v in m.timings_s.values()))})
            rows.append(row)
    finally:
        sensor.close()
    return rows


def node_task(cfg: SensorModelConfig, i: int, j: int) -> dict:
    """Node ``(i, j)``'s task: its poses drawn from ``(seed, i, j)``, its sensor's seed from the same."""
    rng = np.random.default_rng(np.random.SeedSequence([cfg.seed, i, j, 44]))
    poses = []
    for _ in range(cfg.frames_per_node):
        az = float(rng.uniform(0.0, 360.0))
        rng.uniform(0.0, 0.0, 3)  # three draws the committed tables' stream holds here (kept: the same poses)
        att = rng.uniform(-cfg.attitude_deg, cfg.attitude_deg, 3)
        poses.append((cfg.ranges_m[i], cfg.off_axis_deg[j], az, *att.tolist()))
    seed = int(np.random.SeedSequence([cfg.seed, i, j, 45]).generate_state(1)[0])
    return {"camera": cfg.camera, "pattern": cfg.pattern, "seed": seed, "frame_rate_hz": cfg.frame_rate_hz,
            "node": f"{i:02d}-{j:02d}", "poses": poses}


# ---------------------------------------------------------------------- files
def _write_atomic(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".part")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)


def write_frames_csv(path, rows: list[dict]) -> None:
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=list(FRAME_COLUMNS))
        w.writeheader()
        w.writerows(rows)


def check_build_folder(cfg: SensorModelConfig, out_dir) -> dict:
    """The build's manifest; refuses a folder holding another build's (other parameters) or files a
    build would overwrite without a manifest - before any work."""
    out = Path(out_dir)
    manifest = {"kind": "sensor-model build", **asdict(cfg)}
    manifest["ranges_m"], manifest["off_axis_deg"] = list(cfg.ranges_m), list(cfg.off_axis_deg)
    mpath = out / MANIFEST_NAME
    if mpath.exists():
        try:
            stored = json.loads(mpath.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise InputError(f"--out: {str(mpath)!r} cannot be read ({exc}); choose another --out") from None
        if stored != manifest and not _extends(stored, manifest):
            diff = sorted(k for k in set(stored) | set(manifest) if stored.get(k) != manifest.get(k))
            raise InputError(f"--out: {str(out)!r} holds a sensor-model build with other parameters ({', '.join(diff)}); "
                             "rerun with its arguments to continue it (or with ranges or off-axis angles appended to "
                             "its own, to extend it), or choose another --out")
    elif out.is_dir():
        theirs = sorted(p.name for p in out.iterdir() if p.name in ("sensor_model.json", "frames.csv", "nodes"))
        if theirs:
            raise InputError(f"--out: {str(out)!r} holds {', '.join(theirs)} but no {MANIFEST_NAME}: files no build "
                             "made, which a build would overwrite; choose another --out")
    return manifest


def _extends(stored: dict, manifest: dict) -> bool:
    """``manifest`` appends ranges (its off-axis angles the same) or off-axis angles (its ranges the
    same) to the stored build's grid, all else equal: every stored node keeps its index, so its frames
    (drawn from the node's indices) are those a build of the whole grid makes."""
    rest = ("ranges_m", "off_axis_deg")
    if {k: v for k, v in stored.items() if k not in rest} != {k: v for k, v in manifest.items() if k not in rest}:
        return False
    (r0, a0), (r1, a1) = (stored.get(k, []) for k in rest), (manifest[k] for k in rest)
    return (a0 == a1 and r1[:len(r0)] == r0) or (r0 == r1 and a1[:len(a0)] == a0)


def _run_tasks(tasks: list[dict], spec, done, description: str, progress: bool, n_frames: int) -> None:
    """Run ``tasks`` (:func:`measure_poses`) on the executor of ``spec``; ``done(task, rows)`` as each finishes."""
    if not tasks:
        return
    with open_executor(spec) as ex, progress_bar(n_frames, description, progress, unit="frame") as bar:
        futs = {ex.submit(measure_poses, t): t for t in tasks}
        for f in as_completed(futs):
            rows = f.result()
            done(futs[f], rows)
            bar.update(len(rows))


def build_sensor_model(cfg: SensorModelConfig, out_dir, spec, *, progress: bool = True, command: str = "") -> dict:
    """Render the nodes' frames the folder does not hold yet, then write the table, ``frames.csv`` and
    the figure. Returns the summary (what ``--json`` prints)."""
    load_camera(cfg.camera)  # a bad camera name fails here, before any work
    out = Path(out_dir)
    manifest = check_build_folder(cfg, out)
    nodes_dir = out / "nodes"
    nodes_dir.mkdir(parents=True, exist_ok=True)
    _write_atomic(out / MANIFEST_NAME, json.dumps(manifest, indent=1) + "\n")
    tasks = [node_task(cfg, i, j) for i, j in cfg.nodes()]
    todo = [t for t in tasks if not (nodes_dir / f"node-{t['node']}.json").exists()]
    if len(todo) < len(tasks):
        print(f"sensor-model build: {len(tasks) - len(todo)} of {len(tasks)} nodes already in {nodes_dir}, "
              f"{len(todo)} to render", file=sys.stderr)

    def done(task, rows):
        _write_atomic(nodes_dir / f"node-{task['node']}.json", json.dumps(rows) + "\n")

    _run_tasks(todo, spec, done, f"sensor model {cfg.camera}", progress, len(todo) * cfg.frames_per_node)
    rows = [r for t in tasks for r in json.loads((nodes_dir / f"node-{t['node']}.json").read_text(encoding="utf-8"))]
    table = table_from_rows(cfg, rows, {"config": manifest, "command": command})
    table.save(out / "sensor_model.json")
    write_frames_csv(out / "frames.csv", rows)
    plot_sensor_model(table, out / "sensor_model.png")
    return {"ok": True, "camera": cfg.camera, "nodes": len(tasks), "frames": len(rows),
            "solved": int(table.n_solved.sum()), "gross_errors": int(table.n_gross.sum()),
            "wrong_locks": int(table.n_wrong_lock.sum()),
            "dropouts": {k: int(v.sum()) for k, v in table.dropouts.items()},
            "envelope": {"range_m": [cfg.ranges_m[0], cfg.ranges_m[-1]], "off_axis_deg_max": cfg.off_axis_deg[-1],
                         "attitude_deg_max": cfg.attitude_deg},
            "outputs": {k: str(out / v) for k, v in (("table", "sensor_model.json"), ("frames", "frames.csv"),
                                                     ("figure", "sensor_model.png"))}}


def _errors(rows: list[dict], prefix: str = "err") -> np.ndarray:
    return np.array([[float(r[f"{prefix}_{k}"]) for k in STATE_KEYS] for r in rows], float).reshape(-1, 6)


def gross_mask(errors: np.ndarray) -> np.ndarray:
    """Which of a node's solved frames (``errors`` (n, 6)) are gross errors: a component farther than
    :data:`~svgs_sim.sim.statistical_sensor.GROSS_ERROR_SIGMA` robust standard deviations (1.4826 x the
    median absolute deviation) from the median. Shape (n,), bool."""
    med = np.median(errors, 0)
    mad = 1.4826 * np.median(np.abs(errors - med), 0)
    return np.any(np.abs(errors - med) > GROSS_ERROR_SIGMA * np.where(mad > 0, mad, np.inf), axis=1)


def table_from_rows(cfg: SensorModelConfig, rows: list[dict], provenance: dict) -> SensorTable:
    """The table of the build's frames: per node the counts by outcome (solutions split into the core
    and gross errors, :func:`gross_mask`), and the core's mean, covariance (``ddof=1``) and median bound
    (NaN with fewer than :data:`~svgs_sim.sim.statistical_sensor.MIN_SOLVED_FOR_STATISTICS` solved frames,
    whose solutions all count as the core)."""
    shape = (len(cfg.ranges_m), len(cfg.off_axis_deg))
    n, n_sol, n_gross, n_wl = (np.zeros(shape, int) for _ in range(4))
    bias, crlb = np.full(shape + (6,), np.nan), np.full(shape + (6,), np.nan)
    cov = np.full(shape + (6, 6), np.nan)
    reasons = sorted({r["reason"] for r in rows if not int(r["ok"])})
    drops = {k: np.zeros(shape, int) for k in reasons}
    wl = [[[] for _ in range(shape[1])] for _ in range(shape[0])]
    gross = [[[] for _ in range(shape[1])] for _ in range(shape[0])]
    for i, j in cfg.nodes():
        mine = [r for r in rows if r["node"] == f"{i:02d}-{j:02d}"]
        n[i, j] = len(mine)
        solved = [r for r in mine if int(r["ok"]) and not int(r["wrong_lock"])]
        locks = [r for r in mine if int(r["ok"]) and int(r["wrong_lock"])]
        n_wl[i, j] = len(locks)
        wl[i][j] = list(_errors(locks))
        for k in reasons:
            drops[k][i, j] = sum(1 for r in mine if not int(r["ok"]) and r["reason"] == k)
        e, c = _errors(solved), _errors(solved, "crlb")
        if len(solved) >= MIN_SOLVED_FOR_STATISTICS:
            out = gross_mask(e)
            gross[i][j] = list(e[out])
            e, c = e[~out], c[~out]
            bias[i, j], cov[i, j] = e.mean(0), np.cov(e, rowvar=False, ddof=1)
            crlb[i, j] = np.nanmedian(c, axis=0)
        n_sol[i, j], n_gross[i, j] = len(e), len(gross[i][j])
    return SensorTable(camera=cfg.camera, pattern=cfg.pattern, ranges_m=np.asarray(cfg.ranges_m),
                       off_axis_deg=np.asarray(cfg.off_axis_deg), attitude_max_deg=float(cfg.attitude_deg),
                       frame_rate_hz=float(cfg.frame_rate_hz), n=n, n_solved=n_sol, n_gross=n_gross, n_wrong_lock=n_wl,
                       dropouts=drops, bias=bias, covariance=cov, crlb_std=crlb, wrong_lock_errors=wl,
                       gross_errors=gross, provenance=provenance)


def plot_sensor_model(table: SensorTable, path) -> None:
    """The table at a glance: each component's 1-sigma scatter (and the median bound, dashed) and the
    fraction of frames solved, against range, one line per off-axis angle."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(14, 6.5), constrained_layout=True)
    FigureCanvasAgg(fig)
    axes = fig.subplots(2, 4).ravel()
    for j, off in enumerate(table.off_axis_deg):
        c = f"C{j}"
        for k, key in enumerate(STATE_KEYS):
            ax = axes[k if k < 3 else k + 1]
            std = np.sqrt(table.covariance[:, j, k, k])
            ax.loglog(table.ranges_m, std, "o-", color=c, label=f"scatter, {off:g} deg off axis")
            ax.loglog(table.ranges_m, np.abs(table.bias[:, j, k]), "x:", color=c, alpha=0.6, label="|bias|")
            ax.loglog(table.ranges_m, table.crlb_std[:, j, k], "--", color=c, alpha=0.6, label="median CRLB")
            ax.set_title(key)
            ax.set_xlabel("range, m")
        axes[3].plot(table.ranges_m, table.n_solved[:, j] / table.n[:, j], "o-", color=c, label=f"{off:g} deg")
    axes[0].legend(fontsize=7)
    axes[7].axis("off")
    axes[3].set_xscale("log")
    axes[3].set_ylim(-0.05, 1.05)
    axes[3].set_title("fraction solved")
    axes[3].set_xlabel("range, m")
    axes[3].legend(fontsize=7)
    fig.suptitle(f"Sensor model: {table.camera}, {int(table.n[0, 0])} frames a node, attitude within "
                 f"+-{table.attitude_max_deg:g} deg, {table.frame_rate_hz:g} frames/s")
    fig.savefig(path, dpi=90)


# ---------------------------------------------------------------------- validation
def validation_poses(table: SensorTable, n: int, seed: int) -> list[tuple]:
    """``n`` poses inside the table's envelope: range log-uniform, off-axis angle uniform, azimuth and
    each angle uniform (``(range_m, off_axis_deg, azimuth_deg, roll, pitch, yaw)``)."""
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 46]))
    lo, hi = np.log(table.ranges_m[0]), np.log(table.ranges_m[-1])
    a = table.attitude_max_deg
    return [(float(np.exp(rng.uniform(lo, hi))), float(rng.uniform(0.0, table.off_axis_deg[-1])),
             float(rng.uniform(0.0, 360.0)), *rng.uniform(-a, a, 3).tolist()) for _ in range(int(n))]


def render_validation_frames(table: SensorTable, n: int, seed: int, spec, store_dir, *,
                             progress: bool = True) -> list[dict]:
    """The held-out rendered frames: :func:`validation_poses` in tasks of :data:`VALIDATION_CHUNK`
    (poses sorted by range, so a task's auto-exposure moves little from frame to frame), each task's
    frames kept in ``store_dir`` as it finishes (a rerun renders only what is missing)."""
    poses = sorted(validation_poses(table, n, seed))
    tasks = []
    for c in range(0, len(poses), VALIDATION_CHUNK):
        sd = int(np.random.SeedSequence([int(seed), c, 47]).generate_state(1)[0])
        tasks.append({"camera": table.camera, "pattern": table.pattern, "seed": sd,
                      "frame_rate_hz": table.frame_rate_hz, "node": f"v{c // VALIDATION_CHUNK:03d}",
                      "poses": poses[c:c + VALIDATION_CHUNK]})
    store = Path(store_dir)
    store.mkdir(parents=True, exist_ok=True)
    todo = [t for t in tasks if not (store / f"{t['node']}.json").exists()]
    _run_tasks(todo, spec, lambda t, rows: _write_atomic(store / f"{t['node']}.json", json.dumps(rows) + "\n"),
               f"validation {table.camera}", progress, sum(len(t["poses"]) for t in todo))
    return [r for t in tasks for r in json.loads((store / f"{t['node']}.json").read_text(encoding="utf-8"))]


def _model_at(table: SensorTable, rows: list[dict]) -> tuple[np.ndarray, np.ndarray]:
    """The model's core at each frame's pose: bias (n, 6) and standard deviation (n, 6); NaN where no
    node of the table has statistics."""
    bias, std = [], []
    for r in rows:
        try:
            b, c, _ = table.error_statistics(float(r["range_m"]), float(r["off_axis_deg"]))
        except OutsideEnvelope:  # no node of the table has enough solved frames: nothing to compare with
            b, c = np.full(6, np.nan), np.full((6, 6), np.nan)
        bias.append(b)
        std.append(np.sqrt(np.diag(c)))
    return np.array(bias).reshape(-1, 6), np.array(std).reshape(-1, 6)


def _model_draws(table: SensorTable, rows: list[dict], seed: int) -> np.ndarray:
    """:data:`MODEL_DRAWS_PER_FRAME` solved errors of the statistical sensor at each solved frame's pose,
    shape (n * draws, 6)."""
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 48]))
    out = []
    for r in rows:
        b, c, _ = table.error_statistics(float(r["range_m"]), float(r["off_axis_deg"]))
        out.append(rng.multivariate_normal(b, c, size=MODEL_DRAWS_PER_FRAME, method="eigh"))
    return np.concatenate(out) if out else np.zeros((0, 6))


def outcome_of(row: dict, bias: np.ndarray, std: np.ndarray) -> str:
    """A frame's outcome against the model's core at its pose (``bias``, ``std`` (6,)): its dropout
    reason, ``wrong_lock``, ``gross_error`` (a component beyond
    :data:`~svgs_sim.sim.statistical_sensor.GROSS_ERROR_SIGMA` of the core's standard deviations) or
    ``solved``."""
    if not int(row["ok"]):
        return row["reason"]
    if int(row["wrong_lock"]):
        return WRONG_LOCK
    e = np.array([float(row[f"err_{k}"]) for k in STATE_KEYS])
    if np.all(np.isfinite(std)) and np.any(np.abs(e - bias) > GROSS_ERROR_SIGMA * std):
        return GROSS_ERROR
    return "solved"


def _node_counts(table: SensorTable, keys: list) -> np.ndarray:
    """Each node's frames by outcome, shape (R * A, K)."""
    R, A = table.n.shape
    c = np.zeros((R * A, len(keys)))
    for k, key in enumerate(keys):
        arr = {"solved": table.n_solved, GROSS_ERROR: table.n_gross, WRONG_LOCK: table.n_wrong_lock}.get(key)
        arr = table.dropouts.get(key) if arr is None else arr
        if arr is not None:
            c[:, k] = np.asarray(arr).ravel()
    return c


def dropout_check(table: SensorTable, rows: list[dict], outcomes: list[str], seed: int) -> dict:
    """Each outcome's rendered count against the model's 90 % predictive interval: per draw each node's
    outcome probabilities from their posterior given the node's frames (Dirichlet: the node's counts
    plus the table's Jeffreys prior, 1/2 per outcome, shared among the nodes by their frames),
    interpolated to each held-out pose, and each pose's outcome drawn; :data:`OUTCOME_DRAWS` draws (the
    count's 5th and 95th percentiles). The interval so holds the table's own sampling error: an outcome
    the table never saw keeps a probability of 1/2 over the table's frames at each node."""
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 49]))
    keys = sorted(set(_table_outcomes(table)) | set(outcomes))
    R, A = table.n.shape
    W = np.zeros((len(rows), R * A))
    for f, r in enumerate(rows):
        for i, j, w in table.weights(float(r["range_m"]), float(r["off_axis_deg"])):
            W[f, i * A + j] = w
    counts = _node_counts(table, keys)
    alpha = counts + 0.5 * counts.sum(1, keepdims=True) / counts.sum()
    P = np.stack([rng.dirichlet(a, size=OUTCOME_DRAWS) for a in alpha], 1)  # (draws, nodes, K)
    cum = np.cumsum(np.einsum("fn,dnk->dfk", W, P), -1)
    u = rng.random((OUTCOME_DRAWS, len(rows), 1))
    drawn = np.minimum((u > cum).sum(-1), len(keys) - 1)  # (draws, frames): the outcome index
    out = {}
    for j, k in enumerate(keys):
        counts = (drawn == j).sum(1)
        lo, hi = (int(x) for x in np.percentile(counts, [5, 95]))
        obs = sum(1 for o in outcomes if o == k)
        out[k] = {"observed": obs, "model_mean": float(counts.mean()), "model_interval90": [lo, hi],
                  "within": bool(lo <= obs <= hi)}
    return out


def _table_outcomes(table: SensorTable) -> list:
    return ["solved", GROSS_ERROR, WRONG_LOCK, *table.dropouts]


def error_check(table: SensorTable, rows: list[dict], outcomes: list[str], bias: np.ndarray, std: np.ndarray,
                seed: int) -> dict:
    """Per component: the two-sample KS test of the rendered core solutions' errors (``outcomes``
    ``solved``, :func:`outcome_of`) against the model's core draws
    at the same poses (all ranges, and each third of the log-range), and the scatter ratio
    ``std((e - bias) / std_model)`` with its 90 % chi-square interval (1 if the model is right)."""
    from scipy.stats import chi2, ks_2samp

    solved = [k for k, r in enumerate(rows) if outcomes[k] == "solved" and np.isfinite(bias[k, 0])]
    e = _errors([rows[k] for k in solved])
    draws = _model_draws(table, [rows[k] for k in solved], seed)
    owner = np.repeat(np.arange(len(solved)), MODEL_DRAWS_PER_FRAME)
    edges = np.exp(np.linspace(np.log(table.ranges_m[0]), np.log(table.ranges_m[-1]), 4))
    rng_of = np.array([float(rows[k]["range_m"]) for k in solved])
    band = np.clip(np.searchsorted(edges, rng_of) - 1, 0, 2)
    out = {}
    for c, key in enumerate(STATE_KEYS):
        d = {"n_rendered": len(solved)}
        if len(solved) >= 5:
            d["ks_p"] = float(ks_2samp(e[:, c], draws[:, c]).pvalue)
            z = (e[:, c] - bias[solved, c]) / std[solved, c]
            n = z.size
            ratio = float(np.sqrt(np.mean(z**2)))
            d["scatter_ratio"] = ratio
            d["scatter_ratio_interval90"] = [float(ratio * np.sqrt(n / chi2.ppf(0.95, n))),
                                             float(ratio * np.sqrt(n / chi2.ppf(0.05, n)))]
            d["bands"] = []
            for b in range(3):
                sel = band == b
                if sel.sum() >= 5:
                    d["bands"].append({"range_m": [float(edges[b]), float(edges[b + 1])], "n_rendered": int(sel.sum()),
                                       "ks_p": float(ks_2samp(e[sel, c], draws[np.isin(owner, np.flatnonzero(sel)), c]).pvalue)})
        out[key] = d
    return out


def check_validation_folder(table: SensorTable, out_dir, frames: int, seed: int) -> dict:
    """The validation's manifest; refuses bad counts and a folder holding a validation with other
    parameters or of another table - before any work."""
    check_seed(seed)
    if not 10 <= int(frames) <= 100000:
        raise InputError(f"--frames: expected 10-100000 held-out frames, got {frames!r}")
    out = Path(out_dir)
    mpath = out / "validation_manifest.json"
    manifest = {"kind": "sensor-model validate", "table": table.to_json()["provenance"], "camera": table.camera,
                "frames": int(frames), "seed": int(seed)}
    try:
        stored = json.loads(mpath.read_text(encoding="utf-8")) if mpath.exists() else manifest
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"--out: {str(mpath)!r} cannot be read ({exc}); choose another --out") from None
    if stored != manifest:
        raise InputError(f"--out: {str(out)!r} holds a validation with other parameters or of another table; "
                         "rerun with its arguments, or choose another --out")
    return manifest


def validate_sensor_model(table_path, out_dir, *, frames: int = 200, seed: int = 1, spec=None,
                          progress: bool = True, command: str = "") -> dict:
    """Render ``frames`` held-out frames inside the table's envelope and compare them with the
    statistical sensor (:func:`dropout_check`, :func:`error_check`). Writes ``validation.json``,
    ``validation.csv`` and ``validation.png`` in ``out_dir``; returns the validation."""
    table = SensorTable.load(table_path)
    out = Path(out_dir)
    manifest = check_validation_folder(table, out, frames, seed)
    out.mkdir(parents=True, exist_ok=True)
    _write_atomic(out / "validation_manifest.json", json.dumps(manifest, indent=1) + "\n")
    rows = render_validation_frames(table, frames, seed, spec, out / "validation_frames", progress=progress)
    bias, std = _model_at(table, rows)
    kinds = [outcome_of(r, b, sd) for r, b, sd in zip(rows, bias, std)]
    outcomes = dropout_check(table, rows, kinds, seed)
    errors = error_check(table, rows, kinds, bias, std, seed)
    res = {"camera": table.camera, "frames": len(rows), "seed": int(seed), "command": command,
           "envelope": {"range_m": [float(table.ranges_m[0]), float(table.ranges_m[-1])],
                        "off_axis_deg_max": float(table.off_axis_deg[-1]), "attitude_deg_max": table.attitude_max_deg},
           "outcomes": outcomes, "errors": errors,
           "outcomes_within": all(v["within"] for v in outcomes.values()),
           "ks_min_p": min((v["ks_p"] for v in errors.values() if "ks_p" in v), default=None)}
    write_frames_csv(out / "validation.csv", rows)
    (out / "validation.json").write_text(json.dumps(res, indent=1) + "\n", encoding="utf-8")
    plot_validation(table, rows, kinds, bias, std, res, out / "validation.png")
    return res


def plot_validation(table: SensorTable, rows: list[dict], kinds: list[str], bias: np.ndarray, std: np.ndarray,
                    res: dict, path) -> None:
    """The rendered held-out frames against the model: each component's error in units of the
    model's scatter (``(e - bias) / std``) against range, with the model's +-1 and +-2 sigma band, and
    the outcome counts with the model's 90 % intervals."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(14, 6.5), constrained_layout=True)
    FigureCanvasAgg(fig)
    axes = fig.subplots(2, 4).ravel()
    solved = [k for k, r in enumerate(rows) if kinds[k] in ("solved", GROSS_ERROR) and np.isfinite(bias[k, 0])]
    rng_m = np.array([float(rows[k]["range_m"]) for k in solved])
    e = _errors([rows[k] for k in solved])
    for c, key in enumerate(STATE_KEYS):
        ax = axes[c if c < 3 else c + 1]
        z = (e[:, c] - bias[solved, c]) / std[solved, c] if solved else np.zeros(0)
        ax.axhspan(-2, 2, color="0.9")
        ax.axhspan(-1, 1, color="0.8")
        ax.semilogx(rng_m, z, ".", ms=4)
        d = res["errors"][key]
        ax.set_title(f"{key}: KS p {d.get('ks_p', float('nan')):.2g}, scatter x{d.get('scatter_ratio', float('nan')):.2f}",
                     fontsize=9)
        ax.set_xlabel("range, m")
        ax.set_ylim(-1.5 * GROSS_ERROR_SIGMA, 1.5 * GROSS_ERROR_SIGMA)
        ax.axhline(GROSS_ERROR_SIGMA, color="r", lw=0.6)
        ax.axhline(-GROSS_ERROR_SIGMA, color="r", lw=0.6)
    axes[0].set_ylabel("(error - model bias) / model std (red: gross)")
    ax = axes[3]
    names = list(res["outcomes"])
    obs = [res["outcomes"][k]["observed"] for k in names]
    lo = [res["outcomes"][k]["model_interval90"][0] for k in names]
    hi = [res["outcomes"][k]["model_interval90"][1] for k in names]
    x = np.arange(len(names))
    ax.bar(x, obs, color="C0", alpha=0.6, label="rendered")
    ax.errorbar(x, [(a + b) / 2 for a, b in zip(lo, hi)], yerr=[[(b - a) / 2 for a, b in zip(lo, hi)]] * 2, fmt="none",
                ecolor="k", capsize=6, label="model, 90 %")
    ax.set_xticks(x, names, rotation=30, fontsize=8)
    ax.set_title("outcomes of the held-out frames", fontsize=9)
    ax.legend(fontsize=7)
    fig.suptitle(f"Sensor model validation: {table.camera}, {len(rows)} held-out rendered frames inside the envelope")
    fig.savefig(path, dpi=90)
