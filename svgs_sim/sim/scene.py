"""The scene around the target - what lights it and what lies behind it - declared once.

Every SVGS scenario holds one frozen :class:`Scene`: the closed loop's
:class:`svgs_sim.sim.closed_loop.Scenario`, the render trial's
:class:`svgs_sim.sim.render_trial.RenderScenario` (and so every campaign, sensitivity study and
range sweep) and the range sweep's configuration. Each field is declared here once, as a
:func:`quantity` with its unit, meaning, domain and default; the rest of the house derives
from that declaration:

- the render trial's row parameters (:func:`scene_parameters`; a sensitivity study may vary
  each, a results store holds each in a column of its own),
- the CLI options of the commands that render a scene (:func:`add_scene_options`,
  :func:`scene_from_args`), their bounds and their help,
- the JSON record of a scenario (:meth:`Scene.to_json`, flat in ``truth.json``),
- the render cache's key (a Scene is hashable: equal scenes share one render).

So a new scene parameter is one field here and the code that uses its value (see
``docs/architecture.md``). Today the scene is the paper's lab (:mod:`svgs_sim.sim.lab`): a grey
backdrop behind the target and the room's light; the on-orbit issue adds the sun, the Earth and
the target's body.

>>> from svgs_sim.sim.scene import Scene
>>> Scene().backdrop_distance_m            # the lab's (assets/labs/msfc-frl.toml)
3.0
>>> Scene(backdrop_distance_m=None).row_values()["backdrop_distance_m"]   # the results row's code for None
0.0
>>> Scene(backdrop_distance_m=-1)
Traceback (most recent call last):
...
svgs_sim.base.errors.InputError: backdrop_distance_m: expected > 0 and <= 1000 m (or None for none), got -1 - grey backdrop behind the target
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from svgs_sim.base.errors import InputError, number_items
from svgs_sim.base.limits import INPUT_BOUNDS
from svgs_sim.render.sun import sun_direction_target
from svgs_sim.render.earth import in_eclipse
from svgs_sim.sim.lab import load_lab

#: The paper's lab (:mod:`svgs_sim.sim.lab`, ``assets/labs/msfc-frl.toml``): a matt grey backdrop
#: 3 m behind the target (ASSUMPTION) and a dimly lit room, its ambient radiance fitted to the
#: Amaze 4G's merging range (``assets/labs/fitted/msfc-frl.toml``). The defaults of :class:`Scene`.
LAB = load_lab()


@dataclass(frozen=True)
class Quantity:
    """The declaration of one scene parameter (the metadata of a :class:`Scene` field).

    Attributes
    ----------
    unit : str
        ``"1"`` for a dimensionless number.
    meaning : str
        One sentence for reports, ``--help`` and error messages.
    lower, upper : float or None
        The physical domain (inclusive unless ``lower_open``).
    lower_open : bool
    none_means : str or None
        What None means (the field may then be None), e.g. ``"no backdrop"``.
    row_none : float or None
        How a results row and a CLI option write None (with ``none_means``).
    trial : bool
        A parameter of the render trial (a row column, varied by a sensitivity study) and a CLI
        option of the commands that render a scene.
    flag : str or None
        The CLI option (default ``--`` and the field's name with dashes).
    help : str or None
        The CLI option's help (default the meaning, the unit and the default).
    choices : tuple of str
        A choice, not a quantity: the words it takes (the field holds the word; a results row
        holds its index in ``choices``, the first being the default's code 0).
    component : int or None
        One component of a CLI option that several quantities share (the same ``flag``, given
        as ``A,B``): this quantity's place in it.
    option : bool
        Whether :func:`add_scene_options` makes its CLI option (False: the commands take it their
        own way, as ``--body``, which also takes a mesh file where a command can render one).
    """

    unit: str
    meaning: str
    lower: float | None = None
    upper: float | None = None
    lower_open: bool = False
    none_means: str | None = None
    row_none: float | None = None
    trial: bool = True
    flag: str | None = None
    help: str | None = None
    choices: tuple = ()
    component: int | None = None
    option: bool = True


def quantity(default, **declaration) -> Any:
    """A :class:`Scene` field: its ``default`` and its :class:`Quantity` (keyword arguments)."""
    return field(default=default, metadata={"quantity": Quantity(**declaration)})


def _domain(q: Quantity) -> str:
    if q.choices:
        return "one of " + ", ".join(repr(c) for c in q.choices)
    unit = "" if q.unit in ("", "1") else f" {q.unit}"
    if q.lower is not None and q.upper is not None:
        lo = f"> {q.lower:g} and <= {q.upper:g}" if q.lower_open else f"{q.lower:g} to {q.upper:g}"
        out = f"{lo}{unit}"
    elif q.lower is not None:
        out = f"{'>' if q.lower_open else '>='} {q.lower:g}{unit}"
    else:
        out = f"a finite number{unit}"
    return out + (f" (or None for {q.none_means})" if q.none_means else "")


#: The environments a scene may be in (:attr:`Scene.environment`): the first is the default.
ENVIRONMENTS = ("lab", "orbit")
#: The shipped target bodies a trial may hold (:attr:`Scene.body`; :mod:`svgs_sim.render.cubesat`):
#: the first is the default.
BODIES = ("plate", "3u", "none")


@dataclass(frozen=True)
class Scene:
    """The scene around the target (frozen, hashable; the defaults are the paper's lab).

    Attributes
    ----------
    environment : {"lab", "orbit"}
        ``"lab"``: the paper's (the backdrop and the room's light below). ``"orbit"``: black space;
        the backdrop is None and the ambient radiance 0 (left at the lab's defaults, they are set
        so; any other value is refused), the flash still lights the target.
    sun_azimuth_deg, sun_elevation_deg : float or None
        The direction toward the sun in the target frame, deg (orbit only; both None: no sun, the
        target in eclipse): azimuth from +x toward +y, elevation from the pattern plane toward +z
        (:func:`svgs_sim.render.sun.sun_direction_target`).
    earth_azimuth_deg, earth_elevation_deg : float or None
        The direction toward the Earth's centre in the target frame, deg (orbit only; both None: no
        Earth). The Earth: :mod:`svgs_sim.render.earth`.
    altitude_km : float
        The target's altitude above the Earth, km (with the Earth).
    earth_albedo : float
        The Earth's Lambertian albedo (with the Earth).
    body : {"plate", "3u", "none"}
        The target's body: the lab's breadboard (the default), the shipped 3U cubesat or none
        (:mod:`svgs_sim.render.cubesat`). A mesh file is a render option of the commands that
        render single scenes and approaches (:class:`svgs_sim.sim.closed_loop.RenderOptions`).
    backdrop_distance_m : float or None
        A grey Lambertian backdrop this far behind the target origin, m (None: no backdrop).
    backdrop_reflectance : float
        The backdrop's Lambertian reflectance, 0-1 (not a trial parameter: the lab's).
    ambient_radiance_w_m2_sr : float
        Uniform scene radiance from the room's lights in the camera's band, W m^-2 sr^-1.
    """

    environment: str = quantity(
        "lab", unit="1", choices=ENVIRONMENTS,
        meaning="what surrounds the target: 'lab' (the paper's: a grey backdrop and the room's light), 'orbit' "
        "(black space: no backdrop, no room light; the flash still lights the target)",
        help="what surrounds the target: 'lab' (the paper's, the default: a grey backdrop, --backdrop-m, and the "
        "room's light, --ambient) or 'orbit' (black space: no backdrop and no room light; the flash still on)")
    sun_azimuth_deg: float | None = quantity(
        None, unit="deg", meaning="azimuth of the direction toward the sun in the target frame, from +x toward +y",
        lower=-360.0, upper=360.0, none_means="no sun (eclipse, or the lab)", row_none=None, flag="--sun-deg",
        component=0,
        help="orbit only: the direction toward the sun in the target frame, deg: azimuth from +x toward +y, "
        "elevation from the pattern plane toward +z, the face normal (toward a head-on camera); default: none, the "
        "target in eclipse. "
        "Negative values: --sun-deg=-30,10")
    sun_elevation_deg: float | None = quantity(
        None, unit="deg", meaning="elevation of the direction toward the sun from the pattern plane toward +z",
        lower=-90.0, upper=90.0, none_means="no sun (eclipse, or the lab)", row_none=None, flag="--sun-deg",
        component=1)
    earth_azimuth_deg: float | None = quantity(
        None, unit="deg", meaning="azimuth of the direction toward the Earth's centre in the target frame, from +x "
        "toward +y", lower=-360.0, upper=360.0, none_means="no Earth", row_none=None, flag="--earth-deg", component=0,
        help="orbit only: the direction toward the Earth's centre in the target frame, deg (azimuth, elevation as "
        "--sun-deg); default: none, no Earth. The Earth is a Lambertian sphere lit by the sun (its shine lights the "
        "target); the target is in eclipse when the Earth hides the sun. Negative values: --earth-deg=0,-60")
    earth_elevation_deg: float | None = quantity(
        None, unit="deg", meaning="elevation of the direction toward the Earth's centre from the pattern plane toward +z",
        lower=-90.0, upper=90.0, none_means="no Earth", row_none=None, flag="--earth-deg", component=1)
    altitude_km: float = quantity(
        400.0, unit="km", meaning="the target's altitude above the Earth (its apparent size and the eclipse)",
        lower=100.0, upper=100000.0, flag="--altitude-km",
        help="orbit only, with --earth-deg: the target's altitude above the Earth, km (default 400)")
    earth_albedo: float = quantity(
        0.3, unit="1", meaning="the Earth's Lambertian albedo (0.3 the Bond albedo; 0.05 ocean, 0.8 a cloud deck)",
        lower=0.0, upper=1.0, flag="--earth-albedo",
        help="orbit only, with --earth-deg: the Earth's Lambertian albedo (default 0.3, its Bond albedo; 0.05 open "
        "ocean, 0.8 a bright cloud deck)")
    body: str = quantity(
        "plate", unit="1", choices=BODIES, option=False, flag="--body",
        meaning="the target's body: 'plate' (the lab's breadboard behind the pattern), '3u' (the shipped 3U cubesat) "
        "or 'none'")
    backdrop_distance_m: float | None = quantity(
        LAB.backdrop_distance_m, unit="m", meaning="grey backdrop behind the target",
        lower=0.0, upper=INPUT_BOUNDS["backdrop_m"][1], lower_open=True, none_means="none", row_none=0.0,
        flag="--backdrop-m", help="distance of a grey backdrop behind the target (m; default 3; 0 = none)")
    backdrop_reflectance: float = quantity(
        LAB.backdrop_reflectance, unit="1", meaning="the backdrop's Lambertian reflectance", lower=0.0, upper=1.0,
        trial=False)
    ambient_radiance_w_m2_sr: float = quantity(
        LAB.ambient_radiance_w_m2_sr, unit="W m^-2 sr^-1",
        meaning="uniform ambient scene radiance from room lights, in band (default: the lab's, svgs_sim.sim.lab)",
        lower=0.0, upper=INPUT_BOUNDS["ambient"][1], flag="--ambient",
        help="ambient scene radiance from room lights, W m^-2 sr^-1 in band (default: the lab's, 0.028, fitted in "
        "assets/labs/fitted/msfc-frl.toml; 0: lights off)")

    def __post_init__(self):
        for f in dataclasses.fields(self):
            q = f.metadata["quantity"]
            v = getattr(self, f.name)
            if v is None and q.none_means:
                continue
            object.__setattr__(self, f.name, check_quantity(f.name, q, v))
        if self.environment == "orbit":
            self._no_lab()
        sun = (self.sun_azimuth_deg, self.sun_elevation_deg)
        if (sun[0] is None) != (sun[1] is None):
            raise InputError("sun_azimuth_deg, sun_elevation_deg: give both (--sun-deg AZ,EL) or neither (eclipse)")
        if sun[0] is not None and self.environment != "orbit":
            raise InputError("--sun-deg: the sun lights the target on orbit only (give --environment orbit)")
        earth = (self.earth_azimuth_deg, self.earth_elevation_deg)
        if (earth[0] is None) != (earth[1] is None):
            raise InputError("earth_azimuth_deg, earth_elevation_deg: give both (--earth-deg AZ,EL) or neither")
        if earth[0] is not None and self.environment != "orbit":
            raise InputError("--earth-deg: the Earth is in the scene on orbit only (give --environment orbit)")
        if earth[0] is None and (self.altitude_km != 400.0 or self.earth_albedo != 0.3):
            raise InputError("--altitude-km, --earth-albedo: the Earth's; give them with --earth-deg AZ,EL")

    @property
    def sun_direction_target(self) -> tuple | None:
        """Unit vector toward the sun in the target frame (None: no sun)."""
        if self.sun_azimuth_deg is None:
            return None
        return tuple(float(x) for x in sun_direction_target(self.sun_azimuth_deg, self.sun_elevation_deg))

    @property
    def earth_direction_target(self) -> tuple | None:
        """Unit vector toward the Earth's centre in the target frame (None: no Earth)."""
        if self.earth_azimuth_deg is None:
            return None
        return tuple(float(x) for x in sun_direction_target(self.earth_azimuth_deg, self.earth_elevation_deg))

    def natural_light(self) -> dict:
        """The renderer's natural-light fields of this scene (:class:`svgs_sim.render.geometry.SceneOptions`:
        ``sun_direction_target``, ``earth_direction_target``, ``altitude_m``, ``earth_albedo``;
        :meth:`svgs_sim.render.api.Renderer.set_natural_light`). The lab's gives the defaults."""
        return {"sun_direction_target": self.sun_direction_target, "earth_direction_target": self.earth_direction_target,
                "altitude_m": 1e3 * self.altitude_km, "earth_albedo": self.earth_albedo}

    @property
    def eclipsed(self) -> bool:
        """Whether the Earth hides the sun from the target (:func:`svgs_sim.render.earth.in_eclipse`)."""
        return (self.sun_direction_target is not None and self.earth_direction_target is not None
                and in_eclipse(self.sun_direction_target, self.earth_direction_target, 1e3 * self.altitude_km))

    def _no_lab(self) -> None:
        """In orbit: no backdrop and no room light (the lab's defaults read so; other values are refused)."""
        lab = {"backdrop_distance_m": (None, LAB.backdrop_distance_m),
               "ambient_radiance_w_m2_sr": (0.0, LAB.ambient_radiance_w_m2_sr)}
        for name, (none, lab_default) in lab.items():
            v = getattr(self, name)
            if v not in (none, lab_default):
                q = self.quantities()[name]
                raise InputError(f"{name}: the environment 'orbit' has no {q.meaning} (got {v!r}); give "
                                 f"{_flag(name, q)} only with --environment lab")
            object.__setattr__(self, name, none)

    @staticmethod
    def quantities() -> dict:
        """Field name -> :class:`Quantity`, in declaration order."""
        return {f.name: f.metadata["quantity"] for f in dataclasses.fields(Scene)}

    def replace(self, **changes) -> "Scene":
        """A copy with fields changed (checked again)."""
        return dataclasses.replace(self, **changes)

    def to_json(self) -> dict:
        """The fields as JSON values (None as null)."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}

    def row_values(self) -> dict:
        """The trial parameters as a results row writes them (None as the quantity's ``row_none``)."""
        out = {}
        for name, q in self.quantities().items():
            if q.trial:
                v = getattr(self, name)
                out[name] = (float(q.choices.index(v)) if q.choices else None if v is None and q.row_none is None
                             else float(q.row_none) if v is None else float(v))
        return out

    @classmethod
    def from_row(cls, values: dict) -> "Scene":
        """The scene of a row's values (missing trial parameters at their defaults; ``row_none``
        read as None)."""
        kw = {}
        for name, q in cls.quantities().items():
            if q.trial and name in values:
                v = values[name]
                if q.choices:
                    kw[name] = _choice_of_code(name, q, v)
                    continue
                if v is None or (q.row_none is None and isinstance(v, float) and np.isnan(v)):
                    kw[name] = None  # an empty cell: none (a quantity whose row writes none as empty)
                    continue
                v = float(v)
                kw[name] = None if (q.none_means and v == q.row_none) else v
        return cls(**kw)


def _choice_of_code(name: str, q: Quantity, value) -> str:
    """The word of a results row's code (its index in the choices; a word is taken as it is)."""
    if isinstance(value, str):
        return value
    v = float(value)
    if v != int(v) or not 0 <= v < len(q.choices):
        raise InputError(f"{name}: expected a code 0 to {len(q.choices) - 1} ({_domain(q)}), got {value!r}")
    return q.choices[int(v)]


def check_quantity(name: str, q: Quantity, value):
    """``float(value)`` within the quantity's domain (a choice: the word, one of its words), else
    :class:`InputError` naming ``name``."""
    if q.choices:
        word = value.strip().lower() if isinstance(value, str) else value
        if word not in q.choices:
            raise InputError(f"{name}: expected {_domain(q)}, got {value!r} - {q.meaning}")
        return word
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name}: expected {_domain(q)}, got {value!r}") from None
    bad = (not np.isfinite(v) or (q.lower is not None and (v < q.lower or (q.lower_open and v == q.lower)))
           or (q.upper is not None and v > q.upper))
    if bad:
        raise InputError(f"{name}: expected {_domain(q)}, got {value!r} - {q.meaning}")
    return v


def scene_parameters() -> dict:
    """The render trial's row parameters of the scene (:class:`svgs_sim.sim.trials.Parameter`,
    name -> parameter, in declaration order): every :class:`Quantity` with ``trial``. A row writes
    None as ``row_none``, which the parameter's domain then includes."""
    # not at module level: a cycle (the trial kinds' scenarios hold the closed loop's Scenario, which holds a Scene)
    from svgs_sim.sim.trials import Code, Parameter

    default = Scene()
    out = {}
    for name, q in Scene.quantities().items():
        if not q.trial:
            continue
        if q.choices:  # a choice: held fixed by a study (its words), never varied
            out[name] = Parameter(name, "1", q.meaning, 0.0, True,
                                  codes=tuple(Code(float(i), w, f"the {w} {name}") for i, w in enumerate(q.choices)))
            continue
        d = getattr(default, name)
        lower, lower_open = q.lower, q.lower_open
        meaning = q.meaning
        if q.none_means and q.row_none is None:  # none: an empty cell
            out[name] = Parameter(name, q.unit, f"{meaning} (empty: {q.none_means})", d, True, lower=lower,
                                  upper=q.upper, lower_open=lower_open, optional=True)
            continue
        if q.none_means:
            meaning = f"{meaning} ({q.row_none:g}: {q.none_means})"
            if q.row_none == q.lower:
                lower_open = False
        out[name] = Parameter(name, q.unit, meaning, float(q.row_none if d is None else d), True, lower=lower,
                              upper=q.upper, lower_open=lower_open)
    return out


def _dest(flag: str) -> str:
    return flag.lstrip("-").replace("-", "_")


def _flag(name: str, q: Quantity) -> str:
    return q.flag or "--" + name.replace("_", "-")


def add_scene_options(parser) -> None:
    """The scene's CLI options (one per trial :class:`Quantity`; default: the scene's). Each option
    carries its quantity's domain as ``action.bounds`` (``(low, high, unit)``, checked by
    :func:`svgs_sim.cli.validate.check_args` before any work)."""
    default = Scene()
    for name, q in Scene.quantities().items():
        if not q.trial or not q.option or (q.component or 0) > 0:  # a shared option: added with its first component
            continue
        text = q.help
        if q.component is not None:
            parts = [n for n, x in Scene.quantities().items() if x.flag == q.flag]
            parser.add_argument(_flag(name, q), default=None, metavar=",".join(p.split("_")[1][:2].upper()
                                                                               for p in parts), help=text)
            continue
        if q.choices:
            parser.add_argument(_flag(name, q), choices=q.choices, default=None,
                                help=text or f"{q.meaning} (default {getattr(default, name)})")
            continue
        if text is None:
            d = getattr(default, name)
            unit = "" if q.unit in ("", "1") else f", {q.unit}"
            text = f"{q.meaning}{unit} (default {d if d is None else f'{d:g}'}" + (
                f"; {q.row_none:g}: {q.none_means})" if q.none_means else ")")
        action = parser.add_argument(_flag(name, q), type=float, default=None, help=text)
        # the option's physical bounds, read by svgs_sim.cli.validate.check_args before any work
        action.bounds = (-np.inf if q.lower is None else q.lower, np.inf if q.upper is None else q.upper,
                         "" if q.unit == "1" else q.unit)


def scene_from_args(args, base: Scene | None = None) -> Scene:
    """The :class:`Scene` of the options of :func:`add_scene_options` (an option not given keeps
    ``base``'s value, default the scene's own; an optional quantity's ``row_none`` is None)."""
    base = base or Scene()
    kw = {}
    for name, q in Scene.quantities().items():
        if not q.trial or not q.option:
            continue
        v = getattr(args, _dest(_flag(name, q)), None)
        if v is not None and q.component is not None:
            v = _component(v, q)
        if v is not None:
            kw[name] = None if (q.none_means and v == q.row_none) else v
    if kw.get("environment", base.environment) == "orbit":
        lab_given = [_flag(n, Scene.quantities()[n]) for n in ("backdrop_distance_m", "ambient_radiance_w_m2_sr")
                     if n in kw]
        if lab_given:
            raise InputError(f"{', '.join(lab_given)}: the lab's; --environment orbit has no backdrop and no room "
                             "light (give them only with --environment lab)")
    return base.replace(**kw) if kw else base


def _component(text, q: Quantity) -> float:
    """Component ``q.component`` of a shared option's ``A,B`` text (InputError naming the option)."""
    parts = [n for n, x in Scene.quantities().items() if x.flag == q.flag]
    try:
        vals = number_items(text, q.flag)
    except InputError:
        vals = []
    if len(vals) != len(parts) or not all(np.isfinite(vals)):
        raise InputError(f"{q.flag}: expected {len(parts)} numbers separated by a comma "
                         f"({', '.join(parts)}), got {text!r}")
    return vals[q.component]


def scene_option_words(args) -> list[str]:
    """The scene options given in ``args`` as command-line words (``["--environment", "orbit"]``
    ...), for a report's command that rebuilds the same study."""
    out = []
    for name, q in Scene.quantities().items():
        if not q.trial or not q.option or (q.component or 0) > 0:
            continue
        v = getattr(args, _dest(_flag(name, q)), None)
        if v is None:
            continue
        if q.component is not None:  # one word, A,B after "=" (a negative A is not taken for an option)
            out.append(f"{_flag(name, q)}={v}")
        else:
            out += [_flag(name, q), v if isinstance(v, str) else repr(float(v))]
    return out
