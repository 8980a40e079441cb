"""A sensor model derived from rendered frames: the bias and covariance of the six state components,
the dropout probability by reason and the wrong-lock probability, as a table over range and
off-axis angle, sampled frame by frame where rendering every frame is too slow (a closed-loop
Monte Carlo of hundreds of runs).

The table (:class:`SensorTable`) is built by ``svgs sensor-model build`` (:mod:`svgs_sim.studies.sensor_model`)
from frames of :class:`svgs_sim.sim.approach.ApproachSensor` rendered at its nodes: each node a range
(the target's depth along the boresight, ``t_cam_target_m[2]``) and an off-axis angle (the target
origin's angle from the boresight), each frame of a node at a seeded azimuth and attitude within the
table's attitude envelope. :class:`StatisticalSensor` has the interface of the rendered sensor
(``measure(t_s, R_cam_target, t_cam_target_m) -> Measurement``) and draws each frame independently:

1. the cell's probabilities, interpolated bilinearly over log-range and off-axis angle between the
   four nodes around the pose: a dropout (by reason), a wrong lock, a solution with a gross error
   (:data:`GROSS_ERROR`), or a solution in the core;
2. a core solution's error ``bias + L z`` (``L L^T`` the interpolated covariance of the core, ``z``
   standard normal), in m and deg; a wrong lock's or a gross error's one of those stored at the
   nearest node that has one;
3. the frame's 1-sigma bound: the node's median per-frame Cramer-Rao bound, interpolated.

What it does not model: the errors' correlation from frame to frame (a static pose's weak-mode bias
is one draw of the cell's scatter per frame, not a bias held over a run), motion blur (the nodes are
static frames; at docking speeds of cm/s the blur is a fraction of a pixel), the sun and the Earth
(the table is the lab's). Outside the table's envelope (range, off-axis angle, attitude) it refuses
with :class:`OutsideEnvelope`: a table says nothing where no frame was rendered.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from svgs_sim.base.errors import InputError
from svgs_sim.base.profiles import Camera, load_camera
from svgs_sim.svgs.frames import STATE_KEYS, check_pose, pose_to_state, state_dict

from .approach.sensor import Measurement

#: ``sensor_model.json``'s ``kind``.
TABLE_KIND = "svgs-sim sensor model"
#: The layout's version.
TABLE_VERSION = 1
#: Fewest solved frames at a node for its bias and covariance; a node with fewer lends none (the
#: nearest node with enough in its off-axis column gives them, :meth:`SensorTable.error_statistics`).
MIN_SOLVED_FOR_STATISTICS = 8
#: The outcome of a wrong-locked frame (it is a solution: ``ok`` is True, ``wrong_lock`` says it).
WRONG_LOCK = "wrong_lock"
#: The outcome of a solution with a gross error: one of its components farther than
#: :data:`GROSS_ERROR_SIGMA` robust standard deviations from its node's core (a solution the
#: consistency test let through with a spot biased by a glint, say). It is a solution, ``ok`` True.
GROSS_ERROR = "gross_error"
#: The distance from the core, in robust standard deviations (1.4826 x the median absolute deviation
#: about the median) of any one component, beyond which a solved frame is a gross error: a normal
#: core puts one frame in about 10^8 beyond it.
GROSS_ERROR_SIGMA = 6.0


class OutsideEnvelope(InputError):
    """A pose outside the table's envelope: nothing was rendered there, the table refuses."""


@dataclass
class SensorTable:
    """The statistics of one sensor at a grid of nodes.

    Attributes
    ----------
    camera, pattern : str
    ranges_m : ndarray, shape (R,)
        The nodes' ranges, increasing, m (the target's depth along the boresight).
    off_axis_deg : ndarray, shape (A,)
        The nodes' off-axis angles, increasing from 0, deg.
    attitude_max_deg : float
        Every frame's roll, pitch and yaw was drawn within +-this, deg (the envelope).
    frame_rate_hz : float
    n : ndarray, shape (R, A), int
        Frames rendered at each node.
    n_solved : ndarray, shape (R, A), int
        Frames with a solution that locked onto the targets and whose error is in the node's core
        (not a gross error).
    n_gross : ndarray, shape (R, A), int
        Solutions with a gross error (:data:`GROSS_ERROR`).
    n_wrong_lock : ndarray, shape (R, A), int
    dropouts : dict of str -> ndarray, shape (R, A), int
        Frames without a solution, by reason.
    bias : ndarray, shape (R, A, 6)
        Mean error of the core's solved frames (:data:`svgs_sim.svgs.frames.STATE_KEYS`: m and deg); NaN
        where fewer than :data:`MIN_SOLVED_FOR_STATISTICS`.
    covariance : ndarray, shape (R, A, 6, 6)
        Their covariance (m and deg), NaN likewise.
    crlb_std : ndarray, shape (R, A, 6)
        Median per-frame 1-sigma Cramer-Rao bound of the solved frames, NaN likewise.
    wrong_lock_errors, gross_errors : list (R) of list (A) of list of ndarray, shape (6,)
        The wrong-locked frames' and the gross errors' errors at each node (m and deg).
    provenance : dict
        How the table was made (the build's configuration and command).
    """

    camera: str
    pattern: str
    ranges_m: np.ndarray
    off_axis_deg: np.ndarray
    attitude_max_deg: float
    frame_rate_hz: float
    n: np.ndarray
    n_solved: np.ndarray
    n_gross: np.ndarray
    n_wrong_lock: np.ndarray
    dropouts: dict
    bias: np.ndarray
    covariance: np.ndarray
    crlb_std: np.ndarray
    wrong_lock_errors: list
    gross_errors: list
    provenance: dict = field(default_factory=dict)

    # ------------------------------------------------------------------ the envelope
    def check_pose(self, range_m: float, off_axis_deg: float, attitude_deg) -> None:
        """Refuse a pose outside the envelope (:class:`OutsideEnvelope`, naming what is out)."""
        lo, hi = float(self.ranges_m[0]), float(self.ranges_m[-1])
        if not lo <= range_m <= hi:
            raise OutsideEnvelope(f"range {range_m:.3f} m: outside the sensor model's {lo:g}-{hi:g} m "
                                  f"({self.camera}; build a table that covers it: svgs sensor-model build --ranges)")
        if off_axis_deg > float(self.off_axis_deg[-1]):
            raise OutsideEnvelope(f"off-axis angle {off_axis_deg:.2f} deg: beyond the sensor model's "
                                  f"{float(self.off_axis_deg[-1]):g} deg ({self.camera})")
        a = np.abs(np.asarray(attitude_deg, float))
        if np.any(a > self.attitude_max_deg):
            raise OutsideEnvelope(f"attitude {np.round(attitude_deg, 2).tolist()} deg (roll, pitch, yaw): beyond the "
                                  f"sensor model's +-{self.attitude_max_deg:g} deg ({self.camera})")

    # ------------------------------------------------------------------ interpolation
    def weights(self, range_m: float, off_axis_deg: float) -> list[tuple[int, int, float]]:
        """The bilinear weights ``[(i_range, i_off_axis, w), ...]`` of the nodes around a pose:
        linear in log-range and in the off-axis angle (a coordinate with one node: weight 1)."""
        def axis(nodes, x):
            if len(nodes) == 1:
                return [(0, 1.0)]
            j = int(np.clip(np.searchsorted(nodes, x) - 1, 0, len(nodes) - 2))
            f = float(np.clip((x - nodes[j]) / (nodes[j + 1] - nodes[j]), 0.0, 1.0))
            return [(j, 1.0 - f), (j + 1, f)]

        ra = axis(np.log(self.ranges_m), np.log(range_m))
        oa = axis(np.asarray(self.off_axis_deg, float), off_axis_deg)
        return [(i, j, wi * wj) for i, wi in ra for j, wj in oa if wi * wj > 0]

    def probabilities(self, range_m: float, off_axis_deg: float) -> dict:
        """``{"solved": p, "wrong_lock": p, REASON: p, ...}`` at a pose (each node's fractions,
        interpolated; they sum to 1)."""
        w = self.weights(range_m, off_axis_deg)
        out = {"solved": sum(wk * self.n_solved[i, j] / self.n[i, j] for i, j, wk in w),
               GROSS_ERROR: sum(wk * self.n_gross[i, j] / self.n[i, j] for i, j, wk in w),
               WRONG_LOCK: sum(wk * self.n_wrong_lock[i, j] / self.n[i, j] for i, j, wk in w)}
        for reason, counts in self.dropouts.items():
            out[reason] = sum(wk * counts[i, j] / self.n[i, j] for i, j, wk in w)
        return out

    def error_statistics(self, range_m: float, off_axis_deg: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(bias (6,), covariance (6, 6), crlb_std (6,))`` at a pose: the nodes around it that have
        statistics, interpolated (their weights renormalised); where none has, the node nearest in
        log-range in the nearest off-axis column that has."""
        w = [(i, j, wk) for i, j, wk in self.weights(range_m, off_axis_deg) if np.isfinite(self.bias[i, j, 0])]
        total = sum(wk for _, _, wk in w)
        if total <= 0:
            j = int(np.argmin(np.abs(np.asarray(self.off_axis_deg) - off_axis_deg)))
            ok = np.flatnonzero(np.isfinite(self.bias[:, j, 0]))
            if ok.size == 0:
                raise OutsideEnvelope(f"the sensor model ({self.camera}) has no solved frames at off-axis "
                                      f"{float(self.off_axis_deg[j]):g} deg")
            i = int(ok[np.argmin(np.abs(np.log(self.ranges_m[ok]) - np.log(range_m)))])
            w, total = [(i, j, 1.0)], 1.0
        bias = sum(wk * self.bias[i, j] for i, j, wk in w) / total
        cov = sum(wk * self.covariance[i, j] for i, j, wk in w) / total
        crlb = sum(wk * self.crlb_std[i, j] for i, j, wk in w) / total
        return bias, cov, crlb

    def stored_error(self, outcome: str, range_m: float, off_axis_deg: float, rng: np.random.Generator) -> np.ndarray:
        """One stored error (6,) of a wrong lock or a gross error, drawn from the nearest node (in
        log-range and angle) that holds one."""
        pool = self.wrong_lock_errors if outcome == WRONG_LOCK else self.gross_errors
        nodes = [(abs(np.log(self.ranges_m[i] / range_m)) + abs(self.off_axis_deg[j] - off_axis_deg) / 90.0, i, j)
                 for i in range(len(self.ranges_m)) for j in range(len(self.off_axis_deg)) if pool[i][j]]
        if not nodes:
            raise InputError(f"the sensor model ({self.camera}) gives {outcome} a probability but holds no such error")
        _, i, j = min(nodes)
        return np.asarray(pool[i][j][int(rng.integers(len(pool[i][j])))], float)

    # ------------------------------------------------------------------ files
    def to_json(self) -> dict:
        def nan_list(a):
            return np.where(np.isfinite(a), a, np.nan).tolist()

        return {"kind": TABLE_KIND, "version": TABLE_VERSION, "camera": self.camera, "pattern": self.pattern,
                "state_keys": list(STATE_KEYS), "ranges_m": self.ranges_m.tolist(),
                "off_axis_deg": self.off_axis_deg.tolist(), "attitude_max_deg": self.attitude_max_deg,
                "frame_rate_hz": self.frame_rate_hz, "n": self.n.tolist(), "n_solved": self.n_solved.tolist(),
                "n_gross": self.n_gross.tolist(), "n_wrong_lock": self.n_wrong_lock.tolist(),
                "dropouts": {k: v.tolist() for k, v in sorted(self.dropouts.items())},
                "bias": nan_list(self.bias), "covariance": nan_list(self.covariance),
                "crlb_std": nan_list(self.crlb_std),
                "wrong_lock_errors": _nested(self.wrong_lock_errors), "gross_errors": _nested(self.gross_errors),
                "provenance": self.provenance}

    def save(self, path) -> Path:
        """Write the table as JSON (NaN where a node has no statistics)."""
        path = Path(path)
        path.write_text(json.dumps(self.to_json(), indent=1) + "\n", encoding="utf-8")
        return path

    @classmethod
    def from_json(cls, d: dict, source: str = "the table") -> "SensorTable":
        if not isinstance(d, dict) or d.get("kind") != TABLE_KIND:
            raise InputError(f"{source}: not a sensor model (svgs sensor-model build writes sensor_model.json)")
        if d.get("version") != TABLE_VERSION:
            raise InputError(f"{source}: sensor model version {d.get('version')!r}, this svgs-sim reads "
                             f"{TABLE_VERSION}; rebuild it")
        try:
            t = cls(camera=str(d["camera"]), pattern=str(d["pattern"]), ranges_m=np.asarray(d["ranges_m"], float),
                    off_axis_deg=np.asarray(d["off_axis_deg"], float), attitude_max_deg=float(d["attitude_max_deg"]),
                    frame_rate_hz=float(d["frame_rate_hz"]), n=np.asarray(d["n"], int),
                    n_solved=np.asarray(d["n_solved"], int), n_gross=np.asarray(d["n_gross"], int),
                    n_wrong_lock=np.asarray(d["n_wrong_lock"], int),
                    dropouts={k: np.asarray(v, int) for k, v in d["dropouts"].items()},
                    bias=np.asarray(d["bias"], float), covariance=np.asarray(d["covariance"], float),
                    crlb_std=np.asarray(d["crlb_std"], float),
                    wrong_lock_errors=_arrays(d["wrong_lock_errors"]), gross_errors=_arrays(d["gross_errors"]),
                    provenance=dict(d.get("provenance", {})))
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"{source}: a malformed sensor model ({type(exc).__name__}: {exc})") from None
        shape = (t.ranges_m.size, t.off_axis_deg.size)
        if (t.n.shape != shape or t.bias.shape != shape + (6,) or t.covariance.shape != shape + (6, 6)
                or np.any(t.n <= 0) or np.any(np.diff(t.ranges_m) <= 0) or t.ranges_m[0] <= 0):
            raise InputError(f"{source}: a malformed sensor model (its arrays do not match its {shape} nodes)")
        return t

    @classmethod
    def load(cls, path) -> "SensorTable":
        """Read ``sensor_model.json`` (a folder holding one is read too)."""
        p = Path(path)
        if p.is_dir():
            p = p / "sensor_model.json"
        try:
            d = json.loads(p.read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise InputError(f"sensor model {str(path)!r}: no such file") from None
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise InputError(f"sensor model {str(path)!r}: cannot be read ({type(exc).__name__}: {exc})") from None
        return cls.from_json(d, f"sensor model {str(path)!r}")


def _nested(errors: list) -> list:
    return [[[np.asarray(e).tolist() for e in cell] for cell in row] for row in errors]


def _arrays(errors: list) -> list:
    return [[[np.asarray(e, float) for e in cell] for cell in row] for row in errors]


def pose_coordinates(R_cam_target, t_cam_target_m) -> tuple[float, float, dict]:
    """``(range_m, off_axis_deg, truth)`` of a pose: the target's depth along the boresight, the
    target origin's angle from the boresight, and the paper's state (m and deg)."""
    R, t = check_pose(R_cam_target, t_cam_target_m)
    off = float(np.degrees(np.arctan2(np.hypot(t[0], t[1]), t[2])))
    return float(t[2]), off, state_dict(pose_to_state(R, t))


class StatisticalSensor:
    """A sensor drawn from a :class:`SensorTable`: the interface of
    :class:`svgs_sim.sim.approach.ApproachSensor` for :class:`svgs_sim.sim.basilisk_svgs.SVGSModule`.

    Parameters
    ----------
    table : SensorTable or str or Path
        The table, or its ``sensor_model.json`` (or the folder holding it).
    seed : int
        Every frame's draws come from ``(seed, frame index)``: the same seed gives the same frames.
    frame_rate_hz : float, optional
        The rate the module takes frames at (default the table's).
    """

    def __init__(self, table, *, seed: int = 0, frame_rate_hz: float | None = None):
        self.table = table if isinstance(table, SensorTable) else SensorTable.load(table)
        if int(seed) < 0:
            raise InputError(f"seed: expected a non-negative integer, got {seed!r}")
        self.seed = int(seed)
        self.frame_rate_hz = float(frame_rate_hz) if frame_rate_hz is not None else self.table.frame_rate_hz
        self.frame_index = 0
        #: Why the sensor refused a pose (:class:`OutsideEnvelope`'s message, with the time), or None.
        self.refused = None

    @property
    def camera(self) -> Camera:
        """The table's camera profile (its focal length scales the docking filter's floors)."""
        return load_camera(self.table.camera)

    def _rng(self, k: int) -> np.random.Generator:
        return np.random.default_rng(np.random.SeedSequence([self.seed, int(k), 43]))

    def measure(self, t_s: float, R_cam_target, t_cam_target_m, *, image_velocity_px_s=None) -> Measurement:
        """One frame drawn at a pose (``image_velocity_px_s`` is accepted and ignored: the table's frames
        are static). Raises :class:`OutsideEnvelope` outside the table's envelope."""
        range_m, off, truth = pose_coordinates(R_cam_target, t_cam_target_m)
        att = [truth[k] for k in STATE_KEYS[3:]]
        try:
            self.table.check_pose(range_m, off, att)
        except OutsideEnvelope as exc:  # kept: a caller that only sees its own wrapper (Basilisk's) can ask
            self.refused = f"t = {float(t_s):g} s: {exc}"
            raise
        k = self.frame_index
        self.frame_index += 1
        rng = self._rng(k)
        p = self.table.probabilities(range_m, off)
        outcomes = list(p)
        probs = np.array([max(p[o], 0.0) for o in outcomes])
        outcome = outcomes[int(rng.choice(len(outcomes), p=probs / probs.sum()))]
        nan = float("nan")
        m = Measurement(frame=k, t_s=float(t_s), ok=False, reason=None, truth=truth, estimate=None, error=None,
                        crlb_std=None, range_m=range_m, exposure_s=nan, iso=nan, metered_level=nan,
                        next_exposure_s=nan, next_iso=nan, n_blobs=None)
        if outcome not in ("solved", WRONG_LOCK, GROSS_ERROR):
            m.reason = outcome
            return m
        bias, cov, crlb = self.table.error_statistics(range_m, off)
        if outcome in (WRONG_LOCK, GROSS_ERROR):  # one of the stored errors of the nearest node that has one
            err = self.table.stored_error(outcome, range_m, off, rng)
            m.wrong_lock = outcome == WRONG_LOCK
        else:
            err = rng.multivariate_normal(bias, cov, method="eigh")
        m.ok = True
        m.error = {key: float(e) for key, e in zip(STATE_KEYS, err)}
        m.estimate = {key: truth[key] + m.error[key] for key in STATE_KEYS}
        m.crlb_std = {key: float(c) for key, c in zip(STATE_KEYS, crlb)}
        return m

    def close(self) -> None:
        pass
