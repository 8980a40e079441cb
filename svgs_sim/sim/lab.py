"""The test lab around the target: backdrop and room light, from ``assets/labs/<name>.toml``.

The lab's values are priors (ASSUMPTIONS: the paper does not describe the room); a fitted
overlay ``assets/labs/fitted/<name>.toml`` (the same format as the camera overlays, see
:func:`svgs_sim.base.profiles.read_fitted_overlay`) sets the ones fitted to a result of the paper.

>>> from svgs_sim.sim.lab import load_lab
>>> load_lab().ambient_radiance_w_m2_sr   # the fitted value
0.028
>>> load_lab(fitted=False).ambient_radiance_w_m2_sr
0.0
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from svgs_sim.base.errors import ProfileError
from svgs_sim.base.profile_parts import FittedValue
from svgs_sim.base.profiles import apply_fitted, cached, fitted_overlay_path, read_fitted_overlay, read_toml

from svgs_sim.assets import ASSETS_DIR

#: The lab of the SVGS paper's tests.
DEFAULT_LAB = "msfc-frl"
LAB_KEYS = ("backdrop_distance_m", "backdrop_reflectance", "ambient_radiance_w_m2_sr")
#: The lab's error sources (``[errors]`` of the lab file, issue 24): the gimbal's and the translation
#: stage's positioning accuracy (each setting's error uniform within +/- it), the hand-held
#: rangefinder's 1-sigma (the rail position the lab recorded, and the paper's focal calibration) and
#: the air's C_n^2 (:mod:`svgs_sim.sim.turbulence`).
ERROR_KEYS = ("gimbal_accuracy_deg", "stage_accuracy_m", "rangefinder_sigma_m", "turbulence_cn2_m23")


@dataclass(frozen=True)
class LabErrors:
    """The lab's error sources (``[errors]``; 0: absent): sourced values, none fitted.

    Attributes
    ----------
    gimbal_accuracy_deg : float
        Each gimbal axis' positioning error at a setting, uniform within +/- it, deg.
    stage_accuracy_m : float
        The translation stage's positioning error, uniform within +/- it, m.
    rangefinder_sigma_m : float
        1-sigma of a range recorded with the hand-held rangefinder, m.
    turbulence_cn2_m23 : float
        The air's refractive-index structure constant C_n^2, m^-2/3.
    """

    gimbal_accuracy_deg: float = 0.0
    stage_accuracy_m: float = 0.0
    rangefinder_sigma_m: float = 0.0
    turbulence_cn2_m23: float = 0.0


@dataclass(frozen=True)
class Lab:
    """The test lab around the target (``assets/labs/<name>.toml`` with its fitted overlay).

    Attributes
    ----------
    name : str
    backdrop_distance_m : float
        A Lambertian backdrop this far behind the target origin, m.
    backdrop_reflectance : float
    ambient_radiance_w_m2_sr : float
        The room's light, W m^-2 sr^-1 in the camera band.
    stand_yaw_deg : tuple of (str, float)
        ``(camera key, yaw)``: each phone's misalignment in its holder about the boresight, deg.
    errors : LabErrors
    fitted : tuple of svgs_sim.base.profile_parts.FittedValue
        The values the overlay set (empty: the unfitted lab).
    source : str
        The lab file.
    """

    name: str
    backdrop_distance_m: float
    backdrop_reflectance: float
    ambient_radiance_w_m2_sr: float
    stand_yaw_deg: tuple = ()
    errors: LabErrors = LabErrors()
    fitted: tuple = ()
    source: str = ""

    def yaw_deg(self, camera_key: str | None) -> float:
        """The phone's yaw in its holder, deg (0 for a phone the lab does not list)."""
        return float(dict(self.stand_yaw_deg).get(camera_key, 0.0)) if camera_key is not None else 0.0


_YAW_SUFFIX = "_misalignment_yaw_deg"


def _load(name: str, fitted: bool) -> Lab:
    path = Path(name) if name.endswith(".toml") else ASSETS_DIR / "labs" / f"{name}.toml"
    if not path.is_file():
        known = sorted(p.stem for p in (ASSETS_DIR / "labs").glob("*.toml"))
        raise ProfileError(f"lab {name!r}: no such lab file (known: {', '.join(known)})")
    overlay = fitted_overlay_path(path) if fitted else None
    files = (path,) if overlay is None else (path, overlay)
    return cached("lab", (str(path), bool(fitted)), files, lambda: _build(path, overlay))


def _build(path: Path, overlay: Path | None) -> Lab:
    data = read_toml(path, "lab")
    if overlay is not None:
        data = apply_fitted(data, read_fitted_overlay(overlay, data), overlay.name)
    where = f"lab file {str(path)!r}"
    lab = data.get("lab") or {}
    missing = [k for k in LAB_KEYS if k not in lab]
    if missing:
        raise ProfileError(f"{where}: [lab] lacks {', '.join(missing)}")
    stand = []
    for k, v in (data.get("stand") or {}).items():
        if not k.endswith(_YAW_SUFFIX):
            raise ProfileError(f"{where}: [stand] {k}: expected <camera key with '_'>{_YAW_SUFFIX}")
        stand.append((k[:-len(_YAW_SUFFIX)].replace("_", "-"), float(v)))
    errors = data.get("errors") or {}
    bad = sorted(set(errors) - set(ERROR_KEYS))
    if bad:
        raise ProfileError(f"{where}: [errors] has unknown key(s) {', '.join(bad)} "
                           f"(known: {', '.join(ERROR_KEYS)})")
    err = {}
    for k in ERROR_KEYS:
        v = float(errors.get(k, 0.0))
        if not (v >= 0 and v < float("inf")):
            raise ProfileError(f"{where}: [errors] {k} = {v!r}: expected a finite value >= 0")
        err[k] = v
    fitted = tuple(FittedValue.from_entry(k, e) for k, e in (data.get("fitted") or {}).items())
    return Lab(name=str(data.get("name", path.stem)), **{k: float(lab[k]) for k in LAB_KEYS},
               stand_yaw_deg=tuple(stand), errors=LabErrors(**err), fitted=fitted, source=str(path))


def stand_misalignment_deg(camera_key: str | None, name: str = DEFAULT_LAB, *, fitted: bool = True) -> tuple:
    """The phone's (roll, pitch, yaw) in the stand's holder, deg, from the lab's ``[stand]``
    table (``<key>_misalignment_yaw_deg``, the camera profile's ``key`` with ``-`` as ``_``);
    (0, 0, 0) for a phone the lab does not list or a camera without a key."""
    return (0.0, 0.0, load_lab(name, fitted=fitted).yaw_deg(camera_key))


def lab_errors(name: str = DEFAULT_LAB) -> dict:
    """The lab's error sources, :data:`ERROR_KEYS` (sourced values, none fitted; 0: absent)."""
    e = load_lab(name).errors
    return {k: float(getattr(e, k)) for k in ERROR_KEYS}


def load_lab(name: str = DEFAULT_LAB, *, fitted: bool = True) -> Lab:
    """The lab ``name`` (a name in ``assets/labs`` or a path), read once per process.

    Parameters
    ----------
    name : str
    fitted : bool
        Apply the lab's fitted overlay (default).

    Returns
    -------
    Lab
    """
    return _load(str(name), bool(fitted))
