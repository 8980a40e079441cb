"""Ctrl-C and SIGTERM: a command stops at once, keeps what it finished and says so in one line.

:func:`interruptible` wraps a command's handler (``args.func``). While the handler runs,
SIGTERM raises :class:`Terminated` in the main thread, as Ctrl-C (SIGINT) raises
``KeyboardInterrupt``; both unwind the command as an exception does, so the study loop
(:func:`studies.execution.run_study`) stores every finished row, closes its store and stops
its workers before the process exits. The wrapper then prints one line on stderr - what was
stopped and, for a study, how many of its trials are stored and that rerunning the same
command resumes - and returns the exit code: 130 after Ctrl-C (``EXIT_INTERRUPTED``), 143
(128 + SIGTERM, as a shell reports a process ended by it) after SIGTERM.

With ``--json`` the interrupt is also one JSON object on stdout (:func:`report_interrupt`). Run
as the program, a watchdog thread stops the process within a second even while the main thread
is inside a render (:mod:`sim.hard_stop`).

A SIGTERM that the caller set to be ignored stays ignored, and the previous handler is put
back when the command returns (``main`` is also called in-process, by tests).
"""

from __future__ import annotations

import contextlib
import json
import signal
import sys
import threading

from cli.exit_codes import EXIT_INTERRUPTED

#: Exit code after SIGTERM: 128 + the signal number, as a shell reports it.
EXIT_TERMINATED = 128 + int(signal.SIGTERM)


class Terminated(KeyboardInterrupt):
    """The process received SIGTERM (raised in the main thread by :func:`interruptible`'s handler).

    A ``KeyboardInterrupt`` subclass, so every ``except Exception`` lets it through and every
    clean-up written for Ctrl-C runs for it too.
    """


def _raise_terminated(signum, frame):
    raise Terminated()


def command_name(args) -> str:
    """The command as typed: ``campaign``, ``calibrate study``, ``tof solve``."""
    words = [getattr(args, "command", None), getattr(args, "calibrate_command", None),
             getattr(args, "tof_command", None)]
    return " ".join(w for w in words if w) or "svgs"


def interrupted_line(name: str, exc: KeyboardInterrupt) -> str:
    """The one line printed when command ``name`` is stopped by ``exc``.

    Parameters
    ----------
    name : str
        The command (:func:`command_name`).
    exc : KeyboardInterrupt
        The interrupt; a :class:`Terminated` for SIGTERM. A study's interrupt carries what its
        store holds (``svgs_stored``: :class:`studies.execution.StoredProgress`).
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


def interruptible(args, *, hard_stop: bool = False):
    """``args.func`` wrapped: SIGTERM handled like Ctrl-C while it runs, one line and the exit
    code (130 or 143) when either stops it.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed command line, with the handler ``func`` (and ``json``, if the command has it).
    hard_stop : bool
        The command runs as the program (not called in-process): a watchdog
        (:func:`sim.hard_stop.watchdog`) ends the process within a second of the signal when
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
        from sim import hard_stop as hs

        previous = None
        if threading.current_thread() is threading.main_thread():
            previous = signal.getsignal(signal.SIGTERM)
            if previous == signal.SIG_IGN:
                previous = None  # the caller wants SIGTERM ignored: leave it so
            else:
                signal.signal(signal.SIGTERM, _raise_terminated)
        try:
            with hs.watchdog(announce) if hard_stop else contextlib.nullcontext():
                return func(a)
        except KeyboardInterrupt as exc:  # Ctrl-C or Terminated: the command has unwound, its rows are kept
            report_interrupt(name, exc, as_json)
            return EXIT_TERMINATED if isinstance(exc, Terminated) else EXIT_INTERRUPTED
        finally:
            if previous is not None:
                signal.signal(signal.SIGTERM, previous)

    return run
