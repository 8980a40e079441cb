"""Rendered calibration sets: planar boards through Mitsuba and the phone camera model.

A calibration board (:class:`calibration.Board`) is a Lambertian rectangle textured with the
board's printable image (:meth:`calibration.Board.draw`: paper and ink reflectances), lit by
a uniform constant environment (a room's diffuse light), in front of a grey Lambertian wall.
The camera is the profile's exact OpenCV model - focal lengths, principal point and
Brown-Conrady distortion - through the custom sensor of :mod:`render.sensor` (thin-lens
aperture focused at the profile's ``focus_distance_m``, or a pinhole). The rendered radiance
becomes photons per pixel (:func:`render.optics.radiance_to_photon_rate`), then the phone's
image through :class:`render.phone.PhoneCamera` (lens PSF, noise, ADC, tone curve, and the
profile's downscale / JPEG if any) at a **manual exposure** chosen so that the board's paper
reaches a set fraction of full well.

Sampling: the ``direct`` integrator with BSDF sampling only. Under a constant environment a
cosine-sampled Lambertian bounce has weight ``rho * L`` exactly, so a pixel's only Monte Carlo
error is its area (and aperture) integral of the texture - anti-aliasing, not lighting noise.
The texture is bilinearly filtered at ``px_per_m`` texels per metre, chosen so a texel is at
most half a pixel at the nearest board point (checked: detected chessboard corners agree
with the true projections to the detector's own precision, 0.05 px RMS, no bias).

World frame = board frame (x right, y down, z away from the camera, ``z = 0`` on the board);
the camera pose is ``p_cam = R_cam_board @ p_board + t_cam_board_m``.

Nothing here is imported by :mod:`svgs` or :mod:`calibration` at import time; Mitsuba is
imported inside :class:`BoardRenderer` only, after :func:`render.variant.select_variant`.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from svgs.errors import InputError, ProfileError, check_finite_positive
from svgs.profiles import Camera

#: Samples per pixel of a board render (rounded up to a power of four for ``ldsampler``).
DEFAULT_BOARD_SPP = 16
#: Radiance of the room's uniform light, W m^-2 sr^-1 in the camera band. ASSUMPTION: an
#: office-lit scene (~500 lx on the board: a white page at ~130 cd/m^2 ~ 0.4 W m^-2 sr^-1
#: in 400-700 nm). With the manual exposure below only the exposure time depends on it.
DEFAULT_AMBIENT_RADIANCE_W_M2_SR = 0.5
#: Reflectance of the board's paper and ink (matt laser print). ASSUMPTION.
DEFAULT_PAPER_REFLECTANCE = 0.85
DEFAULT_INK_REFLECTANCE = 0.04
#: A grey wall this far behind the board plane, with this reflectance. ASSUMPTION.
DEFAULT_WALL_DISTANCE_M = 1.0
DEFAULT_WALL_REFLECTANCE = 0.3
#: Manual exposure: the paper (99.5th percentile of the signal) at this fraction of full well.
DEFAULT_EXPOSURE_FILL = 0.7
#: Texels per pixel at the nearest board point (bilinear filtering).
DEFAULT_TEXELS_PER_PX = 2.0
#: Largest texture, texels (float32: 4 bytes each).
MAX_TEXELS = 1 << 25
#: Samples in one Mitsuba pass (memory ~100 bytes per sample): the frame is rendered in strips.
MAX_SAMPLES_PER_PASS = 1 << 22
#: Longest manual exposure, s (a tripod scene); beyond it the ISO goes up.
MAX_MANUAL_EXPOSURE_S = 1.0


def _pow4(n: int) -> int:
    k = 1
    while k < int(n):
        k *= 4
    return k


def texture_px_per_m(board, camera: Camera, R_cam_board, t_cam_board_m, texels_per_px: float = DEFAULT_TEXELS_PER_PX) -> float:
    """Texture resolution for a set of views: ``texels_per_px`` texels per pixel at the
    nearest board point, rounded up so that one spacing is a whole number of texels (the
    squares' edges then fall on texel boundaries), and capped at :data:`MAX_TEXELS`.

    Parameters
    ----------
    board : calibration.Board
    camera : Camera
    R_cam_board : array_like, shape (V, 3, 3) or (3, 3)
    t_cam_board_m : array_like, shape (V, 3) or (3,)
    texels_per_px : float

    Returns
    -------
    float
        Texels per metre.
    """
    R = np.asarray(R_cam_board, float).reshape(-1, 3, 3)
    t = np.asarray(t_cam_board_m, float).reshape(-1, 3)
    x0, y0, x1, y1 = board.extent_m
    q = board.quiet_zone_m
    corners = np.array([[a, b, 0.0] for a in (x0 - q, x1 + q) for b in (y0 - q, y1 + q)])
    zmin = min(float(np.min((corners @ Rk.T + tk)[:, 2])) for Rk, tk in zip(R, t))
    if zmin <= 0:
        raise InputError("board render: the board is (partly) behind the camera")
    ppm = float(texels_per_px) * max(camera.fx, camera.fy) / zmin
    area = (x1 - x0 + 2 * q) * (y1 - y0 + 2 * q)
    ppm = min(ppm, np.sqrt(MAX_TEXELS / area))
    return float(np.ceil(ppm * board.spacing_m) / board.spacing_m)


@dataclass
class BoardFrame:
    """One rendered board view (noise-free).

    Attributes
    ----------
    radiance : ndarray of float32, shape (H, W)
        Mean radiance over each pixel (and the aperture), W m^-2 sr^-1 in band.
    flux : ndarray of float32, shape (H, W)
        Photons per second reaching each pixel, in band.
    R_cam_board : ndarray, shape (3, 3)
    t_cam_board_m : ndarray, shape (3,)
    features_px : ndarray, shape (N, 2)
        True projections of :meth:`calibration.Board.object_points` (distortion included).
    timings_s : dict
    """

    radiance: np.ndarray
    flux: np.ndarray
    R_cam_board: np.ndarray
    t_cam_board_m: np.ndarray
    features_px: np.ndarray
    timings_s: dict = field(default_factory=dict)


class BoardRenderer:
    """A loaded Mitsuba scene of one board seen by one camera.

    Parameters
    ----------
    camera : str, path or Camera
        Needs an ``[optics]`` table (aperture, focus distance, band).
    board : calibration.Board
    px_per_m : float
        Texture resolution (see :func:`texture_px_per_m`).
    spp : int
        Samples per pixel (rounded up to a power of four).
    pinhole : bool
        A pinhole camera instead of the profile's thin lens (no defocus).
    ambient_radiance_w_m2_sr : float
        The room's uniform radiance (in band).
    paper_reflectance, ink_reflectance, wall_reflectance : float
        Lambertian reflectances (0..1).
    wall_distance_m : float
        Distance of the wall behind the board plane.
    variant : str, optional
        Passed to :func:`render.variant.select_variant`.

    Raises
    ------
    InputError
        Bad parameters; ProfileError when the camera lacks ``[optics]``.
    """

    def __init__(self, camera, board, *, px_per_m: float, spp: int = DEFAULT_BOARD_SPP, pinhole: bool = False,
                 ambient_radiance_w_m2_sr: float = DEFAULT_AMBIENT_RADIANCE_W_M2_SR,
                 paper_reflectance: float = DEFAULT_PAPER_REFLECTANCE, ink_reflectance: float = DEFAULT_INK_REFLECTANCE,
                 wall_reflectance: float = DEFAULT_WALL_REFLECTANCE, wall_distance_m: float = DEFAULT_WALL_DISTANCE_M,
                 variant: str | None = None):
        from .optics import Optics, photometry

        self.camera = Camera.load(camera)
        self.board = board
        self.optics = Optics.from_camera(self.camera)
        spectrum = str((self.camera.tables.get("flash") or {}).get("spectrum", "white-led"))
        try:
            self.photometry = photometry(spectrum, self.optics.band_nm)
        except InputError as exc:
            raise ProfileError(f"camera {self.camera.name!r}: {exc}") from None
        if isinstance(spp, bool) or not isinstance(spp, (int, np.integer)) or spp < 1:
            raise InputError(f"spp: expected a positive integer, got {spp!r}")
        self.spp = _pow4(int(spp))
        self.pinhole = bool(pinhole)
        self.ambient = check_finite_positive(ambient_radiance_w_m2_sr, "ambient_radiance_w_m2_sr")
        for name, v in (("paper_reflectance", paper_reflectance), ("ink_reflectance", ink_reflectance),
                        ("wall_reflectance", wall_reflectance)):
            if not (np.isfinite(v) and 0.0 <= v <= 1.0):
                raise InputError(f"{name}: expected a reflectance in 0..1, got {v!r}")
        if ink_reflectance >= paper_reflectance:
            raise InputError(f"ink_reflectance ({ink_reflectance}) must be below paper_reflectance ({paper_reflectance})")
        self.paper, self.ink, self.wall = float(paper_reflectance), float(ink_reflectance), float(wall_reflectance)
        self.wall_distance_m = check_finite_positive(wall_distance_m, "wall_distance_m")
        self.px_per_m = check_finite_positive(px_per_m, "px_per_m")

        from .variant import select_variant

        self.variant = select_variant(variant)
        import drjit as dr
        import mitsuba as mi

        from .scene import film_dict
        from .sensor import PLUGIN_NAME, CameraModel, sensor_class

        self._mi, self._dr = mi, dr
        t0 = time.perf_counter()
        tex = board.draw(self.px_per_m)
        self.texture = tex
        h, w = tex.image.shape
        albedo = (self.ink + (self.paper - self.ink) * tex.image.astype(np.float32) / 255.0).astype(np.float32)
        # texel (i, j) centre <-> board point ((j - ox) / ppm, (i - oy) / ppm); Mitsuba's bitmap
        # puts texel centres at uv = ((j + 0.5) / w, (i + 0.5) / h) and the rectangle maps local
        # (x, y) in [-1, 1]^2 to uv = ((x + 1) / 2, (y + 1) / 2) (both checked numerically).
        ppm = tex.px_per_m
        X0, X1 = (-0.5 - tex.origin_px[0]) / ppm, (w - 0.5 - tex.origin_px[0]) / ppm
        Y0, Y1 = (-0.5 - tex.origin_px[1]) / ppm, (h - 0.5 - tex.origin_px[1]) / ppm
        cxb, cyb, hx, hy = 0.5 * (X0 + X1), 0.5 * (Y0 + Y1), 0.5 * (X1 - X0), 0.5 * (Y1 - Y0)
        M_board = [[hx, 0, 0, cxb], [0, hy, 0, cyb], [0, 0, 1, 0], [0, 0, 0, 1]]
        big = 50.0
        M_wall = [[big, 0, 0, cxb], [0, big, 0, cyb], [0, 0, 1, self.wall_distance_m], [0, 0, 0, 1]]
        sensor_class()
        W, H = self.camera.width, self.camera.height
        spp_pass = self.spp
        while spp_pass > 1 and spp_pass * W > MAX_SAMPLES_PER_PASS:
            spp_pass //= 4
        self._spp_pass = spp_pass
        self._strip_h = int(max(1, min(H, MAX_SAMPLES_PER_PASS // (spp_pass * W))))
        scene = {
            "type": "scene",
            # BSDF sampling only: exact (zero-variance) lighting by a constant environment
            "integrator": {"type": "direct", "emitter_samples": 0, "bsdf_samples": 1, "hide_emitters": True},
            "sensor": {"type": PLUGIN_NAME, "film": film_dict(W, self._strip_h),
                       "sampler": {"type": "ldsampler", "sample_count": spp_pass}},
            # normals flipped: the printed side faces -z, towards the camera
            "board": {"type": "rectangle", "flip_normals": True, "to_world": mi.ScalarTransform4f(M_board),
                      "bsdf": {"type": "diffuse", "reflectance": {
                          "type": "bitmap", "bitmap": mi.Bitmap(albedo), "raw": True,
                          "filter_type": "bilinear", "wrap_mode": "clamp"}}},
            "wall": {"type": "rectangle", "flip_normals": True, "to_world": mi.ScalarTransform4f(M_wall),
                     "bsdf": {"type": "diffuse", "reflectance": {"type": "uniform", "value": self.wall}}},
            "room": {"type": "constant", "radiance": {"type": "uniform", "value": self.ambient}},
        }
        self.scene = mi.load_dict(scene)
        self._sensor = self.scene.sensors()[0]
        aperture = 0.0 if self.pinhole else self.optics.aperture_radius_m
        self.model = CameraModel(self.camera, aperture, self.optics.focus_distance_m)
        self._sensor.set_model(self.model)
        self._factor = None
        self.load_time_s = time.perf_counter() - t0

    def flux_factor(self) -> np.ndarray:
        """Photons/s per pixel per unit radiance, float32 (H, W)."""
        if self._factor is None:
            from .optics import pixel_normalized_grid, radiance_to_photon_rate

            xy = pixel_normalized_grid(self.camera)
            self._factor = radiance_to_photon_rate(self.camera, self.optics, self.photometry["mean_photon_energy_j"],
                                                   xy).astype(np.float32)
        return self._factor

    def render(self, R_cam_board, t_cam_board_m, *, seed: int = 0, spp: int | None = None) -> BoardFrame:
        """Render one view.

        Parameters
        ----------
        R_cam_board : array_like, shape (3, 3)
        t_cam_board_m : array_like, shape (3,)
        seed : int
            Seed of the low-discrepancy sampler (each pass and strip gets its own).
        spp : int, optional
            Override the renderer's samples per pixel.

        Returns
        -------
        BoardFrame
        """
        mi = self._mi
        R = np.asarray(R_cam_board, float)
        t = np.asarray(t_cam_board_m, float)
        if R.shape != (3, 3) or t.shape != (3,) or not (np.all(np.isfinite(R)) and np.all(np.isfinite(t))):
            raise InputError(f"board pose: expected a finite 3x3 rotation and 3-vector, got shapes {R.shape}, {t.shape}")
        if np.max(np.abs(R @ R.T - np.eye(3))) > 1e-6 or np.linalg.det(R) < 0:
            raise InputError("R_cam_board: not a proper rotation")
        pts = self.board.object_points() @ R.T + t
        if np.any(pts[:, 2] <= 0):
            raise InputError("board pose: the board is (partly) behind the camera")
        spp = self.spp if spp is None else _pow4(max(1, int(spp)))
        n_pass = max(1, spp // self._spp_pass)
        t0 = time.perf_counter()
        self.model.set_pose(R.T, -R.T @ t)
        W, H, hs = self.camera.width, self.camera.height, self._strip_h
        starts = list(range(0, H, hs))
        rad = np.zeros((H, W))
        seeds = np.random.SeedSequence([int(seed), 0xB0A2D]).generate_state(n_pass * len(starts), dtype=np.uint32)
        k = 0
        for y0 in starts:
            y0c = min(y0, H - hs)  # the last strip may overlap its neighbour
            self._sensor.set_windows(np.array([[0.0, float(y0c)]]), hs)
            acc = np.zeros((hs, W))
            for _ in range(n_pass):
                img = np.asarray(mi.render(self.scene, sensor=self._sensor, spp=self._spp_pass, seed=int(seeds[k])),
                                 dtype=np.float64)
                acc += img.mean(axis=2) if img.ndim == 3 else img
                k += 1
            rad[y0c:y0c + hs] = acc / n_pass
        t1 = time.perf_counter()
        flux = (rad * self.flux_factor()).astype(np.float32)
        feats = self.camera.project(pts)
        return BoardFrame(rad.astype(np.float32), flux, R, t, feats,
                          {"render_s": t1 - t0, "convert_s": time.perf_counter() - t1})

    def info(self) -> dict:
        """Scene parameters for the truth record."""
        return {
            "integrator": "direct (BSDF sampling only: exact under a constant environment)",
            "spp": int(self.spp),
            "texture_px_per_m": float(self.texture.px_per_m),
            "texture_size_px": [int(self.texture.image.shape[1]), int(self.texture.image.shape[0])],
            "texture_filter": "bilinear",
            "lens": "pinhole" if self.pinhole else "thin lens",
            "aperture_radius_m": 0.0 if self.pinhole else float(self.optics.aperture_radius_m),
            "focus_distance_m": float(self.optics.focus_distance_m),
            "ambient_radiance_w_m2_sr": self.ambient,
            "paper_reflectance": self.paper,
            "ink_reflectance": self.ink,
            "wall_reflectance": self.wall,
            "wall_distance_m": self.wall_distance_m,
            "band_nm": list(self.optics.band_nm),
            "mean_photon_energy_j": float(self.photometry["mean_photon_energy_j"]),
            "variant": self.variant.name,
            "variant_notice": self.variant.notice,
        }


# --------------------------------------------------------------------------- exposure
def manual_exposure(phone, exposer, fill: float = DEFAULT_EXPOSURE_FILL) -> tuple[float, float]:
    """Manual exposure that puts the brightest paper at ``fill`` of full well.

    The 99.5th percentile of the noise-free signal after the lens PSF is taken as the
    paper's level. The time is capped at :data:`MAX_MANUAL_EXPOSURE_S`; beyond it the ISO
    rises (up to the profile's ``max_iso``).

    Parameters
    ----------
    phone : render.phone.PhoneCamera
    exposer : render.phone.Exposer
    fill : float
        Fraction of full well, in (0, 1].

    Returns
    -------
    exposure_s, iso : float
    """
    if not (np.isfinite(fill) and 0.0 < fill <= 1.0):
        raise InputError(f"exposure fill: expected a fraction of full well in (0, 1], got {fill!r}")
    sp, ex = phone.params.sensor, phone.params.exposure
    white = float(np.percentile(exposer.flux_optics, 99.5)) * sp.qe  # e-/s
    if not white > 0:
        raise InputError("board render: the image is black (no light reaches the sensor)")
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
        import cv2

        out = Path(out_dir)
        if out.exists() and not out.is_dir():
            raise InputError(f"--out {str(out)!r} exists and is not a folder")
        out.mkdir(parents=True, exist_ok=True)
        files = []
        for img, n in zip(self.images, self.names):
            p = out / n
            if not cv2.imwrite(str(p), img):
                raise InputError(f"cannot write {str(p)!r}")
            files.append(str(p))
        with open(out / "truth.json", "w") as fh:
            json.dump(self.truth, fh, indent=1)
        self.camera.save(out / "camera_true.toml")
        return {"images": files, "truth": str(out / "truth.json"), "camera": str(out / "camera_true.toml")}

    @classmethod
    def load(cls, folder) -> "BoardSet":
        """Read a set written by :meth:`save` (``svgs calibrate render-board``)."""
        from calibration.boards import Board
        from svgs.pipeline import load_image

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
        camera = Camera.load(d / "camera_true.toml")
        images = [load_image(d / n) for n in names]
        return cls(images, names, camera, board, R, t, truth)


def _versions() -> dict:
    import cv2

    out = {"numpy": np.__version__, "opencv": cv2.__version__}
    try:
        import drjit as dr
        import mitsuba as mi

        out.update(mitsuba=mi.__version__, drjit=dr.__version__)
    except ImportError:  # pragma: no cover - only called after a render
        pass
    return out


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
        Seeds the poses (:func:`calibration.sample_board_poses`), each view's sampler and
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
        Passed to :func:`calibration.sample_board_poses`.
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
    from calibration.boards import sample_board_poses

    from .phone import PhoneCamera
    from .simulate import solver_camera

    cam = Camera.load(camera)
    try:
        n = int(n_views)
    except (TypeError, ValueError):
        raise InputError(f"views: expected a positive integer, got {n_views!r}") from None
    if n < 1 or n != n_views:
        raise InputError(f"views: expected a positive integer, got {n_views!r}")
    from .optics import Optics

    Optics.from_camera(cam)  # fail early (ProfileError) without [optics]
    phone = PhoneCamera(cam)
    st = tuple(phone.params.isp.stages) if stages is None else tuple(stages)
    ss = np.random.SeedSequence(int(seed))
    s_pose, s_render, s_expose = (int(c.generate_state(1)[0]) for c in ss.spawn(3))
    if poses is None:
        R, t = sample_board_poses(board, cam, n, seed=s_pose, fill=fill, max_tilt_deg=max_tilt_deg,
                                  max_roll_deg=max_roll_deg)
    else:
        R = np.asarray(poses[0], float).reshape(-1, 3, 3)
        t = np.asarray(poses[1], float).reshape(-1, 3)
        if R.shape[0] != n or t.shape[0] != n:
            raise InputError(f"poses: expected {n} rotations and translations, got {R.shape[0]} and {t.shape[0]}")
    ppm = texture_px_per_m(board, cam, R, t, texels_per_px)
    renderer = BoardRenderer(cam, board, px_per_m=ppm, spp=spp, pinhole=pinhole, **(renderer_options or {}))
    r_seeds = np.random.SeedSequence(s_render).generate_state(n, dtype=np.uint32)
    e_seeds = np.random.SeedSequence(s_expose).generate_state(n, dtype=np.uint32)
    images, names, views = [], [], []
    delivered = None
    for k in range(n):
        frame = renderer.render(R[k], t[k], seed=int(r_seeds[k]))
        t0 = time.perf_counter()
        ex = phone.exposer(frame.flux, stages=st)
        exposure_s, iso = manual_exposure(phone, ex, exposure_fill)
        shot = ex.expose(seed=int(e_seeds[k]), exposure_s=exposure_s, iso=iso)
        expose_s = time.perf_counter() - t0
        img = shot.image
        delivered = solver_camera(cam, img.shape)
        name = f"view_{k:03d}.png"
        images.append(img)
        names.append(name)
        feats = delivered.project(board.object_points() @ R[k].T + t[k])
        views.append({
            "image": name,
            "R_cam_board": R[k].tolist(),
            "t_cam_board_m": t[k].tolist(),
            "distance_m": float(np.linalg.norm(t[k] + R[k] @ np.array([*_centre(board), 0.0]))),
            "features_px": np.round(feats, 6).tolist(),
            "exposure_s": float(shot.exposure_s),
            "iso": float(shot.iso),
            "render_seed": int(r_seeds[k]),
            "exposure_seed": int(e_seeds[k]),
            "saturated_fraction": float(np.mean(img >= 255)),
            "timings_s": {**{k2: round(v, 4) for k2, v in frame.timings_s.items()}, "expose_s": round(expose_s, 4)},
        })
        if progress is not None:
            progress(f"view {k + 1}/{n}: rendered in {frame.timings_s['render_s']:.1f} s, "
                     f"exposure {shot.exposure_s * 1e3:.2f} ms ISO {shot.iso:.0f}")
    truth = {
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
        "n_views": n,
        "render": renderer.info(),
        "phone": {"stages": list(st), "exposure": "manual", "exposure_fill_of_full_well": float(exposure_fill)},
        "views": views,
        "versions": _versions(),
    }
    out = BoardSet(images, names, delivered, board, R, t, truth)
    if out_dir is not None:
        out.save(out_dir)
    return out


def _centre(board) -> tuple[float, float]:
    x0, y0, x1, y1 = board.extent_m
    return 0.5 * (x0 + x1), 0.5 * (y0 + y1)


__all__ = [
    "BoardRenderer",
    "BoardFrame",
    "BoardSet",
    "render_board_set",
    "manual_exposure",
    "texture_px_per_m",
    "DEFAULT_BOARD_SPP",
]
