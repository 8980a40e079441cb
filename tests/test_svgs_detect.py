"""Blob detector: centroids against synthetic ground truth, gates, input types, bad input."""

import numpy as np
import pytest

from svgs_sim.svgs.detect import GATES, Blobs, auto_threshold, detect_blobs
from svgs_sim.base.errors import InputError
from synth_svgs import draw_elliptical_spots, draw_gaussian_spots, noise_field, quantize


def _spot_grid(shape, sigma, rng, spacing=None):
    """Random sub-pixel centres on a grid (one spot per cell), shape (N, 2)."""
    H, W = shape
    sp = spacing or int(12 * sigma) + 12
    g_u = np.arange(sp, W - sp, sp)
    g_v = np.arange(sp, H - sp, sp)
    cu, cv = np.meshgrid(g_u, g_v)
    c = np.stack([cu.ravel(), cv.ravel()], 1).astype(float)
    return c + rng.uniform(-0.5, 0.5, c.shape)


def _match(found, truth):
    """For each true centre the nearest found centroid's error vector, shape (N, 2)."""
    d = np.linalg.norm(found[:, None] - truth[None], axis=2)
    j = np.argmin(d, axis=0)
    return found[j] - truth


def _frame(shape, centres, sigma, peak, *, background, read_noise, gain, dtype, seed):
    rng = np.random.default_rng(seed)
    img = np.full(shape, float(background), np.float32)
    if read_noise:
        img += noise_field(shape, read_noise, rng, tile_px=None)
    draw_gaussian_spots(img, centres, sigma, 2 * np.pi * sigma**2 * peak, photon_gain=gain, rng=rng)
    return quantize(img, dtype)


# ---------------------------------------------------------------- centroid accuracy
@pytest.mark.parametrize(
    "dtype, peak, read_noise, gain",
    [
        # 16-bit: peak 20000 DN, 20 DN read noise, photon noise at 1 e-/DN (peak SNR ~140)
        ("uint16", 20000.0, 20.0, 1.0),
        # 8-bit: a bright unsaturated spot, 1 DN read noise, quantisation
        ("uint8", 200.0, 1.0, None),
    ],
)
def test_centroids_within_0p02_px_of_truth(dtype, peak, read_noise, gain):
    """Acceptance: centroids within 0.02 px for well-sampled (sigma 1-3 px) unsaturated
    spots with noise, over many random sub-pixel centres."""
    rng = np.random.default_rng(11)
    errs = []
    for sigma in (1.0, 1.5, 2.0, 3.0):
        shape = (420, 420)
        c = _spot_grid(shape, sigma, rng)
        img = _frame(shape, c, sigma, peak, background=10.0, read_noise=read_noise, gain=gain, dtype=dtype,
                     seed=int(sigma * 10))
        b = detect_blobs(img, threshold="auto", centroid="window")
        assert len(b) == len(c), f"sigma {sigma}: found {len(b)} of {len(c)} spots"
        errs.append(_match(b.centroid_px, c))
    e = np.concatenate(errs)
    r = np.linalg.norm(e, axis=1)
    assert len(r) > 300
    assert r.max() <= 0.02, f"max centroid error {r.max():.4f} px"
    assert np.sqrt(np.mean(r**2)) <= 0.008
    # unbiased: the mean error is far below the scatter
    assert np.all(np.abs(e.mean(0)) < 0.002)


def test_windowed_centroid_beats_threshold_truncated_centroid():
    """The plain weighted centroid of the thresholded pixels is biased by the threshold
    cutting the wings (pixel-locking); the windowed centroid is not. Noise-free spots."""
    rng = np.random.default_rng(3)
    shape = (400, 400)
    c = _spot_grid(shape, 1.0, rng)
    img = _frame(shape, c, 1.0, 1000.0, background=0.0, read_noise=0.0, gain=None, dtype="float64", seed=0)
    win = np.linalg.norm(_match(detect_blobs(img, threshold="auto", centroid="window").centroid_px, c), axis=1)
    comp = np.linalg.norm(_match(detect_blobs(img, threshold="auto", centroid="weighted").centroid_px, c), axis=1)
    assert win.max() < 2e-3
    assert comp.max() > 0.03  # the bias the windowed centroid removes
    assert np.sqrt(np.mean(comp**2)) > 10 * np.sqrt(np.mean(win**2))


def test_spot_measurements():
    """Flux, peak, area, bbox and shape of isolated noise-free spots."""
    img = np.zeros((80, 120), np.float64)
    draw_gaussian_spots(img, [[30.3, 40.7]], 2.0, 5000.0)
    draw_elliptical_spots(img, [[90.0, 40.0]], 6.0, 1.5, 0.0, 300.0)  # horizontal streak
    b = detect_blobs(img, threshold=5.0, max_eccentricity=1.0, centroid="window")
    assert len(b) == 2
    k = int(np.argmin(np.abs(b.centroid_px[:, 0] - 30.3)))
    assert np.allclose(b.centroid_px[k], [30.3, 40.7], atol=1e-3)
    x, y, w, h = b.bbox[k]
    assert x <= 30.3 <= x + w - 1 and y <= 40.7 <= y + h - 1
    # flux above the threshold: all but the wings below 5 (of a 5000 total flux)
    assert 4300 < b.flux[k] <= 5000
    assert b.peak[k] == pytest.approx(img[:, :60].max())
    assert b.eccentricity[k] < 0.4 and b.roundness[k] > 0.8
    assert b.eccentricity[1 - k] > 0.9 and b.roundness[1 - k] < b.roundness[k]
    assert b.saturated_fraction[k] == 0.0


def test_saturated_spot_fraction_and_centre():
    """A saturated 8-bit spot: saturated fraction counted, centroid still on the centre."""
    img = np.full((60, 60), 5.0, np.float32)
    draw_gaussian_spots(img, [[29.4, 31.2]], 2.5, 2 * np.pi * 2.5**2 * 2000.0)
    u8 = quantize(img, "uint8")
    b = detect_blobs(u8, threshold="auto", centroid="window")
    assert len(b) == 1
    assert b.saturated_fraction[0] > 0.3
    assert b.peak[0] == 255
    assert np.allclose(b.centroid_px[0], [29.4, 31.2], atol=0.02)
    # an explicit saturation level
    b2 = detect_blobs(u8, saturation_level=300, threshold="auto", centroid="window")
    assert b2.saturated_fraction[0] == 0.0


# ---------------------------------------------------------------- gates
def test_gates_reject_and_count():
    img = np.zeros((200, 300), np.float32)
    draw_gaussian_spots(img, [[50.2, 50.6], [150.5, 60.1]], 1.5, 2 * np.pi * 1.5**2 * 200.0)  # 2 targets
    img[150, 40] = 180.0  # hot pixel (area 1)
    draw_elliptical_spots(img, [[200.0, 150.0]], 12.0, 1.0, 0.3, 200.0)  # long glint
    img[10:130, 240:290] = 150.0  # a large bright region (6000 px)
    b = detect_blobs(img, threshold=20.0, max_area_px=2000)
    assert len(b) == 2
    assert b.rejected["min_area"] == 1
    assert b.rejected["eccentricity"] == 1
    assert b.rejected["max_area"] == 1
    assert set(b.rejected) == set(GATES)
    assert b.n_components == 5
    # gates off: everything comes back
    b_all = detect_blobs(img, threshold=20.0, min_area_px=1, max_area_px=10**6, max_eccentricity=1.0, min_roundness=0.0)
    assert len(b_all) == 5


def test_roundness_gate_drops_ragged_regions():
    img = np.zeros((100, 100), np.float32)
    img[20:80, 48:52] = 100.0  # a cross: round second moments, ragged outline
    img[48:52, 20:80] = 100.0
    b = detect_blobs(img, threshold=50.0)
    assert len(b) == 0 and b.rejected["roundness"] == 1
    assert len(detect_blobs(img, threshold=50.0, min_roundness=0.0)) == 1


def test_max_blobs_keeps_the_largest():
    img = np.zeros((100, 400), np.float32)
    for k in range(20):
        img[40:40 + 2 + k % 5, 10 + 18 * k: 12 + 18 * k + k % 5] = 100.0
    b = detect_blobs(img, threshold=10.0, max_blobs=5, min_area_px=1)
    assert len(b) == 5 and b.rejected["max_blobs"] == 15
    assert b.area_px.tolist() == [36, 36, 36, 36, 25]  # the four 6 x 6 squares and a 5 x 5


# ---------------------------------------------------------------- threshold
def test_auto_threshold_ignores_noise_and_finds_spots():
    rng = np.random.default_rng(5)
    shape = (1000, 1200)
    noise_only = quantize(10.0 + noise_field(shape, 2.0, rng, tile_px=None), "uint8")
    assert len(detect_blobs(noise_only, threshold="auto", centroid="window")) == 0
    c = np.array([[100.3, 200.7], [900.1, 700.4], [500.5, 500.5]])
    img = _frame(shape, c, 1.5, 60.0, background=10.0, read_noise=2.0, gain=None, dtype="uint8", seed=1)
    b = detect_blobs(img, threshold="auto", centroid="window")
    assert len(b) == 3
    level, bg, sigma = auto_threshold(img)
    assert bg == pytest.approx(10.0, abs=0.6)
    assert sigma == pytest.approx(2.0, rel=0.25)
    assert b.threshold_used == pytest.approx(level)
    assert level > bg + 5 * sigma


def test_fixed_and_otsu_thresholds():
    img = np.zeros((100, 100), np.uint8)
    img[40:45, 40:45] = 100
    img[70:74, 10:14] = 30
    assert len(detect_blobs(img, threshold=50)) == 1
    assert len(detect_blobs(img, threshold=20)) == 2
    b = detect_blobs(img, threshold="otsu")
    assert len(b) >= 1 and 0 <= b.threshold_used < 100
    from svgs_sim.svgs.detect import app_level

    assert detect_blobs(img).threshold_used == app_level(img.dtype)  # no option: the app's level, not the automatic rule


# ---------------------------------------------------------------- input types
def test_16bit_colour_and_float_give_the_same_blobs():
    rng = np.random.default_rng(8)
    shape = (300, 400)
    c = np.array([[50.3, 60.2], [320.7, 250.1], [200.2, 150.9]])
    img = np.full(shape, 8.0, np.float32) + noise_field(shape, 1.0, rng, tile_px=None)
    draw_gaussian_spots(img, c, 1.8, 2 * np.pi * 1.8**2 * 150.0)
    u8 = quantize(img, "uint8")
    ref = detect_blobs(u8, threshold="auto", centroid="window")
    assert len(ref) == 3
    u16 = u8.astype(np.uint16) * 257
    rgb = np.repeat(u8[..., None], 3, axis=2)
    f32 = u8.astype(np.float32) / 255.0
    for other in (u16, rgb, f32, u8.astype(np.int32)):
        b = detect_blobs(other, threshold="auto", centroid="window")
        assert len(b) == 3
        assert np.allclose(b.centroid_px, ref.centroid_px, atol=1e-6)
        assert np.array_equal(b.area_px, ref.area_px)
    # RGBA and (H, W, 1)
    assert len(detect_blobs(np.dstack([rgb, np.full(shape, 255, np.uint8)]), threshold="auto", centroid="window")) == 3
    assert len(detect_blobs(u8[..., None], threshold="auto", centroid="window")) == 3
    # colour weights: a pure-blue spot is dimmer in luminance than a pure-green one
    col = np.zeros((50, 100, 3), np.uint8)
    col[20:25, 20:25, 1] = 200
    col[20:25, 70:75, 2] = 200
    b = detect_blobs(col, threshold=10)
    assert len(b) == 2 and b.centroid_px[0, 0] < 50  # the green spot is the brighter


def test_sizes_not_multiple_of_block_and_border_spots():
    img = np.zeros((77, 101), np.float32)
    draw_gaussian_spots(img, [[100.2, 40.0], [3.3, 76.1], [50.5, 38.2]], 1.2, 500.0)
    b = detect_blobs(img, threshold=5.0, min_area_px=2, centroid="window")
    assert len(b) == 3
    assert np.any(np.abs(b.centroid_px[:, 0] - 100.2) < 1.0)
    assert np.any(np.abs(b.centroid_px[:, 1] - 76.1) < 1.0)
    k = int(np.argmin(np.linalg.norm(b.centroid_px - [50.5, 38.2], axis=1)))
    assert np.allclose(b.centroid_px[k], [50.5, 38.2], atol=1e-3)


def test_many_regions_fall_back_to_full_frame_labelling():
    """Over ~400 coarse regions the detector labels the whole frame at once: same answer."""
    rng = np.random.default_rng(2)
    img = np.zeros((800, 800), np.float32)
    c = _spot_grid(img.shape, 1.0, rng, spacing=30)
    assert len(c) > 500
    draw_gaussian_spots(img, c, 1.0, 2 * np.pi * 300.0)
    b = detect_blobs(img, threshold=20.0, max_blobs=10_000, centroid="window")
    assert b.n_components == len(c) and len(b) == len(c)
    assert np.abs(_match(b.centroid_px, c)).max() < 2e-3


def test_empty_results_are_well_shaped():
    for img in (np.zeros((64, 48), np.uint8), np.full((64, 48), 7.5), np.zeros((10, 10, 3), np.uint16)):
        b = detect_blobs(img, threshold="auto", centroid="window")
        assert isinstance(b, Blobs) and len(b) == 0
        assert b.centroid_px.shape == (0, 2) and b.bbox.shape == (0, 4)
        for k in ("area_px", "peak", "saturated_fraction", "eccentricity", "roundness", "flux"):
            assert getattr(b, k).shape == (0,)
        assert np.isfinite(b.threshold_used)
    b = detect_blobs(np.zeros((64, 48), np.uint8))
    assert b.to_json()["n_blobs"] == 0


def test_sorted_by_flux_and_subset():
    img = np.zeros((100, 200), np.float32)
    draw_gaussian_spots(img, [[30, 50], [100, 50], [170, 50]], 1.5, [1000.0, 3000.0, 2000.0])
    b = detect_blobs(img, threshold=5.0)
    assert np.all(np.diff(b.flux) < 0)
    assert np.allclose(b.centroid_px[:, 0], [100, 170, 30], atol=1e-3)
    s = b.subset([2, 0])
    assert len(s) == 2 and np.allclose(s.centroid_px[:, 0], [30, 100], atol=1e-3)
    assert s.threshold_used == b.threshold_used


# ---------------------------------------------------------------- bad input
@pytest.mark.parametrize(
    "bad",
    [
        np.zeros(10),
        np.zeros((4, 4, 4, 4)),
        np.zeros((10, 10, 2)),
        np.zeros((0, 10)),
        np.zeros((10, 0, 3)),
        np.array([["a", "b"], ["c", "d"]]),
        np.zeros((5, 5), dtype=bool),
        np.array([[1.0, np.nan], [0.0, 1.0]]),
        np.array([[1.0, np.inf], [0.0, 1.0]], np.float32),
        None,
        "image.png",
    ],
)
def test_bad_image_raises_input_error_naming_image(bad):
    with pytest.raises(InputError, match="image"):
        detect_blobs(bad)


@pytest.mark.parametrize(
    "kw, name",
    [
        ({"threshold": "median"}, "threshold"),
        ({"threshold": float("nan")}, "threshold"),
        ({"threshold": [1, 2]}, "threshold"),
        ({"min_area_px": 0}, "min_area_px"),
        ({"max_blobs": 2.5}, "max_blobs"),
        ({"centroid": "peak"}, "centroid"),
    ],
)
def test_bad_options_raise_input_error(kw, name):
    with pytest.raises(InputError, match=name):
        detect_blobs(np.zeros((8, 8), np.uint8), **kw)
