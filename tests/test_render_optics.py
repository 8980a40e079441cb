"""Profiles, photometry, cube geometry and geometric-optics predictions (numpy only, fast)."""

import numpy as np
import pytest

from svgs_sim.render.constants import CIE_V, CIE_V_WAVELENGTH_NM, nbk7_index
from svgs_sim.render.geometry import Reflector, SceneOptions, box_mesh, build_target, corner_cube_meshes, cube_triad
from svgs_sim.render.optics import Flash, Optics, photometry, pixel_solid_angle_sr, radiance_to_photon_rate
from svgs_sim.render.predict import (
    binned_spot,
    fresnel_normal,
    retro_factor,
    retro_pass_factor,
    spot_direction_cam,
    virtual_source_cam,
)
from svgs_sim.base.errors import InputError, ProfileError
from svgs_sim.base.profiles import Camera, Pattern


def test_nbk7_index_matches_schott_datasheet():
    # SCHOTT N-BK7: n_d (587.56 nm) = 1.5168, n_F (486.13) = 1.5224, n_C (656.27) = 1.5143
    assert nbk7_index(587.56) == pytest.approx(1.5168, abs=1e-4)
    assert nbk7_index(486.13) == pytest.approx(1.5224, abs=1e-4)
    assert nbk7_index(656.27) == pytest.approx(1.5143, abs=1e-4)


def test_cie_v_table_peaks_at_555():
    assert CIE_V_WAVELENGTH_NM[np.argmax(CIE_V)] in (550.0, 560.0)
    assert CIE_V.max() == pytest.approx(0.995, abs=1e-3)


def test_photometry_of_monochromatic_555_is_683_lm_per_w(monkeypatch):
    import svgs_sim.render.optics as ro

    monkeypatch.setitem(ro.SPECTRA, "narrow555", ((555.0, 0.5, 1.0),))
    ph = photometry("narrow555", (400.0, 700.0))
    assert ph["luminous_efficacy_lm_per_w"] == pytest.approx(683.0 * 1.0, rel=0.01)
    assert ph["mean_photon_energy_j"] == pytest.approx(6.62607015e-34 * 299792458.0 / 555e-9, rel=1e-4)


def test_white_led_photometry_is_plausible():
    ph = photometry("white-led", (400.0, 700.0))
    # phosphor white LEDs: 250-350 lm/W of radiation; photons mostly green-yellow
    assert 250 < ph["luminous_efficacy_lm_per_w"] < 360
    assert 0.95 < ph["band_fraction"] <= 1.0
    assert 500 < ph["mean_wavelength_nm"] < 570


@pytest.mark.parametrize("name", ["galaxy-nexus", "htc-amaze-4g"])
def test_profiles_have_consistent_optics_and_flash(name):
    cam = Camera.load(name, fitted=False)  # a model test: the physical profile, no fitted values
    opt = Optics.from_camera(cam)
    fl = Flash.from_camera(cam, opt.band_nm)
    # focal length in pixels = f / pitch, as the intrinsics were derived
    assert cam.fx == pytest.approx(opt.focal_length_m / opt.pixel_pitch_m, rel=2e-3)
    # the lens must lie inside the cube return footprint (offset < cube diameter)
    assert np.all(np.hypot(fl.led_offsets_m[:, 0], fl.led_offsets_m[:, 1]) + opt.aperture_radius_m < 0.0127)
    # cd -> W/sr through the stated spectrum
    assert fl.radiant_intensity_w_sr == pytest.approx(
        fl.luminous_intensity_cd / fl.photometry["luminous_efficacy_lm_per_w"] * fl.photometry["band_fraction"])
    # every new number has a [sources] line
    src = cam.tables["sources"]
    for key in ("optics_f_number", "optics_focus_distance_m", "flash_led_offsets_m", "flash_luminous_intensity_cd",
                "flash_emitter_diameter_m", "flash_cos_exponent", "flash_spectrum"):
        assert key in src


def _cam(**tables):
    return Camera(name="t", width=64, height=48, fx=100.0, fy=100.0, cx=31.5, cy=23.5, tables=tables)


def test_missing_flash_table_is_a_clear_error():
    cam = _cam(optics={"focal_length_m": 0.003, "f_number": 2.0, "focus_distance_m": 2.0})
    with pytest.raises(ProfileError, match=r"no \[flash\] table"):
        Flash.from_camera(cam, (400, 700))
    with pytest.raises(ProfileError, match=r"no \[optics\] table"):
        Optics.from_camera(_cam())


@pytest.mark.parametrize(
    "flash, msg",
    [
        ({"emitter_diameter_m": 0.001, "radiant_intensity_w_sr": 1.0}, "led_offsets_m"),
        ({"led_offsets_m": [0.01, 0, 0], "emitter_diameter_m": -1.0, "radiant_intensity_w_sr": 1.0}, "emitter_diameter_m"),
        ({"led_offsets_m": [0.0001, 0, 0], "emitter_diameter_m": 0.001, "radiant_intensity_w_sr": 1.0}, "covers the lens"),
        ({"led_offsets_m": [0.01, 0, 0], "emitter_diameter_m": 0.001}, "luminous_intensity_cd or radiant"),
        ({"led_offsets_m": [0.01, 0, 0], "emitter_diameter_m": 0.001, "luminous_intensity_cd": 5, "spectrum": "xenon"}, "spectrum = 'xenon'"),
    ],
)
def test_bad_flash_tables(flash, msg):
    with pytest.raises(ProfileError, match=msg):
        Flash.from_camera(_cam(flash=flash), (400, 700))


def test_pixel_solid_angle_sums_to_the_field_of_view():
    # a 2 x 2 normalised-unit square at unit distance: a pyramid of half-angles 45 deg,
    # solid angle 4 asin(sin 45 * sin 45) = 2 pi / 3
    cam = Camera(name="s", width=200, height=200, fx=100.0, fy=100.0, cx=99.5, cy=99.5)
    u, v = np.meshgrid(np.arange(200.0), np.arange(200.0))
    xy = np.stack([(u - 99.5) / 100, (v - 99.5) / 100], -1)
    assert pixel_solid_angle_sr(cam, xy).sum() == pytest.approx(2 * np.pi / 3, rel=1e-4)


def test_radiance_to_photons_is_irradiance_times_pixel_area():
    # on axis: E_image = L * pi / (4 N^2) (image at infinity), photons = E * pitch^2 / E_ph
    f, N, pitch = 0.004, 2.0, 2e-6
    cam = Camera(name="s", width=3, height=3, fx=f / pitch, fy=f / pitch, cx=1.0, cy=1.0)
    opt = Optics(focal_length_m=f, f_number=N, focus_distance_m=1e9, band_nm=(400, 700))
    k = radiance_to_photon_rate(cam, opt, 3e-19, np.zeros(2))
    assert k == pytest.approx(np.pi / (4 * N * N) * pitch ** 2 / 3e-19, rel=1e-12)


def test_cube_triad_is_orthonormal_and_symmetric():
    for clock in (0.0, 17.0):
        E = cube_triad(clock)
        assert np.allclose(E @ E.T, np.eye(3), atol=1e-14)
        assert np.allclose(E.sum(0) / np.sqrt(3), [0, 0, 1], atol=1e-14)


@pytest.mark.parametrize("kind", ["solid", "hollow"])
def test_cube_faces_are_exact_planes_with_the_right_normals(kind):
    refl = Reflector(kind=kind, segments=16)
    meshes = {m.name: m for m in corner_cube_meshes(refl)}
    E = cube_triad(0.0)
    back = meshes["cube_glass"] if kind == "solid" else meshes["cube_mirrors"]
    n = back.face_normals()
    sign = -1.0 if kind == "solid" else 1.0  # solid: out of the glass; hollow: into the cube
    planes = [sign * e for e in E] + ([np.array([0, 0, 1.0])] if kind == "solid" else [])
    # every triangle lies on one of the planes (double precision, nothing truncated)
    d = np.abs(np.stack([n @ p for p in planes], 1) - 1.0).min(1)
    assert d.max() < 1e-12
    v = back.vertices_m[back.faces]
    for tri, nn in zip(v, n):
        k = int(np.argmin([abs(nn @ p - 1) for p in planes]))
        if k < 3:
            assert np.abs(tri @ E[k]).max() < 1e-15  # on the plane e_k . p = 0 through the vertex
    # the rim reaches the full clear aperture
    r = np.hypot(back.vertices_m[:, 0], back.vertices_m[:, 1])
    assert r.max() == pytest.approx(refl.radius_m, rel=1e-12)


def test_reflector_validation():
    with pytest.raises(InputError, match="too short"):
        Reflector(height_m=0.008)
    with pytest.raises(InputError, match="kind"):
        Reflector(kind="prism")
    with pytest.raises(InputError, match="unknown model"):
        Reflector.resolve("catseye")
    with pytest.raises(InputError, match="unknown fields"):
        Reflector.resolve({"colour": "red"})
    assert Reflector.resolve("hollow", Pattern.load("svgs-3u")).kind == "hollow"
    assert Reflector.resolve(None, Pattern.load("svgs-3u")).model == "edmund-nbk7-12.7mm"


def test_scene_options_validation():
    with pytest.raises(InputError, match="max_depth"):
        SceneOptions(max_depth=5)
    with pytest.raises(InputError, match="distractors"):
        SceneOptions(distractors=({"type": "glint"},))
    with pytest.raises(InputError, match="unknown keys"):
        SceneOptions.resolve({"bodyy": "plate"})


def test_target_places_reference_points_on_the_pattern():
    pat = Pattern.load("svgs-3u")
    refl = Reflector()
    tg = build_target(pat, refl, SceneOptions())
    n = refl.index((400, 700))
    # apparent vertex h/n behind the front face sits on the pattern point
    front = tg.cube_vertex_m + refl.height_m * tg.cube_axis
    assert np.allclose(front - refl.height_m / n * tg.cube_axis, pat.points_m, atol=1e-15)
    # one boom, for target 3, from the face to the mount base
    assert [b["target"] for b in tg.info["booms"]] == [3]
    assert tg.info["face_z_m"] < tg.cube_vertex_m[:, 2].min()


def test_box_mesh_normals_point_out():
    b = box_mesh("b", [0, 0, 0], [1, 2, 3], "body")
    c = b.vertices_m[b.faces].mean(1)
    assert np.all(np.einsum("ij,ij->i", b.face_normals(), c - [0.5, 1, 1.5]) > 0)


def test_retro_factors():
    refl = Reflector()
    n = refl.index((400, 700))
    rf = fresnel_normal(n)
    assert rf == pytest.approx(0.0425, abs=1e-3)
    # a lossless solid cube returns everything at normal incidence
    assert retro_factor(refl) == pytest.approx(1.0, abs=1e-12)
    assert retro_pass_factor(refl) == pytest.approx((1 - rf) ** 2)
    assert retro_factor(Reflector(kind="hollow", mirror_reflectance=0.9)) == pytest.approx(0.729)


def test_hollow_spot_direction_is_2V_minus_S():
    refl = Reflector(kind="hollow")
    S = np.array([0.008, -0.003, 0.0])
    V = np.array([0.3, -0.2, 7.0])
    axis = np.array([0.05, 0.1, -1.0])
    d = spot_direction_cam(S, V, axis, refl)
    X = virtual_source_cam(S, V)
    assert np.allclose(d, X / np.linalg.norm(X), atol=1e-12)


def test_solid_spot_direction_uses_the_apparent_vertex():
    refl = Reflector()
    n = refl.index((400, 700))
    S = np.array([0.008, 0.0, 0.0])
    axis = np.array([0.0, 0.0, -1.0])
    Vref = np.array([0.1, 0.05, 10.0])
    V = Vref - (refl.height_m - refl.height_m / n) * axis  # physical vertex, deeper than the apparent one
    d = spot_direction_cam(S, V, axis, refl)
    X = virtual_source_cam(S, Vref)
    # paraxial: the apparent vertex is exact to second order in the small angles
    assert np.degrees(np.arccos(np.clip(d @ X / np.linalg.norm(X), -1, 1))) * 3600 < 0.05  # arcsec


def test_binned_spot_converges_to_the_chief_ray_for_a_wide_spot():
    cam = Camera(name="s", width=64, height=64, fx=2450.0, fy=2450.0, cx=31.5, cy=31.5)
    X = np.array([0.0013, -0.0007, 2.0])
    # strong defocus: a spot many pixels wide has no pixel-phase bias
    a_m, focus_m, n_ap, n_src = 0.002, 0.5, 20000, 16
    c, chief = binned_spot(cam, a_m, focus_m, X, 0.0005, n_aperture=n_ap, n_source=n_src)
    # Derived tolerance. Thin lens: defocus disk radius rho = f_px a (1 - focus / z) / focus (7.35 px).
    # Binning into unit pixels biases the centroid by the sawtooth's Fourier series weighted by the
    # spot's 1-D marginal: |bias| <= sum_k |2 J1(2 pi k rho) / (2 pi k rho)| / (pi k) (uniform disk; the
    # source disk only multiplies each term by a factor <= 1). The finite sample set adds a sawtooth
    # average over N = n_ap n_src points: standard error 1 / sqrt(12 N), taken at 5 sigma.
    from scipy.special import j1

    rho = cam.fx * a_m * (1 - focus_m / X[2]) / focus_m
    x = 2 * np.pi * np.arange(1, 100001) * rho
    pixel_lock_px = float(np.sum(np.abs(2 * j1(x) / x) / (x / (2 * rho))))  # ~0.0019 px
    sampling_px = 5 / np.sqrt(12 * n_ap * n_src)  # ~0.0026 px
    assert np.allclose(c, chief, atol=pixel_lock_px + sampling_px)
