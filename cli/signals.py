"""Ctrl-C and SIGTERM: a command stops at once, keeps what it finished and says so in one line.

:func:`interruptible` wraps a command's handler (``args.func``). While the handler runs,
SIGTERM raises :class:`Terminated` in the main thread, as Ctrl-C (SIGINT) raises
``KeyboardInterrupt``; both unwind the command as an exception does, so the study loop
(:func:`studies.execution.run_study`) stores every finished row, closes its store and stops
its workers before the process exits. The wrapper then prints one line on stderr - what was
stopped and, for a study, how many of its trials are stored and that rerunning the same
command resumes - and returns the exit code: 130 after Ctrl-C (``EXIT_INTERRUPTED``), 143
(128 + SIGTERM, as a shell reports a process ended by it) after SIGTERM.

A SIGTERM that the caller set to be ignored stays ignored, and the previous handler is put
back when the command returns (``main`` is also called in-process, by tests).
"""

from __future__ import annotations

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


def interruptible(args):
    """``args.func`` wrapped: SIGTERM handled like Ctrl-C while it runs, one line and the exit
    code (130 or 143) when either stops it.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed command line, with the handler ``func``.

    Returns
    -------
    callable
        Takes ``args`` like ``args.func`` and returns its exit code.
    """
    func, name = args.func, command_name(args)

    def run(a) -> int:
        previous = None
        if threading.current_thread() is threading.main_thread():
            previous = signal.getsignal(signal.SIGTERM)
            if previous == signal.SIG_IGN:
                previous = None  # the caller wants SIGTERM ignored: leave it so
            else:
                signal.signal(signal.SIGTERM, _raise_terminated)
        try:
            return func(a)
        except KeyboardInterrupt as exc:  # Ctrl-C or Terminated: the command has unwound, its rows are kept
            print(interrupted_line(name, exc), file=sys.stderr, flush=True)
            return EXIT_TERMINATED if isinstance(exc, Terminated) else EXIT_INTERRUPTED
        finally:
            if previous is not None:
                signal.signal(signal.SIGTERM, previous)

    return run
