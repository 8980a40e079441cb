"""Benchmark (issue 40): a frame of the statistical sensor against a frame of the rendered sensor it
stands in for, and a closed-loop docking run with each.

Ours: :class:`svgs_sim.sim.statistical_sensor.StatisticalSensor` drawn from a committed table
(``docs/reports/sensor-model-<phone>/sensor_model.json``). Peer: :class:`svgs_sim.sim.approach.ApproachSensor`,
the rendered sensor (render, camera model, detection, identification, solution, bound), on the same
poses, measured in the same run. Prints each one's seconds a frame, the ratio, and one docking run's
wall time from 3 m with each (``examples/basilisk_docking.py``'s :func:`run`, Basilisk needed).

Run: ``.venv/bin/python benchmarks/bench_statistical_sensor.py [--camera NAME] [--frames N]``
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def poses(n: int, seed: int = 0):
    from svgs_sim.svgs.frames import pose_from_scenario

    rng = np.random.default_rng(seed)
    return [pose_from_scenario(float(r), 0.02, -0.01, *rng.uniform(-3, 3, 3)) for r in np.linspace(10.0, 3.0, n)]


def per_frame_s(sensor, ps) -> float:
    sensor.measure(0.0, *ps[0], image_velocity_px_s=np.zeros((4, 2)))  # warm-up
    t0 = time.perf_counter()
    for k, (R, t) in enumerate(ps[1:], start=1):
        sensor.measure(k * 0.5, R, t, image_velocity_px_s=np.zeros((4, 2)))
    return (time.perf_counter() - t0) / (len(ps) - 1)


def docking_s(phone: str, model: Path | None) -> float:
    sys.path.insert(0, str(ROOT / "examples"))
    import basilisk_docking as ex

    t0 = time.perf_counter()
    ex.run(phone, start_state=(0.05, -0.03, 3.0, 2.0, -1.0, 3.0), sensor_model=None if model is None else str(model),
           max_time_s=200.0)
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--camera", default="galaxy-nexus")
    ap.add_argument("--frames", type=int, default=8, help="rendered frames (the statistical sensor takes 100x)")
    a = ap.parse_args()
    from svgs_sim.sim.approach import ApproachSensor
    from svgs_sim.sim.statistical_sensor import StatisticalSensor

    model = ROOT / "docs" / "reports" / f"sensor-model-{a.camera}"
    ours = per_frame_s(StatisticalSensor(model, seed=1), poses(100 * a.frames))
    peer = per_frame_s(ApproachSensor(a.camera, seed=1, motion=False, frame_rate_hz=2.0), poses(a.frames + 1))
    print(f"a frame, {a.camera}: ours (statistical) {ours * 1e3:.3f} ms, peer (rendered) {peer * 1e3:.1f} ms, "
          f"ratio {ours / peer:.2e}")
    if importlib.util.find_spec("Basilisk") is None:
        print("docking run: Basilisk not installed (pip install -e '.[basilisk]')")
        return
    d_ours, d_peer = docking_s(a.camera, model), docking_s(a.camera, None)
    print(f"a docking run from 3 m at 2 frames/s: ours (statistical) {d_ours:.1f} s, peer (rendered) {d_peer:.1f} s, "
          f"ratio {d_ours / d_peer:.3f}")


if __name__ == "__main__":
    main()
