"""Longitudinal decisions of the traffic manager: each driver's car-following
acceleration behind every leader it has (one per lane it occupies), and the
deceleration it would need to stay clear of them (emergency braking).

The acceleration itself is tracked by the vehicle model (``Controls.accel``), which
adds feedforward for grade, rolling resistance and drag.
"""

import numpy as np

from twin.core.i24 import N_LANES
from twin.traffic.models.base import CarFollowingModel, take

MIN_SPEED_PATH = 5.0  # [m/s] lane-change paths are at least this speed times their time


def follow(
    scene, drivers, body_lane: np.ndarray, speed: np.ndarray, model: CarFollowingModel, config
) -> tuple[np.ndarray, np.ndarray]:
    """Car-following accelerations and emergency needs of the managed vehicles.

    Args:
        scene: the step's :class:`~twin.traffic.scene.Scene`; its ``accel`` still holds
            the last commands (the leaders' braking the emergency test assumes).
        drivers: the :class:`~twin.traffic.driver_state.DriverState` (n,).
        body_lane: (n,) the lane each body is in; speed: (n,) [m/s], >= 0.
        model: the drivers' car-following model.
        config: the :class:`~twin.traffic.config.TrafficConfig`.

    Returns:
        accel: (n,) [m/s^2] the model's acceleration behind the most constraining
            leader; need: (n,) [m/s^2] >= 0 the deceleration staying clear of every
            leader needs (:func:`required_decel`).
    """
    n, occupancy = scene.n, scene.occupancy
    driven = occupancy.owner < n
    owner = occupancy.owner[driven]
    gap, leader = occupancy.leaders(scene.x, scene.length)
    gap, leader = gap[driven], leader[driven]
    # a slow vehicle past the middle of its lane change no longer follows the leader
    # of the lane it leaves (its followers there still see it): it finishes the
    # change rather than stopping across the line behind a queue it is leaving
    entry_lane = -(occupancy.group[driven] % N_LANES) - 1
    left_behind = (
        (entry_lane == drivers.lane_from[owner])
        & (drivers.lane_from[owner] != drivers.lane[owner])
        & (body_lane[owner] == drivers.lane[owner])
        & (speed[owner] < MIN_SPEED_PATH)  # slow: its path is made for this speed
    )
    gap = np.where(left_behind, np.inf, gap)
    leader = np.where(left_behind, owner, leader)
    v_lead = scene.speed[leader]
    accel = np.full(n, np.inf)
    np.minimum.at(accel, owner, model.accel(speed[owner], v_lead, gap, take(drivers.model, owner)))
    need_entry = required_decel(
        gap,
        speed[owner],
        v_lead,
        np.maximum(-scene.accel[leader], 0.0),
        config.emergency_margin,
        config.reaction_time,
    )
    need = np.zeros(n)
    np.maximum.at(need, owner, need_entry)
    return accel, need


def required_decel(
    gap: np.ndarray,
    v: np.ndarray,
    v_lead: np.ndarray,
    lead_decel: np.ndarray,
    margin: float,
    reaction: float,
) -> np.ndarray:
    """Deceleration [m/s^2] (>= 0) a follower needs to stay ``margin`` behind its leader
    if the leader keeps decelerating at ``lead_decel`` (>= 0) until it stops.

    After ``reaction`` [s] of travel at the current speeds, the follower brakes at a
    constant deceleration. If it would close the gap before the leader stops, the
    relative motion decides (``lead_decel + closing^2 / (2 room)``); otherwise the
    final gap with both stopped does. Where the room is used up already, the result
    is ``inf``. Shapes (n,); ``gap`` inf gives 0.
    """
    closing = v - v_lead
    room = gap - margin - np.maximum(closing, 0.0) * reaction
    with np.errstate(divide="ignore", invalid="ignore"):
        lead_stop_time = np.where(lead_decel > 1e-6, v_lead / lead_decel, np.inf)
        lead_stop = np.where(lead_decel > 1e-6, 0.5 * v_lead * lead_stop_time, np.inf)
        stop_room = gap - margin - closing * reaction + lead_stop
        both_stop = np.where(stop_room > 0, v**2 / (2.0 * stop_room), np.inf)
        # the relative motion's closest approach comes at 2 room / closing
        catches_up = (closing > 0) & (2.0 * room < closing * lead_stop_time)
        relative = np.where(room > 0, lead_decel + closing**2 / (2.0 * room), np.inf)
    need = np.where(catches_up, relative, both_stop)
    return np.where(np.isfinite(gap), need, 0.0)
