"""Where the SVGS renderer samples: the windows around the spots and the background tiles.

numpy only. The renderer (:class:`render.api.Renderer`) renders the full frame's dark,
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
        ``(x0, y0)`` per tile; None when the scene is partly behind the lens, the camera has
        distortion (a box's edges are not straight), or more tiles than the largest mosaic
        (or the whole frame's area) would be needed.
    """
    T = tile_px
    p = scene_corners_m @ R.T + t
    if np.any(p[:, 2] <= 1e-3):
        return None
    uv = camera.project(p)
    if camera.has_distortion:
        return None  # a box's edges are not straight under distortion: be safe
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
