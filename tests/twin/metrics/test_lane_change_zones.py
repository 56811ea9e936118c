"""Lane changes by zone: before a drop, the weave at an on-ramp, elsewhere."""

import numpy as np
import pytest

from twin.core.i24 import Road
from twin.core.ramps import SEGMENT_LENGTH, segment_ramps
from twin.metrics import lane_change_zones as lcz


def test_a_place_is_before_a_drop_in_a_weave_or_elsewhere_and_a_drop_wins():
    ramp = next(r for r in segment_ramps() if r.road == Road.WESTBOUND)
    zones = lcz.road_zones("westbound", drop_x=1200.0)
    assert zones.drops == ((1200.0 - lcz.BEFORE_DROP, 1200.0),)
    assert zones.weaves == ((ramp.x_start, ramp.x_end + lcz.WEAVE_AFTER),)
    x = [ramp.x_end + 50.0, ramp.x_end + lcz.WEAVE_AFTER + 1.0, 699.0, 700.0, 1199.9, 1200.0]
    names = [lcz.ZONES[k] for k in zones.of(x)]
    assert names == ["weave", "elsewhere", "elsewhere", "before_drop", "before_drop", "elsewhere"]
    # a drop reaching back into the weave takes the place
    both = lcz.road_zones("westbound", drop_x=ramp.x_end + 10.0)
    assert lcz.ZONES[int(both.of([ramp.x_end])[0])] == "before_drop"
    assert lcz.road_zones(Road.EASTBOUND).drops == ()
    with pytest.raises(ValueError, match="finite"):
        lcz.road_zones("westbound", drop_x=float("nan"))


def test_a_lane_the_recorded_traffic_stops_using_is_found_ending():
    rng = np.random.default_rng(0)
    lanes, xs = [], []
    for lane, end in ((-1, SEGMENT_LENGTH), (-2, SEGMENT_LENGTH), (-3, SEGMENT_LENGTH),
                      (-4, 930.0)):  # fmt: skip
        xs.append(rng.uniform(0.0, end, 20_000))
        lanes.append(np.full(20_000, lane))
    lane, x = np.concatenate(lanes), np.concatenate(xs)
    # a few stragglers past the end (under END_SHARE of the lane's use) change nothing
    lane = np.r_[lane, [-4, -4]]
    x = np.r_[x, [1100.0, 1400.0]]
    # the first bin it is all but empty in: 930 m lies in the bin from 900 m
    assert lcz.recorded_lane_ends(lane, x, SEGMENT_LENGTH) == [950.0]
    through = lane != -4
    assert lcz.recorded_lane_ends(lane[through], x[through], SEGMENT_LENGTH) == []
    # a lane used only downstream (an acceleration lane's) is no drop
    late = np.r_[np.full(1000, -4), np.full(1000, -3)]
    spread = np.r_[rng.uniform(1000.0, 1500.0, 1000), rng.uniform(0.0, SEGMENT_LENGTH, 1000)]
    assert lcz.recorded_lane_ends(late, spread, SEGMENT_LENGTH) == []


def test_changes_are_counted_by_zone_side_by_side():
    zones = lcz.Zones(drops=((700.0, 1200.0),), weaves=((0.0, 250.0),))
    changes = {"simulated_x": [10.0, 20.0, 800.0, 1300.0], "recorded_x": [900.0, 1000.0, 100.0]}
    counts = lcz.by_zone(changes, zones)
    assert counts["before_drop"] == {"simulated": 1, "recorded": 2, "ratio": 0.5}
    assert counts["weave"] == {"simulated": 2, "recorded": 1, "ratio": 2.0}
    assert counts["elsewhere"] == {"simulated": 1, "recorded": 0, "ratio": None}
    assert lcz.describe(counts) == "before drop 1 / 2; weave 2 / 1; elsewhere 1 / 0"
    assert lcz.by_zone(None, zones)["weave"]["simulated"] is None
    table = lcz.markdown({"calibrated": counts, "paper": None}, zones)
    assert "| before drop | 1 / 2 |" in table and "before a drop 700 to 1200 m" in table
