"""I-24 MOTION day files: one JSON array of trajectory documents, many GB large.
Reading: gzip'd or not, parsed as a stream (ijson) one document at a time, with the
non-standard ``NaN`` and ``Infinity`` tokens some writers emit read as ``null``.
Writing (:func:`write_day`): the twin's test data (the synthesiser's, SUMO's) in the
real layout."""

import contextlib
import gzip
import zlib
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import BinaryIO

import ijson
import numpy as np
import orjson

from twin.core import i24
from twin.core.atomic import atomic_file
from twin.core.errors import DataFormatError
from twin.core.progress import progress_bar

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


def write_day(path, road, anchor: float, vid: np.ndarray, tracks: list,
              vehicle_class: np.ndarray, dimensions: np.ndarray, *, flag: str = "synthetic",
              progress: bool = False) -> Path:  # fmt: skip
    """Write recorded tracks as an I-24 MOTION day file (a JSON array of documents,
    ordered by first time), each vehicle's ``_id`` made of ``anchor`` [s unix], the
    road and its id in ``vid``.

    Args:
        road: the carriageway (``twin.core.i24.Road``). tracks: per vehicle (t [s unix],
            x [m], y [m]) arrays in the road frame, back centre. vehicle_class: (m,)
            I-24 classes. dimensions: (m, 3) length, width, height [m]. flag: the
            documents' ``flags`` entry (who made the data).

    Written to a temporary file beside ``path`` and renamed, so an interrupted write
    never leaves a truncated file under the final name.
    """
    path = Path(path)
    order = np.argsort([track[0][0] for track in tracks], kind="stable")
    prefix = f"{int(anchor) & 0xFFFFFFFF:08x}{road.code:02x}"
    with atomic_file(path) as tmp, open(tmp, "wb") as out:
        out.write(b"[\n")
        for n, i in enumerate(progress_bar(order, progress=progress, desc="write", leave=False)):
            t, x, y = tracks[i]
            x_ft = np.round(i24.x_feet(x, road), 2)
            y_ft = np.round(i24.y_feet(y, road), 2)
            t = np.round(t, 3)
            length, width, height = (dimensions[i] / i24.FT).round(3).tolist()
            doc = {
                "_id": {"$oid": f"{prefix}{int(vid[i]):014x}"},
                "timestamp": t.tolist(),
                "first_timestamp": float(t[0]),
                "last_timestamp": float(t[-1]),
                "x_position": x_ft.tolist(),
                "y_position": y_ft.tolist(),
                "starting_x": float(x_ft[0]),
                "ending_x": float(x_ft[-1]),
                "length": length,
                "width": width,
                "height": height,
                "coarse_vehicle_class": int(vehicle_class[i]),
                "fine_vehicle_class": int(vehicle_class[i]),
                "direction": road.direction,
                "merged_ids": [],
                "fragment_ids": [],
                "compute_node_id": 0,
                "local_fragment_id": int(vid[i]),
                "road_segment_ids": [],
                "configuration_id": 0,
                "flags": [flag],
                "x_score": 0.0,
                "y_score": 0.0,
                "feasibility": 1.0,
            }
            if n:
                out.write(b",\n")
            out.write(orjson.dumps(doc))
        out.write(b"\n]\n")
    return path
