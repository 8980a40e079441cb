"""Radiometry of the renderer against analytic values (issue 3 acceptance).

- A Lambertian plate lit by the flash has radiance rho * E / pi, E = I cos(i) / d^2.
- A single corner cube returns E = factor * I / |2V - S|^2 at the lens when the lens is
  inside the return footprint (hollow: factor 1; solid uncoated N-BK7 at normal
  incidence: T^2 / (1 - R_F) + R_F = 1), summed over the spot as radiance x pixel solid
  angle x cos; and (almost) nothing when the flash is beyond the footprint.

The test camera has the Galaxy Nexus focal length and f-number and a 96 x 96 frame; the
cube sits at the target origin and points at the flash (normal incidence: the front-face
glint and the retro return coincide, as the analytic sum assumes).
"""

import numpy as np
import pytest

from svgs_sim.render.optics import pixel_normalized_grid, pixel_solid_angle_sr
from svgs_sim.render.predict import retro_irradiance_w_m2
from svgs_sim.base.profiles import Camera, Pattern

pytestmark = pytest.mark.render

I_W_SR = 0.03  # on-axis radiant intensity of the test LED (in band)


def _camera(offset_m=0.004, size=96, cos_exponent=1.0):
    return Camera(name="test-96", width=size, height=size, fx=2450.0, fy=2450.0, cx=(size - 1) / 2, cy=(size - 1) / 2,
                  tables={"optics": {"focal_length_m": 0.00343, "f_number": 2.4, "focus_distance_m": 1.8,
                                     "band_nm": [400.0, 700.0]},
                          "flash": {"led_offsets_m": [[offset_m, 0.0, 0.0]], "emitter_diameter_m": 0.0012,
                                    "radiant_intensity_w_sr": I_W_SR, "cos_exponent": cos_exponent}})


# one cube at the origin; three dummies far outside the field (a pattern needs four points)
SINGLE = Pattern(name="single-cube", ids=np.arange(1, 5),
                 points_m=np.array([[0.0, 0.0, 0.0], [5.0, 0.0, 0.0], [0.0, 5.0, 0.0], [5.0, 5.0, -1.0]]))


def _pose_facing(point_cam, range_m):
    """Target at (0, 0, range) in the camera frame, its +z (the cube axis) towards ``point_cam``."""
    P = np.array([0.0, 0.0, range_m])
    z = np.asarray(point_cam, float) - P
    z /= np.linalg.norm(z)
    x = np.cross([0.0, 1.0, 0.0], z)
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z], 1), P


def _irradiance(res, cam):
    """sum(L * Omega_pix * cos theta) over the frame, W/m^2 at the lens."""
    xy = pixel_normalized_grid(cam)
    cos = 1.0 / np.sqrt(1.0 + (xy ** 2).sum(-1))
    return float((res.radiance.astype(np.float64) * pixel_solid_angle_sr(cam, xy) * cos).sum())


@pytest.fixture(scope="module")
def renderers():
    from svgs_sim.render.api import Renderer

    out = {}
    for kind in ("hollow", "solid"):
        out[kind] = Renderer(_camera(), SINGLE, reflector=kind, scene_options={"body": "none"}, spp=4, roi_spp=16,
                             spot_samples=1 << 17)
    return out


@pytest.mark.parametrize("kind", ["hollow", "solid"])
@pytest.mark.parametrize("range_m", [1.0, 5.0, 20.0, 40.0])
def test_single_cube_return_matches_geometric_optics(renderers, kind, range_m):
    r = renderers[kind]
    S = r.flash.led_offsets_m[0]
    R, t = _pose_facing(S, range_m)
    res = r.render(R, t, seed=3)
    E = _irradiance(res, r.camera)
    Vref = r.target.reference_m[0] @ R.T + t
    E_pred = retro_irradiance_w_m2(I_W_SR, S, Vref, r.reflector)
    # the truth record carries the same prediction, in photons/s
    ph = res.truth["radiometry"]["retro_photons_per_s_predicted"]["1"]
    # (it includes the LED's cos profile towards the cube: 4 mm / range off its axis)
    assert ph == pytest.approx(E_pred * r.optics.aperture_area_m2 / r.flash.photometry["mean_photon_energy_j"], rel=1e-4)
    tol = K_SIGMA * _guided_rel_sigma(res, r)
    assert E / E_pred == pytest.approx(1.0, abs=tol), f"{kind} at {range_m} m: ratio {E / E_pred:.4f}, tol {tol:.4f}"


#: Monte Carlo bounds are taken at this many standard errors (fixed seeds: a genuine
#: disagreement beyond 4 sigma is a bug, not bad luck; two-sided 6e-5 per case).
K_SIGMA = 4.0


def _guided_rel_sigma(res, r):
    """Relative standard error of the retro spot's irradiance from the guided estimator.

    Each of the N samples of the retro strategy lands uniformly in a disk of radius rho
    (px) around the LED's image and scores a constant (L0 cos^(m-1), m = 1) when it hits
    the LED image, a disk of radius r_img = f_px r_led / |X - C| (virtual source X at
    2V - S): a binomial with p = (r_img / rho)^2, sigma_rel = sqrt((1 - p) / (N p)). For
    the solid cube the front-face and second-surface strategies overlap the retro one at
    normal incidence (3N samples, balance heuristic), which only lowers it. Measured
    seed-to-seed scatter (hollow, 40 seeds): 0.23 % at 1 m, 0.48 % at 40 m; this gives
    0.225 % and 0.47 %."""
    st = next(s for s in res.truth["render"]["spot_strategies"] if s["label"] == "cube0:led0:retro")
    r_led = r.flash.emitter_diameter_m / 2
    r_img = max(r.camera.fx, r.camera.fy) * r_led / np.linalg.norm(st["source_cam_m"])
    p = (r_img / st["radius_px"]) ** 2
    return float(np.sqrt((1 - p) / (st["samples"] * p)))


@pytest.mark.parametrize("range_m", [1.0, 40.0])
def test_no_return_when_the_flash_is_beyond_the_footprint(range_m):
    from svgs_sim.render.api import Renderer

    # LED 16 mm from the lens: the footprint (radius ~ cube diameter 12.7 mm, centred on
    # the LED) no longer covers the lens
    r = Renderer(_camera(offset_m=0.016), SINGLE, reflector="solid", scene_options={"body": "none"}, spp=4, roi_spp=16,
                 spot_samples=1 << 15)
    S = r.flash.led_offsets_m[0]
    R, t = _pose_facing(S, range_m)
    res = r.render(R, t, seed=1)
    E_pred = retro_irradiance_w_m2(I_W_SR, S, r.target.reference_m[0] @ R.T + t, r.reflector)
    assert _irradiance(res, r.camera) < 0.01 * E_pred


def test_brute_force_path_tracing_agrees_at_1m():
    """The reference: the LED as a disk area emitter, everything path traced."""
    from svgs_sim.render.api import Renderer

    r = Renderer(_camera(), SINGLE, reflector="hollow", scene_options={"body": "none"}, spp=4, roi_spp=1024,
                 method="path")
    S = r.flash.led_offsets_m[0]
    R, t = _pose_facing(S, 1.0)
    res = r.render(R, t, seed=2)
    E_pred = retro_irradiance_w_m2(I_W_SR, S, r.target.reference_m[0] @ R.T + t, r.reflector)
    # Tolerance left at 3 %: the i.i.d. bound (Poisson hits, n = roi_spp pi r_img^2 = 1740 at
    # r_img = 0.735 px) is 1 / sqrt(n) = 2.4 %, but the ldsampler's stratification cuts the
    # seed-to-seed scatter to 0.57 % (12 seeds), so 3 % is 5.3 of its measured sigmas.
    assert _irradiance(res, r.camera) / E_pred == pytest.approx(1.0, abs=0.03)


@pytest.mark.parametrize("range_m", [1.0, 3.0])
def test_lambertian_plate_radiance(range_m):
    from svgs_sim.render.api import Renderer
    from svgs_sim.render.geometry import box_mesh

    rho = 0.5
    plate = box_mesh("plate", [-0.3, -0.3, -0.02], [0.3, 0.3, 0.0], "body")
    # cubes far outside the field; the plate's front face is the plane z = 0 of the target
    far = Pattern(name="far", ids=np.arange(1, 5),
                  points_m=np.array([[3.0, 3.0, 0.05], [4.0, 3.0, 0.05], [3.0, 4.0, 0.05], [4.0, 4.0, 0.1]]))
    cam = _camera(offset_m=0.008, cos_exponent=1.0)
    r = Renderer(cam, far, scene_options={"body": "none", "body_reflectance": rho}, spp=16, roi_spp=4,
                 spot_samples=1024, extra_meshes=[plate])
    # the plate square to the boresight, target origin on the axis
    R = np.diag([1.0, -1.0, -1.0])
    t = np.array([0.0, 0.0, range_m])
    res = r.render(R, t, seed=5, check_fov=False)
    # analytic radiance at each pixel of a central patch: the plate point seen by the
    # pixel's chief ray, lit by the LED (Lambertian: I(theta) = I0 cos theta)
    c = cam.width // 2
    sl = (slice(c - 8, c + 8), slice(c - 8, c + 8))
    xy = pixel_normalized_grid(cam)[sl]
    P = np.concatenate([xy * range_m, np.full(xy.shape[:2] + (1,), range_m)], -1)  # z_cam = range on the plate
    S = r.flash.led_offsets_m[0]
    d = P - S
    dist = np.linalg.norm(d, axis=-1)
    cos_led = d[..., 2] / dist  # LED axis = +z_cam
    cos_inc = d[..., 2] / dist  # plate normal = -z_cam
    E = I_W_SR * cos_led * cos_inc / dist ** 2
    L_pred = rho * E / np.pi
    # The guided method's point light carries the profile I0 cos^m evaluated once towards the
    # target origin (docs/renderer.md): its documented approximation, cos(t0) / cos(t) - 1
    # per pixel (<= 3.5e-5 here), is taken out of the comparison rather than tolerated.
    O = np.array([0.0, 0.0, range_m]) - S
    approx = (O[2] / np.linalg.norm(O)) / cos_led
    L = res.radiance.astype(np.float64)[sl]
    # Derived per-pixel bound. Monte Carlo: L varies across a pixel's footprint on the plate
    # with |grad ln L| <= 4 |s| / z^2 (s: LED offset); the footprint is the pixel box
    # (width z / f_px, variance w^2 / 12) and the defocus disk of the aperture (radius
    # a |1 - z / z_f|, variance R^2 / 4): sigma_sample <= |grad ln L| sd, sigma_pixel =
    # sigma_sample / sqrt(spp). Floating point: single-precision rendering, a 16-ulp budget.
    spp = r.spp
    a_m = r.optics.aperture_radius_m
    w_m = range_m / cam.fx
    defocus_m = a_m * abs(1 - range_m / r.optics.focus_distance_m)
    sd_m = np.sqrt(w_m ** 2 / 12 + defocus_m ** 2 / 4)
    sigma_pixel = 4 * np.hypot(*S[:2]) / range_m ** 2 * sd_m / np.sqrt(spp)  # 1.6e-6 at 1 m
    fp32 = 16 * np.finfo(np.float32).eps  # 1.9e-6
    tol = K_SIGMA * sigma_pixel + fp32
    assert np.abs(L / (L_pred * approx) - 1).max() < tol  # was 1 %; measured 5.6e-7
    assert L.mean() / (L_pred * approx).mean() == pytest.approx(1.0, abs=K_SIGMA * sigma_pixel / 16 + fp32)
    assert np.abs(L / L_pred - 1).max() < np.abs(approx - 1).max() + tol  # the physics, within the approximation
