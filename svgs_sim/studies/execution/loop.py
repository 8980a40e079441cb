"""The study loop (:func:`run_study`, :func:`run_stored_study`): feeds tasks to an executor, stores
rows as they finish, and stops at once on an interrupt with the stored rows kept
(:class:`StoredProgress`)."""

from __future__ import annotations

import contextlib
import importlib.metadata as md
import platform
import signal
import sys
import threading
import time
from concurrent.futures import (
    FIRST_COMPLETED,
    Executor,
    ProcessPoolExecutor,
    wait,
)
from dataclasses import dataclass

from svgs_sim.base.errors import interrupt_in
from svgs_sim.sim import hard_stop
from svgs_sim.sim.trials import TrialKind

from ..progress import progress_bar
from ..store import ResultStore, cell_text
from .executors import (
    ExecutorSpec,
    InlineExecutor,
    _count,
    _stop_pool,
    check_executor,
    open_executor,
)
from .tasks import DEFAULT_CHUNK_SIZE, Trial, _group_rows, _warm, make_tasks, run_task

#: Tasks in flight per worker (keeps workers busy while the main process writes rows).
TASKS_PER_WORKER = 4


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

    _warm(kind)
    with hard_stop.scope(progress):
        for items in tasks:
            groups = _group_rows(kind, items)
            while True:
                with _signals_held(escalate=True):
                    try:
                        rows = next(groups, None)
                    except SystemError as exc:
                        interrupt = interrupt_in(exc)
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

    check_executor(spec)
    store = ResultStore(out_dir, manifest, kind.columns(list(trials[0].scenario)),
                        trial_ids=[t.trial_id for t in trials], added_columns=added_columns(kind))
    stats = None
    with store:
        if {t.trial_id for t in trials} - store.done_ids:
            with open_executor(spec, kind) as ex:
                stats = run_study(kind, trials, store, ex, chunk_size=chunk_size or DEFAULT_CHUNK_SIZE,
                                  n_workers=max(spec.n_workers, 1), progress=progress, description=description,
                                  spec=spec)
    return store, stats


def added_columns(kind) -> dict:
    """The kind's parameter columns with the text of each default in a results row: what a row
    stored before the parameter existed stands for (a :class:`ResultStore` fills it in when it
    upgrades such a store; codes as their numbers, None as empty); its outputs empty (a row stored
    before an output existed does not know it)."""
    out = {name: "" for name in kind.outputs}  # an output added since: unknown (empty) in older rows
    out.update({name: cell_text(p.default) for name, p in kind.parameters.items()})
    return out


def library_versions() -> dict:
    """Versions of the libraries a study's numbers depend on (for reports)."""

    out = {"python": sys.version.split()[0], "platform": platform.platform()}
    for name in ("svgs-sim", "numpy", "scipy", "numba", "opencv-python-headless", "matplotlib", "dask", "distributed",
                 "mitsuba", "drjit"):
        try:
            out[name] = md.version(name)
        except md.PackageNotFoundError:
            pass
    return out
