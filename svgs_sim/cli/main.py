"""The ``svgs`` command line: one registry of every sub-command.

:data:`COMMANDS` lists each command module and the group it belongs to (``None`` for a
top-level command, ``"calibrate"`` or ``"tof"`` for ``svgs calibrate ...`` / ``svgs tof ...``).
A command module exposes ``register(subparsers)``, which adds its parsers to the sub-parsers
it is given, and imports nothing heavy at module level: the handlers import the renderer,
studies or calibration code when they run, so ``svgs solve`` on a photo loads only
:mod:`svgs` (checked by ``tests/test_architecture.py``).

Exit codes (:mod:`svgs_sim.cli.exit_codes`): 0 solved / done, 1 no solution or a simulated physical
failure (:class:`svgs_sim.base.errors.SimulationFailure`; the reason is printed), 2 bad input or usage,
3 output that could not be written (``io_error``: a full disk, a path the system refuses, a closed
stdout or a broken pipe; :mod:`svgs_sim.cli.stdout_guard`), 130 interrupted.

Errors: one line on stderr, ``svgs <command> [<subcommand>]: error: <message>`` - the prefix
names the command that was run (``svgs calibrate focal``), for argparse's usage errors as for
an :class:`~svgs_sim.base.errors.InputError`; ``svgs <command>: no solution (<reason>): <message>`` for a
simulated failure. With ``--json`` the same message also goes to stdout as exactly one JSON
object, ``{"ok": false, "error": "..."}`` (exit 2), or ``{"ok": false, "reason": "...",
"error": "..."}`` for a simulated failure (exit 1), ``{"ok": false, "signal": "SIGINT", "error":
"..."}`` for an interrupt (exit 130; 143 for SIGTERM; :func:`svgs_sim.cli.signals.report_interrupt`).
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import re
import sys

from svgs_sim.cli.examples import add_examples
from svgs_sim.cli.exit_codes import EXIT_BAD_INPUT, EXIT_INTERRUPTED, EXIT_IO_ERROR, EXIT_NO_SOLUTION
from svgs_sim.cli.signals import GROUP_DESTS, interruptible
from svgs_sim.cli.stdout_guard import GuardedStdout
from svgs_sim.base.errors import InputError, SimulationFailure

#: Command groups: name -> (help, description, dest, metavar).
GROUPS = {
    "calibrate": (
        "calibrate a camera: focal length from the target at known ranges, or full intrinsics from boards",
        "Camera calibration. 'focal': the paper's focal length from spot spacings at known ranges. 'board': "
        "full intrinsics and distortion from chessboard, ChArUco or circle-grid images. 'render-board': "
        "rendered calibration sets. 'study': how calibrations converge and what their errors cost.",
        "calibrate_command", "METHOD"),
    "tof": (
        "time-of-flight sensor (Zhu et al. 2022): pose from gray + depth frames",
        "Time-of-flight sensor commands (second seed, Zhu et al. 2022).",
        "tof_command", "TOF_COMMAND"),
    "sensor-model": (
        "the statistical sensor: its table from rendered frames, and its check against held-out frames",
        "The statistical sensor for closed-loop Monte Carlo (svgs_sim.sim.statistical_sensor): 'build' renders "
        "frames over range and off-axis angle and keeps each node's error bias, covariance and dropouts; 'validate' "
        "compares it with rendered frames that were not used to build it.",
        "sensor_model_command", "SENSOR_MODEL_COMMAND"),
}

#: Every command module, in help order: (group or None, module, the commands it adds).
COMMANDS = (
    (None, "svgs_sim.cli.solve", ("solve",)),
    (None, "svgs_sim.cli.render", ("render", "doctor")),
    (None, "svgs_sim.cli.sim", ("render-and-solve", "range-sweep")),
    (None, "svgs_sim.cli.exposure", ("exposure-study",)),
    ("calibrate", "svgs_sim.cli.calibrate", ("focal", "board")),
    ("calibrate", "svgs_sim.cli.calibrate_study", ("render-board", "study")),
    ("tof", "svgs_sim.cli.tof", ("solve",)),
    ("tof", "svgs_sim.cli.tof_render", ("render-and-solve",)),
    ("tof", "svgs_sim.cli.tof_stability", ("stability", "study")),
    (None, "svgs_sim.cli.studies", ("campaign", "sensitivity", "merge-range", "sun-study")),
    (None, "svgs_sim.cli.approach", ("approach",)),
    ("sensor-model", "svgs_sim.cli.sensor_model", ("build", "validate")),
)


def _selected(argv) -> set[str] | None:
    """The command modules needed to parse ``argv``, or None for all of them.

    ``svgs solve IMAGE ...`` needs only :mod:`svgs_sim.cli.solve`: a command module may import the
    library it drives while it builds its parser (a default, a list of choices), so building
    only the invoked command keeps ``svgs solve`` free of renderer, study and calibration code.
    ``svgs --help`` and anything unrecognised build every command."""
    words = [a for a in (argv or []) if not a.startswith("-")]
    if not words:
        return set() if "--version" in (argv or []) else None  # svgs --version needs no command
    first = words[0]
    mods = {m for g, m, names in COMMANDS if (g is None and first in names) or g == first}
    return mods or None


class UsageError(Exception):
    """An argparse usage error, raised (instead of exiting) by :class:`Parser` so that
    :func:`main` can report it with ``--json``; ``parser`` is the (sub)parser that failed."""

    def __init__(self, parser: argparse.ArgumentParser, message: str):
        super().__init__(message)
        self.parser = parser


class Parser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose usage errors raise :class:`UsageError` (its subparsers too)."""

    def error(self, message):
        raise UsageError(self, message)


def _version() -> str:
    """The installed distribution's version (``svgs_sim.__version__``)."""
    from svgs_sim import __version__

    return __version__


def build_parser(argv=None) -> argparse.ArgumentParser:
    """The ``svgs`` parser: every registered command, or only those that ``argv`` invokes."""
    parser = Parser(
        prog="svgs",
        description="Smartphone Video Guidance Sensor simulator: render, expose, detect, solve.",
    )
    parser.add_argument("--version", action="version", version=f"svgs-sim {_version()}",
                        help="print the installed svgs-sim version and exit")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    groups: dict[str, argparse._SubParsersAction] = {}
    selected = _selected(argv)
    for group, module, _names in COMMANDS:
        if selected is not None and module not in selected:
            continue
        target = sub
        if group is not None:
            if group not in groups:
                help_, description, dest, metavar = GROUPS[group]
                gp = sub.add_parser(group, help=help_, description=description)
                groups[group] = gp.add_subparsers(dest=dest, metavar=metavar)
                groups[group].required = True
            target = groups[group]
        importlib.import_module(module).register(target)
    add_examples(parser, iter_commands)  # every command's help ends with examples that work as written
    return parser


def iter_commands(parser: argparse.ArgumentParser, prefix: tuple = ()):
    """Every command's parser below ``parser``: ``(words, parser)`` pairs, e.g.
    ``(("calibrate", "focal"), <parser>)``, the groups included, depth first (for the tests and the
    docs that walk every option)."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield prefix + (name,), sub
                yield from iter_commands(sub, prefix + (name,))


#: A value that starts with a minus and a digit: a negative number or a list that starts with one
#: (``-20``, ``-30,10``, ``-0.5:2``).
_NEGATIVE_VALUE = re.compile(r"^-\.?\d[\w.,:+-]*$")


def join_negative_values(parser: argparse.ArgumentParser, argv: list) -> list:
    """``argv`` with ``--opt -30,10`` written ``--opt=-30,10`` where ``--opt`` takes a value.

    argparse reads a token that starts with ``-`` after a space as an option unless it is a single
    number, so a list option given a negative first item (``--sun-deg -30,10``, ``--attitude
    -5,0,0``) was refused with "expected one argument" (issue 41). Joining the pair with ``=`` is
    what the user meant, for every command and option alike.
    """
    takes_value = set()
    for p in [parser, *(q for _, q in iter_commands(parser))]:
        for a in p._actions:
            if a.option_strings and a.nargs != 0:
                takes_value.update(a.option_strings)
    out, i = [], 0
    while i < len(argv):
        tok = argv[i]
        if (tok in takes_value and tok.startswith("--") and i + 1 < len(argv)
                and _NEGATIVE_VALUE.match(str(argv[i + 1]))):
            out.append(f"{tok}={argv[i + 1]}")
            i += 2
            continue
        out.append(tok)
        i += 1
    return out


def leaf_parser(parser: argparse.ArgumentParser, args) -> argparse.ArgumentParser:
    """The (sub)parser of the command that ``args`` ran (``svgs calibrate focal``'s parser)."""
    p = parser
    for key in ("command", *GROUP_DESTS):
        name = getattr(args, key, None)
        if not name:
            continue
        sub = next((a for a in p._actions if isinstance(a, argparse._SubParsersAction)), None)
        if sub is None or name not in sub.choices:
            break
        p = sub.choices[name]
    return p


def report_error(prog: str, message: str, as_json: bool, reason: str | None = None) -> None:
    """One line on stderr, ``PROG: error: MESSAGE`` (bad input) or ``PROG: no solution (REASON):
    MESSAGE`` (a simulated failure); with ``as_json`` also one JSON object on stdout,
    ``{"ok": false, "error": MESSAGE}`` (plus ``"reason"`` for a simulated failure)."""
    line = " ".join(str(message).split())  # one line, whatever the message held
    head = "error" if reason is None else "error (io_error)" if reason == "io_error" else f"no solution ({reason})"
    print(f"{prog}: {head}: {line}", file=sys.stderr, flush=True)
    if as_json:
        obj = {"ok": False, **({"reason": reason} if reason is not None else {}), "error": line}
        print(json.dumps(obj), file=sys.stdout, flush=True)


def _parse(parser: argparse.ArgumentParser, argv: list):
    """``parser.parse_args(argv)``, but an unrecognised argument is reported by the sub-command's parser."""
    args, extra = parser.parse_known_args(argv)
    if extra:
        leaf_parser(parser, args).error(f"unrecognized arguments: {' '.join(extra)}")
    return args


def main(argv=None) -> int:
    """Run the CLI; returns the exit code.

    Parameters
    ----------
    argv : list of str, optional
        The arguments. None: ``sys.argv[1:]``, and the call is the program itself (the ``svgs``
        script, ``python -m svgs_sim.cli.main``), so an interrupt may end the process from a watchdog
        thread (:mod:`svgs_sim.sim.hard_stop`); with a list (tests, in-process callers) it never does.
    """
    as_program = argv is None
    argv = sys.argv[1:] if argv is None else list(argv)
    if as_program:  # a path or text the locale cannot encode is escaped, never a UnicodeEncodeError
        for stream in (sys.stdout, sys.stderr):
            if stream is not None and hasattr(stream, "reconfigure"):
                stream.reconfigure(errors="backslashreplace")
    parser = build_parser(argv)
    argv = join_negative_values(parser, argv)
    try:
        args = _parse(parser, argv)
    except UsageError as exc:  # usage errors: exit 2, named by the sub-command's parser
        exc.parser.print_usage(sys.stderr)
        report_error(exc.parser.prog, str(exc), "--json" in argv)
        return EXIT_BAD_INPUT
    except SystemExit as exc:  # --help, --version: exit 0
        return int(exc.code or 0)
    prog = leaf_parser(parser, args).prog  # "svgs calibrate focal"
    as_json = bool(getattr(args, "json", False))
    real_stdout, guard = sys.stdout, GuardedStdout(sys.stdout)
    sys.stdout = guard  # a reader that went away does not stop the command half-way (exit 3 at the end)
    try:
        code = _run(args, parser, prog, as_json, as_program, argv)
    finally:
        sys.stdout = real_stdout
    if guard.broken:
        _stdout_lost(prog, as_program, guard.error)
        return EXIT_IO_ERROR
    return code


def _stdout_lost(prog: str, as_program: bool, error: OSError | None) -> None:
    """One line on stderr: the output that was to be printed is lost (the files are written)."""
    why = ("stdout is closed" if error is None else
           f"stdout could not be written ({error.strerror or error}; a reader that went away, a full disk)")
    print(f"{prog}: error (io_error): {why}, so what was to be printed is lost; the files the command writes "
          "are complete", file=sys.stderr, flush=True)
    if as_program and sys.stdout is not None:
        try:  # the interpreter's last flush must not fail on the dead pipe
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        except (OSError, ValueError):
            pass


def named_by_option(parser: argparse.ArgumentParser, message: str, argv=None) -> str:
    """``message`` with a leading API name (``misalignment_deg: ...``, the Python API's word for an
    argument) replaced by the command's option that sets it (``--misalignment-deg: ...``) when the
    user gave that option (``argv``; None: any): a user of the CLI is told the option they typed,
    not an internal key (issue 41). A value the command derived itself (a focal error from the
    rendered calibration) keeps its own name."""
    head, sep, rest = message.partition(": ")
    if not sep or not head.isidentifier():
        return message
    for a in parser._actions:
        if a.dest == head and a.option_strings:
            typed = argv is None or any(t == f or t.startswith(f + "=") for t in argv for f in a.option_strings)
            return f"{max(a.option_strings, key=len)}: {rest}" if typed else message
    return message


def io_error_message(exc: OSError) -> str:
    """One line for an output that could not be written: the path, the system's reason, what is kept."""
    path = exc.filename if exc.filename is not None else None
    what = exc.strerror or str(exc)
    shown = os.fsdecode(path) if path is not None else ""
    if len(shown) > 120:  # one readable line, whatever the path's length
        shown = f"{shown[:40]}...{shown[-60:]} ({len(shown)} characters)"
    where = f" {shown!r}" if path is not None else ""
    return (f"the file system refused{where}: {what} [errno {exc.errno}]; what was written before is kept (a "
            "study resumes from its stored trials when rerun with the same command)")


def _run(args, parser, prog: str, as_json: bool, as_program: bool, argv: list) -> int:
    try:
        from svgs_sim.cli.validate import check_args

        check_args(args, parser)  # every argument checked before any work (exit 2)
        if args.command != "doctor":
            from svgs_sim.cli.compile_kernels import kernels_cached

            if not kernels_cached():  # a fresh install that skipped `make`: say why the first call waits
                print("compiling the solver and camera kernels (first run only, ~20 s; cached for later runs) ...",
                      file=sys.stderr, flush=True)
        # Ctrl-C and SIGTERM: one line, exit 130 / 143 (svgs_sim.cli.signals); run as the program, within a
        # second even inside a render (a watchdog that may end the process: never in-process)
        args.func = interruptible(args, hard_stop=as_program)
        return int(args.func(args))
    except InputError as exc:
        report_error(prog, named_by_option(leaf_parser(parser, args), str(exc), argv), as_json)
        return EXIT_BAD_INPUT
    except SimulationFailure as exc:  # valid input, the simulated physics measured nothing: no solution
        report_error(prog, str(exc), as_json, reason=exc.reason)
        return EXIT_NO_SOLUTION
    except KeyboardInterrupt as exc:  # before the command's handler started
        from svgs_sim.cli.signals import report_interrupt

        report_interrupt(prog.removeprefix("svgs "), exc, as_json)
        return EXIT_INTERRUPTED
    except OSError as exc:  # the output could not be written: disk full, a path the system refuses, ...
        report_error(prog, io_error_message(exc), as_json, reason="io_error")
        return EXIT_IO_ERROR


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
