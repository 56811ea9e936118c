"""Car following, free flow and lane changes as a recording shows them: the data side of
the calibration (:mod:`twin.calibration.car_following` and the others fit models to what
this module finds).

Every trajectory of a road is resampled onto one time grid (``dt``, 0.1 s by default,
the step the drivers are simulated at). At each grid time the vehicles of each lane are
ordered by x, which gives every vehicle its leader (the next vehicle ahead in its lane)
and the gap to it, bumper to bumper. From that:

- **following runs**: stretches in which a vehicle keeps the same leader in the same
  lane, long enough to identify a car-following model (the leader's recorded motion is
  replayed to a simulated follower);
- **free-flow speeds**: each vehicle's median speed while nothing is close ahead of it
  and it cruises (not still accelerating out of a queue), the estimate of its desired
  speed, per lane;
- **lane changes**: a vehicle's lane (by its y) changing and holding, with the speed of
  the lanes around it, and the exposure (vehicle-km) they are counted against.

Positions are the I-24 MOTION reference, the back centre, so a vehicle covers
``[x, x + length]`` and the gap to its leader is ``x_leader - x - length``.
"""

import itertools
import math
from dataclasses import dataclass

import numpy as np

from twin.core.errors import TwinError
from twin.core.i24 import Road, lane_of
from twin.core.ramps import RAMP_LANE
from twin.data.store import TrajectoryStore

GRID_DT = 0.1  # [s] the grid the trajectories are resampled on
MAX_SAMPLE_GAP = 0.5  # [s] grid times farther than this from a sample are not used
LANE_HOLD = 1.0  # [s] a new lane counts once the vehicle has stayed in it this long
FREE_GAP = 60.0  # [m] free flow: at least this gap to the leader ...
FREE_HEADWAY = 6.0  # [s] ... and at least this time gap ...
FREE_MIN_SPEED = 10.0  # [m/s] ... at a speed no queue discharges at (not leaving a stop)
FREE_SPREAD = 1.5  # [m/s] ... cruising: its free speeds' p10 to p90 within this (a driver
# still accelerating towards its desired speed is not at it)
CELL = 100.0  # [m] cells along the road in which "the speed of a lane" is measured
SPEED_BINS = (0.0, 5.0, 15.0, 25.0, math.inf)  # [m/s] lane-speed bins of the lane-change rates
SPEED_BIN_NAMES = ("0-5", "5-15", "15-25", "25+")


class CalibrationDataError(TwinError):
    """The recording cannot support a calibration (too short, no following, no data)."""


@dataclass(frozen=True)
class GridTraffic:
    """The trajectories of one road on a common time grid, one row per (tid, k), sorted
    by (tid, k); each trajectory's rows are consecutive grid steps.

    Attributes:
        road: the carriageway.
        dt: [s] grid step; ``t0``: [s] unix time of grid step 0.
        tid, k: (n,) trajectory and grid step of each row.
        x, speed, y: (n,) [m], [m/s], [m] (road frame, back centre).
        lane: (n,) int8 lane by y; 0 where the trajectory has no sample near the step
            or lies outside the lanes.
        length, vehicle_class: (n,) the vehicle's length [m] and coarse class.
        leader: (n,) row of the vehicle ahead in the same lane at the same step, -1 if none.
        gap: (n,) [m] bumper-to-bumper gap to it (inf if none).
    """

    road: Road
    dt: float
    t0: float
    tid: np.ndarray
    k: np.ndarray
    x: np.ndarray
    speed: np.ndarray
    y: np.ndarray
    lane: np.ndarray
    length: np.ndarray
    vehicle_class: np.ndarray
    leader: np.ndarray
    gap: np.ndarray

    def __len__(self) -> int:
        return self.tid.size

    @property
    def time(self) -> np.ndarray:
        """(n,) [s] unix time of each row."""
        return self.t0 + self.k * self.dt


def load_grid(
    store: TrajectoryStore,
    road: Road | str,
    t_from: float | None = None,
    t_until: float | None = None,
    *,
    dt: float = GRID_DT,
) -> GridTraffic:
    """The recording of ``road`` between ``t_from`` and ``t_until`` (default: all of it)
    on a grid of step ``dt``, with every vehicle's leader.

    Raises:
        CalibrationDataError: the window holds no data of ``road``.
        StoreError: the store has no ``road``.
    """
    road = Road.parse(road)
    first, last = store.time_range(road)
    lo = first if t_from is None else max(float(t_from), first)
    hi = last if t_until is None else min(float(t_until), last)
    if not hi > lo:
        raise CalibrationDataError(
            f"no {road.value} data between unix {t_from} and {t_until}: the store's "
            f"{road.value} data run from {first:.1f} to {last:.1f}"
        )
    samples = store.samples(road, lo, hi)
    return _grid(store, road, samples, math.floor(lo / dt) * dt, dt, lane_of)


def ramp_grid(
    store: TrajectoryStore, road: Road | str, samples: dict, t0: float, *, dt: float = GRID_DT
) -> GridTraffic:
    """The samples of ``samples`` (a store's, sorted by (tid, t), with the ramps':
    :meth:`~twin.data.store.TrajectoryStore.samples` with ``ramps=True``) on an on-ramp's
    acceleration lane (lane -5), on the grid from ``t0`` [s] by ``dt``, as
    :func:`load_grid` gives the through lanes': each ramp vehicle's leader is the next
    ramp vehicle ahead (pass one ramp's samples: the ramps of a road share lane -5)."""
    road = Road.parse(road)
    keep = np.asarray(samples["lane"]) == RAMP_LANE
    samples = {name: np.asarray(column)[keep] for name, column in samples.items()}
    return _grid(store, road, samples, t0, dt, _ramp_lane)


def _ramp_lane(y: np.ndarray) -> np.ndarray:
    """Every position of a ramp sample is on lane -5 (the store placed it there)."""
    return np.full(np.shape(y), RAMP_LANE, np.int8)


def _grid(store, road, samples, t0, dt, lanes) -> GridTraffic:
    """``samples`` (sorted by tid, t) on the grid from ``t0`` [s] by ``dt`` [s], their
    lanes by ``lanes(y)``, with every vehicle's leader."""
    info = store.trajectory_arrays
    columns = _resample(samples, t0, dt, lanes)
    tid = columns["tid"]
    columns["length"] = info["length"][tid].astype(np.float64)
    columns["vehicle_class"] = info["vehicle_class"][tid].astype(np.int64)
    leader, gap = _leaders(columns["k"], columns["lane"], columns["x"], columns["length"])
    return GridTraffic(road=road, dt=dt, t0=t0, leader=leader, gap=gap, **columns)


def _resample(samples: dict, t0: float, dt: float, lanes=lane_of) -> dict:
    """Every trajectory's samples (sorted by tid, t) at the grid steps inside its span,
    their lanes by ``lanes(y)``."""
    tid = samples["tid"]
    starts = np.flatnonzero(np.r_[True, tid[1:] != tid[:-1]]) if tid.size else np.zeros(0, int)
    ends = np.r_[starts[1:], tid.size].astype(int)[: starts.size]  # none for no samples
    out = {name: [] for name in ("tid", "k", "x", "speed", "y", "lane")}
    t_all = samples["t"]
    for a, b in zip(starts, ends, strict=True):
        if b - a < 2:
            continue
        t = t_all[a:b]
        k = np.arange(math.ceil((t[0] - t0) / dt - 1e-9), math.floor((t[-1] - t0) / dt + 1e-9) + 1)
        if k.size == 0:
            continue
        tk = t0 + k * dt
        y = np.interp(tk, t, samples["y"][a:b].astype(np.float64))
        nearest = np.minimum(np.searchsorted(t, tk), t.size - 1)
        near = np.minimum(np.abs(t[nearest] - tk), np.abs(t[np.maximum(nearest - 1, 0)] - tk))
        lane = np.where(near <= MAX_SAMPLE_GAP, lanes(y), 0).astype(np.int8)
        out["tid"].append(np.full(k.size, tid[a], dtype=np.int64))
        out["k"].append(k.astype(np.int64))
        out["x"].append(np.interp(tk, t, samples["x"][a:b]))
        out["speed"].append(np.interp(tk, t, samples["speed"][a:b].astype(np.float64)))
        out["y"].append(y)
        out["lane"].append(lane)
    empty = {"tid": np.int64, "k": np.int64, "lane": np.int8}
    return {
        name: np.concatenate(parts) if parts else np.zeros(0, empty.get(name, np.float64))
        for name, parts in out.items()
    }


def _leaders(k, lane, x, length) -> tuple[np.ndarray, np.ndarray]:
    """Row of the next vehicle ahead in the same lane at the same step, and the gap."""
    order = np.lexsort((x, lane, k))
    same = np.zeros(order.size, dtype=bool)
    if order.size > 1:
        a, b = order[:-1], order[1:]
        same[:-1] = (k[a] == k[b]) & (lane[a] == lane[b]) & (lane[a] != 0)
    leader = np.full(order.size, -1, dtype=np.int64)
    leader[order[:-1][same[:-1]]] = order[1:][same[:-1]]
    gap = np.full(order.size, np.inf)
    has = leader >= 0
    gap[has] = x[leader[has]] - x[has] - length[has]
    return leader, gap


@dataclass(frozen=True)
class FollowingRuns:
    """Stretches in which a vehicle follows one leader in one lane, padded to (R, N).

    Attributes:
        tid: (R,) the follower; leader_tid: (R,) its leader.
        lane: (R,) the lane; vehicle_class: (R,) the follower's class.
        length: (R,) [m] the follower's length.
        t_start: (R,) [s] unix time of the first step; steps: (R,) how many steps.
        dt: [s] step.
        x, speed: (R, N) [m], [m/s] the follower as recorded (NaN past ``steps``).
        x_lead, speed_lead: (R, N) the leader's back-centre x and speed.
    """

    tid: np.ndarray
    leader_tid: np.ndarray
    lane: np.ndarray
    vehicle_class: np.ndarray
    length: np.ndarray
    t_start: np.ndarray
    steps: np.ndarray
    dt: float
    x: np.ndarray
    speed: np.ndarray
    x_lead: np.ndarray
    speed_lead: np.ndarray

    def __len__(self) -> int:
        return self.tid.size

    @property
    def gap(self) -> np.ndarray:
        """(R, N) [m] recorded bumper-to-bumper gap."""
        return self.x_lead - self.x - self.length[:, None]

    @property
    def valid(self) -> np.ndarray:
        """(R, N) bool, the steps inside each run."""
        return np.arange(self.x.shape[1])[None, :] < self.steps[:, None]

    def take(self, rows) -> "FollowingRuns":
        rows = np.asarray(rows)
        n = int(self.steps[rows].max()) if rows.size else 0
        cut = {}
        for name in ("x", "speed", "x_lead", "speed_lead"):
            cut[name] = getattr(self, name)[rows, :n]
        simple = {
            name: getattr(self, name)[rows]
            for name in ("tid", "leader_tid", "lane", "vehicle_class", "length", "t_start", "steps")
        }
        return FollowingRuns(dt=self.dt, **simple, **cut)


def following_runs(
    grid: GridTraffic,
    *,
    min_duration: float = 20.0,
    max_duration: float = 120.0,
    trim: float = 2.0,
    max_gap: float = 150.0,
) -> FollowingRuns:
    """The stretches in which a vehicle keeps one leader in one lane.

    Each stretch loses ``trim`` seconds at each end (where a leader cuts in or leaves,
    or the follower starts to change lanes, who follows whom is ambiguous), is kept if
    at least ``min_duration`` long with the gap below ``max_gap`` throughout, and is cut
    into pieces of at most ``max_duration`` (a replay drifts; and the pieces batch well).
    """
    n = len(grid)
    if n == 0:
        return _no_runs(grid.dt)
    leader_tid = np.where(grid.leader >= 0, grid.tid[np.maximum(grid.leader, 0)], -1)
    ok = (grid.leader >= 0) & (grid.lane != 0) & (grid.gap < max_gap) & (grid.gap > 0)
    new = np.ones(n, dtype=bool)
    new[1:] = (
        (grid.tid[1:] != grid.tid[:-1])
        | (grid.k[1:] != grid.k[:-1] + 1)
        | (leader_tid[1:] != leader_tid[:-1])
        | (grid.lane[1:] != grid.lane[:-1])
        | (ok[1:] != ok[:-1])
    )
    starts = np.flatnonzero(new)
    ends = np.r_[starts[1:], n]
    cut = round(trim / grid.dt)
    shortest, longest = round(min_duration / grid.dt), round(max_duration / grid.dt)
    pieces = []
    for a, b in zip(starts, ends, strict=True):
        if not ok[a]:
            continue
        a, b = a + cut, b - cut
        if b - a < shortest:
            continue
        count = math.ceil((b - a) / longest)
        bounds = np.linspace(a, b, count + 1).round().astype(int)
        pieces.extend(itertools.pairwise(bounds))
    if not pieces:
        return _no_runs(grid.dt)
    pieces = np.array(pieces)
    steps = pieces[:, 1] - pieces[:, 0]
    width = int(steps.max())
    index = pieces[:, :1] + np.arange(width)[None, :]
    inside = np.arange(width)[None, :] < steps[:, None]
    index = np.where(inside, index, pieces[:, :1])
    lead_rows = grid.leader[index]

    def padded(values):
        return np.where(inside, values, np.nan)

    first = pieces[:, 0]
    return FollowingRuns(
        tid=grid.tid[first],
        leader_tid=leader_tid[first],
        lane=grid.lane[first],
        vehicle_class=grid.vehicle_class[first],
        length=grid.length[first],
        t_start=grid.t0 + grid.k[first] * grid.dt,
        steps=steps,
        dt=grid.dt,
        x=padded(grid.x[index]),
        speed=padded(grid.speed[index]),
        x_lead=padded(grid.x[lead_rows]),
        speed_lead=padded(grid.speed[lead_rows]),
    )


def _no_runs(dt: float) -> FollowingRuns:
    empty = np.zeros(0)
    return FollowingRuns(
        tid=np.zeros(0, np.int64), leader_tid=np.zeros(0, np.int64), lane=np.zeros(0, np.int8),
        vehicle_class=np.zeros(0, np.int64), length=empty, t_start=empty,
        steps=np.zeros(0, np.int64), dt=dt, x=np.zeros((0, 0)), speed=np.zeros((0, 0)),
        x_lead=np.zeros((0, 0)), speed_lead=np.zeros((0, 0)),
    )  # fmt: skip


@dataclass(frozen=True)
class FreeFlow:
    """Each vehicle's free-flow speed: its median speed while free (see the module doc),
    per lane it was free in for at least ``min_time``.

    Attributes:
        tid, lane, vehicle_class: (m,) per (vehicle, lane).
        speed: (m,) [m/s] median free speed; seconds: (m,) [s] time it was free there.
    """

    tid: np.ndarray
    lane: np.ndarray
    vehicle_class: np.ndarray
    speed: np.ndarray
    seconds: np.ndarray

    def __len__(self) -> int:
        return self.tid.size


def free_flow_speeds(grid: GridTraffic, *, min_time: float = 5.0) -> FreeFlow:
    """The free-flow speeds of the vehicles of ``grid``."""
    free = (
        (grid.lane != 0)
        & (grid.gap >= FREE_GAP)
        & (grid.gap >= FREE_HEADWAY * np.maximum(grid.speed, 0.0))
        & (grid.speed >= FREE_MIN_SPEED)
    )
    rows = np.flatnonzero(free)
    key = grid.tid[rows] * 8 + (-grid.lane[rows].astype(np.int64))
    order = np.lexsort((grid.speed[rows], key))
    rows, key = rows[order], key[order]
    starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]]) if key.size else np.zeros(0, int)
    counts = np.diff(np.r_[starts, key.size])
    p10 = grid.speed[rows[starts + (counts - 1) // 10]]
    p90 = grid.speed[rows[starts + 9 * (counts - 1) // 10]]
    spread = p90 - p10
    keep = (counts * grid.dt >= min_time) & (spread <= FREE_SPREAD)
    starts, counts = starts[keep], counts[keep]
    lower = rows[starts + (counts - 1) // 2]
    upper = rows[starts + counts // 2]
    first = rows[starts]
    return FreeFlow(
        tid=grid.tid[first],
        lane=grid.lane[first],
        vehicle_class=grid.vehicle_class[first],
        speed=0.5 * (grid.speed[lower] + grid.speed[upper]),
        seconds=counts * grid.dt,
    )


@dataclass(frozen=True)
class LaneChanges:
    """The recording's lane changes and the exposure they happen in.

    Attributes:
        tid, time, x: (c,) who changed, when [s unix] and where [m] it crossed the line.
        lane_from, lane_to: (c,) lanes.
        speed_from, speed_to: (c,) [m/s] the mean speed of the two lanes in the
            ``CELL`` around the vehicle when it crossed.
        exposure_km: (4 lanes, speed bins) vehicle-km driven in each lane by lane speed.
    """

    tid: np.ndarray
    time: np.ndarray
    x: np.ndarray
    lane_from: np.ndarray
    lane_to: np.ndarray
    speed_from: np.ndarray
    speed_to: np.ndarray
    exposure_km: np.ndarray

    def __len__(self) -> int:
        return self.tid.size

    @property
    def speed_bin(self) -> np.ndarray:
        """(c,) index into ``SPEED_BINS`` of the lane left."""
        return speed_bin(self.speed_from)


def distance_driven(grid: GridTraffic) -> np.ndarray:
    """(n,) [m] the distance each row's vehicle drove since its previous grid step (0 for
    a trajectory's first row, or after a gap in it; never negative)."""
    distance = np.zeros(len(grid))
    if len(grid) > 1:
        same = (grid.tid[1:] == grid.tid[:-1]) & (grid.k[1:] == grid.k[:-1] + 1)
        distance[1:] = np.where(same, np.maximum(np.diff(grid.x), 0.0), 0.0)
    return distance


def speed_bin(speed: np.ndarray) -> np.ndarray:
    """Index into ``SPEED_BINS`` of each speed [m/s]."""
    return np.clip(np.searchsorted(SPEED_BINS, speed, side="right") - 1, 0, len(SPEED_BINS) - 2)


def lane_speeds(grid: GridTraffic) -> np.ndarray:
    """(n, 4) [m/s] the mean speed of each lane in each row's ``CELL`` at its step (NaN
    where the lane is empty there)."""
    cell = np.floor(grid.x / CELL).astype(np.int64)
    cell -= cell.min() if cell.size else 0
    n_cells = int(cell.max()) + 1 if cell.size else 1
    on = grid.lane != 0
    lane_index = -grid.lane.astype(np.int64) - 1
    k = grid.k - (grid.k.min() if grid.k.size else 0)
    key = (k * n_cells + cell) * 4
    size = int(key.max()) + 4 if key.size else 4
    total = np.bincount(key[on] + lane_index[on], grid.speed[on], minlength=size)
    count = np.bincount(key[on] + lane_index[on], minlength=size)
    mean = np.divide(total, count, out=np.full(size, np.nan), where=count > 0)
    return mean[key[:, None] + np.arange(4)[None, :]]


def held_changes(vehicle, lane, hold: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The lane changes in rows of vehicles ``vehicle`` (n,), grouped and in time order,
    in ``lane`` (n,) (0: outside the lanes, skipped): a vehicle's lane changing to one
    it then holds for ``hold`` rows (flicker on a line is not a change).

    Returns:
        row: (c,) the first row in the new lane; lane_from, lane_to: (c,) int8.
    """
    changes = {name: [] for name in ("row", "lane_from", "lane_to")}
    starts = np.flatnonzero(np.r_[True, vehicle[1:] != vehicle[:-1]]) if vehicle.size else []
    ends = np.r_[starts[1:], vehicle.size].astype(int) if vehicle.size else []
    for a, b in zip(starts, ends, strict=True):
        rows = np.flatnonzero(lane[a:b] != 0)
        if rows.size < 2:
            continue
        seq = lane[a:b][rows]
        switch = np.flatnonzero(seq[1:] != seq[:-1]) + 1  # first row in a new lane
        bounds = np.r_[0, switch, seq.size]
        held = np.diff(bounds) >= hold  # each constant stretch
        stretch_lane = seq[bounds[:-1]]
        current = None
        for j in range(len(held)):
            if not held[j]:
                continue
            if current is not None and stretch_lane[j] != current:
                changes["row"].append(a + rows[bounds[j]])
                changes["lane_from"].append(current)
                changes["lane_to"].append(stretch_lane[j])
            current = stretch_lane[j]
    return (
        np.array(changes["row"], dtype=np.int64),
        np.array(changes["lane_from"], dtype=np.int8),
        np.array(changes["lane_to"], dtype=np.int8),
    )


def lane_changes(grid: GridTraffic) -> LaneChanges:
    """The lane changes of ``grid``: a vehicle's lane changing to one it then holds for
    ``LANE_HOLD`` (flicker on a line is not a change), and the exposure."""
    speeds = lane_speeds(grid)
    own = np.take_along_axis(speeds, np.maximum(-grid.lane.astype(np.int64) - 1, 0)[:, None], 1)[
        :, 0
    ]
    row, lane_from, lane_to = held_changes(grid.tid, grid.lane, round(LANE_HOLD / grid.dt))
    distance = distance_driven(grid)
    on = grid.lane != 0
    exposure = np.zeros((4, len(SPEED_BINS) - 1))
    np.add.at(
        exposure,
        (-grid.lane[on].astype(np.int64) - 1, speed_bin(np.nan_to_num(own[on], nan=0.0))),
        distance[on] / 1000.0,
    )
    return LaneChanges(
        tid=grid.tid[row],
        time=grid.t0 + grid.k[row] * grid.dt,
        x=grid.x[row],
        lane_from=lane_from,
        lane_to=lane_to,
        speed_from=speeds[row, np.maximum(-lane_from.astype(np.int64) - 1, 0)]
        if row.size
        else np.zeros(0),
        speed_to=speeds[row, np.maximum(-lane_to.astype(np.int64) - 1, 0)]
        if row.size
        else np.zeros(0),
        exposure_km=exposure,
    )
