"""The synthesiser's lanes that end: a lane drop and an on-ramp (twin.data.synth.lane_ends)."""

from dataclasses import replace

import numpy as np
import pytest

from twin.core import i24
from twin.core.i24 import SCENARIO_TIME
from twin.data.synth import (
    OTHER_DRIVERS,
    PRESET_C,
    PRESET_D,
    PRESET_E,
    LaneDrop,
    OnRamp,
    Simulation,
    synthesize,
)
from twin.data.synth.lane_ends import RAMP_LANE, lanes_to_cross, needed_decel

# a short road (1.1 km simulated) so that a few minutes run in seconds
SHORT = replace(
    PRESET_C,
    bottleneck=None,
    x_record=(0.0, 600.0),
    upstream=100.0,
    downstream=400.0,
    warmup=0.0,
    drivers=OTHER_DRIVERS,
)


def _run(config, steps, watch=None):
    sim = Simulation(config, np.random.default_rng(3))
    sim.populate()
    for _ in range(steps):
        sim.step()
        if watch is not None:
            watch(sim)
    return sim


def test_drivers_leave_dropped_lanes_before_their_end_and_the_lane_that_continues_flows():
    drop = LaneDrop(x=800.0, lanes=(-3, -4))
    config = replace(SHORT, flow=(0.0, 700.0, 450.0, 300.0), lane_drop=drop)
    seen = {"past_end": 0, "through": set()}

    def watch(sim):
        v = sim.vehicles
        in_dropped = np.isin(v.lane, drop.lanes)  # not counting a change under way out
        seen["past_end"] += int(np.count_nonzero(in_dropped & (v.x + v.length > drop.x + 0.5)))
        seen["through"].update(v.vid[(v.x > drop.x + 50.0) & (v.lane == -2)].tolist())

    sim = _run(config, 1200, watch)
    assert seen["past_end"] == 0
    assert sim.collisions == 0
    assert sim.lane_changes >= 30  # lane -3's drivers once, lane -4's twice, in 2 minutes
    assert len(seen["through"]) >= 25  # lane -2 discharges past the drop: no gridlock
    v = sim.vehicles
    assert not np.any(np.isin(v.lane, drop.lanes) & (v.x > drop.x))


def test_on_ramp_drivers_merge_into_lane_4_before_the_ramp_ends():
    ramp = OnRamp(x_start=0.0, x_end=300.0, flow=900.0)
    config = replace(SHORT, flow=(0.0, 0.0, 900.0, 1200.0), on_ramp=ramp)
    merged = set()
    seen = {"past_end": 0, "on_ramp": set()}

    def watch(sim):
        v = sim.vehicles
        on = v.lane == RAMP_LANE
        seen["on_ramp"].update(v.vid[on].tolist())
        seen["past_end"] += int(np.count_nonzero(on & (v.x + v.length > ramp.x_end + 0.5)))
        merged.update(v.vid[(v.lane == -4) & np.isin(v.vid, list(seen["on_ramp"]))].tolist())

    sim = _run(config, 1000, watch)
    assert len(seen["on_ramp"]) >= 15  # 900 veh/h for 100 s
    assert seen["past_end"] == 0
    assert len(merged) >= 12
    assert sim.collisions == 0


def test_ramp_vehicles_are_recorded_outside_the_lane_bands_until_they_are_in_lane_4():
    ramp = OnRamp(x_start=-300.0, x_end=200.0, flow=900.0)
    config = replace(SHORT, x_record=(-300.0, 600.0), upstream=50.0, on_ramp=ramp)
    result = synthesize(replace(config, start=SCENARIO_TIME, minutes=0.75, warmup=45.0))
    outside_then_lane_4 = 0
    for _, x, y in result.tracks:
        lanes = i24.lane_of(y)
        if lanes[0] != 0:
            assert np.all(lanes != 0)  # a mainline vehicle never leaves the lane bands
            continue
        assert y[0] > 4 * i24.LANE_WIDTH  # beyond lane -4, on the ramp's side
        joined = np.flatnonzero(lanes != 0)
        if joined.size:
            assert np.all(lanes[joined[0] :] == -4)  # once in, in lane -4 (within the clip)
            assert np.all(lanes[: joined[0]] == 0)
            assert x[joined[0]] <= ramp.x_end + 1.0
            outside_then_lane_4 += 1
    assert outside_then_lane_4 >= 5


@pytest.mark.parametrize(
    "change, match",
    [
        ({"lane_drop": LaneDrop(x=2000.0, lanes=(-2, -3, -4))}, "lane_drop"),
        ({"lane_drop": LaneDrop(x=2000.0, lanes=(-3,))}, "lane_drop"),
        ({"lane_drop": LaneDrop(x=-1300.0, lanes=(-4,))}, "lane_drop"),
        ({"on_ramp": OnRamp(x_start=0.0, x_end=20.0, flow=500.0)}, "on_ramp"),
        ({"on_ramp": OnRamp(x_start=0.0, x_end=500.0, flow=5000.0)}, "on_ramp"),
        ({"merge_lookahead": (300.0, 100.0)}, "merge_lookahead"),
        ({"courtesy": 1.5}, "courtesy"),
    ],
)
def test_impossible_lane_ends_are_named(change, match):
    with pytest.raises(ValueError, match=match):
        replace(PRESET_C, **change)


def test_a_ramp_ending_past_a_lane_drop_is_refused():
    with pytest.raises(ValueError, match="on-ramp must end before the lane drop"):
        replace(PRESET_D, on_ramp=OnRamp(x_start=0.0, x_end=2200.0, flow=500.0))


def test_lanes_to_cross_and_needed_braking():
    assert lanes_to_cross(PRESET_D, np.array([-1, -2, -3, -4])).tolist() == [0, 0, 1, 2]
    assert lanes_to_cross(PRESET_E, np.array([-4, RAMP_LANE])).tolist() == [0, 1]
    # closing at 10 m/s with 26 m to spare (1 m kept): 100 / (2 * 25)
    assert needed_decel(np.array([20.0]), np.array([10.0]), np.array([26.0]))[0] == 2.0
    assert needed_decel(np.array([5.0]), np.array([10.0]), np.array([3.0]))[0] == 0.0
    assert needed_decel(np.array([0.0]), np.array([0.0]), np.array([0.5]))[0] == np.inf


def test_presets_d_and_e_match_the_real_segment():
    assert PRESET_D.lane_drop.x == pytest.approx(i24.SEGMENT_LENGTH + 300.0)
    # the westbound Old Hickory merge ends at MM 61.51
    assert i24.mile_marker(PRESET_E.on_ramp.x_end, i24.Road.WESTBOUND) == pytest.approx(61.51)


@pytest.mark.slow
def test_a_day_with_lanes_that_end_is_deterministic_by_seed():
    config = replace(
        SHORT,
        start=SCENARIO_TIME,
        minutes=0.25,
        warmup=20.0,
        on_ramp=OnRamp(x_start=0.0, x_end=300.0, flow=900.0),
        lane_drop=LaneDrop(x=800.0, lanes=(-4,)),
    )
    a, b = synthesize(config), synthesize(config)
    c = synthesize(replace(config, seed=1))
    assert np.array_equal(a.vid, b.vid) and a.lane_changes == b.lane_changes
    for (ta, xa, ya), (tb, xb, yb) in zip(a.tracks, b.tracks, strict=True):
        assert np.array_equal(ta, tb) and np.array_equal(xa, xb) and np.array_equal(ya, yb)
    assert len(a.tracks) != len(c.tracks) or not np.array_equal(a.tracks[0][1], c.tracks[0][1])
