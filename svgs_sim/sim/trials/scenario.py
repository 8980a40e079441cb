"""Typed trial scenarios: :class:`TrialScenario` (a kind's scenario; as a mapping, its results-store
row), :class:`PoseScenario` (the pose, the stand and the solver's calibration errors) and
:func:`build_scenario`.

Part of :mod:`svgs_sim.sim.trials`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import ClassVar

import numpy as np

from svgs_sim.base.errors import InputError
from svgs_sim.base.profiles import load_camera, load_pattern
from svgs_sim.sim.closed_loop import Scenario
from svgs_sim.sim.target_pose import TargetPose
from svgs_sim.sim.trials.registry import ID_COLUMNS, TIMING_COLUMNS, TrialKind, get_trial_kind

#: Scenario keys of the pose (the geometric kind's render key; the render kind adds its own).
POSE_KEYS = ("range_m", "rail_m", "target_x_m", "target_y_m", "roll_deg", "pitch_deg", "yaw_deg", "stand", "stage_m",
             "misalign_yaw_deg", "misalign_pitch_deg", "misalign_roll_deg", "stand_err_roll_deg",
             "stand_err_pitch_deg", "stand_err_yaw_deg", "stand_err_stage_m", "rail_err_m")


#: The truth's switches: which of the truth errors the errors are taken against.
TRUTH_KEYS = ("truth_actual", "truth_stand", "truth_rail")


#: Row columns of every study that are not scenario values (their ids, seeds, timings).
_NON_SCENARIO = (*ID_COLUMNS, *TIMING_COLUMNS)


def _given(value) -> bool:
    """A row value that is there (not None, not the NaN of an empty cell)."""
    return value is not None and not (isinstance(value, (float, np.floating)) and np.isnan(value))


class RowView(Mapping):
    """A typed scenario read as its results-store row (read-only): the subclass keeps the row,
    a dict of column -> value, in ``self._row``."""

    def __getitem__(self, key):
        return self._row[key]

    def __iter__(self):
        return iter(self._row)

    def __len__(self):
        return len(self._row)


@dataclass(frozen=True, eq=False)
class TrialScenario(RowView):
    """A trial kind's scenario: a typed, frozen, hashable value; the base of the kinds' scenarios.

    Attributes hold what a trial means (None where the profile's or the phone's own value is
    used, ``bool`` switches, ``mount`` names the stand). The *row view* is what a results store
    holds: :meth:`to_row` (and the read-only :class:`~collections.abc.Mapping` interface,
    ``scenario["range_m"]``, ``scenario.get(...)``, ``dict(scenario)``, ``{**scenario}``) gives
    the row's values - every parameter a number, with the sentinels the stores have always held
    (e.g. ``spp = -1``: the renderer's default) so that a sensitivity study varies them and old
    stores read back - then the ``labels`` (study keys such as ``pose_index`` or ``variant``,
    carried into the rows unchanged). :meth:`from_row` reads a row (new or old) back.

    Subclasses set ``KIND`` (the trial kind's name), declare their fields and may map
    special columns in :meth:`_decode` / :meth:`_encode`; plain parameters have a field of the
    same name (a float, an int in ``_INTS``, a bool in ``_BOOLS``, None for the sentinel of
    ``_OPTIONAL``).

    Attributes
    ----------
    camera, pattern : str
        Profile names or paths (loaded in the worker through :func:`svgs_sim.base.profiles.load_camera`
        and :func:`svgs_sim.base.profiles.load_pattern`).
    labels : tuple of (str, object)
        Study keys carried into the rows; give a dict to the builders.
    """

    camera: str
    pattern: str = "svgs-3u"
    labels: tuple = ()

    KIND: ClassVar[str] = ""
    #: Typed parts (field name -> class with ``row_values()`` and ``from_row(values)``, e.g. the
    #: :class:`svgs_sim.sim.scene.Scene`): their row parameters are theirs, decoded into one object.
    _PARTS: ClassVar[dict] = {}
    _OPTIONAL: ClassVar[dict] = {}
    _INTS: ClassVar[tuple] = ()
    _BOOLS: ClassVar[tuple] = ()

    def __post_init__(self):
        labels = self.labels.items() if isinstance(self.labels, Mapping) else self.labels
        object.__setattr__(self, "labels", tuple((str(k), v) for k, v in labels))
        object.__setattr__(self, "camera", str(self.camera))
        object.__setattr__(self, "pattern", str(self.pattern))
        self._normalise()
        row = self._encode()
        kind = self.kind()
        for name, p in kind.parameters.items():
            p.check(row[name])
        self._validate(row)
        for k, _ in self.labels:
            if k in row or k in ("camera", "pattern"):
                raise InputError(f"scenario label {k!r} clashes with a parameter")
        object.__setattr__(self, "_row", {"camera": self.camera, "pattern": self.pattern, **row, **dict(self.labels)})

    # ------------------------------------------------------------------ the kind's hooks
    @classmethod
    def kind(cls) -> "TrialKind":
        return get_trial_kind(cls.KIND)

    def _normalise(self) -> None:
        """Coerce the fields' types (bools, ints, floats)."""
        for f in fields(self):
            if f.name in ("camera", "pattern", "labels") or not f.init:
                continue
            v = getattr(self, f.name)
            if f.name in self._PARTS:
                part = self._PARTS[f.name]
                if isinstance(v, Mapping):
                    object.__setattr__(self, f.name, part(**v))
                elif not isinstance(v, part):
                    raise InputError(f"{f.name}: expected a {part.__module__}.{part.__name__}, got {v!r}")
                continue
            if v is None or isinstance(v, str):
                continue
            if f.name in self._BOOLS:
                v = bool(v)
            elif f.name in self._INTS:
                if float(v) != int(v):
                    raise InputError(f"{f.name}: expected an integer, got {v!r}")
                v = int(v)
            else:
                v = float(v)
            object.__setattr__(self, f.name, v)

    def _validate(self, row: dict) -> None:
        """Checks across fields (profiles exist...), after each parameter's own domain."""

        load_camera(self.camera)  # InputError for an unknown profile, now rather than in a worker
        load_pattern(self.pattern)

    @classmethod
    def _decode(cls, values: dict) -> dict:
        """Field values of the row values of the kind's parameters (sentinels to None...)."""
        out = {}
        values = dict(values)
        for name, part in cls._PARTS.items():
            keys = part().row_values()
            out[name] = part.from_row({k: values.pop(k) for k in keys if k in values})
        for k, v in values.items():
            if v is None:  # an optional parameter not given (range_m or rail_m, by the mount)
                out[k] = None
            elif k in cls._OPTIONAL and v == cls._OPTIONAL[k]:
                out[k] = None
            elif k in cls._BOOLS:
                if v not in (0.0, 1.0):
                    raise InputError(f"{k}: expected 0 or 1, got {v!r}")
                out[k] = bool(v)
            elif k in cls._INTS:
                if v != int(v):
                    raise InputError(f"{k}: expected an integer, got {v!r}")
                out[k] = int(v)
            else:
                out[k] = float(v)
        return out

    def _encode(self) -> dict:
        """Row values of the kind's parameters, in the kind's order."""
        return {k: self._row_value(k) for k in self.kind().parameters}

    def _row_value(self, key: str) -> float:
        """The row value of one parameter (the field of that name, or a part's; None: its sentinel)."""
        for name in self._PARTS:
            part_row = getattr(self, name).row_values()
            if key in part_row:
                return part_row[key]
        return self.row_code(key, getattr(self, key))

    @classmethod
    def row_code(cls, key: str, value) -> float:
        """How the results row writes ``value`` of the field ``key`` (None: the row's code for
        "the default"; the flat row exists only in the results store's codec)."""
        return float(cls._OPTIONAL[key]) if value is None else float(value)

    # ------------------------------------------------------------------ rows
    def to_row(self) -> dict:
        """The row view: ``camera``, ``pattern``, every parameter (numbers), the labels."""
        return dict(self._row)

    @property
    def label_dict(self) -> dict:
        return dict(self.labels)

    @classmethod
    def from_values(cls, values: Mapping, labels: Mapping | None = None) -> "TrialScenario":
        """A validated scenario of row values: ``camera`` (required), ``pattern`` (default
        ``svgs-3u``) and the kind's parameters (numbers with the row's sentinels; defaults filled
        in); an unknown key is an :class:`InputError`."""
        kind = cls.kind()
        values = dict(values)
        if "camera" not in values:
            raise InputError(f"{kind.name} scenario: 'camera' is required")
        camera, pattern = str(values.pop("camera")), str(values.pop("pattern", "svgs-3u"))
        unknown = sorted(set(values) - set(kind.parameters))
        if unknown:
            raise InputError(f"trial kind {kind.name!r} has no parameter {', '.join(map(repr, unknown))}; "
                             f"known: {', '.join(kind.parameters)}")
        nums = {name: p.check(values.get(name, p.default)) for name, p in kind.parameters.items()}
        for k in (labels or {}):
            if k in nums or k in ("camera", "pattern"):
                raise InputError(f"scenario label {k!r} clashes with a parameter")
        return cls(camera=camera, pattern=pattern, labels=tuple((labels or {}).items()), **cls._decode(nums))

    @classmethod
    def from_row(cls, row: Mapping) -> "TrialScenario":
        """The scenario of a results-store row (or of any mapping of row values): the kind's
        parameters (missing ones - rows of older stores - at their defaults; the sentinels of the
        old rows read as None), and as labels every other column that is not an output, an id
        or a timing."""
        if isinstance(row, cls):
            return row
        kind = cls.kind()
        skip = {"camera", "pattern", *kind.parameters, *kind.outputs, *_NON_SCENARIO}
        values = {k: row[k] for k in ("camera", "pattern", *kind.parameters) if k in row}
        return cls.from_values(values, {k: v for k, v in row.items() if k not in skip})

    # ------------------------------------------------------------------ the row view (RowView)
    def __eq__(self, other):
        if isinstance(other, TrialScenario):
            return type(self) is type(other) and self._row == other._row
        if isinstance(other, Mapping):
            return self._row == dict(other)
        return NotImplemented

    def __hash__(self):
        return hash((type(self).__name__, repr(tuple(self._row.items()))))

    def replace(self, **changes) -> "TrialScenario":
        """A copy with fields changed (validated again)."""
        return dataclasses.replace(self, **changes)

    # ------------------------------------------------------------------ the pose
    def closed_loop_scenario(self, **kw):
        """The :class:`svgs_sim.sim.closed_loop.Scenario` of this trial's pose (the profiles through the
        cached loaders; ``kw``: more of its fields)."""

        return Scenario(camera=self.camera, **self.pose_kwargs(), **kw)

    def pose_kwargs(self) -> dict:
        """The :class:`svgs_sim.sim.closed_loop.Scenario` pose fields of this trial."""
        raise NotImplementedError


@dataclass(frozen=True, eq=False)
class PoseScenario(TrialScenario, TargetPose):
    """The pose, the stand and the solver's calibration errors, shared by the geometric and the
    render kinds (see :data:`GEOMETRIC_PARAMETERS` for each one's meaning and unit).

    Attributes
    ----------
    range_m : float or None
        The boresight distance to the target origin, m (``mount="target"``; default 10).
    rail_m : float or None
        The gimbal pivot's rail position, m (``mount="stand"``, required). The row has both
        columns; the one that does not apply is empty.
    target_x_m, target_y_m, roll_deg, pitch_deg, yaw_deg : float
        The pose besides the range (keyword-only, :class:`svgs_sim.sim.target_pose.TargetPose`).
    mount : {"target", "stand"}
        What the angles turn (the row's ``stand``: 0 or 1).
    truth_actual, truth_stand, truth_rail : bool
        Which of the truth's errors the trial's errors are taken against.
    pp_error_u_px, pp_error_v_px, focal_error_frac, k1_error : float
        The calibration errors injected into the solver's camera
        (:func:`camera_with_calibration_errors`).
    """

    range_m: float | None = None
    rail_m: float | None = None
    mount: str = "target"
    stage_m: float = 0.0
    misalign_roll_deg: float = 0.0
    misalign_pitch_deg: float = 0.0
    misalign_yaw_deg: float = 0.0
    stand_err_roll_deg: float = 0.0
    stand_err_pitch_deg: float = 0.0
    stand_err_yaw_deg: float = 0.0
    stand_err_stage_m: float = 0.0
    rail_err_m: float = 0.0
    truth_actual: bool = False
    truth_stand: bool = False
    truth_rail: bool = False
    focal_error_frac: float = 0.0
    pp_error_u_px: float = 0.0
    pp_error_v_px: float = 0.0
    k1_error: float = 0.0

    _BOOLS: ClassVar[tuple] = TRUTH_KEYS

    def _normalise(self) -> None:
        if self.mount not in ("target", "stand"):
            raise InputError(f"mount: expected 'target' or 'stand', got {self.mount!r}")
        if self.mount == "target" and self.range_m is None and self.rail_m is None:
            object.__setattr__(self, "range_m", 10.0)
        if self.mount == "stand" and (self.rail_m is None or self.range_m is not None):
            raise InputError("rail_m: a stand scenario (mount='stand') gives the rail position as rail_m, not range_m")
        if self.mount == "target" and (self.range_m is None or self.rail_m is not None):
            raise InputError("range_m: a target scenario gives the boresight distance as range_m (rail_m: the stand's)")
        super()._normalise()

    @classmethod
    def from_values(cls, values: Mapping, labels: Mapping | None = None) -> "PoseScenario":
        """As :meth:`TrialScenario.from_values`, the distance by its one meaning: ``range_m`` (the
        boresight distance) on a target scenario, ``rail_m`` (the stand's rail position) on a stand
        scenario (``stand = 1``), never both. The mount may be given by its name, ``mount``
        (``"target"`` or ``"stand"``), instead of the row's ``stand`` code; ``rail_m`` alone
        implies the stand."""
        values = dict(values)
        if "mount" in values:
            mount = values.pop("mount")
            if mount not in ("target", "stand"):
                raise InputError(f"mount: expected 'target' or 'stand', got {mount!r}")
            if "stand" in values:
                raise InputError("give the mount as mount='stand' or 'target', not also as stand")
            values["stand"] = 1.0 if mount == "stand" else 0.0
        elif "stand" not in values and values.get("rail_m") is not None:
            values["stand"] = 1.0
        stand = cls.kind().parameters["stand"].check(values.get("stand", 0.0))
        given = {k for k in ("range_m", "rail_m") if _given(values.get(k))}
        if stand == 1.0:
            if "range_m" in given:
                raise InputError("range_m: the boresight distance of a target scenario; a stand scenario "
                                 "(stand = 1, mount='stand') gives the rail position as rail_m")
            if "rail_m" not in given:
                raise InputError("rail_m: a stand scenario (stand = 1, mount='stand') needs the rail position, m")
            values["range_m"] = None
        elif "rail_m" in given:
            raise InputError("rail_m: only the test stand (stand = 1, mount='stand') has a rail; give range_m")
        return super().from_values(values, labels)

    @classmethod
    def _decode(cls, values: dict) -> dict:
        values = dict(values)
        stand = values.pop("stand")
        if stand not in (0.0, 1.0):
            raise InputError(f"stand: expected 0 (target turned) or 1 (phone on the stand's gimbal), got {stand!r}")
        out = super()._decode(values)
        out["mount"] = "stand" if stand == 1.0 else "target"
        return out

    def _row_value(self, key: str):
        if key in ("range_m", "rail_m"):  # one of them, by the mount; the other's cell is empty
            return getattr(self, key)
        if key == "stand":
            return 1.0 if self.mount == "stand" else 0.0
        return super()._row_value(key)

    def _validate(self, row: dict) -> None:
        super()._validate(row)
        self.closed_loop_scenario()  # the pose fields together (lateral offsets and misalignment need the mount)

    @property
    def distance_m(self) -> float:
        """:attr:`rail_m` on the stand, else :attr:`range_m`."""
        return self.rail_m if self.mount == "stand" else self.range_m

    def pose_kwargs(self) -> dict:
        kw = {"rail_m": self.rail_m} if self.mount == "stand" else {"range_m": self.range_m}
        kw.update({k: getattr(self, k) for k in ("target_x_m", "target_y_m", "roll_deg", "pitch_deg", "yaw_deg",
                                                 "mount", "stage_m")})
        kw["misalignment_deg"] = (self.misalign_roll_deg, self.misalign_pitch_deg, self.misalign_yaw_deg)
        kw["stand_error"] = (self.stand_err_roll_deg, self.stand_err_pitch_deg, self.stand_err_yaw_deg,
                             self.stand_err_stage_m, self.rail_err_m)
        return kw

    @property
    def truth(self) -> tuple:
        """``(misalignment, stand, rail)``: which truth errors the trial's truth includes
        (:meth:`svgs_sim.sim.closed_loop.Scenario.truth_pose`)."""
        return (self.truth_actual, self.truth_stand, self.truth_rail)

    def poses(self):
        """``(R, t)`` actual and ``(R, t)`` of the truth the errors are taken against."""
        sc = self.closed_loop_scenario()
        return sc.pose(), sc.truth_pose(*self.truth)


def as_scenario(kind: "TrialKind", scenario):
    """``scenario`` as ``kind``'s typed scenario (a mapping of row values read with
    :meth:`TrialScenario.from_row`); a kind without a type gets it back as is."""
    if kind.scenario_type is None or isinstance(scenario, kind.scenario_type):
        return scenario
    return kind.scenario_type.from_row(scenario)


def camera_with_calibration_errors(camera, scenario: Mapping):
    """The camera the solver believes: ``camera`` with the scenario's calibration errors.

    Parameters
    ----------
    camera : svgs_sim.base.profiles.Camera
        The true camera.
    scenario : mapping
        ``focal_error_frac`` (fx and fy scaled by ``1 + e``), ``pp_error_u_px``,
        ``pp_error_v_px`` (added to cx, cy), ``k1_error`` (added to the radial k1).

    Returns
    -------
    svgs_sim.base.profiles.Camera
    """
    return camera.replace(
        fx=camera.fx * (1.0 + scenario["focal_error_frac"]),
        fy=camera.fy * (1.0 + scenario["focal_error_frac"]),
        cx=camera.cx + scenario["pp_error_u_px"],
        cy=camera.cy + scenario["pp_error_v_px"],
        dist=camera.dist + np.array([scenario["k1_error"], 0.0, 0.0, 0.0, 0.0]),
    )


def build_scenario(kind: TrialKind, values: dict, labels: dict | None = None):
    """A complete, validated scenario of ``kind``: defaults filled in, domains checked.

    Parameters
    ----------
    kind : TrialKind
    values : dict
        Row values: text keys (``camera`` required, ``pattern`` default ``svgs-3u``) and
        numeric parameters of ``kind`` (with the row's sentinels); an unknown key is an
        :class:`InputError`.
    labels : dict, optional
        Extra keys carried into the rows unchanged (e.g. ``nominal_range_m``).

    Returns
    -------
    TrialScenario or dict
        The kind's typed scenario (:attr:`TrialKind.scenario_type`), else a dict of row values.
    """
    if kind.scenario_type is not None:
        return kind.scenario_type.from_values(values, labels)

    values = dict(values)
    if "camera" not in values:
        raise InputError(f"{kind.name} scenario: 'camera' is required")
    out = {"camera": str(values.pop("camera")), "pattern": str(values.pop("pattern", "svgs-3u"))}
    load_camera(out["camera"])  # InputError for an unknown profile, now rather than in a worker
    load_pattern(out["pattern"])
    unknown = sorted(set(values) - set(kind.parameters))
    if unknown:
        raise InputError(f"trial kind {kind.name!r} has no parameter {', '.join(map(repr, unknown))}; "
                         f"known: {', '.join(kind.parameters)}")
    for name, p in kind.parameters.items():
        out[name] = p.check(values.get(name, p.default))
    for k, v in (labels or {}).items():
        if k in out:
            raise InputError(f"scenario label {k!r} clashes with a parameter")
        out[k] = v
    return out


@dataclass(frozen=True)
class PoseKey:
    """What decides a trial's geometry (hashable): the profiles, the pose fields of
    :meth:`PoseScenario.pose_kwargs` as ``(name, value)`` pairs and the truth's switches."""

    camera: str
    pattern: str
    pose: tuple
    truth: tuple

    @classmethod
    def of(cls, scenario: PoseScenario) -> "PoseKey":
        return cls(scenario.camera, scenario.pattern, tuple(scenario.pose_kwargs().items()), scenario.truth)
