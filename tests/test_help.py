"""Every command's --help: a description line, and the default of every option stated.

Walks the whole ``rtsar`` parser (every command group registered in rtsar.app.cli, whoever added
it): each subcommand has a one-line help in ``rtsar --help`` and a description in its own
``--help``; each option with a default (not None, not suppressed, not an on/off flag) mentions
"default" and the value in its help, or uses argparse's %(default)s.
"""

import argparse

import pytest

from rtsar.app.cli import build_parser, main


def _commands(parser, path=("rtsar",)):
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            helps = {c.dest: c.help for c in action._choices_actions}
            for name, sub in action.choices.items():
                yield path + (name,), sub, helps.get(name)
                yield from _commands(sub, path + (name,))


def _states_default(action) -> bool:
    text = action.help or ""
    if "%(default)" in text:
        return True
    value = action.default
    forms = {str(value)}
    if isinstance(value, float):
        forms |= {f"{value:g}", f"{value:,g}"}
    if isinstance(value, (list, tuple)):
        forms |= {", ".join(map(str, value)), " ".join(map(str, value))}
    return "default" in text and any(f in text for f in forms)


def _options_with_defaults(parser):
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction) or action.help == argparse.SUPPRESS:
            continue
        if action.default in (None, argparse.SUPPRESS) or action.nargs == 0:
            continue  # no default to state, or an on/off flag
        if action.option_strings or action.nargs in ("?", "*"):
            yield action


COMMANDS = list(_commands(build_parser()))


def test_the_parser_has_the_known_commands():
    names = {path[1] for path, _, _ in COMMANDS}
    assert {"run", "replay", "process", "simulate", "quicklook", "view", "table1"} <= names


@pytest.mark.parametrize("path, sub, line", COMMANDS, ids=[" ".join(c[0]) for c in COMMANDS])
def test_every_command_has_a_help_line_and_a_description(path, sub, line):
    assert line and line.strip(), f"{' '.join(path)}: no help line in the parent's --help"
    assert sub.description and sub.description.strip(), f"{' '.join(path)}: no description"


@pytest.mark.parametrize("path, sub, line", COMMANDS, ids=[" ".join(c[0]) for c in COMMANDS])
def test_every_default_is_stated(path, sub, line):
    missing = [
        f"{'/'.join(a.option_strings) or a.dest} (default {a.default!r}): {a.help!r}"
        for a in _options_with_defaults(sub)
        if not _states_default(a)
    ]
    assert not missing, f"{' '.join(path)}: defaults not stated in --help:\n" + "\n".join(missing)


def test_help_prints_for_every_command(capsys):
    for path, _, _ in COMMANDS:
        with pytest.raises(SystemExit) as done:
            main(list(path[1:]) + ["--help"])
        assert done.value.code == 0
        out = capsys.readouterr().out
        assert out.startswith("usage: rtsar " + " ".join(path[1:]))
        # a description is printed as written (only option help is %-formatted): no "%%"
        assert "%%" not in out, f"{' '.join(path)}: '%%' printed in its --help"
