"""The rendered ToF camera (render/tof): depth, phase wrapping, flying pixels, multipath,
1/d^2 radiometry and centroids on rendered markers. Small windows, modest spp."""

import importlib.util

import numpy as np
import pytest

if importlib.util.find_spec("mitsuba") is None:  # not imported here: svgs_sim.render.variant picks the LLVM first
    pytest.skip("Mitsuba is not installed (the 'render' extra)", allow_module_level=True)

from svgs_sim.assets import ASSETS_DIR  # noqa: E402
from svgs_sim.camera.amcw import TofSensor, phasor_depth_m, unambiguous_range_m  # noqa: E402
from svgs_sim.render.tof import TofRenderer  # noqa: E402
from svgs_sim.base.errors import InputError  # noqa: E402
from svgs_sim.svgs.frames import pose_from_scenario  # noqa: E402

pytestmark = pytest.mark.render

#: A bare plate whose front face is the target origin (tof-8's own plate lies 125 mm behind its
#: origin, the marker faces' centroid): the pose's range is the plate's distance.
PLATE = {"markers": False, "plate_size_m": (30.0, 30.0), "plate_albedo": 0.5, "plate_centre_m": (0.0, 0.0, 0.0)}
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
    """The published table of a sheeting, read straight from the asset (not through svgs_sim.render.tof.retro)."""
    import tomllib
    
    path = ASSETS_DIR / "materials" / "retroreflective-sheeting.toml"
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
                                     "sheeting": "en12899-ra2-white", "plate_centre_m": (0.0, 0.0, 0.0)})
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
                          scene_options={"markers": False, "plate_size_m": (4.0, 4.0), "plate_albedo": 0.85,
                                         "plate_centre_m": (0.0, 0.0, 0.0)})
        L_white = crop(lam.render(R, t, seed=3, window=win).active_radiance, win).mean()
        assert L_white == pytest.approx(0.85 / np.pi * e_perp * np.cos(b), rel=0.03)
        assert L / L_white > 300


@pytest.fixture(scope="module")
def edge_scene():
    """tof-8 on a larger plate, emitters at the lens centre (no shadow fringe), head-on, its
    plate's centre on the boresight at 1.0 m (the faces at 0.85 and 0.9 m);
    white (Lambertian) markers so that rim pixels mix comparable returns (a retroreflective
    face outshines the plate ~100x and pulls the mixed depth onto itself)."""
    r = TofRenderer(spp=256, illumination={"ring_radius_m": 0.0},
                    scene_options={"plate_size_m": (1.0, 1.0), "marker_material": "lambertian"})
    return r, pose_from_scenario(0.875, 0.0225, -0.000625)  # the origin: the markers' centroid, 125 mm before the plate


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
    # mixed depth between marker 7's face (0.9 m) and the plate (1.0 m), as the phasor sum predicts
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
    opts = {"markers": False, "plate_size_m": (1.0, 1.0), "plate_albedo": 0.5, "distractors": [wall],
            "plate_centre_m": (0.0, 0.0, 0.0)}
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
    from svgs_sim.tof import load_camera

    return load_camera("tof-epc660")


def test_centroids_of_rendered_markers_within_the_paper_figure():
    from svgs_sim import tof

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
    # uncorrected, the 80 mm markers' centroids sit on their ellipses' centres: the projective offset
    # of a tilted circle's image centre from its centre's image (the exact conic; ~0.05 px at the
    # paper's pose, its faces 0.67-0.72 m away)
    from svgs_sim.tof.ellipse import project_circle_conic

    C = r.target.points_m @ R.T + t
    con = np.array([project_circle_conic(r.camera.K, c, R[:, 2], rad) for c, rad in zip(C, r.target.radius_m)])
    bias = np.linalg.norm(-np.linalg.solve(con[:, :2, :2], con[:, :2, 2:3])[:, :, 0] - r.camera.project(C), axis=1)
    assert bias[big].min() > 0.04
    np.testing.assert_allclose(err[False][big], bias[big], atol=0.02)
    assert err[False][big].mean() > 2 * err[True][big].mean()
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


# ---------------------------------------------------------------------- issue 23: the sampler
def test_sobol_points_are_owen_scrambled_joe_kuo_sobol():
    """The per-pixel sequence (svgs_sim/render/tof/sobol.py): unscrambled, the points of scipy's Sobol'
    (Joe-Kuo direction numbers; scipy lists them in Gray-code order); the Dr.Jit points equal
    the numpy twin; scrambled, the first 2^k points of a seed are still a net: one point in
    every 1/2^k interval of each dimension, one in every elementary box of area 2^-k of the
    film pair (dims 0, 1: a (0, k, 2)-net) and two in every box of area 2^(1-k) of the aperture
    pair (dims 2, 3: a (1, k, 2)-net)."""
    from scipy.stats import qmc

    from svgs_sim.render.tof import sobol

    TofRenderer(scene_options=PLATE, spp=1)  # chooses the JIT variant (before drjit is imported here)
    import drjit as dr
    import mitsuba as mi

    V = sobol.direction_numbers().astype(np.uint64)
    n = 1 << 10
    g = np.arange(n) ^ (np.arange(n) >> 1)  # scipy's Gray-code order
    x = np.zeros((n, V.shape[0]), np.uint64)
    for b in range(11):
        x[((g >> b) & 1).astype(bool)] ^= V[:, b]
    np.testing.assert_array_equal(x / 2.0**32, qmc.Sobol(V.shape[0], scramble=False).random(n))

    k = 8
    idx = np.arange(1 << k)
    for seed in (0, 12345, 0xDEADBEEF):
        p = sobol.sobol_owen_numpy(idx, seed, range(sobol.MAX_DIMS))
        q = sobol.sobol_owen(mi, dr, mi.UInt32(idx.astype(np.uint32)), mi.UInt32(np.full(idx.size, seed, np.uint32)),
                             range(sobol.MAX_DIMS))
        np.testing.assert_array_equal(np.stack([np.asarray(c, np.float64) for c in q], 1), p)
        assert np.all((p >= 0) & (p < 1))
        for d in range(sobol.MAX_DIMS):
            assert np.unique(np.floor(p[:, d] * 2**k)).size == 2**k
        for d0, d1, t_net in ((0, 1, 0), (2, 3, 1)):  # the t of these Sobol' pairs (scrambling keeps it)
            m = k - t_net
            for a in range(m + 1):
                cells = (np.floor(p[:, d0] * 2**a) * 2 ** (m - a) + np.floor(p[:, d1] * 2 ** (m - a))).astype(int)
                assert np.all(np.bincount(cells, minlength=2**m) == 2**t_net)
    other = sobol.sobol_owen_numpy(idx, 1, range(4))
    assert not np.allclose(other, sobol.sobol_owen_numpy(idx, 0, range(4)))


def test_rim_band_is_the_blur_and_half_pixel_around_the_projected_rims():
    """Head-on, each marker face projects to a circle: the rim pixels are those whose centre
    lies within blur + sqrt(2)/2 + margin of it (to the 0.25 px spacing of the rim points)."""
    from svgs_sim.render.tof.camera import RIM_MARGIN_PX

    r = TofRenderer()
    R, t = pose_from_scenario(2.0)
    mask = r.rim_mask(R, t)
    v, u = np.mgrid[0:r.camera.height, 0:r.camera.width]
    near = np.zeros_like(mask)
    far = np.ones_like(mask)
    for c, rad in zip(r.geometry.marker_centres_m, r.geometry.marker_radius_m):
        cc = R @ c + t
        uv = r.camera.project(cc[None])[0]
        r_px = r.camera.fx * rad / cc[2]
        reach = float(r.blur_radius_px(cc[2])) + 0.5 * np.sqrt(2) + RIM_MARGIN_PX
        d = np.abs(np.hypot(u - uv[0], v - uv[1]) - r_px)
        near |= d <= reach - 0.05
        far &= d > reach + 0.05
    assert near.sum() > 500
    assert np.all(mask[near]) and not np.any(mask[far])
    assert not TofRenderer(scene_options=PLATE).rim_mask(R, t).any()  # no markers, no rims


def test_render_is_deterministic_per_seed():
    r = TofRenderer(spp=16, rim_spp_factor=4)
    R, t = pose_from_scenario(5.712)
    a, b, c = (r.render(R, t, seed=s) for s in (7, 7, 8))
    np.testing.assert_array_equal(a.phasor_radiance, b.phasor_radiance)
    np.testing.assert_array_equal(a.ambient_factor, b.ambient_factor)
    assert not np.array_equal(a.phasor_radiance, c.phasor_radiance)
    assert a.truth["render"]["sampler"] == "sobol" and a.truth["render"]["rim_spp"] == 64
    assert a.truth["render"]["rim_pixels"] > 100
    with pytest.raises(InputError, match="sampler"):
        TofRenderer(sampler="halton")


def _marker_flux(rd, r, R, t):
    """Per marker of a head-on render: the sum of radiance x pixel solid angle over the pixels
    within 3 px of its blurred image and nearer to its rim than to any other (W m^-2), and that
    sum predicted from the sheeting's R_A, the emitters' irradiance (cos^m / d^2) and the plate
    (Lambertian) seen around the face (the face hides the plate behind it)."""
    from svgs_sim.render.tof.retro import load_sheeting

    cam, ill, geo = r.camera, r.illumination, r.geometry
    v, u = np.mgrid[0:cam.height, 0:cam.width]
    x, y = (u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy
    omega = (1 + x**2 + y**2) ** -1.5 / (cam.fx * cam.fy)  # pixel solid angle, sr
    tab = load_sheeting(geo.materials["sheeting"])
    em = ill.positions_cam_m()
    n = R @ np.array([0.0, 0.0, 1.0])
    P = geo.marker_centres_m @ R.T + t
    uv = cam.project(P)
    r_px = cam.fx * geo.marker_radius_m / P[:, 2]
    gap = np.stack([np.hypot(u - a, v - b) - rr for (a, b), rr in zip(uv, r_px)])  # px beyond each rim
    owner = np.argmin(gap, axis=0)

    def irradiance(p):  # per emitter: unit vector to it and W/m^2 across the beam
        w = em - p
        d = np.linalg.norm(w, axis=1)
        return w / d[:, None], ill.intensity_w_sr * (-w[:, 2] / d) ** ill.cos_exponent / d**2

    got, want = [], []
    for k, (p, rad) in enumerate(zip(P, geo.marker_radius_m)):
        region = (owner == k) & (gap[k] < r.blur_radius_px(p[2]) + 3)
        got.append(float(np.sum(rd.active_radiance[region] * omega[region])))
        to_cam = -p / np.linalg.norm(p)
        w, E = irradiance(p)
        alpha = np.degrees(2 * np.arcsin(np.linalg.norm(w - to_cam, axis=1) / 2))
        beta = np.degrees(np.arccos(w @ n))
        L = np.sum((tab.ra(alpha, beta) / (n @ to_cam) + tab.diffuse_albedo / np.pi * (w @ n)) * E)
        face_sr = np.pi * rad**2 * (n @ to_cam) / (p @ p)
        p_plate = p - (geo.marker_centres_m[k][2] - geo.plate_centre_m[2]) * n  # the plate behind the face
        w, E = irradiance(p_plate)
        L_plate = geo.albedo["plate"] / np.pi * np.sum((w @ n) * E)
        want.append(float(L * face_sr + L_plate * (np.sum(omega[region]) - face_sr)))
    return np.array(got), np.array(want)


def test_sobol_estimator_has_the_expectation_of_the_independent_one():
    """Issue 23: the default estimator (Owen-scrambled Sobol' film x aperture x emitter, more
    samples on the marker rims) against the earlier one (R2 film, independent aperture and
    emitter, uniform spp), 5.712 m head-on: per pixel the means of many seeds agree within
    their Monte Carlo error, and each marker's flux agrees within 0.5 % and with the flux
    predicted from the sheeting's R_A and the emitters' irradiance (1/d^2, cos^m)."""
    R, t = pose_from_scenario(5.712)
    old = TofRenderer(sampler="r2", spp=1024, rim_spp_factor=1)
    new = TofRenderer()
    a = np.array([old.render(R, t, seed=s).active_radiance for s in range(24)])
    b_r = [new.render(R, t, seed=s) for s in range(4)]
    b = np.array([x.active_radiance for x in b_r])
    lit = a.mean(0) > 1e-3 * a.mean(0).max()
    se = np.sqrt(a.var(0, ddof=1) / len(a) + b.var(0, ddof=1) / len(b))[lit]
    z = (b.mean(0) - a.mean(0))[lit] / np.maximum(se, 1e-12 * a.max())
    assert lit.sum() > 100
    # z is not quite normal where the old estimator's 1024 samples meet a marker only a few
    # times (pixels at the edge of the blur: max |z| 4.7 here, 2.2 sigma with 100 more seeds)
    assert np.mean(np.abs(z) > 3) < 0.02 and np.abs(z).max() < 6 and 0.3 < np.mean(z**2) < 2.0, \
        (np.abs(z).max(), np.mean(z**2))
    # the new one is far less noisy per render (here > 5x in the median over the lit pixels)
    assert np.median(np.sqrt(b.var(0, ddof=1))[lit] / np.sqrt(a.var(0, ddof=1))[lit]) < 0.2
    from types import SimpleNamespace

    f_old, f_pred = _marker_flux(SimpleNamespace(active_radiance=a.mean(0)), old, R, t)  # linear in the radiance
    f_new = np.array([_marker_flux(x, new, R, t)[0] for x in b_r])
    np.testing.assert_allclose(f_new[0], f_old, rtol=5e-3)  # one render of the new vs 24 of the old
    np.testing.assert_allclose(f_new.mean(0), f_pred, rtol=5e-3)
