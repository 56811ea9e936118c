"""The road model against its sources: posts, profile, and its own inverse."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mapgen.params import load_params
from mapgen.road import RoadModel
from mapgen.sources import load_sources
from tests.mapgen import oracles
from twin.core import i24


@pytest.fixture(scope="module")
def road() -> RoadModel:
    return RoadModel.from_sources(load_sources(), load_params())


def test_bearing_and_origin_match_the_mile_marker_posts(road):
    posts = oracles.posts().set_index("MM")
    start, end = posts.loc[60.6], posts.loc[61.6]
    azimuth = oracles.azimuth(start.Y_WGS84, start.X_WGS84, end.Y_WGS84, end.X_WGS84)
    # the bearing is fitted to the posts from MM 60.4 to 61.8, not to these two alone
    assert road.bearing == pytest.approx(azimuth, abs=0.15)
    assert 137.0 < road.bearing < 139.0  # DESIGN.md: about 138 degrees

    lat, lon, elevation = road.to_geodetic(np.zeros((1, 3)))
    assert lat[0] == pytest.approx(start.Y_WGS84, abs=1e-8)
    assert lon[0] == pytest.approx(start.X_WGS84, abs=1e-8)
    table = oracles.grade_table().set_index("MM")
    assert elevation[0] == pytest.approx(table.loc[60.6, "elevation (ft)"] * oracles.FT, abs=1e-3)


def test_every_post_lies_on_the_centre_line_at_its_nominal_station(road):
    posts = oracles.posts()
    posts = posts[(posts.MM >= 60.4) & (posts.MM <= 61.8)]
    points = road.from_geodetic(posts.Y_WGS84.to_numpy(), posts.X_WGS84.to_numpy())
    station = points[:, :2] @ road.direction_vector
    lateral = points[:, :2] @ road.right_vector
    np.testing.assert_allclose(station, (posts.MM.to_numpy() - 60.6) * oracles.MILE, atol=0.01)
    # the real road bends a little: the posts lie within 2.5 m of the fitted line
    assert np.abs(lateral).max() < 2.5
    assert np.sqrt(np.mean(lateral**2)) < 1.2


def test_local_frame_distances_agree_with_the_globe_and_the_state_plane(road):
    posts = oracles.posts().set_index("MM")
    a, b = posts.loc[60.6], posts.loc[61.6]
    enu = road.from_geodetic([a.Y_WGS84, b.Y_WGS84], [a.X_WGS84, b.X_WGS84])
    # from_geodetic stations by nominal miles; the geographic distance is in post_along
    along = np.interp([60.6, 61.6], road.post_mm, road.post_along)
    geographic = along[1] - along[0]
    assert geographic == pytest.approx(
        oracles.haversine(a.Y_WGS84, a.X_WGS84, b.Y_WGS84, b.X_WGS84), rel=5e-3
    )
    us_survey_foot = 1200.0 / 3937.0
    state_plane = math.hypot(b.X_TN - a.X_TN, b.Y_TN - a.Y_TN) * us_survey_foot
    assert geographic == pytest.approx(state_plane, rel=1e-3)
    # ... and the map itself is stationed by nominal miles, as the data's x is
    assert np.linalg.norm(enu[1, :2] - enu[0, :2]) == pytest.approx(oracles.MILE, abs=1.5)


def test_map_extends_at_least_400_m_beyond_each_end(road):
    s0, s1 = road.station_range
    assert s0 <= -400.0
    assert s1 >= i24.SEGMENT_LENGTH + 400.0
    for name in ("eastbound", "westbound"):
        lo, hi = road.x_range(name)
        assert lo <= -400.0 and hi >= i24.SEGMENT_LENGTH + 400.0


def test_pavement_height_follows_the_grade_table(road):
    x = np.linspace(*road.x_range("eastbound"), 997)
    for name in ("eastbound", "westbound"):
        positions, _, _ = road.to_world(name, x, np.full(x.size, 9.0))
        mm = i24.mile_marker(x, i24.Road.parse(name))
        np.testing.assert_allclose(positions[:, 2], oracles.profile_height(mm), atol=1e-9)
    rise = road.surface_z(np.array([i24.SEGMENT_LENGTH]))[0]
    assert rise == pytest.approx(17.9, abs=0.1)  # DESIGN.md: about 17.9 m of rise eastbound


def test_heading_and_pitch(road):
    _, heading, pitch = road.to_world("eastbound", [800.0], [5.0])
    assert math.degrees(heading[0]) == pytest.approx(90.0 - road.bearing)
    assert math.tan(pitch[0]) == pytest.approx(0.01111856, rel=1e-3)  # the 1.112 % grade
    _, heading_wb, pitch_wb = road.to_world("westbound", [800.0], [5.0])
    assert math.cos(heading_wb[0] - heading[0]) == pytest.approx(-1.0)
    assert pitch_wb[0] == pytest.approx(-pitch[0])


def test_carriageways_lie_on_either_side_of_the_median(road):
    eb, _, _ = road.to_world("eastbound", [500.0], [10.0])
    wb, _, _ = road.to_world("westbound", [i24.SEGMENT_LENGTH - 500.0], [10.0])
    # same station, mirrored across the median; eastbound is to the south-west (right
    # of travel at a bearing of 138 degrees)
    assert np.linalg.norm(eb[0, :2] - wb[0, :2]) == pytest.approx(20.0)
    assert eb[0, 1] < wb[0, 1] and eb[0, 0] < wb[0, 0]


@settings(max_examples=300, deadline=None)
@given(
    road_name=st.sampled_from(["eastbound", "westbound"]),
    x=st.floats(-402.0, 2011.0),
    y=st.floats(1e-3, 40.0),  # y = 0 is the median centre line, which is eastbound
    height=st.floats(-2.0, 30.0),
)
def test_round_trip_road_world_road_is_below_a_millimetre(road, road_name, x, y, height):
    position, _, _ = road.to_world(road_name, [x], [y])
    position[:, 2] += height
    back = road.to_road(position)
    assert back.road[0] == i24.Road.parse(road_name).direction
    assert abs(back.x[0] - x) < 1e-3 and abs(back.y[0] - y) < 1e-3
    assert abs(back.height[0] - height) < 1e-3
    # the lane: the four bands, and the acceleration lane's where it runs (an oracle
    # worked out from the landmark layer in feet; points within a micron of an edge,
    # where rounding decides, are not judged)
    width = oracles.ramp_lane_width(road_name, x)
    beyond = y - 5 * i24.LANE_WIDTH
    expected = i24.lane_of(np.array([y]))[0]
    if 0.0 <= beyond < width:
        expected = -5
    if min(abs(beyond), abs(beyond - width), abs(y % i24.LANE_WIDTH)) > 1e-6:
        assert back.lane[0] == expected


def test_round_trip_world_road_world_vectorised(road):
    rng = np.random.default_rng(7)
    points = np.column_stack(
        [rng.uniform(-300, 1300, 5000), rng.uniform(-1400, 300, 5000), rng.uniform(-5, 20, 5000)]
    )
    points = points[np.abs(points[:, :2] @ road.right_vector) > 1e-6]
    points = points[
        (points[:, :2] @ road.direction_vector > -400)
        & (points[:, :2] @ road.direction_vector < 2000)
    ]
    coords = road.to_road(points)
    back, _, _ = road.to_world(coords.road, coords.x, coords.y)
    back[:, 2] += coords.height
    assert np.abs(back - points).max() < 1e-3


def test_geodetic_round_trip(road):
    points = road.lane_center_line("westbound", -3, np.linspace(-300, 1900, 50))
    lat, lon, elevation = road.to_geodetic(points)
    back = road.from_geodetic(lat, lon, elevation)
    assert np.abs(back - points).max() < 1e-3


def test_lane_centre_lines_and_lookup(road):
    for lane in i24.LANES:
        line = road.lane_center_line("eastbound", lane, [100.0, 900.0])
        coords = road.to_road(line)
        np.testing.assert_allclose(coords.y, (-lane + 0.5) * i24.LANE_WIDTH)
        assert (coords.lane == lane).all()
        assert (i24.lane_of(coords.y) == lane).all()
    assert i24.lane_of(np.array([1.0, 19.0]))[0] == 0  # median and shoulder are no lane


def test_bad_inputs_raise_clear_errors(road):
    with pytest.raises(ValueError, match="beyond the map"):
        road.to_world("eastbound", [5000.0], [5.0])
    with pytest.raises(ValueError, match="finite"):
        road.to_world("eastbound", [float("nan")], [5.0])
    with pytest.raises(ValueError, match="unknown road"):
        road.to_world("northbound", [1.0], [5.0])
    with pytest.raises(ValueError, match=r"\(n, 3\)"):
        road.to_road(np.zeros((4, 2)))
    with pytest.raises(ValueError, match="array of"):
        road.to_world(np.array([1, 2]), [1.0, 2.0], [5.0, 5.0])


def test_description_round_trips_through_json(road):
    import json

    again = RoadModel.from_dict(json.loads(json.dumps(road.to_dict())))
    points, _, _ = road.to_world("eastbound", [10.0, 1500.0], [4.0, 17.0])
    np.testing.assert_array_equal(
        again.to_world("eastbound", [10.0, 1500.0], [4.0, 17.0])[0], points
    )
