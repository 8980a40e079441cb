"""Stop within a second of Ctrl-C even when the main thread is inside native code (a render).

Python runs a signal handler only between bytecodes of the main thread. A Mitsuba render or a
Dr.Jit evaluation is one long native call that releases the GIL but returns only when done
(seconds to minutes), so Ctrl-C would wait for it. The CLI therefore runs a *watchdog* thread
while a command runs as the program (:func:`watchdog`): the C-level signal handler writes the
signal's number into a socket (``signal.set_wakeup_fd``) even while the main thread is busy, the
watchdog reads it, gives the main thread :data:`HARD_STOP_AFTER_S` to stop on its own, and if
the command is still inside a :func:`scope` by then it stops the process itself:

1. it takes the write lock (:func:`protected`), so no row or file is half written;
2. it prints the command's one interrupt line (what the scope says is stored, and that a rerun
   resumes);
3. it ends the process with ``os._exit`` and the interrupt's exit code (130, or 143 for SIGTERM).

Code that may be stopped this way says so by running inside :func:`scope`: the in-process study
loop (each render group; its rows are written under :func:`protected`, so every stored row is
whole) and the render commands' render. Outside a scope - a process pool being stopped, an
output file being written - the main thread's own handling is waited for, as before. Nothing
of this runs when :func:`cli.main.main` is called in-process with an argument list (tests):
``os._exit`` would end the caller.
"""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import sys
import threading
import time
from typing import Callable

#: Seconds the main thread has, after the first Ctrl-C or SIGTERM, to stop on its own before the
#: watchdog stops the process (the acceptance bound is one second from the signal to the exit).
HARD_STOP_AFTER_S = 0.5
#: Signals the watchdog acts on.
STOP_SIGNALS = (int(signal.SIGINT), int(signal.SIGTERM))

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
        :class:`studies.execution.StoredProgress`), or None.
    """
    entry = (progress,)
    with _scopes_lock:
        _scopes.append(entry)
    try:
        yield
    finally:
        with _scopes_lock:
            _scopes.remove(entry)


def _active_scope():
    with _scopes_lock:
        return _scopes[-1] if _scopes else None


def exit_code(signum: int) -> int:
    """130 after Ctrl-C, 128 + the signal number otherwise (143 for SIGTERM), as a shell reports it."""
    return 130 if signum == int(signal.SIGINT) else 128 + int(signum)


class _Watchdog(threading.Thread):
    def __init__(self, sock: socket.socket, announce: Callable[[int, object], None]):
        super().__init__(name="svgs-hard-stop", daemon=True)
        self.sock, self.announce = sock, announce
        self.finished = threading.Event()

    def run(self) -> None:
        while not self.finished.is_set():
            try:
                data = self.sock.recv(64)
            except OSError:
                return
            if not data or self.finished.is_set():
                return
            signums = [b for b in data if b in STOP_SIGNALS]
            if signums:
                self._stop_if_stuck(signums[0])

    def _stop_if_stuck(self, signum: int) -> None:
        """Wait :data:`HARD_STOP_AFTER_S`; stop the process if the command is still in a scope."""
        deadline = time.monotonic() + HARD_STOP_AFTER_S
        while time.monotonic() < deadline:
            if self.finished.wait(0.02):
                return
        entry = _active_scope()
        if entry is None or self.finished.is_set():
            return  # the main thread is stopping on its own (or outside a scope): let it
        _write_lock.acquire()  # never released: the process ends below
        if self.finished.is_set():
            _write_lock.release()
            return
        kept = None
        try:
            kept = entry[0]() if entry[0] is not None else None
        except Exception:  # noqa: BLE001 - the count is a courtesy; the stop must happen
            kept = None
        try:
            self.announce(signum, kept)
            sys.stderr.flush()
            sys.stdout.flush()
        finally:
            os._exit(exit_code(signum))


@contextlib.contextmanager
def watchdog(announce: Callable[[int, object], None]):
    """Run the block with the watchdog (main thread only; elsewhere a no-op).

    Parameters
    ----------
    announce : callable
        ``announce(signum, kept)`` prints the command's interrupt line before the process ends;
        ``kept`` is what the scope's ``progress`` returned (or None).
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    reader, writer = socket.socketpair()
    writer.setblocking(False)
    try:
        previous = signal.set_wakeup_fd(writer.fileno(), warn_on_full_buffer=False)
    except (ValueError, OSError):  # not allowed here: the main thread's own handling only
        reader.close()
        writer.close()
        yield
        return
    dog = _Watchdog(reader, announce)
    dog.start()
    try:
        yield
    finally:
        dog.finished.set()
        signal.set_wakeup_fd(previous)
        try:
            writer.send(b"\0")  # wake the reader so it ends
        except OSError:
            pass
        dog.join(1.0)
        reader.close()
        writer.close()
