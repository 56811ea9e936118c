"""How ``twin`` ends when something goes wrong: the user's mistake in one line with
status 2, a bug with its traceback and a request to report it with status 70, an
interrupt with status 130."""

import os
import subprocess
import sys
import traceback

import pytest

import twin.cli.data
from twin import __version__
from twin.cli import EXIT_BROKEN_PIPE, EXIT_BUG, EXIT_INTERRUPTED, EXIT_USER_ERROR, main

BUG_LINE = (
    f"twin: internal error: this is a bug in i24-twin {__version__}; "
    "please report it with the command and the traceback above"
)


def _fail_with(monkeypatch, error: BaseException) -> None:
    """Make ``twin data info`` raise ``error``."""

    def handler(args):
        raise error

    monkeypatch.setattr(twin.cli.data, "_info", handler)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (
            ["data", "info", "embedded:nosuch"],
            "no embedded data 'nosuch': choose one of embedded:default, embedded:morning",
        ),
        (["run", "--data", "missing", "--quiet"], "--data missing: no such file or folder"),
        (["data", "ingest", "missing.json", "--out", "s"], "input file not found: missing.json"),
        (
            ["data", "synth", "--preset", "A", "--out", "day.json", "--start", "06:45"],
            "--start: time '06:45' is neither unix seconds nor ISO 8601 "
            "(e.g. 2022-11-30T06:45:50-06:00)",
        ),
        (
            ["data", "synth", "--preset", "A", "--out", "day.json", "--minutes", "-1"],
            "SynthConfig.minutes is invalid: -1.0",
        ),
        (
            ["calibrate", "missing", "--road", "north"],
            "unknown road 'north': expected 'eastbound' or 'westbound' (or +1/-1)",
        ),
        (["bench", "eval", "--workers", "1,x"], "--workers must be integers like 1,2, got '1,x'"),
        (["bench", "env", "--steps", "0"], "--steps, --repeats and --workers must be >= 1"),
        (["bench", "traffic", "--vehicles", "0"], "--vehicles must be > 0, got 0"),
        (
            ["run", "--world", "kinematic", "--camera", "--quiet"],
            "command line: cameras need the physics world: the kinematic world has no bodies "
            'to render (set world = "physics", or turn the camera off)',
        ),
        (
            ["run", "--world", "kinematic", "--dt", "0.2", "--quiet"],
            "command line: the kinematic world's dt must be in (0, 0.1] s, got 0.2",
        ),
        (
            ["map", "build", "--seed", "-1", "--out", "m"],
            "seed must be a non-negative integer, got -1",
        ),
    ],
)
def test_a_value_the_twin_cannot_use_is_one_line_with_status_2(
    argv, message, tmp_path, monkeypatch, capsys
):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == EXIT_USER_ERROR
    captured = capsys.readouterr()
    assert captured.err == f"twin: error: {message}\n"
    assert not list(tmp_path.iterdir())  # nothing was written


def test_bad_input_data_are_named_without_a_traceback(tmp_path, capsys):
    bad = tmp_path / "bad.json"
    bad.write_text('{"not": "an array"}')
    assert main(["data", "ingest", str(bad), "--out", str(tmp_path / "s"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("twin: error:") and "bad.json" in err and "Traceback" not in err
    assert main(["data", "info", str(tmp_path / "nowhere")]) == 2
    assert "no trajectory store" in capsys.readouterr().err


@pytest.mark.parametrize(
    "error", [KeyError("x"), ValueError("x"), FileNotFoundError("x"), ZeroDivisionError()]
)
def test_any_other_exception_is_a_bug_shown_with_its_traceback(error, monkeypatch, capsys):
    _fail_with(monkeypatch, error)
    assert main(["data", "info"]) == EXIT_BUG == 70
    err = capsys.readouterr().err.splitlines()
    assert err[0] == "Traceback (most recent call last):"
    assert err[-2] == traceback.format_exception_only(error)[-1].rstrip()  # e.g. KeyError: 'x'
    assert err[-1] == BUG_LINE
    assert not any(line.startswith("twin: error:") for line in err)


def test_an_interrupt_ends_with_status_130_and_no_traceback(monkeypatch, capsys):
    _fail_with(monkeypatch, KeyboardInterrupt())
    assert main(["data", "info"]) == EXIT_INTERRUPTED == 130
    assert capsys.readouterr().err == "twin: interrupted; nothing partial was left behind\n"


def test_an_option_argparse_rejects_ends_in_its_usage_error(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["run", "--scenario", "C"])
    assert exit_.value.code == 2
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith("usage: twin run ")
    assert err[-1].startswith("twin run: error: argument --scenario: invalid choice: 'C'")


def test_no_command_prints_the_help_with_status_2(capsys):
    assert main([]) == 2
    assert capsys.readouterr().out.startswith("usage: twin ")


def test_the_exit_status_reaches_the_shell():
    done = subprocess.run(
        [sys.executable, "-m", "twin", "data", "info", "embedded:nosuch"],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 2
    assert done.stderr.splitlines() == [
        "twin: error: no embedded data 'nosuch': choose one of embedded:default, embedded:morning"
    ]


def test_a_reader_that_goes_away_ends_the_command_quietly(wave_store):
    """``twin data info | head -1``: the reader leaves before the twin writes; the twin
    stops with SIGPIPE's status, as other tools do, not with a bug's traceback."""
    read, write = os.pipe()
    os.close(read)
    try:
        done = subprocess.run(
            [sys.executable, "-m", "twin", "data", "info", str(wave_store.path)],
            stdout=write, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
    finally:
        os.close(write)
    assert (done.returncode, done.stderr) == (EXIT_BROKEN_PIPE, "")


def test_repeats_below_one_are_refused_by_every_benchmark(capsys):
    """``--repeats 0`` left a benchmark with nothing timed (a bug's traceback)."""
    with pytest.raises(SystemExit) as stop:
        main(["bench", "map", "--repeats", "0"])
    assert stop.value.code == EXIT_USER_ERROR
    assert "argument --repeats: must be >= 1, got 0" in capsys.readouterr().err


def test_the_behaviours_the_command_line_offers_are_the_cosimulations():
    from twin.cli import build_parser
    from twin.cosim.behaviour import AUTO, BEHAVIOURS

    commands = build_parser()._subparsers._group_actions[0].choices
    (action,) = [a for a in commands["run"]._actions if a.dest == "behaviour"]
    assert tuple(action.choices) == (AUTO, *BEHAVIOURS)
