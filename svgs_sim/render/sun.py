"""The sun on orbit, as the renderer draws it: a disk emitter far away in the sun's direction.

The sun is an extended source, not a delta ``directional`` light: the camera sees its disk, and
smooth surfaces (a cube's front face, cover glass) mirror it. It is a disk of
angular diameter :data:`SUN_ANGULAR_DIAMETER_DEG` and uniform radiance (limb darkening
ignored: ASSUMPTION), its band radiance the solar irradiance in the camera's band over the
disk's solid angle. The irradiance's spectral shape is ASTM G173-03's extraterrestrial spectrum
(through pvlib), scaled to :data:`SOLAR_CONSTANT_W_M2`.

The disk sits :data:`SUN_DISTANCE_M` from the target origin: far enough that its direction is the
same over the target (the target spans < 1 m: < 0.06 deg of parallax) and near enough that single
precision resolves it (a ray's intersection 1 km away is good to ~0.1 mm; the disk is 9.3 m wide).

The sun's light is rendered in a pass of its own (:class:`svgs_sim.render.api.Renderer`, the sun's
scene: the target without the flash) and converted to photons with the sun's own mean photon
energy in the band (:func:`sun_in_band`), then summed with the flash's.

>>> d = sun_direction_target(90.0, 60.0)   # azimuth from +x toward +y, elevation toward +z
>>> [round(float(x), 3) for x in d]
[0.0, 0.5, 0.866]
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from svgs_sim.base.errors import InputError

from .constants import PLANCK_J_S, SPEED_OF_LIGHT_M_S
from .optics import spectrum

#: Total solar irradiance at 1 AU, W/m^2. Kopp & Lean (2011), Geophys. Res. Lett. 38, L01706:
#: 1360.8 +/- 0.5 W/m^2 at solar minimum; 1361 is the IAU 2015 nominal value (Resolution B3).
SOLAR_CONSTANT_W_M2 = 1361.0
#: The sun's mean angular diameter seen from 1 AU, deg (its radius 695 700 km, IAU 2015 B3, over
#: 1 AU = 149 597 870.7 km: 2 asin(R/AU) = 0.533 deg).
SUN_ANGULAR_DIAMETER_DEG = 0.533
#: Distance of the rendered sun disk from the target origin, m (see the module docstring).
SUN_DISTANCE_M = 1000.0


def sun_solid_angle_sr() -> float:
    """Solid angle of the sun's disk, sr: ``2 pi (1 - cos(d / 2))`` = 6.80e-5 sr."""
    half = np.deg2rad(0.5 * SUN_ANGULAR_DIAMETER_DEG)
    return float(2.0 * np.pi * (1.0 - np.cos(half)))


@lru_cache(maxsize=1)
def solar_spectrum() -> tuple[np.ndarray, np.ndarray]:
    """The solar spectral irradiance at 1 AU: ASTM G173-03 extraterrestrial, scaled to
    :data:`SOLAR_CONSTANT_W_M2` (G173-03's own integrates to 1348 W/m^2 over 280-4000 nm).

    Returns
    -------
    wavelength_nm : ndarray, shape (n,)
    irradiance_w_m2_nm : ndarray, shape (n,)

    Raises
    ------
    InputError
        pvlib (the ``orbit`` extra) is not installed.
    """
    try:
        from pvlib.spectrum import get_reference_spectra
    except ImportError:
        raise InputError("the sun needs pvlib (the solar spectrum, ASTM G173-03): pip install -e \".[orbit]\"") from None
    s = get_reference_spectra(standard="ASTM G173-03")
    wl = np.asarray(s.index, float)
    e = np.asarray(s["extraterrestrial"], float)
    return wl, e * (SOLAR_CONSTANT_W_M2 / np.trapezoid(e, wl))


def sun_in_band(band_nm) -> dict:
    """The sun's light in a camera band.

    Parameters
    ----------
    band_nm : (float, float)
        The band the renderer counts flux in, nm.

    Returns
    -------
    dict
        ``irradiance_w_m2`` (on a surface facing the sun, in band), ``radiance_w_m2_sr`` (of the
        disk, in band), ``mean_photon_energy_j`` (in band), ``band_fraction`` (of the total).
    """
    wl, e = solar_spectrum()
    lo, hi = float(band_nm[0]), float(band_nm[1])
    grid = np.arange(lo, hi + 1e-9, 0.5)
    eg = np.interp(grid, wl, e)
    p = float(np.trapezoid(eg, grid))
    photons = float(np.trapezoid(eg * grid * 1e-9 / (PLANCK_J_S * SPEED_OF_LIGHT_M_S), grid))
    return {"irradiance_w_m2": p, "radiance_w_m2_sr": p / sun_solid_angle_sr(), "mean_photon_energy_j": p / photons,
            "band_fraction": p / SOLAR_CONSTANT_W_M2}


def photon_spectra(band_nm, flash_spectrum: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The sun's and the flash's photon spectra over a band, for the camera's colour filters.

    The Earth's light has the sun's spectrum: its albedo is grey (ASSUMPTION, docs/orbit.md), so
    one spectrum serves all natural light.

    Parameters
    ----------
    band_nm : (float, float)
    flash_spectrum : str
        The flash's spectrum (:data:`svgs_sim.render.optics.SPECTRA`).

    Returns
    -------
    wavelength_nm : ndarray, shape (n,)
        A 0.5 nm grid over the band.
    photons_sun, photons_flash : ndarray, shape (n,)
        Photons per nm (any scale each): spectral power times wavelength. Read-only.
    """
    return _photon_spectra(float(band_nm[0]), float(band_nm[1]), str(flash_spectrum))


@lru_cache(maxsize=4)
def _photon_spectra(lo: float, hi: float, flash_spectrum: str):
    grid = np.arange(lo, hi + 1e-9, 0.5)
    wl, e = solar_spectrum()
    out = (grid, np.interp(grid, wl, e) * grid, spectrum(flash_spectrum, grid) * grid)
    for a in out:
        a.setflags(write=False)
    return out


def sun_direction_target(azimuth_deg: float, elevation_deg: float) -> np.ndarray:
    """Unit vector toward the sun in the target frame, shape (3,): elevation from the pattern
    plane toward +z (the face normal, toward a head-on camera), azimuth from +x toward +y."""
    for name, v, lim in (("sun azimuth", azimuth_deg, 360.0), ("sun elevation", elevation_deg, 90.0)):
        if not (np.isfinite(float(v)) and -lim <= float(v) <= lim):
            raise InputError(f"{name}: expected -{lim:g} to {lim:g} deg, got {v!r}")
    a, e = np.deg2rad(float(azimuth_deg)), np.deg2rad(float(elevation_deg))
    return np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])


def sun_in_image(camera, R_cam_target, direction_target, margin_px: float = 0.0) -> bool:
    """Whether the sun's disk (its centre within a disk radius plus ``margin_px``) projects into the
    image of ``camera`` at the attitude ``R_cam_target``, the sun toward ``direction_target``."""
    d = np.asarray(R_cam_target, float) @ np.asarray(direction_target, float)  # camera frame
    if d[2] <= 0:
        return False
    uv = camera.project(d[None, :] * 1e6)[0]
    m = float(np.sqrt(camera.fx * camera.fy)) * np.tan(np.deg2rad(SUN_ANGULAR_DIAMETER_DEG)) + margin_px
    return bool(-m <= uv[0] <= camera.width - 1 + m and -m <= uv[1] <= camera.height - 1 + m)


def sun_disk_to_world(direction) -> np.ndarray:
    """The 4x4 ``to_world`` of Mitsuba's unit ``disk`` that is the sun: centred
    :data:`SUN_DISTANCE_M` along ``direction``, radius the sun's angular radius at that
    distance, facing the target origin (its normal ``-direction``; a right-handed frame)."""
    d = np.asarray(direction, float)
    d = d / np.linalg.norm(d)
    n = -d
    a = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(a, n)
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    r = SUN_DISTANCE_M * np.tan(np.deg2rad(0.5 * SUN_ANGULAR_DIAMETER_DEG))
    M = np.eye(4)
    M[:3, 0], M[:3, 1], M[:3, 2] = u * r, v * r, n
    M[:3, 3] = d * SUN_DISTANCE_M
    return M
