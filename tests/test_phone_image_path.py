"""The phone's image path (issue 24): JPEG with its chroma sampling and block grid, the demosaic
variants, noise reduction and sharpening, each against an independent implementation (Pillow's
libjpeg, OpenCV called directly, scikit-image), and their switches in the error budget."""

import dataclasses
import io

import cv2
import numpy as np
import pytest
from PIL import Image
from scipy.special import erf

from svgs_sim.camera.phone import ALL_STAGES, Exposer, PhoneCamera
from svgs_sim.camera.phone.cfa import linear_bgr
from svgs_sim.camera.phone.isp import jpeg_roundtrip, noise_reduction, unsharp_mask
from svgs_sim.camera.phone.params import CfaParams, IspParams
from svgs_sim.svgs import Camera, InputError


def small_camera(w=96, h=80, **tables):
    return Camera(name="test", width=w, height=h, fx=300.0, fy=300.0, cx=(w - 1) / 2, cy=(h - 1) / 2, tables=tables)


def pillow_roundtrip(image_rgb_or_grey: np.ndarray, quality: int, subsampling: int | None = None) -> np.ndarray:
    """Pillow's JPEG encode and decode (its own libjpeg binding): the reference."""
    buf = io.BytesIO()
    kw = {"format": "JPEG", "quality": int(quality)}
    if subsampling is not None:
        kw["subsampling"] = subsampling
    Image.fromarray(image_rgb_or_grey).save(buf, **kw)
    return np.asarray(Image.open(io.BytesIO(buf.getvalue())))


def smooth_scene(shape, seed, colour=False):
    """A smooth random scene with some edges, uint8 (what a JPEG codes without extreme ringing)."""
    rng = np.random.default_rng(seed)
    H, W = shape
    y, x = np.mgrid[0:H, 0:W]
    planes = []
    for _ in range(3 if colour else 1):
        a = rng.uniform(0.02, 0.2, 4)
        p = 128 + 60 * np.sin(a[0] * x + a[1] * y) + 40 * np.cos(a[2] * x - a[3] * y)
        p += np.where((x - W / 2) ** 2 + (y - H / 2) ** 2 < (min(H, W) / 5) ** 2, 50, 0)
        planes.append(np.clip(p + rng.normal(0, 4, (H, W)), 0, 255).astype(np.uint8))
    return np.stack(planes, -1) if colour else planes[0]


# ------------------------------------------------------------------ JPEG against Pillow
@pytest.mark.parametrize("quality", [85, 90, 95])
def test_grey_jpeg_equals_pillows(quality):
    img = smooth_scene((72, 88), quality)
    ours = jpeg_roundtrip(img, quality, "gray")
    ref = pillow_roundtrip(img, quality)
    assert ours.shape == img.shape and ours.dtype == np.uint8
    assert np.abs(ours.astype(int) - ref.astype(int)).max() <= 1
    assert np.abs(ours.astype(int) - img.astype(int)).max() > 0  # it is lossy


@pytest.mark.parametrize("sub, pil_sub", [("4:2:0", 2), ("4:4:4", 0)])
def test_colour_jpeg_equals_pillows_at_the_same_chroma_sampling(sub, pil_sub):
    bgr = smooth_scene((64, 80), 7, colour=True)
    ours = jpeg_roundtrip(bgr, 90, sub)
    ref = pillow_roundtrip(np.ascontiguousarray(bgr[..., ::-1]), 90, pil_sub)[..., ::-1]  # Pillow is RGB
    assert ours.shape == bgr.shape
    assert np.abs(ours.astype(int) - ref.astype(int)).max() <= 2
    assert np.mean(ours != ref) < 0.05


def test_chroma_subsampling_changes_the_colours_and_not_a_grey_scene():
    """4:2:0 halves the chroma's resolution: a coloured scene's decoded colours differ from the
    4:4:4 coding's; a neutral one (no chroma) decodes the same."""
    bgr = smooth_scene((64, 64), 3, colour=True)
    a, b = jpeg_roundtrip(bgr, 90, "4:2:0"), jpeg_roundtrip(bgr, 90, "4:4:4")
    assert np.mean(np.abs(a.astype(int) - b.astype(int))) > 0.5
    grey = np.repeat(smooth_scene((64, 64), 4)[..., None], 3, axis=2)
    a, b = jpeg_roundtrip(grey, 90, "4:2:0"), jpeg_roundtrip(grey, 90, "4:4:4")
    assert np.abs(a.astype(int) - b.astype(int)).max() <= 1


@pytest.mark.parametrize("offset", [(3, 0), (0, 5), (4, 4), (13, 9)])
def test_block_grid_offset_is_a_pillow_round_trip_of_the_padded_picture(offset):
    """Image pixel (u, v) coded at (u + x, v + y) of the grid: Pillow coding the picture padded
    by x columns and y rows (edge replicated), cropped back."""
    ox, oy = offset
    bgr = smooth_scene((48, 56), 11, colour=True)
    ours = jpeg_roundtrip(bgr, 90, "4:2:0", grid_offset_px=offset)
    padded = np.pad(bgr, ((oy, 0), (ox, 0), (0, 0)), mode="edge")
    ref = pillow_roundtrip(np.ascontiguousarray(padded[..., ::-1]), 90, 2)[oy:, ox:, ::-1]
    assert np.abs(ours.astype(int) - ref.astype(int)).max() <= 2


def spot_image(x0, y0, shape=(48, 48), sigma_px=0.8, peak=230.0, background=12.0):
    """A Gaussian spot integrated over the pixels (erf), centre (x0, y0) in OpenCV's
    pixel-centre convention, uint8 (what the app thresholds: a compact bright spot)."""
    H, W = shape
    xe, ye = np.arange(W + 1) - 0.5, np.arange(H + 1) - 0.5
    s = np.sqrt(2) * sigma_px
    fx = np.diff(0.5 * erf((xe - x0) / s))
    fy = np.diff(0.5 * erf((ye - y0) / s))
    img = background + peak * 2 * np.pi * sigma_px**2 * np.outer(fy, fx)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def centroid_x(img, background=12.0):
    """Intensity-weighted centroid (x) above the background."""
    w = np.clip(img.astype(float) - background, 0, None)
    return float((w.sum(axis=0) * np.arange(img.shape[1])).sum() / w.sum())


def test_block_phase_moves_a_spot_centroid_as_pillows_jpeg_does():
    """A spot stepped across one 8-px block in quarter pixels: the JPEG's centroid error (decoded
    minus coded, px) follows the block phase exactly as Pillow's coding does, repeats every 8 px,
    and a block grid moved by k pixels is the spot moved by k pixels."""
    shifts = np.arange(0.0, 8.0, 0.25)
    ours, ref = [], []
    for s in shifts:
        img = spot_image(20.0 + s, 23.3)
        c0 = centroid_x(img)
        ours.append(centroid_x(jpeg_roundtrip(img, 90, "gray")) - c0)
        ref.append(centroid_x(pillow_roundtrip(img, 90)) - c0)
    ours, ref = np.array(ours), np.array(ref)
    np.testing.assert_allclose(ours, ref, atol=2e-3)
    assert np.ptp(ours) > 5e-3  # the phase matters: the error is not a constant
    # the same phase one block over
    again = [centroid_x(jpeg_roundtrip(spot_image(28.0 + s, 23.3), 90, "gray")) - centroid_x(spot_image(28.0 + s, 23.3))
             for s in shifts[:6]]
    np.testing.assert_allclose(again, ours[:6], atol=1e-9)
    # moving the grid by 3 px equals moving the spot by 3 px: the spot at 23.25 coded at 26.25
    img = spot_image(23.25, 23.3)
    moved = jpeg_roundtrip(img, 90, "gray", grid_offset_px=(3, 0))
    c = centroid_x(moved) - centroid_x(img)
    k = int(np.argmin(np.abs(shifts - (20.0 + 6.25 - 20.0))))  # coded at 26.25: the phase of the spot at 26.25
    assert c == pytest.approx(ours[k], abs=1e-9)


@pytest.mark.parametrize("sub", ["gray", "4:4:4", "4:2:0"])
@pytest.mark.parametrize("rows, offset", [(1944, (0, 0)), (1001, (0, 0)), (777, (5, 11))])
def test_a_tall_image_coded_in_bands_is_the_whole_image_coded_at_once(sub, rows, offset):
    """Issue 40: an image of :data:`JPEG_BAND_MIN_ROWS` rows or more is coded in two bands on two
    threads; the result is OpenCV's libjpeg round trip of the whole (padded) picture, to the byte."""
    from svgs_sim.camera.phone.isp import JPEG_BAND_MIN_ROWS, _jpeg_strips

    assert rows >= JPEG_BAND_MIN_ROWS
    img = smooth_scene((rows, 600), 7, colour=sub != "gray")
    img[300:320, 200:230] = 255  # a spot across the cut of the bands' neighbourhood
    img[rows // 2 - 20:rows // 2 + 20, 100:140] = 250
    ox, oy = offset
    padded = cv2.copyMakeBorder(img, oy, 0, ox, 0, cv2.BORDER_REPLICATE)
    params = [cv2.IMWRITE_JPEG_QUALITY, 90]
    if sub == "4:4:4":
        params += [cv2.IMWRITE_JPEG_SAMPLING_FACTOR, cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444]
    elif sub == "4:2:0":
        params += [cv2.IMWRITE_JPEG_SAMPLING_FACTOR, cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420]
    ok, buf = cv2.imencode(".jpg", padded, params)
    ref = cv2.imdecode(buf, cv2.IMREAD_UNCHANGED if sub == "gray" else cv2.IMREAD_COLOR)[oy:, ox:]
    ours = jpeg_roundtrip(img, 90, sub, grid_offset_px=offset)
    assert _jpeg_strips(padded.shape[0]) == 2 and ours.shape == img.shape
    assert np.array_equal(ours, ref)


def test_jpeg_inputs_are_checked_before_work():
    img = np.zeros((16, 16), np.uint8)
    with pytest.raises(InputError, match="quality"):
        jpeg_roundtrip(img, 0)
    with pytest.raises(InputError, match="quality"):
        jpeg_roundtrip(img, 90.5)
    with pytest.raises(InputError, match="subsampling"):
        jpeg_roundtrip(img, 90, "4:1:1")
    with pytest.raises(InputError, match="grid_offset_px"):
        jpeg_roundtrip(img, 90, "gray", grid_offset_px=(16, 0))
    with pytest.raises(InputError, match="shape"):
        jpeg_roundtrip(img, 90, "4:2:0")
    with pytest.raises(InputError, match="uint8"):
        jpeg_roundtrip(img.astype(np.float32), 90)


# ------------------------------------------------------------------ demosaic against OpenCV
@pytest.mark.parametrize("method, suffix", [("bilinear", ""), ("edge_aware", "_EA"), ("vng", "_VNG")])
def test_demosaic_variants_are_opencvs_on_the_same_mosaic(method, suffix):
    """The ISP's white-balanced linear colour from a random RGGB mosaic, against OpenCV's
    ``COLOR_BayerBG2BGR*`` called directly (OpenCV names RGGB by its second row: BG) with the
    black level and white balance applied by hand."""
    rng = np.random.default_rng(5)
    black, white = 64.0, 1023.0
    raw = rng.integers(64, 1024, (40, 52)).astype(np.float32)
    cfa = CfaParams(pattern="RGGB", response=(0.5, 1.0, 0.6))
    ours = linear_bgr(raw, cfa, black, white, method)
    code = getattr(cv2, f"COLOR_BayerBG2BGR{suffix}")
    r16 = raw.astype(np.uint16)
    if method == "vng":  # 8-bit only: the top 8 of 10 bits, scaled back
        bgr = cv2.cvtColor((r16 >> 2).astype(np.uint8), code).astype(np.float64) * 4
    else:
        bgr = cv2.cvtColor(r16, code).astype(np.float64)
    ref = np.clip((bgr - black) / ((white - black) * np.array([0.6, 1.0, 0.5])), 0, 1)
    np.testing.assert_allclose(ours, ref, atol=1e-6)


def test_the_exposures_demosaic_is_chosen_per_exposure():
    """``expose(demosaic=...)`` changes the image as OpenCV's method does, on the same raw."""
    cam = small_camera(cfa={"pattern": "RGGB"})
    phone = PhoneCamera(cam)
    rng = np.random.default_rng(2)
    flux = rng.uniform(0, 4e5, phone.shape).astype(np.float32)
    ex = Exposer(phone, flux, stages=("cfa", "shot", "read", "adc", "tone"))
    st = ("cfa", "shot", "read", "adc", "tone")
    a = ex.expose(seed=1, exposure_s=0.01, iso=100, stages=st)
    b = ex.expose(seed=1, exposure_s=0.01, iso=100, stages=st, demosaic="edge_aware")
    np.testing.assert_array_equal(a.raw_dn, b.raw_dn)
    sp = phone.params.sensor
    r16 = b.raw_dn.astype(np.uint16)
    for img, code in ((a.image, cv2.COLOR_BayerBG2BGR), (b.image, cv2.COLOR_BayerBG2BGR_EA)):
        bgr = cv2.cvtColor(r16, code).astype(np.float64)
        lin = np.clip((bgr - sp.black_level_dn) / ((sp.white_dn - sp.black_level_dn) * np.array([0.6, 1.0, 0.5])), 0, 1)
        y = lin @ np.array([0.114, 0.587, 0.299])
        ref = 255 * y ** (1 / 2.2)
        assert np.abs(img - ref).max() <= 1.0 + 1e-6
    assert b.info["demosaic"] == "edge_aware" and np.any(a.image != b.image)
    with pytest.raises(InputError, match="demosaic"):
        ex.expose(seed=1, demosaic="ahd")


# ------------------------------------------------------------------ noise reduction and sharpening
def test_gaussian_noise_reduction_is_scikit_images_gaussian():
    from skimage.filters import gaussian

    img = np.random.default_rng(1).uniform(0, 1, (40, 50)).astype(np.float32)
    for sigma in (0.5, 0.8, 1.5):
        ref = gaussian(img.astype(np.float64), sigma=sigma, mode="nearest", truncate=4.0, preserve_range=True)
        np.testing.assert_allclose(noise_reduction(img, sigma), ref, atol=2e-3)


def bilateral_reference(img, sigma_px, range_sigma):
    """The bilateral filter from its definition (Tomasi & Manduchi 1998): each pixel the mean of
    its neighbours within ``ceil(4 sigma)`` (a disk, edges replicated), weighted by
    ``exp(-r^2 / 2 sigma^2) exp(-(I - I_0)^2 / 2 range_sigma^2)``."""
    R = int(np.ceil(4 * sigma_px))
    H, W = img.shape
    p = np.pad(img.astype(np.float64), R, mode="edge")
    num = np.zeros((H, W))
    den = np.zeros((H, W))
    for di in range(-R, R + 1):
        for dj in range(-R, R + 1):
            if di * di + dj * dj > R * R:
                continue
            v = p[R + di:R + di + H, R + dj:R + dj + W]
            w = np.exp(-(di * di + dj * dj) / (2 * sigma_px**2)) * np.exp(-((v - img) ** 2) / (2 * range_sigma**2))
            num += w * v
            den += w
    return num / den


def test_bilateral_noise_reduction_is_the_bilateral_filter():
    """Against the filter's definition written out here (scikit-image's ``denoise_bilateral``
    weighs the range differently: it departs from the definition by up to 0.06 on this image)."""
    rng = np.random.default_rng(3)
    img = np.where(np.arange(48)[None, :] < 24, 0.2, 0.8) + rng.normal(0, 0.03, (40, 48))
    img = np.clip(img, 0, 1).astype(np.float32)
    for sigma, rs in ((1.0, 0.1), (0.7, 0.05)):
        ours = noise_reduction(img, sigma, rs)
        np.testing.assert_allclose(ours, bilateral_reference(img, sigma, rs), atol=1e-4)
    ours = noise_reduction(img, 1.0, 0.1)
    assert np.std(ours[:, 2:20]) < 0.5 * np.std(img[:, 2:20])  # it smooths the flat region
    assert abs(ours[20, 22] - ours[20, 25]) > 0.5  # and keeps the edge
    with pytest.raises(InputError, match="sigma_px"):
        noise_reduction(img, 0.0)
    with pytest.raises(InputError, match="range_sigma"):
        noise_reduction(img, 1.0, -0.1)


def test_sharpening_is_scikit_images_unsharp_mask():
    from skimage.filters import unsharp_mask as sk_unsharp

    img = spot_image(20.3, 18.6, shape=(40, 40)).astype(np.float32)
    for amount, sigma in ((0.5, 1.0), (1.0, 1.5)):
        ref = sk_unsharp(img.astype(np.float64), radius=sigma, amount=amount, preserve_range=True)
        inner = (slice(8, -8), slice(8, -8))
        np.testing.assert_allclose(unsharp_mask(img, amount, sigma)[inner], ref[inner], atol=0.05)


def test_the_isp_stages_act_where_the_profile_turns_them_on():
    """Mono sensor, no noise, float output: the image is skimage's unsharp mask of the toned
    image, and noise reduction is skimage's Gaussian of the linear image before the tone curve;
    with the stage switched off, the image is the plain tone curve."""
    from skimage.filters import gaussian
    from skimage.filters import unsharp_mask as sk_unsharp

    cam = small_camera(isp={"sharpen_amount": 0.8, "sharpen_sigma_px": 1.0, "nr_sigma_px": 0.7})
    phone = PhoneCamera(cam)
    sp = phone.params.sensor
    flux = np.full(phone.shape, 2e4, np.float32)
    flux[30:34, 40:45] = 4e5
    ex = Exposer(phone, flux, stages=("adc", "tone"))
    kw = {"exposure_s": 0.01, "iso": 100}
    plain = ex.expose(stages=("adc", "tone"), **kw)
    lin = np.clip((plain.raw_dn - sp.black_level_dn) / (sp.white_dn - sp.black_level_dn), 0, 1)
    np.testing.assert_allclose(plain.image, 255 * lin ** (1 / 2.2), atol=0.5 + 1e-6)  # 8-bit rounding
    sharp = ex.expose(stages=("adc", "tone", "sharpen", "u8"), **kw).image
    ref = np.clip(sk_unsharp(255 * lin ** (1 / 2.2), radius=1.0, amount=0.8, preserve_range=True), 0, 255)
    inner = (slice(6, -6), slice(6, -6))
    assert np.abs(sharp[inner] - ref[inner]).max() <= 0.5 + 0.05
    smooth = ex.expose(stages=("adc", "nr", "tone", "u8"), **kw).image
    ref = 255 * np.clip(gaussian(lin, sigma=0.7, mode="nearest", truncate=4.0, preserve_range=True), 0, 1) ** (1 / 2.2)
    assert np.abs(smooth[inner] - ref[inner]).max() <= 0.5 + 0.05


def test_colour_output_of_a_white_scene_is_the_luminance_output():
    """A colour JPEG's luma and the one-plane JPEG agree where the scene is neutral (the flash's
    white light after white balance): the chroma carries nothing."""
    cam = small_camera(cfa={"pattern": "RGGB"}, isp={"jpeg_quality": 90})
    phone = PhoneCamera(cam)
    sp = phone.params.sensor
    y, x = np.mgrid[0:phone.shape[0], 0:phone.shape[1]]
    level = 0.1 + 0.5 * np.exp(-((x - 40.3) ** 2 + (y - 30.7) ** 2) / 60.0)
    flux = (level * sp.full_well_e / (sp.qe * 0.01)).astype(np.float32)
    st = ("cfa", "adc", "tone", "u8", "chroma", "jpeg")
    ex = Exposer(phone, flux, stages=st)
    grey = ex.expose(exposure_s=0.01, iso=sp.base_iso).image
    isp = dataclasses.replace(phone.params.isp, jpeg_subsampling="4:2:0")
    colour = ex.expose(exposure_s=0.01, iso=sp.base_iso, isp=isp).image
    assert colour.dtype == np.uint8 and colour.shape == grey.shape
    assert np.abs(colour.astype(int) - grey.astype(int)).max() <= 2
    no_chroma = ex.expose(exposure_s=0.01, iso=sp.base_iso, isp=isp, stages=tuple(s for s in st if s != "chroma")).image
    assert np.abs(colour.astype(int) - no_chroma.astype(int)).max() <= 1
    with pytest.raises(InputError, match="isp"):
        ex.expose(isp={"jpeg_quality": 90})


def test_new_stages_are_known_and_off_where_the_profile_leaves_them_off():
    for s in ("nr", "sharpen", "chroma", "jpeg"):
        assert s in ALL_STAGES
    isp = IspParams()
    assert isp.nr_sigma_px == 0 and isp.sharpen_amount == 0 and isp.jpeg_subsampling == "gray"
    for name in ("galaxy-nexus", "htc-amaze-4g"):
        p = PhoneCamera(name).params.isp
        # the sourced coding: a colour JPEG at 4:2:0 (the dataclass' own default stays the luminance alone)
        assert p.jpeg_subsampling == "4:2:0" and p.jpeg_quality == 90 and p.jpeg_grid_offset_px == (0, 0)
        assert p.nr_sigma_px == 0 and p.sharpen_amount == 0


def test_the_preview_stream_is_read_as_its_y_plane_not_a_jpeg():
    """A preview frame is the ISP's YCbCr 4:2:0 handed to the app: the binned preview camera has
    no JPEG and keeps the colour output (its luma is the Y plane)."""
    from svgs_sim.camera.phone.preview import binned_camera

    isp = PhoneCamera(binned_camera("galaxy-nexus")).params.isp
    # no JPEG; the Y plane as the stills' ISP makes it (the profile's jpeg_subsampling)
    assert isp.jpeg_quality == 0
    assert isp.jpeg_subsampling == PhoneCamera("galaxy-nexus").params.isp.jpeg_subsampling
    assert PhoneCamera("galaxy-nexus").params.isp.jpeg_quality == 90  # the stills keep theirs


# ------------------------------------------------------------------ switches and the error budget
def test_render_trial_switches_map_onto_the_stages():
    from svgs_sim.sim.render_trial import exposure_stages, render_trial_scenario

    sc = render_trial_scenario(camera="galaxy-nexus")
    assert exposure_stages(sc) == ALL_STAGES
    for k in ("cfa", "nr", "sharpen", "chroma", "jpeg"):
        off = render_trial_scenario(camera="galaxy-nexus", **{k: 0})
        assert exposure_stages(off) == tuple(s for s in ALL_STAGES if s != k)
    assert "u8" not in exposure_stages(render_trial_scenario(camera="galaxy-nexus", quantise=0))
    for bad in ({"jpeg_quality": 0}, {"demosaic": 1.5}, {"jpeg_grid_offset_u_px": 16}, {"chroma": 0.5}):
        with pytest.raises(InputError, match=next(iter(bad))):
            render_trial_scenario(camera="galaxy-nexus", **bad)


def test_render_trial_isp_choices():
    from svgs_sim.sim.render_trial import exposure_isp, render_trial_scenario

    class _Ex:  # what _isp reads of an exposer
        phone = PhoneCamera("galaxy-nexus")

    isp, dem = exposure_isp(_Ex, render_trial_scenario(camera="galaxy-nexus"))
    assert isp is _Ex.phone.params.isp and dem is None
    isp, dem = exposure_isp(_Ex, render_trial_scenario(camera="galaxy-nexus", jpeg_quality=95, demosaic=3,
                                                jpeg_grid_offset_u_px=5, jpeg_grid_offset_v_px=12))
    assert isp.jpeg_quality == 95 and isp.jpeg_grid_offset_px == (5, 12) and dem == "vng"


def test_error_budget_variants_of_the_image_path():
    from svgs_sim.studies.error_budget import SOURCE_IDS, SOURCE_LABELS, VARIANT_NAMES, VARIANTS, applicable_variants

    # the earlier variants keep their places (their trial ids)
    assert VARIANT_NAMES[:6] == ("perfect_calibration", "no_sensor_noise", "no_glare", "no_quantisation",
                                 "no_misalignment", "all_removed")
    by = {v.name: v for v in VARIANTS}
    assert by["no_jpeg"].values == {"jpeg": 0.0} and by["no_chroma_subsampling"].values == {"chroma": 0.0}
    assert by["no_cfa"].values == {"cfa": 0.0}
    floor = by["all_removed"].values
    assert floor["cfa"] == floor["nr"] == floor["sharpen"] == floor["quantise"] == 0.0
    for n in VARIANT_NAMES:
        assert n in SOURCE_IDS and (n in SOURCE_LABELS or n == "all_removed")
    # a phone on the luminance JPEG alone, no NR, no sharpening: the budget before issue 24
    from svgs_sim.studies.error_budget import image_path_on

    image_vars = {"no_jpeg", "no_chroma_subsampling", "no_cfa", "no_noise_reduction", "no_sharpening"}
    cam = Camera.load("galaxy-nexus")
    tables = {k: dict(v) if isinstance(v, dict) else v for k, v in cam.tables.items()}
    tables["isp"]["jpeg_subsampling"] = "gray"
    grey = cam.replace(tables=tables)
    assert not image_path_on(PhoneCamera(grey).params)
    assert not {v.name for v in applicable_variants(grey)} & image_vars
    # the profiles (the sourced colour JPEG at 4:2:0): the image path's stages are variants of their own
    for name in ("galaxy-nexus", "htc-amaze-4g"):
        assert image_path_on(PhoneCamera(name).params)
        ran = {v.name for v in applicable_variants(name)}
        assert {"no_jpeg", "no_chroma_subsampling", "no_cfa"} <= ran
    assert not ran & {"no_noise_reduction", "no_sharpening"}  # the profile leaves them off: nothing to remove
