"""``svgs calibrate study`` prints its plan - counts per part and an estimate from measured costs -
before any work, warns above an hour like the other studies, and stops there with ``--plan-only``
(issue 26)."""

import time

from svgs_sim.cli.main import main
from svgs_sim.studies.calibration import plan_calibration_study
from svgs_sim.studies.calibration.plan import part_plan
from svgs_sim.studies.execution import LONG_STUDY_S, ExecutorSpec, Trial


def _plan_only(capsys, tmp_path, *extra):
    out = tmp_path / "study"
    t0 = time.perf_counter()
    rc = main(["calibrate", "study", "--camera", "galaxy-nexus", "--processes", "0", "--plan-only", "--out", str(out),
               *extra])
    elapsed_s = time.perf_counter() - t0
    cap = capsys.readouterr()
    assert rc == 0 and cap.out == "" and "Traceback" not in cap.err, cap.err
    assert not out.exists() and not list(tmp_path.iterdir())  # nothing written
    return [ln for ln in cap.err.splitlines() if ln.strip()], elapsed_s


def test_plan_only_prints_the_counts_and_an_estimate_and_writes_nothing(capsys, tmp_path):
    _plan_only(capsys, tmp_path)  # the imports and the profile loads, once
    lines, elapsed_s = _plan_only(capsys, tmp_path)
    assert elapsed_s < 1.0
    assert len(lines) == 1 and lines[0].startswith("plan: 40 board view(s) rendered (16 spp) at 2592x1944 px"), lines
    for counts in ("10 calibration(s)", "10 focal frame(s) of 4 exposure(s)", "20 focal-method case(s)",
                   "264 pose-error cell(s) of 16 pose(s)"):
        assert counts in lines[0], lines[0]
    assert " min of one core (measured costs, svgs_sim/studies/calibration/plan.py)" in lines[0]


def test_a_study_over_an_hour_is_warned_about(capsys, tmp_path):
    lines, _ = _plan_only(capsys, tmp_path, "--views-list", "100,400", "--spp", "256")
    assert lines[0].startswith("plan: 400 board view(s) rendered (256 spp)") and " h of one core" in lines[0]
    assert len(lines) == 2 and lines[1].startswith("warning: this study is estimated to take about "), lines


def test_the_geometric_study_costs_its_board_set_mostly(tmp_path):
    """The default geometric study, measured at 187 s (svgs_sim/studies/calibration/plan.py), is planned
    at a few minutes, nearly all of it the board set made in this process."""
    plan = plan_calibration_study("galaxy-nexus", tmp_path / "s", geometric=True, spec=ExecutorSpec("inline", 1))
    assert 100 < plan.core_s < 300 and plan.serial_s > 0.95 * plan.core_s
    assert plan.wall_s < LONG_STUDY_S and plan.warnings() == []
    assert plan.describe().startswith("plan: 40 board view(s) geometric at 2592x1944 px")


def test_a_part_says_its_trials_and_their_estimate():
    trials = [Trial(i, {"n_views": n}, 0) for i, n in enumerate((5, 10, 40))]
    line = part_plan("convergence", trials, ExecutorSpec("inline", 1), done_ids={0}).describe()
    assert line.startswith("plan: 2 trial(s) (1 already stored); ~0.5 s of one core"), line
