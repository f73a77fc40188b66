"""Help texts: every command has a description, every option its help, defaults are shown."""
from __future__ import annotations

import argparse

import pytest

from relaff_jax import cli


def _commands(parser, prefix=()):
    """(name, parser) of every command and subcommand under ``parser``."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield prefix + (name,), sub
                yield from _commands(sub, prefix + (name,))


COMMANDS = list(_commands(cli.build_parser()))


def test_every_command_is_listed():
    names = {" ".join(n) for n, _ in COMMANDS}
    assert {"generate", "features", "show", "report", "reproduce", "real segment", "real study"} <= names


@pytest.mark.parametrize("name,parser", COMMANDS, ids=[" ".join(n) for n, _ in COMMANDS])
def test_every_command_has_a_description_and_every_option_a_help(name, parser):
    assert parser.description, f"relaff {' '.join(name)} has no description"
    missing = [a.dest for a in parser._actions
               if not isinstance(a, argparse._SubParsersAction) and not a.help]
    assert missing == [], f"relaff {' '.join(name)}: options without help: {missing}"
    parser.format_help()  # every help string formats (a stray % would raise here)


def test_defaults_are_shown_and_percent_signs_print_once(capsys):
    with pytest.raises(SystemExit):
        cli.main(["generate", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "%%" not in text
    assert "50% positives" in text
    assert "(default: 0)" in text  # --seed
    assert "dataset.rollout_batch" in text  # --batch names the tree key it sets


def test_reproduce_status_help_names_the_positional_folder(capsys):
    with pytest.raises(SystemExit):
        cli.main(["reproduce", "--help"])
    assert "--redo-dataset ACTION" in capsys.readouterr().out
