"""Every option of every ``svgs`` command has a help text that says its default, its unit, and
for the options that size a long job, what it costs (issue 26, deliverable 9).

The parser is walked from :func:`svgs_sim.cli.main.build_parser` through every sub-parser, so a new
command or option is checked without being listed here.
"""

from __future__ import annotations

import argparse
import re

import pytest

from svgs_sim.cli.main import build_parser

#: A unit or a word saying the number has none; a float option's help must name one.
UNIT = re.compile(r"\b(m|s|ms|deg|px|mm|Hz|lux|LSB|DN|ISO|metres|seconds|pixels)\b"
                  r"|fraction|dimensionless|ratio|%|factor|f-number")
#: A cost: a time per item or for the run (``~50 ms each``, ``~1-2 s``, ``minutes``).
COST = re.compile(r"\d[\d.\-]*\s*(ms|s|min|h)\b|\bminutes\b|\bhours\b")

#: Options that size a long job: their help says what one unit of them costs.
LONG_JOB_OPTIONS = (
    ("svgs campaign", "--trials"),
    ("svgs sensitivity", "--n"),
    ("svgs sensitivity", "--trial-kind"),
    ("svgs range-sweep", "--ranges"),
    ("svgs exposure-study", "--trials"),
    ("svgs merge-range", "--exposures"),
    ("svgs calibrate study", "--geometric"),
    ("svgs tof stability", "--frames"),
    ("svgs tof render-and-solve", "--frames"),
    ("svgs approach", "--fps"),
)


def _walk(parser: argparse.ArgumentParser, prefix: str = "svgs"):
    """``("svgs calibrate focal", parser)`` for the top parser and every command's
    (:func:`svgs_sim.cli.main.iter_commands`)."""
    from svgs_sim.cli.main import iter_commands

    yield prefix, parser
    for words, sub in iter_commands(parser):
        yield " ".join((prefix, *words)), sub


def _options():
    """(command, flag, action) of every argument of every command (help and sub-command choices excluded)."""
    out = []
    for name, p in _walk(build_parser()):
        for a in p._actions:
            if isinstance(a, (argparse._HelpAction, argparse._SubParsersAction, argparse._VersionAction)):
                continue
            flag = max(a.option_strings, key=len) if a.option_strings else a.dest
            out.append((name, flag, a))
    return out


OPTIONS = _options()


def _help(p, a) -> str:
    """The help as the user reads it (``%(default)s`` expanded)."""
    return p._get_formatter()._expand_help(a) if a.help else ""


def _parser_of(command: str) -> argparse.ArgumentParser:
    return dict(_walk(build_parser()))[command]


def test_the_walk_reaches_every_command():
    names = {n for n, _ in _walk(build_parser())}
    for cmd in ("svgs solve", "svgs calibrate focal", "svgs calibrate study", "svgs tof stability", "svgs tof study",
                "svgs sensitivity", "svgs merge-range", "svgs approach"):
        assert cmd in names
    assert len(OPTIONS) > 200


@pytest.mark.parametrize("command,flag,action", OPTIONS, ids=[f"{c} {f}" for c, f, _ in OPTIONS])
def test_every_option_has_help(command, flag, action):
    assert action.help and action.help.strip() and action.help != argparse.SUPPRESS, f"{command} {flag}: no help text"


@pytest.mark.parametrize("command,flag,action", OPTIONS, ids=[f"{c} {f}" for c, f, _ in OPTIONS])
def test_every_optional_value_states_its_default(command, flag, action):
    """An option that takes a value and may be left out says what it is when left out."""
    if not action.option_strings or action.required or action.nargs == 0:
        return  # positional, required, or a flag (store_true: off unless given)
    text = _help(_parser_of(command), action).lower()
    assert "default" in text, f"{command} {flag}: the help does not say the default ({action.default!r}): {text!r}"


@pytest.mark.parametrize("command,flag,action", [o for o in OPTIONS if o[2].type is float],
                         ids=[f"{c} {f}" for c, f, a in OPTIONS if a.type is float])
def test_every_number_option_names_its_unit(command, flag, action):
    assert UNIT.search(action.help or ""), f"{command} {flag}: no unit in {action.help!r}"


@pytest.mark.parametrize("command,flag", LONG_JOB_OPTIONS)
def test_long_job_options_state_the_cost(command, flag):
    p = _parser_of(command)
    a = next(a for a in p._actions if flag in a.option_strings)
    assert COST.search(_help(p, a)), f"{command} {flag}: no cost in {a.help!r}"


def test_geometric_calibration_study_does_not_promise_seconds():
    """It takes minutes with the defaults (issue 26): the help must not say seconds."""
    p = _parser_of("svgs calibrate study")
    a = next(a for a in p._actions if "--geometric" in a.option_strings)
    assert "seconds" not in a.help and "minutes" in a.help


def test_issue_26_options_have_help():
    """The options the issue found without help or without a stated default."""
    for command, flag in (("svgs exposure-study", "--seed"), ("svgs sensitivity", "--method"),
                          ("svgs sensitivity", "--seed"), ("svgs sensitivity", "--trial-kind"),
                          ("svgs sensitivity", "--pattern"), ("svgs merge-range", "--seed"),
                          ("svgs merge-range", "--pattern"), ("svgs sensitivity", "--n"),
                          ("svgs range-sweep", "--jitter-deg"), ("svgs range-sweep", "--jitter-m"),
                          ("svgs render", "--roi-spp")):
        p = _parser_of(command)
        a = next(a for a in p._actions if flag in a.option_strings)
        text = _help(p, a)
        assert "default" in text.lower(), (command, flag, text)
        if a.default not in (None, "") and not isinstance(a.default, list):
            assert str(a.default) in text, (command, flag, text)
