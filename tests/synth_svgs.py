"""Synthetic SVGS frames for tests and benchmarks: Gaussian spots at known sub-pixel centres.

Pure numpy (no renderer): each target is a pixel-integrated isotropic Gaussian (the exact
integral of the profile over each pixel's square, via ``erf``), so the true centroid of the
spot is its centre. Distractors (noise blobs, glints, hot pixels) are added at random places,
some of them near the pattern. Noise is Gaussian read noise (plus the background's shot noise)
everywhere and the spots' photon noise (Gaussian approximation of Poisson statistics) in their
windows. The result is quantised to 8 or 16 bit (clipped at full scale, i.e. saturating),
or kept as float, optionally as a 3-channel colour image.

Pixel convention: OpenCV's - pixel centres at integer coordinates, ``u`` to the right,
``v`` down; pixel ``(v, u)`` covers ``[u - 0.5, u + 0.5] x [v - 0.5, v + 0.5]``.

Every random draw comes from ``np.random.default_rng(seed)`` built inside the call.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.special import erf

from svgs_sim.base.errors import InputError
from svgs_sim.svgs.frames import pose_from_scenario, sample_envelope_scenario
from svgs_sim.base.profiles import Camera, Pattern

#: Half-width of a spot's drawing window in Gaussian sigmas (the flux beyond is < 1e-12).
WINDOW_SIGMAS = 7.0

_DTYPES = {"uint8": np.uint8, "uint16": np.uint16, "float32": np.float32, "float64": np.float64}


def _rng(seed):
    return seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)


def _pixel_integrals(lo: int, n: int, centre: float, sigma: float) -> np.ndarray:
    """Fraction of a 1-D Gaussian's mass in pixels ``lo .. lo + n - 1``, shape (n,)."""
    edges = (np.arange(lo, lo + n + 1) - 0.5 - centre) / (np.sqrt(2.0) * sigma)
    return 0.5 * np.diff(erf(edges))


def draw_gaussian_spots(image: np.ndarray, centers_px, sigma_px, flux, *, photon_gain=None, rng=None) -> np.ndarray:
    """Add pixel-integrated isotropic Gaussian spots to ``image`` in place.

    Parameters
    ----------
    image : ndarray, shape (H, W), float
        Image to add to (electrons or DN, the unit of ``flux``).
    centers_px : array_like, shape (N, 2)
        Spot centres ``(u, v)`` in pixels.
    sigma_px : float or array_like, shape (N,)
        Gaussian sigma of each spot, pixels.
    flux : float or array_like, shape (N,)
        Total flux of each spot (sum over all pixels of an untruncated spot).
    photon_gain : float, optional
        If given, add photon noise with variance ``signal / photon_gain`` per pixel
        (Gaussian approximation of Poisson noise; ``photon_gain`` in photo-electrons per
        image unit).
    rng : numpy.random.Generator, optional
        Needed when ``photon_gain`` is given.

    Returns
    -------
    image : ndarray, shape (H, W)
        The same array.
    """
    c = np.asarray(centers_px, float).reshape(-1, 2)
    n = c.shape[0]
    sig = np.broadcast_to(np.asarray(sigma_px, float), (n,))
    fl = np.broadcast_to(np.asarray(flux, float), (n,))
    H, W = image.shape
    for (u, v), s, f in zip(c, sig, fl):
        r = int(np.ceil(WINDOW_SIGMAS * s)) + 1
        u0, u1 = max(int(np.floor(u)) - r, 0), min(int(np.floor(u)) + r + 2, W)
        v0, v1 = max(int(np.floor(v)) - r, 0), min(int(np.floor(v)) + r + 2, H)
        if u1 <= u0 or v1 <= v0:
            continue
        spot = f * np.outer(_pixel_integrals(v0, v1 - v0, v, s), _pixel_integrals(u0, u1 - u0, u, s))
        if photon_gain is not None:
            spot = spot + np.sqrt(spot / photon_gain) * rng.standard_normal(spot.shape)
        image[v0:v1, u0:u1] += spot
    return image


def draw_elliptical_spots(image: np.ndarray, centers_px, sigma_major_px, sigma_minor_px, angle_rad, peak) -> np.ndarray:
    """Add point-sampled elongated Gaussian blobs (glints) to ``image`` in place.

    Parameters
    ----------
    image : ndarray, shape (H, W), float
    centers_px : array_like, shape (N, 2)
    sigma_major_px, sigma_minor_px, angle_rad, peak : float or array_like, shape (N,)
        Sigmas along the major/minor axes (px), angle of the major axis from ``+u`` (rad),
        and the peak value.

    Returns
    -------
    image : ndarray, shape (H, W)
    """
    c = np.asarray(centers_px, float).reshape(-1, 2)
    n = c.shape[0]
    sa, sb, ang, pk = (np.broadcast_to(np.asarray(x, float), (n,))
                       for x in (sigma_major_px, sigma_minor_px, angle_rad, peak))
    H, W = image.shape
    for (u, v), a, b, t, p in zip(c, sa, sb, ang, pk):
        r = int(np.ceil(5.0 * a)) + 1
        u0, u1 = max(int(round(u)) - r, 0), min(int(round(u)) + r + 1, W)
        v0, v1 = max(int(round(v)) - r, 0), min(int(round(v)) + r + 1, H)
        if u1 <= u0 or v1 <= v0:
            continue
        yy, xx = np.mgrid[v0:v1, u0:u1]
        dx, dy = xx - u, yy - v
        ca, sn = np.cos(t), np.sin(t)
        p_ = dx * ca + dy * sn
        q_ = -dx * sn + dy * ca
        image[v0:v1, u0:u1] += p * np.exp(-0.5 * ((p_ / a) ** 2 + (q_ / b) ** 2))
    return image


def quantize(image: np.ndarray, dtype="uint8", *, full_scale=None, colour=False) -> np.ndarray:
    """Clip and round a float image to an output type (saturating at full scale).

    Parameters
    ----------
    image : ndarray, shape (H, W), float
    dtype : {"uint8", "uint16", "float32", "float64"}
    full_scale : float, optional
        Saturation level; default the integer type's maximum, no clipping for floats.
    colour : bool
        Return an (H, W, 3) image with the same value in each channel (its luminance is
        the grey image for any luminance weights summing to 1).

    Returns
    -------
    ndarray, shape (H, W) or (H, W, 3)
    """
    if dtype not in _DTYPES:
        raise InputError(f"dtype: expected one of {sorted(_DTYPES)}, got {dtype!r}")
    dt = _DTYPES[dtype]
    if np.issubdtype(dt, np.integer):
        top = np.iinfo(dt).max if full_scale is None else min(float(full_scale), np.iinfo(dt).max)
        x = cv2.min(cv2.max(np.asarray(image, np.float32), 0.0), float(top))
        if dt == np.uint8:
            out = cv2.convertScaleAbs(x)  # rounds to nearest, x >= 0 here
        else:
            x += 0.5
            out = x.astype(dt)
    else:
        out = image.astype(dt) if full_scale is None else np.minimum(image, full_scale).astype(dt)
    if colour:
        out = np.repeat(out[..., None], 3, axis=2)
    return out


def noise_field(shape, sigma, rng, *, tile_px: int | None = 256) -> np.ndarray:
    """Zero-mean Gaussian noise of standard deviation ``sigma``, shape ``shape`` (float32).

    With ``tile_px`` the field repeats a random ``tile_px`` square (shifted by a random
    offset): statistically the same per pixel and ~20x cheaper on a multi-megapixel frame,
    which is what the detector tests need. ``tile_px=None`` draws every pixel.
    """
    H, W = shape
    if tile_px is None or (H <= tile_px and W <= tile_px):
        return (sigma * rng.standard_normal((H, W), dtype=np.float32)).astype(np.float32)
    tile = (sigma * rng.standard_normal((tile_px, tile_px), dtype=np.float32)).astype(np.float32)
    oy, ox = rng.integers(0, tile_px, 2)
    reps = (-(-(H + oy) // tile_px), -(-(W + ox) // tile_px))
    return cv2.repeat(tile, reps[0], reps[1])[oy:oy + H, ox:ox + W]


def random_envelope_pose(rng=None, *, range_interval_m=(1.0, 40.0), roll_deg=25.0, pitch_deg=25.0, yaw_deg=45.0,
                         lateral_fraction=0.15):
    """A pose drawn over the paper's test envelope.

    Range log-uniform in ``range_interval_m``; roll and pitch uniform in +/-``roll_deg``/``pitch_deg``,
    yaw in +/-``yaw_deg``; lateral offsets of the target origin uniform up to
    +/-``lateral_fraction`` of the range (see :func:`svgs_sim.svgs.frames.pose_from_scenario`).

    Returns
    -------
    R_cam_target : ndarray, shape (3, 3)
    t_cam_target_m : ndarray, shape (3,)
    scenario : dict
        ``range_m, target_x_m, target_y_m, roll_deg, pitch_deg, yaw_deg``.
    """
    sc = sample_envelope_scenario(_rng(rng), range_interval_m=range_interval_m, roll_deg=roll_deg, pitch_deg=pitch_deg, yaw_deg=yaw_deg,
                                  lateral_fraction=lateral_fraction)
    R, t = pose_from_scenario(**sc)
    return R, t, sc


@dataclass
class SynthFrame:
    """A synthetic frame and its truth.

    Attributes
    ----------
    image : ndarray, shape (H, W) or (H, W, 3)
    targets_px : ndarray, shape (n, 2)
        True spot centres ordered by pattern id, pixels.
    distractors_px : ndarray, shape (m, 2)
        Centres of the distractor blobs.
    distractor_kind : list of str, length m
        ``"spot"``, ``"glint"`` or ``"hot"`` per distractor.
    sigma_px : float
        Target spot sigma, px.
    peak : float
        Target spot peak (continuous profile), image units before quantisation.
    """

    image: np.ndarray
    targets_px: np.ndarray
    distractors_px: np.ndarray
    distractor_kind: list = field(default_factory=list)
    sigma_px: float = 1.5
    peak: float = 0.0


def _place(rng, n, shape, avoid_px, avoid_r, near_box, near_fraction, margin, max_tries=200):
    """Draw ``n`` centres, ``near_fraction`` of them inside ``near_box``, keeping clear of
    ``avoid_px`` by ``avoid_r`` (px) and of each other."""
    H, W = shape
    out = []
    pts = [np.asarray(avoid_px, float).reshape(-1, 2)]
    for k in range(n):
        near = rng.random() < near_fraction
        for _ in range(max_tries):
            if near:
                u0, v0, u1, v1 = near_box
                c = np.array([rng.uniform(u0, u1), rng.uniform(v0, v1)])
            else:
                c = np.array([rng.uniform(margin, W - 1 - margin), rng.uniform(margin, H - 1 - margin)])
            if not (margin <= c[0] <= W - 1 - margin and margin <= c[1] <= H - 1 - margin):
                continue
            allp = np.concatenate(pts + [np.asarray(out).reshape(-1, 2)])
            if allp.size == 0 or np.min(np.linalg.norm(allp - c, axis=1)) >= avoid_r:
                out.append(c)
                break
    return np.asarray(out, float).reshape(-1, 2)


def synth_frame(
    camera,
    pattern,
    R_cam_target,
    t_cam_target_m,
    *,
    sigma_px: float = 1.5,
    peak: float = 180.0,
    background: float = 6.0,
    read_noise: float = 1.5,
    photon_gain: float | None = 4.0,
    n_distractors: int = 0,
    near_fraction: float = 0.5,
    dtype: str = "uint8",
    colour: bool = False,
    full_scale=None,
    noise_tile_px: int | None = 256,
    seed=None,
) -> SynthFrame:
    """Project a pattern through a pose and draw its spots, distractors and noise.

    Parameters
    ----------
    camera : Camera or str
    pattern : Pattern or str
    R_cam_target : ndarray, shape (3, 3)
    t_cam_target_m : ndarray, shape (3,)
    sigma_px : float
        Gaussian sigma of the target spots, px.
    peak : float
        Peak of the (continuous) spot profile in image units (DN); the flux is
        ``2 pi sigma^2 peak``. Above full scale the spots saturate.
    background : float
        Mean background level, DN.
    read_noise : float
        Read noise (plus background shot noise), DN RMS, everywhere.
    photon_gain : float or None
        Photo-electrons per DN for the spots' photon noise; ``None`` for none.
    n_distractors : int
        Number of distractor blobs: round spots of random brightness and size, elongated
        glints and single hot pixels, drawn clear of the targets (so the truth stays
        unambiguous).
    near_fraction : float
        Fraction of distractors placed near the pattern (within about one pattern size).
    dtype : {"uint8", "uint16", "float32", "float64"}
    colour : bool
        Return an (H, W, 3) image.
    full_scale : float, optional
        Saturation level (default: the integer type's maximum).
    noise_tile_px : int or None
        See :func:`noise_field`.
    seed : int or numpy.random.Generator, optional

    Returns
    -------
    SynthFrame
    """
    rng = _rng(seed)
    camera = Camera.load(camera)
    pattern = Pattern.load(pattern)
    shape = (camera.height, camera.width)
    uv = camera.project_target(pattern.points_m, R_cam_target, t_cam_target_m)
    if read_noise > 0:
        img = noise_field(shape, float(read_noise), rng, tile_px=noise_tile_px)
        img = cv2.add(img, float(background))  # also makes the tiled view contiguous
    else:
        img = np.full(shape, float(background), np.float32)
    flux = 2.0 * np.pi * sigma_px**2 * peak
    draw_gaussian_spots(img, uv, sigma_px, flux, photon_gain=photon_gain, rng=rng)

    kinds: list[str] = []
    dpts = np.zeros((0, 2))
    if n_distractors > 0:
        lo, hi = uv.min(0), uv.max(0)
        size = max(float(np.max(hi - lo)), 30.0)
        near_box = (lo[0] - size, lo[1] - size, hi[0] + size, hi[1] + size)
        kinds = list(rng.choice(["spot", "spot", "glint", "hot"], n_distractors))
        # clearance: the largest distractor's 3-sigma radius plus the target's
        avoid_r = 3.0 * (sigma_px + 4.0 * sigma_px) + 3.0
        dpts = _place(rng, n_distractors, shape, uv, avoid_r, near_box, near_fraction, margin=8.0)
        kinds = kinds[: len(dpts)]
        for c, k in zip(dpts, kinds):
            if k == "spot":
                s = sigma_px * rng.uniform(0.7, 1.6)
                draw_gaussian_spots(img, c[None], s, 2 * np.pi * s**2 * peak * rng.uniform(0.3, 1.5))
            elif k == "glint":
                a = sigma_px * rng.uniform(2.5, 4.0)
                draw_elliptical_spots(img, c[None], a, sigma_px * rng.uniform(0.6, 1.0), rng.uniform(0, np.pi),
                                      peak * rng.uniform(0.5, 1.5))
            else:  # hot pixel
                iu, iv = int(round(c[0])), int(round(c[1]))
                img[iv, iu] += peak * rng.uniform(0.5, 2.0)
    out = quantize(img, dtype, full_scale=full_scale, colour=colour)
    return SynthFrame(out, uv, dpts, kinds, float(sigma_px), float(peak))


__all__ = [
    "SynthFrame",
    "synth_frame",
    "random_envelope_pose",
    "draw_gaussian_spots",
    "draw_elliptical_spots",
    "quantize",
    "noise_field",
]
