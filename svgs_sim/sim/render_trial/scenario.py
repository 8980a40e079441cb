"""What a ``render`` trial is: its row parameters (:data:`RENDER_PARAMETERS`, with the scene's), the
typed :class:`RenderScenario` (as a mapping, its results-store row), the threshold's row code and
:class:`RenderKey`, what decides the rendered flux.

Part of :mod:`svgs_sim.sim.render_trial`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import ClassVar

from svgs_sim.base.errors import InputError
from svgs_sim.base.limits import MAX_SEED, MAX_SPP, bounds
from svgs_sim.base.profiles import load_camera, load_pattern
from svgs_sim.sim.closed_loop import Scenario
from svgs_sim.sim.metrics import ERR_KEYS, POS_ERR_NORM_M, ROT_ERR_DEG
from svgs_sim.sim.scene import Scene, scene_parameters
from svgs_sim.sim.trials import GEOMETRIC_PARAMETERS, POSE_KEYS, TRUTH_KEYS, Code, Parameter, PoseScenario
from svgs_sim.svgs.frames import STATE_KEYS

_POSE = POSE_KEYS


#: ``threshold`` values that are not levels (the parameter is numeric, so a sensitivity study can vary it):
#: 0 the app's brightness threshold for the camera (:mod:`svgs_sim.svgs.app`, the default), -1 Otsu's, -2 the
#: automatic rule.
THRESHOLD_APP, THRESHOLD_OTSU, THRESHOLD_AUTO = 0.0, -1.0, -2.0

#: The row codes of "not a quantity" values: written and shown as the words, held as the numbers.
_RENDERER = Code(-1.0, "renderer", "the renderer's default")
_PHONE = Code(0.0, "phone", "the phone's auto-exposure")


RENDER_PARAMETERS = {
    **{k: GEOMETRIC_PARAMETERS[k] for k in _POSE},
    **scene_parameters(),  # the scene around the target, declared once (svgs_sim.sim.scene)
    "spp": Parameter("spp", "1", "samples per pixel of the full frame", -1.0, True, lower=1.0, upper=MAX_SPP,
                     codes=(_RENDERER,)),
    "roi_spp": Parameter("roi_spp", "1", "samples per pixel in the spot windows", -1.0, True, lower=1.0,
                         upper=MAX_SPP, codes=(_RENDERER,)),
    "render_seed": Parameter("render_seed", "1", "seed of the render's Monte Carlo sampling", 0.0, True, lower=0.0,
                              upper=MAX_SEED),
    "pattern_scale": Parameter("pattern_scale", "1", "the pattern scaled about its origin by this factor (a wider target)",
                               1.0, True, lower=0.0, upper=10.0, lower_open=True),
    "target_scale": Parameter("target_scale", "1", "multiplies the target's flux, not the lab's (an ND filter of "
                              "transmission T over every reflector: T**2)", 1.0, False, lower=0.0, upper=1.0,
                              lower_open=True),
    "exposure_s": Parameter("exposure_s", "s", "exposure time forced on the phone", 0.0, False, **bounds("exposure_s"),
                            lower_open=True, codes=(_PHONE,)),
    "iso": Parameter("iso", "ISO", "sensitivity forced on the phone", 0.0, False, **bounds("iso"), codes=(_PHONE,)),
    "threshold": Parameter("threshold", "DN", "detector threshold in 8-bit counts", 0.0, False, lower=0.0, upper=255.0,
                           lower_open=True,
                           codes=(Code(THRESHOLD_APP, "app", "the app's for the camera, svgs_sim.svgs.app"),
                                  Code(THRESHOLD_OTSU, "otsu", "Otsu's"),
                                  Code(THRESHOLD_AUTO, "auto", "the automatic rule"))),
    **{k: GEOMETRIC_PARAMETERS[k] for k in ("focal_error_frac", "pp_error_u_px", "pp_error_v_px", "k1_error")},
    # the true lens (the solver's calibration errors above are relative to it)
    "lens_pp_u_px": Parameter("lens_pp_u_px", "px", "the true lens' principal point cx minus the profile's (the image "
                              "is rendered through the true lens)", 0.0, True, lower=-200.0, upper=200.0),
    "lens_pp_v_px": Parameter("lens_pp_v_px", "px", "the true lens' principal point cy minus the profile's", 0.0, True,
                              lower=-200.0, upper=200.0),
    "lens_k1": Parameter("lens_k1", "1", "radial distortion k1 of the true lens added to the profile's", 0.0, True,
                         lower=-1.0, upper=1.0),
    # error sources switched off one at a time (the campaign's error budget); they act after the render
    "sensor_noise": Parameter("sensor_noise", "1", "1: the sensor's noise (shot, dark, fixed pattern, read); 0: none",
                              1.0, False, lower=0.0, upper=1.0),
    "glare": Parameter("glare", "1", "1: the lens' glare (veiling wings, ghosts); 0: a glare-free lens with the same "
                       "diffraction and aberration core", 1.0, False, lower=0.0, upper=1.0),
    "quantise": Parameter("quantise", "1", "1: the delivered image in 8 bits and JPEG; 0: a float image (same tone "
                          "curve), no JPEG", 1.0, False, lower=0.0, upper=1.0),
    "cfa": Parameter("cfa", "1", "1: the profile's colour filter array (Bayer mosaic, demosaic); 0: a mono sensor",
                     1.0, False, lower=0.0, upper=1.0),
    "nr": Parameter("nr", "1", "1: the ISP's noise reduction as the profile sets it ([isp] nr_*); 0: none", 1.0, False,
                    lower=0.0, upper=1.0),
    "sharpen": Parameter("sharpen", "1", "1: the ISP's sharpening as the profile sets it ([isp] sharpen_*); 0: none",
                         1.0, False, lower=0.0, upper=1.0),
    "chroma": Parameter("chroma", "1", "1: a colour JPEG's chroma subsampled as the profile sets it ([isp] "
                        "jpeg_subsampling); 0: full chroma (4:4:4)", 1.0, False, lower=0.0, upper=1.0),
    "jpeg": Parameter("jpeg", "1", "1: the JPEG round trip; 0: the 8-bit image the encoder would get", 1.0, False,
                      lower=0.0, upper=1.0),
    # the ISP's choices (after the render, per exposure)
    "demosaic": Parameter("demosaic", "1", "the ISP's demosaic", 0.0, False,
                          codes=(Code(0.0, "profile", "the profile's [cfa] demosaic"),
                                 Code(1.0, "bilinear", "bilinear (OpenCV)"), Code(2.0, "edge_aware", "edge-aware (OpenCV)"),
                                 Code(3.0, "vng", "VNG (OpenCV)"))),
    "jpeg_quality": Parameter("jpeg_quality", "1", "JPEG quality 1-100 (the switch jpeg = 0 turns the JPEG round "
                              "trip off)", -1.0, False, lower=1.0, upper=100.0, codes=(Code(-1.0, "profile", "the profile's [isp] jpeg_quality"),)),
    "jpeg_grid_offset_u_px": Parameter("jpeg_grid_offset_u_px", "px", "the JPEG block grid moved right by this "
                                       "many pixels against the image, added to the profile's (0-15)", 0.0, False,
                                       lower=0.0, upper=15.0),
    "jpeg_grid_offset_v_px": Parameter("jpeg_grid_offset_v_px", "px", "the JPEG block grid moved down by this "
                                       "many pixels against the image, added to the profile's (0-15)", 0.0, False,
                                       lower=0.0, upper=15.0),
    **{k: GEOMETRIC_PARAMETERS[k] for k in TRUTH_KEYS},
    # the lab's air (svgs_sim.sim.turbulence), per exposure
    "turbulence_cn2": Parameter("turbulence_cn2", "m^-2/3", "C_n^2 of the air between the phone and the target: "
                                "each exposure's spots moved by a frozen draw of their angles of arrival "
                                "(svgs_sim.sim.turbulence; 0: still air)", 0.0, False, lower=0.0, upper=1e-9),
    # the physics a sensitivity study varies ('profile': the profile's value)
    "f_number": Parameter("f_number", "1", "the lens' f-number, for the render (aperture) and the PSF", -1.0, True,
                          lower=1.0, upper=16.0, codes=(Code(-1.0, "profile", "the profile's [optics] f_number"),)),
    "led_offset_scale": Parameter("led_offset_scale", "1", "every flash LED's offset from the lens scaled by this "
                                  "factor (the retro spots' parallax and the return's angle)", 1.0, True, lower=0.0,
                                  upper=5.0, lower_open=True),
    "glare_veiling_fraction": Parameter("glare_veiling_fraction", "1", "share of the light in the lens' glare wings",
                                        -1.0, False, lower=0.0, upper=0.5,
                                        codes=(Code(-1.0, "profile", "the profile's [glare] veiling_fraction"),)),
    "glare_wing_exponent": Parameter("glare_wing_exponent", "1", "the glare wings fall as r^-exponent", -1.0, False,
                                     lower=1.0, upper=10.0, lower_open=True,
                                     codes=(Code(-1.0, "profile", "the profile's [glare] wing_exponent"),)),
    "exposure_compensation_ev": Parameter("exposure_compensation_ev", "EV", "the exposure time the phone chooses "
                                          "(or is forced to) times 2^EV, the gain kept", 0.0, False, lower=-4.0,
                                          upper=4.0),
}


#: The error-budget switches (1: the source on, the default).
SOURCE_SWITCHES = ("sensor_noise", "glare", "quantise", "cfa", "nr", "sharpen", "chroma", "jpeg")


#: The ``demosaic`` parameter's codes.
DEMOSAIC_CODES = {0.0: None, 1.0: "bilinear", 2.0: "edge_aware", 3.0: "vng"}


RENDER_OUTPUTS = (
    "ok", "reason", "message", "n_blobs",
    *(f"true_{k}" for k in STATE_KEYS),
    *(f"est_{k}" for k in STATE_KEYS),
    *ERR_KEYS, POS_ERR_NORM_M, ROT_ERR_DEG,
    "residual_rms_px", "chi2", "chi2_dof", "p_value", "p_value_crlb", "min_separation_px",
    *(f"crlb_{k}" for k in STATE_KEYS),
    "merge_margin_dn",
    "centroid_err_rms_px", *(f"cen_{a}_px_{k}" for k in range(4) for a in ("du", "dv")), "crlb_centroid_px",
    *(f"crlb_sensor_{k}" for k in STATE_KEYS),
    "exposure_s_used", "iso_used", "expose_s", "solve_s",
    "match_err_max_px", "stray_px", "stray_saturated_px", "outside_test_envelope",
    "paper_gates_reported", "paper_gates_match_err_max_px",
)


#: Outputs that are timings (they differ from run to run; every other output is reproducible).
RENDER_TIMING_OUTPUTS = ("expose_s", "solve_s")


def check_threshold(text) -> str:
    """A threshold option: ``app`` (None), ``auto``, ``otsu`` or a positive level (as text);
    :class:`InputError` otherwise."""
    from svgs_sim.svgs.detect import parse_threshold

    v = parse_threshold(None if text is None else str(text).strip())
    return "app" if v is None else v if isinstance(v, str) else repr(v)


def threshold_parameter(text) -> float:
    """The ``threshold`` scenario value of a threshold option (``app`` or None: 0, ``otsu``: -1,
    ``auto``: -2, a level: itself)."""
    t = check_threshold(text)
    named = {"app": THRESHOLD_APP, "auto": THRESHOLD_AUTO, "otsu": THRESHOLD_OTSU}
    return named[t] if t in named else float(t)


def _threshold(value: float):
    """The detector's ``threshold`` argument of a scenario value (None: the app's)."""
    v = float(value)
    if v == THRESHOLD_APP:
        return None
    if v == THRESHOLD_AUTO:
        return "auto"
    if v == THRESHOLD_OTSU:
        return "otsu"
    if v < 0:
        raise InputError(f"threshold: expected {RENDER_PARAMETERS['threshold'].domain()}")
    return v


@dataclass(frozen=True, eq=False)
class RenderScenario(PoseScenario):
    """A ``render`` trial's scenario (:data:`RENDER_PARAMETERS`; the row view, the pose, the
    stand and the solver's calibration errors: :class:`svgs_sim.sim.trials.TrialScenario`,
    :class:`svgs_sim.sim.trials.PoseScenario`). None: the profile's, the renderer's or the phone's own
    value (the row holds the old sentinel: -1, or 0 for ``exposure_s`` and ``iso``).

    Attributes
    ----------
    scene : svgs_sim.sim.scene.Scene
        The scene around the target (its trial parameters are row columns of their own,
        :func:`svgs_sim.sim.scene.scene_parameters`).
    spp, roi_spp : int or None
        Samples per pixel of the full frame and the spot windows (None: the renderer's).
    render_seed : int
    pattern_scale, target_scale : float
        The pattern scaled about its origin; the target's flux multiplied (an ND filter).
    exposure_s, iso : float or None
        Forced on the phone (None: its auto-exposure).
    threshold : None, float, "otsu" or "auto"
        The detector's threshold (None: the app's for the camera; row 0, -1, -2 or the level).
    lens_pp_u_px, lens_pp_v_px, lens_k1 : float
        The true lens' departures from the profile.
    sensor_noise, glare, quantise, cfa, nr, sharpen, chroma, jpeg : bool
        Error sources (True: on).
    demosaic : str or None
        ``"bilinear"``, ``"edge_aware"`` or ``"vng"`` (None: the profile's; row 0-3).
    jpeg_quality : int or None
        JPEG quality 1-100 (None: the profile's).
    jpeg_grid_offset_u_px, jpeg_grid_offset_v_px : int
    turbulence_cn2 : float
    f_number : float or None
        The lens' f-number (None: the profile's).
    led_offset_scale : float
    glare_veiling_fraction, glare_wing_exponent : float or None
        The lens' glare (None: the profile's).
    exposure_compensation_ev : float
    """

    scene: Scene = Scene()
    spp: int | None = None
    roi_spp: int | None = None
    render_seed: int = 0
    pattern_scale: float = 1.0
    target_scale: float = 1.0
    exposure_s: float | None = None
    iso: float | None = None
    threshold: float | str | None = None
    lens_pp_u_px: float = 0.0
    lens_pp_v_px: float = 0.0
    lens_k1: float = 0.0
    sensor_noise: bool = True
    glare: bool = True
    quantise: bool = True
    cfa: bool = True
    nr: bool = True
    sharpen: bool = True
    chroma: bool = True
    jpeg: bool = True
    demosaic: str | None = None
    jpeg_quality: int | None = None
    jpeg_grid_offset_u_px: int = 0
    jpeg_grid_offset_v_px: int = 0
    turbulence_cn2: float = 0.0
    f_number: float | None = None
    led_offset_scale: float = 1.0
    glare_veiling_fraction: float | None = None
    glare_wing_exponent: float | None = None
    exposure_compensation_ev: float = 0.0

    KIND: ClassVar[str] = "render"
    _PARTS: ClassVar[dict] = {"scene": Scene}
    _OPTIONAL: ClassVar[dict] = {"spp": -1.0, "roi_spp": -1.0, "exposure_s": 0.0,
                                 "iso": 0.0, "jpeg_quality": -1.0, "f_number": -1.0, "glare_veiling_fraction": -1.0,
                                 "glare_wing_exponent": -1.0}
    _INTS: ClassVar[tuple] = ("spp", "roi_spp", "render_seed", "jpeg_quality", "jpeg_grid_offset_u_px",
                              "jpeg_grid_offset_v_px")
    _BOOLS: ClassVar[tuple] = (*TRUTH_KEYS, *SOURCE_SWITCHES)

    @classmethod
    def _decode(cls, values: dict) -> dict:
        values = dict(values)
        thr, dem = values.pop("threshold"), values.pop("demosaic")
        if dem != int(dem):
            raise InputError(f"demosaic: expected an integer, got {dem!r}")
        out = super()._decode(values)
        out["threshold"], out["demosaic"] = _threshold(thr), DEMOSAIC_CODES[float(dem)]
        return out

    def _row_value(self, key: str) -> float:
        if key == "threshold":
            return threshold_parameter("app" if self.threshold is None else self.threshold)
        if key == "demosaic":
            codes = {v: k for k, v in DEMOSAIC_CODES.items()}
            if self.demosaic not in codes:
                raise InputError(f"demosaic: expected one of {sorted(c for c in codes if c)} or None, got "
                                 f"{self.demosaic!r}")
            return codes[self.demosaic]
        return super()._row_value(key)

    def _normalise(self) -> None:
        thr = self.threshold
        if thr is not None:  # "app", "otsu", "auto", a level or the row's code: None, a name or a level
            object.__setattr__(self, "threshold", _threshold(threshold_parameter(thr) if isinstance(thr, str) else thr))
        super()._normalise()

    def _validate(self, row: dict) -> None:
        super()._validate(row)
        if self.roi_spp == 0:
            raise InputError("roi_spp: expected >= 1 (or None: the renderer's default), got 0")
        if self.jpeg_quality == 0:
            raise InputError("jpeg_quality: expected 1-100 (or None: the profile's), got 0 (the JPEG is switched off "
                             "with jpeg = 0)")
        if self.f_number is not None and self.f_number < 1.0:
            raise InputError(f"f_number: expected an f-number >= 1 (or None: the profile's), got {self.f_number:g}")
        if self.glare_wing_exponent is not None and self.glare_wing_exponent <= 1.0:
            raise InputError(f"glare_wing_exponent: expected > 1 (or None: the profile's), got "
                             f"{self.glare_wing_exponent:g}")
        if self.glare_veiling_fraction is not None and self.glare_veiling_fraction < 0:
            raise InputError(f"glare_veiling_fraction: expected 0 to 0.5 (or None: the profile's), got "
                             f"{self.glare_veiling_fraction:g}")


@dataclass(frozen=True)
class RenderKey:
    """What decides a ``render`` trial's rendered flux (hashable; see the module docstring):
    trials with equal keys share one render."""

    camera: str
    pattern: str
    pattern_scale: float
    pose: tuple
    lens_pp_u_px: float
    lens_pp_v_px: float
    lens_k1: float
    f_number: float | None
    led_offset_scale: float
    scene: Scene
    spp: int | None
    roi_spp: int | None
    render_seed: int

    @classmethod
    def of(cls, scenario: RenderScenario) -> "RenderKey":
        return cls(**{f.name: getattr(scenario, f.name) for f in dataclasses.fields(cls) if f.name != "pose"},
                   pose=tuple(scenario.pose_kwargs().items()))

    def scenario(self):
        """The :class:`svgs_sim.sim.closed_loop.Scenario` to render (the pattern scaled as an object,
        :meth:`svgs_sim.base.profiles.Pattern.scaled`)."""

        return Scenario(camera=self.camera, pattern=load_pattern(self.pattern).scaled(self.pattern_scale),
                        **dict(self.pose), lens_pp_offset_px=(self.lens_pp_u_px, self.lens_pp_v_px),
                        lens_k1=self.lens_k1,
                        camera_overrides=camera_overrides(self.camera, self.f_number, self.led_offset_scale),
                        scene=self.scene, spp=self.spp, roi_spp=self.roi_spp)


def render_trial_scenario(labels: dict | None = None, **values) -> RenderScenario:
    """A complete, validated ``render`` scenario: defaults filled in, domains checked.

    Parameters
    ----------
    labels : dict, optional
        Extra keys carried into the rows unchanged (``pose_index``, ``trial``, ``remedy``...).
    **values
        Row values: ``camera`` (required), ``pattern`` (default ``svgs-3u``) and
        :data:`RENDER_PARAMETERS` (numbers with the row's sentinels; ``threshold`` as a number,
        see :func:`threshold_parameter`); an unknown key is an :class:`InputError`.

    Returns
    -------
    RenderScenario
    """
    return RenderScenario.from_values(values, labels)


def render_key(scenario) -> RenderKey:
    """What decides the rendered flux (see the module docstring)."""
    return RenderKey.of(RenderScenario.from_row(scenario))


def camera_overrides(camera: str, f_number: float | None, led_offset_scale: float) -> tuple:
    """The profile values a scenario replaces (:attr:`svgs_sim.sim.closed_loop.Scenario.camera_overrides`);
    ``f_number`` None: the profile's."""
    out = []
    if f_number is not None:
        out.append(("optics", "f_number", float(f_number)))
    if led_offset_scale != 1.0:

        leds = load_camera(camera).flash.led_offsets_m or ()
        out.append(("flash", "led_offsets_m", [[float(x) * led_offset_scale for x in led] for led in leds]))
    return tuple((t, k, tuple(map(tuple, v)) if isinstance(v, list) else v) for t, k, v in out)
