"""Indoor air turbulence over the lab's path: the image motion of each retro spot.

Light from a retroreflector reaches the phone's aperture through the lab's air; temperature
fluctuations (refractive-index structure constant ``C_n^2``, m^-2/3) tilt the arriving wave
front and move the spot's image. The exposures are short and the eddies crossing a
millimetre aperture are larger than it, so each exposure sees a frozen tilt (an upper bound:
averaging over an exposure that is long against the aperture's crossing time only lowers it). A
second reason it is an upper bound: the phone's pupil (1.3-1.4 mm) is about the Fresnel scale
sqrt(lambda L) (1.7 mm at 5 m, 4.1 mm at 30 m), where the geometric-optics formulas below overstate
the variance by up to about 2x, and an indoor inner scale larger than the pupil lowers it further.

Angle of arrival, one axis, circular aperture of diameter ``D`` (Kolmogorov turbulence; Tatarskii;
Andrews & Phillips, *Laser Beam Propagation through Random Media*, 2nd ed., 2005, ch. 6)::

    plane wave        sigma_a^2 = 2.91 D^(-1/3) integral_0^L C_n^2(z) dz
    spherical wave    sigma_a^2 = 2.91 D^(-1/3) integral_0^L C_n^2(z) (z / L)^(5/3) dz
                                = 2.91 * 3/8 * C_n^2 L D^(-1/3)   (uniform C_n^2)

with ``z`` measured from the source (a retro spot is a point source at the target; a layer at
``z`` is crossed by the cone from the source to the aperture over a footprint ``D z / L``).

Two spots. In each layer the two cones cross the air ``s |P_i - P_j|`` apart (``s`` the
fraction of the way from the camera), on footprints ``D (1 - s)``; their tilts are correlated
as two apertures of that size that far apart. The tilt correlations of two apertures of
diameter ``D`` at separation ``d >> D`` (Sarazin & Roddier 1990, A&A 227, 294, the DIMM
formulas; their differential variances ``2 lambda^2 r0^(-5/3) (0.179 D^(-1/3) - 0.0968 d^(-1/3))``
along the separation and ``... - 0.145 d^(-1/3)`` across it)::

    longitudinal   0.541 (D / d)^(1/3)          transverse   0.810 (D / d)^(1/3)

capped at 1 where ``d`` falls below about the footprint (the last ~D / |P_i - P_j| of the path:
well under 1 % of the variance for spots 27.5 cm apart). The covariance of all spots' tilts is
the path integral of the layers' covariances (:func:`tilt_covariance`); what differs between the
spots (the differential part) distorts the pattern, the common part turns it.
"""

from __future__ import annotations

import numpy as np

from svgs_sim.base.errors import InputError

#: One-axis angle-of-arrival coefficient (plane wave, Kolmogorov): sigma^2 = 2.91 C_n^2 L D^(-1/3).
AOA_COEFFICIENT = 2.91
#: The DIMM correlation coefficients (Sarazin & Roddier 1990): 0.0968 / 0.179 and 0.145 / 0.179.
CORR_LONGITUDINAL = 0.0968 / 0.179
CORR_TRANSVERSE = 0.145 / 0.179


def _check(cn2_m23: float, aperture_m: float) -> None:
    if not (np.isfinite(cn2_m23) and cn2_m23 >= 0):
        raise InputError(f"cn2_m23: expected C_n^2 >= 0 in m^-2/3, got {cn2_m23!r}")
    if not (np.isfinite(aperture_m) and aperture_m > 0):
        raise InputError(f"aperture_m: expected a positive aperture diameter in metres, got {aperture_m!r}")


def aoa_variance_rad2(cn2_m23: float, path_m: float, aperture_m: float, wave: str = "spherical") -> float:
    """One-axis angle-of-arrival variance, rad^2, of a uniform path (module formulas).

    Parameters
    ----------
    cn2_m23 : float
        Refractive-index structure constant, m^-2/3.
    path_m : float
        Path length, m.
    aperture_m : float
        Receiver aperture diameter, m.
    wave : {"spherical", "plane"}
        A point source at the path's far end, or a plane wave.
    """
    _check(cn2_m23, aperture_m)
    if wave not in ("spherical", "plane"):
        raise InputError(f"wave: expected 'spherical' or 'plane', got {wave!r}")
    factor = 3.0 / 8.0 if wave == "spherical" else 1.0
    return AOA_COEFFICIENT * factor * float(cn2_m23) * float(path_m) * float(aperture_m) ** (-1.0 / 3.0)


def tilt_covariance(points_cam_m, aperture_m: float, cn2_m23: float, n_layers: int = 400) -> np.ndarray:
    """Covariance of the spots' angles of arrival, rad^2.

    Parameters
    ----------
    points_cam_m : array_like, shape (N, 3)
        The point sources (the retro spots' apparent positions) in the camera frame, m
        (OpenCV axes: +z the boresight).
    aperture_m : float
        The camera's entrance pupil diameter, m.
    cn2_m23 : float
        Uniform C_n^2 along the path, m^-2/3.
    n_layers : int
        Midpoint layers of the path integral.

    Returns
    -------
    ndarray, shape (2N, 2N)
        Rows/columns ``(a_x0, a_y0, a_x1, a_y1, ...)``: the tilts about the camera's x and y
        image axes of each spot. Symmetric positive semi-definite (the layers' small negative
        eigenvalues from the capped correlation are clipped).
    """
    _check(cn2_m23, aperture_m)
    P = np.asarray(points_cam_m, float)
    if P.ndim != 2 or P.shape[1] != 3 or not np.all(np.isfinite(P)) or np.any(P[:, 2] <= 0):
        raise InputError("points_cam_m: expected (N, 3) finite points in front of the camera (z > 0)")
    n = len(P)
    cov = np.zeros((2 * n, 2 * n))
    if cn2_m23 == 0:
        return cov
    L = np.linalg.norm(P, axis=1)
    D = float(aperture_m)
    s = (np.arange(n_layers) + 0.5) / n_layers  # fraction of the way from the camera to the sources
    # the layer's weight per source: 2.91 D^-1/3 C_n^2 dz (z/L)^(5/3), z = (1 - s) L from the source
    Lm = float(L.mean())
    w = AOA_COEFFICIENT * cn2_m23 * D ** (-1.0 / 3.0) * (Lm / n_layers) * (1.0 - s) ** (5.0 / 3.0)
    foot = D * (1.0 - s)  # the cones' footprints
    for i in range(n):
        cov[2 * i:2 * i + 2, 2 * i:2 * i + 2] = np.eye(2) * w.sum()
        for j in range(i + 1, n):
            dp = (P[i] - P[j])[:2]
            dist = np.linalg.norm(dp)
            if dist == 0:
                block = np.eye(2) * w.sum()
            else:
                u = dp / dist
                r = s * dist / foot
                cl = np.minimum(1.0, CORR_LONGITUDINAL * r ** (-1.0 / 3.0))
                ct = np.minimum(1.0, CORR_TRANSVERSE * r ** (-1.0 / 3.0))
                Pu = np.outer(u, u)
                block = (w * cl).sum() * Pu + (w * ct).sum() * (np.eye(2) - Pu)
            cov[2 * i:2 * i + 2, 2 * j:2 * j + 2] = block
            cov[2 * j:2 * j + 2, 2 * i:2 * i + 2] = block.T
    lam, V = np.linalg.eigh(cov)
    return (V * np.clip(lam, 0.0, None)) @ V.T


def draw_tilts(cov: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """One frozen draw of the spots' tilts, rad, shape (N, 2), from :func:`tilt_covariance`."""
    lam, V = np.linalg.eigh(np.asarray(cov, float))
    z = rng.standard_normal(len(lam))
    return (V @ (np.sqrt(np.clip(lam, 0.0, None)) * z)).reshape(-1, 2)


def image_shifts_px(points_cam_m, focal_px: float, aperture_m: float, cn2_m23: float,
                    rng: np.random.Generator) -> np.ndarray:
    """One exposure's image motion of each spot, px, shape (N, 2) ``(du, dv)``: the tilts of
    :func:`draw_tilts` times the focal length in pixels (small angles)."""
    return float(focal_px) * draw_tilts(tilt_covariance(points_cam_m, aperture_m, cn2_m23), rng)
