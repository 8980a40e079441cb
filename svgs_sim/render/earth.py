"""The Earth on orbit, as the renderer draws it: a Lambertian sphere lit by the sun, seen from the
target's altitude, as an environment map.

The Earth is 400 km or more away and the camera a few metres from the target, so its parallax
over the scene is below 1e-3 deg: it is a radiance that depends on the direction only, and the
renderer takes it as Mitsuba's ``envmap`` emitter. The map's texels are computed here in closed
form, in double precision (the ray from the target toward the texel's direction meets the sphere
or not; where it does, the surface's radiance is ``albedo E max(0, n . s) / pi``, ``n`` the
surface normal, ``s`` the sun's direction, ``E`` the sun's irradiance in band), so the sphere's
6.4e6 m never meets single precision. The camera sees the map behind the target; the path
integrator samples it as a light, which is the Earth shine on the target.

The map is laid out with the Earth's centre at its pole, where the lat-long grid is finest across
the limb: 2048 rows over 180 deg put the limb within 0.09 deg (about 4 px of a phone's pixel).

- **Radius**: :data:`EARTH_RADIUS_M` (IUGG mean radius; the oblateness, 21 km, is ignored:
  ASSUMPTION). The Earth's apparent half-angle from altitude ``h`` is ``asin(R / (R + h))``:
  70.2 deg from 400 km.
- **Albedo**: one Lambertian reflectance for the whole disk (``--earth-albedo``, default 0.3,
  the Earth's Bond albedo, 0.29-0.31 from CERES: Stephens et al. (2015), Rev. Geophys. 53,
  141-163; the study sweeps 0.05 for open ocean and 0.8 for a bright cloud deck (ASSUMPTION: the
  values' order, from the same review's ranges); the atmosphere's limb glow, its Rayleigh colour
  and the sun's glint off water are not modelled (ASSUMPTION).
- **Eclipse**: the target is in the Earth's shadow when the sun's direction lies inside the
  Earth's disk seen from the target (:func:`in_eclipse`): the cylindrical shadow model for a sun
  at infinity, umbra only (the penumbra, where the sun's 0.53 deg disk is partly hidden, lasts
  ~8 s of a 400 km orbit and is taken as sunlit: ASSUMPTION). In eclipse the sun lights neither
  the target nor the camera's view of it; the Earth's day side, where it is in view, still shines.
"""

from __future__ import annotations

import functools

import numpy as np

from svgs_sim.base.errors import InputError

#: The Earth's mean radius, m (IUGG: R1 = 6 371 008.8 m).
EARTH_RADIUS_M = 6371008.8
#: Default altitude of the target above the Earth's surface, m (the ISS's, ~400 km).
DEFAULT_ALTITUDE_M = 400e3
#: Default Lambertian albedo of the Earth's disk (the Bond albedo, see the module docstring).
DEFAULT_ALBEDO = 0.3
#: Rows of the environment map (columns: twice as many).
MAP_ROWS = 2048


def earth_half_angle_deg(altitude_m: float) -> float:
    """The Earth's apparent angular radius from ``altitude_m`` above its surface, deg."""
    return float(np.degrees(np.arcsin(EARTH_RADIUS_M / (EARTH_RADIUS_M + float(altitude_m)))))


def _unit(v, name: str) -> np.ndarray:
    d = np.asarray(v, float).reshape(-1)
    if d.shape != (3,) or not np.all(np.isfinite(d)) or abs(np.linalg.norm(d) - 1.0) > 1e-6:
        raise InputError(f"{name}: expected a unit 3-vector, got {v!r}")
    return d / np.linalg.norm(d)


def in_eclipse(sun_direction, earth_direction, altitude_m: float) -> bool:
    """Whether the Earth hides the sun from the target (see the module docstring).

    Parameters
    ----------
    sun_direction, earth_direction : array_like, shape (3,)
        Unit vectors toward the sun and toward the Earth's centre, any one frame.
    altitude_m : float
        The target's altitude above the Earth's surface, m.

    Returns
    -------
    bool
    """
    s, e = _unit(sun_direction, "sun_direction"), _unit(earth_direction, "earth_direction")
    angle = np.degrees(np.arccos(np.clip(float(s @ e), -1.0, 1.0)))
    return bool(angle < earth_half_angle_deg(altitude_m))


def map_frame(earth_direction) -> np.ndarray:
    """The 3x3 rotation from the map's frame to the target frame: the map's +y (its pole, Mitsuba's
    ``envmap`` convention) toward the Earth's centre."""
    e = _unit(earth_direction, "earth_direction")
    a = np.array([1.0, 0.0, 0.0]) if abs(e[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
    x = np.cross(e, a)
    x /= np.linalg.norm(x)
    z = np.cross(x, e)
    return np.stack([x, e, z], axis=1)


def map_directions(rows: int = MAP_ROWS, frame=np.eye(3)) -> np.ndarray:
    """The direction of every texel centre of a lat-long map, in the frame ``frame`` maps to.

    Mitsuba's ``envmap`` looks a direction ``v`` (map frame) up at ``u = atan2(v_x, -v_z) / 2 pi``,
    ``v = acos(v_y) / pi``; so a texel ``(u, v)`` is ``(sin t sin p, cos t, -sin t cos p)`` with
    ``t = pi v``, ``p = 2 pi u``.

    Returns
    -------
    ndarray, shape (rows, 2 rows, 3)
    """
    cols = 2 * rows
    t = np.pi * (np.arange(rows) + 0.5) / rows
    p = 2 * np.pi * (np.arange(cols) + 0.5) / cols
    st, ct = np.sin(t)[:, None], np.cos(t)[:, None]
    d = np.stack([st * np.sin(p)[None], np.broadcast_to(ct, (rows, cols)), -st * np.cos(p)[None]], -1)
    return d @ np.asarray(frame, float).T


def earth_radiance(directions, earth_direction, sun_direction, altitude_m: float, albedo: float,
                   sun_irradiance_w_m2: float, uniform_radiance_w_m2_sr: float | None = None) -> np.ndarray:
    """The Earth's radiance toward the target along each direction, W m^-2 sr^-1 in band (0 where a
    direction misses the Earth).

    Parameters
    ----------
    directions : ndarray, shape (..., 3)
        Unit directions from the target, the target frame.
    earth_direction, sun_direction : array_like, shape (3,)
        Unit vectors toward the Earth's centre and the sun (``sun_direction`` None: the Earth unlit).
    altitude_m : float
    albedo : float
        Lambertian reflectance of the surface, 0-1.
    sun_irradiance_w_m2 : float
        The sun's irradiance in band at normal incidence, W/m^2.
    uniform_radiance_w_m2_sr : float, optional
        For checks: the whole disk at this radiance (no sun, no albedo).

    Returns
    -------
    ndarray, shape (...)
    """
    e = _unit(earth_direction, "earth_direction")
    w = np.asarray(directions, float)
    R = EARTH_RADIUS_M
    p = -(R + float(altitude_m)) * e  # the target, from the Earth's centre
    b = w @ p
    disc = b * b - (p @ p - R * R)
    hit = (disc >= 0) & (b < 0)
    if uniform_radiance_w_m2_sr is not None:
        return np.where(hit, float(uniform_radiance_w_m2_sr), 0.0)
    if sun_direction is None:
        return np.zeros(w.shape[:-1])
    s = _unit(sun_direction, "sun_direction")
    dist = -b - np.sqrt(np.maximum(disc, 0.0))
    q = p + dist[..., None] * w
    cos_sun = (q @ s) / R
    return np.where(hit, float(albedo) * float(sun_irradiance_w_m2) * np.maximum(cos_sun, 0.0) / np.pi, 0.0)


@functools.lru_cache(maxsize=1)
def _earth_hits(earth_direction: tuple, altitude_m: float, rows: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The map's frame, the flat indices of the texels whose direction meets the Earth and the
    points they meet, from the Earth's centre (m, float64, shape (n, 3)): what the map's radiance
    needs besides the sun. Kept for the last two geometries (a sun that moves over an orbit's phase
    recomputes only the cosine: :func:`earth_map`; about 100 MB for 2048 rows); the arithmetic is
    :func:`earth_radiance`'s."""
    e = _unit(earth_direction, "earth_direction")
    frame = map_frame(e)
    w = map_directions(rows, frame).reshape(-1, 3)
    R = EARTH_RADIUS_M
    p = -(R + float(altitude_m)) * e
    b = w @ p
    disc = b * b - (p @ p - R * R)
    hit = np.flatnonzero((disc >= 0) & (b < 0))
    dist = -b[hit] - np.sqrt(np.maximum(disc[hit], 0.0))
    q = p + dist[:, None] * w[hit]
    return frame, hit, q


def earth_map(earth_direction, sun_direction, altitude_m: float, albedo: float, sun_irradiance_w_m2: float,
              uniform_radiance_w_m2_sr: float | None = None, rows: int = MAP_ROWS) -> tuple[np.ndarray, np.ndarray]:
    """The environment map of the Earth and its frame: :func:`earth_radiance` at each texel centre's
    direction (the geometry kept between calls for the same Earth, :func:`_earth_hits`).

    Returns
    -------
    radiance : ndarray of float32, shape (rows, 2 rows)
        W m^-2 sr^-1 in band, at each texel centre's direction.
    to_world : ndarray, shape (4, 4)
        The map's ``to_world`` (a rotation): its pole toward the Earth's centre.
    """
    e = _unit(earth_direction, "earth_direction")
    frame, hit, q = _earth_hits(tuple(float(x) for x in e), float(altitude_m), int(rows))
    rad = np.zeros(rows * 2 * rows)
    if uniform_radiance_w_m2_sr is not None:
        rad[hit] = float(uniform_radiance_w_m2_sr)
    elif sun_direction is not None:
        s = _unit(sun_direction, "sun_direction")
        cos_sun = (q @ s) / EARTH_RADIUS_M
        rad[hit] = float(albedo) * float(sun_irradiance_w_m2) * np.maximum(cos_sun, 0.0) / np.pi
    M = np.eye(4)
    M[:3, :3] = frame
    return rad.reshape(rows, 2 * rows).astype(np.float32), M


def earth_in_image(camera, R_cam_target, earth_direction, altitude_m: float, grid: int = 24) -> bool:
    """Whether any of a ``grid`` x ``grid`` set of pixel directions over the image (borders
    included) sees the Earth, at the attitude ``R_cam_target``."""
    u = np.linspace(0, camera.width - 1, grid)
    v = np.linspace(0, camera.height - 1, grid)
    uv = np.stack(np.meshgrid(u, v), -1).reshape(-1, 2)
    xy = camera.pixels_to_normalized(uv)
    d_cam = np.concatenate([xy, np.ones((len(xy), 1))], 1)
    d_cam /= np.linalg.norm(d_cam, axis=1, keepdims=True)
    d_target = d_cam @ np.asarray(R_cam_target, float)  # R^T d
    return bool(np.any(earth_radiance(d_target, earth_direction, None, altitude_m, 0.0, 0.0, 1.0) > 0))
