"""Trajectories of an approach: poses against time (a straight approach, or a CSV file in the
paper's state or the test stand's chain), and the check that the camera sees the pattern along one."""

from __future__ import annotations

import csv
import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from svgs_sim.base.errors import InputError
from svgs_sim.svgs.frames import D_CAM_PHOTO, STATE_KEYS, state_to_pose
from svgs_sim.svgs.envelope import ATTITUDE_LIMITS_DEG, check_attitude_deg, check_range_m
from svgs_sim.base.profiles import load_camera, load_pattern

from svgs_sim.sim.closed_loop import Scenario
from svgs_sim.sim.orbit_light import azimuth_elevation_deg

#: Columns of a trajectory file in the paper's state: the camera position in the target frame
#: and the paper's attitude (x-y-z sequence).
STATE_COLUMNS = STATE_KEYS
#: Columns of a trajectory file in the test stand's chain (:class:`svgs_sim.sim.stand.TestStand`): the
#: gimbal pivot's rail position, the translation stage and the gimbal angles.
STAND_COLUMNS = ("rail_m", "stage_m", "roll_deg", "pitch_deg", "yaw_deg")
#: Internal form of a target-mounted trajectory: :class:`svgs_sim.sim.closed_loop.Scenario`'s fields.
TARGET_FIELDS = ("range_m", "target_x_m", "target_y_m", "roll_deg", "pitch_deg", "yaw_deg")
#: Internal form of a stand trajectory: the file's own columns (the rail position is ``rail_m``,
#: never ``range_m``, which is the boresight distance).
STAND_FIELDS = STAND_COLUMNS
#: Optional columns of a trajectory file: the direction toward the sun in the target frame per
#: row, deg (as ``--sun-deg AZ,EL``: azimuth from +x toward +y, elevation from the pattern plane
#: toward +z), for an approach on orbit whose sun moves (an orbit's phase). Both or neither.
SUN_COLUMNS = ("sun_azimuth_deg", "sun_elevation_deg")
#: Largest turn of the sun's direction between two rows, deg: the direction is interpolated along
#: the chord between the rows' unit vectors and renormalised, which is the great circle's path
#: only for turns well under 180 deg.
MAX_SUN_TURN_DEG = 90.0
#: Time step of the central difference that gives the image velocity of the spots, s.
VELOCITY_STEP_S = 1e-3
#: Most frames one approach may have.
MAX_FRAMES = 100000
#: A pose is visible when every target projects this far inside the image, px.
VISIBILITY_MARGIN_PX = 2.0


def _round_up(x: float, digits: int = 3) -> float:
    """``x`` (> 0) rounded up to ``digits`` significant digits (a bound that still holds when printed)."""
    step = 10.0 ** (np.floor(np.log10(x)) - (digits - 1))
    return float(np.ceil(x / step - 1e-9) * step)


@dataclass(frozen=True)
class Trajectory:
    """Poses against time, interpolated linearly between knots.

    Attributes
    ----------
    t_s : ndarray, shape (N,)
        Knot times, s, strictly increasing.
    values : ndarray, shape (N, K)
        At each knot, the :data:`TARGET_FIELDS` (``mount="target"``: the target's position in
        the camera's frame and the paper's attitude) or the :data:`STAND_FIELDS`
        (``mount="stand"``).
    mount : {"target", "stand"}
    source : str
        Where it came from (a file, or the generator's parameters).
    sun_deg : ndarray, shape (N, 2), optional
        At each knot, the direction toward the sun in the target frame, (azimuth, elevation) deg
        (:data:`SUN_COLUMNS`); None: the scene's own sun (``--sun-deg``) at every frame.
    """

    t_s: np.ndarray
    values: np.ndarray
    mount: str = "target"
    source: str = ""
    sun_deg: np.ndarray | None = None

    def __post_init__(self):
        t = np.asarray(self.t_s, float)
        v = np.asarray(self.values, float)
        object.__setattr__(self, "t_s", t)
        object.__setattr__(self, "values", v)
        if self.mount not in ("target", "stand"):
            raise InputError(f"trajectory: mount must be 'target' or 'stand', got {self.mount!r}")
        if t.ndim != 1 or t.size < 2 or v.shape != (t.size, len(self.fields)):
            raise InputError(f"trajectory: expected at least 2 knots of {len(self.fields)} values, got times "
                             f"{t.shape} and values {v.shape}")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(v))):
            raise InputError("trajectory: times and values must be finite")
        if np.any(np.diff(t) <= 0):
            raise InputError("trajectory: knot times t_s must increase strictly")
        if self.sun_deg is not None:
            object.__setattr__(self, "sun_deg", _checked_sun(self.sun_deg, t.size, f"trajectory ({self.source})"))

    @property
    def fields(self) -> tuple:
        return TARGET_FIELDS if self.mount == "target" else STAND_FIELDS

    @property
    def duration_s(self) -> float:
        return float(self.t_s[-1] - self.t_s[0])

    def at(self, t_s: float) -> dict:
        """The Scenario fields at a time, interpolated linearly between the knots.

        Parameters
        ----------
        t_s : float
            Time, s (clamped to the trajectory's span).

        Returns
        -------
        dict
            :attr:`fields` -> value (m, deg).
        """
        t = float(np.clip(t_s, self.t_s[0], self.t_s[-1]))
        return {k: float(np.interp(t, self.t_s, self.values[:, j])) for j, k in enumerate(self.fields)}

    def sun_at(self, t_s: float) -> tuple[float, float] | None:
        """The direction toward the sun at a time, (azimuth, elevation) deg, or None (no sun columns).

        The knots' unit vectors are interpolated linearly and renormalised (a turn between two
        rows is at most :data:`MAX_SUN_TURN_DEG`); ``t_s`` is clamped to the span.
        """
        if self.sun_deg is None:
            return None
        t = float(np.clip(t_s, self.t_s[0], self.t_s[-1]))
        v = _sun_vectors(self.sun_deg)
        d = np.array([np.interp(t, self.t_s, v[:, j]) for j in range(3)])
        return azimuth_elevation_deg(d / np.linalg.norm(d))

    def scenario(self, t_s: float, base: Scenario) -> Scenario:
        """``base`` (camera, lab, ...) at this trajectory's pose at time ``t_s`` (s): a
        :class:`~svgs_sim.sim.closed_loop.Scenario` with this trajectory's mount (and, with sun
        columns, its sun at that time in place of the base scene's)."""
        other = {"range_m": None} if self.mount == "stand" else {"rail_m": None}  # one distance, by the mount
        sun = self.sun_at(t_s)
        if sun is not None:
            other["scene"] = dataclasses.replace(base.scene, sun_azimuth_deg=sun[0], sun_elevation_deg=sun[1])
        return base.replace(mount=self.mount, **other, **self.at(t_s))

    def frame_times(self, fps: float) -> np.ndarray:
        """Frame timestamps ``t0 + k / fps`` within the span.

        Parameters
        ----------
        fps : float
            Frames per second (> 0).

        Returns
        -------
        ndarray, shape (n,)
            Times, s; at least 2, at most :data:`MAX_FRAMES`.

        Raises
        ------
        InputError
            A rate that is not positive, or that gives fewer than 2 or more than :data:`MAX_FRAMES`
            frames over the span.
        """
        fps = float(fps)
        if not np.isfinite(fps) or fps <= 0:
            raise InputError(f"--fps: expected a positive frame rate, got {fps!r}")
        n = int(np.floor(self.duration_s * fps + 1e-9)) + 1
        if n < 2:  # one frame is no approach: say how to get more
            raise InputError(f"--fps: {fps:g} frames per second over the {self.duration_s:g} s trajectory gives {n} "
                             f"frame; an approach needs at least 2: give --fps {_round_up(1.0 / self.duration_s):g} or more, "
                             "or a longer trajectory")
        if n > MAX_FRAMES:
            raise InputError(f"--fps: {n} frames over {self.duration_s:g} s; at most {MAX_FRAMES}")
        return self.t_s[0] + np.arange(n) / fps

    def to_json(self) -> dict:
        """The knots as JSON-ready lists (the study's manifest: a changed file is a changed study)."""
        out = {"mount": self.mount, "fields": list(self.fields), "t_s": self.t_s.tolist(),
               "values": self.values.tolist(), "source": self.source}
        if self.sun_deg is not None:  # only then: a study made before the sun columns resumes
            out["sun_deg"] = self.sun_deg.tolist()
        return out

    @classmethod
    def from_json(cls, d: dict) -> "Trajectory":
        """The inverse of :meth:`to_json`."""
        sun = d.get("sun_deg")
        return cls(np.array(d["t_s"]), np.array(d["values"]), d["mount"], d["source"],
                   None if sun is None else np.array(sun, float))

    # ------------------------------------------------------------------ constructors
    @classmethod
    def straight(cls, from_m: float, to_m: float, duration_s: float, *, lateral_m=(0.0, 0.0),
                 attitude_deg=(0.0, 0.0, 0.0)) -> "Trajectory":
        """A straight approach along the boresight from ``from_m`` to ``to_m`` over ``duration_s``.

        ``lateral_m`` (x right, y up, m) and ``attitude_deg`` (the paper's roll, pitch, yaw) are
        the target's offsets at the start; they are nulled linearly along the way, as a docking
        approach lines up on the docking axis.
        """
        for name, v in (("--from", from_m), ("--to", to_m), ("--duration", duration_s)):
            if not np.isfinite(float(v)) or float(v) <= 0:
                raise InputError(f"{name}: expected a positive number, got {v!r}")
        lat = [float(x) for x in lateral_m]
        att = [float(x) for x in attitude_deg]
        if len(lat) != 2 or len(att) != 3 or not np.all(np.isfinite(lat + att)):
            raise InputError(f"lateral_m/attitude_deg: expected (x, y) m and (roll, pitch, yaw) deg, got {lateral_m!r}, "
                             f"{attitude_deg!r}")
        for name, v in zip(("roll_deg", "pitch_deg", "yaw_deg"), att):
            check_attitude_deg(name, v, f"--attitude {name}")
        start = [float(from_m), *lat, *att]
        end = [float(to_m), 0.0, 0.0, 0.0, 0.0, 0.0]
        src = (f"straight approach {float(from_m):g} -> {float(to_m):g} m in {float(duration_s):g} s, lateral {lat} m, "
               f"attitude {att} deg at the start, nulled linearly")
        return cls(np.array([0.0, float(duration_s)]), np.array([start, end]), "target", src)

    @classmethod
    def load(cls, path) -> "Trajectory":
        """Read a trajectory CSV: ``t_s`` and either the paper's state (:data:`STATE_COLUMNS`) or
        the test stand's chain (:data:`STAND_COLUMNS`) per row, not both (a header with columns of
        both is refused). Every problem is an
        :class:`~svgs_sim.base.errors.InputError` naming the file, the row and the column."""
        p = Path(path)
        where = f"--trajectory {str(path)!r}"
        if p.exists() and not p.is_file():
            raise InputError(f"{where}: not a regular file (a folder, device, FIFO or socket); give a CSV file")
        if not p.is_file():
            raise InputError(f"{where}: no such file")
        try:
            text = p.read_text(encoding="utf-8-sig")  # a byte-order mark (spreadsheets write one) is not a column
        except (OSError, UnicodeDecodeError) as exc:
            raise InputError(f"{where}: cannot read it as text ({exc})") from None
        kept = [(n, line) for n, line in enumerate(text.splitlines(), start=1)
                if line.strip() and not line.lstrip().startswith("#")]
        line_no = [n for n, _ in kept]  # the file's own line numbers, for the messages
        rows = list(csv.reader(line for _, line in kept))
        if not rows:
            raise InputError(f"{where}: empty file; expected a header with t_s and "
                             f"{', '.join(STATE_COLUMNS)} (paper state) or {', '.join(STAND_COLUMNS)} (test stand)")
        header = [h.strip() for h in rows[0]]
        if "t_s" not in header:
            raise InputError(f"{where}: no t_s column in the header {header}")
        own = {"state": [c for c in STATE_COLUMNS if c not in STAND_COLUMNS],
               "stand": [c for c in STAND_COLUMNS if c not in STATE_COLUMNS]}
        if all(any(c in header for c in cs) for cs in own.values()):
            # both: refuse rather than pick one silently (the angles are shared, the rest are not)
            raise InputError(
                f"{where}: the header has columns of both the paper state ({', '.join(STATE_COLUMNS)}) and the test "
                f"stand's chain ({', '.join(STAND_COLUMNS)}): found {', '.join(c for c in own['state'] if c in header)}"
                f" and {', '.join(c for c in own['stand'] if c in header)}; keep one set (with t_s)")
        if set(STATE_COLUMNS) <= set(header):
            mount, cols = "target", STATE_COLUMNS
        elif set(STAND_COLUMNS) <= set(header):
            mount, cols = "stand", STAND_COLUMNS
        else:
            raise InputError(f"{where}: the header {header} has neither the paper state ({', '.join(STATE_COLUMNS)}) "
                             f"nor the test stand's chain ({', '.join(STAND_COLUMNS)})")
        sun_cols = _sun_columns(header, where)
        idx = [header.index(c) for c in ("t_s", *cols, *sun_cols)]
        data = []
        for i, row in enumerate(rows[1:], start=1):
            n = line_no[i]
            if len(row) != len(header):
                raise InputError(f"{where}: line {n} has {len(row)} fields, the header {len(header)}")
            vals = []
            for j, c in zip(idx, ("t_s", *cols, *sun_cols)):
                try:
                    x = float(row[j])
                except ValueError:
                    raise InputError(f"{where}: line {n}, column {c}: {row[j]!r} is not a number") from None
                if not np.isfinite(x):
                    raise InputError(f"{where}: line {n}, column {c}: {row[j]!r} is not finite")
                if c in ATTITUDE_LIMITS_DEG:  # the envelope --roll/--pitch/--yaw take
                    check_attitude_deg(c, x, f"{where}: line {n}, column {c}")
                if c == "sun_elevation_deg" and not -90.0 <= x <= 90.0:
                    raise InputError(f"{where}: line {n}, column {c}: {row[j]!r} is outside -90 to 90 deg")
                vals.append(x)
            data.append(vals)
        if len(data) < 2:
            raise InputError(f"{where}: expected at least 2 rows of poses, got {len(data)}")
        a = np.array(data)
        sun = None
        if sun_cols:
            sun, a = a[:, -2:].copy(), a[:, :-2]
        rows_line = line_no[1:]
        dt = np.diff(a[:, 0])
        if np.any(dt <= 0):
            k = int(np.argmax(dt <= 0))
            raise InputError(f"{where}: t_s must increase strictly; line {rows_line[k + 1]} (t_s = {a[k + 1, 0]:g}) "
                             f"follows t_s = {a[k, 0]:g}")
        # angles: the shorter way round between rows (yaw 179 -> -179 is a 2 deg turn, not 358)
        ang = [1 + cols.index(c) for c in ("roll_deg", "pitch_deg", "yaw_deg")]
        a[:, ang] = np.degrees(np.unwrap(np.radians(a[:, ang]), axis=0))
        if mount == "stand":
            values = a[:, 1:]
        else:  # paper state -> the target's position in the camera frame (Scenario's fields)
            R, t = state_to_pose(np.column_stack([a[:, 1:4], np.deg2rad(a[:, 4:7])]))
            if np.any(t[:, 2] <= 0):
                k = int(np.argmax(t[:, 2] <= 0))
                raise InputError(f"{where}: line {rows_line[k]}: the target is behind the camera (range along the "
                                 f"boresight {t[k, 2]:.3g} m)")
            xyz = t @ D_CAM_PHOTO  # D t: (target_x, target_y, -range) in the paper's camera frame
            values = np.column_stack([t[:, 2], xyz[:, 0], xyz[:, 1], a[:, 4:7]])
        if sun is not None:
            _check_sun_turns(sun, rows_line, where)
        return cls(a[:, 0], values, mount, str(path), sun)


def _sun_vectors(sun_deg: np.ndarray) -> np.ndarray:
    """Unit vectors (N, 3) of (azimuth, elevation) deg rows (N, 2), target frame."""
    az, el = np.radians(sun_deg[:, 0]), np.radians(sun_deg[:, 1])
    return np.column_stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])


def _sun_turns_deg(sun_deg: np.ndarray) -> np.ndarray:
    """The angle between consecutive rows' sun directions, deg, shape (N - 1,)."""
    v = _sun_vectors(sun_deg)
    return np.degrees(np.arccos(np.clip(np.sum(v[1:] * v[:-1], axis=1), -1.0, 1.0)))


def _sun_columns(header: list, where: str) -> tuple:
    """The file's sun columns: :data:`SUN_COLUMNS` or none (InputError for one without the other)."""
    has = [c in header for c in SUN_COLUMNS]
    if any(has) and not all(has):
        raise InputError(f"{where}: the sun's direction needs both columns {', '.join(SUN_COLUMNS)}; found only "
                         f"{SUN_COLUMNS[has.index(True)]}")
    return SUN_COLUMNS if all(has) else ()


def _check_sun_turns(sun_deg: np.ndarray, rows_line: list, where: str) -> None:
    """Refuse a turn of the sun's direction over :data:`MAX_SUN_TURN_DEG` between rows, naming the line."""
    turn = _sun_turns_deg(sun_deg)
    if turn.size and turn.max() > MAX_SUN_TURN_DEG:
        k = int(np.argmax(turn))
        raise InputError(f"{where}: line {rows_line[k + 1]}: the sun's direction turns {turn[k]:.0f} deg from "
                         f"the row before; at most {MAX_SUN_TURN_DEG:g} deg between rows (add rows between)")


def _checked_sun(sun_deg, n: int, where: str) -> np.ndarray:
    """``sun_deg`` as a checked (n, 2) array of (azimuth, elevation) deg."""
    a = np.asarray(sun_deg, float)
    if a.shape != (n, 2) or not np.all(np.isfinite(a)):
        raise InputError(f"{where}: sun_deg: expected finite (azimuth, elevation) deg at each of the {n} knots, shape "
                         f"({n}, 2), got shape {a.shape}")
    if np.any(np.abs(a[:, 1]) > 90.0):
        raise InputError(f"{where}: sun_deg: elevations must lie within -90 to 90 deg")
    turn = _sun_turns_deg(a)
    if turn.size and turn.max() > MAX_SUN_TURN_DEG:
        raise InputError(f"{where}: sun_deg: the sun's direction turns {turn.max():.0f} deg between two knots; at most "
                         f"{MAX_SUN_TURN_DEG:g}")
    return a


def check_envelope(trajectory: Trajectory, camera, pattern) -> None:
    """Refuse a trajectory with a knot outside the envelope ``--range`` and ``--roll/--pitch/--yaw``
    take (:func:`svgs_sim.svgs.envelope.range_envelope_m`, :data:`svgs_sim.svgs.envelope.ATTITUDE_LIMITS_DEG`).

    Between knots the fields are interpolated linearly, so the knots bound every frame. The
    range is the boresight range (``mount="target"``) or the rail position (``"stand"``).

    Raises
    ------
    InputError
        Naming the trajectory, the knot's time, the value and the allowed range.
    """
    for k, t in enumerate(trajectory.t_s):
        where = f"trajectory ({trajectory.source}) at t_s = {t:g}"
        check_range_m(trajectory.values[k, 0], camera, pattern, f"{where}: {trajectory.fields[0]}")


def check_visible(trajectory: Trajectory, times_s, camera, pattern, base: Scenario | None = None) -> None:
    """Refuse a trajectory on which the camera cannot see the whole pattern at some frame.

    Parameters
    ----------
    trajectory : Trajectory
    times_s : array_like, shape (n,)
        The frame times, s.
    camera : svgs.Camera or str
        The camera the frames are made through.
    pattern : svgs.Pattern or str
    base : Scenario, optional
        The scenario the trajectory's poses are set in.

    Raises
    ------
    InputError
        Naming the first frame time whose pose puts a target behind the camera or outside the
        image (with :data:`VISIBILITY_MARGIN_PX`), shows the camera the back of the target (its
        reflectors face the target's +z), or is a stand setting the stand cannot take.
    """
    cam = load_camera(camera)
    pat = load_pattern(pattern)
    check_envelope(trajectory, cam, pat)
    base = base or Scenario(camera=cam, pattern=pat)
    for t in np.asarray(times_s, float):
        try:
            sc = trajectory.scenario(t, base)
            R, tv = sc.pose()
        except InputError as exc:
            raise InputError(f"trajectory ({trajectory.source}) at t = {t:g} s: {exc}") from None
        p = pat.points_m @ R.T + tv
        facing = float(-(R[:, 2] @ tv) / np.linalg.norm(tv))  # cos(target +z, direction to the camera)
        if facing <= 0:
            raise InputError(f"trajectory ({trajectory.source}) at t = {t:g} s: the camera sees the back of the target "
                             f"({np.degrees(np.arccos(np.clip(facing, -1, 1))):.0f} deg from its face normal); its "
                             "reflectors return no light there")
        if np.any(p[:, 2] <= 0.05):
            raise InputError(f"trajectory ({trajectory.source}) at t = {t:g} s: a target is behind (or at) the lens")
        uv = cam.project(p)
        m = VISIBILITY_MARGIN_PX
        bad = ~((uv[:, 0] >= m) & (uv[:, 0] <= cam.width - 1 - m) & (uv[:, 1] >= m) & (uv[:, 1] <= cam.height - 1 - m))
        if np.any(bad):
            ids = [int(i) for i in np.asarray(pat.ids)[bad]]
            raise InputError(f"trajectory ({trajectory.source}) at t = {t:g} s: target(s) {ids} fall outside the "
                             f"{cam.width} x {cam.height} image (at {np.round(uv[bad], 1).tolist()} px); the camera "
                             "cannot see the whole pattern there")
