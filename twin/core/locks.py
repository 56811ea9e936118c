"""Locks between twin processes, so that two commands started at once never corrupt
what they share: a cache entry (the embedded data, the map, an ingested day) is built
by one process while the others wait for it; an output folder that a command fills
over time (an evaluation, a dataset) is written by one command at a time, and a second
is refused. POSIX advisory locks (``flock``) on a hidden file beside the target: the
operating system releases them when a process ends, even when it is killed."""

import fcntl
import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from twin.core.errors import TwinError


class BusyError(TwinError):
    """Another twin command is writing the same output folder."""


def lock_path(target: Path) -> Path:
    """The lock file of ``target``: ``.NAME.lock`` beside it."""
    target = Path(target)
    return target.parent / f".{target.name}.lock"


@contextmanager
def build_lock(target: Path) -> Iterator[None]:
    """Hold the lock of the cache entry ``target`` while it is built, waiting for
    another process that holds it (and saying so once on stderr)."""
    path = lock_path(target)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a") as file:
        try:
            fcntl.flock(file, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            print(f"waiting for another twin process to finish {target}", file=sys.stderr)
            fcntl.flock(file, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(file, fcntl.LOCK_UN)


@contextmanager
def output_lock(out: Path, command: str) -> Iterator[None]:
    """Hold the lock of the output folder ``out`` (which exists: claimed by the command)
    for ``command`` (``twin eval``); refuse when another process holds it.

    Raises:
        BusyError: naming ``out``, the other process and what to do.
    """
    path = lock_path(out)
    with open(path, "a+") as file:
        try:
            fcntl.flock(file, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            file.seek(0)
            holder = file.read().strip() or "another process"
            raise BusyError(
                f"{out} is being written by {holder}; wait for it to finish (then run "
                f"{command} again to resume or extend it), or choose another --out"
            ) from None
        file.seek(0)
        file.truncate()
        file.write(f"{command} (pid {os.getpid()})\n")
        file.flush()
        try:
            yield
        finally:
            file.seek(0)
            file.truncate()
            fcntl.flock(file, fcntl.LOCK_UN)
