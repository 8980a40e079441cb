"""The deterministic convolution of the points with the lens PSF (issue 23) against what it
replaced: the Monte Carlo convolution's expectation, averaged over independent draws.

Spots shaped as the guided estimator delivers them at 5, 20 and 40 m (the flash's image through
a cube: a disk of ~1.5 px at 5 m defocused, 0.2 px at 20 m, 0.05 px at 40 m), mono (one Airy
pattern) and colour (the CFA's three channels). The reference is the other, independent
algorithm - PSF draws counted in the pixels that contain them - so the test can fail on the
kernel, its sub-pixel phases, the splat or the window bookkeeping.
"""

from __future__ import annotations

import numpy as np
import pytest

from svgs_sim.camera.phone import PhoneCamera
from svgs_sim.camera.phone.optics import core_image
from svgs_sim.camera.phone.psf import CorePSF
from svgs_sim.camera.rendered import PointFlux

#: Monte Carlo runs averaged for the expectation (each 2^20 PSF draws per channel).
MC_RUNS = 6
SPOT_RADIUS_PX = {5: 1.5, 20: 0.2, 40: 0.05}


def _spots(radius_px: float, seed: int = 3) -> PointFlux:
    rng = np.random.default_rng(seed)
    us, vs, ws = [], [], []
    for cu, cv in ((60.37, 52.81), (141.12, 90.46)):  # two spots, arbitrary sub-pixel phases
        n = 20000
        r = radius_px * np.sqrt(rng.random(n))
        phi = rng.random(n) * 2 * np.pi
        us.append(cu + r * np.cos(phi))
        vs.append(cv + r * np.sin(phi))
        ws.append(rng.random(n) + 0.5)
    return PointFlux(np.concatenate(us), np.concatenate(vs), np.concatenate(ws))


def _moments(img, box):
    y0, y1, x0, x1 = box
    a = img[y0:y1, x0:x1]
    yy, xx = np.mgrid[y0:y1, x0:x1]
    f = a.sum()
    return f, (a * xx).sum() / f, (a * yy).sum() / f


BOXES = ((32, 74, 40, 82), (70, 112, 120, 162))


@pytest.mark.parametrize("range_m", [5, 20, 40])
@pytest.mark.slow
def test_grid_equals_monte_carlo_expectation_mono(range_m):
    pts = _spots(SPOT_RADIUS_PX[range_m])
    psf = CorePSF.from_optics(2.4, 535.0, 1.4e-6, 0.6)
    shape = (140, 200)
    zero = np.zeros(shape, np.float32)
    grid = core_image(zero, psf, pts)
    mc = np.mean([core_image(zero, psf, pts, np.random.default_rng(s), method="monte-carlo")
                  for s in range(MC_RUNS)], axis=0)
    for box in BOXES:
        fg, ug, vg = _moments(grid, box)
        fm, um, vm = _moments(mc, box)
        assert abs(fg / fm - 1) < 1e-3
        assert abs(ug - um) < 0.002 and abs(vg - vm) < 0.002
    assert abs(grid.sum() / mc.sum() - 1) < 1e-3


@pytest.mark.parametrize("range_m", [5, 20, 40])
@pytest.mark.slow
def test_grid_equals_monte_carlo_expectation_colour(range_m):
    pts = _spots(SPOT_RADIUS_PX[range_m], seed=4)
    shape = (140, 200)
    zero = np.zeros(shape, np.float32)
    grid_cam = PhoneCamera("galaxy-nexus")
    mc_cam = PhoneCamera("galaxy-nexus", point_method="monte-carlo")
    grid = grid_cam.core_mosaic(zero, pts)
    mc = np.mean([mc_cam.core_mosaic(zero, pts, seed=s) for s in range(MC_RUNS)], axis=0)
    for box in BOXES:
        fg, ug, vg = _moments(grid, box)
        fm, um, vm = _moments(mc, box)
        assert abs(fg / fm - 1) < 1e-3
        assert abs(ug - um) < 0.002 and abs(vg - vm) < 0.002


def test_grid_image_is_deterministic_and_conserves_charge():
    pts = _spots(0.2)
    psf = CorePSF.from_optics(2.2, 600.0, 1.4e-6, 0.6)
    a = psf.splat(pts.u_px, pts.v_px, pts.rate_ph_s, (140, 200))
    b = psf.splat(pts.u_px, pts.v_px, pts.rate_ph_s, (140, 200))
    assert np.array_equal(a, b)
    # all the light lands inside the frame except the Airy tail beyond the frame's edge (< 1 %)
    assert 0.99 < a.sum() / pts.total_ph_s <= 1.0 + 1e-12


def test_grid_centroid_follows_a_subpixel_shift():
    """Moving every point by d moves the image's centroid by d (the physics' translation
    invariance, not the code's), at phases between the splat grid's nodes; one spot in a frame
    that holds its whole PSF, so no window truncates it."""
    rng = np.random.default_rng(7)
    n = 5000
    u = 200.37 + 0.05 * rng.standard_normal(n)
    v = 150.81 + 0.05 * rng.standard_normal(n)
    w = rng.random(n) + 0.5
    psf = CorePSF.from_optics(2.4, 535.0, 1.4e-6, 0.6)
    box = (0, 300, 0, 400)
    f0, u0, v0 = _moments(psf.splat(u, v, w, (300, 400)), box)
    assert abs(u0 - np.average(u, weights=w)) < 0.002 and abs(v0 - np.average(v, weights=w)) < 0.002
    for d in (0.013, 0.0625, 0.31, 0.5):
        f1, u1, v1 = _moments(psf.splat(u + d, v - d, w, (300, 400)), box)
        assert abs((u1 - u0) - d) < 0.002 and abs((v1 - v0) + d) < 0.002
        assert abs(f1 / f0 - 1) < 1e-6


def test_gradient_equals_finite_difference_of_the_image():
    pts = _spots(1.5)
    psf = CorePSF.from_optics(2.4, 535.0, 1.4e-6, 0.6)
    _, gu, gv = psf.splat(pts.u_px, pts.v_px, pts.rate_ph_s, (140, 200), gradient=True)
    h = 0.05
    fd_u = (psf.splat(pts.u_px + h, pts.v_px, pts.rate_ph_s, (140, 200))
            - psf.splat(pts.u_px - h, pts.v_px, pts.rate_ph_s, (140, 200))) / (2 * h)
    fd_v = (psf.splat(pts.u_px, pts.v_px + h, pts.rate_ph_s, (140, 200))
            - psf.splat(pts.u_px, pts.v_px - h, pts.rate_ph_s, (140, 200))) / (2 * h)
    # Fisher information (sum of squared derivatives) within 2 %
    assert abs((gu**2).sum() / (fd_u**2).sum() - 1) < 0.02
    assert abs((gv**2).sum() / (fd_v**2).sum() - 1) < 0.02
    assert np.abs(gu - fd_u).max() < 0.03 * np.abs(fd_u).max()


def test_support_windowed_convolution_equals_full_frame_filter():
    """Light in a small part of the frame is convolved over its support only: the result must
    equal OpenCV's convolution of the whole frame (zero outside), also at the frame's edge."""
    import cv2

    psf = CorePSF.from_optics(2.4, 535.0, 1.4e-6, 0.6)
    rng = np.random.default_rng(7)
    img = np.zeros((400, 600), np.float32)
    img[150:190, 300:350] = rng.random((40, 50))
    img[0:5, 590:600] = 3.0  # a corner: the window is clipped by the frame
    k = psf.pixel_kernel().astype(np.float32)
    ref = cv2.filter2D(img, -1, k, borderType=cv2.BORDER_CONSTANT)
    out = psf.convolve(img)
    assert np.abs(out - ref).max() <= 1e-6 * ref.max()
    assert not psf.convolve(np.zeros((40, 60), np.float32)).any()


@pytest.mark.slow
def test_background_kept_between_frames_equals_its_sum():
    """A background given as (scale, unit) - the lab's light, kept by the camera model from
    frame to frame - gives the optical image of the summed flux (the optics are linear), and the
    kept image is reused for the same array (not for a new one)."""
    cam = PhoneCamera("galaxy-nexus")
    H, W = cam.shape
    yy, xx = np.mgrid[0:H, 0:W]
    unit = (1.0 + 0.3 * np.cos(xx / 400.0) * np.sin(yy / 300.0)).astype(np.float32) * 1e3
    target = np.zeros((H, W), np.float32)
    target[900:1000, 1200:1350] = 5e4
    pts = _spots(0.2)
    pts = PointFlux(pts.u_px + 1200, pts.v_px + 880, pts.rate_ph_s * 1e6)
    for scale in (0.7, 2.5):
        ref = cam.optics(target + np.float32(scale) * unit, pts)
        out = cam.optics(target, pts, background=(scale, unit))
        assert np.abs(out - ref).max() <= 2e-6 * ref.max()
    from svgs_sim.camera.phone import _BACKGROUND_CACHE

    _BACKGROUND_CACHE.clear()
    cam.optics(target, pts, background=(1.0, unit))
    PhoneCamera("galaxy-nexus").optics(target, pts, background=(1.0, unit))  # another phone, same model
    assert len(_BACKGROUND_CACHE) == 1  # one unit array, kept
    cam.optics(target, pts, background=(1.0, unit.copy()))
    assert len(_BACKGROUND_CACHE) == 2
