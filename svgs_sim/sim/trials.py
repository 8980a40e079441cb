"""Trial kinds: what one trial of a study computes, registered by name.

A trial kind is a top-level (picklable) function ``run_trial(scenario: dict, seed: int) ->
dict`` plus a description of its inputs and outputs. Studies (campaign, sensitivity, range
sweeps) only build scenarios and hand them, with per-trial seeds (:mod:`svgs_sim.studies.seeding`),
to an executor (:mod:`svgs_sim.studies.execution`); they never call a renderer or solver themselves.
So the render-and-solve trial plugs in with :func:`register_trial_kind` and every study runs
on it unchanged.

Render once, expose many
    A kind may declare ``render_key(scenario) -> hashable``: trials with equal keys need the
    same expensive render (same geometry, camera, pattern, flash...), differing only in what
    happens after it (noise draw, exposure, centroiding, calibration used by the solver).
    The runner packs such trials into one task and calls ``run_group(scenarios, seeds)``,
    which renders once and exposes/solves each trial. ``run_group`` must return exactly the
    rows ``run_trial`` would (a trial's numbers never depend on its companions).

The built-in kind ``geometric`` projects the pattern through the camera at the scenario's
pose, adds seeded Gaussian centroid noise, optionally gives the solver a wrong calibration
(focal length, principal point, radial distortion), solves with
:func:`svgs_sim.svgs.solve_centroids` and records truth, estimate, errors and the Cramer-Rao bound.
Its "render" (the projection) is grouped the same way, so the mechanism is exercised today.
"""

from __future__ import annotations

import dataclasses
import importlib
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Callable, ClassVar, Hashable

import numpy as np

from svgs_sim.sim.metrics import ERR_KEYS, POS_ERR_NORM_M, ROT_ERR_DEG, error_columns, state_m_deg
from svgs_sim.base.errors import InputError
from svgs_sim.svgs.frames import STATE_KEYS
from svgs_sim.svgs.envelope import ATTITUDE_LIMITS_DEG
from svgs_sim.base.limits import RANGE_LIMIT_M, bounds
from svgs_sim.sim.target_pose import TargetPose

#: Modules that may register more trial kinds; imported when an unknown name is asked for
#: (a module that is not installed is skipped). The render-and-solve trial of the campaign,
#: the sensitivity study, the range sweep and the exposure study registers itself from
#: ``svgs_sim.sim.render_trial``. Studies run the trials with :func:`svgs_sim.studies.execution.run_task`.
KIND_MODULES = ("svgs_sim.sim.render_trial", "svgs_sim.sim.tof_trial")

#: Columns every study row has besides the scenario and the kind's outputs.
ID_COLUMNS = ("trial_id", "seed")
TIMING_COLUMNS = ("wall_s", "cpu_s")


def _number(x) -> str:
    """``x`` for a message: a whole number in full (a seed, samples per pixel), else ``:g``."""
    if x is None:
        return ""
    x = float(x)
    return str(int(x)) if x.is_integer() and abs(x) < 1e15 else f"{x:g}"


@dataclass(frozen=True)
class Parameter:
    """A scenario parameter a study may set or vary.

    Attributes
    ----------
    name : str
        Scenario key (units in the name).
    unit : str
    meaning : str
        One sentence for reports and ``--help``.
    default : float
    needs_render : bool
        True if changing it changes the rendered flux (geometry, optics, flash); False if
        it acts after the render (noise, exposure, detector, calibration used by the solver),
        so trials differing only in it can share one render.
    lower, upper : float or None
        Physical domain (inclusive unless ``*_open``).
    """

    name: str
    unit: str
    meaning: str
    default: float
    needs_render: bool
    lower: float | None = None
    upper: float | None = None
    lower_open: bool = False

    def domain(self) -> str:
        """The allowed values in words, with the unit (none for a dimensionless "1")."""
        unit = "" if self.unit in ("", "1") else f" {self.unit}"
        lo, hi = _number(self.lower), _number(self.upper)
        if self.lower is not None and self.upper is not None:
            if self.lower_open:
                return f"a value > {lo} and <= {hi}{unit}"
            return f"{lo} to {hi}{unit}"
        if self.lower is not None:
            return f"a value {'>' if self.lower_open else '>='} {lo}{unit}"
        if self.upper is not None:
            return f"a value <= {hi}{unit}"
        return f"a finite number{unit}"

    def check(self, value, what: str = "") -> float:
        """``float(value)`` if it lies in the domain, else :class:`InputError`."""
        label = what or self.name
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise InputError(f"{label}: expected {self.domain()}, got {value!r}") from None
        if not np.isfinite(v):
            raise InputError(f"{label}: expected {self.domain()}, got {value!r}")
        low_bad = self.lower is not None and (v < self.lower or (self.lower_open and v == self.lower))
        if low_bad or (self.upper is not None and v > self.upper):
            raise InputError(f"{label}: expected {self.domain()}, got {v:g} - {self.meaning}")
        return v


@dataclass(frozen=True)
class TrialKind:
    """A registered kind of trial.

    Attributes
    ----------
    name : str
    run_trial : callable
        ``run_trial(scenario: dict, seed: int) -> dict`` (top-level, picklable). The dict
        holds the kind's ``outputs``.
    outputs : tuple of str
        Output columns, in order.
    parameters : mapping of str -> Parameter
        Numeric scenario parameters (for validation and sensitivity studies).
    text_keys : tuple of str
        Non-numeric scenario keys (camera, pattern...).
    run_group : callable, optional
        ``run_group(scenarios, seeds) -> list[dict]`` for trials sharing one render key.
    render_key : callable, optional
        ``render_key(scenario) -> hashable``.
    warm_up : callable, optional
        Called once per worker process (JIT compilation, caches).
    description : str
    module : str
        Module that registers the kind; workers import it to find the kind.
    scenario_type : type, optional
        The kind's typed scenario (a :class:`TrialScenario` subclass): :func:`build_scenario`
        makes one; without it a scenario is a plain dict of row values.
    """

    name: str
    run_trial: Callable[[dict, int], dict]
    outputs: tuple
    parameters: Mapping[str, Parameter]
    text_keys: tuple = ("camera", "pattern")
    run_group: Callable | None = None
    render_key: Callable[[dict], Hashable] | None = None
    warm_up: Callable | None = None
    description: str = ""
    module: str = field(default="")
    scenario_type: type | None = None

    @property
    def ref(self) -> tuple[str, str]:
        return (self.module or self.run_trial.__module__, self.name)

    def columns(self, scenario_keys) -> list[str]:
        """All columns of a study of this kind whose scenarios have ``scenario_keys``."""
        clash = set(scenario_keys) & (set(self.outputs) | set(ID_COLUMNS) | set(TIMING_COLUMNS))
        if clash:
            raise ValueError(f"scenario keys {sorted(clash)} clash with output columns")
        return [*ID_COLUMNS, *scenario_keys, *self.outputs, *TIMING_COLUMNS]


_REGISTRY: dict[str, TrialKind] = {}


def register_trial_kind(kind: TrialKind) -> TrialKind:
    """Register (or replace) a trial kind under ``kind.name``."""
    if not kind.module:
        kind = TrialKind(**{**kind.__dict__, "module": kind.run_trial.__module__})
    _REGISTRY[kind.name] = kind
    return kind


def known_trial_kinds() -> list[str]:
    """Names of the registered trial kinds (the built-in ones of :data:`KIND_MODULES` included)."""
    _import_kind_modules()
    return sorted(_REGISTRY)


def _import_kind_modules() -> None:
    for m in KIND_MODULES:
        try:
            importlib.import_module(m)
        except ModuleNotFoundError as exc:
            if exc.name and (exc.name == m or m.startswith(exc.name + ".")):
                continue
            raise


def get_trial_kind(name: str) -> TrialKind:
    """The trial kind called ``name`` (:class:`InputError` listing the known ones)."""
    if name not in _REGISTRY and name not in known_trial_kinds():
        raise InputError(f"--trial-kind: unknown trial kind {name!r}; known: {', '.join(known_trial_kinds())}")
    return _REGISTRY[name]


# --------------------------------------------------------------------------- geometric trial
# Every numeric parameter of every kind has a physical lower and upper bound (a test walks the
# registry): the CLI's for the same quantity (svgs_sim.base.limits, one table), the sensor's envelope, or
# the parameter's own (a switch 0-1, an error a calibration could have).
GEOMETRIC_PARAMETERS = {
    p.name: p
    for p in (
        Parameter("range_m", "m", "distance from the camera to the target origin along the boresight", 10.0, True,
                  lower=0.0, upper=RANGE_LIMIT_M, lower_open=True),
        Parameter("target_x_m", "m", "lateral offset of the target origin from the boresight, camera right", 0.0, True,
                  **bounds("target_x_m")),
        Parameter("target_y_m", "m", "lateral offset of the target origin from the boresight, camera up", 0.0, True,
                  **bounds("target_y_m")),
        Parameter("roll_deg", "deg", "relative attitude, rotation about the target x axis (paper phi)", 0.0, True,
                  lower=-ATTITUDE_LIMITS_DEG["roll_deg"], upper=ATTITUDE_LIMITS_DEG["roll_deg"]),
        Parameter("pitch_deg", "deg", "relative attitude, rotation about the target y axis (paper theta)", 0.0, True,
                  lower=-ATTITUDE_LIMITS_DEG["pitch_deg"], upper=ATTITUDE_LIMITS_DEG["pitch_deg"]),
        Parameter("yaw_deg", "deg", "relative attitude, rotation about the target z axis (paper psi)", 0.0, True,
                  lower=-ATTITUDE_LIMITS_DEG["yaw_deg"], upper=ATTITUDE_LIMITS_DEG["yaw_deg"]),
        Parameter("sigma_px", "px", "1-sigma Gaussian centroid noise per image axis", 0.1, False,
                  **bounds("sigma_px")),
        Parameter("focal_error_frac", "1", "relative error of the focal length the solver uses (fx and fy scaled by 1 + e)",
                  0.0, False, **bounds("focal_error_frac")),
        Parameter("pp_error_u_px", "px", "error of the principal point cx the solver uses", 0.0, False,
                  **bounds("true_pp_offset_px")),
        Parameter("pp_error_v_px", "px", "error of the principal point cy the solver uses", 0.0, False,
                  **bounds("true_pp_offset_px")),
        Parameter("k1_error", "1", "error of the radial distortion k1 the solver uses (the lens has the profile's k1)",
                  0.0, False, **bounds("k1_error")),
        Parameter("merge_px", "px", "spots closer than this in the image merge into one (0: never)", 0.0, True,
                  **bounds("merge_px")),
        # the paper's test stand (svgs_sim.sim.stand): the gimbal turns the phone, the target stays still
        Parameter("stand", "1", "1: the angles turn the phone on the test stand's gimbal about its pivot, range_m is "
                  "the rail position (svgs_sim.sim.stand.TestStand); 0: they turn the target in front of the camera", 0.0, True,
                  lower=0.0, upper=1.0),
        Parameter("stage_m", "m", "the stand's translation stage along the rail, positive away from the target "
                  "(stand = 1 only)", 0.0, True, **bounds("stage_m")),
        Parameter("misalign_yaw_deg", "deg", "the phone's yaw in its holder on the stand (stand = 1 only)", 0.0, True,
                  lower=-10.0, upper=10.0),
        Parameter("misalign_pitch_deg", "deg", "the phone's pitch in its holder on the stand (stand = 1 only)", 0.0,
                  True, lower=-10.0, upper=10.0),
        Parameter("misalign_roll_deg", "deg", "the phone's roll in its holder on the stand (stand = 1 only)", 0.0, True,
                  lower=-10.0, upper=10.0),
        Parameter("truth_actual", "1", "0: errors against the pose the lab commanded (the stand's setting); 1: against "
                  "the pose with the phone's misalignment in its holder included", 0.0, False, lower=0.0,
                  upper=1.0),
        # the stand's errors at this setting (svgs_sim.sim.closed_loop.Scenario.stand_error; the lab's, svgs_sim.sim.lab)
        Parameter("stand_err_roll_deg", "deg", "the gimbal's actual roll minus the commanded (stand = 1 only)", 0.0,
                  True, lower=-5.0, upper=5.0),
        Parameter("stand_err_pitch_deg", "deg", "the gimbal's actual pitch minus the commanded (stand = 1 only)", 0.0,
                  True, lower=-5.0, upper=5.0),
        Parameter("stand_err_yaw_deg", "deg", "the gimbal's actual yaw minus the commanded (stand = 1 only)", 0.0,
                  True, lower=-5.0, upper=5.0),
        Parameter("stand_err_stage_m", "m", "the translation stage's actual position minus the commanded (stand = 1 "
                  "only)", 0.0, True, lower=-1.0, upper=1.0),
        Parameter("rail_err_m", "m", "the rail position's actual minus the recorded one (the range the lab measured "
                  "with its rangefinder; stand = 1 only)", 0.0, True, lower=-1.0, upper=1.0),
        Parameter("truth_stand", "1", "1: errors against the pose with the gimbal's and the stage's errors "
                  "included (they are then no error); 0: against the commanded setting", 0.0, False, lower=0.0,
                  upper=1.0),
        Parameter("truth_rail", "1", "1: errors against the pose with the rail position's error included; 0: "
                  "against the recorded range", 0.0, False, lower=0.0, upper=1.0),
    )
}

#: Scenario keys of the pose (the geometric kind's render key; the render kind adds its own).
POSE_KEYS = ("range_m", "target_x_m", "target_y_m", "roll_deg", "pitch_deg", "yaw_deg", "stand", "stage_m",
             "misalign_yaw_deg", "misalign_pitch_deg", "misalign_roll_deg", "stand_err_roll_deg",
             "stand_err_pitch_deg", "stand_err_yaw_deg", "stand_err_stage_m", "rail_err_m")
#: The truth's switches: which of the truth errors the errors are taken against.
TRUTH_KEYS = ("truth_actual", "truth_stand", "truth_rail")


# --------------------------------------------------------------------------- typed scenarios
#: Row columns of every study that are not scenario values (their ids, seeds, timings).
_NON_SCENARIO = (*ID_COLUMNS, *TIMING_COLUMNS)


@dataclass(frozen=True, eq=False)
class TrialScenario(Mapping):
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
        from svgs_sim.base.profiles import load_camera, load_pattern

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
            if k in cls._OPTIONAL and v == cls._OPTIONAL[k]:
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

    # ------------------------------------------------------------------ the row view (Mapping)
    def __getitem__(self, key):
        return self._row[key]

    def __iter__(self):
        return iter(self._row)

    def __len__(self):
        return len(self._row)

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
        from svgs_sim.sim.closed_loop import Scenario

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
        The gimbal pivot's rail position, m (``mount="stand"``, required); the row's
        ``range_m`` column holds it with ``stand = 1``.
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
    def _decode(cls, values: dict) -> dict:
        values = dict(values)
        stand = values.pop("stand")
        if stand not in (0.0, 1.0):
            raise InputError(f"stand: expected 0 (target turned) or 1 (phone on the stand's gimbal), got {stand!r}")
        distance = values.pop("range_m")
        out = super()._decode(values)
        out["mount"] = "stand" if stand == 1.0 else "target"
        out["rail_m" if stand == 1.0 else "range_m"] = float(distance)
        return out

    def _row_value(self, key: str) -> float:
        if key == "range_m":  # the row's range_m: the rail position on the stand
            return float(self.distance_m)
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


@dataclass(frozen=True, eq=False)
class GeometricScenario(PoseScenario):
    """A ``geometric`` trial's scenario (:data:`GEOMETRIC_PARAMETERS`; see
    :class:`TrialScenario` for the row view).

    Attributes
    ----------
    sigma_px : float
        1-sigma Gaussian centroid noise per image axis, px.
    merge_px : float
        Spots closer than this in the image merge (0: never).
    """

    sigma_px: float = 0.1
    merge_px: float = 0.0

    KIND: ClassVar[str] = "geometric"


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
    from svgs_sim.base.profiles import load_camera, load_pattern

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


def geometric_scenario(labels: dict | None = None, **values) -> GeometricScenario:
    """A complete, validated geometric scenario (see :func:`build_scenario`)."""
    return build_scenario(GEOMETRIC, values, labels)


GEOMETRIC_OUTPUTS = (
    "ok", "reason",
    *(f"true_{k}" for k in STATE_KEYS),
    *(f"est_{k}" for k in STATE_KEYS),
    *ERR_KEYS,
    POS_ERR_NORM_M, ROT_ERR_DEG, "residual_rms_px", "min_separation_px",
    *(f"crlb_{k}" for k in STATE_KEYS),
)


def _geometric_render(scenario: GeometricScenario):
    """The geometric "render": the pattern's true image points through the true camera.

    Returns
    -------
    uv_px : ndarray, shape (n, 2)
    depth_ok : bool
        All points in front of the camera.
    state_true : ndarray, shape (6,)
    """
    from svgs_sim.svgs.frames import pose_to_state
    from svgs_sim.base.profiles import load_camera, load_pattern

    cam, pat = load_camera(scenario.camera), load_pattern(scenario.pattern)
    (R, t), (R_truth, t_truth) = scenario.poses()
    p_cam = pat.points_m @ R.T + t
    depth_ok = bool(np.all(p_cam[:, 2] > 0))
    uv = cam.project(p_cam)
    return uv, depth_ok, pose_to_state(R_truth, t_truth)


def _geometric_expose_solve(scenario: GeometricScenario, seed: int, rendered) -> dict:
    from svgs_sim.base.profiles import load_camera, load_pattern
    from svgs_sim.svgs.solver import solve_centroids

    uv_true, depth_ok, state_true = rendered
    cam, pat = load_camera(scenario.camera), load_pattern(scenario.pattern)
    rng = np.random.default_rng(seed)
    uv = uv_true + scenario.sigma_px * rng.standard_normal(uv_true.shape)
    out = {k: None for k in GEOMETRIC_OUTPUTS}
    out.update({f"true_{k}": float(v) for k, v in zip(STATE_KEYS, state_m_deg(state_true))})
    d = np.linalg.norm(uv_true[:, None] - uv_true[None], axis=-1) + np.eye(len(uv_true)) * 1e12
    out["min_separation_px"] = float(d.min())
    reason = None
    if not depth_ok or not np.all(cam.in_image(uv_true)):
        reason = "too_few_blobs"  # a target outside the image: the detector sees fewer than four spots
    elif scenario.merge_px > 0 and d.min() < scenario.merge_px:
        reason = "merged_spots"
    if reason is None:
        solver_cam = camera_with_calibration_errors(cam, scenario)
        try:
            sol = solve_centroids(uv, solver_cam, pat, sigma_px=1.0)
        except InputError:  # a degenerate image (e.g. all points on one line)
            sol = None
            reason = "degenerate"
        if sol is not None and not sol:
            reason = sol.reason
    out["ok"] = reason is None
    out["reason"] = reason
    if reason is None:
        out.update(estimate_outputs(sol, state_true, crlb_scale=scenario.sigma_px))
    return out


def estimate_outputs(sol, state_true, crlb_scale: float = 1.0) -> dict:
    """The ``est_*``, ``err_*``, ``crlb_*``, ``pos_err_norm_m``, ``rot_err_deg`` and
    ``residual_rms_px`` outputs of a solved trial (errors from :mod:`svgs_sim.sim.metrics`).

    Parameters
    ----------
    sol : svgs.Solution
    state_true : ndarray, shape (6,)
        The true paper state (m, rad).
    crlb_scale : float
        Multiplies the solution's 1-sigma bound (its covariance is for ``sol.sigma_px``).
    """
    crlb = state_m_deg(np.sqrt(np.diag(sol.covariance)) * crlb_scale)
    out = {f"est_{k}": float(v) for k, v in zip(STATE_KEYS, state_m_deg(sol.state))}
    out.update(error_columns(sol.state, state_true, R_cam_target_est=sol.R_cam_target))
    out.update({f"crlb_{k}": float(v) for k, v in zip(STATE_KEYS, crlb)})
    out["residual_rms_px"] = float(sol.residual_rms_px)
    return out


def geometric_trial(scenario: GeometricScenario | Mapping, seed: int) -> dict:
    """One geometric trial: project, add centroid noise, solve with the solver's calibration.

    Parameters
    ----------
    scenario : GeometricScenario or mapping
        See :func:`geometric_scenario` (camera, pattern, pose, ``sigma_px``, calibration
        errors, ``merge_px``); a mapping of row values is read with
        :meth:`TrialScenario.from_row`.
    seed : int
        Seeds the centroid noise.

    Returns
    -------
    dict
        :data:`GEOMETRIC_OUTPUTS`: ``ok``, ``reason`` (a :data:`svgs_sim.svgs.result.REASONS` code or
        None), ``true_*``/``est_*``/``err_*`` for x, y, z (m; the camera's perspective centre in
        the target frame) and roll, pitch, yaw (deg; paper angles, errors wrapped to
        [-180, 180)), ``pos_err_norm_m`` (norm of the position error), ``rot_err_deg``
        (rotation angle between solved and true attitude; see :mod:`svgs_sim.sim.metrics`), ``residual_rms_px``, ``min_separation_px`` (closest pair of true
        image points) and ``crlb_*`` (Cramer-Rao 1-sigma for ``sigma_px``, at the estimate).
    """
    scenario = GeometricScenario.from_row(scenario)
    return _geometric_expose_solve(scenario, seed, _geometric_render(scenario))


def geometric_group(scenarios: list, seeds: list) -> list[dict]:
    """Trials sharing one projection (same :func:`geometric_render_key`): project once."""
    scenarios = [GeometricScenario.from_row(s) for s in scenarios]
    rendered = _geometric_render(scenarios[0])
    return [_geometric_expose_solve(s, seed, rendered) for s, seed in zip(scenarios, seeds)]


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


def geometric_render_key(scenario) -> PoseKey:
    """What decides the geometric "render": camera, pattern, pose (and the truth it is judged by)."""
    return PoseKey.of(GeometricScenario.from_row(scenario))


def geometric_warm_up() -> None:
    """Load the compiled solver (numba, cached on disk after the first compilation)."""
    from svgs_sim.svgs.frames import pose_from_scenario
    from svgs_sim.base.profiles import Camera, load_pattern
    from svgs_sim.svgs.solver import solve_centroids

    cam = Camera(name="warm-up", width=1000, height=1000, fx=1000.0, fy=1000.0, cx=499.5, cy=499.5)
    pat = load_pattern("svgs-3u")
    R, t = pose_from_scenario(5.0, 0.0, 0.0, 5.0, -5.0, 10.0)
    solve_centroids(cam.project_target(pat.points_m, R, t), cam, pat)


GEOMETRIC = register_trial_kind(TrialKind(
    name="geometric",
    run_trial=geometric_trial,
    outputs=GEOMETRIC_OUTPUTS,
    parameters=GEOMETRIC_PARAMETERS,
    run_group=geometric_group,
    render_key=geometric_render_key,
    warm_up=geometric_warm_up,
    description="pattern projected through the camera, Gaussian centroid noise, solver with a (possibly wrong) calibration",
    scenario_type=GeometricScenario,
))
