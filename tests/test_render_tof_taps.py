"""The AMCW 4-tap pixel model (camera/amcw.py): numpy only, no rendering."""

import numpy as np
import pytest

from camera.amcw import RenderedTof, TofSensor, phase_noise_rad, phasor_depth_m, unambiguous_range_m
from svgs.errors import InputError

C_LIGHT_M_S = 299_792_458.0  # exact (SI); the test's own value, not the code's

F_MOD = 10.0e6


def flat(depth_m, radiance=1.0, ambient=0.0, shape=(24, 24), photons=1.0e9, f=F_MOD):
    """A uniform rendered frame: every pixel returns ``radiance`` from ``depth_m``."""
    k = 4 * np.pi * f / C_LIGHT_M_S
    ones = np.ones(shape)
    return RenderedTof(active_radiance=radiance * ones, phasor_radiance=radiance * np.exp(1j * k * depth_m) * ones,
                       ambient_factor=ambient * ones, photons_per_radiance=photons * ones, hit_fraction=ones,
                       range_first_m=depth_m * ones, modulation_frequency_hz=f)


SENSOR = TofSensor(modulation_frequency_hz=F_MOD, demodulation_contrast=0.6, quantum_efficiency=0.25,
                   transmittance=0.9, read_noise_e=30.0, full_well_e=1.0e5, dark_current_e_per_s=1000.0,
                   adc_bits=12, ambient_suppression=0.9, ambient_lux=1000.0, ambient_w_m2_per_lux=4.1e-4,
                   integration_time_s=1.0e-4, min_amplitude_dn=3.0)


def test_depth_is_unbiased_and_its_noise_follows_the_shot_noise_formula():
    rd = flat(3.3, radiance=0.4, ambient=5.0)
    T = SENSOR.integration_time_s
    e = SENSOR.electrons(rd, T)
    B = float((e["signal"] + e["ambient"] + e["dark"]).mean())  # DC per tap
    A = float(SENSOR.demodulation_contrast * np.abs(e["phasor"]).mean())  # amplitude per tap
    q_var = (1 / SENSOR.gain_dn_per_e) ** 2 / 12  # ADC quantisation, e^2
    sig_phi = phase_noise_rad(B, A, np.sqrt(SENSOR.read_noise_e**2 + q_var))
    sig_d = C_LIGHT_M_S * sig_phi / (4 * np.pi * F_MOD)
    d = np.stack([f.depth_m for f in SENSOR.frames(rd, 60, seed=3)]).astype(float)
    assert np.all(np.isfinite(d))
    n = d.size
    assert abs(d.mean() - 3.3) < 4 * sig_d / np.sqrt(n)
    assert d.std() == pytest.approx(sig_d, rel=0.05)
    # ambient adds shot noise even though suppression removes its charge
    dark = SENSOR.replace(ambient_lux=0.0)
    d0 = np.stack([f.depth_m for f in dark.frames(rd, 60, seed=3)]).astype(float)
    assert d0.std() < 0.8 * d.std()


def test_amplitude_is_the_demodulated_phasor_and_gray_modes():
    rd = flat(1.0, radiance=0.2, ambient=1.0)
    T = 2e-4
    fr = SENSOR.frame(rd, integration_time_s=T, noise=False)
    e = SENSOR.electrons(rd, T)
    expect = SENSOR.gain_dn_per_e * SENSOR.demodulation_contrast * np.abs(e["phasor"])
    np.testing.assert_allclose(fr.amplitude_dn, expect, rtol=1e-5)
    np.testing.assert_allclose(fr.gray, fr.amplitude_dn)
    np.testing.assert_allclose(fr.depth_m, 1.0, atol=1e-5)
    # half the radiance, half the amplitude (a linear camera)
    half = SENSOR.frame(flat(1.0, radiance=0.1, ambient=1.0), integration_time_s=T, noise=False)
    np.testing.assert_allclose(half.amplitude_dn, 0.5 * fr.amplitude_dn, rtol=1e-5)
    # passive gray mode: illumination off, the image is the ambient (+ dark) charge, no depth
    pas = SENSOR.frame(rd, integration_time_s=T, mode="passive", noise=False)
    np.testing.assert_allclose(pas.gray, SENSOR.gain_dn_per_e * (e["ambient"] + e["dark"]), rtol=1e-5)
    assert np.all(np.isnan(pas.depth_m)) and np.all(pas.amplitude_dn < 1e-6)
    # active mode suppresses 90 % of the ambient charge
    np.testing.assert_allclose(fr.intensity_dn, SENSOR.gain_dn_per_e * (e["signal"] + 0.1 * e["ambient"] + e["dark"]), rtol=1e-5)


def test_phase_wraps_at_the_unambiguous_range():
    U = unambiguous_range_m(F_MOD)
    assert U == pytest.approx(14.9896229, abs=1e-6)
    for d in (0.3 * U, 1.3 * U, 2.05 * U):
        fr = SENSOR.frame(flat(d, radiance=0.5), noise=False)
        np.testing.assert_allclose(fr.depth_m, d % U, atol=1e-4)
        np.testing.assert_allclose(phasor_depth_m(flat(d).phasor_radiance, F_MOD), d % U, atol=1e-6)


def test_saturation_and_low_amplitude_invalidate_depth():
    rd = flat(2.0, radiance=1.0)
    sat = SENSOR.frame(rd, integration_time_s=1e-2, rng=1)
    assert sat.saturated.all() and np.all(np.isnan(sat.depth_m))
    faint = SENSOR.frame(flat(2.0, radiance=1e-9), rng=1)
    assert np.all(np.isnan(faint.depth_m))


def test_auto_integration_time_puts_the_peak_tap_at_the_target():
    rd = flat(1.5, radiance=0.3, ambient=0.5)
    auto = SENSOR.replace(integration_time_s=None, integration_time_max_s=1.0)
    T = auto.auto_integration_time(rd)
    e = auto.electrons(rd, T)
    peak = e["signal"] + (1 - auto.ambient_suppression) * e["ambient"] + e["dark"] + auto.demodulation_contrast * np.abs(e["phasor"])
    assert peak.max() == pytest.approx(auto.auto_exposure_target * auto.full_well_e, rel=1e-6)  # any phase
    mu = auto.tap_means_e(rd, T) - auto.ambient_suppression * e["ambient"]
    assert mu.max() <= peak.max() * (1 + 1e-9)
    fr = auto.frame(rd, rng=2)
    assert fr.integration_time_s == pytest.approx(T) and not fr.saturated.any()
    # a faint scene hits the upper limit
    assert auto.replace(integration_time_max_s=2e-3).auto_integration_time(flat(1.5, radiance=1e-6)) == 2e-3


def test_frames_are_seeded():
    rd = flat(2.0, radiance=0.3)
    a = [f.depth_m for f in SENSOR.frames(rd, 2, seed=5)]
    b = [f.depth_m for f in SENSOR.frames(rd, 2, seed=5)]
    c = [f.depth_m for f in SENSOR.frames(rd, 2, seed=6)]
    np.testing.assert_array_equal(a[1], b[1])
    assert not np.array_equal(a[1], c[1]) and not np.array_equal(a[0], a[1])


def test_profile_and_bad_parameters():
    from tof import load_camera

    s = TofSensor.from_camera(load_camera("tof-epc660"))
    assert s.modulation_frequency_hz == 10e6 and s.integration_time_s is None and s.ambient_lux == 1000.0
    assert TofSensor.from_camera(load_camera("tof-epc660"), integration_time_s=1e-3).integration_time_s == 1e-3
    with pytest.raises(InputError, match="unknown parameter"):
        TofSensor.from_camera(load_camera("tof-epc660"), exposure=1)
    with pytest.raises(InputError, match="demodulation_contrast"):
        SENSOR.replace(demodulation_contrast=1.5)
    with pytest.raises(InputError, match="read_noise_e"):
        SENSOR.replace(read_noise_e=float("nan"))
    with pytest.raises(InputError, match="rendered frame was made for"):
        SENSOR.frame(flat(1.0, f=20e6))
    with pytest.raises(InputError, match="mode"):
        SENSOR.frame(flat(1.0), mode="gray")
