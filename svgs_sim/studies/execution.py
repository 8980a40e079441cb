"""Where trials run: a ``concurrent.futures.Executor`` chosen by the user, and the loop that
feeds it and stores rows as they finish.

Executors (:func:`executor_spec`)
    - default: a local process pool with one process per CPU core;
    - ``--processes N``: a local process pool of N processes (``0``: run in this process,
      no pool - for debugging);
    - ``--workers N``: a Dask ``LocalCluster`` of N single-threaded worker processes,
      through ``distributed.Client(cluster).get_executor()``;
    - ``--scheduler tcp://HOST:PORT``: an existing Dask cluster.

Dask is an optional extra (``pip install 'svgs-sim[dask]'``). Missing Dask and an
unreachable scheduler are :class:`~svgs_sim.base.errors.InputError`\\ s raised by
:func:`check_executor`, before any work starts.

Workers die with their parent: a local pool's or LocalCluster's worker processes end when the
process that started them dies, even by SIGKILL (:func:`die_with_parent`).

Interrupts: Ctrl-C (``KeyboardInterrupt``, or a subclass such as the CLI's SIGTERM exception)
stops a study at once. In this process (``--processes 0``) the trials run render group by render
group and each group's rows are stored as it finishes; an interrupt lets the group under way
finish (a few trials, or one render and its exposures: a second Ctrl-C abandons it), stores it
and stops, so no group starts after the interrupt; run from the command line, a group still
under way half a second after the signal (a render cannot be entered by Python's handler) is
abandoned and the process stops with the rows stored so far (:mod:`svgs_sim.sim.hard_stop`). On a pool
the rows of every finished task are stored, then the workers are terminated (they ignore SIGINT themselves: Ctrl-C in a
terminal reaches the whole process group). The interrupt is re-raised with :class:`StoredProgress` attached as its
``svgs_stored`` attribute (:func:`stored_progress`): how many trials the store holds.

Results do not depend on the executor: each trial carries its own seed
(:mod:`svgs_sim.studies.seeding`) and trials never share random state. Trials are packed into tasks
(chunks of ``chunk_size`` trials, trials sharing a render key kept together) to amortise the
per-task overhead; the packing does not change any trial's numbers either.
"""

from __future__ import annotations

import contextlib
import ctypes
import importlib
import logging
import multiprocessing
import os
import re
import signal
import socket
import sys
import threading
import time
from concurrent.futures import FIRST_COMPLETED, Executor, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass

from svgs_sim.base.errors import InputError

from svgs_sim.sim.trials import TrialKind, get_trial_kind

#: Seconds to wait for a Dask scheduler to answer before giving up.
SCHEDULER_TIMEOUT_S = 5.0
#: Default number of trials per task.
DEFAULT_CHUNK_SIZE = 16
#: Tasks in flight per worker (keeps workers busy while the main process writes rows).
TASKS_PER_WORKER = 4
#: Seconds between two looks at the parent pid by the fallback watchdog of :func:`die_with_parent`.
PARENT_POLL_S = 1.0

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ExecutorSpec:
    """How to run a study's tasks.

    Attributes
    ----------
    mode : str
        ``"inline"``, ``"process"``, ``"dask-local"`` or ``"dask-scheduler"``.
    n_workers : int
        Workers (processes) for the local modes; 0 for a remote scheduler (unknown).
    scheduler : str or None
        ``tcp://HOST:PORT`` for ``dask-scheduler``.
    """

    mode: str
    n_workers: int = 1
    scheduler: str | None = None

    def describe(self) -> str:
        if self.mode == "inline":
            return "in this process (no pool)"
        if self.mode == "process":
            return f"local process pool, {self.n_workers} process(es)"
        if self.mode == "dask-local":
            return f"Dask LocalCluster, {self.n_workers} single-threaded worker process(es)"
        return f"Dask cluster at {self.scheduler}"


def _count(value, name: str, minimum: int) -> int:
    if isinstance(value, bool):
        raise InputError(f"{name}: expected an integer >= {minimum}, got {value!r}")
    try:
        v = int(value)
    except (TypeError, ValueError):
        raise InputError(f"{name}: expected an integer >= {minimum}, got {value!r}") from None
    if v != value and not (isinstance(value, str) and str(v) == value.strip()):
        raise InputError(f"{name}: expected an integer >= {minimum}, got {value!r}")
    if v < minimum:
        raise InputError(f"{name}: expected an integer >= {minimum}, got {value!r}")
    return v


_ADDRESS = re.compile(r"^(tcp|tls)://(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9_.\-]+):(\d{1,5})$")


def parse_scheduler_address(address: str) -> tuple[str, str, int]:
    """Split ``tcp://HOST:PORT`` (or ``tls://``) into (scheme, host, port); InputError if malformed."""
    m = _ADDRESS.match(str(address).strip())
    if not m:
        raise InputError(f"--scheduler: expected an address like tcp://HOST:PORT, got {address!r}")
    port = int(m.group(3))
    if not 1 <= port <= 65535:
        raise InputError(f"--scheduler: port {port} is out of range 1..65535 in {address!r}")
    return m.group(1), m.group(2).strip("[]"), port


def executor_spec(processes=None, workers=None, scheduler=None) -> ExecutorSpec:
    """Validate the executor options (at most one of them) into an :class:`ExecutorSpec`.

    Parameters
    ----------
    processes : int, optional
        Local process pool size (0: in this process).
    workers : int, optional
        Dask LocalCluster worker count.
    scheduler : str, optional
        Address of a running Dask scheduler.
    """
    given = [n for n, v in (("--processes", processes), ("--workers", workers), ("--scheduler", scheduler)) if v is not None]
    if len(given) > 1:
        raise InputError(f"{' and '.join(given)}: choose one way to run the trials")
    if workers is not None:
        return ExecutorSpec("dask-local", _count(workers, "--workers", 1))
    if scheduler is not None:
        parse_scheduler_address(scheduler)
        return ExecutorSpec("dask-scheduler", 0, str(scheduler).strip())
    if processes is not None:
        n = _count(processes, "--processes", 0)
        return ExecutorSpec("inline", 1) if n == 0 else ExecutorSpec("process", n)
    return ExecutorSpec("process", max(1, os.cpu_count() or 1))


def _require_dask(flag: str):
    try:
        import distributed  # noqa: F401
    except ModuleNotFoundError:
        raise InputError(
            f"{flag} runs trials on Dask, which is not installed; install the optional extra with "
            "pip install 'svgs-sim[dask]' (or pip install 'dask[distributed]'), or use --processes N for a local pool"
        ) from None


def check_executor(spec: ExecutorSpec) -> None:
    """Fail fast, before any work: Dask importable, scheduler reachable (a TCP connect)."""
    if spec.mode == "dask-local":
        _require_dask("--workers")
    elif spec.mode == "dask-scheduler":
        _require_dask("--scheduler")
        _, host, port = parse_scheduler_address(spec.scheduler)
        try:
            with socket.create_connection((host, port), timeout=SCHEDULER_TIMEOUT_S):
                pass
        except OSError as exc:
            raise InputError(
                f"--scheduler: cannot reach a Dask scheduler at {spec.scheduler} ({exc.strerror or exc}); "
                "is it running and reachable from here?"
            ) from None


# --------------------------------------------------------------------------- in the workers
def run_task(kind_ref: tuple[str, str], items: list) -> list[dict]:
    """Run one task of a study (in a worker process): trials sharing a render key or a chunk.

    Parameters
    ----------
    kind_ref : (module, name)
        Where the trial kind is registered (:attr:`svgs_sim.sim.trials.TrialKind.ref`).
    items : list of (trial_id, scenario, seed)

    Returns
    -------
    list of dict
        One row per trial: ``trial_id``, ``seed``, the scenario, the outputs, ``wall_s`` and
        ``cpu_s`` (wall-clock and worker CPU seconds, averaged over a render group).
    """
    kind = _kind(kind_ref)
    _warm(kind)
    return [row for rows in _group_rows(kind, items) for row in rows]


def _group_rows(kind: TrialKind, items: list):
    """Run the trials of one task render group by render group, yielding each group's rows.

    Parameters
    ----------
    kind : TrialKind
    items : list of (trial_id, scenario, seed)

    Yields
    ------
    list of dict
        The rows of one group of consecutive items sharing a render key (one row per trial
        when the kind has no ``run_group``), as :func:`run_task` returns them.
    """
    groups: list[list] = []
    for it in items:
        key = kind.render_key(it[1]) if (kind.render_key and kind.run_group) else None
        if groups and key is not None and groups[-1][0] == key:
            groups[-1][1].append(it)
        else:
            groups.append([key, [it]])
    for key, grp in groups:
        t0, c0 = time.perf_counter(), time.process_time()
        if key is not None and len(grp) > 1:
            outs = kind.run_group([g[1] for g in grp], [g[2] for g in grp])
        else:
            outs = [kind.run_trial(g[1], g[2]) for g in grp]
        dt, dc = (time.perf_counter() - t0) / len(grp), (time.process_time() - c0) / len(grp)
        yield [{"trial_id": int(tid), "seed": int(seed), **scen, **out, "wall_s": dt, "cpu_s": dc}
               for (tid, scen, seed), out in zip(grp, outs)]


def _kind(kind_ref: tuple[str, str]) -> TrialKind:
    """Import the module that registers the kind (in a fresh worker), then look it up."""
    module, name = kind_ref
    importlib.import_module(module)
    return get_trial_kind(name)


#: Trial kinds already warmed up in this process.
_WARMED: set = set()


def _warm(kind: TrialKind) -> None:
    if kind.warm_up is not None and kind.name not in _WARMED:
        kind.warm_up()
        _WARMED.add(kind.name)


def warm_up_worker(kind_ref: tuple[str, str]) -> None:
    """Import the kind's module and warm it up (in each worker of a pool or a LocalCluster)."""
    _warm(_kind(kind_ref))


#: From <linux/prctl.h>.
_PR_SET_PDEATHSIG = 1


def _set_pdeathsig_sigkill() -> None:
    """``prctl(PR_SET_PDEATHSIG, SIGKILL)`` through libc; OSError (or AttributeError) if unavailable."""
    libc = ctypes.CDLL(None, use_errno=True)
    prctl = libc.prctl
    prctl.argtypes = [ctypes.c_int, ctypes.c_ulong, ctypes.c_ulong, ctypes.c_ulong, ctypes.c_ulong]
    prctl.restype = ctypes.c_int
    if prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0) != 0:
        err = ctypes.get_errno()
        raise OSError(err, os.strerror(err))


def _watch_parent(parent_pid: int) -> None:
    while os.getppid() == parent_pid:
        time.sleep(PARENT_POLL_S)
    os._exit(1)


def die_with_parent(parent_pid: int) -> str:
    """Make this (worker) process end when its parent, ``parent_pid``, dies - SIGKILL included.

    On Linux the kernel sends this process SIGKILL when its parent dies
    (``prctl(PR_SET_PDEATHSIG)``), which also stops a worker busy in native code (a render).
    Linux ties the signal to the parent *thread* that started the process: a pool must be
    used from the thread that opened it (as :func:`run_stored_study` does). Where prctl is
    unavailable (not Linux, or refused), a daemon thread polls ``os.getppid()`` every
    :data:`PARENT_POLL_S` s and exits the process once the parent has changed; it runs only
    between Python bytecodes, and on Windows, where ``getppid`` does not change, it never fires.

    Parameters
    ----------
    parent_pid : int
        The pid of the process that started this one; if it is already gone (this
        process's parent is no longer ``parent_pid``), this process exits at once.

    Returns
    -------
    str
        ``"prctl"`` or ``"watchdog"``: how the parent is watched.
    """
    how = "watchdog"
    if sys.platform.startswith("linux"):
        try:
            _set_pdeathsig_sigkill()
            how = "prctl"
        except (OSError, AttributeError) as exc:
            log.debug("prctl(PR_SET_PDEATHSIG) unavailable (%s); watching the parent pid with a thread", exc)
    else:
        log.debug("no prctl on %s; watching the parent pid with a thread", sys.platform)
    if os.getppid() != parent_pid:  # the parent died before prctl took effect (or before we got here)
        os._exit(1)
    if how == "watchdog":
        threading.Thread(target=_watch_parent, args=(parent_pid,), name="svgs-parent-watch", daemon=True).start()
    return how


def _init_pool_worker(parent_pid: int, kind_ref: tuple[str, str] | None) -> None:
    """Process-pool initializer: ignore SIGINT (the parent stops the pool), die with the parent,
    then warm the trial kind up."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    die_with_parent(parent_pid)
    if kind_ref is not None:
        warm_up_worker(kind_ref)


def _die_with_parent_plugin(parent_pid: int):
    """A Dask ``WorkerPlugin`` calling :func:`die_with_parent` in each worker of a LocalCluster,
    including workers a nanny restarts later. Only for clusters whose workers are our children."""
    from distributed.diagnostics.plugin import WorkerPlugin

    class DieWithParent(WorkerPlugin):
        name = "svgs-die-with-parent"

        def __init__(self, pid: int):
            self.pid = pid

        def setup(self, worker):
            die_with_parent(self.pid)

    return DieWithParent(parent_pid)


class InlineExecutor(Executor):
    """Runs each task at submission, in this process (no parallelism; for debugging).

    An exception of the task is handed to the caller through the future; an interrupt
    (``KeyboardInterrupt``, ``SystemExit``) is not a result and propagates at once.
    :func:`run_study` does not submit to it: it runs the tasks itself, group by group.
    """

    def submit(self, fn, /, *args, **kwargs):
        fut = Future()
        try:
            fut.set_result(fn(*args, **kwargs))
        except Exception as exc:  # noqa: BLE001 - handed to the caller through the future
            fut.set_exception(exc)
        return fut


#: Seconds to wait for each terminated pool worker to end.
STOP_JOIN_S = 5.0


def _stop_pool(ex: ProcessPoolExecutor) -> None:
    """Stop a process pool now: cancel the queued tasks, terminate (SIGTERM) the workers and
    wait for them, so the pool's queues and semaphores are released before this process exits
    (no "leaked semaphore" warning from the resource tracker)."""
    procs = list((getattr(ex, "_processes", None) or {}).values())  # no public API before Python 3.14
    manager = getattr(ex, "_executor_manager_thread", None)
    ex.shutdown(wait=False, cancel_futures=True)
    for p in procs:
        if p.is_alive():
            p.terminate()
    for p in procs:
        p.join(STOP_JOIN_S)
    if manager is not None:
        # let the pool's manager thread end and close its wake-up pipe now: at exit, Python 3.11's
        # concurrent.futures wakes every manager thread and races one that is closing its pipe
        # ("OSError: Bad file descriptor" under "Exception ignored", about 1 stop in 8)
        manager.join(STOP_JOIN_S)


@contextlib.contextmanager
def open_executor(spec: ExecutorSpec, kind: TrialKind | None = None):
    """Start the executor of ``spec``; yields a ``concurrent.futures.Executor``.

    Local process pools use the ``spawn`` start method (no forked locks or threads) and warm
    the trial kind up in every worker (e.g. load the compiled solver). The workers of a local
    pool or LocalCluster die with this process (:func:`die_with_parent`); use the executor
    from the thread that opened it.
    """
    check_executor(spec)
    if spec.mode == "inline":
        if kind is not None:
            warm_up_worker(kind.ref)
        yield InlineExecutor()
        return
    if spec.mode == "process":
        with ProcessPoolExecutor(max_workers=spec.n_workers, mp_context=multiprocessing.get_context("spawn"),
                                 initializer=_init_pool_worker,
                                 initargs=(os.getpid(), kind.ref if kind is not None else None)) as ex:
            try:
                yield ex
            except BaseException:  # an interrupt or a failed trial: the tasks under way are not waited for
                _stop_pool(ex)
                raise
        return
    from distributed import Client, LocalCluster

    if spec.mode == "dask-local":
        cluster = LocalCluster(n_workers=spec.n_workers, threads_per_worker=1, processes=True,
                               dashboard_address="127.0.0.1:0", silence_logs=logging.ERROR)  # no fixed port, loopback
        try:
            with Client(cluster) as client:
                # the nannies run in this process: the worker processes are our children
                client.register_plugin(_die_with_parent_plugin(os.getpid()))
                if kind is not None:
                    client.run(warm_up_worker, kind.ref)
                yield client.get_executor(pure=False)
        finally:
            cluster.close()
        return
    try:
        client = Client(spec.scheduler, timeout=f"{SCHEDULER_TIMEOUT_S}s")
    except (OSError, TimeoutError) as exc:
        raise InputError(f"--scheduler: cannot connect to the Dask scheduler at {spec.scheduler}: {exc}") from None
    try:
        ex = client.get_executor(pure=False)
        # the cluster's size is not known from the command line and may change while the study
        # runs (adaptive clusters): run_study asks it for its worker threads before each submission
        ex.svgs_slots = lambda: max(1, sum(client.nthreads().values()))
        yield ex
    finally:
        client.close()


# --------------------------------------------------------------------------- the study loop
@dataclass(frozen=True)
class Trial:
    """One trial of a study: its id (unique in the study), scenario and seed."""

    trial_id: int
    scenario: dict
    seed: int


def make_tasks(kind: TrialKind, trials: list[Trial], chunk_size: int) -> list[list]:
    """Pack trials into tasks of at most ``chunk_size`` trials (larger only to keep a render
    group whole, up to ``4 * chunk_size``); trials with equal render keys go to the same task,
    consecutively.

    Returns
    -------
    list of list of (trial_id, scenario, seed)
    """
    groups: dict = {}
    for tr in trials:
        key = kind.render_key(tr.scenario) if kind.render_key is not None else ("__trial__", tr.trial_id)
        groups.setdefault(key, []).append((tr.trial_id, tr.scenario, tr.seed))
    tasks, cur = [], []
    for grp in groups.values():
        while len(grp) > 4 * chunk_size:  # a huge group: split it (each part renders once)
            if cur:
                tasks.append(cur)
                cur = []
            tasks.append(grp[: 4 * chunk_size])
            grp = grp[4 * chunk_size:]
        if cur and len(cur) + len(grp) > chunk_size:
            tasks.append(cur)
            cur = []
        cur = cur + grp
    if cur:
        tasks.append(cur)
    return tasks


@dataclass
class RunStats:
    """What a call of :func:`run_study` did."""

    n_trials: int
    n_already_done: int
    n_run: int
    n_tasks: int
    n_render_groups: int
    elapsed_s: float
    executor: str

    @property
    def trials_per_s(self) -> float:
        return self.n_run / self.elapsed_s if self.elapsed_s > 0 else float("nan")

    @property
    def rate_text(self) -> str:
        """The throughput for a person: ``"23.4 trials/s"``, or ``"12 s/trial"`` below one a second."""
        if self.n_run <= 0 or not self.elapsed_s > 0:
            return "no trial run"
        r = self.n_run / self.elapsed_s
        return f"{r:.3g} trials/s" if r >= 1.0 else f"{1.0 / r:.3g} s/trial"


@dataclass(frozen=True)
class StoredProgress:
    """What an interrupted study keeps: attached by :func:`run_study` to the interrupt it
    re-raises, as the attribute ``svgs_stored`` (read it with :func:`stored_progress`).

    Attributes
    ----------
    n_stored : int
        Trials of the study whose rows are in the store.
    n_trials : int
        Trials of the study.
    out_dir : str
        The study's store directory.
    """

    n_stored: int
    n_trials: int
    out_dir: str

    def describe(self) -> str:
        """One sentence: how many trials are stored where, and that a rerun resumes."""
        return (f"{self.n_stored} of {self.n_trials} trials are stored in {self.out_dir}; "
                "rerun the same command to resume")


def stored_progress(exc: BaseException) -> StoredProgress | None:
    """The :class:`StoredProgress` attached to an interrupt by :func:`run_study`, or None."""
    return getattr(exc, "svgs_stored", None)


@contextlib.contextmanager
def _signals_held(escalate: bool = False):
    """Hold SIGINT and SIGTERM during the block and act on the first one that arrived right after it.

    Rows are written inside such a block, so a batch is stored whole (never torn, never written
    but uncounted); in this process a render group is also computed inside one, so an
    interrupt lets the group under way finish and be stored, and is then raised before the
    next group starts. Only Python-level handlers are held, and only in the main thread (the
    only one that runs them); a signal whose action is the default or ignore is left alone.

    Parameters
    ----------
    escalate : bool
        A second signal during the block is acted on at once (Ctrl-C twice: stop now, the
        group under way is lost).
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []
    held = {}

    def hold(signum, frame):
        caught.append(signum)
        if escalate and len(caught) > 1:
            held[signum](signum, frame)

    for signum in (signal.SIGINT, signal.SIGTERM):
        handler = signal.getsignal(signum)
        if callable(handler):
            held[signum] = handler
            signal.signal(signum, hold)
    try:
        yield
    finally:
        for signum, handler in held.items():
            signal.signal(signum, handler)
    if caught:  # the block ended normally: the first signal decides
        held[caught[0]](caught[0], None)


def _interrupt_in(exc: BaseException) -> KeyboardInterrupt | None:
    """The interrupt that caused ``exc``, if any: an interrupt raised inside a callback from
    compiled code (a Numba kernel) comes back as a ``SystemError`` caused by it."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return exc
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return None


def _store_rows(store, rows: list, bar) -> None:
    with _signals_held():
        store.append(rows)
    bar.update(len(rows))


def _run_inline(kind: TrialKind, tasks: list, store, bar, progress) -> None:
    """Run ``tasks`` in this process, storing each render group's rows as it finishes.

    Ctrl-C or SIGTERM during a group lets it finish (a few trials, or one render and its
    exposures), stores its rows and then propagates: no group starts after it. A second
    signal stops the group under way. A failing trial raises after every finished group
    was stored. When the CLI runs as the program, a group that does not finish within
    :data:`svgs_sim.sim.hard_stop.HARD_STOP_AFTER_S` of the signal (a render: native code the
    handler cannot enter) is abandoned and the process stops with the rows stored so far
    (:mod:`svgs_sim.sim.hard_stop`; ``progress()`` says how many).
    """
    from svgs_sim.sim import hard_stop

    _warm(kind)
    with hard_stop.scope(progress):
        for items in tasks:
            groups = _group_rows(kind, items)
            while True:
                with _signals_held(escalate=True):
                    try:
                        rows = next(groups, None)
                    except SystemError as exc:
                        interrupt = _interrupt_in(exc)
                        if interrupt is None:
                            raise
                        raise interrupt from None
                    if rows is None:
                        break
                    with hard_stop.protected():  # a hard stop waits for the rows to be written whole
                        store.append(rows)
                bar.update(len(rows))


def _run_on_executor(kind: TrialKind, tasks: list, store, executor: Executor, bar, window) -> None:
    """Feed ``tasks`` to ``executor``, at most ``window()`` in flight; store rows as tasks finish.

    A failing trial raises after the rows of every finished task are stored; so does an
    interrupt, which also cancels the tasks not yet started and stops a process pool's workers.
    """
    todo = list(reversed(tasks))
    in_flight: set = set()
    try:
        while todo or in_flight:
            limit = window() if todo else 0
            while todo and len(in_flight) < limit:
                in_flight.add(executor.submit(run_task, kind.ref, todo.pop()))
            finished, in_flight = wait(in_flight, return_when=FIRST_COMPLETED)
            error = None
            for fut in finished:
                if fut.exception() is not None:  # a bug in a trial: keep every finished row, then raise
                    error = error or fut.exception()
                    continue
                _store_rows(store, fut.result(), bar)
            if error is not None:
                raise error
    except BaseException as exc:
        for fut in in_flight:
            fut.cancel()
        with _signals_held():  # tasks that finished while the loop was stopping: keep their rows
            for fut in in_flight:
                if fut.done() and not fut.cancelled() and fut.exception() is None:
                    store.append(fut.result())
        if isinstance(exc, KeyboardInterrupt) and isinstance(executor, ProcessPoolExecutor):
            _stop_pool(executor)  # whoever opened the pool: the tasks under way are not waited for
        raise


def run_study(kind: TrialKind, trials: list[Trial], store, executor: Executor, *, chunk_size: int = DEFAULT_CHUNK_SIZE,
              n_workers: int = 1, progress: bool = True, description: str = "trials", spec: ExecutorSpec | None = None
              ) -> RunStats:
    """Run the trials of ``trials`` not yet in ``store`` on ``executor``; store rows as they finish.

    Parameters
    ----------
    kind : TrialKind
    trials : list of Trial
        The whole study (finished ones are skipped).
    store : ResultStore
        Open store (:meth:`ResultStore.open`).
    executor : concurrent.futures.Executor
    chunk_size : int
        Trials per task.
    n_workers : int
        Used to size the window of tasks in flight (``TASKS_PER_WORKER`` per worker). An
        executor with an ``svgs_slots()`` method (an existing Dask cluster) is asked instead, so
        the window follows the cluster's worker threads as they come and go.
    progress : bool
        Show a progress bar with ETA on stderr.

    Returns
    -------
    RunStats

    Raises
    ------
    KeyboardInterrupt
        Interrupted (Ctrl-C, or a subclass such as SIGTERM's in the CLI): every finished row is
        stored first; the exception carries a :class:`StoredProgress` (:func:`stored_progress`).
        On an :class:`InlineExecutor` the trials run group by group in this process and no task
        starts after the interrupt.
    """
    from .progress import progress_bar

    ids = [t.trial_id for t in trials]
    if len(set(ids)) != len(ids):
        raise ValueError("run_study: duplicate trial ids")
    done = store.done_ids
    pending = [t for t in trials if t.trial_id not in done]
    tasks = make_tasks(kind, pending, _count(chunk_size, "--chunk-size", 1))
    n_groups = len({kind.render_key(t.scenario) for t in pending}) if kind.render_key else len(pending)
    t0 = time.perf_counter()
    slots = getattr(executor, "svgs_slots", None)

    def window() -> int:
        return max(2, TASKS_PER_WORKER * max(1, slots() if slots is not None else n_workers))

    def kept() -> StoredProgress:
        return StoredProgress(len(set(ids) & store.done_ids), len(ids), str(store.dir))

    try:
        with progress_bar(len(pending), description, enabled=progress) as bar:
            if isinstance(executor, InlineExecutor):
                _run_inline(kind, tasks, store, bar, kept)
            else:
                _run_on_executor(kind, tasks, store, executor, bar, window)
    except KeyboardInterrupt as exc:  # Ctrl-C, or a subclass (the CLI's SIGTERM): say what is kept
        if getattr(exc, "svgs_stored", None) is None:
            exc.svgs_stored = kept()
        raise
    return RunStats(len(trials), len(trials) - len(pending), len(pending), len(tasks), n_groups,
                    time.perf_counter() - t0, spec.describe() if spec else type(executor).__name__)


def run_stored_study(kind: TrialKind, trials: list[Trial], out_dir, manifest: dict, spec: ExecutorSpec, *,
                     chunk_size: int | None = None, progress: bool = True, description: str = ""):
    """Run the trials of a study that its results store does not hold yet.

    The one loop of every study (campaign, sensitivity, range sweep, exposure study): open the
    resumable store in ``out_dir`` (a changed ``manifest`` is refused), start the executor only
    if a trial is missing, store rows as they finish.

    Parameters
    ----------
    kind : TrialKind
    trials : list of Trial
        Every trial of the study (those already stored are skipped).
    out_dir : str or Path
    manifest : dict
        What the study computes (its configuration), checked against a resumed store.
    spec : ExecutorSpec
    chunk_size : int, optional
        Trials per task (default :data:`DEFAULT_CHUNK_SIZE`).
    progress : bool
        Show a progress bar.
    description : str
        Label of the progress bar.

    Returns
    -------
    store : ResultStore
        Closed; read the rows with ``store.read_rows()`` or ``store.read_table()``.
    stats : RunStats or None
        None when every trial was already stored.
    """
    from .store import ResultStore

    check_executor(spec)
    store = ResultStore(out_dir, manifest, kind.columns(list(trials[0].scenario)),
                        trial_ids=[t.trial_id for t in trials])
    stats = None
    with store:
        if {t.trial_id for t in trials} - store.done_ids:
            with open_executor(spec, kind) as ex:
                stats = run_study(kind, trials, store, ex, chunk_size=chunk_size or DEFAULT_CHUNK_SIZE,
                                  n_workers=max(spec.n_workers, 1), progress=progress, description=description,
                                  spec=spec)
    return store, stats


def library_versions() -> dict:
    """Versions of the libraries a study's numbers depend on (for reports)."""
    import importlib.metadata as md
    import platform

    out = {"python": sys.version.split()[0], "platform": platform.platform()}
    for name in ("svgs-sim", "numpy", "scipy", "numba", "opencv-python-headless", "matplotlib", "dask", "distributed",
                 "mitsuba", "drjit"):
        try:
            out[name] = md.version(name)
        except md.PackageNotFoundError:
            pass
    return out


# --------------------------------------------------------------------------- plans
#: Core-seconds of one render and of one trial (an exposure, or a geometric trial) per trial
#: kind: the cost table a study's plan is estimated from (docs/performance.md, "Plans"). The
#: render kind's are the 400-trial campaigns' measured cost (97 s and 172 s on two processes,
#: 100 renders and 400 exposures: about 1 s a render and 0.3 s an exposure of one core).
#: The tof kind's: the committed ToF study (docs/reports/tof_stability.md, 15,800 frames, 20
#: renders): renders of 2.8-20 s (about 10 s), each frame's exposure and pipeline 0.067 s.
COST_TABLE_S = {"render": (1.0, 0.3), "geometric": (0.0, 0.001), "tof": (10.0, 0.067)}
#: A plan warns when its estimated wall-clock time exceeds this many seconds.
LONG_STUDY_S = 3600.0


def cpu_cores() -> int:
    """The CPU cores this process may run on (``os.sched_getaffinity`` where there is one,
    else ``os.cpu_count()``; at least 1)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def _duration(seconds: float) -> str:
    if seconds < 90:
        return f"{seconds:.2g} s" if seconds < 10 else f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.0f} min"
    if seconds < 2 * 86400:
        return f"{seconds / 3600:.1f} h"
    return f"{seconds / 86400:.1f} days"


@dataclass(frozen=True)
class StudyPlan:
    """What a study is about to do and how long it should take, before any work starts.

    Attributes
    ----------
    kind : str
        Trial kind (a key of :data:`COST_TABLE_S`).
    n_trials : int
        Trials of the study (those already stored are skipped when it runs).
    n_renders : int
        Renders (distinct render keys); 0 for a kind that does not render.
    spec : ExecutorSpec
        Where the trials run.
    cores : int
        CPU cores this process may use (:func:`cpu_cores`).
    note : str
        Said after the counts (e.g. what they leave out); may be empty.
    """

    kind: str
    n_trials: int
    n_renders: int
    spec: ExecutorSpec
    cores: int
    note: str = ""

    @property
    def core_s(self) -> float | None:
        """Estimated core-seconds, from :data:`COST_TABLE_S` (None for a kind not in it)."""
        if self.kind not in COST_TABLE_S:
            return None
        render_s, trial_s = COST_TABLE_S[self.kind]
        return self.n_renders * render_s + self.n_trials * trial_s

    @property
    def parallel(self) -> int:
        """Trials running at once on this machine (0: a remote cluster of unknown size)."""
        if self.spec.mode == "dask-scheduler":
            return 0
        return max(1, min(self.spec.n_workers, self.cores))

    @property
    def wall_s(self) -> float | None:
        """Estimated wall-clock seconds (None on a remote cluster or without a cost)."""
        return self.core_s / self.parallel if self.parallel and self.core_s is not None else None

    def warnings(self) -> list[str]:
        """Lines to print after the plan: above :data:`LONG_STUDY_S`, more workers than cores."""
        out = []
        local = self.spec.mode in ("process", "dask-local")
        if local and self.spec.n_workers > self.cores:
            flag = "--processes" if self.spec.mode == "process" else "--workers"
            out.append(f"warning: {flag} {self.spec.n_workers} exceeds the {self.cores} CPU core(s) this process may "
                       f"use: the workers share them and each trial is slower (use {flag} {self.cores} or fewer)")
        if self.wall_s is not None and self.wall_s > LONG_STUDY_S:
            out.append(f"warning: this study is estimated to take about {_duration(self.wall_s)}; interrupt it with "
                       "Ctrl-C (finished trials are kept and a rerun resumes), or ask for fewer trials; --plan-only "
                       "prints this plan without running")
        return out

    def describe(self) -> str:
        """One line: trials, renders, the estimate and where it comes from."""
        renders = f"{self.n_renders:,} render(s)" if self.n_renders else "no render"
        note = f" ({self.note})" if self.note else ""
        if self.core_s is None:
            return f"plan: {self.n_trials:,} {self.kind} trial(s), {renders}{note}; no cost table entry for the estimate"
        render_s, trial_s = COST_TABLE_S[self.kind]
        table = (f"{render_s:g} s a render, {trial_s:g} s a trial" if render_s else f"{trial_s:g} s a trial")
        est = f"~{_duration(self.core_s)} of one core ({self.kind} cost table, docs/performance.md: {table})"
        return f"plan: {self.n_trials:,} {self.kind} trial(s), {renders}{note}; {est}{self.spread_text()}"

    def spread_text(self) -> str:
        """How the estimate spreads over the executor: ``", ~T on N core(s) (pool)"``, or the
        Dask cluster's share (its size is not known here)."""
        if self.wall_s is not None:
            return f", ~{_duration(self.wall_s)} on {self.parallel} core(s) ({self.spec.describe()})"
        return f", divided among the workers of the Dask cluster at {self.spec.scheduler}"

    def lines(self) -> list[str]:
        """:meth:`describe` and :meth:`warnings`."""
        return [self.describe(), *self.warnings()]


def plan_study(kind: str, n_trials: int, n_renders: int, spec: ExecutorSpec, *, note: str = "") -> StudyPlan:
    """The :class:`StudyPlan` of a study, from its counts alone (nothing is built: a plan of
    ten million trials costs nothing).

    Parameters
    ----------
    kind : str
        Trial kind (``"render"``, ``"geometric"``, ``"tof"``).
    n_trials, n_renders : int
        Trials and renders (distinct render keys) of the study.
    spec : ExecutorSpec
    note : str
        Said after the counts.
    """
    return StudyPlan(str(kind), int(n_trials), int(n_renders), spec, cpu_cores(), note)


def plan_trials(kind: TrialKind, trials: list[Trial], spec: ExecutorSpec, *, done_ids=()) -> StudyPlan:
    """The :class:`StudyPlan` of built trials: those not in ``done_ids``, renders counted as
    their distinct render keys."""
    done = set(done_ids)
    pending = [t for t in trials if t.trial_id not in done]
    costly = COST_TABLE_S.get(kind.name, (1.0, 0.0))[0] > 0  # a geometric "render" (a projection) costs nothing
    renders = len({kind.render_key(t.scenario) for t in pending}) if kind.render_key and costly else 0
    note = f"{len(trials) - len(pending):,} already stored" if done else ""
    return plan_study(kind.name, len(pending), renders, spec, note=note)
