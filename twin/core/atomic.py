"""Folders written whole or not at all: build under a temporary name, then rename.

Used by everything the twin writes as a folder (trajectory stores, maps, runs), so
that an interrupt or an error never leaves a half-written folder under the real name
and never destroys the previous one.
"""

import json
import os
import re
import shutil
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from twin.core.errors import TwinError

#: A writer's temporary name beside its output: ``.NAME.partial-PID[.EXT]`` while it
#: writes, ``.NAME.old-PID`` for the earlier output it moves aside to replace it.
TEMPORARY = re.compile(
    r"^\.(?P<name>.+?)\.(?P<kind>partial|old)-(?P<pid>\d+)(?P<suffix>\.[^./]*)?$"
)


def naming(error: OSError, path: Path) -> OSError:
    """``error`` naming ``path`` when it names no file (a full disk's ``write``, and
    pyarrow's I/O errors, carry no file name): the output that was being written."""
    if error.filename is not None:
        return error
    return OSError(error.errno, error.strerror or str(error), str(path))


def output_name(name: str) -> str | None:
    """The output a writer's temporary ``name`` stands for (``.x.partial-12.png`` for
    ``x.png``), or None when ``name`` is not one."""
    match = TEMPORARY.match(name)
    return None if match is None else match["name"] + (match["suffix"] or "")


class AtomicFolder:
    """Context manager: write into ``self.tmp``; on success it replaces ``out``.

    ``out`` may be replaced only when it does not exist or ``recognise(out)`` says it
    is a folder of the same kind; anything else raises ``error`` (user data is never
    overwritten). On an exception (or KeyboardInterrupt) inside the ``with`` block the
    temporary folder is removed and ``out`` is left as it was. Leftovers of a killed
    process are removed by the next writer of the same folder.
    """

    def __init__(
        self,
        out: Path,
        *,
        recognise: Callable[[Path], bool],
        kind: str,
        error: type[TwinError] = TwinError,
    ):
        self.out = Path(out)
        self.tmp = self.out.parent / f".{self.out.name}.partial-{os.getpid()}"
        self._recognise = recognise
        self._kind = kind
        self._error = error

    def check_replaceable(self) -> None:
        if self.out.exists() and not self._recognise(self.out):
            raise self._error(
                f"{self.out} exists and is not an i24-twin {self._kind}; refusing to overwrite "
                "it (choose another --out or remove it yourself)"
            )

    def __enter__(self):
        self.check_replaceable()
        self.out.parent.mkdir(parents=True, exist_ok=True)
        remove_stale(self.out.parent, self.out.name)
        shutil.rmtree(self.tmp, ignore_errors=True)
        self.tmp.mkdir()
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is not None:
            shutil.rmtree(self.tmp, ignore_errors=True)
            if isinstance(exc, OSError) and exc.filename is None:  # a full disk's write
                raise naming(exc, self.out) from exc
            return
        try:
            self.check_replaceable()
            if self.out.exists():
                old = self.out.parent / f".{self.out.name}.old-{os.getpid()}"
                os.rename(self.out, old)
                try:
                    os.rename(self.tmp, self.out)
                except BaseException:
                    os.rename(old, self.out)  # the earlier folder back under its name
                    raise
                shutil.rmtree(old, ignore_errors=True)
            else:
                os.rename(self.tmp, self.out)
        except BaseException:  # a full disk or a read-only folder at the last step
            shutil.rmtree(self.tmp, ignore_errors=True)
            raise


@contextmanager
def atomic_file(out: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``out`` (same suffix, so writers pick the format
    by it); on success it is renamed to ``out``, on any error it is removed and
    ``out`` is left as it was."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.stem}.partial-{os.getpid()}{out.suffix}")
    try:
        yield tmp
        os.replace(tmp, out)
    except OSError as error:
        if error.filename is None:  # a full disk's write names no file
            raise naming(error, out) from error
        raise
    finally:
        tmp.unlink(missing_ok=True)


def remove_stale(parent: Path, name: str = "*") -> None:
    """Remove what writers of ``parent/name`` (a glob) left behind when they were killed
    (their process is gone): temporary folders and files, and put back an earlier
    output that a writer killed between its two renames had moved aside."""
    for stale in sorted(Path(parent).glob(f".{name}.*-*")):
        match = TEMPORARY.match(stale.name)
        if match is None or _pid_alive(match["pid"]):
            continue
        out = stale.with_name(output_name(stale.name))
        if match["kind"] == "old" and not out.exists():
            os.rename(stale, out)
        elif stale.is_dir():
            shutil.rmtree(stale, ignore_errors=True)
        else:
            stale.unlink(missing_ok=True)


def marked_as(folder: Path, marker: str, fmt: str) -> bool:
    """True when ``folder`` holds the JSON file ``marker`` whose "format" is ``fmt``."""
    path = Path(folder) / marker
    if not path.is_file():
        return False
    try:
        return json.loads(path.read_text()).get("format") == fmt
    except (OSError, ValueError, AttributeError):
        return False


def _pid_alive(pid: str) -> bool:
    try:
        os.kill(int(pid), 0)
    except (ValueError, ProcessLookupError):
        return False
    except PermissionError:
        return True
    return True
