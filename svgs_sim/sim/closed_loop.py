"""Closing the loop: scenario -> rendered flux -> phone image -> SVGS solution -> errors.

The data path of ``docs/design`` in one place::

    Scenario --render--> Flux --expose--> Raw --isp--> Image --detect/identify/solve--> Solution

- :class:`Scenario`: camera, pattern, pose (range along the boresight, lateral offsets,
  the paper's attitude), the lab around the target, render quality.
- :func:`render_scenario`: Mitsuba renders the target under the flash (retro returns,
  target body); the lab - a flash-lit backdrop behind the target and the room's ambient
  light, both uniform and smooth - is added analytically (nothing to ray trace in a
  Lambertian wall).
- :class:`Frame` holds one rendered flux and its truth; :meth:`Frame.exposer` gives the
  phone's :class:`svgs_sim.camera.phone.Exposer` (render once, expose many).
- :func:`expose_and_solve` makes one exposure and runs the SVGS chain on the delivered
  image, returning a row of results (truth, solution, errors, timings, reasons).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field

import numpy as np

from svgs_sim.base.errors import InputError, check_finite
from svgs_sim.base.profiles import Camera, Pattern, load_camera, load_pattern
from svgs_sim.render.api import render_flux
from svgs_sim.render.constants import DEFAULT_SPOT_SAMPLES
from svgs_sim.render.optics import Flash, Optics, radiance_to_photon_rate
from svgs_sim.render.materials import check_body
from svgs_sim.sim.metrics import no_pose_errors, pose_errors
from svgs_sim.sim.scene import Scene
from svgs_sim.sim.stand import TestStand
from svgs_sim.sim.target_pose import TargetPose
from svgs_sim.svgs.frames import pose_from_scenario, pose_to_state, state_dict
from svgs_sim.svgs.pipeline import solve_image


@dataclass(frozen=True, eq=False)
class Scenario(TargetPose):
    """One simulated situation (what a test stand would set up).

    The profiles travel as objects: ``camera`` and ``pattern`` may be given as names or paths
    for convenience; they are resolved once, at construction, through the cached loaders
    (:func:`svgs_sim.base.profiles.load_camera`, :func:`svgs_sim.base.profiles.load_pattern`), and the scenario
    holds the loaded :class:`~svgs_sim.base.profiles.Camera` and :class:`~svgs_sim.base.profiles.Pattern`.

    Attributes
    ----------
    camera : Camera
        The camera profile (given as a Camera, a profile name or a path).
    pattern : Pattern
        The target pattern (given as a Pattern - e.g. :meth:`Pattern.scaled` - a name or a path).
    range_m : float or None
        Along the boresight to the target origin, m (``mount="target"``; default 10). None with
        ``mount="stand"``, whose distance is :attr:`rail_m` (default 10).
    rail_m : float or None
        The gimbal pivot's position on the test stand's rail, m (``mount="stand"`` only, where it
        defaults to 10; :class:`svgs_sim.sim.stand.TestStand`). For callers that still give a stand's rail
        position as ``range_m``, a stand scenario with ``range_m`` and no ``rail_m`` takes it as
        ``rail_m``.
    target_x_m, target_y_m, roll_deg, pitch_deg, yaw_deg : float
        The target's pose besides its range (keyword-only, declared once in
        :class:`svgs_sim.sim.target_pose.TargetPose`): lateral offsets, m, and the paper's attitude, deg.
    scene : Scene
        The scene around the target (:class:`svgs_sim.sim.scene.Scene`; default the paper's lab:
        a grey backdrop behind the target, the room's light).
    focus_distance_m : float or None
        Where the lens is focused, m. None: the phone's autofocus locks on the target (the
        distance to the target origin); both phones of the paper had autofocus.
    spp, roi_spp : int or None
        Samples per pixel of the full frame and of the spot windows (None: the renderer's
        defaults).
    mount : {"target", "stand"}
        What the angles turn. ``"target"`` (default): the target's attitude in front of the
        camera (:func:`svgs_sim.svgs.frames.pose_from_scenario`). ``"stand"``: the paper's test stand -
        the target fixed, the phone turned by the gimbal about its pivot, :attr:`rail_m` the
        pivot's rail position (:class:`svgs_sim.sim.stand.TestStand`); lateral offsets must then be 0.
    stage_m : float
        The stand's translation stage along the rail, m (``mount="stand"`` only).
    misalignment_deg : tuple of float
        The phone's (roll, pitch, yaw) in its holder, deg (``mount="stand"`` only; see
        :class:`svgs_sim.sim.stand.TestStand`). The image is made at the actual pose; the truth the
        lab knew is the commanded one (:meth:`commanded_pose`).
    stand_error : tuple of float
        The stand's errors at this setting (``mount="stand"`` only): the gimbal's actual roll,
        pitch and yaw minus the commanded ones (deg), the translation stage's actual minus
        commanded position (m) and the rail position's actual minus the one recorded (m; the
        range the lab measured with its hand-held rangefinder). The image is made at the actual
        pose; the truth the lab knew is the commanded one (:meth:`truth_pose`).
    lens_pp_offset_px : tuple of float
        The true lens' principal point minus the profile's ``(cx, cy)``, px: the image is
        rendered through :meth:`camera_profile`, the profile's camera with this offset.
    lens_k1 : float
        Radial distortion k1 added to the profile's for the true lens.
    camera_overrides : tuple of (table, key, value)
        Profile values replaced for this scenario (e.g. ``(("optics", "f_number", 2.8),)``):
        the renderer and the camera model both read them (:meth:`camera_profile`).
    """

    camera: Camera | str = "galaxy-nexus"
    pattern: Pattern | str = "svgs-3u"
    range_m: float | None = None
    scene: Scene = Scene()
    focus_distance_m: float | None = None
    spp: int | None = None
    roi_spp: int | None = None
    mount: str = "target"
    stage_m: float = 0.0
    misalignment_deg: tuple = (0.0, 0.0, 0.0)
    stand_error: tuple = (0.0, 0.0, 0.0, 0.0, 0.0)
    lens_pp_offset_px: tuple = (0.0, 0.0)
    lens_k1: float = 0.0
    camera_overrides: tuple = ()
    rail_m: float | None = None
    _lens: Camera | None = field(default=None, init=False, repr=False, compare=False)

    def __post_init__(self):
        object.__setattr__(self, "camera", load_camera(self.camera))
        object.__setattr__(self, "pattern", load_pattern(self.pattern))
        self._check_distances()
        object.__setattr__(self, "camera_overrides", tuple(tuple(x) for x in self.camera_overrides))
        for ov in self.camera_overrides:
            if len(ov) != 3 or not all(isinstance(x, str) for x in ov[:2]):
                raise InputError(f"camera_overrides: expected (table, key, value) entries, got {ov!r}")
        object.__setattr__(self, "misalignment_deg", tuple(float(x) for x in self.misalignment_deg))
        object.__setattr__(self, "lens_pp_offset_px", tuple(float(x) for x in self.lens_pp_offset_px))
        if len(self.misalignment_deg) != 3 or len(self.lens_pp_offset_px) != 2:
            raise InputError("misalignment_deg: expected (roll, pitch, yaw); lens_pp_offset_px: expected (du, dv)")
        if self.mount == "target" and any(self.misalignment_deg):
            raise InputError("misalignment_deg: only the test stand (mount='stand') holds the phone in a holder")
        object.__setattr__(self, "stand_error", tuple(float(x) for x in self.stand_error))
        se = np.asarray(self.stand_error, float)
        if se.shape != (5,) or not np.all(np.isfinite(se)) or np.any(np.abs(se[:3]) > 5) or np.any(np.abs(se[3:]) > 1):
            raise InputError(f"stand_error: expected (roll_deg, pitch_deg, yaw_deg, stage_m, rail_m) within +/-5 deg "
                             f"and +/-1 m, got {self.stand_error!r}")
        if self.mount == "target" and np.any(se):
            raise InputError("stand_error: only the test stand (mount='stand') has a gimbal, a stage and a rail")
        if not (np.all(np.isfinite(self.lens_pp_offset_px)) and max(map(abs, self.lens_pp_offset_px)) <= 200
                and np.isfinite(self.lens_k1) and abs(self.lens_k1) <= 1):
            raise InputError(f"lens_pp_offset_px/lens_k1: expected offsets within +/-200 px and |k1| <= 1, got "
                             f"{self.lens_pp_offset_px!r}, {self.lens_k1!r}")
        if self.mount not in ("target", "stand"):
            raise InputError(f"mount: expected 'target' or 'stand', got {self.mount!r}")
        if self.mount == "stand" and (self.target_x_m != 0 or self.target_y_m != 0):
            raise InputError("target_x_m/target_y_m: the test stand has no lateral stage; with mount='stand' "
                             "the phone is turned by the gimbal and moved along the rail only (stage_m)")
        if self.mount == "target" and self.stage_m != 0:
            raise InputError("stage_m: only the test stand (mount='stand') has a translation stage")
        if not np.isfinite(float(self.stage_m)) or abs(float(self.stage_m)) > 1.0:
            raise InputError(f"stage_m: expected a finite stage position within +/-1 m, got {self.stage_m!r}")
        for k in ("target_x_m", "target_y_m", "roll_deg", "pitch_deg", "yaw_deg"):
            check_finite(getattr(self, k), k)
        if not isinstance(self.scene, Scene):
            raise InputError(f"scene: expected a svgs_sim.sim.scene.Scene, got {self.scene!r}")
        if self.focus_distance_m is not None and not (np.isfinite(self.focus_distance_m) and self.focus_distance_m > 0):
            raise InputError(f"focus_distance_m: expected a positive distance or None (autofocus), got {self.focus_distance_m!r}")
        if (self.spp is not None and int(self.spp) < 0) or (self.roi_spp is not None and int(self.roi_spp) < 1):
            raise InputError(f"spp/roi_spp: expected spp >= 0 and roi_spp >= 1, got {self.spp}, {self.roi_spp}")
        object.__setattr__(self, "_lens", self._true_lens())

    def _check_distances(self) -> None:
        """``range_m`` (the target) or ``rail_m`` (the stand): present, finite and positive."""
        if self.range_m is None and self.rail_m is None:  # the default distance, 10 m
            object.__setattr__(self, "rail_m" if self.mount == "stand" else "range_m", 10.0)
        if self.mount == "stand" and self.range_m is not None:
            raise InputError("range_m: the boresight distance of a target scenario; the test stand's rail "
                             "position is rail_m (give one of them)")
        if self.mount != "stand" and self.rail_m is not None:
            raise InputError("rail_m: only the test stand (mount='stand') has a rail; give range_m")
        name = "rail_m" if self.mount == "stand" else "range_m"
        v = getattr(self, name)
        try:
            fv = float(v)
        except (TypeError, ValueError):
            raise InputError(f"{name}: expected a number, got {v!r}") from None
        if not np.isfinite(fv):
            raise InputError(f"{name}: expected a finite number, got {v!r}")
        if fv <= 0:
            raise InputError(f"{name}: expected a positive distance in metres, got {v!r}")

    @property
    def distance_m(self) -> float:
        """The nominal distance along the rail or the boresight: :attr:`rail_m` on the stand,
        else :attr:`range_m`."""
        return self.rail_m if self.mount == "stand" else self.range_m

    def pose(self):
        """(R_cam_target, t_cam_target_m) of this scenario: the actual pose (the misalignment and
        the stand's errors included)."""
        return self.truth_pose(True, True, True)

    def commanded_pose(self):
        """(R_cam_target, t_cam_target_m) the lab knew: the stand's setting without the phone's
        misalignment in its holder and without the stand's errors (equal to :meth:`pose` when
        there are none)."""
        return self.truth_pose(False, False, False)

    def truth_pose(self, misalignment: bool, stand: bool, rail: bool):
        """(R_cam_target, t_cam_target_m) with some of the truth's errors included: the phone's
        ``misalignment`` in its holder, the gimbal's and the stage's errors (``stand``), the
        rail position's (``rail``). All three: :meth:`pose`; none: :meth:`commanded_pose`."""
        if self.mount == "stand":

            mis = self.misalignment_deg if misalignment else (0.0, 0.0, 0.0)
            er, ep, ey, es, _ = self.stand_error if stand else (0.0,) * 5
            rail_m = self.stand_error[4] if rail else 0.0
            return TestStand(misalignment_deg=tuple(mis)).pose(
                self.rail_m + rail_m, stage_m=self.stage_m + es, roll_deg=self.roll_deg + er,
                pitch_deg=self.pitch_deg + ep, yaw_deg=self.yaw_deg + ey)
        return pose_from_scenario(self.range_m, self.target_x_m, self.target_y_m, self.roll_deg, self.pitch_deg,
                                  self.yaw_deg)

    def camera_profile(self) -> Camera:
        """The true lens: the profile's camera with :attr:`camera_overrides`,
        :attr:`lens_pp_offset_px` and :attr:`lens_k1` (made once, at construction)."""
        return self._lens

    def _true_lens(self) -> Camera:
        cam = self.camera
        if self.camera_overrides:
            cam = cam.with_values(self.camera_overrides)
        du, dv = self.lens_pp_offset_px
        if du == 0 and dv == 0 and self.lens_k1 == 0:
            return cam
        return cam.replace(cx=cam.cx + du, cy=cam.cy + dv, dist=cam.dist + np.array([self.lens_k1, 0.0, 0.0, 0.0, 0.0]))

    def replace(self, **kw) -> "Scenario":
        """A copy with the fields ``kw`` changed (the profiles kept as objects)."""
        mount = kw.get("mount", self.mount)
        if "rail_m" not in kw and ((mount == "stand" and "range_m" in kw) or (mount == "target" and self.mount == "stand")):
            kw["rail_m"] = None  # a new rail position given as range_m (see rail_m), or off the stand
        return dataclasses.replace(self, **kw)

    def _key(self) -> tuple:
        """What the scenario is (its fields, the profiles by content) for ``==`` and ``hash``."""
        d = self.to_json()
        d["camera"] = self.camera.fingerprint()
        d["pattern"] = self.pattern.fingerprint()
        return tuple((k, repr(v)) for k, v in d.items() if k not in ("camera_source", "pattern_source"))

    def __eq__(self, other):
        if not isinstance(other, Scenario):
            return NotImplemented
        return self is other or self._key() == other._key()

    def __hash__(self):
        return hash(self._key())

    def to_json(self) -> dict:
        """The fields as JSON values; the profiles by name (``camera``, ``pattern``) and by the
        file they were read from (``camera_source``, ``pattern_source``)."""
        out = {}
        for f in dataclasses.fields(self):
            if f.name == "scene":
                out.update(self.scene.to_json())  # flat: one name per quantity
            elif f.init:
                out[f.name] = getattr(self, f.name)
        out["camera"], out["pattern"] = self.camera.name, self.pattern.name
        out["camera_source"], out["pattern_source"] = self.camera.source, self.pattern.source
        for k in ("misalignment_deg", "stand_error", "lens_pp_offset_px"):
            out[k] = list(out[k])
        out["camera_overrides"] = [list(x) for x in self.camera_overrides]
        return out


@dataclass
class Frame:
    """One rendered frame: noise-free flux and its truth.

    Attributes
    ----------
    scenario : Scenario
    flux : ndarray, float32, shape (H, W)
        Photons per second per pixel (target render + backdrop + ambient).
        Everything binned where it meets the film, before the lens PSF.
    lab : ndarray, float32, shape (H, W)
        The backdrop + ambient part of ``flux`` (so ``flux - lab`` is the target alone).
    truth : dict
        The renderer's truth record plus the lab's parameters.
    render_s : float
        Wall time of the render.
    target_diffuse : ndarray, float32, shape (H, W), optional
        The target's light rendered per pixel (its diffuse part); with ``points``, what the
        camera takes instead of ``flux - lab``.
    points : svgs_sim.camera.rendered.PointFlux, optional
        The target's retro spots as samples at exact film positions (photons/s each).
    lab_unit : (float, ndarray), optional
        ``(radiance_w_m2_sr, factor)`` with ``lab = radiance_w_m2_sr * factor``
        (:func:`lab_flux`, :func:`lab_photon_factor`): the camera model keeps the optical image
        of ``factor`` and scales it, instead of convolving the lab's light again every frame.
    natural : (ndarray, tuple), optional
        ``(flux_sun, spectra)``: the sun's and the Earth's part of ``target_diffuse`` (float32
        (H, W), photons/s per pixel) and their photon spectra with the flash's
        (:attr:`svgs_sim.render.api.RenderResult.natural_spectra`): through the colour filters each
        channel takes that light with its own weight (:func:`svgs_sim.camera.phone.cfa.light_weights`).
    """

    scenario: Scenario
    flux: np.ndarray
    truth: dict
    render_s: float = 0.0
    lab: np.ndarray | None = None
    target_diffuse: np.ndarray | None = None
    points: object = None
    lab_unit: tuple | None = None
    natural: tuple | None = None
    _phone: object = field(default=None, repr=False)

    @property
    def camera(self) -> Camera:
        """The true camera the frame was rendered through (:meth:`Scenario.camera_profile`,
        made once with the scenario)."""
        return self.scenario.camera_profile()

    @property
    def pattern(self) -> Pattern:
        """The target pattern the frame was rendered with."""
        return self.scenario.pattern

    def phone(self, *, glare: bool = True, veiling_fraction: float | None = None, wing_exponent: float | None = None):
        """The phone camera model; ``glare=False``: the same phone with a glare-free lens (no
        veiling wings, no ghosts; the diffraction and aberration core kept);
        ``veiling_fraction``, ``wing_exponent``: the glare's, instead of the profile's."""

        from svgs_sim.camera.phone import PhoneCamera

        if self._phone is None:
            self._phone = {}
        key = (glare, veiling_fraction, wing_exponent)
        if key not in self._phone:
            ph = PhoneCamera(self.camera)
            g = ph.params.glare
            if veiling_fraction is not None:
                g = dataclasses.replace(g, veiling_fraction=float(veiling_fraction))
            if wing_exponent is not None:
                g = dataclasses.replace(g, wing_exponent=float(wing_exponent))
            if not glare:
                g = dataclasses.replace(g, veiling_fraction=0.0, ghosts=())
            if g != ph.params.glare:
                ph = PhoneCamera(self.camera, params=dataclasses.replace(ph.params, glare=g))
            self._phone[key] = ph
        return self._phone[key]

    def exposer(self, stages=None, *, target_scale: float = 1.0, glare: bool = True,
                veiling_fraction: float | None = None, wing_exponent: float | None = None):
        """The phone's exposer for this flux (optics and metering done once).

        ``target_scale`` multiplies the target's flux (not the lab's): a neutral-density
        filter of transmission T over every reflector is ``target_scale = T**2`` (two
        passes; the target body's own diffuse light is ~1e-7 of the spots'). ``glare=False``:
        a glare-free lens; ``veiling_fraction``, ``wing_exponent``: other glare (:meth:`phone`)."""
        from svgs_sim.camera.phone import ALL_STAGES, Exposer

        stages = ALL_STAGES if stages is None else stages
        phone = self.phone(glare=glare, veiling_fraction=veiling_fraction, wing_exponent=wing_exponent)
        seed = render_seed(self.truth)
        lab = self.lab if self.lab is not None else np.float32(0.0)
        natural = None
        if self.natural is not None and phone.params.cfa.enabled:  # the sun's colour through the filters
            from svgs_sim.camera.phone.cfa import light_weights

            flux_nat, spectra = self.natural
            flux_nat = flux_nat if target_scale == 1.0 else (flux_nat * np.float32(target_scale)).astype(np.float32)
            natural = (flux_nat, light_weights(phone.params.cfa, *spectra))
        if self.points is not None and self.target_diffuse is not None:
            pts = self.points if target_scale == 1.0 else self.points.scaled(target_scale)
            if self.lab_unit is not None:  # the lab's optical image kept by the camera model
                flux = (self.target_diffuse * np.float32(target_scale)).astype(np.float32)
                return Exposer(phone, flux, points=pts, stages=stages, optics_seed=seed, background=self.lab_unit,
                               natural=natural)
            flux = (lab + self.target_diffuse * np.float32(target_scale)).astype(np.float32)
            return Exposer(phone, flux, points=pts, stages=stages, optics_seed=seed, natural=natural)
        flux = self.flux
        if target_scale != 1.0:
            flux = (lab + (self.flux - lab) * np.float32(target_scale)).astype(np.float32)
        return Exposer(phone, flux, stages=stages, optics_seed=seed, natural=natural)


def render_seed(truth: dict) -> int:
    """The render's sampler seed from a truth record (0 when it has none): it also seeds the
    Monte Carlo convolution of the frame's points with the PSF."""
    return int((truth.get("render") or {}).get("seed", 0) or 0)


def lab_flux(camera: Camera, scenario: Scenario, factor: np.ndarray | None = None) -> tuple[np.ndarray, dict]:
    """Photon flux of the lab around the target: a flash-lit Lambertian backdrop and
    uniform ambient light, photons/s/px, with the parameters used.

    Backdrop radiance ``rho * I_flash / (pi * D^2)`` (D from the camera to the backdrop,
    the flash's on-axis intensity, its cos^m fall-off towards the field edge ignored),
    plus the ambient radiance; photons per pixel through the aperture from
    :func:`lab_photon_factor`; ``factor`` is that conversion when the caller has it already.
    """

    optics = Optics.from_camera(camera)
    flash = Flash.from_camera(camera, optics.band_nm)
    scene = scenario.scene
    L = float(scene.ambient_radiance_w_m2_sr)
    info = {"ambient_radiance_w_m2_sr": L}
    if scene.backdrop_distance_m is not None:
        D = scenario.distance_m + scene.backdrop_distance_m
        n_led = len(flash.led_offsets_m)
        Lb = scene.backdrop_reflectance * n_led * flash.radiant_intensity_w_sr / (np.pi * D * D)
        L += Lb
        info.update({"backdrop_distance_from_camera_m": D, "backdrop_reflectance": scene.backdrop_reflectance,
                     "backdrop_radiance_w_m2_sr": Lb})
    info["radiance_w_m2_sr"] = L
    if L == 0:
        return np.zeros((camera.height, camera.width), np.float32), info
    if factor is None:
        factor = lab_photon_factor(camera)
    return (L * np.asarray(factor, np.float32)).astype(np.float32), info


_LAB_FACTORS: dict = {}


def lab_photon_factor(camera: Camera) -> np.ndarray:
    """Photons/s per pixel per unit scene radiance (W m^-2 sr^-1) through the lens, float32 (H, W):
    :func:`svgs_sim.render.optics.radiance_to_photon_rate`, which varies smoothly, on a 16-px grid
    interpolated to every pixel. Read-only; the same array for the same camera (cached by the
    profile's content), so that the camera model can keep its optical image between frames."""
    key = camera.fingerprint()
    hit = _LAB_FACTORS.get(key)
    if hit is None:
        if len(_LAB_FACTORS) >= 8:
            _LAB_FACTORS.clear()
        hit = _lab_photon_factor(camera)
        hit.setflags(write=False)
        _LAB_FACTORS[key] = hit
    return hit


def _lab_photon_factor(camera: Camera) -> np.ndarray:
    import cv2


    optics = Optics.from_camera(camera)
    flash = Flash.from_camera(camera, optics.band_nm)
    step = 16
    u, v = np.meshgrid(np.arange(0, camera.width, step, dtype=float), np.arange(0, camera.height, step, dtype=float))
    xy = camera.pixels_to_normalized(np.stack([u, v], -1))  # the 16-px grid only
    k = radiance_to_photon_rate(camera, optics, flash.photometry["mean_photon_energy_j"], xy).astype(np.float32)
    full = cv2.resize(k, (k.shape[1] * step, k.shape[0] * step), interpolation=cv2.INTER_LINEAR)
    return np.ascontiguousarray(full[: camera.height, : camera.width])


@dataclass(frozen=True)
class RenderOptions:
    """How a scenario is rendered (not what is in it): the estimator and the target's model.

    Attributes
    ----------
    method : {"guided", "path"}
        The guided spot estimator (default) or brute-force path tracing (the reference; slow
        beyond a few metres).
    reflector : str or None
        ``"solid"``, ``"hollow"`` or a reflector model name (None: the pattern's).
    body : {"plate", "3u", "none"}, str or None
        The target's body (None: the renderer's, a plate), or a mesh file (``.ply`` / ``.obj``,
        metres in the target frame; :mod:`svgs_sim.render.body_mesh`).
    body_material : str or None
        A mesh body's surface from the library (:mod:`svgs_sim.render.materials`).
    body_materials : tuple of (str, str)
        A mesh body's parts and their surfaces (a dict is accepted).
    spot_samples : int or None
        Guided samples per spot strategy (None: the renderer's, 16384).
    full_frame : bool
        Render the whole frame at the scenario's ``spp``, no spot windows.
    """

    method: str = "guided"
    reflector: str | None = None
    body: str | None = None
    spot_samples: int | None = None
    full_frame: bool = False
    body_material: str | None = None
    body_materials: tuple = ()

    def scene_options(self) -> dict:
        """The renderer's :class:`~svgs_sim.render.geometry.SceneOptions` fields of the body (empty
        for the renderer's own, the plate)."""
        out = {} if self.body is None else {"body": self.body}
        if self.body_material is not None or self.body_materials:  # a mesh body's surfaces
            out.update(body_material=self.body_material, body_materials=self.body_materials)
        return out

    def __post_init__(self):
        if self.method not in ("guided", "path"):
            raise InputError(f"method: expected 'guided' or 'path', got {self.method!r}")
        if isinstance(self.body_materials, dict):
            object.__setattr__(self, "body_materials", tuple(sorted(self.body_materials.items())))
        check_body(self.body, self.body_material, self.body_materials, builtin=(None, "plate", "3u", "none"))
        if self.spot_samples is not None and (isinstance(self.spot_samples, bool) or int(self.spot_samples) < 1):
            raise InputError(f"spot_samples: expected a positive whole number (or None: the renderer's), got "
                             f"{self.spot_samples!r}")


def render_scenario(scenario: Scenario, *, seed: int = 0, options: RenderOptions | None = None) -> Frame:
    """Render a scenario: Mitsuba for the target, analytic lab light around it.

    The one route from a scenario to a rendered frame: ``svgs render``, ``svgs render-and-solve``,
    the render trials of every study and the approach all come through here.

    Parameters
    ----------
    scenario : Scenario
    seed : int
        The render's Monte Carlo seed.
    options : RenderOptions, optional
        How to render (default: the guided estimator, the pattern's reflectors, a plate body).

    Returns
    -------
    Frame
    """
    options = options or RenderOptions()
    camera = scenario.camera_profile()
    pattern = scenario.pattern
    R, t = scenario.pose()
    t0 = time.perf_counter()
    kw = {k: int(getattr(scenario, k)) for k in ("spp", "roi_spp") if getattr(scenario, k) is not None}
    focus = scenario.focus_distance_m if scenario.focus_distance_m is not None else float(np.linalg.norm(t))
    scene_options = {"focus_distance_m": focus, **options.scene_options()}
    # the sun (a pass of its own, svgs_sim.render.sun) and the Earth (in the sun's pass, svgs_sim.render.earth);
    # the lab's are the defaults
    scene_options.update(scenario.scene.natural_light())
    if scenario.scene.body != "plate":  # a trial's shipped body (svgs_sim.sim.scene.Scene.body)
        if options.body is not None and options.body != scenario.scene.body:
            raise InputError(f"body: the scene holds {scenario.scene.body!r} and the render options {options.body!r}; "
                             "give one")
        scene_options["body"] = scenario.scene.body
    res = render_flux(camera, pattern, R, t, seed=int(seed), scene_options=scene_options, method=options.method,
                      reflector=options.reflector, full_frame=options.full_frame,
                      spot_samples=DEFAULT_SPOT_SAMPLES if options.spot_samples is None else int(options.spot_samples),
                      **kw)
    factor = lab_photon_factor(camera)
    lab, info = lab_flux(camera, scenario, factor=factor)
    dt = time.perf_counter() - t0
    truth = dict(res.truth)
    truth["lab"] = info
    truth["scenario"] = scenario.to_json()
    truth["focus_distance_m"] = focus
    return Frame(scenario, res.flux + lab, truth, dt, lab, target_diffuse=res.flux_diffuse, points=res.points,
                 lab_unit=(info["radiance_w_m2_sr"], factor), natural=natural_part(res))


def natural_part(res) -> tuple | None:
    """``(flux_sun, spectra)`` of a render (:attr:`Frame.natural`), or None without the sun."""
    return None if res.flux_sun is None else (res.flux_sun, res.natural_spectra)


def solver_camera(camera: Camera, image_shape) -> Camera:
    """The camera geometry of a delivered image (scaled when the ISP downscaled it)."""
    h, w = image_shape[:2]
    return camera if (w, h) == (camera.width, camera.height) else camera.scaled(w, h)


def _truth_flags(truth) -> tuple:
    """``(misalignment, stand, rail)`` of a ``truth`` argument (see :func:`expose_and_solve`)."""
    if isinstance(truth, str):
        if truth == "commanded":
            return (False, False, False)
        if truth == "actual":
            return (True, True, True)
    elif isinstance(truth, tuple) and len(truth) == 3:
        return tuple(bool(x) for x in truth)
    raise InputError(f"truth: expected 'commanded', 'actual' or (misalignment, stand, rail), got {truth!r}")


def expose_and_solve(frame: Frame, exposer, *, seed: int, threshold=None, exposure_s=None, iso=None,
                     solver_camera_profile: Camera | None = None, stages=None, truth: str = "commanded", isp=None,
                     demosaic=None) -> dict:
    """One exposure of a rendered frame through the SVGS chain.

    Parameters
    ----------
    frame : Frame
    exposer : svgs_sim.camera.phone.Exposer
        From :meth:`Frame.exposer` (reused across calls).
    seed : int
        Noise seed of this exposure.
    threshold : None, float or str
        Detector threshold: None, the app's for the camera (:func:`svgs_sim.svgs.pipeline.camera_threshold`);
        else as :func:`svgs_sim.svgs.detect.detect_blobs` takes it.
    exposure_s, iso : float, optional
        Override the phone's exposure.
    solver_camera_profile : Camera, optional
        The geometry the solver believes (a calibration with errors); default: the truth.
    stages : sequence of str, optional
        This exposure's stages (:meth:`svgs_sim.camera.phone.Exposer.expose`); default the exposer's.
    truth : {"commanded", "actual"} or tuple of 3 bool
        The pose the errors are taken against: the one the lab knew
        (:meth:`Scenario.commanded_pose`, default), the actual one (the phone's
        misalignment in its holder and the stand's errors included), or
        ``(misalignment, stand, rail)``: which of them the truth includes
        (:meth:`Scenario.truth_pose`).
    isp : svgs_sim.camera.phone.params.IspParams, optional
        This exposure's ISP instead of the profile's ``[isp]`` (:meth:`svgs_sim.camera.phone.Exposer.expose`).
    demosaic : str, optional
        This exposure's demosaic instead of the profile's ``[cfa] demosaic``.

    Returns
    -------
    dict
        ``ok``, ``reason``, ``message``, ``n_blobs``, ``outside_test_envelope`` (solved: the pose
        lies outside the paper's test envelope; None when unsolved), ``identified_px`` (the identified
        blobs' centroids by target id, px, in the delivered image: solved or ``inconsistent``; else
        None), ``state`` (solved, paper keys) or None,
        ``truth_state``, the :data:`svgs_sim.sim.metrics.POSE_ERROR_KEYS` (``pos_err_vec_m``,
        ``att_err_vec_deg``, ``pos_err_norm_m``, ``rot_err_deg``; None when unsolved),
        ``residual_rms_px``, ``chi2``, ``chi2_dof``, ``p_value`` (the consistency test,
        :func:`svgs_sim.svgs.app.consistency`; also for an ``inconsistent`` failure),
        ``exposure_s``, ``iso``, ``expose_s``, ``solve_s``; and ``_exposure`` / ``_solution``
        (objects, for callers that write images).
    """
    _truth_flags(truth)
    t0 = time.perf_counter()
    ex = exposer.expose(seed=seed, exposure_s=exposure_s, iso=iso, stages=stages, isp=isp, demosaic=demosaic)
    t1 = time.perf_counter()
    row = solve_exposure(frame, ex, threshold=threshold, solver_camera_profile=solver_camera_profile, truth=truth)
    row["expose_s"] = t1 - t0
    return row


def solve_exposure(frame: Frame, ex, *, threshold=None, solver_camera_profile: Camera | None = None,
                   truth: str = "commanded", blobs=None) -> dict:
    """The SVGS chain on one exposure (:meth:`svgs_sim.camera.phone.Exposer.expose`) of a frame: the row
    of :func:`expose_and_solve` (``expose_s`` 0). ``blobs``: the image's detections when the
    caller has made them (:func:`svgs_sim.svgs.pipeline.solve_image`)."""

    _truth_flags(truth)
    t1 = time.perf_counter()
    img = ex.detect_image
    cam = solver_camera(solver_camera_profile or frame.camera, img.shape)
    sol = solve_image(img, cam, frame.scenario.pattern, threshold=threshold, blobs=blobs)
    t2 = time.perf_counter()
    R, t = frame.scenario.truth_pose(*_truth_flags(truth))
    truth_state = pose_to_state(R, t)
    row = {
        "ok": bool(sol),
        "reason": None if sol else sol.reason,
        "message": None if sol else sol.message,
        "n_blobs": sol.n_blobs if sol else sol.details.get("n_blobs"),
        "outside_test_envelope": bool(sol.outside_test_envelope) if sol else None,
        "identified_px": ({str(k): [float(x) for x in v] for k, v in sol.targets_px.items()} if sol
                          else sol.details.get("targets_px")),
        "truth_state": state_dict(truth_state),
        "exposure_s": ex.exposure_s,
        "iso": ex.iso,
        "expose_s": 0.0,
        "solve_s": t2 - t1,
        "_exposure": ex,
        "_solution": sol,
    }
    cons = sol.consistency.to_json() if sol and sol.consistency is not None else (sol.details if not sol else {})
    row.update({"chi2": cons.get("chi2"), "chi2_dof": cons.get("dof"), "p_value": cons.get("p_value")})
    if sol:
        row.update({"state": sol.state_dict, "residual_rms_px": sol.residual_rms_px,
                    **pose_errors(sol.state, truth_state)})
    else:
        row.update({"state": None, "residual_rms_px": sol.details.get("residual_rms_px"), **no_pose_errors()})
    return row
