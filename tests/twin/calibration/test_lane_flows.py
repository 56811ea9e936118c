"""Lane-change flows of a recording: by lane pair and position, discretionary and strategic."""

import numpy as np
import pytest

from twin.calibration.following import GridTraffic, lane_changes
from twin.calibration.lane_changes import Incentives
from twin.calibration.lane_flows import (
    describe_flows,
    explained_by_mobil,
    lane_change_flows,
)
from twin.core.i24 import Road, lane_center

DT = 0.1


def _grid(tracks, speeds=None):
    """A recording on the grid: each track (first step, lane before, change x or None,
    lane after) driven at 20 m/s (or its ``speeds``) from x = 0 to 1000 m."""
    cols = {name: [] for name in ("tid", "k", "x", "lane", "speed")}
    for tid, (k0, lane, x_change, lane_after) in enumerate(tracks):
        v = 20.0 if speeds is None else speeds[tid]
        x = np.arange(0.0, 1000.0, v * DT)
        cols["speed"].append(np.full(x.size, v))
        lanes = np.full(x.size, lane, dtype=np.int8)
        if x_change is not None:
            lanes[x >= x_change] = lane_after
        cols["tid"].append(np.full(x.size, tid))
        cols["k"].append(k0 + np.arange(x.size))
        cols["x"].append(x)
        cols["lane"].append(lanes)
    c = {name: np.concatenate(v) for name, v in cols.items()}
    n = c["tid"].size
    return GridTraffic(
        road=Road.WESTBOUND, dt=DT, t0=1.0e9, tid=c["tid"], k=c["k"], x=c["x"],
        speed=c["speed"], y=lane_center(c["lane"]), lane=c["lane"],
        length=np.full(n, 4.5), vehicle_class=np.zeros(n, dtype=np.int8),
        leader=np.full(n, -1), gap=np.full(n, np.inf),
    )  # fmt: skip


def _recording(strategic: int, seed: int = 0):
    """Vehicles in lanes -3 and -2; ``strategic`` of lane -3's leave it between x = 600
    and 700 m; 20 each way change between the two lanes anywhere (no direction)."""
    rng = np.random.default_rng(seed)
    tracks = []
    for i in range(200):
        k0 = 15 * i
        if i < strategic:
            tracks.append((k0, -3, rng.uniform(600.0, 700.0), -2))
        elif i < strategic + 20:
            tracks.append((k0, -3, rng.uniform(50.0, 900.0), -2))
        elif i < strategic + 40:
            tracks.append((k0, -2, rng.uniform(50.0, 900.0), -3))
        else:
            tracks.append((k0, -3 if i % 2 else -2, None, None))
    return _grid(tracks)


def test_a_directional_unexplained_flow_is_found_where_and_between_which_lanes_it_is():
    grid = _recording(60)
    changes = lane_changes(grid)
    assert len(changes) == 100
    flows = lane_change_flows(changes, grid, np.zeros(len(changes), dtype=bool))
    assert flows["identified"] and flows["changes"] == 100
    edges = np.array(flows["x_edges"])
    strategic = flows["strategic"]
    assert list(strategic) == ["-3>-2"]  # the way back is no flow of its own
    by_position = np.array(strategic["-3>-2"]["by_position"])
    assert set(edges[np.flatnonzero(by_position)]) == {600.0}  # the bin where they leave
    assert 55 <= strategic["-3>-2"]["count"] <= 62  # the 60, less the noise's chance excess
    # the share of lane -3's vehicles passing that bin who leave it there
    bin_600 = int(np.flatnonzero(edges == 600.0)[0])
    passing = flows["passing"]["-3"][bin_600]
    p = strategic["-3>-2"]["probability"][bin_600]
    assert p == round(by_position[bin_600] / passing, 4) and 0.4 < p < 0.8
    # changes by pair and position, and the net flow out of lane -3 there
    assert flows["pairs"]["-3>-2"]["count"] == 80 and flows["pairs"]["-2>-3"]["count"] == 20
    net = np.array(flows["net_out"]["-3"])
    assert net[bin_600] >= 55 and net.sum() == 60
    assert sum(flows["pairs"]["-3>-2"]["by_time"]) == 80
    lines = describe_flows(flows)
    assert "strategic" in lines[0] and "-3>-2" in lines[1] and "600 to 700 m" in lines[1]


def test_the_strategic_probability_is_conditioned_on_the_traffic_state():
    # lane -3 ends for 40 of 100 free-flowing vehicles and, later, for 10 of 100 in a
    # queue, all between 600 and 700 m
    rng = np.random.default_rng(1)
    tracks, speeds = [], []
    for i in range(200):
        queue = i >= 100
        k0 = 15 * i + (3000 if queue else 0)  # the queue after the free flow has gone
        leaves = (i - 100 if queue else i) < (10 if queue else 40)
        tracks.append((k0, -3, rng.uniform(600.0, 700.0) if leaves else None, -2))
        speeds.append(3.0 if queue else 20.0)
    grid = _grid(tracks, speeds)
    changes = lane_changes(grid)
    assert len(changes) == 50
    flows = lane_change_flows(changes, grid, np.zeros(len(changes), dtype=bool))
    assert flows["states"]["names"] == ["queue", "congested", "free"]
    bin_600 = flows["x_edges"].index(600.0)
    passing = {s: flows["states"]["passing"][s]["-3"][bin_600] for s in ("queue", "free")}
    # those that leave inside the bin pass half of it
    assert passing["queue"] == pytest.approx(95, abs=2)
    assert passing["free"] == pytest.approx(80, abs=2)
    flow = flows["strategic"]["-3>-2"]
    pooled = flow["probability"][bin_600]
    by_state = {s: p[bin_600] for s, p in flow["probability_by_state"].items()}
    assert 0.2 < pooled < 0.3
    # each state's own share, pulled towards the pooled one by PRIOR_PASSAGES vehicles
    prior = flows["states"]["prior_passages"]
    for state, left in (("free", 40), ("queue", 10)):
        expected = (left + prior * pooled) / (passing[state] + prior)
        assert by_state[state] == pytest.approx(expected, abs=0.02), state
    assert by_state["queue"] < 0.17 < pooled < by_state["free"]
    assert by_state["congested"] == pooled  # seen by no one: the pooled figure
    # outside the flow's bins no state leaves
    assert all(p[bin_600 - 1] == 0.0 for p in flow["probability_by_state"].values())


def test_changes_mobil_explains_or_too_few_to_tell_leave_mobil_alone():
    grid = _recording(60)
    changes = lane_changes(grid)
    explained = np.ones(len(changes), dtype=bool)
    flows = lane_change_flows(changes, grid, explained)
    assert not flows["identified"] and flows["strategic"] == {}
    assert "MOBIL alone" in flows["note"] and flows["explained"] == 100
    few = _recording(6)
    changes = lane_changes(few)
    flows = lane_change_flows(changes, few, np.zeros(len(changes), dtype=bool))
    assert not flows["identified"] and "need 10" in flows["note"]
    assert "MOBIL alone" in describe_flows(flows)[1]


def test_a_change_is_explained_by_mobil_wanting_it_in_the_seconds_before():
    grid = _recording(0)
    changes = lane_changes(grid)
    order = np.argsort(changes.tid)
    tid, time = changes.tid[order][:3], changes.time[order][:3]
    direction = np.sign(changes.lane_to[order][:3].astype(int) - changes.lane_from[order][:3])
    decision = np.floor((time - grid.t0) / 1.0).astype(int)
    # change 0: wanted 2 s before; change 1: wanted 10 s before only; change 2: wanted
    # the other way
    incentives = Incentives(
        tid=np.array([tid[0], tid[1], tid[2]]),
        decision=np.array([decision[0] - 2, decision[1] - 10, decision[2]]),
        direction=np.array([direction[0], direction[1], -direction[2]], dtype=np.int8),
        gain=np.array([1.0, 1.0, 1.0]),
        possible=np.ones(3, dtype=bool),
        x=np.zeros(3),
        lane=np.full(3, -2),
    )
    lex = np.lexsort((incentives.decision, incentives.direction, incentives.tid))
    incentives = Incentives(*(getattr(incentives, f)[lex] for f in Incentives.__dataclass_fields__))
    explained = explained_by_mobil(changes, incentives, 0.5, grid.t0, 1.0)
    assert explained[order][:3].tolist() == [True, False, False]
    assert not explained_by_mobil(changes, incentives, 1.5, grid.t0, 1.0).any()  # below it


def test_the_threshold_is_refitted_away_from_the_strategic_bins_on_both_sides():
    from types import SimpleNamespace

    from twin.calibration.calibrate import _away_from_strategic

    flows = {
        "x_edges": [0.0, 100.0, 200.0, 300.0],
        "strategic": {
            "-4>-3": {"by_position": [0, 0, 5], "probability": [0.0, 0.0, 0.1]},
            "-3>-2": {"by_position": [0, 2, 0], "probability": [0.0, 0.05, 0.0]},
        },
    }
    changes = SimpleNamespace(x=np.array([50.0, 150.0, 250.0, 350.0]), lane_to=np.full(4, -2))
    incentives = SimpleNamespace(
        x=np.array([10.0, 120.0, 299.0, -20.0]),
        lane=np.full(4, -3),
        direction=np.full(4, 1, dtype=np.int8),
    )
    away_changes, away_decisions = _away_from_strategic(flows, changes, incentives)
    # beyond the edges a place counts in the nearest bin, as the flows count it
    assert away_changes.tolist() == [True, False, False, False]
    assert away_decisions.tolist() == [True, False, False, True]


def test_a_lane_most_drivers_must_leave_ahead_is_kept_out_of_upstream():
    from twin.calibration.lane_flows import in_keep_out, keep_out

    edges = np.arange(0.0, 1100.0, 100.0)  # 10 bins
    p = np.zeros(10)
    p[8], p[9] = 0.5, 1.0  # lane -4 ends at 1000 m: half leave in 800-900, all by 1000
    flows = {
        "x_edges": edges.tolist(),
        "strategic": {
            "-4>-3": {"by_position": (p > 0).astype(int).tolist(), "probability": p.tolist()},
            "-2>-3": {"by_position": [0] * 9 + [1], "probability": [0.0] * 9 + [0.1]},
        },
    }
    zones = keep_out(flows, lookahead=300.0)
    # from 300 m before the first bin that leaves half; lane -2's 10 % is no lane end
    assert zones == [{"lane": -4, "x0": 600.0, "x1": 1000.0}]
    assert in_keep_out(zones, [-4, -4, -3, -4], [599.0, 600.0, 700.0, 999.0]).tolist() == [
        False,
        True,
        False,
        True,
    ]
    assert keep_out({**flows, "strategic": {}}) == []


def test_the_refit_keeps_the_first_fit_where_too_few_decisions_lie_away(monkeypatch):
    from types import SimpleNamespace

    import twin.calibration.calibrate as calibrate
    from twin.calibration.lane_changes import fit_threshold

    # every decision lies in a bin with a strategic flow: nothing to refit on (before,
    # the refit judged no decision at all and returned a threshold of 0)
    flows = {
        "identified": True,
        "x_edges": [0.0, 100.0],
        "strategic": {"-4>-3": {"by_position": [3], "probability": [0.2]}},
        "strategic_count": 3,
    }
    monkeypatch.setattr(calibrate, "lane_change_flows", lambda *args, **kwargs: dict(flows))
    monkeypatch.setattr(calibrate, "grid_edges", lambda grid: None)
    monkeypatch.setattr(calibrate, "traffic_states", lambda *args: None)
    monkeypatch.setattr(calibrate, "explained_by_mobil", lambda *args: np.zeros(1, bool))
    incentives = Incentives(
        tid=np.array([1, 1]),
        decision=np.array([0, 2]),  # two onsets at a threshold of 0
        direction=np.ones(2, dtype=np.int8),
        gain=np.array([0.5, 2.0]),
        possible=np.ones(2, dtype=bool),
        x=np.array([50.0, 60.0]),
        lane=np.full(2, -3),
    )

    class Changes(SimpleNamespace):
        def __len__(self):
            return self.x.size

    changes = Changes(x=np.array([50.0]), lane_to=np.array([-2]))
    grid = SimpleNamespace(dt=0.1, t0=0.0)
    mobil, _ = calibrate._lane_change_flows(
        grid, changes, incentives, SimpleNamespace(decision_every=1.0)
    )
    assert mobil["threshold"] == fit_threshold(incentives, 1)["threshold"] > 0.0
    assert "too few" in mobil["note"]


def test_a_change_is_in_the_state_of_the_lane_it_left_the_vehicle_itself_counted():
    from twin.calibration.lane_flows import STATE_NAMES, grid_edges, traffic_states

    # one vehicle alone, crawling in lane -3, leaves it for lane -2 at 600 m: its lane
    # was a queue (before, the lane was judged without it: empty, so free)
    grid = _grid([(0, -3, 600.0, -2)], speeds=[3.0])
    changes = lane_changes(grid)
    passing, state = traffic_states(grid, changes, grid_edges(grid))
    assert [STATE_NAMES[s] for s in state] == ["queue"]
    assert passing[0].sum() > 0 and passing[2].sum() == 0
