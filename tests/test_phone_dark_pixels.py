"""Issue 40's dark pixels (``Exposer.expose(dark_pixels="fast")``, ``ApproachSensor(dark_pixels="fast")``):
the pixels that cannot reach the detection threshold draw their shot noise from a table sampler
of the same Poisson law (other variates than the exact path), the others keep the exact path's
bytes. Every test compares against the exact path (``dark_pixels="exact"``, the default):

* the sampler's law on patches of constant and of ramped expected charge (two-sample
  chi-square against the exact path and goodness of fit to the Poisson law, p > 1e-3), through
  the readout too (the delivered DN);
* a faint spot drawn entirely by the table sampler: its centroid's bias and scatter agree with
  the exact path's within 3.5 combined standard errors;
* the tiles that can reach the threshold, and the spots' windows, keep the exact bytes; a bright
  frame (more than ``DARK_FALLBACK_FRACTION`` of it can reach the threshold) and a frame without
  a numeric threshold take the exact path (the same bytes);
* rendered frames of the Galaxy Nexus at 5, 10 and 20 m (render once, expose many): the same
  blobs as the exact path for the same seed (no extra noise blob), and over independent seeds
  the spots' centroid bias and scatter within 3.5 combined standard errors of the exact path's.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from svgs_sim.base.profiles import load_camera
from svgs_sim.camera.phone import ALL_STAGES, DARK_FALLBACK_FRACTION, DARK_TAIL_P, DARK_TILE_PX, Exposer, PhoneCamera
from svgs_sim.camera.phone.params import PhoneParams
from svgs_sim.camera.phone.sensor import (DARK_TABLE_MAX_E, dark_charge_limit, electrons, electrons_dark, fixed_patterns,
                                          readout)

#: Family-wise bound of the statistical comparisons: |difference| < Z_MAX combined standard errors.
Z_MAX = 3.5
P_MIN = 1e-3


def _sensor():
    return PhoneParams.from_camera(load_camera("galaxy-nexus")).sensor


def _flux_for(mu_e, sp, t):
    """Flux (photons/s/px) whose expected charge (signal and dark current) is ``mu_e`` at ``t``."""
    return ((np.asarray(mu_e, np.float64) - sp.dark_current_e_s * t) / (sp.qe * t)).astype(np.float32)


def _both(flux, sp, t, seed, fpn=False, fast_seed=None):
    """The exact path's charge (``seed``) and the table sampler's, every tile dark (``fast_seed``,
    default ``seed``; another seed: an independent sample)."""
    prnu, dsnu = fixed_patterns(sp, flux.shape)
    dark = np.ones((-(-flux.shape[0] // DARK_TILE_PX), -(-flux.shape[1] // DARK_TILE_PX)), bool)
    a = electrons(flux, sp, t, prnu, dsnu, seed, fpn=fpn)
    b = electrons_dark(flux, sp, t, prnu, dsnu, seed if fast_seed is None else fast_seed, dark, DARK_TILE_PX, fpn=fpn)
    return a, b


def _two_sample_p(a, b):
    """Chi-square two-sample test of two integer samples (bins merged so that each expects >= 5)."""
    lo, hi = int(min(a.min(), b.min())), int(max(a.max(), b.max()))
    ca = np.bincount((a - lo).astype(int).ravel(), minlength=hi - lo + 1)
    cb = np.bincount((b - lo).astype(int).ravel(), minlength=hi - lo + 1)
    rows, acc = [], np.zeros(2)
    for x, y in zip(ca, cb):
        acc += (x, y)
        if acc.sum() >= 20:
            rows.append(acc.copy())
            acc[:] = 0
    if acc.sum():
        rows[-1] += acc
    if len(rows) < 2:
        return 1.0
    return stats.chi2_contingency(np.array(rows).T)[1]


@pytest.mark.parametrize("mu", [0.37, 3.0, 7.77, 23.9])
def test_constant_patch_same_law_as_exact_path(mu):
    """On a patch of constant expected charge the table sampler's counts follow the exact
    path's (two-sample chi-square) and the Poisson law (goodness of fit), and so do the
    delivered DN after read noise, gain and the ADC."""
    sp, t = _sensor(), 0.01
    flux = np.full((256, 256), _flux_for(mu, sp, t), np.float32)
    a, b = _both(flux, sp, t, seed=11, fast_seed=12)  # independent samples
    assert _two_sample_p(a, b) > P_MIN
    k = np.arange(int(b.max()) + 1)
    obs = np.bincount(b.astype(int).ravel(), minlength=k.size)
    exp = stats.poisson.pmf(k, mu) * b.size
    keep = exp >= 5
    obs_m = np.append(obs[keep], obs[~keep].sum())
    exp_m = np.append(exp[keep], b.size - exp[keep].sum())
    assert stats.chisquare(obs_m, exp_m * obs_m.sum() / exp_m.sum())[1] > P_MIN
    assert abs(b.mean() - mu) < Z_MAX * np.sqrt(mu / b.size)
    ra, _ = readout(a, sp, 100.0, 11)
    rb, _ = readout(b, sp, 100.0, 12)
    assert _two_sample_p(ra, rb) > P_MIN


def test_ramp_same_law_as_exact_path():
    """Expected charge ramped over the table's levels (0 .. 24 e-, the remainders between levels
    drawn too): each band of the ramp agrees with the exact path (two-sample chi-square), the
    whole patch's mean with the expected charge."""
    sp, t = _sensor(), 0.01
    mu = np.linspace(0.0, DARK_TABLE_MAX_E - 1e-3, 512 * 256).reshape(512, 256)
    flux = np.maximum(_flux_for(mu, sp, t), 0).astype(np.float32)
    a, b = _both(flux, sp, t, seed=5, fast_seed=6)
    for band in range(8):
        rows = slice(band * 64, (band + 1) * 64)
        assert _two_sample_p(a[rows], b[rows]) > P_MIN
    m = sp.qe * t * flux.astype(np.float64) + sp.dark_current_e_s * t
    assert abs((b - m).mean()) < Z_MAX * np.sqrt(m.sum()) / m.size


def _spot_centroids(sp, seeds, fast):
    """Weighted centroids (background subtracted) of a faint Gaussian spot (peak 20 e- over
    3 e-), every pixel drawn by the table sampler (``fast``) or the exact one."""
    t = 0.01
    y, x = np.mgrid[0:64, 0:64]
    mu = 3.0 + 17.0 * np.exp(-((x - 31.3) ** 2 + (y - 32.6) ** 2) / (2 * 1.5 ** 2))
    flux = _flux_for(mu, sp, t)
    out = []
    prnu, dsnu = fixed_patterns(sp, flux.shape)
    dark = np.ones((2, 2), bool)
    for s in seeds:
        e = (electrons_dark(flux, sp, t, prnu, dsnu, int(s), dark, DARK_TILE_PX, fpn=False) if fast
             else electrons(flux, sp, t, prnu, dsnu, int(s), fpn=False)) - 3.0
        w = np.where(mu > 6.0, e, 0.0)
        out.append(((w * x).sum() / w.sum(), (w * y).sum() / w.sum()))
    return np.array(out)


def _agree(a, b):
    """|difference of means| and |difference of standard deviations| of two samples (N, k) in
    combined standard errors, per column."""
    n_a, n_b = len(a), len(b)
    z_bias = np.abs(a.mean(0) - b.mean(0)) / np.sqrt(a.var(0, ddof=1) / n_a + b.var(0, ddof=1) / n_b)
    sa, sb = a.std(0, ddof=1), b.std(0, ddof=1)
    z_sd = np.abs(sa - sb) / np.sqrt(sa ** 2 / (2 * (n_a - 1)) + sb ** 2 / (2 * (n_b - 1)))
    return z_bias, z_sd


def test_faint_spot_centroid_bias_and_scatter_as_exact_path():
    """A spot drawn entirely by the table sampler: centroid bias and scatter (400 independent
    seeds each side) within Z_MAX combined standard errors of the exact path's."""
    sp = _sensor()
    exact = _spot_centroids(sp, np.arange(400), fast=False)
    fast = _spot_centroids(sp, np.arange(400, 800), fast=True)
    z_bias, z_sd = _agree(fast, exact)
    assert np.all(z_bias < Z_MAX), z_bias
    assert np.all(z_sd < Z_MAX), z_sd


def test_dark_limit_bound():
    """The bound: a pixel at the limit reaches the threshold's charge with probability below
    DARK_TAIL_P (hard bounds on the DSNU and the read noise's largest quantile)."""
    sp = _sensor()
    mu = dark_charge_limit(40.0, sp, 3.0, DARK_TAIL_P)
    n = int(np.ceil(40.0 - 3.0 - 3.0 * 4.33))
    assert 0 < mu < DARK_TABLE_MAX_E
    assert stats.poisson.sf(n - 1, mu) < DARK_TAIL_P <= stats.poisson.sf(n - 1, mu * 1.01)
    assert dark_charge_limit(1000.0, sp, 3.0, DARK_TAIL_P) == DARK_TABLE_MAX_E
    assert dark_charge_limit(5.0, sp, 3.0, DARK_TAIL_P) == 0.0


NO_GLARE = tuple(s for s in ALL_STAGES if s != "glare")


def _exposer(small_camera, flux):
    phone = PhoneCamera(small_camera)
    return Exposer(phone, flux, stages=NO_GLARE)


def test_bright_tiles_keep_exact_bytes_and_bright_frame_falls_back(small_camera):
    """A dark frame with a small bright patch: the tiles that can reach the threshold (and their
    neighbours) keep the exact path's charge to the bit, the others draw other variates. Half the
    frame bright (over DARK_FALLBACK_FRACTION): the exact path, the same bytes. No numeric
    threshold: the exact path."""
    phone = PhoneCamera(small_camera)
    H, W = phone.shape
    sp = phone.params.sensor
    t = phone.params.exposure.exposure_s
    flux = np.full((H, W), _flux_for(3.0, sp, t), np.float32)
    flux[200:230, 300:330] = _flux_for(4000.0, sp, t)
    ex = Exposer(phone, flux, stages=NO_GLARE)
    a = ex.expose(seed=4, keep_electrons=True)
    b = ex.expose(seed=4, keep_electrons=True, dark_pixels="fast", threshold_u8=64.0)
    assert b.info["dark_pixels"]["path"] == "fast"
    assert b.info["dark_pixels"]["reach_fraction"] < DARK_FALLBACK_FRACTION
    px = np.kron(ex.dark_tiles(t, 100.0, NO_GLARE, phone.params.isp, "bilinear", 64.0)[0],
                 np.ones((DARK_TILE_PX, DARK_TILE_PX), bool))[:H, :W]
    assert not px[180:250, 280:350].any()
    np.testing.assert_array_equal(a.electrons[~px], b.electrons[~px])
    assert not np.array_equal(a.electrons[px], b.electrons[px])
    bright = flux.copy()
    bright[:, : W // 2] = _flux_for(400.0, sp, t)
    exb = Exposer(phone, bright, stages=NO_GLARE)
    c = exb.expose(seed=4, dark_pixels="fast", threshold_u8=64.0)
    d = exb.expose(seed=4)
    assert c.info["dark_pixels"]["path"] == "exact" and c.info["dark_pixels"]["reach_fraction"] > DARK_FALLBACK_FRACTION
    np.testing.assert_array_equal(c.raw_dn, d.raw_dn)
    np.testing.assert_array_equal(c.image, d.image)
    e = ex.expose(seed=4, dark_pixels="fast", threshold_u8=None)
    assert e.info["dark_pixels"]["path"] == "exact"
    np.testing.assert_array_equal(e.image, a.image)


# ----------------------------------------------------------------------------- rendered frames
RANGES_M = (5.0, 10.0, 20.0)
N_SEEDS = 12


def _blobs(image, threshold=64.0):
    from svgs_sim.svgs.detect import detect_blobs

    return detect_blobs(image, threshold=threshold).centroid_px


def _match(ref, found, tol_px=3.0):
    """Each reference spot's nearest blob within ``tol_px`` (NaN when none), (N, 2)."""
    out = np.full(ref.shape, np.nan)
    if len(found):
        d = np.linalg.norm(ref[:, None, :] - found[None, :, :], axis=2)
        j = d.argmin(1)
        ok = d[np.arange(len(ref)), j] < tol_px
        out[ok] = found[j[ok]]
    return out


@pytest.mark.slow
@pytest.mark.render
@pytest.mark.parametrize("range_m", RANGES_M)
def test_rendered_frames_same_blobs_and_centroid_statistics(range_m):
    """The Galaxy Nexus at full resolution (render once, expose many): for the same seed the
    fast path finds the same blobs as the exact path (no extra noise blob; the spots' windows
    keep their bytes); over independent seeds (N_SEEDS each side) each spot's centroid bias
    and scatter agree within Z_MAX combined standard errors."""
    from svgs_sim.sim.closed_loop import Scenario, render_scenario

    fr = render_scenario(Scenario(camera="galaxy-nexus", range_m=range_m), seed=1)
    ex = fr.exposer()
    for s in range(3):
        a, b = ex.expose(seed=s), ex.expose(seed=s, dark_pixels="fast", threshold_u8=64.0)
        assert b.info["dark_pixels"]["path"] == "fast"
        assert not np.array_equal(a.image, b.image)
        np.testing.assert_array_equal(_blobs(a.image), _blobs(b.image))
    ref = _blobs(ex.expose(seed=0).image)
    assert len(ref) >= 4
    exact = np.array([_match(ref, _blobs(ex.expose(seed=s).image)) for s in range(100, 100 + N_SEEDS)])
    fast = np.array([_match(ref, _blobs(ex.expose(seed=s, dark_pixels="fast", threshold_u8=64.0).image))
                     for s in range(200, 200 + N_SEEDS)])
    assert np.isnan(exact).sum() == np.isnan(fast).sum() == 0
    a, b = exact.reshape(N_SEEDS, -1), fast.reshape(N_SEEDS, -1)
    z_bias, z_sd = _agree(b, a)
    assert np.all(z_bias < Z_MAX), z_bias
    assert np.all(z_sd < Z_MAX), z_sd


@pytest.mark.slow
@pytest.mark.render
def test_approach_sensor_option(small_camera):
    """``ApproachSensor(dark_pixels="fast")`` at full resolution: other noise in the dark
    pixels, the same blobs and solution as the default sensor's for the same seed. The small
    camera (16 times the pixel area: its lab background, ~46 e-, beyond the tables' 24 e-) takes
    the exact path: the same image. A wrong value is refused."""
    from svgs_sim.base.errors import InputError
    from svgs_sim.sim.approach import ApproachSensor
    from svgs_sim.svgs.frames import pose_from_scenario

    pose = pose_from_scenario(10.0, pitch_deg=2.0)
    a = ApproachSensor("galaxy-nexus", seed=3, crlb=False, keep_images=True).measure(0.0, *pose)
    b = ApproachSensor("galaxy-nexus", seed=3, crlb=False, keep_images=True, dark_pixels="fast").measure(0.0, *pose)
    assert a.ok and b.ok
    assert not np.array_equal(a.image, b.image)
    np.testing.assert_array_equal(a.blobs_px, b.blobs_px)
    assert a.estimate == b.estimate
    pose = pose_from_scenario(6.0, pitch_deg=2.0)
    c = ApproachSensor(small_camera, seed=3, crlb=False, keep_images=True).measure(0.0, *pose)
    d = ApproachSensor(small_camera, seed=3, crlb=False, keep_images=True, dark_pixels="fast").measure(0.0, *pose)
    np.testing.assert_array_equal(c.image, d.image)
    with pytest.raises(InputError):
        ApproachSensor(small_camera, dark_pixels="quick")
    with pytest.raises(InputError, match="keep_images"):
        ApproachSensor(small_camera, keep_images="all")
    for truthy in (1, np.True_):  # what bool() takes for True keeps the delivered image, as before
        assert ApproachSensor(small_camera, keep_images=truthy).keep_images is True
    assert ApproachSensor(small_camera, keep_images=None).keep_images is False


def test_cli_flag_and_config():
    """``svgs approach --fast-dark-pixels`` records ``dark_pixels = "fast"`` in the study's config;
    without it the config has no such key (the default's config and numbers unchanged)."""
    from svgs_sim.cli.approach import command_line, config_from_args
    from svgs_sim.cli.main import build_parser

    argv = ["approach", "--from", "10", "--to", "5", "--duration", "2", "--fps", "1", "--out", "x"]
    args = build_parser().parse_args(argv)
    assert "dark_pixels" not in config_from_args(args)
    args = build_parser().parse_args(argv + ["--fast-dark-pixels"])
    assert config_from_args(args)["dark_pixels"] == "fast"
    assert "--fast-dark-pixels" in command_line(args)
