"""Seeded synthetic ToF data for tests and benchmarks (not the physical renderer).

- :func:`random_pose`: poses in a plausible envelope of the ToF experiments.
- :func:`synth_marker_points`: noise-free (or noisy) 3-D marker sets with missing and
  spurious points, for the matching and SVD tests.
- :func:`synth_frame`: a gray + depth frame pair of the marker target by analytic ray casting
  with ``s x s`` supersampling per pixel: the marker faces are exact 3-D disks (their images
  are exact projected ellipses), the plate a rectangle; gray is Lambertian with the light at
  the lens (``albedo cos(i) / range^2``), depth is the AMCW phasor mean of the samples (so
  rim pixels mix the marker and the plate as a real camera does), and both get seeded
  Gaussian noise (depth noise growing as ``1/sqrt(amplitude)``). Marker posts are not drawn.

The physically based ToF camera (Mitsuba, taps, multipath) is ``render/``'s job; this
module only needs numpy.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from svgs_sim.svgs.frames import pose_from_scenario
from svgs_sim.base.profiles import Camera

from svgs_sim.tof.camera import MarkerTarget
from svgs_sim.tof.ellipse import project_circle_conic

C_LIGHT = 299_792_458.0  # m/s


def _plane_basis_local(n):
    a = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(n, a)
    u /= np.linalg.norm(u)
    return u, np.cross(n, u)


def _cast(camera, target, R, t, centres, normal, pw, ph, a_m, a_p, f_mod, gray_scale_dn, roi, s):
    """Supersampled ray casting of the box ``roi = (r0, r1, c0, c1)``: pixel amplitude and
    amplitude-weighted AMCW phasor (``t``: the plate's front-face centre in the camera frame)."""
    r0, r1, c0, c1 = roi
    h, w = r1 - r0, c1 - c0
    off = (np.arange(s) + 0.5) / s - 0.5
    uu = (np.arange(c0, c1)[:, None] + off[None, :]).ravel()
    vv = (np.arange(r0, r1)[:, None] + off[None, :]).ravel()
    U, V = np.meshgrid(uu, vv)
    xy = camera.pixels_to_normalized(np.stack([U, V], -1))
    d = np.concatenate([xy, np.ones(xy.shape[:-1] + (1,))], -1)
    dn = np.linalg.norm(d, axis=-1)
    best = np.full(U.shape, np.inf)
    alb = np.zeros(U.shape)
    ndd = d @ normal  # n . d, one plane normal for all faces
    with np.errstate(divide="ignore", invalid="ignore"):
        front = ndd < 0
        sp = (normal @ t) / ndd
        X = d * sp[..., None] - t
        lx, ly = X @ R[:, 0], X @ R[:, 1]
        hit = front & (sp > 0) & (np.abs(lx) <= pw / 2) & (np.abs(ly) <= ph / 2)
        best = np.where(hit, sp, best)
        alb = np.where(hit, a_p, alb)
        for c, r in zip(centres, target.radius_m):
            sm = (normal @ c) / ndd
            X = d * sm[..., None] - c
            hit = front & (sm > 0) & (np.einsum("...k,...k->...", X, X) <= r * r) & (sm < best)
            best = np.where(hit, sm, best)
            alb = np.where(hit, a_m, alb)
        valid = np.isfinite(best)
        rng_m = np.where(valid, best * dn, 1.0)
        amp = np.where(valid, gray_scale_dn * alb * (np.abs(ndd) / dn) / rng_m**2, 0.0)
    k = 4 * np.pi * f_mod / C_LIGHT
    ph = amp * np.exp(1j * k * rng_m)

    def pix(a):
        return a.reshape(h, s, w, s).mean(axis=(1, 3))

    return pix(amp), pix(ph)


def random_pose(rng=None, range_m=(0.7, 6.0), max_tilt_deg: float = 25.0, max_roll_deg: float = 180.0,
                lateral_frac: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    """A random pose of the target in front of the camera.

    Parameters
    ----------
    rng : int or numpy.random.Generator, optional
        Seed or generator.
    range_m : (float, float)
        Range interval (log-uniform), metres.
    max_tilt_deg : float
        Pitch and yaw uniform in +-this.
    max_roll_deg : float
        Roll uniform in +-this.
    lateral_frac : float
        Lateral offsets uniform in +-this fraction of the range.

    Returns
    -------
    R_cam_target : ndarray, shape (3, 3)
    t_cam_target_m : ndarray, shape (3,)
    """
    rng = np.random.default_rng(rng)
    r = float(np.exp(rng.uniform(np.log(range_m[0]), np.log(range_m[1]))))
    return pose_from_scenario(
        r, rng.uniform(-lateral_frac, lateral_frac) * r, rng.uniform(-lateral_frac, lateral_frac) * r,
        rng.uniform(-max_roll_deg, max_roll_deg), rng.uniform(-max_tilt_deg, max_tilt_deg),
        rng.uniform(-max_tilt_deg, max_tilt_deg),
    )


def synth_marker_points(points_target_m, R_cam_target, t_cam_target_m, *, n_missing: int = 0, n_spurious: int = 0,
                        noise_m: float = 0.0, spurious_margin_m: float = 0.1, min_separation_m: float = 0.03,
                        rng=None) -> tuple[np.ndarray, np.ndarray]:
    """Observed 3-D marker set: a shuffled subset of the true points plus spurious points.

    Spurious points are drawn uniformly in the target's bounding box grown by
    ``spurious_margin_m`` (target frame), at least ``min_separation_m`` from every marker.

    Returns
    -------
    obs_cam_m : ndarray, shape (N - n_missing + n_spurious, 3)
    true_index : ndarray of int, shape (same,)
        Catalogue index of each observation, -1 for spurious ones.
    """
    rng = np.random.default_rng(rng)
    p = np.asarray(points_target_m, float)
    N = p.shape[0]
    keep = np.sort(rng.choice(N, N - int(n_missing), replace=False))
    lo, hi = p.min(0) - spurious_margin_m, p.max(0) + spurious_margin_m
    spur = []
    while len(spur) < n_spurious:
        x = rng.uniform(lo, hi)
        if np.min(np.linalg.norm(p - x, axis=1)) >= min_separation_m:
            spur.append(x)
    pts = np.vstack([p[keep]] + ([np.array(spur)] if spur else []))
    idx = np.concatenate([keep, -np.ones(len(spur), int)])
    obs = pts @ np.asarray(R_cam_target).T + np.asarray(t_cam_target_m)
    if noise_m > 0:
        obs = obs + rng.normal(0, noise_m, obs.shape)
    perm = rng.permutation(obs.shape[0])
    return obs[perm], idx[perm]


@dataclass
class SynthFrame:
    """A synthetic gray + depth frame pair and its truth.

    Attributes
    ----------
    gray : ndarray of float32, shape (H, W)
        Amplitude in DN.
    depth_m : ndarray of float32, shape (H, W)
        Radial depth, NaN where invalid (no return or amplitude below the floor).
    R_cam_target, t_cam_target_m : ndarray
    centres_px : ndarray, shape (N, 2)
        Projections of the marker face centres (the truth the centroids should hit).
    ellipse_centres_px : ndarray, shape (N, 2)
        Centres of the marker images (biased by the projection).
    conics : ndarray, shape (N, 3, 3)
        Exact image conics of the marker rims.
    visible : ndarray of bool, shape (N,)
        Marker centre inside the image and not hidden.
    range_m : ndarray, shape (N,)
        True radial range of each marker face centre.
    """

    gray: np.ndarray
    depth_m: np.ndarray
    R_cam_target: np.ndarray
    t_cam_target_m: np.ndarray
    centres_px: np.ndarray
    ellipse_centres_px: np.ndarray
    conics: np.ndarray
    visible: np.ndarray
    range_m: np.ndarray


def synth_frame(camera: Camera, target: MarkerTarget, R_cam_target, t_cam_target_m, *, seed=None,
                supersample: int = 4, gray_scale_dn: float = 800.0, gray_noise_dn: float = 2.0,
                gray_shot_dn: float = 1.0, ambient_dn: float = 5.0, depth_noise_m: float = 0.01,
                depth_ref_dn: float = 1000.0,
                min_amplitude_dn: float = 0.5, modulation_frequency_hz: float | None = None,
                marker_albedo: float | None = None, plate_albedo: float | None = None,
                full_scale_dn: float = 4095.0) -> SynthFrame:
    """Ray-cast a gray + depth frame of the marker target (see the module notes).

    Parameters
    ----------
    camera : Camera
    target : MarkerTarget
    R_cam_target, t_cam_target_m : array_like
        Pose of the target.
    seed : int, optional
        Seed of the noise (``None`` draws fresh entropy; tests pass a seed).
    supersample : int
        Samples per pixel along each axis.
    gray_scale_dn : float
        Gray of a unit-albedo face seen head-on at 1 m.
    gray_noise_dn, ambient_dn : float
        Gaussian gray (read) noise and constant ambient offset, DN.
    gray_shot_dn : float
        Shot-noise variance per DN of signal (``sigma^2 = gray_noise_dn^2 + gray_shot_dn * A``).
    depth_noise_m : float
        Per-pixel depth noise at amplitude ``depth_ref_dn``; scales as ``sqrt(depth_ref_dn / A)``
        (ASSUMPTION: 1 cm at 1000 DN, the order of EPC660-class repeatability at 1 m).
    min_amplitude_dn : float
        Pixels returning less signal are invalid (NaN depth).
    modulation_frequency_hz : float, optional
        AMCW frequency for the phasor mixing (default: the profile's ``tof`` table, else 10 MHz).
    marker_albedo, plate_albedo : float, optional
        Default: the target's ``[marker]`` / ``[plate]`` albedo (0.85 / 0.04).
    full_scale_dn : float
        Gray saturates here.

    Returns
    -------
    SynthFrame
    """
    rng = np.random.default_rng(seed)
    R = np.asarray(R_cam_target, float)
    t = np.asarray(t_cam_target_m, float)
    H, W, s = camera.height, camera.width, int(supersample)
    f_mod = modulation_frequency_hz or float(camera.tables.get("tof", {}).get("modulation_frequency_hz", 10e6))
    a_m = float(target.marker.get("albedo", 0.85)) if marker_albedo is None else float(marker_albedo)
    a_p = float(target.plate.get("albedo", 0.04)) if plate_albedo is None else float(plate_albedo)
    normal = R[:, 2]
    centres = target.points_m @ R.T + t
    pw, ph = float(target.plate.get("width_m", 0.0)), float(target.plate.get("height_m", 0.0))
    pc = target.plate_centre_m  # the plate's front-face centre, target frame
    # ray-cast only the box that can hold the target (plate corners, marker rims)
    corners = (np.array([[x, y, 0.0] for x in (-pw / 2, pw / 2) for y in (-ph / 2, ph / 2)]) + pc) @ R.T + t
    u_, v_ = _plane_basis_local(normal)
    ang = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    ring = np.cos(ang)[:, None] * u_ + np.sin(ang)[:, None] * v_  # (16, 3)
    rim = (centres[:, None, :] + target.radius_m[:, None, None] * ring[None]).reshape(-1, 3)
    pts = np.vstack([corners, rim])
    pts = pts[pts[:, 2] > 1e-6]
    A = np.zeros((H, W))
    P = np.zeros((H, W), complex)
    if pts.shape[0]:
        uv = camera.project(pts)
        c0 = int(np.clip(np.floor(uv[:, 0].min()) - 2, 0, W))
        c1 = int(np.clip(np.ceil(uv[:, 0].max()) + 3, 0, W))
        r0 = int(np.clip(np.floor(uv[:, 1].min()) - 2, 0, H))
        r1 = int(np.clip(np.ceil(uv[:, 1].max()) + 3, 0, H))
        if c1 > c0 and r1 > r0:
            a_roi, p_roi = _cast(camera, target, R, R @ pc + t, centres, normal, pw, ph, a_m, a_p, f_mod, gray_scale_dn,
                                 (r0, r1, c0, c1), s)
            A[r0:r1, c0:c1] = a_roi
            P[r0:r1, c0:c1] = p_roi
    k = 4 * np.pi * f_mod / C_LIGHT
    unamb = C_LIGHT / (2 * f_mod)
    depth = np.mod(np.angle(P), 2 * np.pi) / k
    depth = np.where(depth > unamb, depth - unamb, depth)
    gray = A + ambient_dn + rng.normal(0.0, 1.0, A.shape) * np.sqrt(gray_noise_dn**2 + gray_shot_dn * A)
    gray = np.clip(gray, 0, full_scale_dn)
    ok = A >= min_amplitude_dn
    sig = depth_noise_m * np.sqrt(depth_ref_dn / np.maximum(A, min_amplitude_dn))
    depth = np.where(ok, depth + rng.normal(0.0, 1.0, A.shape) * sig, np.nan)
    # truth
    K = camera.K
    normal = R[:, 2]
    conics = np.array([project_circle_conic(K, c, normal, r) for c, r in zip(centres, target.radius_m)])
    centres_px = camera.project(centres)
    ell = -np.linalg.solve(conics[:, :2, :2], conics[:, :2, 2:3])[:, :, 0]
    vis = camera.in_image(centres_px, 0.5) & (centres[:, 2] > 0)
    # hidden: the ray to the centre hits something nearer
    for i, c in enumerate(centres):
        if not vis[i]:
            continue
        dd = c / c[2]
        for j, (c2, r2) in enumerate(zip(centres, target.radius_m)):
            if j == i:
                continue
            sm = (normal @ c2) / (normal @ dd)
            if 0 < sm < c[2] - 1e-9 and np.linalg.norm(dd * sm - c2) <= r2:
                vis[i] = False
    return SynthFrame(gray.astype(np.float32), depth.astype(np.float32), R, t, centres_px, ell, conics, vis,
                      np.linalg.norm(centres, axis=1))
