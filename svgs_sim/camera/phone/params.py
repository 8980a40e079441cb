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
    gamma = 2.2                   # tone curve: out = in^(1/gamma) (1 = linear; 0.5-5)
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

Every value is validated against :data:`svgs_sim.base.profile_schema.PHONE_TABLES` (type, physical range,
choices; an unknown key is refused), when the profile is loaded (:meth:`svgs_sim.svgs.Camera.load`, before
any render) and again where a table enters here; a bad one raises :class:`svgs_sim.base.errors.InputError`
naming ``[table] key`` and the allowed range.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

from svgs_sim.base.profile_schema import (  # the allowed values live in svgs, where Camera.load checks them at load
    ALL_STAGES,
    CFA_PATTERNS,
    DEMOSAIC_METHODS,
    JPEG_SUBSAMPLING,
    METERING,
    PHONE_TABLES,
    Stages,
    check_table,
)

#: Stages that act on the optical image before the exposure (fixed per :class:`svgs_sim.camera.phone.Exposer`).
OPTICS_STAGES = ("glare", "cfa")
#: The sensor's noise sources (off together: a noise-free sensor).
NOISE_STAGES = ("shot", "dark", "fpn", "read")

__all__ = ["ALL_STAGES", "CFA_PATTERNS", "DEMOSAIC_METHODS", "JPEG_SUBSAMPLING", "METERING", "OPTICS_STAGES",
           "NOISE_STAGES", "SensorParams", "GlareParams", "ExposureParams", "CfaParams", "IspParams", "PhoneParams",
           "check_demosaic", "check_subsampling", "check_grid_offset", "check_stages"]


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
        """The ``[sensor]`` table checked (:data:`svgs_sim.base.profile_schema.PHONE_TABLES`: type, range,
        choices, unknown keys refused; :class:`InputError` naming ``[sensor] key``); missing keys
        take the defaults above."""
        return cls(**check_table("sensor", t))


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
        """The ``[glare]`` table checked (:data:`svgs_sim.base.profile_schema.PHONE_TABLES`: type, range,
        choices, unknown keys refused; :class:`InputError` naming ``[glare] key``); missing keys
        take the defaults above."""
        return cls(**check_table("glare", t))


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
        """The ``[exposure]`` table checked (:data:`svgs_sim.base.profile_schema.PHONE_TABLES`: type, range,
        choices, unknown keys refused; :class:`InputError` naming ``[exposure] key``); missing keys
        take the defaults above."""
        return cls(**check_table("exposure", t))


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
        """The ``[cfa]`` table checked (:data:`svgs_sim.base.profile_schema.PHONE_TABLES`: type, range,
        choices, unknown keys refused; :class:`InputError` naming ``[cfa] key``); missing keys
        take the defaults above."""
        return cls(**check_table("cfa", t))


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
        """The ``[isp]`` table checked (:data:`svgs_sim.base.profile_schema.PHONE_TABLES`: type, range,
        choices, unknown keys refused; :class:`InputError` naming ``[isp] key``); missing keys
        take the defaults above."""
        return cls(**check_table("isp", t))

def check_demosaic(method, name="demosaic") -> str:
    """A demosaic method of :data:`DEMOSAIC_METHODS` (:class:`InputError` naming ``name`` otherwise)."""
    return PHONE_TABLES["cfa"]["demosaic"].check(method, name)


def check_subsampling(value, name="jpeg_subsampling") -> str:
    """A JPEG chroma sampling of :data:`JPEG_SUBSAMPLING` (:class:`InputError` naming ``name`` otherwise)."""
    return PHONE_TABLES["isp"]["jpeg_subsampling"].check(value, name)


def check_grid_offset(value, name="jpeg_grid_offset_px") -> tuple:
    """``(x, y)``, whole pixels 0-15: where the image's top-left pixel sits in the JPEG's block
    grid (:class:`InputError` naming ``name`` otherwise)."""
    return PHONE_TABLES["isp"]["jpeg_grid_offset_px"].check(value, name)


def check_stages(stages, name="stages") -> tuple:
    """Validate a list of pipeline stage names (or a comma-separated string of them)."""
    return Stages().check(stages, name)


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
        """Read the tables of a :class:`svgs_sim.svgs.Camera` (missing tables take the defaults)."""
        f_number = camera.optics.given("f_number", 2.4)
        band = camera.optics.given("band_nm", (400.0, 700.0))
        return cls(
            sensor=SensorParams.from_table(camera.sensor.to_dict()),
            glare=GlareParams.from_table(camera.glare.to_dict()),
            exposure=ExposureParams.from_table(camera.exposure.to_dict()),
            isp=IspParams.from_table(camera.isp.to_dict()),
            cfa=CfaParams.from_table(camera.cfa.to_dict()),
            f_number=f_number,
            band_nm=band,
        )

    def to_dict(self) -> dict:
        return asdict(self)
