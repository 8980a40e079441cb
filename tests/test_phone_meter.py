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
