"""The camera model's array backend (issue 23): the GPU's code path, run with numpy on the CPU
("numpy-fft"), gives the CPU path's optical image; a GPU backend that cannot start falls back to
the CPU and says so. References: OpenCV's filter2D and scipy's fftconvolve (not this code)."""

from __future__ import annotations

import importlib.util
import warnings

import cv2
import numpy as np
import pytest
from scipy.signal import fftconvolve

from svgs_sim.camera.backend import BACKENDS, get_backend
from svgs_sim.camera.phone import PhoneCamera
from svgs_sim.camera.rendered import PointFlux
from svgs_sim.base.errors import InputError


def test_fft_filter_equals_opencv():
    rng = np.random.default_rng(1)
    img = rng.random((123, 201)).astype(np.float32)
    k = rng.random((17, 17)).astype(np.float32)  # not symmetric: the correlation's orientation counts
    ref = cv2.filter2D(img, -1, k, borderType=cv2.BORDER_CONSTANT)
    out = get_backend("numpy-fft").filter_same(img, k)
    assert np.abs(out - ref).max() < 1e-5 * np.abs(ref).max()


@pytest.mark.parametrize("shape,kshape", [((64, 90), (151, 151)), ((300, 200), (21, 15))])
def test_fft_convolutions_equal_scipy(shape, kshape):
    rng = np.random.default_rng(2)
    a, k = rng.random(shape), rng.random(kshape)
    be = get_backend("numpy-fft")
    np.testing.assert_allclose(be.fft_convolve_same(a, k), fftconvolve(a, k, mode="same"), rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(be.fft_convolve_full(a, k), fftconvolve(a, k, mode="full"), rtol=1e-10, atol=1e-9)


@pytest.mark.slow
def test_phone_optics_on_the_gpu_code_path_equal_the_cpu_path():
    rng = np.random.default_rng(3)
    cpu = PhoneCamera("galaxy-nexus")
    gpu_path = PhoneCamera("galaxy-nexus", backend="numpy-fft")
    H, W = cpu.shape
    flux = np.full((H, W), 2e3, np.float32)
    flux[800:900, 1000:1200] += 1e5 * rng.random((100, 200)).astype(np.float32)
    n = 5000
    pts = PointFlux(1300.3 + 0.3 * rng.standard_normal(n), 950.6 + 0.3 * rng.standard_normal(n), np.full(n, 1e5))
    a = cpu.optics(flux, pts)
    b = gpu_path.optics(flux, pts)
    assert np.abs(a - b).max() <= 1e-5 * a.max()


def test_backend_names_are_checked():
    assert set(BACKENDS) == {"cpu", "cupy", "numpy-fft"}
    with pytest.raises(ValueError, match="array backend"):
        get_backend("opencl")
    with pytest.raises(InputError, match="array backend"):
        PhoneCamera("galaxy-nexus", backend="opencl")


def test_environment_variable_chooses_the_backend(monkeypatch):
    monkeypatch.setenv("SVGS_ARRAY_BACKEND", "numpy-fft")
    assert PhoneCamera("galaxy-nexus").backend.name == "numpy-fft"
    monkeypatch.delenv("SVGS_ARRAY_BACKEND")
    assert PhoneCamera("galaxy-nexus").backend.name == "cpu"


@pytest.mark.skipif(importlib.util.find_spec("cupy") is not None, reason="CuPy is installed: no fallback to show")
def test_cupy_without_cupy_falls_back_to_the_cpu_and_says_so():
    from svgs_sim.camera import backend as mod

    mod._cupy.cache_clear()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        be = get_backend("cupy")
    assert be.name == "cpu" and be.requested == "cupy"
    assert "not available" in be.notice and "CPU" in be.notice
    assert any("cupy" in str(w.message) for w in caught)
