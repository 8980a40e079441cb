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
