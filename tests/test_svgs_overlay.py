"""The overlay picture (svgs_sim/svgs/overlay.py) and its centroid ellipses."""

import numpy as np
import pytest

from svgs_sim.svgs.overlay import centroid_sigma_from_image, crop_box, render_overlay, window_centroid


def spot_image(centres, shape=(120, 160), sigma_psf=1.3, peak=400.0, background=20.0):
    yy, xx = np.mgrid[0:shape[0], 0:shape[1]]
    img = np.full(shape, background)
    for u, v in centres:
        img += peak * np.exp(-((xx - u) ** 2 + (yy - v) ** 2) / (2 * sigma_psf**2))
    return img


def test_the_ellipse_is_the_scatter_of_the_window_centroid_under_the_noise():
    """First-order propagation of the background noise against a Monte Carlo of the same estimator."""
    c = (60.3, 55.7)
    clean = spot_image([c], peak=60.0)
    s = 4.0
    rng = np.random.default_rng(0)
    est = np.array([window_centroid(clean + rng.normal(0, s, clean.shape), *c)[:2] for _ in range(3000)])
    pred = centroid_sigma_from_image(clean, [c], s)[0]
    np.testing.assert_allclose(est.std(0), pred, rtol=0.08)
    assert abs(est[:, 0].mean() - c[0]) < 0.05 and abs(est[:, 1].mean() - c[1]) < 0.05


def test_crop_holds_the_points_with_a_margin_and_the_picture_has_the_parts():
    pts = np.array([[50.0, 40.0], [90.0, 42.0], [70.0, 80.0], [72.0, 60.0]])
    x0, y0, x1, y1 = crop_box(pts, (120, 160), margin_px=10)
    assert x0 <= pts[:, 0].min() - 10 and x1 >= pts[:, 0].max() + 10
    assert y0 <= pts[:, 1].min() - 10 and y1 >= pts[:, 1].max() + 10
    img = spot_image(pts)
    targets = {str(i + 1): p.tolist() for i, p in enumerate(pts)}
    sig = centroid_sigma_from_image(img, pts, 2.0)
    out = render_overlay(img, blobs_px=pts, targets_px=targets, reprojected_px=targets,
                         sigma_px=dict(zip(targets, sig.tolist())), sigma_label="test", title="t", size_px=600)
    assert out.dtype == np.uint8 and out.ndim == 3 and out.shape[2] == 3
    assert max(out.shape[:2]) >= 600
    # the labels are drawn in yellow (BGR 0, 255, 255) and the ellipses in green
    yellow = np.all(out == (0, 255, 255), axis=2).sum()
    green = np.all(out == (80, 255, 80), axis=2).sum()
    assert yellow > 50 and green > 20


def test_an_unsolved_frame_still_gets_a_picture():
    img = spot_image([(30.0, 30.0)])
    out = render_overlay(img, blobs_px=[[30.0, 30.0]], title="NO SOLUTION")
    assert out.shape[0] > 58
    with pytest.raises(Exception):
        render_overlay(np.zeros((0, 0)))


def _stretch_per_pixel(gray, box, lo):
    """The display's square-root stretch written out on every pixel in float64 (the formula the
    table of an integer image must reproduce)."""
    x0, y0, x1, y1 = box
    g = np.asarray(gray, np.float64)
    hi = max(float(g[y0:y1, x0:x1].max()), lo + 1e-9)
    return (255.0 * np.sqrt(np.clip((g - lo) / (hi - lo), 0.0, 1.0)) + 0.5).astype(np.uint8)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_the_display_table_of_an_integer_image_is_the_per_pixel_stretch(dtype):
    """An 8- or 16-bit image goes through a table of its levels: the same bytes as the formula on
    every pixel, from the frame's median and from a given black level (pixels at or below it
    black)."""
    from svgs_sim.svgs.overlay import _display_u8

    rng = np.random.default_rng(4)
    top = np.iinfo(dtype).max
    img = rng.integers(0, top // 3, (90, 130)).astype(dtype)
    img[40:50, 60:70] = rng.integers(top // 2, top, (10, 10))
    box = (55, 35, 80, 60)
    sub = np.asarray(img[:: max(1, 90 // 200), :: max(1, 130 // 200)], np.float64)
    np.testing.assert_array_equal(_display_u8(img, box), _stretch_per_pixel(img, box, float(np.median(sub))))
    lo = float(top // 4)
    got = _display_u8(img, box, lo)
    np.testing.assert_array_equal(got, _stretch_per_pixel(img, box, lo))
    assert not got[img <= lo].any() and got[img > lo].all()


def test_the_thumbnail_reduction_covers_the_whole_frame():
    """The two-step area reduction of the inset thumbnail against OpenCV's one-step ``INTER_AREA``
    on a smooth frame (within a count), and a lone pixel in the last row and column lands in the
    thumbnail's last pixel (the whole frame is covered)."""
    import cv2

    from svgs_sim.svgs.overlay import _area_reduce

    yy, xx = np.mgrid[0:1944, 0:2592]
    ramp = (40 + 150 * (xx / 2592.0) * (0.5 + yy / 3888.0)).astype(np.uint8)
    ref = cv2.resize(ramp, (170, 128), interpolation=cv2.INTER_AREA).astype(int)
    assert np.abs(_area_reduce(ramp, 170, 128).astype(int) - ref).max() <= 1
    dot = np.zeros((1944, 2592), np.uint8)
    dot[-1, -1] = 255
    t = _area_reduce(dot, 170, 128)
    assert t.shape == (128, 170) and t[-1, -1] > 0 and t.sum() == t[-1, -1]


def test_a_frame_under_twice_the_thumbnail_takes_one_step():
    """No whole-factor step when the frame is less than twice the thumbnail (or smaller, scaled
    up): OpenCV's one-step ``INTER_AREA`` itself."""
    import cv2

    from svgs_sim.svgs.overlay import _area_reduce

    rng = np.random.default_rng(2)
    for shape, size in (((200, 300), (240, 160)), ((100, 120), (170, 142)), ((240, 320), (170, 128))):
        img = rng.integers(0, 256, shape).astype(np.uint8)
        np.testing.assert_array_equal(_area_reduce(img, *size), cv2.resize(img, size, interpolation=cv2.INTER_AREA))
