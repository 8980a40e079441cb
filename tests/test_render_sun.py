"""The sun on orbit against physics this code did not produce: a sunlit Lambertian plate's
absolute radiance E cos(theta) rho / pi, the sun's disk seen directly at the sun's radiance and
size, a mirror's glint where the law of reflection puts it, irradiance against the sun's
elevation. The solar numbers come from ASTM G173-03 (pvlib's table) and the IAU's values here,
not from :mod:`svgs_sim.render.sun`."""

from __future__ import annotations

import numpy as np
import pytest

from svgs_sim.base.profiles import Camera, Pattern

pytestmark = pytest.mark.render
pvlib = pytest.importorskip("pvlib", reason="the orbit extra (pip install -e '.[orbit]')")

H_J_S, C_M_S = 6.62607015e-34, 299792458.0
TSI_W_M2 = 1361.0  # IAU 2015 Resolution B3 nominal total solar irradiance
SUN_RADIUS_DEG = np.degrees(np.arcsin(695700.0 / 149597870.7))  # IAU 2015 B3 radius over 1 AU
BAND_NM = (400.0, 700.0)


def _sun_in_band():
    """(irradiance W/m^2, mean photon energy J) of the sun in BAND_NM, from the G173-03 table."""
    from pvlib.spectrum import get_reference_spectra

    s = get_reference_spectra(standard="ASTM G173-03")
    wl, e = np.asarray(s.index, float), np.asarray(s["extraterrestrial"], float)
    e = e * TSI_W_M2 / np.trapezoid(e, wl)
    m = (wl >= BAND_NM[0]) & (wl <= BAND_NM[1])
    power = np.trapezoid(e[m], wl[m])
    photons = np.trapezoid(e[m] * wl[m] * 1e-9 / (H_J_S * C_M_S), wl[m])
    return power, power / photons


def _camera(size=256, f_px=2450.0):
    return Camera(name="test-sun", width=size, height=size, fx=f_px, fy=f_px, cx=(size - 1) / 2, cy=(size - 1) / 2,
                  tables={"optics": {"focal_length_m": 0.00343, "f_number": 2.4, "focus_distance_m": 3.0,
                                     "band_nm": list(BAND_NM)},
                          "flash": {"led_offsets_m": [[0.008, 0.0, 0.0]], "emitter_diameter_m": 0.0012,
                                    "radiant_intensity_w_sr": 0.03, "cos_exponent": 1.0}})


# the cubes far outside the field: the scene is the plate (or the mirror) alone
FAR = Pattern(name="far", ids=np.arange(1, 5),
              points_m=np.array([[3.0, 3.0, 0.05], [4.0, 3.0, 0.05], [3.0, 4.0, 0.05], [4.0, 4.0, 0.1]]))
HEAD_ON = (np.diag([1.0, -1.0, -1.0]), np.array([0.0, 0.0, 3.0]))  # the camera 3 m in front, on +z


def _render(sun_az_el, material, rho=1.0, spp=16, half_m=0.3):
    from svgs_sim.render.api import Renderer
    from svgs_sim.render.geometry import box_mesh
    from svgs_sim.render.sun import sun_direction_target

    plate = box_mesh("plate", [-half_m, -half_m, -0.02], [half_m, half_m, 0.0], material)
    r = Renderer(_camera(), FAR, scene_options={"body": "none", "body_reflectance": rho,
                                               "sun_direction_target": tuple(sun_direction_target(*sun_az_el))},
                 spp=spp, roi_spp=4, spot_samples=64, extra_meshes=[plate])
    return r, r.render(*HEAD_ON, seed=3, check_fov=False)


def _sun_radiance(r, res, e_ph_sun):
    """The sun's radiance per pixel from its photon flux: the pixel's photons per unit radiance
    (the flash's factor, which holds the flash's photon energy) scaled to the sun's photon energy."""
    return res.flux_sun / (r.flux_factor() * r.flash.photometry["mean_photon_energy_j"] / e_ph_sun)


@pytest.mark.parametrize("elevation_deg", [30.0, 70.0])
def test_a_sunlit_lambertian_plate_has_the_radiance_E_cos_theta_rho_over_pi(elevation_deg):
    E, e_ph = _sun_in_band()
    rho = 0.5
    r, res = _render((20.0, elevation_deg), "body", rho=rho)
    L = _sun_radiance(r, res, e_ph)[96:160, 96:160]  # the plate's middle
    L_pred = E * np.sin(np.deg2rad(elevation_deg)) * rho / np.pi  # cos of the angle from the normal
    # Monte Carlo: the sun's disk sampled by next-event estimation at 16 spp: the per-pixel scatter
    # is the disk's cosine spread (< 1e-5), so the mean of 4096 pixels is exact to float32
    assert np.mean(L) == pytest.approx(L_pred, rel=2e-3)
    assert np.std(L) / L_pred < 1e-3
    # the photon energy: photons counted with the sun's mean photon energy, not the flash's
    assert r._sun["light"]["mean_photon_energy_j"] == pytest.approx(e_ph, rel=1e-3)


def test_the_plates_sun_flux_follows_the_cosine_of_the_suns_angle_from_its_normal():
    fluxes = {el: _render((90.0, el), "body", half_m=0.3)[1].flux_sun.sum() for el in (60.0, 30.0)}
    assert fluxes[30.0] / fluxes[60.0] == pytest.approx(np.cos(np.deg2rad(60.0)) / np.cos(np.deg2rad(30.0)), rel=0.05)


def test_the_suns_disk_seen_directly_has_the_suns_radiance_and_size():
    E, e_ph = _sun_in_band()
    omega = 2 * np.pi * (1 - np.cos(np.deg2rad(SUN_RADIUS_DEG)))
    # the sun 1.5 deg off the boresight (64 px) behind the target (the camera looks along -z of the target)
    r, res = _render((0.0, -88.5), "black", rho=0.0, half_m=0.01)
    L = _sun_radiance(r, res, e_ph)
    disk = L > 0.5 * E / omega
    assert disk.sum() == pytest.approx(np.pi * (2450.0 * np.tan(np.deg2rad(SUN_RADIUS_DEG))) ** 2, rel=0.05)
    inner = L > 0.99 * E / omega
    assert np.median(L[inner]) == pytest.approx(E / omega, rel=0.01)
    assert res.truth["sun"]["in_view"] is True


def test_a_mirrors_sun_glint_lands_where_the_law_of_reflection_puts_it():
    el = 88.0
    r, res = _render((0.0, el), "mirror", half_m=0.3)
    d = np.array([np.cos(np.deg2rad(el)), 0.0, np.sin(np.deg2rad(el))])  # toward the sun
    C = np.array([0.0, 0.0, 3.0])  # the camera in the target frame
    p = C - (C[2] / d[2]) * np.array([-d[0], -d[1], d[2]])  # the mirror point whose reflection reaches C
    R, t = HEAD_ON
    uv_pred = r.camera.project((R @ p + t)[None])[0]
    f = res.flux_sun
    glint = f > 0.2 * f.max()
    v, u = np.nonzero(glint)
    w = f[glint]
    assert np.hypot(np.sum(u * w) / w.sum() - uv_pred[0], np.sum(v * w) / w.sum() - uv_pred[1]) < 1.0


def _channel_shares(photons, wl):
    """Each colour filter's share of a photon spectrum over BAND_NM, shape (3,), by direct summation
    over the wavelength grid (the filters: the camera model's stated ASSUMPTION,
    svgs_sim.camera.phone.cfa.filter_transmission; the spectra: G173-03 and the flash's LED here)."""
    from svgs_sim.camera.phone.cfa import filter_transmission
    from svgs_sim.camera.phone.params import CfaParams

    t = filter_transmission(CfaParams(pattern="RGGB"), wl)
    return (t * photons).sum(axis=1) / photons.sum()


def test_a_sunlit_plate_gives_each_colour_channel_the_photons_its_filter_passes():
    """Per channel, absolute: through the colour filter array (a perfect lens, no noise), a pixel of
    colour c on the sunlit plate collects response_c x (the photons of E cos(theta) rho / pi that
    filter c passes) / (filter c's share of the flash's photons): the sun's colour, not the flash's.
    The photon spectra are summed here from pvlib's G173-03 table and the flash's LED model."""
    import dataclasses

    from pvlib.spectrum import get_reference_spectra

    from svgs_sim.camera.phone import PhoneCamera
    from svgs_sim.camera.phone.cfa import channel_map
    from svgs_sim.camera.phone.params import CfaParams, PhoneParams
    from svgs_sim.render.optics import WHITE_LED
    from svgs_sim.sim.closed_loop import Frame, natural_part

    E, e_ph = _sun_in_band()
    rho, el = 0.5, 70.0
    r, res = _render((20.0, el), "body", rho=rho)
    wl = np.arange(BAND_NM[0], BAND_NM[1] + 0.01, 0.25)
    s = get_reference_spectra(standard="ASTM G173-03")
    sun = np.interp(wl, np.asarray(s.index, float), np.asarray(s["extraterrestrial"], float)) * wl
    led = sum(a * np.exp(-0.5 * ((wl - c) / (f / 2.3548200450309493)) ** 2) for c, f, a in WHITE_LED) * wl
    weights = _channel_shares(sun, wl) / _channel_shares(led, wl)
    # the mono photons per pixel of E cos(theta) rho / pi, from the radiance test's chain above
    photons = E * np.sin(np.deg2rad(el)) * rho / np.pi * r.flux_factor() * r.flash.photometry["mean_photon_energy_j"] / e_ph
    base = PhoneParams.from_camera(r.camera)
    params = dataclasses.replace(base, cfa=CfaParams(pattern="RGGB", response=(0.5, 1.0, 0.6)))
    frame = Frame(None, res.flux, res.truth, target_diffuse=res.flux_diffuse, points=res.points,
                  natural=natural_part(res), _phone={(True, None, None): PhoneCamera(r.camera, params=params)})
    got = frame.exposer(stages=("cfa",)).flux_optics[96:160, 96:160]
    chan = channel_map("RGGB", (256, 256))[96:160, 96:160]
    for c, resp in enumerate((0.5, 1.0, 0.6)):
        want = resp * weights[c] * photons[96:160, 96:160][chan == c]
        assert np.mean(got[chan == c]) == pytest.approx(np.mean(want), rel=3e-3), "RGB"[c]
    # and the sun is not the flash's colour: red up, green down by more than 10 %
    assert weights[0] > 1.1 and weights[1] < 0.9


# ---------------------------------------------------------------- a mesh body and its surfaces
def _plate_ply(path):
    """A 0.6 m square plate, 1 cm thick, its face 2 cm behind the pattern plane (metres, target frame)."""
    trimesh = pytest.importorskip("trimesh")
    b = trimesh.creation.box(extents=[0.6, 0.6, 0.01])
    b.apply_translation([0.0, 0.0, -0.025])
    b.export(str(path))
    return str(path)


def test_a_sunlit_mesh_plate_follows_the_cosine_law_through_the_cli(tmp_path):
    """The issue's acceptance: svgs render ... --environment orbit --sun-deg 90,EL --body plate.ply
    --body-material lambertian-white at EL 60 and 30: total flux in the ratio cos 60 / cos 30 (5 %)."""
    from svgs_sim.cli.main import main

    ply = _plate_ply(tmp_path / "plate.ply")
    total = {}
    for el in (60, 30):
        rc = main(["render", "--camera", "galaxy-nexus", "--range", "5", "--environment", "orbit", "--sun-deg",
                   f"90,{el}", "--body", ply, "--body-material", "lambertian-white", "--no-expose",
                   "--out", str(tmp_path / str(el))])
        assert rc == 0
        total[el] = float(np.load(tmp_path / str(el) / "flux.npy").sum())
    assert total[30] / total[60] == pytest.approx(np.cos(np.deg2rad(60)) / np.cos(np.deg2rad(30)), rel=0.05)


def test_a_mesh_body_is_refused_without_a_known_surface_before_any_render(tmp_path, capsys):
    from svgs_sim.cli.main import main

    ply = _plate_ply(tmp_path / "plate.ply")
    base = ["render", "--camera", "galaxy-nexus", "--range", "5", "--environment", "orbit"]
    for extra, words in (([ "--body", ply], "--body-material"),
                         (["--body", ply, "--body-material", "unobtainium"], "unknown surface"),
                         (["--body", str(tmp_path / "none.ply"), "--body-material", "mli"], "does not exist"),
                         (["--body", "sphere", "--body-material", "mli"], "--body"),
                         (["--body", "plate", "--body-material", "mli"], "only a mesh body")):
        out = tmp_path / "out"
        rc = main([*base, *extra, "--out", str(out)])
        err = capsys.readouterr().err
        assert rc == 2 and words in err and "Traceback" not in err and not out.exists(), (extra, err)


def test_every_library_surface_has_a_source_and_loads_in_mitsuba():
    import mitsuba as mi

    from svgs_sim.render.materials import bsdf_dict, surfaces
    from svgs_sim.render.variant import select_variant

    select_variant(None)
    lib = surfaces()
    assert {"solar-cell", "mli", "anodised-aluminium", "white-paint", "lambertian-white"} <= set(lib)
    for name, s in lib.items():
        assert len(s["source"]) > 20, name  # a citation, or a stated ASSUMPTION
        mi.load_dict(bsdf_dict(name))
    assert lib["lambertian-white"]["reflectance"] == 1.0
