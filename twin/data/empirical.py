"""Recorded traffic at any time: ``EmpiricalTraffic`` answers snapshots and ego selection.

The cosimulator, the metrics and the cameras ask for the recorded vehicles in an x
window at a time, thousands of times an episode. The answer comes from the road's
recording in memory (:mod:`twin.data.recording`: every trajectory resampled once onto
the data's 25 Hz grid, loaded once per process, memory-mapped from the cache): a
snapshot is a search in the time index and an interpolation between two frames of the
vehicles near the window, in a compiled kernel; no query reads Parquet.

Between grid frames positions are linear in time, so a snapshot departs from the
samples' polyline by at most a quarter of its largest second difference and is exact
on a straight piece; speeds are the store's smoothed speeds
(:func:`twin.data.ingest.smoothed_speed`), interpolated the same way.
"""

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import pandas as pd

from twin.core import i24
from twin.core.i24 import Road
from twin.data.recording import window
from twin.data.store import TrajectoryStore, open_store


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


class EmpiricalTraffic:
    """Query recorded traffic from a store.

    Args:
        store: a :class:`TrajectoryStore` or the path of one.
    """

    def __init__(self, store: TrajectoryStore | str):
        self.store = store if isinstance(store, TrajectoryStore) else open_store(store)
        self._out = tuple(np.empty(1024, t) for t in (np.int32, float, float, float))
        self._recordings: dict = {}
        self._local: dict = {}
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
        rec = self.recording(road)
        out = self._out
        while True:
            n = window(rec, float(t), float(x_min), float(x_max), *out)
            if n >= 0:
                break
            out = self._out = tuple(np.empty(2 * out[0].size, a.dtype) for a in out)
        r, x, y, v = (a[:n].copy() for a in out)
        return Snapshot(
            road=road,
            t=float(t),
            tid=np.asarray(rec.tid)[r],
            x=x,
            y=y,
            lane=i24.lane_of(y),
            speed=v,
            meta=self._meta,
        )

    def recording(self, road: Road | str):
        """The road's recording in memory (:func:`twin.data.recording.load_recording`:
        loaded once per process)."""
        from twin.data.recording import load_recording

        road = Road.parse(road)
        if road not in self._recordings:
            self._recordings[road] = load_recording(self.store, road)
        return self._recordings[road]

    def snapshots(self, road: Road | str, times, x_min, x_max) -> dict[str, np.ndarray]:
        """:meth:`snapshot` at each of ``times`` (m,) [s unix] with the windows' ends
        ``x_min``, ``x_max`` (m,) [m], in one pass: ``query`` (the index of the time of
        each row), ``tid``, ``x``, ``y``, ``lane``, ``speed``."""
        from twin.data.recording import windows

        rec = self.recording(road)
        times, x_min, x_max = (
            np.ascontiguousarray(a, dtype=np.float64) for a in (times, x_min, x_max)
        )
        size = max(1024, 256 * times.size)
        while True:
            out = (np.empty(size, np.int64), np.empty(size, np.int32), np.empty(size),
                   np.empty(size), np.empty(size))  # fmt: skip
            n = windows(rec, times, x_min, x_max, *out)
            if n >= 0:
                break
            size *= 2
        k, r, x, y, v = (a[:n] for a in out)
        return {"query": k, "tid": np.asarray(rec.tid)[r], "x": x, "y": y,
                "lane": i24.lane_of(y), "speed": v}  # fmt: skip

    def track(self, road: Road | str, tid: int) -> dict[str, np.ndarray]:
        """Recorded vehicle ``tid``'s path from the recording in memory (the arrays of
        :meth:`TrajectoryStore.trajectory`): ``t`` [s unix], ``x``, ``y`` [m], ``lane``,
        ``speed`` [m/s] at its first and last sample's times and the grid's times
        between, where it was present.

        Raises:
            KeyError: ``tid`` is not a trajectory of ``road``.
        """
        rec = self.recording(road)
        local = self._local_index(road)
        if not 0 <= tid < local.size or local[tid] < 0:
            raise KeyError(f"no trajectory with tid {tid} on {Road.parse(road).value}")
        r = int(local[tid])
        t = rec.base + (int(rec.frame0[r]) + np.arange(int(rec.count[r]))) * rec.dt
        t = np.concatenate([[rec.t_first[r]], t[(t > rec.t_first[r]) & (t < rec.t_last[r])],
                            [rec.t_last[r]]])  # fmt: skip
        present, x, y, speed = self._replay(road, np.full(t.size, r), t)
        y = y[present]
        return {"t": t[present], "x": x[present], "y": y, "lane": i24.lane_of(y),
                "speed": speed[present]}  # fmt: skip

    def recorded_speeds(self, road: Road | str, tids, times) -> tuple[np.ndarray, np.ndarray]:
        """(present, speed [m/s]) of recorded vehicles ``tids`` (m,) at ``times`` (m,)."""
        present, _, _, speed = self.recorded_states(road, tids, times)
        return present, speed

    def recorded_states(self, road: Road | str, tids, times) -> tuple[np.ndarray, ...]:
        """(present, x [m], y [m], speed [m/s]) of recorded vehicles ``tids`` (m,) at
        unix ``times`` (m,) [s]; the values are 0 where a vehicle is absent."""
        r = self._local_index(road)[np.asarray(tids, np.int64)]
        return self._replay(road, r, np.asarray(times, np.float64))

    def _local_index(self, road) -> np.ndarray:
        """Per store tid, its index in the road's recording (-1: not of the road)."""
        road = Road.parse(road)
        if road not in self._local:
            rec = self.recording(road)
            local = np.full(len(self._meta.id), -1, np.int64)
            local[np.asarray(rec.tid)] = np.arange(rec.tid.size)
            self._local[road] = local
        return self._local[road]

    def _replay(self, road, r: np.ndarray, times: np.ndarray):
        from twin.data.recording import replay_many

        m = r.size
        present, x, y, speed = np.zeros(m, bool), np.zeros(m), np.zeros(m), np.zeros(m)
        known = np.flatnonzero(r >= 0)
        if known.size:
            out = [np.zeros(known.size, bool), *(np.zeros(known.size) for _ in range(3))]
            replay_many(self.recording(road), r[known], times[known], *out)
            present[known], x[known], y[known], speed[known] = out
        return present, x, y, speed

    def preload(self, road: Road | str, t_start: float, t_end: float) -> int:
        """Load the road's recording now (once per process), so that no snapshot pauses
        for it. Returns 1."""
        self.recording(road)
        return 1

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
        from twin.data.recording import closest_vehicle

        road = Road.parse(road)
        if lane not in i24.LANES:
            raise ValueError(f"lane must be one of {i24.LANES}, got {lane!r}")
        rec = self.recording(road)
        r, t_best, x_best, y_best, v_best = closest_vehicle(
            self.store, road, rec, lane, x, t, max_distance, max_time, speed_scale, self._out
        )
        tid = int(rec.tid[r])
        return RecordedVehicle(
            tid=tid,
            id=str(self._meta.id[tid]),
            road=road,
            t=float(t_best),
            x=float(x_best),
            y=float(y_best),
            lane=int(i24.lane_of(np.array([y_best]))[0]),
            speed=float(v_best),
            length=float(self._meta.sizes[tid, 0]),
            width=float(self._meta.sizes[tid, 1]),
            height=float(self._meta.sizes[tid, 2]),
            vehicle_class=int(self._meta.vehicle_class[tid]),
        )
