"""The ToF camera rendered with Mitsuba: per-sample path lengths -> per-pixel AMCW phasors.

:class:`TofRenderer` loads the marker scene (:mod:`svgs_sim.render.tof.scene`) once and renders a pose
into a :class:`svgs_sim.camera.amcw.RenderedTof` (noise-free per-pixel means, numpy);
:class:`svgs_sim.camera.amcw.TofSensor` then draws noisy tap frames from it (render once, many frames).

Camera (``assets/cameras/tof-epc660.toml``)
    EPC660 320 x 240, 6.5 mm lens: the OpenCV camera of the profile, exactly (rays from
    :class:`svgs_sim.render.sensor.CameraModel`, the same film -> ray map as the SVGS renderer), a thin
    lens of the profile's f-number focused at ``[optics] focus_distance_m`` (``pinhole=True``
    drops the defocus; the radiometry keeps the real aperture).

Illumination
    ``n_emitters`` small Lambertian-disk emitters (``emitter_diameter_m``) on a ring of
    ``ring_radius_m`` around the lens, facing the boresight, each with radiant intensity
    ``I(theta) = I0 cos^m theta``: ``m`` from the divergence (half intensity at half the full
    angle; 90 deg -> m = 2), ``I0 = duty * I_e`` with the emitter's on-axis intensity ``I_e``
    (``radiant_intensity_w_sr``, else ``flux * (m + 1) / (2 pi)``). Not in the Mitsuba
    scene: sampled explicitly (next-event estimation with a shadow ray), so the light has its
    real size and position and casts real (soft) shadows, and camera rays never see it.

Integrator (custom, wavefront, Dr.Jit)
    Per sample: a camera ray through a point of the pixel and of the aperture; at the first
    hit, one point of one emitter (chosen uniformly; shadow ray) gives the return
    ``L = f cos / r^2 * n I(theta)``; its optical path length is ``opl = |x - lens centre| + |x - emitter point|`` (Fermat: the path through the lens to the
    pixel is the chief ray's). The sample adds ``L``, ``L cos(2 pi f opl / c)`` and
    ``L sin(...)`` to its pixel, so a pixel straddling a depth edge returns the phasor sum of
    both surfaces (flying pixel) and, with ``max_bounces > 1`` (BSDF-sampled bounces, each with
    next-event estimation and its accumulated path length), multipath returns too. The same
    BSDF-sampled ray gives the ambient term (uniform sky of unit radiance, occlusion included).
    ``dr.block_sum`` reduces the samples of each pixel; passes are summed in float64.

Sampling (``sampler``)
    ``"sobol"`` (default): the film point, the aperture point, the emitter's index and the point
    on its disk (seven dimensions) are one Owen-scrambled Sobol' point per sample, one sequence
    per pixel and seed (:mod:`svgs_sim.render.tof.sobol`); the ambient ray and later bounces draw from a
    PCG32 stream per lane. ``"r2"`` (the estimator before issue 23): the film point from a
    Cranley-Patterson rotated R2 sequence per pixel, everything else from PCG32. Both are
    unbiased estimators of the same pixel integrals; they differ only in noise. Measured
    (issue 23, docs/tof.md): with ``"r2"`` the render noise on the marker pixels was dominated by the aperture point drawn independently of the film point at
    5.7 m (the lens blurs a 2-4 px marker over ~1.5 px) and by the emitter choice at 0.7 m
    (the retroreflector's return falls with the observation angle, which the emitter and the
    aperture point set).

Sample allocation
    Every pixel of the traced box gets ``spp`` samples; the pixels within the defocus blur
    radius + 0.71 px + :data:`RIM_MARGIN_PX` of a marker face's projected rim (where the
    pixel integral has a jump: most of the noise) get ``spp * rim_spp_factor``, continuing
    the same per-pixel sequence. The band is chosen from the pose and the geometry only, never
    from rendered values, so every pixel's estimate stays unbiased.

Only the box of pixels that can see the target (plate, markers, distractors) is traced; the
rest of the frame returns nothing (no background, ``background_factor`` of ambient).
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass

import numpy as np

from svgs_sim.assets import package_relative
from svgs_sim.base.constants import PLANCK_J_S, SPEED_OF_LIGHT_M_S
from svgs_sim.base.errors import InputError, ProfileError, check_finite, check_finite_positive
from svgs_sim.base.profile_schema import TOF_CAMERA_TABLES, check_table
from svgs_sim.camera.amcw import RenderedTof, unambiguous_range_m
from svgs_sim.render.optics import pixel_normalized_grid, radiance_to_photon_rate
from svgs_sim.render.sampling import check_spp, to_numpy
from svgs_sim.render.sensor import CameraModel
from svgs_sim.render.variant import select_variant
from svgs_sim.svgs.frames import check_pose, pose_to_state, state_dict
from svgs_sim.tof.camera import DEFAULT_CAMERA, DEFAULT_PATTERN, load_camera, load_target

from .scene import TofSceneOptions, build_tof_scene
from .sobol import sobol_owen

#: Default samples per pixel of the traced window (power of two).
DEFAULT_SPP = 256
#: Default factor on ``spp`` for the pixels on the marker faces' rims (:meth:`TofRenderer.rim_mask`):
#: with the ``"sobol"`` sampler, 256 x 64 = 16384 samples there keep the render noise at most a
#: third of the sensor's single-frame noise at 5.712 m, per marker pixel and in the pose of a
#: noise-free frame (issue 23; ``tools/tof_render_noise.py``, docs/tof.md).
DEFAULT_RIM_SPP_FACTOR = 64
#: Rim band half-width beyond the defocus blur and the pixel's half diagonal, px.
RIM_MARGIN_PX = 0.5
#: Sample generators of :class:`TofRenderer` (see the module docstring).
SAMPLERS = ("sobol", "r2")
#: What a modulation frequency may be: the profile's ``[tof] modulation_frequency_hz`` entry.
MODULATION_FREQUENCY_HZ = TOF_CAMERA_TABLES["tof"]["modulation_frequency_hz"]
#: Dimensions of the per-pixel Sobol' point: film u, v; aperture u, v; emitter index; emitter disk u, v.
SOBOL_DIMS = (0, 1, 2, 3, 4, 5, 6)
#: Most samples traced in one pass (memory: six float32 channels and the wavefront state per lane).
MAX_LANES_PER_PASS = 1 << 22
#: R2 low-discrepancy sequence (Roberts 2018): 1/g, 1/g^2 with g the plastic number, as 0.32 fixed point.
_G = 1.32471795724474602596
R2_STEP_U32 = (int(round(2**32 / _G)) & 0xFFFFFFFF, int(round(2**32 / _G**2)) & 0xFFFFFFFF)


@dataclass(frozen=True)
class Illumination:
    """The ToF light source: ``n_emitters`` disks on a ring around the lens.

    Attributes
    ----------
    n_emitters : int
    radiant_flux_per_emitter_w : float
        Optical flux of one emitter while on, W (used when ``radiant_intensity_w_sr`` is None).
    radiant_intensity_w_sr : float or None
        On-axis radiant intensity of one emitter while on, W/sr (a datasheet's I_e); when
        given it sets the intensity and the flux follows from the ``cos^m`` profile.
    duty_cycle : float
        Mean / peak optical power of the modulated drive (square wave: 0.5).
    divergence_full_angle_deg : float
        Full angle at half intensity.
    ring_radius_m : float
        Distance of the emitter centres from the lens axis (0: all at the lens centre).
    emitter_diameter_m : float
        Diameter of each emitting disk (the source size that softens shadows).
    offset_from_lens_m : tuple of float
        Centre of the ring in the camera frame (OpenCV axes), m.
    """

    n_emitters: int = 8
    radiant_flux_per_emitter_w: float = 1.0
    duty_cycle: float = 0.5
    divergence_full_angle_deg: float = 90.0
    ring_radius_m: float = 0.016
    emitter_diameter_m: float = 0.002
    offset_from_lens_m: tuple = (0.0, 0.0, 0.0)
    radiant_intensity_w_sr: float | None = None

    def __post_init__(self):
        """Check every field with the profile's ``[illumination]`` entry of the same name
        (:data:`svgs_sim.base.profile_schema.TOF_CAMERA_TABLES`); ``offset_from_lens_m`` becomes a tuple."""
        given = {f: getattr(self, f) for f in self.__dataclass_fields__}
        if given["radiant_intensity_w_sr"] is None:
            del given["radiant_intensity_w_sr"]
        for k, v in check_table("illumination", given).items():
            object.__setattr__(self, k, v)

    @classmethod
    def from_camera(cls, camera, **overrides) -> "Illumination":
        """From the profile's ``[illumination]`` table (missing keys: class defaults)."""
        t = camera.illumination.to_dict()
        names = set(cls.__dataclass_fields__)
        kw = {k: v for k, v in t.items() if k in names}
        for k, v in overrides.items():
            if k not in names:
                raise InputError(f"illumination: unknown parameter {k!r}; known {sorted(names)}")
            if v is not None:
                kw[k] = v
        try:
            return cls(**kw)
        except InputError as exc:
            if overrides:
                raise
            raise ProfileError(f"camera {camera.name!r}: {exc}") from None

    @property
    def cos_exponent(self) -> float:
        """``m`` of ``I0 cos^m``: half intensity at half the full divergence angle."""
        return float(np.log(0.5) / np.log(np.cos(np.radians(0.5 * self.divergence_full_angle_deg))))

    @property
    def peak_intensity_w_sr(self) -> float:
        """On-axis radiant intensity of one emitter while on: ``radiant_intensity_w_sr``, else
        ``flux (m + 1) / (2 pi)``."""
        if self.radiant_intensity_w_sr is not None:
            return float(self.radiant_intensity_w_sr)
        return self.radiant_flux_per_emitter_w * (self.cos_exponent + 1) / (2 * np.pi)

    @property
    def intensity_w_sr(self) -> float:
        """Mean (time-averaged) on-axis radiant intensity of one emitter, ``duty * peak``."""
        return self.duty_cycle * self.peak_intensity_w_sr

    def positions_cam_m(self) -> np.ndarray:
        """Emitter centres in the camera frame, shape (n, 3)."""
        n = int(self.n_emitters)
        a = 2 * np.pi * (np.arange(n) + 0.5) / n
        ring = self.ring_radius_m * np.stack([np.cos(a), np.sin(a), np.zeros(n)], 1)
        return ring + np.asarray(self.offset_from_lens_m)

    def to_json(self) -> dict:
        d = asdict(self)
        d.update(offset_from_lens_m=list(self.offset_from_lens_m), cos_exponent=self.cos_exponent,
                 intensity_w_sr_per_emitter=self.intensity_w_sr, peak_intensity_w_sr=self.peak_intensity_w_sr)
        return d


@dataclass(frozen=True)
class TofOptics:
    """Thin lens and wavelength of the ToF camera (``[optics]``, ``[tof]``)."""

    focal_length_m: float = 0.0065
    f_number: float = 1.2
    focus_distance_m: float = 1.0
    wavelength_m: float = 850e-9

    @property
    def aperture_radius_m(self) -> float:
        return self.focal_length_m / (2.0 * self.f_number)

    @property
    def aperture_area_m2(self) -> float:
        return float(np.pi * self.aperture_radius_m**2)

    @property
    def photon_energy_j(self) -> float:
        return PLANCK_J_S * SPEED_OF_LIGHT_M_S / self.wavelength_m

    @classmethod
    def from_camera(cls, camera) -> "TofOptics":
        """The lens of ``[optics]`` and the wavelength of ``[tof]`` (missing keys: class defaults),
        checked by the profile's own entries (:mod:`svgs_sim.base.profile_schema`)."""
        o = camera.optics.to_dict()
        t = camera.tof.to_dict()
        try:
            lens = check_table("optics", {k: o[k] for k in ("focal_length_m", "f_number", "focus_distance_m") if k in o})
            light = check_table("tof", {k: t[k] for k in ("wavelength_m",) if k in t})
        except InputError as exc:
            raise ProfileError(f"camera {camera.name!r}: {exc}") from None
        return cls(**lens, **light)

    def to_json(self) -> dict:
        d = asdict(self)
        d.update(aperture_radius_m=self.aperture_radius_m, aperture_area_m2=self.aperture_area_m2)
        return d


def marker_truth(camera, target, R, t) -> dict:
    """Projected marker face centres (the centroid truth), visibility and ranges.

    Returns
    -------
    dict
        ``centres_cam_m`` (N, 3), ``centres_px`` (N, 2) (NaN behind the lens), ``in_image`` (N,)
        bool, ``slant_range_m`` (N,): the radial distance of each face centre from the lens, m.
    """
    c = np.asarray(target.points_m, float) @ np.asarray(R, float).T + np.asarray(t, float)
    front = c[:, 2] > 1e-9
    uv = np.full((c.shape[0], 2), np.nan)
    if np.any(front):
        uv[front] = camera.project(c[front])
    vis = front & camera.in_image(np.nan_to_num(uv, nan=-1e9), 0.5)
    return {"centres_cam_m": c, "centres_px": uv, "in_image": vis, "slant_range_m": np.linalg.norm(c, axis=1)}


def check_target_in_view(camera, target, R, t) -> dict:
    """:func:`marker_truth`, raising :class:`InputError` when a marker lies behind the lens or
    no marker projects inside the image (the target is outside the field of view)."""
    m = marker_truth(camera, target, R, t)
    z = m["centres_cam_m"][:, 2]
    if np.any(z <= 0):
        bad = [int(i) for i, zz in zip(target.ids, z) if zz <= 0]
        raise InputError(f"pose: marker(s) {bad} lie behind the camera (t_cam_target_m = {np.round(t, 4).tolist()}); "
                         "the range must be positive and the target in front of the lens")
    if not np.any(m["in_image"]):
        raise InputError(f"pose: no marker projects inside the {camera.width}x{camera.height} image (markers at "
                         f"{np.round(m['centres_px'], 1).tolist()} px); the target is outside the field of view")
    return m


def _passes(n_pixels: int, j0: int, n_samples: int) -> list:
    """Split samples ``j0 .. j0 + n_samples - 1`` of ``n_pixels`` pixels into passes of at most
    :data:`MAX_LANES_PER_PASS` lanes each: list of ``(first, count)``."""
    cap = 1 << max(0, (MAX_LANES_PER_PASS // max(1, n_pixels)).bit_length() - 1)
    per = max(1, min(n_samples, cap))
    return [(j, min(per, j0 + n_samples - j)) for j in range(j0, j0 + n_samples, per)]


def _next_2d(mi, rng):
    """Two floats from a lane's PCG32 stream as an mi.Point2f."""
    return mi.Point2f(rng.next_float32(), rng.next_float32())


def _mean_channel(s):
    """A BSDF value or weight as one number: itself (mono) or the mean of three channels."""
    return s[0] if len(s) == 1 else (s[0] + s[1] + s[2]) / 3.0


class TofRenderer:
    """A loaded ToF scene (camera profile + marker target + options).

    Parameters
    ----------
    camera : str, Path or svgs.Camera
        ToF camera profile (default ``tof-epc660``).
    target : str, Path or tof.MarkerTarget
        Marker target (default ``tof-8``).
    scene_options : None, dict or svgs_sim.render.tof.scene.TofSceneOptions
    spp : int or None
        Default samples per pixel (rounded up to a power of two; None: :data:`DEFAULT_SPP`).
    rim_spp_factor : int or None
        Default factor on ``spp`` for the pixels on the marker rims (rounded up to a power of
        two; None: :data:`DEFAULT_RIM_SPP_FACTOR`; 1: every pixel gets ``spp``).
    max_bounces : int
        1: direct returns only (default); 2-4: also multipath via diffuse inter-reflections.
    modulation_frequency_hz : float, optional
        Default: the profile's ``[tof] modulation_frequency_hz``.
    pinhole : bool
        Trace through the lens centre only (no defocus).
    illumination : dict, optional
        Overrides of :class:`Illumination` fields.
    background_factor : float
        Ambient radiance (per unit sky radiance) of pixels that see no geometry; 0 = space.
    variant : str, optional
        Passed to :func:`svgs_sim.render.variant.select_variant` (a JIT variant is needed).
    sampler : {"sobol", "r2"}
        Sample generator (module docstring): ``"sobol"`` (default) or the earlier, noisier ``"r2"``.

    Raises
    ------
    InputError
        Unknown profile, bad options, or no JIT variant of Mitsuba.
    """

    def __init__(self, camera=DEFAULT_CAMERA, target=DEFAULT_PATTERN, *, scene_options=None, spp: int | None = DEFAULT_SPP,
                 max_bounces: int = 1, modulation_frequency_hz: float | None = None, pinhole: bool = False,
                 illumination: dict | None = None, background_factor: float = 0.0, variant: str | None = None,
                 sampler: str = "sobol", rim_spp_factor: int | None = DEFAULT_RIM_SPP_FACTOR):


        self.camera = camera if hasattr(camera, "fx") else load_camera(camera, render=True)
        self.target = load_target(target)
        self.options = TofSceneOptions.resolve(scene_options)
        self.optics = TofOptics.from_camera(self.camera)
        self.illumination = Illumination.from_camera(self.camera, **(illumination or {}))
        f = modulation_frequency_hz
        if f is None:
            f = self.camera.tof.given("modulation_frequency_hz", 10.0e6)
        self.modulation_frequency_hz = MODULATION_FREQUENCY_HZ.check(f, "modulation_frequency_hz")
        self.spp = check_spp(DEFAULT_SPP if spp is None else spp, "spp", base=2)
        self.rim_spp_factor = check_spp(DEFAULT_RIM_SPP_FACTOR if rim_spp_factor is None else rim_spp_factor,
                                        "rim_spp_factor", base=2)
        if int(max_bounces) != max_bounces or not 1 <= max_bounces <= 4:
            raise InputError(f"max_bounces: expected an integer 1..4, got {max_bounces!r}")
        self.max_bounces = int(max_bounces)
        self.pinhole = bool(pinhole)
        if sampler not in SAMPLERS:
            raise InputError(f"sampler: expected one of {list(SAMPLERS)}, got {sampler!r}")
        self.sampler = sampler
        self.background_factor = check_finite_positive(background_factor, "background_factor", allow_zero=True)
        self.variant = select_variant(variant)
        if self.variant.backend == "scalar":
            raise InputError(f"the ToF renderer needs Mitsuba's llvm or cuda variant, got {self.variant.name} "
                             f"({self.variant.notice or 'set SVGS_MI_VARIANT=llvm'})")
        import drjit as dr
        import mitsuba as mi


        self._mi, self._dr = mi, dr
        t0 = time.perf_counter()
        self.scene, self.geometry = build_tof_scene(self.target, self.options)
        self.model = CameraModel(self.camera, 0.0 if self.pinhole else self.optics.aperture_radius_m,
                                 self.optics.focus_distance_m)
        self.load_time_s = time.perf_counter() - t0
        self._photons = None

    # ------------------------------------------------------------------ geometry helpers
    def photons_per_radiance(self) -> np.ndarray:
        """Photons/s per pixel per W m^-2 sr^-1, shape (H, W) (aperture, pixel solid angle, cos^4)."""
        if self._photons is None:

            xy = pixel_normalized_grid(self.camera)
            self._photons = radiance_to_photon_rate(self.camera, self.optics, self.optics.photon_energy_j, xy)
        return self._photons

    def window(self, R, t, margin_px: int = 2) -> tuple:
        """Pixel box ``(x0, y0, w, h)`` that can see the scene geometry (full frame if a corner
        is behind the lens)."""
        W, H = self.camera.width, self.camera.height
        pts = [self.geometry.corners_m()]
        for dd in self.options.distractors:
            if dd["type"] == "sphere":
                p, r = np.asarray(dd["position_m"]), dd["radius_m"]
                lo, hi = p - r, p + r
            else:
                lo, hi = np.asarray(dd["lo_m"]), np.asarray(dd["hi_m"])
            pts.append(np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]))
        P = np.vstack(pts) @ R.T + t
        if np.any(P[:, 2] <= 1e-3) or self.camera.has_distortion:
            return (0, 0, W, H)
        uv = self.camera.project(P)
        x0 = int(np.clip(np.floor(uv[:, 0].min()) - margin_px, 0, W))
        x1 = int(np.clip(np.ceil(uv[:, 0].max()) + margin_px + 1, 0, W))
        y0 = int(np.clip(np.floor(uv[:, 1].min()) - margin_px, 0, H))
        y1 = int(np.clip(np.ceil(uv[:, 1].max()) + margin_px + 1, 0, H))
        return (x0, y0, max(0, x1 - x0), max(0, y1 - y0))

    def blur_radius_px(self, z_cam_m) -> np.ndarray:
        """Thin-lens defocus blur radius (circle of confusion), px, of points at depth ``z_cam_m``
        (array_like, m): ``fx r_aperture |1/focus - 1/z|`` (0 with ``pinhole=True``)."""
        z = np.asarray(z_cam_m, float)
        if self.pinhole:
            return np.zeros_like(z)
        return self.camera.fx * self.optics.aperture_radius_m * np.abs(1.0 / self.optics.focus_distance_m - 1.0 / z)

    def rim_mask(self, R, t) -> np.ndarray:
        """Pixels on the marker faces' rims: centre within ``blur + sqrt(2)/2 + RIM_MARGIN_PX`` of
        the projected rim circle of a face (the distance and the blur taken per rim point).

        Parameters
        ----------
        R : ndarray, shape (3, 3)
        t : ndarray, shape (3,)
            Pose ``p_cam = R p_target + t``.

        Returns
        -------
        ndarray of bool, shape (H, W)
            All False without markers.
        """
        W, H = self.camera.width, self.camera.height
        mask = np.zeros((H, W), bool)
        g = self.geometry
        if not self.options.markers or g.marker_centres_m.size == 0:
            return mask
        for c, rad in zip(np.asarray(g.marker_centres_m, float), np.asarray(g.marker_radius_m, float)):
            z_c = float((R @ c + t)[2])
            if z_c <= rad:
                continue
            n = int(min(1 << 16, max(64, np.ceil(4 * 2 * np.pi * rad * self.camera.fx / (z_c - rad)))))  # <= 0.25 px apart
            th = 2 * np.pi * np.arange(n) / n
            P = (c + rad * np.stack([np.cos(th), np.sin(th), np.zeros(n)], 1)) @ R.T + t
            P = P[P[:, 2] > 1e-6]
            if not len(P):
                continue
            uv = self.camera.project(P)
            reach = self.blur_radius_px(P[:, 2]) + 0.5 * np.sqrt(2.0) + RIM_MARGIN_PX
            ok = np.all(np.isfinite(uv), 1) & (uv[:, 0] > -reach - 1) & (uv[:, 0] < W + reach) & \
                (uv[:, 1] > -reach - 1) & (uv[:, 1] < H + reach)
            uv, reach = uv[ok], reach[ok]
            if not len(uv):
                continue
            r_max = int(np.ceil(reach.max()))
            base = np.round(uv).astype(int)
            for dy in range(-r_max, r_max + 1):
                for dx in range(-r_max, r_max + 1):
                    px, py = base[:, 0] + dx, base[:, 1] + dy
                    inside = (np.hypot(px - uv[:, 0], py - uv[:, 1]) <= reach) & (px >= 0) & (px < W) & (py >= 0) & (py < H)
                    mask[py[inside], px[inside]] = True
        return mask

    # ------------------------------------------------------------------ rendering
    def render(self, R_cam_target, t_cam_target_m, *, seed: int = 0, spp: int | None = None,
               window: tuple | None = None, modulation_frequency_hz: float | None = None,
               rim_spp_factor: int | None = None) -> RenderedTof:
        """Render the noise-free per-pixel means at one pose.

        Parameters
        ----------
        R_cam_target : array_like, shape (3, 3)
        t_cam_target_m : array_like, shape (3,)
            ``p_cam = R_cam_target @ p_target + t_cam_target_m`` (OpenCV camera frame).
        seed : int
            Seed of the sample positions (passes derive theirs with ``numpy.random.SeedSequence``).
        spp : int, optional
            Samples per pixel (power of two), default the renderer's.
        rim_spp_factor : int, optional
            Factor on ``spp`` for the pixels of :meth:`rim_mask` (power of two), default the renderer's.
        window : (x0, y0, w, h), optional
            Trace only this pixel box (default: the box that can see the target).
        modulation_frequency_hz : float, optional
            Make the phasors for this frequency instead of the renderer's.

        Returns
        -------
        RenderedTof

        Raises
        ------
        InputError
            Not a rotation; a marker behind the lens; no marker inside the image.
        """
        R, t = check_pose(R_cam_target, t_cam_target_m)
        seed = int(check_finite(seed, "seed"))
        spp = self.spp if spp is None else check_spp(spp, "spp", base=2)
        factor = self.rim_spp_factor if rim_spp_factor is None else check_spp(rim_spp_factor, "rim_spp_factor", base=2)
        f_mod = self.modulation_frequency_hz if modulation_frequency_hz is None else \
            MODULATION_FREQUENCY_HZ.check(modulation_frequency_hz, "modulation_frequency_hz")
        if self.options.markers:
            truth_m = check_target_in_view(self.camera, self.target, R, t)
        else:
            truth_m = marker_truth(self.camera, self.target, R, t)
        if t[2] <= 0:
            raise InputError(f"pose: the target origin lies behind the camera (t_cam_target_m = {t.tolist()})")
        W, H = self.camera.width, self.camera.height
        if window is None:
            win = self.window(R, t)
        else:
            try:
                win = tuple(int(v) for v in window)
            except (TypeError, ValueError):
                raise InputError(f"window: expected (x0, y0, w, h) pixels, got {window!r}") from None
            x0, y0, w, h = win
            if len(win) != 4 or x0 < 0 or y0 < 0 or w < 1 or h < 1 or x0 + w > W or y0 + h > H:
                raise InputError(f"window: expected a box inside the {W}x{H} image, got {window!r}")
        timings = {}
        x0, y0, w, h = win
        rim = self.rim_mask(R, t)[y0:y0 + h, x0:x0 + w] if factor > 1 else np.zeros((h, w), bool)
        t0 = time.perf_counter()
        sums = self._render_window(R, t, win, spp, seed, f_mod, rim, spp * factor)
        timings["trace_s"] = time.perf_counter() - t0
        n = np.where(rim, float(spp * factor), float(spp))
        active = np.zeros((H, W))
        phasor = np.zeros((H, W), complex)
        amb = np.full((H, W), float(self.background_factor))
        hit = np.zeros((H, W))
        rng1 = np.full((H, W), np.nan)
        sl = (slice(y0, y0 + h), slice(x0, x0 + w))
        if w > 0 and h > 0:
            active[sl] = sums["dc"] / n
            phasor[sl] = (sums["re"] + 1j * sums["im"]) / n
            amb[sl] = sums["amb"] / n
            hit[sl] = sums["hit"] / n
            with np.errstate(invalid="ignore", divide="ignore"):
                rng1[sl] = np.where(sums["hit"] > 0, sums["r1"] / np.maximum(sums["hit"], 1), np.nan)
        truth = self.truth(R, t, truth_m, seed=seed, spp=spp, window=win, timings=timings, f_mod=f_mod,
                           rim_spp=spp * factor, rim_pixels=int(rim.sum()))
        return RenderedTof(active_radiance=active, phasor_radiance=phasor, ambient_factor=amb,
                           photons_per_radiance=self.photons_per_radiance(), hit_fraction=hit, range_first_m=rng1,
                           modulation_frequency_hz=f_mod, truth=truth, timings_s=timings)

    def _render_window(self, R, t, win, spp, seed, f_mod, rim=None, rim_spp=None) -> dict:
        """Per-pixel sums over the window, shape (h, w) each: ``spp`` samples in every pixel,
        then samples ``spp .. rim_spp - 1`` of the same sequences in the pixels of ``rim``
        (bool, shape (h, w)). Passes: at most :data:`MAX_LANES_PER_PASS` lanes each."""
        x0, y0, w, h = win
        out = {k: np.zeros((h, w)) for k in ("dc", "re", "im", "amb", "hit", "r1")}
        if w == 0 or h == 0:
            return out
        self._set_pose(R, t)
        ys, xs = np.mgrid[y0:y0 + h, x0:x0 + w]
        box = _passes(w * h, 0, spp)
        # word 0 of SeedSequence(seed): the per-pixel sequences; words 1..: the box's passes' lane streams
        words = np.random.SeedSequence(seed).generate_state(len(box) + 1, dtype=np.uint32)
        seed_render = int(words[0])
        self._trace_pixels(xs.ravel(), ys.ravel(), box, words[1:], seed_render, f_mod, out, (slice(None), slice(None)))
        if rim is not None and rim_spp is not None and rim_spp > spp and np.any(rim):
            ry, rx = np.nonzero(rim)
            passes = _passes(rx.size, spp, rim_spp - spp)
            words = np.random.SeedSequence([seed, 1]).generate_state(len(passes), dtype=np.uint32)
            self._trace_pixels(rx + x0, ry + y0, passes, words, seed_render, f_mod, out, (ry, rx))
        return out

    def _trace_pixels(self, gx, gy, passes, pass_seeds, seed_render, f_mod, out, where):
        """Trace the pixels ``(gx, gy)`` (int arrays, shape (n,)) in ``passes`` (``(j0, count)``:
        samples ``j0 .. j0 + count - 1`` of each pixel's sequence, lane streams seeded by
        ``pass_seeds``) and add the per-pixel sums to ``out[name][where]``."""
        pix = (self._mi.UInt32(np.asarray(gx, np.uint32)), self._mi.UInt32(np.asarray(gy, np.uint32)))
        for (j0, count), s in zip(passes, pass_seeds):
            res = self._trace(pix, count, j0, int(s), seed_render, f_mod)
            for name, arr in res.items():
                out[name][where] += arr.reshape(out[name][where].shape)

    def _set_pose(self, R, t):
        mi, dr = self._mi, self._dr
        R_wc = R.T
        p_wc = -R.T @ t
        self.model.set_pose(R_wc, p_wc)
        em = self.illumination.positions_cam_m() @ R_wc.T + p_wc
        self._em = [mi.Float(em[:, i].tolist()) for i in range(3)]
        self._axes = [mi.Vector3f(*R_wc[:, i].tolist()) for i in range(3)]  # camera x, y, z in the world
        self._lens = mi.Point3f(*p_wc.tolist())
        dr.make_opaque(*self._em, *self._axes, self._lens)

    def _trace(self, pix, spp_pass: int, j0: int, seed_pass: int, seed_render: int, f_mod: float) -> dict:
        """One wavefront pass over the pixels ``pix`` (mi.UInt32 columns and rows): per-pixel
        sums of samples ``j0 .. j0 + spp_pass - 1`` (numpy float64, flat)."""
        mi, dr = self._mi, self._dr
        Float = mi.Float
        rng, ray, nee_sample = self._primary_rays(pix, spp_pass, j0, seed_pass, seed_render)
        si = self.scene.ray_intersect(ray)
        hit0 = si.is_valid()
        r_first = dr.select(hit0, dr.norm(si.p - self._lens), 0.0)

        k_phase = 2.0 * np.pi * f_mod / SPEED_OF_LIGHT_M_S
        ctx = mi.BSDFContext()
        dc = Float(0.0)
        re = Float(0.0)
        im = Float(0.0)
        amb = dr.select(hit0, Float(0.0), Float(self.background_factor))
        beta = Float(1.0)
        opl0 = r_first  # path length from the lens to the current vertex
        active = mi.Bool(hit0)
        for bounce in range(self.max_bounces):
            bsdf = si.bsdf()
            L, dist = self._emitter_return(si, bsdf, ctx, rng, active, beta, nee_sample if bounce == 0 else None)
            phase = k_phase * (opl0 + dist)
            dc += L
            re += L * dr.cos(phase)
            im += L * dr.sin(phase)
            # BSDF-sampled ray: ambient sky if it escapes, next vertex otherwise
            bs, wgt = bsdf.sample(ctx, si, rng.next_float32(), _next_2d(mi, rng), active)
            wgt = _mean_channel(wgt)
            ray2 = si.spawn_ray(si.to_world(bs.wo))
            ok = active & (wgt > 0.0)
            if bounce + 1 < self.max_bounces:
                si2 = self.scene.ray_intersect(ray2, ok)
                escaped = ok & ~si2.is_valid()
                amb += dr.select(escaped, beta * wgt, 0.0)
                opl0 = opl0 + dr.select(ok & si2.is_valid(), dr.norm(si2.p - si.p), 0.0)
                beta = beta * wgt
                active = ok & si2.is_valid()
                si = si2
            else:
                escaped = ok & ~self.scene.ray_test(ray2, ok)
                amb += dr.select(escaped, beta * wgt, 0.0)
        hitf = dr.select(hit0, Float(1.0), Float(0.0))
        chans = [dc, re, im, amb, hitf, r_first]
        dr.eval(*chans)
        sums = [dr.block_sum(c, spp_pass) for c in chans]
        dr.eval(*sums)
        names = ("dc", "re", "im", "amb", "hit", "r1")
        return {nm: to_numpy(s, np.float64) for nm, s in zip(names, sums)}

    def _primary_rays(self, pix, spp_pass: int, j0: int, seed_pass: int, seed_render: int):
        """The pass's camera rays, ``spp_pass`` per pixel of ``pix`` (pixel-major), the lanes'
        random streams and the samples of the first vertex's emitter.

        Each pixel's samples are numbered ``j = j0 + 0 .. spp_pass - 1``.
        ``sampler="sobol"``: the film point, aperture point, emitter index and emitter-disk
        point are the dimensions :data:`SOBOL_DIMS` of point ``j`` of an Owen-scrambled Sobol'
        sequence whose scramble seed hashes the pixel and ``seed_render`` (the same for every
        pass: the passes together are one net). ``sampler="r2"``: film points from a per-pixel
        R2 sequence (sample ``j``) with a per-pixel Cranley-Patterson shift from
        ``seed_render``; aperture, emitter and everything after from the lane's stream. The
        lane's PCG32 stream is seeded by ``seed_pass`` and the lane index.

        Returns
        -------
        rng : mi.PCG32
        ray : mi.Ray3f
        nee_sample : (mi.Float, mi.Point2f) or None
            Emitter-index and emitter-disk samples of the first vertex (None: draw from ``rng``).
        """
        mi, dr = self._mi, self._dr
        UInt32, UInt64, Float = mi.UInt32, mi.UInt64, mi.Float
        n = dr.width(pix[0]) * spp_pass
        idx = dr.arange(UInt32, n)
        sp = dr.opaque(UInt32, spp_pass)
        k_pix = idx // sp
        j = idx - k_pix * sp + dr.opaque(UInt32, j0)
        gx = dr.gather(UInt32, pix[0], k_pix)
        gy = dr.gather(UInt32, pix[1], k_pix)
        pid = gy * self.camera.width + gx
        rng = mi.PCG32()
        a, b = mi.sample_tea_32(idx, dr.opaque(UInt32, seed_pass), 4)
        rng.seed(UInt64(a) | (UInt64(b) << 32), UInt64(idx))
        if self.sampler == "sobol":
            seed_px, _ = mi.sample_tea_32(pid, dr.opaque(UInt32, seed_render), 8)
            q = sobol_owen(mi, dr, j, seed_px, SOBOL_DIMS)
            u = Float(gx) + q[0] - 0.5
            v = Float(gy) + q[1] - 0.5
            a_cam = mi.Vector3f(0.0) if self.pinhole else self.model.aperture_point(mi.Point2f(q[2], q[3]))
            return rng, self.model.ray(u, v, a_cam), (q[4], mi.Point2f(q[5], q[6]))
        # per-pixel Cranley-Patterson shift (same for all passes) of a per-pixel R2 sequence
        s0, s1 = mi.sample_tea_32(pid, dr.opaque(UInt32, seed_render), 8)
        fu = Float(j * R2_STEP_U32[0] + s0) * (2.0**-32)
        fv = Float(j * R2_STEP_U32[1] + s1) * (2.0**-32)
        one = 1.0 - 2.0**-24
        u = Float(gx) + dr.minimum(fu, one) - 0.5
        v = Float(gy) + dr.minimum(fv, one) - 0.5
        if self.pinhole:
            a_cam = mi.Vector3f(0.0)
        else:
            a_cam = self.model.aperture_point(_next_2d(mi, rng))
        return rng, self.model.ray(u, v, a_cam), None

    def _emitter_return(self, si, bsdf, ctx, rng, active, beta, sample=None):
        """Next-event estimation from the vertex ``si`` to one point of one emitter (chosen
        uniformly; shadow ray): the return ``L = beta f (n I(theta)) / r^2`` and the distance
        ``r`` from the vertex to the emitter point (mi.Float each). ``sample``: the emitter
        index (mi.Float in [0, 1)) and disk (mi.Point2f) samples; None draws them from ``rng``."""
        mi, dr = self._mi, self._dr
        UInt32, Float = mi.UInt32, mi.Float
        ill = self.illumination
        n_e = int(ill.n_emitters)
        m_exp = ill.cos_exponent
        I0 = ill.intensity_w_sr
        r_e = 0.5 * ill.emitter_diameter_m
        ex, ey, ez = self._axes
        u_k, u_disk = (rng.next_float32(), None) if sample is None else sample
        k = UInt32(dr.minimum(u_k * n_e, n_e - 1))
        cx_ = dr.gather(Float, self._em[0], k, active)
        cy_ = dr.gather(Float, self._em[1], k, active)
        cz_ = dr.gather(Float, self._em[2], k, active)
        if u_disk is None:
            u_disk = _next_2d(mi, rng)
        dsk = mi.warp.square_to_uniform_disk_concentric(u_disk) * r_e
        e_pt = mi.Point3f(cx_, cy_, cz_) + ex * dsk.x + ey * dsk.y
        dvec = e_pt - si.p
        dist2 = dr.squared_norm(dvec)
        dist = dr.sqrt(dist2)
        wi = dvec / dist
        cos_e = -dr.dot(wi, ez)
        intensity = I0 * dr.power(dr.maximum(cos_e, 0.0), m_exp)
        f = _mean_channel(bsdf.eval(ctx, si, si.to_local(wi), active))
        vis = ~self.scene.ray_test(si.spawn_ray_to(e_pt), active)
        L = dr.select(active & vis & (cos_e > 0.0), beta * f * (n_e * intensity) / dist2, 0.0)
        return L, dist

    # ------------------------------------------------------------------ truth
    def truth(self, R, t, truth_m, **info) -> dict:
        """The ground-truth record (JSON-serialisable)."""
        import drjit as dr
        import mitsuba as mi

        cam, tgt = self.camera, self.target
        ids = [str(int(i)) for i in tgt.ids]
        return {
            "camera": cam.name,
            "camera_source": package_relative(cam.source),
            "pattern": tgt.pattern.name,
            "R_cam_target": np.asarray(R).tolist(),
            "t_cam_target_m": np.asarray(t).tolist(),
            "state": state_dict(pose_to_state(R, t)),
            "range_m": float(t[2]),
            "targets_px": {i: [float(x) for x in uv] for i, uv in zip(ids, truth_m["centres_px"])},
            "targets_in_image": {i: bool(b) for i, b in zip(ids, truth_m["in_image"])},
            "targets_slant_range_m": {i: float(r) for i, r in zip(ids, truth_m["slant_range_m"])},
            "modulation_frequency_hz": info["f_mod"],
            "unambiguous_range_m": unambiguous_range_m(info["f_mod"]),
            "optics": self.optics.to_json(),
            "illumination": self.illumination.to_json(),
            "scene": {**self.options.to_json(), "geometry": self.geometry.to_json()},
            "render": {
                "variant": self.variant.name, "variant_notice": self.variant.notice,
                "integrator": "custom AMCW phasor integrator (svgs_sim/render/tof/camera.py): NEE to the emitter ring, "
                              + ("direct returns only" if self.max_bounces == 1 else f"{self.max_bounces} bounces (multipath)"),
                "sampler": self.sampler,
                "max_bounces": self.max_bounces, "pinhole": self.pinhole, "background_factor": self.background_factor,
                "seed": info["seed"], "spp": info["spp"], "rim_spp": info.get("rim_spp", info["spp"]),
                "rim_pixels": info.get("rim_pixels", 0), "window": list(info["window"]),
                "timings_s": info["timings"],
                "versions": {"mitsuba": mi.__version__, "drjit": dr.__version__, "numpy": np.__version__},
            },
        }


def render_tof(R_cam_target, t_cam_target_m, camera=DEFAULT_CAMERA, target=DEFAULT_PATTERN, *, seed: int = 0,
               spp: int = DEFAULT_SPP, **kw) -> RenderedTof:
    """One-call form of :class:`TofRenderer` (loads the scene every call)."""
    return TofRenderer(camera, target, spp=spp, **kw).render(R_cam_target, t_cam_target_m, seed=seed)


__all__ = ["DEFAULT_SPP", "DEFAULT_RIM_SPP_FACTOR", "SAMPLERS", "Illumination", "TofOptics", "TofRenderer", "render_tof", "check_pose", "check_target_in_view", "marker_truth"]
