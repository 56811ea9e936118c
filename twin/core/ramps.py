"""The segment's on-ramps: their acceleration lanes, the twin's lane -5.

Two on-ramps' acceleration lanes reach the segment (the I-24 MOTION landmark layer,
``assets/i24_aux/ramp_and_landmark_layer.csv``, Gloudemans et al. 2023): eastbound the
Hickory Hollow Pkwy on-ramp (``eb_HH_on_start`` MM 60.43 to ``eb_HH_on_end`` MM 60.70),
westbound the Old Hickory Blvd on-ramp (``wb_OH_on_start`` MM 62.29 to ``wb_OH_on_end``
MM 61.51). Each is a lane beside lane -4, lane :data:`RAMP_LANE` (-5), spanning
``y in [5, 6] * 12 ft`` where it is a full lane:

* its pavement opens over :data:`OPENING` before the landmark's start (the gore, where
  the ramp's roadway, which joins at an angle, becomes a lane beside lane -4);
* it runs beside lane -4 at full width to the taper;
* it narrows linearly over :data:`TAPER` to nothing at the landmark's end, where the
  merge must be done.

Its width at ``x`` is :meth:`Ramp.width`, and :func:`lane_at` is the lane query that
knows it (``twin.core.i24.lane_of`` knows the four through lanes only).
"""

import functools
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from twin.core.i24 import FEET_PER_MILE, LANE_WIDTH, N_LANES, SEGMENT_LENGTH, Road, lane_of, road_x
from twin.core.jit import kernel
from twin.core.paths import asset

RAMP_LANE = -5
#: [m] the acceleration lane's taper, 300 ft: a parallel-type entrance's taper on a
#: freeway (AASHTO, A Policy on Geometric Design of Highways and Streets, 2018, 10.9.6)
TAPER = 91.44
#: [m] over which the ramp's pavement widens to a full lane before its gore
OPENING = 30.0
LANDMARKS = "ramp_and_landmark_layer.csv"


#: [m] a body in lane -5's band is on the acceleration lane this far beyond the lane's
#: ends too (a merge begun at the lane's end runs a few metres past it); elsewhere that
#: band is the shoulder, off the lanes (:func:`on_ramp`)
SPAN_MARGIN = 10.0


def ramp_spans(road, ramps: tuple["Ramp", ...] | None = None) -> np.ndarray:
    """(k, 2) [m] x from where each on-ramp's pavement opens to where its taper ends,
    on carriageway ``road`` (the segment's ramps unless ``ramps`` are given), by x."""
    road = Road.parse(road)
    ramps = segment_ramps() if ramps is None else ramps
    rows = sorted((r.x_start - OPENING, r.x_end) for r in ramps if r.road == road)
    return np.array(rows, dtype=np.float64).reshape(-1, 2)


@kernel(inline=True)
def on_ramp(spans, x):
    """Whether road-frame ``x`` [m] lies on an on-ramp's acceleration lane's span, within
    SPAN_MARGIN of its ends: ``spans``' rows begin with the span's start and end with
    its end (:func:`ramp_spans`, or the cosimulation's ``CoreSettings.merges``)."""
    last = spans.shape[1] - 1
    for k in range(spans.shape[0]):
        if spans[k, 0] - SPAN_MARGIN <= x <= spans[k, last] + SPAN_MARGIN:
            return True
    return False


def body_lanes(road: np.ndarray, x: np.ndarray, y: np.ndarray, ramps) -> np.ndarray:
    """(n,) int8 the lane of bodies on carriageways ``road`` (+1 / -1 each) at road-frame
    ``x``, ``y`` [m], as both worlds report it: by ``y``'s band (:func:`lane_of_y`), lane
    -5's band on an on-ramp's span (:func:`on_ramp`, ``ramps`` the map's), else 0 (the
    shoulder)."""
    y = np.asarray(y, dtype=np.float64)
    x = np.asarray(x, dtype=np.float64)
    lane = lane_of(y)
    band = y / LANE_WIDTH + 1e-9
    ramp_band = (band >= -RAMP_LANE) & (band < -RAMP_LANE + 1.0)
    if not ramp_band.any():
        return lane
    road = np.broadcast_to(np.asarray(road), y.shape)
    for r in (Road.EASTBOUND, Road.WESTBOUND):
        spans = ramp_spans(r, ramps)
        here = ramp_band & (road == r.direction)
        inside = np.zeros(y.shape, bool)
        for x0, x1 in spans:
            inside |= (x >= x0 - SPAN_MARGIN) & (x <= x1 + SPAN_MARGIN)
        lane[here & inside] = RAMP_LANE
    return lane


@kernel(inline=True)
def lane_of_y(y):
    """The lane (-1..-5) of road-frame ``y`` [m], one value, for the compiled kernels; 0
    outside the five bands or NaN (:func:`twin.core.i24.lane_of` with lane -5's band).

    Lane -5's band counts wherever ``y`` lies in it, without asking whether a ramp is
    there: the recording holds samples in it only on an acceleration lane (the ingest
    keeps no other, :func:`lane_at`). A body's lane is this one where it is on a ramp's
    span (:func:`on_ramp`), else 0: the cosimulation's step sets the shoulder's (see
    :func:`body_lanes` for the worlds')."""
    band = y / LANE_WIDTH + 1e-9
    if not band >= 1.0 or band >= -RAMP_LANE + 1.0:
        return 0
    return -int(band)


@dataclass(frozen=True)
class Ramp:
    """An on-ramp's acceleration lane in the road frame of its carriageway.

    Attributes:
        road: the carriageway it joins.
        name: its landmarks' stem (``eb_HH_on``).
        x_start: [m] the gore: where it is a full lane beside lane -4.
        x_end: [m] where its taper ends (its width is 0 there).
    """

    road: Road
    name: str
    x_start: float
    x_end: float

    def __post_init__(self):
        if not self.x_end - self.x_start >= TAPER:
            raise ValueError(
                f"on-ramp {self.name}: its lane from x = {self.x_start:.1f} to {self.x_end:.1f} m "
                f"is shorter than its {TAPER} m taper"
            )

    @property
    def x_taper(self) -> float:
        """[m] where the taper begins."""
        return self.x_end - TAPER

    @property
    def breakpoints(self) -> np.ndarray:
        """(4,) [m] x where its width changes slope: opening, gore, taper, end."""
        return np.array([self.x_start - OPENING, self.x_start, self.x_taper, self.x_end])

    def width(self, x: np.ndarray) -> np.ndarray:
        """[m] the lane's width at road-frame ``x`` (0 where it is not), shape of ``x``."""
        return np.interp(x, self.breakpoints, [0.0, LANE_WIDTH, LANE_WIDTH, 0.0], 0.0, 0.0)


def ramps_from_landmarks(landmarks: dict[str, tuple[str, float]]) -> tuple[Ramp, ...]:
    """The acceleration lanes that reach the segment.

    Args:
        landmarks: landmark name -> (direction ``eb``/``wb``, mile marker), as in
            ``ramp_and_landmark_layer.csv``; an on-ramp is a pair ``<stem>_on_start``,
            ``<stem>_on_end``.

    Returns:
        one :class:`Ramp` per pair whose lane overlaps the segment (0 <= x <= its
        length), ordered by road then x.

    Raises:
        ValueError: a pair's direction is unknown or differs between its ends, or its
            end lies before its start along travel.
    """
    found = []
    for name, (direction, mm_end) in landmarks.items():
        if not name.endswith("_on_end") or name[:-4] + "_start" not in landmarks:
            continue
        stem = name[: -len("_end")]
        start_direction, mm_start = landmarks[stem + "_start"]
        if start_direction != direction:
            raise ValueError(f"on-ramp {stem}: its ends lie on {start_direction} and {direction}")
        road = Road.parse(direction)
        x_start, x_end = (float(road_x(mm * FEET_PER_MILE, road)) for mm in (mm_start, mm_end))
        if x_end < x_start:
            raise ValueError(f"on-ramp {stem}: its end lies before its start along travel")
        if x_end > 0.0 and x_start - OPENING < SEGMENT_LENGTH:
            found.append(Ramp(road, stem, x_start, x_end))
    return tuple(sorted(found, key=lambda r: (r.road.code, r.x_start)))


@functools.cache
def segment_ramps() -> tuple[Ramp, ...]:
    """The segment's on-ramps, from the shipped landmark layer (read once)."""
    return ramps_from_landmarks(read_landmarks(asset("i24_aux") / LANDMARKS))


def read_landmarks(path: Path) -> dict[str, tuple[str, float]]:
    """Landmark name -> (direction, mile marker) of a ``ramp_and_landmark_layer.csv``.

    Raises:
        ValueError: the file lacks a column or holds a mile marker that is not a number.
    """
    frame = pd.read_csv(path)
    missing = {"Direction", "Landmark name", "MM"} - set(frame.columns)
    if missing:
        raise ValueError(f"{path.name}: missing column(s) {sorted(missing)}")
    mm = pd.to_numeric(frame["MM"], errors="coerce").to_numpy(dtype=np.float64)
    if not np.all(np.isfinite(mm)):
        raise ValueError(f"{path.name}: a mile marker is not a number")
    return {
        str(name): (str(direction), float(m))
        for name, direction, m in zip(frame["Landmark name"], frame["Direction"], mm, strict=True)
    }


def ramp_width(road, x: np.ndarray, ramps: tuple[Ramp, ...] | None = None) -> np.ndarray:
    """[m] the acceleration lanes' width at road-frame ``x``, 0 where there is none.

    Args:
        road: a :class:`~twin.core.i24.Road` for all points, or (n,) directions +1/-1.
        x: (n,) [m] along travel.
        ramps: the acceleration lanes (default: :func:`segment_ramps`).
    """
    x = np.asarray(x, dtype=np.float64)
    direction = Road.parse(road).direction if isinstance(road, (Road, str)) else np.asarray(road)
    width = np.zeros(x.shape)
    for ramp in segment_ramps() if ramps is None else ramps:
        width = np.maximum(width, np.where(direction == ramp.road.direction, ramp.width(x), 0.0))
    return width


def lane_at(road, x: np.ndarray, y: np.ndarray, ramps: tuple[Ramp, ...] | None = None):
    """Lane id of road-frame points, the acceleration lanes included: -1..-4 in the
    through lanes' bands, :data:`RAMP_LANE` within an acceleration lane's width beyond
    lane -4, 0 elsewhere (the shoulders, NaN).

    Args:
        road: a :class:`~twin.core.i24.Road` for all points, or (n,) directions +1/-1.
        x: (n,) [m] along travel.
        y: (n,) [m] from the median centre line outward.
        ramps: the acceleration lanes (default: :func:`segment_ramps`).

    Returns:
        (n,) int8.
    """
    y = np.asarray(y, dtype=np.float64)
    lane = lane_of(y)
    # in lane widths beyond lane -4, with lane_of's nanometre: a lane's inner edge given
    # in feet (60 ft) belongs to it, its outer edge (72 ft where it is full) does not
    beyond = (y / LANE_WIDTH + 1e-9 - (N_LANES + 1)) * LANE_WIDTH
    ramp = (lane == 0) & (beyond >= 0.0) & (beyond < ramp_width(road, x, ramps))
    return np.where(ramp, np.int8(RAMP_LANE), lane).astype(np.int8)
