"""The SVGS Basilisk module (svgs_sim.sim.basilisk_svgs) inside a Basilisk simulation.

Skipped, with the reason, where the ``basilisk`` extra is not installed. The geometry of each
case is set by hand (bodies drifting without gravity, so their states at any time are known
without Basilisk), and the expected measurement is :meth:`svgs_sim.sim.approach.ApproachSensor.measure`
of a second sensor given that hand-made pose.
"""

import importlib
import sys

import numpy as np
import pytest

D = np.diag([1.0, -1.0, -1.0])
#: The chaser's start (m), its velocity (m/s); target at rest at the origin with N's axes; the
#: chaser's camera (= its body) turned 180 deg about x (sigma = (1, 0, 0)) to look down -z_N.
R0_M = np.array([0.1, -0.05, 6.0])
V_M_S = np.array([0.0, 0.0, -0.2])


def test_import_without_basilisk_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "Basilisk", None)  # "import Basilisk..." now fails as if absent
    monkeypatch.delitem(sys.modules, "Basilisk.architecture", raising=False)
    monkeypatch.delitem(sys.modules, "svgs_sim.sim.basilisk_svgs", raising=False)
    with pytest.raises(ImportError, match=r"pip install -e \"\.\[basilisk\]\""):
        importlib.import_module("svgs_sim.sim.basilisk_svgs")
    monkeypatch.delitem(sys.modules, "svgs_sim.sim.basilisk_svgs", raising=False)


def _sim(module, stop_s, task_s=0.25):
    """Two drifting spacecraft (no gravity) and the module, run to ``stop_s``."""
    pytest.importorskip("Basilisk", reason="the basilisk extra is not installed (pip install -e \".[basilisk]\")")
    from Basilisk.simulation import spacecraft
    from Basilisk.utilities import SimulationBaseClass, macros

    sim = SimulationBaseClass.SimBaseClass()
    proc = sim.CreateNewProcess("p")
    proc.addTask(sim.CreateNewTask("dyn", macros.sec2nano(task_s)))
    tgt, ch = spacecraft.Spacecraft(), spacecraft.Spacecraft()
    tgt.ModelTag, ch.ModelTag = "target", "chaser"
    ch.hub.r_CN_NInit = R0_M.tolist()
    ch.hub.v_CN_NInit = V_M_S.tolist()
    ch.hub.sigma_BNInit = [[1.0], [0.0], [0.0]]
    for sc in (tgt, ch):
        sim.AddModelToTask("dyn", sc, 10)
    module.ModelTag = "svgs"
    module.chaserStateInMsg.subscribeTo(ch.scStateOutMsg)
    module.targetStateInMsg.subscribeTo(tgt.scStateOutMsg)
    rec = module.opNavOutMsg.recorder()
    sim.AddModelToTask("dyn", module, 1)
    sim.AddModelToTask("dyn", rec, 0)
    sim.InitializeSimulation()
    sim.ConfigureStopTime(macros.sec2nano(stop_s))
    sim.ExecuteSimulation()
    return rec


def _hand_pose(t_s):
    r_c = R0_M + V_M_S * t_s
    return D.copy(), D @ (np.zeros(3) - r_c)  # [CN] = D, t = [CN](r_T - r_C)


def test_ideal_sensor_frames_latency_and_opnav_message():
    pytest.importorskip("Basilisk", reason="the basilisk extra is not installed (pip install -e \".[basilisk]\")")
    from svgs_sim.sim.basilisk_frames import Mount
    from svgs_sim.sim.basilisk_svgs import IdealSensor, SVGSModule

    mod = SVGSModule(IdealSensor(), Mount(), Mount(), frame_rate_hz=2.0, latency_s=0.3)
    rec = _sim(mod, 2.0, task_s=0.1)
    hist = mod.measurementOutMsg.history
    # frames at 0, 0.5, 1.0, 1.5, 2.0 s; released 0.3 s later: four by 2.0 s
    np.testing.assert_allclose([m.t_image_s for m in hist], [0.0, 0.5, 1.0, 1.5], atol=1e-9)
    np.testing.assert_allclose([m.t_available_s for m in hist], [0.3, 0.8, 1.3, 1.8], atol=1e-9)
    for m in hist:
        r_c = R0_M + V_M_S * m.t_image_s
        # the camera's position in the target frame is the chaser's position; zero attitude
        np.testing.assert_allclose([m.state[k] for k in ("x_m", "y_m", "z_m")], r_c, atol=1e-9)
        np.testing.assert_allclose([m.state[k] for k in ("roll_deg", "pitch_deg", "yaw_deg")], 0.0, atol=1e-9)
        assert m.ok and m.reason is None
    # Basilisk's OpNav message: written when released, stamped with the image's time; r_BN_C
    # is the camera relative to the target in the camera frame, r_BN_N the same in N.
    times = rec.times() * 1e-9
    tags = np.asarray(rec.timeTag)
    valid = np.asarray(rec.valid)
    i = int(np.argmin(np.abs(times - 0.8)))
    assert valid[i] == 1 and tags[i] == pytest.approx(0.5)
    np.testing.assert_allclose(np.asarray(rec.r_BN_N)[i], R0_M + V_M_S * 0.5, atol=1e-9)
    np.testing.assert_allclose(np.asarray(rec.r_BN_C)[i], D @ (R0_M + V_M_S * 0.5), atol=1e-9)
    assert valid[int(np.argmin(np.abs(times - 0.2)))] == 0  # nothing released before 0.3 s


@pytest.mark.render
def test_module_measurement_equals_approach_sensor(small_camera):
    pytest.importorskip("Basilisk", reason="the basilisk extra is not installed (pip install -e \".[basilisk]\")")
    from svgs_sim.sim.approach import ApproachSensor
    from svgs_sim.sim.basilisk_frames import Mount
    from svgs_sim.sim.basilisk_svgs import SVGSModule

    kw = dict(seed=3, keep_images=True, frame_rate_hz=2.0)
    mod = SVGSModule(ApproachSensor(small_camera, **kw), Mount(), Mount(), frame_rate_hz=2.0, latency_s=0.25)
    _sim(mod, 0.75)
    hist = mod.measurementOutMsg.history
    assert [m.t_image_s for m in hist] == [0.0, 0.5]
    ref = ApproachSensor(small_camera, **kw)
    for m in hist:
        R, t = _hand_pose(m.t_image_s)
        h = 1e-3
        vel = (ref.targets_px(*_hand_pose(m.t_image_s + h)) - ref.targets_px(*_hand_pose(m.t_image_s - h))) / (2 * h)
        e = ref.measure(m.t_image_s, R, t, image_velocity_px_s=vel)
        assert e.ok and m.ok and m.reason == e.reason
        for k in e.estimate:
            assert m.state[k] == pytest.approx(e.estimate[k], rel=1e-9, abs=1e-12), k
            assert m.crlb_std[k] == pytest.approx(e.crlb_std[k], rel=1e-9), k
            assert m.truth[k] == pytest.approx(e.truth[k], rel=1e-12, abs=1e-12), k
        assert m.p_value == pytest.approx(e.p_value, rel=1e-9)
        # the 6 x 6 covariance's diagonal is the CRLB per component (m, rad)
        std = np.sqrt(np.diag(m.covariance))
        np.testing.assert_allclose(std[:3], [e.crlb_std[k] for k in ("x_m", "y_m", "z_m")], rtol=1e-9)
        np.testing.assert_allclose(np.degrees(std[3:]), [e.crlb_std[k] for k in ("roll_deg", "pitch_deg", "yaw_deg")],
                                   rtol=1e-9)


class _SceneRecorder:
    """A sensor that records the scenario each frame is measured in (no rendering)."""

    frame_rate_hz = None

    def __init__(self):
        from svgs_sim.sim.closed_loop import Scenario

        self.base = Scenario()
        self.frame_index = 0
        self.scenarios = []

    def measure(self, t_s, R_cam_target=None, t_cam_target_m=None, *, scenario=None, image_velocity_px_s=None):
        from svgs_sim.sim.basilisk_svgs import IdealSensor

        self.scenarios.append(scenario)
        R, t = scenario.pose()
        return IdealSensor().measure(t_s, R, t)


@pytest.mark.parametrize("sun_dir,shadow,expect_sun", [
    ((0.0, 1.0, 0.0), None, (90.0, 0.0)),     # the sun along +y_N: lit, azimuth 90 in the target frame (= N)
    ((0.0, 1.0, 0.0), 0.2, None),             # Basilisk's eclipse module says shadow: no sun
    ((-1.0, 0.0, 0.0), None, None),           # the sun behind the Earth: the cylindrical shadow
])
def test_the_module_sets_each_frames_sun_and_earth_from_the_orbit(sun_dir, shadow, expect_sun):
    """The target 400 km above the Earth's surface on +x_N, its frame = N: the Earth's centre lies at
    azimuth 180, elevation 0 of the target frame (-x), the sun along ``sun_dir``; by hand."""
    pytest.importorskip("Basilisk", reason="the basilisk extra is not installed (pip install -e \".[basilisk]\")")
    from Basilisk.architecture import messaging
    from Basilisk.simulation import spacecraft
    from Basilisk.utilities import SimulationBaseClass, macros

    from svgs_sim.render.earth import EARTH_RADIUS_M
    from svgs_sim.sim.basilisk_frames import Mount
    from svgs_sim.sim.basilisk_svgs import SVGSModule

    r_t = np.array([EARTH_RADIUS_M + 400e3, 0.0, 0.0])
    sensor = _SceneRecorder()
    mod = SVGSModule(sensor, Mount(), Mount(), frame_rate_hz=2.0, latency_s=0.0)
    sim = SimulationBaseClass.SimBaseClass()
    proc = sim.CreateNewProcess("p")
    proc.addTask(sim.CreateNewTask("dyn", macros.sec2nano(0.5)))
    tgt, ch = spacecraft.Spacecraft(), spacecraft.Spacecraft()
    tgt.hub.r_CN_NInit = r_t.tolist()
    ch.hub.r_CN_NInit = (r_t + [0.0, 0.0, 6.0]).tolist()
    ch.hub.sigma_BNInit = [[1.0], [0.0], [0.0]]  # the camera looks down -z_N at the pattern
    for sc in (tgt, ch):
        sim.AddModelToTask("dyn", sc, 10)
    sun = messaging.SpicePlanetStateMsgPayload()
    sun.PositionVector = (1.496e11 * np.array(sun_dir)).tolist()
    sun_msg = messaging.SpicePlanetStateMsg().write(sun)
    mod.sunInMsg.subscribeTo(sun_msg)
    if shadow is not None:
        ecl = messaging.EclipseMsgPayload()
        ecl.illuminationFactor = shadow
        ecl_msg = messaging.EclipseMsg().write(ecl)
        mod.eclipseInMsg.subscribeTo(ecl_msg)
    mod.chaserStateInMsg.subscribeTo(ch.scStateOutMsg)
    mod.targetStateInMsg.subscribeTo(tgt.scStateOutMsg)
    sim.AddModelToTask("dyn", mod, 1)
    sim.InitializeSimulation()
    sim.ConfigureStopTime(macros.sec2nano(0.5))
    sim.ExecuteSimulation()
    assert len(sensor.scenarios) == 2
    for sc, log in zip(sensor.scenarios, mod.light_log):
        s = sc.scene
        assert s.environment == "orbit"
        assert (s.earth_azimuth_deg, s.earth_elevation_deg) == pytest.approx((180.0, 0.0), abs=1e-9)
        assert s.altitude_km == pytest.approx(400.0, abs=1e-6)
        assert sc.range_m == pytest.approx(6.0, abs=1e-6)
        if expect_sun is None:
            assert not log["sunlit"]
            # dropped (Basilisk's shadow, the geometry lit), or kept for the Earth's light with the renderer's
            # own shadow hiding the disk
            assert s.sun_azimuth_deg is None if shadow is not None else s.eclipsed
        else:
            assert log["sunlit"] and log["shadow_factor"] == 1.0
            # from the target, not the Earth's centre: the sun 1 AU along +y_N is seen 0.0026 deg past 90
            az = np.degrees(np.arctan2(1.496e11, -r_t[0])) if expect_sun[0] == 90.0 else expect_sun[0]
            assert (s.sun_azimuth_deg, s.sun_elevation_deg) == pytest.approx((az, expect_sun[1]), abs=1e-9)
