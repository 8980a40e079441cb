"""ToF pipeline stages, each alone: active set, nLoG, blobs, temporal median, persistence."""

import numpy as np
import pytest
from skimage.morphology import reconstruction

from svgs_sim.base.errors import InputError
from svgs_sim.tof.active import active_pixel_set
from svgs_sim.tof.blobs import blobs_from_mask, eccentricity_from_cov, find_blobs
from svgs_sim.tof.centroid import coverage_centroids
from svgs_sim.tof.log_filter import filter_active_set, nlog_at, nlog_image, nlog_kernel
from svgs_sim.tof.temporal import PersistenceCounter, RecursiveMedianDepth, median3


def _disk_image(shape, centres, radii, levels, ss=8, bg=0.0):
    """Anti-aliased disks (supersampled), values in counts."""
    H, W = shape
    img = np.full(shape, bg, float)
    yy, xx = np.mgrid[0:H * ss, 0:W * ss]
    u = (xx + 0.5) / ss - 0.5
    v = (yy + 0.5) / ss - 0.5
    for (cu, cv), r, lv in zip(centres, radii, levels):
        inside = (u - cu) ** 2 + (v - cv) ** 2 <= r * r
        img += lv * inside.reshape(H, ss, W, ss).mean(axis=(1, 3))
    return img


def test_active_set_thresholds_and_caps_dimmest_first():
    rng = np.random.default_rng(0)
    g = rng.uniform(0, 10, (60, 80))
    g[10:20, 10:20] = np.linspace(100, 200, 100).reshape(10, 10)
    a = active_pixel_set(g, threshold_rel=0.3)
    assert a.n == 100 and a.n_above == 100
    assert a.threshold == pytest.approx(60.0)
    capped = active_pixel_set(g, threshold_rel=0.3, max_pixels=30)
    assert capped.n == 30 and capped.n_above == 100
    # the 30 kept are the 30 brightest, in decreasing order
    np.testing.assert_allclose(capped.gray, np.sort(g[10:20, 10:20].ravel())[::-1][:30], rtol=1e-6)
    assert capped.mask().sum() == 30


def test_all_dark_frame_gives_an_empty_active_set():
    rng = np.random.default_rng(1)
    assert active_pixel_set(np.zeros((40, 50))).n == 0
    noise = 5 + rng.normal(0, 1, (240, 320))  # noise only: the noise floor keeps it empty
    assert active_pixel_set(noise).n == 0


def test_active_set_rejects_bad_arguments():
    with pytest.raises(InputError, match="gray"):
        active_pixel_set(np.zeros((3, 4, 5)))
    with pytest.raises(InputError, match="threshold_rel"):
        active_pixel_set(np.zeros((3, 4)), threshold_rel=1.5)


def test_nlog_on_the_active_set_equals_the_full_convolution():
    rng = np.random.default_rng(2)
    g = rng.uniform(0, 100, (50, 70)).astype(np.float32)
    rows = np.array([0, 5, 49, 20, 33])
    cols = np.array([0, 69, 10, 35, 1])
    ref = nlog_image(g, 1.3)[rows, cols]
    np.testing.assert_allclose(nlog_at(g, rows, cols, 1.3), ref, rtol=1e-4, atol=1e-3)


def test_nlog_kernel_is_zero_sum_and_peaks_on_a_matched_blob():
    k = nlog_kernel(1.5)
    assert abs(k.sum()) < 1e-5 and k[k.shape[0] // 2, k.shape[1] // 2] == k.max()
    # a disk of radius sigma*sqrt(2) responds most at its centre; flat areas give 0
    img = _disk_image((41, 41), [(20.0, 20.0)], [1.5 * np.sqrt(2)], [100.0], bg=50.0)
    f = nlog_image(img, 1.5)
    assert np.unravel_index(np.argmax(f), f.shape) == (20, 20)
    assert abs(f[2, 2]) < 1e-3


def test_filtered_threshold_keeps_large_blob_interiors_and_drops_dark_edges():
    img = _disk_image((80, 80), [(40.0, 40.0)], [15.0], [1000.0], bg=10.0)
    a = active_pixel_set(img, threshold_rel=0.05)
    kept, f, thr = filter_active_set(img, a, sigma_px=1.0, threshold_rel=-0.1)
    assert np.all(np.diff(f) <= 0)  # ordered by decreasing filtered intensity
    mk = kept.mask()
    assert mk[40, 40]  # ~0 response inside a large marker is kept
    assert kept.n < a.n  # the dark side of the rim is dropped


def test_hysteresis_blobs_equal_morphological_reconstruction():
    rng = np.random.default_rng(3)
    img = _disk_image((60, 90), [(15, 15), (45, 30), (70, 40)], [5, 6, 4], [900, 300, 1000], bg=5)
    img += rng.normal(0, 2, img.shape)
    a = active_pixel_set(img, threshold_rel=0.1, noise_k=3)
    f = nlog_at(img, a.rows, a.cols, 1.0)
    high = 0.5 * a.gray_max
    b = find_blobs(a, f, high_gray=high, high_filtered=-np.inf, max_eccentricity=1.0, min_pixels=1)
    low_mask = a.mask()
    seed = low_mask & (img > high)
    rec = reconstruction(seed.astype(np.uint8), low_mask.astype(np.uint8), method="dilation").astype(bool)
    np.testing.assert_array_equal(b.mask(img.shape), rec)
    assert b.n == 2  # the dim disk (peak 300 < 0.5 max) is not a candidate


def test_blob_gates_reject_small_and_elongated_components():
    img = np.zeros((60, 80))
    img[10:20, 10:20] = 100.0  # square blob: accepted
    img[40:42, 10:40] = 100.0  # a 2 x 30 streak: eccentric
    img[50, 70] = 100.0  # a single hot pixel: too small
    a = active_pixel_set(img, threshold_rel=0.5)
    b = find_blobs(a, np.ones(a.n), min_pixels=3, max_eccentricity=0.9)
    assert b.n == 1 and b.n_pixels[0] == 100
    assert b.rejected["eccentricity"] == 1 and b.rejected["size"] == 1
    np.testing.assert_allclose(b.centroid_px[0], [14.5, 14.5])
    assert len(b.rejected_rows) == 1  # the streak is kept for the ellipse supplement


def test_eccentricity_of_a_tilted_circle():
    # covariance of an ellipse with axes ratio cos(60 deg) -> eccentricity sin(60 deg)
    a, b, th = 10.0, 5.0, 0.4
    Rm = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    cov = Rm @ np.diag([a * a / 4, b * b / 4]) @ Rm.T
    assert eccentricity_from_cov(cov) == pytest.approx(np.sin(np.radians(60)))


def test_coverage_centroid_is_unbiased_under_an_illumination_gradient():
    """The paper's intensity-weighted centroid is pulled towards the lit side of a marker;
    the coverage-weighted centroid is not."""
    H, W, ss = 60, 60, 8
    yy, xx = np.mgrid[0:H * ss, 0:W * ss]
    u = (xx + 0.5) / ss - 0.5
    v = (yy + 0.5) / ss - 0.5
    c = (30.3, 29.6)
    r = 12.0
    inside = (u - c[0]) ** 2 + (v - c[1]) ** 2 <= r * r
    light = 1000 * (1 + 0.08 * (u - c[0]) / r)  # +-8 % across the marker
    img = (inside * light).reshape(H, ss, W, ss).mean(axis=(1, 3)) + 20
    a = active_pixel_set(img, threshold_rel=0.3)
    b = blobs_from_mask(a.mask(), img)
    assert b.n == 1
    rows, cols = b.rows, b.cols
    w = img[rows, cols] - 20
    intensity = np.array([w @ cols, w @ rows]) / w.sum()
    cov = coverage_centroids(img, b, 20.0)[0]
    assert np.linalg.norm(intensity - c) > 0.2  # the paper's weighting: biased by ~0.08 r^2 / (4 r) px
    assert np.linalg.norm(cov - c) < 0.02


def test_recursive_median_removes_spikes_and_follows_a_ramp():
    f = RecursiveMedianDepth()
    seq = [1.0, 1.0, 5.0, 1.0, 1.0]  # a one-frame flying-pixel spike
    out = [float(f.update(np.full((2, 2), x))[0, 0]) for x in seq]
    assert out == [1.0, 1.0, 1.0, 1.0, 1.0]
    f.reset()
    ramp = [1.0, 1.1, 1.2, 1.3, 1.4, 1.5]
    out = [float(f.update(np.full((1, 1), x))[0, 0]) for x in ramp]
    np.testing.assert_allclose(out[2:], ramp[1:-1], rtol=1e-6)  # follows with one frame of lag
    assert np.isnan(median3(np.nan, np.nan, np.nan)) and median3(np.nan, 2.0, 3.0) == 2.0


def test_persistence_counter_keeps_pixels_seen_often_and_averages_them():
    pc = PersistenceCounter(window=3, min_count=2)
    m = np.zeros((4, 4), bool)
    m[1, 1] = m[2, 2] = True
    flicker = m.copy()
    flicker[3, 3] = True
    keep, g, d, cnt = pc.update(flicker, np.full((4, 4), 10.0), np.full((4, 4), 2.0))
    assert keep[3, 3]  # first frame: min_count is capped at the frames seen
    keep, g, d, cnt = pc.update(m, np.full((4, 4), 20.0), np.full((4, 4), 4.0))
    keep, g, d, cnt = pc.update(m, np.full((4, 4), 30.0), np.full((4, 4), np.nan))
    assert keep[1, 1] and not keep[3, 3] and cnt[1, 1] == 3
    assert g[1, 1] == pytest.approx(20.0)  # (10 + 20 + 30) / 3
    assert d[1, 1] == pytest.approx(3.0)  # NaN depth samples are not counted
    keep, g, d, cnt = pc.update(m, np.full((4, 4), 40.0), np.full((4, 4), 4.0))
    assert cnt[1, 1] == 3 and g[1, 1] == pytest.approx(30.0)  # window slides
    with pytest.raises(InputError):
        PersistenceCounter(window=2, min_count=3)


def test_coverage_centroids_of_markers_2_px_apart():
    rng = np.random.default_rng(4)
    centres = [(20.3, 20.6), (24.9, 20.2), (29.6, 21.1), (60.2, 40.7)]  # three 2-px markers 2 px apart
    img = _disk_image((64, 90), centres, [1.1, 1.1, 1.1, 9.0], [900, 800, 850, 1000], bg=30.0)
    img += rng.normal(0, 2, img.shape)
    a = active_pixel_set(img, threshold_rel=0.1)
    b = find_blobs(a, np.ones(a.n), min_pixels=1, max_eccentricity=1.0)
    assert b.n == 4
    vec = coverage_centroids(img, b, a.background)
    # each blob's rim pixels next to a neighbour count for both: the centres are still found
    truth = np.array(centres)
    d = np.linalg.norm(vec[:, None] - truth[None], axis=-1).min(1)
    assert d.max() < 0.15
