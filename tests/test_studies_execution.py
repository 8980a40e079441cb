"""Executors: identical numbers in-process, on a local process pool and on a Dask LocalCluster;
a campaign killed with SIGKILL resumes to the uninterrupted result; the workers of a killed
campaign die with it; bad executor input."""

import os
import signal
import socket
import subprocess
import sys
import time

import pytest

from svgs_sim.studies.campaign import campaign_trials, make_config
from svgs_sim.studies.execution import (ExecutorSpec, Trial, executor_spec, make_tasks, open_executor, run_study)
from svgs_sim.studies.store import ResultStore, read_rows
from svgs_sim.sim.trials import GEOMETRIC, TrialKind, register_trial_kind
from svgs_sim.cli.main import main
from svgs_sim.base.errors import InputError
from study_helpers import sigkill_after_rows


def _numbers(rows):
    """Rows without the timing columns (the only ones allowed to differ between runs)."""
    return [{k: v for k, v in r.items() if k not in ("wall_s", "cpu_s")} for r in rows]


def _run(config, out_dir, spec, chunk_size=4):
    trials = campaign_trials(config)
    store = ResultStore(out_dir, config.manifest(), GEOMETRIC.columns(list(trials[0].scenario)))
    with store, open_executor(spec, GEOMETRIC) as ex:
        run_study(GEOMETRIC, trials, store, ex, chunk_size=chunk_size, n_workers=max(spec.n_workers, 1), progress=False)
    return read_rows(out_dir / "results.csv")


@pytest.mark.slow
def test_identical_numbers_inline_process_pool_and_dask(tmp_path):
    pytest.importorskip("distributed", reason="the 'dask' extra is not installed")
    config = make_config("galaxy-nexus", ranges_m=(5.0, 20.0), trials_per_range=12, seed=11, sigma_px=0.2,
                         calibration="paper", trial_kind="geometric")
    ref = _run(config, tmp_path / "inline", ExecutorSpec("inline", 1), chunk_size=5)
    assert len(ref) == 24 and all(r["ok"] == 1 for r in ref)
    pool = _run(config, tmp_path / "pool", ExecutorSpec("process", 2), chunk_size=3)
    dask = _run(config, tmp_path / "dask", ExecutorSpec("dask-local", 2), chunk_size=4)
    assert _numbers(pool) == _numbers(ref)
    assert _numbers(dask) == _numbers(ref)


#: Runs the CLI in a child that SIGKILLs itself right after the store has fsynced its
#: KILL_AT-th row: the kill lands mid-campaign at a known point, with no polling and no
#: timing window (the earlier version polled the CSV and raced the run).
KILL_AT = 100
_KILL_CHILD = sigkill_after_rows(KILL_AT, "from svgs_sim.cli.main import main\nsys.exit(main(sys.argv[1:]))")


@pytest.mark.slow
def test_sigkill_halfway_then_rerun_completes_without_duplicates(tmp_path):
    out = tmp_path / "campaign"
    args = ["campaign", "--camera", "galaxy-nexus", "--trial-kind", "geometric", "--calibration", "exact", "--trials",
            "150", "--ranges", "5,15", "--out", str(out), "--processes", "0", "--chunk-size", "1", "--no-progress",
            "--seed", "5"]
    proc = subprocess.run([sys.executable, "-c", _KILL_CHILD, *args], stdout=subprocess.DEVNULL,
                          stderr=subprocess.PIPE, start_new_session=True)
    results = out / "results.csv"
    assert proc.returncode == -signal.SIGKILL, f"the run was not killed mid-way: {proc.stderr[-2000:]!r}"
    n_after_kill = len(read_rows(results))
    assert n_after_kill == KILL_AT, n_after_kill  # chunk size 1: one row per append, killed after the 100th
    assert not (out / "report.html").exists()

    assert main(args) == 0  # the same command again: finishes the missing trials only
    rows = read_rows(results)
    ids = [r["trial_id"] for r in rows]
    assert len(ids) == len(set(ids)) == 300
    raw_lines = results.read_text().splitlines()
    assert len(raw_lines) == 301  # header + one line per trial, nothing twice in the file either

    config = make_config("galaxy-nexus", ranges_m=(5.0, 15.0), trials_per_range=150, seed=5, trial_kind="geometric",
                         calibration="exact")
    ref = _run(config, tmp_path / "reference", ExecutorSpec("inline", 1), chunk_size=16)
    assert _numbers(rows) == _numbers(ref)
    assert (out / "report.html").exists()


#: Runs the CLI in a child that touches the file $SVGS_TEST_MARKER once the store holds its
#: first rows (the workers exist and are busy), then goes on with the campaign.
_MARK_CHILD = """
import os, sys
from pathlib import Path
from svgs_sim.studies.store import ResultStore
_append = ResultStore.append
def append(self, rows):
    n = _append(self, rows)
    Path(os.environ["SVGS_TEST_MARKER"]).touch()
    return n
ResultStore.append = append
from svgs_sim.cli.main import main
sys.exit(main(sys.argv[1:]))
"""


def _cmdline(proc) -> str:
    """A process's command line, or "" once it has ended: short-lived helpers (a zombie not yet
    reaped, a process gone between listing and reading) come and go while the campaign starts."""
    import psutil

    try:
        return " ".join(proc.cmdline())
    except psutil.Error:
        return ""


def _alive(procs):
    import psutil

    out = []
    for p in procs:
        try:
            if p.is_running() and p.status() != psutil.STATUS_ZOMBIE:  # a zombie has ended (its reaper may be slow)
                out.append(p)
        except psutil.NoSuchProcess:
            pass
    return out


@pytest.mark.parametrize("executor", [["--processes", "2"], ["--workers", "2"]], ids=["process-pool", "dask"])
@pytest.mark.slow
def test_workers_die_with_a_sigkilled_parent(tmp_path, executor):
    """SIGKILL of a campaign mid-run: every process it started (pool or Dask workers, the
    multiprocessing resource tracker) ends within a few seconds, none keeps computing."""
    psutil = pytest.importorskip("psutil", reason="psutil comes with the 'dask' extra")
    if executor[0] == "--workers":
        pytest.importorskip("distributed", reason="the 'dask' extra is not installed")
    marker = tmp_path / "first-rows"
    args = ["campaign", "--camera", "galaxy-nexus", "--trials", "5000", "--ranges", "5,15", "--out",
            str(tmp_path / "campaign"), "--trial-kind", "geometric", *executor, "--chunk-size", "4", "--no-progress"]
    proc = subprocess.Popen([sys.executable, "-c", _MARK_CHILD, *args], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True,
                            env={**os.environ, "SVGS_TEST_MARKER": str(marker)})
    parent = psutil.Process(proc.pid)
    children = []
    try:
        deadline = time.monotonic() + 120  # start-up on a loaded machine; not a speed test
        while time.monotonic() < deadline and proc.poll() is None:
            children = parent.children(recursive=True)
            workers = [c for c in children if "spawn_main" in _cmdline(c)]
            if marker.exists() and len(workers) >= 2:
                break
            time.sleep(0.1)
        assert proc.poll() is None and marker.exists(), "the campaign ended before its workers were seen"
        children = parent.children(recursive=True)
        assert len(workers) >= 2, [_cmdline(c) for c in children]
        os.kill(proc.pid, signal.SIGKILL)
        assert proc.wait(timeout=10) == -signal.SIGKILL
        deadline = time.monotonic() + 15
        while _alive(children) and time.monotonic() < deadline:
            time.sleep(0.2)
        left = _alive(children)
        assert not left, [(p.pid, _cmdline(p)) for p in left]
    finally:
        for p in [parent, *children]:  # nothing of this test outlives it, pass or fail
            try:
                p.kill()
            except psutil.Error:
                pass
        proc.wait(timeout=10)


def _pdeathsig() -> int:
    """The parent-death signal of the calling thread (prctl PR_GET_PDEATHSIG)."""
    import ctypes

    value = ctypes.c_int(-1)
    assert ctypes.CDLL(None).prctl(2, ctypes.byref(value), 0, 0, 0) == 0
    return value.value


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux only")
@pytest.mark.slow
def test_local_workers_ask_the_kernel_for_sigkill_when_the_parent_dies():
    """The pool initializer and the LocalCluster's worker plugin set PR_SET_PDEATHSIG (the Dask
    workers also have distributed's own parent watch, so the SIGKILL test cannot tell)."""
    with open_executor(ExecutorSpec("process", 1)) as ex:
        assert ex.submit(_pdeathsig).result() == signal.SIGKILL
    assert _pdeathsig() == 0  # never in the parent (nor with --processes 0)
    pytest.importorskip("distributed", reason="the 'dask' extra is not installed")
    with open_executor(ExecutorSpec("dask-local", 1)) as ex:
        # client.run runs in the worker's main thread, where the plugin set it
        assert list(ex._client.run(_pdeathsig).values()) == [signal.SIGKILL]


def test_die_with_parent_falls_back_to_a_watchdog_without_prctl(monkeypatch, caplog):
    """No prctl (not Linux, or refused): a debug line and a watchdog thread, never a crash."""
    import logging
    import threading

    from svgs_sim.studies.execution import parent_watch as execution

    def no_prctl():
        raise OSError(38, "Function not implemented")

    monkeypatch.setattr(execution, "_set_pdeathsig_sigkill", no_prctl)
    started = []
    monkeypatch.setattr(threading.Thread, "start", lambda self: started.append(self.name))
    with caplog.at_level(logging.DEBUG, logger="svgs_sim.studies.execution"):
        assert execution.die_with_parent(os.getppid()) == "watchdog"
    assert started == ["svgs-parent-watch"]
    assert "watching the parent pid" in caplog.text


def test_tasks_keep_render_groups_together():
    scen = [{"camera": "galaxy-nexus", "pattern": "svgs-3u", "range_m": r, "target_x_m": 0.0, "target_y_m": 0.0, "roll_deg": 0.0, "pitch_deg": 0.0,
             "yaw_deg": 0.0, "sigma_px": s} for r in (1.0, 2.0, 3.0) for s in (0.1, 0.2, 0.3)]
    trials = [Trial(i, s, i) for i, s in enumerate(scen[::-1])]
    tasks = make_tasks(GEOMETRIC, trials, chunk_size=2)
    for task in tasks:
        assert len({it[1]["range_m"] for it in task}) == 1  # a group of 3 is never split by chunk_size 2
    assert sorted(it[0] for task in tasks for it in task) == list(range(9))


_WARM_CALLS = []


def _echo(scenario, seed):
    return {"y": scenario["range_m"] * 2.0, "s": seed}


def _echo_group(scenarios, seeds):
    return [dict(_echo(s, k), grouped=1) for s, k in zip(scenarios, seeds)]


def test_run_task_rows_ids_scenario_outputs_and_one_warm_up():
    """svgs_sim.studies.execution.run_task: the kind's outputs under the trial's id, seed and scenario; a render
    group goes to run_group, a lone trial to run_trial; the kind warms up once per process."""
    from svgs_sim.studies.execution import run_task, warm_up_worker

    kind = register_trial_kind(TrialKind("test-echo", _echo, ("y", "s", "grouped"), {}, text_keys=(),
                                         run_group=_echo_group, render_key=lambda s: s["range_m"],
                                         warm_up=lambda: _WARM_CALLS.append(1)))
    items = [(10, {"range_m": 1.0}, 5), (11, {"range_m": 1.0}, 6), (12, {"range_m": 3.0}, 7)]
    rows = run_task(kind.ref, items)
    warm_up_worker(kind.ref)
    assert len(_WARM_CALLS) == 1
    assert [{k: r[k] for k in ("trial_id", "seed", "range_m", "y", "s")} for r in rows] == [
        {"trial_id": 10, "seed": 5, "range_m": 1.0, "y": 2.0, "s": 5},
        {"trial_id": 11, "seed": 6, "range_m": 1.0, "y": 2.0, "s": 6},
        {"trial_id": 12, "seed": 7, "range_m": 3.0, "y": 6.0, "s": 7},
    ]
    assert [r.get("grouped") for r in rows] == [1, 1, None]
    assert all(r["wall_s"] >= 0 and r["cpu_s"] >= 0 for r in rows)


def _boom(scenario, seed):
    if scenario["range_m"] > 2:
        raise RuntimeError("a bug in a trial")
    return {"y": scenario["range_m"]}


def test_a_failing_trial_raises_and_keeps_finished_rows(tmp_path):
    kind = register_trial_kind(TrialKind("test-boom", _boom, ("y",), {}, text_keys=()))
    trials = [Trial(i, {"range_m": float(i)}, 0) for i in range(5)]
    with ResultStore(tmp_path, {}, kind.columns(["range_m"])) as st:
        with pytest.raises(RuntimeError, match="a bug in a trial"):
            run_study(kind, trials, st, _inline(), chunk_size=1, progress=False)
        assert st.done_ids == {0, 1, 2}


def _inline():
    from svgs_sim.studies.execution import InlineExecutor

    return InlineExecutor()


def test_executor_options_are_validated():
    assert executor_spec(processes=0).mode == "inline"
    assert executor_spec(processes=3) == ExecutorSpec("process", 3)
    assert executor_spec(workers=2) == ExecutorSpec("dask-local", 2)
    assert executor_spec().mode == "process"
    with pytest.raises(InputError, match="choose one"):
        executor_spec(processes=2, workers=2)
    with pytest.raises(InputError, match="--workers: expected an integer >= 1"):
        executor_spec(workers=0)
    for bad in ("localhost:8786", "tcp://host", "http://h:1", "tcp://h:99999", "tcp://h:port"):
        with pytest.raises(InputError, match="--scheduler"):
            executor_spec(scheduler=bad)


def _closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_unreachable_scheduler_is_exit_2_before_any_work(tmp_path, capsys, monkeypatch):
    distributed = pytest.importorskip("distributed", reason="the 'dask' extra is not installed")

    def no_client(*a, **k):  # fail fast = the plain TCP check refuses, no Dask client (and its retries) starts
        raise AssertionError("a Dask client was started for an unreachable scheduler")

    monkeypatch.setattr(distributed, "Client", no_client)
    out = tmp_path / "never"
    code = main(["campaign", "--camera", "galaxy-nexus", "--trials", "5", "--out", str(out),
                 "--scheduler", f"tcp://127.0.0.1:{_closed_port()}", "--no-progress"])  # the rendered default
    err = capsys.readouterr().err
    assert code == 2 and "cannot reach a Dask scheduler" in err and "Traceback" not in err
    # "before any work": nothing was written (no timed check: speed is for the benchmarks)
    assert not out.exists()
    code = main(["sensitivity", "--camera", "galaxy-nexus", "--vary", "range_m=5:10", "--vary", "sigma_px=0.1:0.2",
                 "--n", "8", "--out", str(out), "--scheduler", f"tcp://localhost:{_closed_port()}"])
    assert code == 2 and "--scheduler" in capsys.readouterr().err and not out.exists()


def test_missing_dask_is_a_clear_error(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)  # as if the extra were not installed
    code = main(["campaign", "--camera", "galaxy-nexus", "--trials", "5", "--out", str(tmp_path / "x"),
                 "--workers", "2"])
    err = capsys.readouterr().err
    assert code == 2 and "svgs-sim[dask]" in err and not (tmp_path / "x").exists()
