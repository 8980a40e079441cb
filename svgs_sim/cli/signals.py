"""Ctrl-C and SIGTERM: a command stops at once, keeps what it finished and says so in one line.

:func:`interruptible` wraps a command's handler (``args.func``). While the handler runs,
SIGTERM raises :class:`Terminated` in the main thread, as Ctrl-C (SIGINT) raises
``KeyboardInterrupt``; both unwind the command as an exception does, so the study loop
(:func:`svgs_sim.studies.execution.run_study`) stores every finished row, closes its store and stops
its workers before the process exits. The wrapper then prints one line on stderr - what was
stopped and, for a study, how many of its trials are stored and that rerunning the same
command resumes - and returns the exit code: 130 after Ctrl-C (``EXIT_INTERRUPTED``), 143
(128 + SIGTERM, as a shell reports a process ended by it) after SIGTERM.

With ``--json`` the interrupt is also one JSON object on stdout (:func:`report_interrupt`). Run
as the program, a watchdog thread stops the process within a second even while the main thread
is inside a render (:func:`watchdog`; what may be stopped so is registered in :mod:`svgs_sim.sim.hard_stop`).

A SIGTERM that the caller set to be ignored stays ignored, and the previous handler is put
back when the command returns (``main`` is also called in-process, by tests).
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import socket
import sys
import threading
import time

from svgs_sim.base.errors import interrupt_in
from svgs_sim.cli.exit_codes import EXIT_INTERRUPTED

#: Exit code after SIGTERM: 128 + the signal number, as a shell reports it.
EXIT_TERMINATED = 128 + int(signal.SIGTERM)


class Terminated(KeyboardInterrupt):
    """The process received SIGTERM (raised in the main thread by :func:`interruptible`'s handler).

    A ``KeyboardInterrupt`` subclass, so every ``except Exception`` lets it through and every
    clean-up written for Ctrl-C runs for it too.
    """


def _raise_terminated(signum, frame):
    raise Terminated()


#: The argparse ``dest`` of each command group's second word (:data:`svgs_sim.cli.main.GROUPS`).
GROUP_DESTS = ("calibrate_command", "tof_command", "sensor_model_command")


def command_name(args) -> str:
    """The command as typed: ``campaign``, ``calibrate study``, ``tof solve``."""
    words = [getattr(args, "command", None), *(getattr(args, k, None) for k in GROUP_DESTS)]
    return " ".join(w for w in words if w) or "svgs"


def interrupted_line(name: str, exc: KeyboardInterrupt) -> str:
    """The one line printed when command ``name`` is stopped by ``exc``.

    Parameters
    ----------
    name : str
        The command (:func:`command_name`).
    exc : KeyboardInterrupt
        The interrupt; a :class:`Terminated` for SIGTERM. A study's interrupt carries what its
        store holds (``svgs_stored``: :class:`svgs_sim.studies.execution.StoredProgress`).
    """
    what = "terminated (SIGTERM)" if isinstance(exc, Terminated) else "interrupted"
    stored = getattr(exc, "svgs_stored", None)
    return f"svgs {name}: {what}" + (f"; {stored.describe()}" if stored is not None else "")


def report_interrupt(name: str, exc: KeyboardInterrupt, as_json: bool = False) -> None:
    """Print the one line of an interrupted command on stderr; with ``as_json`` also one JSON
    object on stdout, ``{"ok": false, "signal": "SIGINT", "error": LINE}`` plus, for a study,
    ``"stored"``, ``"trials"`` and ``"out"`` (what its store holds)."""
    line = interrupted_line(name, exc)
    print(line, file=sys.stderr, flush=True)
    if as_json:
        obj = {"ok": False, "signal": "SIGTERM" if isinstance(exc, Terminated) else "SIGINT", "error": line}
        stored = getattr(exc, "svgs_stored", None)
        if stored is not None:
            obj.update(stored=stored.n_stored, trials=stored.n_trials, out=stored.out_dir)
        print(json.dumps(obj), file=sys.stdout, flush=True)


# --------------------------------------------------------------------------- the watchdog
#: Signals the watchdog acts on.
STOP_SIGNALS = (int(signal.SIGINT), int(signal.SIGTERM))
#: The registry of stoppable parts (:mod:`svgs_sim.sim.hard_stop`); looked up only when a signal arrives.
HARD_STOP_MODULE = "svgs_sim.sim.hard_stop"


def exit_code(signum: int) -> int:
    """130 after Ctrl-C, 128 + the signal number otherwise (143 for SIGTERM), as a shell reports it."""
    return EXIT_INTERRUPTED if signum == int(signal.SIGINT) else 128 + int(signum)


class _Watchdog(threading.Thread):
    """Reads the signal numbers the C-level handler writes into ``sock`` (see :func:`watchdog`)."""

    def __init__(self, sock: socket.socket, announce):
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
        """Give the main thread its time; end the process if the command is still in a stoppable part."""
        hs = sys.modules.get(HARD_STOP_MODULE)
        if hs is None:  # never imported: no stoppable part has run
            return
        deadline = time.monotonic() + hs.HARD_STOP_AFTER_S
        while time.monotonic() < deadline:
            if self.finished.wait(0.02):
                return
        entry = hs.active_progress()
        if entry is None or self.finished.is_set():
            return  # the main thread is stopping on its own (or outside a stoppable part): let it
        hs.hold_writes()  # a row or file being written is finished first; never given back below
        if self.finished.is_set():
            hs.release_writes()
            return
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
def watchdog(announce):
    """Run the block with the hard-stop watchdog (main thread only; elsewhere a no-op).

    The C-level signal handler writes each signal's number into a socket
    (``signal.set_wakeup_fd``) even while the main thread is inside native code; a daemon thread
    reads it. After Ctrl-C or SIGTERM it waits :data:`svgs_sim.sim.hard_stop.HARD_STOP_AFTER_S`; if the
    command is then still inside a :func:`svgs_sim.sim.hard_stop.scope` it takes the write lock, calls
    ``announce`` and ends the process with :func:`exit_code`.

    Parameters
    ----------
    announce : callable
        ``announce(signum, kept)`` prints the command's interrupt line; ``kept`` is what the
        scope's ``progress`` returned (or None).
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
            writer.send(b"\0")  # wake the reader so that it ends
        except OSError:
            pass
        dog.join(1.0)
        reader.close()
        writer.close()


def interruptible(args, *, hard_stop: bool = False):
    """``args.func`` wrapped: SIGTERM handled like Ctrl-C while it runs, one line and the exit
    code (130 or 143) when either stops it.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed command line, with the handler ``func`` (and ``json``, if the command has it).
    hard_stop : bool
        The command runs as the program (not called in-process): a watchdog
        (:func:`watchdog`) ends the process within a second of the signal when
        the main thread is stuck in native code inside a stoppable part (a render, an in-process
        study's render group), after printing the same line.

    Returns
    -------
    callable
        Takes ``args`` like ``args.func`` and returns its exit code.
    """
    func, name = args.func, command_name(args)
    as_json = bool(getattr(args, "json", False))

    def announce(signum: int, kept) -> None:
        exc = Terminated() if signum == int(signal.SIGTERM) else KeyboardInterrupt()
        if kept is not None:
            exc.svgs_stored = kept
        if sys.stderr.isatty():
            print(file=sys.stderr)  # past a progress bar's line
        report_interrupt(name, exc, as_json)

    def run(a) -> int:
        previous = None
        if threading.current_thread() is threading.main_thread():
            previous = signal.getsignal(signal.SIGTERM)
            if previous == signal.SIG_IGN:
                previous = None  # the caller wants SIGTERM ignored: leave it so
            else:
                signal.signal(signal.SIGTERM, _raise_terminated)
        try:
            with watchdog(announce) if hard_stop else contextlib.nullcontext():
                return func(a)
        except KeyboardInterrupt as exc:  # Ctrl-C or Terminated: the command has unwound, its rows are kept
            report_interrupt(name, exc, as_json)
            return EXIT_TERMINATED if isinstance(exc, Terminated) else EXIT_INTERRUPTED
        except Exception as exc:  # a native library (Dr.Jit's custom ops) that wrapped the interrupt in its error
            interrupt = interrupt_in(exc)
            if interrupt is None:
                raise
            report_interrupt(name, interrupt, as_json)
            return EXIT_TERMINATED if isinstance(interrupt, Terminated) else EXIT_INTERRUPTED
        finally:
            if previous is not None:
                signal.signal(signal.SIGTERM, previous)

    return run
