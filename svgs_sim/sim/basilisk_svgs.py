"""The simulated SVGS sensor as a Basilisk flight-software module (a Python ``SysModel``).

:class:`SVGSModule` reads the chaser's and the target's ``SCStatesMsg`` (Basilisk's
``Spacecraft.scStateOutMsg``), forms the sensor's pose in the paper's frames
(:mod:`svgs_sim.sim.basilisk_frames`: the camera frame on the chaser, the target frame on the target),
calls the simulated sensor (:class:`svgs_sim.sim.approach.ApproachSensor`: render, phone, detect,
identify, solve, Cramer-Rao bound) at the phone's frame rate, and releases each measurement
``latency_s`` after its image was taken, stamped with the image's time.

Outputs
    ``measurementOutMsg``
        The whole measurement (:class:`SVGSMeasurement`: the paper's state, its 6 x 6 CRLB
        covariance, the consistency test's p-value and residual, ``ok`` and the failure reason,
        the image time and the release time). Basilisk's message payloads are C structures
        generated when Basilisk is built; a new payload cannot be declared from Python. So this
        output is a Python-side message (:class:`MeasurementOutput`: ``read()``, ``isWritten()``,
        and every released measurement in ``history``), which other Python modules read.
    ``opNavOutMsg``
        The position part as Basilisk's own ``OpNavMsgPayload`` (for Basilisk's C/C++ relative
        navigation modules): ``r_BN_C``, ``r_BN_B``, ``r_BN_N`` the camera relative to the
        target pattern's origin in the camera frame, the chaser's body frame and inertial
        components (the last with the chaser's attitude from its state message: perfect attitude
        knowledge), their covariances from the CRLB, ``valid`` = ``ok``, ``timeTag`` the image
        time, s. An unsolved frame is written with ``valid = 0`` and ``faultDetected = 1``.

The sun and the Earth (optional inputs)
    ``sunInMsg`` (a ``SpicePlanetStateMsg``: the sun's inertial position) and ``eclipseInMsg``
    (an ``EclipseMsg``, from Basilisk's ``eclipse`` module for the target). With ``sunInMsg``
    linked, each frame is rendered on orbit (:mod:`svgs_sim.sim.orbit_light`): the sun's and the
    Earth's directions in the target frame from the target's state (the Earth is the central body,
    at the inertial origin) and its altitude. The frame is sunlit while ``illuminationFactor >= 0.5``
    (without ``eclipseInMsg``: the cylindrical shadow of :func:`svgs_sim.render.earth.in_eclipse`)
    and the renderer's own shadow agrees; in shadow the Earth's day side, where in view, still
    shines. The renderer cannot dim the sun, so the penumbra (~10 s at 400 km) is lit or not, at
    half light. ``light_log`` keeps each frame's light.

Timing. The module must run in a task at least as fast as the frame rate. A frame is taken at the
first update at or after each frame time ``t0 + k / frame_rate_hz`` (``t0``: the first update),
with the states of that update; its measurement is written at the first update at or after
``t_image + latency_s``.

Basilisk is optional (``pip install -e ".[basilisk]"``); importing this module without it
raises an ImportError that names the extra. Nothing here needs Vizard.
"""

from __future__ import annotations

import dataclasses
import warnings
from dataclasses import dataclass, field

import numpy as np

try:
    from Basilisk.architecture import messaging, sysModel
except ImportError as exc:  # pragma: no cover - exercised where the extra is missing
    raise ImportError("svgs_sim.sim.basilisk_svgs needs Basilisk (the bsk package): install the extra with "
                      "pip install -e \".[basilisk]\"") from exc

from svgs_sim.base.errors import InputError, check_finite_positive
from svgs_sim.svgs.frames import STATE_KEYS, pose_to_state, state_dict, state_to_pose

from svgs_sim.sim.approach import OUT_OF_VIEW, Measurement, scenario_from_pose
from svgs_sim.sim.basilisk_frames import Mount, mrp_to_dcm, propagate_body, relative_pose
from svgs_sim.sim.orbit_light import sun_and_earth_in_target
from svgs_sim.sim.scene import Scene

#: The phone's frame rate, frames/s (ASSUMPTION: the SVGS papers on these 2011 phones do not give
#: the rate at which the app delivered solutions; 2 frames/s is the rate the project's own loop
#: example uses, ``examples/approach_kalman.py``, and below the 30 frames/s preview stream).
PHONE_FRAME_RATE_HZ = 2.0
#: Time from an image's exposure to its solution's release, s (ASSUMPTION: not published for the
#: SVGS app; a quarter second for a 2011 phone's Java blob extraction and solve on a 5 Mpx frame,
#: an order of magnitude only. Our own processing on a PC, ``timings_s["solve"]``, is ~5 ms and
#: is not the phone's).
PROCESSING_LATENCY_S = 0.25
#: Half-step of the central difference that gives the spots' image velocity from the two bodies'
#: velocities and angular velocities, s (as :data:`svgs_sim.sim.approach.VELOCITY_STEP_S`).
VELOCITY_STEP_S = 1e-3
#: Step of the numerical Jacobian of the camera position with respect to the paper's state (m, rad).
JACOBIAN_STEP = 1e-6
#: The 1-sigma the ideal sensor reports (m for positions, deg for angles): a filter needs a
#: positive measurement variance; these are far below anything the guidance resolves.
IDEAL_STD = {"x_m": 1e-4, "y_m": 1e-4, "z_m": 1e-4, "roll_deg": 1e-3, "pitch_deg": 1e-3, "yaw_deg": 1e-3}


@dataclass
class SVGSMeasurement:
    """One measurement as the module releases it.

    Attributes
    ----------
    t_image_s : float
        Simulation time of the image (the frame's timestamp), s.
    t_available_s : float
        Simulation time the measurement is released: ``t_image_s + latency_s``.
    frame : int
    ok : bool
    reason : str or None
        Why there is no solution (:class:`svgs_sim.sim.approach.Measurement` reasons; ``out_of_view``
        also for a target behind the camera).
    state : dict or None
        The solved paper's state (:data:`svgs_sim.svgs.frames.STATE_KEYS`, m and deg).
    state_vector : ndarray, shape (6,), or None
        The same in m and rad (:func:`svgs_sim.svgs.frames.state_to_pose` order).
    covariance : ndarray, shape (6, 6), or None
        The frame's Cramer-Rao covariance of ``state_vector`` (m^2, m rad, rad^2): the solver's
        unit-noise covariance scaled by the frame's centroid bound (:func:`svgs_sim.sim.crlb.pose_crlb`);
        diagonal from ``crlb_std`` when the sensor keeps no solution.
    crlb_std : dict or None
        1-sigma CRLB per component (m, deg).
    p_value : float or None
        The consistency test's p-value (:func:`svgs_sim.svgs.app.consistency`).
    residual_rms_px : float or None
        The solution's reprojection residual, px (the test's statistic).
    truth : dict
        The true paper's state at ``t_image_s`` (m, deg).
    range_m : float
        Along the boresight to the target's origin at ``t_image_s``.
    sensor_measurement : svgs_sim.sim.approach.Measurement or None
        What the sensor returned (its delivered image dropped).
    sigma_chaser_BN : ndarray, shape (3,), or None
        The chaser's attitude at ``t_image_s`` (for the inertial components of ``opNavOutMsg``).
    """

    t_image_s: float
    t_available_s: float
    frame: int
    ok: bool
    reason: str | None
    state: dict | None
    state_vector: np.ndarray | None
    covariance: np.ndarray | None
    crlb_std: dict | None
    p_value: float | None
    residual_rms_px: float | None
    truth: dict
    range_m: float
    sensor_measurement: Measurement | None = field(default=None, repr=False)
    sigma_chaser_BN: np.ndarray | None = field(default=None, repr=False)


class MeasurementOutput:
    """The Python-side output message of :class:`SVGSModule` (see the module docstring).

    ``read()`` gives the latest :class:`SVGSMeasurement`, ``isWritten()`` whether there is one,
    ``history`` every one in release order, and ``since(n)`` those after the first ``n``
    (a reader keeps its own ``n``, so a slower task misses none)."""

    def __init__(self):
        self.history: list[SVGSMeasurement] = []

    def write(self, measurement: SVGSMeasurement) -> None:
        self.history.append(measurement)

    def isWritten(self) -> bool:  # noqa: N802 - Basilisk's spelling
        return bool(self.history)

    def read(self) -> SVGSMeasurement:
        if not self.history:
            raise InputError("measurementOutMsg: nothing written yet (check isWritten())")
        return self.history[-1]

    def since(self, n: int) -> list[SVGSMeasurement]:
        return self.history[int(n):]


def crlb_covariance(m: Measurement) -> np.ndarray | None:
    """The 6 x 6 CRLB covariance (m, rad) of a sensor measurement.

    With the frame's solution (a sensor made with ``keep_images="detector"`` or True): the solver's covariance
    for unit centroid noise, scaled by the frame's centroid bound, which is recovered from
    ``crlb_std`` (``std_x = sqrt(unit_xx) * sigma_centroid``, :func:`svgs_sim.sim.crlb.pose_crlb`). Without
    it: ``diag(crlb_std^2)`` (angles in rad). None when there is no bound.
    """
    if not m.ok or not m.crlb_std:
        return None
    sol = m.solution
    cov = getattr(sol, "covariance", None)
    if cov is not None:
        unit = np.asarray(cov, float) / float(sol.sigma_px) ** 2
        if unit[0, 0] > 0:
            c = float(m.crlb_std["x_m"]) / np.sqrt(unit[0, 0])
            return unit * c * c
    std = np.array([float(m.crlb_std[k]) for k in STATE_KEYS])
    std[3:] = np.radians(std[3:])
    return np.diag(std**2)


def camera_position_covariance(state_vector, covariance) -> tuple[np.ndarray, np.ndarray]:
    """The camera relative to the target's origin in the camera frame, ``-t_cam_target``, and its
    covariance, propagated linearly from the paper's state (numerical Jacobian, :data:`JACOBIAN_STEP`).

    Parameters
    ----------
    state_vector : array_like, shape (6,)
        m and rad.
    covariance : array_like, shape (6, 6)

    Returns
    -------
    r_cam_target_C_m : ndarray, shape (3,)
    covariance_C : ndarray, shape (3, 3), m^2
    """
    s = np.asarray(state_vector, float)
    d = JACOBIAN_STEP * np.eye(6)
    t = state_to_pose(np.concatenate([s[None], s + d, s - d]))[1]  # one batched call: (13, 3)
    J = -(t[1:7] - t[7:13]).T / (2 * JACOBIAN_STEP)
    return -t[0], J @ np.asarray(covariance, float) @ J.T


class IdealSensor:
    """A sensor that measures the true pose, always, with :data:`IDEAL_STD` as its bound: the
    reference a run with the simulated phone is compared with. Same interface as
    :class:`svgs_sim.sim.approach.ApproachSensor` for :class:`SVGSModule`."""

    frame_rate_hz = None

    def __init__(self):
        self.frame_index = 0

    def measure(self, t_s: float, R_cam_target, t_cam_target_m, *, image_velocity_px_s=None) -> Measurement:
        truth = state_dict(pose_to_state(R_cam_target, t_cam_target_m))
        k = self.frame_index
        self.frame_index += 1
        nan = float("nan")
        return Measurement(frame=k, t_s=float(t_s), ok=True, reason=None, truth=truth, estimate=dict(truth),
                           error={k_: 0.0 for k_ in STATE_KEYS}, crlb_std=dict(IDEAL_STD),
                           range_m=float(np.asarray(t_cam_target_m, float)[2]), exposure_s=nan, iso=nan,
                           metered_level=nan, next_exposure_s=nan, next_iso=nan, n_blobs=None)

    def close(self) -> None:
        pass


def illumination_factor(payload) -> float:
    """An ``EclipseMsgPayload``'s fraction of the sun's disk in view (1 sunlit, 0 umbra). Basilisk
    renamed ``shadowFactor`` to ``illuminationFactor`` (the same value); the payload a reader returns
    has one or both, so read the new name where there is one, else the old without its warning."""
    try:
        return float(payload.illuminationFactor)
    except AttributeError:
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message=".*shadowFactor.*")
            return float(payload.shadowFactor)


class SVGSModule(sysModel.SysModel):
    """The SVGS sensor inside a Basilisk simulation (see the module docstring).

    Parameters
    ----------
    sensor : svgs_sim.sim.approach.ApproachSensor or IdealSensor
        The simulated sensor. Make an ApproachSensor with ``keep_images="detector"`` (or True)
        for the full 6 x 6 covariance (the module drops each frame's images), and with the same
        ``frame_rate_hz`` or none.
    camera_mount : svgs_sim.sim.basilisk_frames.Mount
        The camera frame on the chaser.
    pattern_mount : svgs_sim.sim.basilisk_frames.Mount
        The target frame on the target.
    frame_rate_hz : float
        The rate the sensor takes frames at, frames/s (default :data:`PHONE_FRAME_RATE_HZ`).
    latency_s : float
        Image to release, s (default :data:`PROCESSING_LATENCY_S`).
    scene : svgs_sim.sim.scene.Scene, optional
        With ``sunInMsg`` linked: the scene each frame's sun and Earth are set in (its
        ``earth_albedo``; the environment becomes ``orbit``). Default: the sensor's own.

    Attributes
    ----------
    chaserStateInMsg, targetStateInMsg : messaging.SCStatesMsgReader
        Subscribe them to the two spacecraft's ``scStateOutMsg``.
    sunInMsg : messaging.SpicePlanetStateMsgReader
        Optional: the sun's inertial position (see the module docstring).
    eclipseInMsg : messaging.EclipseMsgReader
        Optional: the target's ``illuminationFactor`` (formerly ``shadowFactor``) from Basilisk's ``eclipse`` module.
    measurementOutMsg : MeasurementOutput
    opNavOutMsg : messaging.OpNavMsg
    light_log : list of dict
        With the sun: each frame's ``t_s``, ``sun_azimuth_deg``, ``sun_elevation_deg``,
        ``earth_azimuth_deg``, ``earth_elevation_deg`` (deg, target frame), ``shadow_factor``
        (Basilisk's, or 0/1 from the cylindrical shadow), ``sunlit`` (bool) and ``altitude_m``.
    """

    def __init__(self, sensor, camera_mount: Mount, pattern_mount: Mount, *,
                 frame_rate_hz: float = PHONE_FRAME_RATE_HZ, latency_s: float = PROCESSING_LATENCY_S,
                 scene: Scene | None = None):
        super().__init__()
        self.sensor = sensor
        if not isinstance(camera_mount, Mount) or not isinstance(pattern_mount, Mount):
            raise InputError("camera_mount, pattern_mount: expected svgs_sim.sim.basilisk_frames.Mount objects")
        self.camera_mount = camera_mount
        self.pattern_mount = pattern_mount
        self.frame_rate_hz = check_finite_positive(frame_rate_hz, "frame_rate_hz")
        own = getattr(sensor, "frame_rate_hz", None)
        if own is not None and abs(float(own) - self.frame_rate_hz) > 1e-12 * self.frame_rate_hz:
            raise InputError(f"frame_rate_hz: the module takes frames at {self.frame_rate_hz:g} frames/s, the "
                             f"sensor was made for {float(own):g}")
        self.latency_s = check_finite_positive(latency_s, "latency_s", allow_zero=True)
        self.chaserStateInMsg = messaging.SCStatesMsgReader()
        self.targetStateInMsg = messaging.SCStatesMsgReader()
        self.sunInMsg = messaging.SpicePlanetStateMsgReader()
        self.eclipseInMsg = messaging.EclipseMsgReader()
        if scene is not None and not isinstance(scene, Scene):
            raise InputError(f"scene: expected a svgs_sim.sim.scene.Scene, got {type(scene).__name__}")
        self.scene = scene
        self.light_log: list[dict] = []
        self.measurementOutMsg = MeasurementOutput()
        self.opNavOutMsg = messaging.OpNavMsg()
        self._t0_s = None
        self._n_frames = 0
        self._pending: list[SVGSMeasurement] = []

    # ------------------------------------------------------------------ Basilisk's interface
    def Reset(self, CurrentSimNanos):  # noqa: N802, N803 - Basilisk's names
        for name in ("chaserStateInMsg", "targetStateInMsg"):
            if not getattr(self, name).isLinked():
                self.bskLogger.error(f"SVGSModule.{name} is not linked")
        if self.sunInMsg.isLinked() and not hasattr(self.sensor, "base"):
            self.bskLogger.error("SVGSModule.sunInMsg is linked but the sensor renders no scene (an IdealSensor)")
        self._t0_s = None
        self._n_frames = 0
        self._pending = []
        self.light_log = []
        self.opNavOutMsg.write(messaging.OpNavMsgPayload(), CurrentSimNanos, self.moduleID)

    def UpdateState(self, CurrentSimNanos):  # noqa: N802, N803
        t_s = CurrentSimNanos * 1e-9
        if self._t0_s is None:
            self._t0_s = t_s
        eps = 1e-9
        if t_s >= self._t0_s + self._n_frames / self.frame_rate_hz - eps:
            self._pending.append(self.take_frame(t_s))
            # the next frame time after this one, on the grid t0 + k / rate (no drift)
            self._n_frames = int(np.floor((t_s - self._t0_s) * self.frame_rate_hz + eps)) + 1
        while self._pending and self._pending[0].t_available_s <= t_s + eps:
            self._release(self._pending.pop(0), CurrentSimNanos)

    # ------------------------------------------------------------------ the measurement
    def _states(self):
        ch, tg = self.chaserStateInMsg(), self.targetStateInMsg()
        return ({k: np.array(getattr(ch, k), float) for k in ("r_BN_N", "v_BN_N", "sigma_BN", "omega_BN_B")},
                {k: np.array(getattr(tg, k), float) for k in ("r_BN_N", "v_BN_N", "sigma_BN", "omega_BN_B")})

    def pose_at(self, ch: dict, tg: dict, dt_s: float = 0.0):
        """``(R_cam_target, t_cam_target_m)`` of the two bodies' states moved on by ``dt_s``
        (constant velocities and angular velocities)."""
        rc, sc = propagate_body(ch["r_BN_N"], ch["v_BN_N"], ch["sigma_BN"], ch["omega_BN_B"], dt_s)
        rt, st = propagate_body(tg["r_BN_N"], tg["v_BN_N"], tg["sigma_BN"], tg["omega_BN_B"], dt_s)
        return relative_pose(rc, sc, rt, st, self.camera_mount, self.pattern_mount)

    def image_velocity_px_s(self, ch: dict, tg: dict):
        """The spots' image velocity (N, 2) px/s from the bodies' motion, or None for a sensor
        without a camera model (:class:`IdealSensor`) or with a target behind the camera."""
        project = getattr(self.sensor, "targets_px", None)
        if project is None:
            return None
        (R1, t1), (R2, t2) = self.pose_at(ch, tg, -VELOCITY_STEP_S), self.pose_at(ch, tg, VELOCITY_STEP_S)
        if t1[2] <= 0 or t2[2] <= 0:
            return None
        return (project(R2, t2) - project(R1, t1)) / (2 * VELOCITY_STEP_S)

    def take_frame(self, t_s: float) -> SVGSMeasurement:
        """One frame now: read the states, measure, and return the measurement (to be released
        ``latency_s`` later)."""
        ch, tg = self._states()
        R, tv = self.pose_at(ch, tg)
        truth = state_dict(pose_to_state(R, tv))
        if tv[2] <= 0:  # the target's origin behind the camera: the sensor cannot even point at it
            return SVGSMeasurement(t_s, t_s + self.latency_s, self._next_index(), False, OUT_OF_VIEW, None, None,
                                   None, None, None, None, truth, float(tv[2]), None,
                                   ch["sigma_BN"])
        vel = self.image_velocity_px_s(ch, tg)
        scene = self.frame_scene(t_s, tg) if self.sunInMsg.isLinked() and hasattr(self.sensor, "base") else None
        if scene is None:
            m = self.sensor.measure(t_s, R, tv, image_velocity_px_s=vel)
        else:
            m = self.sensor.measure(t_s, scenario=scenario_from_pose(R, tv, self.sensor.base.replace(scene=scene)),
                                    image_velocity_px_s=vel)
        m.image = m.detect_image = None  # a full frame a measurement is too much to keep
        sv = None
        if m.ok and m.estimate:
            sv = np.array([m.estimate[k] for k in STATE_KEYS], float)
            sv[3:] = np.radians(sv[3:])
        return SVGSMeasurement(float(m.t_s), float(m.t_s) + self.latency_s, int(m.frame), bool(m.ok), m.reason,
                               dict(m.estimate) if m.ok and m.estimate else None, sv, crlb_covariance(m),
                               m.crlb_std, m.p_value, m.residual_rms_px, truth, float(m.range_m), m, ch["sigma_BN"])

    def frame_scene(self, t_s: float, tg: dict) -> Scene:
        """The frame's scene on orbit: the sun (unless the target is in the Earth's shadow) and the
        Earth in the target frame, from the target's state and the sun's message; logged in
        :attr:`light_log`."""
        r_t = tg["r_BN_N"]
        r_sun = np.array(self.sunInMsg().PositionVector, float)
        dcm_TN = self.pattern_mount.dcm_frame_body @ mrp_to_dcm(tg["sigma_BN"])
        geo = sun_and_earth_in_target(r_t, dcm_TN, r_sun - r_t)
        if self.eclipseInMsg.isLinked():
            shadow = illumination_factor(self.eclipseInMsg())
        else:
            shadow = 0.0 if geo["eclipsed"] else 1.0
        lit = shadow >= 0.5
        # the sun's direction stays in the scene when the renderer's own shadow hides it too (it then drops
        # the disk and the direct light, and still lights the Earth); it goes only where Basilisk says
        # shadow and the renderer's geometry says sunlit (the two models' seconds apart at the edge)
        keep = lit or geo["eclipsed"]
        base = self.scene if self.scene is not None else self.sensor.base.scene
        scene = dataclasses.replace(
            base, environment="orbit", sun_azimuth_deg=geo["sun_azimuth_deg"] if keep else None,
            sun_elevation_deg=geo["sun_elevation_deg"] if keep else None, earth_azimuth_deg=geo["earth_azimuth_deg"],
            earth_elevation_deg=geo["earth_elevation_deg"], altitude_km=geo["altitude_m"] / 1e3)
        self.light_log.append({"t_s": float(t_s), **{k: geo[k] for k in ("sun_azimuth_deg", "sun_elevation_deg",
                                                                         "earth_azimuth_deg", "earth_elevation_deg",
                                                                         "altitude_m")},
                               "shadow_factor": shadow, "sunlit": bool(lit and not scene.eclipsed)})
        return scene

    def _next_index(self) -> int:
        k = int(getattr(self.sensor, "frame_index", 0))
        if hasattr(self.sensor, "frame_index"):
            self.sensor.frame_index = k + 1
        return k

    def _release(self, meas: SVGSMeasurement, nanos: int) -> None:
        self.measurementOutMsg.write(meas)
        p = messaging.OpNavMsgPayload()
        p.timeTag = float(meas.t_image_s)
        p.valid = int(bool(meas.ok and meas.state_vector is not None))
        p.faultDetected = int(not p.valid)
        if p.valid:
            r_C, cov_C = camera_position_covariance(meas.state_vector,
                                                    meas.covariance if meas.covariance is not None
                                                    else np.zeros((6, 6)))
            CB = self.camera_mount.dcm_frame_body
            BN = mrp_to_dcm(meas.sigma_chaser_BN)
            r_B, cov_B = CB.T @ r_C, CB.T @ cov_C @ CB
            r_N, cov_N = BN.T @ r_B, BN.T @ cov_B @ BN
            p.r_BN_C, p.r_BN_B, p.r_BN_N = r_C.tolist(), r_B.tolist(), r_N.tolist()
            p.covar_C, p.covar_B, p.covar_N = (c.ravel().tolist() for c in (cov_C, cov_B, cov_N))
        self.opNavOutMsg.write(p, nanos, self.moduleID)
