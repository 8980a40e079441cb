"""Full intrinsic calibration from views of planar boards, with OpenCV.

Calibration (:func:`calibrate`, :func:`calibrate_images`)
    ``cv2.calibrateCameraExtended`` with the pinhole + Brown-Conrady model (k1, k2, p1, p2,
    k3) and optional constraints: fixed aspect ratio, fixed principal point (the image
    centre ``((W - 1) / 2, (H - 1) / 2)`` in the OpenCV pixel-centre convention, or a
    given point), zero tangential distortion, fixed ``k3 = 0``. Returns the intrinsics,
    their standard deviations, the RMS and per-view reprojection errors.

Everything is in metres; ``t`` vectors come out in metres. :func:`mapping_error_px` says how
far an estimated camera maps rays from where the true one does.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from svgs_sim.base.errors import InputError, check_finite_positive
from svgs_sim.base.profiles import DISTORTION_KEYS, Camera
from svgs_sim.svgs.pipeline import load_image
from svgs_sim.svgs.result import Failure

from .boards import Board
from .detection import DistinctViews, detect_views, to_gray8

#: Fewest usable views :func:`calibrate` accepts by default (Zhang's method needs 3 for
#: the five pinhole parameters without constraints).
MIN_VIEWS = 3
#: Names of the standard deviations reported (OpenCV's ``stdDeviationsIntrinsics`` order).
STD_KEYS = ("fx", "fy", "cx", "cy") + DISTORTION_KEYS


#: How far fx / fy may be from 1 before :attr:`Calibration.warnings` says the pixels are not square
#: (phone sensors have square pixels; calibrations of real phones give fx / fy within a few 0.1 %).
NON_SQUARE_ASPECT = 0.05


@dataclass
class Calibration:
    """The result of an intrinsic calibration.

    Attributes
    ----------
    camera_matrix : ndarray, shape (3, 3)
    dist : ndarray, shape (5,)
        ``k1, k2, p1, p2, k3``.
    image_size : tuple of int
        ``(width, height)``, pixels.
    rms_px : float
        RMS reprojection error over all points (OpenCV's definition: the root of the mean
        squared 2-D residual norm).
    per_view_rms_px : ndarray, shape (V,)
    std : dict
        1-sigma standard deviation of each parameter (:data:`STD_KEYS`), from OpenCV's
        covariance with the residual variance; 0 for a fixed parameter.
    rvecs : ndarray, shape (V, 3)
    tvecs_m : ndarray, shape (V, 3)
        Board poses (board -> camera), metres.
    views : list of str
        Names of the views used.
    n_points : ndarray of int, shape (V,)
    skipped : list of (str, Failure)
        Views not used and why.
    constraints : dict
    flags : int
        The OpenCV flags used.
    board : Board or None
    """

    camera_matrix: np.ndarray
    dist: np.ndarray
    image_size: tuple
    rms_px: float
    per_view_rms_px: np.ndarray
    std: dict
    rvecs: np.ndarray
    tvecs_m: np.ndarray
    views: list
    n_points: np.ndarray
    skipped: list = field(default_factory=list)
    constraints: dict = field(default_factory=dict)
    flags: int = 0
    board: Board | None = None

    @property
    def fx(self) -> float:
        return float(self.camera_matrix[0, 0])

    @property
    def warnings(self) -> list:
        """Signs of a poorly constrained calibration, as sentences (empty when none)."""
        w, h = self.image_size
        out = []
        for k in ("fx", "fy"):
            if self.std[k] > 0.01 * getattr(self, k):
                out.append(f"{k} is uncertain by {100 * self.std[k] / getattr(self, k):.1f} % (1 sigma)")
        for k, size in (("cx", w), ("cy", h)):
            if self.std[k] > 0.02 * size:
                out.append(f"{k} is uncertain by {self.std[k]:.1f} px (1 sigma)")
        if len(self.views) < 8:
            out.append(f"only {len(self.views)} views: 10-25 views, tilted in different directions, are usual")
        if out:
            out.append("add views (tilted boards, covering the image corners) or constrain the model "
                       "(--fix-aspect, --fix-principal-point, --zero-tangent, --fix-k3)")
        aspect = self.fx / self.fy
        if abs(aspect - 1.0) > NON_SQUARE_ASPECT:
            out.append(f"the pixels come out non-square: fx {self.fx:.1f} px, fy {self.fy:.1f} px (fx/fy {aspect:.3g}); "
                       "a phone's pixels are square, so the images were likely resized to another shape (render-board "
                       "--width/--height not in the profile's proportion) or the board is misdescribed")
        return out

    @property
    def fy(self) -> float:
        return float(self.camera_matrix[1, 1])

    @property
    def cx(self) -> float:
        return float(self.camera_matrix[0, 2])

    @property
    def cy(self) -> float:
        return float(self.camera_matrix[1, 2])

    def to_camera(self, name: str = "calibrated", base: Camera | None = None) -> Camera:
        """A camera profile with these intrinsics.

        Parameters
        ----------
        name : str
        base : Camera, optional
            Keep this profile's other tables (sensor, optics...) and its key (the same phone,
            recalibrated); its image size must match.

        Returns
        -------
        Camera
            With a ``[calibration]`` table recording the method, board, RMS and
            standard deviations.
        """
        w, h = self.image_size
        if base is not None and (base.width, base.height) != (w, h):
            raise InputError(
                f"camera {base.name!r} is {base.width} x {base.height} px but the calibration images are {w} x {h} px"
            )
        record = {
            "method": "opencv-calibrateCamera",
            "board": self.board.describe() if self.board is not None else "given points",
            "n_views": len(self.views),
            "n_skipped": len(self.skipped),
            "rms_px": float(self.rms_px),
            "constraints": ", ".join(k for k, v in self.constraints.items() if v is True) or "none",
            **{f"std_{k}": float(v) for k, v in self.std.items()},
        }
        geometry = dict(name=name, width=int(w), height=int(h), fx=self.fx, fy=self.fy, cx=self.cx, cy=self.cy,
                        dist=np.asarray(self.dist, float), source="")
        cam = Camera(**geometry) if base is None else base.replace(**geometry)
        return cam.with_tables(calibration=record)

    def to_json(self) -> dict:
        """JSON-ready dict (non-finite numbers become ``None``)."""
        w, h = self.image_size
        return _finite_or_none({
            "ok": True,
            "board": self.board.to_json() if self.board is not None else None,
            "image_size": [int(w), int(h)],
            "fx_px": self.fx, "fy_px": self.fy, "cx_px": self.cx, "cy_px": self.cy,
            "dist": {k: float(v) for k, v in zip(DISTORTION_KEYS, self.dist)},
            "std": {k: float(v) for k, v in self.std.items()},
            "rms_px": float(self.rms_px),
            "constraints": dict(self.constraints),
            "n_views": len(self.views),
            "per_view": [
                {"image": v, "rms_px": float(e), "n_points": int(n)}
                for v, e, n in zip(self.views, self.per_view_rms_px, self.n_points)
            ],
            "skipped": [{"image": v, "reason": f.reason, "message": f.message} for v, f in self.skipped],
            "warnings": self.warnings,
        })

    def summary(self) -> str:
        """A readable multi-line report."""
        s = self.std
        w, h = self.image_size
        lines = []
        if self.board is not None:
            lines.append(f"board: {self.board.describe()}")
        cons = [k for k, v in self.constraints.items() if v is True]
        lines += [
            f"image size: {w} x {h} px; views used: {len(self.views)}, skipped: {len(self.skipped)}; "
            f"constraints: {', '.join(cons) or 'none'}",
            f"fx = {self.fx:.3f} +- {s['fx']:.3f} px   fy = {self.fy:.3f} +- {s['fy']:.3f} px",
            f"cx = {self.cx:.3f} +- {s['cx']:.3f} px   cy = {self.cy:.3f} +- {s['cy']:.3f} px",
            "distortion: " + "  ".join(f"{k} = {v:+.6f} +- {s[k]:.6f}" for k, v in zip(DISTORTION_KEYS, self.dist)),
            f"RMS reprojection error: {self.rms_px:.4f} px",
            "per-view RMS (px):",
        ]
        for v, e, n in zip(self.views, self.per_view_rms_px, self.n_points):
            lines.append(f"  {v}: {e:.4f} ({n} points)")
        if self.skipped:
            lines.append("skipped (board not used):")
            for v, f in self.skipped:
                lines.append(f"  {v}: {f.reason}: {f.message}")
        for text in self.warnings:
            lines.append(f"warning: {text}")
        return "\n".join(lines)


def _finite_or_none(obj):
    if isinstance(obj, dict):
        return {k: _finite_or_none(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite_or_none(v) for v in obj]
    if isinstance(obj, (float, np.floating)):
        return float(obj) if np.isfinite(obj) else None
    return obj


def calibrate(
    object_points,
    image_points,
    image_size,
    *,
    fix_aspect: bool = False,
    aspect_ratio: float = 1.0,
    fix_principal_point: bool = False,
    principal_point=None,
    zero_tangent: bool = False,
    fix_k3: bool = False,
    views=None,
    min_views: int = MIN_VIEWS,
    board: Board | None = None,
    skipped=None,
) -> Calibration:
    """Calibrate the intrinsics from point correspondences of planar boards.

    Parameters
    ----------
    object_points : sequence of ndarray, each shape (M_k, 3)
        Board-frame points (``z = 0``), metres.
    image_points : sequence of ndarray, each shape (M_k, 2)
        Their pixel positions (pixel centres at integer coordinates).
    image_size : (int, int)
        ``(width, height)``, pixels.
    fix_aspect : bool
        Keep ``fx / fy = aspect_ratio`` (``CALIB_FIX_ASPECT_RATIO``).
    aspect_ratio : float
        ``fx / fy`` when ``fix_aspect``.
    fix_principal_point : bool
        Keep the principal point at ``principal_point`` (``CALIB_FIX_PRINCIPAL_POINT``).
    principal_point : (float, float), optional
        Default: the image centre ``((W - 1) / 2, (H - 1) / 2)``. Giving it implies
        ``fix_principal_point``.
    zero_tangent : bool
        ``p1 = p2 = 0`` (``CALIB_ZERO_TANGENT_DIST``).
    fix_k3 : bool
        ``k3 = 0`` (``CALIB_FIX_K3``), for few or near-frontal views.
    views : sequence of str, optional
        View names for the report.
    min_views : int
        Fewest views accepted.
    board : Board, optional
        Recorded in the result.
    skipped : list of (str, Failure), optional
        Recorded in the result.

    Returns
    -------
    Calibration

    Raises
    ------
    InputError
        Too few views, mismatched point arrays, or a calibration OpenCV cannot solve.
    """
    obj, img, names = _check_views(object_points, image_points, views, min_views)
    w, h = _check_image_size(image_size)
    if principal_point is not None:
        fix_principal_point = True
    pp = _principal_point(principal_point, w, h)
    aspect = check_finite_positive(aspect_ratio, "aspect ratio") if fix_aspect else 1.0
    out, flags = _calibrate_opencv(obj, img, (w, h), pp, aspect, fix_aspect=fix_aspect,
                                   fix_principal_point=fix_principal_point, zero_tangent=zero_tangent, fix_k3=fix_k3)
    rms, K, dist, rvecs, tvecs, std_intr, _std_extr, per_view = out
    K, dist = _checked_intrinsics(K, dist, len(obj))
    std = _intrinsic_std(std_intr, fix_aspect, aspect)
    constraints = _constraints(fix_aspect, aspect, fix_principal_point, pp, zero_tangent, fix_k3)
    return Calibration(
        camera_matrix=K,
        dist=dist,
        image_size=(w, h),
        rms_px=float(rms),
        per_view_rms_px=np.asarray(per_view, float).reshape(-1),
        std=std,
        rvecs=np.asarray(rvecs, float).reshape(-1, 3),
        tvecs_m=np.asarray(tvecs, float).reshape(-1, 3),
        views=names,
        n_points=np.array([o.shape[0] for o in obj]),
        skipped=list(skipped or []),
        constraints=constraints,
        flags=int(flags),
        board=board,
    )


def _checked_intrinsics(K, dist, n_views: int) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV's camera matrix and distortion as arrays; :class:`InputError` when they diverged.

    Parameters
    ----------
    K : array_like, shape (3, 3)
        Camera matrix, px.
    dist : array_like
        Distortion coefficients (the first five are kept).
    n_views : int
        Views calibrated (for the message).

    Returns
    -------
    K : ndarray, shape (3, 3)
    dist : ndarray, shape (5,)
        ``(k1, k2, p1, p2, k3)``.
    """
    K = np.asarray(K, float)
    dist = np.asarray(dist, float).reshape(-1)[:5]
    if not (np.all(np.isfinite(K)) and np.all(np.isfinite(dist)) and K[0, 0] > 0 and K[1, 1] > 0):
        raise InputError(f"calibrate: the calibration from these {n_views} views diverged; use more, better spread views")
    return K, dist


def _intrinsic_std(std_intr, fix_aspect: bool, aspect: float) -> dict:
    """OpenCV's standard deviations of the intrinsics, keyed by :data:`STD_KEYS`.

    Parameters
    ----------
    std_intr : array_like
        ``stdDeviationsIntrinsics`` of ``cv2.calibrateCameraExtended``.
    fix_aspect : bool
        With a fixed aspect ratio OpenCV estimates ``fy`` only; ``fx``'s is then ``aspect * fy``'s.
    aspect : float
        ``fx / fy``.

    Returns
    -------
    dict
        Key -> standard deviation (px for the focal lengths and principal point).
    """
    sd = np.asarray(std_intr, float).reshape(-1)
    std = {k: float(v) for k, v in zip(STD_KEYS, sd[: len(STD_KEYS)])}
    if fix_aspect:  # OpenCV estimates fy only; fx = aspect * fy
        std["fx"] = aspect * std["fy"]
    return std


def _constraints(fix_aspect, aspect, fix_principal_point, pp, zero_tangent, fix_k3) -> dict:
    """The constraints as recorded in :attr:`Calibration.constraints`."""
    constraints = {
        "fix_aspect": bool(fix_aspect),
        "fix_principal_point": bool(fix_principal_point),
        "zero_tangent": bool(zero_tangent),
        "fix_k3": bool(fix_k3),
    }
    if fix_aspect:
        constraints["aspect_ratio"] = aspect
    if fix_principal_point:
        constraints["principal_point_px"] = [pp[0], pp[1]]
    return constraints


def _check_views(object_points, image_points, views, min_views: int):
    """Validated point sets of the views.

    Returns
    -------
    obj : list of ndarray, each shape (M_k, 3), float64
    img : list of ndarray, each shape (M_k, 2), float64
    names : list of str
    """
    obj = [np.asarray(o, np.float64).reshape(-1, 3) for o in object_points]
    img = [np.asarray(i, np.float64).reshape(-1, 2) for i in image_points]
    if len(obj) != len(img):
        raise InputError(f"calibrate: {len(obj)} object point sets but {len(img)} image point sets")
    names = [f"view {k + 1}" for k in range(len(obj))] if views is None else [str(v) for v in views]
    if len(names) != len(obj):
        raise InputError(f"calibrate: {len(names)} view names for {len(obj)} views")
    for n, o, i in zip(names, obj, img):
        if o.shape[0] != i.shape[0]:
            raise InputError(f"calibrate: {n}: {o.shape[0]} object points but {i.shape[0]} image points")
        if o.shape[0] < 4:
            raise InputError(f"calibrate: {n}: needs at least 4 points, got {o.shape[0]}")
        if not (np.all(np.isfinite(o)) and np.all(np.isfinite(i))):
            raise InputError(f"calibrate: {n}: points must be finite")
        if np.any(np.abs(o[:, 2]) > 1e-9 * max(np.abs(o).max(), 1.0)):
            raise InputError(f"calibrate: {n}: object points must be planar with z = 0")
    if len(obj) < max(int(min_views), 1):
        raise InputError(f"calibrate: {len(obj)} usable view(s), need at least {min_views}")
    return obj, img, names


def _check_image_size(image_size) -> tuple[int, int]:
    """``(width, height)`` in pixels, both positive integers."""
    try:
        w, h = (int(image_size[0]), int(image_size[1]))
    except (TypeError, ValueError, IndexError):
        raise InputError(f"calibrate: image_size must be (width, height), got {image_size!r}") from None
    if w <= 0 or h <= 0:
        raise InputError(f"calibrate: image_size must be positive, got {image_size!r}")
    return w, h


def _principal_point(principal_point, w: int, h: int) -> tuple[float, float]:
    """The given principal point (checked to lie in the image) or the image centre, pixels."""
    if principal_point is None:
        return ((w - 1) / 2.0, (h - 1) / 2.0)
    pp = (float(principal_point[0]), float(principal_point[1]))
    if not (np.all(np.isfinite(pp)) and -0.5 <= pp[0] <= w - 0.5 and -0.5 <= pp[1] <= h - 0.5):
        raise InputError(f"principal point {pp} lies outside the {w} x {h} px image")
    return pp


def _calibrate_opencv(obj, img, size, pp, aspect: float, *, fix_aspect: bool, fix_principal_point: bool,
                      zero_tangent: bool, fix_k3: bool):
    """Run ``cv2.calibrateCameraExtended`` with the constraints as OpenCV flags.

    Returns
    -------
    out : tuple
        OpenCV's ``(rms, K, dist, rvecs, tvecs, std_intrinsics, std_extrinsics, per_view_errors)``.
    flags : int
        The flags used.
    """
    import cv2

    flags = 0
    if fix_aspect:
        flags |= cv2.CALIB_FIX_ASPECT_RATIO
    if zero_tangent:
        flags |= cv2.CALIB_ZERO_TANGENT_DIST
    if fix_k3:
        flags |= cv2.CALIB_FIX_K3
    obj32 = [o.astype(np.float32) for o in obj]
    img32 = [i.astype(np.float32).reshape(-1, 1, 2) for i in img]
    try:
        if fix_principal_point:
            # Start from OpenCV's closed-form guess and put the principal point where asked.
            K0 = cv2.initCameraMatrix2D(obj32, img32, size, aspect if fix_aspect else 0.0)
            K0[0, 2], K0[1, 2] = pp
            flags |= cv2.CALIB_FIX_PRINCIPAL_POINT | cv2.CALIB_USE_INTRINSIC_GUESS
        else:
            K0 = np.array([[aspect, 0.0, pp[0]], [0.0, 1.0, pp[1]], [0.0, 0.0, 1.0]])
        crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-12)
        out = cv2.calibrateCameraExtended(obj32, img32, size, K0, np.zeros(5), flags=flags, criteria=crit)
    except cv2.error as exc:
        msg = str(exc).strip().splitlines()[-1] if str(exc).strip() else "OpenCV error"
        raise InputError(
            f"calibrate: OpenCV could not calibrate from these {len(obj)} views ({msg}); "
            "use more views with the board tilted in different directions"
        ) from None
    return out, flags


def calibrate_images(images, board: Board, *, names=None, min_views: int = MIN_VIEWS, **constraints) -> Calibration:
    """Detect the board in each image and calibrate.

    Parameters
    ----------
    images : sequence of str, Path or ndarray
        Image files or arrays (grey or RGB, any depth), all of one size.
    board : Board
    names : sequence of str, optional
        View names (default: the file names, or ``view N`` for arrays).
    min_views : int
        Fewest views in which the board must be found.
    **constraints
        Passed to :func:`calibrate` (``fix_aspect``, ``fix_principal_point``,
        ``principal_point``, ``zero_tangent``, ``fix_k3``, ``aspect_ratio``).

    Returns
    -------
    Calibration
        Views where the board was not found are in ``skipped``.

    Raises
    ------
    InputError
        No images, no readable image, images of different sizes (the message names the files
        of each size), or fewer than ``min_views`` views with the board (the message lists the
        skipped views). An unreadable file is skipped (reason ``unreadable``), as a view without
        the board is.
    """

    images = list(images)
    if not images:
        raise InputError("calibrate: no images given")
    if names is None:
        names = [Path(im).name if isinstance(im, (str, Path)) else f"view {k + 1}" for k, im in enumerate(images)]
    names = [str(n) for n in names]
    if len(names) != len(images):
        raise InputError(f"calibrate: {len(names)} names for {len(images)} images")
    grays, kept, unreadable = [], [], []
    for im, n in zip(images, names):
        try:  # one unreadable view is listed and skipped like a view without the board (issue 41)
            arr = load_image(im) if isinstance(im, (str, Path)) else np.asarray(im)
            grays.append(to_gray8(arr))
            kept.append(n)
        except InputError as exc:
            unreadable.append((n, Failure("unreadable", str(exc))))
    names = kept
    if not grays:
        raise InputError("calibrate: no image could be read: " + "; ".join(f"{n} ({f.message})" for n, f in unreadable[:5]))
    sizes = {}
    for g, n in zip(grays, names):
        sizes.setdefault((g.shape[1], g.shape[0]), []).append(n)
    if len(sizes) > 1:
        groups = "; ".join(
            f"{w} x {h} px: {', '.join(ns[:6])}{' ...' if len(ns) > 6 else ''}" for (w, h), ns in sizes.items()
        )
        raise InputError(f"calibration images differ in size ({groups}); all views must come from one camera mode")
    (w, h), = sizes.keys()
    obj, img, used, skipped = detect_views(grays, names, board)
    skipped = unreadable + skipped
    distinct, used_set = DistinctViews("images"), set(used)  # a used view given twice would count twice
    for g, n in zip(grays, names):
        if n in used_set:
            distinct.add(g, n)
    if len(used) < max(int(min_views), 1):
        lst = "; ".join(f"{n} ({f.message})" for n, f in skipped[:10]) + (" ..." if len(skipped) > 10 else "")
        hint = {
            "chessboard": "--cols/--rows count inner corners",
            "charuco": "--cols/--rows count squares; check --dictionary and --marker-mm",
            "circles": "--cols/--rows count circles per row and rows",
            "acircles": "--cols counts circles per row, --rows the rows (OpenCV: 4 x 11)",
        }[board.kind]
        raise InputError(
            f"board {board.describe()} found in {len(used)} of {len(grays)} images, need at least {min_views} "
            f"(check the board dimensions: {hint}); skipped: {lst}"
        )
    return calibrate(obj, img, (w, h), views=used, min_views=min_views, board=board, skipped=skipped, **constraints)


def mapping_error_px(camera_true: Camera, camera_est: Camera, step_px: float = 16.0, align: str = "none") -> np.ndarray:
    """How far the estimated camera maps each ray from where the true camera does.

    For a grid of pixels over the image, the ray the true camera sees there is projected
    with the estimated camera; the distance is the mapping error.

    Parameters
    ----------
    camera_true, camera_est : Camera
        Of the same image size.
    step_px : float
        Grid step, pixels.
    align : {"none", "rotation"}
        ``"rotation"``: first rotate the estimated camera by the small rotation that best
        aligns the two (least squares). A principal-point error is then largely absorbed
        (it is nearly a rotation - which shows up as an attitude bias, not here), and
        what remains is the error of the focal lengths and the distortion.

    Returns
    -------
    err_px : ndarray, shape (M,)
    """
    if (camera_true.width, camera_true.height) != (camera_est.width, camera_est.height):
        raise InputError("mapping_error_px: the two cameras differ in image size")
    if align not in ("none", "rotation"):
        raise InputError(f"mapping_error_px: align must be 'none' or 'rotation', got {align!r}")
    u = np.arange(0.0, camera_true.width - 0.5, step_px)
    v = np.arange(0.0, camera_true.height - 0.5, step_px)
    uv = np.stack(np.meshgrid(u, v), -1).reshape(-1, 2)
    xy = camera_true.pixels_to_normalized(uv)
    rays = np.concatenate([xy, np.ones((xy.shape[0], 1))], -1)
    if align == "none":
        return np.linalg.norm(camera_est.project(rays) - uv, axis=-1)
    import cv2
    from scipy.optimize import least_squares

    def resid(rv):
        R = cv2.Rodrigues(np.asarray(rv, float).reshape(3, 1))[0]
        return (camera_est.project(rays @ R.T) - uv).ravel()

    sol = least_squares(resid, np.zeros(3), method="lm", x_scale=1.0 / camera_true.fx)
    return np.linalg.norm(resid(sol.x).reshape(-1, 2), axis=-1)


__all__ = ["MIN_VIEWS", "STD_KEYS", "Calibration", "calibrate", "calibrate_images", "mapping_error_px"]
