"""Camera profiles and target patterns: TOML files loaded by name or by path.

Named profiles live in ``assets/cameras/<name>.toml`` and ``assets/patterns/<name>.toml``.
A camera profile needs only an ``[intrinsics]`` table to solve; ``[distortion]`` is
optional (zero when absent); any other table (``[sensor]``, ``[optics]``, ``[flash]``,
``[isp]``, ``[sources]``...) is kept verbatim in :attr:`Camera.tables` for the renderer and
camera model, and is not needed for solving real photos.

Fitted values live apart from the physical profile: ``assets/cameras/fitted/<name>.toml``
(in general ``fitted/<file name>`` beside the profile) lists each value that was fitted to a
result of a paper, with what it was fitted to, its plausible physical range and that
range's source. :meth:`Camera.load` applies the overlay by default;
``Camera.load(name, fitted=False)`` gives the unfitted profile (the documented priors),
which the model tests use.
"""

from __future__ import annotations

import copy
import os
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import tomli_w

from ..assets import ASSETS_DIR
from .errors import InputError, ProfileError, check_finite, check_finite_positive
from .profile_parts import CAMERA_PARTS, PATTERN_PARTS, FittedValue, ProfilePart, TargetSpec
from .profile_schema import (
    DISTINCT_TARGETS_M,
    INTRINSICS_KEYS,
    check_camera_tables,
    check_pattern_tables,
    check_table,
)

CAMERAS_DIR = ASSETS_DIR / "cameras"
PATTERNS_DIR = ASSETS_DIR / "patterns"

DISTORTION_KEYS = ("k1", "k2", "p1", "p2", "k3")

#: Folder of fitted overlays: beside a profile, and the package's ``assets/cameras/fitted``.
FITTED_DIRNAME = "fitted"
#: A camera key: lower-case letters, digits and dashes (``galaxy-nexus``).
KEY_RE = re.compile(r"[a-z0-9][a-z0-9-]*")
#: Fields every ``[[fit]]`` entry of an overlay must have.
FIT_FIELDS = ("key", "value", "fitted_to", "range", "range_source")
#: Tables an overlay may not change: the solve geometry is calibrated, never fitted.
UNFITTABLE_TABLES = ("name", "intrinsics", "distortion", "sources", "fitted")


def _available(folder: Path) -> list[str]:
    return sorted(p.stem for p in folder.glob("*.toml"))


def _resolve(name_or_path, folder: Path, kind: str) -> Path:
    """Find a profile file: an existing path, or a name in ``folder``."""
    if isinstance(name_or_path, Path) or (isinstance(name_or_path, str) and (
        name_or_path.endswith(".toml") or "/" in name_or_path or "\\" in name_or_path
    )):
        p = Path(name_or_path)
        if not p.is_file():
            what = "is not a regular file (a folder, device, FIFO or socket)" if p.exists() else "does not exist"
            raise ProfileError(f"{kind} file {str(p)!r} {what}")
        return p
    if not isinstance(name_or_path, str) or not name_or_path:
        raise ProfileError(f"{kind}: expected a name or a path to a .toml file, got {name_or_path!r}")
    p = folder / f"{name_or_path}.toml"
    if not p.is_file():
        raise ProfileError(
            f"unknown {kind} {name_or_path!r}; known: {', '.join(_available(folder)) or 'none'} "
            f"(or give a path to a .toml file)"
        )
    return p


def cached(kind: str, key: tuple, files, build):
    """The one cache of every file-backed object of the project: profiles, patterns, labs, the
    app's settings, material tables and the parsed TOML under them.

    An entry is kept with the modification time and size of each file it was built from, and
    built again when one of them changed (an edited profile is read again; a file that did not
    change is opened once per process).

    Parameters
    ----------
    kind : str
        What is cached (``"toml"``, ``"camera"``, ``"pattern"``, ``"lab"``, ``"app"``,
        ``"sheeting"``...).
    key : tuple
        What tells two entries of one kind apart (the resolved path, options).
    files : iterable of Path
        The files the object is built from.
    build : callable
        ``build()`` makes the object (called on a miss).

    Returns
    -------
    object
        Shared by every caller in the process: treat it as read-only (the profile objects
        are frozen).
    """
    stamps = []
    for f in files:
        try:
            st = os.stat(f)
            stamps.append((str(f), st.st_mtime_ns, st.st_size))
        except OSError:
            stamps.append((str(f), None, None))
    full = (kind, *key)
    hit = _CACHE.get(full)
    if hit is not None and hit[0] == tuple(stamps):
        return hit[1]
    value = build()
    if len(_CACHE) >= _CACHE_SIZE:
        _CACHE.clear()
    _CACHE[full] = (tuple(stamps), value)
    return value


def clear_cache() -> None:
    """Forget every cached object (:func:`cached`): the next load reads its files again."""
    _CACHE.clear()


#: ``(kind, *key) -> (file stamps, object)``: :func:`cached`.
_CACHE: dict = {}
_CACHE_SIZE = 256


def _read_shared(path, kind: str) -> dict:
    """As :func:`read_toml`, but the cached parse itself, not a copy: for lookups that only read it."""
    return _shared_toml(Path(path), _toml_parser(Path(path), kind))


def read_toml(path, kind: str) -> dict:
    """A TOML file of the project's kinds, parsed (a fresh copy: callers may change it).

    Parameters
    ----------
    path : str or Path
    kind : str
        What the file is, for the message (``"camera profile"``, ``"lab file"``...).

    Raises
    ------
    ProfileError
        Naming the file: not TOML, not UTF-8, unreadable.
    """
    path = Path(path)
    return copy.deepcopy(_shared_toml(path, _toml_parser(path, kind)))


def _toml_parser(path: Path, kind: str):
    """A function that parses ``path`` (ProfileError naming the file and ``kind`` when it cannot)."""

    def parse():
        try:
            with open(path, "rb") as fh:
                return tomllib.load(fh)
        except tomllib.TOMLDecodeError as exc:
            raise ProfileError(f"{kind} file {str(path)!r} is not valid TOML: {exc}") from None
        except UnicodeDecodeError as exc:
            raise ProfileError(f"{kind} file {str(path)!r} is not UTF-8 text (TOML files are): byte "
                               f"0x{exc.object[exc.start]:02x} at offset {exc.start}") from None
        except OSError as exc:
            raise ProfileError(f"{kind} file {str(path)!r} cannot be read: {exc}") from None

    return parse


def _shared_toml(path: Path, parse):
    """The cached parse of ``path`` itself (read-only: the loader's own lookups, no copy)."""
    return cached("toml", (str(path),), (path,), parse)




def fitted_overlay_path(profile_path, key: str | None = None) -> Path | None:
    """The fitted overlay of a profile file, or None when it has none.

    Parameters
    ----------
    profile_path : str or Path
        A profile (``.../<name>.toml``).
    key : str, optional
        The profile's :attr:`Camera.key` (a camera profile's identity). Given, the overlay is
        ``fitted/<key>.toml`` beside the profile or else in the package's
        ``assets/cameras/fitted/``: a copy of a profile, wherever it lies and whatever its
        display name, gets the overlay of the camera it describes. None: ``fitted/<file name>``
        beside the profile (a lab).

    Returns
    -------
    Path or None
        The overlay file, if it exists.
    """
    p = Path(profile_path)
    if key is None:
        o = p.parent / FITTED_DIRNAME / p.name
        return o if o.is_file() else None
    for folder in (p.parent / FITTED_DIRNAME, CAMERAS_DIR / FITTED_DIRNAME):
        o = folder / f"{key}.toml"
        if o.is_file():
            return o
    return None


def read_fitted_overlay(path, base: dict | None = None) -> list[dict]:
    """Read and check a fitted overlay.

    The file holds ``[[fit]]`` tables, each with ``key`` (``"table.name"``), ``value``,
    ``fitted_to`` (which table or figure of which paper, and how), ``range`` (``[lo, hi]``
    for a number, the list of choices for a string) and ``range_source``.

    Parameters
    ----------
    path : str or Path
    base : dict, optional
        The profile's TOML structure; when given, every fitted table must exist in it.

    Returns
    -------
    list of dict
        The entries, in file order.

    Raises
    ------
    ProfileError
        Naming the file and the entry: a missing field, a key that is not
        ``table.name`` or names a geometry table, a value outside its range, a key twice.
    """
    path = Path(path)
    data = read_toml(path, "fitted overlay")
    fits = data.get("fit")
    where = f"fitted overlay {str(path)!r}"
    if not isinstance(fits, list) or not fits:
        raise ProfileError(f"{where}: expected [[fit]] tables with {', '.join(FIT_FIELDS)}")
    seen = set()
    for i, f in enumerate(fits):
        missing = [k for k in FIT_FIELDS if k not in f or f[k] in ("", [])]
        if missing:
            raise ProfileError(f"{where}: fit #{i + 1} lacks {', '.join(missing)}")
        key = f["key"]
        parts = key.split(".") if isinstance(key, str) else []
        if len(parts) != 2 or not all(parts):
            raise ProfileError(f"{where}: fit #{i + 1} key {key!r} must be 'table.name'")
        if parts[0] in UNFITTABLE_TABLES:
            raise ProfileError(f"{where}: fit {key!r}: [{parts[0]}] cannot be fitted")
        if base is not None and not isinstance(base.get(parts[0]), dict):
            raise ProfileError(f"{where}: fit {key!r}: the profile has no [{parts[0]}] table")
        if key in seen:
            raise ProfileError(f"{where}: fit {key!r} is given twice")
        seen.add(key)
        v, rng = f["value"], f["range"]
        if isinstance(v, str):
            if not isinstance(rng, list) or v not in rng:
                raise ProfileError(f"{where}: fit {key!r} = {v!r} is not one of its range {rng!r}")
        else:
            ok = (isinstance(rng, list) and len(rng) == 2 and all(isinstance(x, (int, float)) for x in rng)
                  and not isinstance(v, bool) and isinstance(v, (int, float)))
            if not ok:
                raise ProfileError(f"{where}: fit {key!r}: expected a number and range = [lo, hi], got {v!r}, {rng!r}")
            if not (rng[0] <= v <= rng[1]):
                raise ProfileError(f"{where}: fit {key!r} = {v} lies outside its plausible range {rng}")
    return fits


def apply_fitted(data: dict, fits: list[dict], overlay_name: str = "") -> dict:
    """The profile structure with the fitted values in place (``data`` is not changed).

    The result carries a ``[fitted]`` table: for each fitted key its value, what it was
    fitted to, range, range source, the overlay's file name and (where the profile had one)
    the unfitted ``prior``.
    """
    out = {k: (dict(v) if isinstance(v, dict) else v) for k, v in data.items()}
    record = {}
    for f in fits:
        table, name = f["key"].split(".")
        entry = {k: f[k] for k in ("value", "fitted_to", "range", "range_source")}
        if name in out[table]:
            entry["prior"] = out[table][name]
        if overlay_name:
            entry["overlay"] = overlay_name
        out[table][name] = f["value"]
        record[f["key"]] = entry
    out["fitted"] = record
    return out


def _camera_overlay(path: Path, data: dict) -> Path | None:
    """The fitted overlay a camera profile's data calls for: by its ``key``; none when the data
    already records fitted values (a saved camera whose overlay was applied) or has no key."""
    key = data.get("key")
    if "fitted" in data or not isinstance(key, str):
        return None
    return fitted_overlay_path(path, key)


class _Tables(dict):
    """The tables a camera or pattern owns (a copy of what it was built from) with the typed
    parts built from them: a copy of the object (``Camera.replace``) keeps both, without
    copying or checking them again. Nothing outside this module reads or changes them."""

    kind: str = ""
    parts: dict | None = None


@dataclass(frozen=True)
class Camera:
    """A camera's geometry (pinhole + Brown-Conrady distortion, OpenCV conventions).

    Pixel centres sit at integer coordinates (OpenCV): the top-left pixel's centre is
    (0, 0), its area spans [-0.5, 0.5]. ``u`` grows to the right, ``v`` downwards.

    Attributes
    ----------
    name : str
        The display name (free: a copy of a profile may carry any).
    width, height : int
        Image size, pixels.
    fx, fy, cx, cy : float
        Focal lengths and principal point, pixels.
    dist : ndarray, shape (5,)
        OpenCV distortion coefficients ``(k1, k2, p1, p2, k3)``.
    tables : dict
        Every other table of the profile as read from its file: the loader's own record, from
        which it builds the typed parts and writes the profile back (:meth:`to_dict`). Other
        modules read the typed parts (:attr:`sensor`, :attr:`optics`, :attr:`flash`...,
        :mod:`svgs_sim.base.profile_parts`), never this (a test keeps it so).
    source : str
        Where the profile was loaded from.
    key : str or None
        The camera's identity (the profile's top-level ``key``): it, not the display name,
        chooses the SVGS app's per-camera settings (:meth:`svgs_sim.svgs.app.AppSettings.threshold_for`),
        the fitted overlay (:func:`fitted_overlay_path`) and the lab's per-phone values. None: a
        camera the project has no per-camera values for.
    """

    name: str
    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    dist: np.ndarray = field(default_factory=lambda: np.zeros(5))
    tables: dict = field(default_factory=dict)
    source: str = ""
    key: str | None = None

    def __post_init__(self):
        if self.key is not None and not (isinstance(self.key, str) and KEY_RE.fullmatch(self.key)):
            raise ProfileError(f"camera {self.name!r}: key must be lower-case letters, digits and '-' "
                               f"(the camera's identity, e.g. 'galaxy-nexus'), got {self.key!r}")
        for k in ("width", "height"):
            v = getattr(self, k)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v <= 0:
                if isinstance(v, float) and v.is_integer() and v > 0:
                    object.__setattr__(self, k, int(v))
                else:
                    raise ProfileError(f"camera {self.name!r}: intrinsics.{k} must be a positive integer, got {v!r}")
        for k in ("fx", "fy"):
            object.__setattr__(self, k, _wrap(check_finite_positive, getattr(self, k), f"camera {self.name!r}: intrinsics.{k}"))
        for k, lim in (("cx", self.width), ("cy", self.height)):
            v = _wrap(check_finite, getattr(self, k), f"camera {self.name!r}: intrinsics.{k}")
            if not (-0.5 <= v <= lim - 0.5):
                raise ProfileError(f"camera {self.name!r}: intrinsics.{k} = {v} lies outside the image (0..{lim - 1} px)")
            object.__setattr__(self, k, v)
        d = np.asarray(self.dist, float).reshape(-1)
        if d.shape != (5,) or not np.all(np.isfinite(d)):
            raise ProfileError(f"camera {self.name!r}: distortion must be 5 finite numbers (k1, k2, p1, p2, k3), got {self.dist!r}")
        object.__setattr__(self, "dist", d)
        if isinstance(self.tables, _Tables) and self.tables.kind == "camera":
            object.__setattr__(self, "_parts", self.tables.parts)  # a copy of a camera (replace): parts kept
            return
        tables = _Tables(copy.deepcopy(dict(self.tables or {})))  # the camera's own: no caller shares it
        where = f"camera profile {self.source!r}" if self.source else f"camera {self.name!r}"
        parts = {name: cls.from_table(tables.get(name), where) for name, cls in CAMERA_PARTS.items()}
        fitted = tables.get("fitted") or {}
        if not isinstance(fitted, dict):
            raise ProfileError(f"{where}: [fitted] must be a table of fitted values")
        parts["fitted"] = tuple(FittedValue.from_entry(k, e) for k, e in fitted.items() if isinstance(e, dict))
        preview = tables.get("preview")
        parts["preview_of"] = preview.get("of") if isinstance(preview, dict) else None
        tables.kind, tables.parts = "camera", parts
        object.__setattr__(self, "tables", tables)
        object.__setattr__(self, "_parts", parts)

    # ------------------------------------------------------------------ typed parts
    @property
    def sensor(self):
        """The image sensor (:class:`svgs_sim.base.profile_parts.Sensor`; fields None where not given)."""
        return self._parts["sensor"]

    @property
    def glare(self):
        """The lens' stray light (:class:`svgs_sim.base.profile_parts.Glare`)."""
        return self._parts["glare"]

    @property
    def exposure(self):
        """The exposure control (:class:`svgs_sim.base.profile_parts.Exposure`)."""
        return self._parts["exposure"]

    @property
    def cfa(self):
        """The colour filter array (:class:`svgs_sim.base.profile_parts.Cfa`)."""
        return self._parts["cfa"]

    @property
    def isp(self):
        """The image signal processor (:class:`svgs_sim.base.profile_parts.Isp`)."""
        return self._parts["isp"]

    @property
    def optics(self):
        """The lens (:class:`svgs_sim.base.profile_parts.Optics`)."""
        return self._parts["optics"]

    @property
    def flash(self):
        """The LED flash (:class:`svgs_sim.base.profile_parts.Flash`)."""
        return self._parts["flash"]

    @property
    def tof(self):
        """A ToF camera's pixel (:class:`svgs_sim.base.profile_parts.Tof`)."""
        return self._parts["tof"]

    @property
    def noise(self):
        """A ToF camera's noise (:class:`svgs_sim.base.profile_parts.Noise`)."""
        return self._parts["noise"]

    @property
    def illumination(self):
        """A ToF camera's emitters (:class:`svgs_sim.base.profile_parts.Illumination`)."""
        return self._parts["illumination"]

    @property
    def fitted(self) -> tuple:
        """The values a fitted overlay set, tuple of :class:`svgs_sim.base.profile_parts.FittedValue`
        (empty: an unfitted profile)."""
        return self._parts["fitted"]

    @property
    def preview_of(self) -> str | None:
        """The key of the phone whose preview stream this camera is (``[preview] of``), or None."""
        return self._parts["preview_of"]

    @property
    def is_tof(self) -> bool:
        """A ToF camera: the profile has a ``[tof]`` table and no ``[flash]``."""
        return "tof" in self.tables and "flash" not in self.tables

    def has(self, table: str) -> bool:
        """Whether the profile has the table ``table`` (``"flash"``, ``"optics"``...)."""
        return isinstance(self.tables.get(table), dict)

    def with_values(self, values) -> "Camera":
        """A copy with single values of its tables changed, checked by the schema.

        Parameters
        ----------
        values : iterable of (str, str, object)
            ``(table, key, value)``, e.g. ``("optics", "f_number", 2.8)``.

        Returns
        -------
        Camera
        """
        tables = copy.deepcopy(dict(self.tables))
        for table, key, value in values:
            tables.setdefault(table, {})[key] = value
        return self.replace(tables=tables)

    def fingerprint(self) -> tuple:
        """The camera by content (hashable): name, geometry and every table."""
        return (self.name, self.width, self.height, self.fx, self.fy, self.cx, self.cy,
                tuple(np.asarray(self.dist, float).tolist()), repr(self.tables))

    def with_tables(self, **tables) -> "Camera":
        """A copy with whole tables replaced (``None``: removed), checked as a file's would be.

        Parameters
        ----------
        **tables : dict or None
            ``name=table`` in the TOML structure (``calibration={...}``, ``sensor={...}``).

        Returns
        -------
        Camera
        """
        new = copy.deepcopy(dict(self.tables))
        for k, v in tables.items():
            if v is None:
                new.pop(k, None)
            else:
                new[k] = v  # in its place; a new table last
        where = f"camera profile {self.source!r}" if self.source else f"camera {self.name!r}"
        try:
            check_camera_tables(new)
        except ProfileError:
            raise
        except InputError as exc:
            raise ProfileError(f"{where}: {exc}") from None
        return self.replace(tables=new)

    # ------------------------------------------------------------------ loading
    @classmethod
    def load(cls, name_or_path, *, fitted: bool = True) -> "Camera":
        """Load a camera profile by name (``assets/cameras/<name>.toml``) or path.

        Parameters
        ----------
        name_or_path : str, Path or Camera
            A profile name, a path to a ``.toml`` file, or a camera (returned as is).
        fitted : bool
            Apply the profile's fitted overlay (``fitted/<file name>`` beside it), if it
            has one: the values fitted to the papers' results (default). ``False`` gives
            the unfitted profile, its documented priors.

        Returns
        -------
        Camera
            With ``tables["fitted"]`` recording each fitted value when an overlay applied.
        """
        if isinstance(name_or_path, Camera):
            return name_or_path
        path = _resolve(name_or_path, CAMERAS_DIR, "camera profile")
        data = read_toml(path, "camera profile")
        overlay = _camera_overlay(path, data) if fitted else None
        if overlay is not None:
            cls.from_dict(data, source=str(path), default_name=path.stem)  # the file's own values checked too
            data = apply_fitted(data, read_fitted_overlay(overlay, data), f"{FITTED_DIRNAME}/{overlay.name}")
        return cls.from_dict(data, source=str(path), default_name=path.stem)

    @classmethod
    def from_dict(cls, data: dict, source: str = "", default_name: str = "camera") -> "Camera":
        """Build a camera from the TOML structure (see :meth:`to_dict`).

        Every value of the tables :mod:`svgs_sim.base.profile_schema` knows is checked here, before any
        use (type, physical range, choices, unknown keys): :class:`ProfileError` naming the
        file (``source``), ``[table] key`` and the allowed range.
        """
        name = str(data.get("name", default_name))
        where = f"camera profile {source!r}" if source else f"camera {name!r}"
        intr = data.get("intrinsics")
        if not isinstance(intr, dict):
            raise ProfileError(f"{where}: missing [intrinsics] table")
        missing = [k for k in ("width", "height", "fx", "fy", "cx", "cy") if k not in intr]
        if missing:
            raise ProfileError(f"{where}: [intrinsics] lacks {', '.join(missing)}")
        try:
            check_table("intrinsics", intr, INTRINSICS_KEYS)
            check_camera_tables(data)
        except ProfileError:
            raise
        except InputError as exc:
            raise ProfileError(f"{where}: {exc}") from None
        dist_t = data.get("distortion", {}) or {}
        if not isinstance(dist_t, dict):
            raise ProfileError(f"camera {name!r}: [distortion] must be a table")
        unknown = set(dist_t) - set(DISTORTION_KEYS)
        if unknown:
            raise ProfileError(f"camera {name!r}: unknown [distortion] keys {sorted(unknown)}; expected {DISTORTION_KEYS}")
        dist = [_wrap(check_finite, dist_t.get(k, 0.0), f"camera {name!r}: distortion.{k}") for k in DISTORTION_KEYS]
        tables = {k: v for k, v in data.items() if k not in ("name", "key", "intrinsics", "distortion")}
        return cls(
            name=name,
            width=intr["width"],
            height=intr["height"],
            fx=intr["fx"],
            fy=intr["fy"],
            cx=intr["cx"],
            cy=intr["cy"],
            dist=np.array(dist),
            tables=tables,
            source=source,
            key=data.get("key"),
        )

    def to_dict(self) -> dict:
        """The TOML structure of this profile."""
        out = {"name": self.name}
        if self.key is not None:
            out["key"] = self.key
            if "fitted" not in self.tables:
                # the values are complete as they stand (an unfitted camera): reading the file back
                # applies no overlay, so load(save(camera)) is the camera
                out["fitted"] = {}
        for k, v in self.tables.items():
            if not isinstance(v, dict):
                out[k] = v
        out["intrinsics"] = {
            "width": int(self.width), "height": int(self.height),
            "fx": float(self.fx), "fy": float(self.fy), "cx": float(self.cx), "cy": float(self.cy),
        }
        out["distortion"] = {k: float(v) for k, v in zip(DISTORTION_KEYS, self.dist)}
        for k, v in self.tables.items():
            if isinstance(v, dict):
                out[k] = v
        return out

    def save(self, path) -> Path:
        """Write this profile as TOML; :meth:`load` reads it back unchanged."""

        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(path, "wb") as fh:
            tomli_w.dump(self.to_dict(), fh)
        return path

    def replace(self, **changes) -> "Camera":
        """A copy with some fields changed (e.g. ``fx=...``)."""
        d = {k: getattr(self, k) for k in ("name", "width", "height", "fx", "fy", "cx", "cy", "dist", "tables", "source", "key")}
        d.update(changes)
        return Camera(**d)

    def scaled(self, width: int, height: int) -> "Camera":
        """The same camera delivering images resized to ``width x height`` (a preview
        stream): focal lengths scale, and the principal point keeps its place in the
        field (pixel centres at integers: ``c' = (c + 0.5) * s - 0.5``). Distortion, in
        normalised coordinates, is unchanged."""
        sx, sy = width / self.width, height / self.height
        return self.replace(
            width=int(width), height=int(height), fx=self.fx * sx, fy=self.fy * sy,
            cx=(self.cx + 0.5) * sx - 0.5, cy=(self.cy + 0.5) * sy - 0.5,
        )

    # --------------------------------------------------------------- geometry
    @property
    def K(self) -> np.ndarray:
        """Camera matrix, shape (3, 3)."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def has_distortion(self) -> bool:
        return bool(np.any(self.dist != 0))

    def table(self, name: str) -> ProfilePart:
        """A part the operation needs (``"optics"``, ``"flash"``...): :class:`ProfileError` naming
        the table if the profile lacks it.

        Returns
        -------
        ProfilePart
            The typed part (:mod:`svgs_sim.base.profile_parts`).
        """
        if name not in CAMERA_PARTS or not self.has(name):
            raise ProfileError(f"camera {self.name!r} ({self.source or 'dict'}) has no [{name}] table, which this operation needs")
        return self._parts[name]

    def distort_normalized(self, xy: np.ndarray) -> np.ndarray:
        """Apply the distortion model to normalised (undistorted) coordinates.

        Parameters
        ----------
        xy : ndarray, shape (..., 2)
            ``(X/Z, Y/Z)`` in the OpenCV camera frame.

        Returns
        -------
        ndarray, shape (..., 2)
        """
        xy = np.asarray(xy, float)
        if not self.has_distortion:
            return xy.copy()
        k1, k2, p1, p2, k3 = self.dist
        x, y = xy[..., 0], xy[..., 1]
        r2 = x * x + y * y
        radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        return np.stack([xd, yd], -1)

    def normalized_to_pixels(self, xy: np.ndarray) -> np.ndarray:
        """Normalised coordinates -> pixels, distortion included. Shapes (..., 2)."""
        d = self.distort_normalized(xy)
        return np.stack([self.fx * d[..., 0] + self.cx, self.fy * d[..., 1] + self.cy], -1)

    def project(self, p_cam_m: np.ndarray) -> np.ndarray:
        """Project points given in the OpenCV camera frame to pixels (distortion included).

        Parameters
        ----------
        p_cam_m : ndarray, shape (..., 3)
            Points with positive z (in front of the camera), metres.

        Returns
        -------
        uv_px : ndarray, shape (..., 2)
        """
        p = np.asarray(p_cam_m, float)
        return self.normalized_to_pixels(p[..., :2] / p[..., 2:3])

    def project_target(self, points_target_m, R_cam_target, t_cam_target_m) -> np.ndarray:
        """Project target-frame points through a pose. Shapes: (..., N, 3) -> (..., N, 2)."""
        R = np.asarray(R_cam_target, float)
        t = np.asarray(t_cam_target_m, float)
        p = np.einsum("...ij,...nj->...ni", R, np.asarray(points_target_m, float)) + t[..., None, :]
        return self.project(p)

    def pixels_to_normalized(self, uv_px: np.ndarray) -> np.ndarray:
        """Undistort pixel coordinates to normalised coordinates ``(X/Z, Y/Z)``.

        Newton iteration on the Brown-Conrady model (:meth:`undistort_normalized`),
        converged to ~1e-15, where OpenCV's fixed-point ``undistortPoints`` stops at ~1e-6.

        Parameters
        ----------
        uv_px : ndarray, shape (..., 2)

        Returns
        -------
        ndarray, shape (..., 2)
        """
        uv = np.asarray(uv_px, float)
        if not self.has_distortion:
            return np.stack([(uv[..., 0] - self.cx) / self.fx, (uv[..., 1] - self.cy) / self.fy], -1)
        target = np.stack([(uv[..., 0] - self.cx) / self.fx, (uv[..., 1] - self.cy) / self.fy], -1)
        return self.undistort_normalized(target)

    def undistort_normalized(self, xy_d: np.ndarray, n_iter: int = 20) -> np.ndarray:
        """Invert :meth:`distort_normalized` by Newton's method (converges to ~1e-15; at most
        ``n_iter`` = 20 steps per point, compiled: :func:`svgs_sim.base.distortion.undistort_points`).

        Parameters
        ----------
        xy_d : ndarray, shape (..., 2)
            Distorted normalised coordinates.

        Returns
        -------
        ndarray, shape (..., 2)
        """
        xy_d = np.asarray(xy_d, float)
        if not self.has_distortion:
            return xy_d.copy()
        from .distortion import undistort_points  # compiled: per point, in parallel

        flat = np.ascontiguousarray(xy_d.reshape(-1, 2))
        out = np.empty_like(flat)
        undistort_points(flat, np.ascontiguousarray(self.dist, dtype=np.float64).reshape(5), out)
        xy = out.reshape(xy_d.shape)
        return xy

    def in_image(self, uv_px: np.ndarray, margin_px: float = 0.0) -> np.ndarray:
        """True where pixel coordinates lie inside the image (by ``margin_px``). Shape (...)."""
        uv = np.asarray(uv_px, float)
        return (
            (uv[..., 0] >= -0.5 + margin_px) & (uv[..., 0] <= self.width - 0.5 - margin_px)
            & (uv[..., 1] >= -0.5 + margin_px) & (uv[..., 1] <= self.height - 0.5 - margin_px)
        )


def _wrap(fn, value, name):
    try:
        return fn(value, name)
    except InputError as exc:
        raise ProfileError(str(exc)) from None


@dataclass(frozen=True)
class Pattern:
    """A target pattern: retroreflector positions in the target frame.

    Attributes
    ----------
    name : str
    ids : ndarray of int, shape (N,)
        Target ids, in the order of ``points_m``.
    points_m : ndarray, shape (N, 3)
        Target positions in the target frame, metres.
    tables : dict
        Any other table of the file as read (the loader's record; other modules read the typed
        parts :attr:`reflector`, :attr:`plate`, :attr:`marker` and :attr:`targets`).
    source : str
        Where the pattern was loaded from.
    target_sizes_m : tuple
        Per target, in the order of ``ids``: ``(diameter_m, standoff_m)`` of its ``[[target]]``
        table, each None where the file does not give it.
    """

    name: str
    ids: np.ndarray
    points_m: np.ndarray
    tables: dict = field(default_factory=dict)
    source: str = ""
    target_sizes_m: tuple = ()

    def __post_init__(self):
        ids = np.asarray(self.ids)
        pts = np.asarray(self.points_m, float)
        where = f"target pattern {self.source!r}" if self.source else f"pattern {self.name!r}"
        if pts.ndim != 2 or pts.shape[1] != 3 or pts.shape[0] != ids.shape[0]:
            raise ProfileError(f"{where}: expected N ids and N x 3 points, got {ids.shape} and {pts.shape}")
        if pts.shape[0] < 4:
            raise ProfileError(f"{where}: needs at least 4 targets, got {pts.shape[0]}")
        if not np.all(np.isfinite(pts)):
            raise ProfileError(f"{where}: target coordinates must be finite")
        if len(set(ids.tolist())) != len(ids):
            raise ProfileError(f"{where}: target ids must be unique, got {ids.tolist()}")
        gap = np.linalg.norm(pts[:, None, :] - pts[None, :, :], axis=-1)
        np.fill_diagonal(gap, np.inf)
        i, j = np.unravel_index(np.argmin(gap), gap.shape)
        if gap[i, j] < DISTINCT_TARGETS_M:
            raise ProfileError(f"{where}: targets {ids[i]} and {ids[j]} share one position "
                               f"({', '.join(f'{v:g}' for v in pts[i])}) m: target positions must be at least "
                               f"{DISTINCT_TARGETS_M:g} m apart")
        c = pts - pts.mean(0)
        sv = np.linalg.svd(c, compute_uv=False)
        if sv[1] < 1e-6 * max(sv[0], 1e-12):
            raise ProfileError(f"{where}: targets are collinear; a pose cannot be solved from them")
        object.__setattr__(self, "ids", ids.astype(int))
        object.__setattr__(self, "points_m", pts)
        sizes = tuple(tuple(x) for x in self.target_sizes_m) or ((None, None),) * len(ids)
        if len(sizes) != len(ids) or any(len(x) != 2 for x in sizes):
            raise ProfileError(f"{where}: target_sizes_m must hold (diameter_m, standoff_m) per target")
        object.__setattr__(self, "target_sizes_m", sizes)
        if not (isinstance(self.tables, _Tables) and self.tables.kind == "pattern"):
            tables = _Tables(copy.deepcopy(dict(self.tables or {})))
            tables.kind, tables.parts = "pattern", {n: c.from_table(tables.get(n), where) for n, c in PATTERN_PARTS.items()}
            object.__setattr__(self, "tables", tables)
        object.__setattr__(self, "_parts", self.tables.parts)

    def fingerprint(self) -> tuple:
        """The pattern by content (hashable): name, targets and every table."""
        return (self.name, self.ids.tolist(), self.points_m.tolist(), repr(self.tables), self.target_sizes_m)

    @property
    def reflector(self):
        """The corner cubes (:class:`svgs_sim.base.profile_parts.Reflector`; fields None where not given)."""
        return self._parts["reflector"]

    @property
    def plate(self):
        """A ToF target's plate (:class:`svgs_sim.base.profile_parts.Plate`)."""
        return self._parts["plate"]

    @property
    def marker(self):
        """A ToF target's markers (:class:`svgs_sim.base.profile_parts.Marker`)."""
        return self._parts["marker"]

    @property
    def targets(self) -> tuple:
        """Each target, tuple of :class:`svgs_sim.base.profile_parts.TargetSpec` in the order of ``ids``."""
        return tuple(TargetSpec(int(i), float(p[0]), float(p[1]), float(p[2]), d, so)
                     for i, p, (d, so) in zip(self.ids, self.points_m, self.target_sizes_m))

    @classmethod
    def load(cls, name_or_path) -> "Pattern":
        """Load a pattern by name (``assets/patterns/<name>.toml``) or path.

        Every value is checked here, before any use (:func:`svgs_sim.base.profile_schema.check_pattern_tables`:
        ``[reflector]``, each ``[[target]]``, the ToF target's ``[plate]`` and ``[marker]``, unknown
        keys): :class:`ProfileError` naming the file, ``[table] key`` and the allowed range.
        """
        if isinstance(name_or_path, Pattern):
            return name_or_path
        path = _resolve(name_or_path, PATTERNS_DIR, "target pattern")
        data = read_toml(path, "target pattern")
        name = str(data.get("name", path.stem))
        where = f"target pattern {str(path)!r}"
        targets = data.get("target")
        if not isinstance(targets, list) or not targets:
            raise ProfileError(f"{where}: expected [[target]] tables with id, x_m, y_m, z_m")
        try:  # every value checked at load (svgs_sim.base.profile_schema): nothing unknown is ignored
            checked = check_pattern_tables(data)
        except InputError as exc:
            raise ProfileError(f"{where}: {exc}") from None
        ids = [c["id"] for c in checked]
        pts = [[c[k] for k in ("x_m", "y_m", "z_m")] for c in checked]
        sizes = [(c.get("diameter_m"), c.get("standoff_m")) for c in checked]
        order = np.argsort(ids)
        tables = {k: v for k, v in data.items() if k not in ("name", "target")}
        return cls(name=name, ids=np.asarray(ids)[order], points_m=np.asarray(pts)[order], tables=tables, source=str(path),
                   target_sizes_m=tuple(sizes[i] for i in order))

    @property
    def n(self) -> int:
        return int(self.points_m.shape[0])

    def scaled(self, factor: float) -> "Pattern":
        """This pattern scaled about its origin by ``factor`` (a wider or narrower target).

        Parameters
        ----------
        factor : float
            Scale of every target position (> 0).

        Returns
        -------
        Pattern
            Named ``<name>-x<factor>``; the same ids, tables and source; ``points_m * factor``.
            ``factor == 1`` returns this pattern.
        """
        f = float(factor)
        if not (np.isfinite(f) and f > 0):
            raise InputError(f"pattern scale: expected a positive finite factor, got {factor!r}")
        if f == 1.0:
            return self
        return Pattern(name=f"{self.name}-x{f:g}", ids=self.ids.copy(), points_m=self.points_m * f,
                       tables=dict(self.tables), source=self.source, target_sizes_m=self.target_sizes_m)

    def point(self, target_id: int) -> np.ndarray:
        """The position of one target, shape (3,)."""
        idx = np.flatnonzero(self.ids == target_id)
        if idx.size == 0:
            raise InputError(f"pattern {self.name!r} has no target {target_id}")
        return self.points_m[idx[0]]


def load_camera(name_or_path, *, fitted: bool = True) -> Camera:
    """The camera profile ``name_or_path``, read once per process (:meth:`Camera.load`, kept in
    the one cache, :func:`cached`, with the profile's and its overlay's file stamps, so an edited
    profile is read again). A :class:`Camera` is returned as is. Treat the result as read-only: it is
    shared by every caller in the process.
    """
    if isinstance(name_or_path, Camera):
        return name_or_path
    path = _resolve(name_or_path, CAMERAS_DIR, "camera profile")
    overlay = _camera_overlay(path, _read_shared(path, "camera profile")) if fitted else None
    files = (path,) if overlay is None else (path, overlay)
    return cached("camera", (str(path), bool(fitted)), files, lambda: Camera.load(path, fitted=fitted))


def load_pattern(name_or_path) -> Pattern:
    """The target pattern ``name_or_path``, read once per process (:meth:`Pattern.load`, kept in
    the one cache, :func:`cached`). A :class:`Pattern` is returned as is."""
    if isinstance(name_or_path, Pattern):
        return name_or_path
    path = _resolve(name_or_path, PATTERNS_DIR, "target pattern")
    return cached("pattern", (str(path),), (path,), lambda: Pattern.load(path))
