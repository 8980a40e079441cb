"""The AMCW 4-tap pixel model (svgs_sim/camera/amcw.py): numpy only, no rendering."""

import numpy as np
import pytest

from svgs_sim.camera.amcw import RenderedTof, TofSensor, phase_noise_rad, phasor_depth_m, unambiguous_range_m
from svgs_sim.base.errors import InputError

C_LIGHT_M_S = 299_792_458.0  # exact (SI); the test's own value, not the code's

F_MOD = 10.0e6


def flat(depth_m, radiance=1.0, ambient=0.0, shape=(24, 24), photons=1.0e9, f=F_MOD):
    """A uniform rendered frame: every pixel returns ``radiance`` from ``depth_m``."""
    k = 4 * np.pi * f / C_LIGHT_M_S
    ones = np.ones(shape)
    return RenderedTof(active_radiance=radiance * ones, phasor_radiance=radiance * np.exp(1j * k * depth_m) * ones,
                       ambient_factor=ambient * ones, photons_per_radiance=photons * ones, hit_fraction=ones,
                       range_first_m=depth_m * ones, modulation_frequency_hz=f)


SENSOR = TofSensor(modulation_frequency_hz=F_MOD, demodulation_contrast=0.39, quantum_efficiency=0.8,
                   transmittance=0.9, read_noise_e=30.0, full_well_e=8.0e6, dark_current_e_per_s=1000.0,
                   adc_bits=12, ambient_suppression=0.9, ambient_lux=1000.0, ambient_w_m2_per_lux=4.1e-4,
                   integration_time_s=1.0e-5, min_amplitude_dn=25.0)

#: Planck constant (exact, SI), the test's own value.
H_J_S = 6.62607015e-34
#: The EPC660 datasheet V2.20, Table 5: TOF sensitivity at 850 nm (nW/mm^2 per LSB at 100 us).
S_TOF_NW_MM2 = 0.6
PIXEL_AREA_MM2 = 0.020**2


def depth_sigma_m(sensor, rd, T):
    """Shot + read + quantisation noise of one 4-DCS depth frame, written out here:

    DCS_k = A_k - B_k with Poisson taps of means (N +- m_k) / 2, so var(DCS_k) = N + 2 s_r^2
    (+ g^2 / 12 of the ADC); DCS2 - DCS0 and DCS3 - DCS1 have twice that and the mean
    2 c_d |P|, hence sigma_phi = sqrt(2 var(DCS)) / (2 c_d |P|)."""
    T = float(T)
    ppr = float(rd.photons_per_radiance.mean())
    k = ppr * sensor.quantum_efficiency * sensor.transmittance * T
    N = k * float(rd.active_radiance.mean() + rd.ambient_factor.mean() * sensor.ambient_lux
                  * sensor.ambient_w_m2_per_lux / np.pi) + sensor.dark_current_e_per_s * T
    M = sensor.demodulation_contrast * k * float(np.abs(rd.phasor_radiance).mean())
    g = sensor.gain_e_per_lsb
    var_dcs = N + 2 * sensor.read_noise_e**2 + g**2 / 12
    sig_phi = np.sqrt(2 * var_dcs) / (2 * M)
    return C_LIGHT_M_S * sig_phi / (4 * np.pi * sensor.modulation_frequency_hz), M / g


@pytest.mark.parametrize("amplitude_lsb", [120.0, 600.0, 1500.0])
def test_depth_is_unbiased_and_its_noise_follows_the_shot_noise_formula(amplitude_lsb):
    rd = flat(3.3, radiance=0.3, ambient=5.0)
    T = amplitude_lsb / float(SENSOR.expected_amplitude_lsb(rd, 1.0).mean())
    sig_d, amp_lsb = depth_sigma_m(SENSOR, rd, T)
    assert amp_lsb == pytest.approx(amplitude_lsb, rel=1e-6)  # the test's radiometry = the module's
    d = np.stack([f.depth_m for f in SENSOR.frames(rd, 60, seed=3, integration_time_s=T)]).astype(float)
    assert np.all(np.isfinite(d))
    n = d.size
    assert abs(d.mean() - 3.3) < 4 * sig_d / np.sqrt(n)
    assert d.std() == pytest.approx(sig_d, rel=0.05)
    # the module's closed form agrees with the one written out above
    e = SENSOR.electrons(rd, T)
    N = float((e["signal"] + e["ambient"] + e["dark"]).mean())  # noqa: N806
    M = float(SENSOR.demodulation_contrast * np.abs(e["phasor"]).mean())
    q = SENSOR.gain_e_per_lsb**2 / 12
    phi = phase_noise_rad(N, M, np.sqrt(SENSOR.read_noise_e**2 + q / 2))
    assert C_LIGHT_M_S * phi / (4 * np.pi * F_MOD) == pytest.approx(sig_d, rel=1e-6)
    # ambient adds shot noise although its charge cancels in the DCS differences
    dark = SENSOR.replace(ambient_lux=0.0)
    d0 = np.stack([f.depth_m for f in dark.frames(rd, 60, seed=3, integration_time_s=T)]).astype(float)
    assert d0.std() < d.std()
    assert abs(d0.mean() - d.mean()) < 4 * sig_d / np.sqrt(n) * 2


def test_amplitude_reproduces_the_datasheet_sensitivity():
    """An irradiance E on the pixel for T gives E T / (S_TOF x 100 us) LSB of amplitude (EPC660 Table 5)."""
    T = 2.0e-5
    ppr = 1.0e9
    rd = flat(1.0, radiance=0.2, ambient=1.0, photons=ppr)
    fr = SENSOR.frame(rd, integration_time_s=T, noise=False)
    # irradiance at the pixel (after the lens and filter): photons/s x h nu / area
    e_w_mm2 = 0.2 * ppr * SENSOR.transmittance * H_J_S * C_LIGHT_M_S / 850e-9 / PIXEL_AREA_MM2
    expect_lsb = (e_w_mm2 * 1e9) * T / (S_TOF_NW_MM2 * 1e-4)
    np.testing.assert_allclose(fr.amplitude_dn, expect_lsb, rtol=1e-4)
    np.testing.assert_allclose(fr.gray, fr.amplitude_dn)
    np.testing.assert_allclose(fr.depth_m, 1.0, atol=1e-5)
    # half the radiance, half the amplitude (a linear camera); ambient does not enter the amplitude
    half = SENSOR.frame(flat(1.0, radiance=0.1, ambient=7.0, photons=ppr), integration_time_s=T, noise=False)
    np.testing.assert_allclose(half.amplitude_dn, 0.5 * fr.amplitude_dn, rtol=1e-5)
    # passive gray mode: illumination off, the ambient charge at the grayscale sensitivity (0.25 nW/mm^2/LSB)
    pas = SENSOR.frame(rd, integration_time_s=T, mode="passive", noise=False)
    amb_w_mm2 = 1.0 * 1000.0 * 4.1e-4 / np.pi * ppr * SENSOR.transmittance * H_J_S * C_LIGHT_M_S / 850e-9 / PIXEL_AREA_MM2
    dark_lsb = SENSOR.dark_current_e_per_s * T / SENSOR.gray_gain_e_per_lsb
    np.testing.assert_allclose(pas.gray, amb_w_mm2 * 1e9 * T / (0.25 * 1e-4) + dark_lsb, rtol=1e-4)
    assert np.all(np.isnan(pas.depth_m)) and np.all(pas.amplitude_dn < 1e-6)


def test_the_datasheet_distance_noise_figure_at_250_lsb():
    """EPC660 datasheet 9.5: about 2.5 cm (1 sigma) at ~250 LSB amplitude, no ambient (12 MHz
    default). The profile's demodulation contrast was derived from this figure, so this checks
    the chain (sensitivity -> gain -> taps -> noise) reproduces it."""
    from svgs_sim.tof import load_camera

    s = TofSensor.from_camera(load_camera("tof-epc660"), modulation_frequency_hz=12e6, ambient_lux=0.0)
    rd = flat(2.0, radiance=1.0, f=12e6)
    T = 250.0 / float(s.expected_amplitude_lsb(rd, 1.0).mean())
    fr = s.frame(rd, integration_time_s=T, noise=False)
    assert float(fr.amplitude_dn.mean()) == pytest.approx(250.0, rel=1e-4)
    d = np.stack([f.depth_m for f in s.frames(rd, 40, seed=1, integration_time_s=T)]).astype(float)
    assert d.std() == pytest.approx(0.025, rel=0.1)


def test_phase_wraps_at_the_unambiguous_range():
    U = unambiguous_range_m(F_MOD)
    assert U == pytest.approx(14.9896229, abs=1e-6)
    for d in (0.3 * U, 1.3 * U, 2.05 * U):
        fr = SENSOR.frame(flat(d, radiance=0.5), noise=False)
        np.testing.assert_allclose(fr.depth_m, d % U, atol=1e-4)
        np.testing.assert_allclose(phasor_depth_m(flat(d).phasor_radiance, F_MOD), d % U, atol=1e-6)


def test_saturation_and_low_amplitude_invalidate_depth():
    rd = flat(2.0, radiance=1.0)
    # the DCS range: 2047 LSB; a return 3x beyond it clips every DCS near its peak (SAT flag, no depth)
    T_full = 2047.0 / float(SENSOR.expected_amplitude_lsb(rd, 1.0).mean())
    sat = SENSOR.frame(rd, integration_time_s=3 * T_full, rng=1)
    assert sat.saturated.all() and np.all(np.isnan(sat.depth_m))
    ok = SENSOR.frame(rd, integration_time_s=0.5 * T_full, rng=1)
    assert not ok.saturated.any() and np.all(np.isfinite(ok.depth_m))
    # the storage node fills with ambient light that the suppression does not remove
    bright = flat(2.0, radiance=1e-3, ambient=1e7)
    assert SENSOR.frame(bright, integration_time_s=1e-4, noise=False).saturated.all()
    faint = SENSOR.frame(flat(2.0, radiance=1e-9), rng=1)
    assert np.all(np.isnan(faint.depth_m))


def test_auto_integration_time_puts_the_brightest_amplitude_at_the_target():
    rd = flat(1.5, radiance=0.3, ambient=0.5)
    auto = SENSOR.replace(integration_time_s=None, integration_time_max_s=1.0)
    T = auto.auto_integration_time(rd)
    fr = auto.frame(rd, noise=False)
    assert fr.integration_time_s == pytest.approx(T)
    assert float(fr.amplitude_dn.max()) == pytest.approx(auto.auto_exposure_target * 2047, rel=1e-6)
    assert not auto.frame(rd, rng=2).saturated.any()
    # a faint scene hits the upper limit, a bright one the lower
    assert auto.replace(integration_time_max_s=2e-3).auto_integration_time(flat(1.5, radiance=1e-6)) == 2e-3
    assert auto.auto_integration_time(flat(1.5, radiance=1e6)) == auto.integration_time_min_s


def test_frames_are_seeded():
    rd = flat(2.0, radiance=0.3)
    a = [f.depth_m for f in SENSOR.frames(rd, 2, seed=5)]
    b = [f.depth_m for f in SENSOR.frames(rd, 2, seed=5)]
    c = [f.depth_m for f in SENSOR.frames(rd, 2, seed=6)]
    np.testing.assert_array_equal(a[1], b[1])
    assert not np.array_equal(a[1], c[1]) and not np.array_equal(a[0], a[1])


def test_profile_and_bad_parameters():
    from svgs_sim.tof import load_camera

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
