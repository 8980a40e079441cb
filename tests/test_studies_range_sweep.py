"""The range sweep and the exposure study run on the study engine: the same rows in this process
and on a process pool, a rerun recomputes only the missing rows, a changed config is refused.

Small frames: the Galaxy Nexus profile scaled to 648 x 486 (a preview stream of the same lens),
so each render takes about a second."""

import json

import numpy as np
import pytest

from svgs_sim.cli.main import main
from svgs_sim.studies import exposure_study, range_sweep
from svgs_sim.studies.execution import ExecutorSpec
from svgs_sim.studies.store import RESULTS, read_rows
from svgs_sim.base.errors import InputError

#: Columns that are wall times (they differ from run to run).
TIMINGS = ("wall_s", "cpu_s", "expose_s", "solve_s")


def _numbers(rows):
    return [{k: v for k, v in r.items() if k not in TIMINGS} for r in rows]


def _drop_rows(out_dir, trial_ids):
    """Delete the rows of ``trial_ids`` from the store (as if those trials had never finished)."""
    path = out_dir / RESULTS
    lines = path.read_text().splitlines(keepends=True)
    keep = [lines[0]] + [ln for ln in lines[1:] if int(ln.split(",", 1)[0]) not in trial_ids]
    assert len(keep) == len(lines) - len(trial_ids)
    path.write_text("".join(keep))


@pytest.mark.render
def test_range_sweep_same_rows_inline_and_on_two_processes_and_resumes(small_camera, tmp_path):
    cfg = range_sweep.make_config(small_camera, [5.0, 12.0], trials=3, poses=2, seed=4)
    table, stats = range_sweep.run_range_sweep(cfg, tmp_path / "inline", ExecutorSpec("inline", 1), progress=False)
    ref = read_rows(tmp_path / "inline" / RESULTS)
    assert stats.n_run == 12 and [r["trial_id"] for r in ref] == list(range(12))
    # chunk_size 1 splits a pose's render group over tasks: each part renders again, same numbers
    _, pool = range_sweep.run_range_sweep(cfg, tmp_path / "pool", ExecutorSpec("process", 2), chunk_size=1,
                                          progress=False)
    assert pool.n_run == 12
    assert _numbers(read_rows(tmp_path / "pool" / RESULTS)) == _numbers(ref)

    # the scenarios: pose 0 is the nominal pose, pose 1 is jittered; one render seed per pose
    by_pose = {}
    for r in ref:
        by_pose.setdefault((r["range_m"], r["pose_index"]), []).append(r)
    assert sorted(by_pose) == [(5.0, 0), (5.0, 1), (12.0, 0), (12.0, 1)]
    for (rng_m, pk), rows in by_pose.items():
        assert len(rows) == 3 and len({r["render_seed"] for r in rows}) == 1
        assert len({(r["target_x_m"], r["yaw_deg"]) for r in rows}) == 1
        assert (rows[0]["target_x_m"] == 0.0 and rows[0]["yaw_deg"] == 0.0) == (pk == 0)
        assert len({r["seed"] for r in rows}) == 3  # three noise draws
    assert ref[0]["true_z_m"] == pytest.approx(5.0, abs=1e-12)

    # trials.jsonl: one record per trial, the error vectors of svgs_sim.sim.metrics, and the summary agrees
    recs = [json.loads(ln) for ln in (tmp_path / "inline" / "trials.jsonl").read_text().splitlines()]
    assert len(recs) == 12
    solved = [x for x in recs if x["ok"]]
    assert solved and all(len(x["pos_err_vec_m"]) == 3 and len(x["att_err_vec_deg"]) == 3 for x in solved)
    near = [x for x in solved if x["range_m"] == 5.0]
    assert table[0]["success_rate"] == sum(x["ok"] for x in recs if x["range_m"] == 5.0) / 6
    assert table[0]["err_mean_z_m"] == pytest.approx(np.mean([x["pos_err_vec_m"][2] for x in near]))
    for name in ("summary.csv", "range_sweep.png", "manifest.json"):
        assert (tmp_path / "inline" / name).is_file()

    # resume: the deleted rows, and only they, run again, to the same numbers
    _drop_rows(tmp_path / "pool", {1, 7, 11})
    _, again = range_sweep.run_range_sweep(cfg, tmp_path / "pool", ExecutorSpec("inline", 1), progress=False)
    assert (again.n_run, again.n_already_done) == (3, 9)
    assert _numbers(read_rows(tmp_path / "pool" / RESULTS)) == _numbers(ref)
    _, none = range_sweep.run_range_sweep(cfg, tmp_path / "pool", ExecutorSpec("inline", 1), progress=False)
    assert none is None

    # another config in the same folder is refused, naming what changed
    other = range_sweep.make_config(small_camera, [5.0, 12.0], trials=4, poses=2, seed=4)
    with pytest.raises(InputError, match="trials"):
        range_sweep.run_range_sweep(other, tmp_path / "pool", ExecutorSpec("inline", 1), progress=False)


@pytest.mark.render
def test_exposure_study_same_rows_inline_and_on_two_processes_and_resumes(small_camera, tmp_path):
    remedies = ["baseline", "nd=1", "exposure=0.001", "spacing=1.5"]
    cfg = exposure_study.make_config(small_camera, [5.0, 12.0], remedies, trials=2, seed=3)
    trials = exposure_study.exposure_study_trials(cfg)
    from svgs_sim.sim.render_trial import render_key

    # remedies that keep the scene share one render per range; the wider pattern renders its own
    assert len({render_key(t.scenario) for t in trials}) == 2 * 2
    lines, stats = exposure_study.run_exposure_study(cfg, tmp_path / "inline", ExecutorSpec("inline", 1),
                                                     progress=False)
    ref = read_rows(tmp_path / "inline" / RESULTS)
    assert stats.n_run == 16 and len(ref) == 16
    nd = [r for r in ref if r["remedy"] == "nd=1"]
    assert all(r["target_scale"] == pytest.approx(0.01) for r in nd)
    fixed = [r for r in ref if r["remedy"] == "exposure=0.001"]
    assert all(r["exposure_s_used"] == pytest.approx(1e-3) for r in fixed)
    _, pool = exposure_study.run_exposure_study(cfg, tmp_path / "pool", ExecutorSpec("process", 2), chunk_size=2,
                                                progress=False)
    assert pool.n_run == 16
    assert _numbers(read_rows(tmp_path / "pool" / RESULTS)) == _numbers(ref)

    # trials.csv and summary.md from the rows
    assert (tmp_path / "inline" / "trials.csv").read_text().splitlines()[0] == \
        "remedy,range_m,trial,ok,reason,n_blobs,exposure_s,iso,pos_err_norm_m,rot_err_deg"
    base_5 = [r["ok"] for r in ref if r["remedy"] == "baseline" and r["range_m"] == 5.0]
    assert lines[2].startswith("| baseline | " + f"{np.mean(base_5):.2f} |")

    _drop_rows(tmp_path / "pool", {0, 9, 15})
    _, again = exposure_study.run_exposure_study(cfg, tmp_path / "pool", ExecutorSpec("inline", 1), progress=False)
    assert (again.n_run, again.n_already_done) == (3, 13)
    assert _numbers(read_rows(tmp_path / "pool" / RESULTS)) == _numbers(ref)


def test_study_commands_take_the_executor_options_and_refuse_bad_ones(capsys):
    assert main(["range-sweep", "--camera", "galaxy-nexus", "--ranges", "5", "--processes", "1", "--workers", "2"]) == 2
    assert main(["exposure-study", "--camera", "galaxy-nexus", "--chunk-size", "0"]) == 2
    assert "--chunk-size" in capsys.readouterr().err
    assert main(["range-sweep", "--camera", "galaxy-nexus", "--ranges", "5,5"]) == 2
    assert "repeated range" in capsys.readouterr().err
    assert main(["exposure-study", "--camera", "galaxy-nexus", "--remedy", "nd=1", "--remedy", "nd=1"]) == 2
    assert "repeated remedy" in capsys.readouterr().err
    assert main(["range-sweep", "--camera", "galaxy-nexus", "--ranges", "5", "--threshold", "-3"]) == 2
    assert "--threshold" in capsys.readouterr().err
