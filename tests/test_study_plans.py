"""Plans before long work (issue 26, deliverable 4): each study prints its plan - trials,
renders, an estimate from the cost table - on stderr before any work, warns above an hour and
when ``--processes`` exceeds the cores; a huge request prints its plan within a second."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from svgs_sim.studies.execution import COST_TABLE_S, LONG_STUDY_S, ExecutorSpec, cpu_cores, plan_study

ROOT = Path(__file__).resolve().parents[1]


def _svgs(args, tmp_path, timeout=60):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-m", "svgs_sim.cli.main", *args], cwd=tmp_path, env=env, capture_output=True,
                       text=True, timeout=timeout)
    return p, time.perf_counter() - t0


def test_cpu_cores_is_the_affinity_set():
    want = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    assert cpu_cores() == want


def test_plan_counts_and_estimate_follow_the_cost_table():
    render_s, trial_s = COST_TABLE_S["render"]
    plan = plan_study("render", 400, 100, ExecutorSpec("inline", 1))
    assert plan.core_s == pytest.approx(100 * render_s + 400 * trial_s)
    assert plan.wall_s == pytest.approx(plan.core_s)  # one process
    line = plan.describe()
    assert line.startswith("plan: 400 render trial(s), 100 render(s)")
    assert "cost table" in line and "docs/performance.md" in line
    assert plan.warnings() == []  # ~3.7 min: no warning


def test_plan_warns_above_an_hour():
    render_s, trial_s = COST_TABLE_S["render"]
    n = int(LONG_STUDY_S / trial_s) + 10  # trials alone exceed an hour in one process
    plan = plan_study("render", n, 0, ExecutorSpec("inline", 1))
    assert plan.wall_s > LONG_STUDY_S
    (w,) = plan.warnings()
    assert w.startswith("warning: this study is estimated to take about")
    short = plan_study("render", int(0.5 * LONG_STUDY_S / trial_s), 0, ExecutorSpec("inline", 1))
    assert short.warnings() == []


def test_plan_warns_when_processes_exceed_the_cores():
    n = cpu_cores()
    over = plan_study("geometric", 10, 0, ExecutorSpec("process", n + 1))
    assert any(f"--processes {n + 1} exceeds the {n} CPU core(s)" in w for w in over.warnings())
    assert over.parallel == n  # the estimate does not count processes that share cores
    assert plan_study("geometric", 10, 0, ExecutorSpec("process", n)).warnings() == []
    workers = plan_study("geometric", 10, 0, ExecutorSpec("dask-local", n + 3))
    assert any(w.startswith(f"warning: --workers {n + 3} exceeds") for w in workers.warnings())


def test_remote_cluster_and_unknown_kind_say_what_they_cannot_estimate():
    remote = plan_study("render", 10, 2, ExecutorSpec("dask-scheduler", 0, "tcp://10.0.0.5:8786"))
    assert remote.wall_s is None and "Dask cluster at tcp://10.0.0.5:8786" in remote.describe()
    assert "no cost table entry" in plan_study("no-such-kind", 10, 1, ExecutorSpec("inline", 1)).describe()


def test_huge_campaign_plan_only_within_a_second_writes_nothing(tmp_path):
    out = tmp_path / "c"
    p, dt = _svgs(["campaign", "--camera", "galaxy-nexus", "--trials", "10000000", "--plan-only",
                   "--processes", str(cpu_cores() + 1), "--out", str(out)], tmp_path)
    assert p.returncode == 0, p.stderr
    assert "Traceback" not in p.stderr and p.stdout == ""
    lines = [ln for ln in p.stderr.splitlines() if ln.startswith(("plan:", "warning:"))]
    assert lines[0].startswith("plan: 50,000,000 render trial(s), 12,500,000 render(s)")  # 5 paper ranges
    assert any("exceeds the" in ln for ln in lines) and any("estimated to take about" in ln for ln in lines)
    assert not out.exists()
    assert dt < 10  # the interpreter's start-up and imports; the plan itself builds nothing


@pytest.mark.slow
def test_huge_campaign_prints_its_plan_within_a_second_before_any_trial(tmp_path):
    """Without --plan-only: the plan line comes first and fast; the run is then killed."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-u", "-m", "svgs_sim.cli.main", "campaign", "--camera", "galaxy-nexus",
                             "--trial-kind", "geometric", "--trials", "10000000", "--processes", "0",
                             "--out", str(tmp_path / "c")], cwd=tmp_path, env=env, stderr=subprocess.PIPE, text=True)
    try:
        t0 = time.perf_counter()
        first = ""
        while not first.startswith("plan:"):
            first = proc.stderr.readline()
            assert first, "stderr closed before the plan"
        seen = time.perf_counter() - t0
    finally:
        proc.kill()
        proc.wait()
        proc.stderr.close()
        proc.stderr.close()
    assert first.startswith("plan: 50,000,000 geometric trial(s)")
    # start-up (imports) is a few seconds on a loaded machine; building the 50M trials takes minutes
    assert seen < 15


@pytest.mark.parametrize("args, head", [
    (["sensitivity", "--camera", "galaxy-nexus", "--vary", "range_m=5:10", "--vary", "roll_deg=-5:5", "--n", "1024"],
     "plan: 4,096 geometric trial(s), no render (sobol over 2 parameter(s))"),
    (["exposure-study", "--camera", "galaxy-nexus", "--ranges", "2,4", "--trials", "3"], "plan: "),
    (["range-sweep", "--camera", "galaxy-nexus", "--ranges", "1,2,3", "--trials", "4", "--poses", "2"],
     "plan: 24 render trial(s), 6 render(s)"),
])
def test_study_plan_only(args, head, tmp_path):
    out = tmp_path / "o"
    p, _ = _svgs([*args, "--plan-only", "--processes", "0", "--out", str(out)], tmp_path)
    assert p.returncode == 0, p.stderr
    plan = [ln for ln in p.stderr.splitlines() if ln.startswith("plan:")]
    assert len(plan) == 1 and plan[0].startswith(head)
    assert not out.exists() and "Traceback" not in p.stderr


def test_a_long_render_is_announced_before_it_starts():
    """``--spp 1000000 --full-frame`` is ~5e12 samples: hours at the demo's rate, said before the
    render; the demo's own render (2e7 samples, 1.8 s) is not announced."""
    from svgs_sim.cli.render import LONG_RENDER_S, RENDER_SAMPLES_PER_S, render_cost_warning

    assert render_cost_warning(2592, 1944, 4, 64, 4) is None  # the demo
    line = render_cost_warning(2592, 1944, 1_000_000, 64, 4, full_frame=True)
    assert line.startswith("warning: this render draws 5e+12 samples") and " h at " in line
    # the threshold: just above LONG_RENDER_S is announced, just below is not
    spp_edge = LONG_RENDER_S * RENDER_SAMPLES_PER_S / (100 * 100)
    assert render_cost_warning(100, 100, int(spp_edge * 1.01), 0, 0, full_frame=True) is not None
    assert render_cost_warning(100, 100, int(spp_edge * 0.99), 0, 0, full_frame=True) is None


@pytest.mark.slow
def test_svgs_render_says_a_long_render_before_starting(tmp_path):
    """The warning is the first thing ``svgs render --spp 1000000 --full-frame`` says (read from
    the running process, which is then stopped)."""
    import subprocess
    import time

    proc = subprocess.Popen([sys.executable, "-m", "svgs_sim.cli.main", "render", "--camera", "galaxy-nexus", "--range", "5",
                             "--spp", "1000000", "--full-frame", "--out", str(tmp_path / "r")],
                            stderr=subprocess.PIPE, text=True, cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)})
    try:
        t0 = time.monotonic()
        line = ""
        while time.monotonic() - t0 < 30:
            line = proc.stderr.readline()
            if "warning: this render draws" in line or not line:
                break
        assert "svgs render: warning: this render draws 5e+12 samples" in line, line
    finally:
        proc.kill()
        proc.wait()
        proc.stderr.close()
