"""The sun and the Earth seen from an orbit: the light a target on orbit gets, from its inertial state.

Pure numpy, with astropy imported inside :func:`sun_direction_gcrs` only (the ``orbit`` extra; heavy).
Nothing here needs Basilisk; the inputs are Basilisk's inertial state (``r_BN_N``, ``v_BN_N``, m and
m/s) and an attitude as a direction cosine matrix, and the outputs are the scene's ``--sun-deg AZ,EL``
and ``--earth-deg AZ,EL`` (:mod:`svgs_sim.sim.scene`) and whether the target is in eclipse.

- **Sun**: the direction from the Earth's centre toward the sun at a fixed epoch
  (:data:`SUN_EPOCH_UTC`), from astropy's built-in ephemeris, in GCRS. Over one docking (an hour or
  two) the sun moves ~0.04 deg/h along the ecliptic: it is taken as fixed (ASSUMPTION). Its
  parallax between the Earth's centre and a spacecraft 6 800 km from it is under 0.003 deg.
- **Frames**: GCRS's axes are the ICRS's; Basilisk's inertial frame ``N`` is SPICE's ``J2000`` when
  it takes the planets from SPICE, which differs from the ICRS by the frame bias (< 0.03 arcsec).
  astropy's GCRS direction is the apparent one (with the annual aberration, 20 arcsec), SPICE's the
  geometric one: both far below anything the renderer resolves, so GCRS is used as Basilisk's ``N``.
- **Eclipse**: the cylindrical shadow of a sun at infinity, umbra only, with the Earth's mean radius
  (:func:`svgs_sim.render.earth.in_eclipse`, :data:`svgs_sim.render.earth.EARTH_RADIUS_M`): the
  target is eclipsed when the sun's centre is inside the Earth's disk seen from it. Basilisk's
  ``eclipse`` module models the penumbra (the sun's 0.53 deg disk partly hidden, 8-10 s of a
  400 km orbit) with the Earth's equatorial radius (6 378.1366 km): our entry and exit fall inside
  its penumbra, ~3 s from its half-light points at 400 km because of the 7 km between the two
  radii (``tests/test_orbit_light.py`` measures it).
- **Angles**: azimuth from the target's +x toward +y, elevation from its x-y plane (the pattern's
  plane) toward +z, so a direction is ``(cos el cos az, cos el sin az, sin el)``
  (:func:`svgs_sim.render.sun.sun_direction_target`); azimuth in (-180, 180] deg.
"""

from __future__ import annotations

import warnings
from functools import lru_cache

import numpy as np

from svgs_sim.base.errors import InputError
from svgs_sim.render.earth import EARTH_RADIUS_M, earth_half_angle_deg, in_eclipse

__all__ = ["SUN_EPOCH_UTC", "azimuth_elevation_deg", "beta_angle_deg", "sun_and_earth_in_target", "sun_direction_gcrs"]

#: The epoch of the sun's direction, UTC (ISO 8601). Fixed, so that runs are reproducible (the same
#: orbit gives the same light on any day it is run); near the March equinox of 2026 (20 March,
#: 14:46 UTC), where the sun crosses the equator's plane, within 0.5 deg of GCRS's +x.
SUN_EPOCH_UTC = "2026-03-20T12:00:00"


def _vec3(x, name: str) -> np.ndarray:
    try:
        a = np.asarray(x, float)
    except (TypeError, ValueError):
        raise InputError(f"{name}: expected a finite 3-vector, got {x!r}") from None
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise InputError(f"{name}: expected a finite 3-vector, got {x!r}")
    return a


def _direction(x, name: str) -> np.ndarray:
    a = _vec3(x, name)
    n = float(np.linalg.norm(a))
    if n == 0.0:
        raise InputError(f"{name}: expected a nonzero 3-vector, got {x!r}")
    return a / n


def azimuth_elevation_deg(v) -> tuple[float, float]:
    """Azimuth (from +x toward +y, in (-180, 180]) and elevation (toward +z) of a unit vector, deg."""
    az = float(np.degrees(np.arctan2(v[1], v[0])))
    el = float(np.degrees(np.arcsin(np.clip(v[2], -1.0, 1.0))))
    return az, el


@lru_cache(maxsize=16)
def _sun_gcrs(epoch_utc: str) -> tuple[float, float, float]:
    from astropy.coordinates import GCRS, get_body
    from astropy.time import Time
    from astropy.utils import iers

    # Never the network: no IERS or leap-second downloads (astropy's bundled tables suffice: GCRS
    # needs no UT1 or polar motion), and no staleness warning once the bundled leap-second table
    # expires (a leap second added after it would shift the sun by < 0.0003 deg).
    with iers.conf.set_temp("auto_download", False), iers.conf.set_temp("auto_max_age", None), \
            warnings.catch_warnings():
        # An epoch past the bundled leap-second table (or before 1960) makes ERFA warn of a "dubious
        # year": UTC there is unknown by the leap seconds yet to be announced, a second or two at most
        # (< 0.001 deg of the sun's motion); the direction is still good.
        warnings.filterwarnings("ignore", message=r'ERFA function "\w+" yielded .*"dubious year')
        try:
            t = Time(epoch_utc, scale="utc")
        except ValueError as exc:
            raise InputError(f"epoch_utc: not a UTC date and time astropy reads ({exc}): {epoch_utc!r}") from exc
        sun = get_body("sun", t).transform_to(GCRS(obstime=t))
        xyz = np.asarray(sun.cartesian.xyz.to_value("m"), float)
    s = xyz / np.linalg.norm(xyz)
    return float(s[0]), float(s[1]), float(s[2])


def sun_direction_gcrs(epoch_utc: str = SUN_EPOCH_UTC) -> np.ndarray:
    """The unit vector from the Earth's centre toward the sun, GCRS components.

    GCRS is taken as Basilisk's inertial frame ``N`` (SPICE's ``J2000``): see the module docstring.
    astropy's built-in ephemeris (no download; ~0.01 deg, far finer than needed), the IERS and
    leap-second downloads off.

    Parameters
    ----------
    epoch_utc : str
        The epoch, UTC, any form astropy's ``Time`` reads (ISO 8601: ``"2026-03-20T12:00:00"``);
        default :data:`SUN_EPOCH_UTC`, fixed so that runs are reproducible.

    Returns
    -------
    ndarray, shape (3,)
        Unit vector toward the sun, GCRS.

    Raises
    ------
    InputError
        ``epoch_utc`` is not a date astropy reads.
    """
    return np.array(_sun_gcrs(str(epoch_utc)))


def beta_angle_deg(r_N_m, v_N_m_s, sun_N) -> float:
    """The beta angle: the sun's elevation above the orbit plane, deg.

    ``asin(h . s)``, ``h`` the unit orbit normal ``r x v / |r x v|`` and ``s`` the unit direction
    toward the sun: +90 when the sun is along the orbit normal, 0 when it is in the plane, negative
    on the other side.

    Parameters
    ----------
    r_N_m : array_like, shape (3,)
        The spacecraft's position from the Earth's centre, inertial components, m.
    v_N_m_s : array_like, shape (3,)
        Its inertial velocity, m/s.
    sun_N : array_like, shape (3,)
        The direction toward the sun, inertial components (any nonzero length: normalised).

    Returns
    -------
    float
        Beta angle, deg, in [-90, 90].
    """
    h = np.cross(_vec3(r_N_m, "r_N_m"), _vec3(v_N_m_s, "v_N_m_s"))
    if float(np.linalg.norm(h)) == 0.0:
        raise InputError("r_N_m, v_N_m_s: parallel (or zero): no orbit plane")
    h_hat = h / np.linalg.norm(h)
    s = _direction(sun_N, "sun_N")
    return float(np.degrees(np.arcsin(np.clip(float(h_hat @ s), -1.0, 1.0))))


def sun_and_earth_in_target(r_target_N_m, dcm_target_N, sun_N) -> dict:
    """The directions toward the sun and the Earth's centre in the target frame, and the eclipse.

    Parameters
    ----------
    r_target_N_m : array_like, shape (3,)
        The target's position from the Earth's centre, inertial components (Basilisk's ``r_BN_N``), m.
    dcm_target_N : array_like, shape (3, 3)
        The rotation from inertial to target components, ``v_T = dcm_target_N @ v_N`` (Basilisk's
        ``[BN]`` when the target frame is the body frame; compose with a mount's matrix otherwise).
    sun_N : array_like, shape (3,)
        The direction toward the sun, inertial components (any nonzero length: normalised; the sun
        is at infinity, so the same from the Earth's centre and from the target).

    Returns
    -------
    dict
        ``sun_azimuth_deg``, ``sun_elevation_deg``, ``earth_azimuth_deg``, ``earth_elevation_deg``
        (float, deg: the scene's ``--sun-deg`` and ``--earth-deg``, see the module docstring);
        ``eclipsed`` (bool: the sun's centre behind the Earth, cylindrical shadow, mean radius
        :data:`~svgs_sim.render.earth.EARTH_RADIUS_M`); ``altitude_m`` (float: ``|r| - R``, m);
        ``earth_half_angle_deg`` (float: the Earth's apparent radius from the target, deg).

    Raises
    ------
    InputError
        A vector that is not a finite 3-vector, a matrix that is not a rotation, or a target at
        or below the Earth's surface.
    """
    r = _vec3(r_target_N_m, "r_target_N_m")
    dcm = np.asarray(dcm_target_N, float)
    if dcm.shape != (3, 3) or not np.all(np.isfinite(dcm)) or not np.allclose(dcm @ dcm.T, np.eye(3), atol=1e-6) \
            or np.linalg.det(dcm) < 0:
        raise InputError(f"dcm_target_N: expected a 3x3 rotation matrix, got {dcm_target_N!r}")
    s_N = _direction(sun_N, "sun_N")
    altitude_m = float(np.linalg.norm(r)) - EARTH_RADIUS_M
    if not altitude_m > 0.0:
        raise InputError(f"r_target_N_m: {np.linalg.norm(r):.0f} m from the Earth's centre: at or below its "
                         f"surface ({EARTH_RADIUS_M:.0f} m)")
    e_N = -r / np.linalg.norm(r)
    sun_T, earth_T = dcm @ s_N, dcm @ e_N
    sun_az, sun_el = azimuth_elevation_deg(sun_T / np.linalg.norm(sun_T))
    earth_az, earth_el = azimuth_elevation_deg(earth_T / np.linalg.norm(earth_T))
    return {
        "sun_azimuth_deg": sun_az, "sun_elevation_deg": sun_el,
        "earth_azimuth_deg": earth_az, "earth_elevation_deg": earth_el,
        "eclipsed": in_eclipse(s_N, e_N, altitude_m),
        "altitude_m": altitude_m,
        "earth_half_angle_deg": earth_half_angle_deg(altitude_m),
    }
