"""On-ramp merges in the cosimulation: recorded vehicles on the westbound Old Hickory
Blvd on-ramp's acceleration lane (lane -5) are replayed there, spawned there once
visible, and merge into lane -4 before the lane's taper ends, with lane -4's drivers
making room; one that finds no gap waits at the lane's end."""

import json
import shutil
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from tests.twin.cosim.scenes import T0, hold_speed, make_store, vehicle
from twin.calibration.calibrate import CALIBRATION, FITS
from twin.calibration.merge_positions import QUANTILES
from twin.core import i24
from twin.core.ramps import RAMP_LANE, segment_ramps
from twin.cosim.config import CosimConfig
from twin.cosim.core.drivers import MID_MERGE
from twin.cosim.cosimulator import Cosimulator
from twin.data.empirical import EmpiricalTraffic
from twin.data.recording import load_recording, replay
from twin.metrics.merges import merge_section

RAMP = next(r for r in segment_ramps() if r.road == i24.Road.WESTBOUND)
EGO_X = 120.0  # [m] the visible window (150 m either side) holds the ramp's end


def ramp_vehicle(n: int, x: float, speed: float, merge_x: float, seconds: float = 40.0, **doc):
    """A westbound document: at T0 its back is at ``x`` [m] on the acceleration lane,
    at constant ``speed``; its recording moves to lane -4 at ``merge_x`` (``doc``:
    :func:`vehicle`'s other settings)."""
    doc = vehicle(n, RAMP_LANE, x, speed, seconds=seconds, **doc)
    x_m = (i24.SEGMENT_END_MM * i24.FEET_PER_MILE - np.asarray(doc["x_position"])) * i24.FT
    lane_4 = 4.5 * i24.LANE_WIDTH_FT  # lane -4's centre [ft]
    doc["y_position"] = np.where(x_m < merge_x, doc["y_position"], lane_4).tolist()
    return doc


def _run(built_map, tmp_path, docs, t_max=30.0, lane=-2, speed=12.0, anchor=None, **traffic):
    """A kinematic run of ``docs`` with the ego in ``lane`` at EGO_X at ``speed``
    (``traffic``: settings of the traffic manager changed; ``anchor`` the run's)."""
    store = make_store(tmp_path, [*docs, vehicle(999, lane, EGO_X, speed, seconds=60.0)])
    config = CosimConfig(road="westbound", lane=lane, x=EGO_X, time=T0, t_max=t_max,
                         world="kinematic", anchor=anchor)  # fmt: skip
    config = replace(config, traffic=replace(config.traffic, **traffic))
    with Cosimulator(config, EmpiricalTraffic(store), built_map) as sim:
        sim.reset()
        sim.run()
        rows = sim.log.vehicles()
        lengths = store.trajectory_arrays["length"]
        return sim, store, rows, merge_section(rows, lengths, [RAMP.x_end]), lengths


def _run_from(built_map, tmp_path, docs, ego_x, t_max, controller=None):
    """A kinematic run of ``docs`` with the ego in lane -2 at ``ego_x`` [m] (driven by
    ``controller``, else its driver): how many recordings were made bodies for crowding
    one (yielded) and held back, and the contacts and collisions."""
    store = make_store(tmp_path, docs)
    config = CosimConfig(road="westbound", lane=-2, x=ego_x, time=T0, t_max=t_max,
                         world="kinematic")  # fmt: skip
    with Cosimulator(config, EmpiricalTraffic(store), built_map, controller=controller) as sim:
        sim.reset()
        sim.run()
        ep = sim.state.episodes
        return {"yielded": int(ep.yielded[0]), "held": int(ep.held[0]),
                "contacts": sim.counters.contacts,
                "collisions": list(sim.counters.collisions)}  # fmt: skip


def test_the_recording_replays_the_ramp_samples(tmp_path):
    doc = ramp_vehicle(1, 0.0, 15.0, merge_x=100.0)
    store = make_store(tmp_path, [doc])
    rec = load_recording(store, "westbound")
    present, x, y, _ = replay(rec, np.int64(0), T0 + 2.0)  # on the ramp: replayed there
    assert present and x == pytest.approx(30.0, abs=0.1)
    assert y == pytest.approx(5.5 * i24.LANE_WIDTH, abs=1e-3)
    # the trajectory table's first time is the four lanes' (its first lane -4 sample)
    assert rec.t_first[0] < store.trajectory_arrays["t_first"][0] - 5.0


def test_ramp_vehicles_merge_before_the_taper_ends_and_lane_4_makes_room(built_map, tmp_path):
    docs = [vehicle(100 + k, -4, -250.0 + 18.0 * k, 12.0, seconds=60.0) for k in range(30)]
    docs += [ramp_vehicle(1 + k, -30.0 + 22.0 * k, 12.0, merge_x=110.0) for k in range(4)]
    # relaxing without anchors, so the simulated region has no bound: the first ramp
    # vehicle, at the window's rear edge, falls 100 m behind it before its merge (with
    # anchors, the default, it ends where it leaves the region and its recording merges)
    sim, store, rows, merges, lengths = _run(built_map, tmp_path, docs, anchor=False)
    # every recorded ramp vehicle was simulated on the ramp and merged in time (one at
    # the window's rear edge is spawned and handed back a few times before it stays)
    ramp_tids = [store.tid_of(f"{1 + k:024x}") for k in range(4)]
    on_ramp = rows[rows["lane"] == RAMP_LANE]
    assert set(on_ramp["tid"]) == set(ramp_tids)
    merged = rows[rows["tid"].isin(ramp_tids) & (rows["lane"] == -4)]
    assert set(merged["tid"]) == set(ramp_tids)
    assert merges["merged"] == merges["before_taper_end"] == 4
    assert merges["waiting"] == 0 and merges["completed_share"] == 1.0
    # counted apart from the lane changes (not the one begun while relaxing toward its
    # recording at the window's rear edge: the recording's)
    assert sim.manager.merges == 3
    assert not sim.counters.collisions
    # nobody drives on the acceleration lane past its end
    front = on_ramp["x"].to_numpy() + lengths[on_ramp["tid"].to_numpy()]
    assert front.max() <= RAMP.x_end


def test_a_ramp_vehicle_with_no_gap_waits_on_its_lane(built_map, tmp_path):
    # lane -4 stands bumper to bumper beside the whole ramp: the ramp vehicle, urgent past
    # the taper's start, settles beside the queue and waits there for a gap
    docs = [vehicle(100 + k, -4, -300.0 + 7.0 * k, 0.0, seconds=60.0) for k in range(90)]
    docs.append(ramp_vehicle(1, 40.0, 10.0, merge_x=130.0))
    sim, store, rows, merges, lengths = _run(
        built_map, tmp_path, docs, t_max=25.0, lane=-1, speed=0.0
    )
    assert merges == {
        "ramp_vehicles": 1, "merged": 0, "before_taper_end": 0, "waiting": 1,
        "waiting_at_end": 0, "unfinished": 0, "entered_past_end": 0, "completed_share": 0.0,
        "in_time_share": None,
    }  # fmt: skip
    own = rows[rows["tid"] == store.tid_of(f"{1:024x}")]
    assert (own["lane"] == RAMP_LANE).all()
    front = own["x"].to_numpy() + lengths[own["tid"].to_numpy()]
    assert front.max() <= RAMP.x_end
    assert own["speed"].iloc[-1] < 0.1
    assert not sim.counters.collisions


def test_the_merges_section_counts_outcomes():
    end = 144.8
    frame = {"id": [], "tid": [], "time": [], "x": [], "lane": [], "speed": []}

    def add(i, lanes, xs, speeds, t0=0.0):
        for k, (lane, x, v) in enumerate(zip(lanes, xs, speeds, strict=True)):
            for name, value in zip(frame, (i, i, t0 + 0.1 * k, x, lane, v), strict=True):
                frame[name].append(value)

    add(0, [-5, -5, -4], [100.0, 110.0, 120.0], [10.0] * 3)  # merged in time
    add(1, [-5, -5, -4], [130.0, 138.0, 141.0], [10.0] * 3)  # its front 145 m: too late
    add(2, [-5, -5], [100.0, 106.0], [2.0, 0.0])  # standing on the ramp, short of its end
    add(3, [-5, -5], [20.0, 30.0], [10.0, 10.0])  # on its way when the run ended
    add(4, [-3, -3], [20.0, 30.0], [10.0, 10.0])  # never on the ramp
    add(5, [-5, -5], [128.0, 132.0], [1.5, 0.2], t0=1.0)  # standing at the end: front 136 m
    # standing in the ramp's queue behind it, its front 129.5 m: near the end, not at it
    add(7, [-5, -5], [124.0, 125.5], [1.5, 0.2], t0=1.0)
    # alone, waiting with a long standstill gap: its front 127.8 m, 17 m short of the end
    add(8, [-5, -5], [122.0, 123.8], [1.5, 0.2], t0=5.0)
    # spawned on the ramp with its front past the end (front 146 m), merged at once: the
    # recording's late merge, counted apart; once the same spawned after a gap
    add(9, [-5, -4], [142.0, 143.0], [5.0, 5.0])
    add(10, [-5, -5], [60.0, 61.0], [10.0, 10.0])
    add(10, [-5, -4], [142.0, 143.0], [5.0, 5.0], t0=20.0)
    # left the window on the ramp, back in it in lane -4 far on: merged out of sight
    frame["time"] += [0.0, 0.1, 30.0]
    for name, values in (("id", [6] * 3), ("tid", [6] * 3), ("x", [40.0, 41.0, 400.0]),
                         ("lane", [-5, -5, -4]), ("speed", [10.0, 10.0, 25.0])):  # fmt: skip
        frame[name] += values

    section = merge_section(pd.DataFrame(frame), np.full(11, 4.0), [end])
    assert section == {
        "ramp_vehicles": 10, "merged": 2, "before_taper_end": 1, "waiting": 4,
        "waiting_at_end": 2, "unfinished": 2, "entered_past_end": 2,
        "completed_share": pytest.approx(1 / 6, abs=1e-6), "in_time_share": 0.25,
    }  # fmt: skip
    assert merge_section(pd.DataFrame(frame), np.full(11, 4.0), []) is None
    with pytest.raises(ValueError, match="tid"):
        merge_section(pd.DataFrame(frame).drop(columns="tid"), np.full(11, 4.0), [end])


def test_a_recorded_ramp_vehicle_makes_its_recorded_changes_after_its_merge(
    built_map, tmp_path, calibrated_wave_store
):
    # its recording merges at x = 60 m and moves on to lane -3 at x = 200 m; the
    # recorded behaviour (no MOBIL) makes that change from its own plan once merged
    doc = ramp_vehicle(1, 0.0, 12.0, merge_x=60.0)
    x_m = (i24.SEGMENT_END_MM * i24.FEET_PER_MILE - np.asarray(doc["x_position"])) * i24.FT
    doc["y_position"] = np.where(x_m < 200.0, doc["y_position"], 3.5 * i24.LANE_WIDTH_FT)
    doc["y_position"] = doc["y_position"].tolist()
    behind = vehicle(998, -1, -300.0, 12.0, seconds=60.0)  # the data reach the ramp
    store = make_store(tmp_path, [doc, behind, vehicle(999, -2, EGO_X, 12.0, seconds=60.0)])
    for name in (CALIBRATION, FITS):  # any calibration of the road: recorded needs one
        shutil.copy(calibrated_wave_store.path / name, store.path / name)
    config = CosimConfig(road="westbound", lane=-2, x=EGO_X, time=T0, t_max=25.0,
                         world="kinematic", behaviour="recorded")  # fmt: skip
    with Cosimulator(config, EmpiricalTraffic(store), built_map) as sim:
        sim.reset()
        sim.run()
        rows = sim.log.vehicles()
    own = rows[rows["tid"] == store.tid_of(f"{1:024x}")]
    lanes = own["lane"].to_numpy()
    assert lanes[0] == RAMP_LANE
    assert (lanes == -4).any() and lanes[-1] == -3


@pytest.mark.parametrize(
    ("behaviour", "own", "recorded_place", "earliest", "latest"),
    [
        ("recorded", 120.0, -140.0, -40.0, 100.0),  # its own recording merges at 120 m
        ("calibrated", 120.0, -140.0, -140.0, -95.0),  # the ramp's recorded merges at -140
        ("paper", 120.0, -140.0, -90.0, -40.0),  # none known: from 150 m before the taper
        # its recording leaves the ramp only past its end (no place of its own there);
        # the ramp's merge place lies 860 m behind it when it is spawned: its target does
        # not expire (recorded drivers have no MOBIL to merge them)
        ("recorded", 250.0, -1000.0, -140.0, -95.0),
    ],
)
def test_a_ramp_driver_merges_where_the_recording_says(
    built_map, tmp_path, calibrated_wave_store, behaviour, own, recorded_place, earliest, latest
):
    # lane -4 is empty: the driver changes as soon as it wants to, MERGE_LEAD metres
    # before its merge place (spawned at x = -140 m, where it wants it at once if its
    # place is there)
    doc = ramp_vehicle(1, -140.0, 12.0, merge_x=own)
    behind = vehicle(998, -1, -400.0, 12.0, seconds=60.0)  # the data reach the ramp
    store = make_store(tmp_path, [doc, behind, vehicle(999, -2, 0.0, 12.0, seconds=60.0)])
    for name in (CALIBRATION, FITS):
        shutil.copy(calibrated_wave_store.path / name, store.path / name)
    calibration = json.loads((store.path / CALIBRATION).read_text())
    calibration["roads"]["westbound"]["merges"] = [{
        "ramp": RAMP.name, "gore_m": RAMP.x_start, "end_m": RAMP.x_end, "merged": 40,
        "x_quantiles": [recorded_place] * QUANTILES,
    }]  # fmt: skip
    (store.path / CALIBRATION).write_text(json.dumps(calibration))
    config = CosimConfig(road="westbound", lane=-2, x=0.0, time=T0, t_max=20.0,
                         world="kinematic", behaviour=behaviour)  # fmt: skip
    with Cosimulator(config, EmpiricalTraffic(store), built_map) as sim:
        sim.reset()
        sim.run()
        rows = sim.log.vehicles()
    own_rows = rows[rows["tid"] == store.tid_of(f"{1:024x}")]
    assert own_rows["lane"].iloc[0] == RAMP_LANE
    merged = own_rows[own_rows["lane"] == -4]
    assert len(merged), "it never merged"
    assert earliest <= merged["x"].iloc[0] <= latest
    assert sim.manager.merges == 1 and not sim.counters.collisions


def test_a_ramp_vehicle_that_reaches_its_lane_end_waits_where_its_change_crosses_before_it(
    built_map, tmp_path
):
    # lane -4 stands bumper to bumper beside the whole ramp and makes no room
    # (courtesy 0): the ramp vehicle drives on to its lane's end and waits where a
    # change from a stop (an urgent change's shortest path, crossing half-way) still
    # crosses into lane -4 before the end
    docs = [vehicle(100 + k, -4, -300.0 + 7.0 * k, 0.0, seconds=60.0) for k in range(90)]
    docs.append(ramp_vehicle(1, 40.0, 10.0, merge_x=130.0))
    sim, store, rows, merges, lengths = _run(
        built_map, tmp_path, docs, lane=-1, speed=0.0, courtesy=0.0
    )
    own = rows[rows["tid"] == store.tid_of(f"{1:024x}")]
    assert (own["lane"] == RAMP_LANE).all()
    front = own["x"].to_numpy() + lengths[own["tid"].to_numpy()]
    wait = RAMP.x_end - 0.5 * sim.config.traffic.urgent_path
    assert wait - 5.0 <= front.max() <= wait
    assert own["speed"].iloc[-1] < 0.1
    assert merges["waiting"] == 1 and merges["waiting_at_end"] == 1
    assert not sim.counters.collisions


def test_a_change_out_of_a_lane_that_ends_crosses_into_lane_4_before_the_end(built_map, tmp_path):
    # lane -4 stands bumper to bumper and makes no room beside the ramp but for its last
    # 30 m: the ramp vehicle, driving on, changes there at speed, on a path short
    # enough to cross into lane -4 before the taper's end
    docs = [vehicle(100 + k, -4, -300.0 + 7.0 * k, 0.0, seconds=60.0) for k in range(59)]
    docs.append(ramp_vehicle(1, 40.0, 10.0, merge_x=130.0))
    sim, _, _, merges, _ = _run(built_map, tmp_path, docs, lane=-1, speed=0.0, courtesy=0.0)
    assert merges["merged"] == merges["before_taper_end"] == 1
    assert not sim.counters.collisions


def crossing_vehicle(n: int, x: float, speed: float, y: float, cross_x: float):
    """A westbound document on the ramp at back ``x`` [m] at T0, at constant ``speed``,
    ``y`` [m] across (inside lane -5's band) until ``cross_x``, in lane -4 after."""
    doc = vehicle(n, RAMP_LANE, x, speed, seconds=40.0)
    x_m = (i24.SEGMENT_END_MM * i24.FEET_PER_MILE - np.asarray(doc["x_position"])) * i24.FT
    lane_4 = 4.5 * i24.LANE_WIDTH_FT
    doc["y_position"] = np.where(x_m < cross_x, y / i24.FT, lane_4).tolist()
    return doc


def test_a_ramp_vehicle_spawned_crossing_into_lane_4_goes_on_with_its_merge(built_map, tmp_path):
    # recorded halfway across near the taper's end (its front 4 m short of it), with a
    # vehicle in lane -4 8 m behind closing at 3.4 m/s (room for it to brake behind, not
    # the gap a merge decision takes): spawned there, it merges on from where it is, in
    # time, never pulled back out to its lane's centre first (which made it cross past
    # the end)
    y = 5.0 * i24.LANE_WIDTH + 0.15  # just inside lane -5's band
    x = RAMP.x_end - 8.5
    docs = [crossing_vehicle(1, x, 3.5, y, cross_x=RAMP.x_end + 5.0)]
    docs.append(vehicle(2, -4, x - 7.9 - 4.572, 6.9))
    sim, store, rows, merges, _ = _run(built_map, tmp_path, docs, t_max=10.0)
    own = rows[rows["tid"] == store.tid_of(f"{1:024x}")].sort_values("time")
    assert own["lane"].iloc[0] == RAMP_LANE
    assert own["y"].max() <= y + 1e-6
    assert merges["merged"] == merges["before_taper_end"] == 1
    assert not sim.counters.collisions


def test_a_ramp_vehicle_spawned_crossing_with_no_room_in_lane_4_waits_for_a_gap(
    built_map, tmp_path
):
    # a quarter lane inside its lane's centre 40 m short of the end (the taper's
    # pavement still 1.6 m wide), with a vehicle in lane -4 closing on it fast from 6 m
    # behind (not beside it: it fits where it is): too close for the merge to go on at
    # once, it is spawned in its lane and merges when there is a gap
    y = 5.5 * i24.LANE_WIDTH - MID_MERGE - 0.05
    x = RAMP.x_end - 40.0
    docs = [crossing_vehicle(1, x, 3.5, y, cross_x=RAMP.x_end + 5.0)]
    docs.append(vehicle(2, -4, x - 6.0 - 4.572, 12.0))
    sim, store, rows, _, _ = _run(built_map, tmp_path, docs, t_max=10.0)
    own = rows[rows["tid"] == store.tid_of(f"{1:024x}")].sort_values("time")
    assert own["time"].iloc[0] == 0.0
    assert (own[own["time"] <= 1.5]["lane"] == RAMP_LANE).all()
    assert not sim.counters.collisions


@pytest.mark.parametrize("inside", [0.6, 0.2])
def test_a_ramp_recording_over_the_line_beside_a_body_closing_on_it_becomes_a_body(
    built_map, tmp_path, inside
):
    # in the front ghost cell a ramp recording crawls at 1 m/s ``inside`` [m] from the
    # line to lane -4 (its side 0.3 m past it, or 0.7 m) and crosses into lane -4 2 s
    # on; a body in lane -4 comes up behind it at 9 m/s from 20 m back. Its side 0.3 m
    # over the line, it is not yet in lane -4 for the traffic: once it would be too
    # close there it becomes a body (its merge the traffic's), although the body behind
    # it could no longer stop for it: a body behind is no reason to stay a ghost (as
    # one, it crossed into lane -4 in front of the body: a collision). Its side 0.7 m
    # over, it is in lane -4 as a body reaching so far would be (the obstacles' reach,
    # twin/traffic/kernels/neighbours.py): the body brakes for it from the first
    ego_x = -40.0  # the visible window ends at 110 m, the ramp's taper at 145 m
    x = 125.0
    docs = [crossing_vehicle(1, x, 1.0, 5.0 * i24.LANE_WIDTH + inside, cross_x=x + 2.0),
            vehicle(2, -4, x - 4.7 - 20.0, 9.0),
            vehicle(999, -2, ego_x, 2.0, seconds=60.0)]  # fmt: skip
    run = _run_from(built_map, tmp_path, docs, ego_x, t_max=6.0)
    assert not run["collisions"]
    assert (run["yielded"] >= 1) if inside > 0.5 else (run["yielded"] == 0)


@pytest.mark.parametrize("ramp_speed", [None, 12.0])
def test_a_ramp_driver_wants_the_ramps_speed_there_and_its_own_once_merged(
    built_map, tmp_path, calibrated_wave_store, ramp_speed
):
    # alone on the ramp at 12 m/s, merging near the taper's end: with the ramp's speed
    # calibrated (its free drivers drove 12 m/s there) it holds 12 m/s along the ramp;
    # without, it speeds up towards its through-lane speed (on SUMO's on-ramp morning one
    # ran up to 33 m/s on a ramp whose drivers cruised at 16.7); merged, it wants its own
    doc = ramp_vehicle(1, -140.0, 12.0, merge_x=RAMP.x_end - 10.0)
    behind = vehicle(998, -1, -400.0, 12.0, seconds=60.0)  # the data reach the ramp
    store = make_store(tmp_path, [doc, behind, vehicle(999, -2, 0.0, 12.0, seconds=60.0)])
    for name in (CALIBRATION, FITS):
        shutil.copy(calibrated_wave_store.path / name, store.path / name)
    calibration = json.loads((store.path / CALIBRATION).read_text())
    road = calibration["roads"]["westbound"]
    road["merges"] = [{
        "ramp": RAMP.name, "gore_m": RAMP.x_start, "end_m": RAMP.x_end, "merged": 40,
        "x_quantiles": [RAMP.x_end - 10.0] * QUANTILES,
    }]  # fmt: skip
    free = None if ramp_speed is None else {"count": 9, "mean": ramp_speed, "sd": 0.0,
                                            "p10": ramp_speed, "p50": ramp_speed,
                                            "p90": ramp_speed}  # fmt: skip
    road["ramp_speeds"] = [{"ramp": RAMP.name, "end_m": RAMP.x_end, "free": 9,
                            "free_speed": free}]  # fmt: skip
    (store.path / CALIBRATION).write_text(json.dumps(calibration))
    config = CosimConfig(road="westbound", lane=-2, x=0.0, time=T0, t_max=20.0,
                         world="kinematic", behaviour="calibrated")  # fmt: skip
    tid = store.tid_of(f"{1:024x}")
    on_ramp, merged = [], []  # (desired speed now, own desired speed) of the ramp driver
    last_on_ramp = None  # [s] the last step before its merge began
    # the ego held at 12 m/s: the ramp driver stays in the visible window (not relaxing)
    with Cosimulator(config, EmpiricalTraffic(store), built_map, controller=hold_speed) as sim:
        sim.reset()
        while not sim.done:
            sim.step()
            ids = sim.manager.ids
            own = ids[sim.tids_of(ids) == tid]
            if own.size:
                pair = (sim.manager.desired_speed(own)[0], sim.base_speeds(own)[0])
                lane = sim.manager.lanes(own)[0]
                (on_ramp if lane == RAMP_LANE else merged).append(pair)
                if lane == RAMP_LANE:
                    last_on_ramp = sim.sim_time
        rows = sim.log.vehicles()
        assert sim.manager.merges == 1 and not sim.counters.collisions
    assert on_ramp and merged, "it was not simulated on the ramp and merged"
    wanted, base = np.array(on_ramp).T
    assert np.all(base > 14.0)  # its own: the through lanes' (calibrated at 25+)
    assert np.all(wanted == (base if ramp_speed is None else ramp_speed))
    wanted, base = np.array(merged[1:]).T  # (its wish is set before its merge begins)
    assert np.all(wanted == base)  # merging or merged: its own again
    own_rows = rows[(rows["tid"] == tid) & (rows["time"] <= last_on_ramp)]
    if ramp_speed is None:
        assert own_rows["speed"].max() > 14.0  # speeding up towards it on the ramp
    else:
        assert own_rows["speed"].max() <= 12.1  # holding the ramp's speed


def test_a_ramp_recording_resuming_just_ahead_of_a_body_that_cannot_stop_is_held_back(
    built_map, tmp_path
):
    # SUMO's on-ramp morning, episode 18: a ramp vehicle's track resumed after a gap in
    # the front ghost cell, crossing into lane -4 half a metre ahead of a body there 5.6
    # m/s faster; cutting in, it was made a body to merge as the traffic lets it, and was
    # run into at once. Appearing where a body cannot stop for it, it is held back
    ego_x, speed = -66.1, 14.0
    body_x = ego_x + 147.0  # lane -4, at the visible window's front edge, 14 m/s
    length = 15 * i24.FT
    at = 1.0  # [s] the ramp track begins, its back 0.5 m ahead of the body's front
    ramp = vehicle(1, RAMP_LANE, body_x + speed * at + length + 0.5 - 8.8 * at, 8.8,
                   start=at, seconds=6.0)  # fmt: skip
    t = np.asarray(ramp["timestamp"]) - (T0 + at)
    across = np.clip(t, 0.0, 1.0)  # from over the line into lane -4's centre in 1 s
    ramp["y_position"] = ((18.32 + across * (4.5 * i24.LANE_WIDTH - 18.32)) / i24.FT).tolist()
    docs = [
        vehicle(999, -2, ego_x, speed, seconds=60.0),
        vehicle(2, -4, body_x, speed, seconds=60.0),
        vehicle(3, -4, ego_x + 200.0, speed, seconds=60.0),  # a ghost ahead: the pace
        ramp,
    ]
    run = _run_from(built_map, tmp_path, docs, ego_x, t_max=4.0)
    assert run["held"] >= 1 and run["contacts"] == 0


def test_a_ramp_recording_appearing_behind_a_slower_lane_4_body_is_not_held_back(
    built_map, tmp_path
):
    # a ramp recording whose track begins 10 m behind a body in lane -4 beside it, 10.7
    # m/s faster, with no body behind it: crowding that body in the lane it goes into,
    # it is made a body and brakes for it. The test of a body behind that could not stop
    # is no reason to hold it back here: judging the body ahead as if it were behind
    # held back every ramp recording appearing beside a crawling lane -4
    ego_x, speed, at = 0.0, 6.0, 1.0
    body_x = ego_x - 148.0  # lane -4, at the visible window's rear edge
    length = 15 * i24.FT
    # (its recording merges past x 0: a track on the ramp alone is no trajectory)
    ramp = ramp_vehicle(1, body_x + speed * at - 10.0 - length - 16.7 * at, 16.7, merge_x=0.0,
                        seconds=12.0, start=at)  # fmt: skip
    docs = [vehicle(999, -2, ego_x, speed, seconds=60.0),
            vehicle(2, -4, body_x, speed, seconds=60.0), ramp]  # fmt: skip
    run = _run_from(built_map, tmp_path, docs, ego_x, t_max=3.0, controller=hold_speed)
    assert run["held"] == 0 and run["yielded"] == 1 and run["contacts"] == 0
