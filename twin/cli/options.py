"""What the command groups share: options declared once, and the reading of the values
users give, where a bad one becomes a :class:`UsageError` naming it.

Heavy modules are imported inside the functions, so that ``twin --help`` stays quick.
"""

import argparse
import os
from pathlib import Path

from twin.core.errors import TwinError

DATA_HELP = "store folder, I-24 JSON or embedded:morning (default: the embedded data)"
QUIET_HELP = "no progress bar"


class UsageError(TwinError):
    """A value given on the command line that the twin cannot use."""


def add_data(parser: argparse.ArgumentParser, help: str = DATA_HELP, type=Path) -> None:
    """``--data``: where the recorded traffic comes from (read with :func:`open_data`)."""
    parser.add_argument("--data", type=type, default=None, help=help)


def add_store(parser: argparse.ArgumentParser) -> None:
    """The optional STORE argument: a store folder or ``embedded:NAME``."""
    parser.add_argument(
        "store", nargs="?", type=Path, help="store folder (default: the embedded data)"
    )


class _ModelNames:
    """The registered car-following models' names (and ``extra`` names), read from the
    registry only when argparse checks a value or writes a help (it imports numpy)."""

    def __init__(self, extra: tuple[str, ...] = ()):
        self.extra = extra

    def _names(self) -> list[str]:
        from twin.traffic.models import MODELS

        return [*self.extra, *sorted(MODELS)]

    def __iter__(self):
        return iter(self._names())

    def __contains__(self, name) -> bool:
        return name in self._names()


def add_car_following(
    parser: argparse.ArgumentParser, flag: str, default: str, help: str, extra=()
):
    """A car-following model by its registered name, or one of ``extra`` (``help`` may
    say ``%(choices)s``)."""
    parser.add_argument(
        flag, choices=_ModelNames(tuple(extra)), default=default, metavar="MODEL", help=help
    )


def add_world(parser: argparse.ArgumentParser) -> None:
    """``--world``: where the vehicles move (``world`` of the run's configuration)."""
    parser.add_argument(
        "--world",
        choices=["physics", "kinematic"],
        default=None,
        help="physics: pybullet rigid bodies at 100 Hz, the reference and the only world "
        "with cameras; kinematic: point masses on kinematic bicycles at 10 Hz, for "
        "training and sweeps (default: physics, or the configuration's)",
    )


def at_least_one(text: str) -> int:
    """An integer option that must be >= 1 (argparse names the option when it is not)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    return value


def positive_float(text: str) -> float:
    """A number option that must be finite and > 0 (argparse names the option when it
    is not)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (value > 0.0 and value != float("inf")):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text}")
    return value


def add_set(parser: argparse.ArgumentParser, help: str) -> None:
    """``--set KEY=VALUE`` (repeatable), collected in ``args.assignments``."""
    parser.add_argument(
        "--set", dest="assignments", action="append", default=[], metavar="KEY=VALUE", help=help
    )


def add_quiet(parser: argparse.ArgumentParser, help: str | None = QUIET_HELP) -> None:
    """``--quiet``: no progress bar."""
    parser.add_argument("--quiet", action="store_true", help=help)


def add_config(
    parser: argparse.ArgumentParser,
    help: str = "TOML configuration file (default: none, the preset's settings)",
) -> None:
    """``--config``: a TOML file of settings."""
    parser.add_argument("--config", type=Path, default=None, help=help)


def add_workers(parser: argparse.ArgumentParser, help: str) -> None:
    """``--workers N``: how many processes (None: the cores available)."""
    parser.add_argument("--workers", type=int, default=None, help=help)


def add_worker_counts(parser: argparse.ArgumentParser) -> None:
    """``--workers 1,2,4``: the worker counts a benchmark is timed with."""
    parser.add_argument(
        "--workers", default=None, help="worker counts, comma-separated (default: 1 to cores)"
    )


def add_engine(parser: argparse.ArgumentParser) -> None:
    """``--engine`` and ``--ray-address``: where the episodes run."""
    parser.add_argument(
        "--engine", choices=["local", "ray"], default="local",
        help="local: processes on this machine; ray: Ray tasks, here or on a cluster",
    )  # fmt: skip
    parser.add_argument(
        "--ray-address", default=None,
        help="Ray cluster to join (--engine ray; default: a local Ray started for the run)",
    )  # fmt: skip


def add_start(parser: argparse.ArgumentParser, help: str) -> None:
    """``--start``: a time, unix or ISO 8601 with offset (read with :func:`unix_time`)."""
    parser.add_argument("--start", default=None, help=help)


def add_window(parser: argparse.ArgumentParser, from_help: str, until_help: str) -> None:
    """``--from`` and ``--until`` (``args.t_from``, ``args.t_until``): a time window."""
    parser.add_argument(
        "--from", dest="t_from", default=None, help=f"{from_help} (default: the data's start)"
    )
    parser.add_argument("--until", dest="t_until", default=None,
                        help=f"{until_help} (default: the data's end)")  # fmt: skip


def add_map(parser: argparse.ArgumentParser) -> None:
    """``--map`` and ``--seed``: a built map folder, else the cached map of a terrain seed."""
    parser.add_argument(
        "--map", type=Path, default=None, help="map folder (default: the cached map)"
    )
    parser.add_argument("--seed", type=int, default=0, help="terrain seed of the cached map")


def unix_time(text: str | None, option: str) -> float | None:
    """The time option ``option`` as unix seconds (None stays None).

    Raises:
        UsageError: naming ``option``, when ``text`` is neither unix seconds (1970 to
            2100) nor ISO 8601 with an offset.
    """
    from twin.core.timeutil import parse_time

    if text is None:
        return None
    try:
        return parse_time(text)
    except ValueError as error:
        raise UsageError(f"{option}: {error}") from None


def checked_road(text: str) -> str:
    """A ``--road`` value, returned as given once it names a carriageway.

    Raises:
        UsageError: ``text`` names no carriageway.
    """
    from twin.core.i24 import Road

    try:
        Road.parse(text)
    except ValueError as error:
        raise UsageError(str(error)) from None
    return text


def checked_data(data: str | os.PathLike | None) -> str | os.PathLike | None:
    """A ``--data`` value, returned as given once it names embedded data that exist or a
    path that does (what the path holds is checked where it is opened).

    Raises:
        UsageError: an unknown ``embedded:NAME``, or no such file or folder.
    """
    from twin.data.embedded import embedded_name

    if data is None:
        return None
    if (name := embedded_name(data)) is not None:
        _check_embedded(name)
    elif not Path(data).exists():
        raise UsageError(f"--data {Path(data)}: no such file or folder")
    return data


def open_data(data: str | os.PathLike | None, *, progress: bool = True):
    """The trajectory store of a ``--data`` value (see ``twin.runners.run.open_data``).

    Raises:
        StoreError, DataFormatError: an unknown ``embedded:NAME``, no such file or
            folder, or a path that holds no store or I-24 MOTION data.
    """
    from twin.runners.run import open_data as open_run_data

    return open_run_data(data, progress=progress)


def open_store(path: Path | None):
    """The store of a STORE argument: the embedded default (None), ``embedded:NAME`` or a
    store folder.

    Raises:
        StoreError: an unknown ``embedded:NAME``, or the folder is not a store.
    """
    from twin.data.embedded import default_store, embedded_name, embedded_store
    from twin.data.store import open_store

    if path is None:
        return default_store()
    if (name := embedded_name(path)) is not None:
        return embedded_store(name)
    return open_store(path)


def _check_embedded(name: str) -> None:
    from twin.data.embedded import EMBEDDED, EMBEDDED_PREFIX

    if name not in EMBEDDED:
        raise UsageError(
            f"no embedded data {name!r}: choose one of "
            + ", ".join(EMBEDDED_PREFIX + n for n in EMBEDDED)
        )


def listed(text: str | None) -> tuple[str, ...]:
    """A comma-separated option as a tuple (empty for None)."""
    return tuple(t.strip() for t in (text or "").split(",") if t.strip())


def worker_counts(text: str | None) -> tuple[int, ...] | None:
    """``--workers 1,2,4`` as integers (None stays None).

    Raises:
        UsageError: a count is not an integer.
    """
    if text is None:
        return None
    try:
        return tuple(int(w) for w in text.split(","))
    except ValueError:
        raise UsageError(f"--workers must be integers like 1,2, got {text!r}") from None


def workers_or_cores(workers: int | None) -> int:
    """``--workers``, else the cores this process may use."""
    return workers if workers is not None else len(os.sched_getaffinity(0))


def check_seed(seed: int) -> None:
    """Raise :class:`UsageError` unless ``--seed`` can seed a random generator (>= 0)."""
    if seed < 0:
        raise UsageError(f"--seed must be a non-negative integer, got {seed}")
