"""The typed, immutable parts of a camera profile and a target pattern.

A profile file is a set of TOML tables; :mod:`svgs_sim.base.profiles` parses and checks it once
(:mod:`svgs_sim.base.profile_schema`) and hands every other module frozen objects, never the
tables. Each checked table of the schema becomes one frozen dataclass here, generated from the
schema's own key list, so a key is declared once (its name carries its unit, ``pixel_pitch_m``,
``full_well_e``, ``modulation_frequency_hz``):

- :class:`Sensor` (``[sensor]``), :class:`Glare`, :class:`Exposure`, :class:`Cfa`, :class:`Isp`:
  the phone camera model (the renderer's optics read the sensor's pixel pitch);
- :class:`Optics` (``[optics]``): the renderer, the phone and the ToF camera models;
- :class:`Flash` (``[flash]``): the SVGS and board renderers, the lab geometry;
- :class:`Tof`, :class:`Noise`, :class:`Illumination` (``[tof]``, ``[noise]``,
  ``[illumination]``): the ToF camera model, renderer and pipeline;
- a pattern's :class:`Reflector` (``[reflector]``: the SVGS renderer's corner cubes) and
  :class:`Plate`, :class:`Marker` (``[plate]``, ``[marker]``: the ToF target).

A field is ``None`` where the profile does not give the key: the model that reads it applies
its own documented default (:data:`svgs_sim.base.profile_schema.PHONE_DEFAULTS` and the
models' dataclasses). ``bool(part)`` is whether the profile has the table at all.

The records a profile carries that nothing computes with are typed too: :class:`FittedValue`
(one entry of the ``[fitted]`` record an overlay leaves) and :class:`TargetSpec` (one
``[[target]]`` of a pattern with its optional diameter and standoff).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import ClassVar

from .errors import InputError, ProfileError
from .profile_schema import (
    PHONE_TABLES,
    REFLECTOR_KEYS,
    RENDER_TABLES,
    TOF_CAMERA_TABLES,
    TOF_PATTERN_TABLES,
    AutoOr,
    Choice,
    Num,
    Text,
    check_table,
)


@dataclass(frozen=True)
class ProfilePart:
    """One checked table of a profile: a frozen object, a field per key of the schema.

    Subclasses are generated from :mod:`svgs_sim.base.profile_schema` (:func:`_part`); do not
    write one by hand.
    """

    #: The table's name in the profile file.
    TABLE: ClassVar[str] = ""

    @classmethod
    def from_table(cls, table, where: str = ""):
        """The part of a TOML table (None or absent: every field None).

        Parameters
        ----------
        table : dict or None
            The table as read from the file.
        where : str
            The file, for the message.

        Raises
        ------
        ProfileError
            A value the schema refuses (naming ``[table] key``, the value and its range).
        """
        if table is None:
            return cls()
        if not isinstance(table, dict):
            raise ProfileError(f"{where + ': ' if where else ''}[{cls.TABLE}] must be a table, got {table!r}")
        try:
            if cls.TABLE == "reflector":
                values = check_table("reflector", table, REFLECTOR_KEYS)
            else:
                values = check_table(cls.TABLE, table)
        except ProfileError:
            raise
        except InputError as exc:
            raise ProfileError(f"{where + ': ' if where else ''}{exc}") from None
        return cls(**values)

    def __bool__(self) -> bool:
        return any(getattr(self, f.name) is not None for f in dataclasses.fields(self))

    def to_dict(self) -> dict:
        """The keys the profile gives, as a TOML table (tuples as lists)."""
        return {f.name: _plain(getattr(self, f.name)) for f in dataclasses.fields(self)
                if getattr(self, f.name) is not None}

    def given(self, key: str, default):
        """``self.<key>`` if the profile gives it, else ``default`` (the reading model's own)."""
        v = getattr(self, key)
        return default if v is None else v


def _plain(v):
    if isinstance(v, tuple):
        return [_plain(x) for x in v]
    return v


def _annotation(spec) -> str:
    if isinstance(spec, Num):
        return "int | None" if spec.integer else "float | None"
    if isinstance(spec, (Choice, Text)):
        return "str | None"
    if isinstance(spec, AutoOr):
        return "float | str | None"
    return "tuple | None"


def _part(class_name: str, table: str, specs: dict, what: str) -> type:
    """A frozen dataclass with one ``None``-defaulted field per key of ``specs``."""
    fields = [(key, _annotation(spec), dataclasses.field(default=None)) for key, spec in specs.items()]
    doc = [f"The profile's ``[{table}]`` table: {what}.", "", "Attributes", "----------"]
    for key, spec in specs.items():
        doc += [f"{key} : {_annotation(spec).replace(' | ', ' or ')}", f"    {spec.describe()}."]
    cls = dataclasses.make_dataclass(class_name, fields, bases=(ProfilePart,), frozen=True,
                                     namespace={"TABLE": table, "__doc__": "\n".join(doc)})
    cls.__module__ = __name__
    return cls


Sensor = _part("Sensor", "sensor", PHONE_TABLES["sensor"], "the image sensor (pixels, charge, noise, ADC)")
Glare = _part("Glare", "glare", PHONE_TABLES["glare"], "the lens' stray light (aberration, veiling glare, wings, ghosts)")
Exposure = _part("Exposure", "exposure", PHONE_TABLES["exposure"], "the auto-exposure or the manual exposure")
Cfa = _part("Cfa", "cfa", PHONE_TABLES["cfa"], "the colour filter array and demosaic")
Isp = _part("Isp", "isp", PHONE_TABLES["isp"], "the phone's image signal processor")
Optics = _part("Optics", "optics", RENDER_TABLES["optics"], "the lens")
Flash = _part("Flash", "flash", RENDER_TABLES["flash"], "the phone's LED flash")
Tof = _part("Tof", "tof", TOF_CAMERA_TABLES["tof"], "the ToF pixel's demodulation, ADC and exposure")
Noise = _part("Noise", "noise", TOF_CAMERA_TABLES["noise"], "the ToF pixel's noise and ambient light")
Illumination = _part("Illumination", "illumination", TOF_CAMERA_TABLES["illumination"],
                     "the ToF camera's modulated emitters")
Plate = _part("Plate", "plate", TOF_PATTERN_TABLES["plate"], "the ToF target's plate")
Marker = _part("Marker", "marker", TOF_PATTERN_TABLES["marker"], "the ToF target's markers")
Reflector = _part("Reflector", "reflector", REFLECTOR_KEYS, "the SVGS target's corner cubes")

#: The typed parts of a camera profile, by table name.
CAMERA_PARTS = {c.TABLE: c for c in (Sensor, Glare, Exposure, Cfa, Isp, Optics, Flash, Tof, Noise, Illumination)}
#: The typed parts of a target pattern, by table name.
PATTERN_PARTS = {c.TABLE: c for c in (Reflector, Plate, Marker)}


@dataclass(frozen=True)
class FittedValue:
    """One value a fitted overlay set (an entry of the profile's ``[fitted]`` record).

    Attributes
    ----------
    key : str
        ``"table.name"`` of the value in the profile.
    value : float or str
    fitted_to : str
        Which table or figure of which paper, and how.
    range : tuple
        ``(lo, hi)`` for a number, the choices for a text.
    range_source : str
    prior : float or str or None
        The unfitted value of the profile, where it had one.
    overlay : str or None
        The overlay's file, ``fitted/<key>.toml``.
    """

    key: str
    value: object
    fitted_to: str
    range: tuple
    range_source: str
    prior: object = None
    overlay: str | None = None

    @classmethod
    def from_entry(cls, key: str, entry: dict) -> "FittedValue":
        return cls(key=str(key), value=entry.get("value"), fitted_to=str(entry.get("fitted_to", "")),
                   range=tuple(entry.get("range") or ()), range_source=str(entry.get("range_source", "")),
                   prior=entry.get("prior"), overlay=entry.get("overlay"))

    def entry(self) -> dict:
        """The record's TOML entry (as :func:`svgs_sim.base.profiles.apply_fitted` writes it)."""
        out = {"value": self.value, "fitted_to": self.fitted_to, "range": list(self.range),
               "range_source": self.range_source}
        if self.prior is not None:
            out["prior"] = self.prior
        if self.overlay is not None:
            out["overlay"] = self.overlay
        return out


@dataclass(frozen=True)
class TargetSpec:
    """One ``[[target]]`` of a pattern file.

    Attributes
    ----------
    id : int
    x_m, y_m, z_m : float
        Position in the target frame, m.
    diameter_m : float or None
        The target's own diameter (None: the pattern's ``[marker]`` or ``[reflector]`` one).
    standoff_m : float or None
        Height of the marker's face above the plate (None: ``z_m``).
    """

    id: int
    x_m: float
    y_m: float
    z_m: float
    diameter_m: float | None = None
    standoff_m: float | None = None
