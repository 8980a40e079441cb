"""svgs_sim.sim.orbit_light: the sun's direction against the Astronomical Almanac's low-precision
formula, the azimuth/elevation convention against a frame built by hand, the beta angle, and the
eclipse against Basilisk's own ``eclipse`` module over one 400 km orbit (skipped with its reason
where the basilisk extra is missing)."""

from datetime import datetime

import numpy as np
import pytest

from svgs_sim.base.errors import InputError
from svgs_sim.render.earth import EARTH_RADIUS_M
from svgs_sim.render.sun import sun_direction_target
from svgs_sim.sim.orbit_light import (
    SUN_EPOCH_UTC,
    beta_angle_deg,
    sun_and_earth_in_target,
    sun_direction_gcrs,
)


def _angle_deg(a, b):
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b)), a @ b)))


def _almanac_sun_j2000(epoch_utc: str) -> np.ndarray:
    """The sun's direction, J2000 equator and equinox, from the Astronomical Almanac's low-precision
    formula (section C, "Low precision formulas for the Sun": 0.01 deg from 1950 to 2050)."""
    n = (datetime.fromisoformat(epoch_utc) - datetime(2000, 1, 1, 12)).total_seconds() / 86400.0  # JD - 2451545.0
    L = 280.460 + 0.9856474 * n
    g = np.radians(357.528 + 0.9856003 * n)
    lam = L + 1.915 * np.sin(g) + 0.020 * np.sin(2 * g)  # ecliptic longitude, mean equinox of date
    # to the J2000 equinox: less the general precession in longitude, 5029.0966 arcsec per Julian
    # century (Lieske et al. 1977) (0.36 deg by 2026: seven times the tolerance); the ecliptic's own
    # motion, 47 arcsec per century, is left out (< 0.004 deg here), and the obliquity is J2000's
    lam_j2000 = np.radians(lam - 5029.0966 / 3600.0 * n / 36525.0)
    eps = np.radians(84381.448 / 3600.0)
    return np.array([np.cos(lam_j2000), np.cos(eps) * np.sin(lam_j2000), np.sin(eps) * np.sin(lam_j2000)])


@pytest.mark.parametrize("epoch", ["2000-01-01T12:00:00", SUN_EPOCH_UTC, "2031-08-09T05:30:00"])
def test_sun_direction_matches_the_almanac_formula(epoch):
    s = sun_direction_gcrs(epoch)
    assert s.shape == (3,) and abs(np.linalg.norm(s) - 1.0) < 1e-12
    err = _angle_deg(s, _almanac_sun_j2000(epoch))
    assert err < 0.05, f"{epoch}: astropy vs the Almanac's formula, {err:.4f} deg"


def test_default_epoch_is_the_stated_one_near_the_equinox():
    s = sun_direction_gcrs()
    np.testing.assert_array_equal(s, sun_direction_gcrs(SUN_EPOCH_UTC))
    # near the March equinox the sun is near the equinox's direction, +x (J2000's is 0.36 deg off)
    assert _angle_deg(s, [1.0, 0.0, 0.0]) < 1.0
    with pytest.raises(InputError, match="epoch_utc"):
        sun_direction_gcrs("the spring equinox")


# a target frame built by hand: its x is inertial +y, its y inertial +z, its z inertial +x
# (rows: the target's axes in inertial components)
DCM_T_N = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
R_EQUATOR_M = EARTH_RADIUS_M + 400e3


@pytest.mark.parametrize("sun_N, az_deg, el_deg", [
    ([1.0, 1.0, 0.0], 0.0, 45.0),  # target (s_y, s_z, s_x) = (0.707, 0, 0.707)
    ([0.0, -1.0, np.sqrt(3.0)], 120.0, 0.0),  # (-1/2, sqrt(3)/2, 0)
    ([-0.5, -0.5, -np.sqrt(0.5)], -180.0 + np.degrees(np.arctan(np.sqrt(0.5) / 0.5)), -30.0),  # (-1/2, -0.707, -1/2)
    ([0.0, 1.0, 0.0], 0.0, 0.0),  # the target's +x
])
def test_azimuth_elevation_in_a_hand_built_frame(sun_N, az_deg, el_deg):
    # the target on the equator at -y: the Earth's centre along inertial +y, the target's +x
    out = sun_and_earth_in_target([0.0, -R_EQUATOR_M, 0.0], DCM_T_N, sun_N)
    assert out["sun_azimuth_deg"] == pytest.approx(az_deg, abs=1e-9)
    assert out["sun_elevation_deg"] == pytest.approx(el_deg, abs=1e-9)
    assert out["earth_azimuth_deg"] == pytest.approx(0.0, abs=1e-9)
    assert out["earth_elevation_deg"] == pytest.approx(0.0, abs=1e-9)
    # round trip through the scene's convention (--sun-deg AZ,EL): back to the inertial direction
    v_T = sun_direction_target(out["sun_azimuth_deg"], out["sun_elevation_deg"])
    np.testing.assert_allclose(DCM_T_N.T @ v_T, np.asarray(sun_N) / np.linalg.norm(sun_N), atol=1e-12)


def test_earth_direction_and_altitude_in_a_hand_built_frame():
    # the target below the equator plane, at -z: the Earth's centre along inertial +z, the target's +y
    out = sun_and_earth_in_target([0.0, 0.0, -R_EQUATOR_M], DCM_T_N, [1.0, 0.0, 0.0])
    assert (out["earth_azimuth_deg"], out["earth_elevation_deg"]) == pytest.approx((90.0, 0.0), abs=1e-9)
    assert out["altitude_m"] == pytest.approx(400e3, abs=1e-6)
    assert out["earth_half_angle_deg"] == pytest.approx(np.degrees(np.arcsin(EARTH_RADIUS_M / R_EQUATOR_M)))
    # at -x: the Earth's centre along inertial +x, the target's +z
    out = sun_and_earth_in_target([-R_EQUATOR_M, 0.0, 0.0], DCM_T_N, [1.0, 0.0, 0.0])
    assert out["earth_elevation_deg"] == pytest.approx(90.0, abs=1e-9)


def test_eclipse_is_the_sun_behind_the_earths_disk():
    r = [R_EQUATOR_M, 0.0, 0.0]
    assert sun_and_earth_in_target(r, np.eye(3), [-1.0, 0.0, 0.0])["eclipsed"]  # midnight
    assert not sun_and_earth_in_target(r, np.eye(3), [1.0, 0.0, 0.0])["eclipsed"]  # noon
    # the limb from 400 km: the sun 70.2 deg from the Earth's centre; 0.1 deg either side
    half = np.degrees(np.arcsin(EARTH_RADIUS_M / R_EQUATOR_M))
    for off_deg, dark in ((-0.1, True), (0.1, False)):
        a = np.radians(180.0 - half - off_deg)  # angle from the zenith (+x)
        assert sun_and_earth_in_target(r, np.eye(3), [np.cos(a), np.sin(a), 0.0])["eclipsed"] is dark


def test_bad_inputs_are_refused():
    with pytest.raises(InputError, match="dcm_target_N"):
        sun_and_earth_in_target([R_EQUATOR_M, 0, 0], np.diag([1.0, 1.0, -1.0]), [1, 0, 0])
    with pytest.raises(InputError, match="surface"):
        sun_and_earth_in_target([EARTH_RADIUS_M - 1.0, 0, 0], np.eye(3), [1, 0, 0])
    with pytest.raises(InputError, match="sun_N"):
        sun_and_earth_in_target([R_EQUATOR_M, 0, 0], np.eye(3), [0, 0, 0])
    with pytest.raises(InputError, match="r_target_N_m"):
        sun_and_earth_in_target([R_EQUATOR_M, 0], np.eye(3), [1, 0, 0])
    with pytest.raises(InputError, match="orbit plane"):
        beta_angle_deg([R_EQUATOR_M, 0, 0], [1.0, 0, 0], [0, 0, 1])


def test_beta_angle():
    r, v = [R_EQUATOR_M, 0.0, 0.0], [0.0, 7.67e3, 0.0]  # orbit normal +z
    assert beta_angle_deg(r, v, [0.0, 0.0, 2.0]) == pytest.approx(90.0)
    assert beta_angle_deg(r, v, [0.0, 0.0, -1.0]) == pytest.approx(-90.0)
    assert beta_angle_deg(r, v, [1.0, 1.0, 0.0]) == pytest.approx(0.0, abs=1e-12)
    assert beta_angle_deg(r, v, [0.0, 1.0, 1.0]) == pytest.approx(45.0)


def _crossing_s(t, y, level, k):
    """The time where ``y`` crosses ``level`` between samples k and k + 1, linearly."""
    return float(t[k] + (level - y[k]) / (y[k + 1] - y[k]) * (t[k + 1] - t[k]))


def _basilisk_orbit(sun_N, inclination_deg, raan_deg, step_s=1.0):
    """One orbit, 400 km above Basilisk's equatorial radius, circular, from the ascending node; two
    ``eclipse`` modules on it: Basilisk's Earth (equatorial radius) and a "custom" planet of our
    mean radius. The sun is a fixed SPICE message 1 AU along ``sun_N``, the Earth one at the origin.
    Returns the times (s), r_BN_N (m), the two shadow factors, and the initial r, v."""
    from Basilisk.architecture import messaging
    from Basilisk.simulation import eclipse, spacecraft
    from Basilisk.utilities import (
        SimulationBaseClass,
        macros,
        orbitalMotion,
        simIncludeGravBody,
    )

    sim = SimulationBaseClass.SimBaseClass()
    proc = sim.CreateNewProcess("p")
    proc.addTask(sim.CreateNewTask("dyn", macros.sec2nano(step_s)))
    grav = simIncludeGravBody.gravBodyFactory()
    earth = grav.createEarth()
    earth.isCentralBody = True
    sc = spacecraft.Spacecraft()
    sc.ModelTag = "target"
    grav.addBodiesTo(sc)
    oe = orbitalMotion.ClassicElements()
    oe.a, oe.e, oe.i = orbitalMotion.REQ_EARTH * 1e3 + 400e3, 0.0, np.radians(inclination_deg)
    oe.Omega, oe.omega, oe.f = np.radians(raan_deg), 0.0, 0.0
    r0, v0 = orbitalMotion.elem2rv(earth.mu, oe)
    sc.hub.r_CN_NInit, sc.hub.v_CN_NInit = r0.tolist(), v0.tolist()
    sim.AddModelToTask("dyn", sc, 10)

    def planet(name, pos_m):
        p = messaging.SpicePlanetStateMsgPayload()
        p.PositionVector = [float(x) for x in pos_m]
        p.PlanetName = name
        return messaging.SpicePlanetStateMsg().write(p)

    msgs = [planet("sun", orbitalMotion.AU * 1e3 * np.asarray(sun_N)), planet("earth", np.zeros(3)),
            planet("custom", np.zeros(3))]  # kept alive: the modules subscribe to them
    recs = [sc.scStateOutMsg.recorder()]
    mods = []
    for i, tag in enumerate(("eclipse_equatorial", "eclipse_mean")):
        ecl = eclipse.Eclipse()
        ecl.ModelTag = tag
        ecl.sunInMsg.subscribeTo(msgs[0])
        ecl.addPlanetToModel(msgs[1 + i])
        if tag == "eclipse_mean":
            ecl.rEqCustom = EARTH_RADIUS_M
        ecl.addSpacecraftToModel(sc.scStateOutMsg)
        sim.AddModelToTask("dyn", ecl, 5)  # after the spacecraft: the same step's state
        recs.append(ecl.eclipseOutMsgs[0].recorder())
        mods.append(ecl)
    for rec in recs:
        sim.AddModelToTask("dyn", rec, 0)
    sim.InitializeSimulation()
    period_s = 2 * np.pi * np.sqrt(oe.a**3 / earth.mu)
    sim.ConfigureStopTime(macros.sec2nano(np.ceil(period_s)))
    sim.ExecuteSimulation()
    t_s = recs[0].times() * 1e-9
    assert np.array_equal(t_s, recs[1].times() * 1e-9)
    return t_s, np.asarray(recs[0].r_BN_N), np.asarray(recs[1].illuminationFactor), np.asarray(recs[2].illuminationFactor), r0, v0


def test_eclipse_matches_basilisks_eclipse_module():
    """Our umbra-only cylindrical shadow against Basilisk's conical one with the penumbra, one ISS-like
    orbit (400 km, 51.6 deg, the node 30 deg from the sun: beta 23 deg), 1 s steps."""
    pytest.importorskip("Basilisk", reason="the basilisk extra is not installed (pip install -e \".[basilisk]\")")
    s = sun_direction_gcrs()
    t, r, f_eq, f_mean, r0, v0 = _basilisk_orbit(s, 51.6, 30.0)
    # the beta angle by hand: the orbit normal (sin W sin i, -cos W sin i, cos i)
    i, w = np.radians(51.6), np.radians(30.0)
    h = [np.sin(w) * np.sin(i), -np.cos(w) * np.sin(i), np.cos(i)]
    assert beta_angle_deg(r0, v0, s) == pytest.approx(np.degrees(np.arcsin(h @ s)), abs=1e-6)

    ours = np.array([sun_and_earth_in_target(x, np.eye(3), s)["eclipsed"] for x in r])
    assert ours.any() and not ours.all(), "no eclipse (or no light) over the orbit"
    step = t[1] - t[0]
    changes = np.flatnonzero(np.diff(ours.astype(int))) + 1
    assert len(changes) == 2, f"one eclipse expected, transitions at {t[changes]} s"
    entry, exit_ = changes  # our first eclipsed sample; our first sunlit one after it
    # our margin (angle sun - Earth's centre less the Earth's half-angle), for sub-step times
    rn = np.linalg.norm(r, axis=1)
    margin = np.degrees(np.arccos(np.clip(-(r @ s) / rn, -1, 1)) - np.arcsin(EARTH_RADIUS_M / rn))
    ours_s = [_crossing_s(t, margin, 0.0, k - 1) for k in (entry, exit_)]
    report = []
    for name, f in (("equatorial radius (Basilisk's Earth)", f_eq), ("mean radius (ours, 'custom')", f_mean)):
        # Basilisk's penumbra around each transition: the last sample fully lit before, the first dark
        lit, dark = np.flatnonzero(f == 1.0), np.flatnonzero(f == 0.0)
        assert dark.size, f"{name}: Basilisk sees no umbra"
        enter_lo, enter_hi = t[lit[lit < dark[0]][-1]] - step, t[dark[0]] + step
        leave_lo, leave_hi = t[dark[-1]] - step, t[lit[lit > dark[-1]][0]] + step
        half = [_crossing_s(t, f, 0.5, k) for k in np.flatnonzero(np.diff(np.sign(f - 0.5)))]
        d = [o - b for o, b in zip(ours_s, half)]
        report.append(f"{name}: entry {d[0]:+.2f} s, exit {d[1]:+.2f} s from its half-light points "
                      f"(penumbra {enter_hi - enter_lo - 2 * step:.0f} s, {leave_hi - leave_lo - 2 * step:.0f} s)")
        assert enter_lo <= t[entry] <= enter_hi and leave_lo <= t[exit_] <= leave_hi, "; ".join(report)
        # our flag is Basilisk's half light except inside its penumbra
        differ = np.flatnonzero(ours != (f < 0.5))
        assert np.all((f[differ] > 0.0) & (f[differ] < 1.0)), "; ".join(report)
        assert len(differ) <= 10, "; ".join(report)
    # with the same radius, the two models differ by the sun's disk only: the half-light points
    # are the sun's centre on the limb, our transitions (the sun at infinity: its 1 AU parallax is
    # 0.003 deg, 0.05 s)
    assert max(abs(x) for x in d) < 0.2, "; ".join(report)
    print("; ".join(report))
