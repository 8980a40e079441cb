"""Executors (:func:`executor_spec`, :func:`open_executor`): a local process pool (default, one
process per core; ``--processes 0`` runs in this process), a Dask ``LocalCluster``
(``--workers N``) or an existing Dask cluster (``--scheduler tcp://HOST:PORT``), checked before
any work starts (:func:`check_executor`)."""

from __future__ import annotations

import contextlib
import logging
import multiprocessing
import os
import re
import socket
from concurrent.futures import (
    Executor,
    Future,
    ProcessPoolExecutor,
)
from dataclasses import dataclass

from svgs_sim.base.errors import InputError
from svgs_sim.sim.trials import TrialKind

from .parent_watch import _die_with_parent_plugin, _init_pool_worker
from .tasks import warm_up_worker

#: Seconds to wait for a Dask scheduler to answer before giving up.
SCHEDULER_TIMEOUT_S = 5.0


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
