"""The phone's lens and flash, read from the camera profile; radiometry in numpy.

Profile tables used (all optional for solving, required for rendering)::

    [optics]
    focal_length_m = 0.00343      # thin-lens focal length
    f_number = 2.4                # aperture radius = focal_length_m / (2 f_number)
    focus_distance_m = 1.8        # object distance in focus
    band_nm = [400.0, 700.0]      # the band the flux is counted in

    [flash]
    led_offsets_m = [[0.008, 0.0, 0.0]]  # LED centre(s) minus lens centre, OpenCV camera frame, m
    emitter_diameter_m = 0.0012   # emitting disk of each LED, m
    luminous_intensity_cd = 10.0  # on-axis, per LED   (or radiant_intensity_w_sr, in band)
    cos_exponent = 1.0            # I(theta) = I0 cos^m(theta); 1 = Lambertian
    spectrum = "white-led"        # see WHITE_LED; used to convert cd -> W/sr and W -> photons

    [sensor]
    pixel_pitch_m = 1.4e-6        # optional, for the truth record

Radiometric chain (see ``docs/renderer.md``): the renderer returns radiance ``L``
(W m^-2 sr^-1, in band) per pixel; a pixel at normalised coordinates ``(x, y)``
collects ``P = L * A_ap * cos(theta) * Omega_pix`` watts, ``A_ap = pi (f / 2N)^2``,
``Omega_pix = cos^3(theta) / (fx fy |J|)`` (``|J|`` the distortion Jacobian, 1 without
distortion), ``cos(theta) = 1 / sqrt(1 + x^2 + y^2)``; photons per second are
``P / E_ph`` with ``E_ph`` the mean photon energy of the flash spectrum in the band.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from svgs_sim.base.errors import InputError, ProfileError, check_finite, check_finite_positive

from .constants import (
    CIE_V,
    CIE_V_WAVELENGTH_NM,
    LUMINOUS_EFFICACY_MAX_LM_W,
    PLANCK_J_S,
    SPEED_OF_LIGHT_M_S,
)

#: Built-in white phosphor-converted LED spectrum: a blue InGaN peak plus a broad
#: YAG:Ce phosphor band, each Gaussian: (centre nm, FWHM nm, relative peak height).
#: ASSUMPTION: typical of cool-white phone flash LEDs of 2011 (CCT ~ 6000 K); no
#: datasheet of the two phones' LEDs was found.
WHITE_LED = ((450.0, 20.0, 1.0), (560.0, 120.0, 0.55))
SPECTRA = {"white-led": WHITE_LED}


def spectrum(name: str, wavelength_nm) -> np.ndarray:
    """Relative spectral power of a named spectrum (W/nm, arbitrary scale)."""
    if name not in SPECTRA:
        raise InputError(f"flash.spectrum: unknown spectrum {name!r}; known {sorted(SPECTRA)}")
    wl = np.asarray(wavelength_nm, float)
    out = np.zeros_like(wl)
    for c, fwhm, a in SPECTRA[name]:
        s = fwhm / (2.0 * np.sqrt(2.0 * np.log(2.0)))
        out += a * np.exp(-0.5 * ((wl - c) / s) ** 2)
    return out


def photometry(name: str, band_nm) -> dict:
    """Photometric and photon-counting figures of a spectrum.

    Returns
    -------
    dict
        ``luminous_efficacy_lm_per_w`` (K_r over 380-780 nm), ``band_fraction`` (share
        of the radiant power inside ``band_nm``), ``mean_photon_energy_j`` (in band),
        ``mean_wavelength_nm`` (photon-weighted, in band).
    """
    wl = np.arange(360.0, 830.01, 0.5)
    s = spectrum(name, wl)
    v = np.interp(wl, CIE_V_WAVELENGTH_NM, CIE_V, left=0.0, right=0.0)
    total = np.trapezoid(s, wl)
    K = LUMINOUS_EFFICACY_MAX_LM_W * np.trapezoid(s * v, wl) / total
    inb = (wl >= band_nm[0]) & (wl <= band_nm[1])
    p_band = np.trapezoid(s[inb], wl[inb])
    photons = np.trapezoid(s[inb] * wl[inb] * 1e-9 / (PLANCK_J_S * SPEED_OF_LIGHT_M_S), wl[inb])
    return {
        "luminous_efficacy_lm_per_w": float(K),
        "band_fraction": float(p_band / total),
        "mean_photon_energy_j": float(p_band / photons),
        "mean_wavelength_nm": float(PLANCK_J_S * SPEED_OF_LIGHT_M_S / (p_band / photons) * 1e9),
    }


@dataclass(frozen=True)
class Optics:
    """Thin-lens optics of a camera profile.

    Attributes
    ----------
    focal_length_m, f_number, focus_distance_m : float
    band_nm : tuple of float
        (low, high) wavelength of the band the flux is counted in, nm.
    pixel_pitch_m : float or None
    """

    focal_length_m: float
    f_number: float
    focus_distance_m: float
    band_nm: tuple
    pixel_pitch_m: float | None = None

    @property
    def aperture_radius_m(self) -> float:
        return self.focal_length_m / (2.0 * self.f_number)

    @property
    def aperture_area_m2(self) -> float:
        return float(np.pi * self.aperture_radius_m ** 2)

    def to_json(self) -> dict:
        d = asdict(self)
        d["band_nm"] = list(self.band_nm)
        d["aperture_radius_m"] = self.aperture_radius_m
        d["aperture_area_m2"] = self.aperture_area_m2
        return d

    @classmethod
    def from_camera(cls, camera) -> "Optics":
        """Read ``[optics]`` (and ``[sensor] pixel_pitch_m``) from a camera profile."""
        t = camera.table("optics")
        where = f"camera {camera.name!r} [optics]"
        for k in ("focal_length_m", "f_number", "focus_distance_m"):
            if getattr(t, k) is None:
                raise ProfileError(f"{where} lacks {k}")
        f = _p(check_finite_positive, t.focal_length_m, f"{where}.focal_length_m")
        n = _p(check_finite_positive, t.f_number, f"{where}.f_number")
        fd = _p(check_finite_positive, t.focus_distance_m, f"{where}.focus_distance_m")
        band = t.given("band_nm", [400.0, 700.0])
        try:
            band = (float(band[0]), float(band[1]))
        except (TypeError, ValueError, IndexError):
            raise ProfileError(f"{where}.band_nm: expected [low, high] in nm, got {band!r}") from None
        if not (200.0 <= band[0] < band[1] <= 2000.0):
            raise ProfileError(f"{where}.band_nm: expected 200 <= low < high <= 2000 nm, got {list(band)}")
        pitch = camera.sensor.pixel_pitch_m
        if pitch is not None:
            pitch = _p(check_finite_positive, pitch, f"camera {camera.name!r} [sensor].pixel_pitch_m")
        return cls(focal_length_m=f, f_number=n, focus_distance_m=fd, band_nm=band, pixel_pitch_m=pitch)


@dataclass(frozen=True)
class Flash:
    """The phone's flash LED(s).

    Attributes
    ----------
    led_offsets_m : ndarray, shape (K, 3)
        Centre of each LED's emitting disk relative to the lens centre, OpenCV camera
        frame (x right, y down, z boresight), m. The disks face along +z.
    emitter_diameter_m : float
    radiant_intensity_w_sr : float
        On-axis radiant intensity of one LED in the band, W/sr.
    cos_exponent : float
        Angular profile ``I(theta) = I0 cos^m(theta)``; radiance ``L0 cos^(m-1)``.
    spectrum : str
    luminous_intensity_cd : float or None
        The profile's value when given photometrically.
    photometry : dict
        See :func:`photometry`.
    """

    led_offsets_m: np.ndarray
    emitter_diameter_m: float
    radiant_intensity_w_sr: float
    cos_exponent: float
    spectrum: str
    luminous_intensity_cd: float | None
    photometry: dict

    @property
    def emitter_area_m2(self) -> float:
        return float(np.pi * (0.5 * self.emitter_diameter_m) ** 2)

    @property
    def radiance_w_m2_sr(self) -> float:
        """On-axis radiance of the emitting disk, W m^-2 sr^-1 (in band)."""
        return self.radiant_intensity_w_sr / self.emitter_area_m2

    def intensity_w_sr(self, cos_theta) -> np.ndarray:
        """Radiant intensity of one LED at angle theta from its axis, W/sr."""
        c = np.clip(np.asarray(cos_theta, float), 0.0, 1.0)
        return self.radiant_intensity_w_sr * c ** self.cos_exponent

    def to_json(self) -> dict:
        return {
            "led_offsets_m": np.asarray(self.led_offsets_m).tolist(),
            "emitter_diameter_m": self.emitter_diameter_m,
            "emitter_area_m2": self.emitter_area_m2,
            "radiant_intensity_w_sr": self.radiant_intensity_w_sr,
            "radiance_w_m2_sr": self.radiance_w_m2_sr,
            "cos_exponent": self.cos_exponent,
            "spectrum": self.spectrum,
            "spectrum_model": [list(x) for x in SPECTRA.get(self.spectrum, ())],
            "luminous_intensity_cd": self.luminous_intensity_cd,
            **self.photometry,
        }

    @classmethod
    def from_camera(cls, camera, band_nm) -> "Flash":
        """Read the ``[flash]`` table of a camera profile (ProfileError if absent)."""
        t = camera.table("flash")
        where = f"camera {camera.name!r} [flash]"
        offs = t.led_offsets_m
        if offs is None:
            raise ProfileError(f"{where} lacks led_offsets_m (LED centre(s) minus lens centre, camera frame, m)")
        offs = np.asarray(offs, dtype=float)
        if offs.ndim == 1:
            offs = offs[None, :]
        if offs.ndim != 2 or offs.shape[1] != 3 or offs.shape[0] < 1 or not np.all(np.isfinite(offs)):
            raise ProfileError(f"{where}.led_offsets_m: expected [[x, y, z], ...] finite metres, got {t.led_offsets_m!r}")
        if t.emitter_diameter_m is None:
            raise ProfileError(f"{where} lacks emitter_diameter_m")
        dia = _p(check_finite_positive, t.emitter_diameter_m, f"{where}.emitter_diameter_m")
        if np.any(np.hypot(offs[:, 0], offs[:, 1]) < 0.5 * dia):
            raise ProfileError(f"{where}: an LED disk covers the lens centre (offset < emitter radius)")
        m = _p(check_finite, t.given("cos_exponent", 1.0), f"{where}.cos_exponent")
        if not 0.0 <= m <= 50.0:
            raise ProfileError(f"{where}.cos_exponent: expected 0..50, got {m}")
        spec = str(t.given("spectrum", "white-led"))
        if spec not in SPECTRA:
            raise ProfileError(f"{where}.spectrum: unknown {spec!r}; known {sorted(SPECTRA)}")
        ph = photometry(spec, band_nm)
        cd = None
        if t.radiant_intensity_w_sr is not None:
            ie = _p(check_finite_positive, t.radiant_intensity_w_sr, f"{where}.radiant_intensity_w_sr")
        elif t.luminous_intensity_cd is not None:
            cd = _p(check_finite_positive, t.luminous_intensity_cd, f"{where}.luminous_intensity_cd")
            ie = cd / ph["luminous_efficacy_lm_per_w"] * ph["band_fraction"]
        else:
            raise ProfileError(f"{where} needs luminous_intensity_cd or radiant_intensity_w_sr")
        return cls(led_offsets_m=offs, emitter_diameter_m=dia, radiant_intensity_w_sr=float(ie),
                   cos_exponent=float(m), spectrum=spec, luminous_intensity_cd=cd, photometry=ph)


def _p(fn, value, name):
    try:
        return fn(value, name)
    except InputError as exc:
        raise ProfileError(str(exc)) from None


# ------------------------------------------------------------------ radiance -> photons
def pixel_normalized_grid(camera, u0=0, v0=0, width=None, height=None) -> np.ndarray:
    """Undistorted normalised coordinates of pixel centres of a window.

    Returns
    -------
    xy : ndarray, shape (height, width, 2)
    """
    width = camera.width if width is None else width
    height = camera.height if height is None else height
    u, v = np.meshgrid(np.arange(u0, u0 + width, dtype=float), np.arange(v0, v0 + height, dtype=float))
    uv = np.stack([u, v], -1)
    return camera.pixels_to_normalized(uv)


def distortion_jacobian_det(camera, xy) -> np.ndarray:
    """``|det d(x_d, y_d)/d(x, y)|`` of the profile's distortion at ``xy`` (..., 2)."""
    xy = np.asarray(xy, float)
    if not camera.has_distortion:
        return np.ones(xy.shape[:-1])
    h = 1e-6
    ex, ey = np.array([h, 0.0]), np.array([0.0, h])
    dx = (camera.distort_normalized(xy + ex) - camera.distort_normalized(xy - ex)) / (2 * h)
    dy = (camera.distort_normalized(xy + ey) - camera.distort_normalized(xy - ey)) / (2 * h)
    return np.abs(dx[..., 0] * dy[..., 1] - dx[..., 1] * dy[..., 0])


def pixel_solid_angle_sr(camera, xy) -> np.ndarray:
    """Solid angle seen by the pixels whose centres have normalised coordinates ``xy``."""
    xy = np.asarray(xy, float)
    cos_t = 1.0 / np.sqrt(1.0 + xy[..., 0] ** 2 + xy[..., 1] ** 2)
    return cos_t ** 3 / (camera.fx * camera.fy * distortion_jacobian_det(camera, xy))


def radiance_to_photon_rate(camera, optics: Optics, mean_photon_energy_j: float, xy) -> np.ndarray:
    """Photons per second per pixel for a radiance of 1 W m^-2 sr^-1 (in band).

    ``A_ap * cos(theta) * Omega_pix / E_ph`` at the pixels' normalised coordinates
    ``xy`` (..., 2); multiply by the rendered radiance.
    """
    xy = np.asarray(xy, float)
    cos_t = 1.0 / np.sqrt(1.0 + xy[..., 0] ** 2 + xy[..., 1] ** 2)
    return optics.aperture_area_m2 * cos_t * pixel_solid_angle_sr(camera, xy) / mean_photon_energy_j
