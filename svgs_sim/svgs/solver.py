"""The SVGS collinearity solver in azimuth/elevation form (paper eqs. 1-13).

Measurements
    Each target's centroid is undistorted to normalised coordinates ``(xn, yn)`` (OpenCV
    camera frame) and turned into the paper's azimuth and elevation (eqs. 12-13), with the
    paper's image frame (x right, y up, looking along -z)::

        Az = atan(xn)                       El = asin(-yn / sqrt(xn^2 + yn^2 + 1))

Model
    ``v = M(phi, theta, psi) @ (P - L)`` in the paper camera frame, ``Az = atan2(v_x, -v_z)``,
    ``El = asin(v_y / |v|)``, with the state ``V = [X_L, Y_L, Z_L, phi, theta, psi]``
    (see :mod:`svgs_sim.svgs.frames`).

Estimator
    Levenberg-Marquardt on the az/el residuals with the analytic Jacobian
    ``d(Az, El)/dV``, weighted by the inverse covariance of az/el that isotropic centroid
    noise induces (``Sigma_i = G_i G_i^T sigma^2``, ``G_i = d(Az, El)/d(u, v)``). With that
    weight the estimator is the maximum-likelihood estimator for Gaussian centroid noise, and
    its covariance reaches the Cramer-Rao bound ``(J^T Sigma^-1 J)^-1``, which the solver
    reports. The initial guess comes from POSIT (DeMenthon & Davis 1995, non-coplanar form),
    vectorised over frames; frames that do not converge from it are retried from other
    starts before they are declared failed.

Everything is vectorised over frames: ``points_px`` of shape ``(N, n, 2)`` is solved in one
call (the Monte Carlo path); shape ``(n, 2)`` returns a single :class:`Solution`.
"""

from __future__ import annotations

import functools

from dataclasses import dataclass, field

import numpy as np

from ..base.errors import InputError
from .frames import D_CAM_PHOTO, STATE_KEYS, pose_to_state, rotation_from_angles, state_to_pose
from ..base.profiles import Camera, Pattern, load_camera, load_pattern
from .result import Failure, Solved

#: Default convergence tolerance on the state step: metres for position, radians for angles.
STEP_TOL = 1e-9
#: Batches at least this large run the compiled kernel on all cores.
PARALLEL_MIN_FRAMES = 256
#: Default iteration cap.
MAX_ITER = 200
#: Reprojection residual (px RMS) above which a converged solution is not accepted as "ok"
#: unless the caller raises it. Noise-free data converge to ~1e-9 px.
DEFAULT_MAX_RESIDUAL_PX = 5.0


def azel_from_normalized(xy: np.ndarray) -> np.ndarray:
    """Paper eqs. 12-13 from normalised (undistorted) coordinates.

    Parameters
    ----------
    xy : ndarray, shape (..., 2)
        ``(X/Z, Y/Z)`` in the OpenCV camera frame.

    Returns
    -------
    azel_rad : ndarray, shape (..., 2)
    """
    x, y = xy[..., 0], xy[..., 1]
    return np.stack([np.arctan(x), np.arcsin(-y / np.sqrt(x * x + y * y + 1.0))], -1)


def azel_pixel_jacobian(uv_px: np.ndarray, camera: Camera, h_px: float = 1e-3) -> np.ndarray:
    """``G = d(Az, El) / d(u, v)``: analytic without distortion, else central differences
    through the undistortion.

    Parameters
    ----------
    uv_px : ndarray, shape (..., 2)

    Returns
    -------
    G : ndarray, shape (..., 2, 2), rad/px
    """
    uv = np.asarray(uv_px, float)
    if not camera.has_distortion:
        xn, yn = (uv[..., 0] - camera.cx) / camera.fx, (uv[..., 1] - camera.cy) / camera.fy
        q2 = 1.0 + xn * xn
        s2 = q2 + yn * yn
        q = np.sqrt(q2)
        G = np.zeros(uv.shape[:-1] + (2, 2))
        G[..., 0, 0] = 1.0 / (q2 * camera.fx)
        G[..., 1, 0] = xn * yn / (s2 * q * camera.fx)
        G[..., 1, 1] = -q / (s2 * camera.fy)
        return G
    cols = []
    for k in range(2):
        e = np.zeros(2)
        e[k] = h_px
        ap = azel_from_normalized(camera.pixels_to_normalized(uv + e))
        am = azel_from_normalized(camera.pixels_to_normalized(uv - e))
        cols.append((ap - am) / (2 * h_px))
    return np.stack(cols, -1)


# --------------------------------------------------------------------------- initial guess
@functools.lru_cache(maxsize=16)
def _posit_basis(p_bytes: bytes, shape: tuple) -> np.ndarray:
    """``pinv(P[1:] - P[0])`` of a pattern (the same for every frame: computed once)."""
    P = np.frombuffer(p_bytes, dtype=np.float64).reshape(shape)
    B = np.linalg.pinv(P[1:] - P[0])
    B.setflags(write=False)
    return B


def posit(xy: np.ndarray, points_m: np.ndarray, n_iter: int = 10):
    """POSIT (DeMenthon & Davis 1995) for non-coplanar points, over N frames (compiled).

    Parameters
    ----------
    xy : ndarray, shape (N, n, 2)
        Normalised image coordinates (OpenCV camera frame).
    points_m : ndarray, shape (n, 3)
    n_iter : int
        POSIT iterations; the Levenberg-Marquardt refinement does the rest.

    Returns
    -------
    R_cam_target : ndarray, shape (N, 3, 3)
    t_cam_target_m : ndarray, shape (N, 3)
    """
    from ._lm_kernel import posit_batch

    P = np.ascontiguousarray(points_m, dtype=np.float64)
    B = _posit_basis(P.tobytes(), P.shape)
    N = xy.shape[0]
    R = np.empty((N, 3, 3))
    t = np.empty((N, 3))
    posit_batch(np.ascontiguousarray(xy, dtype=np.float64), P, B, int(n_iter), R, t)
    return R, t


# --------------------------------------------------------------------------- results
@dataclass
class Solution(Solved):
    """A solved pose: truthy.

    Attributes
    ----------
    state : ndarray, shape (6,)
        Paper state ``[X_L_m, Y_L_m, Z_L_m, phi_rad, theta_rad, psi_rad]``.
    R_cam_target : ndarray, shape (3, 3)
    t_cam_target_m : ndarray, shape (3,)
    residual_rms_px : float
        RMS of the whitened residuals (the reprojection error in px to first order).
    covariance : ndarray, shape (6, 6)
        Cramer-Rao bound of the state for centroid noise ``sigma_px`` per axis
        (units m^2, m rad, rad^2). Scales as ``sigma_px^2``.
    sigma_px : float
        The centroid noise the covariance is given for.
    iterations : int
    targets_px : dict
        Target id -> measured ``[u, v]``, when known.
    n_blobs : int or None
        Blobs the detector found (:func:`svgs_sim.svgs.pipeline.solve_image`).
    threshold_used : float or None
        The detector's binarisation level, image counts (:func:`svgs_sim.svgs.pipeline.solve_image`).
    consistency : svgs_sim.svgs.app.Consistency or None
        The residual's chi-square test against the stated centroid noise
        (:func:`svgs_sim.svgs.pipeline.solve_image`).
    outside_test_envelope : bool or None
        Set by the identification (:func:`svgs_sim.svgs.identify.identify`): the pose lies outside
        the paper's test envelope (solved where the paper did not test the sensor). ``None``: not
        judged (a solve of given centroids); then absent from :meth:`to_json`.
    """

    state: np.ndarray
    R_cam_target: np.ndarray
    t_cam_target_m: np.ndarray
    residual_rms_px: float
    covariance: np.ndarray
    sigma_px: float = 1.0
    iterations: int = 0
    targets_px: dict = field(default_factory=dict)
    n_blobs: int | None = None
    threshold_used: float | None = None
    consistency: object = None
    outside_test_envelope: bool | None = None

    @property
    def std(self) -> np.ndarray:
        """1-sigma bound per state component (m, m, m, rad, rad, rad), shape (6,)."""
        return np.sqrt(np.diag(self.covariance))

    def to_json(self) -> dict:
        return {
            "ok": True,
            "reason": None,
            "state": self.state_dict,
            "R_cam_target": self.R_cam_target.tolist(),
            "t_cam_target_m": self.t_cam_target_m.tolist(),
            "targets_px": {str(k): [float(x) for x in v] for k, v in self.targets_px.items()},
            "n_blobs": self.n_blobs,
            "residual_rms_px": float(self.residual_rms_px),
            "iterations": int(self.iterations),
            "crlb_std": dict(zip(
                STATE_KEYS,
                [float(v) for v in np.concatenate([self.std[:3], np.degrees(self.std[3:])])],
            )),
            "crlb_sigma_px": float(self.sigma_px),
            **({} if self.outside_test_envelope is None else {"outside_test_envelope": bool(self.outside_test_envelope)}),
            **(self.consistency.to_json() if self.consistency is not None else {}),
        }


@dataclass
class BatchSolution:
    """Solutions of N frames. Arrays have a leading axis N; failed rows hold NaN.

    Attributes
    ----------
    ok : ndarray of bool, shape (N,)
    reason : ndarray of object, shape (N,)
        ``None`` where solved, else a reason code of :data:`svgs_sim.svgs.result.REASONS`.
    state : ndarray, shape (N, 6)
    R_cam_target : ndarray, shape (N, 3, 3)
    t_cam_target_m : ndarray, shape (N, 3)
    residual_rms_px : ndarray, shape (N,)
    covariance : ndarray, shape (N, 6, 6)
    iterations : ndarray of int, shape (N,)
    sigma_px : float
    """

    ok: np.ndarray
    reason: np.ndarray
    state: np.ndarray
    R_cam_target: np.ndarray
    t_cam_target_m: np.ndarray
    residual_rms_px: np.ndarray
    covariance: np.ndarray
    iterations: np.ndarray
    sigma_px: float = 1.0

    def __len__(self) -> int:
        return int(self.ok.shape[0])

    def __getitem__(self, i: int):
        """Frame ``i`` as a :class:`Solution` or :class:`Failure`."""
        if not self.ok[i]:
            return Failure(str(self.reason[i]), _REASON_TEXT.get(str(self.reason[i]), str(self.reason[i])),
                           {"residual_rms_px": _f(self.residual_rms_px[i])})
        return Solution(self.state[i], self.R_cam_target[i], self.t_cam_target_m[i], float(self.residual_rms_px[i]),
                        self.covariance[i], self.sigma_px, int(self.iterations[i]))


def _f(x):
    x = float(x)
    return None if x != x else x


_REASON_TEXT = {
    "diverged": "the least-squares iteration did not converge to a consistent pose",
    "behind_camera": "the only consistent solution puts the target behind the camera",
}


# --------------------------------------------------------------------------- input checks
def _check_points(points_px, pattern: Pattern) -> tuple[np.ndarray, bool]:
    try:
        pts = np.asarray(points_px, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"points_px: expected numbers, got {type(points_px).__name__}") from None
    single = pts.ndim == 2
    if single:
        pts = pts[None]
    n = pattern.n
    if pts.ndim != 3 or pts.shape[1:] != (n, 2):
        raise InputError(
            f"points_px: expected shape ({n}, 2) or (N, {n}, 2) for pattern {pattern.name!r} with {n} targets, got {np.shape(points_px)}"
        )
    if pts.shape[0] == 0:
        raise InputError("points_px: no frames (N = 0)")
    from ._lm_kernel import check_points_batch

    pts = np.ascontiguousarray(pts, dtype=np.float64)
    flags = np.empty(pts.shape[0], np.int64)
    check_points_batch(pts, flags)
    bad = flags == 1
    if np.any(bad):
        raise InputError(f"points_px: non-finite centroid in frame(s) {np.flatnonzero(bad)[:10].tolist()}")
    deg = flags == 2  # degenerate sets: coincident points or all points on one line
    if np.any(deg):
        which = np.flatnonzero(deg)[:10].tolist()
        raise InputError(
            f"points_px: degenerate point set in frame(s) {which} (coincident or collinear centroids); a pose cannot be solved"
        )
    return pts, single


# --------------------------------------------------------------------------- solver
def _lm(R0, t0, meas_azel, Winv_sqrt, points_m, max_iter, step_tol):
    """Run the compiled Levenberg-Marquardt kernel (:mod:`svgs_sim.svgs._lm_kernel`) on N frames.

    Returns
    -------
    R (N, 3, 3), t (N, 3), converged (N,), iterations (N,), whitened residual (N, 2n),
    unit-noise paper-state covariance (N, 6, 6), smallest information pivot (N,).
    """
    from ._lm_kernel import lm_batch, lm_batch_serial

    R = np.ascontiguousarray(R0, dtype=np.float64).copy()
    t = np.ascontiguousarray(t0, dtype=np.float64).copy()
    kernel = lm_batch if R.shape[0] >= PARALLEL_MIN_FRAMES else lm_batch_serial
    conv, iters, rw, cov, piv = kernel(
        R, t, np.ascontiguousarray(points_m, dtype=np.float64),
        np.ascontiguousarray(meas_azel, dtype=np.float64), np.ascontiguousarray(Winv_sqrt, dtype=np.float64),
        int(max_iter), float(step_tol), np.ones(R.shape[0], np.bool_),
    )
    return R, t, conv, iters, rw, cov, piv


def solve_centroids(
    points_px,
    camera,
    pattern="svgs-3u",
    *,
    sigma_px: float = 1.0,
    max_iter: int = MAX_ITER,
    step_tol: float = STEP_TOL,
    max_residual_px: float = DEFAULT_MAX_RESIDUAL_PX,
    initial_state=None,
    front_side_only: bool = True,
):
    """Solve the 6-DOF state from labelled target centroids.

    Parameters
    ----------
    points_px : array_like, shape (n, 2) or (N, n, 2)
        Centroids in pixels (OpenCV convention, distorted as imaged), ordered by target id
        (``pattern.ids`` ascending).
    camera : Camera or str
        Camera profile (name, path or :class:`Camera`).
    pattern : Pattern or str
        Target pattern (default ``svgs-3u``).
    sigma_px : float
        Centroid noise (px, per axis) for which the Cramer-Rao covariance is reported.
    max_iter : int
        Iteration cap of the Levenberg-Marquardt loop.
    step_tol : float
        Convergence tolerance on the step (relative to range for position, radians for angles).
    max_residual_px : float
        A converged solution whose RMS reprojection residual exceeds this is a failure
        (``diverged``): the points are not an image of the pattern.
    initial_state : array_like, shape (6,) or (N, 6), optional
        A starting state; by default POSIT provides one.
    front_side_only : bool
        Reject solutions with the camera behind the target plane (``Z_L <= 0``), from
        where the retroreflectors (facing +z) return no light: reason ``behind_target``.

    Returns
    -------
    Solution or Failure
        For a single frame.
    BatchSolution
        For ``N`` frames.
    """
    camera = load_camera(camera)
    pattern = load_pattern(pattern)
    if not (np.isfinite(sigma_px) and sigma_px > 0):
        raise InputError(f"sigma_px: expected a positive centroid noise in px, got {sigma_px!r}")
    pts, single = _check_points(points_px, pattern)
    if single and initial_state is None:
        sol = _solve_single(pts, camera, pattern, sigma_px, max_iter, step_tol, max_residual_px, front_side_only)
        if sol is not None:
            return sol
    N, n = pts.shape[:2]
    xy, meas, Winv_sqrt = _measurements(pts, camera)
    P = pattern.points_m

    if initial_state is None:
        R0, t0 = posit(xy, P)
    else:
        R0, t0 = state_to_pose(np.broadcast_to(np.asarray(initial_state, float), (N, 6)))
    R, t, conv, iters, rw, cov1, piv = _lm(R0, t0, meas, Winv_sqrt, P, max_iter, step_tol)
    res = np.sqrt(np.sum(rw * rw, 1) / n)
    fit = [R, t, conv, iters, res, cov1, piv]
    _retry_from_other_starts(fit, xy, meas, Winv_sqrt, P, max_iter, step_tol, max_residual_px)
    x = pose_to_state(R, t)
    ok, reason = _verdicts(R, t, x, conv, res, piv, P, max_residual_px, front_side_only)
    # Cramer-Rao bound: (J^T Sigma^-1 J)^-1 with Sigma = G G^T sigma^2 per point, from the kernel
    cov = cov1 * sigma_px**2
    x[~ok] = np.nan
    R[~ok] = np.nan
    t[~ok] = np.nan
    batch = BatchSolution(ok, reason, x, R, t, res, cov, iters, float(sigma_px))
    if not single:
        return batch
    if not ok[0]:
        return _frame_failure(reason[0], res[0], iters[0])
    sol = batch[0]
    sol.targets_px = {int(i): pts[0, k].tolist() for k, i in enumerate(pattern.ids)}
    return sol


def _frame_failure(reason: str, residual_rms_px: float, iterations: int) -> Failure:
    """The :class:`Failure` of one frame that :func:`solve_centroids` could not solve.

    Parameters
    ----------
    reason : str
        ``diverged``, ``behind_camera``, ``degenerate`` or ``behind_target``.
    residual_rms_px : float
        RMS reprojection residual of the last iterate, px.
    iterations : int
        Levenberg-Marquardt iterations run.

    Returns
    -------
    Failure
    """
    msg = {
        "diverged": f"no pose reproduces the centroids (RMS residual {residual_rms_px:.3g} px after {iterations} "
                    f"iterations)",
        "behind_camera": "the only pose that fits puts the target behind the camera",
        "degenerate": "the centroids do not constrain all six pose parameters",
        "behind_target": "the only pose that fits views the target from behind (a mirror image of the pattern?)",
    }[reason]
    return Failure(reason, msg, {"residual_rms_px": _f(residual_rms_px), "iterations": int(iterations)})


def _solve_single(pts, camera, pattern, sigma_px, max_iter, step_tol, max_residual_px, front_side_only):
    """One frame the short way: the same kernels as the batch path (POSIT start, the compiled
    Levenberg-Marquardt, the paper state from its kernel) without the batch bookkeeping. Returns
    None whenever the batch path has more to do (a start that does not converge or fit, a
    verdict other than solved): that path then runs and decides, so answers never differ."""
    from ._lm_kernel import lm_batch_serial, paper_state, posit_batch

    n = pts.shape[1]
    xy, meas, W = _measurements(pts, camera)
    P = _pattern_points(pattern)
    R = np.empty((1, 3, 3))
    t = np.empty((1, 3))
    posit_batch(xy, P, _posit_basis(P.tobytes(), P.shape), 10, R, t)
    conv, iters, rw, cov1, piv = lm_batch_serial(R, t, P, meas, W, int(max_iter), float(step_tol), _ONE_ACTIVE)
    res = float(np.sqrt(np.dot(rw[0], rw[0]) / n))
    if not (conv[0] and res <= max_residual_px and piv[0] > 1e-14):
        return None
    R0, t0 = R[0], t[0]
    if not (np.isfinite(t0).all() and np.all(P @ R0[2] + t0[2] > 0)):
        return None
    x = np.empty(6)
    paper_state(R0, t0, x)
    if front_side_only and not x[2] > 0:
        return None
    sol = Solution(x, R0, t0, res, cov1[0] * sigma_px**2, float(sigma_px), int(iters[0]))
    sol.targets_px = {int(i): pts[0, k].tolist() for k, i in enumerate(pattern.ids)}
    return sol


_ONE_ACTIVE = np.ones(1, np.bool_)


def _pattern_points(pattern) -> np.ndarray:
    P = getattr(pattern, "_points_c64", None)
    if P is None:
        P = np.ascontiguousarray(pattern.points_m, dtype=np.float64)
        try:
            object.__setattr__(pattern, "_points_c64", P)
        except (AttributeError, TypeError):
            pass
    return P


def _measurements(pts: np.ndarray, camera: Camera):
    """Normalised coordinates, az/el measurements and their whitening of centroids (N, n, 2).

    Returns
    -------
    xy : ndarray, shape (N, n, 2)
        Undistorted normalised coordinates (OpenCV camera frame).
    meas : ndarray, shape (N, n, 2)
        Azimuth and elevation, rad.
    Winv_sqrt : ndarray, shape (N, n, 2, 2)
        ``G^-1`` (px/rad): whitens az/el residuals into pixel residuals.
    """
    from ._lm_kernel import measurements_batch

    pts = np.ascontiguousarray(pts, dtype=np.float64)
    xy = np.empty_like(pts)
    meas = np.empty_like(pts)
    Winv_sqrt = np.empty(pts.shape + (2,))
    measurements_batch(pts, float(camera.fx), float(camera.fy), float(camera.cx), float(camera.cy),
                       np.ascontiguousarray(camera.dist, dtype=np.float64).reshape(5), xy, meas, Winv_sqrt)
    return xy, meas, Winv_sqrt


def _retry_from_other_starts(fit: list, xy, meas, Winv_sqrt, P, max_iter: int, step_tol: float,
                             max_residual_px: float) -> None:
    """Re-solve the frames that did not converge or fit badly from :func:`_alternative_starts`.

    ``fit`` is ``[R, t, conv, iters, res, cov1, piv]`` (arrays over frames), updated in place
    where a start converges to a smaller residual.
    """
    R, t, conv, iters, res, cov1, piv = fit
    n = xy.shape[1]
    bad = ~conv | ~(res <= max_residual_px) | ~np.all(np.isfinite(t), 1)
    if not np.any(bad):
        return
    bi = np.flatnonzero(bad)
    n_starts = len(_alternative_starts(xy[:1], P))
    for k in range(n_starts):
        Rs, ts = state_to_pose(_alternative_starts(xy[bi], P)[k])
        Rk, tk, cs, its, rws, covk, pivk = _lm(Rs, ts, meas[bi], Winv_sqrt[bi], P, max_iter, step_tol)
        rs = np.sqrt(np.sum(rws * rws, 1) / n)
        take = cs & (rs < np.where(np.isfinite(res[bi]) & conv[bi], res[bi], np.inf))
        R[bi[take]], t[bi[take]] = Rk[take], tk[take]
        cov1[bi[take]], piv[bi[take]] = covk[take], pivk[take]
        conv[bi[take]] = True
        res[bi[take]] = rs[take]
        iters[bi[take]] += its[take]
        bad = ~conv | ~(res <= max_residual_px)
        bi = np.flatnonzero(bad)
        if bi.size == 0:
            break


def _verdicts(R, t, x, conv, res, piv, P, max_residual_px: float, front_side_only: bool):
    """Which frames are solved, and the reason code of the others.

    Returns
    -------
    ok : ndarray of bool, shape (N,)
    reason : ndarray of object, shape (N,)
        ``None`` where solved, else ``diverged``, ``behind_camera``, ``behind_target`` or
        ``degenerate``.
    """
    N = x.shape[0]
    depth_ok = np.all(np.einsum("kij,nj->kni", R, P)[..., 2] + t[:, None, 2] > 0, axis=1)
    ok = conv & (res <= max_residual_px) & np.all(np.isfinite(x), 1) & depth_ok
    reason = np.full(N, None, dtype=object)
    reason[~ok] = "diverged"
    reason[conv & ~depth_ok] = "behind_camera"
    if front_side_only:
        # the reflectors face the target's +z: a camera at Z_L <= 0 cannot see their return
        back = conv & depth_ok & (x[:, 2] <= 0)
        ok &= ~back
        reason[back] = "behind_target"
    degenerate = ok & ~(piv > 1e-14)
    ok[degenerate] = False
    reason[degenerate] = "degenerate"
    return ok, reason

def _alternative_starts(xy, P):
    """Fallback starting states (N, 6): the target facing the camera at the POSIT-free range
    estimate, with the in-image rotation taken from the two most distant targets."""
    N = xy.shape[0]
    # range from the largest image baseline versus the largest pattern baseline
    dP = np.linalg.norm(P[:, None] - P[None], axis=-1)
    a, b = np.unravel_index(np.argmax(dP), dP.shape)
    d_img = np.linalg.norm(xy[:, a] - xy[:, b], axis=-1)
    rng = dP[a, b] / np.maximum(d_img, 1e-12)
    c = xy.mean(1)
    # in-image rotation: angle of (b -> a) in the image versus the pattern (photo frame: v up)
    ang_img = np.arctan2(-(xy[:, a, 1] - xy[:, b, 1]), xy[:, a, 0] - xy[:, b, 0])
    ang_pat = np.arctan2(P[a, 1] - P[b, 1], P[a, 0] - P[b, 0])
    starts = []
    for tilt in (0.0, 0.35, -0.35):
        for axis in (3, 4):
            psi = -(ang_img - ang_pat)
            s = np.zeros((N, 6))
            s[:, axis] = tilt
            s[:, 5] = psi
            # perspective centre such that the pattern centroid lies along the measured ray
            M = rotation_from_angles(s[:, 3], s[:, 4], s[:, 5])
            ray_photo = np.stack([c[:, 0], -c[:, 1], -np.ones(N)], -1)
            p_photo = ray_photo * rng[:, None]
            Pc = P.mean(0)
            s[:, :3] = Pc[None] - np.einsum("kji,kj->ki", M, p_photo)
            starts.append(s)
            if tilt == 0.0:
                break
    return starts


__all__ = [
    "Solution",
    "BatchSolution",
    "solve_centroids",
    "azel_from_normalized",
    "azel_pixel_jacobian",
    "posit",
    "D_CAM_PHOTO",
]
