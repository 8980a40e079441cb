"""Benchmark (issue 26): the per-unit costs of ``svgs calibrate study``'s parts, for its plan.

Runs small calibration studies in this process (:func:`svgs_sim.studies.calibration.run_calibration_study`,
``processes=0``) in a temporary folder and times each part from the study's own progress lines
and run statistics:

- geometric board set (``--geometric``): the rays shared by the views (once) and each view, per
  megapixel of the image;
- rendered board set (Mitsuba and the phone model): each view at two sample counts (the render's
  share grows with the samples, the phone's does not), per megapixel;
- the board's detection (OpenCV), per view and megapixel;
- the calibrations (OpenCV), per view they use;
- the rendered focal frames, per range (one render and ``--focal-exposures`` exposures);
- the focal-method cases, per noise draw; the pose-error cells, per pose.

The numbers are the constants of :mod:`svgs_sim.studies.calibration.plan` (its notes say where they were
measured). ``--geometric-only`` skips the rendered parts (no Mitsuba).

Run: ``.venv/bin/python benchmarks/bench_calibration_study.py [--geometric-only]``
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def _timed_study(out: Path, **kw):
    """Run one study; (result, {progress line prefix: time it was said, s from the start})."""
    from svgs_sim.studies.calibration import run_calibration_study

    t0 = time.perf_counter()
    said = []
    res = run_calibration_study("galaxy-nexus", out, progress=lambda m: said.append((time.perf_counter() - t0, m)),
                                **kw)
    return res, said, time.perf_counter() - t0


def _when(said, start: str) -> float:
    return next(t for t, m in said if m.startswith(start))


def _views_s(said) -> list[float]:
    """Times of the board set's per-view progress lines."""
    return [t for t, m in said if "view " in m and "/" in m and "undistorting" not in m]


def _trial_costs(res, out: Path, poses_per_range: int) -> dict:
    import csv

    st = res.run_stats
    n_views_used = sum(r["n_views"] for r in res.convergence_rows)
    with open(out / "trials" / "focal" / "results.csv", newline="") as fh:
        draws = sum(int(float(r["n_trials"])) for r in csv.DictReader(fh))  # noise draws of the focal cases
    return {"calibration_s_per_view": st["convergence"].elapsed_s / n_views_used,
            "focal_s_per_draw": st["focal"].elapsed_s / draws,
            "pose_s_per_pose": st["pose"].elapsed_s / (st["pose"].n_run * poses_per_range)}


def geometric(tmp: Path) -> dict:
    """The geometric study at the profile's size: board set, detection and the three kinds of trial."""
    res, said, total = _timed_study(tmp / "geometric", geometric=True, views_list=(5, 10), subsets=2,
                                    focal_ranges_m=(2.0, 4.0, 6.0), pose_ranges_m=(2.0, 10.0, 30.0),
                                    poses_per_range=16)
    mpx = res.camera_true.width * res.camera_true.height / 1e6
    views = _views_s(said)
    per_view = (views[-1] - views[0]) / (len(views) - 1)
    detect = (_when(said, "board found") - _when(said, "detecting the board")) / len(views)
    return {"megapixels": mpx, "total_s": total, "geometric_board_setup_s_per_mpx": (views[0] - per_view) / mpx,
            "geometric_board_view_s_per_mpx": per_view / mpx, "detection_s_per_view_mpx": detect / mpx,
            **_trial_costs(res, tmp / "geometric", 16)}


def rendered(tmp: Path, spp: int) -> dict:
    """A rendered study with 3 board views and 2 focal ranges at the profile's size."""
    res, said, total = _timed_study(tmp / f"rendered-{spp}", views_list=(3,), subsets=1, spp=spp,
                                    focal_ranges_m=(2.0, 5.0), pose_ranges_m=(5.0,), poses_per_range=4)
    mpx = res.camera_true.width * res.camera_true.height / 1e6
    board = res.timings_s["board_set_s"] / 3
    focal_frames = res.timings_s["focal_s"] - res.run_stats["focal"].elapsed_s
    return {"spp": spp, "total_s": total, "rendered_board_view_s_per_mpx": board / mpx,
            "focal_frame_s": focal_frames / 2}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--geometric-only", action="store_true", help="skip the rendered parts (no Mitsuba)")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        runs = [geometric(Path(tmp))]
        if not args.geometric_only:
            runs += [rendered(Path(tmp), 4), rendered(Path(tmp), 16)]
    for r in runs:
        print("  ".join(f"{k} {v:.4g}" for k, v in r.items()))
    if len(runs) == 3:
        a, b = runs[1], runs[2]
        per_spp = (b["rendered_board_view_s_per_mpx"] - a["rendered_board_view_s_per_mpx"]) / (b["spp"] - a["spp"])
        fixed = a["rendered_board_view_s_per_mpx"] - a["spp"] * per_spp
        print(f"rendered board view, per megapixel: {fixed:.3g} s + {per_spp:.3g} s per sample per pixel")


if __name__ == "__main__":
    main()
