"""The ``svgs`` command line: one registry of every sub-command.

:data:`COMMANDS` lists each command module and the group it belongs to (``None`` for a
top-level command, ``"calibrate"`` or ``"tof"`` for ``svgs calibrate ...`` / ``svgs tof ...``).
A command module exposes ``register(subparsers)``, which adds its parsers to the sub-parsers
it is given, and imports nothing heavy at module level: the handlers import the renderer,
studies or calibration code when they run, so ``svgs solve`` on a photo loads only
:mod:`svgs` (checked by ``tests/test_architecture.py``).

Exit codes (:mod:`cli.exit_codes`): 0 solved / done, 1 no solution (the reason is printed),
2 bad input or usage, 130 interrupted.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from cli.exit_codes import EXIT_BAD_INPUT, EXIT_INTERRUPTED
from cli.signals import interruptible
from svgs.errors import InputError

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
}

#: Every command module, in help order: (group or None, module, the commands it adds).
COMMANDS = (
    (None, "cli.solve", ("solve",)),
    (None, "cli.render", ("render", "doctor")),
    (None, "cli.sim", ("render-and-solve", "range-sweep")),
    (None, "cli.exposure", ("exposure-study",)),
    ("calibrate", "cli.calibrate", ("focal", "board")),
    ("calibrate", "cli.calibrate_study", ("render-board", "study")),
    ("tof", "cli.tof", ("solve",)),
    ("tof", "cli.tof_render", ("render-and-solve",)),
    ("tof", "cli.tof_stability", ("stability", "study")),
    (None, "cli.studies", ("campaign", "sensitivity")),
    (None, "cli.approach", ("approach",)),
)


def _selected(argv) -> set[str] | None:
    """The command modules needed to parse ``argv``, or None for all of them.

    ``svgs solve IMAGE ...`` needs only :mod:`cli.solve`: a command module may import the
    library it drives while it builds its parser (a default, a list of choices), so building
    only the invoked command keeps ``svgs solve`` free of renderer, study and calibration code.
    ``svgs --help`` and anything unrecognised build every command."""
    words = [a for a in (argv or []) if not a.startswith("-")]
    if not words:
        return None
    first = words[0]
    mods = {m for g, m, names in COMMANDS if (g is None and first in names) or g == first}
    return mods or None


def build_parser(argv=None) -> argparse.ArgumentParser:
    """The ``svgs`` parser: every registered command, or only those that ``argv`` invokes."""
    parser = argparse.ArgumentParser(
        prog="svgs",
        description="Smartphone Video Guidance Sensor simulator: render, expose, detect, solve.",
    )
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
    return parser


def main(argv=None) -> int:
    """Run the CLI; returns the exit code (also used by tests in-process)."""
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(argv)
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse: usage errors exit 2, --help exits 0
        return int(exc.code or 0)
    try:
        from cli.validate import check_args

        check_args(args, parser)  # every argument checked before any work (exit 2)
        if args.command != "doctor":
            from cli.compile_kernels import kernels_cached

            if not kernels_cached():  # a fresh install that skipped `make`: say why the first call waits
                print("compiling the solver and camera kernels (first run only, ~20 s; cached for later runs) ...",
                      file=sys.stderr, flush=True)
        args.func = interruptible(args)  # Ctrl-C and SIGTERM: one line, exit 130 / 143 (cli.signals)
        return int(args.func(args))
    except InputError as exc:
        print(f"svgs {args.command}: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print(f"svgs {args.command}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:  # output piped into a program that stopped reading (e.g. head)
        sys.stderr.close()
        return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
