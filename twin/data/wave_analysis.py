"""Stop-and-go waves as the I-24 MOTION team measures them.

The method of the I-24 MOTION wave-analysis tool (Ji et al. 2024, "Scalable analysis of
stop-and-go waves", arXiv:2409.00326; github I24-MOTION/wave-analysis, ``SAGCC.py``),
written here for the twin's stores, with the same tables as its output:

1. **Virtual trajectories** per lane: vehicles that depart the upstream end every
   ``depart_every`` seconds and move at the lane's speed field (Edie cells), sampled
   every second, numbered ``v_id`` in departure order.
2. **Points**: each virtual trajectory's distance travelled minus that of a reference
   moving at 15 mph (its "oscillation") has a peak where it slows through 15 mph (a wave
   **front**, ``wave_type`` 1) and a trough where it speeds up through it again (a
   **tail**, 2); only points with the speed within 5 mph of 15 mph are kept.
3. **Pairs**: each trajectory's fronts and tails in time order are paired, a leading
   tail and then a trailing front dropped as the tool does.
4. **Traces**: fronts (and tails) of consecutive virtual trajectories are chained
   greedily: from the lowest ``v_id`` left, the next trajectory's latest point within
   -5..+15 s and -0.02..+0.05 mi (upstream) of the last one, until a trajectory has none.
5. **Waves**: front traces and tail traces joined by a pair are one wave (a connected
   component); a wave with 5 pairs or more is kept and numbered ``c_id``; ``CC_15.csv``
   lists each of its pairs twice, as the tool's does.

Statistics (as the shared tables' README measures them; reading the real tables with
:func:`statistics` gives its figures, tested): waves with 20 rows or more in ``CC``; the
front speed of each such wave, the slope of a least-squares line through its fronts'
(time, space), in m/s, positive upstream; fronts per virtual vehicle per mile (fronts
over the trajectories that meet one, over the miles analysed); the time from a front to
its tail over all rows of ``CC``.

Units follow the tables: time [s] from the start of the analysed span, space in mile
markers, speed [mph]; lanes 1 (HOV, the twin's -1) to 4 (-4).
"""

import math
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from scipy.signal import find_peaks

from twin.core import i24
from twin.core.errors import TwinError
from twin.core.i24 import Road
from twin.data.speed_field import speed_field
from twin.data.store import TrajectoryStore

MPH = i24.MILE / 3600.0  # [m/s] per mph
REFERENCE_MPH = 15.0  # the critical speed of the tables (``_15``)
BAND_MPH = 5.0  # points kept within this of it
DEPART_EVERY = 5.0  # [s] between virtual trajectories (the tables' v_id run 5 s apart)
SAMPLE_DT = 1.0  # [s] virtual trajectory samples (the tables' times are whole seconds)
CELL_T = 2.0  # [s] Edie cells of the lane speed field ...
CELL_X = 30.0  # [m] ... along the road
TRACE_BACK, TRACE_AHEAD = 5.0, 15.0  # [s] time window of the next point of a trace
TRACE_DOWN, TRACE_UP = 0.02, 0.05  # [mi] space window (downstream, upstream)
MIN_PAIRS = 5  # pairs of a kept wave
MIN_ROWS = 20  # CC rows of a wave counted in the statistics
LANE_NUMBER = {lane: -lane for lane in i24.LANES}  # twin lane -> table lane (1 = HOV)
POINT_COLUMNS = ["time", "space", "speed", "v_id", "wave_type", "lane", "unique_index"]
#: Miles the real 2022-11-22 tables cover (their README: fronts per vehicle per mile are
#: counted over 3.85 miles, MM 58.7 to 62.6).
REAL_MILES = 3.85


class WaveAnalysisError(TwinError):
    """The span cannot be analysed (no data, too short) or a table is malformed."""


@dataclass(frozen=True)
class VirtualTrajectories:
    """Virtual vehicles through one lane's speed field, (n,) arrays sorted by (v_id, time).

    Attributes:
        v_id: departure index; time: [s] from the span's start; x: [m] road frame;
        speed: [m/s].
    """

    v_id: np.ndarray
    time: np.ndarray
    x: np.ndarray
    speed: np.ndarray


@dataclass
class LaneWaves:
    """One lane's tables, as the tool writes them."""

    lane: int  # table lane, 1 (HOV) .. 4
    road: Road
    front: pd.DataFrame
    tail: pd.DataFrame
    cc: pd.DataFrame
    miles: float
    trajectories: VirtualTrajectories | None = field(default=None, repr=False)


def virtual_trajectories(
    t: np.ndarray,
    x: np.ndarray,
    speed: np.ndarray,
    span: tuple[float, float],
    x_range: tuple[float, float],
    *,
    depart_every: float = DEPART_EVERY,
    dt: float = SAMPLE_DT,
    cell_t: float = CELL_T,
    cell_x: float = CELL_X,
) -> VirtualTrajectories:
    """Virtual trajectories through the speed field of one lane's samples.

    Args:
        t, x, speed: (n,) the lane's samples: time [s] from the span's start, road-frame
            x [m], speed [m/s].
        span: [s] (start, end) of the analysis, from the span's start (so start is 0).
        x_range: [m] (upstream end, downstream end) the trajectories run between.

    Cells without a sample take the speed interpolated along the road from the cells of
    the same time that have one; a time without any sample in the lane ends the
    trajectories on the road then.
    """
    t_edges = np.arange(span[0], span[1] + cell_t, cell_t)
    x_edges = np.arange(x_range[0], x_range[1] + cell_x, cell_x)
    grid = speed_field(t, x, speed, t_edges, x_edges).speed
    x_mid = 0.5 * (x_edges[1:] + x_edges[:-1])
    filled = np.full_like(grid, np.nan)
    for k in range(grid.shape[0]):
        have = np.isfinite(grid[k])
        if have.sum() >= 2:
            filled[k] = np.interp(x_mid, x_mid[have], grid[k][have])
        elif have.any():
            filled[k] = grid[k][have][0]
    departures = np.arange(span[0], span[1], depart_every)
    n_steps = math.floor((span[1] - span[0]) / dt) + 1
    pos = np.full(departures.size, np.nan)
    rows = {"v_id": [], "time": [], "x": [], "speed": []}
    for step in range(n_steps):
        now = span[0] + step * dt
        start = (departures <= now + 1e-9) & (departures > now - dt + 1e-9)
        pos[start] = x_range[0]
        active = np.flatnonzero(np.isfinite(pos))
        if active.size == 0:
            continue
        k = min(int((now - span[0]) // cell_t), filled.shape[0] - 1)
        row = filled[k]
        if not np.isfinite(row).any():
            pos[active] = np.nan
            continue
        v = np.interp(pos[active], x_mid, row)
        rows["v_id"].append(active)
        rows["time"].append(np.full(active.size, now))
        rows["x"].append(pos[active].copy())
        rows["speed"].append(v)
        pos[active] = pos[active] + v * dt
        pos[pos > x_range[1]] = np.nan
    if not rows["v_id"]:
        raise WaveAnalysisError("no virtual trajectory could run: the lane has no data")
    out = {name: np.concatenate(parts) for name, parts in rows.items()}
    order = np.lexsort((out["time"], out["v_id"]))
    return VirtualTrajectories(**{name: values[order] for name, values in out.items()})


def wave_points(
    vt: VirtualTrajectories, road: Road, lane: int, reference_mph: float = REFERENCE_MPH
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Fronts and tails of each virtual trajectory (the tables' columns)."""
    reference = reference_mph * MPH
    found = {1: [], 2: []}
    starts = np.flatnonzero(np.r_[True, vt.v_id[1:] != vt.v_id[:-1]])
    ends = np.r_[starts[1:], vt.v_id.size]
    for a, b in zip(starts, ends, strict=True):
        time, x, v = vt.time[a:b], vt.x[a:b], vt.speed[a:b]
        oscillation = (x - x[0]) - reference * (time - time[0])
        for kind, signal in ((1, oscillation), (2, -oscillation)):
            peaks, _ = find_peaks(signal)
            keep = peaks[np.abs(v[peaks] / MPH - reference_mph) <= BAND_MPH]
            if keep.size:
                found[kind].append(
                    (time[keep], x[keep], v[keep] / MPH, np.full(keep.size, vt.v_id[a]))
                )
    tables = []
    for kind in (1, 2):
        parts = found[kind]
        cols = [np.concatenate([p[j] for p in parts]) if parts else np.zeros(0) for j in range(4)]
        tables.append(
            pd.DataFrame(
                {
                    "time": cols[0],
                    "space": i24.mile_marker(cols[1], road),
                    "speed": cols[2],
                    "v_id": cols[3].astype(np.int64),
                    "wave_type": kind,
                    "lane": lane,
                }
            )
        )
    front, tail = tables
    front["unique_index"] = np.arange(len(front))
    tail["unique_index"] = len(front) + np.arange(len(tail))
    return front[POINT_COLUMNS], tail[POINT_COLUMNS]


def pair_points(front: pd.DataFrame, tail: pd.DataFrame) -> pd.DataFrame:
    """Each virtual trajectory's fronts paired with its tails in time order (the tool's
    rule: where its first point is a tail, that tail and then a last front are dropped;
    unmatched points are left out)."""
    columns = [f"{c}_front" for c in POINT_COLUMNS] + [f"{c}_tail" for c in POINT_COLUMNS]
    points = pd.concat([front, tail], ignore_index=True)
    pieces = []
    for _, vehicle in points.groupby("v_id", sort=False):
        if len(vehicle) < 2:
            continue
        vehicle = vehicle.sort_values("time", kind="stable")
        if vehicle["wave_type"].iloc[0] == 2:
            vehicle = vehicle.iloc[1:]
            if len(vehicle) and vehicle["wave_type"].iloc[-1] == 1:
                vehicle = vehicle.iloc[:-1]
        fronts = vehicle[vehicle["wave_type"] == 1]
        tails = vehicle[vehicle["wave_type"] == 2]
        n = min(len(fronts), len(tails))
        if n == 0:
            continue
        pieces.append(
            np.hstack([fronts[POINT_COLUMNS].to_numpy()[:n], tails[POINT_COLUMNS].to_numpy()[:n]])
        )
    if not pieces:
        return pd.DataFrame(columns=columns)
    return pd.DataFrame(np.vstack(pieces), columns=columns)


def chain(points: pd.DataFrame, road: Road) -> tuple[np.ndarray, np.ndarray]:
    """Trace id (1, 2, ...) of each point (``points`` of one wave type, in the tables'
    order): the tool's greedy chaining through consecutive virtual trajectories.

    Also the number of times the tool lists each point in its trace: twice where it was
    picked among several candidates (its ``SAG_track`` appends such a point in two
    branches), which repeats that point's pairs in ``CC``; kept so that the figures of
    new tables compare with the real ones like for like."""
    n = len(points)
    trace = np.zeros(n, dtype=np.int64)
    listed = np.ones(n, dtype=np.int64)
    if n == 0:
        return trace, listed
    v_id = points["v_id"].to_numpy(np.int64)
    time = points["time"].to_numpy(np.float64)
    # space counted upstream: mile markers grow upstream westbound, fall eastbound
    up = points["space"].to_numpy(np.float64) * (1.0 if road is Road.WESTBOUND else -1.0)
    by_vehicle = {v: np.flatnonzero(v_id == v) for v in np.unique(v_id)}
    masked = np.zeros(n, dtype=bool)
    trace_id = 0
    while not masked.all():
        trace_id += 1
        open_ids = np.unique(v_id[~masked])
        first = by_vehicle[open_ids[0]]
        start = first[~masked[first]][0]
        masked[start] = True
        trace[start] = trace_id
        t_now, u_now, previous = time[start], up[start], open_ids[0]
        for vehicle in open_ids[1:]:
            if vehicle - previous != 1:
                break
            previous = vehicle
            rows = by_vehicle[vehicle]
            rows = rows[~masked[rows]]
            near = rows[
                (time[rows] <= t_now + TRACE_AHEAD)
                & (time[rows] >= t_now - TRACE_BACK)
                & (up[rows] >= u_now - TRACE_DOWN)
                & (up[rows] <= u_now + TRACE_UP)
            ]
            if near.size == 0:
                break
            pick = near[np.argmax(time[near])]
            masked[pick] = True
            trace[pick] = trace_id
            listed[pick] = 2 if near.size > 1 else 1
            t_now, u_now = time[pick], up[pick]
    return trace, listed


def waves_of(
    pairs: pd.DataFrame, front: tuple[dict, dict], tail: tuple[dict, dict]
) -> pd.DataFrame:
    """``CC``: the pairs whose front trace and tail trace are joined through pairs into
    one wave with at least ``MIN_PAIRS`` pairs, numbered ``c_id`` in order of the waves'
    first front traces, each pair listed as often as the tool's table lists it (twice,
    times the times its front and its tail are listed in their traces).

    Args:
        front, tail: (trace id, times listed) of each point, by ``unique_index``.
    """
    pairs = pairs.copy()
    pairs["trace_id_front"] = pairs["unique_index_front"].map(front[0])
    pairs["trace_id_tail"] = pairs["unique_index_tail"].map(tail[0])
    pairs = pairs.dropna(subset=["trace_id_front", "trace_id_tail"])
    repeat = pairs["unique_index_front"].map(front[1]).to_numpy(np.int64) * pairs[
        "unique_index_tail"
    ].map(tail[1]).to_numpy(np.int64)
    pairs = pairs.loc[pairs.index.repeat(repeat)].reset_index(drop=True)
    pairs["trace_id_front"] = pairs["trace_id_front"].astype(np.int64)
    pairs["trace_id_tail"] = pairs["trace_id_tail"].astype(np.int64)
    parent: dict = {}

    def find(node):
        while parent.setdefault(node, node) != node:
            parent[node] = parent[parent[node]]
            node = parent[node]
        return node

    for f, t in zip(pairs["trace_id_front"], pairs["trace_id_tail"], strict=True):
        parent[find(("f", f))] = find(("t", t))
    root = pd.Series([find(("f", f)) for f in pairs["trace_id_front"]], dtype=object)
    wave_of = pd.factorize(root)[0]  # components numbered in order of first appearance
    out, c_id = [], 0
    for _, rows in pairs.groupby(wave_of, sort=True):
        if len(rows) >= MIN_PAIRS:
            c_id += 1
            out.extend([rows.assign(c_id=c_id)] * 2)
    columns = [*pairs.columns, "c_id"]
    if not out:
        return pd.DataFrame(columns=columns)
    return pd.concat(out, ignore_index=True)[columns]


def analyse_lane(vt: VirtualTrajectories, road: Road, lane: int, miles: float) -> LaneWaves:
    """Points, pairs, traces and waves of one lane's virtual trajectories."""
    number = LANE_NUMBER[lane]
    front, tail = wave_points(vt, road, number)
    pairs = pair_points(front, tail)
    cc = waves_of(pairs, _traces(front, road), _traces(tail, road))
    return LaneWaves(number, road, front, tail, cc, miles, vt)


def _traces(points: pd.DataFrame, road: Road) -> tuple[dict, dict]:
    trace, listed = chain(points, road)
    index = points["unique_index"].to_numpy()
    return dict(zip(index, trace, strict=True)), dict(zip(index, listed, strict=True))


def statistics(front: pd.DataFrame, cc: pd.DataFrame, miles: float, *, road: Road) -> dict:
    """The figures of the tables' README for one lane (see the module doc); front speeds
    are positive upstream on either carriageway (mile markers grow upstream westbound
    and fall upstream eastbound)."""
    upstream = 1.0 if Road.parse(road) is Road.WESTBOUND else -1.0
    sizes = cc.groupby("c_id").size() if len(cc) else pd.Series(dtype=int)
    big = sizes[sizes >= MIN_ROWS].index
    speeds = []
    for c in big:
        rows = cc[cc["c_id"] == c]
        if rows["time_front"].nunique() < 2:
            continue
        slope = np.polyfit(rows["time_front"].astype(float), rows["space_front"].astype(float), 1)[
            0
        ]
        speeds.append(upstream * slope * i24.MILE)
    speeds = np.array(speeds)
    gap = (cc["time_tail"].astype(float) - cc["time_front"].astype(float)).to_numpy()
    vehicles = front["v_id"].nunique()

    def r(value, digits=2):
        return None if value is None or not np.isfinite(value) else round(float(value), digits)

    return {
        "waves": len(big),
        "front_speed_mps": {
            "median": r(np.median(speeds)) if speeds.size else None,
            "p25": r(np.percentile(speeds, 25)) if speeds.size else None,
            "p75": r(np.percentile(speeds, 75)) if speeds.size else None,
        },
        "fronts_per_vehicle_mile": r(len(front) / vehicles / miles, 3) if vehicles else 0.0,
        "front_to_tail_s": {
            "median": r(np.median(gap), 1) if gap.size else None,
            "p90": r(np.percentile(gap, 90), 1) if gap.size else None,
        },
        "fronts": len(front),
        "vehicles_meeting_a_front": int(vehicles),
        "miles": round(float(miles), 3),
    }


def analyse_store(
    store: TrajectoryStore,
    road: Road | str,
    start: float | None = None,
    minutes: float | None = None,
    *,
    progress: bool = False,
) -> dict[int, LaneWaves]:
    """Every lane's waves on ``road`` from ``start`` (unix; default: the road's first
    sample) for ``minutes`` (default: to the road's last sample).

    Raises:
        WaveAnalysisError: the span is outside the data or shorter than two minutes.
    """
    road = Road.parse(road)
    first, last = store.time_range(road)
    t0 = first if start is None else float(start)
    t1 = last if minutes is None else t0 + 60.0 * float(minutes)
    t1 = min(t1, last)
    if not (math.isfinite(t0) and math.isfinite(t1)) or t1 - t0 < 120.0:
        raise WaveAnalysisError(
            f"no two minutes of {road.value} data from unix {t0:.0f}: the store's "
            f"{road.value} data run from {first:.0f} to {last:.0f}"
        )
    samples = store.samples(road, t0, t1)
    x_lo, x_hi = float(np.min(samples["x"])), float(np.max(samples["x"]))
    x_range = (x_lo + CELL_X, x_hi - CELL_X)
    miles = (x_range[1] - x_range[0]) / i24.MILE
    out = {}
    lanes = i24.LANES
    if progress:
        from twin.core.progress import progress_bar

        lanes = progress_bar(lanes, desc="lanes", unit="lane", leave=False)
    for lane in lanes:
        rows = samples["lane"] == lane
        if not rows.any():
            continue
        vt = virtual_trajectories(
            samples["t"][rows] - t0,
            samples["x"][rows],
            samples["speed"][rows].astype(np.float64),
            (0.0, t1 - t0),
            x_range,
        )
        out[lane] = analyse_lane(vt, road, lane, miles)
    if not out:
        raise WaveAnalysisError(f"no lane of {road.value} has data from unix {t0:.0f}")
    return out
