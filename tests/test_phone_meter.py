"""The phone's meter (svgs_sim.camera.phone.isp.ExposureSolver): its weighted log histogram of the
noise-free signal, built in parallel chunks from the flux, equals numpy's ``bincount`` of the
same bins in pixel order, and the metered level equals the direct weighted sum of the clipped
signal to within one bin."""

from __future__ import annotations

import numpy as np
import pytest

from svgs_sim.camera.phone.isp import ExposureSolver, metering_weights
from svgs_sim.camera.phone.params import SensorParams


def _flux(shape, seed=0):
    rng = np.random.default_rng(seed)
    f = rng.lognormal(3.0, 2.0, shape).astype(np.float32)
    f[: shape[0] // 3, : shape[1] // 4] = 0.0  # dark pixels: the dark current alone
    return f


@pytest.mark.parametrize("metering", ["mean", "center_weighted", "spot"])
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_histogram_equals_bincount_and_level_the_direct_sum(metering, dtype):
    sensor = SensorParams()
    f = _flux((301, 407)).astype(dtype)
    m = ExposureSolver.from_flux(f, sensor, metering)
    rate = ((sensor.qe * f.astype(np.float64) + sensor.dark_current_e_s) / sensor.full_well_e).ravel()
    w = metering_weights(f.shape, metering).ravel()
    lo, hi = np.log(rate.min()), np.log(rate.max())
    idx = np.clip(((np.log(rate) - lo) / (hi - lo) * 4096).astype(int), 0, 4095)
    np.testing.assert_allclose(m.w_bin, np.bincount(idx, weights=w, minlength=4096), rtol=1e-12, atol=1e-18)
    np.testing.assert_allclose(m.wr_bin, np.bincount(idx, weights=w * rate, minlength=4096), rtol=1e-12, atol=1e-18)
    # the old constructor (a rate map and a weight map) gives the same meter
    m2 = ExposureSolver(rate.reshape(f.shape), w.reshape(f.shape))
    for S in np.geomspace(1e-3 / rate.max(), 10 / rate.min(), 25):
        direct = float(np.sum(w * np.minimum(rate * S, 1.0)))
        assert m.level(S) == pytest.approx(m2.level(S), rel=1e-12, abs=1e-15)
        # within one bin: the straddling bin counts linearly
        assert abs(m.level(S) - direct) <= 2 * (np.exp((hi - lo) / 4096) - 1) * direct + 1e-12


def test_no_signal_meters_zero():
    sensor = SensorParams(dark_current_e_s=0.0)
    m = ExposureSolver.from_flux(np.zeros((20, 30), np.float32), sensor, "mean")
    assert m.edges is None and m.level(1.0) == 0.0 and m.w_zero == pytest.approx(1.0)


def _frame_like(shape, seed=1):
    """A smooth background of a few electrons' flux with bright spots over many octaves."""
    rng = np.random.default_rng(seed)
    H, W = shape
    y, x = np.mgrid[0:H, 0:W]
    f = 5e3 * (1.0 + 0.8 * np.sin(x / 37.0) * np.cos(y / 23.0)) + rng.normal(0.0, 50.0, shape)
    for _ in range(6):
        u, v, s = rng.uniform(0, W), rng.uniform(0, H), rng.uniform(0.7, 3.0)
        f += 10 ** rng.uniform(6, 9) * np.exp(-((x - u) ** 2 + (y - v) ** 2) / (2 * s * s))
    return np.maximum(f, 0.0).astype(np.float32)


@pytest.mark.parametrize("metering", ["mean", "center_weighted", "spot"])
@pytest.mark.parametrize("make", [_frame_like, lambda s: _flux(s, 3)])
def test_float32_path_without_logarithms_gives_the_old_histogram_to_the_bit(metering, make, monkeypatch):
    """The float32 path (bins from tables of bit patterns, :func:`_meter_bins_f32`) against the
    per-pixel logarithms of :func:`_meter_bins` (the path it replaces), compared to the bit."""
    sensor = SensorParams()
    f = make((203, 311))
    new = ExposureSolver.from_flux(f, sensor, metering)
    monkeypatch.setattr(ExposureSolver, "_build_f32", lambda self, *a: False)
    old = ExposureSolver.from_flux(f, sensor, metering)
    for k in ("w_bin", "wr_bin", "edges", "w_above", "wr_below"):
        assert np.array_equal(getattr(new, k), getattr(old, k)), k
    assert new.w_zero == old.w_zero
    for S in np.geomspace(1e-6, 1e3, 19):
        assert new.level(S) == old.level(S)


def test_float32_path_declines_what_it_cannot_bin():
    """Negative values, no dark current at a zero flux (r = 0) and small images take the general path."""
    m = ExposureSolver.__new__(ExposureSolver)
    f = _frame_like((100, 100)).ravel()
    w = np.zeros(0)
    assert m._build_f32(f, 0.5, 10.0, 5000.0, w, 1e-4, 4096)
    neg = f.copy()
    neg[5] = -1.0
    assert not m._build_f32(neg, 0.5, 10.0, 5000.0, w, 1e-4, 4096)
    zero = f.copy()
    zero[7] = 0.0
    assert not m._build_f32(zero, 0.5, 0.0, 5000.0, w, 1e-4, 4096)
    assert not m._build_f32(f[:100], 0.5, 10.0, 5000.0, w, 1e-2, 4096)
    assert not m._build_f32(f.astype(np.float64), 0.5, 10.0, 5000.0, w, 1e-4, 4096)
