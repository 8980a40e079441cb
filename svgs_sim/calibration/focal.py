"""The paper's focal-length calibration: focal length from the target's spot spacings at known ranges.

Becker, Howard & Rakoczy (2014), "Test Setup": "a succession of images was captured using
each phone from a known range to the targets. By iterating between each successive image, a
rough approximation of each camera's focal length was calibrated." This module makes that
a least-squares estimate with an uncertainty.

Model and assumptions
    * The target faces the camera: its frame is parallel to the camera's (zero roll,
      pitch and yaw in :func:`svgs_sim.svgs.frames.pose_from_scenario`), except for a free in-plane
      roll per image (``allow_roll``; the paper's yaw about the boresight) that does not
      change spacings. Out-of-plane tilt is *not* modelled. A tilt ``a`` about the target's
      x axis (the paper's roll) foreshortens the long 1-2 baseline by ``cos a``: ``f``
      comes out low by a little less than ``1 - cos a`` (measured, 1-10 m: -0.05 % at
      2 deg, -0.32 % at 5 deg, -1.3 % at 10 deg). A tilt about y (pitch) shortens the
      2.75x shorter 4-axis spacing but moves target 3 sideways by the boom parallax: ``f``
      comes out *high* (+0.12 % at 2 deg, +0.26 % at 5 deg, +0.42 % at 10 deg). Either
      shows in the residuals (0.5-0.7 px RMS at 2 deg, 1.3-1.6 px at 5 deg), far above
      the centroid noise: compare ``residual_sigma_px`` with the noise you expect.
    * ``range_m`` is the distance along the boresight from the camera's perspective centre
      to the target plane (the target-frame origin, the plane of targets 1, 2 and 4), as in
      :func:`svgs_sim.svgs.frames.pose_from_scenario`. Target 3 stands ``z`` in front of it.
    * Pinhole projection with the profile's pixel aspect ratio ``fy / fx`` (1 for square
      pixels); the profile's distortion, if any, is removed from the centroids first
      (with the focal length being estimated, iterated). The principal point is not
      estimated: spacings of coplanar spots do not depend on it.
    * The lateral offset of the target from the boresight is free per image. It shifts all
      coplanar spots alike, but target 3 (``z`` in front of the plane) by ``z / R`` more:
      that parallax is referred to the profile's principal point, the only place the
      principal point enters (a principal-point error ``dc`` moves target 3 by
      ``dc z / R``, 0.05 dc at 1 m for the 3U pattern).

    In complex pixel coordinates ``y = u + j v / aspect`` (principal point ``p`` likewise)
    and with ``P_i = x_i - j y_i`` (target ``i`` in the OpenCV camera frame axes),
    ``w_i = 1 / (R - z_i)`` and ``g_i = w_i / mean(w)``, the pinhole model is linear::

        y_i - p (1 - g_i) = T g_i + f exp(j theta) P_i w_i

    with ``T`` (the pattern's image position) and ``f exp(j theta)`` unknown per image.
    Projecting out ``T`` (``~`` = the component orthogonal to ``g``), the least-squares
    solution is closed form: ``c_k = sum_i conj(~b_ik) ~y_ik`` with ``b_i = P_i w_i``,
    ``theta_k = arg c_k``, ``f_k = |c_k| / S_k``, ``S_k = sum_i |~b_ik|^2`` and, jointly,
    ``f = sum_k |c_k| / sum_k S_k``. Noise-free projected centroids give ``f`` exactly.

Uncertainty and weighting
    Each image alone gives ``f_k = |c_k| / S_k`` (``S_k = sum_i |a_ik|^2``) with variance
    ``sigma^2 / S_k`` for isotropic centroid noise ``sigma`` per axis, plus
    ``(f sigma_R / R_k)^2`` for a range uncertainty ``sigma_R`` (``f_k`` scales with the
    range). ``f`` is their inverse-variance mean and ``sigma_f = (sum_k 1 / var_k)^-1/2``:
    "iterating between successive images", done as a weighted mean. With ``sigma_R = 0``
    this is exactly the joint least-squares solution above. ``sigma`` is the given
    ``centroid_sigma_px`` or, without one, estimated from the least-squares residuals
    (``sqrt(RSS / dof)``, ``dof = 2 * n_centroids - 3 K - 1``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from svgs_sim.base.errors import InputError, check_finite_positive
from svgs_sim.base.profiles import Camera, Pattern, load_camera, load_pattern
from svgs_sim.svgs.identify import identify
from svgs_sim.svgs.pipeline import camera_threshold, check_image_matches_camera, load_image

from .detection import DistinctViews


@dataclass(frozen=True)
class ImageFocal:
    """The focal length from one image alone.

    Attributes
    ----------
    name : str
    range_m : float
    f_px : float
        This image's own least-squares focal length.
    sigma_f_px : float
        Its 1-sigma uncertainty for the centroid noise the estimate uses.
    roll_deg : float
        In-plane rotation of the pattern in the image, from +u towards +v (clockwise on
        screen), relative to the model with the target upright (0 when not estimated).
    residual_rms_px : float
        RMS of this image's residuals with the *global* focal length, per axis.
    n_points : int
    """

    name: str
    range_m: float
    f_px: float
    sigma_f_px: float
    roll_deg: float
    residual_rms_px: float
    n_points: int

    def to_json(self) -> dict:
        return {k: (float(v) if isinstance(v, (float, np.floating)) else v) for k, v in self.__dict__.items()}


@dataclass(frozen=True)
class FocalEstimate:
    """Focal length estimated from spot spacings at known ranges.

    Attributes
    ----------
    f_px : float
        Focal length ``fx``, pixels (``fy = aspect * fx``).
    sigma_f_px : float
        1-sigma uncertainty: centroid-noise and range terms in quadrature.
    per_image : tuple of ImageFocal
    sigma_f_noise_px, sigma_f_range_px : float
        The two terms of ``sigma_f_px``.
    centroid_sigma_px : float
        The centroid noise used for ``sigma_f_noise_px`` (given, or from the residuals).
    residual_sigma_px : float
        Centroid noise estimated from the residuals, ``sqrt(RSS / dof)`` (NaN if dof = 0).
    residual_rms_px : float
        RMS residual per axis.
    dof : int
        Degrees of freedom of the residuals.
    consistency_chi2 : float
        ``sum_k (f_k - f)^2 / var_k`` over the per-image estimates; about ``K - 1`` when the
        images agree within their noise, much larger when a range is wrong or the target
        was tilted.
    aspect : float
        ``fy / fx`` assumed (from the camera profile).
    iterations : int
    skipped : tuple of (str, str)
        Images not used (image path and why), from :func:`estimate_focal_from_images`.
    """

    f_px: float
    sigma_f_px: float
    per_image: tuple
    sigma_f_noise_px: float
    sigma_f_range_px: float
    centroid_sigma_px: float
    residual_sigma_px: float
    residual_rms_px: float
    dof: int
    consistency_chi2: float = float("nan")
    aspect: float = 1.0
    iterations: int = 0
    skipped: tuple = field(default_factory=tuple)

    @property
    def per_image_f_px(self) -> np.ndarray:
        """Each image's own focal length, shape (K,)."""
        return np.array([p.f_px for p in self.per_image])

    @property
    def ranges_m(self) -> np.ndarray:
        return np.array([p.range_m for p in self.per_image])

    def to_camera(self, camera: Camera) -> Camera:
        """``camera`` with ``fx = f_px`` and ``fy = aspect * f_px``, recording the estimate."""
        record = {
            "method": "focal-from-spacings (Becker et al. 2014)",
            "f_px": float(self.f_px),
            "sigma_f_px": float(self.sigma_f_px),
            "n_images": len(self.per_image),
            "ranges_m": [float(r) for r in self.ranges_m],
            "residual_rms_px": float(self.residual_rms_px),
        }
        return camera.replace(fx=float(self.f_px), fy=float(self.f_px * self.aspect)).with_tables(calibration=record)

    @property
    def warnings(self) -> list[str]:
        """What makes this estimate suspect: images that disagree beyond their errors (chi^2
        probability below 1 %: a range is probably wrong), or a focal length uncertain by over 5 %."""
        from scipy.stats import chi2 as chi2_dist

        out = []
        k = len(self.per_image) - 1
        if k >= 1 and np.isfinite(self.consistency_chi2):
            p = float(chi2_dist.sf(self.consistency_chi2, k))
            if p < 0.01:
                out.append(f"the images disagree: chi2 {self.consistency_chi2:.1f} for {k} dof (p = {p:.1e}); "
                           "check each image's --range (a wrong range moves its focal length)")
        if self.f_px > 0 and self.sigma_f_px > 0.05 * self.f_px:
            out.append(f"the focal length is uncertain by {100 * self.sigma_f_px / self.f_px:.0f} % (1 sigma)")
        return out

    def to_json(self) -> dict:
        def num(x):
            x = float(x)
            return None if x != x else x

        return {
            "ok": True,
            "warnings": self.warnings,
            "f_px": num(self.f_px),
            "sigma_f_px": num(self.sigma_f_px),
            "sigma_f_noise_px": num(self.sigma_f_noise_px),
            "sigma_f_range_px": num(self.sigma_f_range_px),
            "centroid_sigma_px": num(self.centroid_sigma_px),
            "residual_sigma_px": num(self.residual_sigma_px),
            "residual_rms_px": num(self.residual_rms_px),
            "dof": int(self.dof),
            "consistency_chi2": num(self.consistency_chi2),
            "aspect": float(self.aspect),
            "iterations": int(self.iterations),
            "per_image": [
                {k: (num(v) if isinstance(v, (float, np.floating)) else v) for k, v in p.__dict__.items()}
                for p in self.per_image
            ],
            "skipped": [{"image": n, "reason": r} for n, r in self.skipped],
        }

    def summary(self) -> str:
        lines = [
            f"focal length: {self.f_px:.2f} +- {self.sigma_f_px:.2f} px (1 sigma; {100 * self.sigma_f_px / self.f_px:.3f} %)",
            f"  from centroid noise {self.centroid_sigma_px:.3g} px: +- {self.sigma_f_noise_px:.2f} px; "
            f"from range uncertainty: +- {self.sigma_f_range_px:.2f} px",
            f"  residual RMS {self.residual_rms_px:.3f} px per axis; residual sigma "
            f"{self.residual_sigma_px:.3f} px ({self.dof} dof); fy/fx = {self.aspect:g}",
            f"  agreement between images: chi2 {self.consistency_chi2:.2f} for {len(self.per_image) - 1} dof",
            *[f"  WARNING: {w}" for w in self.warnings],
            "  per image:",
        ]
        for p in self.per_image:
            lines.append(
                f"    {p.name}: range {p.range_m:g} m, f {p.f_px:.2f} +- {p.sigma_f_px:.2f} px, "
                f"roll {p.roll_deg:+.2f} deg, residual {p.residual_rms_px:.3f} px"
            )
        for n, r in self.skipped:
            lines.append(f"  skipped {n}: {r}")
        return "\n".join(lines)


def _check_inputs(centroids_px_list, ranges_m, pattern: Pattern, names):
    pts = [np.asarray(c, float) for c in centroids_px_list]
    if len(pts) == 0:
        raise InputError("estimate_focal: no images (centroid sets) given")
    rng = np.asarray(ranges_m, float).reshape(-1)
    if rng.shape[0] != len(pts):
        raise InputError(f"estimate_focal: {len(pts)} centroid sets but {rng.shape[0]} ranges")
    for k, r in enumerate(rng):
        check_finite_positive(r, f"range of image {k + 1}")
    zmax = float(pattern.points_m[:, 2].max())
    if np.any(rng <= zmax):
        raise InputError(f"estimate_focal: every range must exceed the pattern's depth ({zmax:g} m), got {rng.tolist()}")
    if names is None:
        names = [f"image {k + 1}" for k in range(len(pts))]
    names = [str(n) for n in names]
    if len(names) != len(pts):
        raise InputError(f"estimate_focal: {len(names)} names for {len(pts)} images")
    for n, p in zip(names, pts):
        if p.shape != (pattern.n, 2):
            raise InputError(
                f"estimate_focal: {n}: expected {pattern.n} centroids ordered by target id "
                f"{pattern.ids.tolist()} (shape ({pattern.n}, 2)), got shape {p.shape}"
            )
        ok = np.all(np.isfinite(p), axis=1)
        if ok.sum() < 3:
            raise InputError(f"estimate_focal: {n}: needs at least 3 finite centroids (NaN marks a missing target), got {int(ok.sum())}")
        if np.any(np.isinf(p)):
            raise InputError(f"estimate_focal: {n}: centroids must be finite (or NaN for a missing target)")
    return pts, rng, names


def estimate_focal(
    centroids_px_list,
    ranges_m,
    camera,
    pattern="svgs-3u",
    *,
    centroid_sigma_px: float | None = None,
    range_sigma_m: float = 0.0,
    allow_roll: bool = True,
    names=None,
    max_iter: int = 20,
) -> FocalEstimate:
    """Focal length (px) from labelled spot centroids of the target at known ranges.

    Parameters
    ----------
    centroids_px_list : sequence of array_like, each shape (N, 2)
        Per image, the centroids ordered by target id (``pattern.ids``); a row of NaN
        marks a target not seen. At least 3 targets per image.
    ranges_m : array_like, shape (K,)
        Range of each image along the boresight to the target plane, metres.
    camera : Camera or str
        Gives the starting focal length, the pixel aspect ratio ``fy / fx``, the
        principal point (for the lateral offset only) and the distortion (removed first).
    pattern : Pattern or str
    centroid_sigma_px : float, optional
        Known centroid noise per axis, px. Default: estimated from the residuals.
    range_sigma_m : float
        1-sigma uncertainty of each range, metres (added in quadrature).
    allow_roll : bool
        Let the pattern rotate in the image plane by a free angle per image (the spacing
        *lengths* carry the scale; their directions are not used). Default True.
    names : sequence of str, optional
        Image names for the report.
    max_iter : int
        Iterations of the fixed point (distortion removal and lateral offset depend on f).

    Returns
    -------
    FocalEstimate

    Raises
    ------
    InputError
        Mismatched or non-finite input, a range inside the pattern, or a degenerate
        geometry (all targets on one image point).
    """
    camera = load_camera(camera)
    pattern = load_pattern(pattern)
    pts, rng, names = _check_inputs(centroids_px_list, ranges_m, pattern, names)
    if centroid_sigma_px is not None:
        centroid_sigma_px = check_finite_positive(centroid_sigma_px, "centroid_sigma_px")
    range_sigma_m = check_finite_positive(range_sigma_m, "range_sigma_m", allow_zero=True)
    aspect = camera.fy / camera.fx
    f = float(camera.fx)
    it = 0
    n_pts = np.array([int(np.all(np.isfinite(p), axis=1).sum()) for p in pts])
    dof = int(2 * n_pts.sum() - (len(pts) * (2 + (1 if allow_roll else 0)) + 1))
    for it in range(1, int(max_iter) + 1):
        st = _focal_step(pts, rng, pattern, camera, f, aspect, allow_roll=allow_roll, dof=dof, n_pts=n_pts,
                         centroid_sigma_px=centroid_sigma_px, range_sigma_m=range_sigma_m)
        done = abs(st.f_new - f) <= 1e-12 * st.f_new
        f = st.f_new
        if done or not camera.has_distortion:
            break
    return _focal_estimate(st, f, names, rng, n_pts, dof, aspect, it)


def _image_terms(p, R: float, P, camera: Camera, cam_f: Camera, f: float, aspect: float):
    """The linear model of one image's centroids after eliminating the pattern's image position.

    ``y_i = pp + f (exp(j theta) P_i + O) w_i`` in complex pixels (fx units), ``P_i = x_i - j y_i``
    (OpenCV camera frame), ``w_i = 1 / (R - z_i)`` the perspective factor and ``O`` the lateral
    offset. With ``T = pp + f O mean(w)`` (the pattern's image position) and ``g = w / mean(w)``:
    ``y_i - pp (1 - g_i) = T g_i + f exp(j theta) P_i w_i``, linear in ``T`` and ``f exp(j theta)``;
    both sides are projected orthogonally to ``g`` to eliminate ``T``.

    Parameters
    ----------
    p : ndarray, shape (N, 2)
        Centroids by target id, pixels (NaN rows: targets not seen).
    R : float
        Range of the image, metres.
    P : ndarray, shape (N, 3)
        Target points in the target frame, metres.
    cam_f : Camera
        ``camera`` with the current focal length ``f`` (for the undistortion).

    Returns
    -------
    c : complex
        ``sum(conj(a) z_obs)``: ``f exp(j theta)`` times ``s`` at the least-squares fit.
    s : float
        ``sum(|a|^2)``.
    z_obs, a : ndarray of complex, shape (n,)
        Projected observations (px) and model (normalised: ``f exp(j theta) a`` predicts
        ``z_obs``) of the targets seen.
    """
    ok = np.all(np.isfinite(p), axis=1)
    uv = p[ok]
    if camera.has_distortion:  # undistorted pixel coordinates
        xy = cam_f.pixels_to_normalized(uv)
        uv = np.stack([f * xy[:, 0] + camera.cx, f * aspect * xy[:, 1] + camera.cy], -1)
    # complex pixels in fx units: y = u + j v / aspect; principal point likewise
    y = uv[:, 0] + 1j * uv[:, 1] / aspect
    pp = camera.cx + 1j * camera.cy / aspect
    Pk = P[ok]
    w = 1.0 / (R - Pk[:, 2])  # perspective factor of each target
    g = w / w.mean()
    y2 = y - pp * (1.0 - g)
    b = (Pk[:, 0] - 1j * Pk[:, 1]) * w
    # eliminate T: project both sides orthogonally to g
    z_obs = y2 - g * (np.dot(g, y2) / np.dot(g, g))
    a = b - g * (np.dot(g, b) / np.dot(g, g))
    c = np.sum(np.conj(a) * z_obs)
    return c, float(np.sum(np.abs(a) ** 2)), z_obs, a


@dataclass
class _FocalStep:
    """One fixed-point iteration of :func:`estimate_focal`: per-image focal lengths (``f_k``,
    ``theta`` rad), their variances (px^2) and the combined focal length ``f_new`` (px)."""

    f_k: np.ndarray
    theta: np.ndarray
    obs: list
    mod: list
    res_sigma: float
    sigma: float
    v_noise: np.ndarray
    v_range: np.ndarray
    inv_v: np.ndarray
    f_new: float


def _focal_step(pts, rng, pattern: Pattern, camera: Camera, f: float, aspect: float, *, allow_roll: bool,
                dof: int, n_pts, centroid_sigma_px, range_sigma_m: float) -> _FocalStep:
    """Per-image focal lengths at the current ``f`` and their inverse-variance weighted mean.

    ``n_pts`` (shape (K,)) counts each image's centroids; ``dof`` is the residual degrees of
    freedom of the least-squares fit that estimates the centroid noise.
    """
    cam_f = camera.replace(fx=f, fy=f * aspect)
    C, S, obs_list, mod_list = [], [], [], []
    for p, R in zip(pts, rng):
        c, s_k, z_obs, a = _image_terms(p, R, pattern.points_m, camera, cam_f, f, aspect)
        C.append(c if allow_roll else complex(c.real, 0.0))
        S.append(s_k)
        obs_list.append(z_obs)
        mod_list.append(a)
    C = np.array(C)
    S = np.array(S)
    if np.any(S <= 0):
        raise InputError("estimate_focal: degenerate pattern geometry (targets project onto one point)")
    f_k = (np.abs(C) if allow_roll else C.real) / S
    theta = np.angle(C) if allow_roll else np.zeros(len(C))
    # least squares under centroid noise alone; its residuals estimate the noise
    f_ls = float(np.sum(f_k * S) / np.sum(S))
    rss_ls = sum(float(np.sum(np.abs(o - f_ls * np.exp(1j * th) * a) ** 2)) for o, a, th in zip(obs_list, mod_list, theta))
    res_sigma = float(np.sqrt(rss_ls / dof)) if dof > 0 else float("nan")
    sigma = centroid_sigma_px if centroid_sigma_px is not None else res_sigma
    if not np.isfinite(sigma):
        raise InputError(
            f"estimate_focal: {len(pts)} image(s) with {int(n_pts.sum())} centroids leave no residual degrees "
            "of freedom to estimate the centroid noise; give centroid_sigma_px (--centroid-sigma-px) or more images"
        )
    # per-image variances: centroid noise + range uncertainty (f_k scales with R_k)
    v_noise = sigma**2 / S
    v_range = (f_ls * range_sigma_m / rng) ** 2
    inv_v = 1.0 / (v_noise + v_range)
    f_new = float(np.sum(f_k * inv_v) / np.sum(inv_v))
    if not np.isfinite(f_new) or f_new <= 0:
        raise InputError(
            "estimate_focal: no positive focal length fits these centroids; check that they are "
            f"ordered by target id {pattern.ids.tolist()} and that the ranges belong to the images"
        )
    return _FocalStep(f_k, theta, obs_list, mod_list, res_sigma, sigma, v_noise, v_range, inv_v, f_new)


def _focal_estimate(st: _FocalStep, f: float, names, rng, n_pts, dof: int, aspect: float, it: int) -> FocalEstimate:
    """The :class:`FocalEstimate` of the last iteration ``st`` at the focal length ``f``."""
    inv_v, v_noise, v_range, f_k, theta = st.inv_v, st.v_noise, st.v_range, st.f_k, st.theta
    w = inv_v / inv_v.sum()
    sig_noise = float(np.sqrt(np.sum(w**2 * v_noise)))
    sig_range = float(np.sqrt(np.sum(w**2 * v_range)))
    chi2 = float(np.sum((f_k - f) ** 2 * inv_v))
    rss_k = np.array([np.sum(np.abs(o - f * np.exp(1j * th) * a) ** 2) for o, a, th in zip(st.obs, st.mod, theta)])
    per = tuple(
        ImageFocal(
            name=n, range_m=float(R), f_px=float(fk), sigma_f_px=float(np.sqrt(vn + vr)),
            roll_deg=float(np.degrees(th)), residual_rms_px=float(np.sqrt(rk / (2 * npk))), n_points=int(npk),
        )
        for n, R, fk, vn, vr, th, rk, npk in zip(names, rng, f_k, v_noise, v_range, theta, rss_k, n_pts)
    )
    return FocalEstimate(
        f_px=f,
        sigma_f_px=float(1.0 / np.sqrt(inv_v.sum())),
        per_image=per,
        sigma_f_noise_px=sig_noise,
        sigma_f_range_px=sig_range,
        centroid_sigma_px=float(st.sigma),
        residual_sigma_px=st.res_sigma,
        residual_rms_px=float(np.sqrt(rss_k.sum() / (2 * n_pts.sum()))),
        dof=dof,
        consistency_chi2=chi2,
        aspect=float(aspect),
        iterations=it,
    )

def estimate_focal_from_images(
    images,
    ranges_m,
    camera,
    pattern="svgs-3u",
    *,
    threshold=None,
    detect_options: dict | None = None,
    identify_options: dict | None = None,
    **kwargs,
) -> FocalEstimate:
    """The image-level path: detect and identify the spots, then :func:`estimate_focal`.

    Parameters
    ----------
    images : sequence of str, Path or ndarray
        Images of the target facing the camera, each of the camera's size.
    ranges_m : array_like, shape (K,)
        Range of each image, metres.
    camera : Camera or str
        Its focal length need only be rough: identification uses it as a start.
    pattern : Pattern or str
    threshold : None, number or str
        None: the app's brightness threshold for ``camera`` (:func:`svgs_sim.svgs.pipeline.camera_threshold`);
        else as :func:`svgs_sim.svgs.detect.detect_blobs` takes it.
    detect_options, identify_options : dict, optional
        Passed to :func:`svgs_sim.svgs.detect.detect_blobs` and :func:`svgs_sim.svgs.identify.identify`.
    **kwargs
        Passed to :func:`estimate_focal`.

    Returns
    -------
    FocalEstimate
        Images where the targets were not identified are listed in ``skipped``.

    Raises
    ------
    InputError
        Unreadable images, a size that is not the camera's, mismatched ranges, or no image
        in which the targets were identified.
    """

    from svgs_sim.svgs.detect import detect_blobs


    camera = load_camera(camera)
    pattern = load_pattern(pattern)
    images = list(images)
    rng = np.asarray(ranges_m, float).reshape(-1)
    if rng.shape[0] != len(images):
        raise InputError(f"estimate_focal: {len(images)} images but {rng.shape[0]} ranges (give one --range per --image)")
    names = [Path(im).name if isinstance(im, (str, Path)) else f"image {k + 1}" for k, im in enumerate(images)]
    cents, used_r, used_n, skipped = [], [], [], []
    distinct = DistinctViews("--image")
    for im, r, n in zip(images, rng, names):
        arr = load_image(im) if isinstance(im, (str, Path)) else np.asarray(im)
        check_image_matches_camera(arr, camera, name=n)
        blobs = detect_blobs(arr, threshold=camera_threshold(arr, camera, threshold), **(detect_options or {}))
        ident = identify(blobs, camera, pattern, **(identify_options or {}))
        if not ident:
            skipped.append((n, f"{ident.reason}: {ident.message}"))
            continue
        distinct.add(arr, str(im) if isinstance(im, (str, Path)) else n)  # a used view given twice would count twice
        cents.append(np.asarray(ident.points_px, float))
        used_r.append(float(r))
        used_n.append(n)
    if not cents:
        raise InputError(
            "estimate_focal: the targets were identified in none of the images: "
            + "; ".join(f"{n} ({why})" for n, why in skipped)
        )
    est = estimate_focal(cents, used_r, camera, pattern, names=used_n, **kwargs)
    return FocalEstimate(**{**est.__dict__, "skipped": tuple(skipped)})


__all__ = ["FocalEstimate", "ImageFocal", "estimate_focal", "estimate_focal_from_images"]
