"""Examples in every command's help (its epilog) and so in docs/cli.md: each a command line that
works as written (``tests/test_cli_examples.py`` parses every one with the command's parser), and
what it does, and how a negative number is given (:data:`NEGATIVE_NOTE`; the CLI joins ``--opt -1,0``
into ``--opt=-1,0``, :func:`svgs_sim.cli.main.join_negative_values`)."""

from __future__ import annotations

import argparse
import textwrap

#: Command words -> ``(command line, what it does)``.
EXAMPLES = {
    ("solve",): [
        ("svgs solve photo.png --camera galaxy-nexus --out solved --json",
         "the pose from a photo, as JSON; solved/overlay.png shows the blobs and the targets"),
        ("svgs solve photo.png --camera my-phone.toml --threshold 180",
         "a phone of your own (svgs calibrate board makes its profile) and the app's threshold set"),
    ],
    ("render",): [
        ("svgs render --camera galaxy-nexus --range 10 --out frame", "the flux, the image and the truth at 10 m"),
        ("svgs render --camera htc-amaze-4g --range 5 --environment orbit --sun-deg 30,10 --body 3u --out orbit",
         "on orbit: black space, the sun at azimuth 30 deg and elevation 10 deg, a 3U body"),
    ],
    ("doctor",): [("svgs doctor", "what is installed, the Mitsuba variant, LLVM, the libraries' versions")],
    ("render-and-solve",): [
        ("svgs render-and-solve --camera galaxy-nexus --range 10 --out first", "render, expose, detect and solve once"),
        ("svgs render-and-solve --camera htc-amaze-4g --range 4 --roll 10 --yaw -20 --json",
         "a turned target, the result as JSON"),
    ],
    ("range-sweep",): [
        ("svgs range-sweep --camera htc-amaze-4g --ranges 2,4,6,8 --out sweep", "blobs, success and errors per range"),
        ("svgs range-sweep --camera galaxy-nexus --ranges 5,10,20,30,40 --out sweep --plan-only",
         "what it would run and how long it would take, nothing run"),
    ],
    ("exposure-study",): [
        ("svgs exposure-study --camera htc-amaze-4g --ranges 4,6,8 --out exposure",
         "the paper's remedies for the merge against range"),
    ],
    ("calibrate", "focal"): [
        ("svgs calibrate focal --camera galaxy-nexus --image a.png --range 5 --image b.png --range 10 --out nexus.toml",
         "the paper's focal-length calibration from the target at known ranges"),
    ],
    ("calibrate", "board"): [
        ("svgs calibrate board views/*.png --board chessboard --cols 9 --rows 6 --spacing-mm 25 --out phone.toml",
         "full intrinsics and distortion from chessboard photos; an unreadable view is listed and skipped"),
    ],
    ("calibrate", "render-board"): [
        ("svgs calibrate render-board --camera galaxy-nexus --board chessboard --cols 9 --rows 6 --spacing-mm 25 "
         "--views 12 --out boards", "rendered calibration views with their truth"),
    ],
    ("calibrate", "study"): [
        ("svgs calibrate study --camera galaxy-nexus --out calstudy --plan-only",
         "how calibrations converge and what their errors cost: the plan first"),
    ],
    ("tof", "solve"): [
        ("svgs tof solve --gray gray.npy --depth depth.npy --json", "the ToF sensor's pose from a gray and a depth image"),
    ],
    ("tof", "render-and-solve"): [
        ("svgs tof render-and-solve --range 0.697 --json", "one rendered ToF frame at the paper's near range, solved"),
    ],
    ("tof", "stability"): [
        ("svgs tof stability --range 5.712 --frames 200 --json", "the paper's stability run at 5712 mm (Table 2)"),
    ],
    ("tof", "study"): [
        ("svgs tof study --out docs/reports", "Tables 1-3 and Fig. 14 of the ToF paper, the mechanisms measured"),
    ],
    ("campaign",): [
        ("svgs campaign --camera galaxy-nexus --trials 80 --ranges 5,10,15,20,30 --budget --out campaign",
         "the paper's campaign (Tables 2-5) with the error budget; resumes when rerun"),
        ("svgs campaign --camera htc-amaze-4g --trial-kind geometric --trials 400 --out quick",
         "the fast geometric trials (centroid noise only), milliseconds a trial"),
    ],
    ("sensitivity",): [
        ("svgs sensitivity --camera galaxy-nexus --vary range_m=5:30 --vary sigma_px=0.05:0.3 --n 256 --out sens",
         "Sobol' indices of the pose error"),
    ],
    ("merge-range",): [
        ("svgs merge-range --camera htc-amaze-4g --vary threshold --out merge",
         "where the spots merge, with the threshold at its range's ends"),
    ],
    ("sun-study",): [
        ("svgs sun-study --camera galaxy-nexus --ranges 5,10 --sun-azimuths-deg -90,0,90 --sun-elevations-deg 0,30 "
         "--trials 4 --body 3u --out sun", "lock, loss and wrong locks with the sun around the target"),
    ],
    ("sensor-model", "build"): [
        ("svgs sensor-model build --camera galaxy-nexus --out model-nexus",
         "the table over 0.8-34 m and 0-10 deg off axis, 30 frames a node (about 12 min on two cores)"),
        ("svgs sensor-model build --camera htc-amaze-4g --ranges 1,2,4,6.5 --frames-per-node 10 --out amaze --plan-only",
         "what a small table would render and how long it would take, nothing run"),
    ],
    ("sensor-model", "validate"): [
        ("svgs sensor-model validate --model model-nexus --frames 200 --out model-nexus/validation",
         "200 held-out frames against the model: KS tests, scatter ratios, dropout counts"),
    ],
    ("approach",): [
        ("svgs approach --camera galaxy-nexus --from 30 --to 1 --duration 60 --fps 1 --out approach",
         "a docking approach frame by frame, the error against the CRLB, a video"),
    ],
}


def epilog(words) -> str | None:
    """The examples of a command as its help's epilog (None: none)."""
    ex = EXAMPLES.get(tuple(words))
    if not ex:
        return None
    lines = ["examples:"]
    for cmd, what in ex:
        lines.append("  " + cmd)
        lines += textwrap.wrap(what, 74, initial_indent="      ", subsequent_indent="      ")
    lines += [""] + textwrap.wrap(NEGATIVE_NOTE, 78)
    return "\n".join(lines)


#: How a negative number is written (every command's help says it).
NEGATIVE_NOTE = ("A negative number or a list that starts with one goes after a space or after '=' alike: "
                 "--yaw -20, --sun-deg -30,10, --sun-azimuths-deg=-90,0,90.")


class HelpFormatter(argparse.HelpFormatter):
    """argparse's formatter, but an epilog of examples keeps its lines (the description is wrapped)."""

    def _fill_text(self, text, width, indent):
        if text.startswith("examples:"):
            return "\n".join(indent + line for line in text.splitlines())
        return super()._fill_text(text, width, indent)


def add_examples(parser: argparse.ArgumentParser, iter_commands) -> None:
    """Every command's epilog from :data:`EXAMPLES` (``iter_commands``: :func:`svgs_sim.cli.main.iter_commands`)."""
    for words, p in iter_commands(parser):
        text = epilog(words)
        if text:
            p.epilog = text
            p.formatter_class = HelpFormatter


__all__ = ["EXAMPLES", "HelpFormatter", "NEGATIVE_NOTE", "add_examples", "epilog"]
