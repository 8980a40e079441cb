"""Workers die with their parent: a local pool's or LocalCluster's worker processes end when the
process that started them dies, even by SIGKILL (:func:`die_with_parent`)."""

from __future__ import annotations

import ctypes
import logging
import os
import signal
import sys
import threading
import time

from .tasks import warm_up_worker

log = logging.getLogger(__name__)


#: Seconds between two looks at the parent pid by the fallback watchdog of :func:`die_with_parent`.
PARENT_POLL_S = 1.0


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
