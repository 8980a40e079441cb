"""The rendered ToF camera (render/tof): depth, phase wrapping, flying pixels, multipath,
1/d^2 radiometry and centroids on rendered markers. Small windows, modest spp."""

import importlib.util

import numpy as np
import pytest

if importlib.util.find_spec("mitsuba") is None:  # not imported here: render.variant picks the LLVM first
    pytest.skip("Mitsuba is not installed (the 'render' extra)", allow_module_level=True)

from camera.amcw import TofSensor, phasor_depth_m, unambiguous_range_m  # noqa: E402
from render.tof import TofRenderer  # noqa: E402
from svgs.errors import InputError  # noqa: E402
from svgs.frames import pose_from_scenario  # noqa: E402

pytestmark = pytest.mark.render

PLATE = {"markers": False, "plate_size_m": (30.0, 30.0), "plate_albedo": 0.5}
CENTRE = (150, 110, 20, 20)
CORNER = (0, 0, 12, 12)


@pytest.fixture(scope="module")
def plate():
    return TofRenderer(scene_options=PLATE, spp=64)


@pytest.fixture(scope="module")
def plate_point_source():
    """The emitters all at the lens centre: no parallax between light and camera."""
    return TofRenderer(scene_options=PLATE, spp=64, illumination={"ring_radius_m": 0.0})


def radial_m(camera, distance_m, win):
    x0, y0, w, h = win
    u, v = np.meshgrid(np.arange(x0, x0 + w), np.arange(y0, y0 + h))
    return distance_m * np.sqrt(1 + ((u - camera.cx) / camera.fx) ** 2 + ((v - camera.cy) / camera.fy) ** 2)


def crop(a, win):
    x0, y0, w, h = win
    return a[y0:y0 + h, x0:x0 + w]


@pytest.mark.parametrize("distance_m", [0.7, 2.5])
def test_flat_plate_depth_is_the_radial_distance(plate, plate_point_source, distance_m):
    R, t = pose_from_scenario(distance_m)
    for win in (CENTRE, CORNER):
        truth = radial_m(plate.camera, distance_m, win)
        d_pt = crop(plate_point_source.render(R, t, seed=1, window=win).depth_m, win)
        np.testing.assert_allclose(d_pt, truth, atol=6e-4)  # phasor depth = radial range (MC: 0.1-0.3 mm)
        rd = plate.render(R, t, seed=1, window=win)
        # the ring of emitters 16 mm around the lens lengthens the light leg by up to ~1 mm off axis
        np.testing.assert_allclose(crop(rd.depth_m, win), truth, atol=1.5e-3)
    # noisy frames: unbiased within the noise (ambient 1000 lux, automatic integration time)
    sensor = TofSensor.from_camera(plate.camera)
    rd_c = plate.render(R, t, seed=2, window=CENTRE)
    d = np.stack([crop(f.depth_m, CENTRE) for f in sensor.frames(rd_c, 20, 4)])
    err = d - radial_m(plate.camera, distance_m, CENTRE)
    assert np.isfinite(err).all()
    assert abs(err.mean()) < 4 * err.std() / np.sqrt(err.size) + 1e-3
    assert rd_c.truth["render"]["window"] == list(CENTRE)


def test_phase_wraps_beyond_the_unambiguous_range(plate_point_source):
    R, t = pose_from_scenario(2.0)
    f = 100e6  # unambiguous range 1.499 m
    rd = plate_point_source.render(R, t, seed=1, window=CENTRE, modulation_frequency_hz=f)
    U = unambiguous_range_m(f)
    truth = radial_m(plate_point_source.camera, 2.0, CENTRE)
    np.testing.assert_allclose(crop(rd.depth_m, CENTRE), truth - U, atol=3e-4)
    assert rd.modulation_frequency_hz == f and rd.truth["unambiguous_range_m"] == pytest.approx(U)


def test_amplitude_falls_as_inverse_square_and_matches_the_radiometry(plate):
    ill = plate.illumination
    win = (158, 118, 4, 4)  # on axis
    L = {}
    for d in (1.0, 2.0, 4.0):
        R, t = pose_from_scenario(d)
        L[d] = crop(plate.render(R, t, seed=1, window=win).active_radiance, win).mean()
        # Lambertian plate (0.5) lit on axis by n emitters of intensity I0: L = rho / pi * n I0 / d^2
        # (the 16 mm ring tilts each emitter by atan(16 mm / d): cos^(m+1) of that)
        tilt = np.cos(np.arctan(ill.ring_radius_m / d)) ** (ill.cos_exponent + 1)
        assert L[d] == pytest.approx(0.5 / np.pi * ill.n_emitters * ill.intensity_w_sr / d**2 * tilt, rel=3e-3)
    assert L[1.0] / L[2.0] == pytest.approx(4.0, rel=3e-3)
    assert L[2.0] / L[4.0] == pytest.approx(4.0, rel=3e-3)
    # the sensor's amplitude (noise-free, fixed integration time) follows it
    sensor = TofSensor.from_camera(plate.camera, ambient_lux=0.0)
    amp = {}
    T = None
    for d in (1.0, 2.0):
        R, t = pose_from_scenario(d)
        rd = plate.render(R, t, seed=1, window=win)
        T = T or 1000.0 / float(sensor.expected_amplitude_lsb(rd, 1.0).max())  # ~1000 LSB at 1 m: unsaturated
        amp[d] = crop(sensor.frame(rd, integration_time_s=T, noise=False).amplitude_dn, win).mean()
    assert amp[1.0] / amp[2.0] == pytest.approx(4.0, rel=3e-3)


def _sheeting_row(name):
    """The published table of a sheeting, read straight from the asset (not through render.tof.retro)."""
    import tomllib
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "assets" / "materials" / "retroreflective-sheeting.toml"
    with open(path, "rb") as fh:
        return next(t for t in tomllib.load(fh)["sheeting"] if t["name"] == name)


@pytest.mark.parametrize("distance_m, observation_deg, entrance_deg", [
    (0.7, 2.0, 5.0), (2.5, 0.33, 30.0), (5.7, 0.2, 40.0), (1.0, 0.2, 5.0)])
def test_a_retroreflective_sheet_returns_its_coefficient_of_retroreflection(distance_m, observation_deg, entrance_deg):
    """A flat sheet of EN 12899-1 RA2 at a known distance, lit by the emitter ring at the
    radius that makes the observation angle a tabulated one and tilted to a tabulated entrance
    angle: the on-axis radiance is R_A E_perp / cos(view angle) + the diffuse part, with R_A the
    published figure (CIE: R_A = I / (E_perp A), I = L A cos(view angle))."""
    tab = _sheeting_row("en12899-ra2-white")
    ra = tab["ra_cd_lx_m2"][tab["observation_deg"].index(observation_deg)][tab["entrance_deg"].index(entrance_deg)]
    r_ring = distance_m * np.tan(np.radians(observation_deg))
    ren = TofRenderer(spp=64, pinhole=True, illumination={"ring_radius_m": r_ring, "emitter_diameter_m": 1e-5},
                      scene_options={"markers": False, "plate_size_m": (4.0, 4.0), "plate_material": "retroreflective",
                                     "sheeting": "en12899-ra2-white"})
    R, t = pose_from_scenario(distance_m, 0.0, 0.0, 0.0, entrance_deg, 0.0)  # the sheet turned about a vertical axis
    n_target = np.array([0.0, 0.0, 1.0])
    assert np.degrees(np.arccos(-(R @ n_target)[2])) == pytest.approx(entrance_deg, abs=1e-9)
    win = (159, 119, 2, 2)
    L = crop(ren.render(R, t, seed=3, window=win).active_radiance, win).mean()
    ill = ren.illumination
    d2 = distance_m**2 + r_ring**2
    theta_e = np.arctan(r_ring / distance_m)
    e_perp = ill.n_emitters * ill.intensity_w_sr * np.cos(theta_e) ** ill.cos_exponent / d2  # W m^-2 across the beam
    b = np.radians(entrance_deg)
    expect = ra * e_perp / np.cos(b) + tab["diffuse_albedo"] / np.pi * e_perp * np.cos(b)
    assert L == pytest.approx(expect, rel=0.03)
    # the same sheet as white paint returns ~1000x less at the small observation angles
    if observation_deg < 0.5:
        lam = TofRenderer(spp=16, pinhole=True, illumination={"ring_radius_m": r_ring, "emitter_diameter_m": 1e-5},
                          scene_options={"markers": False, "plate_size_m": (4.0, 4.0), "plate_albedo": 0.85})
        L_white = crop(lam.render(R, t, seed=3, window=win).active_radiance, win).mean()
        assert L_white == pytest.approx(0.85 / np.pi * e_perp * np.cos(b), rel=0.03)
        assert L / L_white > 300


@pytest.fixture(scope="module")
def edge_scene():
    """tof-8 on a larger plate, emitters at the lens centre (no shadow fringe), head-on at 1 m;
    white (Lambertian) markers so that rim pixels mix comparable returns (a retroreflective
    face outshines the plate ~100x and pulls the mixed depth onto itself)."""
    r = TofRenderer(spp=256, illumination={"ring_radius_m": 0.0},
                    scene_options={"plate_size_m": (1.0, 1.0), "marker_material": "lambertian"})
    return r, pose_from_scenario(1.0)


def _rim_pixels(rd, marker="7"):
    """Pixels straddling the rim of a marker: (alpha, depth, phasor prediction, linear prediction,
    marker depth, plate depth), alpha from the DC between the pure neighbours 3 px in and out."""
    f = rd.modulation_frequency_hz
    U = unambiguous_range_m(f)
    wrap = lambda x: (x + U / 2) % U - U / 2  # noqa: E731
    c = np.asarray(rd.truth["targets_px"][marker])
    L, P = rd.active_radiance, rd.phasor_radiance
    rows = []
    for v in range(int(c[1]) - 16, int(c[1]) + 17):
        for u in range(int(c[0]) - 16, int(c[0]) + 17):
            dv = np.array([u, v]) - c
            rr = np.hypot(*dv)
            if not 10 < rr < 16:
                continue
            e = dv / rr
            mi = np.round(np.array([u, v]) - 3 * e).astype(int)
            pl = np.round(np.array([u, v]) + 3 * e).astype(int)
            Lm, Lp = L[mi[1], mi[0]], L[pl[1], pl[0]]
            a = (L[v, u] - Lp) / (Lm - Lp)
            if not 0.05 < a < 0.95:
                continue
            Pm, Pp = P[mi[1], mi[0]], P[pl[1], pl[0]]
            dm, dp = phasor_depth_m(Pm, f), phasor_depth_m(Pp, f)
            wm, wp = a * Lm, (1 - a) * Lp
            rows.append((a, phasor_depth_m(P[v, u], f), phasor_depth_m(a * Pm + (1 - a) * Pp, f),
                         dm + wp / (wm + wp) * wrap(dp - dm), dm, dp))
    A = np.array(rows)
    return A, wrap


def test_flying_pixels_are_phasor_sums(edge_scene):
    r, (R, t) = edge_scene
    win = (125, 130, 55, 50)
    rd = r.render(R, t, seed=2, window=win)
    A, wrap = _rim_pixels(rd)
    assert len(A) > 60
    # mixed depth between marker face (0.9 m) and plate (1.0 m), as the phasor sum predicts
    assert np.all(A[:, 1] > A[:, 4] - 2e-3) and np.all(A[:, 1] < A[:, 5] + 2e-3)
    assert np.mean((A[:, 1] > A[:, 4] + 5e-3) & (A[:, 1] < A[:, 5] - 5e-3)) > 0.2  # clearly between
    e = wrap(A[:, 1] - A[:, 2])
    assert np.sqrt(np.mean(e**2)) < 1.5e-3 and np.abs(e).max() < 6e-3
    # at 400 MHz (1.7 rad between face and plate) the phasor sum differs from averaging depths
    rd = r.render(R, t, seed=2, window=win, modulation_frequency_hz=400e6)
    A, wrap = _rim_pixels(rd)
    e_ph = np.sqrt(np.mean(wrap(A[:, 1] - A[:, 2]) ** 2))
    e_lin = np.sqrt(np.mean(wrap(A[:, 1] - A[:, 3]) ** 2))
    assert e_ph < 1.5e-3 and e_lin > 2 * e_ph


def test_multipath_from_a_wall_lengthens_the_depth():
    wall = {"type": "box", "lo_m": [0.05, -0.3, 0.0], "hi_m": [0.06, 0.3, 0.3], "albedo": 0.9}
    opts = {"markers": False, "plate_size_m": (1.0, 1.0), "plate_albedo": 0.5, "distractors": [wall]}
    R, t = pose_from_scenario(1.0)
    win = (110, 112, 60, 16)  # plate pixels left of the wall (the wall stands at u ~ 176)
    rd = {b: TofRenderer(scene_options=opts, spp=128, max_bounces=b).render(R, t, seed=1, window=win) for b in (1, 2)}
    d = {b: crop(x.depth_m, win) for b, x in rd.items()}
    truth = radial_m(_cam(), 1.0, win)
    np.testing.assert_allclose(d[1], truth, atol=1.5e-3)  # direct only: geometry (ring parallax < 1.5 mm)
    bias = d[2] - d[1]
    assert bias.mean() > 4e-4 and np.mean(bias > 0) > 0.9  # light bounced off the wall arrives late
    gain = crop(rd[2].active_radiance, win) / crop(rd[1].active_radiance, win)
    assert gain.mean() > 1.005 and gain[:, -10:].mean() > gain[:, :10].mean()  # more light next to the wall


def _cam():
    from tof import load_camera

    return load_camera("tof-epc660")


def test_centroids_of_rendered_markers_within_the_paper_figure():
    import tof

    r = TofRenderer(spp=64)
    R, t = pose_from_scenario(0.697, 0.0022, -0.0105, -0.38, -2.65, -2.53)
    rd = r.render(R, t, seed=3)
    fr = TofSensor.from_camera(r.camera).frame(rd, noise=False)
    truth = np.array([rd.truth["targets_px"][str(i)] for i in range(1, 9)])
    err = {}
    for cc in (True, False):
        res = tof.solve_frame(fr.gray, fr.depth_m, r.camera, r.target, centre_correction=cc)
        assert res and sorted(res.targets_px) == list(range(1, 9))
        err[cc] = np.linalg.norm(np.array([res.targets_px[k] for k in range(1, 9)]) - truth, axis=1)
    assert err[True].max() < 0.06  # the paper's 0.06 px
    big = r.target.diameter_m > 0.05
    assert err[False][big].max() > 0.08 and err[False][big].mean() > 2 * err[True][big].mean()
    # and the noisy frames solve to the pose
    noisy = TofSensor.from_camera(r.camera).frame(rd, rng=1)
    res = tof.solve_frame(noisy.gray, noisy.depth_m, r.camera, r.target)
    assert np.linalg.norm(res.t_cam_target_m - t) < 2e-3


def test_bad_poses_and_profiles(plate):
    with pytest.raises(InputError, match="behind the camera"):
        TofRenderer(spp=1).render(np.eye(3), np.array([0.0, 0.0, -1.0]))
    with pytest.raises(InputError, match="outside the field of view"):
        TofRenderer(spp=1).render(*pose_from_scenario(1.0, 5.0, 0.0))
    with pytest.raises(InputError, match="unknown camera profile"):
        TofRenderer("no-such-camera")
    with pytest.raises(InputError, match="max_bounces"):
        TofRenderer(max_bounces=9)
    with pytest.raises(InputError, match="window"):
        plate.render(*pose_from_scenario(1.0), window=(300, 0, 50, 10))
    with pytest.raises(InputError, match="unknown keys"):
        TofRenderer(scene_options={"plate_colour": 1})
