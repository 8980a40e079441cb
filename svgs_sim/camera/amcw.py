"""AMCW pixel model of the ToF camera: rendered radiance -> four DCS -> amplitude, depth, gray.

numpy only (no Mitsuba): a frame is drawn from a :class:`RenderedTof` (the noise-free
per-pixel means the renderer produced once) in milliseconds, so a stability run renders once
and draws many noisy frames.

Model: the EPC660's differential 2-tap pixel (its datasheet V2.20, sections 9.1-9.5)
------------------------------------------------------------------------------------
A depth frame is four sequential **DCS** (differential correlation samples) at 0, 90, 180 and
270 deg, each integrating for ``T`` (the chip's integration-time setting). In one DCS the
photogate splits the pixel's charge between two taps A and B in antiphase::

    k     = photons_per_radiance * QE * transmittance * T      electrons per (W m^-2 sr^-1)
    N     = k * (L_active + L_amb) + dark_current * T          total charge of the DCS (both taps)
    P     = k * <L e^{i 2 pi f opl / c}>                       the return's phasor (mixed / flying
                                                               pixels and multipath are phasor sums)
    m_k   = c_d Re(P e^{-i k pi / 2})                          c_d: demodulation contrast
    A_k ~ Poisson((N + m_k) / 2),  B_k ~ Poisson((N - m_k) / 2),  DCS_k = A_k - B_k (+ two reads' noise)

so the DC (ambient, dark, the return's own mean) cancels in the mean and stays in the noise.
A 12-bit ADC converts ``DCS_k`` with ``gain_e_per_lsb`` into -2047..2047 LSB (clipping sets
the SAT flag; so does a total charge beyond the ``full_well_e`` of the storage node after
background suppression). From the DCS (datasheet eqs. 2 and 5)::

    A_TOF = sqrt((DCS2 - DCS0)^2 + (DCS3 - DCS1)^2) / 2                   amplitude (LSB)
    D     = c / (4 pi f) [pi + atan2(DCS3 - DCS1, DCS2 - DCS0)]          distance (wraps at c / 2f)

Gain from the datasheet's TOF sensitivity ``S_TOF`` (irradiance per LSB of amplitude at the
reference integration time ``t_ref``): an irradiance ``E`` on the pixel gives
``A_TOF = E T / (S_TOF t_ref)`` LSB, i.e. ``gain_e_per_lsb = c_d QE a_pix S_TOF t_ref / (h nu)``.
The phase noise of one depth frame is ``sqrt(N / 2 + sigma_r^2) / (c_d |P|)``
(:func:`phase_noise_rad`). Pixels below ``min_amplitude_dn`` or with SAT get NaN depth.
``mode="passive"`` is the gray mode: illumination off, single-ended read-out of the ambient
charge with the grayscale sensitivity.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, fields, replace

import numpy as np

from svgs_sim.base.constants import PLANCK_J_S, SPEED_OF_LIGHT_M_S
from svgs_sim.base.errors import InputError, ProfileError, check_finite_positive
from svgs_sim.base.profile_schema import RENDER_TABLES, TOF_CAMERA_TABLES, Num, check_table
from svgs_sim.camera.rendered import RenderedFrame


@dataclass
class RenderedTof(RenderedFrame):
    """Noise-free per-pixel means of one rendered ToF frame (what :class:`TofSensor` draws from).

    A :class:`svgs_sim.camera.rendered.RenderedFrame` (``truth``, ``timings_s``, ``pose()``): ``flux``
    is the photon rate of the illumination's return, ``active_radiance * photons_per_radiance``.

    Attributes
    ----------
    active_radiance : ndarray of float64, shape (H, W)
        Mean radiance of the illumination's return (time-averaged), W m^-2 sr^-1 at 850 nm.
    phasor_radiance : ndarray of complex128, shape (H, W)
        Mean of ``L exp(i 2 pi f opl / c)`` over the pixel's samples (``opl``: emitter ->
        scene -> lens path length), W m^-2 sr^-1.
    ambient_factor : ndarray of float64, shape (H, W)
        Radiance returned under a uniform ambient sky of unit radiance (dimensionless).
    photons_per_radiance : ndarray of float64, shape (H, W)
        Photons per second reaching the pixel per W m^-2 sr^-1 (aperture area x pixel
        solid angle x cos / photon energy; no QE or transmission).
    hit_fraction : ndarray of float64, shape (H, W)
        Fraction of the pixel's samples that hit the scene.
    range_first_m : ndarray of float64, shape (H, W)
        Mean radial distance (lens centre -> first hit) of the hitting samples; NaN where none.
    modulation_frequency_hz : float
        Frequency the phasors were made for.
    truth : dict
        Pose, marker projections, render settings (JSON-serialisable; keyword-only).
    timings_s : dict
        Render stage timings (keyword-only; also in ``truth["render"]["timings_s"]``).
    """

    active_radiance: np.ndarray
    phasor_radiance: np.ndarray
    ambient_factor: np.ndarray
    photons_per_radiance: np.ndarray
    hit_fraction: np.ndarray
    range_first_m: np.ndarray
    modulation_frequency_hz: float

    @property
    def shape(self) -> tuple:
        return self.active_radiance.shape

    @property
    def flux(self) -> np.ndarray:
        """Photons per second per pixel of the illumination's return (no QE), shape (H, W)."""
        return self.active_radiance * self.photons_per_radiance

    @property
    def depth_m(self) -> np.ndarray:
        """Noise-free phase depth (wrapped, radial), NaN where nothing returns."""
        return phasor_depth_m(self.phasor_radiance, self.modulation_frequency_hz)

    def save(self, path) -> None:
        """All arrays in one ``.npz`` (truth as JSON text)."""

        np.savez_compressed(path, active_radiance=self.active_radiance, phasor_radiance=self.phasor_radiance,
                            ambient_factor=self.ambient_factor, photons_per_radiance=self.photons_per_radiance,
                            hit_fraction=self.hit_fraction, range_first_m=self.range_first_m,
                            modulation_frequency_hz=self.modulation_frequency_hz, truth=json.dumps(self.truth))

    @classmethod
    def load(cls, path) -> "RenderedTof":

        with np.load(path, allow_pickle=False) as z:
            truth = json.loads(str(z["truth"]))
            return cls(z["active_radiance"], z["phasor_radiance"], z["ambient_factor"], z["photons_per_radiance"],
                       z["hit_fraction"], z["range_first_m"], float(z["modulation_frequency_hz"]), truth=truth,
                       timings_s=dict((truth.get("render") or {}).get("timings_s") or {}))


def unambiguous_range_m(modulation_frequency_hz: float) -> float:
    """``c / (2 f)``: depth wraps to 0 beyond this."""
    return SPEED_OF_LIGHT_M_S / (2.0 * float(modulation_frequency_hz))


def phasor_depth_m(phasor, modulation_frequency_hz: float) -> np.ndarray:
    """Depth ``c arg(P) / (4 pi f)`` in ``[0, c / 2f)``; NaN where ``P == 0``."""
    p = np.asarray(phasor)
    phi = np.mod(np.angle(p), 2 * np.pi)
    d = SPEED_OF_LIGHT_M_S * phi / (4 * np.pi * float(modulation_frequency_hz))
    d = np.where(d >= unambiguous_range_m(modulation_frequency_hz), 0.0, d)  # 2 pi rounding
    return np.where(np.abs(p) > 0, d, np.nan)


def phase_noise_rad(total_charge_e, modulated_e, read_noise_e=0.0):
    """Shot + read noise phase error of one 4-DCS depth frame, radians.

    ``sqrt(N / 2 + sigma_r^2) / M``: each DCS difference ``DCS_k - DCS_{k+2}`` has the
    variance ``2 N + 4 sigma_r^2`` and the mean ``2 M``.

    Parameters
    ----------
    total_charge_e : array_like
        Charge ``N`` of one DCS exposure (both taps: signal, ambient, dark), electrons.
    modulated_e : array_like
        ``M = c_d |P|``, electrons.
    read_noise_e : float
        Per tap read, electrons.
    """
    return np.sqrt(0.5 * np.asarray(total_charge_e, float) + float(read_noise_e) ** 2) / np.asarray(modulated_e, float)


@dataclass
class TofFrame:
    """One frame of the ToF camera.

    Attributes
    ----------
    gray : ndarray of float32, shape (H, W)
        Active mode: amplitude (LSB); passive mode: the gray-mode output (LSB).
    depth_m : ndarray of float32, shape (H, W)
        Radial phase depth (wrapped at ``c / 2f``); NaN where invalid (and everywhere in
        passive mode).
    amplitude_dn : ndarray of float32, shape (H, W)
    intensity_dn : ndarray of float32, shape (H, W)
        Charge in the storage node per DCS in gray-mode LSB (active mode, noise-free: what
        fills the well); the gray output in passive mode.
    saturated : ndarray of bool, shape (H, W)
        A DCS clipped at the ADC range or the storage node overflowed (the chip's SAT flag).
    taps_dn : ndarray of float32, shape (4, H, W)
        The four DCS values, LSB (zeros in passive mode).
    integration_time_s : float
    mode : str
    """

    gray: np.ndarray
    depth_m: np.ndarray
    amplitude_dn: np.ndarray
    intensity_dn: np.ndarray
    saturated: np.ndarray
    taps_dn: np.ndarray
    integration_time_s: float
    mode: str = "active"


#: What each :class:`TofSensor` field may be: the entry of the same key in the profile's ``[tof]``,
#: ``[noise]`` or ``[optics]`` table (:mod:`svgs_sim.base.profile_schema`), except ``ambient_lux``: the
#: model takes any light (saturating the sensor on purpose), a profile only natural light.
SENSOR_SPECS = {**TOF_CAMERA_TABLES["tof"], **TOF_CAMERA_TABLES["noise"],
                "transmittance": RENDER_TABLES["optics"]["transmittance"],
                "ambient_lux": Num(0, math.inf, why="any ambient light, saturating included")}


@dataclass(frozen=True)
class TofSensor:
    """The EPC660 pixel and read-out (see the module notes for the model).

    Attributes
    ----------
    modulation_frequency_hz : float
        Must equal the frequency the :class:`RenderedTof` was rendered for.
    demodulation_contrast : float
        ``c_d`` in (0, 1].
    quantum_efficiency, transmittance : float
        At 850 nm; transmittance of lens + band-pass filter.
    read_noise_e : float
        Per tap read, electrons (a DCS difference has sqrt(2) of it).
    full_well_e : float
        Charge the storage node holds per DCS (signal + ambient after suppression), electrons.
    dark_current_e_per_s : float
    adc_bits : int
        DCS values span ``-(2^(bits-1) - 1) .. 2^(bits-1) - 1`` LSB; the gray image ``0 .. 2^(bits-1) - 1``.
    tof_sensitivity_w_m2_per_lsb : float
        Irradiance on the pixel per LSB of amplitude at ``sensitivity_reference_time_s``.
    gray_sensitivity_w_m2_per_lsb : float
        The same for the gray (passive) mode's output.
    sensitivity_reference_time_s : float
    pixel_pitch_m : float
    wavelength_m : float
    ambient_suppression : float
        Fraction of the ambient charge the background suppression removes from the storage node
        (it cancels in the DCS differences anyway; this only sets when the node fills).
    ambient_lux : float
        Ambient illuminance (the paper: 1000 lux normal, 10000 lux high).
    ambient_w_m2_per_lux : float
        In-band (850 nm filter) irradiance per lux of the ambient light.
    integration_time_s : float or None
        Per DCS; None: automatic (:meth:`auto_integration_time`).
    integration_time_min_s, integration_time_max_s : float
        Limits of the automatic integration time.
    auto_exposure_target : float
        The automatic integration time puts the brightest pixel's amplitude at this fraction
        of the DCS range.
    min_amplitude_dn : float
        Depth is invalid (NaN) below this amplitude (LSB).
    """

    modulation_frequency_hz: float = 10.0e6
    demodulation_contrast: float = 0.39
    quantum_efficiency: float = 0.8
    transmittance: float = 0.9
    read_noise_e: float = 30.0
    full_well_e: float = 8.0e6
    dark_current_e_per_s: float = 1000.0
    adc_bits: int = 12
    tof_sensitivity_w_m2_per_lsb: float = 6.0e-4
    gray_sensitivity_w_m2_per_lsb: float = 2.5e-4
    sensitivity_reference_time_s: float = 1.0e-4
    pixel_pitch_m: float = 20e-6
    wavelength_m: float = 850e-9
    ambient_suppression: float = 0.9
    ambient_lux: float = 1000.0
    ambient_w_m2_per_lux: float = 4.1e-4
    integration_time_s: float | None = None
    integration_time_min_s: float = 1.67e-7
    integration_time_max_s: float = 2.0e-3
    auto_exposure_target: float = 0.5
    min_amplitude_dn: float = 25.0

    def __post_init__(self):
        """Check every field with the profile's entry of the same name (:data:`SENSOR_SPECS`)."""
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name == "integration_time_s" and v is None:
                continue
            v = SENSOR_SPECS[f.name].check(v, f"tof sensor {f.name}")
            object.__setattr__(self, f.name, None if v == "auto" else v)
        check_table("tof", {k: getattr(self, k) for k in ("integration_time_min_s", "integration_time_max_s")})

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_camera(cls, camera, **overrides) -> "TofSensor":
        """Parameters from a camera profile's ``[tof]``, ``[noise]`` and ``[optics]`` tables.

        Every field name found in ``[tof]`` or ``[noise]`` is read (``integration_time_s`` may
        be ``"auto"``); ``optics.transmittance``. Missing keys keep the class defaults.
        ``overrides`` replace fields (None values are ignored; ``integration_time_s="auto"``).
        """
        t = camera.tof.to_dict()
        n = camera.noise.to_dict()
        o = camera.optics.to_dict()
        kw = {}
        names = {f.name for f in fields(cls)}
        for src in (t, n):
            for k, v in src.items():
                if k in names:
                    kw[k] = v
        if "transmittance" in o:
            kw["transmittance"] = o["transmittance"]
        if kw.get("integration_time_s") == "auto":
            kw["integration_time_s"] = None
        for k, v in overrides.items():
            if k not in names:
                raise InputError(f"tof sensor: unknown parameter {k!r}")
            if v is None:
                continue
            kw[k] = None if (k == "integration_time_s" and v == "auto") else v
        try:
            return cls(**kw)
        except InputError as exc:
            raise ProfileError(f"camera {camera.name!r}: {exc}") from None

    def replace(self, **kw) -> "TofSensor":
        return replace(self, **kw)

    def to_json(self) -> dict:
        d = asdict(self)
        d.update(gain_e_per_lsb=self.gain_e_per_lsb, gray_gain_e_per_lsb=self.gray_gain_e_per_lsb,
                 dcs_max_lsb=self.dcs_max_lsb)
        return d

    # ------------------------------------------------------------------ radiometry
    @property
    def photon_energy_j(self) -> float:

        return PLANCK_J_S * SPEED_OF_LIGHT_M_S / self.wavelength_m

    def _electrons_per_lsb_irradiance(self, sensitivity_w_m2_per_lsb) -> float:
        """Electrons collected at the reference time from the irradiance of one LSB."""
        return (self.quantum_efficiency * sensitivity_w_m2_per_lsb * self.pixel_pitch_m ** 2
                * self.sensitivity_reference_time_s / self.photon_energy_j)

    @property
    def gain_e_per_lsb(self) -> float:
        """Electrons of a DCS difference per LSB: ``c_d QE a_pix S_TOF t_ref / (h nu)``."""
        return self.demodulation_contrast * self._electrons_per_lsb_irradiance(self.tof_sensitivity_w_m2_per_lsb)

    @property
    def gray_gain_e_per_lsb(self) -> float:
        """Electrons per LSB of the gray mode: ``QE a_pix S_gray t_ref / (h nu)``."""
        return self._electrons_per_lsb_irradiance(self.gray_sensitivity_w_m2_per_lsb)

    @property
    def gain_dn_per_e(self) -> float:
        """LSB per electron of a DCS difference (``1 / gain_e_per_lsb``)."""
        return 1.0 / self.gain_e_per_lsb

    @property
    def dcs_max_lsb(self) -> int:
        return 2 ** (int(self.adc_bits) - 1) - 1

    @property
    def ambient_radiance_w_m2_sr(self) -> float:
        """Radiance of the uniform ambient sky (in band): ``E / pi``."""
        return self.ambient_lux * self.ambient_w_m2_per_lux / np.pi

    def _check(self, rendered: RenderedTof):
        if abs(rendered.modulation_frequency_hz - self.modulation_frequency_hz) > 1e-6 * self.modulation_frequency_hz:
            raise InputError(f"rendered frame was made for {rendered.modulation_frequency_hz:g} Hz but the sensor "
                             f"modulates at {self.modulation_frequency_hz:g} Hz; render again with that frequency")

    def electrons(self, rendered: RenderedTof, integration_time_s: float, mode: str = "active") -> dict:
        """Expected charges of one DCS exposure (electrons, both taps, shape (H, W) each).

        Returns
        -------
        dict
            ``signal`` (the return's mean), ``phasor`` (P, complex), ``ambient``, ``dark`` (scalar).
        """
        T = check_finite_positive(integration_time_s, "integration_time_s")
        k = rendered.photons_per_radiance * self.quantum_efficiency * self.transmittance * T
        on = 1.0 if mode == "active" else 0.0
        return {"signal": on * rendered.active_radiance * k, "phasor": on * rendered.phasor_radiance * k,
                "ambient": rendered.ambient_factor * self.ambient_radiance_w_m2_sr * k,
                "dark": self.dark_current_e_per_s * T}

    def dcs_means_e(self, rendered: RenderedTof, integration_time_s: float) -> np.ndarray:
        """Expected DCS differences ``c_d Re(P e^{-i k pi / 2})``, shape (4, H, W), electrons."""
        P = self.electrons(rendered, integration_time_s)["phasor"]
        return np.stack([self.demodulation_contrast * np.real(P * np.exp(-0.5j * np.pi * k)) for k in range(4)])

    def expected_amplitude_lsb(self, rendered: RenderedTof, integration_time_s: float) -> np.ndarray:
        """Noise-free amplitude ``c_d |P| / gain`` (LSB), shape (H, W)."""
        P = self.electrons(rendered, integration_time_s)["phasor"]
        return self.demodulation_contrast * np.abs(P) / self.gain_e_per_lsb

    def auto_integration_time(self, rendered: RenderedTof, mode: str = "active") -> float:
        """Integration time putting the brightest pixel's amplitude (active) or gray value
        (passive) at ``auto_exposure_target`` of the range, within the limits."""
        self._check(rendered)
        e = self.electrons(rendered, 1.0, mode)
        if mode == "active":
            top = float(np.max(self.demodulation_contrast * np.abs(e["phasor"]))) / self.gain_e_per_lsb
        else:
            top = float(np.max(e["ambient"] + e["dark"])) / self.gray_gain_e_per_lsb
        if top <= 0:
            return float(self.integration_time_max_s)
        return float(np.clip(self.auto_exposure_target * self.dcs_max_lsb / top,
                             self.integration_time_min_s, self.integration_time_max_s))

    # ------------------------------------------------------------------ frames
    def frame(self, rendered: RenderedTof, rng=None, *, integration_time_s: float | None = None,
              mode: str = "active", noise: bool = True) -> TofFrame:
        """Draw one frame.

        Parameters
        ----------
        rendered : RenderedTof
        rng : int or numpy.random.Generator, optional
            Seed or generator of the noise (fresh entropy if None; pass one for repeatability).
        integration_time_s : float, optional
            Default: the sensor's, else automatic.
        mode : {"active", "passive"}
            Depth mode (illumination on) or gray mode (illumination off).
        noise : bool
            False: the expected values (no shot/read noise, no quantisation).

        Returns
        -------
        TofFrame
        """
        if mode not in ("active", "passive"):
            raise InputError(f"mode: expected 'active' or 'passive', got {mode!r}")
        self._check(rendered)
        T = integration_time_s if integration_time_s is not None else self.integration_time_s
        T = self.auto_integration_time(rendered, mode) if T is None else check_finite_positive(T, "integration_time_s")
        e = self.electrons(rendered, T, mode)
        N = e["signal"] + e["ambient"] + e["dark"]
        stored = e["signal"] + (1.0 - self.ambient_suppression) * e["ambient"] + e["dark"]
        top = self.dcs_max_lsb
        f32 = np.float32
        if noise:
            rng = np.random.default_rng(rng)
        if mode == "passive":
            q = rng.poisson(np.maximum(N, 0.0)).astype(np.float64) if noise else N.copy()
            if noise and self.read_noise_e > 0:
                q += rng.normal(0.0, self.read_noise_e, q.shape)
            g = q / self.gray_gain_e_per_lsb
            if noise:
                g = np.round(g)
            sat = (g >= top) | (N > self.full_well_e)
            g = np.clip(g, 0.0, top)
            nan = np.full(g.shape, np.nan)
            zero = np.zeros(g.shape)
            return TofFrame(gray=g.astype(f32), depth_m=nan.astype(f32), amplitude_dn=zero.astype(f32),
                            intensity_dn=g.astype(f32), saturated=sat, taps_dn=np.zeros((4,) + g.shape, f32),
                            integration_time_s=float(T), mode=mode)
        m = self.dcs_means_e(rendered, T)
        if noise:
            a = rng.poisson(np.maximum(0.5 * (N + m), 0.0))
            b = rng.poisson(np.maximum(0.5 * (N - m), 0.0))
            dcs = (a - b).astype(np.float64)
            if self.read_noise_e > 0:  # both taps read: sqrt(2) x the per-tap read noise
                dcs += rng.normal(0.0, np.sqrt(2.0) * self.read_noise_e, dcs.shape)
        else:
            dcs = m
        dn = dcs / self.gain_e_per_lsb
        if noise:
            dn = np.round(dn)
        sat = np.any(np.abs(dn) >= top, axis=0) | (stored > self.full_well_e)
        dn = np.clip(dn, -top, top)
        cx, cy = dn[2] - dn[0], dn[3] - dn[1]
        amp = 0.5 * np.hypot(cx, cy)
        phi = np.mod(np.pi + np.arctan2(cy, cx), 2 * np.pi)
        depth = SPEED_OF_LIGHT_M_S * phi / (4 * np.pi * self.modulation_frequency_hz)
        depth = np.where(depth >= unambiguous_range_m(self.modulation_frequency_hz), 0.0, depth)
        ok = (amp >= self.min_amplitude_dn) & ~sat
        depth = np.where(ok, depth, np.nan)
        intensity = stored / self.gray_gain_e_per_lsb
        return TofFrame(gray=amp.astype(f32), depth_m=depth.astype(f32), amplitude_dn=amp.astype(f32),
                        intensity_dn=intensity.astype(f32), saturated=sat, taps_dn=dn.astype(f32),
                        integration_time_s=float(T), mode=mode)

    def frames(self, rendered: RenderedTof, n: int, seed=None, **kw):
        """``n`` frames from one seeded generator (a generator of :class:`TofFrame`)."""
        rng = np.random.default_rng(seed)
        for _ in range(int(n)):
            yield self.frame(rendered, rng, **kw)
