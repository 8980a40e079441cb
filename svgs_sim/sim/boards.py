"""Rendered calibration sets: boards rendered by :class:`svgs_sim.render.boards.BoardRenderer`, then
exposed by the phone camera model (:class:`svgs_sim.camera.phone.PhoneCamera`) at a manual exposure.

:func:`render_board_set` makes a :class:`BoardSet` (images, truth, the delivered camera) that
``svgs calibrate render-board`` writes and the calibration study (:mod:`svgs_sim.studies.calibration`)
calibrates. See :mod:`svgs_sim.render.boards` for the scene and its radiometry.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from svgs_sim.base.errors import InputError, SimulationFailure
from svgs_sim.base.image_files import write_image
from svgs_sim.base.profiles import Camera, load_camera
from svgs_sim.calibration.boards import Board
from svgs_sim.calibration.synthetic import sample_board_poses
from svgs_sim.render.boards import (
    DEFAULT_BOARD_SPP,
    DEFAULT_EXPOSURE_FILL,
    DEFAULT_TEXELS_PER_PX,
    MAX_MANUAL_EXPOSURE_S,
    BoardRenderer,
    texture_px_per_m,
)
from svgs_sim.render.optics import Optics
from svgs_sim.render.variant import renderer_versions
from svgs_sim.sim import hard_stop
from svgs_sim.sim.closed_loop import solver_camera
from svgs_sim.svgs.pipeline import load_image


def manual_exposure(phone, exposer, fill: float = DEFAULT_EXPOSURE_FILL) -> tuple[float, float]:
    """Manual exposure that puts the brightest paper at ``fill`` of full well.

    The 99.5th percentile of the noise-free signal after the lens PSF is taken as the
    paper's level. The time is capped at :data:`MAX_MANUAL_EXPOSURE_S`; beyond it the ISO
    rises (up to the profile's ``max_iso``).

    Parameters
    ----------
    phone : svgs_sim.camera.phone.PhoneCamera
    exposer : svgs_sim.camera.phone.Exposer
    fill : float
        Fraction of full well, in (0, 1].

    Returns
    -------
    exposure_s, iso : float

    Raises
    ------
    InputError
        ``fill`` outside (0, 1].
    SimulationFailure
        The image is black (reason ``"no_signal"``): no light reaches the sensor, so no exposure
        can bring the paper to ``fill``.
    """
    if not (np.isfinite(fill) and 0.0 < fill <= 1.0):
        raise InputError(f"exposure fill: expected a fraction of full well in (0, 1], got {fill!r}")
    sp, ex = phone.params.sensor, phone.params.exposure
    white = float(np.percentile(exposer.flux_optics, 99.5)) * sp.qe  # e-/s
    if not white > 0:  # valid input, the simulated physics left nothing to expose for: exit 1, not 2
        raise SimulationFailure(f"board render: the image is black (no light reaches the sensor: the brightest "
                                f"pixels collect {white:g} e-/s)", "no_signal")
    S = fill * sp.full_well_e / white  # exposure product: seconds at base ISO
    if S <= MAX_MANUAL_EXPOSURE_S:
        return float(S), float(sp.base_iso)
    return float(MAX_MANUAL_EXPOSURE_S), float(min(sp.base_iso * S / MAX_MANUAL_EXPOSURE_S, ex.max_iso))


# --------------------------------------------------------------------------- sets
@dataclass
class BoardSet:
    """A rendered calibration set with its truth.

    Attributes
    ----------
    images : list of ndarray (h, w) uint8
        What the phone delivered.
    names : list of str
        File names (``view_000.png`` ...).
    camera : Camera
        The true geometry of the delivered images (scaled if the ISP downscaled).
    board : calibration.Board
    R_cam_board : ndarray, shape (V, 3, 3)
    t_cam_board_m : ndarray, shape (V, 3)
    truth : dict
        Everything recorded in ``truth.json``.
    """

    images: list
    names: list
    camera: Camera
    board: object
    R_cam_board: np.ndarray
    t_cam_board_m: np.ndarray
    truth: dict

    def __len__(self) -> int:
        return len(self.images)

    def save(self, out_dir) -> dict:
        """Write the images (PNG), ``truth.json`` and ``camera_true.toml`` into ``out_dir``."""
        out = Path(out_dir)
        if out.exists() and not out.is_dir():
            raise InputError(f"--out {str(out)!r} exists and is not a folder")
        out.mkdir(parents=True, exist_ok=True)
        files = []
        for img, n in zip(self.images, self.names):
            p = out / n
            write_image(p, img)
            files.append(str(p))
        with open(out / "truth.json", "w", encoding="utf-8") as fh:
            json.dump(self.truth, fh, indent=1)
        self.camera.save(out / "camera_true.toml")
        return {"images": files, "truth": str(out / "truth.json"), "camera": str(out / "camera_true.toml")}

    @classmethod
    def load(cls, folder) -> "BoardSet":
        """Read a set written by :meth:`save` (``svgs calibrate render-board``)."""

        d = Path(folder)
        tp = d / "truth.json"
        if not tp.is_file():
            raise InputError(f"{str(d)!r} holds no truth.json: not a rendered board set")
        try:
            truth = json.loads(tp.read_text())
            b = truth["board"]
            board = Board(b["kind"], b["cols"], b["rows"], b["spacing_mm"] * 1e-3,
                          marker_m=None if b.get("marker_mm") is None else b["marker_mm"] * 1e-3,
                          dictionary=b.get("dictionary", "DICT_5X5_100"), legacy=bool(b.get("legacy", False)))
            views = truth["views"]
            names = [v["image"] for v in views]
            R = np.array([v["R_cam_board"] for v in views], float)
            t = np.array([v["t_cam_board_m"] for v in views], float)
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"{str(tp)!r}: not a board-set truth record ({exc})") from None
        camera = load_camera(d / "camera_true.toml")
        images = [load_image(d / n) for n in names]
        return cls(images, names, camera, board, R, t, truth)


def _versions() -> dict:
    import cv2


    return {"numpy": np.__version__, "opencv": cv2.__version__, **renderer_versions()}


def render_board_set(camera, board, n_views: int, *, seed: int = 0, spp: int = DEFAULT_BOARD_SPP,
                     poses=None, pinhole: bool = False, exposure_fill: float = DEFAULT_EXPOSURE_FILL,
                     stages=None, fill=(0.45, 0.8), max_tilt_deg: float = 40.0, max_roll_deg: float = 20.0,
                     texels_per_px: float = DEFAULT_TEXELS_PER_PX, renderer_options: dict | None = None,
                     out_dir=None, progress=None) -> BoardSet:
    """Render a calibration set: board poses covering the field of view, Mitsuba, phone.

    Parameters
    ----------
    camera : str, path or Camera
        The true camera (needs ``[optics]``; the phone tables are optional).
    board : calibration.Board
    n_views : int
    seed : int
        Seeds the poses (:func:`svgs_sim.calibration.sample_board_poses`), each view's sampler and
        each exposure's noise (``numpy.random.SeedSequence``).
    spp : int
    poses : (R (V,3,3), t (V,3)), optional
        Board poses instead of sampled ones.
    pinhole : bool
        No defocus (see :class:`BoardRenderer`).
    exposure_fill : float
        Manual exposure: paper at this fraction of full well (:func:`manual_exposure`).
    stages : sequence of str, optional
        Phone pipeline stages (default: the profile's ``[isp] stages``).
    fill, max_tilt_deg, max_roll_deg
        Passed to :func:`svgs_sim.calibration.sample_board_poses`.
    texels_per_px : float
        Texture resolution at the nearest board point.
    renderer_options : dict, optional
        Extra :class:`BoardRenderer` keywords (lighting, reflectances, variant).
    out_dir : str or Path, optional
        Write the set there (:meth:`BoardSet.save`).
    progress : callable, optional
        Called with a line of text per view.

    Returns
    -------
    BoardSet
    """
    from svgs_sim.camera.phone import PhoneCamera

    cam = load_camera(camera)
    try:
        n = int(n_views)
    except (TypeError, ValueError):
        raise InputError(f"views: expected a positive integer, got {n_views!r}") from None
    if n < 1 or n != n_views:
        raise InputError(f"views: expected a positive integer, got {n_views!r}")

    Optics.from_camera(cam)  # fail early (ProfileError) without [optics]
    phone = PhoneCamera(cam)
    st = tuple(phone.params.isp.stages) if stages is None else tuple(stages)
    ss = np.random.SeedSequence(int(seed))
    s_pose, s_render, s_expose = (int(c.generate_state(1)[0]) for c in ss.spawn(3))
    R, t = _board_poses(board, cam, n, poses, seed=s_pose, fill=fill, max_tilt_deg=max_tilt_deg,
                        max_roll_deg=max_roll_deg)
    ppm = texture_px_per_m(board, cam, R, t, texels_per_px)
    renderer = BoardRenderer(cam, board, px_per_m=ppm, spp=spp, pinhole=pinhole, **(renderer_options or {}))
    r_seeds = np.random.SeedSequence(s_render).generate_state(n, dtype=np.uint32)
    e_seeds = np.random.SeedSequence(s_expose).generate_state(n, dtype=np.uint32)
    images, names, views = [], [], []
    delivered = None

    with hard_stop.scope():  # run from the CLI, Ctrl-C stops a render within a second (nothing is written yet)
        for k in range(n):
            img, delivered, view = _render_view(renderer, phone, cam, board, R[k], t[k], int(r_seeds[k]),
                                                int(e_seeds[k]), st, exposure_fill, name=f"view_{k:03d}.png")
            images.append(img)
            names.append(view["image"])
            views.append(view)
            if progress is not None:
                progress(f"view {k + 1}/{n}: rendered in {view['timings_s']['render_s']:.1f} s, "
                         f"exposure {view['exposure_s'] * 1e3:.2f} ms ISO {view['iso']:.0f}")
    truth = _set_truth(cam, delivered, board, renderer, views, seed=seed, stages=st, exposure_fill=exposure_fill)
    out = BoardSet(images, names, delivered, board, R, t, truth)
    if out_dir is not None:
        out.save(out_dir)
    return out


def _board_poses(board, cam, n: int, poses, *, seed: int, fill, max_tilt_deg, max_roll_deg):
    """The views' poses: drawn (:func:`svgs_sim.calibration.sample_board_poses`) or given, checked.

    Returns
    -------
    R_cam_board : ndarray, shape (n, 3, 3)
    t_cam_board_m : ndarray, shape (n, 3)
    """

    if poses is None:
        return sample_board_poses(board, cam, n, seed=seed, fill=fill, max_tilt_deg=max_tilt_deg,
                                  max_roll_deg=max_roll_deg)
    R = np.asarray(poses[0], float).reshape(-1, 3, 3)
    t = np.asarray(poses[1], float).reshape(-1, 3)
    if R.shape[0] != n or t.shape[0] != n:
        raise InputError(f"poses: expected {n} rotations and translations, got {R.shape[0]} and {t.shape[0]}")
    return R, t


def _render_view(renderer, phone, cam, board, R_cam_board, t_cam_board_m, render_seed: int, exposure_seed: int,
                 stages, exposure_fill: float, *, name: str):
    """Render one view, expose it at the manual exposure; (image, delivered camera, view record)."""

    frame = renderer.render(R_cam_board, t_cam_board_m, seed=render_seed)
    t0 = time.perf_counter()
    ex = phone.exposer(frame.flux, stages=stages)
    exposure_s, iso = manual_exposure(phone, ex, exposure_fill)
    shot = ex.expose(seed=exposure_seed, exposure_s=exposure_s, iso=iso)
    expose_s = time.perf_counter() - t0
    img = shot.image
    delivered = solver_camera(cam, img.shape)
    feats = delivered.project(board.object_points() @ R_cam_board.T + t_cam_board_m)
    view = {
        "image": name,
        "R_cam_board": R_cam_board.tolist(),
        "t_cam_board_m": t_cam_board_m.tolist(),
        "distance_m": float(np.linalg.norm(t_cam_board_m + R_cam_board @ np.array([*_centre(board), 0.0]))),
        "features_px": np.round(feats, 6).tolist(),
        "exposure_s": float(shot.exposure_s),
        "iso": float(shot.iso),
        "render_seed": int(render_seed),
        "exposure_seed": int(exposure_seed),
        "saturated_fraction": float(np.mean(img >= 255)),
        "timings_s": {**{k: round(v, 4) for k, v in frame.timings_s.items()}, "expose_s": round(expose_s, 4)},
    }
    return img, delivered, view


def _set_truth(cam, delivered, board, renderer, views, *, seed: int, stages, exposure_fill: float) -> dict:
    """The truth record of a rendered board set (``truth.json``)."""
    return {
        "what": "rendered calibration-board set (svgs calibrate render-board)",
        "camera": delivered.name,
        "intrinsics": {"width": delivered.width, "height": delivered.height, "fx": delivered.fx, "fy": delivered.fy,
                       "cx": delivered.cx, "cy": delivered.cy},
        "distortion": {k: float(v) for k, v in zip(("k1", "k2", "p1", "p2", "k3"), delivered.dist)},
        "render_intrinsics": {"width": cam.width, "height": cam.height, "fx": cam.fx, "fy": cam.fy, "cx": cam.cx, "cy": cam.cy},
        "pixel_convention": "OpenCV: pixel centres at integer coordinates",
        "board": board.to_json(),
        "board_extent_m": list(board.extent_m),
        "pose_convention": "p_cam = R_cam_board @ p_board + t_cam_board_m (OpenCV camera frame); board x right, y down, z = 0",
        "seed": int(seed),
        "n_views": len(views),
        "render": renderer.info(),
        "phone": {"stages": list(stages), "exposure": "manual", "exposure_fill_of_full_well": float(exposure_fill)},
        "views": views,
        "versions": _versions(),
    }

def _centre(board) -> tuple[float, float]:
    x0, y0, x1, y1 = board.extent_m
    return 0.5 * (x0 + x1), 0.5 * (y0 + y1)


__all__ = ["BoardSet", "render_board_set", "manual_exposure", "DEFAULT_BOARD_SPP", "DEFAULT_EXPOSURE_FILL"]
