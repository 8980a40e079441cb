"""The test lab around the target: backdrop and room light, from ``assets/labs/<name>.toml``.

The lab's values are priors (ASSUMPTIONS: the paper does not describe the room); a fitted
overlay ``assets/labs/fitted/<name>.toml`` (the same format as the camera overlays, see
:func:`svgs_sim.base.profiles.read_fitted_overlay`) sets the ones fitted to a result of the paper.

>>> from svgs_sim.sim.lab import load_lab
>>> load_lab()["ambient_radiance_w_m2_sr"]   # the fitted value
0.028
>>> load_lab(fitted=False)["ambient_radiance_w_m2_sr"]
0.0
"""

from __future__ import annotations

import functools
import tomllib
from pathlib import Path

from svgs_sim.base.errors import ProfileError
from svgs_sim.base.profiles import apply_fitted, fitted_overlay_path, read_fitted_overlay

from svgs_sim.assets import ASSETS_DIR

#: The lab of the SVGS paper's tests.
DEFAULT_LAB = "msfc-frl"
LAB_KEYS = ("backdrop_distance_m", "backdrop_reflectance", "ambient_radiance_w_m2_sr")
#: The lab's error sources (``[errors]`` of the lab file, issue 24): the gimbal's and the translation
#: stage's positioning accuracy (each setting's error uniform within +/- it), the hand-held
#: rangefinder's 1-sigma (the rail position the lab recorded, and the paper's focal calibration) and
#: the air's C_n^2 (:mod:`svgs_sim.sim.turbulence`).
ERROR_KEYS = ("gimbal_accuracy_deg", "stage_accuracy_m", "rangefinder_sigma_m", "turbulence_cn2_m23")


@functools.lru_cache(maxsize=8)
def _load(name: str, fitted: bool) -> tuple:
    path = Path(name) if name.endswith(".toml") else ASSETS_DIR / "labs" / f"{name}.toml"
    if not path.is_file():
        known = sorted(p.stem for p in (ASSETS_DIR / "labs").glob("*.toml"))
        raise ProfileError(f"lab {name!r}: no such lab file (known: {', '.join(known)})")
    with open(path, "rb") as fh:
        data = tomllib.load(fh)
    overlay = fitted_overlay_path(path) if fitted else None
    if overlay is not None:
        data = apply_fitted(data, read_fitted_overlay(overlay, data), overlay.name)
    lab = data.get("lab") or {}
    missing = [k for k in LAB_KEYS if k not in lab]
    if missing:
        raise ProfileError(f"lab file {str(path)!r}: [lab] lacks {', '.join(missing)}")
    out = {k: float(lab[k]) for k in LAB_KEYS}
    for k, v in (data.get("stand") or {}).items():
        out[f"stand.{k}"] = float(v)
    errors = data.get("errors") or {}
    bad = sorted(set(errors) - set(ERROR_KEYS))
    if bad:
        raise ProfileError(f"lab file {str(path)!r}: [errors] has unknown key(s) {', '.join(bad)} "
                           f"(known: {', '.join(ERROR_KEYS)})")
    for k in ERROR_KEYS:
        v = float(errors.get(k, 0.0))
        if not (v >= 0 and v < float("inf")):
            raise ProfileError(f"lab file {str(path)!r}: [errors] {k} = {v!r}: expected a finite value >= 0")
        out[f"errors.{k}"] = v
    return tuple(out.items()), tuple((data.get("fitted") or {}).keys())


def stand_misalignment_deg(camera_key: str | None, name: str = DEFAULT_LAB, *, fitted: bool = True) -> tuple:
    """The phone's (roll, pitch, yaw) in the stand's holder, deg, from the lab's ``[stand]``
    table (``<key>_misalignment_yaw_deg``, the camera profile's ``key`` with ``-`` as ``_``);
    (0, 0, 0) for a phone the lab does not list or a camera without a key."""
    lab = load_lab(name, fitted=fitted)
    if camera_key is None:
        return (0.0, 0.0, 0.0)
    key = f"stand.{str(camera_key).replace('-', '_')}_misalignment_yaw_deg"
    return (0.0, 0.0, float(lab.get(key, 0.0)))


def lab_errors(name: str = DEFAULT_LAB) -> dict:
    """The lab's error sources, :data:`ERROR_KEYS` (sourced values, none fitted; 0: absent)."""
    lab = load_lab(name)
    return {k: float(lab[f"errors.{k}"]) for k in ERROR_KEYS}


def load_lab(name: str = DEFAULT_LAB, *, fitted: bool = True) -> dict:
    """The lab's values: ``backdrop_distance_m``, ``backdrop_reflectance``,
    ``ambient_radiance_w_m2_sr`` (W m^-2 sr^-1 in the camera band), the ``[stand]`` table's as
    ``stand.<name>``, with ``fitted``: the keys the overlay set."""
    items, fitted_keys = _load(str(name), bool(fitted))
    out = dict(items)
    out["fitted"] = list(fitted_keys)
    return out
