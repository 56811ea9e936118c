"""Lane-change flows of a recording: between which lanes, where along the road and when
its drivers change lanes, the net flow out of each lane by position, and how much of
it MOBIL's incentive explains (discretionary) or leaves unexplained in one direction
(strategic: a lane that ends, a merge, an exit beyond the window).

A recorded change is *explained* where MOBIL, judging the recorded scene with the
calibrated median driver, wanted that move at one of its decisions in the
:data:`EXPLAIN_BEFORE` seconds before the vehicle crossed the line. Of the changes it
does not explain, those of one lane pair and position bin are *strategic* where they
go one way more than chance allows: the excess of one direction over the other beyond
:data:`Z_DIRECTIONAL` standard deviations of a fair split (``|a - b| > z sqrt(a + b)``)
is the strategic flow of that bin. Divided by the vehicles passing the bin in the lane
left, it is the probability that a vehicle there leaves that lane for that reason,
which the calibrated behaviour reproduces.

The probability is also conditioned on the traffic state the vehicles were in
(:data:`STATE_NAMES`: the speed of the lane left, its mean in the ``CELL`` around the
vehicle, parted at :data:`STATE_SPEEDS`): a bin's strategic changes are shared among
the states in proportion to its unexplained changes in each, and divided by the
vehicles that passed it in that state, pulled towards the pooled probability by
:data:`PRIOR_PASSAGES` (a state few vehicles saw in a bin keeps near the pooled
figure). Drivers in a queue leave a lane that ends at other places than free-flowing
ones; a morning whose episodes run in another state than its calibration window then
draws the targets of its own state, not the window's average.
"""

import math

import numpy as np

from twin.calibration.following import (
    SPEED_BINS,
    GridTraffic,
    LaneChanges,
    distance_driven,
    lane_speeds,
)
from twin.calibration.lane_changes import Incentives
from twin.core.i24 import LANES

POSITION_BIN = 100.0  # [m] bins along the road
TIME_BIN = 60.0  # [s] bins over the window
EXPLAIN_BEFORE = 4.0  # [s] MOBIL decisions this long before a crossing count as its cause
Z_DIRECTIONAL = 2.0  # standard deviations of a fair split a directional flow must exceed
#: strategic changes a recording needs before its strategic flow is used (fewer: MOBIL alone)
MIN_STRATEGIC = 10
#: [m] how far ahead drivers heed a lane they would have to leave (a lane that ends, a
#: merge): one mile, where the first sign of a lane drop stands on US freeways
LOOKAHEAD = 1609.0
#: a lane is one to keep out of where at least this share of its vehicles must leave it
#: (strategically) within LOOKAHEAD
KEEP_OUT_SHARE = 0.5
#: [m/s] the lane speeds that part the traffic states a strategic flow is conditioned
#: on (module doc): a queue below the first, congested traffic up to the second, free
#: flow above
STATE_SPEEDS = SPEED_BINS[1:3]  # 5 and 15 m/s: the lane-change rates' bins
STATE_NAMES = ("queue", "congested", "free")
#: [vehicles] what the pooled probability weighs against a state's own passages in a bin
PRIOR_PASSAGES = 20.0


def pair_name(lane_from: int, lane_to: int) -> str:
    """``"-3>-2"``: the key of a lane pair."""
    return f"{int(lane_from)}>{int(lane_to)}"


def explained_by_mobil(
    changes: LaneChanges, incentives: Incentives, threshold: float, t0: float, every: float
) -> np.ndarray:
    """(c,) bool: MOBIL wanted each recorded change at a decision in the
    :data:`EXPLAIN_BEFORE` s before it (its incentive beat ``threshold`` where the move
    was possible, as :meth:`Incentives.changes` counts them).

    ``incentives`` are MOBIL's decisions every ``every`` seconds from ``t0`` (the grid's
    start), sorted by (tid, direction, decision) as
    :func:`~twin.calibration.lane_changes.recorded_incentives` returns them.
    """
    out = np.zeros(len(changes), dtype=bool)
    if len(changes) == 0 or incentives.tid.size == 0:
        return out
    # one integer per (tid, direction) in the incentives' order, then the decisions
    key = incentives.tid.astype(np.int64) * 2 + (incentives.direction > 0)
    direction = np.sign(changes.lane_to.astype(np.int64) - changes.lane_from)
    wanted = incentives.possible & (incentives.gain > threshold)  # as fit_threshold counts
    first = np.ceil((changes.time - EXPLAIN_BEFORE - t0) / every - 1e-9).astype(np.int64)
    last = np.floor((changes.time - t0) / every + 1e-9).astype(np.int64)
    for i in range(len(changes)):
        k = int(changes.tid[i]) * 2 + int(direction[i] > 0)
        a, b = np.searchsorted(key, [k, k + 1])
        if a == b:
            continue
        decision = incentives.decision[a:b]
        lo, hi = np.searchsorted(decision, [first[i], last[i] + 1])
        out[i] = bool(wanted[a:b][lo:hi].any())
    return out


def traffic_state(lane_speed) -> np.ndarray:
    """Index into :data:`STATE_NAMES` of each lane speed [m/s] (an empty lane, NaN, is
    free)."""
    v = np.nan_to_num(np.asarray(lane_speed, dtype=np.float64), nan=np.inf)
    return np.searchsorted(np.asarray(STATE_SPEEDS), v, side="right")


def traffic_states(grid: GridTraffic, changes: LaneChanges, x_edges: np.ndarray) -> tuple:
    """(passing, change_state): the vehicles passing each position bin in each lane per
    traffic state (a list, one (4 lanes, bins) array per :data:`STATE_NAMES`), each row
    in the state of its own lane; and (c,) the state of each change, its lane's speed on
    the vehicle's last row before it crossed (the vehicle itself counted, as in the
    passages and in the twin's draw)."""
    if not len(grid):
        empty = np.zeros((len(LANES), x_edges.size - 1))
        return [empty.copy() for _ in STATE_NAMES], np.zeros(len(changes), np.int64)
    speeds = lane_speeds(grid)
    own_lane = np.maximum(-grid.lane.astype(np.int64) - 1, 0)
    row_state = traffic_state(speeds[np.arange(len(grid)), own_lane])
    passing = [passages(grid, x_edges, row_state == s) for s in range(len(STATE_NAMES))]
    span = int(grid.k.max()) + 2
    key = grid.tid.astype(np.int64) * span + grid.k
    step = np.round((changes.time - grid.t0) / grid.dt).astype(np.int64)
    row = np.searchsorted(key, changes.tid.astype(np.int64) * span + step)
    before = np.clip(row - 1, 0, len(grid) - 1)  # a change is never a track's first row
    left = np.maximum(-changes.lane_from.astype(np.int64) - 1, 0)
    return passing, traffic_state(speeds[before, left])


def passages(grid: GridTraffic, x_edges: np.ndarray, rows: np.ndarray | None = None) -> np.ndarray:
    """(4 lanes, bins) vehicles passing each position bin in each lane (vehicle-km
    driven there over the bin's length); ``rows``: (n,) bool, only those rows."""
    distance = distance_driven(grid)
    on = grid.lane != 0
    if rows is not None:
        on &= rows
    at = np.searchsorted(x_edges, grid.x[on], side="right") - 1
    inside = (at >= 0) & (at < x_edges.size - 1)
    out = np.zeros((len(LANES), x_edges.size - 1))
    np.add.at(out, (-grid.lane[on][inside].astype(np.int64) - 1, at[inside]), distance[on][inside])
    return out / np.diff(x_edges)


def grid_edges(grid: GridTraffic) -> np.ndarray:
    """[m] :func:`flow_edges` covering ``grid``'s positions."""
    return flow_edges(float(grid.x.min()), float(grid.x.max())) if len(grid) else flow_edges(0, 0)


def flow_edges(x_min: float, x_max: float) -> np.ndarray:
    """[m] position bin edges of :data:`POSITION_BIN` covering ``[x_min, x_max]``."""
    lo = math.floor(x_min / POSITION_BIN) * POSITION_BIN
    hi = max(math.ceil(x_max / POSITION_BIN) * POSITION_BIN, lo + POSITION_BIN)
    return np.arange(lo, hi + 0.5 * POSITION_BIN, POSITION_BIN)


def by_position(changes: LaneChanges, x_edges: np.ndarray) -> dict:
    """``{pair: counts per position bin}`` and ``{lane: net flow out per bin}`` (changes
    leaving the lane less those entering it)."""
    at = np.clip(np.searchsorted(x_edges, changes.x, side="right") - 1, 0, x_edges.size - 2)
    pairs, net = {}, {str(lane): np.zeros(x_edges.size - 1, dtype=np.int64) for lane in LANES}
    for a, b in sorted(set(zip(changes.lane_from.tolist(), changes.lane_to.tolist(), strict=True))):
        rows = (changes.lane_from == a) & (changes.lane_to == b)
        counts = np.bincount(at[rows], minlength=x_edges.size - 1)
        pairs[pair_name(a, b)] = counts
        net[str(a)] += counts
        net[str(b)] -= counts
    return {"pairs": pairs, "net_out": net}


def lane_change_flows(
    changes: LaneChanges,
    grid: GridTraffic,
    explained: np.ndarray,
    *,
    min_strategic: int = MIN_STRATEGIC,
    states: tuple | None = None,
) -> dict:
    """The recording's lane-change flows (module doc) as a JSON-ready dict.

    Args:
        changes: the recorded lane changes; grid: the recording they come from.
        explained: (c,) bool, :func:`explained_by_mobil` of each change.
        min_strategic: fewer strategic changes than this identify no strategic flow
            (``identified`` false, with the reason in ``note``).
        states: :func:`traffic_states` of ``grid``, ``changes`` and the flows' bins
            (computed when None; the calibration's refits pass them once made).
    """
    x_edges = grid_edges(grid)
    t0 = float(grid.t0)
    t1 = t0 + float(grid.k.max()) * grid.dt if len(grid) else t0
    t_edges = np.arange(0.0, max(t1 - t0, 0.0) + TIME_BIN, TIME_BIN)
    n_bins = x_edges.size - 1
    at_x = np.clip(np.searchsorted(x_edges, changes.x, side="right") - 1, 0, n_bins - 1)
    at_t = np.clip(
        np.searchsorted(t_edges, changes.time - t0, side="right") - 1, 0, max(t_edges.size - 2, 0)
    )
    passing = passages(grid, x_edges)
    if states is None:
        states = traffic_states(grid, changes, x_edges)
    passing_by_state, change_state = states
    pairs, strategic = {}, {}
    position = by_position(changes, x_edges)
    for name, counts in position["pairs"].items():
        a, b = (int(v) for v in name.split(">"))
        rows = (changes.lane_from == a) & (changes.lane_to == b)
        pairs[name] = {
            "count": int(rows.sum()),
            "explained": int((rows & explained).sum()),
            "by_position": counts.tolist(),
            "by_time": np.bincount(at_t[rows], minlength=max(t_edges.size - 1, 1)).tolist(),
        }
        # the unexplained, one way more than a fair split allows
        mine = np.bincount(at_x[rows & ~explained], minlength=n_bins)
        back = (changes.lane_from == b) & (changes.lane_to == a) & ~explained
        theirs = np.bincount(at_x[back], minlength=n_bins)
        excess = mine - theirs
        excess = np.where(excess > Z_DIRECTIONAL * np.sqrt(mine + theirs), excess, 0)
        if excess.any():
            lane_index = -a - 1
            with np.errstate(divide="ignore", invalid="ignore"):
                p = np.where(passing[lane_index] > 0, excess / passing[lane_index], 0.0)
            strategic[name] = {
                "count": int(excess.sum()),
                "by_position": excess.tolist(),
                "probability": np.round(np.minimum(p, 1.0), 4).tolist(),
                "probability_by_state": _by_state(
                    excess, mine, np.minimum(p, 1.0), at_x, rows & ~explained, change_state,
                    [passing_s[lane_index] for passing_s in passing_by_state],
                ),
            }  # fmt: skip
    total = len(changes)
    n_strategic = sum(s["count"] for s in strategic.values())
    identified = n_strategic >= min_strategic
    note = (
        ""
        if identified
        else (
            f"{n_strategic} strategic changes (need {min_strategic}) to identify a strategic "
            "flow: MOBIL alone"
        )
    )
    return {
        "position_bin_m": POSITION_BIN,
        "x_edges": x_edges.tolist(),
        "time_bin_s": TIME_BIN,
        "t_edges": t_edges.tolist(),
        "changes": total,
        "explained": int(explained.sum()),
        "unexplained": int(total - explained.sum()),
        "strategic_count": n_strategic,
        "strategic_share": round(n_strategic / total, 4) if total else 0.0,
        "identified": identified,
        "note": note,
        "pairs": pairs,
        "net_out": {lane: v.tolist() for lane, v in position["net_out"].items()},
        "passing": {str(lane): np.round(passing[k], 2).tolist() for k, lane in enumerate(LANES)},
        "states": {
            "names": list(STATE_NAMES),
            "speeds": list(STATE_SPEEDS),
            "prior_passages": PRIOR_PASSAGES,
            "passing": {
                name: {str(lane): np.round(ps[k], 2).tolist() for k, lane in enumerate(LANES)}
                for name, ps in zip(STATE_NAMES, passing_by_state, strict=True)
            },
        },
        "strategic": strategic if identified else {},
    }


def _by_state(excess, mine, pooled, at_x, rows, change_state, passing) -> dict:
    """``{state: (bins,) probability}`` of one strategic pair (module doc): the bins'
    strategic changes ``excess`` shared among the states as the pair's unexplained
    changes ``rows`` (``mine`` of them per bin) are, over the state's ``passing``
    vehicles, pulled towards the ``pooled`` probability by :data:`PRIOR_PASSAGES`."""
    n_bins = excess.size
    out = {}
    for s, name in enumerate(STATE_NAMES):
        mine_s = np.bincount(at_x[rows & (change_state == s)], minlength=n_bins)
        share = np.divide(mine_s, mine, out=np.zeros(n_bins), where=mine > 0)
        p = (excess * share + PRIOR_PASSAGES * pooled) / (passing[s] + PRIOR_PASSAGES)
        out[name] = np.round(np.minimum(p, 1.0), 4).tolist()
    return out


def keep_out(flows: dict, lookahead: float = LOOKAHEAD, share: float = KEEP_OUT_SHARE) -> list:
    """Where drivers keep out of a lane (no discretionary change into it): where the
    strategic flows say that at least ``share`` of its vehicles must leave it within
    ``lookahead`` metres (a lane that ends, a merge), as the recording's drivers do when
    they resist a faster lane that ends ahead. Returns ``[{"lane", "x0", "x1"}, ...]``
    [m], contiguous bins merged."""
    edges = np.asarray(flows["x_edges"], dtype=np.float64)
    n = edges.size - 1
    zones = []
    for lane in LANES:
        stay = np.ones(n)  # the share of the lane's vehicles a bin lets stay in it
        for name, flow in flows.get("strategic", {}).items():
            if int(name.split(">")[0]) == lane:
                stay *= 1.0 - np.minimum(np.asarray(flow["probability"], dtype=np.float64), 1.0)
        leave = np.array(
            [
                1.0 - stay[(edges[:-1] >= x) & (edges[:-1] < x + lookahead)].prod()
                for x in edges[:-1]
            ]
        )
        inside = leave >= share
        starts = np.flatnonzero(inside & ~np.r_[False, inside[:-1]])
        ends = np.flatnonzero(inside & ~np.r_[inside[1:], False])
        zones += [
            {"lane": lane, "x0": float(edges[a]), "x1": float(edges[b + 1])}
            for a, b in zip(starts, ends, strict=True)
        ]
    return zones


def in_keep_out(zones: list, lane, x) -> np.ndarray:
    """(k,) bool: places ``x`` (k,) [m] in lanes ``lane`` (k,) lie in one of ``zones``."""
    as_tuples = [(0, z["lane"], z["x0"], z["x1"]) for z in zones]  # one road here
    return kept_out(as_tuples, 0, np.asarray(lane), x)


def describe_flows(flows: dict) -> list[str]:
    """Lines for ``twin data info``: what the recording's lane-change flows hold."""
    if not flows:
        return []
    total = flows["changes"]
    lines = [
        f"    lane-change flows: {total} changes in {flows['position_bin_m']:.0f} m bins; "
        f"MOBIL explains {flows['explained']}, {flows['strategic_count']} strategic "
        f"({100 * flows['strategic_share']:.0f} %)"
    ]
    if not flows["identified"]:
        lines.append(f"      {flows['note']}")
        return lines
    edges = flows["x_edges"]
    for name, s in sorted(flows["strategic"].items()):
        bins = np.flatnonzero(np.asarray(s["by_position"]) > 0)
        span = f"x {edges[bins[0]]:.0f} to {edges[bins[-1] + 1]:.0f} m" if bins.size else ""
        lines.append(
            f"      {name}: {s['count']} strategic, {span}, up to "
            f"{100 * max(s['probability']):.0f} % of the lane's vehicles per bin"
        )
    for z in flows.get("keep_out", []):
        lines.append(
            f"      lane {z['lane']} kept out of from x {z['x0']:.0f} to {z['x1']:.0f} m "
            f"(it must be left ahead)"
        )
    return lines


def kept_out(zones, road, lane, x) -> np.ndarray:
    """(k,) bool: ``lane`` (k,) at ``x`` (k,) [m] on ``road`` lies in one of the
    keep-out ``zones``, (road, lane, x0, x1) each (half-open in x; the traffic kernels'
    test, :func:`twin.traffic.kernels.lane_change.kept_out`)."""
    x = np.asarray(x, dtype=np.float64)
    out = np.zeros(x.shape, dtype=bool)
    for z_road, z_lane, x0, x1 in zones:
        out |= (road == z_road) & (lane == z_lane) & (x >= x0) & (x < x1)
    return out
