"""Stop within a second of Ctrl-C even when the main thread is inside native code (a render).

Python runs a signal handler only between bytecodes of the main thread. A Mitsuba render or a
Dr.Jit evaluation is one long native call that releases the GIL but returns only when done
(seconds to minutes), so Ctrl-C would wait for it. The CLI therefore runs a *watchdog* thread
while a command runs as the program (:func:`svgs_sim.cli.signals.watchdog`): the C-level signal handler
writes the signal's number into a socket (``signal.set_wakeup_fd``) even while the main thread is
busy, the watchdog reads it, gives the main thread :data:`HARD_STOP_AFTER_S` to stop on its own,
and if the command is still inside a :func:`scope` by then it stops the process itself:

1. it takes the write lock (:func:`protected`), so no row or file is half written (:func:`hold_writes`);
2. it prints the command's one interrupt line (what the scope says is stored, and that a rerun
   resumes);
3. it ends the process with ``os._exit`` and the interrupt's exit code (130, or 143 for SIGTERM).

Code that may be stopped this way says so by running inside :func:`scope`: the in-process study
loop (each render group; its rows are written under :func:`protected`, so every stored row is
whole) and the render commands' render. Outside a scope - a process pool being stopped, an
output file being written - the main thread's own handling is waited for, as before. Nothing
of this runs when :func:`svgs_sim.cli.main.main` is called in-process with an argument list (tests):
``os._exit`` would end the caller.

This module is the registry only (what may be stopped, and the write lock); the watchdog is the
CLI's (:mod:`svgs_sim.cli.signals`), which looks this module up only when a signal arrives, so a command
that never enters a scope (``svgs solve``) does not import :mod:`sim`.
"""

from __future__ import annotations

import contextlib
import threading
from typing import Callable

#: Seconds the main thread has, after the first Ctrl-C or SIGTERM, to stop on its own before the
#: watchdog stops the process (the acceptance bound is one second from the signal to the exit).
HARD_STOP_AFTER_S = 0.5

_write_lock = threading.RLock()
_scopes: list = []  # the active scopes' progress callables, innermost last
_scopes_lock = threading.Lock()


@contextlib.contextmanager
def protected():
    """Hold off a hard stop while the block runs (a row or file being written is written whole)."""
    with _write_lock:
        yield


@contextlib.contextmanager
def scope(progress: Callable[[], object] | None = None):
    """Let the watchdog stop the process while the block runs, if the main thread does not stop
    within :data:`HARD_STOP_AFTER_S` of a signal.

    Parameters
    ----------
    progress : callable, optional
        Called (in the watchdog thread, holding the write lock) when the process is stopped; returns
        what is kept, an object with a ``describe()`` sentence (a
        :class:`svgs_sim.studies.execution.StoredProgress`), or None.
    """
    entry = (progress,)
    with _scopes_lock:
        _scopes.append(entry)
    try:
        yield
    finally:
        with _scopes_lock:
            _scopes.remove(entry)


def active_progress():
    """``(progress,)`` of the innermost active :func:`scope` (its ``progress`` may be None), or
    None outside every scope."""
    with _scopes_lock:
        return _scopes[-1] if _scopes else None


def hold_writes() -> None:
    """Take the write lock for good (the watchdog, just before it ends the process): a row or file
    being written is finished first, and none starts after."""
    _write_lock.acquire()


def release_writes() -> None:
    """Give back the lock taken by :func:`hold_writes` (the command ended on its own meanwhile)."""
    _write_lock.release()


