"""What a camera profile's and a target pattern's values may be: type, physical range, choices.

One table of allowed values, read by two layers:

- :meth:`svgs_sim.base.profiles.Camera.load` / :meth:`svgs_sim.base.profiles.Pattern.load` check every value
  of a file when it is loaded, before anything is rendered (a bad value costs no render);
- the models build or check their parameters with the same entries: :mod:`svgs_sim.camera.phone.params`
  and :mod:`svgs_sim.render.geometry` (phone camera, reflectors), :class:`svgs_sim.camera.amcw.TofSensor`,
  :class:`svgs_sim.render.tof.camera.Illumination` / ``TofOptics``, :mod:`svgs_sim.render.tof.scene` and
  :mod:`svgs_sim.tof.camera` (ToF camera and target). ``camera``, ``render`` and ``tof`` sit above
  ``svgs`` in the layer contract of ``pyproject.toml`` and may import it; ``svgs`` may import
  none of them, so the table lives here.

Each bound says why it is physical in :attr:`Num.why` where it is not evident. A value is
refused with a message naming the table, the key, the value and the allowed range, e.g.
``[sensor] qe = 1.5: expected a number in (0, 1] (a quantum efficiency)``.

Tables checked (every key; an unknown key is refused): camera ``[intrinsics]``, ``[sensor]``,
``[glare]``, ``[exposure]``, ``[cfa]``, ``[isp]``, ``[optics]``, ``[flash]`` and the ToF
camera's ``[tof]``, ``[noise]``, ``[illumination]`` (:data:`TOF_CAMERA_TABLES`); pattern
``[reflector]``, each ``[[target]]`` and the ToF target's ``[plate]``, ``[marker]``
(:data:`TOF_PATTERN_TABLES`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .errors import InputError

# ----------------------------------------------------------------------------- choices
#: Phone ISP stages, in pipeline order.
ALL_STAGES = ("glare", "cfa", "shot", "dark", "fpn", "read", "bloom", "adc", "nr", "tone", "sharpen", "u8", "downscale",
              "chroma", "jpeg")
#: Bayer layouts (the colours of the top-left 2 x 2 block, row by row); "none": a mono sensor.
CFA_PATTERNS = ("none", "RGGB", "BGGR", "GRBG", "GBRG")
#: Auto-exposure metering modes.
METERING = ("mean", "center_weighted", "spot")
#: OpenCV's demosaic methods (``cv2.COLOR_Bayer*2BGR``, ``*_EA``, ``*_VNG``).
DEMOSAIC_METHODS = ("bilinear", "edge_aware", "vng")
#: What the ISP delivers and the JPEG encodes: one luminance plane, or colour with full (4:4:4)
#: or 2 x 2 subsampled (4:2:0) chroma.
JPEG_SUBSAMPLING = ("gray", "4:4:4", "4:2:0")
#: ``[exposure] mode``.
EXPOSURE_MODES = ("auto", "manual")
#: ``[sensor] bloom_direction``: where the charge above full well that is not drained spills.
BLOOM_DIRECTIONS = ("isotropic", "column")
#: ``[flash] spectrum``: the spectra the renderer knows (``svgs_sim.render.optics.SPECTRA``; a test
#: keeps the two lists equal).
FLASH_SPECTRA = ("white-led",)

#: ``[tof] depth_kind``: what a ToF depth image holds: the distance along the pixel's line of
#: sight (what an AMCW camera measures) or the coordinate along the boresight.
DEPTH_KINDS = ("radial", "z")
#: ``[tof] gray_modes``: the ToF camera's image modes (illumination on: depth; off: gray).
GRAY_MODES = ("active", "passive")
#: ``[marker] material``: the surfaces the ToF renderer knows (:mod:`svgs_sim.render.tof.scene`).
TOF_MATERIALS = ("retroreflective", "lambertian")
#: ``[marker] sheeting``: the retroreflective sheeting tables of
#: ``assets/materials/retroreflective-sheeting.toml`` (``svgs_sim.render.tof.retro.sheeting_names()``;
#: a test keeps the two lists equal).
SHEETINGS = ("en12899-ra2-white", "en12899-ra1-white", "astm-d4956-type-i-white", "3m-983-diamond-grade-white")

#: Named reflector models (``[reflector] model`` in a pattern file), read by
#: :class:`svgs_sim.render.geometry.Reflector`.
REFLECTOR_MODELS = {
    # Edmund Optics mounted N-BK7 corner cube, 12.7 mm (the paper, "Test Setup").
    "edmund-nbk7-12.7mm": dict(kind="solid", diameter_m=0.0127, height_m=0.0095),
    "hollow-12.7mm": dict(kind="hollow", diameter_m=0.0127, height_m=0.0095),
}

#: Targets of a pattern closer than this are one position (m): no two reflectors share a place.
DISTINCT_TARGETS_M = 1e-6


# ----------------------------------------------------------------------------- specs
@dataclass(frozen=True)
class Num:
    """A number in ``[lo, hi]`` (open ends where ``lo_open``/``hi_open``); whole when ``integer``."""

    lo: float
    hi: float
    lo_open: bool = False
    hi_open: bool = False
    integer: bool = False
    why: str = ""

    def describe(self) -> str:
        kind = "a whole number" if self.integer else "a number"
        rng = f"{'(' if self.lo_open else '['}{self.lo:g}, {self.hi:g}{')' if self.hi_open else ']'}"
        return f"{kind} in {rng}" + (f" ({self.why})" if self.why else "")

    def check(self, value, name: str):
        if isinstance(value, bool) or not isinstance(value, (int, float)) and not _is_np_number(value):
            raise InputError(f"{name} = {value!r}: expected {self.describe()}")
        v = float(value)
        ok = math.isfinite(v) and (v > self.lo if self.lo_open else v >= self.lo) and (
            v < self.hi if self.hi_open else v <= self.hi)
        if not ok or (self.integer and not v.is_integer()):
            raise InputError(f"{name} = {value!r}: expected {self.describe()}")
        return int(value) if self.integer else v


def _is_np_number(value) -> bool:
    # numpy scalars without importing numpy's type tree here: they carry dtype and item()
    return hasattr(value, "dtype") and hasattr(value, "item") and getattr(value, "shape", None) == ()


@dataclass(frozen=True)
class Choice:
    """One of ``values`` (texts, or whole numbers: the value must be of the same kind, so
    ``4.0`` is not the choice ``4`` and ``true`` is not ``1``)."""

    values: tuple
    why: str = ""

    def describe(self) -> str:
        return "one of " + ", ".join(repr(v) for v in self.values) + (f" ({self.why})" if self.why else "")

    def check(self, value, name: str):
        if isinstance(value, bool) or not any(isinstance(value, type(v)) and value == v for v in self.values):
            raise InputError(f"{name} = {value!r}: expected {self.describe()}")
        return value


@dataclass(frozen=True)
class Text:
    """A one-line text of 1 to ``max_chars`` characters (a label nothing computes with)."""

    max_chars: int = 200
    why: str = ""

    def describe(self) -> str:
        return f"a one-line text of 1-{self.max_chars} characters" + (f" ({self.why})" if self.why else "")

    def check(self, value, name: str):
        if not isinstance(value, str) or not 0 < len(value) <= self.max_chars or "\n" in value or "\r" in value:
            raise InputError(f"{name} = {value!r}: expected {self.describe()}")
        return value


@dataclass(frozen=True)
class AutoOr:
    """The text ``"auto"`` (the model chooses the value) or a value of ``spec``."""

    spec: object

    def describe(self) -> str:
        return f"'auto' or {self.spec.describe()}"

    def check(self, value, name: str):
        if value == "auto":
            return "auto"
        if isinstance(value, str):
            raise InputError(f"{name} = {value!r}: expected {self.describe()}")
        try:
            return self.spec.check(value, name)
        except InputError:
            raise InputError(f"{name} = {value!r}: expected {self.describe()}") from None


@dataclass(frozen=True)
class Vec:
    """A list of ``n`` items of ``item`` (``n`` = 0: any length of at least ``min_len``);
    returned as a tuple."""

    n: int
    item: object
    labels: str = ""
    min_len: int = 0

    def describe(self) -> str:
        what = f"[{self.labels}]" if self.labels else f"a list of {self.n or f'{self.min_len} or more'}"
        return f"{what}, each {self.item.describe()}"

    def check(self, value, name: str):
        if not isinstance(value, (list, tuple)) or (len(value) != self.n if self.n else len(value) < self.min_len):
            raise InputError(f"{name} = {value!r}: expected {self.describe()}")
        return tuple(self.item.check(x, f"{name}[{i}]") for i, x in enumerate(value))


@dataclass(frozen=True)
class Stages:
    """Phone ISP stage names: a list, or a comma-separated string."""

    def describe(self) -> str:
        return "a list of stage names from " + ", ".join(ALL_STAGES)

    def check(self, value, name: str):
        if isinstance(value, str):
            value = [s for s in value.split(",") if s]
        if not isinstance(value, (list, tuple)):
            raise InputError(f"{name} = {value!r}: expected {self.describe()}")
        for s in value:
            if s not in ALL_STAGES:
                raise InputError(f"{name}: unknown stage {s!r}; known stages: {', '.join(ALL_STAGES)}")
        return tuple(value)


@dataclass(frozen=True)
class LedOffsets:
    """``[flash] led_offsets_m``: one ``[x, y, z]`` or a list of them, metres within 1 m of the lens."""

    def describe(self) -> str:
        return "[x, y, z] or [[x, y, z], ...], each a number in [-1, 1] (m from the lens centre)"

    def check(self, value, name: str):
        one = Vec(3, Num(-1, 1), labels="x, y, z")
        if isinstance(value, (list, tuple)) and value and not isinstance(value[0], (list, tuple)):
            return (one.check(value, name),)
        return Vec(0, one, min_len=1).check(value, name)


@dataclass(frozen=True)
class Ghosts:
    """``[glare] ghosts``: ``[[fraction, scale, blur_px], ...]`` (may be empty)."""

    ITEMS = (("fraction", Num(0, 0.5, why="a ghost's share of the energy")),
             ("scale", Num(-10, 10, why="the ghost's magnification through the centre")),
             ("blur_px", Num(0, 1000)))

    def describe(self) -> str:
        return "[[fraction, scale, blur_px], ...], " + "; ".join(f"{k} {s.describe()}" for k, s in self.ITEMS)

    def check(self, value, name: str):
        if not isinstance(value, (list, tuple)):
            raise InputError(f"{name} = {value!r}: expected {self.describe()}")
        out = []
        for i, g in enumerate(value):
            if not isinstance(g, (list, tuple)) or len(g) != 3:
                raise InputError(f"{name}[{i}] = {g!r}: expected [fraction, scale, blur_px]")
            out.append(tuple(s.check(x, f"{name}[{i}].{k}") for (k, s), x in zip(self.ITEMS, g)))
        return tuple(out)


FRACTION = Num(0, 1)
WAVELENGTH_NM = Num(300.0, 1100.0, lo_open=True, why="silicon's response")

#: Every key of the phone camera tables (their whole key set: other keys are refused).
PHONE_TABLES = {
    "sensor": {
        "pixel_pitch_m": Num(0, 1e-4, lo_open=True, why="image-sensor pixels are 0.5-25 um"),
        "qe": Num(0, 1, lo_open=True, why="a quantum efficiency, e-/photon"),
        "full_well_e": Num(0, 1e7, lo_open=True, why="the largest CCD wells hold ~1e6 e-"),
        "read_noise_e": Num(0, 1e4),
        "dark_current_e_s": Num(0, 1e7),
        "dsnu_e": Num(0, 1e5),
        "prnu": FRACTION,
        "adc_bits": Num(1, 16, integer=True),
        "black_level_dn": Num(0, 65535),
        "base_iso": Num(0, 1e6, lo_open=True),
        "anti_blooming_drain": FRACTION,
        "bloom_direction": Choice(BLOOM_DIRECTIONS),
        "serial": Num(0, 2**53, integer=True, why="a seed"),
        "readout_time_s": Num(0, 10),
    },
    "glare": {
        "aberration_sigma_px": Num(0, 100),
        "veiling_fraction": Num(0, 0.999),
        "wing_exponent": Num(1.0, 10, lo_open=True, why="wings must fall faster than 1/r to hold finite energy"),
        "wing_core_px": Num(0, 1000, lo_open=True),
        "wing_radius_px": Num(1, 1e5),
        "ghosts": Ghosts(),
    },
    "exposure": {
        "mode": Choice(EXPOSURE_MODES),
        "metering": Choice(METERING),
        "target_level": Num(0, 1, lo_open=True, why="a fraction of white"),
        "compensation_ev": Num(-10, 10),
        "min_exposure_s": Num(0, 60, lo_open=True, why="a phone's exposures are under a minute"),
        "max_exposure_s": Num(0, 60, lo_open=True, why="a phone's exposures are under a minute"),
        "exposure_s": Num(0, 60, lo_open=True, why="a phone's exposures are under a minute"),
        "min_iso": Num(0, 1e6, lo_open=True),
        "max_iso": Num(0, 1e6, lo_open=True),
        "iso": Num(0, 1e6, lo_open=True),
    },
    "cfa": {
        "pattern": Choice(CFA_PATTERNS),
        "response": Vec(3, Num(0.0, 1.0, lo_open=True), labels="R, G, B"),
        "wavelength_nm": Vec(3, WAVELENGTH_NM, labels="R, G, B"),
        "demosaic": Choice(DEMOSAIC_METHODS),
    },
    "isp": {
        # the tone curve out = in^(1/gamma): 1 is linear, phones ~2.2; 0 was once "linear" and rendered noise
        # through the stages that take 1/gamma, so it is refused (issue 41)
        "gamma": Num(0.5, 5, why="the tone curve out = in^(1/gamma); 1 is linear, a phone's is about 2.2"),
        "output_width": Num(0, 65535, integer=True, why="0: full resolution"),
        "output_height": Num(0, 65535, integer=True, why="0: full resolution"),
        "jpeg_quality": Num(0, 100, integer=True, why="0: no JPEG"),
        "jpeg_subsampling": Choice(JPEG_SUBSAMPLING),
        "jpeg_grid_offset_px": Vec(2, Num(0, 15, integer=True), labels="x, y"),
        "nr_sigma_px": Num(0, 20.0),
        "nr_range": Num(0, 1.0),
        "sharpen_amount": Num(0, 10.0),
        "sharpen_sigma_px": Num(0, 20.0, lo_open=True),
        "stages": Stages(),
    },
}

#: Renderer tables of a camera profile (phone and ToF cameras share ``[optics]``).
RENDER_TABLES = {
    "optics": {
        "focal_length_m": Num(0, 1, lo_open=True),
        "f_number": Num(0.5, 100, why="N = 1 / (2 NA) >= 0.5 in air"),
        "focus_distance_m": Num(0, 1e4, lo_open=True),
        "band_nm": Vec(2, Num(200.0, 2000.0), labels="low, high"),
        "housing_diameter_m": Num(0, 1, lo_open=True),
        "transmittance": Num(0, 1, lo_open=True),
        "bandpass_center_m": Num(2e-7, 2e-6),
        "bandpass_fwhm_m": Num(0, 1e-6, lo_open=True),
    },
    "flash": {
        "led_offsets_m": LedOffsets(),
        "emitter_diameter_m": Num(0, 0.1, lo_open=True),
        "luminous_intensity_cd": Num(0, 1e7, lo_open=True),
        "radiant_intensity_w_sr": Num(0, 1e5, lo_open=True),
        "cos_exponent": Num(0, 50),
        "spectrum": Choice(FLASH_SPECTRA),
    },
}

#: A reflectance (albedo) at the ToF wavelength.
REFLECTANCE = Num(0, 1, why="a reflectance")
#: Seconds a ToF pixel integrates one DCS: AMCW sensors integrate for microseconds to milliseconds.
_TOF_TIME_S = Num(0, 1, lo_open=True, why="an integration time; ToF pixels integrate us to ms")
#: Irradiance on a pixel per LSB at the reference time: the EPC660's are 6e-4 and 2.5e-4 W m^-2;
#: at 1 W m^-2 per LSB sunlight (~1e3 W m^-2) would fill only a thousand LSB.
_SENSITIVITY = Num(0, 1, lo_open=True, why="W m^-2 per LSB; the EPC660's are 6e-4 (ToF) and 2.5e-4 (gray)")
#: Ambient illuminance: direct sunlight is ~1.1e5 lux (the command line's bound, svgs_sim.cli.validate).
_LUX = Num(0, 2e5, why="natural light; direct sunlight is ~1.1e5 lux")

#: Every key of the ToF camera tables (their whole key set: other keys are refused). Read by
#: :class:`svgs_sim.camera.amcw.TofSensor` (``[tof]``, ``[noise]``), :class:`svgs_sim.render.tof.camera.Illumination`
#: and ``TofOptics``, :func:`svgs_sim.tof.camera.depth_kind` and ``svgs tof solve`` (``depth_png_scale_m``);
#: ``n_taps``, ``frame_rate_hz``, ``gray_modes``, ``ambient_lux_high``, ``[illumination] model`` and
#: ``radiant_flux_per_emitter_w`` (while ``radiant_intensity_w_sr`` is given) are the record's.
TOF_CAMERA_TABLES = {
    "tof": {
        "depth_kind": Choice(DEPTH_KINDS),
        "depth_png_scale_m": Num(0, 1, lo_open=True, why="metres per count of an integer depth image; 0.001: mm"),
        "modulation_frequency_hz": Num(0, 1e9, lo_open=True, why="AMCW pixels demodulate below ~1 GHz"),
        "wavelength_m": Num(3e-7, 1.1e-6, lo_open=True, why="silicon's response"),
        "n_taps": Choice((4,), why="DCS per depth frame: the pixel model draws four"),
        "demodulation_contrast": Num(0, 1, lo_open=True, why="a modulation contrast"),
        "adc_bits": Num(2, 24, integer=True, why="DCS span +-(2^(bits-1) - 1) LSB: one bit holds only 0"),
        "pixel_pitch_m": Num(0, 1e-4, lo_open=True, why="image-sensor pixels are 0.5-50 um"),
        "tof_sensitivity_w_m2_per_lsb": _SENSITIVITY,
        "gray_sensitivity_w_m2_per_lsb": _SENSITIVITY,
        "sensitivity_reference_time_s": _TOF_TIME_S,
        "frame_rate_hz": Num(0, 1e4, lo_open=True),
        "integration_time_s": AutoOr(_TOF_TIME_S),
        "integration_time_min_s": _TOF_TIME_S,
        "integration_time_max_s": _TOF_TIME_S,
        "auto_exposure_target": Num(0, 1, lo_open=True, why="a fraction of the DCS range"),
        "min_amplitude_dn": Num(0, 1e7, why="LSB; 0: every depth pixel valid"),
        "gray_modes": Vec(0, Choice(GRAY_MODES), min_len=1),
    },
    "noise": {
        "quantum_efficiency": Num(0, 1, lo_open=True, why="a quantum efficiency, e-/photon"),
        "read_noise_e": Num(0, 1e4),
        "full_well_e": Num(0, 1e8, lo_open=True, why="the EPC660's storage node holds 8e6 e-"),
        "dark_current_e_per_s": Num(0, 1e7),
        "ambient_lux": _LUX,
        "ambient_lux_high": _LUX,
        "ambient_suppression": Num(0, 1, why="a fraction of the ambient charge removed"),
        "ambient_w_m2_per_lux": Num(0, 0.1, why="in-band W m^-2 per lux; an incandescent lamp's whole "
                                                "spectrum gives ~0.07"),
    },
    "illumination": {
        "n_emitters": Num(1, 1000, integer=True),
        "model": Text(why="the emitter's part name, for the record"),
        "divergence_full_angle_deg": Num(0, 180, lo_open=True, hi_open=True, why="a full cone angle"),
        "radiant_intensity_w_sr": Num(0, 1e5, lo_open=True),
        "radiant_flux_per_emitter_w": Num(0, 1e4, lo_open=True),
        "duty_cycle": Num(0, 1, lo_open=True, why="mean / peak optical power"),
        "offset_from_lens_m": Vec(3, Num(-1, 1, why="m from the lens centre"), labels="x, y, z"),
        "ring_radius_m": Num(0, 1, why="m from the lens axis; 0: at the lens"),
        "emitter_diameter_m": Num(0, 0.1, lo_open=True),
    },
}

#: Defaults the cross-key rules of ``[tof]`` assume for an absent key: those of
#: :class:`svgs_sim.camera.amcw.TofSensor` (a test keeps them equal).
TOF_DEFAULTS = {"tof": {"integration_time_min_s": 1.67e-7, "integration_time_max_s": 2.0e-3}}

#: Every key of the ToF target's tables (read by :func:`svgs_sim.tof.camera.load_target` and
#: :mod:`svgs_sim.render.tof.scene`).
TOF_PATTERN_TABLES = {
    "plate": {
        "width_m": Num(0, 100, lo_open=True),
        "height_m": Num(0, 100, lo_open=True),
        "thickness_m": Num(0, 1, lo_open=True),
        "centre_m": Vec(3, Num(-100, 100, why="the plate's front-face centre, m from the target origin; default 0"),
                         labels="x, y, z"),
        "albedo": REFLECTANCE,
    },
    "marker": {
        "material": Choice(TOF_MATERIALS),
        "sheeting": Choice(SHEETINGS),
        "albedo": REFLECTANCE,
        "post_diameter_ratio": Num(0, 1, lo_open=True, hi_open=True, why="a post narrower than its marker"),
        "diameter_m": Num(0, 1, lo_open=True, why="the markers' diameter where a [[target]] gives none"),
    },
}

#: ``[intrinsics]``: image size and pinhole (the principal point is checked against the size by
#: :class:`svgs_sim.base.profiles.Camera`).
INTRINSICS_KEYS = {
    "width": Num(1, 65535, integer=True, why="pixels; JPEG's limit"),
    "height": Num(1, 65535, integer=True, why="pixels; JPEG's limit"),
    "fx": Num(0, 1e7, lo_open=True, why="pixels"),
    "fy": Num(0, 1e7, lo_open=True, why="pixels"),
    "cx": Num(-1e5, 1e5, why="pixels"),
    "cy": Num(-1e5, 1e5, why="pixels"),
}

#: Defaults the cross-key rules assume for an absent key: those of the dataclasses of
#: :mod:`svgs_sim.camera.phone.params` (a test keeps them equal).
PHONE_DEFAULTS = {"sensor": {"adc_bits": 10, "black_level_dn": 64.0},
                  "exposure": {"min_exposure_s": 1.25e-4, "max_exposure_s": 1.0 / 15.0, "min_iso": 100.0,
                               "max_iso": 800.0}}

#: Top-level keys and tables a camera profile may have.
#: ``calibration`` (what :mod:`calibration` estimated) and ``preview`` (a preview stream's
#: record, :mod:`svgs_sim.camera.phone.preview`) are written by this project's own tools.
CAMERA_KEYS = ("name", "key", "description", "intrinsics", "distortion", "sources", "fitted", "calibration", "preview",
               *PHONE_TABLES, *RENDER_TABLES, *TOF_CAMERA_TABLES)

#: Pattern tables and keys.
REFLECTOR_KEYS = {
    "model": Choice(tuple(REFLECTOR_MODELS)),
    "diameter_m": Num(0, 1, lo_open=True, why="a corner cube's clear aperture"),
    "acceptance_deg": Num(0, 90, lo_open=True, why="the largest incidence at which the cubes return light to the lens"),
}
TARGET_KEYS = {
    "id": Num(0, 2**31 - 1, integer=True),
    "x_m": Num(-100, 100, why="target coordinates within 100 m of the target origin"),
    "y_m": Num(-100, 100, why="target coordinates within 100 m of the target origin"),
    "z_m": Num(-100, 100, why="target coordinates within 100 m of the target origin"),
    "diameter_m": Num(0, 1, lo_open=True),
    "standoff_m": Num(0, 10),
}
PATTERN_KEYS = ("name", "description", "reflector", "target", *TOF_PATTERN_TABLES)

#: Every named table: ``check_table(name, t)`` finds its keys here.
_TABLES = {**PHONE_TABLES, **RENDER_TABLES, **TOF_CAMERA_TABLES, **TOF_PATTERN_TABLES}


# ----------------------------------------------------------------------------- checks
def check_table(table: str, t, specs: dict | None = None, *, closed: bool = True) -> dict:
    """Check one table of a profile and return its values converted (floats, ints, tuples).

    Parameters
    ----------
    table : str
        The table's name (``"sensor"``...): the key of :data:`PHONE_TABLES`,
        :data:`RENDER_TABLES`, :data:`TOF_CAMERA_TABLES` or :data:`TOF_PATTERN_TABLES` when
        ``specs`` is None.
    t : dict or None
        The table as read from TOML (None: empty).
    specs : dict, optional
        ``{key: spec}``; default the table's entry.
    closed : bool
        Refuse keys that are not in ``specs``.

    Returns
    -------
    dict
        The keys present in ``t``, each converted by its spec.

    Raises
    ------
    InputError
        Naming ``[table] key``, the value and the allowed range or choices; an unknown key
        with the known ones; a cross-key rule broken (a black level at or above white, a
        minimum above its maximum...).
    """
    if specs is None:
        specs = _TABLES[table]
    if t is None:
        t = {}
    if not isinstance(t, dict):
        raise InputError(f"[{table}]: expected a table, got {t!r}")
    if closed:
        extra = set(t) - set(specs)
        if extra:
            raise InputError(f"[{table}]: unknown key(s) {sorted(extra)}; known: {sorted(specs)}")
    out = {k: specs[k].check(v, f"[{table}] {k}") for k, v in t.items() if k in specs}
    _CROSS.get(table, lambda o: None)(out)
    return out


def _cross_sensor(o):
    d = {**PHONE_DEFAULTS["sensor"], **o}
    white = float(2 ** d["adc_bits"] - 1)
    if d["black_level_dn"] >= white:
        raise InputError(f"[sensor] black_level_dn = {d['black_level_dn']:g}: must be below the ADC white "
                         f"level {white:g} DN of adc_bits = {d['adc_bits']}")


def _cross_exposure(o):
    d = {**PHONE_DEFAULTS["exposure"], **o}
    for lo, hi in (("min_exposure_s", "max_exposure_s"), ("min_iso", "max_iso")):
        a, b = d[lo], d[hi]
        if a > b:
            raise InputError(f"[exposure] {lo} = {a:g} exceeds {hi} = {b:g}")


def _cross_isp(o):
    if (o.get("output_width", 0) == 0) != (o.get("output_height", 0) == 0):
        raise InputError("[isp] output_width and output_height: must both be 0 (full resolution) or both set")


def _cross_optics(o):
    band = o.get("band_nm")
    if band is not None and not band[0] < band[1]:
        raise InputError(f"[optics] band_nm = {list(band)}: expected low < high")


def _cross_flash(o):
    if "luminous_intensity_cd" in o and "radiant_intensity_w_sr" in o:
        raise InputError("[flash]: give luminous_intensity_cd or radiant_intensity_w_sr, not both "
                         "(radiant_intensity_w_sr would win silently)")


def _cross_tof(o):
    d = {**TOF_DEFAULTS["tof"], **o}
    a, b = d["integration_time_min_s"], d["integration_time_max_s"]
    if a > b:
        raise InputError(f"[tof] integration_time_min_s = {a:g} exceeds integration_time_max_s = {b:g}")


_CROSS = {"sensor": _cross_sensor, "exposure": _cross_exposure, "isp": _cross_isp,
          "optics": _cross_optics, "flash": _cross_flash, "tof": _cross_tof}


def check_camera_tables(data: dict) -> None:
    """Check every table of a camera profile's TOML structure that this module knows.

    Raises
    ------
    InputError
        Naming ``[table] key`` and the allowed range (see :func:`check_table`); a top-level
        key that is not one of :data:`CAMERA_KEYS`.
    """
    extra = set(data) - set(CAMERA_KEYS)
    if extra:
        raise InputError(f"unknown table(s) or key(s) {sorted(extra)}; known: {', '.join(CAMERA_KEYS)}")
    for table in (*PHONE_TABLES, *RENDER_TABLES, *TOF_CAMERA_TABLES):
        if table in data:
            check_table(table, data[table])


def check_pattern_tables(data: dict) -> list[dict]:
    """Check a target pattern's TOML structure: its top-level keys, ``[reflector]``, the ToF
    target's ``[plate]`` and ``[marker]``, and every ``[[target]]``.

    Parameters
    ----------
    data : dict
        The parsed file; ``data["target"]`` a non-empty list.

    Returns
    -------
    list of dict
        The checked values of each ``[[target]]``, in file order.

    Raises
    ------
    InputError
        A key that is not one of :data:`PATTERN_KEYS`; a value refused by :func:`check_table`
        (naming ``[table] key`` and the allowed range).
    """
    extra = set(data) - set(PATTERN_KEYS)
    if extra:
        raise InputError(f"unknown table(s) or key(s) {sorted(extra)}; known: {', '.join(PATTERN_KEYS)}")
    if "reflector" in data:
        check_reflector_table(data["reflector"])
    for table in TOF_PATTERN_TABLES:
        if table in data:
            check_table(table, data[table])
    return [check_target(t, i) for i, t in enumerate(data["target"])]


def check_reflector_table(t) -> dict:
    """Check a pattern's ``[reflector]`` table: ``model`` one of :data:`REFLECTOR_MODELS`,
    ``diameter_m`` a clear aperture its model's cube covers (``height_m >= D / sqrt(2)``).

    Returns
    -------
    dict
        The checked values.
    """
    out = check_table("reflector", t, REFLECTOR_KEYS)
    if "diameter_m" in out:
        h = REFLECTOR_MODELS[out.get("model", "edmund-nbk7-12.7mm")]["height_m"]
        if out["diameter_m"] > h * math.sqrt(2.0) * (1 + 1e-9):
            raise InputError(f"[reflector] diameter_m = {out['diameter_m']:g}: expected at most {h * math.sqrt(2):.5f} m, "
                             f"what a cube of height {h:g} m covers (height >= D / sqrt(2))")
    return out


def check_target(t, i: int) -> dict:
    """Check one ``[[target]]`` table (``i``: its place in the file, from 0); return its values."""
    if not isinstance(t, dict):
        raise InputError(f"target #{i + 1}: expected a [[target]] table, got {t!r}")
    missing = [k for k in ("id", "x_m", "y_m", "z_m") if k not in t]
    if missing:
        raise InputError(f"target #{i + 1} lacks {', '.join(missing)}")
    label = f"target #{i + 1}"
    if isinstance(t["id"], int) and not isinstance(t["id"], bool):
        label = f"target {t['id']}"
    return check_table(label, t, TARGET_KEYS)
