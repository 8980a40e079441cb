"""Closed-loop docking in Basilisk with the simulated SVGS: the cost of the real sensor in delta-v.

A target 3U cubesat (4 kg) in a 400 km circular orbit carries the SVGS pattern on its long face,
facing along its -y (along-track, backwards); it holds the Hill frame (x radial, y along-track,
z orbit normal), spinning at the orbital rate. A chaser (10 kg) starts 30 m behind with the Galaxy
Nexus on its +y face, looking at the pattern. Basilisk propagates both spacecraft (Earth's point-mass
gravity); the chaser's thrusters are an ideal force (``extForceTorque``, at most
:data:`MAX_FORCE_N`). The sensor is :class:`svgs_sim.sim.basilisk_svgs.SVGSModule`: it renders, exposes and
solves a frame at ``--sensor-rate-hz`` and releases it :data:`svgs_sim.sim.basilisk_svgs.PROCESSING_LATENCY_S`
later. A linear Kalman filter on Hill's (Clohessy-Wiltshire) equations takes the measurements
(replaying the control history over the latency), and a glide-slope guidance flies the camera down
the pattern's +z axis to 1 m. The same run with an ideal sensor (the true pose, every frame, no
latency) gives the reference: the real sensor's cost is the difference in delta-v, time and final
error. ``--phones htc-amaze-4g`` flies the HTC Amaze 4G, whose spots merge beyond its merge range
(7.16 m head-on, ``docs/reports/merge-range-htc-amaze-4g/summary.json``; in the committed run its
first solution came at 8.0 m): it flies on the filter's prediction until the measurements start.

Run (from the repository root, with ``pip install -e ".[basilisk]"``)::

    python examples/basilisk_docking.py                 # both phones + ideal; figures in docs/figures
    python examples/basilisk_docking.py --quick --out out/dock   # a bounded form: 5 m, preview, ~20 frames

On orbit (``--environment orbit``) the sun comes from the orbit: the inertial direction toward the
sun at a fixed epoch (:data:`svgs_sim.sim.orbit_light.SUN_EPOCH_UTC`, astropy with IERS downloads off),
the eclipse from Basilisk's own ``eclipse`` module (the Earth's mean radius, the renderer's), the
Earth as the central body; each frame's sun and Earth are set in the target frame by
:class:`svgs_sim.sim.basilisk_svgs.SVGSModule`. The approach starts ``--eclipse-in-s`` before the
eclipse's entry (``--transition exit``: its exit), so its frames cross a transition; ``--raan-deg``
sets the beta angle (printed).
``--case`` picks the corridor: ``vbar`` (behind, the Earth's limb in the frame), ``rbar-below`` (from
below, deep space behind the target), ``rbar-above`` (from above, the Earth behind it). Each phone
gets an orbit-phase figure (``basilisk_docking_orbit_<case>_phase_<phone>.png``: outcomes, wrong locks,
the sun's elevation and the exposure against time)::

    python examples/basilisk_docking.py --environment orbit --case rbar-above --start-z-m 10 --max-time-s 300

Every random draw is seeded (``--seed``). The sensor runs at the phone's own frame rate,
``--sensor-rate-hz`` (default :data:`svgs_sim.sim.basilisk_svgs.PHONE_FRAME_RATE_HZ`, 2 frames/s);
rendering costs 0.4-3 s a frame on a 2-core machine, and the committed single runs of
docs/figures were made at 0.25 frames/s (their JSON records the rate); docs/basilisk.md gives the
time a run takes.

Monte Carlo (``--monte-carlo N``): N runs per sensor with dispersed true initial states, hand-over
(navigation) errors, sensor seeds and thruster magnitude and direction errors and a minimum impulse
(:func:`mc_dispersions`), the ideal sensor on the same seeds; the runs on the project's executors
(``--processes``, ``--workers``, ``--scheduler``); ``OUT/montecarlo.json`` (per run the seed, the
arrival error and time, the delta-v, the dropouts by reason, the wrong locks and the dispersions
drawn; percentiles with order-statistic intervals) and ``OUT/montecarlo.png``::

    python examples/basilisk_docking.py --quick --monte-carlo 3 --phones galaxy-nexus --out out/mc
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from svgs_sim.base.errors import InputError  # noqa: E402
from svgs_sim.sim.basilisk_svgs import PHONE_FRAME_RATE_HZ  # noqa: E402
from svgs_sim.svgs.frames import pose_to_state, state_to_pose  # noqa: E402

from svgs_sim.sim.basilisk_frames import (  # noqa: E402
    Mount, chaser_from_pose, dcm_to_mrp, hill_dcm, hill_from_inertial, mrp_to_dcm,
)

# ----------------------------------------------------------------------------- the scenario
#: Target 3U cubesat: mass (kg) and a 0.1 x 0.1 x 0.34 m box's inertia, long axis along body x (radial).
TARGET_MASS_KG = 4.0
TARGET_INERTIA = np.diag([4.0 / 12 * 0.02, 4.0 / 12 * (0.01 + 0.1156), 4.0 / 12 * (0.01 + 0.1156)])
#: Chaser (ASSUMPTION: a 6U-class chaser; isotropic inertia, so it keeps its attitude in Hill's frame
#: without attitude control).
CHASER_MASS_KG = 10.0
CHASER_INERTIA = np.diag([0.1, 0.1, 0.1])
#: The thrusters' largest force, N (ASSUMPTION: cold-gas cubesat thrusters of tens of mN).
MAX_FORCE_N = 0.05
#: Orbit altitude above Earth's equatorial radius (Basilisk's), m; inclination, deg.
ALTITUDE_M = 400e3
INCLINATION_DEG = 51.6
#: The pattern on the target's -y face: target frame x_T = x_B, y_T = z_B, z_T = -y_B (out of the face).
PATTERN = Mount([[1, 0, 0], [0, 0, 1], [0, -1, 0]], [0.0, -0.05, 0.0])
#: The camera on the chaser's +y face: boresight z_C = +y_B, x_C = x_B, y_C = -z_B.
CAMERA = Mount([[1, 0, 0], [0, 0, -1], [0, 1, 0]], [0.0, 0.1, 0.0])
#: The approach corridors (``--case``): (the pattern on the target, the camera on the chaser, what
#: lies behind the target). Both bodies hold Hill's frame (x radial out, y along-track, z orbit
#: normal); the target's long axis is its body x (radial), so the R-bar faces are its 10 cm ends.
CASES = {
    # V-bar: the chaser behind on -y looking +y along-track; from 400 km the horizon dips 19.8 deg, inside
    # both phones' half-fields along the image's x (the camera's x is radial): the Earth's limb at the left edge
    "vbar": (PATTERN, CAMERA, "the chaser on -y (behind) looking +y: the Earth's limb at the frame's left edge"),
    # R-bar from below: the chaser on -x (nearer the Earth) looking up +x: deep space behind the target
    "rbar-below": (Mount([[0, 1, 0], [0, 0, -1], [-1, 0, 0]], [-0.17, 0.0, 0.0]),
                   Mount([[0, 1, 0], [0, 0, 1], [1, 0, 0]], [0.1, 0.0, 0.0]),
                   "the chaser on -x (below) looking +x (up): deep space behind the target"),
    # R-bar from above: the chaser on +x looking down -x: the Earth fills the view behind the target
    "rbar-above": (Mount([[0, 1, 0], [0, 0, 1], [1, 0, 0]], [0.17, 0.0, 0.0]),
                   Mount([[0, 1, 0], [0, 0, -1], [-1, 0, 0]], [-0.1, 0.0, 0.0]),
                   "the chaser on +x (above) looking -x (down): the Earth behind the target"),
}
#: On orbit (``--environment orbit``): the approach starts this long before the target enters the
#: Earth's shadow, s (``--eclipse-in-s``), so that its frames cross the eclipse entry.
ECLIPSE_IN_S = 120.0
#: The orbit's right ascension of the ascending node, deg (``--raan-deg``): with the sun of
#: :data:`svgs_sim.sim.orbit_light.SUN_EPOCH_UTC` (near the March equinox) 0 gives beta ~ 0.
RAAN_DEG = 0.0
#: The initial sensor pose in the paper's state: the camera at (x, y, z) m in the target frame and
#: the paper's attitude (deg); the chaser holds this attitude in Hill's frame.
START_STATE = (0.3, -0.2, 30.0, 2.0, -1.0, 3.0)
#: The goal: the camera 1 m in front of the pattern on its +z axis, m.
GOAL_Z_M = 1.0

# ----------------------------------------------------------------------------- navigation
#: Filter step (guidance and control rate), s.
CONTROL_PERIOD_S = 1.0
#: The filter's initial 1-sigma: position (m) and velocity (m/s) per axis (ASSUMPTION: a hand-over
#: from a far-range relative navigation at metre level); the initial estimate is drawn from it.
PRIOR_SIGMA_M, PRIOR_SIGMA_M_S = 0.3, 0.002
#: White-acceleration density of the filter's process noise, m^2/s^3 (tuning: Hill's equations and
#: an ideal force leave only the linearisation, ~1e-9 m/s^2 at 30 m).
Q_ACCEL = 1e-10
#: The filter measures the camera relative to the pattern from the sensor's pose, ``-t_cam_target``
#: (its bearing is far better known than the paper's lateral position, whose errors go with the
#: attitude's: an orbit about the target), rotated to Hill's frame with the chaser's attitude
#: (ASSUMPTION: known, a star tracker). Its sigma: the CRLB (the frame's 6 x 6 covariance carried
#: through) and, in quadrature, a floor for the errors the CRLB does not bound (tuning, from the
#: range errors of docs/reports/approach-galaxy-nexus, 0.08 m at 20-30 m, 0.002 m at 5-10 m, and
#: the bearing errors of a few preview frames at 5 m, ~3 mm), scaled by the pixel size against
#: the full frame: (coefficient, lowest value) along the boresight (per m^2) and across it (per m).
FLOOR_ALONG = (1.3e-4, 0.001)
FLOOR_ACROSS = (2e-4, 0.002)
#: The relative attitude's floor, deg: (coefficient per m^2, lowest value); scaled by the pixel
#: size squared (preview frames at 5 m gave 1-3 deg where full frames give ~0.1 deg).
FLOOR_ANGLE_DEG = (2e-3, 0.05)
#: Innovation gate: a measurement whose normalised innovation squared exceeds the chi-square
#: 99.9 % point with 3 degrees of freedom is rejected (a misidentified frame).
NIS_GATE = 16.27
#: Random-walk density of the relative-attitude filter, rad^2/s.
Q_ATTITUDE = 1e-8

# ----------------------------------------------------------------------------- guidance
#: Glide slope: the closing speed is (z - goal) / TAU_S, at least V_MIN_M_S, m/s.
TAU_S = 100.0
V_MIN_M_S = 0.02
#: Lateral: the desired lateral speed is -lateral / TAU_LATERAL_S.
TAU_LATERAL_S = 40.0
#: Velocity-tracking gain, 1/s.
K_VELOCITY = 0.1
#: Below GATE_RANGE_M the guidance closes only with a measurement younger than GATE_AGE_S; else it
#: holds its range (ASSUMPTION: a typical approach rule; nothing of SVGS).
GATE_RANGE_M, GATE_AGE_S = 5.0, 20.0
#: Arrival: the estimated camera within this of the goal along the axis, m.
ARRIVAL_TOL_M = 0.02


def cw_matrices(n_rad_s: float, dt_s: float):
    """Discrete Hill/Clohessy-Wiltshire transition over ``dt_s`` with a constant acceleration:
    ``x+ = Phi x + Gamma a`` (x radial, y along-track, z normal; exact, by the matrix exponential)."""
    from scipy.linalg import expm

    A = np.zeros((9, 9))
    A[0:3, 3:6] = np.eye(3)
    A[3, 0], A[3, 4] = 3 * n_rad_s**2, 2 * n_rad_s
    A[4, 3] = -2 * n_rad_s
    A[5, 2] = -n_rad_s**2
    A[3:6, 6:9] = np.eye(3)
    E = expm(A * dt_s)
    return E[:6, :6], E[:6, 6:9]


def cw_acceleration(n_rad_s: float, x: np.ndarray) -> np.ndarray:
    """The gravity-gradient and Coriolis terms of Hill's equations at state x (6,), m/s^2."""
    return np.array([3 * n_rad_s**2 * x[0] + 2 * n_rad_s * x[4], -2 * n_rad_s * x[3], -n_rad_s**2 * x[2]])


def measurement_floor(range_m: float, pixel_scale: float) -> tuple[np.ndarray, np.ndarray]:
    """The floor of the filter's measurement sigma: the camera position in the camera frame
    (across, across, along the boresight), m, and the angles, rad; ``pixel_scale``: the full
    frame's focal length over the camera's (1 at full resolution)."""
    r = float(range_m)
    along = max(FLOOR_ALONG[0] * r * r, FLOOR_ALONG[1]) * pixel_scale
    across = max(FLOOR_ACROSS[0] * r, FLOOR_ACROSS[1]) * pixel_scale
    ang = np.radians(max(FLOOR_ANGLE_DEG[0] * r * r, FLOOR_ANGLE_DEG[1])) * pixel_scale**2
    return np.array([across, across, along]), np.full(3, ang)


class ThrustErrors:
    """The thrusters' errors: the force they give is ``scale`` times the commanded one, turned by
    ``R_error`` (a misalignment), and nothing when the command's impulse over a control period is
    below ``min_impulse_n_s`` (the minimum impulse bit). The default is the ideal thruster.

    Parameters
    ----------
    scale : float
        Magnitude factor (1: exact).
    R_error : array_like, shape (3, 3)
        Rotation of the applied force from the commanded one.
    min_impulse_n_s : float
        Minimum impulse bit, N s.
    """

    def __init__(self, scale: float = 1.0, R_error=None, min_impulse_n_s: float = 0.0):
        self.scale = float(scale)
        self.R_error = np.eye(3) if R_error is None else np.asarray(R_error, float)
        self.min_impulse_n_s = float(min_impulse_n_s)

    def apply(self, a_cmd: np.ndarray) -> np.ndarray:
        """The acceleration applied for the commanded ``a_cmd`` (m/s^2, shape (3,))."""
        if np.linalg.norm(a_cmd) * CHASER_MASS_KG * CONTROL_PERIOD_S < self.min_impulse_n_s:
            return np.zeros(3)
        return self.scale * (self.R_error @ np.asarray(a_cmd, float))


def _make_gnc_class():
    """The GNC flight-software module, a ``SysModel`` subclass: navigation (a Clohessy-Wiltshire
    Kalman filter replaying late measurements), glide-slope guidance and ideal-force control.

    This function is long (~175 lines) because it defines the class, whose Basilisk base class can
    only be imported lazily (Basilisk is an optional extra); each method is short."""
    from Basilisk.architecture import messaging, sysModel

    from svgs_sim.sim.basilisk_svgs import camera_position_covariance

    class DockingGNC(sysModel.SysModel):
        """Navigation (CW Kalman filter with latency replay), glide-slope guidance, ideal-force control."""

        def __init__(self, svgs_output, n_rad_s, x0_hat, P0, ideal: bool, pixel_scale: float, camera=CAMERA,
                     pattern=PATTERN, thrust: ThrustErrors | None = None):
            super().__init__()
            self.thrust = thrust or ThrustErrors()
            self.camera, self.pattern = camera, pattern
            self.targetStateInMsg = messaging.SCStatesMsgReader()
            self.chaserStateInMsg = messaging.SCStatesMsgReader()
            self.forceOutMsg = messaging.CmdForceInertialMsg()
            self.svgs = svgs_output
            self.n = float(n_rad_s)
            self.ideal = bool(ideal)
            self.pixel_scale = float(pixel_scale)
            self.Phi, self.Gam = cw_matrices(self.n, CONTROL_PERIOD_S)
            self.x0_hat, self.P0 = np.asarray(x0_hat, float), np.asarray(P0, float)
            self.checkpoints = []  # (t, x, P): the estimate at each control time
            self.controls = []  # (t_k, a_H) applied over [t_k, t_k + period)
            self.all_meas = []  # (t_image, z (3,), R (3, 3), log record) of the solved frames
            self.t0 = None
            self._att_t = None
            self.n_seen = 0
            self.att = None  # (x (3,), P (3,3)) relative attitude, rad
            self.last_ok_s = -np.inf
            self.arrived_s = None
            self.log = {k: [] for k in ("t_s", "x_hat", "P", "a_H", "a_applied", "true_rho", "true_rho_dot", "hold",
                                        "cam_true",
                                        "cam_hat", "cam_sigma", "att_hat", "att_sigma", "att_true")}
            self.meas_log = []  # per released frame: t_image, ok, reason, accepted, state, sigma, truth

        # the chaser's camera and the pattern as offsets in Hill's frame (the target is Hill-held)
        def _offsets(self, sigma_chaser_BN, HN):
            HBc = HN @ mrp_to_dcm(sigma_chaser_BN).T
            return HBc @ self.camera.origin_body_m - self.pattern.origin_body_m

        def Reset(self, CurrentSimNanos):  # noqa: N802, N803
            self.forceOutMsg.write(messaging.CmdForceInertialMsgPayload(), CurrentSimNanos, self.moduleID)

        def _propagate(self, x, P, a, dt):
            Phi, Gam = (self.Phi, self.Gam) if abs(dt - CONTROL_PERIOD_S) < 1e-9 else cw_matrices(self.n, dt)
            Qc = Q_ACCEL * np.block([[dt**3 / 3 * np.eye(3), dt**2 / 2 * np.eye(3)],
                                     [dt**2 / 2 * np.eye(3), dt * np.eye(3)]])
            return Phi @ x + Gam @ a, Phi @ P @ Phi.T + Qc

        def _update(self, x, P, z, R):
            H = np.hstack([np.eye(3), np.zeros((3, 3))])
            S = H @ P @ H.T + R
            nu = z - H @ x
            if not self.ideal and float(nu @ np.linalg.solve(S, nu)) > NIS_GATE:
                return x, P, False
            K = P @ H.T @ np.linalg.inv(S)
            I_KH = np.eye(6) - K @ H
            return x + K @ nu, I_KH @ P @ I_KH.T + K @ R @ K.T, True

        def _estimate(self, t_now, new):
            """The posterior at ``t_now``: back to the last checkpoint before the oldest new
            measurement, then forward through every measurement and the controls applied."""
            self.all_meas = (self.all_meas + new)[-100:]
            t_first = min((m[0] for m in new), default=t_now)
            while len(self.checkpoints) > 1 and self.checkpoints[-1][0] >= t_first - 1e-9:
                self.checkpoints.pop()
            t, x, P = self.checkpoints[-1]
            events = [(m[0], 0, m) for m in self.all_meas if m[0] > t + 1e-9]
            events += [(c[0], 1, None) for c in self.controls if t + 1e-9 < c[0] < t_now - 1e-9]
            events.append((t_now, 1, None))
            for te, kind, m in sorted(events, key=lambda e: (e[0], e[1])):
                if te > t + 1e-9:
                    x, P = self._propagate(x, P, self._control_at(t), te - t)
                    t = te
                if kind == 0:
                    x, P, ok = self._update(x, P, m[1], m[2])
                    m[3]["accepted"] = ok
                else:
                    self.checkpoints.append((t, x.copy(), P.copy()))
            self.checkpoints = self.checkpoints[-200:]
            return x, P

        def _control_at(self, t):
            """The acceleration applied at time t (the last command at or before it)."""
            a = np.zeros(3)
            for t_k, a_k in self.controls:
                if t_k <= t + 1e-9:
                    a = a_k
            return a

        def UpdateState(self, CurrentSimNanos):  # noqa: N802, N803
            t = CurrentSimNanos * 1e-9
            tg, ch = self.targetStateInMsg(), self.chaserStateInMsg()
            r_t, v_t = np.array(tg.r_BN_N), np.array(tg.v_BN_N)
            r_c, v_c = np.array(ch.r_BN_N), np.array(ch.v_BN_N)
            sig_c = np.array(ch.sigma_BN)
            HN = hill_dcm(r_t, v_t)
            d_H = self._offsets(sig_c, HN)
            if self.t0 is None:
                self.t0 = t
                self.checkpoints = [(t - 1e-6, self.x0_hat, self.P0)]
            # new measurements (released by the SVGS module since the last step)
            new = []
            for m in self.svgs.since(self.n_seen):
                sm = m.sensor_measurement
                rec = {"t_s": m.t_image_s, "ok": m.ok, "reason": m.reason, "accepted": False, "truth": m.truth,
                       "state": m.state, "sigma": None, "wrong_lock": bool(getattr(sm, "wrong_lock", False)),
                       "exposure_s": getattr(sm, "exposure_s", None)}
                self.meas_log.append(rec)
                if m.ok and m.state_vector is not None:
                    cov6 = m.covariance if m.covariance is not None else np.zeros((6, 6))
                    r_C, cov_C = camera_position_covariance(m.state_vector, cov6)
                    cov_att = cov6[3:, 3:]
                    if not self.ideal:
                        f_pos, f_ang = measurement_floor(m.range_m, self.pixel_scale)
                        cov_C = cov_C + np.diag(f_pos**2)
                        cov_att = cov_att + np.diag(f_ang**2)
                    rec["sigma"] = np.sqrt(np.concatenate([np.diag(cov_C), np.diag(cov_att)]))
                    # z: the chaser relative to the target in Hill's frame, from -t_cam_target
                    HC = HN @ mrp_to_dcm(m.sigma_chaser_BN).T @ self.camera.dcm_frame_body.T
                    z = HC @ r_C - d_H
                    new.append((m.t_image_s, z, HC @ cov_C @ HC.T, rec))
                    self._attitude_update(m.t_image_s, m.state_vector[3:], cov_att)
                    self.last_ok_s = max(self.last_ok_s, m.t_image_s)
            self.n_seen = len(self.svgs.history)
            x, P = self._estimate(t, new)
            # guidance in the target frame (camera position and velocity), then CW compensation
            T = self.pattern.dcm_frame_body
            cam = T @ (x[:3] + d_H)
            vel = T @ x[3:]
            range_m = float(cam[2])
            hold = range_m < GATE_RANGE_M and (t - self.last_ok_s) > GATE_AGE_S
            if self.arrived_s is None and range_m <= GOAL_Z_M + ARRIVAL_TOL_M:
                self.arrived_s = t
            v_des = np.array([-cam[0] / TAU_LATERAL_S, -cam[1] / TAU_LATERAL_S, 0.0])
            if not hold and self.arrived_s is None:
                v_des[2] = -max((range_m - GOAL_Z_M) / TAU_S, V_MIN_M_S)
            a_T = K_VELOCITY * (v_des - vel)
            a_H = T.T @ a_T - cw_acceleration(self.n, x)
            a_max = MAX_FORCE_N / CHASER_MASS_KG
            if np.linalg.norm(a_H) > a_max:
                a_H *= a_max / np.linalg.norm(a_H)
            self.controls.append((t, a_H.copy()))
            self.controls = self.controls[-400:]
            payload = messaging.CmdForceInertialMsgPayload()
            a_app = self.thrust.apply(a_H)  # what the thrusters give: the filter knows only the command
            payload.forceRequestInertial = (HN.T @ a_app * CHASER_MASS_KG).tolist()
            self.forceOutMsg.write(payload, CurrentSimNanos, self.moduleID)
            # the log: truth from the states (for the plots only; nothing above uses it but the
            # Hill frame and the chaser's attitude, which the chaser knows from its own navigation)
            rho, rho_dot = hill_from_inertial(r_t, v_t, r_c, v_c)
            R_true, t_true = _true_pose(tg, ch, self.camera, self.pattern)
            st_true = pose_to_state(R_true, t_true)
            L = self.log
            L["t_s"].append(t)
            L["x_hat"].append(x.copy())
            L["P"].append(np.diag(P).copy())
            L["a_H"].append(a_H.copy())
            L["a_applied"].append(a_app.copy())
            L["true_rho"].append(rho)
            L["true_rho_dot"].append(rho_dot)
            L["hold"].append(hold)
            L["cam_true"].append(st_true[:3])
            L["cam_hat"].append(cam)
            L["cam_sigma"].append(np.sqrt(np.maximum(np.diag(T @ P[:3, :3] @ T.T), 0)))
            xa, Pa = self.att if self.att is not None else (np.full(3, np.nan), np.full((3, 3), np.nan))
            L["att_hat"].append(xa.copy())
            L["att_sigma"].append(np.sqrt(np.abs(np.diag(Pa))))
            L["att_true"].append(st_true[3:])

        def _attitude_update(self, t_s, ang, R):
            if self.att is None:
                self.att = (np.asarray(ang, float).copy(), np.asarray(R, float).copy())
                self._att_t = t_s
                return
            x, P = self.att
            P = P + Q_ATTITUDE * max(t_s - self._att_t, 0.0) * np.eye(3)
            K = P @ np.linalg.inv(P + R)
            self.att = (x + K @ (np.asarray(ang) - x), (np.eye(3) - K) @ P)
            self._att_t = t_s

    return DockingGNC


def _true_pose(tg, ch, camera=CAMERA, pattern=PATTERN):
    from svgs_sim.sim.basilisk_frames import relative_pose

    return relative_pose(np.array(ch.r_BN_N), np.array(ch.sigma_BN), np.array(tg.r_BN_N), np.array(tg.sigma_BN),
                         camera, pattern)


def _sensor(phone: str | None, *, preview: bool, seed: int, rate_hz: float, orbit: bool = False,
            sensor_model: str | None = None):
    """The SVGS sensor of a phone (None: the ideal sensor); ``orbit``: black space around the target
    (the sun and the Earth set per frame by the module); ``sensor_model``: the statistical sensor drawn
    from that table (``svgs sensor-model build``) instead of rendered frames."""
    from svgs_sim.sim.basilisk_svgs import IdealSensor

    if phone is None:
        return IdealSensor()
    if sensor_model is not None:
        from svgs_sim.sim.statistical_sensor import StatisticalSensor

        return StatisticalSensor(sensor_model, seed=seed, frame_rate_hz=rate_hz)
    from svgs_sim.sim.approach import ApproachSensor

    cam = phone
    if preview:
        from svgs_sim.camera.phone.preview import binned_camera
        from svgs_sim.base.profiles import Camera

        cam = binned_camera(Camera.load(phone))
    base = None
    if orbit:
        from svgs_sim.sim.closed_loop import Scenario
        from svgs_sim.sim.scene import Scene

        base = Scenario(scene=Scene(environment="orbit"))
    return ApproachSensor(cam, seed=seed, keep_images="detector", frame_rate_hz=rate_hz, base=base)


def eclipse_entry_phase_deg(sun_N, raan_deg: float, inclination_deg: float, radius_m: float,
                            transition: str = "entry") -> float:
    """The argument of latitude (deg) at which a circular orbit enters the Earth's shadow
    (:func:`svgs_sim.sim.orbit_light.sun_and_earth_in_target`'s cylindrical shadow), or with
    ``transition="exit"`` leaves it, by a 0.01 deg scan; InputError for an orbit never in shadow
    (a high beta angle)."""
    from svgs_sim.render.earth import EARTH_RADIUS_M, in_eclipse

    altitude_m = float(radius_m) - EARTH_RADIUS_M  # above the Earth's mean radius (the renderer's)
    W, i = np.radians(raan_deg), np.radians(inclination_deg)
    u = np.radians(np.arange(0.0, 360.0, 0.01))
    node = np.array([np.cos(W), np.sin(W), 0.0])
    up = np.array([-np.sin(W) * np.cos(i), np.cos(W) * np.cos(i), np.sin(i)])
    r_hat = np.cos(u)[:, None] * node + np.sin(u)[:, None] * up
    dark = np.array([in_eclipse(sun_N, -r, altitude_m) for r in r_hat])
    enter = np.flatnonzero(dark & ~np.roll(dark, 1) if transition == "entry" else ~dark & np.roll(dark, 1))
    if enter.size == 0:
        raise InputError(f"--raan-deg {raan_deg:g}: the orbit never enters the Earth's shadow (beta too high); "
                         "give another --raan-deg (nearer the sun's plane)")
    return float(np.degrees(u[enter[0]]))


def _place_target(tgt, mu: float, sun_N, raan_deg: float, eclipse_in_s: float, transition: str = "entry"):
    """Set the target's initial state: a circular orbit, its body the Hill frame, spinning at the
    orbital rate; on orbit (``sun_N`` given) ``eclipse_in_s`` before the shadow's entry (or exit,
    ``transition``). Returns
    ``(r_N, v_N, [HN], n rad/s, the start's argument of latitude deg)``."""
    from Basilisk.utilities import orbitalMotion

    oe = orbitalMotion.ClassicElements()
    oe.a, oe.e, oe.i = orbitalMotion.REQ_EARTH * 1e3 + ALTITUDE_M, 0.0, np.radians(INCLINATION_DEG)
    n = np.sqrt(mu / oe.a**3)
    u0_deg = 0.0
    if sun_N is not None:
        u0_deg = (eclipse_entry_phase_deg(sun_N, raan_deg, INCLINATION_DEG, oe.a, transition)
                  - np.degrees(n * eclipse_in_s))
    oe.Omega, oe.omega, oe.f = np.radians(raan_deg if sun_N is not None else 0.0), 0.0, np.radians(u0_deg)
    r_t, v_t = orbitalMotion.elem2rv(mu, oe)
    HN = hill_dcm(r_t, v_t)
    tgt.hub.r_CN_NInit, tgt.hub.v_CN_NInit = r_t.tolist(), v_t.tolist()
    tgt.hub.sigma_BNInit = dcm_to_mrp(HN).reshape(3, 1).tolist()
    tgt.hub.omega_BN_BInit = [[0.0], [0.0], [n]]
    return r_t, v_t, HN, n, u0_deg


def _place_chaser(ch, start_state, r_t, v_t, HN, n_rad_s, camera_mount, pattern_mount) -> np.ndarray:
    """Set the chaser's initial state: the start pose (the paper's state) -> inertial position and
    attitude, at rest in the rotating Hill frame. Returns its position in Hill's frame, m."""
    s = np.asarray(start_state, float)
    R0, t0 = state_to_pose(np.concatenate([s[:3], np.radians(s[3:])]))
    r_c, sig_c = chaser_from_pose(R0, t0, r_t, dcm_to_mrp(HN), camera_mount, pattern_mount)
    rho = HN @ (r_c - r_t)
    w_N = HN.T @ np.array([0.0, 0.0, n_rad_s])
    v_c = v_t + np.cross(w_N, HN.T @ rho)  # at rest in the rotating Hill frame
    ch.hub.r_CN_NInit, ch.hub.v_CN_NInit = r_c.tolist(), v_c.tolist()
    ch.hub.sigma_BNInit = sig_c.reshape(3, 1).tolist()
    ch.hub.omega_BN_BInit = (mrp_to_dcm(sig_c) @ w_N).reshape(3, 1).tolist()
    return rho


def _orbit_light(sim, target, sun_N):
    """The sun's message (1 AU along ``sun_N``) and Basilisk's eclipse module for the target, with
    the Earth's mean radius (the renderer's); returned to be kept alive."""
    from Basilisk.architecture import messaging
    from Basilisk.simulation import eclipse
    from Basilisk.utilities import orbitalMotion

    from svgs_sim.render.earth import EARTH_RADIUS_M

    def planet(name, pos_m):
        p = messaging.SpicePlanetStateMsgPayload()
        p.PositionVector = [float(x) for x in pos_m]
        p.PlanetName = name
        return messaging.SpicePlanetStateMsg().write(p)

    sun_msg = planet("sun", orbitalMotion.AU * 1e3 * np.asarray(sun_N, float))
    earth_msg = planet("custom", np.zeros(3))  # the central body at the origin, radius rEqCustom
    ecl = eclipse.Eclipse()
    ecl.ModelTag = "eclipse"
    ecl.sunInMsg.subscribeTo(sun_msg)
    ecl.addPlanetToModel(earth_msg)
    ecl.rEqCustom = EARTH_RADIUS_M
    ecl.addSpacecraftToModel(target.scStateOutMsg)
    sim.AddModelToTask("dyn", ecl, 5)
    return sun_msg, earth_msg, ecl


def run(phone: str | None, *, start_state=START_STATE, sensor_rate_hz=PHONE_FRAME_RATE_HZ, preview=False, seed=0,
        max_time_s=1200.0, latency_s=None, case: str = "vbar", environment: str = "lab",
        eclipse_in_s: float = ECLIPSE_IN_S, raan_deg: float = RAAN_DEG, transition: str = "entry",
        thrust: ThrustErrors | None = None, prior_scale: float = 1.0, sensor_model: str | None = None) -> dict:
    """One closed-loop approach. ``phone`` None: the ideal sensor (no latency). ``case``: the
    corridor (:data:`CASES`); ``environment="orbit"``: the sun from the orbit (astropy, at
    :data:`svgs_sim.sim.orbit_light.SUN_EPOCH_UTC`), the Earth, Basilisk's eclipse module, the
    approach starting ``eclipse_in_s`` before the eclipse's entry (``transition="exit"``: its exit).
    ``thrust``: the thrusters' errors (:class:`ThrustErrors`; default ideal); ``prior_scale``: the
    hand-over's 1-sigma as a multiple of :data:`PRIOR_SIGMA_M` and :data:`PRIOR_SIGMA_M_S`;
    ``sensor_model``: the phone's statistical sensor from this table (``sensor_model.json`` or its
    folder; :class:`svgs_sim.sim.statistical_sensor.StatisticalSensor`) instead of rendered frames.
    Returns the logs and the summary numbers."""
    from Basilisk.simulation import extForceTorque, spacecraft
    from Basilisk.utilities import SimulationBaseClass, macros, simIncludeGravBody

    from svgs_sim.sim.basilisk_svgs import PROCESSING_LATENCY_S, SVGSModule
    from svgs_sim.sim.orbit_light import beta_angle_deg, sun_direction_gcrs
    from svgs_sim.base.profiles import Camera

    pattern_mount, camera_mount, _ = CASES[case]
    orbit = environment == "orbit"
    sun_N = sun_direction_gcrs() if orbit else None

    ideal = phone is None
    lat = 0.0 if ideal else (PROCESSING_LATENCY_S if latency_s is None else float(latency_s))
    sim = SimulationBaseClass.SimBaseClass()
    proc = sim.CreateNewProcess("proc")
    sensor_dt = 0.25
    proc.addTask(sim.CreateNewTask("dyn", macros.sec2nano(sensor_dt)), 30)
    proc.addTask(sim.CreateNewTask("sensor", macros.sec2nano(sensor_dt)), 20)
    proc.addTask(sim.CreateNewTask("gnc", macros.sec2nano(CONTROL_PERIOD_S)), 10)
    grav = simIncludeGravBody.gravBodyFactory()
    earth = grav.createEarth()
    earth.isCentralBody = True
    mu = earth.mu
    tgt, ch = spacecraft.Spacecraft(), spacecraft.Spacecraft()
    tgt.ModelTag, ch.ModelTag = "target", "chaser"
    tgt.hub.mHub, ch.hub.mHub = TARGET_MASS_KG, CHASER_MASS_KG
    tgt.hub.IHubPntBc_B = TARGET_INERTIA.tolist()
    ch.hub.IHubPntBc_B = CHASER_INERTIA.tolist()
    for sc in (tgt, ch):
        grav.addBodiesTo(sc)
    thr = extForceTorque.ExtForceTorque()
    thr.ModelTag = "thrusters"
    ch.addDynamicEffector(thr)
    r_t, v_t, HN, n, u0_deg = _place_target(tgt, mu, sun_N, raan_deg, eclipse_in_s, transition)
    rho = _place_chaser(ch, start_state, r_t, v_t, HN, n, camera_mount, pattern_mount)
    for sc in (tgt, ch):
        sim.AddModelToTask("dyn", sc, 10)
    sim.AddModelToTask("dyn", thr, 9)
    # the sensor
    sensor = _sensor(phone, preview=preview, seed=seed, rate_hz=sensor_rate_hz, orbit=orbit, sensor_model=sensor_model)
    svgs_mod = SVGSModule(sensor, camera_mount, pattern_mount, frame_rate_hz=sensor_rate_hz, latency_s=lat)
    svgs_mod.ModelTag = "svgs"
    svgs_mod.chaserStateInMsg.subscribeTo(ch.scStateOutMsg)
    svgs_mod.targetStateInMsg.subscribeTo(tgt.scStateOutMsg)
    light = None
    if orbit and phone is not None:  # the ideal sensor renders nothing: no light to set
        light = _orbit_light(sim, tgt, sun_N)
        svgs_mod.sunInMsg.subscribeTo(light[0])
        svgs_mod.eclipseInMsg.subscribeTo(light[2].eclipseOutMsgs[0])
    sim.AddModelToTask("sensor", svgs_mod)
    # navigation, guidance, control; the filter starts from a seeded draw around the truth
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 27]))
    P0 = np.diag([PRIOR_SIGMA_M**2] * 3 + [PRIOR_SIGMA_M_S**2] * 3) * float(prior_scale) ** 2
    x0 = np.concatenate([rho, np.zeros(3)]) + rng.multivariate_normal(np.zeros(6), P0)
    fx_full = Camera.load(phone).fx if phone else 1.0
    pixel_scale = fx_full / sensor.camera.fx if phone else 1.0
    gnc = _make_gnc_class()(svgs_mod.measurementOutMsg, n, x0, P0, ideal, pixel_scale, camera_mount, pattern_mount,
                            thrust)
    gnc.ModelTag = "gnc"
    gnc.targetStateInMsg.subscribeTo(tgt.scStateOutMsg)
    gnc.chaserStateInMsg.subscribeTo(ch.scStateOutMsg)
    thr.cmdForceInertialInMsg.subscribeTo(gnc.forceOutMsg)
    sim.AddModelToTask("gnc", gnc)
    sim.InitializeSimulation()
    wall0 = time.perf_counter()
    _fly(sim, gnc, sensor, max_time_s)
    wall = time.perf_counter() - wall0
    out = _run_summary(gnc, phone, preview, sensor_rate_hz, lat, wall)
    out["summary"]["case"] = case
    out["summary"]["environment"] = environment
    if orbit:
        out["summary"]["orbit"] = _orbit_summary(svgs_mod.light_log, gnc.meas_log, n, u0_deg,
                                                 beta_angle_deg(r_t, v_t, sun_N), raan_deg)
        out["light"] = svgs_mod.light_log
    del light
    return out


def _fly(sim, gnc, sensor, max_time_s: float) -> None:
    """Run the simulation 10 s at a time until arrival or ``max_time_s``; a pose the statistical sensor
    refused (Basilisk wraps the sensor's exception in its own) is raised as the refusal itself."""
    from Basilisk.utilities import macros

    t_end = 0.0
    try:
        while t_end < max_time_s and gnc.arrived_s is None:
            t_end = min(t_end + 10.0, max_time_s)
            sim.ConfigureStopTime(macros.sec2nano(t_end))
            try:
                sim.ExecuteSimulation()
            except RuntimeError:
                if getattr(sensor, "refused", None):
                    from svgs_sim.sim.statistical_sensor import OutsideEnvelope

                    raise OutsideEnvelope(sensor.refused) from None
                raise
    finally:
        if hasattr(sensor, "close"):
            sensor.close()


def _orbit_summary(light_log, meas, n_rad_s, u0_deg, beta_deg, raan_deg) -> dict:
    """Dropouts and wrong locks against the orbit's phase: sunlit and eclipsed frames, the eclipse's
    entry and exit within the run, the frames from each transition to the next solution (the
    auto-exposure's lag)."""
    lit = {round(x["t_s"], 6): x["sunlit"] for x in light_log}
    rows = [dict(m, sunlit=lit.get(round(m["t_s"], 6))) for m in meas]
    trans = [(b["t_s"], "entry" if a["sunlit"] else "exit") for a, b in zip(light_log, light_log[1:])
             if a["sunlit"] != b["sunlit"]]

    def tally(sel):
        # solved: a correct pose; a wrong lock: a pose the app would report (solved, or refused only by the
        # consistency test: then also a dropout "inconsistent") with a blob off its target's spot
        return {"frames": len(sel), "solved": sum(r["ok"] and not r["wrong_lock"] for r in sel),
                "wrong_locks": sum(r["wrong_lock"] for r in sel),
                "wrong_locks_solved": sum(r["ok"] and r["wrong_lock"] for r in sel),
                "wrong_locks_accepted": sum(r["wrong_lock"] and r["accepted"] for r in sel),
                "dropouts_by_reason": dict(sorted(((k, sum(1 for r in sel if not r["ok"] and r["reason"] == k))
                                                   for k in {r["reason"] for r in sel if not r["ok"]})))}

    lag = []
    for t_tr, kind in trans:
        after = [r for r in rows if r["t_s"] >= t_tr - 1e-9]
        first = next((r for r in after if r["ok"] and not r["wrong_lock"]), None)
        lag.append({"transition": kind, "t_s": t_tr, "frames_to_first_solution": None if first is None
                    else after.index(first), "time_to_first_solution_s": None if first is None else first["t_s"] - t_tr})
    return {"beta_deg": beta_deg, "raan_deg": raan_deg, "start_phase_deg": u0_deg,
            "phase_rate_deg_s": float(np.degrees(n_rad_s)), "transitions": lag,
            "sunlit": tally([r for r in rows if r["sunlit"]]), "eclipse": tally([r for r in rows if r["sunlit"] is False])}


def _run_summary(gnc, phone, preview, sensor_rate_hz, latency_s, wall_s) -> dict:
    """The logs of one finished run as arrays, and its summary numbers (arrival time, delta-v,
    final errors, frames solved and accepted, dropouts by reason)."""
    lat, wall = latency_s, wall_s
    log = {k: np.asarray(v) for k, v in gnc.log.items()}
    a = np.linalg.norm(log["a_applied"], axis=1)  # what the thrusters gave (= the command when ideal)
    arrived = gnc.arrived_s is not None
    i_end = int(np.argmin(np.abs(log["t_s"] - gnc.arrived_s))) if arrived else len(a) - 1
    final_true = log["cam_true"][i_end]
    ml = gnc.meas_log
    summary = {
        "sensor": phone or "ideal",
        "preview": bool(preview and phone is not None),
        "sensor_rate_hz": sensor_rate_hz,
        "latency_s": lat,
        "arrived": arrived,
        "time_s": float(gnc.arrived_s) if arrived else None,
        "delta_v_m_s": float(np.sum(a[: i_end + 1]) * CONTROL_PERIOD_S),
        "final_position_error_m": [float(final_true[0]), float(final_true[1]), float(final_true[2] - GOAL_Z_M)],
        "final_position_error_norm_m": float(np.linalg.norm(final_true - [0, 0, GOAL_Z_M])),
        "final_navigation_error_m": (log["cam_hat"][i_end] - final_true).tolist(),
        "frames": len(ml),
        "frames_solved": int(sum(m["ok"] for m in ml)),
        "wrong_locks": int(sum(m.get("wrong_lock", False) for m in ml)),  # of them, or "inconsistent" dropouts
        "wrong_locks_accepted": int(sum(m.get("wrong_lock", False) and m["accepted"] for m in ml)),
        "frames_accepted": int(sum(m["accepted"] for m in ml)),
        "dropouts_by_reason": {r: sum(1 for m in ml if not m["ok"] and m["reason"] == r)
                               for r in sorted({m["reason"] for m in ml if not m["ok"]})},
        "first_solved_range_m": next((float(m["truth"]["z_m"]) for m in ml if m["ok"]), None),
        "hold_s": float(np.sum(log["hold"]) * CONTROL_PERIOD_S),
        "wall_s": round(wall, 1),
    }
    return {"summary": summary, "log": log, "meas": ml}


# ----------------------------------------------------------------------------- Monte Carlo
#: The dispersions of ``--monte-carlo`` (1-sigma; each an ASSUMPTION, none sourced to a mission):
#: the true start's lateral offset and range (m, at the 30 m start; scaled by the start's range over
#: 30 m), its attitude (deg per axis), the hand-over's navigation error (the filter's initial
#: estimate drawn from its prior, :data:`PRIOR_SIGMA_M`, :data:`PRIOR_SIGMA_M_S`, per run), the
#: thrusters' magnitude error (a fraction: cold-gas thrusters hold 2-5 %) and misalignment (deg),
#: and the minimum impulse bit (N s; tens of mN thrusters open for ~10 ms at least).
MC_START_SIGMA_M = (0.15, 0.15, 0.6)
MC_START_ATTITUDE_SIGMA_DEG = 1.0
MC_THRUST_SCALE_SIGMA = 0.03
MC_THRUST_ANGLE_SIGMA_DEG = 1.0
MC_MIN_IMPULSE_N_S = 5e-4
#: Runs of each sensor whose dispersions and true path ``montecarlo.json`` keeps (all of the ideal sensor's).
MC_PLOTTED_RUNS = 20
#: The quantities ``montecarlo.json`` gives percentiles of.
MC_KEYS = ("arrival_error_m", "arrival_time_s", "delta_v_m_s", "dropouts", "wrong_locks")


def mc_seeds(base_seed: int, n: int) -> list[int]:
    """``n`` distinct run seeds from ``base_seed`` (``numpy.random.SeedSequence.spawn``), 32 bits each."""
    return [int(c.generate_state(1)[0]) for c in np.random.SeedSequence(int(base_seed)).spawn(int(n))]


def mc_dispersions(seed: int, start_state) -> tuple[list[dict], dict]:
    """One run's dispersed values, drawn from its seed, and recorded as Basilisk's
    ``Basilisk.utilities.MonteCarlo`` records its dispersions (the class that made each one, the
    variable, its parameters, the value drawn).

    Returns
    -------
    records : list of dict
        ``dispersion``, ``variable``, ``mean``, ``stdDeviation``, ``value``.
    kwargs : dict
        ``start_state``, ``thrust`` (:class:`ThrustErrors`) for :func:`run`.
    """
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 40]))
    s0 = np.asarray(start_state, float)
    k = s0[2] / 30.0
    dpos = rng.normal(0.0, np.asarray(MC_START_SIGMA_M) * k)
    datt = rng.normal(0.0, MC_START_ATTITUDE_SIGMA_DEG, 3)
    start = s0 + np.concatenate([dpos, datt])
    scale = 1.0 + rng.normal(0.0, MC_THRUST_SCALE_SIGMA)
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    ang = np.radians(rng.normal(0.0, MC_THRUST_ANGLE_SIGMA_DEG))
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    R = np.eye(3) + np.sin(ang) * K + (1 - np.cos(ang)) * K @ K  # Rodrigues
    records = [
        {"dispersion": "NormalVectorCartDispersion", "variable": "start_position_m", "mean": s0[:3].tolist(),
         "stdDeviation": (np.asarray(MC_START_SIGMA_M) * k).tolist(), "value": start[:3].tolist()},
        {"dispersion": "NormalVectorCartDispersion", "variable": "start_attitude_deg", "mean": s0[3:].tolist(),
         "stdDeviation": [MC_START_ATTITUDE_SIGMA_DEG] * 3, "value": start[3:].tolist()},
        {"dispersion": "NormalDispersion", "variable": "thrust_scale", "mean": 1.0,
         "stdDeviation": MC_THRUST_SCALE_SIGMA, "value": scale},
        {"dispersion": "NormalDispersion", "variable": "thrust_misalignment_deg", "mean": 0.0,
         "stdDeviation": MC_THRUST_ANGLE_SIGMA_DEG, "value": float(np.degrees(ang)), "axis": axis.tolist()},
        {"dispersion": "fixed", "variable": "min_impulse_n_s", "value": MC_MIN_IMPULSE_N_S},
        {"dispersion": "NormalVectorCartDispersion", "variable": "handover_navigation_error",
         "mean": [0.0] * 6, "stdDeviation": [PRIOR_SIGMA_M] * 3 + [PRIOR_SIGMA_M_S] * 3,
         "value": "drawn in run() from the run's seed"},
    ]
    return records, {"start_state": tuple(start), "thrust": ThrustErrors(scale, R, MC_MIN_IMPULSE_N_S)}


def mc_run(task: dict) -> dict:
    """One Monte Carlo run (a task of the executor): :func:`run` with the run's dispersions; its
    outcome as ``montecarlo.json`` records it, with the dispersions and a thinned trajectory where
    the task asks for them (``keep_detail``)."""
    from svgs_sim.sim.statistical_sensor import OutsideEnvelope

    records, kw = mc_dispersions(task["seed"], task["start_state"])
    try:
        r = run(task["phone"], seed=task["seed"], sensor_rate_hz=task["rate"], preview=task["preview"],
                max_time_s=task["max_time_s"], case=task["case"], environment=task["environment"],
                sensor_model=task.get("sensor_model"), **kw)
    except OutsideEnvelope as exc:  # the statistical sensor refused a pose its table says nothing of: no result
        return {"phone": task.get("label") or task["phone"], "seed": task["seed"], "refused": str(exc),
                **{k: None for k in MC_KEYS}, "dropouts_by_reason": None, "frames": None, "wall_s": None,
                "sensor_model_sha256": task.get("sensor_model_sha256")}
    s = r["summary"]
    dropouts = sum(s["dropouts_by_reason"].values())
    out = {"phone": task.get("label") or task["phone"] or "ideal", "seed": task["seed"],
           "arrival_error_m": s["final_position_error_norm_m"] if s["arrived"] else None,
           "arrival_time_s": s["time_s"], "delta_v_m_s": s["delta_v_m_s"], "dropouts": dropouts,
           "dropouts_by_reason": s["dropouts_by_reason"], "wrong_locks": s["wrong_locks"], "frames": s["frames"],
           "wall_s": s["wall_s"]}
    if task.get("sensor_model_sha256"):
        out["sensor_model_sha256"] = task["sensor_model_sha256"]
    if task.get("keep_detail", True):
        traj = r["log"]["cam_true"][:: max(1, len(r["log"]["cam_true"]) // 100)]
        out.update({"dispersions": records, "trajectory_cam_m": np.round(np.asarray(traj), 4).tolist()})
    return out


def order_statistic_interval(values, q: float, level: float = 0.90):
    """A distribution-free interval for the ``q`` quantile: the order statistics ``[x_(l), x_(u)]``
    with ``P(x_(l) <= xi_q <= x_(u)) >= level`` by the binomial law of how many samples fall below
    ``xi_q``; a bound the sample is too small for is None.

    Parameters
    ----------
    values : array_like, shape (n,)
    q : float
        The quantile, 0-1.
    level : float
        The interval's coverage.

    Returns
    -------
    [lo, hi] : list of float or None
    """
    from scipy.stats import binom

    x = np.sort(np.asarray(values, float))
    n = x.size
    if n == 0:
        return [None, None]
    tail = (1.0 - level) / 2
    cdf = binom.cdf(np.arange(n + 1), n, q)  # cdf[j] = P(fewer than j + 1 samples below xi_q)
    lows = [j for j in range(1, n + 1) if cdf[j - 1] <= tail]  # P(B < l) <= tail
    highs = [j for j in range(1, n + 1) if cdf[j - 1] >= 1 - tail]  # P(B < u) >= 1 - tail
    return [float(x[max(lows) - 1]) if lows else None, float(x[min(highs) - 1]) if highs else None]


def mc_percentiles(runs: list[dict]) -> dict:
    """``{key: {"p50", "p90", "p99", "ci90": {"p50": [lo, hi], ...}, "n", "missing"}}`` over the runs
    (a run that never arrived has no arrival error or time: counted in ``missing``)."""
    out = {}
    for key in MC_KEYS:
        v = np.array([r[key] for r in runs if r[key] is not None], float)
        out[key] = {"n": int(v.size), "missing": len(runs) - int(v.size)}
        for q, name in ((0.5, "p50"), (0.9, "p90"), (0.99, "p99")):
            out[key][name] = float(np.quantile(v, q)) if v.size else None
        out[key]["ci90"] = {name: order_statistic_interval(v, q) for q, name in ((0.5, "p50"), (0.9, "p90"), (0.99, "p99"))}
    return out


def _mc_tasks(phones, n: int, statistical_runs: int, sensor_models: dict, common: dict, seeds: list) -> list[dict]:
    """The runs of a Monte Carlo: the ideal sensor on every seed, each phone rendered on the first
    ``n`` seeds and drawn from its sensor model on the first ``statistical_runs`` (the same seeds)."""
    tasks = [{"phone": None, "label": "ideal", "seed": sd, **common} for sd in seeds]
    for ph in phones:  # the statistical runs first: seconds each, where a rendered run takes minutes
        tasks += [{"phone": ph, "label": f"{ph} (statistical)", "seed": sd, "sensor_model": sensor_models[ph],
                   "sensor_model_sha256": _sha256(sensor_models[ph]), **common} for sd in seeds[:statistical_runs]]
    for ph in phones:
        tasks += [{"phone": ph, "label": ph, "seed": sd, **common} for sd in seeds[:n]]
    for t in tasks:  # dispersions and paths kept for the ideal runs (every seed) and the first runs of each sensor
        t["keep_detail"] = t["label"] == "ideal" or seeds.index(t["seed"]) < MC_PLOTTED_RUNS
    return tasks


def _sha256(model) -> str:
    """The SHA-256 of a sensor model's ``sensor_model.json`` (a folder holding one, or the file)."""
    p = Path(model)
    return hashlib.sha256(((p / "sensor_model.json") if p.is_dir() else p).read_bytes()).hexdigest()


#: What a stored run's numbers depend on besides its sensor and seed: a stored Monte Carlo with other
#: values is refused; the phones and the run counts may change (the seeds are the same spawned prefix).
MC_RUN_KEYS = ("base_seed", "start_state", "rate", "preview", "max_time_s", "case", "environment")


def _mc_stored(out: Path, manifest: dict) -> dict:
    """The runs a killed (or smaller) Monte Carlo in ``out`` finished (``montecarlo_runs.jsonl``, one line a
    run), by ``(label, seed)``: a folder holding runs with other :data:`MC_RUN_KEYS` is refused; a
    statistical run drawn from another table than today's (its ``sensor_model_sha256``) is set aside."""
    mpath, rpath = out / "montecarlo_manifest.json", out / "montecarlo_runs.jsonl"
    if mpath.exists():
        stored = json.loads(mpath.read_text(encoding="utf-8"))
        diff = [k for k in MC_RUN_KEYS if stored.get(k) != manifest.get(k)]
        if diff:
            raise InputError(f"--out: {str(out)!r} holds a Monte Carlo with other {', '.join(diff)}; rerun with its "
                             "arguments to continue it, or choose another --out")
    elif rpath.exists():
        raise InputError(f"--out: {str(out)!r} holds montecarlo_runs.jsonl but no montecarlo_manifest.json; "
                         "choose another --out")
    out.mkdir(parents=True, exist_ok=True)
    mpath.write_text(json.dumps(manifest, indent=1) + "\n", encoding="utf-8")
    records = {}
    if rpath.exists():
        for line in rpath.read_text(encoding="utf-8").splitlines():
            try:
                r = json.loads(line)
            except json.JSONDecodeError:  # a line cut by the kill: that run is run again
                continue
            records[(r["phone"], r["seed"])] = r
    report = out / "montecarlo.json"  # the committed form: its runs count as stored too (no runs file needed)
    if report.exists():
        d = json.loads(report.read_text(encoding="utf-8"))
        for r in d.get("ideal_runs", []) + [r for v in d.get("sensors", {}).values() for r in v.get("runs", [])]:
            records.setdefault((r["phone"], r["seed"]), r)
    done, stale, shas = {}, 0, manifest.get("sensor_model_sha256", {})
    for key, r in records.items():
        ph = r["phone"].removesuffix(" (statistical)")
        if r["phone"] != ph and r.get("sensor_model_sha256") != shas.get(ph):
            stale += 1  # drawn from another table
            continue
        done[key] = r
    if stale:
        print(f"monte carlo: {stale} stored statistical runs were drawn from other sensor models: flown again",
              file=sys.stderr, flush=True)
    return done


def monte_carlo(phones, n: int, *, base_seed: int, start_state, rate: float, preview: bool, max_time_s: float,
                case: str, environment: str, spec, out: Path, statistical_runs: int = 0,
                sensor_models: dict | None = None, report_only: bool = False) -> dict:
    """``--monte-carlo N``: per phone N runs with dispersed true initial states, hand-over errors,
    sensor seeds and thruster errors (:func:`mc_dispersions`), the ideal sensor on the same seeds and
    dispersions, and with ``statistical_runs`` M the phone's statistical sensor (``sensor_models``: its
    table) on the first M seeds (the rendered runs' N among them); the runs on the project's executors
    (:func:`svgs_sim.studies.execution.open_executor`: a process pool or Dask; each run is one task, so a
    cluster takes them unchanged). Each finished run is kept in ``out/montecarlo_runs.jsonl``: a killed
    Monte Carlo continues where it stopped when rerun with the same arguments; ``report_only``: nothing
    is flown, the report holds the runs stored so far (each sensor's ``runs_done`` of its
    ``runs_requested``). Writes ``out/montecarlo.json`` and ``out/montecarlo.png``."""
    from concurrent.futures import as_completed

    from svgs_sim.studies.execution import open_executor

    # the runs go to other processes by reference: this file as the importable module basilisk_docking
    # (run as a script it is __main__; a spawned worker imports it by name from the folder added here)
    import importlib

    here = str(Path(__file__).resolve().parent)
    if here not in sys.path:
        sys.path.insert(0, here)
    task_fn = importlib.import_module("basilisk_docking").mc_run
    seeds = mc_seeds(base_seed, max(n, statistical_runs))
    common = {"start_state": tuple(start_state), "rate": rate, "preview": preview, "max_time_s": max_time_s,
              "case": case, "environment": environment}
    tasks = _mc_tasks(phones, n, statistical_runs, sensor_models or {}, common, seeds)
    manifest = {"phones": list(phones), "runs_per_sensor": n, "statistical_runs": statistical_runs,
                "base_seed": base_seed, **{k: (list(v) if isinstance(v, tuple) else v) for k, v in common.items()},
                "sensor_models": {k: str(v) for k, v in (sensor_models or {}).items()},
                "sensor_model_sha256": {k: _sha256(v) for k, v in (sensor_models or {}).items()}}
    done = _mc_stored(out, manifest)
    todo = [t for t in tasks if (t["label"], t["seed"]) not in done]
    if done:
        print(f"monte carlo: {len(tasks) - len(todo)} of {len(tasks)} runs already in {out}/montecarlo_runs.jsonl",
              file=sys.stderr, flush=True)
    if todo and report_only:
        print(f"monte carlo: --report-only: {len(todo)} runs not flown yet; the report holds the "
              f"{len(tasks) - len(todo)} stored", file=sys.stderr, flush=True)
    elif todo:
        with open_executor(spec) as ex, open(out / "montecarlo_runs.jsonl", "a", encoding="utf-8") as log:
            futs = [ex.submit(task_fn, t) for t in todo]
            for k, f in enumerate(as_completed(futs), 1):
                r = f.result()
                log.write(json.dumps(r) + "\n")
                log.flush()
                done[(r["phone"], r["seed"])] = r
                what = (f"delta-v {r['delta_v_m_s'] * 100:.2f} cm/s" if r.get("refused") is None
                        else f"refused by the sensor model: {r['refused']}")
                print(f"monte carlo: {k}/{len(todo)} runs ({r['phone']}, seed {r['seed']}: {what})",
                      file=sys.stderr, flush=True)
    obj = _mc_result(phones, n, statistical_runs, seeds, done, manifest)
    (out / "montecarlo.json").write_text(json.dumps(obj) + "\n", encoding="utf-8")  # one line: ~1 MB for 1500 runs
    counts = ", ".join(f"{k} {len(v['runs'])}" for k, v in obj["sensors"].items())
    plot_monte_carlo({k: v["runs"] for k, v in obj["sensors"].items()} | {"ideal": obj["ideal_runs"]},
                     out / "montecarlo.png", f"Monte Carlo, {rate:g} frames/s, {start_state[2]:g} m -> {GOAL_Z_M:g} m; "
                     f"runs: {counts}")
    return obj


def _mc_result(phones, n: int, statistical_runs: int, seeds: list, done: dict, manifest: dict) -> dict:
    """``montecarlo.json``: the parameters, each sensor's runs and percentiles, the ideal runs, and for
    each phone with both sensors the statistical sensor on the rendered runs' seeds beside the rendered."""
    def runs_of(label, k):  # the stored runs of the first k seeds (all of them but under --report-only)
        out = [dict(done[(label, sd)]) for sd in seeds[:k] if (label, sd) in done]
        for r in out[MC_PLOTTED_RUNS:]:  # the figure draws the first paths only
            r.pop("trajectory_cam_m", None)
        return out

    obj = {"sensor_rate_hz": manifest["rate"], **{k: v for k, v in manifest.items() if k != "rate"},
           "dispersion_sigmas": {"start_position_m_at_30m": list(MC_START_SIGMA_M),
                                 "start_attitude_deg": MC_START_ATTITUDE_SIGMA_DEG,
                                 "thrust_scale": MC_THRUST_SCALE_SIGMA, "thrust_misalignment_deg": MC_THRUST_ANGLE_SIGMA_DEG,
                                 "min_impulse_n_s": MC_MIN_IMPULSE_N_S,
                                 "handover_position_m": PRIOR_SIGMA_M, "handover_velocity_m_s": PRIOR_SIGMA_M_S},
           "sensors": {}, "ideal_runs": runs_of("ideal", len(seeds))}
    obj["ideal_percentiles"] = mc_percentiles(obj["ideal_runs"])
    for ph in phones:
        for label, k in ((ph, n), (f"{ph} (statistical)", statistical_runs)):
            if k:
                runs = runs_of(label, k)
                obj["sensors"][label] = {"runs": runs, "percentiles": mc_percentiles(runs), "runs_requested": k,
                                         "runs_done": len(runs), "runs_refused": sum(1 for r in runs if r.get("refused"))}
        if n and statistical_runs:  # on the seeds of the rendered runs done
            rendered = {r["seed"] for r in obj["sensors"][ph]["runs"]}
            obj["sensors"][f"{ph} (statistical)"]["percentiles_on_rendered_seeds"] = mc_percentiles(
                [r for r in obj["sensors"][f"{ph} (statistical)"]["runs"] if r["seed"] in rendered])
    obj["complete"] = all(v["runs_done"] == v["runs_requested"] for v in obj["sensors"].values())
    if len(phones) == 1 and n:  # the layout for one phone: its runs and percentiles at the top
        obj["runs"], obj["percentiles"] = obj["sensors"][phones[0]]["runs"], obj["sensors"][phones[0]]["percentiles"]
    return obj


def plot_monte_carlo(by: dict, path: Path, title: str) -> None:
    """The dispersion figure: each run's true camera path (lateral offset against range), the
    arrival errors and the delta-v per sensor."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(13, 4), constrained_layout=True)
    FigureCanvasAgg(fig)
    ax = fig.subplots(1, 3)
    phones = [p for p in by if p != "ideal" and not p.endswith("(statistical)")]
    base = {"ideal": "k", **dict(zip(phones, ("tab:blue", "tab:orange", "tab:green", "tab:red")))}
    for ph, runs in by.items():
        stat = ph.endswith(" (statistical)")
        color, ls = base.get(ph.removesuffix(" (statistical)"), "tab:gray"), "--" if stat else "-"
        drawn = [r for r in runs if r.get("trajectory_cam_m")][:MC_PLOTTED_RUNS]
        for i, r in enumerate(drawn):
            tr = np.asarray(r["trajectory_cam_m"])
            ax[0].plot(tr[:, 2], np.hypot(tr[:, 0], tr[:, 1]) * 100, color=color, ls=ls, lw=0.7, alpha=0.6,
                       label=f"{ph} ({len(drawn)} paths)" if i == 0 else None)
        arr = [r["arrival_error_m"] * 100 for r in runs if r["arrival_error_m"] is not None]
        kw = {"bins": 20, "histtype": "step", "color": color, "ls": ls, "density": True}
        if arr:
            ax[1].hist(arr, label=f"{ph} ({len(arr)} of {len(runs)} arrived)", **kw)
        dv = [r["delta_v_m_s"] * 100 for r in runs if r["delta_v_m_s"] is not None]
        if dv:
            ax[2].hist(dv, label=f"{ph} ({len(runs)} runs)", **kw)
    if not any(r["arrival_error_m"] is not None for runs in by.values() for r in runs):
        ax[1].text(0.5, 0.5, "no run arrived within the time limit", ha="center", va="center",
                   transform=ax[1].transAxes)
    ax[0].invert_xaxis()
    ax[0].set_xlabel("range along the pattern's axis, m")
    ax[0].set_ylabel("lateral offset, cm")
    ax[0].set_title("true camera paths", fontsize=9)
    ax[1].set_xlabel("arrival error (final position against the goal), cm")
    ax[1].set_ylabel("density (each sensor's runs)")
    ax[2].set_xlabel("delta-v, cm/s")
    for a in ax:
        if a.get_legend_handles_labels()[0]:
            a.legend(fontsize=7)
    fig.suptitle(title, fontsize=10)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=80)


# ----------------------------------------------------------------------------- figures
def plot_orbit(r: dict, path: Path, title: str) -> None:
    """Against time (and the orbit's phase): each frame's outcome (solved, dropout by reason, wrong
    lock), the sun's elevation over the pattern plane and the eclipse, the exposure time."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    ml, light, orb = r["meas"], r["light"], r["summary"]["orbit"]
    fig = Figure(figsize=(11, 7.5), constrained_layout=True)
    FigureCanvasAgg(fig)
    ax1, ax2, ax3 = fig.subplots(3, 1, sharex=True)
    tl = np.array([x["t_s"] for x in light])
    dark = np.array([not x["sunlit"] for x in light])
    for ax in (ax1, ax2, ax3):
        if tl.size:
            ax.fill_between(tl, 0, 1, where=dark, transform=ax.get_xaxis_transform(), color="0.85", lw=0,
                            label="eclipse")
    t = np.array([m["t_s"] for m in ml])
    reasons = sorted({m["reason"] for m in ml if not m["ok"]})
    ys = {"solved": 0, **{k: i + 1 for i, k in enumerate(reasons)}}
    ok = np.array([m["ok"] and not m["wrong_lock"] for m in ml], bool)
    ax1.plot(t[ok], np.zeros(ok.sum()), "o", ms=3, color="tab:green", label="solved")
    for k in reasons:
        sel = np.array([(not m["ok"]) and m["reason"] == k for m in ml], bool)
        ax1.plot(t[sel], np.full(sel.sum(), ys[k]), "x", ms=4, label=f"dropout: {k}")
    wl = np.array([m["wrong_lock"] for m in ml], bool)
    if wl.any():
        ax1.plot(t[wl], np.full(wl.sum(), -1), "*", ms=8, color="tab:red", label="WRONG LOCK")
    ax1.set_yticks([-1, *ys.values()], ["wrong lock", *ys.keys()])
    ax1.legend(fontsize=7, loc="upper right")
    ax1.set_title(title, fontsize=10)
    ax2.plot(tl, [x["sun_elevation_deg"] for x in light], color="tab:orange", label="sun elevation over the pattern plane")
    ax2.plot(tl, [x["earth_elevation_deg"] for x in light], color="tab:blue", label="Earth's centre elevation")
    ax2.set_ylabel("deg (target frame)")
    ax2.legend(fontsize=7)
    ex = np.array([np.nan if m["exposure_s"] is None else m["exposure_s"] for m in ml], float)
    ax3.semilogy(t, ex * 1e3, ".-", color="k", lw=0.8, ms=3)
    ax3.set_ylabel("exposure, ms")
    ax3.set_xlabel(f"t, s (orbit phase = {orb['start_phase_deg']:.1f} + {orb['phase_rate_deg_s']:.4f} t deg from "
                   "the ascending node)")
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=80)


def plot(runs: dict, path: Path, title: str) -> None:
    """True against estimated camera position and attitude in the target frame with the 1-sigma
    bands, the measurements (dropouts marked), and the control effort, for each run."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    labels = list(runs)
    fig = Figure(figsize=(13, 11), constrained_layout=True)
    FigureCanvasAgg(fig)
    axes = fig.subplots(4, len(labels), squeeze=False, sharex="col")
    names = ("x", "y", "z")
    colors = ("tab:blue", "tab:orange", "tab:green")
    for j, lab in enumerate(labels):
        r = runs[lab]
        L, ml, s = r["log"], r["meas"], r["summary"]
        t = L["t_s"]
        ax = axes[0, j]
        for i in (0, 1):  # lateral: estimate - truth with the filter's 1-sigma
            e = L["cam_hat"][:, i] - L["cam_true"][:, i]
            ax.plot(t, e * 100, color=colors[i], lw=1, label=f"{names[i]} estimate - truth")
            ax.fill_between(t, -L["cam_sigma"][:, i] * 100, L["cam_sigma"][:, i] * 100, color=colors[i], alpha=0.15,
                            lw=0)
        ax.set_ylabel("lateral nav error, cm")
        when = "not arrived" if s["time_s"] is None else f"arrived in {s['time_s']:.0f} s"
        ax.set_title(f"{lab}: {when}, delta-v {s['delta_v_m_s'] * 100:.1f} cm/s", fontsize=9)
        ax.legend(fontsize=7)
        ax = axes[1, j]
        ax.plot(t, L["cam_true"][:, 2], "k-", lw=1, label="true range z (m)")
        ax.plot(t, L["cam_hat"][:, 2], "--", color=colors[2], lw=1, label="estimated z")
        tm = np.array([m["t_s"] for m in ml])
        ok = np.array([m["ok"] for m in ml], bool)
        if tm.size:
            zs = np.array([m["state"]["z_m"] if m["ok"] else np.nan for m in ml])
            sz = np.array([m["sigma"][2] if m["sigma"] is not None else np.nan for m in ml])
            ax.errorbar(tm[ok], zs[ok], yerr=sz[ok], fmt=".", ms=3, color="tab:purple", lw=0.8,
                        label="measured z (1-sigma)")
            for td in tm[~ok]:
                ax.axvline(td, color="tab:red", alpha=0.25, lw=0.8)
        ax.plot([], [], color="tab:red", alpha=0.5, label="dropout")
        ax.set_yscale("log")
        ax.set_ylabel("range along the pattern's z, m")
        ax.legend(fontsize=7)
        ax = axes[2, j]
        for i, nm in enumerate(("roll", "pitch", "yaw")):
            ax.plot(t, np.degrees(L["att_true"][:, i]), "-", color=colors[i], lw=0.8, label=f"true {nm}")
            h, sg = np.degrees(L["att_hat"][:, i]), np.degrees(L["att_sigma"][:, i])
            ax.plot(t, h, "--", color=colors[i], lw=1)
            ax.fill_between(t, h - sg, h + sg, color=colors[i], alpha=0.15, lw=0)
        ax.set_ylabel("relative attitude, deg\n(-- estimate, band 1-sigma)")
        ax.legend(fontsize=7, ncol=3)
        ax = axes[3, j]
        a = L["a_H"] * CHASER_MASS_KG * 1e3
        ax.plot(t, np.linalg.norm(a, axis=1), color="k", lw=0.8, label="|force|")
        ax.set_ylabel("thrust, mN")
        ax.set_xlabel("t, s")
        ax2 = ax.twinx()
        ax2.plot(t, np.cumsum(np.linalg.norm(L["a_H"], axis=1)) * CONTROL_PERIOD_S * 100, color="tab:red", lw=1)
        ax2.set_ylabel("cumulative delta-v, cm/s", color="tab:red")
    fig.suptitle(title, fontsize=10)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=80)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--phones", default="galaxy-nexus,htc-amaze-4g",
                    help="comma-separated phone profiles flown after the ideal sensor")
    ap.add_argument("--sensor-rate-hz", type=float, default=None,
                    help=f"frames/s of the sensor (default the phone's own, {PHONE_FRAME_RATE_HZ:g}; the committed "
                         "single runs of docs/figures were made at 0.25)")
    ap.add_argument("--monte-carlo", type=int, default=None, metavar="N",
                    help="N runs per sensor with dispersed initial states, hand-over errors, sensor seeds and "
                         "thruster errors, and the ideal sensor on the same seeds: OUT/montecarlo.json and .png")
    ap.add_argument("--statistical-runs", type=int, default=None, metavar="M",
                    help="also M runs per phone with its statistical sensor (svgs sensor-model build) on the same "
                         "seeds, the N rendered ones first: the two side by side in OUT/montecarlo.json")
    ap.add_argument("--sensor-models", default="docs/reports/sensor-model-{phone}",
                    help="where each phone's sensor model is ({phone}: its name; default "
                         "docs/reports/sensor-model-{phone})")
    ap.add_argument("--report-only", action="store_true",
                    help="Monte Carlo: fly nothing; write montecarlo.json and .png from the runs stored in --out so "
                         "far (a Monte Carlo under way or stopped)")
    ap.add_argument("--processes", type=int, default=None, help="Monte Carlo: a local pool of N processes (0: here)")
    ap.add_argument("--workers", type=int, default=None, help="Monte Carlo: a Dask LocalCluster of N workers")
    ap.add_argument("--scheduler", default=None, help="Monte Carlo: a running Dask scheduler (tcp://HOST:PORT)")
    ap.add_argument("--preview", action="store_true", help="the phones' 640 x 480 preview stream")
    ap.add_argument("--quick", action="store_true",
                    help="a bounded form for the test suite: from 5 m, the preview stream, 40 s at most (the rate kept)")
    ap.add_argument("--max-time-s", type=float, default=None, help="simulated time limit, s (default 1200)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default="docs/figures", help="folder for basilisk_docking*.png and .json")
    ap.add_argument("--case", choices=sorted(CASES), default="vbar",
                    help="the approach corridor: vbar (the default; along-track from behind), rbar-below (from "
                         "below, deep space behind the target), rbar-above (from above, the Earth behind it)")
    ap.add_argument("--environment", choices=("lab", "orbit"), default="lab",
                    help="lab (the default: the paper's dark lab around the target) or orbit (the sun from the "
                         "orbit at a fixed epoch, the Earth, Basilisk's eclipse module; an orbit-phase figure)")
    ap.add_argument("--eclipse-in-s", type=float, default=ECLIPSE_IN_S,
                    help=f"orbit: start this long before the eclipse's entry (or exit, --transition), s (default "
                         f"{ECLIPSE_IN_S:g})")
    ap.add_argument("--transition", choices=("entry", "exit"), default="entry",
                    help="orbit: the eclipse transition the approach crosses: entry (the default; sunlit, then "
                         "shadow) or exit (shadow, then sunlit)")
    ap.add_argument("--raan-deg", type=float, default=RAAN_DEG,
                    help=f"orbit: the right ascension of the ascending node, deg (default {RAAN_DEG:g}; it sets beta)")
    ap.add_argument("--start-z-m", type=float, default=None,
                    help="start this far out along the pattern's axis, m (default 30; --quick 5)")
    args = ap.parse_args(argv)
    phones = [p.strip() for p in args.phones.split(",") if p.strip()]
    rate = args.sensor_rate_hz or PHONE_FRAME_RATE_HZ
    if not (np.isfinite(rate) and rate > 0):
        raise InputError(f"--sensor-rate-hz: expected a positive rate, got {rate!r}")
    start = (0.1, -0.05, 5.0, 2.0, -1.0, 3.0) if args.quick else START_STATE
    if args.start_z_m is not None:
        if not (np.isfinite(args.start_z_m) and GOAL_Z_M < args.start_z_m <= 60.0):
            raise InputError(f"--start-z-m: expected {GOAL_Z_M:g} < z <= 60 m, got {args.start_z_m!r}")
        start = (start[0], start[1], float(args.start_z_m), *start[3:])
    if not np.isfinite(args.eclipse_in_s) or not np.isfinite(args.raan_deg):
        raise InputError("--eclipse-in-s, --raan-deg: expected finite numbers")
    max_time = args.max_time_s or (40.0 if args.quick else 1200.0)
    preview = args.preview or args.quick
    out = Path(args.out)
    if args.monte_carlo is not None or args.statistical_runs is not None:
        return monte_carlo_from_args(args, phones, start, rate, preview, max_time, out)
    return single_runs(args, phones, start, rate, preview, max_time, out)


def check_sensor_models(args, phones, start, rate: float, preview: bool) -> dict:
    """Each phone's sensor model for ``--statistical-runs`` (``--sensor-models``), checked before any
    run: it loads, it is that phone's, at this frame rate, and the start lies inside its envelope."""
    from svgs_sim.sim.statistical_sensor import SensorTable

    if preview or args.environment != "lab":
        raise InputError("--statistical-runs: the sensor models are the lab's at full resolution (svgs sensor-model "
                         "build); they take neither --preview, --quick's preview nor --environment orbit")
    models = {}
    for ph in phones:
        path = args.sensor_models.format(phone=ph)
        t = SensorTable.load(path)
        if Path(t.camera).stem != Path(ph).stem:
            raise InputError(f"--sensor-models: {path!r} is the model of {t.camera}, not of {ph}")
        if abs(t.frame_rate_hz - rate) > 1e-9 * rate:
            raise InputError(f"--sensor-models: {path!r} was built at {t.frame_rate_hz:g} frames/s, the run takes "
                             f"{rate:g} (--sensor-rate-hz)")
        if not t.ranges_m[0] <= start[2] <= t.ranges_m[-1] or GOAL_Z_M < t.ranges_m[0]:
            raise InputError(f"--sensor-models: {path!r} covers {t.ranges_m[0]:g}-{t.ranges_m[-1]:g} m; the run goes "
                             f"from {start[2]:g} m to {GOAL_Z_M:g} m")
        models[ph] = path
    return models


def monte_carlo_from_args(args, phones, start, rate: float, preview: bool, max_time: float, out: Path) -> dict:
    """``--monte-carlo N`` and ``--statistical-runs M``: checked, then :func:`monte_carlo`."""
    from svgs_sim.studies.execution import executor_spec

    n, m = args.monte_carlo or 0, args.statistical_runs or 0
    if n < 0 or m < 0 or n + m < 1:
        raise InputError(f"--monte-carlo, --statistical-runs: expected runs (at least one in all), got {n} and {m}")
    models = check_sensor_models(args, phones, start, rate, preview) if m else {}
    spec = executor_spec(args.processes, args.workers, args.scheduler)
    mc = monte_carlo(phones, n, base_seed=args.seed, start_state=start, rate=rate, preview=preview,
                     max_time_s=max_time, case=args.case, environment=args.environment, spec=spec, out=out,
                     statistical_runs=m, sensor_models=models, report_only=args.report_only)
    print(f"wrote {out}/montecarlo.json and montecarlo.png")
    return mc


def single_runs(args, phones, start, rate: float, preview: bool, max_time: float, out: Path) -> dict:
    """The ideal sensor, then each phone, once each: their figures and ``basilisk_docking*.json``."""
    results = {}
    for phone in [None] + phones:
        r = run(phone, start_state=start, sensor_rate_hz=rate, preview=preview, seed=args.seed, max_time_s=max_time,
                case=args.case, environment=args.environment, eclipse_in_s=args.eclipse_in_s, raan_deg=args.raan_deg,
                transition=args.transition)
        results[phone or "ideal"] = r
        print(json.dumps(r["summary"]))
    tag = (f"_orbit_{args.case.replace('-', '_')}{'_exit' if args.transition == 'exit' else ''}"
           if args.environment == "orbit"
           else "" if args.case == "vbar" else f"_{args.case.replace('-', '_')}") + ("_quick" if args.quick else "")
    if args.environment == "orbit":
        for phone in phones:
            plot_orbit(results[phone], out / f"basilisk_docking{tag}_phase_{phone}.png",
                       f"{phone}, {args.case} on orbit (beta {results[phone]['summary']['orbit']['beta_deg']:.1f} deg), "
                       f"{start[2]:g} m start {args.eclipse_in_s:g} s before the eclipse's {args.transition}, "
                       f"{rate:g} frames/s"
                       f"{', preview' if preview else ''}")
    for phone in phones:
        plot({"ideal": results["ideal"], phone: results[phone]}, out / f"basilisk_docking{tag}_{phone}.png",
             f"Basilisk docking, {start[2]:g} -> {GOAL_Z_M:g} m, sensor {rate:g} frames/s, latency "
             f"{results[phone]['summary']['latency_s']:g} s{', preview' if preview else ''}: ideal sensor (left) "
             f"against {phone} (right)")
    summary = {k: v["summary"] for k, v in results.items()}
    for phone in phones:  # on orbit: each frame's light and outcome, for the phase plots
        if "light" in results[phone]:
            summary[phone]["frames_by_time"] = [
                {"t_s": m["t_s"], "ok": m["ok"], "reason": m["reason"], "wrong_lock": m["wrong_lock"],
                 "accepted": m["accepted"], "exposure_s": m["exposure_s"]} for m in results[phone]["meas"]]
            summary[phone]["light"] = results[phone]["light"]
    ideal = summary["ideal"]
    for phone in phones:
        s = summary[phone]
        s["cost_vs_ideal"] = {
            "delta_v_m_s": s["delta_v_m_s"] - ideal["delta_v_m_s"],
            "time_s": None if s["time_s"] is None or ideal["time_s"] is None else s["time_s"] - ideal["time_s"],
            "final_position_error_norm_m": s["final_position_error_norm_m"] - ideal["final_position_error_norm_m"],
        }
    out.mkdir(parents=True, exist_ok=True)
    (out / f"basilisk_docking{tag}.json").write_text(json.dumps(summary, indent=1) + "\n")
    print(f"wrote {out}/basilisk_docking{tag}*.png and .json")
    return summary


if __name__ == "__main__":
    main()
