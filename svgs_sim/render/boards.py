"""Rendered calibration sets: planar boards through Mitsuba and the phone camera model.

A calibration board (:class:`svgs_sim.calibration.Board`) is a Lambertian rectangle textured with the
board's printable image (:meth:`svgs_sim.calibration.Board.draw`: paper and ink reflectances), lit by
a uniform constant environment (a room's diffuse light), in front of a grey Lambertian wall.
The camera is the profile's exact OpenCV model - focal lengths, principal point and
Brown-Conrady distortion - through the custom sensor of :mod:`svgs_sim.render.sensor` (thin-lens
aperture focused at the profile's ``focus_distance_m``, or a pinhole). The rendered radiance
becomes photons per pixel (:func:`svgs_sim.render.optics.radiance_to_photon_rate`), then the phone's
image through :class:`svgs_sim.camera.phone.PhoneCamera` (lens PSF, noise, ADC, tone curve, and the
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
imported inside :class:`BoardRenderer` only, after :func:`svgs_sim.render.variant.select_variant`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from svgs_sim.base.errors import InputError, ProfileError, check_finite_positive
from svgs_sim.base.profiles import Camera, load_camera

from .optics import Optics, photometry, pixel_normalized_grid, radiance_to_photon_rate
from .sampling import render_film, round_up_power
from .scene import film_dict
from .sensor import PLUGIN_NAME, CameraModel, sensor_class
from .variant import select_variant

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
        True projections of :meth:`svgs_sim.calibration.Board.object_points` (distortion included).
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
        Passed to :func:`svgs_sim.render.variant.select_variant`.

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

        self.camera = load_camera(camera)
        self.board = board
        self.optics = Optics.from_camera(self.camera)
        spectrum = str(self.camera.flash.given("spectrum", "white-led"))
        try:
            self.photometry = photometry(spectrum, self.optics.band_nm)
        except InputError as exc:
            raise ProfileError(f"camera {self.camera.name!r}: {exc}") from None
        if isinstance(spp, bool) or not isinstance(spp, (int, np.integer)) or spp < 1:
            raise InputError(f"spp: expected a positive integer, got {spp!r}")
        self.spp = round_up_power(int(spp))
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


        self.variant = select_variant(variant)
        import drjit as dr
        import mitsuba as mi


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
        spp = self.spp if spp is None else round_up_power(max(1, int(spp)))
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
                acc += render_film(mi, self.scene, self._sensor, self._spp_pass, int(seeds[k]))
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


__all__ = [
    "BoardRenderer",
    "BoardFrame",
    "texture_px_per_m",
    "DEFAULT_BOARD_SPP",
]
