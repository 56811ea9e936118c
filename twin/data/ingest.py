"""Streaming ingest of I-24 MOTION day files into a trajectory store.

A day file is one JSON array of trajectory documents, many GB large. It is parsed
as a stream (ijson), each document is validated and converted to the road frame
(:mod:`twin.core.i24`), and samples are spilled to disk in time buckets as they
come, so peak memory depends on the traffic in one time bucket, not on file size.
A final pass sorts each bucket by (trajectory, time) and writes one Parquet row
group per bucket. Everything is written under a temporary folder beside the
output and renamed into place at the end: an interrupted ingest leaves the
previous store (if any) untouched and no half-store behind.
"""

import math
import os
import shutil
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.ipc as ipc

from twin.core import i24, ramps
from twin.core.errors import DataFormatError
from twin.core.i24 import Road
from twin.core.progress import progress_bar
from twin.data.day_files import documents
from twin.data.store import (
    SAMPLE_SCHEMA,
    TRAJECTORY_SCHEMA,
    StoreWriter,
    check_replaceable,
)

MIN_MARGIN = 400.0  # [m] ghost windows need this much road beyond each end of the segment
MAX_DIMENSION_FT = 200.0  # [ft] longer than any road vehicle: a tracking error


@dataclass(frozen=True)
class IngestOptions:
    """How to ingest.

    Attributes:
        margin: [m] road kept beyond each end of the segment; None keeps the whole
            recorded range. At least ``MIN_MARGIN`` (the ghost windows need it).
        bucket: [s] time span of one Parquet row group (the unit of a time query).
        speed_smoothing: [s] standard deviation of the Gaussian that smooths the
            finite-difference speed, so tracking noise gives no absurd accelerations.
        flush_rows: samples buffered in memory before they are spilled to disk.
    """

    margin: float | None = None
    bucket: float = 60.0
    speed_smoothing: float = 0.5
    flush_rows: int = 1_000_000

    def __post_init__(self):
        if self.margin is not None and not (
            math.isfinite(self.margin) and self.margin >= MIN_MARGIN
        ):
            raise ValueError(
                f"margin must be a finite number of metres >= {MIN_MARGIN:g} "
                f"(the ghost windows need that much road beyond the segment), got {self.margin!r}"
            )
        if not (math.isfinite(self.bucket) and self.bucket > 0):
            raise ValueError(f"bucket must be a positive number of seconds, got {self.bucket!r}")
        if not (math.isfinite(self.speed_smoothing) and self.speed_smoothing >= 0):
            raise ValueError(f"speed_smoothing must be >= 0 seconds, got {self.speed_smoothing!r}")
        if self.flush_rows < 1:
            raise ValueError(f"flush_rows must be >= 1, got {self.flush_rows!r}")

    @property
    def x_range(self) -> tuple[float, float] | None:
        """[m] the road-frame x range kept, or None for all of it."""
        if self.margin is None:
            return None
        return (-self.margin, i24.SEGMENT_LENGTH + self.margin)


@dataclass
class IngestReport:
    """What an ingest read, kept and rejected (by reason)."""

    documents_read: int = 0
    documents_kept: int = 0
    documents_rejected: Counter = field(default_factory=Counter)
    samples_read: int = 0
    samples_kept: int = 0
    samples_rejected: Counter = field(default_factory=Counter)
    samples_outside_margin: int = 0
    documents_outside_margin: int = 0

    def as_dict(self) -> dict:
        return {
            "documents": {
                "read": self.documents_read,
                "kept": self.documents_kept,
                "rejected": dict(sorted(self.documents_rejected.items())),
                "outside_margin": self.documents_outside_margin,
            },
            "samples": {
                "read": self.samples_read,
                "kept": self.samples_kept,
                "rejected": dict(sorted(self.samples_rejected.items())),
                "outside_margin": self.samples_outside_margin,
            },
        }


class _Rejected(Exception):
    """A document fails validation; ``reason`` is its counter key."""

    def __init__(self, reason: str):
        super().__init__(reason)
        self.reason = reason


@dataclass
class _Trajectory:
    """One valid document in the road frame (samples after validation)."""

    oid: str
    road: Road
    vehicle_class: int
    fine_class: int
    length: float  # [m]
    width: float  # [m]
    height: float  # [m]
    t: np.ndarray  # (n,) float64 [s]
    x: np.ndarray  # (n,) float64 [m]
    y: np.ndarray  # (n,) float64 [m]
    speed: np.ndarray  # (n,) float64 [m/s]
    lane: np.ndarray  # (n,) int8


def ingest(
    sources: Sequence[str | os.PathLike],
    out: str | os.PathLike,
    options: IngestOptions = IngestOptions(),
    *,
    progress: bool = True,
) -> IngestReport:
    """Ingest I-24 MOTION day files into a store folder at ``out``.

    Args:
        sources: JSON (or gzip'd JSON) day files, each a JSON array of documents.
        out: the store folder; an existing store there is replaced atomically.
        options: margin, bucket size, smoothing.
        progress: show a progress bar over the bytes read.

    Returns:
        The counts of what was read, kept and rejected.

    Raises:
        DataFormatError: a file is not a JSON array of documents, or is truncated
            (the message names the file and the position), or no document is valid
            (nothing is written).
        StoreError: ``out`` exists and is not a store (it is never overwritten).
        FileNotFoundError: a source is missing.
    """
    paths = [Path(s) for s in sources]
    if not paths:
        raise ValueError("no input files given")
    for p in paths:
        if not p.is_file():
            raise FileNotFoundError(f"input file not found: {p}")
    out = Path(out)
    check_replaceable(out)
    report = IngestReport()
    with StoreWriter(out) as writer:
        spill = _Spill(writer.tmp / "spill", options.bucket, options.flush_rows)
        trajectories = _TrajectoryTable()
        seen: set[str] = set()
        total = sum(p.stat().st_size for p in paths)
        with progress_bar(
            progress=progress, total=total, unit="B", unit_scale=True, desc="ingest", leave=False
        ) as bar:
            for source_index, path in enumerate(paths):
                for doc in documents(path, bar.update):
                    _ingest_document(doc, source_index, options, report, seen, spill, trajectories)
        if report.documents_kept == 0:  # an empty store would replace a good one
            raise DataFormatError(_nothing_kept(paths, out, report))
        spill.flush()
        lane_counts = _write_samples(writer, spill)
        writer.write_table("trajectories.parquet", trajectories.to_arrow())
        writer.write_metadata(_metadata(paths, options, report, trajectories, lane_counts))
    return report


def _nothing_kept(paths: list[Path], out: Path, report: IngestReport) -> str:
    """Why an ingest kept no document: the rejections, or the margin."""
    reasons = ", ".join(f"{k} {v}" for k, v in sorted(report.documents_rejected.items()))
    why = f"no valid I-24 MOTION document among {report.documents_read} read"
    if report.documents_outside_margin:
        why = (
            f"no document within the margin ({report.documents_outside_margin} of "
            f"{report.documents_read} have no sample in the lanes within it: a larger --margin "
            "keeps them)"
        )
    elif reasons:
        why += f" (rejected: {reasons})"
    kept = f" and the store at {out} is kept as it was" if out.exists() else ""
    return f"{', '.join(map(str, paths))}: {why}; nothing was written{kept}"


def _ingest_document(doc, source_index, options, report, seen, spill, trajectories):
    report.documents_read += 1
    try:
        traj = _parse_document(doc, options, report)
        if traj.oid in seen:
            raise _Rejected("duplicate_id")
    except _Rejected as rejected:
        report.documents_rejected[rejected.reason] += 1
        return
    seen.add(traj.oid)
    x_range = options.x_range
    if x_range is not None:
        inside = (traj.x >= x_range[0]) & (traj.x <= x_range[1])
        n_out = int(np.count_nonzero(~inside))
        report.samples_outside_margin += n_out
        if n_out:
            if not np.any(inside & (traj.lane != ramps.RAMP_LANE)):
                # none of it in the four lanes within the margin: left out whole, every
                # sample counted as left out by the margin
                report.documents_outside_margin += 1
                report.samples_outside_margin += len(inside) - n_out
                return
            traj = _select(traj, inside)
    tid = trajectories.add(traj, source_index)
    spill.add(traj.road, tid, traj)
    report.documents_kept += 1
    report.samples_kept += len(traj.t)


def _select(traj: _Trajectory, mask: np.ndarray) -> _Trajectory:
    return _Trajectory(
        traj.oid,
        traj.road,
        traj.vehicle_class,
        traj.fine_class,
        traj.length,
        traj.width,
        traj.height,
        traj.t[mask],
        traj.x[mask],
        traj.y[mask],
        traj.speed[mask],
        traj.lane[mask],
    )


def _parse_document(doc, options: IngestOptions, report: IngestReport) -> _Trajectory:
    """Validate one document and convert it to the road frame; raise _Rejected if unusable."""
    if not isinstance(doc, dict):
        raise _Rejected("not_an_object")
    for name in ("_id", *i24.REQUIRED_ARRAYS, *i24.REQUIRED_SCALARS):
        if name not in doc:
            raise _Rejected(f"missing_field:{name}")
    oid = doc["_id"]
    if isinstance(oid, dict):
        oid = oid.get("$oid")
    if not isinstance(oid, str) or not oid:
        raise _Rejected("wrong_type:_id")
    direction = _number(doc, "direction")
    if direction not in (1, -1):
        raise _Rejected("unknown_direction")
    road = Road.parse(int(direction))
    dims = [_number(doc, name) for name in ("length", "width", "height")]
    for name, value in zip(("length", "width", "height"), dims, strict=True):
        if not 0 < value <= MAX_DIMENSION_FT:
            raise _Rejected(f"invalid_value:{name}")
    vehicle_class = _number(doc, "coarse_vehicle_class")
    if vehicle_class not in range(len(i24.VEHICLE_CLASSES)):
        raise _Rejected("invalid_value:coarse_vehicle_class")
    fine = doc.get("fine_vehicle_class")
    fine_class = int(fine) if _is_number(fine) and fine in range(len(i24.VEHICLE_CLASSES)) else -1

    t, x_ft, y_ft = (_array(doc, name) for name in i24.REQUIRED_ARRAYS)
    n = len(t)
    if len(x_ft) != n or len(y_ft) != n:
        raise _Rejected("array_length_mismatch")
    if n == 0:
        raise _Rejected("empty_trajectory")
    report.samples_read += n

    keep = _valid_samples(t, x_ft, y_ft, road, report.samples_rejected)
    if np.count_nonzero(keep) < 2:
        report.samples_rejected["too_few_valid_samples"] += int(np.count_nonzero(keep))
        raise _Rejected("too_few_valid_samples")
    t, x, y = t[keep], i24.road_x(x_ft[keep], road), i24.road_y(y_ft[keep])
    lane = ramps.lane_at(road, x, y)
    if np.count_nonzero(lane != ramps.RAMP_LANE) < 2:  # a vehicle seen on its ramp only
        report.samples_rejected["too_few_valid_samples"] += int(np.count_nonzero(keep))
        raise _Rejected("too_few_valid_samples")
    return _Trajectory(
        oid=oid,
        road=road,
        vehicle_class=int(vehicle_class),
        fine_class=fine_class,
        length=dims[0] * i24.FT,
        width=dims[1] * i24.FT,
        height=dims[2] * i24.FT,
        t=t,
        x=x,
        y=y,
        speed=_speeds(t, x, lane, options.speed_smoothing),
        lane=lane,
    )


def _speeds(t: np.ndarray, x: np.ndarray, lane: np.ndarray, sigma: float) -> np.ndarray:
    """:func:`smoothed_speed` of the samples in the four lanes from those samples alone
    (as when the ramps' were not kept), of the ramps' samples from all of them."""
    speed = smoothed_speed(t, x, sigma)
    through = lane != ramps.RAMP_LANE
    if not through.all():
        speed[through] = smoothed_speed(t[through], x[through], sigma)
    return speed


def _valid_samples(t, x_ft, y_ft, road: Road, rejected: Counter) -> np.ndarray:
    """Mask of usable samples; each rejected sample is counted once, under its first reason."""
    keep = np.isfinite(t) & np.isfinite(x_ft) & np.isfinite(y_ft)
    _count(rejected, "non_finite", ~keep)

    previous_max = np.maximum.accumulate(np.where(keep, t, -np.inf))
    increasing = np.ones_like(keep)
    increasing[1:] = t[1:] > previous_max[:-1]
    keep &= ~_count(rejected, "non_increasing_timestamp", keep & ~increasing)

    # I-24 MOTION: y < 0 eastbound, y > 0 westbound.
    keep &= ~_count(rejected, "wrong_side_of_median", keep & (np.sign(y_ft) == road.direction))
    with np.errstate(invalid="ignore"):  # NaN positions are rejected above
        outside = ramps.lane_at(road, i24.road_x(x_ft, road), i24.road_y(y_ft)) == 0
    keep &= ~_count(rejected, "outside_lane_bands", keep & outside)
    return keep


def _count(counter: Counter, reason: str, bad: np.ndarray) -> np.ndarray:
    """Add the number of True entries of ``bad`` to ``counter[reason]``; return ``bad``."""
    n = int(np.count_nonzero(bad))
    if n:
        counter[reason] += n
    return bad


def smoothed_speed(t: np.ndarray, x: np.ndarray, sigma: float) -> np.ndarray:
    """Speed [m/s] at each sample from finite differences, Gaussian-smoothed in time.

    Args:
        t: (n,) float64 [s], strictly increasing, n >= 2.
        x: (n,) float64 [m] along the direction of travel.
        sigma: [s] standard deviation of the smoothing kernel; 0 for none.

    Returns:
        (n,) float64, never negative (a freeway vehicle does not reverse; negative
        values are tracking noise at standstill).
    """
    t_mid = 0.5 * (t[1:] + t[:-1])
    v = np.interp(t, t_mid, np.diff(x) / np.diff(t))
    n = len(v)
    if sigma > 0 and n > 2:
        sigma_samples = sigma / float(np.median(np.diff(t)))
        half = min(math.ceil(3 * sigma_samples), (n - 1) // 2)
        if half >= 1:
            kernel = np.exp(-0.5 * (np.arange(-half, half + 1) / sigma_samples) ** 2)
            v = np.convolve(v, kernel, "same") / np.convolve(np.ones(n), kernel, "same")
    return np.maximum(v, 0.0)


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _number(doc: dict, name: str) -> float:
    value = doc[name]
    if not _is_number(value):
        raise _Rejected(f"wrong_type:{name}")
    if not math.isfinite(value):
        raise _Rejected(f"non_finite:{name}")
    return value


def _array(doc: dict, name: str) -> np.ndarray:
    """A numeric sample array; ``null`` entries become NaN (counted later as non-finite)."""
    value = doc[name]
    if not isinstance(value, list):
        raise _Rejected(f"wrong_type:{name}")
    array = np.array(value)
    if array.dtype.kind == "O" and all(v is None or _is_number(v) for v in value):
        array = np.array(value, dtype=np.float64)
    if array.ndim != 1 or (array.size and array.dtype.kind not in "iuf"):
        raise _Rejected(f"wrong_type:{name}")
    return array.astype(np.float64)


class _TrajectoryTable:
    """Per-trajectory metadata, one row per kept document, in order of arrival (= tid)."""

    def __init__(self):
        self.columns = {name: [] for name in TRAJECTORY_SCHEMA.names}

    def add(self, traj: _Trajectory, source_index: int) -> int:
        tid = len(self.columns["tid"])
        mask = 0
        for lane in np.unique(traj.lane):
            mask |= 1 << (-int(lane) - 1)
        # the row describes the vehicle in the through lanes, as every reader of the
        # store but the ramps' own uses it (samples on an acceleration lane are kept,
        # lane -5, and marked in lanes_seen)
        through = np.flatnonzero(traj.lane != ramps.RAMP_LANE)
        first, last = through[0], through[-1]
        row = {
            "tid": tid,
            "id": traj.oid,
            "road": traj.road.value,
            "vehicle_class": traj.vehicle_class,
            "fine_class": traj.fine_class,
            "length": traj.length,
            "width": traj.width,
            "height": traj.height,
            "t_first": float(traj.t[first]),
            "t_last": float(traj.t[last]),
            "x_first": float(traj.x[first]),
            "x_last": float(traj.x[last]),
            "n_samples": len(through),
            "lanes_seen": mask,
            "source": source_index,
        }
        for name, value in row.items():
            self.columns[name].append(value)
        return tid

    def to_arrow(self) -> pa.Table:
        return pa.table(self.columns, schema=TRAJECTORY_SCHEMA)


class _Spill:
    """Samples buffered in memory and spilled to Arrow IPC files by (road, time bucket)."""

    def __init__(self, folder: Path, bucket: float, flush_rows: int):
        self.folder = folder
        self.bucket = bucket
        self.flush_rows = flush_rows
        self.buffers: dict[Road, list[dict[str, np.ndarray]]] = {road: [] for road in Road}
        self.rows = 0
        self.sequence = 0
        self.buckets: dict[Road, set[int]] = {road: set() for road in Road}

    def add(self, road: Road, tid: int, traj: _Trajectory) -> None:
        n = len(traj.t)
        self.buffers[road].append(
            {
                "tid": np.full(n, tid, np.int32),
                "t": traj.t,
                "x": traj.x,
                "y": traj.y.astype(np.float32),
                "speed": traj.speed.astype(np.float32),
                "lane": traj.lane,
            }
        )
        self.rows += n
        if self.rows >= self.flush_rows:
            self.flush()

    def flush(self) -> None:
        for road, parts in self.buffers.items():
            if not parts:
                continue
            columns = {
                name: np.concatenate([p[name] for p in parts]) for name in SAMPLE_SCHEMA.names
            }
            bucket = np.floor(columns["t"] / self.bucket).astype(np.int64)
            order = np.argsort(bucket, kind="stable")
            bucket = bucket[order]
            starts = np.flatnonzero(np.r_[True, bucket[1:] != bucket[:-1]])
            ends = np.r_[starts[1:], len(bucket)]
            for start, end in zip(starts, ends, strict=True):
                key = int(bucket[start])
                rows = order[start:end]
                table = pa.table(
                    {name: col[rows] for name, col in columns.items()}, schema=SAMPLE_SCHEMA
                )
                folder = self.folder / road.value / str(key)
                folder.mkdir(parents=True, exist_ok=True)
                with ipc.new_file(folder / f"{self.sequence:08d}.arrow", SAMPLE_SCHEMA) as sink:
                    sink.write_table(table)
                self.buckets[road].add(key)
            parts.clear()
        self.sequence += 1
        self.rows = 0

    def read_bucket(self, road: Road, key: int) -> pa.Table:
        folder = self.folder / road.value / str(key)
        tables = []
        for path in sorted(folder.iterdir()):
            with ipc.open_file(path) as source:
                tables.append(source.read_all())
        shutil.rmtree(folder)
        return pa.concat_tables(tables)


def _write_samples(writer: StoreWriter, spill: _Spill) -> dict:
    """Sort each spilled bucket by (tid, t) and write it as one row group; return lane counts."""
    lane_counts = {}
    for road in Road:
        counts = Counter()
        keys = sorted(spill.buckets[road])
        if not keys:
            continue
        with writer.parquet(f"samples_{road.value}.parquet", SAMPLE_SCHEMA) as parquet:
            for key in keys:
                table = spill.read_bucket(road, key)
                tid = table.column("tid").to_numpy()
                t = table.column("t").to_numpy()
                table = table.take(np.lexsort((t, tid)))
                parquet.write_table(table, row_group_size=table.num_rows)
                lanes, n = np.unique(table.column("lane").to_numpy(), return_counts=True)
                counts.update(dict(zip(lanes.tolist(), n.tolist(), strict=True)))
        lane_counts[road.value] = {
            str(lane): counts[lane] for lane in (*i24.LANES, ramps.RAMP_LANE)
        }
    return lane_counts


def _metadata(paths, options, report, trajectories, lane_counts) -> dict:
    table = trajectories.columns
    road_col = np.array(table["road"], dtype=object)
    roads = {}
    for road in Road:
        rows = road_col == road.value
        if not rows.any():
            continue
        t_first = np.array(table["t_first"])[rows]
        t_last = np.array(table["t_last"])[rows]
        xs = np.r_[np.array(table["x_first"])[rows], np.array(table["x_last"])[rows]]
        roads[road.value] = {
            "trajectories": int(rows.sum()),
            "samples": int(sum(lane_counts[road.value].values())),  # the ramps' too
            "samples_per_lane": lane_counts[road.value],
            "t_min": float(t_first.min()),
            "t_max": float(t_last.max()),
            "x_min": float(xs.min()),
            "x_max": float(xs.max()),
        }
    return {
        "sources": [{"name": p.name, "bytes": p.stat().st_size} for p in paths],
        "options": {
            "margin_m": options.margin,
            "x_range_m": options.x_range,
            "bucket_s": options.bucket,
            "speed_smoothing_s": options.speed_smoothing,
        },
        "ingest": report.as_dict(),
        "roads": roads,
    }
