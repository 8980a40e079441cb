"""Deferred dark pixels (issue 40): ``Exposer.expose(dark_pixels="deferred")`` exposes only the
tiles that can reach the detection threshold, and the full frame when its image is read.

The reference is the exact path itself, run on the same seed in the same test: the detection
image must hold the exact image's bytes on every delivered tile and 0 elsewhere, the exact image
must have no pixel at the threshold outside the delivered tiles (what makes the blobs the same),
and the image read afterwards must be the exact path's to the bit. Where the shortcut cannot hold
(a bright frame, no numeric threshold, a downscale, blooming that spills beyond the delivered
tiles) the exposure is the exact one.
"""

import numpy as np
import pytest

from svgs_sim.camera.phone import (
    ALL_STAGES,
    DARK_TILE_PX,
    DeferredExposure,
    Exposer,
    PhoneCamera,
    lit_crops,
)

NO_GLARE = tuple(s for s in ALL_STAGES if s != "glare")
THRESHOLD = 64.0


def _flux_for(mu_e, sp, t):
    return mu_e / (sp.qe * t)


def _frame(small_camera, patches):
    """A dark frame (3 e- expected) with bright square patches ``(row, col, side, e-)``."""
    phone = PhoneCamera(small_camera)
    H, W = phone.shape
    sp = phone.params.sensor
    t = phone.params.exposure.exposure_s
    flux = np.full((H, W), _flux_for(3.0, sp, t), np.float32)
    for r, c, n, mu in patches:
        flux[r:r + n, c:c + n] = _flux_for(mu, sp, t)
    return phone, Exposer(phone, flux, stages=NO_GLARE)


def _delivered_mask(ex, t, iso):
    """The pixels a deferred exposure delivers now (its crops' lit-tile boxes)."""
    p = ex.phone.params
    dark, _ = ex.dark_tiles(t, iso, ex.stages, p.isp, p.cfa.demosaic, THRESHOLD)
    H, W = ex.flux_optics.shape
    mask = np.zeros((H, W), bool)
    for _, (i0, i1, j0, j1) in lit_crops(~dark, 2):
        mask[i0 * DARK_TILE_PX:i1 * DARK_TILE_PX, j0 * DARK_TILE_PX:j1 * DARK_TILE_PX] = True
    return mask


@pytest.mark.parametrize("seed", [0, 7])
def test_delivered_tiles_are_the_exact_bytes_and_the_image_is_the_exact_one(small_camera, seed):
    """Two bright patches far apart (two crops) and a faint one: on the delivered tiles the
    detection image is the exact image byte for byte, elsewhere 0 and the exact image below the
    threshold; the image, raw DN and charge read afterwards are the exact path's."""
    phone, ex = _frame(small_camera, [(100, 120, 20, 4000.0), (380, 520, 12, 2500.0), (300, 60, 6, 60.0)])
    exact = ex.expose(seed=seed, keep_electrons=True)
    d = ex.expose(seed=seed, keep_electrons=True, dark_pixels="deferred", threshold_u8=THRESHOLD)
    assert isinstance(d, DeferredExposure)
    info = d.info["dark_pixels"]
    assert info["path"] == "deferred" and info["crops"] >= 2 and info["exposed_fraction"] < 0.5
    mask = _delivered_mask(ex, exact.exposure_s, exact.iso)
    assert mask.mean() < 0.5
    np.testing.assert_array_equal(d.detect_image[mask], exact.image[mask])
    assert not d.detect_image[~mask].any()
    assert exact.image[~mask].max() < THRESHOLD
    assert (exact.image[mask] >= THRESHOLD).sum() > 100  # the patches are there to be found
    assert d._full is None  # nothing made beyond the crops so far
    np.testing.assert_array_equal(d.image, exact.image)
    np.testing.assert_array_equal(d.raw_dn, exact.raw_dn)
    np.testing.assert_array_equal(d.electrons, exact.electrons)
    assert (d.exposure_s, d.iso, d.gain_dn_per_e) == (exact.exposure_s, exact.iso, exact.gain_dn_per_e)


def test_blobs_and_solution_inputs_are_the_exact_paths(small_camera):
    """The detector's blobs on the detection image equal those on the exact image (same seed)."""
    from svgs_sim.svgs.detect import detect_blobs

    _, ex = _frame(small_camera, [(60, 60, 9, 3000.0), (60, 560, 9, 3000.0), (420, 60, 9, 3000.0),
                                  (420, 560, 9, 3000.0)])
    for seed in range(3):
        a = ex.expose(seed=seed)
        b = ex.expose(seed=seed, dark_pixels="deferred", threshold_u8=THRESHOLD)
        ba, bb = detect_blobs(a.image, threshold=THRESHOLD), detect_blobs(b.detect_image, threshold=THRESHOLD)
        assert len(ba.centroid_px) == 4
        np.testing.assert_array_equal(ba.centroid_px, bb.centroid_px)
        np.testing.assert_array_equal(ba.area_px, bb.area_px)


def test_falls_back_to_the_exact_exposure(small_camera):
    """A half-bright frame, no numeric threshold, a downscaled image, a float image (no ``u8``),
    blooming that spills beyond the delivered tiles: a plain exposure, the exact path's bytes,
    and the reason."""
    from dataclasses import replace

    phone, ex = _frame(small_camera, [(100, 120, 20, 4000.0)])
    H, W = phone.shape
    sp = phone.params.sensor
    t = phone.params.exposure.exposure_s
    bright = np.full((H, W), _flux_for(3.0, sp, t), np.float32)
    bright[:, : W // 2] = _flux_for(400.0, sp, t)
    exb = Exposer(phone, bright, stages=NO_GLARE)
    for e, kw, reason in (
        (exb, {"threshold_u8": THRESHOLD}, "bright frame (fallback)"),
        (ex, {"threshold_u8": None}, "no numeric threshold"),
        (ex, {"threshold_u8": THRESHOLD, "isp": replace(phone.params.isp, output_width=W // 2, output_height=H // 2)},
         "downscaled image"),
        (ex, {"threshold_u8": THRESHOLD, "stages": tuple(s for s in NO_GLARE if s not in ("u8", "jpeg"))},
         "no 8-bit image"),
    ):
        a = e.expose(seed=2, **{k: v for k, v in kw.items() if k in ("isp", "stages")})
        b = e.expose(seed=2, dark_pixels="deferred", **kw)
        assert not isinstance(b, DeferredExposure)
        assert b.info["dark_pixels"]["path"] == "exact" and b.info["dark_pixels"]["reason"] == reason
        np.testing.assert_array_equal(a.image, b.image)
        np.testing.assert_array_equal(a.raw_dn, b.raw_dn)
    # a patch far above full well (a 99 % drain) blooms ~50 px beyond the tiles the flux marks as lit
    _, exs = _frame(small_camera, [(200, 300, 4, 5e8)])
    a = exs.expose(seed=3)
    b = exs.expose(seed=3, dark_pixels="deferred", threshold_u8=THRESHOLD)
    assert a.info["bloom"]["bloomed_px"] > 0
    assert b.info["dark_pixels"]["reason"] == "blooming beyond the lit tiles"
    np.testing.assert_array_equal(a.image, b.image)


def test_lit_crops_group_tiles_within_their_margins():
    lit = np.zeros((20, 30), bool)
    lit[2, 2] = lit[3, 4] = True  # within 2 x 2 tiles of margin of each other: one crop
    lit[15, 25] = True
    crops = sorted(lit_crops(lit, 2))
    assert crops == [((0, 6, 0, 7), (2, 4, 2, 5)), ((13, 18, 23, 28), (15, 16, 25, 26))]
    assert lit_crops(np.zeros((4, 4), bool), 2) == []


def test_a_crop_reads_the_frames_noise():
    """A crop of the charge and the readout with its origin draws the same numbers as the same
    pixels of the full frame; a readout crop must start on a multiple of 4 columns."""
    from svgs_sim.camera.phone.params import SensorParams
    from svgs_sim.camera.phone.sensor import electrons, readout

    sp = SensorParams()
    rng = np.random.default_rng(1)
    flux = rng.uniform(0, 4e5, (40, 52)).astype(np.float32)
    prnu = np.ones_like(flux)
    dsnu = np.zeros_like(flux)
    e = electrons(flux, sp, 1e-3, prnu, dsnu, 5)
    ec = electrons(flux[8:30, 16:44], sp, 1e-3, prnu[8:30, 16:44], dsnu[8:30, 16:44], 5, origin=(8, 16), full_width=52)
    np.testing.assert_array_equal(ec, e[8:30, 16:44])
    raw, _ = readout(e, sp, 100.0, 5)
    rawc, _ = readout(np.ascontiguousarray(e[8:30, 16:44]), sp, 100.0, 5, origin=(8, 16), full_width=52)
    np.testing.assert_array_equal(rawc, raw[8:30, 16:44])
    with pytest.raises(ValueError, match="multiple of 4"):
        readout(np.ascontiguousarray(e[:, 2:10]), sp, 100.0, 5, origin=(0, 2), full_width=52)


@pytest.mark.slow
@pytest.mark.render
def test_approach_sensor_default_is_the_exact_paths_measurement():
    """``ApproachSensor``'s default (``deferred``) against ``dark_pixels="exact"``, the Galaxy
    Nexus at full resolution, three frames of a stream from 12 to 5 m: the same blobs, estimate,
    bound and exposure settings; the deferred frames expose a few per cent of the frame, and the
    kept image is the exact one; ``keep_images="detector"`` keeps the same detector image and no
    delivered image. The video's picture of the pixels the detector keeps, made from
    the deferred frame's detector image (its dark tiles 0), is the picture of the exact frame's
    full image with the same black level."""
    import math

    from svgs_sim.sim.approach import ApproachSensor
    from svgs_sim.svgs.frames import pose_from_scenario
    from svgs_sim.svgs.overlay import render_overlay

    poses = [(0.5 * k, *pose_from_scenario(r, pitch_deg=2.0, yaw_deg=-3.0)) for k, r in enumerate((12.0, 8.0, 5.0))]
    a = ApproachSensor("galaxy-nexus", seed=3, dark_pixels="exact", keep_images=True)
    b = ApproachSensor("galaxy-nexus", seed=3, keep_images=True)
    c = ApproachSensor("galaxy-nexus", seed=3, keep_images="detector")  # the video's: no delivered image
    assert b.dark_pixels == "deferred"
    for (ma, mb, mc) in zip(a.stream(poses), b.stream(poses), c.stream(poses)):
        assert mc.image is None and mc.estimate == mb.estimate and mc.threshold_u8 == mb.threshold_u8
        np.testing.assert_array_equal(mc.detect_image, mb.detect_image)
        assert ma.ok and mb.ok
        np.testing.assert_array_equal(ma.blobs_px, mb.blobs_px)
        assert ma.estimate == mb.estimate and ma.crlb_std == mb.crlb_std
        assert (ma.exposure_s, ma.iso, ma.next_exposure_s) == (mb.exposure_s, mb.iso, mb.next_exposure_s)
        assert mb.threshold_u8 == ma.threshold_u8
        black = float(math.floor(mb.threshold_u8))
        assert (mb.detect_image != ma.image).mean() > 0.01  # the dark tiles' pixels are not in it
        kw = dict(blobs_px=mb.blobs_px, title="t", size_px=680, black_level=black)
        np.testing.assert_array_equal(render_overlay(mb.detect_image, **kw), render_overlay(ma.image, **kw))
        np.testing.assert_array_equal(ma.image, mb.image)
    a.close()
    b.close()
    c.close()


def test_window_tiles_are_the_nine_offsets_definition():
    """The tiles kept around the spots' point samples (:meth:`Exposer._window_tiles`, a dilation on
    a padded tile grid) against their definition: each point moved by -w, 0, +w px in u and v
    (w = DARK_WINDOW_PX), its tile clipped to the frame; points on tile edges and off the frame."""
    from svgs_sim.camera.phone import DARK_WINDOW_PX

    rng = np.random.default_rng(0)
    shape = (40, 50)
    for _ in range(100):
        n = int(rng.integers(1, 30))
        v, u = rng.uniform(-100, 16 * 40 + 100, n), rng.uniform(-100, 16 * 50 + 100, n)
        v[: n // 3] = np.round(v[: n // 3] / DARK_TILE_PX) * DARK_TILE_PX
        want = np.zeros(shape, bool)
        for du in (-DARK_WINDOW_PX, 0, DARK_WINDOW_PX):
            for dv in (-DARK_WINDOW_PX, 0, DARK_WINDOW_PX):
                i = np.clip((v + dv) // DARK_TILE_PX, 0, shape[0] - 1).astype(int)
                j = np.clip((u + du) // DARK_TILE_PX, 0, shape[1] - 1).astype(int)
                want[i, j] = True
        ex = object.__new__(Exposer)
        ex._windows = None
        ex.points = type("Points", (), {"v_px": v, "u_px": u, "__len__": lambda self: len(v)})()
        np.testing.assert_array_equal(ex._window_tiles(shape), want)
