"""Lanes that end in the synthesiser: a lane drop, and an on-ramp's acceleration lane.

The synthesiser's drivers leave a lane that ends by a model of their own, after Gipps
(1986) and the cooperative merging models (Hidas 2005), not the twin's:

- a driver in a lane that ends seeks a gap once the end is nearer than its own
  look-ahead distance per lane it still has to cross (drawn per driver); an on-ramp's
  drivers seek one from the start of the acceleration lane;
- while it seeks, it takes the first gap in which neither it nor its new follower
  must brake harder than a deceleration that grows from the drivers' MOBIL
  ``safe_decel`` when it starts seeking to :data:`MAX_ACCEPT_DECEL` at the end (to
  keep 1 m apart: :func:`needed_decel`), whatever it gains or loses;
- its lane's end is a standing obstacle it brakes for, so one that finds no gap waits
  at the end;
- courteous drivers (a share of all) who have a seeking driver ahead of them in the
  next lane, past half its seek distance and with room ahead of it there, drop back
  for it where they can still stop behind it braking comfortably, decelerating no harder
  than their comfortable deceleration;
- nobody moves by choice into a lane that ends within its look-ahead.

The on-ramp's lane is lane :data:`RAMP_LANE` (-5), beyond lane -4; in the lane
occupancy it is kept apart as lane -1 of the opposite road (the synthesiser simulates
one road, so that slot is free).
"""

import numpy as np

from twin.core import i24
from twin.core.ramps import RAMP_LANE
from twin.data.synth.config import SynthConfig
from twin.traffic.lanes import Occupancy

#: [m/s^2] the hardest braking a driver at its lane's very end asks of its new follower
MAX_ACCEPT_DECEL = 4.0
#: [m] the gap a seeking driver needs ahead of it in the next lane before a courteous
#: driver there drops back for it (one that is alongside the next lane's queue is not
#: waited for: yielding to it would stop the lane)
MERGE_ROOM = 2.0


def any_lane_ends(config: SynthConfig) -> bool:
    """Whether the configuration has a lane that ends (a drop or an on-ramp)."""
    return config.lane_drop is not None or config.on_ramp is not None


def lane_end(config: SynthConfig, lane: np.ndarray) -> np.ndarray:
    """(n,) [m] where each lane in ``lane`` ends (``inf`` where it continues)."""
    lane = np.asarray(lane)
    end = np.full(lane.shape, np.inf)
    if config.lane_drop is not None:
        end[np.isin(lane, config.lane_drop.lanes)] = config.lane_drop.x
    if config.on_ramp is not None:
        end[lane == RAMP_LANE] = config.on_ramp.x_end
    return end


def lanes_to_cross(config: SynthConfig, lane: np.ndarray) -> np.ndarray:
    """(n,) lanes each driver must still cross (to the left) to reach one that
    continues: 0 in a lane that continues."""
    lane = np.asarray(lane, dtype=np.int64)
    n = np.zeros(lane.shape, dtype=np.int64)
    if config.on_ramp is not None:
        n[lane == RAMP_LANE] = 1
    if config.lane_drop is not None:
        dropped = np.array(config.lane_drop.lanes)
        first_kept = int(dropped.max()) + 1  # the innermost continuing lane next to them
        inside = np.isin(lane, dropped)
        n[inside] = first_kept - lane[inside]
    return n


def seek_distance(config: SynthConfig, lane: np.ndarray, lookahead: np.ndarray) -> np.ndarray:
    """(n,) [m] how far before its lane's end each driver seeks a gap: its look-ahead per
    lane to cross; on the ramp, the whole acceleration lane."""
    d = np.asarray(lookahead) * lanes_to_cross(config, lane)
    if config.on_ramp is not None:
        ramp = config.on_ramp
        d = np.where(np.asarray(lane) == RAMP_LANE, ramp.x_end - ramp.x_start, d)
    return d


def seeking(config: SynthConfig, lane, lane_from, x, length, lookahead) -> np.ndarray:
    """(n,) bool: the drivers seeking a gap now (in a lane that ends within their seek
    distance, not already changing lanes)."""
    distance = lane_end(config, lane) - (x + length)
    return (lane == lane_from) & (distance < seek_distance(config, lane, lookahead))


def ends_within(config: SynthConfig, lane: np.ndarray, x: np.ndarray, lookahead) -> np.ndarray:
    """(n,) bool: lane ``lane`` ends within a driver's seek distance ahead of ``x`` (the
    driver does not move into it by choice)."""
    return lane_end(config, lane) - x < seek_distance(config, lane, lookahead)


def accept_decel(config: SynthConfig, distance: np.ndarray, seek: np.ndarray) -> np.ndarray:
    """(n,) [m/s^2] the braking a seeking driver accepts of its new follower, ``distance``
    from its lane's end having started to seek ``seek`` before it: MOBIL's
    ``safe_decel`` at the start, :data:`MAX_ACCEPT_DECEL` at the end."""
    urgency = np.clip(1.0 - distance / np.maximum(seek, 1.0), 0.0, 1.0)
    low = min(config.safe_decel, MAX_ACCEPT_DECEL)
    return low + (MAX_ACCEPT_DECEL - low) * urgency


def needed_decel(v_rear, v_front, gap) -> np.ndarray:
    """[m/s^2] the constant deceleration the rear vehicle needs to match the front
    one's speed 1 m behind it, from ``gap`` [m] apart (``inf`` once closer than 1 m)."""
    closing = np.maximum(np.asarray(v_rear) - np.asarray(v_front), 0.0)
    room = np.asarray(gap, dtype=np.float64) - 1.0
    with np.errstate(divide="ignore", invalid="ignore"):
        need = np.where(room > 0, closing**2 / (2.0 * np.maximum(room, 1e-9)), np.inf)
    return np.where(closing == 0, np.where(room > 0, 0.0, np.inf), need)


def occupancy(x: np.ndarray, lane: np.ndarray, lane_from: np.ndarray) -> Occupancy:
    """Lane occupancy of the synthesiser's road, the ramp's lane kept apart (module doc)."""
    lanes, roads = [], []
    for ids in (lane, lane_from):
        ramp = ids == RAMP_LANE
        lanes.append(np.where(ramp, -1, ids).astype(np.int8))
        roads.append(np.where(ramp, -1, 1))
    return Occupancy.build(roads, x, lanes)


def lane_y(lane: np.ndarray) -> np.ndarray:
    """[m] road-frame y of the centre of each lane, the ramp's (-5) included."""
    return (-np.asarray(lane, dtype=np.float64) + 0.5) * i24.LANE_WIDTH
