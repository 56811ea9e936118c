"""The on-ramps' acceleration lanes read from the landmark layer, and the lane query
that knows them."""

import numpy as np
import pytest

from twin.core import i24, ramps
from twin.core.i24 import LANE_WIDTH, Road


def test_the_segment_has_the_two_on_ramps_the_landmark_layer_places():
    found = {r.name: r for r in ramps.segment_ramps()}
    assert sorted(found) == ["eb_HH_on", "wb_OH_on"]
    hickory, old_hickory = found["eb_HH_on"], found["wb_OH_on"]
    assert hickory.road is Road.EASTBOUND and old_hickory.road is Road.WESTBOUND
    # MM 60.43 -> 60.70 eastbound, 62.29 -> 61.51 westbound (x from MM 60.6 / 61.6)
    assert hickory.x_start == pytest.approx((60.43 - 60.6) * i24.MILE)
    assert hickory.x_end == pytest.approx((60.70 - 60.6) * i24.MILE)
    assert old_hickory.x_start == pytest.approx((61.6 - 62.29) * i24.MILE)
    assert old_hickory.x_end == pytest.approx((61.6 - 61.51) * i24.MILE)


def test_a_lane_opens_runs_full_and_tapers_to_nothing_at_its_end():
    ramp = ramps.Ramp(Road.EASTBOUND, "test_on", 100.0, 500.0)
    x = np.array([60.0, 85.0, 100.0, 300.0, 500.0 - ramps.TAPER, 500.0 - ramps.TAPER / 2, 500.0])
    np.testing.assert_allclose(
        ramp.width(x),
        [0.0, LANE_WIDTH / 2, LANE_WIDTH, LANE_WIDTH, LANE_WIDTH, LANE_WIDTH / 2, 0.0],
    )
    lanes_edge = 5 * LANE_WIDTH
    lane = ramps.lane_at(
        Road.EASTBOUND,
        np.array([300.0, 300.0, 300.0, 600.0, 300.0]),
        np.array(
            [
                lanes_edge + 1.0,
                lanes_edge + LANE_WIDTH + 0.1,
                lanes_edge - 1.0,
                lanes_edge + 1,
                np.nan,
            ]
        ),
        (ramp,),
    )
    assert lane.tolist() == [ramps.RAMP_LANE, 0, -4, 0, 0]
    # per point directions: the westbound side has no lane here
    both = ramps.lane_at(
        np.array([1, -1]), np.array([300.0, 300.0]), np.full(2, lanes_edge + 1), (ramp,)
    )
    assert both.tolist() == [ramps.RAMP_LANE, 0]


def test_the_lanes_inner_edge_belongs_to_it_and_its_outer_edge_does_not():
    """As I-24 MOTION's bands: |y_position| 60 ft is lane -5 where an acceleration lane
    runs, and 72 ft (its full width's outer edge) the shoulder; 48 ft is lane -4."""
    ramp = ramps.Ramp(Road.WESTBOUND, "test_on", -500.0, 500.0)
    y = i24.road_y(np.array([48.0, 59.999, 60.0, 71.999, 72.0]))
    lane = ramps.lane_at(Road.WESTBOUND, np.zeros(5), y, (ramp,))
    assert lane.tolist() == [-4, -4, ramps.RAMP_LANE, ramps.RAMP_LANE, 0]


def test_the_landmarks_of_a_ramp_that_ends_before_it_starts_are_refused():
    with pytest.raises(ValueError, match="x_on: its end lies before its start"):
        ramps.ramps_from_landmarks({"x_on_start": ("eb", 60.9), "x_on_end": ("eb", 60.7)})
    with pytest.raises(ValueError, match="its ends lie on eb and wb"):
        ramps.ramps_from_landmarks({"x_on_start": ("eb", 60.7), "x_on_end": ("wb", 60.9)})
    with pytest.raises(ValueError, match="shorter than its"):
        ramps.Ramp(Road.EASTBOUND, "short", 0.0, 50.0)
    # a pair far from the segment is not the segment's
    assert (
        ramps.ramps_from_landmarks({"y_on_start": ("eb", 62.86), "y_on_end": ("eb", 63.07)}) == ()
    )


def test_the_kernels_lane_of_y_knows_lane_5_and_agrees_with_lane_of_on_the_four():
    y = np.array([0.5, 1.0, 2.0, 3.0, 4.0, 4.99, 5.0, 5.5, 5.999, 6.0, 7.0]) * LANE_WIDTH
    got = [ramps.lane_of_y(v) for v in y]
    assert got == [0, -1, -2, -3, -4, -4, -5, -5, -5, 0, 0]
    four = y < 5.0 * LANE_WIDTH
    assert np.array_equal(np.array(got)[four], i24.lane_of(y[four]))
    assert ramps.lane_of_y(float("nan")) == 0
    # 60 ft, lane -5's inner edge given in feet, belongs to it despite the round-off
    assert ramps.lane_of_y(60.0 * i24.FT) == -5


def test_a_body_in_lane_5s_band_is_on_the_ramp_only_along_its_span():
    west = next(r for r in ramps.segment_ramps() if r.road == Road.WESTBOUND)
    east = next(r for r in ramps.segment_ramps() if r.road == Road.EASTBOUND)
    y = np.full(4, 5.5 * LANE_WIDTH)
    x = np.array([west.x_end - 50.0, west.x_end + ramps.SPAN_MARGIN - 1.0, west.x_end + 50.0,
                  west.x_end - 50.0])  # fmt: skip
    road = np.array([-1, -1, -1, 1])  # the last on the eastbound carriageway there
    on_east = east.x_start - ramps.OPENING - ramps.SPAN_MARGIN <= x[3] <= east.x_end
    lanes = ramps.body_lanes(road, x, y, ramps.segment_ramps()).tolist()
    assert lanes == [-5, -5, 0, -5 if on_east else 0]  # past the end: the shoulder
    assert ramps.body_lanes(road, x, np.full(4, 2.5 * LANE_WIDTH), ()).tolist() == [-2] * 4
    spans = ramps.ramp_spans("westbound")
    assert spans.tolist() == [[west.x_start - ramps.OPENING, west.x_end]]
    assert ramps.on_ramp(spans, west.x_end + 5.0) and not ramps.on_ramp(spans, west.x_end + 11.0)
