"""The ToF closed loop (svgs_sim/sim/tof_closed_loop.py): render -> AMCW frames -> pipeline -> pose, checked
against a reference the loop does not compute (the pattern's pinhole projection and the pose written
out by hand), and the three paths that run it - ``svgs tof render-and-solve``, the stability run and
the study's ``tof`` trials - giving the same frames for the same seed."""

import csv
import importlib.util
import json

import numpy as np
import pytest

if importlib.util.find_spec("mitsuba") is None:
    pytest.skip("Mitsuba is not installed (the 'render' extra)", allow_module_level=True)

from svgs_sim.base.errors import InputError  # noqa: E402

pytestmark = pytest.mark.render

#: Head-on at 1 m, written out: the target frame's z towards the camera, the camera's y down and
#: z along the boresight (docs/frames.md), so R = diag(1, -1, -1) and the origin 1 m ahead.
R_HEAD_ON = np.diag([1.0, -1.0, -1.0])
T_HEAD_ON_M = np.array([0.0, 0.0, 1.0])
#: The paper's headline accuracy (Zhu et al. 2022, abstract): 2 mm and 0.13 deg.
PAPER_MM, PAPER_DEG = 2.0, 0.13


@pytest.fixture(scope="module")
def head_on():
    from svgs_sim.sim.tof_closed_loop import TofScenario, render

    return render(TofScenario(range_m=1.0, spp=16, seed=3))


def test_the_scenario_is_typed_and_refuses_bad_input():
    from svgs_sim.sim.tof_closed_loop import TofScenario, TofScene

    sc = TofScenario(range_m=2.0)
    assert sc.scene == TofScene() and sc.scene_dict() == {}  # the pattern's marker material and sheeting
    assert sc.spp is None and sc.ambient_lux is None and sc.integration_time_s is None  # None: the default
    for kw, what in (({"range_m": -1.0}, "range_m"), ({"spp": -4}, "spp"), ({"max_bounces": 7}, "max_bounces"),
                     ({"ambient_lux": float("nan")}, "ambient_lux"), ({"scene": {"colour": 1}}, "scene"),
                     ({"seed": -1}, "seed")):
        with pytest.raises(InputError, match=what):
            TofScenario(**kw)
    with pytest.raises(InputError, match=r"scene: unknown option\(s\) 'colour'"):
        TofScene.from_dict({"colour": 1})
    with pytest.raises(InputError, match="scene.sheeting: expected one of"):
        TofScene(sheeting="tinfoil")
    assert TofScene.from_dict({"sheeting": "en12899-ra1-white"}).to_dict() == {"sheeting": "en12899-ra1-white"}


def test_the_pose_is_the_one_written_out(head_on):
    np.testing.assert_allclose(head_on.R_cam_target, R_HEAD_ON, atol=1e-15)
    np.testing.assert_allclose(head_on.t_cam_target_m, T_HEAD_ON_M, atol=1e-15)


def test_the_closed_loop_recovers_the_pose_within_the_papers_accuracy(head_on):
    from svgs_sim.sim.tof_closed_loop import noise_free_frame, pipeline, solve, solve_frames

    cam, tgt = head_on.camera, head_on.target
    # the marker face centres through a pinhole (the profile has no distortion), by hand
    P = np.asarray(tgt.points_m) @ R_HEAD_ON.T + T_HEAD_ON_M
    uv = np.c_[cam.fx * P[:, 0] / P[:, 2] + cam.cx, cam.fy * P[:, 1] / P[:, 2] + cam.cy]
    nf = solve(head_on, 0, noise_free_frame(head_on), pipeline(head_on)).solution
    assert nf
    for i, k in enumerate(tgt.ids):
        assert np.hypot(*(np.asarray(nf.targets_px[int(k)]) - uv[i])) < 0.3, k  # sub-pixel centroids
        assert nf.targets_slant_range_m[int(k)] == pytest.approx(np.linalg.norm(P[i]), abs=0.01)  # depth = slant range
    results, _ = solve_frames(head_on, 3)
    for r in results:
        sol = r.solution
        assert sol
        # against the hand-written pose: the camera's position in the target frame is -R^T t
        d_mm = np.linalg.norm(-sol.R_cam_target.T @ sol.t_cam_target_m - (-R_HEAD_ON.T @ T_HEAD_ON_M)) * 1e3
        cos = (np.trace(sol.R_cam_target @ R_HEAD_ON.T) - 1) / 2
        ang_deg = np.degrees(np.arccos(np.clip(cos, -1, 1)))
        assert d_mm < PAPER_MM and ang_deg < PAPER_DEG
        # the loop states its errors through svgs_sim.sim.metrics: the same numbers
        assert r.errors["pos_err_norm_m"] * 1e3 == pytest.approx(d_mm, abs=1e-6)
        assert r.errors["rot_err_deg"] == pytest.approx(ang_deg, abs=1e-4)


def test_frames_do_not_depend_on_where_the_stream_starts(head_on):
    from svgs_sim.sim.tof_closed_loop import expose

    a = list(expose(head_on, 4))
    b = list(expose(head_on, 4, start=2))
    assert len(b) == 2
    np.testing.assert_array_equal(a[2].depth_m, b[0].depth_m)
    np.testing.assert_array_equal(a[3].gray, b[1].gray)


def test_cli_stability_and_study_trials_agree_frame_for_frame(tmp_path, capsys):
    """The same seed: ``svgs tof render-and-solve``, ``svgs tof stability`` and the ``tof`` trials of the
    study engine (a trial alone replays the frames before it) give the same frames."""
    from svgs_sim.cli.main import main
    from svgs_sim.sim.tof_stability import COLUMNS
    from svgs_sim.sim.tof_trial import TofTrialScenario, tof_group, tof_trial
    from svgs_sim.sim.tof_stability import stability_scenario
    from svgs_sim.svgs.frames import STATE_KEYS

    n, seed = 4, 5
    base = ["--range", "3", "--frames", str(n), "--seed", str(seed), "--spp", "8"]
    assert main(["tof", "render-and-solve", *base, "--json", "--out", str(tmp_path / "cli")]) == 0
    assert main(["tof", "stability", *base, "--json", "--out", str(tmp_path / "stab")]) == 0
    capsys.readouterr()
    with open(tmp_path / "cli" / "frames.csv") as fh:
        cli_rows = list(csv.DictReader(fh))
    with open(tmp_path / "stab" / "frames.csv") as fh:
        stab_rows = list(csv.DictReader(fh))
    sc = stability_scenario(3.0, seed=seed, spp=8)
    first = TofTrialScenario(sc, 3.0, n)
    rows = [TofTrialScenario(sc, 3.0, n, k).to_row() for k in range(n)]
    trials = tof_group(rows, [seed] * n)
    alone = tof_trial(rows[2], seed)
    assert first.to_row() == rows[0] and TofTrialScenario.from_row(rows[1]) == TofTrialScenario(sc, 3.0, n, 1)
    assert len(cli_rows) == len(stab_rows) == n
    for k in range(n):
        assert trials[k]["ok"] and cli_rows[k]["ok"] == "1" and stab_rows[k]["ok"] == "1"
        for key in STATE_KEYS:  # the CLI writes the state at full precision
            assert float(cli_rows[k][key]) == trials[k][f"est_{key}"], (k, key)
        for c in COLUMNS:  # the stability run's frames.csv at 6 decimals
            assert float(stab_rows[k][c]) == pytest.approx(trials[k][f"col_{c}"], abs=2e-6), (k, c)
    assert alone == trials[2]
    with pytest.raises(InputError, match="seed"):
        tof_trial(rows[0], seed + 1)  # a trial's seed is its run's
    js = json.loads((tmp_path / "stab" / "summary.json").read_text())
    assert js["solved"] == n and set(js["average"]) == set(COLUMNS)


def test_the_study_engine_stores_a_run_as_the_stability_run_computes_it(tmp_path):
    """A run as trials of the ``tof`` kind through the resumable store (in this process) reads back
    to the numbers of :func:`svgs_sim.sim.tof_stability.run_stability` on the same render; a rerun runs nothing."""
    from svgs_sim.sim.tof_closed_loop import render
    from svgs_sim.sim.tof_stability import run_stability, stability_scenario
    from svgs_sim.sim.tof_trial import TofTrialScenario
    from svgs_sim.sim.trials import get_trial_kind
    from svgs_sim.studies.execution import ExecutorSpec, run_stored_study
    from svgs_sim.studies.tof_study import runs_from_rows, study_trials

    sc = stability_scenario(5.712, seed=2, spp=8)
    first = TofTrialScenario(sc, 5.712, 3, 0, (("persistence_window", 2),), "plate", "one run")
    runs = [("baseline", "one run", first, None)]
    trials = study_trials(runs)
    kind = get_trial_kind("tof")
    store, stats = run_stored_study(kind, trials, tmp_path, {"test": 1}, ExecutorSpec("inline", 1), chunk_size=16,
                                    progress=False)
    assert stats.n_run == 3
    got = runs_from_rows(runs, store.read_rows())[0]
    ref = run_stability(render(sc), 5.712, 3, pipeline={"persistence_window": 2}, reference="plate")
    np.testing.assert_array_equal(got["cols"], ref["cols"])
    np.testing.assert_array_equal(got["truth"], ref["truth"])
    np.testing.assert_array_equal(got["rot_err_deg"], ref["rot_err_deg"])
    assert got["noise_free"] == ref["noise_free"] and got["tables"] == ["2"]
    _, again = run_stored_study(kind, trials, tmp_path, {"test": 1}, ExecutorSpec("inline", 1), progress=False)
    assert again is None  # every trial was stored


def test_a_tof_study_store_of_another_design_is_refused(tmp_path):
    """The study's manifest carries a digest of its runs: the same configuration with other runs
    (here the active-set caps of another near-frame pixel count) gives another digest, so a store
    made by the other design is refused (before any work) instead of read back under the wrong runs."""
    from svgs_sim.studies.store import check_resumable
    from svgs_sim.studies.tof_study.design import TofStudyConfig, design_digest, study_runs

    cfg = TofStudyConfig()
    T = {0.697: 3e-6, 5.712: 9e-6}
    a, b = design_digest(study_runs(cfg, T, 5448)), design_digest(study_runs(cfg, T, 8000))
    assert a == design_digest(study_runs(cfg, T, 5448)) and a != b
    (tmp_path / "manifest.json").write_text(json.dumps({"format_version": 2, "parameters": {**cfg.manifest(),
                                                                                          "design_sha256": b}}))
    with pytest.raises(InputError, match="design_sha256"):
        check_resumable(tmp_path, {**cfg.manifest(), "design_sha256": a})
