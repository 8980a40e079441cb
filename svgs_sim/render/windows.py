"""Where the SVGS renderer samples: the windows around the spots and the background tiles.

numpy only. The renderer (:class:`svgs_sim.render.api.Renderer`) renders the full frame's dark,
diffuse background only over the tiles that cover the projected scene, and every target's
spot inside a fixed-size square window, all windows in one mosaic pass.
"""

from __future__ import annotations

import numpy as np


def spot_windows(spots_px, roi_size_px: int, width: int, height: int) -> np.ndarray:
    """Top-left corners (integers) of the windows centred on the spots, clamped into the frame.

    Parameters
    ----------
    spots_px : ndarray, shape (N, 2)
        Predicted spot centres, px (non-finite: treated as 0).
    roi_size_px : int
        Side of the square windows.
    width, height : int
        Frame size, px.

    Returns
    -------
    ndarray of int, shape (N, 2)
        ``(x0, y0)`` of each window.
    """
    w = roi_size_px
    c = np.where(np.isfinite(spots_px), spots_px, 0.0)
    x0 = np.clip(np.round(c[:, 0] + 0.5 - w / 2.0), 0, width - w).astype(int)
    y0 = np.clip(np.round(c[:, 1] + 0.5 - w / 2.0), 0, height - w).astype(int)
    return np.stack([x0, y0], 1)


def background_tiles(camera, scene_corners_m, R, t, tile_px: int, tile_counts) -> np.ndarray | None:
    """Origins of the tiles covering the projected scene; None: render the whole frame.

    Parameters
    ----------
    camera : svgs.Camera
    scene_corners_m : ndarray, shape (8, 3)
        Corners of the scene's bounding box, target (world) frame.
    R, t : ndarray, shapes (3, 3), (3,)
        ``R_cam_target``, ``t_cam_target_m``.
    tile_px : int
        Side of a square tile.
    tile_counts : sequence of int
        The tile mosaics the scene has sensors for.

    Returns
    -------
    ndarray of int, shape (n, 2), or None
        ``(x0, y0)`` per tile; None when the scene is partly behind the lens, the camera's
        distortion is not one-to-one over the frame (:func:`_distorted_box_outline`), or more
        tiles than the largest mosaic (or the whole frame's area) would be needed.
    """
    T = tile_px
    p = scene_corners_m @ R.T + t
    if np.any(p[:, 2] <= 1e-3):
        return None
    uv = _distorted_box_outline(camera, p) if camera.has_distortion else camera.project(p)
    if uv is None:
        return None
    W, H = camera.width, camera.height
    u0, v0 = np.floor(uv.min(0) - 2.0)
    u1, v1 = np.ceil(uv.max(0) + 2.0)
    u0, v0 = max(0, int(u0)), max(0, int(v0))
    u1, v1 = min(W, int(u1) + 1), min(H, int(v1) + 1)
    if u1 <= u0 or v1 <= v0:
        return np.zeros((0, 2), int)
    xs = np.arange(u0, u1, T)
    ys = np.arange(v0, v1, T)
    if len(xs) * len(ys) > max(tile_counts) or (len(xs) * len(ys)) * T * T >= W * H:
        return None
    # keep tiles inside the frame (a last tile may overlap its neighbour)
    xs = np.minimum(xs, max(0, W - T)) if W >= T else xs
    ys = np.minimum(ys, max(0, H - T)) if H >= T else ys
    return np.array([[x, y] for y in ys for x in xs], int)


#: Samples per side of the rectangle whose distorted outline bounds a box's image.
OUTLINE_SAMPLES = 256
#: Grid of the one-to-one check of the distortion (points per axis).
JACOBIAN_GRID = 33


def _distorted_box_outline(camera, p_cam_m) -> np.ndarray | None:
    """Pixels bounding the image of a box under the camera's distortion, or None.

    A ray meets the box only if its undistorted normalised coordinates lie in the rectangle
    spanned by the box corners' ``(X/Z, Y/Z)``. Where the distortion is one-to-one and
    continuous, it maps that rectangle's boundary onto the boundary of its image, so the
    distorted boundary (sampled densely) bounds every pixel that can see the box. One-to-one is
    checked as a positive Jacobian determinant of the distortion on a grid over the rectangle
    and the whole frame's undistorted extent; otherwise None (render the whole frame).

    Returns
    -------
    ndarray, shape (4 * OUTLINE_SAMPLES, 2) or None
        Pixel coordinates of the distorted outline.
    """
    xy = p_cam_m[:, :2] / p_cam_m[:, 2:3]
    (x0, y0), (x1, y1) = xy.min(0), xy.max(0)
    W, H = camera.width, camera.height
    frame = np.array([[0, 0], [W - 1, 0], [0, H - 1], [W - 1, H - 1], [W / 2, 0], [W / 2, H - 1], [0, H / 2],
                      [W - 1, H / 2]], float)
    und = camera.pixels_to_normalized(frame)
    if not np.all(np.isfinite(und)):
        return None
    gx0, gy0 = min(x0, und[:, 0].min()), min(y0, und[:, 1].min())
    gx1, gy1 = max(x1, und[:, 0].max()), max(y1, und[:, 1].max())
    gx, gy = np.meshgrid(np.linspace(gx0, gx1, JACOBIAN_GRID), np.linspace(gy0, gy1, JACOBIAN_GRID))
    g = np.stack([gx.ravel(), gy.ravel()], -1)
    h = 1e-6 * max(1.0, gx1 - gx0, gy1 - gy0)
    dx = (camera.distort_normalized(g + [h, 0.0]) - camera.distort_normalized(g - [h, 0.0])) / (2 * h)
    dy = (camera.distort_normalized(g + [0.0, h]) - camera.distort_normalized(g - [0.0, h])) / (2 * h)
    if np.any(dx[:, 0] * dy[:, 1] - dx[:, 1] * dy[:, 0] <= 0.0):
        return None
    t = np.linspace(0.0, 1.0, OUTLINE_SAMPLES)
    one = np.ones_like(t)
    edge = np.concatenate([np.stack([x0 + (x1 - x0) * t, y0 * one], -1), np.stack([x0 + (x1 - x0) * t, y1 * one], -1),
                           np.stack([x0 * one, y0 + (y1 - y0) * t], -1), np.stack([x1 * one, y0 + (y1 - y0) * t], -1)])
    return camera.normalized_to_pixels(edge)
