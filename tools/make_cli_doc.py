"""Write docs/cli.md from the argparse help of every ``svgs`` command (keeps docs and code in step).

Run: ``.venv/bin/python tools/make_cli_doc.py`` (a test checks the file is current).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from svgs_sim.cli.json_out import SCHEMAS  # noqa: E402
from svgs_sim.cli.main import build_parser  # noqa: E402

DOC = Path(__file__).resolve().parents[1] / "docs" / "cli.md"


def _walk(parser: argparse.ArgumentParser, prefix: str):
    yield prefix, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _walk(sub, f"{prefix} {name}")


def render() -> str:
    import os

    old = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = "100"  # argparse wraps to $COLUMNS: fix it so the file is stable
    try:
        return _render()
    finally:
        if old is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = old


def _render() -> str:
    parser = build_parser()
    parser.prog = "svgs"
    out = ["# Command reference", "",
           "Generated from the commands' own help by `tools/make_cli_doc.py`; do not edit by hand.", "",
           "Exit codes everywhere (`svgs_sim/cli/exit_codes.py`):", "",
           "| code | meaning | `--json` |", "|---|---|---|",
           "| 0 | done / solved | the command's object |",
           "| 1 | no solution, or a simulated physical failure (the simulated sensor measured nothing, e.g. every "
           "pixel saturated; the reason is printed) | `{\"ok\": false, \"reason\": REASON, \"error\": ...}` |",
           "| 2 | bad input or usage: one line naming the input, before any work | `{\"ok\": false, \"error\": ...}` |",
           "| 3 | output that could not be written: a full disk, a path the system refuses, a closed stdout, a broken "
           "pipe (a command piped into `head`); the files written before are kept, and a command whose stdout was lost still "
           "writes its files | `{\"ok\": false, \"reason\": \"io_error\", \"error\": ...}` |",
           "| 130 / 143 | interrupted (SIGINT / SIGTERM); a study resumes when rerun | `{\"ok\": false, \"signal\": ...}` |",
           "",
           ("An error is one line on stderr that names the command: `svgs calibrate focal: error: ...` (exit 2), "
            "`svgs tof stability: no solution (saturated): ...` (exit 1), `svgs solve: error (io_error): ...` "
            "(exit 3)."), "",
           ("Every argument is checked before any work starts (`svgs_sim/cli/validate.py`): output locations (a writable "
            "folder, or a file where the metavar says `.toml`), seeds (0 to 2^32 - 1), counts (>= 1; samples per "
            "pixel at most 2^24), finite numbers, physical quantities within physical bounds (`svgs_sim/base/limits.py`, "
            "the table the study parameters of `sensitivity --vary`/`--fixed` take too), ranges (positive, distinct, inside the sensor's "
            "physical envelope: for a phone, closer than where the pattern spans fewer than 4 px; for the ToF "
            "camera 0.27-15 m) and the kind of camera profile. A bad input exits 2 with one line naming it and "
            "writes nothing."), "",
           ("`--json`: every command that takes it prints exactly one JSON object on stdout (tables, status lines "
           "and progress bars go to stderr). Its object is shown after the command's help (`svgs_sim/cli/json_out.py`); "
           "the study commands (range-sweep, exposure-study, campaign, sensitivity, calibrate study) write NaN as "
           "`null` and also write the object to their folder's `summary.json`. A refused run (exit 2) prints "
           "`{\"ok\": false, \"error\": \"...\"}` instead, a simulated physical failure (exit 1) "
           "`{\"ok\": false, \"reason\": \"...\", \"error\": \"...\"}`, an interrupted one (Ctrl-C: exit 130, "
           "SIGTERM: exit 143) `{\"ok\": false, \"signal\": \"SIGINT\", \"error\": \"...\"}` with, for a study, "
           "`\"stored\"`, `\"trials\"` and `\"out\"` (what its store holds); the message is also on stderr."), "",
           ("`--plan-only` (the studies): the run's checks (the arguments, the executor, an output folder that holds "
            "files no study made) and the plan on stderr, nothing run; with `--json` the plan on stdout as "
            "`{\"ok\": true, \"plan_only\": true, \"plan\": {\"kind\", \"trials\", \"renders\", \"core_s\", "
            "\"wall_s\", \"parallel\", \"executor\", \"note\", \"warnings\"}}`. A study never writes over files "
            "it did not make: an `--out` folder holding a report, a summary or results but no study's "
            "`manifest.json` is refused (exit 2)."), ""]
    for name, p in _walk(parser, "svgs"):
        out += [f"## `{name}`", "", "```", p.format_help().rstrip(), "```", ""]
        if name in SCHEMAS:
            out += ["JSON output (`--json`): one object on stdout"
                    + (", also written to the output folder's `summary.json`" if "summary_json" in SCHEMAS[name]
                       or "calibrate study" in name else "") + ":", "",
                    "```", SCHEMAS[name].rstrip(), "```", ""]
    missing = sorted(set(SCHEMAS) - {name for name, _ in _walk(parser, "svgs")})
    if missing:
        raise SystemExit(f"svgs_sim.cli.json_out.SCHEMAS names unknown commands: {missing}")
    return "\n".join(out)


if __name__ == "__main__":
    DOC.write_text(render())
    print(f"wrote {DOC}")
