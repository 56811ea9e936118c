"""The ``twin`` command line: one module per command group, the options they share in
:mod:`twin.cli.options`.

A problem with what the user asked for (a :class:`~twin.core.errors.TwinError`), or a
fault of the machine the user can fix (a read-only folder, a full disk:
:mod:`twin.core.faults`), is one line on stderr, ``twin: error: ...``, and exit status
2, as argparse's own errors are.
Values read from the command line are checked where they are read
(:mod:`twin.cli.options`), so any other exception is a bug in the twin: its traceback,
a line asking to report it, and exit status 70.
"""

import argparse
import os
import re
import sys
import traceback

from twin import __version__
from twin.cli import bench, calibrate, data, dataset, evaluate, export, maps, run, train
from twin.core import faults
from twin.core.errors import TwinError

EXIT_USER_ERROR = 2  # as argparse's own errors
EXIT_BUG = 70  # EX_SOFTWARE of sysexits.h: an internal software error
EXIT_INTERRUPTED = 130  # 128 + SIGINT, as a shell reports it
EXIT_BROKEN_PIPE = 141  # 128 + SIGPIPE: the reader of stdout went away
BUG_HINT = (
    f"twin: internal error: this is a bug in i24-twin {__version__}; "
    "please report it with the command and the traceback above"
)


def main(argv: list[str] | None = None) -> int:
    """Run the ``twin`` command ``argv`` (default: the process's arguments).

    Returns:
        The exit status: 0, ``EXIT_USER_ERROR``, ``EXIT_BUG``, ``EXIT_INTERRUPTED`` or
        ``EXIT_BROKEN_PIPE`` (argparse exits with 2 itself on an option it rejects).
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    if not hasattr(args, "handler"):
        parser.print_help()
        return EXIT_USER_ERROR
    try:
        return args.handler(args) or 0
    except TwinError as error:
        print(f"twin: error: {error}", file=sys.stderr)
        return EXIT_USER_ERROR
    except KeyboardInterrupt:
        print("twin: interrupted; nothing partial was left behind", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:  # twin ... | head: stop quietly, as other command-line tools do
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no flush error at exit
        return EXIT_BROKEN_PIPE
    except Exception as error:
        if faults.is_machine_fault(error):
            print(f"twin: error: {faults.describe(error)}", file=sys.stderr)
            return EXIT_USER_ERROR
        traceback.print_exc()
        print(BUG_HINT, file=sys.stderr)
        return EXIT_BUG


class DefaultsFormatter(argparse.HelpFormatter):
    """Help lines end with the option's default where it has one and its help does not
    already say it (argparse's ``ArgumentDefaultsHelpFormatter`` repeats those)."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        default = action.default
        unset = default is None or default is False or default is argparse.SUPPRESS
        if unset or default == [] or not action.option_strings or says_default(text):
            return text
        return f"{text} (default %(default)s)"


def says_default(text: str) -> bool:
    """Whether a help line already gives its option's default (the word, not
    "defaults")."""
    return re.search(r"\bdefault\b", text) is not None


def build_parser() -> argparse.ArgumentParser:
    """The ``twin`` parser; each command's ``handler(args)`` is in ``args.handler``."""
    parser = argparse.ArgumentParser(
        prog="twin", description="i24-twin: a physics-based digital twin of I-24 (MM 60.6-61.6)."
    )
    parser.add_argument("--version", action="version", version=f"i24-twin {__version__}")
    commands = parser.add_subparsers(title="commands")
    for group in (run, data, maps, export, dataset, calibrate, evaluate, train, bench):
        group.register(commands)
    for command in _parsers(parser):
        command.formatter_class = DefaultsFormatter
    return parser


def _parsers(parser: argparse.ArgumentParser):
    """``parser`` and every subcommand's parser under it."""
    yield parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                yield from _parsers(sub)
