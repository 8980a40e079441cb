"""The pixels that see only the environment (the Earth, the sun's disk, black space), in closed form.

On orbit the natural-light pass must cover the whole frame once the Earth is in view, but only the
pixels that see the target's scene (the tiles over its projected bounding box) need the path
tracer: every other pixel's ray meets nothing but the environment, whose radiance along a direction
is known exactly (:func:`svgs_sim.render.earth.earth_radiance`, the sun's disk of
:func:`svgs_sim.render.sun.sun_disk_to_world`). :func:`environment_radiance` evaluates it
where it can change the result:

- the Earth on a coarse grid of pixel centres (every :data:`STEP_PX` pixels, double precision),
  interpolated linearly in between (the lit disk is smooth: its radiance varies over degrees);
- every pixel of a coarse cell whose corners disagree on whether light comes from the Earth (the
  limb of its lit part, and the terminator, where the radiance's cosine has a kink that linear
  interpolation would smear), at :data:`LIMB_SUBSAMPLES` x :data:`LIMB_SUBSAMPLES` points per pixel
  (the pixel's mean, as the path tracer's jittered samples estimate it);
- the sun's disk, where it projects, at :data:`SUN_SUBSAMPLES` x :data:`SUN_SUBSAMPLES` points per
  pixel, each ray intersected with the rendered disk (1 km from the target origin, so seen from the
  camera with the same parallax as in the path tracer) and drawn over the Earth, as the renderer
  draws it.

The lens's defocus of the environment is not applied (ASSUMPTION): the thin lens is focused on the
target, and its blur circle for a source at infinity is ``f_x D / s`` px (``D`` the aperture, ``s`` the
focus distance): for the Galaxy Nexus 3.5 px / s, 1.75 px at 2 m, 0.35 px at 10 m. The path-traced
tiles are blurred, so the limb and the sun's disk are that much sharper outside them. ``tests/test_render_environment.py`` compares it with the
path tracer's full-frame pass.
"""

from __future__ import annotations

import numpy as np

from .earth import earth_radiance
from .sun import SUN_ANGULAR_DIAMETER_DEG, SUN_DISTANCE_M

#: Spacing of the coarse grid the Earth is evaluated on, px.
STEP_PX = 8
#: Sub-samples per pixel side across the Earth's limb.
LIMB_SUBSAMPLES = 2
#: Coarse cells on each side of the lit disk's edge evaluated at every pixel's centre.
EDGE_BAND_CELLS = 2
#: Sub-samples per pixel side over the sun's disk.
SUN_SUBSAMPLES = 4


def _directions(camera, u_px: np.ndarray, v_px: np.ndarray) -> np.ndarray:
    """Unit ray directions (camera frame, OpenCV) through pixel points, shape (n, 3)."""
    xy = camera.pixels_to_normalized(np.column_stack([u_px, v_px]))
    d = np.column_stack([xy, np.ones(len(xy))])
    return d / np.linalg.norm(d, axis=1, keepdims=True)


class EnvironmentGrid:
    """The pixel geometry :func:`environment_radiance` reuses frame after frame (one per camera):
    the ray directions at the centres of ``step_px`` x ``step_px`` pixel blocks.

    Parameters
    ----------
    camera : svgs.Camera
    step_px : int
        The coarse grid's spacing, px (even).
    """

    def __init__(self, camera, step_px: int = STEP_PX):
        self.camera = camera
        self.step_px = s = int(step_px)
        if s < 2 or s % 2:
            raise ValueError(f"step_px: expected an even number >= 2, got {step_px!r}")
        H, W = camera.height, camera.width
        self.gw, self.gh = -(-W // s), -(-H // s)
        gx = np.arange(self.gw) * s + (s - 1) / 2.0
        gy = np.arange(self.gh) * s + (s - 1) / 2.0
        uu, vv = np.meshgrid(gx, gy)
        self.coarse_dirs_cam = _directions(camera, uu.ravel(), vv.ravel()).reshape(self.gh, self.gw, 3)

    def upsample(self, coarse: np.ndarray) -> np.ndarray:
        """Bilinear interpolation of the coarse image (gh, gw) to the full frame, float32 (H, W): the
        coarse samples sit at the blocks' centres, which is OpenCV's ``INTER_LINEAR`` geometry
        (edge samples held beyond the outermost centres, half a block)."""
        import cv2  # heavy: only a frame with the Earth in view needs it

        s = self.step_px
        up = cv2.resize(coarse.astype(np.float32), (self.gw * s, self.gh * s), interpolation=cv2.INTER_LINEAR)
        return up[: self.camera.height, : self.camera.width]

    def cell_pixels(self, mixed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The pixels ``(xs, ys)`` between the coarse samples of each flagged cell ``mixed``
        (gh - 1, gw - 1), the cells on the frame's edge extended to it."""
        s, H, W = self.step_px, self.camera.height, self.camera.width
        js, is_ = np.nonzero(mixed)
        if js.size == 0:
            return np.zeros(0, int), np.zeros(0, int)
        h = s // 2
        y0 = np.where(js == 0, 0, js * s + h)
        y1 = np.where(js == self.gh - 2, H, (js + 1) * s + h)
        x0 = np.where(is_ == 0, 0, is_ * s + h)
        x1 = np.where(is_ == self.gw - 2, W, (is_ + 1) * s + h)
        span = int(max((x1 - x0).max(), (y1 - y0).max()))  # the largest block side (an edge cell)
        oy, ox = np.mgrid[0:span, 0:span]
        ys = y0[:, None] + oy.ravel()[None, :]
        xs = x0[:, None] + ox.ravel()[None, :]
        keep = (ys < np.minimum(y1, H)[:, None]) & (xs < np.minimum(x1, W)[:, None])
        return xs[keep], ys[keep]


def _disagree(flags: np.ndarray) -> np.ndarray:
    """The cells (gh - 1, gw - 1) whose four corner samples do not all agree."""
    a = flags[:-1, :-1]
    return (a != flags[1:, :-1]) | (a != flags[:-1, 1:]) | (a != flags[1:, 1:])


def _dilate(mask: np.ndarray, k: int) -> np.ndarray:
    """``mask`` grown by ``k`` cells in every direction (a square neighbourhood)."""
    out = mask.copy()
    H, W = mask.shape
    for dy in range(-k, k + 1):
        for dx in range(-k, k + 1):
            out[max(dy, 0):H + min(dy, 0), max(dx, 0):W + min(dx, 0)] |= mask[max(-dy, 0):H + min(-dy, 0),
                                                                              max(-dx, 0):W + min(-dx, 0)]
    return out


def _points_subsampled(camera, R, xs: np.ndarray, ys: np.ndarray, n: int) -> np.ndarray:
    """Ray directions (target frame) at n x n points in each of the pixels ``(xs, ys)``: shape (m, n * n, 3)."""
    off = (np.arange(n) + 0.5) / n - 0.5
    ou, ov = (a.ravel() for a in np.meshgrid(off, off))
    su = (xs[:, None] + ou[None, :]).ravel()
    sv = (ys[:, None] + ov[None, :]).ravel()
    return (_directions(camera, su, sv) @ np.asarray(R, float)).reshape(len(xs), n * n, 3)


def environment_radiance(grid: EnvironmentGrid, R_cam_target, t_cam_target_m, *, earth: dict | None = None,
                         sun: dict | None = None) -> np.ndarray:
    """The environment's radiance in every pixel, W m^-2 sr^-1 in band (see the module docstring).

    Parameters
    ----------
    grid : EnvironmentGrid
        The camera's coarse grid.
    R_cam_target : array_like, shape (3, 3)
    t_cam_target_m : array_like, shape (3,)
        The pose (``p_cam = R p_target + t``).
    earth : dict, optional
        :func:`svgs_sim.render.earth.earth_radiance`'s ``earth_direction``, ``sun_direction``,
        ``altitude_m``, ``albedo``, ``sun_irradiance_w_m2``, ``uniform_radiance_w_m2_sr``.
    sun : dict, optional
        ``direction`` (unit, target frame) and ``radiance_w_m2_sr`` of the sun's disk (None: no
        disk, e.g. in eclipse).

    Returns
    -------
    ndarray of float32, shape (H, W)
    """
    cam = grid.camera
    R = np.asarray(R_cam_target, float)
    H, W = cam.height, cam.width
    rad = np.zeros((H, W), np.float32)
    if earth is not None:
        w = grid.coarse_dirs_cam @ R  # target frame
        coarse = earth_radiance(w, **earth)
        rad = grid.upsample(coarse)
        # the lit disk's edges (the limb and the terminator, where the radiance has a kink): coarse cells
        # whose corners disagree on whether any light comes, pixel by pixel
        lit = coarse > 0
        seen = earth_radiance(w, earth["earth_direction"], None, earth["altitude_m"], 0.0, 0.0, 1.0) > 0
        mixed = _disagree(lit) | _disagree(seen)  # a lit crescent thinner than a cell lies on the limb
        if mixed.any():
            # next to the edge the radiance bends fast (the surface is seen grazing near the limb, the
            # cosine starts at the terminator): the cells around it at each pixel's centre, then the
            # edge's own cells at sub-samples
            near = _dilate(mixed, EDGE_BAND_CELLS)
            xs, ys = grid.cell_pixels(near & ~mixed)
            if xs.size:
                rad[ys, xs] = earth_radiance(_points_subsampled(cam, R, xs, ys, 1), **earth)[:, 0]
            xs, ys = grid.cell_pixels(mixed)
            d = _points_subsampled(cam, R, xs, ys, LIMB_SUBSAMPLES)
            rad[ys, xs] = earth_radiance(d, **earth).mean(axis=-1)
    if sun is not None:
        _add_sun_disk(rad, cam, R, np.asarray(t_cam_target_m, float), sun)
    return rad


def _add_sun_disk(rad: np.ndarray, cam, R: np.ndarray, t: np.ndarray, sun: dict) -> None:
    """Draw the sun's rendered disk over ``rad`` (in place): each sub-sample ray from the camera
    meets the disk (centre 1 km along the sun's direction from the target origin, facing it) or not."""
    d = np.asarray(sun["direction"], float)
    d = d / np.linalg.norm(d)
    c_t = -R.T @ t  # the camera in the target frame
    centre = SUN_DISTANCE_M * d
    radius = SUN_DISTANCE_M * np.tan(np.deg2rad(0.5 * SUN_ANGULAR_DIAMETER_DEG))
    to_centre = R @ (centre - c_t)  # camera frame
    if to_centre[2] <= 0:
        return
    uv = cam.project(to_centre[None, :])[0]
    r_px = float(np.sqrt(cam.fx * cam.fy)) * radius / float(np.linalg.norm(centre - c_t)) + 3.0
    u0, u1 = int(np.floor(uv[0] - r_px)), int(np.ceil(uv[0] + r_px)) + 1
    v0, v1 = int(np.floor(uv[1] - r_px)), int(np.ceil(uv[1] + r_px)) + 1
    u0, u1, v0, v1 = max(u0, 0), min(u1, cam.width), max(v0, 0), min(v1, cam.height)
    if u0 >= u1 or v0 >= v1:
        return
    vv, uu = np.mgrid[v0:v1, u0:u1]
    w = _points_subsampled(cam, R, uu.ravel(), vv.ravel(), SUN_SUBSAMPLES).reshape(v1 - v0, u1 - u0, -1, 3)
    denom = w @ d
    s = np.where(denom > 0, ((centre - c_t) @ d) / np.where(denom > 0, denom, 1.0), -1.0)
    p = c_t + s[..., None] * w
    inside = (s > 0) & (np.linalg.norm(p - centre, axis=-1) <= radius)
    cover = inside.mean(axis=-1)
    box = rad[v0:v1, u0:u1]
    rad[v0:v1, u0:u1] = np.where(cover > 0, box * (1 - cover) + cover * float(sun["radiance_w_m2_sr"]), box)
