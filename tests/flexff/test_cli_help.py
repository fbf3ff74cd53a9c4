"""The command line speaks of any machine: the manipulator's signals, figures and tables appear
in a help text only where it names the manipulator as the one they belong to."""

import argparse

from flexff.cli import build_parser

MANIPULATOR_WORDS = ("theta_s", "Fx", "Table 5", "Table 6", "wrist", "1.8 Hz", "i1..i3")


def _helps(parser: argparse.ArgumentParser, where: str = "flexff"):
    """(where, text) of the parser's description and every command's and argument's help."""
    yield where, parser.description or ""
    for action in parser._actions:
        yield f"{where} {'/'.join(action.option_strings) or action.dest}", action.help or ""
        if isinstance(action, argparse._SubParsersAction):
            for choice in action._choices_actions:
                yield f"{where} {choice.dest}", choice.help or ""
            for name, sub in action.choices.items():
                yield from _helps(sub, f"{where} {name}")


def test_the_manipulator_is_named_wherever_its_signals_are():
    for where, text in _helps(build_parser()):
        found = [w for w in MANIPULATOR_WORDS if w in text]
        assert not found or "manipulator" in text, (where, text)


def test_the_description_is_of_any_machine():
    description = build_parser().description
    assert description.startswith("Learned feedforward control for a machine's loop")
    assert "manipulator is the built-in example" in description
