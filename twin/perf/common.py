"""What the benchmarks share: the commit, date and machine of each line, timing,
medians, the worker counts and scaling of the runners' benchmarks, and the class mix
of the vehicles spawned on the I-24 mesh."""

import os
import platform
import resource
import subprocess
import time
from collections.abc import Callable, Sequence
from datetime import UTC, datetime
from importlib import metadata
from pathlib import Path

import numpy as np

DT = 0.01  # [s] the physics step the simulation benchmarks run at
SIZE_COLUMNS = ("length_m", "width_m", "height_m")


def context() -> dict:
    """Commit, date and machine, printed with every benchmark line.

    Returns:
        ``commit`` (short hash, ``None`` outside a git checkout), ``dirty`` (the work
        tree differs from it), ``date`` (UTC, ISO 8601), ``python``, ``cpus`` (the cores
        this process may use) and ``machine``: ``cpu`` (model name), ``cores`` (of the
        machine), ``memory_gb``, ``os``, and the versions of ``numpy`` and ``pybullet``.
    """
    commit = _git("rev-parse", "--short", "HEAD") or None
    return {
        "commit": commit,
        "dirty": bool(_git("status", "--porcelain", "--untracked-files=no")) if commit else None,
        "date": datetime.now(UTC).isoformat(timespec="seconds"),
        "python": platform.python_version(),
        "cpus": cores(),
        "machine": machine(),
    }


def machine() -> dict:
    """What the benchmarks ran on: CPU model, its cores, memory [GB], OS and the versions
    of the libraries the figures depend on (``None`` where unknown)."""
    return {
        "cpu": _cpu_model(),
        "cores": os.cpu_count(),
        "memory_gb": _memory_gb(),
        "os": platform.platform(terse=True),
        "numpy": _version("numpy"),
        "pybullet": _version("pybullet"),
    }


def _git(*args: str) -> str:
    """The stripped output of ``git ARGS`` in this checkout ('' where git fails)."""
    try:
        done = subprocess.run(
            ["git", *args], capture_output=True, text=True, cwd=Path(__file__).parent
        )
    except OSError:
        return ""
    return done.stdout.strip() if done.returncode == 0 else ""


def _cpu_model() -> str | None:
    """The CPU's model name (Linux ``/proc/cpuinfo``), else what ``platform`` says."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or None


def _memory_gb() -> float | None:
    """Physical memory [GB] (POSIX ``sysconf``), ``None`` where it cannot be read."""
    try:
        return round(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 1e9, 1)
    except (ValueError, OSError, AttributeError):
        return None


def _version(package: str) -> str | None:
    """The installed version of ``package``, ``None`` where it is not installed."""
    try:
        return metadata.version(package)
    except metadata.PackageNotFoundError:
        return None


def cores() -> int:
    """The cores this process may run on."""
    return len(os.sched_getaffinity(0))


def median(values) -> float:
    """The median of ``values`` (any array-like of numbers) as a Python float."""
    return float(np.median(values))


def ms(seconds: float, digits: int) -> float:
    """``seconds`` in milliseconds, rounded to ``digits`` decimals."""
    return round(1e3 * float(seconds), digits)


def timed(call: Callable, *args, **kwargs) -> tuple[object, float]:
    """``call(*args, **kwargs)``'s result and its wall time [s]."""
    start = time.perf_counter()
    result = call(*args, **kwargs)
    return result, time.perf_counter() - start


def seconds_per_call(call: Callable, arguments: Sequence[tuple]) -> np.ndarray:
    """Wall time [s] of ``call(*args)`` for each tuple ``args`` of ``arguments``, in
    order: shape ``(len(arguments),)`` float."""
    seconds = np.empty(len(arguments))
    for k, args in enumerate(arguments):
        start = time.perf_counter()
        call(*args)
        seconds[k] = time.perf_counter() - start
    return seconds


def cpu_seconds() -> float:
    """CPU seconds of this process and of its children that have ended."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def worker_counts(workers: tuple[int, ...] | None) -> tuple[int, ...]:
    """``workers``, or by default every count from 1 up to the cores available."""
    return workers or tuple(range(1, cores() + 1))


def scaling(by_workers: dict, key: str, *, lower_is_better: bool = False) -> float | None:
    """How figure ``key`` of ``by_workers`` (figures by worker count, as strings) scales
    from one worker to the most: the most's over one's, or one's over the most's where
    lower is better (wall time). None without both one worker and more."""
    most = str(max(int(count) for count in by_workers))
    if "1" not in by_workers or most == "1":
        return None
    one, many = by_workers["1"][key], by_workers[most][key]
    return round(one / many if lower_is_better else many / one, 2)


def store_or_default(store):
    """``store``, or the embedded default store (built and cached on first use)."""
    from twin.data.embedded import default_store

    return store if store is not None else default_store(progress=False)


def class_mix(table, rng: np.random.Generator, n: int) -> np.ndarray:
    """Vehicle classes of ``n`` vehicles drawn at the corridor's shares: shape (n,) int."""
    return rng.choice(7, n, p=table.column("share"))


def dimensions(table, classes: np.ndarray) -> list[np.ndarray]:
    """Length, width and height [m] of vehicles of ``classes``: three arrays of shape (n,)."""
    return [table.column(c)[classes] for c in SIZE_COLUMNS]
