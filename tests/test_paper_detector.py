"""The paper's detector (fixed threshold -> binary image -> blobs -> each blob's own centroid),
the deblended windowed option, and the consistency statistic's false-alarm rate.

The references are independent of the detector: blob centroids from scipy.ndimage's labelling
and numpy sums written here, an analytic two-spot image, and Monte Carlo chi-square draws.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from svgs_sim.svgs.app import consistency, settings
from svgs_sim.svgs.detect import app_level, detect_blobs
from svgs_sim.svgs.frames import pose_from_scenario
from svgs_sim.svgs.pipeline import camera_threshold, solve_image
from svgs_sim.base.profiles import Camera, Pattern
from svgs_sim.svgs.solver import solve_centroids


def _gauss(shape, centres, sigma, amp):
    yy, xx = np.mgrid[: shape[0], : shape[1]].astype(np.float64)
    img = np.zeros(shape)
    for (u, v), a in zip(centres, amp):
        img += a * np.exp(-((xx - u) ** 2 + (yy - v) ** 2) / (2 * sigma**2))
    return img


def _reference_centroids(img, level, background, weighted):
    """Independent implementation: 8-connected components of ``img > level`` (scipy.ndimage),
    then each component's centroid from its own pixels, weighted by ``img - background``
    (clipped at 0) or unweighted."""
    lab, n = ndimage.label(img > level, structure=np.ones((3, 3)))
    out = []
    for k in range(1, n + 1):
        ys, xs = np.nonzero(lab == k)
        if weighted:
            w = np.clip(img[ys, xs].astype(np.float64) - background, 0, None)
            out.append((np.sum(w * xs) / np.sum(w), np.sum(w * ys) / np.sum(w)))
        else:
            out.append((xs.mean(), ys.mean()))
    return np.array(out)


def _match(found, ref):
    d = np.linalg.norm(found[:, None] - ref[None], axis=-1)
    return d.min(axis=0)


@pytest.mark.parametrize("rule,weighted", [("weighted", True), ("binary", False)])
def test_paper_centroids_equal_an_independent_blob_centroid(rule, weighted):
    """Synthetic 8-bit blobs (some saturated, asymmetric by a second component, on a flat
    background): the detector's centroids at a fixed threshold equal scipy.ndimage labelling +
    numpy sums to 1e-9 px."""
    rng = np.random.default_rng(4)
    shape = (200, 260)
    centres = np.c_[np.linspace(25, 235, 6), rng.uniform(30, 170, 6)] + rng.uniform(-0.5, 0.5, (6, 2))
    yy, xx = np.mgrid[: shape[0], : shape[1]].astype(np.float64)
    img = np.full(shape, 20.0)
    for (u, v), a in zip(centres, rng.uniform(150, 600, 6)):  # compact, asymmetric, some saturated
        r2 = (xx - u) ** 2 + (yy - v) ** 2
        img += a * np.clip(1 - r2 / 36.0, 0, None) ** 2
        img += 90.0 * np.clip(1 - ((xx - u - 1.7) ** 2 + (yy - v + 0.9) ** 2) / 4.0, 0, None)
    u8 = np.clip(np.round(img), 0, 255).astype(np.uint8)
    b = detect_blobs(u8, threshold=24.0, centroid=rule, max_eccentricity=1.0, min_roundness=0.0)
    ref = _reference_centroids(u8, 24, 20.0, weighted)  # flat beyond the spots: the ring background is 20
    assert len(b) == len(ref) == 6
    assert _match(b.centroid_px, ref).max() < 1e-9
    # the blobs are those of the binary image: every reference blob found, and no other
    assert _match(ref, b.centroid_px).max() < 1e-9


def test_default_is_the_app_threshold_and_the_weighted_centroid():
    """No option: the app's fixed 8-bit level (not the automatic rule) and the weighted rule."""
    app = settings()
    assert app.centroid == "weighted"
    img = np.full((60, 80), 10, np.uint8)
    img[20:25, 30:36] = 250
    img[22, 36] = 140
    b = detect_blobs(img)
    assert b.threshold_used == app.threshold_dn
    ref = _reference_centroids(img, app.threshold_dn, 10.0, True)
    assert np.allclose(b.centroid_px, ref, atol=1e-9)
    assert app_level(np.uint16) == app.threshold_dn * 257
    # a 16-bit and an RGB copy of the frame give the same blobs at the same (scaled) level
    b16 = detect_blobs(img.astype(np.uint16) * 257)
    assert b16.threshold_used == app.threshold_dn * 257 and np.allclose(b16.centroid_px, b.centroid_px, atol=1e-9)
    brgb = detect_blobs(np.dstack([img] * 3))
    assert np.allclose(brgb.centroid_px, b.centroid_px, atol=1e-9)
    # the camera's test set-up sets the value the pipeline uses
    for name in ("galaxy-nexus", "htc-amaze-4g"):
        assert camera_threshold(img, Camera.load(name)) == app.threshold_for(name)
        lo, hi = app.threshold_range_dn
        assert lo <= app.threshold_for(name) <= hi


def test_windowed_centroid_does_not_move_toward_a_neighbours_halo():
    """Two spots whose halos overlap (sigma 3 px, 16 and 14 px apart, the neighbour 3x brighter):
    the deblended windowed centroid of the fainter one moves less than 0.005 px toward the
    neighbour (the windowed centroid without deblending, the detector's old default, moves 0.04
    and 0.21 px; the paper's weighted centroid 0.045 and 0.07 px)."""
    from svgs_sim.svgs.detect import windowed_centroid

    shape = (80, 120)
    for sep, thr, plain_min in ((16.0, 60.0, 0.03), (14.0, 100.0, 0.15)):
        c = np.array([[50.0, 40.0], [50.0 + sep, 40.0]])
        img = 10.0 + _gauss(shape, c, 3.0, [300.0, 900.0])
        b = detect_blobs(img, threshold=thr, centroid="window")
        assert len(b) == 2
        k = int(np.argmin(np.abs(b.centroid_px[:, 0] - 50.0)))
        du = b.centroid_px[k, 0] - 50.0  # the neighbour is at +u
        assert abs(du) < 0.005, f"deblended window moved {du:+.4f} px (the neighbour is at +u)"
        assert abs(b.centroid_px[k, 1] - 40.0) < 1e-6
        # the same window without deblending is pulled toward the neighbour (what the option fixes)
        plain = windowed_centroid(img, 50.0, 40.0, 3.0, 10.0)
        assert plain[0] - 50.0 > plain_min


@pytest.mark.slow
def test_consistency_false_alarm_rate_equals_its_level():
    """Gaussian centroid noise of the stated sigma on exact projections of the 3U pattern,
    solved by the collinearity solver: the fraction flagged inconsistent equals alpha within
    4 binomial standard deviations (20000 draws at alpha = 0.05 and 0.01), and the p-values
    are uniform (Kolmogorov-Smirnov p > 1e-3)."""
    from scipy import stats

    cam = Camera.load("galaxy-nexus")
    pat = Pattern.load("svgs-3u")
    R, t = pose_from_scenario(6.0, 0.05, -0.03, 2.0, -1.0, 3.0)
    uv = cam.project_target(pat.points_m, R, t)
    sigma = 0.1
    n = 20000
    rng = np.random.default_rng(22)
    pts = uv[None] + rng.normal(0.0, sigma, size=(n, *uv.shape))
    batch = solve_centroids(pts, cam, pat, sigma_px=sigma)
    assert batch.ok.all()
    p = np.array([consistency(r, len(uv), sigma_px=sigma).p_value for r in batch.residual_rms_px])
    for alpha in (0.05, 0.01):
        rate = np.mean(p < alpha)
        tol = 4 * np.sqrt(alpha * (1 - alpha) / n)
        assert abs(rate - alpha) < tol, f"false-alarm rate {rate:.4f} at alpha {alpha}"
    assert stats.kstest(p, "uniform").pvalue > 1e-3
    # and a centroid 5 px off on one target is caught (most of a smaller one is absorbed by the pose)
    bad = uv.copy()
    bad[2] += [5.0, 0.0]
    sol = solve_centroids(bad, cam, pat, sigma_px=sigma)
    assert consistency(sol.residual_rms_px, len(uv), sigma_px=sigma).p_value < settings().alpha


def test_solve_image_reports_inconsistent_instead_of_solved():
    """A rendered-free image with one spot displaced by 2 px: solve_image returns the failure
    ``inconsistent`` (with the rejected state and the statistic), not a solution; the same image
    undisplaced solves with p >= alpha."""
    cam = Camera.load("galaxy-nexus")
    pat = Pattern.load("svgs-3u")
    R, t = pose_from_scenario(5.0)
    uv = cam.project_target(pat.points_m, R, t)
    shape = (cam.height, cam.width)

    def image(points):
        img = np.full(shape, 8.0)
        for u, v in points:
            y0, x0 = int(v) - 12, int(u) - 12
            img[y0:y0 + 25, x0:x0 + 25] += _gauss((25, 25), [(u - x0, v - y0)], 2.0, [230.0])
        return np.clip(np.round(img), 0, 255).astype(np.uint8)

    good = solve_image(image(uv), cam, pat)
    assert good and good.consistency.p_value >= settings().alpha
    moved = uv.copy()
    moved[3] += [2.0, 0.0]
    bad = solve_image(image(moved), cam, pat)
    assert not bad and bad.reason == "inconsistent"
    assert bad.details["p_value"] < settings().alpha and bad.details["dof"] == 2
    assert set(bad.details["state"]) >= {"x_m", "pitch_deg"}
