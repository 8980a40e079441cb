"""Synthetic views of calibration boards: random board poses and geometric images.

Synthetic views (:func:`synthesize_views`, :func:`sample_board_poses`)
    A geometric (not photometric) image of the board through a
    :class:`svgs_sim.base.profiles.Camera` - distortion included - for tests and as the ground truth
    of rendered sets.
"""

from __future__ import annotations

import numpy as np

from svgs_sim.base.errors import InputError
from svgs_sim.base.profiles import Camera

from .boards import Board, ink_mask


def _rot(axis: str, a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    if axis == "x":
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    if axis == "y":
        return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def sample_board_poses(
    board: Board,
    camera: Camera,
    n_views: int,
    *,
    seed=None,
    fill=(0.45, 0.8),
    max_tilt_deg: float = 40.0,
    max_roll_deg: float = 20.0,
    margin_px: float = 8.0,
):
    """Random board poses that keep the whole printed board inside the image.

    The board faces the camera (``R_cam_board`` near identity: board x right, y down),
    tilted about its x and y axes by up to ``max_tilt_deg`` and rolled by up to
    ``max_roll_deg``, at a distance where it spans a ``fill`` fraction of the image,
    with its centre anywhere in the image.

    Parameters
    ----------
    board : Board
    camera : Camera
    n_views : int
    seed : int or None
        Seed of the generator built inside.
    fill : (float, float)
        Range of the board's size as a fraction of the image size (of its width or height,
        whichever the board's aspect makes the tighter fit).
    max_tilt_deg, max_roll_deg : float
    margin_px : float
        Keep the board's printed extent this far inside the image.

    Returns
    -------
    R_cam_board : ndarray, shape (V, 3, 3)
    t_cam_board_m : ndarray, shape (V, 3)
    """
    rng = np.random.default_rng(seed)
    n = int(n_views)
    if n < 1:
        raise InputError(f"n_views: expected a positive integer, got {n_views!r}")
    x0, y0, x1, y1 = board.extent_m
    corners = np.array([[x0, y0, 0], [x1, y0, 0], [x1, y1, 0], [x0, y1, 0]], float)
    # densify the outline: distortion bends straight edges
    t = np.linspace(0, 1, 9)[:, None]
    outline = np.concatenate([corners[k] + t * (corners[(k + 1) % 4] - corners[k]) for k in range(4)])
    centre = 0.5 * (corners[0] + corners[2])
    # metres per pixel at fill = 1: the board's larger relative dimension fills the image
    m_per_px = max((x1 - x0) / camera.width, (y1 - y0) / camera.height)
    Rs, ts = [], []
    for _ in range(n):
        for _attempt in range(500):
            ax, ay = np.deg2rad(rng.uniform(-max_tilt_deg, max_tilt_deg, 2))
            az = np.deg2rad(rng.uniform(-max_roll_deg, max_roll_deg))
            R = _rot("z", az) @ _rot("y", ay) @ _rot("x", ax)
            z = camera.fx * m_per_px / rng.uniform(*fill)
            u = rng.uniform(0, camera.width - 1)
            v = rng.uniform(0, camera.height - 1)
            ray = np.array([(u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy, 1.0])
            tv = z * ray - R @ centre
            p = outline @ R.T + tv
            if np.any(p[:, 2] <= 0.05 * z):
                continue
            uv = camera.project(p)
            if np.all(camera.in_image(uv, margin_px)):
                Rs.append(R)
                ts.append(tv)
                break
        else:
            raise InputError("sample_board_poses: no pose keeps the board inside the image; lower fill")
    return np.array(Rs), np.array(ts)


def synthesize_views(
    board: Board,
    camera: Camera,
    R_cam_board,
    t_cam_board_m,
    *,
    oversample: int = 3,
    levels=(25, 230),
    background: float = 110.0,
    blur_px: float = 0.0,
    noise_dn: float = 0.0,
    seed=None,
    progress=None,
) -> np.ndarray:
    """Geometric images of the board through the camera (distortion included).

    Each output pixel is the mean of ``oversample x oversample`` point samples of the
    board texture along the camera rays through it (box filter = pixel area), so edges are
    anti-aliased. No optics, no photometry: a test and reference image, not a render.

    Parameters
    ----------
    board : Board
    camera : Camera
    R_cam_board : array_like, shape (3, 3) or (V, 3, 3)
        ``p_cam = R_cam_board @ p_board + t_cam_board``.
    t_cam_board_m : array_like, shape (3,) or (V, 3)
    oversample : int
        Samples per pixel along each axis.
    levels : (float, float)
        Grey level of ink and of paper.
    background : float
        Grey level where the ray misses the board.
    blur_px : float
        Gaussian blur sigma, pixels (0: none).
    noise_dn : float
        Gaussian noise sigma, grey levels (0: none).
    seed : int or None
        Seed of the noise generator built inside.
    progress : callable, optional
        Called with a line of text when the rays are ready and after each view.

    Returns
    -------
    images : ndarray of uint8, shape (H, W) or (V, H, W)
    """
    import cv2

    R = np.asarray(R_cam_board, float)
    t = np.asarray(t_cam_board_m, float)
    single = R.ndim == 2
    R = R.reshape(-1, 3, 3)
    t = t.reshape(-1, 3)
    if R.shape[0] != t.shape[0]:
        raise InputError(f"synthesize_views: {R.shape[0]} rotations but {t.shape[0]} translations")
    s = int(oversample)
    if s < 1:
        raise InputError(f"oversample: expected a positive integer, got {oversample!r}")
    W, H = camera.width, camera.height
    zmin = min(float(np.min((board.object_points() @ Rk.T + tk)[:, 2])) for Rk, tk in zip(R, t))
    if zmin <= 0:
        raise InputError("synthesize_views: the board is (partly) behind the camera")
    if progress is not None:
        progress(f"undistorting {W * s} x {H * s} sample rays (shared by the views) ...")
    xy = _subsample_rays(camera, s)  # (H s, W s, 2), shared by all views
    lo, hi = float(levels[0]), float(levels[1])
    tex = tex_img = None
    if board.kind == "charuco":
        # texels at most half a sub-sample at the nearest board point
        tex = board.draw(2.0 * s * max(camera.fx, camera.fy) / zmin)
        tex_img = np.where(tex.image > 127, np.float32(hi), np.float32(lo)).astype(np.float32)
    rng = np.random.default_rng(seed)
    out = np.empty((R.shape[0], H, W), np.uint8)
    for k, (Rk, tk) in enumerate(zip(R, t)):
        fine = _board_samples(board, Rk, tk, xy, lo, hi, background, tex, tex_img)
        img = cv2.resize(fine, (W, H), interpolation=cv2.INTER_AREA) if s > 1 else fine
        if blur_px > 0:
            img = cv2.GaussianBlur(img, (0, 0), float(blur_px))
        if noise_dn > 0:
            img = img + rng.normal(0.0, float(noise_dn), img.shape).astype(np.float32)
        out[k] = np.clip(np.round(img), 0, 255).astype(np.uint8)
        if progress is not None:
            progress(f"view {k + 1}/{R.shape[0]}")
    return out[0] if single else out


def _board_samples(board: Board, Rk, tk, xy, lo: float, hi: float, background, tex, tex_img) -> np.ndarray:
    """The board's grey level at each sample ray of one view (before the pixel box filter).

    Parameters
    ----------
    board : Board
    Rk : ndarray, shape (3, 3)
        ``R_cam_board`` of the view.
    tk : ndarray, shape (3,)
        ``t_cam_board_m`` of the view, m.
    xy : ndarray, shape (H s, W s, 2)
        Undistorted normalised coordinates of the sample rays.
    lo, hi : float
        Grey level of ink and of paper.
    background : float
        Grey level where the ray misses the board.
    tex : BoardImage or None
        The drawn board (ChArUco boards), else None: the ink is evaluated analytically.
    tex_img : ndarray of float32 or None
        ``tex``'s image in grey levels ``lo``/``hi``.

    Returns
    -------
    ndarray of float32, shape (H s, W s)
    """
    import cv2

    x0, y0, x1, y1 = board.extent_m
    q = board.quiet_zone_m
    Hinv = np.linalg.inv(np.column_stack([Rk[:, 0], Rk[:, 1], tk]))  # ray -> board (X, Y, 1)
    w = Hinv[2, 0] * xy[..., 0] + Hinv[2, 1] * xy[..., 1] + Hinv[2, 2]
    front = w > 1e-12
    wz = np.where(front, w, 1.0)
    X = np.where(front, (Hinv[0, 0] * xy[..., 0] + Hinv[0, 1] * xy[..., 1] + Hinv[0, 2]) / wz, 1e6)
    Y = np.where(front, (Hinv[1, 0] * xy[..., 0] + Hinv[1, 1] * xy[..., 1] + Hinv[1, 2]) / wz, 1e6)
    if tex is None:
        paper = (X >= x0 - q) & (X <= x1 + q) & (Y >= y0 - q) & (Y <= y1 + q)
        fine = np.where(paper, np.where(ink_mask(board, X, Y), lo, hi), float(background)).astype(np.float32)
    else:
        mx = (tex.origin_px[0] + X * tex.px_per_m).astype(np.float32)
        my = (tex.origin_px[1] + Y * tex.px_per_m).astype(np.float32)
        fine = cv2.remap(tex_img, mx, my, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT,
                         borderValue=float(background))
    return fine


def _subsample_rays(camera: Camera, s: int) -> np.ndarray:
    """Undistorted normalised coordinates at the centres of ``s x s`` sub-pixels.

    Undistorting ~10^6 points with OpenCV's iteration is slow, so the rays are computed at
    pixel centres (and one pixel beyond the border) and interpolated bilinearly; the
    distortion is smooth enough that the interpolation error is far below 1e-3 px.

    Returns
    -------
    xy : ndarray, shape (H s, W s, 2)
    """
    W, H = camera.width, camera.height
    un = np.arange(-1, W + 1, dtype=float)
    vn = np.arange(-1, H + 1, dtype=float)
    nodes = camera.pixels_to_normalized(np.stack(np.meshgrid(un, vn), -1))  # (H+2, W+2, 2)
    us = (np.arange(W * s) + 0.5) / s - 0.5 + 1.0  # index into the node grid
    vs = (np.arange(H * s) + 0.5) / s - 0.5 + 1.0
    iu = np.floor(us).astype(int)
    iv = np.floor(vs).astype(int)
    fu = (us - iu)[None, :, None]
    fv = (vs - iv)[:, None, None]
    a = nodes[iv][:, iu]
    b = nodes[iv][:, iu + 1]
    c = nodes[iv + 1][:, iu]
    d = nodes[iv + 1][:, iu + 1]
    return (1 - fv) * ((1 - fu) * a + fu * b) + fv * ((1 - fu) * c + fu * d)


__all__ = ["sample_board_poses", "synthesize_views"]
