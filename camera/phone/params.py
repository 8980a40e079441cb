"""Phone camera model parameters, read from the camera profile's optional tables.

Tables (all optional; a missing key takes the documented default, marked ASSUMPTION)::

    [sensor]                      # EMVA 1288 linear model
    pixel_pitch_m = 1.4e-6
    qe = 0.5                      # mean quantum efficiency in the band (e-/photon)
    full_well_e = 6000.0          # saturation capacity (e-)
    read_noise_e = 3.0            # temporal dark noise sigma_d (e-)
    dark_current_e_s = 10.0       # mean dark current at the operating temperature (e-/s)
    dsnu_e = 1.0                  # dark-signal non-uniformity, sigma over pixels (e-)
    prnu = 0.007                  # photo-response non-uniformity, sigma (fraction)
    adc_bits = 10
    black_level_dn = 64.0
    base_iso = 100.0              # ISO at which full well maps to the ADC's white level
    anti_blooming_drain = 0.99    # fraction of the charge above full well that is drained
    bloom_direction = "isotropic" # or "column": where the rest spills (charge conserved)
    serial = 1                    # seed of the fixed patterns (DSNU, PRNU): one per camera
    readout_time_s = 0.0          # rolling shutter: top-to-bottom row delay of a frame (0: global)

    [glare]                       # lens PSF = diffraction/aberration core + power-law wings
    aberration_sigma_px = 0.5     # Gaussian blur of the lens besides diffraction
    veiling_fraction = 1e-3       # share of the energy in the power-law wings
    wing_exponent = 2.5           # wings fall as r^-wing_exponent
    wing_core_px = 2.0            # radius below which the wings flatten
    wing_radius_px = 300.0        # support of the wings
    ghosts = []                   # [[fraction, scale, blur_px], ...] images mirrored through the centre

    [exposure]                    # what the phone's camera software did
    mode = "auto"                 # "auto" (metering) or "manual"
    metering = "mean"             # "mean", "center_weighted" or "spot"
    target_level = 0.18           # metered linear level the AE aims at (fraction of white)
    compensation_ev = 0.0         # exposure compensation applied by the app
    min_exposure_s = 1.25e-4
    max_exposure_s = 0.0667       # 1/15 s
    min_iso = 100.0
    max_iso = 800.0
    exposure_s = 0.01             # used when mode = "manual"
    iso = 100.0                   # used when mode = "manual"

    [cfa]                         # colour filter array; absent or pattern = "none": mono
    pattern = "RGGB"              # Bayer layout of the top-left 2 x 2 pixels
    response = [0.5, 1.0, 0.6]    # R, G, B electrons per photon of the flash, relative to qe (G = 1)
    wavelength_nm = [600, 535, 460]  # each channel's mean wavelength (the PSF's Airy pattern)
    demosaic = "bilinear"         # OpenCV: "bilinear", "edge_aware" or "vng"

    [isp]
    gamma = 2.2                   # tone curve: out = in^(1/gamma) (0 = linear)
    output_width = 0              # 0 = full resolution; else downscale (INTER_AREA) to this size
    output_height = 0
    jpeg_quality = 0              # 0 = no JPEG round trip; else 1-100
    jpeg_subsampling = "gray"     # "gray": one luminance plane (tone after luma); "4:4:4" or "4:2:0":
                                  # a colour image (tone per channel), JPEG with that chroma sampling,
                                  # read back as its BT.601 luma
    jpeg_grid_offset_px = [0, 0]  # (x, y): image pixel (u, v) lies at (u + x, v + y) of the JPEG's
                                  # block grid (0-15: the 8 x 8 blocks, 16 x 16 MCUs at 4:2:0)
    nr_sigma_px = 0.0             # noise reduction on the linear image after demosaic (0: none):
    nr_range = 0.0                # Gaussian of this sigma (px), bilateral when nr_range (fraction of
                                  # white) > 0
    sharpen_amount = 0.0          # unsharp mask on the toned image (0: none):
    sharpen_sigma_px = 1.0        # out = in + amount (in - Gaussian_sigma(in))
    stages = ["glare", "cfa", "shot", "dark", "fpn", "read", "bloom", "adc", "nr", "tone", "sharpen", "u8",
              "downscale", "chroma", "jpeg"]

Every value is validated where it enters; a bad one raises :class:`svgs.errors.InputError`
naming ``table.key``.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields

import numpy as np

from svgs.errors import InputError

ALL_STAGES = ("glare", "cfa", "shot", "dark", "fpn", "read", "bloom", "adc", "nr", "tone", "sharpen", "u8", "downscale",
              "chroma", "jpeg")
#: Stages that act on the optical image before the exposure (fixed per :class:`camera.phone.Exposer`).
OPTICS_STAGES = ("glare", "cfa")
#: The sensor's noise sources (off together: a noise-free sensor).
NOISE_STAGES = ("shot", "dark", "fpn", "read")
#: Bayer layouts (the colours of the top-left 2 x 2 block, row by row).
CFA_PATTERNS = ("none", "RGGB", "BGGR", "GRBG", "GBRG")
METERING = ("mean", "center_weighted", "spot")
#: OpenCV's demosaic methods (``cv2.COLOR_Bayer*2BGR``, ``*_EA``, ``*_VNG``).
DEMOSAIC_METHODS = ("bilinear", "edge_aware", "vng")
#: What the ISP delivers and the JPEG encodes: one luminance plane, or a colour image with full
#: (4:4:4) or 2 x 2 subsampled (4:2:0) chroma.
JPEG_SUBSAMPLING = ("gray", "4:4:4", "4:2:0")


def _num(table: str, key: str, value, *, lo=None, hi=None, lo_open=False, integer=False):
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"[{table}] {key}: expected a number, got {value!r}") from None
    if not np.isfinite(v):
        raise InputError(f"[{table}] {key}: expected a finite number, got {value!r}")
    if integer and not float(v).is_integer():
        raise InputError(f"[{table}] {key}: expected a whole number, got {value!r}")
    if lo is not None and (v < lo or (lo_open and v == lo)):
        raise InputError(f"[{table}] {key}: must be {'>' if lo_open else '>='} {lo}, got {value!r}")
    if hi is not None and v > hi:
        raise InputError(f"[{table}] {key}: must be <= {hi}, got {value!r}")
    return int(v) if integer else v


def _unknown(table: str, given: dict, cls) -> None:
    names = {f.name for f in fields(cls)}
    extra = set(given) - names
    if extra:
        raise InputError(f"[{table}]: unknown key(s) {sorted(extra)}; known: {sorted(names)}")


@dataclass(frozen=True)
class SensorParams:
    pixel_pitch_m: float = 1.4e-6
    qe: float = 0.5
    full_well_e: float = 6000.0
    read_noise_e: float = 3.0
    dark_current_e_s: float = 10.0
    dsnu_e: float = 1.0
    prnu: float = 0.007
    adc_bits: int = 10
    black_level_dn: float = 64.0
    base_iso: float = 100.0
    anti_blooming_drain: float = 0.99
    bloom_direction: str = "isotropic"
    serial: int = 1
    readout_time_s: float = 0.0

    @property
    def white_dn(self) -> float:
        return float(2**self.adc_bits - 1)

    def gain_dn_per_e(self, iso: float) -> float:
        """Overall system gain K (DN/e-) at an ISO: full well maps to white at base ISO."""
        return (self.white_dn - self.black_level_dn) / self.full_well_e * (iso / self.base_iso)

    @classmethod
    def from_table(cls, t: dict | None, *, allow_sensor_keys=("pixel_pitch_m",)) -> "SensorParams":
        t = dict(t or {})
        _unknown("sensor", t, cls)
        kw = {}
        T = "sensor"
        if "pixel_pitch_m" in t:
            kw["pixel_pitch_m"] = _num(T, "pixel_pitch_m", t["pixel_pitch_m"], lo=0, lo_open=True)
        if "qe" in t:
            kw["qe"] = _num(T, "qe", t["qe"], lo=0, lo_open=True, hi=1)
        for k in ("full_well_e", "base_iso"):
            if k in t:
                kw[k] = _num(T, k, t[k], lo=0, lo_open=True)
        for k in ("read_noise_e", "dark_current_e_s", "dsnu_e", "prnu", "black_level_dn", "readout_time_s"):
            if k in t:
                kw[k] = _num(T, k, t[k], lo=0)
        if "adc_bits" in t:
            kw["adc_bits"] = _num(T, "adc_bits", t["adc_bits"], lo=1, hi=16, integer=True)
        if "anti_blooming_drain" in t:
            kw["anti_blooming_drain"] = _num(T, "anti_blooming_drain", t["anti_blooming_drain"], lo=0, hi=1)
        if "bloom_direction" in t:
            if t["bloom_direction"] not in ("isotropic", "column"):
                raise InputError(f"[sensor] bloom_direction: expected 'isotropic' or 'column', got {t['bloom_direction']!r}")
            kw["bloom_direction"] = t["bloom_direction"]
        if "serial" in t:
            kw["serial"] = _num(T, "serial", t["serial"], lo=0, integer=True)
        p = cls(**kw)
        if p.black_level_dn >= p.white_dn:
            raise InputError(f"[sensor] black_level_dn ({p.black_level_dn}) must be below the ADC white level ({p.white_dn})")
        return p


@dataclass(frozen=True)
class GlareParams:
    aberration_sigma_px: float = 0.5
    veiling_fraction: float = 1e-3
    wing_exponent: float = 2.5
    wing_core_px: float = 2.0
    wing_radius_px: float = 300.0
    ghosts: tuple = ()

    @classmethod
    def from_table(cls, t: dict | None) -> "GlareParams":
        t = dict(t or {})
        _unknown("glare", t, cls)
        T = "glare"
        kw = {}
        if "aberration_sigma_px" in t:
            kw["aberration_sigma_px"] = _num(T, "aberration_sigma_px", t["aberration_sigma_px"], lo=0)
        if "veiling_fraction" in t:
            kw["veiling_fraction"] = _num(T, "veiling_fraction", t["veiling_fraction"], lo=0, hi=0.999)
        if "wing_exponent" in t:
            kw["wing_exponent"] = _num(T, "wing_exponent", t["wing_exponent"], lo=1.0, lo_open=True, hi=10)
        if "wing_core_px" in t:
            kw["wing_core_px"] = _num(T, "wing_core_px", t["wing_core_px"], lo=0, lo_open=True)
        if "wing_radius_px" in t:
            kw["wing_radius_px"] = _num(T, "wing_radius_px", t["wing_radius_px"], lo=1)
        if "ghosts" in t:
            gh = []
            for i, g in enumerate(t["ghosts"] or []):
                if not isinstance(g, (list, tuple)) or len(g) != 3:
                    raise InputError(f"[glare] ghosts[{i}]: expected [fraction, scale, blur_px], got {g!r}")
                gh.append((_num(T, f"ghosts[{i}].fraction", g[0], lo=0, hi=0.5),
                           _num(T, f"ghosts[{i}].scale", g[1]),
                           _num(T, f"ghosts[{i}].blur_px", g[2], lo=0)))
            kw["ghosts"] = tuple(gh)
        return cls(**kw)


@dataclass(frozen=True)
class ExposureParams:
    mode: str = "auto"
    metering: str = "mean"
    target_level: float = 0.18
    compensation_ev: float = 0.0
    min_exposure_s: float = 1.25e-4
    max_exposure_s: float = 1.0 / 15.0
    min_iso: float = 100.0
    max_iso: float = 800.0
    exposure_s: float = 0.01
    iso: float = 100.0

    @classmethod
    def from_table(cls, t: dict | None) -> "ExposureParams":
        t = dict(t or {})
        _unknown("exposure", t, cls)
        T = "exposure"
        kw = {}
        if "mode" in t:
            if t["mode"] not in ("auto", "manual"):
                raise InputError(f"[exposure] mode: expected 'auto' or 'manual', got {t['mode']!r}")
            kw["mode"] = t["mode"]
        if "metering" in t:
            if t["metering"] not in METERING:
                raise InputError(f"[exposure] metering: expected one of {METERING}, got {t['metering']!r}")
            kw["metering"] = t["metering"]
        if "target_level" in t:
            kw["target_level"] = _num(T, "target_level", t["target_level"], lo=0, lo_open=True, hi=1)
        if "compensation_ev" in t:
            kw["compensation_ev"] = _num(T, "compensation_ev", t["compensation_ev"], lo=-10, hi=10)
        for k in ("min_exposure_s", "max_exposure_s", "exposure_s", "min_iso", "max_iso", "iso"):
            if k in t:
                kw[k] = _num(T, k, t[k], lo=0, lo_open=True)
        p = cls(**kw)
        if p.min_exposure_s > p.max_exposure_s:
            raise InputError(f"[exposure] min_exposure_s ({p.min_exposure_s}) exceeds max_exposure_s ({p.max_exposure_s})")
        if p.min_iso > p.max_iso:
            raise InputError(f"[exposure] min_iso ({p.min_iso}) exceeds max_iso ({p.max_iso})")
        return p


@dataclass(frozen=True)
class CfaParams:
    """The colour filter array over the pixels (``pattern = "none"``: a mono sensor).

    ``response`` is, per channel (R, G, B), the photoelectrons a pixel of that colour
    collects from the flash's white light relative to the mono model's ``qe`` (which is the
    green pixel's: G = 1); the ISP's white balance divides by it, so a white scene gives equal
    R, G, B and the luminance the mono model gives, and a saturated one stays white. ``wavelength_nm`` is each channel's mean wavelength: the PSF's Airy pattern
    is drawn at it.
    """

    pattern: str = "none"
    response: tuple = (0.5, 1.0, 0.6)
    wavelength_nm: tuple = (600.0, 535.0, 460.0)
    demosaic: str = "bilinear"

    @property
    def enabled(self) -> bool:
        return self.pattern != "none"

    @classmethod
    def from_table(cls, t: dict | None) -> "CfaParams":
        t = dict(t or {})
        _unknown("cfa", t, cls)
        kw = {}
        if "pattern" in t:
            if t["pattern"] not in CFA_PATTERNS:
                raise InputError(f"[cfa] pattern: expected one of {CFA_PATTERNS}, got {t['pattern']!r}")
            kw["pattern"] = t["pattern"]
        for k, lo, hi in (("response", 0.0, 1.0), ("wavelength_nm", 300.0, 1100.0)):
            if k in t:
                v = t[k]
                if not isinstance(v, (list, tuple)) or len(v) != 3:
                    raise InputError(f"[cfa] {k}: expected [R, G, B], got {v!r}")
                kw[k] = tuple(_num("cfa", f"{k}[{i}]", x, lo=lo, hi=hi, lo_open=True) for i, x in enumerate(v))
        if "demosaic" in t:
            kw["demosaic"] = check_demosaic(t["demosaic"], "[cfa] demosaic")
        return cls(**kw)


@dataclass(frozen=True)
class IspParams:
    """The ISP after the readout (see the module docstring's ``[isp]`` table).

    ``jpeg_subsampling``: ``"gray"``, the ISP delivers the luminance (white-balanced linear
    channels -> BT.601 luma -> tone curve) and the JPEG codes that one plane; ``"4:4:4"`` or
    ``"4:2:0"``, it delivers a colour image (the tone curve on each channel), the JPEG codes it
    in YCbCr with full or 2 x 2 subsampled chroma, and the app reads the decoded image's BT.601
    luma. ``jpeg_grid_offset_px``: image pixel ``(u, v)`` sits at ``(u + x, v + y)`` of the
    JPEG's block grid (what moves the 8 x 8 blocks against the spots without moving the spots).
    ``nr_sigma_px`` > 0: noise reduction of the linear image (after the demosaic, before the tone
    curve): a Gaussian of that sigma, bilateral with range sigma ``nr_range`` (fraction of white)
    when that is > 0. ``sharpen_amount`` > 0: an unsharp mask of the toned image's luminance,
    ``out = in + amount (in - G_sigma * in)``.
    """

    gamma: float = 2.2
    output_width: int = 0
    output_height: int = 0
    jpeg_quality: int = 0
    jpeg_subsampling: str = "gray"
    jpeg_grid_offset_px: tuple = (0, 0)
    nr_sigma_px: float = 0.0
    nr_range: float = 0.0
    sharpen_amount: float = 0.0
    sharpen_sigma_px: float = 1.0
    stages: tuple = ALL_STAGES

    @classmethod
    def from_table(cls, t: dict | None) -> "IspParams":
        t = dict(t or {})
        _unknown("isp", t, cls)
        T = "isp"
        kw = {}
        if "gamma" in t:
            kw["gamma"] = _num(T, "gamma", t["gamma"], lo=0, hi=10)
        for k in ("output_width", "output_height"):
            if k in t:
                kw[k] = _num(T, k, t[k], lo=0, integer=True)
        if "jpeg_quality" in t:
            kw["jpeg_quality"] = _num(T, "jpeg_quality", t["jpeg_quality"], lo=0, hi=100, integer=True)
        if "jpeg_subsampling" in t:
            kw["jpeg_subsampling"] = check_subsampling(t["jpeg_subsampling"], "[isp] jpeg_subsampling")
        if "jpeg_grid_offset_px" in t:
            kw["jpeg_grid_offset_px"] = check_grid_offset(t["jpeg_grid_offset_px"], "[isp] jpeg_grid_offset_px")
        for k, hi in (("nr_sigma_px", 20.0), ("nr_range", 1.0), ("sharpen_amount", 10.0)):
            if k in t:
                kw[k] = _num(T, k, t[k], lo=0, hi=hi)
        if "sharpen_sigma_px" in t:
            kw["sharpen_sigma_px"] = _num(T, "sharpen_sigma_px", t["sharpen_sigma_px"], lo=0, lo_open=True, hi=20.0)
        if "stages" in t:
            kw["stages"] = check_stages(t["stages"], "[isp] stages")
        p = cls(**kw)
        if (p.output_width == 0) != (p.output_height == 0):
            raise InputError("[isp] output_width and output_height must both be 0 (full resolution) or both set")
        return p


def check_demosaic(method, name="demosaic") -> str:
    """A demosaic method of :data:`DEMOSAIC_METHODS` (:class:`InputError` naming ``name`` otherwise)."""
    if method not in DEMOSAIC_METHODS:
        raise InputError(f"{name}: expected one of {', '.join(DEMOSAIC_METHODS)}, got {method!r}")
    return str(method)


def check_subsampling(value, name="jpeg_subsampling") -> str:
    """A JPEG chroma sampling of :data:`JPEG_SUBSAMPLING` (:class:`InputError` naming ``name`` otherwise)."""
    if value not in JPEG_SUBSAMPLING:
        raise InputError(f"{name}: expected one of {', '.join(JPEG_SUBSAMPLING)}, got {value!r}")
    return str(value)


def check_grid_offset(value, name="jpeg_grid_offset_px") -> tuple:
    """``(x, y)``, whole pixels 0-15: where the image's top-left pixel sits in the JPEG's block
    grid (:class:`InputError` naming ``name`` otherwise)."""
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        raise InputError(f"{name}: expected [x, y], got {value!r}")
    out = []
    for v in value:
        try:
            f = float(v)
        except (TypeError, ValueError):
            raise InputError(f"{name}: expected whole pixels 0-15, got {value!r}") from None
        if not (np.isfinite(f) and f.is_integer() and 0 <= f <= 15):
            raise InputError(f"{name}: expected whole pixels 0-15, got {value!r}")
        out.append(int(f))
    return tuple(out)


def check_stages(stages, name="stages") -> tuple:
    """Validate a list of pipeline stage names."""
    if isinstance(stages, str):
        stages = [s for s in stages.split(",") if s]
    out = []
    for s in stages:
        if s not in ALL_STAGES:
            raise InputError(f"{name}: unknown stage {s!r}; known stages: {', '.join(ALL_STAGES)}")
        out.append(s)
    return tuple(out)


@dataclass(frozen=True)
class PhoneParams:
    """Everything the phone camera model needs besides the geometry."""

    sensor: SensorParams = field(default_factory=SensorParams)
    glare: GlareParams = field(default_factory=GlareParams)
    exposure: ExposureParams = field(default_factory=ExposureParams)
    isp: IspParams = field(default_factory=IspParams)
    cfa: CfaParams = field(default_factory=CfaParams)
    f_number: float = 2.4
    band_nm: tuple = (400.0, 700.0)

    @classmethod
    def from_camera(cls, camera) -> "PhoneParams":
        """Read the tables of a :class:`svgs.Camera` (missing tables take the defaults)."""
        tabs = camera.tables
        optics = tabs.get("optics", {}) or {}
        f_number = _num("optics", "f_number", optics.get("f_number", 2.4), lo=0, lo_open=True)
        band = tuple(optics.get("band_nm", (400.0, 700.0)))
        return cls(
            sensor=SensorParams.from_table(tabs.get("sensor")),
            glare=GlareParams.from_table(tabs.get("glare")),
            exposure=ExposureParams.from_table(tabs.get("exposure")),
            isp=IspParams.from_table(tabs.get("isp")),
            cfa=CfaParams.from_table(tabs.get("cfa")),
            f_number=f_number,
            band_nm=band,
        )

    def to_dict(self) -> dict:
        return asdict(self)
