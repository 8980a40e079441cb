"""Numpy-returning entry points of the renderer.

>>> from svgs_sim.render import Renderer, render_flux
>>> from svgs_sim.svgs.frames import pose_from_scenario
>>> R, t = pose_from_scenario(10.0)
>>> res = render_flux("galaxy-nexus", "svgs-3u", R, t, seed=1)   # doctest: +SKIP
>>> res.flux.shape, res.truth["targets_px"]                       # doctest: +SKIP

:class:`Renderer` keeps the scene and its compiled kernels; :meth:`Renderer.render`
updates the pose in place. ``render_flux`` is a one-call form that reuses a cached
renderer for the same camera/pattern/reflector/options.

Sampling plan: the full frame at ``spp`` samples per pixel (the dark diffuse
background; 0 skips it), plus one fixed-size window (``roi_size_px`` square) around the
predicted spot of every target in the image at ``roi_spp`` - all windows in one
Mitsuba pass (a mosaic film), composed into the full frame. ``full_frame=True`` renders
the whole frame at ``spp`` instead (the reference the ROI scheme is tested against).
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from svgs_sim.base.errors import InputError, check_finite
from svgs_sim.base.image_files import write_image
from svgs_sim.base.limits import check_focus_beyond_focal_length
from svgs_sim.base.profiles import load_camera, load_pattern
from svgs_sim.camera.rendered import PointFlux, RenderedFrame
from svgs_sim.camera.tonemap import encode_u8, log_stretch
from svgs_sim.svgs.frames import check_pose

from .constants import (
    DEFAULT_ROI_SIZE_PX,
    DEFAULT_ROI_SPP,
    DEFAULT_ROI_SPP_PATH,
    DEFAULT_SPOT_SAMPLER,
    DEFAULT_SPOT_SAMPLES,
    DEFAULT_SPP,
)
from .geometry import Reflector, SceneOptions
from .optics import Flash, Optics, pixel_normalized_grid, radiance_to_photon_rate
from .predict import predicted_centroids_px, predicted_spots_px, virtual_sources
from .sampling import check_spp, render_film, to_numpy
from .scene import TILE_COUNTS
from .scene import TILE_SIZE_PX as T
from .scene import build_scene
from .sensor import CameraModel
from .spots import SPOT_SAMPLERS, SpotEstimator
from .sun import photon_spectra, sun_in_band, sun_in_image
from .earth import earth_half_angle_deg, earth_in_image, earth_map
from .environment import EnvironmentGrid, environment_radiance
from .truth import svgs_frame_truth
from .variant import select_variant
from .windows import background_tiles, spot_windows

#: Upper bound of samples in one Mitsuba pass (memory: ~100 bytes per lane).
MAX_SAMPLES_PER_PASS = 1 << 24
#: The :class:`~svgs_sim.render.geometry.SceneOptions` fields of the natural light, which
#: :meth:`Renderer.set_natural_light` changes on a built renderer.
NATURAL_LIGHT_FIELDS = ("sun_direction_target", "earth_direction_target", "altitude_m", "earth_albedo")


@dataclass
class RenderResult(RenderedFrame):
    """One rendered frame: a :class:`svgs_sim.camera.rendered.RenderedFrame` (``truth``, ``timings_s``,
    ``pose()``) with the flux and radiance of the SVGS renderer.

    Attributes
    ----------
    flux : ndarray of float32, shape (H, W)
        Photons per second reaching each pixel, in the camera band (noise-free
        expectation, up to Monte Carlo error), before the lens PSF: everything binned into
        the pixel where it meets the film.
    radiance : ndarray of float32, shape (H, W)
        Mean radiance over each pixel and the aperture, W m^-2 sr^-1 in band.
    flux_diffuse : ndarray of float32, shape (H, W), optional
        The part of ``flux`` rendered per pixel (diffuse light; with method "path",
        everything).
    points : svgs_sim.camera.rendered.PointFlux, optional
        The rest of ``flux`` (the flash through the cubes, guided method) as samples at exact
        film positions, photons/s each: the camera applies its PSF to them before pixel
        integration (:meth:`film`).
    flux_sun : ndarray of float32, shape (H, W), optional
        The sun's part of ``flux`` and ``flux_diffuse`` (a scene with the sun,
        :mod:`svgs_sim.render.sun`), photons/s per pixel counted with the sun's mean photon
        energy in the band.
    natural_spectra : tuple of ndarray, optional
        With ``flux_sun``: ``(wavelength_nm (n,), photons_natural (n,), photons_flash (n,))``, the
        sun's (and the grey Earth's) and the flash's photon spectra over the band (any scale
        each; :func:`svgs_sim.render.sun.photon_spectra`), for the camera's colour filters.
    truth : dict
        Pose, projections, every physical parameter used (JSON-serialisable; keyword-only).
    timings_s : dict
        Keyword-only.
    """

    flux: np.ndarray
    radiance: np.ndarray
    flux_diffuse: np.ndarray | None = None
    points: PointFlux | None = None
    flux_sun: np.ndarray | None = None
    natural_spectra: tuple | None = None

    def film(self) -> tuple[np.ndarray, PointFlux | None]:
        """What the camera model takes: ``(flux already integrated over pixels (H, W), point
        samples or None)``; the two parts are disjoint and ``flux`` is their pixel sum."""
        if self.points is None or self.flux_diffuse is None:
            return self.flux, None
        return self.flux_diffuse, self.points

    def save(self, out_dir) -> dict:
        """Write ``flux.npy``, ``truth.json`` and ``preview.png`` into ``out_dir`` (and, for the
        guided method, ``flux_diffuse.npy`` and ``points.npz``: the film before the lens PSF)."""

        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        np.save(out / "flux.npy", self.flux.astype(np.float32))
        if self.points is not None and self.flux_diffuse is not None:
            np.save(out / "flux_diffuse.npy", self.flux_diffuse.astype(np.float32))
            self.points.save(out / "points.npz")
        with open(out / "truth.json", "w", encoding="utf-8") as fh:
            json.dump(self.truth, fh, indent=2)
        write_preview(out / "preview.png", self.flux)
        paths = {"flux": str(out / "flux.npy"), "truth": str(out / "truth.json"), "preview": str(out / "preview.png")}
        if self.points is not None and self.flux_diffuse is not None:
            paths.update({"flux_diffuse": str(out / "flux_diffuse.npy"), "points": str(out / "points.npz")})
        return paths


def write_preview(path, flux: np.ndarray) -> None:
    """Tone-mapped 8-bit preview for people: log scale between the 1st percentile of
    the lit pixels and the maximum (the spots are ~1e7 x the background)."""

    write_image(path, encode_u8(log_stretch(flux)))


class Renderer:
    """A loaded scene for one camera, pattern, reflector and scene options.

    Parameters
    ----------
    camera : str, path or svgs.Camera
        Needs ``[optics]`` and ``[flash]`` tables (see :mod:`svgs_sim.render.optics`).
    pattern : str, path or svgs.Pattern
    reflector : None, str, dict or Reflector
        See :meth:`svgs_sim.render.geometry.Reflector.resolve` (default: the pattern's model).
    scene_options : None, dict or SceneOptions
    roi_size_px : int
        Side of the square windows rendered around each spot (constant for the
        renderer's life: changing it would recompile).
    spp, roi_spp : int
        Default samples per pixel of the background (tiles covering the projected
        scene, or the full frame) and of the windows around the spots, rounded up to
        powers of four as Mitsuba's ``ldsampler`` needs; ``spp=0`` skips the background.
        ``roi_spp`` defaults to 64 (guided) or 4096 (path).
    spot_samples : int
        Guided samples per virtual source (:mod:`svgs_sim.render.spots`), method ``"guided"``.
    spot_sampler : {"kronecker", "sobol", "independent"}
        How the guided samples are placed (:class:`svgs_sim.render.spots.SpotEstimator`): the 4-D R4
        low-discrepancy sequence (default), padded scrambled Sobol' points, or independent random
        numbers.
    method : {"guided", "path"}
        ``"guided"`` (default): diffuse light by Mitsuba's ``path`` integrator with the
        LEDs as point lights, the flash seen through glass and mirrors by the guided
        spot estimator. ``"path"``: the LEDs as disk area emitters and everything path
        traced (brute force, the reference; needs ~1e5+ spp per pixel beyond ~10 m).
    variant : str, optional
        Passed to :func:`render.select_variant`.
    extra_meshes : sequence of svgs_sim.render.geometry.MeshSpec
        Extra geometry in the target frame (tests).

    Raises
    ------
    InputError
        Unknown profile, missing ``[optics]``/``[flash]`` table, bad options.
    """

    def __init__(self, camera, pattern="svgs-3u", *, reflector=None, scene_options=None,
                 roi_size_px: int = DEFAULT_ROI_SIZE_PX, spp: int = DEFAULT_SPP, roi_spp: int | None = None,
                 spot_samples: int = DEFAULT_SPOT_SAMPLES, method: str = "guided", variant: str | None = None,
                 extra_meshes=(), spot_sampler: str = DEFAULT_SPOT_SAMPLER):
        self.camera = load_camera(camera)
        self.pattern = load_pattern(pattern)
        self.optics = Optics.from_camera(self.camera)
        self.flash = Flash.from_camera(self.camera, self.optics.band_nm)
        self.reflector = Reflector.resolve(reflector, self.pattern)
        self.options = SceneOptions.resolve(scene_options)
        if self.options.focus_distance_m is not None:

            self.optics = replace(self.optics, focus_distance_m=float(self.options.focus_distance_m))
        check_focus_beyond_focal_length(self.optics.focus_distance_m, self.optics.focal_length_m,
                                        "focus_distance_m" if self.options.focus_distance_m is not None
                                        else f"{self.camera.name}'s [optics] focus_distance_m")
        roi = int(roi_size_px)
        if roi < 4:
            raise InputError(f"roi_size_px: expected >= 4, got {roi_size_px!r}")
        self.roi_size_px = min(roi, self.camera.width, self.camera.height)
        self.spp = check_spp(spp, "spp", allow_zero=True)
        if roi_spp is None:
            roi_spp = DEFAULT_ROI_SPP if method == "guided" else DEFAULT_ROI_SPP_PATH
        self.roi_spp = check_spp(roi_spp, "roi_spp")
        self.n_windows = int(self.pattern.n)
        if method not in ("guided", "path"):
            raise InputError(f"method: expected 'guided' or 'path', got {method!r}")
        self.method = method
        self.spot_samples = check_spp(spot_samples, "spot_samples")
        if spot_sampler not in SPOT_SAMPLERS:
            raise InputError(f"spot_sampler: expected one of {', '.join(SPOT_SAMPLERS)}, got {spot_sampler!r}")
        self.spot_sampler = spot_sampler
        self.variant = select_variant(variant)
        t0 = time.perf_counter()
        self._extra_meshes = tuple(extra_meshes)  # once: both scenes (and a later sun) take the same meshes
        self._env_grid = None  # the closed-form environment's pixel grid (made on first use)
        self._sun_factor32 = None  # (the flux factor, the sun's photon ratio, their product in float32)
        self._load_scene(self._extra_meshes)
        self._sun = None
        if self.options.light_pass:
            self._load_sun_scene(self._extra_meshes)
        self.load_time_s = time.perf_counter() - t0
        self._factor_full = None

    def _load_scene(self, extra_meshes) -> None:
        """Build the Mitsuba scene, its sensors and camera model, and the spot estimator."""
        import drjit as dr
        import mitsuba as mi


        self._mi, self._dr = mi, dr
        self.scene, h = build_scene(self.camera, self.pattern, self.optics, self.flash, self.reflector, self.options,
                                    self.roi_size_px, self.n_windows, extra_meshes=extra_meshes, method=self.method)
        self._sensor_full, self._sensor_roi = h["sensor_full"], h["sensor_roi"]
        self._sensor_tiles = h["sensor_tiles"]
        self.target = h["target"]
        self._flash_keys = h["flash_keys"]
        self._params = h["params"]
        self.model = CameraModel(self.camera, self.optics.aperture_radius_m, self.optics.focus_distance_m)
        for s in (self._sensor_full, self._sensor_roi, *self._sensor_tiles.values()):
            s.set_model(self.model)
        bb = self.scene.bbox()
        lo, hi = to_numpy(bb.min), to_numpy(bb.max)
        self._scene_corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        self._sensor_full.set_windows(np.zeros((1, 2)), self.camera.height)
        self._glints = [d for d in self.options.distractors if d["type"] == "glint"]
        n_leds = self.flash.led_offsets_m.shape[0]
        self._n_strategies = self.pattern.n * n_leds * 3 + len(self._glints) * n_leds
        self.spots = None
        if self.method == "guided":
            self.spots = SpotEstimator(self.scene, self.model, self._n_strategies, n_leds,
                                       0.5 * self.flash.emitter_diameter_m, self.flash.radiance_w_m2_sr,
                                       self.flash.cos_exponent, self.options.max_depth, self.camera.width,
                                       self.camera.height, sampler=self.spot_sampler)

    def _load_sun_scene(self, extra_meshes) -> None:
        """The sun's scene: the same target without the flash, the sun as a disk emitter
        (:mod:`svgs_sim.render.sun`; none when the Earth eclipses it) and the Earth as an environment
        map (:mod:`svgs_sim.render.earth`); its sensors share the flash scene's camera model."""
        o = self.options
        light = sun_in_band(self.optics.band_nm)
        earth = None
        if o.earth_direction_target is not None:
            earth = earth_map(o.earth_direction_target, o.sun_direction_target, o.altitude_m, o.earth_albedo,
                              light["irradiance_w_m2"], o.earth_uniform_radiance_w_m2_sr)
        sun_dir = None if o.eclipsed else o.sun_direction_target
        scene, h = build_scene(self.camera, self.pattern, self.optics, self.flash, self.reflector, self.options,
                               self.roi_size_px, self.n_windows, extra_meshes=extra_meshes, method=self.method,
                               sun=(sun_dir, light["radiance_w_m2_sr"]), earth=earth)
        for s in (h["sensor_full"], h["sensor_roi"], *h["sensor_tiles"].values()):
            s.set_model(self.model)
        h["sensor_full"].set_windows(np.zeros((1, 2)), self.camera.height)
        self._sun = {"scene": scene, "full": h["sensor_full"], "tiles": h["sensor_tiles"], "light": light}

    def set_natural_light(self, **fields) -> None:
        """Change the sun and the Earth of a built renderer (the sun moving over an orbit's phase).

        Only the natural light's scene is rebuilt (:meth:`_load_sun_scene`); the flash's scene,
        its compiled kernels and the camera model are kept, so a frame rendered after the change
        equals one from a renderer built with the new fields (the same bytes for the same seed).
        Fields equal to the current ones change nothing.

        Parameters
        ----------
        **fields
            Any of :data:`NATURAL_LIGHT_FIELDS` (:class:`~svgs_sim.render.geometry.SceneOptions`'
            ``sun_direction_target``, ``earth_direction_target``, ``altitude_m``, ``earth_albedo``),
            checked as the constructor checks them.
        """
        bad = sorted(set(fields) - set(NATURAL_LIGHT_FIELDS))
        if bad:
            raise InputError(f"set_natural_light: unknown fields {bad}; known {list(NATURAL_LIGHT_FIELDS)}")
        new = replace(self.options, **fields)
        if new == self.options:
            return
        self.options = new
        self._sun = None
        if new.light_pass:
            self._load_sun_scene(self._extra_meshes)

    def set_focus_distance(self, focus_distance_m: float) -> None:
        """Refocus the lens (an autofocus following the target along an approach) without
        rebuilding the scene: the camera model's values are opaque Dr.Jit variables, so the
        compiled kernels are reused.

        Parameters
        ----------
        focus_distance_m : float
            Where the lens is focused, m (> 0).
        """

        f = float(check_finite(focus_distance_m, "focus_distance_m"))
        if f <= 0:
            raise InputError(f"focus_distance_m: expected a positive distance, got {focus_distance_m!r}")
        check_focus_beyond_focal_length(f, self.optics.focal_length_m, "focus_distance_m")
        if f == self.optics.focus_distance_m:
            return
        self.optics = replace(self.optics, focus_distance_m=f)
        self.options = replace(self.options, focus_distance_m=f)
        m = self.model
        m.values[-1] = f
        if m.jit:
            m._k = self._mi.Float(m.values)
            self._dr.make_opaque(m._k)

    # ------------------------------------------------------------------ geometry
    def predicted_spots_px(self, R_cam_target, t_cam_target_m) -> np.ndarray:
        """Geometric-optics spot centre of every target, averaged over the LEDs
        (:func:`svgs_sim.render.predict.predicted_spots_px`), shape (N, 2) px."""

        return predicted_spots_px(self.camera, self.flash, self.reflector, self.optics, self.target,
                                  R_cam_target, t_cam_target_m)

    def predicted_centroids_px(self, R_cam_target, t_cam_target_m) -> np.ndarray:
        """Geometric-optics pixel centroid of every retro spot, binned into pixels
        (:func:`svgs_sim.render.predict.predicted_centroids_px`), shape (N, 2) px."""

        return predicted_centroids_px(self.camera, self.flash, self.reflector, self.optics, self.target,
                                      R_cam_target, t_cam_target_m)

    def _set_pose(self, R, t):
        mi = self._mi
        R_wc = R.T
        p_wc = -R.T @ t
        self.model.set_pose(R_wc, p_wc)
        r = 0.5 * self.flash.emitter_diameter_m
        centre_cam = np.asarray(t, float)  # the target origin, camera frame
        for keys, off in zip(self._flash_keys, self.flash.led_offsets_m):
            if "to_world" in keys:
                M = np.eye(4)
                M[:3, :3] = R_wc * np.array([r, r, 1.0])  # disk radius r, normal = camera +z
                M[:3, 3] = R_wc @ off + p_wc
                self._params[keys["to_world"]] = mi.Transform4f(M.tolist())
                # a Lambertian disk: the cos^(m-1) radiance profile evaluated towards the target origin
                d = centre_cam - off
                c = d[2] / np.linalg.norm(d)
                if keys["radiance"] in self._params:  # identical textures of several LEDs are shared
                    self._params[keys["radiance"]] = float(self.flash.radiance_w_m2_sr * max(c, 0.0) ** (self.flash.cos_exponent - 1.0))
            else:
                d = centre_cam - off
                self._params[keys["position"]] = mi.Point3f(*(R_wc @ off + p_wc).tolist())
                # the profile I0 cos^m evaluated towards the target origin (see docs/renderer.md)
                if keys["intensity"] in self._params:  # identical textures of several LEDs are shared
                    self._params[keys["intensity"]] = float(self.flash.intensity_w_sr(d[2] / np.linalg.norm(d)))
        self._params.update()

    def _spot_image(self, R, t, seed):
        """Radiance of the flash seen through specular chains (guided estimator)."""

        V = self.target.cube_vertex_m @ R.T + t
        A = self.target.cube_axis @ R.T
        glints = [(np.asarray(g["position_m"]) @ R.T + t, g["radius_m"]) for g in self._glints]
        src, rad, act, labels = virtual_sources(self.camera, self.flash, self.reflector, self.optics.band_nm, V, A, glints)
        counts = np.where(act, self.spot_samples, 0)
        R_wc, p_wc = R.T, -R.T @ t
        leds_w = self.flash.led_offsets_m @ R_wc.T + p_wc
        img, samples = self.spots.render(src, rad, counts, leds_w, R_wc @ np.array([0.0, 0.0, 1.0]), seed)
        info = [{"label": lab, "source_cam_m": s_.tolist(), "radius_px": float(r_), "samples": int(c)}
                for lab, s_, r_, c in zip(labels, src, rad, counts) if c > 0]
        return img, info, samples

    def _radiance(self, sensor, spp, seed, scene=None):
        """Mean radiance image of one sensor (of ``scene``, default the flash's), float64, shape (h, w)."""
        mi = self._mi
        scene = self.scene if scene is None else scene
        fs = sensor.film().size()
        npx = int(fs[0]) * int(fs[1])
        per_pass = spp
        while per_pass > 4 and per_pass * npx > MAX_SAMPLES_PER_PASS:
            per_pass //= 4
        n_pass = max(1, spp // per_pass)
        acc = None
        seeds = np.random.SeedSequence(int(seed)).generate_state(n_pass, dtype=np.uint32)
        for k in range(n_pass):
            a = render_film(mi, scene, sensor, per_pass, int(seeds[k]))
            acc = a if acc is None else acc + a
        return acc / n_pass

    def spot_flux(self, R_cam_target, t_cam_target_m, *, seed: int = 0) -> float:
        """Total flux of the guided spot estimator's samples at a pose: the cubes' return as
        :meth:`render` adds it to a frame of the same ``seed`` (the same samples, the same sum as its
        ``points``), without the diffuse background, the spots' windows or the truth record, in
        about half a frame's time. No field-of-view check.

        Parameters
        ----------
        R_cam_target, t_cam_target_m : array_like, shapes (3, 3) and (3,)
            The pose, as :meth:`render` takes it.
        seed : int
            The frame's seed (as :meth:`render`'s).

        Returns
        -------
        float
            Photons/s reaching the sensor through the cubes; 0 without a spot estimator.
        """
        R, t = check_pose(R_cam_target, t_cam_target_m)
        seed = int(check_finite(seed, "seed"))
        if self.spots is None:
            return 0.0
        self._set_pose(R, t)
        _, _, (su, sv, sval) = self._spot_image(R, t, seed + _SPOT_SEED_OFFSET)
        if not len(su):
            return 0.0
        ui, vi = _sample_pixels(su, sv)
        return float(np.sum(sval * self.flux_factor()[vi, ui]))

    def flux_factor(self, u0=0, v0=0, width=None, height=None) -> np.ndarray:
        """Photons/s per pixel per unit radiance (W m^-2 sr^-1) of a window of the frame."""
        ph = self.flash.photometry["mean_photon_energy_j"]
        if u0 == 0 and v0 == 0 and width in (None, self.camera.width) and height in (None, self.camera.height):
            if self._factor_full is None:
                self._factor_full = _full_frame_factor(self.camera, self.optics, ph)
            return self._factor_full
        xy = pixel_normalized_grid(self.camera, u0, v0, width, height)
        return radiance_to_photon_rate(self.camera, self.optics, ph, xy)

    def _project_targets(self, R, t, check_fov: bool):
        """Projected targets ``(N, 2)`` px and their visibility ``(N,)``; InputError for a target
        behind the lens or (``check_fov``) none inside the image."""
        cam, pat = self.camera, self.pattern
        p_cam = pat.points_m @ R.T + t
        if np.any(p_cam[:, 2] <= 0.0):
            bad = [int(i) for i, z in zip(pat.ids, p_cam[:, 2]) if z <= 0]
            raise InputError(
                f"pose: target(s) {bad} lie behind the camera (z_cam <= 0; t_cam_target_m = {t.tolist()}); "
                "the range must be positive and the target in front of the lens"
            )
        targets_px = cam.project(p_cam)
        visible = cam.in_image(targets_px)
        if check_fov and not np.any(visible):
            raise InputError(
                f"pose: no target projects inside the {cam.width}x{cam.height} image "
                f"(targets_px = {np.round(targets_px, 1).tolist()}); the target is outside the field of view"
            )
        return targets_px, visible

    def _background(self, R, t, spp: int, seed: int, timings: dict, sun: bool = False):
        """The diffuse background at ``spp``: over the tiles covering the projected scene (or the
        full frame), zeros elsewhere; float64 (H, W) (float32 with the closed-form environment), the
        box ``(y0, y1, x0, x1)`` that holds it (None when ``spp == 0``: zeros) and whether the
        environment was taken in closed form. ``sun``: the sun's scene, over the full frame when the
        sun's disk or the Earth is in view (the tiles cover the target only): with the Earth, the
        pixels outside the tiles see only the environment and take it in closed form
        (:meth:`_environment`); with the sun's disk alone the full frame is path traced."""

        H, W = self.camera.height, self.camera.width
        if spp <= 0:
            return np.zeros((H, W)), None, False
        t0 = time.perf_counter()
        key = "sun_" if sun else "background_"
        scene, full, tile_sensors = ((self._sun["scene"], self._sun["full"], self._sun["tiles"]) if sun else
                                     (self.scene, self._sensor_full, self._sensor_tiles))
        tiles = background_tiles(self.camera, self._scene_corners, R, t, T, TILE_COUNTS)
        box = None
        closed_form = bool(sun and tiles is not None and self._earth_in_view(R))
        if closed_form:
            # the Earth in view: every pixel's environment in closed form, the scene's tiles traced over it
            rad = self._environment(R, t)  # float32
            timings[key + "environment"] = "closed form"
            box = (0, H, 0, W)
        elif tiles is None or (sun and self._sun_in_view(R)):
            rad = self._radiance(full, spp, seed, scene)
            timings[key + "tiles"] = "full frame"
            timings[key + "s"] = time.perf_counter() - t0
            return rad, (0, H, 0, W), False
        else:
            rad = np.zeros((H, W))
        if len(tiles) == 0:  # nothing of the scene projects into the image
            timings[key + "tiles"] = 0
        else:
            n = next(c for c in sorted(tile_sensors) if c >= len(tiles))
            org = np.concatenate([tiles, np.repeat(tiles[-1:], n - len(tiles), axis=0)])
            sensor = tile_sensors[n]
            sensor.set_windows(org, T)
            mosaic = self._radiance(sensor, spp, seed, scene)
            for k, (x0, y0) in enumerate(tiles):
                rad[y0:y0 + T, x0:x0 + T] = mosaic[k * T:(k + 1) * T, :][: H - y0, : W - x0]
            timings[key + "tiles"] = int(len(tiles))
            if box is None:
                box = _union_box([(int(y0), min(H, int(y0) + T), int(x0), min(W, int(x0) + T)) for x0, y0 in tiles])
        timings[key + "s"] = time.perf_counter() - t0
        return rad, box, closed_form

    def _earth_in_view(self, R) -> bool:
        """Whether the Earth projects into the image at this attitude."""
        o = self.options
        return o.earth_direction_target is not None and earth_in_image(self.camera, R, o.earth_direction_target,
                                                                       o.altitude_m)

    def _environment(self, R, t) -> np.ndarray:
        """The natural-light pass's environment (the Earth, the sun's disk) in every pixel, in closed
        form (:mod:`svgs_sim.render.environment`), float32 (H, W)."""
        o = self.options
        if self._env_grid is None:
            self._env_grid = EnvironmentGrid(self.camera)
        light = self._sun["light"]
        earth = dict(earth_direction=o.earth_direction_target, sun_direction=o.sun_direction_target,
                     altitude_m=o.altitude_m, albedo=o.earth_albedo, sun_irradiance_w_m2=light["irradiance_w_m2"],
                     uniform_radiance_w_m2_sr=o.earth_uniform_radiance_w_m2_sr)
        sun = None if o.eclipsed or o.sun_direction_target is None else {
            "direction": o.sun_direction_target, "radiance_w_m2_sr": light["radiance_w_m2_sr"]}
        return environment_radiance(self._env_grid, R, t, earth=earth, sun=sun)

    def _sun_in_view(self, R) -> bool:
        """Whether the sun's disk (or its edge) or the Earth projects into the image at this attitude
        (the natural-light pass then covers the full frame)."""
        o = self.options
        if o.sun_direction_target is not None and not o.eclipsed and sun_in_image(self.camera, R, o.sun_direction_target,
                                                                                  margin_px=2.0):
            return True
        if o.earth_direction_target is not None:
            return earth_in_image(self.camera, R, o.earth_direction_target, o.altitude_m)
        return False

    def _render_windows(self, rad, spots, roi_spp: int, seed: int, timings: dict):
        """Render the window around every spot (one mosaic pass) into ``rad`` (in place; where
        windows overlap, their mean). Returns the windows' records for the truth and the box
        ``(y0, y1, x0, x1)`` that holds them."""
        H, W = self.camera.height, self.camera.width
        t0 = time.perf_counter()
        win = spot_windows(spots, self.roi_size_px, W, H)
        w = self.roi_size_px
        self._sensor_roi.set_windows(win, w)
        mosaic = self._radiance(self._sensor_roi, roi_spp, seed)
        box = _union_box([(int(y0), min(H, int(y0) + w), int(x0), min(W, int(x0) + w)) for x0, y0 in win])
        by0, by1, bx0, bx1 = box
        acc = np.zeros((by1 - by0, bx1 - bx0))  # over the windows' box only
        cnt = np.zeros((by1 - by0, bx1 - bx0))
        rois = []
        for k, (x0, y0) in enumerate(win):
            acc[y0 - by0:y0 - by0 + w, x0 - bx0:x0 - bx0 + w] += mosaic[k * w:(k + 1) * w, :]
            cnt[y0 - by0:y0 - by0 + w, x0 - bx0:x0 - bx0 + w] += 1
            rois.append({"target": int(self.pattern.ids[k]), "x0": int(x0), "y0": int(y0), "width": w, "height": w})
        m = cnt > 0
        rad[by0:by1, bx0:bx1][m] = acc[m] / cnt[m]
        timings["roi_s"] = time.perf_counter() - t0
        return rois, box

    # ------------------------------------------------------------------ rendering
    def render(self, R_cam_target, t_cam_target_m, *, seed: int = 0, spp: int | None = None,
               roi_spp: int | None = None, full_frame: bool = False, check_fov: bool = True) -> RenderResult:
        """Render one frame at a pose.

        Parameters
        ----------
        R_cam_target : array_like, shape (3, 3)
        t_cam_target_m : array_like, shape (3,)
            ``p_cam = R_cam_target @ p_target + t_cam_target_m`` (OpenCV camera frame).
        seed : int
            Seed of the low-discrepancy sampler (each pass gets its own, derived with
            ``numpy.random.SeedSequence``).
        spp, roi_spp : int, optional
            Override the renderer's defaults for this frame.
        full_frame : bool
            Render the whole frame at ``spp`` and no windows.
        check_fov : bool
            Refuse a pose with no target in the image (default). False lets scenes
            without targets in view render (calibration plates in tests).

        Returns
        -------
        RenderResult

        Raises
        ------
        InputError
            Not a rotation, a target point behind (or in the plane of) the lens, or no
            target inside the image.
        """
        R, t = check_pose(R_cam_target, t_cam_target_m)
        seed = int(check_finite(seed, "seed"))
        spp = self.spp if spp is None else check_spp(spp, "spp", allow_zero=not full_frame)
        roi_spp = self.roi_spp if roi_spp is None else check_spp(roi_spp, "roi_spp")
        targets_px, visible = self._project_targets(R, t, check_fov)
        timings = {}
        t0 = time.perf_counter()
        self._set_pose(R, t)
        spots = self.predicted_spots_px(R, t)
        timings["setup_s"] = time.perf_counter() - t0
        rois = []
        H, W = self.camera.height, self.camera.width
        if full_frame:
            t0 = time.perf_counter()
            rad = self._radiance(self._sensor_full, spp, seed)
            timings["full_frame_s"] = time.perf_counter() - t0
            lit = [(0, H, 0, W)]
        else:
            rad, bg_box, _ = self._background(R, t, spp, seed, timings)
            rois, win_box = self._render_windows(rad, spots, roi_spp, seed + 0x9E3779B1, timings)
            lit = [b for b in (bg_box, win_box) if b is not None]
        # the light lies in these boxes, zeros elsewhere: the conversions below work on the box
        # holding them all (the same numbers as over the whole frame)
        strategies = []
        points = None
        factor = self.flux_factor()
        flux_diffuse = None
        if self.spots is not None:
            strategies, points, flux_diffuse = self._add_spots(R, t, rad, lit, factor, seed, timings)
        t0 = time.perf_counter()
        sl = _box_slices(_union_box(lit)) if lit else None
        flux = _times_factor(rad, factor, sl)
        radiance = np.zeros((H, W), np.float32)
        if sl is not None:
            radiance[sl] = rad[sl]
        timings["convert_s"] = time.perf_counter() - t0
        flux_sun = None
        if self._sun is not None:
            flux_sun, sun_rad = self._sun_flux(R, t, max(spp, 1), seed, factor, timings)
            flux += flux_sun
            radiance += sun_rad
            if flux_diffuse is not None:
                flux_diffuse = flux_diffuse + flux_sun
        truth = self.truth(R, t, targets_px, visible, spots, seed=seed, spp=spp, roi_spp=roi_spp,
                           full_frame=full_frame, rois=rois, timings=timings, strategies=strategies)
        o = self.options
        if self._sun is not None and o.sun_direction_target is not None:
            truth["sun"] = {"direction_target": list(o.sun_direction_target), "eclipsed": o.eclipsed,
                            "in_view": (not o.eclipsed) and sun_in_image(self.camera, R, o.sun_direction_target, 2.0),
                            **self._sun["light"]}
        if o.earth_direction_target is not None:
            truth["earth"] = {"direction_target": list(o.earth_direction_target), "altitude_m": o.altitude_m,
                              "albedo": o.earth_albedo, "half_angle_deg": earth_half_angle_deg(o.altitude_m),
                              "in_view": earth_in_image(self.camera, R, o.earth_direction_target, o.altitude_m),
                              "shadow_model": "cylindrical, umbra only (svgs_sim.render.earth)"}
        spectra = None if flux_sun is None else photon_spectra(self.optics.band_nm, self.flash.spectrum)
        return RenderResult(flux=flux, truth=truth, radiance=radiance, timings_s=timings,
                            flux_diffuse=flux_diffuse, points=points, flux_sun=flux_sun, natural_spectra=spectra)

    def _sun_flux(self, R, t, spp: int, seed: int, factor, timings: dict):
        """The sun's flux (photons/s per pixel, float32 (H, W); the flash's radiance-to-photon
        factor times the ratio of the flash's mean photon energy to the sun's) and radiance."""
        rad, box, closed_form = self._background(R, t, spp, seed + 0x2545F491, timings, sun=True)
        ratio = self.flash.photometry["mean_photon_energy_j"] / self._sun["light"]["mean_photon_energy_j"]
        if closed_form:  # the Earth in view: single precision, one pass
            if self._sun_factor32 is None or self._sun_factor32[0] is not factor or self._sun_factor32[1] != ratio:
                self._sun_factor32 = (factor, ratio, (factor * ratio).astype(np.float32))
            return rad * self._sun_factor32[2], rad
        flux = np.zeros((self.camera.height, self.camera.width), np.float32)
        if box is not None:
            sl = _box_slices(box)
            flux[sl] = (rad[sl] * factor[sl] * ratio).astype(np.float32)
        return flux, rad.astype(np.float32)

    def _add_spots(self, R, t, rad, lit: list, factor, seed: int, timings: dict):
        """Add the guided spot estimator's image to ``rad`` (in place) and box it in ``lit``.

        Parameters
        ----------
        R : ndarray, shape (3, 3)
        t : ndarray, shape (3,)
            ``R_cam_target``, ``t_cam_target_m``.
        rad : ndarray, float32, shape (H, W)
            The diffuse radiance; the spots' radiance is added in place.
        lit : list of (int, int, int, int)
            Boxes ``(y0, y1, x0, x1)`` holding the light; the spots' box is appended.
        factor : ndarray, shape (H, W)
            Radiance -> flux factor per pixel (:meth:`flux_factor`).
        seed : int
            The frame's seed.
        timings : dict
            ``spots_s`` is set, s.

        Returns
        -------
        strategies : list
            The spot estimator's strategies.
        points : PointFlux
            The spot samples and their flux.
        flux_diffuse : ndarray, shape (H, W)
            The flux of the diffuse radiance alone (before the spots were added).
        """
        H, W = self.camera.height, self.camera.width
        t0 = time.perf_counter()
        spot_img, strategies, (su, sv, sval) = self._spot_image(R, t, seed + _SPOT_SEED_OFFSET)
        sl = _box_slices(_union_box(lit)) if lit else None
        flux_diffuse = _times_factor(rad, factor, sl)
        if len(su):
            ui, vi = _sample_pixels(su, sv)
            # one pixel more each side: the estimator bins in float32 (a sample at a pixel
            # border may land one pixel over from this float64 rounding)
            sbox = (max(0, int(vi.min()) - 1), min(H, int(vi.max()) + 2), max(0, int(ui.min()) - 1),
                    min(W, int(ui.max()) + 2))
            ss = _box_slices(sbox)
            rad[ss] += spot_img[ss]
            lit.append(sbox)
            points = PointFlux(su, sv, sval * factor[vi, ui])
        else:
            points = PointFlux(su, sv, sval)
        timings["spots_s"] = time.perf_counter() - t0
        return strategies, points, flux_diffuse

    # ------------------------------------------------------------------ truth
    def truth(self, R, t, targets_px, visible, spots, **render_info) -> dict:
        """The ground-truth record of a frame (JSON-serialisable; :func:`svgs_sim.render.truth.svgs_frame_truth`)."""

        return svgs_frame_truth(self, R, t, targets_px, visible, spots, **render_info)


#: Added to a frame's seed for its spot estimator's samples (:meth:`Renderer.render`, :meth:`Renderer.spot_flux`).
_SPOT_SEED_OFFSET = 0x5BD1E995


def _sample_pixels(su, sv):
    """The pixel (column ``ui``, row ``vi``; int64 arrays) each spot sample falls in, rounded in float64."""
    return np.floor(su + 0.5).astype(np.int64), np.floor(sv + 0.5).astype(np.int64)


def _full_frame_factor(camera, optics, mean_photon_energy_j: float) -> np.ndarray:
    """Photons/s per pixel per unit radiance over the whole frame (read-only), kept per camera
    geometry, aperture and photon energy: under a distorted lens it costs seconds (the distortion's
    Jacobian at 5-8 Mpx), and the renderers of a sweep's focus distances share it."""
    key = (json.dumps(camera.to_dict(), sort_keys=True, default=str), float(optics.aperture_area_m2),
           float(mean_photon_energy_j))
    hit = _FACTORS.get(key)
    if hit is None:
        hit = radiance_to_photon_rate(camera, optics, mean_photon_energy_j, pixel_normalized_grid(camera))
        hit.setflags(write=False)
        if len(_FACTORS) >= 4:
            _FACTORS.clear()
        _FACTORS[key] = hit
    return hit


_FACTORS: dict = {}


def _union_box(boxes):
    """The smallest box ``(y0, y1, x0, x1)`` holding all of ``boxes`` (a non-empty list)."""
    return (min(b[0] for b in boxes), max(b[1] for b in boxes), min(b[2] for b in boxes), max(b[3] for b in boxes))


def _box_slices(box):
    y0, y1, x0, x1 = box
    return (slice(y0, y1), slice(x0, x1))


def _times_factor(rad, factor, sl):
    """``(rad * factor)`` as float32 (H, W), computed over the slices ``sl`` that hold all of
    ``rad``'s light (None: none), zeros elsewhere."""
    out = np.zeros(rad.shape, np.float32)
    if sl is not None:
        out[sl] = rad[sl] * factor[sl]
    return out


_CACHE: dict = {}


def render_flux(camera, pattern, R_cam_target, t_cam_target_m, *, spp: int = DEFAULT_SPP,
                roi_spp: int | None = None, roi_size_px: int = DEFAULT_ROI_SIZE_PX, seed: int = 0,
                full_frame: bool = False, reflector=None, scene_options=None, spot_samples: int = DEFAULT_SPOT_SAMPLES,
                method: str = "guided", spot_sampler: str = DEFAULT_SPOT_SAMPLER) -> RenderResult:
    """Render the photon flux of one frame (see :class:`Renderer` for the parameters).

    A renderer per (camera, pattern, reflector, options, window size) is cached, so a
    loop of calls reuses the loaded scene and compiled kernels.
    """

    cam = load_camera(camera)
    pat = load_pattern(pattern)
    refl = Reflector.resolve(reflector, pat)
    opts = SceneOptions.resolve(scene_options)
    # the focus distance is not part of the scene: a renderer is refocused, not rebuilt
    key = json.dumps([cam.to_dict(), pat.name, pat.points_m.tolist(), refl.to_json(),
                      replace(opts, focus_distance_m=None).to_json(), int(roi_size_px), method, int(spot_samples),
                      spot_sampler], sort_keys=True, default=str)
    r = _CACHE.get(key)
    if r is None:
        r = Renderer(cam, pat, reflector=refl, scene_options=opts, roi_size_px=roi_size_px, spp=spp, roi_spp=roi_spp,
                     spot_samples=spot_samples, method=method, spot_sampler=spot_sampler)
        _CACHE.clear()  # one scene at a time: they hold a lot of memory
        _CACHE[key] = r
    elif r.options.focus_distance_m != opts.focus_distance_m:
        focus = opts.focus_distance_m
        r.set_focus_distance(Optics.from_camera(cam).focus_distance_m if focus is None else focus)
        r.options = replace(r.options, focus_distance_m=focus)  # as asked (None: the profile's)
    return r.render(R_cam_target, t_cam_target_m, seed=seed, spp=spp, roi_spp=roi_spp, full_frame=full_frame)

