"""Conics, ellipse fits and the projected-circle-centre correction (Kanatani)."""

import numpy as np
import pytest

from svgs_sim.tof.camera import load_camera
from svgs_sim.tof.ellipse import (centre_correction_px, circle_poses_from_conic, conic_center, detect_ellipse_arcs,
                         ellipse_to_conic, fit_ellipse, fit_ellipse_subpixel, level_crossings, project_circle_conic,
                         projected_circle_centre)


def _random_circles(n, seed, radius_m=0.04, z_range=(0.5, 6.0)):
    """Circles in front of the EPC660 camera, tilted up to ~40 deg, inside the field of view."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        z = rng.uniform(*z_range)
        c = np.array([rng.uniform(-0.4, 0.4) * z, rng.uniform(-0.3, 0.3) * z, z])
        nrm = np.array([0, 0, -1.0]) + rng.uniform(-0.6, 0.6, 3) * [1, 1, 0]
        out.append((c, nrm / np.linalg.norm(nrm), radius_m))
    return out


def test_ellipse_conic_holds_the_parametric_ellipse():
    C = ellipse_to_conic((12.5, -3.25), (7.0, 2.5), 0.7)
    t = np.linspace(0, 2 * np.pi, 37)
    ca, sa = np.cos(0.7), np.sin(0.7)
    on = np.stack([12.5 + 7.0 * np.cos(t) * ca - 2.5 * np.sin(t) * sa,
                   -3.25 + 7.0 * np.cos(t) * sa + 2.5 * np.sin(t) * ca, np.ones_like(t)], 1)
    np.testing.assert_allclose(np.einsum("ij,jk,ik->i", on, C, on), 0.0, atol=1e-12)
    assert np.array([12.5, -3.25, 1.0]) @ C @ np.array([12.5, -3.25, 1.0]) == pytest.approx(-1.0)  # inside < 0
    np.testing.assert_allclose(conic_center(C), [12.5, -3.25], atol=1e-12)


def test_projected_circle_centre_is_exact_and_the_ellipse_centre_is_biased():
    """Acceptance: on analytically projected circles the corrected centre equals the
    projection of the 3-D centre to ~1e-9 px, while the raw ellipse centre is off by the
    predicted bias f (r/Z)^2 [n_z n_xy + m_xy (1 - n_z^2)]."""
    cam = load_camera()
    K = cam.K
    worst_corr, worst_pred_rel, biases = 0.0, 0.0, []
    for c, n, r in _random_circles(200, seed=7):
        C = project_circle_conic(K, c, n, r)
        truth = cam.project(c)
        corrected = projected_circle_centre(C, K, n)
        worst_corr = max(worst_corr, np.abs(corrected - truth).max())
        raw = conic_center(C)
        bias = raw - truth
        m = c[:2] / c[2]  # the module notes' first-order bias f (r/Z)^2 [n_z n_xy + m_xy (1 - n_z^2)]
        pred = np.array([cam.fx, cam.fy]) * (r / c[2]) ** 2 * (n[2] * n[:2] + m * (1 - n[2] ** 2))
        np.testing.assert_allclose(centre_correction_px(C, K, n), -bias, atol=1e-9)
        biases.append(np.linalg.norm(bias))
        if np.linalg.norm(bias) > 1e-3:
            # first-order prediction: relative error O(r / Z)
            worst_pred_rel = max(worst_pred_rel, np.linalg.norm(bias - pred) / np.linalg.norm(bias) / (r / c[2]))
    assert worst_corr < 1e-9
    assert worst_pred_rel < 5.0  # |bias - pred| / |bias| <= 5 r / Z (r / Z <= 0.08 here)
    assert max(biases) > 0.1  # the bias matters at these ranges (80 mm marker at 0.5 m)


def test_centre_bias_grows_as_r_over_z_squared():
    cam = load_camera()
    c = np.array([0.3, -0.2, 1.0])
    n = np.array([0.3, -0.2, -1.0])
    n /= np.linalg.norm(n)
    b = [np.linalg.norm(conic_center(project_circle_conic(cam.K, c * s, n, 0.04)) - cam.project(c * s)) for s in (1, 2, 4, 8)]
    ratios = np.array(b[:-1]) / np.array(b[1:])
    np.testing.assert_allclose(ratios, 4.0, rtol=0.06)  # doubling the distance quarters the bias


def test_circle_poses_from_conic_recovers_the_circle():
    cam = load_camera()
    for c, n, r in _random_circles(50, seed=8, radius_m=0.04, z_range=(0.5, 2.0)):
        C = project_circle_conic(cam.K, c, n, r)
        centres, normals = circle_poses_from_conic(C, cam.K, r)
        k = np.argmin(np.linalg.norm(centres - c, axis=1) + np.linalg.norm(normals - n, axis=1))
        # the cone is ill-conditioned (nearly circular), hence the loose-looking tolerances
        np.testing.assert_allclose(centres[k], c, atol=1e-7 * np.linalg.norm(c))
        np.testing.assert_allclose(normals[k], n, atol=1e-5)
        # both solutions reproject to the same conic
        for cc, nn in zip(centres, normals):
            C2 = project_circle_conic(cam.K, cc, nn, r)
            np.testing.assert_allclose(C2 / np.linalg.norm(C2), C / np.linalg.norm(C), atol=1e-8)


def test_fit_ellipse_recovers_points_on_an_ellipse():
    C = ellipse_to_conic((50.2, 40.7), (12.0, 7.5), -0.3)
    t = np.linspace(0, 2 * np.pi, 60, endpoint=False)
    a, b, th = 12.0, 7.5, -0.3
    pts = np.stack([50.2 + a * np.cos(t) * np.cos(th) - b * np.sin(t) * np.sin(th),
                    40.7 + a * np.cos(t) * np.sin(th) + b * np.sin(t) * np.cos(th)], 1)
    for method in ("direct", "ams"):
        f = fit_ellipse(pts, method)
        np.testing.assert_allclose(f.center_px, [50.2, 40.7], atol=1e-3)
        np.testing.assert_allclose(f.axes_px, [12.0, 7.5], atol=1e-3)
        assert f.rms_px < 1e-3 and f.coverage == 1.0
        np.testing.assert_allclose(f.conic / f.conic[0, 0], C / C[0, 0], atol=1e-4)
    assert fit_ellipse(pts[:4]) is None


def _aa_ellipse_image(C, shape, ss=8, level=100.0, bg=5.0):
    H, W = shape
    yy, xx = np.mgrid[0:H * ss, 0:W * ss]
    X = np.stack([(xx + 0.5) / ss - 0.5, (yy + 0.5) / ss - 0.5, np.ones(xx.shape)], -1)
    inside = np.einsum("...i,ij,...j->...", X, C, X) < 0
    return bg + level * inside.reshape(H, ss, W, ss).mean(axis=(1, 3))


def test_subpixel_ellipse_fit_on_an_antialiased_marker():
    C = ellipse_to_conic((40.37, 30.81), (14.0, 9.0), 0.5)
    img = _aa_ellipse_image(C, (64, 80))
    pts = level_crossings(img, 55.0)
    assert pts.shape[0] > 60
    f = fit_ellipse_subpixel(img, (20, 15, 60, 46), 55.0)
    np.testing.assert_allclose(f.center_px, [40.37, 30.81], atol=0.01)
    np.testing.assert_allclose(f.axes_px, [14.0, 9.0], atol=0.05)


def test_arc_detection_recovers_a_marker_glued_to_a_glint():
    """Edge following: a marker merged with a bright bar is not an ellipse as a whole, but its
    elliptical arc is found and fitted."""
    C = ellipse_to_conic((40.3, 40.7), (15.0, 11.0), 0.3)
    img = _aa_ellipse_image(C, (80, 100))
    img[42:49, 53:76] = 105.0  # a glint touching the marker
    whole = fit_ellipse(level_crossings(img, 55.0))
    assert np.linalg.norm(whole.center_px - [40.3, 40.7]) > 1.0
    fits = detect_ellipse_arcs(img, (20, 25, 80, 60), 55.0)
    best = min(fits, key=lambda f: np.linalg.norm(f.center_px - [40.3, 40.7]))
    np.testing.assert_allclose(best.center_px, [40.3, 40.7], atol=0.05)
    np.testing.assert_allclose(best.axes_px, [15.0, 11.0], atol=0.1)
