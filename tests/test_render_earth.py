"""The Earth on orbit against geometry and radiometry this code did not produce: its apparent
half-angle asin(R / (R + h)) (70.2 deg from 400 km) in the rendered background, the Earth shine on
a nadir-facing Lambertian plate from a uniformly bright Earth, (R / (R + h))^2 of the Earth's
radiance (the view factor of a sphere to a plate facing its centre), the sunlit sphere's radiance
rho E cos(i) / pi, and the eclipse by the Earth's disk (a cylindrical shadow)."""

from __future__ import annotations

import json

import numpy as np
import pytest

R_EARTH_M = 6371.0088e3  # IUGG mean radius R1
H_M = 400e3


def test_the_sunlit_spheres_radiance_is_rho_e_cos_i_over_pi():
    """Seen from the target, a direction beta off nadir meets the sphere at central angle
    gamma = asin((R + h) / R sin beta) - beta from the sub-target point; with the sun over that point
    the surface there is lit at incidence gamma (law of sines in the Earth-target-point triangle)."""
    from svgs_sim.render.earth import earth_radiance

    e = np.array([0.0, 0.0, -1.0])  # the Earth below the target
    rho, E = 0.3, 535.1
    for beta_deg in (0.0, 20.0, 45.0, 65.0, 70.0):
        b = np.radians(beta_deg)
        w = np.array([np.sin(b), 0.0, -np.cos(b)])
        gamma = np.arcsin((R_EARTH_M + H_M) / R_EARTH_M * np.sin(b)) - b
        got = earth_radiance(w, e, -e, H_M, rho, E)
        assert got == pytest.approx(rho * E * np.cos(gamma) / np.pi, rel=1e-9), beta_deg
    # beyond the limb: space
    b = np.radians(np.degrees(np.arcsin(R_EARTH_M / (R_EARTH_M + H_M))) + 0.01)
    assert earth_radiance(np.array([np.sin(b), 0.0, -np.cos(b)]), e, -e, H_M, rho, E) == 0.0
    # the night side: the sun behind the Earth lights nothing the target sees at nadir
    assert earth_radiance(e, e, e, H_M, rho, E) == 0.0


def test_eclipse_is_the_sun_inside_the_earths_disk():
    """A cylindrical shadow: the target at p = -(R + h) e from the Earth's centre is in the umbra when
    the sun is on the far side (p . s < 0) and p lies within R of the shadow's axis."""
    from svgs_sim.render.earth import in_eclipse

    rng = np.random.default_rng(1)
    for _ in range(400):
        e, s = (v / np.linalg.norm(v) for v in rng.normal(size=(2, 3)))
        h = float(rng.uniform(200e3, 36000e3))
        p = -(R_EARTH_M + h) * e
        shadow = p @ s < 0 and np.linalg.norm(p - (p @ s) * s) < R_EARTH_M
        assert in_eclipse(s, e, h) == shadow


def _camera(size=256, f_px=2450.0):
    from svgs_sim.base.profiles import Camera

    return Camera(name="test-earth", width=size, height=size, fx=f_px, fy=f_px, cx=(size - 1) / 2, cy=(size - 1) / 2,
                  tables={"optics": {"focal_length_m": 0.00343, "f_number": 2.4, "focus_distance_m": 3.0,
                                     "band_nm": [400.0, 700.0]},
                          "flash": {"led_offsets_m": [[0.008, 0.0, 0.0]], "emitter_diameter_m": 0.0012,
                                    "radiant_intensity_w_sr": 0.03, "cos_exponent": 1.0}})


def _render(earth_direction, plate=False, L=100.0, spp=64):
    from svgs_sim.base.profiles import Pattern
    from svgs_sim.render.api import Renderer
    from svgs_sim.render.geometry import box_mesh

    far = Pattern(name="far", ids=np.arange(1, 5),  # the cubes far outside the field
                  points_m=np.array([[3.0, 3.0, 0.05], [4.0, 3.0, 0.05], [3.0, 4.0, 0.05], [4.0, 4.0, 0.1]]))
    extra = [box_mesh("plate", [-0.3, -0.3, -0.02], [0.3, 0.3, 0.0], "surface:lambertian-white")] if plate else []
    r = Renderer(_camera(), far, scene_options={"body": "none", "earth_direction_target": tuple(earth_direction),
                                                "altitude_m": H_M, "earth_uniform_radiance_w_m2_sr": L},
                 spp=spp, roi_spp=4, spot_samples=64, extra_meshes=extra)
    head_on = (np.diag([1.0, -1.0, -1.0]), np.array([0.0, 0.0, 3.0]))  # the camera 3 m in front, on +z
    return r.render(*head_on, seed=3, check_fov=False)


@pytest.mark.render
def test_earth_shine_on_a_plate_facing_the_earth_is_the_view_factor():
    L = 100.0
    res = _render((0.0, 0.0, 1.0), plate=True, L=L)  # the Earth behind the camera, the plate facing it
    got = float(res.radiance[100:156, 100:156].mean())
    assert got == pytest.approx(L * (R_EARTH_M / (R_EARTH_M + H_M)) ** 2, rel=0.01)
    assert res.truth["earth"]["half_angle_deg"] == pytest.approx(np.degrees(np.arcsin(R_EARTH_M / (R_EARTH_M + H_M))))


@pytest.mark.render
def test_the_earths_limb_lies_at_its_apparent_half_angle():
    """The boresight 1 deg outside the Earth's disk: the limb crosses the centre row where a pixel's
    direction is asin(R / (R + h)) = 70.2 deg from the Earth's centre (within 0.05 deg)."""
    rho = np.arcsin(R_EARTH_M / (R_EARTH_M + H_M))
    assert np.degrees(rho) == pytest.approx(70.2, abs=0.05)
    a = rho + np.radians(1.0)
    e = np.array([np.sin(a), 0.0, -np.cos(a)])  # the camera looks along the target's -z
    L = 100.0
    res = _render(e, L=L, spp=16)
    cam = _camera()
    row = res.radiance[int(cam.cy)]
    x = (np.arange(cam.width) - cam.cx) / cam.fx
    ang = np.arccos((x * np.sin(a) + np.cos(a)) / np.sqrt(1 + x * x))  # each pixel's angle from the Earth's centre
    assert row[ang < rho - np.radians(0.3)].min() > 0.95 * L and row[ang > rho + np.radians(0.3)].max() < 0.05 * L
    k = int(np.flatnonzero(row > L / 2)[0])  # the first Earth pixel from the left (the Earth toward +x)
    u = k - 1 + (L / 2 - row[k - 1]) / (row[k] - row[k - 1])  # where the row crosses L / 2
    ang_limb = np.arccos(((u - cam.cx) / cam.fx * np.sin(a) + np.cos(a)) / np.hypot(1, (u - cam.cx) / cam.fx))
    assert np.degrees(ang_limb) == pytest.approx(np.degrees(rho), abs=0.05)


@pytest.mark.render
@pytest.mark.slow
def test_svgs_render_with_the_earth_and_an_eclipse(tmp_path):
    """The command line: the Earth behind the target and the sun behind the Earth - the target in
    eclipse, the sun's disk not drawn, the Earth's dark side."""
    from svgs_sim.cli.main import main

    out = tmp_path / "e"
    rc = main(["render", "--camera", "galaxy-nexus", "--range", "5", "--environment", "orbit", "--sun-deg=0,-80",
               "--earth-deg=0,-85", "--out", str(out), "--spp", "4", "--no-expose"])
    assert rc == 0
    truth = json.loads((out / "truth.json").read_text())
    assert truth["sun"]["eclipsed"] is True and truth["sun"]["in_view"] is False
    assert truth["earth"]["in_view"] is True


def test_the_map_keeps_its_geometry_between_suns_without_changing_a_texel():
    """earth_map keeps the Earth's ray hits between calls (a sun that moves over an orbit's phase):
    each map equals earth_radiance evaluated afresh at every texel's direction, bit for bit."""
    from svgs_sim.render.earth import earth_map, earth_radiance, map_directions, map_frame

    e = np.array([0.3, -0.2, -0.9])
    e /= np.linalg.norm(e)
    for s in ([0.0, 1.0, 0.0], [0.6, 0.0, 0.8], [-0.3, 0.9, -0.3]):
        s = np.array(s) / np.linalg.norm(s)
        got, M = earth_map(e, s, H_M, 0.3, 535.1, rows=128)
        ref = earth_radiance(map_directions(128, map_frame(e)), e, s, H_M, 0.3, 535.1).astype(np.float32)
        assert np.array_equal(got, ref)
        np.testing.assert_allclose(M[:3, :3], map_frame(e), atol=0)
