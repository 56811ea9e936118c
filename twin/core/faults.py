"""What a fault of the machine means to the user: an ``OSError`` from writing or reading
files (a read-only folder, a full disk, no permission) as one line that names the path
the user gave and the cause, and what to do. The command line prints it instead of a
traceback; every writer of the twin writes under a temporary name and renames, so such a
fault leaves earlier outputs as they were.

An error counts as the machine's only when it names a file: the writers re-raise a full
disk's path-less ``write`` error with the output they were writing
(:func:`twin.core.atomic.naming`), and a
path-less permission error (from a socket, a signal) stays a bug with its traceback."""

import errno
import re
from pathlib import Path

from twin.core.atomic import output_name
from twin.core.paths import cache_dir

#: Faults of the machine a user can fix (space, permissions, a read-only mount), by errno.
REMEDIES = {
    errno.EROFS: "the file system is read-only",
    errno.EACCES: "permission denied",
    errno.EPERM: "operation not permitted",
    errno.ENOSPC: "no space left on the device",
    errno.EDQUOT: "the disk quota is exceeded",
    errno.ENAMETOOLONG: "the file name is too long",
}
#: A lock beside its output, ``.NAME.lock`` (:func:`twin.core.locks.lock_path`).
_LOCK = re.compile(r"^\.(?P<name>.+)\.lock$")


def is_machine_fault(error: BaseException) -> bool:
    """Whether ``error`` is a fault of the machine the user can fix: an ``OSError`` of
    :data:`REMEDIES` that names a file."""
    return isinstance(error, OSError) and error.errno in REMEDIES and error.filename is not None


def describe(error: OSError) -> str:
    """One line: the path the user knows (the final name of a temporary one), the
    cause, and what to do."""
    path = _shown(error.filename)
    cause = REMEDIES.get(error.errno, error.strerror or str(error))
    if _inside(path, cache_dir()) or _inside(cache_dir(), path):
        return (
            f"{path}: {cause}; the twin's cache is there: set I24_TWIN_CACHE to a writable "
            "folder with a few GB free"
        )
    if error.errno in (errno.ENOSPC, errno.EDQUOT):
        return (
            f"{path}: {cause}; free some space or write elsewhere (outputs are written "
            "whole or not at all: earlier ones are as they were)"
        )
    return f"{path}: {cause}"


def _shown(filename) -> Path:
    """``filename`` with the writers' temporary names in it replaced by the names of the
    outputs they stand for (``.run.partial-123`` for ``run``, ``.x.partial-123.png`` for
    ``x.png``), and a lock by its output (``.map-1f.lock`` for ``map-1f``): the path
    the user knows."""
    parts = [output_name(part) or part for part in Path(str(filename)).parts]
    if parts and (lock := _LOCK.match(parts[-1])) is not None:
        parts[-1] = lock["name"]
    return Path(*parts)


def _inside(path: Path, folder: Path) -> bool:
    try:
        path.resolve().relative_to(folder.resolve())
    except (ValueError, OSError):
        return False
    return True
