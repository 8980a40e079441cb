"""Every command's help ends with examples (svgs_sim.cli.examples), and each works as written: it
parses with the command's own parser, every argument checked (svgs_sim.cli.validate) where its files
are not needed."""

from __future__ import annotations

import shlex

import pytest

from svgs_sim.cli.examples import EXAMPLES
from svgs_sim.cli.main import UsageError, join_negative_values, build_parser, iter_commands, leaf_parser

PARSER = build_parser()
LEAVES = {words: p for words, p in iter_commands(PARSER)
          if not any(a.__class__.__name__ == "_SubParsersAction" for a in p._actions)}


def test_every_command_has_examples_in_its_help():
    assert set(LEAVES) <= set(EXAMPLES), sorted(set(LEAVES) - set(EXAMPLES))
    for words, p in LEAVES.items():
        text = p.format_help()
        assert "examples:" in text
        for cmd, _ in EXAMPLES[words]:
            assert cmd in text  # kept on one line, as typed


@pytest.mark.parametrize("words,cmd", [(w, c) for w, ex in EXAMPLES.items() for c, _ in ex],
                         ids=[c[:60] for ex in EXAMPLES.values() for c, _ in ex])
def test_each_example_parses_as_written(words, cmd):
    argv = shlex.split(cmd)
    assert argv[0] == "svgs" and tuple(argv[1:1 + len(words)]) == words
    try:
        args, extra = PARSER.parse_known_args(join_negative_values(PARSER, argv[1:]))
    except UsageError as exc:  # pragma: no cover - the failure's message
        pytest.fail(f"{cmd!r}: {exc}")
    assert not extra, f"{cmd!r}: unrecognised {extra}"
    assert leaf_parser(PARSER, args) is LEAVES[words]


def test_every_help_says_how_a_negative_number_is_given():
    for p in LEAVES.values():
        assert "--sun-deg -30,10" in " ".join(p.format_help().split())


def test_a_negative_list_after_a_space_is_read_as_the_value_for_every_option_that_takes_one():
    """Every option of every command that takes a value gets ``-30,10`` after a space as its value
    (argparse refused it as 'expected one argument'); a flag never swallows a following token."""
    checked = 0
    for words, p in LEAVES.items():
        for a in p._actions:
            flag = max(a.option_strings, key=len, default="")
            if not flag.startswith("--") or a.nargs == 0:
                continue
            joined = join_negative_values(PARSER, [*words, flag, "-30,10"])
            assert joined == [*words, f"{flag}=-30,10"], (words, flag)
            checked += 1
    assert checked > 100
    assert join_negative_values(PARSER, ["render", "--json", "-5"]) == ["render", "--json", "-5"]


def test_every_command_group_names_its_dest_where_the_cli_looks_for_it():
    """A new command group must join signals.GROUP_DESTS, or its commands' names and leaf parsers are lost."""
    from svgs_sim.cli.main import GROUPS
    from svgs_sim.cli.signals import GROUP_DESTS

    assert sorted(g[2] for g in GROUPS.values()) == sorted(GROUP_DESTS)
