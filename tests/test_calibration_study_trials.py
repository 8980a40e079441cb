"""The calibration study run as trials (svgs_sim.studies.calibration.trials via svgs_sim.studies.execution):
identical rows in this process and on a 2-process pool, resume after an interrupted run,
refusal of other parameters, and trials computed alone that draw exactly the numbers of the
whole study's random streams (references: the sequential draws, computed here)."""

import numpy as np
import pytest

from svgs_sim.studies.calibration import run_calibration_study, study_poses, true_camera
from svgs_sim.studies.calibration.focal import focal_cases, focal_frames_geometric, focal_study
from svgs_sim.studies.calibration.pose import range_noise, range_poses
from svgs_sim.studies.execution import ExecutorSpec
from svgs_sim.studies.store import read_rows
from svgs_sim.base.profiles import Camera
from svgs_sim.base.errors import InputError

PARTS = ("convergence", "focal", "pose")
SMALL = {"views_list": (3, 4), "subsets": 2, "geometric": True, "focal_ranges_m": (1.0, 3.0, 5.0),
         "focal_exposures": 2, "pose_ranges_m": (2.0, 10.0), "poses_per_range": 3, "floor_noise_px": (0.2,)}


@pytest.fixture(scope="module")
def small_camera():
    return Camera.load("galaxy-nexus", fitted=False).scaled(640, 480)


def _numbers(rows):
    """Rows without the timing columns and the input path (the only ones allowed to differ)."""
    return [{k: v for k, v in r.items() if k not in ("wall_s", "cpu_s", "inputs")} for r in rows]


def _rows(out):
    return {p: read_rows(out / "trials" / p / "results.csv") for p in PARTS}


def _run(cam, out, spec, **kw):
    return run_calibration_study(cam, out, spec=spec, chunk_size=3, **{**SMALL, **kw})


@pytest.mark.slow
def test_inline_and_two_processes_give_identical_rows(tmp_path, small_camera):
    a = _run(small_camera, tmp_path / "inline", ExecutorSpec("inline", 1))
    b = _run(small_camera, tmp_path / "pool", ExecutorSpec("process", 2))
    ra, rb = _rows(tmp_path / "inline"), _rows(tmp_path / "pool")
    # calibrations: 2 subsets of 3 views, 1 of 4 (a random 4 of 4 is the first subset again);
    # focal: 3 range sets (all, far 2, the farthest) x 4 noise levels; pose: (11 error cases +
    # focal-only + 2 full calibrations) x 2 ranges, and 3 floor cases x 2 ranges with noise
    assert [len(ra[p]) for p in PARTS] == [3, 12, 34]
    for p in PARTS:
        assert _numbers(rb[p]) == _numbers(ra[p]), p
    assert a.pose_rows == b.pose_rows and a.convergence_rows == b.convergence_rows
    assert set(a.run_stats) == set(PARTS) and a.run_stats["pose"].n_run == 34


@pytest.mark.slow
def test_rerun_resumes_and_other_parameters_are_refused(tmp_path, small_camera):
    out = tmp_path / "study"
    first = _run(small_camera, out, ExecutorSpec("inline", 1))
    # an interrupted run: the pose part stopped after 10 of its rows
    results = out / "trials" / "pose" / "results.csv"
    lines = results.read_text().splitlines(keepends=True)
    results.write_text("".join(lines[:11]))
    again = _run(small_camera, out, ExecutorSpec("inline", 1))
    assert set(again.run_stats) == {"pose"}
    assert again.run_stats["pose"].n_already_done == 10 and again.run_stats["pose"].n_run == 24
    rows = read_rows(results)
    assert [r["trial_id"] for r in rows] == list(range(34))
    assert again.pose_rows == first.pose_rows and again.convergence_rows == first.convergence_rows
    done = _run(small_camera, out, ExecutorSpec("inline", 1))
    assert done.run_stats == {} and done.pose_rows == first.pose_rows
    with pytest.raises(InputError, match="different parameters.*poses_per_range"):
        _run(small_camera, out, ExecutorSpec("inline", 1), poses_per_range=4)


def test_a_range_alone_draws_the_study_poses_and_noise(pattern):
    ranges, n = (1.0, 7.5, 40.0), 5
    rr, R, t = study_poses(ranges, n, seed=21)
    for i, r in enumerate(ranges):
        Ri, ti = range_poses(r, i, n, seed=21)
        assert np.array_equal(Ri, R[rr == r]) and np.array_equal(ti, t[rr == r])
    full = np.random.default_rng(4).normal(0.0, 0.3, (len(rr), pattern.n, 2))  # one draw for the whole study
    assert np.array_equal(range_noise(0.3, (n, pattern.n, 2), 2 * n, seed=4), full[2 * n:])


def test_focal_cases_alone_draw_the_sequential_noise(pattern):
    # reference: the whole study's noise drawn from one generator, case after case
    from svgs_sim.calibration import estimate_focal

    nominal = Camera.load("galaxy-nexus", fitted=False)
    cam = true_camera(nominal)
    frames = focal_frames_geometric(cam, pattern, [1.0, 4.0, 9.0], exposures=2, seed=3)
    frames.centroids_px[2, 1] = np.nan  # one exposure not identified
    rows, _ = focal_study(frames, nominal, pattern, cam.fx, noise_levels_px=(0.0, 0.5), trials=3, seed=8)
    rng = np.random.default_rng(8)
    ok = frames.ok()
    ref = []
    for case in focal_cases(frames, None, (0.0, 0.5), 3):
        idx, sig = list(case["range_indices"]), case["added_noise_px"]
        f = []
        for e in range(2):
            if ok[idx, e].all():
                for _ in range(case["n_trials"]):
                    cs = [frames.centroids_px[k, e] + (rng.normal(0.0, sig, (pattern.n, 2)) if sig > 0 else 0.0)
                          for k in idx]
                    kw = {"centroid_sigma_px": sig or 0.05} if len(idx) == 1 else {}
                    f.append(estimate_focal(cs, frames.ranges_m[idx], nominal, pattern, **kw).f_px)
        ref.append(100.0 * (np.mean(f) / cam.fx - 1.0))
    assert [r["mean_err_pct"] for r in rows] == pytest.approx(ref, rel=1e-12, abs=1e-12)
