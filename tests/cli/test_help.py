"""Every option of every command says what it is, and its default where it has one."""

import argparse

import pytest

from twin.cli import build_parser, main


def _options(parser: argparse.ArgumentParser, path: tuple[str, ...] = ()):
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _options(sub, (*path, name))
        elif action.option_strings and not isinstance(action, argparse._HelpAction):
            yield " ".join(path), parser, action


def test_every_option_has_a_help_line_that_gives_its_default():
    silent, no_default = [], []
    for command, parser, action in _options(build_parser()):
        name = f"twin {command} {action.option_strings[-1]}"
        if not (action.help or "").strip():
            silent.append(name)
            continue
        shown = parser.formatter_class(command)._get_help_string(action)
        has_default = action.default not in (None, False, [], argparse.SUPPRESS)
        if has_default and "default" not in shown.lower():
            no_default.append(name)
    assert not silent, f"options without a help line: {silent}"
    assert not no_default, f"options whose help does not give the default: {no_default}"


def test_defaults_are_printed_once(capsys):
    with pytest.raises(SystemExit):
        main(["data", "plot", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "time span plotted [min] (default 10.0)" in text
    assert "PNG file to write (default timespace.png)" in text
    # an option whose help already says its default is not given it twice
    assert text.count("(default: data start)") == 1 and "data start) (default" not in text
