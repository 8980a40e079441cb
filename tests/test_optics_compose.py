"""The optical image's parts summed in one pass (issue 23): the fused composition of the core
image, the glare wings, the kept background and the CFA's responses equals the same sum made
step by step with numpy, the wings spread back by OpenCV's ``cv2.resize`` (an implementation
this code did not write), and the wings binned over the lit box equal the whole frame's
binning by the sparse tent matrices."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from svgs_sim.camera.phone.optics import _tent_pair, compose, glare_source, wing_kernel, wing_step, wings_coarse
from svgs_sim.camera.phone.params import GlareParams
from svgs_sim.camera.rendered import PointFlux

GLARE = GlareParams(veiling_fraction=0.06, wing_exponent=3.0, wing_core_px=2.5, wing_radius_px=150.0)


def _scene(H, W, seed=0):
    rng = np.random.default_rng(seed)
    flux = np.zeros((H, W), np.float32)
    flux[300:420, 500:700] = rng.random((120, 200)).astype(np.float32) * 50.0  # a lit patch
    pts = PointFlux(rng.uniform(610, 640, 4000), rng.uniform(350, 380, 4000), rng.random(4000) * 1e4)
    return flux, pts


@pytest.mark.parametrize("shape", [(1200, 1600), (1944, 2592), (700, 900)])
def test_box_binning_equals_the_whole_frame_binning(shape):
    H, W = shape
    flux, pts = _scene(H, W)
    wc, s = wings_coarse(flux, GLARE, pts)
    assert s == wing_step((H, W))
    whole = glare_source(flux, pts)
    if s == 1:
        from scipy.signal import fftconvolve

        ref = fftconvolve(whole, wing_kernel(GLARE, 1), mode="same")
    else:
        Ay, Ax = _tent_pair(H, W, s)
        coarse = (Ax @ (Ay @ whole).T).T
        from scipy.signal import fftconvolve

        ref = fftconvolve(coarse, wing_kernel(GLARE, s), mode="same") / float(s * s)
    np.testing.assert_allclose(wc, ref, rtol=1e-9, atol=1e-9 * np.abs(ref).max())


@pytest.mark.parametrize("shape", [(1944, 2592), (1201, 1599), (700, 900)])
@pytest.mark.parametrize("with_background", [False, True])
@pytest.mark.slow
def test_fused_composition_equals_numpy_and_cv2_resize(shape, with_background):
    H, W = shape
    rng = np.random.default_rng(1)
    flux, pts = _scene(H, W, 1)
    core = rng.random((H, W)) * 100.0
    resp = (0.5 + rng.random((H, W))).astype(np.float32)
    bg = rng.random((H, W)) * 3.0 if with_background else None
    share, eta, scale = 0.9, GLARE.veiling_fraction, 0.37
    wc, s = wings_coarse(flux, GLARE, pts)
    out = compose(core, share, wc, s, eta, resp, None if bg is None else (scale, bg))
    # the reference: the step-by-step sum, the wings spread back by OpenCV
    Hc, Wc = wc.shape
    fine = cv2.resize(wc, (Wc * s, Hc * s), interpolation=cv2.INTER_LINEAR)[:H, :W] if s > 1 else wc
    ref = core * share + eta * fine
    if bg is not None:
        ref = ref + scale * bg
    ref = (ref * resp).astype(np.float32)
    assert out.dtype == np.float32 and out.shape == (H, W)
    np.testing.assert_allclose(out, ref, rtol=2e-6, atol=1e-6 * np.abs(ref).max())


def test_no_light_gives_no_wings():
    wc, s = wings_coarse(np.zeros((800, 1000), np.float32), GLARE)
    assert s == wing_step((800, 1000)) and not wc.any()
