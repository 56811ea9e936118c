"""The I-24 MOTION boundary: units, roads, lanes and the conversion to the twin's road frame.

Feet and mile markers exist only here (and in plots). Conventions are those of
the twin's (``docs/architecture.md``):

* road ``eastbound`` (direction +1, mile markers increase) or ``westbound`` (-1);
* ``x`` [m] along the direction of travel from the segment entry
  (MM 60.6 eastbound, MM 61.6 westbound);
* ``y`` [m] from the median centre line toward the outside, ``|y_ft| * 0.3048``;
* lane ``-k`` (k = 1..4) spans ``y in [k, k+1] * 12 ft``; lane -1 is the HOV lane.

I-24 MOTION records the back-centre of each vehicle; the twin keeps that reference,
so a vehicle occupies ``[x, x + length]`` along its road.
"""

from enum import StrEnum

import numpy as np

FT = 0.3048  # [m/ft]
MILE = 1609.344  # [m/mi]
FEET_PER_MILE = 5280.0  # [ft/mi]
SEGMENT_START_MM = 60.6  # [mi] mile marker of the segment's west end
SEGMENT_END_MM = 61.6  # [mi] mile marker of the segment's east end
SEGMENT_LENGTH = (SEGMENT_END_MM - SEGMENT_START_MM) * MILE  # [m]
LANE_WIDTH_FT = 12.0  # [ft]
LANE_WIDTH = LANE_WIDTH_FT * FT  # [m]
N_LANES = 4
HOV_LANE = -1
LANES = (-1, -2, -3, -4)
#: [s] unix, 2022-11-30 06:45:50 CST: the time of the paper's scenarios A and B.
SCENARIO_TIME = 1669812350.0

#: I-24 MOTION coarse vehicle classes, by class id.
VEHICLE_CLASSES = ("sedan", "midsize", "pickup", "van", "semi", "truck", "motorcycle")

#: Fields every trajectory document must carry, with what the twin needs of them.
REQUIRED_ARRAYS = ("timestamp", "x_position", "y_position")
REQUIRED_SCALARS = ("direction", "length", "width", "height", "coarse_vehicle_class")


class Road(StrEnum):
    """A carriageway of the segment."""

    EASTBOUND = "eastbound"
    WESTBOUND = "westbound"

    @property
    def direction(self) -> int:
        """+1 eastbound (mile markers increase along travel), -1 westbound."""
        return 1 if self is Road.EASTBOUND else -1

    @property
    def code(self) -> int:
        """A small integer for columnar storage: 0 eastbound, 1 westbound."""
        return 0 if self is Road.EASTBOUND else 1

    @classmethod
    def parse(cls, value: "Road | str | int") -> "Road":
        """Accept a Road, its name (``eastbound``, ``EB``, ``wb`` ...) or a direction (+1/-1).

        Raises:
            ValueError: naming the value when it is none of these.
        """
        if isinstance(value, Road):
            return value
        if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
            if value == 1:
                return Road.EASTBOUND
            if value == -1:
                return Road.WESTBOUND
        if isinstance(value, str):
            key = value.strip().lower()
            for road, names in (
                (Road.EASTBOUND, ("eastbound", "eb", "east")),
                (Road.WESTBOUND, ("westbound", "wb", "west")),
            ):
                if key in names:
                    return road
        raise ValueError(f"unknown road {value!r}: expected 'eastbound' or 'westbound' (or +1/-1)")


def road_x(x_ft: np.ndarray, road: Road) -> np.ndarray:
    """Road-frame x [m] from I-24 ``x_position`` [ft].

    Args:
        x_ft: (n,) float, feet along the roadway (``x / 5280`` is the mile marker).
        road: the carriageway.

    Returns:
        (n,) float64 metres from the segment entry along the direction of travel.
    """
    mm = np.asarray(x_ft, dtype=np.float64) / FEET_PER_MILE
    if road is Road.EASTBOUND:
        return (mm - SEGMENT_START_MM) * MILE
    return (SEGMENT_END_MM - mm) * MILE


def x_feet(x_m: np.ndarray, road: Road) -> np.ndarray:
    """Inverse of :func:`road_x`: I-24 ``x_position`` [ft] from road-frame x [m]."""
    return mile_marker(x_m, road) * FEET_PER_MILE


def mile_marker(x_m: np.ndarray, road: Road) -> np.ndarray:
    """Mile marker [mi] of road-frame x [m] on ``road``."""
    x = np.asarray(x_m, dtype=np.float64) / MILE
    return SEGMENT_START_MM + x if road is Road.EASTBOUND else SEGMENT_END_MM - x


def road_y(y_ft: np.ndarray) -> np.ndarray:
    """Road-frame y [m] (from the median centre, outward) from I-24 ``y_position`` [ft]."""
    return np.abs(np.asarray(y_ft, dtype=np.float64)) * FT


def y_feet(y_m: np.ndarray, road: Road) -> np.ndarray:
    """Inverse of :func:`road_y`: I-24 ``y_position`` [ft], < 0 eastbound, > 0 westbound."""
    return -road.direction * np.asarray(y_m, dtype=np.float64) / FT


_LANE_OF_BAND = np.array([0, *(-k for k in range(1, N_LANES + 1)), 0], dtype=np.int8)


def lane_of(y_m: np.ndarray) -> np.ndarray:
    """Lane id (-1..-4) of road-frame y [m]; 0 where y lies outside the four lane bands
    (or is NaN).

    Returns:
        (n,) int8.
    """
    # A nanometre of tolerance so that band edges given in feet (e.g. 60 ft) land on
    # the band they start, despite the ft -> m round-off. fmin/fmax send NaN to the
    # outside band; the cosimulator calls this every step, so it is kept to few ops.
    band = np.asarray(y_m, dtype=np.float64) / LANE_WIDTH + 1e-9
    band = np.fmax(np.fmin(band, N_LANES + 1.0), 0.0)
    return _LANE_OF_BAND[band.astype(np.intp)]


def lane_center(lane: np.ndarray | int) -> np.ndarray:
    """Road-frame y [m] of the centre line of lane ``lane`` (-1..-4)."""
    lane = np.asarray(lane)
    if np.any((lane > -1) | (lane < -N_LANES)):
        raise ValueError(f"lane ids must be in -1..-{N_LANES}, got {lane!r}")
    return (-lane + 0.5) * LANE_WIDTH
