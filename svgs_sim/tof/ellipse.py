"""Ellipses: conics, fits, projected circle centres (paper sections 3.3 and 3.4).

Conventions
    A conic is a symmetric 3 x 3 matrix ``C`` in homogeneous pixel coordinates
    ``x = (u, v, 1)``: the ellipse is ``x^T C x = 0``, with ``x^T C x < 0`` inside.

Projected circle centre (Kanatani)
    The image of a circle's centre is *not* the centre of the image ellipse. With the
    plane's unit normal ``n`` in the camera frame, the plane's vanishing line is
    ``l = K^-T n`` and the image of the circle's centre is its pole, ``x_c ~ C^-1 l``
    (:func:`projected_circle_centre`). The ellipse centre, the pole of the image's line at
    infinity, differs from it by a bias that grows as ``(r / Z)^2``; to first order::

        bias = f (r / Z)^2 [ n_z n_xy + m_xy (1 - n_z^2) ]

    with ``m = c / Z`` the circle centre in normalised coordinates (checked against the
    exact conic computation in ``tests/test_tof_ellipse.py``).

Circle from its image (paper eqs. 22-24)
    The cone ``Q = K^T C K`` of a circle of known radius gives two (centre, normal) pairs
    (:func:`circle_poses_from_conic`, the eigen-decomposition of the paper's section 3.4).

Ellipse detection
    :func:`fit_ellipse_subpixel` fits ``cv2.fitEllipseDirect`` to the sub-pixel crossings of
    an iso-level (:func:`level_crossings`) around a blob; :func:`detect_ellipse_arcs` is the
    edge-following detector used to supplement blobs when the count is wrong: it splits a
    contour into elliptical arcs by the paper's angle and curvature conditions and fits each
    arc (ellipse fits replace the paper's ElliFit).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from svgs_sim.base.errors import InputError


# --------------------------------------------------------------------------- conics
def ellipse_to_conic(center_px, axes_px, angle_rad) -> np.ndarray:
    """Conic of an ellipse.

    Parameters
    ----------
    center_px : array_like, shape (2,)
        ``(u, v)`` of the centre.
    axes_px : array_like, shape (2,)
        Semi-axes ``(a, b)``; ``a`` lies along ``angle_rad``.
    angle_rad : float
        Angle of the ``a`` axis from the +u axis (towards +v).

    Returns
    -------
    C : ndarray, shape (3, 3)
    """
    c = np.asarray(center_px, float)
    a, b = (float(x) for x in axes_px)
    if not (a > 0 and b > 0):
        raise InputError(f"axes_px: expected positive semi-axes, got {axes_px!r}")
    ct, st = np.cos(angle_rad), np.sin(angle_rad)
    R = np.array([[ct, -st], [st, ct]])
    A = R @ np.diag([1 / a**2, 1 / b**2]) @ R.T
    C = np.empty((3, 3))
    C[:2, :2] = A
    C[:2, 2] = C[2, :2] = -A @ c
    C[2, 2] = c @ A @ c - 1.0
    return C


def conic_center(C) -> np.ndarray:
    """Centre of a central conic, shape (..., 3, 3) -> (..., 2)."""
    C = np.asarray(C, float)
    return -np.linalg.solve(C[..., :2, :2], C[..., :2, 2:3])[..., 0]


# ------------------------------------------------------------- circles and projection
def _cross(a, b):
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def _plane_basis(n):
    n = np.asarray(n, float) / np.sqrt(n[0] ** 2 + n[1] ** 2 + n[2] ** 2)
    u = _cross(n, (1.0, 0.0, 0.0) if abs(n[0]) < 0.9 else (0.0, 1.0, 0.0))
    u /= np.sqrt(u @ u)
    return u, _cross(n, u), n


def project_circle_conic(K, center_cam_m, normal_cam, radius_m) -> np.ndarray:
    """Exact image conic of a 3-D circle through a pinhole camera.

    Parameters
    ----------
    K : array_like, shape (3, 3)
    center_cam_m : array_like, shape (3,)
        Circle centre in the camera frame (z > 0).
    normal_cam : array_like, shape (3,)
        Normal of the circle's plane.
    radius_m : float

    Returns
    -------
    C : ndarray, shape (3, 3)
        ``C = H^-T diag(1, 1, -r^2) H^-1`` with ``H = K [u v c]``; scaled to unit max norm.
    """
    u, v, _ = _plane_basis(normal_cam)
    H = np.asarray(K, float) @ np.column_stack([u, v, np.asarray(center_cam_m, float)])
    Hi = np.linalg.inv(H)
    C = Hi.T @ np.diag([1.0, 1.0, -float(radius_m) ** 2]) @ Hi
    C = C / np.abs(C).max()
    return C if np.linalg.det(C[:2, :2]) > 0 and C[0, 0] > 0 else -C


def project_circle_conics(K, centers_cam_m, normal_cam, radii_m) -> np.ndarray:
    """Batched :func:`project_circle_conic` for circles sharing one plane normal.

    Parameters
    ----------
    K : array_like, shape (3, 3)
    centers_cam_m : array_like, shape (n, 3)
    normal_cam : array_like, shape (3,)
    radii_m : array_like, shape (n,)

    Returns
    -------
    C : ndarray, shape (n, 3, 3)
        Unnormalised conics (``H^-T diag(1, 1, -r^2) H^-1``).
    """
    u, v, _ = _plane_basis(np.asarray(normal_cam, float))
    c = np.asarray(centers_cam_m, float)
    n = c.shape[0]
    B = np.empty((n, 3, 3))
    B[:, :, 0] = u
    B[:, :, 1] = v
    B[:, :, 2] = c
    Hi = np.linalg.inv(np.asarray(K, float) @ B)
    D = np.zeros((n, 3, 3))
    D[:, 0, 0] = D[:, 1, 1] = 1.0
    D[:, 2, 2] = -np.asarray(radii_m, float) ** 2
    return np.swapaxes(Hi, 1, 2) @ D @ Hi


def projected_circle_centre(C, K, normal_cam) -> np.ndarray:
    """Image of a circle's centre: the pole of the plane's vanishing line ``K^-T n``.

    Parameters
    ----------
    C : array_like, shape (..., 3, 3)
        Image conic(s) of the circle(s).
    K : array_like, shape (3, 3)
    normal_cam : array_like, shape (..., 3)
        Plane normal(s) in the camera frame (either orientation).

    Returns
    -------
    uv_px : ndarray, shape (..., 2)
    """
    C = np.asarray(C, float)
    line = np.einsum("ji,...j->...i", np.linalg.inv(np.asarray(K, float)), np.asarray(normal_cam, float))
    x = np.linalg.solve(C, line[..., None])[..., 0]
    return x[..., :2] / x[..., 2:3]


def centre_correction_px(C, K, normal_cam) -> np.ndarray:
    """Shift from the ellipse centre to the projected circle centre, shape (..., 2)."""
    return projected_circle_centre(C, K, normal_cam) - conic_center(C)


def circle_poses_from_conic(C, K, radius_m) -> tuple[np.ndarray, np.ndarray]:
    """The two 3-D circles of known radius that project to a conic (paper section 3.4).

    Eigen-decomposition of the cone ``Q = K^T C K = V diag(l1, l2, l3) V^T`` with
    ``l1 >= l2 > 0 > l3``; the normal is ``V (+-sqrt((l1-l2)/(l1-l3)), 0, -sqrt((l2-l3)/(l1-l3)))``
    and the centre ``z0 V (+-(l3/l2) sqrt((l1-l2)/(l1-l3)), 0, -(l1/l2) sqrt((l2-l3)/(l1-l3)))``,
    ``z0 = +-l2 r / sqrt(-l1 l3)``, signs chosen to put the centre in front of the camera.

    Returns
    -------
    centers_cam_m : ndarray, shape (2, 3)
    normals_cam : ndarray, shape (2, 3)
        Unit normals facing the camera (``n . c < 0``).
    """
    Q = np.asarray(K, float).T @ np.asarray(C, float) @ np.asarray(K, float)
    lam, V = np.linalg.eigh((Q + Q.T) / 2)
    if np.sum(lam > 0) == 1:
        lam = -lam
    if np.sum(lam > 0) != 2:
        raise InputError("conic: not the image of a circle in front of the camera")
    o = np.argsort(-lam)
    (l1, l2, l3), V = lam[o], V[:, o]
    a = np.sqrt(max(l1 - l2, 0.0) / (l1 - l3))
    b = np.sqrt(max(l2 - l3, 0.0) / (l1 - l3))
    centers, normals = [], []
    for s1, s2 in itertools.product((1.0, -1.0), repeat=2):
        n = V @ np.array([s2 * a, 0.0, -s1 * b])
        c = V @ np.array([s2 * (l3 / l2) * a, 0.0, -s1 * (l1 / l2) * b]) * (l2 * float(radius_m) / np.sqrt(-l1 * l3))
        if c[2] < 0:
            c = -c
            n = -n
        if n @ c > 0:
            n = -n
        if not any(np.allclose(c, c2, atol=1e-12 * max(1.0, np.abs(c).max())) for c2 in centers):
            centers.append(c)
            normals.append(n)
    while len(centers) < 2:  # fronto-parallel: the two solutions coincide
        centers.append(centers[0])
        normals.append(normals[0])
    return np.array(centers[:2]), np.array(normals[:2])


# ------------------------------------------------------------------------ fitting
@dataclass
class EllipseFit:
    """An ellipse fitted to edge points.

    Attributes
    ----------
    conic : ndarray, shape (3, 3)
    center_px : ndarray, shape (2,)
    axes_px : ndarray, shape (2,)
        Semi-axes ``a >= b``.
    angle_rad : float
    rms_px : float
        RMS Sampson distance of the points to the ellipse.
    n_points : int
    coverage : float
        Fraction of the ellipse's angular range covered by the points (1 for a closed contour).
    """

    conic: np.ndarray
    center_px: np.ndarray
    axes_px: np.ndarray
    angle_rad: float
    rms_px: float
    n_points: int
    coverage: float = 1.0


def fit_ellipse(points_px, method: str = "direct") -> EllipseFit | None:
    """Fit an ellipse to points with OpenCV (``fitEllipseDirect`` or ``fitEllipseAMS``).

    Parameters
    ----------
    points_px : array_like, shape (n, 2)
        ``(u, v)``; at least 5 points.
    method : {"direct", "ams"}

    Returns
    -------
    EllipseFit or None
        None when the fit is degenerate.
    """
    import cv2

    p = np.asarray(points_px, float)
    if p.ndim != 2 or p.shape[0] < 5:
        return None
    mean = p.mean(0)
    q = (p - mean).astype(np.float32).reshape(-1, 1, 2)  # centred: float32 keeps precision
    fn = cv2.fitEllipseDirect if method == "direct" else cv2.fitEllipseAMS
    try:
        (cu, cv_), (w, h), ang = fn(q)
    except cv2.error:
        return None
    if not (np.isfinite([cu, cv_, w, h, ang]).all() and w > 0 and h > 0):
        return None
    a, b, th = w / 2.0, h / 2.0, np.radians(ang)
    if b > a:
        a, b, th = b, a, th + np.pi / 2
    th = float(np.arctan2(np.sin(th), np.cos(th)))
    center = np.array([cu + mean[0], cv_ + mean[1]])
    C = ellipse_to_conic(center, (a, b), th)
    # RMS Sampson distance and angular coverage, in the ellipse's centred frame
    d = p - center
    A2 = C[:2, :2]
    Ad = d @ A2  # gradient / 2 of (x - c)^T A (x - c) - 1
    qv = np.sum(Ad * d, axis=1) - 1.0
    gn = 2 * np.sqrt(np.sum(Ad * Ad, axis=1))
    rms = float(np.sqrt(np.mean((qv / np.maximum(gn, 1e-300)) ** 2)))
    ang_pts = np.arctan2(d[:, 1], d[:, 0])
    bins = np.minimum(((ang_pts + np.pi) * (36 / (2 * np.pi))).astype(int), 35)
    coverage = np.count_nonzero(np.bincount(bins, minlength=36)) / 36.0
    return EllipseFit(C, center, np.array([a, b]), th, rms, int(p.shape[0]), float(coverage))


def subpixel_contours(gray_roi, level: float) -> list[np.ndarray]:
    """Ordered iso-contours of an image patch at ``level`` (marching squares), as ``(u, v)`` arrays."""
    from skimage.measure import find_contours

    return [c[:, ::-1] for c in find_contours(np.asarray(gray_roi, float), level)]


def level_crossings(gray, level: float, member_mask=None, bbox=None, margin: int = 2) -> np.ndarray:
    """Sub-pixel edge points: where the image crosses ``level`` between 4-neighbours.

    Between each horizontally or vertically adjacent pixel pair that straddles ``level``,
    the crossing is placed by linear interpolation (the marching-squares vertices, without
    assembling contours - an ellipse fit needs no order).

    Parameters
    ----------
    gray : ndarray, shape (H, W)
    level : float
    member_mask : ndarray of bool, shape (H, W), optional
        Keep only crossings with one pixel of the pair in the mask (the blob), so that the
        edges of neighbouring markers in the box are ignored.
    bbox : tuple of int, optional
        ``(u0, v0, u1, v1)`` inclusive; searched with ``margin`` pixels around it.

    Returns
    -------
    pts_px : ndarray, shape (n, 2)
        ``(u, v)`` of the crossings.
    """
    H, W = gray.shape
    if bbox is None:
        u0, v0, u1, v1 = 0, 0, W - 1, H - 1
    else:
        u0, v0, u1, v1 = bbox
        u0, v0 = max(u0 - margin, 0), max(v0 - margin, 0)
        u1, v1 = min(u1 + margin, W - 1), min(v1 + margin, H - 1)
    g = np.asarray(gray[v0:v1 + 1, u0:u1 + 1], float) - level
    m = None if member_mask is None else member_mask[v0:v1 + 1, u0:u1 + 1]
    out = []
    # horizontal pairs (v, u) - (v, u + 1)
    a, b = g[:, :-1], g[:, 1:]
    sel = (a > 0) != (b > 0)
    if m is not None:
        sel &= m[:, :-1] | m[:, 1:]
    vv, uu = np.nonzero(sel)
    fa, fb = a[vv, uu], b[vv, uu]
    out.append(np.stack([uu + fa / (fa - fb) + u0, vv + float(v0)], 1))
    # vertical pairs (v, u) - (v + 1, u)
    a, b = g[:-1, :], g[1:, :]
    sel = (a > 0) != (b > 0)
    if m is not None:
        sel &= m[:-1, :] | m[1:, :]
    vv, uu = np.nonzero(sel)
    fa, fb = a[vv, uu], b[vv, uu]
    out.append(np.stack([uu + float(u0), vv + fa / (fa - fb) + v0], 1))
    return np.vstack(out)


def fit_ellipse_subpixel(gray, bbox, level: float, member_mask=None, margin: int = 2,
                         min_points: int = 8) -> EllipseFit | None:
    """Fit an ellipse to the sub-pixel ``level`` crossings around a blob.

    Parameters
    ----------
    gray : ndarray, shape (H, W)
    bbox : tuple of int
        ``(u0, v0, u1, v1)`` inclusive pixel bounds of the blob.
    level : float
        Iso-level (e.g. half-way between background and marker plateau).
    member_mask : ndarray of bool, shape (H, W), optional
        The blob's pixels (crossings must touch them); strongly advised when markers are close.
    margin : int
        Pixels added around the box.
    min_points : int

    Returns
    -------
    EllipseFit or None
        In full-image pixel coordinates.
    """
    pts = level_crossings(gray, level, member_mask, bbox, margin)
    if pts.shape[0] < min_points:
        return None
    return fit_ellipse(pts)


# ------------------------------------------------------------- edge-following arcs
def split_arcs(contour_px, max_turn_deg: float = 40.0, step: int = 2, min_points: int = 6,
               reverse_tol_deg: float = 10.0) -> list[np.ndarray]:
    """Split an edge contour into candidate elliptical arcs (paper section 3.3).

    Directions are taken between points ``step`` apart on the (3-point smoothed) contour.
    The contour is cut where the direction turns by more than ``max_turn_deg`` between
    successive chords (angle condition) and where it turns against the contour's dominant
    sense by more than ``reverse_tol_deg`` (curvature condition: an elliptical arc turns one
    way; the tolerance absorbs the pixel-level jitter of iso-contours); pieces with fewer
    than ``min_points`` points are dropped (point condition).

    Parameters
    ----------
    contour_px : ndarray, shape (n, 2)
        An ordered (closed or open) edge curve.

    Returns
    -------
    list of ndarray, each shape (m, 2)
    """
    p = np.asarray(contour_px, float)
    if p.shape[0] < min_points:
        return []
    closed = p.shape[0] > 2 and np.allclose(p[0], p[-1])
    if closed:
        p = p[:-1]
    if closed:
        sm = (np.roll(p, 1, 0) + p + np.roll(p, -1, 0)) / 3
    else:
        sm = p.copy()
        sm[1:-1] = (p[:-2] + p[1:-1] + p[2:]) / 3
    q = sm[::step]
    if q.shape[0] < 4:
        return [p] if p.shape[0] >= min_points else []
    d = np.diff(np.vstack([q, q[:1]]) if closed else q, axis=0)
    ang = np.arctan2(d[:, 1], d[:, 0])
    turn = np.angle(np.exp(1j * (np.roll(ang, -1) - ang)))[: (len(ang) if closed else len(ang) - 1)]
    dominant = np.sign(np.sum(turn)) or 1.0
    cut = (np.abs(turn) > np.radians(max_turn_deg)) | (dominant * turn < -np.radians(reverse_tol_deg))
    if not cut.any():
        return [np.vstack([p, p[:1]])] if closed else [p]
    pts_idx = np.minimum((np.flatnonzero(cut) + 1) * step, p.shape[0])
    if closed:
        start = pts_idx[0]
        p = np.roll(p, -start, axis=0)
        pts_idx = np.sort((pts_idx - start) % p.shape[0])
        pts_idx = np.append(pts_idx[pts_idx > 0], p.shape[0])
    pieces, prev = [], 0
    for k in pts_idx:
        seg = p[prev:k + 1]
        if seg.shape[0] >= min_points:
            pieces.append(seg)
        prev = k
    if not closed and prev < p.shape[0] - 1:
        seg = p[prev:]
        if seg.shape[0] >= min_points:
            pieces.append(seg)
    return pieces


def detect_ellipse_arcs(gray, bbox, level: float, *, max_rms_px: float = 0.35, min_axis_px: float = 1.5,
                        max_axis_px: float = 200.0, min_coverage: float = 0.3, margin: int = 2,
                        max_turn_deg: float = 40.0, group_dist_px: float = 1.0) -> list[EllipseFit]:
    """Edge-following ellipse detection in a blob's box (paper section 3.3).

    Iso-contours of the box are split into elliptical arcs (:func:`split_arcs`), each arc
    with enough points is fitted; arcs whose ellipses share a centre (within
    ``group_dist_px``) are grouped and refitted together (neighbourhood grouping), and the
    ellipses with a small residual and enough angular coverage are returned.

    Returns
    -------
    list of EllipseFit
        In full-image pixel coordinates, largest coverage first.
    """
    H, W = gray.shape
    u0, v0, u1, v1 = bbox
    u0, v0 = max(u0 - margin, 0), max(v0 - margin, 0)
    u1, v1 = min(u1 + margin, W - 1), min(v1 + margin, H - 1)
    roi = gray[v0:v1 + 1, u0:u1 + 1]
    arcs = []
    for c in subpixel_contours(roi, level):
        arcs.extend(split_arcs(c + [u0, v0], max_turn_deg=max_turn_deg))
    fits = []
    for arc in arcs:
        f = fit_ellipse(arc)
        if f is not None and f.rms_px <= max_rms_px and min_axis_px <= f.axes_px[1] and f.axes_px[0] <= max_axis_px:
            fits.append((f, arc))
    # neighbourhood grouping: arcs of one ellipse share its centre
    groups: list[list] = []
    for f, arc in fits:
        for g in groups:
            if np.linalg.norm(g[0][0].center_px - f.center_px) <= max(group_dist_px, 0.1 * f.axes_px[0]):
                g.append((f, arc))
                break
        else:
            groups.append([(f, arc)])
    out = []
    for g in groups:
        pts = np.vstack([a for _, a in g])
        f = fit_ellipse(pts) if len(g) > 1 else g[0][0]
        if f is None or f.rms_px > max_rms_px or f.coverage < min_coverage:
            continue
        if not (min_axis_px <= f.axes_px[1] and f.axes_px[0] <= max_axis_px):
            continue
        out.append(f)
    out.sort(key=lambda f: -f.coverage)
    return out
