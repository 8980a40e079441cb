"""Image formation against GalSim: the lens PSF before pixel integration (issue 11).

The reference is GalSim (``galsim.Airy`` convolved with ``galsim.Gaussian``, drawn with its
pixel response, ``drawImage(method="auto")``), which this code did not produce. Our path is
the one the closed loop takes: point samples at sub-pixel positions through
:meth:`svgs_sim.camera.phone.PhoneCamera.optics` (Monte Carlo convolution with the Airy pattern and
the aberration Gaussian, exact pixel-area integration).
"""

from __future__ import annotations

import dataclasses

import galsim  # a test dependency (pyproject [test]): the reference must be there, never skipped
import numpy as np
import pytest

from svgs_sim.camera.phone import PhoneCamera
from svgs_sim.camera.phone.optics import tent_matrix, wings
from svgs_sim.camera.phone.psf import CorePSF
from svgs_sim.camera.rendered import PointFlux
from svgs_sim.base.profiles import Camera

#: Ten sub-pixel offsets (px) of the point source, both axes, corners and centre of the pixel included.
OFFSETS = [(0.0, 0.0), (0.5, 0.5), (-0.5, 0.25), (0.125, -0.375), (0.3, 0.1), (-0.2, -0.45), (0.45, -0.05),
           (-0.35, 0.4), (0.05, 0.2), (0.25, -0.25)]
#: Samples standing for one point (the guided estimator gives ~1e4-1e5 per spot).
N_SAMPLES = 1 << 16


def _centroid(img):
    y, x = np.mgrid[:img.shape[0], :img.shape[1]]
    s = img.sum()
    return np.array([(img * x).sum() / s, (img * y).sum() / s])


def _galsim_psf(psf: CorePSF):
    return galsim.Convolve(galsim.Airy(lam_over_diam=psf.lam_over_d_px), galsim.Gaussian(sigma=psf.aberration_sigma_px))


def _core_only_phone(name):
    """The profile's phone with the glare wings off: the optical image is the core PSF alone."""
    cam = Camera.load(name, fitted=False)
    ph = PhoneCamera(cam)
    glare = dataclasses.replace(ph.params.glare, veiling_fraction=0.0, ghosts=())
    return PhoneCamera(cam, dataclasses.replace(ph.params, glare=glare))


@pytest.mark.parametrize("name", ["galaxy-nexus", "htc-amaze-4g"])
def test_point_source_matches_galsim_at_ten_subpixel_offsets(name):
    phone = _core_only_phone(name)
    psf = phone.core_psf()
    gs = _galsim_psf(psf)
    H, W = phone.shape
    u0, v0 = W // 2, H // 2
    half = 24
    for k, (dx, dy) in enumerate(OFFSETS):
        pts = PointFlux(np.full(N_SAMPLES, u0 + dx), np.full(N_SAMPLES, v0 + dy), np.full(N_SAMPLES, 1.0 / N_SAMPLES))
        ours = phone.optics(np.zeros(phone.shape, np.float32), pts, seed=k, cfa=False)  # the mono optical image
        ours = ours[v0 - half:v0 + half + 1, u0 - half:u0 + half + 1].astype(np.float64)
        ref = gs.drawImage(nx=2 * half + 1, ny=2 * half + 1, scale=1.0, offset=(dx, dy)).array.astype(np.float64)
        assert np.abs(ours - ref).max() < 0.02 * ref.max(), (name, dx, dy, np.abs(ours - ref).max() / ref.max())
        c_ours, c_ref = _centroid(ours), _centroid(ref)
        assert np.abs(c_ours - c_ref).max() < 0.005, (name, dx, dy, c_ours - c_ref)
        # and GalSim put it where it must be: the centre pixel plus the offset
        assert np.abs(c_ref - (half + np.array([dx, dy]))).max() < 2e-3


@pytest.mark.parametrize("name", ["galaxy-nexus", "htc-amaze-4g"])
def test_pixel_kernel_of_the_diffuse_path_is_galsims_pixel_integrated_psf(name):
    """Pixel images (diffuse light) take the PSF integrated over a pixel at integer offsets:
    GalSim's drawImage of a point at a pixel centre."""
    psf = PhoneCamera(Camera.load(name, fitted=False)).core_psf()
    k = psf.pixel_kernel(16, normalise=False)
    ref = _galsim_psf(psf).drawImage(nx=33, ny=33, scale=1.0).array
    assert np.abs(k - ref).max() < 1e-4 * ref.max()
    assert psf.pixel_kernel().sum() == pytest.approx(1.0, abs=1e-12)


def test_monte_carlo_convolution_conserves_the_light():
    psf = CorePSF.from_optics(2.4, 550.0, 1.4e-6, 0.6)
    rng = np.random.default_rng(3)
    u = 200.0 + rng.random(5000) * 3
    v = 150.0 + rng.random(5000) * 3
    w = rng.random(5000)
    out = psf.splat(u, v, w, (300, 400), rng)
    # light beyond 100 px (where it leaves this frame) is 2/(pi x) ~ 0.3 % of the Airy pattern's
    assert out.sum() == pytest.approx(w.sum(), rel=5e-3)
    assert out.sum() <= w.sum() * (1 + 1e-12)
    assert out.min() >= 0.0


def test_the_order_matters_psf_after_binning_loses_the_subpixel_position():
    """What the issue measured: a Gaussian PSF applied after the flux is binned to pixels
    puts every sub-pixel position of a small spot on the pixel centre (a staircase)."""
    from svgs_sim.camera.phone.optics import apply_psf
    from svgs_sim.camera.phone.params import GlareParams

    g = GlareParams(aberration_sigma_px=0.6, veiling_fraction=0.0)
    psf = CorePSF.from_optics(2.4, 550.0, 1.4e-6, 0.6)
    err_new, err_old = [], []
    for k in range(8):
        x = 20.0 + k / 8.0
        pts = PointFlux(np.full(4096, x), np.full(4096, 20.0), np.full(4096, 1.0))
        new = apply_psf(np.zeros((41, 41)), g, psf, points=pts, rng=np.random.default_rng(k))
        old = apply_psf(pts.binned((41, 41)), g, psf.sigma_equivalent_px)
        err_new.append(_centroid(new)[0] - x)
        err_old.append(_centroid(old)[0] - x)
    assert np.sqrt(np.mean(np.square(err_new))) < 0.005
    assert np.sqrt(np.mean(np.square(err_old))) > 0.2  # 0.29 px RMS: the staircase


def test_glare_wings_never_move_a_spot():
    """The wing convolution on a coarse grid (tent binning and spreading back) keeps the first
    moment of a point at any sub-pixel position."""
    from svgs_sim.camera.phone.params import GlareParams

    g = GlareParams(veiling_fraction=0.08, wing_exponent=4.0, wing_core_px=2.0, wing_radius_px=120.0)
    H, W = 1200, 1400  # coarse step 2 (at most 2^19 coarse pixels)
    for dx, dy in OFFSETS[:5]:
        x, y = 700.0 + dx + 0.37, 600.0 + dy - 0.21
        pts = PointFlux([x], [y], [1.0])
        out = wings(pts.bilinear((H, W)), g)
        assert out.sum() == pytest.approx(1.0, rel=1e-9)
        assert np.abs(_centroid(out) - (x, y)).max() < 1e-6


def test_tent_matrix_reproduces_positions():
    A = tent_matrix(37, 4).toarray()
    assert np.allclose(A.sum(0), 1.0)
    c = np.arange(A.shape[0]) * 4 + 1.5
    inner = slice(2, 33)  # away from the two ends, where the outer weight is folded in
    assert np.allclose((A * c[:, None]).sum(0)[inner], np.arange(37)[inner])


@pytest.mark.slow
def test_centroid_crlb_matches_the_fisher_information_of_galsims_image():
    """svgs_sim.sim.crlb's centroid bound of an unsaturated spot against the Fisher information of
    GalSim's image of the same PSF with the same pixel noise (shot, read, quantisation):
    ``I = sum (d mu / dx)^2 / var``, the derivative by finite differences of GalSim images."""
    from types import SimpleNamespace

    from svgs_sim.camera.phone import Exposer
    from svgs_sim.sim.crlb import centroid_crlb_px

    phone = _core_only_phone("galaxy-nexus")
    sp, isp = phone.params.sensor, phone.params.isp
    psf = phone.core_psf()
    gs = _galsim_psf(psf)
    H, W = phone.shape
    u, v = W // 2 + 0.3, H // 2 - 0.2
    t_s = 1e-3
    rate = 0.5 * sp.full_well_e / (sp.qe * t_s * 0.3)  # peak near half of full well
    pts = PointFlux(np.full(N_SAMPLES, u), np.full(N_SAMPLES, v), np.full(N_SAMPLES, rate / N_SAMPLES))
    ex = Exposer(phone, np.zeros(phone.shape, np.float32), points=pts, stages=("glare", "shot", "read", "adc", "tone"),
                 optics_seed=1)
    exposure = ex.expose(seed=0, exposure_s=t_s, iso=sp.base_iso)
    frame = SimpleNamespace(points=pts, truth={"render": {"seed": 1}})
    ours = centroid_crlb_px(frame, ex, exposure, np.array([[u, v]]))[0]
    # the reference
    n, h = 49, 0.05
    cu, cv = int(round(u)), int(round(v))

    def img(dx, dy):
        return gs.drawImage(nx=n, ny=n, scale=1.0, offset=(u - cu + dx, v - cv + dy)).array.astype(np.float64)

    k = sp.qe * t_s * rate
    mu = k * img(0, 0) + sp.dark_current_e_s * t_s
    gain = sp.gain_dn_per_e(sp.base_iso)
    white_e = (sp.white_dn - sp.black_level_dn) / gain
    lin = np.clip(mu / white_e, 1e-6, 1.0)
    q = white_e * isp.gamma / 255.0 * lin ** (1.0 - 1.0 / isp.gamma)
    var = mu + sp.read_noise_e**2 + (q**2 + (1.0 / gain) ** 2) / 12.0
    dx = k * (img(h, 0) - img(-h, 0)) / (2 * h)
    dy = k * (img(0, h) - img(0, -h)) / (2 * h)
    ref = np.array([1 / np.sqrt(np.sum(dx**2 / var)), 1 / np.sqrt(np.sum(dy**2 / var))])
    assert ours == pytest.approx(ref, rel=0.05), (ours, ref)
    # and the shot-noise scale: about sigma_PSF / sqrt(N) for N photo-electrons
    assert 0.5 < ref[0] / (psf.sigma_equivalent_px / np.sqrt(k)) < 2.0
