"""Phone camera model: EMVA 1288 photon transfer, charge conservation, optics, ISP, AE."""

import numpy as np
import pytest

from svgs_sim.camera.phone import Exposer, PhoneCamera, PhoneParams
from svgs_sim.camera.phone.optics import apply_psf, core_sigma_px
from svgs_sim.camera.phone.params import GlareParams, SensorParams
from svgs_sim.camera.phone.sensor import bloom
from svgs_sim.svgs import Camera, InputError

FLAT_STAGES = ("shot", "dark", "fpn", "read", "bloom", "adc")


def small_camera(w=320, h=240, **tables):
    return Camera(name="test", width=w, height=h, fx=300.0, fy=300.0, cx=(w - 1) / 2, cy=(h - 1) / 2, tables=tables)


def photon_transfer(phone, iso, levels_ph_s, exposure_s=0.01, seed=0):
    """EMVA 1288 photon-transfer method on simulated flat-field pairs.

    Returns K (DN/e-), dark noise sigma_d (e-), the EMVA saturation point (mean at the
    maximum of the temporal variance, e-), and the saturated plateau (e-)."""
    shape = phone.shape
    mu, var = [], []
    dark = Exposer(phone, np.zeros(shape), stages=FLAT_STAGES)
    a = dark.expose(seed=seed, exposure_s=exposure_s, iso=iso).raw_dn.astype(np.float64)
    b = dark.expose(seed=seed + 1, exposure_s=exposure_s, iso=iso).raw_dn.astype(np.float64)
    mu_dark = 0.5 * (a.mean() + b.mean())
    var_dark = np.var(a - b) / 2
    for k, lvl in enumerate(levels_ph_s):
        ex = Exposer(phone, np.full(shape, lvl), stages=FLAT_STAGES)
        a = ex.expose(seed=seed + 10 + 2 * k, exposure_s=exposure_s, iso=iso).raw_dn.astype(np.float64)
        b = ex.expose(seed=seed + 11 + 2 * k, exposure_s=exposure_s, iso=iso).raw_dn.astype(np.float64)
        mu.append(0.5 * (a.mean() + b.mean()) - mu_dark)
        var.append(np.var(a - b) / 2 - var_dark)  # temporal variance, fixed patterns cancel
    mu, var = np.array(mu), np.array(var)
    i_sat = int(np.argmax(var))
    lin = mu < 0.7 * mu[i_sat]  # the linear range of the PTC
    K = np.polyfit(mu[lin], var[lin], 1)[0]
    sigma_d = np.sqrt(max(var_dark - 1 / 12, 0)) / K
    return K, sigma_d, mu[i_sat] / K, mu.max() / K


@pytest.mark.slow
def test_photon_transfer_recovers_profile_parameters():
    sp = SensorParams(full_well_e=6000, read_noise_e=3.0, qe=0.5, prnu=0.01, dsnu_e=1.5, adc_bits=12,
                      black_level_dn=256, dark_current_e_s=20.0)
    phone = PhoneCamera(small_camera(), PhoneParams(sensor=sp))
    iso = 100.0  # base ISO: the full well maps to the ADC's white level
    # exposure 10 ms, qe 0.5: 1.2e6 ph/s -> 6000 e-; fine steps near saturation
    levels = np.concatenate([np.linspace(2e4, 9e5, 12), np.linspace(1.0e6, 1.3e6, 31), [2e6, 3e6]])
    K, sigma_d, sat_e, plateau_e = photon_transfer(phone, iso, levels)
    K_true = sp.gain_dn_per_e(iso)
    print(f"K {K:.5f} vs {K_true:.5f}; sigma_d {sigma_d:.3f} vs {sp.read_noise_e}; sat {sat_e:.0f} vs {sp.full_well_e}")
    # tolerance: a temporal variance from N = 320 x 240 pixel differences has a relative
    # standard error sqrt(2 / N) = 0.5 %; K is fitted over ~20 such levels and sigma_d is a
    # square root (0.26 %): 2 % is > 4 standard errors for each
    assert K == pytest.approx(K_true, rel=0.02)
    # dark temporal noise includes the dark current's shot noise (EMVA: sigma_y.dark)
    expected_dark = np.sqrt(sp.read_noise_e**2 + sp.dark_current_e_s * 0.01)
    assert sigma_d == pytest.approx(expected_dark, rel=0.02)
    # saturation capacity: the saturated plateau is the full well
    assert plateau_e == pytest.approx(sp.full_well_e, rel=0.02)
    # EMVA's saturation point (maximum of the temporal variance) lies below it by the spread
    # of the signal as it clips: shot noise and PRNU, sigma = sqrt(FW + (prnu FW)^2) ~ 98 e-
    spread = np.sqrt(sp.full_well_e + (sp.prnu * sp.full_well_e) ** 2)
    assert sp.full_well_e - 4 * spread < sat_e < sp.full_well_e


@pytest.mark.parametrize("direction", ["isotropic", "column"])
def test_blooming_conserves_charge(direction):
    rng = np.random.default_rng(0)
    e = rng.uniform(0, 3000, (200, 200)).astype(np.float32)
    e[100, 100] = 6000 * 60  # 60 full wells in one pixel (a column of 200 px holds ~150)
    e[60:63, 140:142] = 6000 * 10
    before = float(e.sum(dtype=np.float64))
    stats = bloom(e, 6000.0, drain=0.0, direction=direction)
    after = float(e.sum(dtype=np.float64))
    assert stats["lost_e"] == 0 and stats["drained_e"] == 0
    assert after == pytest.approx(before, rel=1e-6)
    assert e.max() <= 6000.0 * (1 + 1e-6)
    assert stats["bloomed_px"] > 60  # the charge went somewhere visible
    if direction == "column":  # spill stays in the column
        assert np.all(e[:, 98] < 6000) and np.all(e[:, 102] < 6000)


def test_blooming_drain_and_frame_edge():
    e = np.zeros((50, 50), np.float32)
    e[25, 25] = 6000 * 101.0
    stats = bloom(e, 6000.0, drain=0.9, direction="isotropic")
    # 100 full wells of excess, 90 % drained, 10 wells spill into the neighbours
    assert stats["drained_e"] == pytest.approx(6000 * 100 * 0.9, rel=1e-6)
    assert e.sum() == pytest.approx(6000 * 11, rel=1e-5)
    e = np.zeros((20, 20), np.float32)
    e[0, 0] = 6000 * 1000.0  # more than the frame holds
    stats = bloom(e, 6000.0, drain=0.0)
    assert stats["lost_e"] == pytest.approx(6000 * 1000 - 6000 * 400, rel=1e-6)
    assert np.all(e == 6000)


def _wing_share_beyond(r, r_in, glare):
    """Share of the PSF's energy beyond ``r_in`` px carried by the wings: the documented
    wing law eta (1 + r^2/r_c^2)^(-alpha/2) inside R_w, summed over the pixel grid ``r``
    (the discrete sum; the continuous integral differs by ~1 % at r_c = 2 px)."""
    w = (1 + (r / glare.wing_core_px) ** 2) ** (-glare.wing_exponent / 2)
    w[r > glare.wing_radius_px] = 0.0
    return glare.veiling_fraction * w[r > r_in].sum() / w.sum()


def test_psf_conserves_energy_and_core_width():
    f = np.zeros((400, 400), np.float32)
    f[200, 200] = 1e6
    g = GlareParams(aberration_sigma_px=0.0, veiling_fraction=0.01, wing_exponent=3.0, wing_core_px=2.0, wing_radius_px=100)
    s = core_sigma_px(2.4, (400.0, 700.0), 1.4e-6, 0.0)
    assert s == pytest.approx(0.42 * 0.55e-6 * 2.4 / 1.4e-6)
    out = apply_psf(f, g, s)
    # energy: float32 image, relative rounding ~ 6e-8 per value and log2(1.6e5) ~ 17 levels of
    # pairwise summation: 1e-5 bounds it
    assert out.sum(dtype=np.float64) == pytest.approx(1e6, rel=1e-5)
    y, x = np.mgrid[:400, :400]
    r = np.hypot(x - 200, y - 200)
    # the wings carry their share beyond 5 px; the core (sigma 0.4 px) leaves < 1e-30 there
    assert out[r > 5].sum(dtype=np.float64) / 1e6 == pytest.approx(_wing_share_beyond(r, 5, g), rel=1e-5)
    # and the continuous law: energy beyond r ~ (1 + r^2/rc^2)^-0.5 - (1 + R^2/rc^2)^-0.5 for alpha = 3,
    # which the pixel sum approaches to the discretisation error of a 2 px core (~1 %, < 2 %)
    tail = lambda a: (1 + (a / 2.0) ** 2) ** -0.5  # noqa: E731
    assert out[r > 5].sum() / 1e6 == pytest.approx(0.01 * (tail(5) - tail(100)) / (1 - tail(100)), rel=0.02)
    # wing profile between 20 and 80 px: the log-slope of (1 + r^2/rc^2)^(-3/2) between those
    # radii, -1.5 ln(1601/101) / ln 4 = -2.990; ring means (+-2 px, +-5 px) shift it < 0.02
    ring = lambda a, b: out[(r >= a) & (r < b)].mean()  # noqa: E731
    slope = np.log(ring(75, 85) / ring(18, 22)) / np.log(80 / 20)
    assert slope == pytest.approx(-1.5 * np.log(1601 / 101) / np.log(4), abs=0.02)


@pytest.mark.parametrize("name", ["galaxy-nexus", "htc-amaze-4g"])
def test_profile_psf_conserves_energy_with_the_unfitted_glare(name):
    """The model on the physical (unfitted) profile: the PSF keeps the energy of a point
    inside the frame and its wings carry the share the wing law gives."""
    from svgs_sim.camera.phone.params import PhoneParams as PP

    cam = Camera.load(name, fitted=False)
    pp = PP.from_camera(cam)
    g = pp.glare
    n = 2 * int(g.wing_radius_px) + 41  # the whole wing support inside the frame
    f = np.zeros((n, n), np.float32)
    f[n // 2, n // 2] = 1e6
    out = apply_psf(f, g, core_sigma_px(pp.f_number, pp.band_nm, pp.sensor.pixel_pitch_m, g.aberration_sigma_px))
    assert out.sum(dtype=np.float64) == pytest.approx(1e6, rel=1e-5)
    y, x = np.mgrid[:n, :n]
    r = np.hypot(x - n // 2, y - n // 2)
    # beyond 8 px the core (sigma < 1 px) leaves < 1e-14 of the energy
    assert out[r > 8].sum(dtype=np.float64) / 1e6 == pytest.approx(_wing_share_beyond(r, 8, g), rel=1e-4)


def test_auto_exposure_meters_the_target_and_hits_limits():
    cam = small_camera(exposure={"mode": "auto", "metering": "mean", "target_level": 0.18, "max_exposure_s": 0.05,
                                 "max_iso": 800})
    phone = PhoneCamera(cam)
    sp = phone.params.sensor
    # a uniform scene: S (qe flux + dark) / fw = 0.18. Its metered level is linear in S below
    # clipping, so the AE's bisection (60 halvings of the log range) lands on it to double
    # precision: 1e-9 leaves room for rounding only
    flux = np.full(phone.shape, 1e5, np.float32)
    ex = Exposer(phone, flux, stages=("shot", "read", "adc"))
    t, iso, info = ex.auto_exposure()
    S = t * iso / sp.base_iso
    assert (sp.qe * 1e5 + sp.dark_current_e_s) * S / sp.full_well_e == pytest.approx(0.18, rel=1e-9)
    assert not info["limited"]
    # a dark scene: the phone runs into its limits (max exposure, then max ISO)
    ex = Exposer(phone, np.full(phone.shape, 10.0, np.float32), stages=("shot", "read", "adc"))
    t, iso, info = ex.auto_exposure()
    assert t == pytest.approx(0.05) and iso == pytest.approx(800) and info["limited"]


def test_same_seed_same_image_and_render_once_expose_many():
    phone = PhoneCamera(small_camera())
    rng = np.random.default_rng(3)
    flux = rng.uniform(0, 1e5, phone.shape).astype(np.float32)
    ex = Exposer(phone, flux)
    a, b, c = ex.expose(seed=5), ex.expose(seed=5), ex.expose(seed=6)
    np.testing.assert_array_equal(a.raw_dn, b.raw_dn)
    np.testing.assert_array_equal(a.image, b.image)
    assert np.any(a.raw_dn != c.raw_dn)
    assert a.image.dtype == np.uint8 and a.image.shape == phone.shape


def test_isp_downscale_and_jpeg():
    cam = small_camera(isp={"output_width": 160, "output_height": 120, "jpeg_quality": 80})
    phone = PhoneCamera(cam)
    img = phone.expose(np.full(phone.shape, 5e4, np.float32), seed=1, exposure_s=0.01, iso=100).image
    assert img.shape == (120, 160) and img.dtype == np.uint8


@pytest.mark.parametrize(
    "tables, match",
    [
        ({"sensor": {"read_noise_e": -1}}, "read_noise_e"),
        ({"sensor": {"adc_bits": 20}}, "adc_bits"),
        ({"sensor": {"adc_bits": 0}}, "adc_bits"),
        ({"sensor": {"qe": 1.5}}, "qe"),
        ({"sensor": {"nonsense": 1}}, "unknown key"),
        ({"isp": {"stages": ["tone", "dehaze"]}}, "unknown stage 'dehaze'"),
        ({"isp": {"jpeg_subsampling": "4:1:1"}}, "jpeg_subsampling"),
        ({"isp": {"jpeg_grid_offset_px": [3, 16]}}, "jpeg_grid_offset_px"),
        ({"isp": {"sharpen_amount": -1}}, "sharpen_amount"),
        ({"isp": {"nr_sigma_px": float("nan")}}, "nr_sigma_px"),
        ({"cfa": {"pattern": "RGGB", "demosaic": "ahd"}}, "demosaic"),
        ({"exposure": {"min_exposure_s": 1, "max_exposure_s": 0.1}}, "min_exposure_s"),
        ({"exposure": {"mode": "magic"}}, "mode"),
        ({"glare": {"veiling_fraction": 2}}, "veiling_fraction"),
    ],
)
def test_bad_parameters(tables, match):
    with pytest.raises(InputError, match=match):
        PhoneCamera(small_camera(**tables))


def test_impossible_exposure_and_bad_flux():
    phone = PhoneCamera(small_camera())
    ex = Exposer(phone, np.zeros(phone.shape))
    for bad in (-0.01, 0.0, float("nan"), 1e4):
        with pytest.raises(InputError, match="exposure"):
            ex.expose(exposure_s=bad, iso=100)
    with pytest.raises(InputError, match="iso"):
        ex.expose(exposure_s=0.01, iso=-5)
    with pytest.raises(InputError, match="shape"):
        Exposer(phone, np.zeros((10, 10)))
    with pytest.raises(InputError, match="non-negative"):
        Exposer(phone, np.full(phone.shape, -1.0))


# ------------------------------------------------------------------ colour filter array
def test_bayer_layouts_demosaic_to_their_colours():
    """A mosaic sampled from a constant (R, G, B) scene in each layout comes back as that
    colour through OpenCV's demosaic code chosen for the layout."""
    import cv2

    from svgs_sim.camera.phone.cfa import channel_map, demosaic_code
    from svgs_sim.camera.phone.params import CfaParams

    rgb = np.array([900, 500, 100], np.uint16)
    for pattern in ("RGGB", "BGGR", "GRBG", "GBRG"):
        cfa = CfaParams(pattern=pattern)
        mosaic = rgb[channel_map(pattern, (8, 10))]
        bgr = cv2.cvtColor(mosaic, demosaic_code(cfa))
        assert bgr[4, 4].tolist() == [100, 500, 900], pattern


def test_cfa_keeps_white_light_and_saturation_as_the_mono_sensor_sees_them():
    """White balance for the flash: a uniform scene gives the mono model's luminance (to one
    8-bit code), and a saturated one stays white."""
    cam = small_camera()
    phone = PhoneCamera(cam)
    sp = phone.params.sensor
    mono = ("adc", "tone")
    colour = ("cfa", "adc", "tone")
    import dataclasses

    from svgs_sim.camera.phone.params import CfaParams

    phone_c = PhoneCamera(cam, dataclasses.replace(phone.params, cfa=CfaParams(pattern="RGGB")))
    for level in (0.05, 0.3, 0.7):
        flux = np.full(phone.shape, level * sp.full_well_e / (sp.qe * 0.01), np.float32)
        a = Exposer(phone_c, flux, stages=mono).expose(exposure_s=0.01, iso=sp.base_iso).image.astype(int)
        b = Exposer(phone_c, flux, stages=colour).expose(exposure_s=0.01, iso=sp.base_iso).image.astype(int)
        assert np.abs(a - b).max() <= 1, level
    hot = np.full(phone.shape, 50 * sp.full_well_e / (sp.qe * 0.01), np.float32)
    assert Exposer(phone_c, hot, stages=colour).expose(exposure_s=0.01, iso=sp.base_iso).image.min() == 255


@pytest.mark.parametrize("cfa", [False, True], ids=["mono", "bayer"])
def test_the_float_output_is_the_8_bit_image_before_rounding(cfa):
    """Stage ``u8`` off: the same tone curve as a float32 image on the 0-255 scale, so the 8-bit
    image is that float image rounded: within half a code for the mono sensor; within one with the
    Bayer mosaic, whose 8-bit path also rounds the luminance to a whole DN before its tone LUT;
    no JPEG (it needs 8 bits)."""
    tables = {"isp": {"jpeg_quality": 90}}
    if cfa:
        tables["cfa"] = {"pattern": "RGGB"}
    phone = PhoneCamera(small_camera(**tables))
    rng = np.random.default_rng(4)
    flux = rng.uniform(0, 3e5, phone.shape).astype(np.float32)
    ex = Exposer(phone, flux)
    no_jpeg = tuple(s for s in ex.stages if s != "jpeg")
    a = ex.expose(seed=2, exposure_s=0.01, iso=100, stages=no_jpeg)
    f = ex.expose(seed=2, exposure_s=0.01, iso=100, stages=tuple(s for s in ex.stages if s != "u8"))
    assert a.image.dtype == np.uint8 and f.image.dtype == np.float32
    np.testing.assert_array_equal(a.raw_dn, f.raw_dn)  # the same noise draw
    d = np.abs(f.image - a.image.astype(np.float32))
    assert d.max() <= 1.0 and 50 < f.image.mean() < 250
    assert np.mean(d <= 0.5 + 1e-3) > (0.8 if cfa else 0.999) and d.mean() < 0.3
    # a stage list that changes the optics is refused: the exposer's optical image is made
    with pytest.raises(InputError, match="optics stages"):
        ex.expose(seed=2, stages=tuple(s for s in ex.stages if s != "glare"))


@pytest.mark.parametrize("rings_from", ["distance", "shipped"])
@pytest.mark.parametrize("direction", ["isotropic", "column"])
@pytest.mark.parametrize("case", range(8))
def test_blooming_rings_match_dilation(direction, case, rings_from, monkeypatch):
    """The spill equals its ring-by-ring definition (``rings="dilation"``: one dilation per ring
    and region, the code before the distance transform) to the bit: small and huge excess (a
    frame filled to the brim, as the sun at 66.7 ms does), regions at the frame's edge, several
    regions, a frame already full."""
    import svgs_sim.camera.phone.sensor as sensor

    if rings_from == "distance":  # every window through the distance transform, not just the large ones
        monkeypatch.setattr(sensor, "RING_DILATION_MAX_PX", 0)
    rng = np.random.default_rng(case)
    fw = 4500.0
    h, w = (60, 90) if case % 2 else (97, 41)
    e = rng.uniform(0, fw * 1.1, (h, w)).astype(np.float32)  # scattered saturated pixels
    for _ in range(1 + case):
        y, x = int(rng.integers(0, h)), int(rng.integers(0, w))
        e[y, x] = fw * float(10.0 ** rng.uniform(1, 5))
    if case == 6:
        e[:] = fw * 2  # full already
    if case == 7:
        e[0, 0] = fw * h * w * 50  # more than the frame holds, from a corner
    ref = e.copy()
    got = e.copy()
    stats = bloom(got, fw, drain=0.5 if case % 3 else 0.0, direction=direction)
    stats_ref = bloom(ref, fw, drain=0.5 if case % 3 else 0.0, direction=direction, rings="dilation")
    assert np.array_equal(got, ref)
    assert stats == stats_ref
