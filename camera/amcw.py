"""AMCW pixel model of the ToF camera: rendered radiance -> four taps -> amplitude, depth, gray.

numpy only (no Mitsuba): a frame is drawn from a :class:`RenderedTof` (the noise-free
per-pixel means the renderer produced once) in milliseconds, so a stability run renders once
and draws many noisy frames.

Model (``shared/notes/physics.md`` section 6)
---------------------------------------------
Four sequential correlation samples (DCS, the EPC660 scheme), each integrating for ``T`` (the
chip's integration-time setting; a depth frame takes four of them). Per pixel and tap::

    k     = photons_per_radiance * QE * transmittance * T          electrons per (W m^-2 sr^-1)
    S     = k * L_active           (DC of the modulated return, electrons per tap)
    P     = k * <L e^{i 2 pi f opl / c}>   (its phasor: mixed / flying pixels and multipath
                                            are the per-pixel phasor sums the renderer made)
    Amb   = k * L_amb,  L_amb = ambient_factor * ambient_lux * ambient_w_m2_per_lux / pi
    D     = dark_current * T
    mu_k  = S + Amb + D + c_d Re(P e^{-i k pi / 2}),   k = 0..3

(``c_d`` the demodulation contrast). The charge of each tap is Poisson(mu_k); background
suppression (SBI) then removes the fraction ``ambient_suppression`` of the ambient *charge*
(not its shot noise), the well clips at ``full_well_e``, read noise (Gaussian) is added and
a ``adc_bits`` ADC quantises with the gain ``(2^bits - 1) / full_well_e`` DN/e-. From the
taps ``m0..m3`` (DN)::

    phi = atan2(m1 - m3, m0 - m2) mod 2 pi      depth = c phi / (4 pi f)   (wraps at c / 2f)
    amplitude = sqrt((m0 - m2)^2 + (m1 - m3)^2) / 2                       (the gray image)

and the shot-noise phase error is ``sqrt(B + sigma_read^2) / (sqrt(2) A)`` (B the DC per tap,
A the tap amplitude ``c_d |P|``, in electrons; :func:`phase_noise_rad`). Pixels below
``min_amplitude_dn`` or with a saturated tap get NaN depth. ``mode="passive"`` is the gray
mode: illumination off, no suppression, gray = the mean of the taps (ambient image).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields, replace

import numpy as np

from svgs.constants import SPEED_OF_LIGHT_M_S
from svgs.errors import InputError, ProfileError, check_finite_positive

from camera.rendered import RenderedFrame


@dataclass
class RenderedTof(RenderedFrame):
    """Noise-free per-pixel means of one rendered ToF frame (what :class:`TofSensor` draws from).

    A :class:`camera.rendered.RenderedFrame` (``truth``, ``timings_s``, ``pose()``): ``flux``
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
        import json

        np.savez_compressed(path, active_radiance=self.active_radiance, phasor_radiance=self.phasor_radiance,
                            ambient_factor=self.ambient_factor, photons_per_radiance=self.photons_per_radiance,
                            hit_fraction=self.hit_fraction, range_first_m=self.range_first_m,
                            modulation_frequency_hz=self.modulation_frequency_hz, truth=json.dumps(self.truth))

    @classmethod
    def load(cls, path) -> "RenderedTof":
        import json

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


def phase_noise_rad(dc_per_tap_e, amplitude_per_tap_e, read_noise_e=0.0):
    """Shot + read noise phase error ``sqrt(B + sigma_r^2) / (sqrt(2) A)`` (radians).

    Parameters
    ----------
    dc_per_tap_e : array_like
        Mean charge per tap ``B`` (signal, ambient and dark), electrons.
    amplitude_per_tap_e : array_like
        Modulated amplitude per tap ``A = c_d |P|``, electrons.
    read_noise_e : float
    """
    return np.sqrt(np.asarray(dc_per_tap_e, float) + float(read_noise_e) ** 2) / (np.sqrt(2.0) * np.asarray(amplitude_per_tap_e, float))


@dataclass
class TofFrame:
    """One frame of the ToF camera.

    Attributes
    ----------
    gray : ndarray of float32, shape (H, W)
        Active mode: amplitude (DN); passive mode: mean of the taps (DN).
    depth_m : ndarray of float32, shape (H, W)
        Radial phase depth (wrapped at ``c / 2f``); NaN where invalid (and everywhere in
        passive mode).
    amplitude_dn : ndarray of float32, shape (H, W)
    intensity_dn : ndarray of float32, shape (H, W)
        Mean of the four taps.
    saturated : ndarray of bool, shape (H, W)
        A tap's well or ADC clipped.
    taps_dn : ndarray of float32, shape (4, H, W)
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


@dataclass(frozen=True)
class TofSensor:
    """The AMCW pixel and read-out (see the module notes for the model).

    Attributes
    ----------
    modulation_frequency_hz : float
        Must equal the frequency the :class:`RenderedTof` was rendered for.
    demodulation_contrast : float
        ``c_d`` in (0, 1].
    quantum_efficiency, transmittance : float
        At 850 nm; transmittance of lens + band-pass filter.
    read_noise_e, full_well_e, dark_current_e_per_s : float
    adc_bits : int
    ambient_suppression : float
        Fraction of the ambient charge removed by background suppression (active mode).
    ambient_lux : float
        Ambient illuminance (the paper: 1000 lux normal, 10000 lux high).
    ambient_w_m2_per_lux : float
        In-band (850 nm filter) irradiance per lux of the ambient light.
    integration_time_s : float or None
        Per tap (DCS); None: automatic (:meth:`auto_integration_time`).
    integration_time_min_s, integration_time_max_s : float
        Limits of the automatic integration time.
    auto_exposure_target : float
        Automatic integration time puts the brightest pixel's peak tap at this fraction of
        the full well.
    min_amplitude_dn : float
        Depth is invalid (NaN) below this amplitude.
    """

    modulation_frequency_hz: float = 10.0e6
    demodulation_contrast: float = 0.6
    quantum_efficiency: float = 0.25
    transmittance: float = 0.9
    read_noise_e: float = 30.0
    full_well_e: float = 1.0e5
    dark_current_e_per_s: float = 1000.0
    adc_bits: int = 12
    ambient_suppression: float = 0.9
    ambient_lux: float = 1000.0
    ambient_w_m2_per_lux: float = 4.1e-4
    integration_time_s: float | None = None
    integration_time_min_s: float = 1.0e-5
    integration_time_max_s: float = 2.0e-3
    auto_exposure_target: float = 0.5
    min_amplitude_dn: float = 3.0

    def __post_init__(self):
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name == "integration_time_s" and v is None:
                continue
            zero_ok = f.name in ("read_noise_e", "dark_current_e_per_s", "ambient_suppression", "ambient_lux",
                                 "ambient_w_m2_per_lux", "min_amplitude_dn")
            check_finite_positive(v, f"tof sensor {f.name}", allow_zero=zero_ok)
        for k in ("demodulation_contrast", "quantum_efficiency", "transmittance", "ambient_suppression",
                  "auto_exposure_target"):
            if getattr(self, k) > 1:
                raise InputError(f"tof sensor {k}: expected a fraction in [0, 1], got {getattr(self, k)!r}")
        if int(self.adc_bits) != self.adc_bits or not 1 <= self.adc_bits <= 24:
            raise InputError(f"tof sensor adc_bits: expected an integer 1..24, got {self.adc_bits!r}")
        if self.integration_time_min_s > self.integration_time_max_s:
            raise InputError("tof sensor: integration_time_min_s exceeds integration_time_max_s")

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_camera(cls, camera, **overrides) -> "TofSensor":
        """Parameters from a camera profile's ``[tof]``, ``[noise]`` and ``[optics]`` tables.

        Keys read: ``tof.modulation_frequency_hz, demodulation_contrast, adc_bits,
        integration_time_s`` (a number, or ``"auto"``), ``integration_time_min_s``,
        ``integration_time_max_s``, ``auto_exposure_target``, ``min_amplitude_dn``;
        ``noise.quantum_efficiency, read_noise_e, full_well_e, dark_current_e_per_s,
        ambient_lux, ambient_w_m2_per_lux, ambient_suppression``; ``optics.transmittance``.
        Missing keys keep the class defaults. ``overrides`` replace fields (None values are
        ignored, except ``integration_time_s=None`` is "auto" only when given as ``"auto"``).
        """
        t = dict(camera.tables.get("tof") or {})
        n = dict(camera.tables.get("noise") or {})
        o = dict(camera.tables.get("optics") or {})
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
        return asdict(self)

    # ------------------------------------------------------------------ radiometry
    @property
    def gain_dn_per_e(self) -> float:
        return (2 ** int(self.adc_bits) - 1) / self.full_well_e

    @property
    def ambient_radiance_w_m2_sr(self) -> float:
        """Radiance of the uniform ambient sky (in band): ``E / pi``."""
        return self.ambient_lux * self.ambient_w_m2_per_lux / np.pi

    def _check(self, rendered: RenderedTof):
        if abs(rendered.modulation_frequency_hz - self.modulation_frequency_hz) > 1e-6 * self.modulation_frequency_hz:
            raise InputError(f"rendered frame was made for {rendered.modulation_frequency_hz:g} Hz but the sensor "
                             f"modulates at {self.modulation_frequency_hz:g} Hz; render again with that frequency")

    def electrons(self, rendered: RenderedTof, integration_time_s: float, mode: str = "active") -> dict:
        """Expected charges of one tap's integration (electrons, shape (H, W) each).

        Returns
        -------
        dict
            ``signal`` (S), ``phasor`` (P, complex), ``ambient`` (Amb), ``dark`` (D, scalar).
        """
        T = check_finite_positive(integration_time_s, "integration_time_s")
        k = rendered.photons_per_radiance * self.quantum_efficiency * self.transmittance * T
        on = 1.0 if mode == "active" else 0.0
        return {"signal": on * rendered.active_radiance * k, "phasor": on * rendered.phasor_radiance * k,
                "ambient": rendered.ambient_factor * self.ambient_radiance_w_m2_sr * k,
                "dark": self.dark_current_e_per_s * T}

    def tap_means_e(self, rendered: RenderedTof, integration_time_s: float, mode: str = "active") -> np.ndarray:
        """Expected tap charges ``mu_k`` (before suppression), shape (4, H, W), electrons."""
        e = self.electrons(rendered, integration_time_s, mode)
        dc = e["signal"] + e["ambient"] + e["dark"]
        cd = self.demodulation_contrast if mode == "active" else 0.0
        return np.stack([dc + cd * np.real(e["phasor"] * np.exp(-0.5j * np.pi * k)) for k in range(4)])

    def auto_integration_time(self, rendered: RenderedTof, mode: str = "active") -> float:
        """Integration time putting the brightest peak tap (after suppression) at
        ``auto_exposure_target`` of the full well, within the limits."""
        self._check(rendered)
        e = self.electrons(rendered, 1.0, mode)
        s = self.ambient_suppression if mode == "active" else 0.0
        cd = self.demodulation_contrast if mode == "active" else 0.0
        peak = e["signal"] + (1 - s) * e["ambient"] + e["dark"] + cd * np.abs(e["phasor"])
        top = float(np.max(peak)) if peak.size else 0.0
        if top <= 0:
            return float(self.integration_time_max_s)
        return float(np.clip(self.auto_exposure_target * self.full_well_e / top,
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
            False: the expected taps (no shot/read noise, no quantisation).

        Returns
        -------
        TofFrame
        """
        if mode not in ("active", "passive"):
            raise InputError(f"mode: expected 'active' or 'passive', got {mode!r}")
        self._check(rendered)
        T = integration_time_s if integration_time_s is not None else self.integration_time_s
        T = self.auto_integration_time(rendered, mode) if T is None else check_finite_positive(T, "integration_time_s")
        mu = self.tap_means_e(rendered, T, mode)
        amb = self.electrons(rendered, T, mode)["ambient"]
        s = self.ambient_suppression if mode == "active" else 0.0
        if noise:
            rng = np.random.default_rng(rng)
            q = rng.poisson(np.maximum(mu, 0.0)).astype(np.float64)
        else:
            q = mu.copy()
        q -= s * amb
        sat = np.any(q > self.full_well_e, axis=0)
        q = np.minimum(q, self.full_well_e)
        if noise and self.read_noise_e > 0:
            q += rng.normal(0.0, self.read_noise_e, q.shape)
        dn = q * self.gain_dn_per_e
        top = 2 ** int(self.adc_bits) - 1
        if noise:
            dn = np.round(dn)
        sat |= np.any(dn >= top, axis=0)
        dn = np.clip(dn, 0.0, top)
        i_ = dn.mean(0)
        re, im = dn[0] - dn[2], dn[1] - dn[3]
        amp = 0.5 * np.hypot(re, im)
        if mode == "active":
            phi = np.mod(np.arctan2(im, re), 2 * np.pi)
            depth = SPEED_OF_LIGHT_M_S * phi / (4 * np.pi * self.modulation_frequency_hz)
            depth = np.where(depth >= unambiguous_range_m(self.modulation_frequency_hz), 0.0, depth)
            ok = (amp >= self.min_amplitude_dn) & ~sat
            depth = np.where(ok, depth, np.nan)
            gray = amp
        else:
            depth = np.full(amp.shape, np.nan)
            gray = i_
        f32 = np.float32
        return TofFrame(gray=gray.astype(f32), depth_m=depth.astype(f32), amplitude_dn=amp.astype(f32),
                        intensity_dn=i_.astype(f32), saturated=sat, taps_dn=dn.astype(f32),
                        integration_time_s=float(T), mode=mode)

    def frames(self, rendered: RenderedTof, n: int, seed=None, **kw):
        """``n`` frames from one seeded generator (a generator of :class:`TofFrame`)."""
        rng = np.random.default_rng(seed)
        for _ in range(int(n)):
            yield self.frame(rendered, rng, **kw)
