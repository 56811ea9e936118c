"""What a fault of the machine means to the user: an ``OSError`` from writing or reading
files (a read-only folder, a full disk, no permission) as one line that names the path
the user gave and the cause, and what to do. The command line prints it instead of a
traceback; every writer of the twin writes under a temporary name and renames, so such a
fault leaves earlier outputs as they were."""

import errno
import re
from pathlib import Path

from twin.core.paths import cache_dir

#: Faults of the machine a user can fix (space, permissions, a read-only mount), by errno.
REMEDIES = {
    errno.EROFS: "the file system is read-only",
    errno.EACCES: "permission denied",
    errno.EPERM: "operation not permitted",
    errno.ENOSPC: "no space left on the device",
    errno.EDQUOT: "the disk quota is exceeded",
    errno.EMFILE: "too many open files",
    errno.ENAMETOOLONG: "the file name is too long",
}
_PARTIAL = re.compile(r"^\.(?P<name>.+?)\.(?:(?:partial|old)-\d+|lock)(?P<suffix>\.[^./]*)?$")


def is_machine_fault(error: BaseException) -> bool:
    """Whether ``error`` is a fault of the machine the user can fix."""
    return isinstance(error, OSError) and error.errno in REMEDIES


def describe(error: OSError) -> str:
    """One line: the path the user knows (the final name of a temporary one), the
    cause, and what to do."""
    path = _shown(error.filename) if error.filename is not None else None
    cause = REMEDIES.get(error.errno, error.strerror or str(error))
    where = f"cannot write {path}: " if path is not None else ""
    advice = "nothing partial was left behind and earlier outputs are as they were"
    if path is not None and _inside(path, cache_dir()):
        advice = (
            "the cache is there; set I24_TWIN_CACHE to a writable folder with a few GB "
            f"free ({advice})"
        )
    elif error.errno in (errno.ENOSPC, errno.EDQUOT):
        advice = f"free some space or choose another --out ({advice})"
    elif error.errno in (errno.EROFS, errno.EACCES, errno.EPERM):
        advice = f"choose another --out ({advice})"
    return f"{where}{cause}; {advice}"


def _shown(filename) -> Path:
    """``filename`` with each writer's temporary name or lock in it replaced by the name
    of the output it stands for (``.run.partial-123`` for ``run``, ``.x.partial-123.png``
    for ``x.png``, ``.map-1f.lock`` for ``map-1f``): the path the user knows."""
    path = Path(str(filename))
    parts = []
    for part in path.parts:
        match = _PARTIAL.match(part)
        parts.append(part if match is None else match["name"] + (match["suffix"] or ""))
    return Path(*parts)


def _inside(path: Path, folder: Path) -> bool:
    try:
        path.resolve().relative_to(folder.resolve())
    except (ValueError, OSError):
        return False
    return True
