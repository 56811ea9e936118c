"""Recorded traffic at any time: ``EmpiricalTraffic`` answers snapshots and ego selection.

The cosimulator asks for the recorded vehicles in an x window every 10 ms step. To
answer in microseconds, recorded samples are resampled once per chunk of time
(default 20 s) onto a regular grid (default 25 Hz): for every grid frame, one row
per vehicle present, sorted by x, holding the position, lateral offset and speed at
the frame and their rates of change until the next frame. A snapshot at time t is
then two binary searches and a fused multiply-add over the rows in the window.

Between recorded samples positions are linear in time (so a snapshot on a sample's
time returns that sample exactly); speeds are the store's smoothed speeds
(:func:`twin.data.ingest.smoothed_speed`), interpolated the same way.
"""

import math
from collections import OrderedDict
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import pandas as pd

from twin.core import i24
from twin.core.errors import NoVehicleNearError
from twin.core.i24 import Road
from twin.core.timeutil import format_local
from twin.data.store import TrajectoryStore

_EPS = 1e-6  # [s] tolerance on validity ends; unix times near 1.7e9 s resolve 2.4e-7 s


@dataclass(frozen=True, eq=False)
class Snapshot:
    """Recorded vehicles on one road at one time, as struct-of-arrays sorted by x.

    Attributes:
        road, t: the road and unix time [s] asked for.
        tid: (n,) int32 store trajectory index.
        x: (n,) float64 [m] road-frame x of the back centre.
        y: (n,) float64 [m] from the median centre line.
        lane: (n,) int8, -1..-4 (0 if between bands after interpolation, which
            ingest makes impossible for recorded samples).
        speed: (n,) float64 [m/s].
        id: (n,) object, I-24 MOTION ``_id`` strings.
        length, width, height: (n,) float64 [m].
        vehicle_class: (n,) int8, index into ``i24.VEHICLE_CLASSES``.

    ``id``, the sizes and the class are looked up on first use: the cosimulator
    queries every step and needs them only for the few vehicles it spawns.
    """

    road: Road
    t: float
    tid: np.ndarray
    x: np.ndarray
    y: np.ndarray
    lane: np.ndarray
    speed: np.ndarray
    meta: "_Meta"

    def __len__(self) -> int:
        return len(self.tid)

    @cached_property
    def id(self) -> np.ndarray:
        return self.meta.id[self.tid]

    @cached_property
    def _sizes(self) -> np.ndarray:
        return self.meta.sizes[self.tid]

    @property
    def length(self) -> np.ndarray:
        return self._sizes[:, 0]

    @property
    def width(self) -> np.ndarray:
        return self._sizes[:, 1]

    @property
    def height(self) -> np.ndarray:
        return self._sizes[:, 2]

    @cached_property
    def vehicle_class(self) -> np.ndarray:
        return self.meta.vehicle_class[self.tid]

    def to_frame(self) -> pd.DataFrame:
        """The vehicles as a DataFrame (one row per vehicle)."""
        names = ("id", "x", "y", "lane", "speed", "length", "width", "height", "vehicle_class")
        return pd.DataFrame({name: getattr(self, name) for name in names})


@dataclass(frozen=True)
class _Meta:
    """Per store tid: ``id`` (object), ``sizes`` (n, 3) length, width, height [m],
    ``vehicle_class`` (int8)."""

    id: np.ndarray
    sizes: np.ndarray
    vehicle_class: np.ndarray


@dataclass(frozen=True)
class RecordedVehicle:
    """One recorded vehicle at one time (the result of :meth:`EmpiricalTraffic.closest`)."""

    tid: int
    id: str
    road: Road
    t: float  # [s] unix
    x: float  # [m] back centre
    y: float  # [m]
    lane: int
    speed: float  # [m/s]
    length: float  # [m]
    width: float  # [m]
    height: float  # [m]
    vehicle_class: int


@dataclass(frozen=True)
class _Chunk:
    """Grid frames ``base + j * dt`` (j < n_frames) of one road; rows sorted by (frame, x)."""

    base: float
    offsets: np.ndarray  # (n_frames + 1,) int64 row offset of each frame
    tid: np.ndarray  # (rows,) int32
    x0: np.ndarray  # (rows,) [m] at the frame
    dx: np.ndarray  # (rows,) [m/s] rate until the next frame
    y0: np.ndarray
    dy: np.ndarray
    v0: np.ndarray
    dv: np.ndarray
    lo: np.ndarray  # (rows,) [s] after the frame, vehicle present from
    hi: np.ndarray  # (rows,) [s] after the frame, vehicle present until
    pad: float  # [m] largest distance any row moves within one frame


class EmpiricalTraffic:
    """Query recorded traffic from a store.

    Args:
        store: a :class:`TrajectoryStore` or the path of one.
        grid_dt: [s] resampling period of the frame tables.
        chunk: [s] time span of one frame table (built on first use, cached).
        max_gap: [s] a vehicle is absent inside gaps between its samples longer than this.
        cache_chunks: frame tables kept in memory per road.
    """

    def __init__(
        self,
        store: TrajectoryStore | str,
        *,
        grid_dt: float = 0.04,
        chunk: float = 20.0,
        max_gap: float = 1.0,
        cache_chunks: int = 4,
    ):
        self.store = store if isinstance(store, TrajectoryStore) else TrajectoryStore(store)
        n_frames = chunk / grid_dt
        if not (grid_dt > 0 and chunk > 0 and abs(n_frames - round(n_frames)) < 1e-9):
            raise ValueError(
                f"chunk ({chunk} s) must be a positive multiple of grid_dt ({grid_dt} s)"
            )
        if not max_gap > 0:
            raise ValueError(f"max_gap must be > 0 s, got {max_gap}")
        self.grid_dt = grid_dt
        self.chunk = chunk
        self.n_frames = round(n_frames)
        self.max_gap = max_gap
        self.cache_chunks = cache_chunks
        self._cache: OrderedDict[tuple[Road, int], _Chunk] = OrderedDict()
        meta = self.store.trajectory_arrays
        self._meta = _Meta(
            id=meta["id"],
            sizes=np.stack([meta[k].astype(np.float64) for k in ("length", "width", "height")], 1),
            vehicle_class=meta["vehicle_class"],
        )

    def snapshot(self, road: Road | str, t: float, x_min: float, x_max: float) -> Snapshot:
        """Every recorded vehicle on ``road`` present at ``t`` with ``x_min <= x <= x_max``.

        Args:
            road: the carriageway.
            t: [s] unix time.
            x_min: [m] lower end of the road-frame window on the vehicles' back centre.
            x_max: [m] upper end of that window.

        Raises:
            ValueError: for a non-finite time or an empty/reversed window.
            StoreError: when the store has no data for ``road``.
        """
        road = Road.parse(road)
        if not (math.isfinite(t) and math.isfinite(x_min) and math.isfinite(x_max)):
            raise ValueError(f"snapshot needs finite t, x_min, x_max; got {t}, {x_min}, {x_max}")
        if x_max < x_min:
            raise ValueError(f"snapshot window is reversed: x_min {x_min} > x_max {x_max}")
        k = math.floor(t / self.chunk)
        chunk = self._chunk(road, k)
        j = min(math.floor((t - chunk.base) / self.grid_dt + 1e-6), self.n_frames - 1)
        s = t - chunk.base - j * self.grid_dt
        a, b = chunk.offsets[j], chunk.offsets[j + 1]
        xs = chunk.x0[a:b]
        i0 = a + np.searchsorted(xs, x_min - chunk.pad)
        i1 = a + np.searchsorted(xs, x_max + chunk.pad, side="right")
        x = chunk.x0[i0:i1] + chunk.dx[i0:i1] * s
        keep = (
            (x >= x_min)
            & (x <= x_max)
            & (chunk.lo[i0:i1] <= s + _EPS)
            & (chunk.hi[i0:i1] >= s - _EPS)
        )
        rows = keep.nonzero()[0]
        rows = rows[np.argsort(x[rows], kind="stable")]
        x = x[rows]
        rows += i0
        y = chunk.y0[rows] + chunk.dy[rows] * s
        return Snapshot(
            road=road,
            t=float(t),
            tid=chunk.tid[rows],
            x=x,
            y=y,
            lane=i24.lane_of(y),
            speed=np.maximum(chunk.v0[rows] + chunk.dv[rows] * s, 0.0),
            meta=self._meta,
        )

    def preload(self, road: Road | str, t_start: float, t_end: float) -> int:
        """Build the frame tables covering ``t_start`` to ``t_end`` now (as many as the
        cache holds, earliest first), so that snapshots in that span never pause to
        build one. Returns how many tables are in the cache for the span."""
        road = Road.parse(road)
        first, last = math.floor(t_start / self.chunk), math.floor(t_end / self.chunk)
        keys = list(range(first, last + 1))[: self.cache_chunks]
        for k in reversed(keys):  # the earliest is used first: keep it the most recent
            self._chunk(road, k)
        return len(keys)

    def closest(
        self,
        road: Road | str,
        lane: int,
        x: float,
        t: float,
        *,
        max_distance: float = 50.0,
        max_time: float = 5.0,
        speed_scale: float = 10.0,
    ) -> RecordedVehicle:
        """The recorded vehicle spatio-temporally closest to ``lane``, ``x`` and ``t``.

        Candidates are the vehicles in ``lane`` within ``max_distance`` of ``x`` at times
        within ``max_time`` of ``t`` (on the grid, and at ``t`` itself); the cost is
        ``hypot(x_vehicle - x, speed_scale * (t_vehicle - t))``, ties broken by tid.
        The result's ``t`` is the time at which the vehicle was closest (the paper's t0).

        Raises:
            NoVehicleNearError: when no vehicle is within the tolerances; the message
                names the request and what the store covers.
        """
        road = Road.parse(road)
        if lane not in i24.LANES:
            raise ValueError(f"lane must be one of {i24.LANES}, got {lane!r}")
        k0 = math.ceil((t - max_time) / self.grid_dt)
        k1 = math.floor((t + max_time) / self.grid_dt)
        times = np.r_[t, np.arange(k0, k1 + 1) * self.grid_dt]
        times = times[np.argsort(np.abs(times - t), kind="stable")]
        best = None
        for tau in times:
            if best is not None and speed_scale * abs(tau - t) > best[0]:
                break
            snap = self.snapshot(road, float(tau), x - max_distance, x + max_distance)
            rows = np.flatnonzero(snap.lane == lane)
            if len(rows) == 0:
                continue
            cost = np.hypot(snap.x[rows] - x, speed_scale * (tau - t))
            i = rows[np.lexsort((snap.tid[rows], cost))[0]]
            candidate = (float(np.hypot(snap.x[i] - x, speed_scale * (tau - t))), int(snap.tid[i]))
            if best is None or candidate < best[:2]:
                best = (*candidate, snap, i)
        if best is None:
            t_min, t_max = self.store.time_range(road)
            raise NoVehicleNearError(
                f"no recorded vehicle in lane {lane} of {road.value} within {max_distance:g} m of "
                f"x = {x:g} m and {max_time:g} s of {format_local(t)} CST (unix {t:.2f}); "
                f"the store covers {format_local(t_min)} to {format_local(t_max)} CST on this road"
            )
        _, _, snap, i = best
        return RecordedVehicle(
            tid=int(snap.tid[i]),
            id=str(snap.id[i]),
            road=road,
            t=snap.t,
            x=float(snap.x[i]),
            y=float(snap.y[i]),
            lane=int(snap.lane[i]),
            speed=float(snap.speed[i]),
            length=float(snap.length[i]),
            width=float(snap.width[i]),
            height=float(snap.height[i]),
            vehicle_class=int(snap.vehicle_class[i]),
        )

    def _chunk(self, road: Road, k: int) -> _Chunk:
        key = (road, k)
        chunk = self._cache.get(key)
        if chunk is None:
            chunk = self._build_chunk(road, k * self.chunk)
            self._cache[key] = chunk
            if len(self._cache) > self.cache_chunks * len(Road):
                self._cache.popitem(last=False)
        else:
            self._cache.move_to_end(key)
        return chunk

    def _build_chunk(self, road: Road, base: float) -> _Chunk:
        dt, n_frames = self.grid_dt, self.n_frames
        t_lo = base - self.max_gap
        s = self.store.samples(road, t_lo, base + self.chunk + self.max_gap)
        n = len(s["t"])
        new_run = np.r_[True, s["tid"][1:] != s["tid"][:-1]] if n else np.zeros(0, bool)
        starts = np.flatnonzero(new_run)
        ends = np.append(starts[1:], n).astype(np.int64) if n else starts
        t_first, t_last = s["t"][starts], s["t"][ends - 1]
        j_start = np.clip(np.floor((t_first - base) / dt), 0, n_frames - 1).astype(np.int64)
        j_end = np.clip(np.floor((t_last - base) / dt), -1, n_frames - 1).astype(np.int64)
        use = (
            (ends - starts >= 2)
            & (t_last >= base)
            & (t_first < base + self.chunk)
            & (j_end >= j_start)
        )

        # Keep the samples of the trajectories in use; number those trajectories 0..m-1.
        kept = use[np.cumsum(new_run) - 1]
        s = {name: column[kept] for name, column in s.items()}
        t = s["t"]
        lengths = (ends - starts)[use]
        first = np.cumsum(lengths) - lengths
        t_first, t_last, j_start = t_first[use], t_last[use], j_start[use]
        counts = (j_end + 1)[use] - j_start

        # One row per (trajectory, frame) it overlaps.
        run = np.repeat(np.arange(len(lengths)), counts)
        j = j_start[run] + np.arange(len(run)) - np.repeat(np.cumsum(counts) - counts, counts)
        g = base + j * dt
        ta = np.clip(g, t_first[run], t_last[run])
        tb = np.clip(g + dt, t_first[run], t_last[run])

        # Binary search of every (trajectory, time) query at once on one sorted key.
        span = 2.0 ** math.ceil(math.log2(self.chunk + 2 * self.max_gap + 1))
        key = np.repeat(np.arange(len(lengths)), lengths) * span + (t - t_lo)
        lowest, highest = first[run], first[run] + lengths[run] - 2

        def locate(tq):
            i = np.searchsorted(key, run * span + (tq - t_lo), side="right") - 1
            i = np.clip(i, lowest, highest)
            return i, (tq - t[i]) / (t[i + 1] - t[i]), t[i + 1] - t[i]

        ia, wa, gap_a = locate(ta)
        ib, wb, gap_b = locate(tb)
        duration = tb - ta
        lo, hi = ta - g, tb - g

        def rate(column):
            values = s[column].astype(np.float64)
            va = values[ia] + wa * (values[ia + 1] - values[ia])
            vb = values[ib] + wb * (values[ib + 1] - values[ib])
            slope = np.divide(vb - va, duration, out=np.zeros_like(va), where=duration > 0)
            return va - slope * lo, slope

        x0, dx = rate("x")
        y0, dy = rate("y")
        v0, dv = rate("speed")
        order = np.lexsort((x0, j))
        order = order[(gap_a <= self.max_gap)[order] & (gap_b <= self.max_gap)[order]]
        offsets = np.searchsorted(j[order], np.arange(n_frames + 1))
        pad = float(np.max(np.abs(dx), initial=0.0)) * dt + 1e-6
        return _Chunk(
            base=base,
            offsets=offsets,
            tid=s["tid"][first][run][order],
            x0=x0[order],
            dx=dx[order],
            y0=y0[order],
            dy=dy[order],
            v0=v0[order],
            dv=dv[order],
            lo=lo[order],
            hi=hi[order],
            pad=pad,
        )
