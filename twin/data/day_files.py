"""Reading I-24 MOTION day files: one JSON array of trajectory documents, many GB large,
gzip'd or not, parsed as a stream (ijson) one document at a time, with the
non-standard ``NaN`` and ``Infinity`` tokens some writers emit read as ``null``."""

import contextlib
import gzip
import zlib
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import BinaryIO

import ijson

from twin.core.errors import DataFormatError

READ_CHUNK = 1 << 16  # [bytes]


class _CountingReader:
    """A binary file wrapper that counts the bytes handed to the parser."""

    def __init__(self, raw: BinaryIO, on_read: Callable[[int], object]):
        self.raw = raw
        self.position = 0
        self.on_read = on_read

    def read(self, size: int = -1) -> bytes:
        data = self.raw.read(size)
        self.position += len(data)
        self.on_read(len(data))
        return data


def documents(path: Path, on_read: Callable[[int], object]) -> Iterator:
    """Yield the documents of one day file as Python objects, one at a time.

    Raises:
        DataFormatError: naming the file and the byte position, when the file is not
            a JSON array or breaks off, and the file when its gzip data do.
    """
    try:
        yield from _documents(path, on_read)
    except (EOFError, gzip.BadGzipFile, zlib.error) as error:
        raise DataFormatError(
            f"{path}: the gzip data are truncated or corrupt ({error}); an interrupted "
            "download or copy leaves a file like this: fetch it again"
        ) from None


def _documents(path: Path, on_read: Callable[[int], object]) -> Iterator:
    with open(path, "rb") as file, _decompressed(file) as raw:
        head = raw.read(READ_CHUNK)
        stripped = head.lstrip()
        if not stripped:
            raise DataFormatError(
                f"{path}: empty file, expected a JSON array of I-24 MOTION documents"
            )
        if stripped[:1] != b"[":
            offset = len(head) - len(stripped)
            raise DataFormatError(
                f"{path}: not an I-24 MOTION day file: expected a JSON array of trajectory "
                f"documents, found {stripped[:20]!r} at byte {offset}"
            )
        reader = _CountingReader(_Prepend(head, raw), on_read)
        index = -1
        try:
            for index, doc in enumerate(ijson.items(reader, "item", use_float=True)):  # noqa: B007
                yield doc
        except ijson.JSONError as error:
            raise DataFormatError(
                f"{path}: malformed or truncated JSON after document {index + 1} "
                f"(parser stopped within bytes {max(reader.position - READ_CHUNK, 0)}.."
                f"{reader.position}): {str(error).splitlines()[0]}"
            ) from None


def _decompressed(file: BinaryIO):
    """The file itself, or a gzip reader over it when it starts with gzip's magic bytes."""
    if file.peek(2)[:2] == b"\x1f\x8b":
        return gzip.GzipFile(fileobj=file)
    return contextlib.nullcontext(file)


class _Prepend:
    """A reader that returns ``head`` first, then the rest of ``raw``.

    Non-standard ``NaN``, ``Infinity`` and ``-Infinity`` tokens (Python's json module
    writes them) are handed to the parser as ``null``, which the validation counts as
    a non-finite sample. A few bytes are held back at each chunk's end so that a
    token split between chunks is still replaced.
    """

    _HOLD = len(b"-Infinity")

    def __init__(self, head: bytes, raw: BinaryIO):
        self.pending = head
        self.raw = raw

    def read(self, size: int = -1) -> bytes:
        if size == 0:  # ijson probes with read(0) to tell bytes from text
            return b""
        while True:
            more = self.raw.read(size if size and size > 0 else READ_CHUNK)
            data = self.pending + more
            if not more:
                self.pending = b""
                return _nonfinite_to_null(data)
            cut = max(len(data) - self._HOLD, 0)
            self.pending = data[cut:]
            if cut:
                return _nonfinite_to_null(data[:cut])


def _nonfinite_to_null(data: bytes) -> bytes:
    if b"N" not in data and b"I" not in data:
        return data
    return (
        data.replace(b"-Infinity", b"null").replace(b"Infinity", b"null").replace(b"NaN", b"null")
    )
