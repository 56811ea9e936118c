"""Every option of every command says what it is, and its default where it has one."""

import argparse

import pytest

from twin.cli import build_parser, main, says_default


def _options(parser: argparse.ArgumentParser, path: tuple[str, ...] = ()):
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _options(sub, (*path, name))
        elif action.option_strings and not isinstance(action, argparse._HelpAction):
            yield " ".join(path), parser, action


def _takes_a_value(action: argparse.Action) -> bool:
    """An option given a value (not a flag, not repeatable, not required)."""
    return (
        action.nargs != 0 and not action.required and not isinstance(action, argparse._AppendAction)
    )


def test_every_option_has_a_help_line_that_gives_its_default():
    silent, no_default = [], []
    for command, parser, action in _options(build_parser()):
        name = f"twin {command} {action.option_strings[-1]}"
        if not (action.help or "").strip():
            silent.append(name)
            continue
        shown = parser.formatter_class(command)._get_help_string(action)
        if _takes_a_value(action) and not says_default(shown):
            no_default.append(name)
    assert not silent, f"options without a help line: {silent}"
    assert not no_default, f"options whose help does not give the default: {no_default}"


@pytest.mark.parametrize(
    ("command", "expected"),
    [
        (["data", "plot"], "time span plotted [min] (default 10.0)"),
        (["data", "plot"], "PNG file to write (default timespace.png)"),
        (["data", "synth"], "(default 0)"),  # a default of 0 is a default too
        (["render"], "time of the frame [s after t0] (default 0.0)"),
    ],
)
def test_defaults_are_printed(capsys, command, expected):
    with pytest.raises(SystemExit):
        main([*command, "--help"])
    assert expected in " ".join(capsys.readouterr().out.split())


def test_a_help_line_that_gives_its_default_is_not_given_it_twice(capsys):
    with pytest.raises(SystemExit):
        main(["data", "plot", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert text.count("(default: data start)") == 1 and "data start) (default" not in text


def test_twin_runs_help_gives_the_defaults_the_run_has(capsys):
    from twin.cosim.config import SCENARIO_B, CosimConfig

    with pytest.raises(SystemExit):
        main(["run", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    default = CosimConfig()
    for shown in (
        f"(default: the preset's; B {SCENARIO_B.road.value})",
        f"(default: the preset's; B {SCENARIO_B.lane})",
        f"(default: the preset's; B {SCENARIO_B.x:g})",
        f"(default {default.t_max:g})",
        f"(default {default.vel_default:.2f}, the posted 70 mph)",
        f"visible window each side [m] (default {default.w_visible:g})",
        f"ghost window beyond it [m] (default {default.w_ghost:g})",
        f"(default {default.ghost_smoothing:g}: off)",
    ):
        assert shown in text
