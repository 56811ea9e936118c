import numpy as np
import pytest

from twin.core import i24
from twin.core.i24 import Road


def test_segment_ends_map_to_zero_and_one_mile():
    assert i24.road_x(np.array([60.6 * 5280]), Road.EASTBOUND)[0] == pytest.approx(0.0, abs=1e-9)
    assert i24.road_x(np.array([61.6 * 5280]), Road.EASTBOUND)[0] == pytest.approx(1609.344)
    assert i24.road_x(np.array([61.6 * 5280]), Road.WESTBOUND)[0] == pytest.approx(0.0, abs=1e-9)
    assert i24.road_x(np.array([60.6 * 5280]), Road.WESTBOUND)[0] == pytest.approx(1609.344)
    assert pytest.approx(1609.344) == i24.SEGMENT_LENGTH


@pytest.mark.parametrize("road", list(Road))
def test_x_and_y_round_trip(road):
    x = np.linspace(-3000, 4000, 101)
    assert np.allclose(i24.road_x(i24.x_feet(x, road), road), x, atol=1e-9)
    y = np.linspace(3.7, 18.2, 50)
    y_ft = i24.y_feet(y, road)
    assert np.all(np.sign(y_ft) == -road.direction)  # I-24: y < 0 eastbound
    assert np.allclose(i24.road_y(y_ft), y)


def test_lane_bands_are_12_ft_from_the_yellow_line():
    y_ft = np.array([11.9, 12.0, 23.9, 24.0, 35.9, 36.0, 47.9, 48.0, 59.9, 60.0, 70.0])
    lanes = i24.lane_of(i24.road_y(y_ft))
    assert lanes.tolist() == [0, -1, -1, -2, -2, -3, -3, -4, -4, 0, 0]
    assert i24.lane_of(i24.lane_center(np.array(i24.LANES))).tolist() == list(i24.LANES)
    assert i24.lane_center(-1) == pytest.approx(1.5 * 3.6576)


def test_road_parse_accepts_names_and_directions_and_names_bad_values():
    assert Road.parse("EB") is Road.EASTBOUND
    assert Road.parse(-1) is Road.WESTBOUND
    with pytest.raises(ValueError, match="northbound"):
        Road.parse("northbound")
    with pytest.raises(ValueError):
        Road.parse(True)
