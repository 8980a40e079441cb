"""Ctrl-C and SIGTERM: a study stops at once, keeps every finished row, says so in one line and
resumes to the uninterrupted result.

The acceptance tests signal a real ``svgs campaign`` (geometric trials, a few seconds of work)
in a subprocess once its store holds rows: SIGINT to an in-process run (``--processes 0``),
SIGTERM to a process-pool run. The others check the study loop and the CLI wrapper in this
process, with a trial kind that signals its own process at a known trial (no timing window).
"""

import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from svgs_sim.cli.exit_codes import EXIT_INTERRUPTED
from svgs_sim.cli.main import main
from svgs_sim.cli.signals import EXIT_TERMINATED, Terminated, interruptible
from svgs_sim.sim.trials import TrialKind, register_trial_kind
from svgs_sim.studies.execution import InlineExecutor, StoredProgress, Trial, run_study, stored_progress
from svgs_sim.studies.store import ResultStore, read_rows

REPO = Path(__file__).resolve().parents[1]
#: The acceptance bound: seconds from the signal to the end of the process.
EXIT_WITHIN_S = 1.0
#: Rows the store holds before the signal is sent.
ROWS_BEFORE_SIGNAL = 100
#: The same campaign for every run below: 2 x 600 geometric trials (a few seconds of work).
CAMPAIGN = ["campaign", "--camera", "galaxy-nexus", "--trial-kind", "geometric", "--calibration", "exact",
            "--trials", "600", "--ranges", "5,15", "--seed", "7", "--no-progress"]
N_TRIALS = 1200
#: The CLI in a child whose SIGINT raises KeyboardInterrupt even when the test runner was
#: started with SIGINT ignored (a background job): the child of ``python -m svgs_sim.cli.main``.
_CLI_CHILD = ("import signal, sys\nsignal.signal(signal.SIGINT, signal.default_int_handler)\n"
              "from svgs_sim.cli.main import main\nsys.exit(main())")  # main() without arguments: run as the program
_STORED = re.compile(r"(\d+) of (\d+) trials are stored in (.+); rerun the same command to resume$")


def _numbers(rows):
    """Rows without the timing columns (the only ones allowed to differ between runs)."""
    return [{k: v for k, v in r.items() if k not in ("wall_s", "cpu_s")} for r in rows]


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory):
    """The rows of the campaign run without interruption (in this process, no pool)."""
    out = tmp_path_factory.mktemp("uninterrupted") / "campaign"
    assert main([*CAMPAIGN, "--out", str(out), "--processes", "0"]) == 0
    rows = read_rows(out / "results.csv")
    assert len(rows) == N_TRIALS
    return _numbers(rows)


def _count_rows(results: Path) -> int:
    try:
        return max(0, results.read_bytes().count(b"\n") - 1)
    except FileNotFoundError:
        return 0


def _signal_mid_run(out: Path, signum: int, executor: list):
    """Start the campaign in a child, send ``signum`` once its store holds rows.

    Returns
    -------
    rows_before : list of dict
        The stored rows just before the signal.
    proc : subprocess.Popen
        The ended child.
    exit_s : float
        Seconds from the signal to the end of the child.
    stderr : str
    workers : list of psutil.Process
        The child's processes seen before the signal (empty without psutil).
    """
    proc = subprocess.Popen([sys.executable, "-c", _CLI_CHILD, *CAMPAIGN, "--out", str(out), *executor],
                            cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True,
                            text=True)
    err: list[str] = []
    reader = threading.Thread(target=lambda: err.append(proc.stderr.read()), daemon=True)
    reader.start()
    workers = []
    try:
        results = out / "results.csv"
        deadline = time.monotonic() + 180  # start-up on a loaded machine; not a speed test
        while _count_rows(results) < ROWS_BEFORE_SIGNAL and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.02)
        assert proc.poll() is None, f"the campaign ended before the signal: {''.join(err)[-2000:]!r}"
        assert _count_rows(results) >= ROWS_BEFORE_SIGNAL, "no rows stored within the deadline"
        try:
            import psutil

            workers = psutil.Process(proc.pid).children(recursive=True)
        except ImportError:
            pass
        rows_before = read_rows(results)
        t0 = time.perf_counter()
        os.kill(proc.pid, signum)
        proc.wait(timeout=30)
        exit_s = time.perf_counter() - t0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    reader.join(timeout=30)  # the pipe closes when every process that holds it has ended
    proc.stderr.close()
    return rows_before, proc, exit_s, "".join(err), workers


def _check_stopped(out, rows_before, proc, exit_s, stderr, code, what):
    """Exit code, time, one line naming the stored count, every row stored before kept."""
    assert proc.returncode == code, stderr[-3000:]
    assert exit_s < EXIT_WITHIN_S, f"{exit_s:.2f} s from the signal to the exit"
    assert "Traceback" not in stderr and "leaked" not in stderr, stderr[-3000:]
    last = stderr.strip().splitlines()[-1]
    assert last.startswith(f"svgs campaign: {what}; "), stderr[-3000:]
    m = _STORED.search(last)
    assert m and int(m.group(2)) == N_TRIALS and m.group(3) == str(out), last
    rows_after = read_rows(out / "results.csv")
    assert int(m.group(1)) == len(rows_after) < N_TRIALS  # the line says what the store holds
    by_id = {r["trial_id"]: r for r in rows_after}
    assert all(by_id.get(r["trial_id"]) == r for r in rows_before), "a row stored before the signal was lost"
    assert not (out / "report.html").exists()


@pytest.mark.slow
def test_ctrl_c_stops_an_in_process_campaign_within_a_second_and_resumes(tmp_path, uninterrupted):
    out = tmp_path / "campaign"
    rows_before, proc, exit_s, stderr, _ = _signal_mid_run(out, signal.SIGINT, ["--processes", "0"])
    _check_stopped(out, rows_before, proc, exit_s, stderr, EXIT_INTERRUPTED, "interrupted")

    assert main([*CAMPAIGN, "--out", str(out), "--processes", "0"]) == 0  # the same command: resumes
    rows = read_rows(out / "results.csv")
    assert _numbers(rows) == uninterrupted
    assert (out / "results.csv").read_text().count("\n") == N_TRIALS + 1  # no row written twice


@pytest.mark.slow
def test_sigterm_stops_a_process_pool_campaign_without_leaks_and_resumes(tmp_path, uninterrupted):
    out = tmp_path / "campaign"
    rows_before, proc, exit_s, stderr, workers = _signal_mid_run(out, signal.SIGTERM, ["--processes", "2"])
    _check_stopped(out, rows_before, proc, exit_s, stderr, EXIT_TERMINATED, "terminated (SIGTERM)")
    for w in workers:  # the pool's workers were terminated, not left computing
        try:
            assert not w.is_running() or w.status() == "zombie", w.cmdline()
        except Exception as exc:  # noqa: BLE001 - psutil.NoSuchProcess: gone, as it should be
            assert type(exc).__name__ == "NoSuchProcess", exc

    assert main([*CAMPAIGN, "--out", str(out), "--processes", "0"]) == 0
    assert _numbers(read_rows(out / "results.csv")) == uninterrupted


# --------------------------------------------------------------------------- in this process
#: Trial id at which the test trial kind signals its own process, and how often.
_SIGNAL_AT = {"trial": 3, "times": 1, "signum": int(signal.SIGINT)}


def _self_signalling(scenario, seed):
    if scenario["i"] == _SIGNAL_AT["trial"]:
        for _ in range(_SIGNAL_AT["times"]):
            os.kill(os.getpid(), _SIGNAL_AT["signum"])
            time.sleep(0.01)  # the handler runs in the main thread between bytecodes
    return {"y": 2.0 * scenario["i"]}


_KIND = register_trial_kind(TrialKind("test-self-signal", _self_signalling, ("y",), {}, text_keys=()))


def _run_self_signalling(tmp_path, n=8, chunk_size=16, **signal_at):
    """Run the self-signalling kind in this process under Python's own SIGINT handler, installed
    here: a test runner started with SIGINT ignored (``make test &`` of a non-interactive shell)
    has none, and a self-sent SIGINT would then be lost."""
    _SIGNAL_AT.update({"trial": 3, "times": 1, "signum": int(signal.SIGINT), **signal_at})
    trials = [Trial(i, {"i": i}, 0) for i in range(n)]
    store = ResultStore(tmp_path, {}, _KIND.columns(["i"]), trial_ids=range(n))
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with store:
            with pytest.raises(KeyboardInterrupt) as info:
                run_study(_KIND, trials, store, InlineExecutor(), chunk_size=chunk_size, progress=False)
    finally:
        signal.signal(signal.SIGINT, previous)
    return info.value, read_rows(store.results_path)


def test_ctrl_c_in_process_finishes_the_trial_keeps_its_row_and_starts_no_other(tmp_path):
    """One task of 8 trials: the interrupt during trial 3 lets it finish and be stored, then stops."""
    exc, rows = _run_self_signalling(tmp_path)
    assert type(exc) is KeyboardInterrupt
    assert [r["trial_id"] for r in rows] == [0, 1, 2, 3]
    assert [r["y"] for r in rows] == [0.0, 2.0, 4.0, 6.0]
    assert stored_progress(exc) == StoredProgress(4, 8, str(tmp_path))
    assert stored_progress(exc).describe() == (f"4 of 8 trials are stored in {tmp_path}; "
                                               "rerun the same command to resume")


def test_a_second_ctrl_c_abandons_the_trial_under_way(tmp_path):
    exc, rows = _run_self_signalling(tmp_path, times=2)
    assert type(exc) is KeyboardInterrupt
    assert [r["trial_id"] for r in rows] == [0, 1, 2]
    assert stored_progress(exc).n_stored == 3


def test_the_in_process_interrupt_tests_pass_when_sigint_is_ignored():
    """A background job of a non-interactive shell (``make test &``) starts with SIGINT ignored,
    and Python then installs no KeyboardInterrupt handler: the tests above install their own, so
    they pass in a test run started that way too."""
    tests = ["test_ctrl_c_in_process_finishes_the_trial_keeps_its_row_and_starts_no_other",
             "test_a_second_ctrl_c_abandons_the_trial_under_way"]
    ignore = "import signal, sys, pytest; signal.signal(signal.SIGINT, signal.SIG_IGN); sys.exit(pytest.main(sys.argv[1:]))"
    check = "import signal; assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN"
    p = subprocess.run([sys.executable, "-c", f"{check}; {ignore}", "-q", "-p", "no:cacheprovider",
                        *[f"{Path(__file__).name}::{t}" for t in tests]],
                       cwd=Path(__file__).parent, capture_output=True, text=True, timeout=300,
                       preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
    assert p.returncode == 0, p.stdout[-3000:] + p.stderr[-3000:]
    assert "2 passed" in p.stdout


def test_sigterm_in_process_is_held_like_ctrl_c(tmp_path):
    """Under the CLI's SIGTERM handler: the trial finishes, is stored, and Terminated propagates."""
    def raise_terminated(signum, frame):
        raise Terminated()

    previous = signal.signal(signal.SIGTERM, raise_terminated)
    try:
        exc, rows = _run_self_signalling(tmp_path, signum=int(signal.SIGTERM), chunk_size=2)
    finally:
        signal.signal(signal.SIGTERM, previous)
    assert isinstance(exc, Terminated)
    assert [r["trial_id"] for r in rows] == [0, 1, 2, 3]
    assert stored_progress(exc) == StoredProgress(4, 8, str(tmp_path))


def _args(func, **extra):
    from argparse import Namespace

    return Namespace(command="campaign", func=func, **extra)


def test_the_cli_wrapper_turns_sigterm_into_one_line_and_exit_143(capsys):
    before = signal.getsignal(signal.SIGTERM)

    def command(args):
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(5)  # interrupted by the handler
        return 0

    t0 = time.perf_counter()
    assert interruptible(_args(command))(None) == EXIT_TERMINATED == 143
    assert time.perf_counter() - t0 < EXIT_WITHIN_S
    assert capsys.readouterr().err == "svgs campaign: terminated (SIGTERM)\n"
    assert signal.getsignal(signal.SIGTERM) == before  # put back for the caller


def test_the_cli_wrapper_says_what_an_interrupted_study_stored(capsys):
    def command(args):
        exc = KeyboardInterrupt()
        exc.svgs_stored = StoredProgress(12, 40, "runs/x")
        raise exc

    args = _args(command, calibrate_command="study")
    assert interruptible(args)(args) == EXIT_INTERRUPTED == 130
    assert capsys.readouterr().err == ("svgs campaign study: interrupted; 12 of 40 trials are stored in runs/x; "
                                       "rerun the same command to resume\n")


def test_the_cli_wrapper_treats_an_interrupt_wrapped_by_native_code_as_the_interrupt(capsys):
    """Dr.Jit's custom ops (``mi.render``) re-raise a Ctrl-C as RuntimeError from it: still exit 130."""
    def command(args):
        try:
            raise KeyboardInterrupt()
        except KeyboardInterrupt as exc:
            raise RuntimeError("drjit.custom(<_RenderOp>): error while performing a custom operation") from exc

    assert interruptible(_args(command))(None) == EXIT_INTERRUPTED
    assert capsys.readouterr().err == "svgs campaign: interrupted\n"

    def failing(args):
        raise RuntimeError("a real error")  # nothing interrupted: the error stays an error

    with pytest.raises(RuntimeError, match="a real error"):
        interruptible(_args(failing))(None)


@pytest.mark.render
def test_a_ctrl_c_inside_a_drjit_custom_op_leaves_render_film_as_keyboardinterrupt():
    """The cause of a flaky failure (exit 1 instead of 130 when Ctrl-C landed inside ``mi.render``'s
    ``dr.custom`` frame): Dr.Jit's real wrapping, undone by :func:`render_film`."""
    dr = pytest.importorskip("drjit")
    from svgs_sim.render.sampling import render_film
    from svgs_sim.render.variant import select_variant

    select_variant()

    class _Op(dr.CustomOp):
        def eval(self, x):
            raise KeyboardInterrupt()

    class _Mitsuba:  # stands in for the module: its render runs a custom op, as mi.render does
        @staticmethod
        def render(scene, sensor, spp, seed):
            return dr.custom(_Op, dr.llvm.Float(1.0) if hasattr(dr, "llvm") else 1.0)

    with pytest.raises(RuntimeError) as wrapped:  # what Dr.Jit does with it
        _Mitsuba.render(None, None, 4, 0)
    assert isinstance(wrapped.value.__cause__, KeyboardInterrupt)
    with pytest.raises(KeyboardInterrupt):
        render_film(_Mitsuba, None, None, 4, 0)


def test_an_ignored_sigterm_stays_ignored():
    previous = signal.signal(signal.SIGTERM, signal.SIG_IGN)
    try:
        seen = []
        interruptible(_args(lambda a: seen.append(signal.getsignal(signal.SIGTERM)) or 0))(None)
        assert seen == [signal.SIG_IGN]
        assert signal.getsignal(signal.SIGTERM) == signal.SIG_IGN
    finally:
        signal.signal(signal.SIGTERM, previous)


# --------------------------------------------------------------------------- stuck in native code
#: A child whose study's trials sit in native code that holds no GIL and never returns to Python
#: for seconds (as a Mitsuba render does): a Numba ``nogil`` loop. Run under the CLI's wrapper as
#: the program would (``hard_stop=True``); trial 0 is fast, so one row is stored before the signal.
_NATIVE_CHILD = r"""
import signal, sys, time
signal.signal(signal.SIGINT, signal.default_int_handler)
from argparse import Namespace
from pathlib import Path
import numba
from svgs_sim.cli.signals import interruptible
from svgs_sim.sim.trials import TrialKind, register_trial_kind
from svgs_sim.studies.execution import ExecutorSpec, Trial, run_stored_study

@numba.njit(nogil=True, cache=False)
def spin(n):
    x = 1
    for i in range(n):
        x = (x * 1103515245 + 12345) % 2147483648
    return x

def trial(scenario, seed):
    if scenario["i"] > 0:
        sys.stderr.write("native\n"); sys.stderr.flush()
        spin(20_000_000_000)  # far longer than the test: only a hard stop ends it
    return {"y": float(scenario["i"])}

spin(10)  # compiled before the study starts
kind = register_trial_kind(TrialKind("test-native", trial, ("y",), {}, text_keys=()))
out = Path(sys.argv[1])
trials = [Trial(i, {"i": i}, 0) for i in range(4)]

def command(args):
    run_stored_study(kind, trials, out, {"study": "native"}, ExecutorSpec("inline"), chunk_size=1, progress=False)
    return 0

args = Namespace(command="campaign", func=command, json="--json" in sys.argv)
sys.exit(interruptible(args, hard_stop=True)(args))
"""


def _signal_after_marker(argv, marker: str, delay_s: float, signum: int):
    """Start ``argv``, wait for ``marker`` on its stderr, then ``delay_s``, and send ``signum``.

    Returns
    -------
    proc : subprocess.Popen
        The ended child.
    exit_s : float
        Seconds from the signal to the end of the child.
    stdout, stderr : str
        What the child printed (stderr: after the marker).
    """
    proc = subprocess.Popen(argv, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True,
                            text=True)
    try:
        deadline = time.monotonic() + 180  # start-up on a loaded machine; not a speed test
        line = ""
        while marker not in line and time.monotonic() < deadline:
            line = proc.stderr.readline()
            assert line or proc.poll() is None, f"the child ended before {marker!r}"
        time.sleep(delay_s)
        assert proc.poll() is None, "the child ended before the signal"
        t0 = time.perf_counter()
        os.kill(proc.pid, signum)
        stdout, stderr = proc.communicate(timeout=60)
        exit_s = time.perf_counter() - t0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return proc, exit_s, stdout, stderr


@pytest.mark.parametrize("signum, code, what", [(signal.SIGINT, EXIT_INTERRUPTED, "interrupted"),
                                                (signal.SIGTERM, EXIT_TERMINATED, "terminated (SIGTERM)")])
def test_a_study_inside_native_code_stops_within_a_second_keeping_its_rows(tmp_path, signum, code, what):
    """The main thread cannot run Python's handler until the native call returns: the watchdog
    stops the process, after the stored row, with the one line and the exit code."""
    out = tmp_path / "study"
    proc, exit_s, stdout, stderr = _signal_after_marker([sys.executable, "-c", _NATIVE_CHILD, str(out), "--json"],
                                                        "native", 0.3, signum)  # well inside the native loop
    assert proc.returncode == code, stderr
    assert exit_s < EXIT_WITHIN_S, f"{exit_s:.2f} s from the signal to the exit"
    assert "Traceback" not in stderr, stderr
    expected = (f"svgs campaign: {what}; 1 of 4 trials are stored in {out}; rerun the same command to resume")
    assert stderr.strip().splitlines() == [expected]
    import json

    assert json.loads(stdout) == {"ok": False, "signal": signal.Signals(signum).name, "error": expected,
                                  "stored": 1, "trials": 4, "out": str(out)}
    assert [r["trial_id"] for r in read_rows(out / "results.csv")] == [0]


def test_json_output_of_an_interrupt_is_one_object(capsys):
    def command(args):
        exc = KeyboardInterrupt()
        exc.svgs_stored = StoredProgress(3, 9, "runs/y")
        raise exc

    args = _args(command, json=True)
    assert interruptible(args)(args) == EXIT_INTERRUPTED
    cap = capsys.readouterr()
    import json

    line = "svgs campaign: interrupted; 3 of 9 trials are stored in runs/y; rerun the same command to resume"
    assert cap.err == line + "\n"
    assert json.loads(cap.out) == {"ok": False, "signal": "SIGINT", "error": line, "stored": 3, "trials": 9,
                                   "out": "runs/y"}


@pytest.mark.slow
@pytest.mark.render
def test_ctrl_c_stops_svgs_render_inside_its_render_within_a_second(tmp_path):
    """A real Mitsuba render (announced as long) interrupted mid-render: exit 130 within a second."""
    out = tmp_path / "render"
    argv = [sys.executable, "-c", _CLI_CHILD, "render", "--camera", "galaxy-nexus", "--range", "5", "--spp", "1024",
            "--full-frame", "--out", str(out)]
    # 3 s after the warning: the render's kernels compiled and running
    proc, exit_s, _, stderr = _signal_after_marker(argv, "warning: this render", 3.0, signal.SIGINT)
    assert proc.returncode == EXIT_INTERRUPTED, stderr
    assert exit_s < EXIT_WITHIN_S, f"{exit_s:.2f} s from the signal to the exit"
    assert "Traceback" not in stderr and stderr.strip().splitlines()[-1] == "svgs render: interrupted", stderr
    assert not (out / "image.png").exists()
