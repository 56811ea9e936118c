"""The recording in memory: one road of a store as arrays indexed by time, loaded once
per process and answered by compiled kernels.

Every trajectory is resampled onto one time grid (``GRID_DT``, the data's 25 Hz) from
the frame before its first sample to the frame after its last (its samples on an
on-ramp's acceleration lane, lane -5, included, though the store's trajectory table
describes the four lanes only): its position, lateral
offset and speed at each grid time, interpolated linearly between its samples and
extended along its first and last piece beyond them. Between two frames a query
interpolates linearly again, so a snapshot departs from the samples' polyline by at
most a quarter of its largest second difference (the chord across one kink) and is
exact on a straight piece. A frame inside a gap of more than ``MAX_GAP`` between two
samples is NaN: the vehicle is absent there, as it is before its first and after its
last sample.

A time index finds the vehicles in an x window without looking at the others: per
second of the recording (a bucket), the trajectories present in it, sorted by the
least x they hold in it, and the most any of them moves within it.

The arrays are built from the store's Parquet files once per machine (a time block
at a time, so that a day of many gigabytes never sits in memory whole), kept as
``.npy`` files inside the store (``STORE/.recording/ROAD-KEY``; where the store is
read-only, in the twin's cache, ``$I24_TWIN_CACHE/recording-KEY-ROAD``), and
memory-mapped by every process that needs them (:func:`load_recording`): worker
processes share the pages, and no query reads Parquet again. A small road (fewer than
``IN_MEMORY_SAMPLES`` samples) is built in memory by each process instead.

Layout (:class:`RecordingArrays`; ``r`` numbers the road's trajectories, in store
order): per trajectory ``tid`` (the store's), ``frame0`` (its first frame), ``count``
(its frames), ``offset`` (where they start in the frame arrays), ``t_first``,
``t_last``, ``length``, ``width``, ``height``, ``vehicle_class``; per frame ``x``
[m, back centre], ``y`` [m], ``speed`` [m/s]; per bucket ``bucket_start`` (offsets
into ``bucket_r``, ``bucket_x``) and ``bucket_pad`` [m].
"""

import hashlib
import json
import math
import os
import shutil
from collections import namedtuple
from pathlib import Path

import numpy as np

from twin.core.atomic import AtomicFolder, marked_as
from twin.core.errors import NoVehicleNearError, StoreError
from twin.core.i24 import Road
from twin.core.jit import kernel
from twin.core.locks import build_lock
from twin.core.paths import cache_dir
from twin.core.ramps import RAMP_LANE
from twin.core.ramps import lane_of_y as lane_of
from twin.core.timeutil import format_local
from twin.data.store import TrajectoryStore

GRID_DT = 0.04  # [s] the grid's step (the data's 25 Hz)
MAX_GAP = 1.0  # [s] a vehicle is absent inside longer gaps between its samples
BUCKET_S = 1.0  # [s] the time index's bucket
BLOCK_S = 120.0  # [s] of samples read from the store at a time while building
PRESENT_EPS = 1e-6  # [s] tolerance on a trajectory's first and last time
IN_MEMORY_SAMPLES = 2_000_000  # a road with fewer samples is built in memory, not cached
FORMAT = "i24-twin-recording"
VERSION = 2  # 2: samples on an on-ramp's acceleration lane replayed too
MARKER = "recording.json"
CACHE_FOLDER = ".recording"  # inside a store: its cached recordings

RecordingArrays = namedtuple(
    "RecordingArrays",
    "base dt bucket_s tid frame0 count offset t_first t_last length width height "
    "vehicle_class x y speed bucket_start bucket_r bucket_x bucket_pad",
)
_PER_TRAJECTORY = (
    "tid", "frame0", "count", "offset", "t_first", "t_last", "length", "width", "height",
    "vehicle_class",
)  # fmt: skip
_ARRAYS = (
    *_PER_TRAJECTORY,
    "x",
    "y",
    "speed",
    "bucket_start",
    "bucket_r",
    "bucket_x",
    "bucket_pad",
)


# -- kernels ----------------------------------------------------------------------------


@kernel(inline=True)
def replay(rec, r, t):
    """Trajectory ``r`` at unix time ``t`` [s]: (present, x [m], y [m], speed [m/s]);
    the values are 0 where it is absent."""
    if not (rec.t_first[r] - PRESENT_EPS <= t <= rec.t_last[r] + PRESENT_EPS):
        return False, 0.0, 0.0, 0.0
    u = (t - rec.base) / rec.dt
    whole = math.floor(u)
    j = int(whole) - rec.frame0[r]
    last = rec.count[r] - 2
    if j < 0:
        j = 0
    elif j > last:
        j = last
    w = u - (rec.frame0[r] + j)
    k = rec.offset[r] + j
    xa, xb = rec.x[k], rec.x[k + 1]
    if not (math.isfinite(xa) and math.isfinite(xb)):
        return False, 0.0, 0.0, 0.0
    y = rec.y[k] + w * (rec.y[k + 1] - rec.y[k])
    v = rec.speed[k] + w * (rec.speed[k + 1] - rec.speed[k])
    return True, xa + w * (xb - xa), float(y), max(float(v), 0.0)


@kernel(inline=True)
def mean_accel(rec, r, t, span):
    """[m/s^2] trajectory ``r``'s mean acceleration over the ``span`` [s] from unix
    time ``t`` (its speed's change over the span), or 0 where it is absent at either
    end (a recording that ends soon foresees nothing)."""
    if span <= 0.0:
        return 0.0
    here, _, _, v0 = replay(rec, r, t)
    there, _, _, v1 = replay(rec, r, t + span)
    return (v1 - v0) / span if here and there else 0.0


@kernel
def window(rec, t, x_lo, x_hi, out_r, out_x, out_y, out_v):
    """The trajectories present at ``t`` [s] with ``x_lo <= x <= x_hi`` [m], sorted by x:
    their ``r``, x, y and speed written into the ``out_*`` arrays. Returns how many,
    or -1 when there are more than the arrays hold."""
    k = math.floor((t - rec.base) / rec.bucket_s)
    if k < 0 or k >= rec.bucket_pad.size:
        return 0
    a, b = rec.bucket_start[k], rec.bucket_start[k + 1]
    low = x_lo - rec.bucket_pad[k]
    lo, hi = a, b  # the first entry whose least x reaches low
    while lo < hi:
        mid = (lo + hi) // 2
        if rec.bucket_x[mid] < low:
            lo = mid + 1
        else:
            hi = mid
    n = 0
    capacity = out_r.size
    for e in range(lo, b):
        if rec.bucket_x[e] > x_hi:
            break
        r = np.int64(rec.bucket_r[e])  # as every caller's r: one compilation of replay
        present, x, y, v = replay(rec, r, t)
        if not present or x < x_lo or x > x_hi:
            continue
        if n == capacity:
            return -1
        j = n  # insertion by x (the entries come nearly sorted)
        while j > 0 and out_x[j - 1] > x:
            out_r[j], out_x[j], out_y[j], out_v[j] = (
                out_r[j - 1],
                out_x[j - 1],
                out_y[j - 1],
                out_v[j - 1],
            )
            j -= 1
        out_r[j], out_x[j], out_y[j], out_v[j] = r, x, y, v
        n += 1
    return n


@kernel
def windows(rec, times, x_lo, x_hi, out_k, out_r, out_x, out_y, out_v):
    """:func:`window` at each of ``times`` (m,) with its bounds ``x_lo``, ``x_hi`` (m,):
    the rows of all of them, each tagged with its query in ``out_k``. Returns how many,
    or -1 when the arrays are too small."""
    n = 0
    capacity = out_r.size
    for k in range(times.size):
        got = window(rec, times[k], x_lo[k], x_hi[k], out_r[n:], out_x[n:], out_y[n:], out_v[n:])
        if got < 0 or n + got > capacity:
            return -1
        out_k[n : n + got] = k
        n += got
    return n


@kernel
def replay_many(rec, r, times, present, x, y, speed):
    """Trajectories ``r`` (m,) at ``times`` (m,): whether each is present, its x and y
    [m] and its speed [m/s] (0 where absent)."""
    for k in range(r.size):
        present[k], x[k], y[k], speed[k] = replay(rec, r[k], times[k])


def closest_vehicle(store: TrajectoryStore, road: Road, rec, lane: int, x: float, t: float,
                    max_distance: float, max_time: float, speed_scale: float,
                    out) -> tuple:  # fmt: skip
    """:func:`closest` of ``road``'s recording ``rec`` (``out``: its four working
    arrays): (r, time [s], x [m], y [m], speed [m/s]).

    Raises:
        NoVehicleNearError: none within the tolerances; the message names the request
            and what the store covers.
    """
    found = closest(rec, int(lane), float(x), float(t), float(max_distance), float(max_time),
                    float(speed_scale), *out)  # fmt: skip
    if found[0] < 0:
        t_min, t_max = store.time_range(road)
        raise NoVehicleNearError(
            f"no recorded vehicle in lane {lane} of {road.value} within {max_distance:g} m of "
            f"x = {x:g} m and {max_time:g} s of {format_local(t)} CST (unix {t:.2f}); "
            f"the store covers {format_local(t_min)} to {format_local(t_max)} CST on this road"
        )
    return found


@kernel
def closest(rec, lane, x, t, max_distance, max_time, speed_scale, out_r, out_x, out_y, out_v):
    """The recorded vehicle spatio-temporally closest to ``lane``, ``x`` [m] and ``t``
    [s] (:meth:`twin.data.empirical.EmpiricalTraffic.closest`): candidates within
    ``max_distance`` and ``max_time`` at ``t`` and on the grid around it, nearest times
    first; cost ``hypot(dx, speed_scale dt)``, ties to the lower trajectory. Returns
    (r, its time [s], x, y, speed), r -1 where none; ``out_*`` are working arrays."""
    best_cost, best_r, best_t = math.inf, -1, 0.0
    best_x, best_y, best_v = 0.0, 0.0, 0.0
    dt = GRID_DT
    k_low = math.ceil((t - max_time) / dt)
    k_high = math.floor((t + max_time) / dt)
    below = math.floor(t / dt)  # grid times walk away from t on both sides
    above = below + 1
    first = True
    while True:
        if first:
            tau = t
            first = False
        else:
            lower_ok = below >= k_low
            upper_ok = above <= k_high
            if not (lower_ok or upper_ok):
                break
            if lower_ok and (not upper_ok or t - below * dt <= above * dt - t):
                tau = below * dt
                below -= 1
            else:
                tau = above * dt
                above += 1
            if tau < t - max_time - 1e-9 or tau > t + max_time + 1e-9:
                continue
        if best_r >= 0 and speed_scale * abs(tau - t) > best_cost:
            break
        n = window(rec, tau, x - max_distance, x + max_distance, out_r, out_x, out_y, out_v)
        for k in range(max(n, 0)):
            if lane_of(out_y[k]) != lane:
                continue
            cost = math.hypot(out_x[k] - x, speed_scale * (tau - t))
            r = out_r[k]
            if cost < best_cost or (cost == best_cost and rec.tid[r] < rec.tid[best_r]):
                best_cost, best_r, best_t = cost, r, tau
                best_x, best_y, best_v = out_x[k], out_y[k], out_v[k]
    return best_r, best_t, best_x, best_y, best_v


@kernel
def _fill_frames(
    run_r, run_start, run_end, t, x, y, v, frame0, count, offset, t_first, t_last, base, dt,
    max_gap, j_lo, j_hi, out_x, out_y, out_v,
):  # fmt: skip
    """The frames ``j_lo <= j < j_hi`` of the trajectories whose samples (sorted by time)
    are the runs ``run_start[i]:run_end[i]`` of trajectory ``run_r[i]``."""
    for i in range(run_r.size):
        r, s0, s1 = run_r[i], run_start[i], run_end[i]
        first_j = max(frame0[r], j_lo)
        last_j = min(frame0[r] + count[r], j_hi)
        p = s0
        for j in range(first_j, last_j):
            g = base + j * dt
            while p + 2 < s1 and t[p + 1] <= g:
                p += 1
            k = offset[r] + j - frame0[r]
            if s1 - s0 < 2:
                out_x[k] = np.nan
                continue
            a = p if p + 1 < s1 else s1 - 2
            ta, tb = t[a], t[a + 1]
            before = g < t[s0] and t[s0] > t_first[r] + PRESENT_EPS  # cut off: a gap
            after = g > t[s1 - 1] and t[s1 - 1] < t_last[r] - PRESENT_EPS
            if before or after or (ta <= g <= tb and tb - ta > max_gap) or tb <= ta:
                out_x[k] = np.nan
                out_y[k] = np.nan
                out_v[k] = np.nan
                continue
            w = (g - ta) / (tb - ta)
            out_x[k] = x[a] + w * (x[a + 1] - x[a])
            out_y[k] = y[a] + w * (y[a + 1] - y[a])
            out_v[k] = v[a] + w * (v[a + 1] - v[a])


@kernel
def _bucket_ranges(frame0, count, offset, x, base, dt, bucket_s, n_buckets, lo_x, hi_x):
    """Per (bucket, trajectory) the least and largest finite frame x of the trajectory
    among the frames that bound the bucket's times: written into ``lo_x``/``hi_x``
    (n_buckets, R), NaN where it has none."""
    for r in range(frame0.size):
        for f in range(count[r]):
            value = x[offset[r] + f]
            if not math.isfinite(value):
                continue
            g = (frame0[r] + f) * dt  # after base
            k0 = max(math.floor((g - dt) / bucket_s), 0)
            k1 = min(math.floor((g + dt) / bucket_s), n_buckets - 1)
            for k in range(k0, k1 + 1):
                if not lo_x[k, r] <= value:  # NaN (none yet) or larger
                    lo_x[k, r] = value
                if not hi_x[k, r] >= value:
                    hi_x[k, r] = value


# -- loading ------------------------------------------------------------------------------

_LOADED: dict[tuple[str, str], RecordingArrays] = {}


def load_recording(store: TrajectoryStore, road: Road | str) -> RecordingArrays:
    """``road`` of ``store`` as :class:`RecordingArrays`: memory-mapped from the cache,
    built there first if needed (once per machine; other processes wait for it), and
    kept for the rest of the process; a small road (under IN_MEMORY_SAMPLES samples) is
    built in memory instead.

    Raises:
        StoreError: the store has no such road (or a damaged file, named).
    """
    road = Road.parse(road)
    key = (store_key(store), road.value)
    if (
        key not in _LOADED
        and store.metadata["roads"].get(road.value, {}).get("samples", 0) < IN_MEMORY_SAMPLES
    ):
        _LOADED[key] = build(store, road)  # small: built faster than a cache is read
    if key not in _LOADED:
        folder = cached_folder(store, road)
        if not marked_as(folder, MARKER, FORMAT):
            folder.parent.mkdir(parents=True, exist_ok=True)
            with build_lock(folder):
                if not marked_as(folder, MARKER, FORMAT):
                    with AtomicFolder(
                        folder, recognise=lambda p: marked_as(p, MARKER, FORMAT),
                        kind="recording", error=StoreError,
                    ) as out:  # fmt: skip
                        _write(build(store, road), out.tmp, store, road)
                    _remove_stale(folder)
        _LOADED[key] = _read(folder)
    return _LOADED[key]


def cached_folder(store: TrajectoryStore, road: Road | str) -> Path:
    """Where the recording of ``road`` of ``store`` is cached: inside the store
    (``STORE/.recording/ROAD-KEY``, removed with it, as ``calibration.json`` is kept
    there), or where the store's folder is read-only, in the twin's cache folder
    (``recording-KEY-ROAD``)."""
    road = Road.parse(road)
    key = store_key(store)
    if os.access(store.path, os.W_OK):
        return store.path / CACHE_FOLDER / f"{road.value}-{key}"
    return cache_dir() / f"recording-{key}-{road.value}"


def _remove_stale(folder: Path) -> None:
    """Inside a store, the recordings of the same road under older keys (the store was
    written again): they can never be read."""
    if folder.parent.name != CACHE_FOLDER:
        return
    road = folder.name.split("-")[0]
    for old in folder.parent.glob(f"{road}-*"):
        if old != folder and marked_as(old, MARKER, FORMAT):
            shutil.rmtree(old, ignore_errors=True)


def store_key(store: TrajectoryStore) -> str:
    """A digest of what a store holds: its metadata and its files' sizes and times (a
    store written again is a new key); taken once per store object."""
    key = getattr(store, "_recording_key", None)
    if key is None:
        key = _digest(store)
        store._recording_key = key
    return key


def _digest(store: TrajectoryStore) -> str:
    digest = hashlib.sha256((store.path / "metadata.json").read_bytes())
    for path in sorted(store.path.glob("*.parquet")):
        stat = path.stat()
        digest.update(f"{path.name}:{stat.st_size}:{stat.st_mtime_ns}".encode())
    digest.update(f"{VERSION}:{GRID_DT}:{MAX_GAP}:{BUCKET_S}".encode())
    return digest.hexdigest()[:16]


def _write(arrays: RecordingArrays, folder: Path, store: TrajectoryStore, road: Road) -> None:
    for name in _ARRAYS:
        np.save(folder / f"{name}.npy", getattr(arrays, name))
    meta = {
        "format": FORMAT,
        "version": VERSION,
        "store": str(store.path),
        "road": road.value,
        "base": arrays.base,
        "dt": arrays.dt,
        "bucket_s": arrays.bucket_s,
        "trajectories": int(arrays.tid.size),
        "frames": int(arrays.x.size),
    }
    (folder / MARKER).write_text(json.dumps(meta, indent=1) + "\n")


def _read(folder: Path) -> RecordingArrays:
    meta = json.loads((folder / MARKER).read_text())
    # copy-on-write maps: writable arrays (the kernels never write them, so the file and
    # the shared pages stay as they are), typed as the in-memory ones are; read-only
    # maps would be another type and compile every kernel a second time
    arrays = {name: np.load(folder / f"{name}.npy", mmap_mode="c") for name in _ARRAYS}
    # small arrays are read whole: the kernels take plain arrays (a memory map is one)
    return RecordingArrays(base=float(meta["base"]), dt=float(meta["dt"]),
                           bucket_s=float(meta["bucket_s"]), **arrays)  # fmt: skip


def build(store: TrajectoryStore, road: Road | str) -> RecordingArrays:
    """The recording of ``road`` from the store's files (the module doc), in memory.

    Raises:
        StoreError: the store has no such road.
    """
    road = Road.parse(road)
    meta = store.trajectory_arrays
    rows = np.flatnonzero((meta["road"] == road.value) & (meta["n_samples"] >= 2))
    rows = rows[meta["t_last"][rows] > meta["t_first"][rows]]
    t_first, t_last = _with_ramp_samples(store, road, rows)
    t_min, t_max = store.time_range(road)
    if rows.size:
        t_min, t_max = min(t_min, t_first.min()), max(t_max, t_last.max())
    base = math.floor(t_min)
    frame0 = np.floor((t_first - base) / GRID_DT + 1e-9).astype(np.int64)
    frame1 = np.ceil((t_last - base) / GRID_DT - 1e-9).astype(np.int64)
    frame1 = np.maximum(frame1, frame0 + 1)
    count = (frame1 - frame0 + 1).astype(np.int64)
    offset = np.concatenate([[0], np.cumsum(count)[:-1]]).astype(np.int64)
    total = int(count.sum())
    x, y, v = (
        np.full(total, np.nan),
        np.full(total, np.nan, np.float32),
        np.full(total, np.nan, np.float32),
    )
    local = np.full(meta["tid"].size, -1, dtype=np.int64)
    local[rows] = np.arange(rows.size)
    for start in np.arange(base, t_max + BLOCK_S, BLOCK_S):
        s = store.samples(
            road, start - MAX_GAP - GRID_DT, start + BLOCK_S + MAX_GAP + GRID_DT, ramps=True
        )
        r = local[s["tid"]]
        keep = r >= 0
        if not keep.any():
            continue
        r, t = r[keep], s["t"][keep]
        runs = np.flatnonzero(np.r_[True, r[1:] != r[:-1]])
        ends = np.append(runs[1:], r.size)
        j_lo = math.floor((start - base) / GRID_DT + 1e-9)
        j_hi = math.floor((start + BLOCK_S - base) / GRID_DT + 1e-9)
        _fill_frames(
            r[runs], runs, ends, t, s["x"][keep], s["y"][keep].astype(np.float64),
            s["speed"][keep].astype(np.float64), frame0, count, offset, t_first, t_last,
            float(base), GRID_DT, MAX_GAP, j_lo, j_hi, x, y, v,
        )  # fmt: skip
    n_buckets = math.floor((t_max - base) / BUCKET_S) + 1
    bucket_start, bucket_r, bucket_x, bucket_pad = _buckets(
        frame0, count, offset, x, float(base), n_buckets
    )
    sizes = {name: meta[name][rows].astype(np.float64) for name in ("length", "width", "height")}
    return RecordingArrays(
        base=float(base), dt=GRID_DT, bucket_s=BUCKET_S, tid=rows.astype(np.int32),
        frame0=frame0, count=count, offset=offset, t_first=t_first.astype(np.float64),
        t_last=t_last.astype(np.float64), vehicle_class=meta["vehicle_class"][rows].astype(np.int8),
        x=x, y=y, speed=v, bucket_start=bucket_start, bucket_r=bucket_r, bucket_x=bucket_x,
        bucket_pad=bucket_pad, **sizes,
    )  # fmt: skip


def _with_ramp_samples(store: TrajectoryStore, road: Road, rows):
    """(t_first, t_last) [s] of trajectories ``rows``, their samples on an on-ramp's
    acceleration lane (lane -5) included: the trajectory table describes the four
    through lanes only. Read only where a trajectory has such samples."""
    meta = store.trajectory_arrays
    t_first = meta["t_first"][rows].astype(np.float64)
    t_last = meta["t_last"][rows].astype(np.float64)
    if not np.any(meta["lanes_seen"][rows] & (1 << (-RAMP_LANE - 1))):
        return t_first, t_last
    local = np.full(meta["tid"].size, -1, dtype=np.int64)
    local[rows] = np.arange(rows.size)
    t_min, t_max = store.sample_time_range(road)
    for start in np.arange(math.floor(t_min), t_max + BLOCK_S, BLOCK_S):
        s = store.samples(road, start, start + BLOCK_S, ramps=True)
        on_ramp = s["lane"] == RAMP_LANE
        r, t = local[s["tid"][on_ramp]], s["t"][on_ramp]
        keep = r >= 0
        np.minimum.at(t_first, r[keep], t[keep])
        np.maximum.at(t_last, r[keep], t[keep])
    return t_first, t_last


def _buckets(frame0, count, offset, x, base, n_buckets):
    """The time index (module doc): per bucket its entries sorted by least x."""
    entries_r, entries_k, entries_x, pad = [], [], [], np.zeros(n_buckets)
    step = max(1, 2_000_000 // max(frame0.size, 1))  # buckets at a time, bounded memory
    for k0 in range(0, n_buckets, step):
        k1 = min(k0 + step, n_buckets)
        lo_x = np.full((k1 - k0, frame0.size), np.nan)
        hi_x = np.full((k1 - k0, frame0.size), np.nan)
        # frames are placed by their time after base; shift so that bucket k0 is row 0
        shift = round(k0 * BUCKET_S / GRID_DT)
        _bucket_ranges(frame0 - shift, count, offset, x, base, GRID_DT, BUCKET_S, k1 - k0,
                       lo_x, hi_x)  # fmt: skip
        k, r = np.nonzero(np.isfinite(lo_x))
        entries_k.append(k + k0)
        entries_r.append(r)
        entries_x.append(lo_x[k, r])
        moved = np.where(np.isfinite(lo_x), hi_x - lo_x, 0.0)
        pad[k0:k1] = moved.max(axis=1, initial=0.0)
    k, r, lo = (np.concatenate(a) if a else np.empty(0) for a in (entries_k, entries_r, entries_x))
    order = np.lexsort((r, lo, k))
    k = k[order].astype(np.int64)
    bucket_start = np.searchsorted(k, np.arange(n_buckets + 1)).astype(np.int64)
    return bucket_start, r[order].astype(np.int32), lo[order].astype(np.float64), pad + 1e-6


def clear_loaded() -> None:
    """Forget the recordings loaded by this process (tests that rewrite a store)."""
    _LOADED.clear()


def remove_cached(store: TrajectoryStore) -> None:
    """Remove the cached recordings of ``store`` (all roads) and the files kept beside
    them under the same key (derived data, such as the recording's lane changes)."""
    key = store_key(store)
    for path in [*cache_dir().glob(f"recording-{key}-*"),
                 *(store.path / CACHE_FOLDER).glob(f"*-{key}"),
                 *(store.path / CACHE_FOLDER).glob(f"*-{key}.*")]:  # fmt: skip
        if path.is_dir():
            shutil.rmtree(path, ignore_errors=True)
        else:
            path.unlink(missing_ok=True)
    for k in [k for k in _LOADED if k[0] == key]:
        del _LOADED[k]


def cached_size(folder: os.PathLike) -> int:
    """[bytes] of a cached recording folder."""
    return sum(p.stat().st_size for p in Path(folder).iterdir())
