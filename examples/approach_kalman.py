"""The SVGS sensor inside a user's own loop: a constant-velocity Kalman filter on its measurements.

A chaser closes from 12 m to 4 m in 16 s (0.5 m/s) with the target turned by (2, -1, 3) deg
and 0.2 m off the boresight. :class:`svgs_sim.sim.approach.ApproachSensor` takes the pose at each frame
time (here from a generator, as a dynamics simulation would give them) and returns a
measurement: the paper's state (the camera's position in the target frame, the attitude), its
1-sigma Cramer-Rao bound, ``ok`` and the reason. A constant-velocity Kalman filter, written with
numpy, filters the position; dropouts are simply skipped (prediction only).

The filter's measurement noise is the frame's CRLB with a floor (``FLOOR_M``), since the
simulated sensor's errors are not all noise: a filter removes scatter, never a bias.

Run: ``.venv/bin/python examples/approach_kalman.py [--out docs/figures/approach_kalman.png]``
(about 1.5 min on 2 cores; the numbers are seeded).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from svgs_sim.sim.approach import ApproachSensor  # noqa: E402
from svgs_sim.svgs.frames import pose_from_scenario  # noqa: E402

#: Frames per second of the sensor.
FPS = 2.0
#: White-acceleration spectral density of the constant-velocity model, m^2/s^3 (the chaser's
#: thrusting is unknown to the filter; this is the user's choice, not the sensor's).
Q_ACCEL = 1e-3
#: Floor added in quadrature to each frame's CRLB as the measurement sigma, m.
FLOOR_M = 0.02


def poses(duration_s=16.0, r0=12.0, r1=4.0):
    """(t_s, R_cam_target, t_cam_target_m) along the approach, one per frame."""
    for t in np.arange(0.0, duration_s + 1e-9, 1.0 / FPS):
        rng = r0 + (r1 - r0) * t / duration_s
        R, tv = pose_from_scenario(rng, 0.2, -0.1, 2.0, -1.0, 3.0)
        yield float(t), R, tv


def kalman(ts, z, sig):
    """Constant-velocity filter on 3-D positions: ``z`` (N, 3) (NaN rows: dropouts), ``sig`` (N, 3)
    measurement sigmas. Returns the filtered positions (N, 3)."""
    x = None
    P = None
    out = np.full_like(z, np.nan)
    H = np.hstack([np.eye(3), np.zeros((3, 3))])
    t_prev = None
    for k, t in enumerate(ts):
        if x is not None:
            dt = t - t_prev
            F = np.eye(6)
            F[:3, 3:] = dt * np.eye(3)
            Q = Q_ACCEL * np.block([[dt**3 / 3 * np.eye(3), dt**2 / 2 * np.eye(3)],
                                    [dt**2 / 2 * np.eye(3), dt * np.eye(3)]])
            x = F @ x
            P = F @ P @ F.T + Q
        if np.all(np.isfinite(z[k])):
            Rk = np.diag(sig[k] ** 2)
            if x is None:  # start on the first measurement, velocity unknown
                x = np.concatenate([z[k], np.zeros(3)])
                P = np.diag(np.concatenate([sig[k] ** 2, np.full(3, 1.0)]))
            else:
                S = H @ P @ H.T + Rk
                K = P @ H.T @ np.linalg.inv(S)
                x = x + K @ (z[k] - H @ x)
                P = (np.eye(6) - K @ H) @ P
        if x is not None:
            out[k] = x[:3]
        t_prev = t
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--camera", default="galaxy-nexus")
    ap.add_argument("--out", default="docs/figures/approach_kalman.png")
    args = ap.parse_args(argv)

    sensor = ApproachSensor(args.camera, seed=7)
    ts, truth, z, sig = [], [], [], []
    for m in sensor.stream(poses()):  # one measurement per pose, as the loop gives them
        ts.append(m.t_s)
        truth.append([m.truth[k] for k in ("x_m", "y_m", "z_m")])
        if m.ok:
            z.append([m.estimate[k] for k in ("x_m", "y_m", "z_m")])
            c = m.crlb_std or {}
            sig.append([np.hypot(c.get(k, 0.0) or 0.0, FLOOR_M) for k in ("x_m", "y_m", "z_m")])
        else:
            z.append([np.nan] * 3)
            sig.append([np.nan] * 3)
        print(f"t = {m.t_s:5.1f} s  range {m.range_m:5.2f} m  {'ok' if m.ok else m.reason:>12s}")
    ts, truth, z, sig = map(np.asarray, (ts, truth, z, sig))
    filt = kalman(ts, z, sig)
    raw_err, filt_err = z - truth, filt - truth

    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(9, 7), constrained_layout=True)
    FigureCanvasAgg(fig)
    axes = fig.subplots(3, 1, sharex=True)
    for i, (ax, name) in enumerate(zip(axes, ("x", "y", "z"))):
        ax.plot(ts, raw_err[:, i] * 1e3, ".", color="tab:blue", label="raw measurement - truth")
        ax.plot(ts, filt_err[:, i] * 1e3, "-", color="tab:orange", label="Kalman filter - truth")
        ax.fill_between(ts, -sig[:, i] * 1e3, sig[:, i] * 1e3, color="tab:green", alpha=0.2, lw=0,
                        label=f"measurement sigma (CRLB, {FLOOR_M * 1e3:.0f} mm floor)")
        ax.axhline(0, color="k", lw=0.5)
        ax.set_ylabel(f"{name} error, mm")
        rr = np.sqrt(np.nanmean(raw_err[:, i] ** 2)) * 1e3
        rf = np.sqrt(np.nanmean(filt_err[2:, i] ** 2)) * 1e3
        ax.set_title(f"camera {name} in the target frame: RMS raw {rr:.1f} mm, filtered {rf:.1f} mm", fontsize=9)
    axes[0].legend(fontsize=8)
    axes[-1].set_xlabel("t, s")
    fig.suptitle(f"{args.camera}: 12 -> 4 m at 0.5 m/s, {FPS:g} frames/s, constant-velocity Kalman filter")
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=90)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
