"""The ``render`` trial kind: Mitsuba render -> phone exposure -> SVGS solve.

Registers with :mod:`svgs_sim.sim.trials`, so ``svgs campaign --trial-kind render`` and
``svgs sensitivity --trial-kind render`` run the full physical chain, and
``svgs_sim.studies.range_sweep`` and ``svgs_sim.studies.exposure_study`` build its scenarios (with
:func:`render_trial_scenario`). A trial is :func:`svgs_sim.sim.closed_loop.render_scenario` (Mitsuba, the
lab light) followed by :func:`svgs_sim.sim.closed_loop.expose_and_solve` (phone model, detector,
solver), exactly the chain of ``svgs render-and-solve``.

Render once, expose many
    The render key is everything that decides the rendered flux: camera, pattern and its
    scale, pose, lab, samples per pixel and the render's own Monte Carlo seed
    (``render_seed``, a scenario parameter, so trials sharing a render agree on it). What acts
    after the render - the noise draw (the trial's seed), a forced exposure or ISO, a
    neutral-density filter over the reflectors (``target_scale``), the detector threshold,
    the calibration the solver uses - varies within a render group. A trial's numbers depend
    only on its scenario and seed, whether it runs alone or in a group.

Scenario keys
    Text: ``camera``, ``pattern`` (name or path). Numbers: :data:`RENDER_PARAMETERS` (the
    defaults are a render with seed 0 of the pattern as it is, no ND filter, the renderer's
    samples per pixel, the phone's auto-exposure, the app's brightness threshold (svgs_sim.svgs.app) and the exact
    calibration). With ``stand = 1`` the angles turn the phone on the test stand
    (:mod:`svgs_sim.sim.stand`); ``lens_*`` make the true lens differ from the profile (the solver's
    ``*_error`` are relative to it); ``sensor_noise``, ``glare``, ``quantise``, ``cfa``, ``nr``,
    ``sharpen``, ``chroma``, ``jpeg`` switch error sources off and ``truth_actual``,
    ``truth_stand``, ``truth_rail`` take the errors against the pose with the phone's
    misalignment, the stand's errors (``stand_err_*``) or the rail's (``rail_err_m``) included (the
    campaign's error budget); ``turbulence_cn2`` moves each exposure's spots through the lab's air
    (:func:`turbulent_points`); ``demosaic``,
    ``jpeg_quality`` and ``jpeg_grid_offset_*_px`` choose the ISP's demosaic and JPEG;
    ``f_number``, ``led_offset_scale``, ``glare_*``, ``exposure_compensation_ev`` are the physics
    a sensitivity study varies. Studies add labels (``nominal_range_m``, ``pose_index``,
    ``trial``, ``remedy``...) carried into the rows unchanged.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from svgs_sim.sim.scene import Scene, scene_parameters
from svgs_sim.sim.metrics import (
    ATT_ERR_VEC_DEG,
    ERR_KEYS,
    POS_ERR_NORM_M,
    POS_ERR_VEC_M,
    ROT_ERR_DEG,
)
from svgs_sim.sim.trials import (
    GEOMETRIC_PARAMETERS,
    POSE_KEYS,
    TRUTH_KEYS,
    Parameter,
    PoseScenario,
    TrialKind,
    camera_with_calibration_errors,
    register_trial_kind,
)
from svgs_sim.base.errors import InputError
from svgs_sim.svgs.frames import STATE_KEYS
from svgs_sim.base.limits import INPUT_BOUNDS, MAX_SEED, MAX_SPP, bounds

_POSE = POSE_KEYS

#: ``threshold`` values that are not levels (the parameter is numeric, so a sensitivity study can vary it):
#: 0 the app's brightness threshold for the camera (:mod:`svgs_sim.svgs.app`, the default), -1 Otsu's, -2 the
#: automatic rule.
THRESHOLD_APP, THRESHOLD_OTSU, THRESHOLD_AUTO = 0.0, -1.0, -2.0

RENDER_PARAMETERS = {
    **{k: GEOMETRIC_PARAMETERS[k] for k in _POSE},
    **scene_parameters(),  # the scene around the target, declared once (svgs_sim.sim.scene)
    "spp": Parameter("spp", "1", "samples per pixel of the full frame (-1: the renderer's default)", -1.0, True,
                     lower=-1.0, upper=MAX_SPP),
    "roi_spp": Parameter("roi_spp", "1", "samples per pixel in the spot windows (-1: the renderer's default)", -1.0,
                         True, lower=-1.0, upper=MAX_SPP),
    "render_seed": Parameter("render_seed", "1", "seed of the render's Monte Carlo sampling", 0.0, True, lower=0.0,
                              upper=MAX_SEED),
    "pattern_scale": Parameter("pattern_scale", "1", "the pattern scaled about its origin by this factor (a wider target)",
                               1.0, True, lower=0.0, upper=10.0, lower_open=True),
    "target_scale": Parameter("target_scale", "1", "multiplies the target's flux, not the lab's (an ND filter of "
                              "transmission T over every reflector: T**2)", 1.0, False, lower=0.0, upper=1.0,
                              lower_open=True),
    "exposure_s": Parameter("exposure_s", "s", "exposure time forced on the phone (0: the phone's auto-exposure)", 0.0,
                            False, **bounds("exposure_s")),
    "iso": Parameter("iso", "ISO", "sensitivity forced on the phone (0: the phone's auto-exposure)", 0.0, False,
                     lower=0.0, upper=INPUT_BOUNDS["iso"][1]),
    "threshold": Parameter("threshold", "DN", "detector threshold in 8-bit counts (0: the app's for the camera, "
                           "svgs_sim.svgs.app; -1: Otsu's; -2: the automatic rule)", 0.0, False, lower=-2.0, upper=255.0),
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
    "demosaic": Parameter("demosaic", "1", "the ISP's demosaic: 0 the profile's ([cfa] demosaic), 1 bilinear, "
                          "2 edge-aware, 3 VNG (OpenCV)", 0.0, False, lower=0.0, upper=3.0),
    "jpeg_quality": Parameter("jpeg_quality", "1", "JPEG quality 1-100 (-1: the profile's [isp] jpeg_quality)", -1.0,
                              False, lower=-1.0, upper=100.0),
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
    # the physics a sensitivity study varies (-1: the profile's value)
    "f_number": Parameter("f_number", "1", "the lens' f-number, for the render (aperture) and the PSF (-1: the "
                          "profile's)", -1.0, True, lower=-1.0, upper=16.0),
    "led_offset_scale": Parameter("led_offset_scale", "1", "every flash LED's offset from the lens scaled by this "
                                  "factor (the retro spots' parallax and the return's angle)", 1.0, True, lower=0.0,
                                  upper=5.0, lower_open=True),
    "glare_veiling_fraction": Parameter("glare_veiling_fraction", "1", "share of the light in the lens' glare wings "
                                        "(-1: the profile's)", -1.0, False, lower=-1.0, upper=0.5),
    "glare_wing_exponent": Parameter("glare_wing_exponent", "1", "the glare wings fall as r^-exponent (-1: the "
                                     "profile's)", -1.0, False, lower=-1.0, upper=10.0),
    "exposure_compensation_ev": Parameter("exposure_compensation_ev", "EV", "the exposure time the phone chooses "
                                          "(or is forced to) times 2^EV, the gain kept", 0.0, False, lower=-4.0,
                                          upper=4.0),
}

#: The error-budget switches (1: the source on, the default).
_SOURCE_SWITCHES = ("sensor_noise", "glare", "quantise", "cfa", "nr", "sharpen", "chroma", "jpeg")
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
)

#: Outputs that are timings (they differ from run to run; every other output is reproducible).
RENDER_TIMING_OUTPUTS = ("expose_s", "solve_s")


def merge_margin_dn(image: np.ndarray, targets_px: np.ndarray, threshold: float, step_px: float = 0.25) -> float:
    """How far the spots are from merging at the detector's threshold, image counts.

    For every pair of targets the darkest level of the image along the segment between their
    true positions (bilinear, ``step_px`` apart) is their saddle; ``threshold - saddle`` is the
    pair's margin: positive, the two spots are separate blobs at that threshold; negative, the
    binary image joins them (along that line). Returns the smallest margin over the pairs.

    Parameters
    ----------
    image : ndarray, shape (H, W)
        The delivered image (8-bit or float counts).
    targets_px : ndarray, shape (N, 2)
        True target positions in that image, px.
    threshold : float
        The detector's binarisation level, counts.
    """
    import cv2

    g = np.asarray(image, np.float32)
    if g.ndim == 3:
        g = g.mean(axis=2)
    out = np.inf
    n = len(targets_px)
    for a in range(n):
        for b in range(a + 1, n):
            p, q = np.asarray(targets_px[a], float), np.asarray(targets_px[b], float)
            m = max(2, int(np.ceil(np.linalg.norm(q - p) / step_px)))
            s = np.linspace(0.0, 1.0, m + 1)[1:-1]
            xy = p[None] + s[:, None] * (q - p)[None]
            vals = cv2.remap(g, xy[:, 0].astype(np.float32).reshape(1, -1), xy[:, 1].astype(np.float32).reshape(1, -1),
                             cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)
            out = min(out, float(threshold - vals.min()))
    return float(out)


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
        raise InputError(f"threshold: {v:g} is neither a level (>= 0) nor 0 (app), -1 (otsu) or -2 (auto)")
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
    _BOOLS: ClassVar[tuple] = (*TRUTH_KEYS, *_SOURCE_SWITCHES)

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
        from svgs_sim.sim.closed_loop import Scenario
        from svgs_sim.base.profiles import load_pattern

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
    ``f_number`` None (or the row's -1): the profile's."""
    out = []
    if f_number is not None and f_number != -1:
        out.append(("optics", "f_number", float(f_number)))
    if led_offset_scale != 1.0:
        from svgs_sim.base.profiles import load_camera

        leds = (load_camera(camera).tables.get("flash") or {}).get("led_offsets_m") or []
        out.append(("flash", "led_offsets_m", [[float(x) * led_offset_scale for x in led] for led in leds]))
    return tuple((t, k, tuple(map(tuple, v)) if isinstance(v, list) else v) for t, k, v in out)


@functools.lru_cache(maxsize=2)
def _frame(key: RenderKey):
    from svgs_sim.sim.closed_loop import render_scenario

    return render_scenario(key.scenario(), seed=key.render_seed), {}


def rendered_frame(scenario):
    """The rendered frame of a ``render`` scenario (:class:`svgs_sim.sim.closed_loop.Frame`), from this
    process's render cache: the trials of one render group share it."""
    return _frame(render_key(scenario))[0]


def _glare_key(scenario: RenderScenario) -> tuple:
    """What decides the exposer of a trial (after the render): ND filter, the lens' glare and the
    colour filter array."""
    return (scenario.target_scale, scenario.glare, scenario.glare_veiling_fraction, scenario.glare_wing_exponent,
            scenario.cfa)


def _exposer(frame, cache: dict, key: tuple):
    k = ("exposer", *key)
    if k not in cache:
        ts, glare, veil, expo, cfa = key
        cache[k] = frame.exposer(_stages({"cfa": cfa}), target_scale=ts, glare=glare, veiling_fraction=veil,
                                 wing_exponent=expo)
    return cache[k]


def _stages(scenario) -> tuple:
    """The exposure's stages: every stage, less those the error-budget switches turn off (absent
    switches: on). ``scenario``: a mapping of row values (a scenario's row view)."""
    from svgs_sim.camera.phone import ALL_STAGES, NOISE_STAGES

    off = set()
    if not scenario.get("sensor_noise", 1):
        off |= set(NOISE_STAGES)
    if not scenario.get("quantise", 1):
        off |= {"u8", "jpeg"}
    off |= {k for k in ("cfa", "nr", "sharpen", "chroma", "jpeg") if not scenario.get(k, 1)}
    return tuple(s for s in ALL_STAGES if s not in off)


def _isp(exposer, scenario: RenderScenario) -> tuple:
    """``(isp, demosaic)`` of a trial's exposure: the profile's ``[isp]`` with the scenario's JPEG
    quality and block-grid offset, and its demosaic (None: the profile's)."""
    scenario = RenderScenario.from_row(scenario)
    isp = exposer.phone.params.isp
    q = scenario.jpeg_quality
    ox, oy = isp.jpeg_grid_offset_px
    du, dv = scenario.jpeg_grid_offset_u_px, scenario.jpeg_grid_offset_v_px
    new = dataclasses.replace(isp, jpeg_quality=isp.jpeg_quality if q is None else q,
                              jpeg_grid_offset_px=((ox + du) % 16, (oy + dv) % 16))
    return (isp if new == isp else new), scenario.demosaic


def _sensor_centroid_sigma(frame, exposer, row, cache: dict, key, spots_px) -> float | None:
    """The simulated sensor's centroid bound (RMS over the spots, px; :func:`svgs_sim.sim.crlb.centroid_crlb_px`)
    at the targets' true positions, once per exposer and exposure setting: it depends on the
    render and the exposure, not on the noise draw (so not on which trial of a group asks first).
    None when a spot carries no information."""
    from svgs_sim.sim.crlb import centroid_crlb_px

    k = ("crlb", *key, row["exposure_s"], row["iso"])
    if k not in cache:
        sig = centroid_crlb_px(frame, exposer, row["_exposure"], spots_px)
        cache[k] = float(np.sqrt(np.mean(sig**2))) if np.all(np.isfinite(sig)) else None
    return cache[k]


#: Exposures kept per render group, so that variants judged differently (the solver's
#: calibration, the truth) reuse the same image instead of exposing it again.
_EXPOSURE_CACHE = 12


def turbulent_points(frame, cn2_m23: float, seed: int):
    """The frame's retro-spot samples as one exposure through the lab's air sees them: each
    spot's samples moved by a frozen draw of its angle of arrival (:mod:`svgs_sim.sim.turbulence`; the
    phone's entrance pupil, the spots at the actual pose), seeded by the exposure's seed on a
    stream of its own (the sensor noise's draw unchanged). A sample belongs to the spot whose
    true image point is nearest.

    Returns
    -------
    points : svgs_sim.camera.rendered.PointFlux
    shifts_px : ndarray, shape (N, 2)
        Each target's image motion ``(du, dv)``, px.
    """
    from svgs_sim.camera.rendered import PointFlux
    from svgs_sim.sim.turbulence import image_shifts_px

    cam = frame.camera
    R, t = frame.scenario.pose()
    pat = frame.pattern
    p_cam = pat.points_m @ R.T + t
    optics = cam.tables.get("optics") or {}
    aperture_m = float(optics["focal_length_m"]) / float(optics["f_number"])
    rng = np.random.default_rng([int(seed), 0x7475726E])  # "turn": the air's own stream
    shifts = image_shifts_px(p_cam, cam.fx, aperture_m, float(cn2_m23), rng)
    uv = cam.project_target(pat.points_m, R, t)
    pts = frame.points
    near = np.argmin((pts.u_px[:, None] - uv[None, :, 0]) ** 2 + (pts.v_px[:, None] - uv[None, :, 1]) ** 2, axis=1)
    return PointFlux(pts.u_px + shifts[near, 0], pts.v_px + shifts[near, 1], pts.rate_ph_s), shifts


def _exposure_exposer(frame, exposers: dict, gkey, scenario: RenderScenario, seed: int):
    """The exposer of one exposure: the render group's, or - through turbulent air - one made
    for this exposure's moved spots (its optics redone)."""
    exposer = _exposer(frame, exposers, gkey)
    cn2 = scenario.turbulence_cn2
    if cn2 == 0 or frame.points is None:
        return exposer
    pts, _ = turbulent_points(frame, cn2, seed)
    ts, glare, veil, expo, cfa = gkey
    return dataclasses.replace(frame, points=pts).exposer(_stages({"cfa": cfa}), target_scale=ts, glare=glare,
                                                         veiling_fraction=veil, wing_exponent=expo)


def _exposure(frame, exposers: dict, key, scenario: RenderScenario, seed: int):
    """The exposure of ``(render, seed, stages, setting, air)``, made once per render group."""
    import time

    from collections import OrderedDict

    store = exposers.setdefault("exposures", OrderedDict())
    ev = scenario.exposure_compensation_ev
    isp, demosaic = _isp(_exposer(frame, exposers, key), scenario)
    cn2 = scenario.turbulence_cn2
    k = (key, int(seed), _stages(scenario), scenario.exposure_s, scenario.iso, ev, isp, demosaic, cn2)
    if k in store:
        store.move_to_end(k)
        return store[k], 0.0
    t0 = time.perf_counter()
    exposer = _exposure_exposer(frame, exposers, key, scenario, seed)
    t_s, iso = scenario.exposure_s, scenario.iso
    if ev != 0:  # exposure compensation: the time the phone would choose, times 2^EV
        t_s, iso, _ = exposer.settings(t_s, iso)
        t_s *= 2.0 ** ev
    ex = exposer.expose(seed=int(seed), exposure_s=t_s, iso=iso, stages=_stages(scenario), isp=isp, demosaic=demosaic)
    dt = time.perf_counter() - t0
    store[k] = ex
    while len(store) > _EXPOSURE_CACHE:
        store.popitem(last=False)
    return ex, dt


def _is_baseline(scenario: RenderScenario) -> bool:
    """Every error-budget switch on (the default; the sensor bound is computed for these only)."""
    return all(getattr(scenario, k) for k in _SOURCE_SWITCHES)


def _solve_one(scenario: RenderScenario, seed: int, frame, exposers: dict) -> dict:
    from svgs_sim.sim.closed_loop import solve_exposure, solver_camera
    from svgs_sim.sim.metrics import state_m_deg

    cam = frame.camera  # the true lens
    gkey = _glare_key(scenario)
    exposer = _exposer(frame, exposers, gkey)
    ex, expose_s = _exposure(frame, exposers, gkey, scenario, seed)
    row = solve_exposure(frame, ex, threshold=scenario.threshold,
                         solver_camera_profile=camera_with_calibration_errors(cam, scenario),
                         truth=scenario.truth)
    row["expose_s"] = expose_s
    out = {k: None for k in RENDER_OUTPUTS}
    out.update({k: row[k] for k in ("ok", "reason", "message", "n_blobs", "residual_rms_px", "chi2", "chi2_dof",
                                    "p_value", "expose_s", "solve_s", POS_ERR_NORM_M, ROT_ERR_DEG)})
    out["ok"] = bool(row["ok"])
    out["exposure_s_used"], out["iso_used"] = float(row["exposure_s"]), float(row["iso"])
    out.update({f"true_{k}": v for k, v in row["truth_state"].items()})
    R, t = frame.scenario.pose()
    pat = frame.pattern
    uv = cam.project_target(pat.points_m, R, t)
    d = np.linalg.norm(uv[:, None] - uv[None], axis=-1) + np.eye(len(uv)) * 1e12
    out["min_separation_px"] = float(d.min())
    sol = row["_solution"]
    level = sol.threshold_used if sol else sol.details.get("threshold_used")
    if level is not None:
        img = ex.image
        out["merge_margin_dn"] = merge_margin_dn(img, solver_camera(cam, img.shape).project_target(pat.points_m, R, t),
                                                 float(level))
    if row["state"] is not None:
        out.update({f"est_{k}": v for k, v in row["state"].items()})
        out.update(dict(zip(ERR_KEYS, [*row[POS_ERR_VEC_M], *row[ATT_ERR_VEC_DEG]])))
        # Cramer-Rao 1-sigma for the solver's default centroid noise (0.1 px)
        crlb = state_m_deg(np.sqrt(np.diag(sol.covariance)))
        out.update({f"crlb_{k}": float(v) for k, v in zip(STATE_KEYS, crlb)})
        # the centroids' error: identified centroids against the targets' true projections
        # (the true lens, the actual pose), in the delivered image's pixels
        uv_img = solver_camera(cam, row["_exposure"].image.shape).project_target(pat.points_m, R, t)
        found = np.array([sol.targets_px[i] for i in pat.ids], float)
        out["centroid_err_rms_px"] = float(np.sqrt(np.mean((found - uv_img) ** 2)))
        for k, (du, dv) in enumerate((found - uv_img)[:4]):
            out[f"cen_du_px_{k}"], out[f"cen_dv_px_{k}"] = float(du), float(dv)
        # the bound from the simulated sensor at this exposure (svgs_sim.sim.crlb)
        rms = (_sensor_centroid_sigma(frame, exposer, row, exposers, gkey, uv) if _is_baseline(scenario) and
               frame.points is not None else None)
        if rms is not None:
            from svgs_sim.sim.crlb import pose_crlb

            out["crlb_centroid_px"] = rms
            # the consistency test against the sensor's bound alone (what the residual would be
            # judged by if the centroids were as good as the CRLB): reported, not applied
            from svgs_sim.svgs.app import consistency

            out["p_value_crlb"] = consistency(sol.residual_rms_px, len(pat.ids), sigma_px=rms).p_value
            out.update({f"crlb_sensor_{k}": float(v) for k, v in pose_crlb(sol, rms).items()})
    if out["message"] is not None:
        out["message"] = " ".join(str(out["message"]).split())  # one line (a CSV field)
    return out


def trial_picture(scenario, seed: int) -> dict:
    """What one trial's sensor saw, for pictures (``overlay.png`` panels of the study reports):
    the same render, exposure and solve as :func:`render_trial` (same seeds, same numbers).

    Returns
    -------
    dict
        ``image`` (the delivered image), ``camera`` (the solver's, at the image's size),
        ``pattern``, ``threshold`` and ``row`` (:func:`svgs_sim.sim.closed_loop.solve_exposure`'s row,
        ``_solution`` included).
    """
    from svgs_sim.sim.closed_loop import solve_exposure, solver_camera

    scenario = RenderScenario.from_row(scenario)
    frame, exposers = _frame(RenderKey.of(scenario))
    gkey = _glare_key(scenario)
    ex, _ = _exposure(frame, exposers, gkey, scenario, seed)
    cam_solver = camera_with_calibration_errors(frame.camera, scenario)
    thr = scenario.threshold
    row = solve_exposure(frame, ex, threshold=thr, solver_camera_profile=cam_solver, truth=scenario.truth)
    return {"image": ex.image, "camera": solver_camera(cam_solver, ex.image.shape),
            "pattern": frame.pattern, "threshold": thr, "row": row}


def render_trial(scenario, seed: int) -> dict:
    """One rendered trial: render (or reuse this worker's last render of the same key), expose, solve.

    Parameters
    ----------
    scenario : dict
        ``camera``, ``pattern`` and :data:`RENDER_PARAMETERS` (labels ignored).
    seed : int
        Seeds the exposure's noise draw.

    Returns
    -------
    dict
        :data:`RENDER_OUTPUTS`: ``ok``, ``reason``, ``message``, ``n_blobs``; ``true_*``,
        ``est_*`` (m, deg; the camera's perspective centre in the target frame and the paper's
        attitude) and the errors of :mod:`svgs_sim.sim.metrics` (``err_*``, ``pos_err_norm_m``,
        ``rot_err_deg``; None when unsolved); ``residual_rms_px``; ``min_separation_px``
        (closest pair of true image points); ``merge_margin_dn`` (the detector's threshold minus
        the darkest level between the targets, image counts: negative, the spots join;
        :func:`merge_margin_dn`); ``crlb_*`` (Cramer-Rao 1-sigma for 0.1 px centroid noise, at
        the estimate); ``cen_du_px_k``, ``cen_dv_px_k``, ``centroid_err_rms_px`` (the identified
        centroids of the first four targets minus their true projections, px, in the delivered
        image); ``crlb_centroid_px``, ``crlb_sensor_*`` (the simulated sensor's centroid bound at
        the targets' true positions and the pose bound at this trial's solution, :mod:`svgs_sim.sim.crlb`;
        with every error source on only); ``exposure_s_used``,
        ``iso_used``; ``expose_s``, ``solve_s`` (wall times).
    """
    scenario = RenderScenario.from_row(scenario)
    frame, exposers = _frame(RenderKey.of(scenario))
    return _solve_one(scenario, seed, frame, exposers)


def _exposure_order(scenario: RenderScenario, seed: int) -> tuple:
    """What decides a trial's exposure within its render group (:func:`_exposure`'s key, less
    the exposer's own): trials that judge one image differently (the solver's calibration, the
    truth) sort together, so each exposure is made once however many variants share it."""
    return (repr(_glare_key(scenario)), int(seed), _stages(scenario), scenario["exposure_s"], scenario["iso"],
            scenario["exposure_compensation_ev"], scenario["jpeg_quality"], scenario["jpeg_grid_offset_u_px"],
            scenario["jpeg_grid_offset_v_px"], scenario["demosaic"], scenario["turbulence_cn2"])


def render_group(scenarios, seeds) -> list[dict]:
    """Trials sharing one render key: render once, expose and solve each (in the order that
    shares exposures, :func:`_exposure_order`; the rows come back in the given order - a trial's
    numbers depend only on its scenario and seed)."""
    scenarios = [RenderScenario.from_row(s) for s in scenarios]
    frame, exposers = _frame(RenderKey.of(scenarios[0]))
    order = sorted(range(len(scenarios)), key=lambda i: _exposure_order(scenarios[i], seeds[i]))
    out = [None] * len(scenarios)
    for i in order:
        out[i] = _solve_one(scenarios[i], int(seeds[i]), frame, exposers)
    return out


def _warm_up():
    from svgs_sim.render.variant import select_variant

    select_variant()


RENDER = register_trial_kind(TrialKind(
    name="render",
    run_trial=render_trial,
    outputs=RENDER_OUTPUTS,
    parameters=RENDER_PARAMETERS,
    run_group=render_group,
    render_key=render_key,
    warm_up=_warm_up,
    description="Mitsuba render of the target under the flash (pose, lab, pattern scale), exposures through the "
                "phone model (forced exposure, ND filter), SVGS detector and solver (with calibration errors)",
    module=__name__,
    scenario_type=RenderScenario,
))
