"""Lane-change decisions of the traffic manager: MOBIL for the drivers due to decide,
the changes asked for (by a controller), the strategic targets (a lane to leave by a
place: :mod:`twin.traffic.strategic`), and the HOV rule.

A driver decides on a grid of ``decision_period`` at random intervals around
``decision_interval``; a change it starts lasts a drawn manoeuvre time, along a path
:mod:`twin.traffic.steering` tracks. Accelerations are the drivers' car-following
model's; obstacles (the ghosts) are judged as the class table's mean driver.
"""

from dataclasses import dataclass, replace

import numpy as np

from twin.core.i24 import HOV_LANE, N_LANES
from twin.traffic.controller_api import LEFT, RIGHT
from twin.traffic.longitudinal import MIN_SPEED_PATH
from twin.traffic.mobil import mobil_incentive, mobil_safe
from twin.traffic.models.base import take
from twin.traffic.strategic import urgency

MIN_LANE_CHANGE_GAP = 1.0  # [m] bumper to bumper, to each of the new neighbours
# [m] the shortest path of an urgent (strategic) change: a driver who must leave its
# lane noses across a queue in about three car lengths (the path's peak heading about
# 21 degrees, its least radius about 12.5 m), where a discretionary change keeps a path
# made for MIN_SPEED_PATH; without it no change in a crawling queue finds room
URGENT_PATH = 15.0


@dataclass(frozen=True, eq=False)
class _Candidates:
    """The drivers deciding now, (k,) each: their index, where they are, and what
    their old lane's follower does now and would do once they have left."""

    index: np.ndarray
    x: np.ndarray
    speed: np.ndarray
    lane: np.ndarray
    road: np.ndarray
    room: np.ndarray  # bool: the change can get across behind the current leader
    urgent: np.ndarray  # bool: a strategic change under way (the short path)
    old_follower_now: np.ndarray
    old_follower_after: np.ndarray


def decide(
    drivers, scene, centre_x, *, time, rng, model, params, config, excluded, keep_out=()
) -> int:
    """Start the lane changes MOBIL chooses for the drivers due to decide, and the
    changes asked for where they are safe; returns how many started.

    Args:
        drivers: the :class:`~twin.traffic.driver_state.DriverState`, changed in place.
        scene: the step's :class:`~twin.traffic.scene.Scene`, ``accel`` holding the
            vehicles' car-following accelerations now.
        centre_x: (n,) [m] the vehicles' centres along the road.
        time: [s] the manager's clock. rng: its random generator.
        model: the car-following model; params: its parameters for the scene's
            vehicles and obstacles, (n + k,).
        config: the :class:`~twin.traffic.config.TrafficConfig`.
        excluded: ids whose controller decides their lane changes (no MOBIL).
        keep_out: (road, lane, x0, x1) zones with no discretionary change into the lane
            (:meth:`TrafficManager.set_keep_out`).
    """
    auto = drivers.auto_lane_change
    strategic = (drivers.strategic != 0) & (centre_x >= drivers.strategic_from)
    if excluded:
        free = ~np.isin(drivers.id, list(excluded))
        auto, strategic = auto & free, strategic & free
    wants = (drivers.requested != 0) | strategic
    due = (drivers.lane_from == drivers.lane) & (((drivers.next_decision <= time) & auto) | wants)
    cand = np.flatnonzero(due)
    if cand.size == 0:
        return 0
    urge = urgency(drivers, cand, centre_x[cand])
    timed = drivers.next_decision[cand] <= time
    drivers.next_decision[cand[timed]] = time + config.decision_interval * rng.uniform(
        0.5, 1.5, int(timed.sum())
    )
    c = _candidates(drivers, scene, cand, model, params, config, urge >= 0)
    best = np.zeros(cand.size)
    choice = np.zeros(cand.size, dtype=np.int8)
    # a change asked for, or a strategic target's once its urgency has started
    requested = np.where(
        drivers.requested[cand] != 0,
        drivers.requested[cand],
        np.where(urge >= 0, drivers.strategic[cand], 0),
    )
    for step in (LEFT, RIGHT):
        target = c.lane + step
        allowed = (target <= -1) & (target >= -N_LANES)
        allowed &= hov_allows(drivers, cand, c.lane, target, c.x, config.hov_openings)
        allowed &= (requested == 0) | (requested == step)
        allowed &= ~((urge >= 0) & (drivers.strategic[cand] == -step))  # not away from it
        if keep_out:  # no discretionary change into a lane that must be left ahead
            allowed &= (requested == step) | ~kept_out(keep_out, c.road, target, c.x)
        if not allowed.any():
            continue
        gain, safe = _judge(
            drivers, scene, c, target, step, model, params, urge, config.emergency_decel
        )
        gain = np.where(requested == step, np.inf, gain)
        better = allowed & safe & (gain > best)
        best[better] = gain[better]
        choice[better] = step
    movers = choice != 0
    if movers.any():
        _start(
            drivers, scene, centre_x, cand[movers], choice[movers], c.urgent[movers], rng, config
        )
        done = cand[movers & (choice == drivers.strategic[cand])]
        drivers.strategic[done] = 0
        drivers.strategic_from[done] = np.nan
        drivers.strategic_by[done] = np.nan
    return int(np.count_nonzero(movers))


def path_length(speed, duration, urgent) -> np.ndarray:
    """[m] the length of a lane-change path at ``speed`` [m/s] lasting ``duration`` [s]:
    made for at least MIN_SPEED_PATH, or, for an ``urgent`` (bool) change, at least
    :data:`URGENT_PATH` long."""
    return np.where(
        urgent,
        np.maximum(speed * duration, URGENT_PATH),
        np.maximum(speed, MIN_SPEED_PATH) * duration,
    )


def _candidates(drivers, scene, cand, model, params, config, urgent) -> _Candidates:
    """Where the deciding drivers are, whether they have room to get across, and their
    old follower's acceleration now and after they have left its lane; ``urgent``
    (k,) bool: their changes are strategic (the short path)."""
    x, speed = scene.x[cand], scene.speed[cand]
    lane, road = drivers.lane[cand].astype(np.int64), drivers.road[cand]
    ahead_now, behind_now = scene.occupancy.around(road, lane, x)
    # room to reach the middle of the change behind the leader it still follows
    # until then (a vehicle in a standing queue cannot get across)
    high = config.lane_change_time[1]
    half_path = 0.5 * path_length(speed, high, urgent)
    gap_now = np.where(ahead_now >= 0, scene.x[ahead_now] - x - scene.length[cand], np.inf)
    lead_now = np.where(ahead_now >= 0, scene.speed[ahead_now], 0.0)
    room = gap_now + lead_now * 0.5 * high >= half_path + MIN_LANE_CHANGE_GAP
    old_gap = np.where(
        (behind_now >= 0) & (ahead_now >= 0),
        scene.x[ahead_now] - scene.x[behind_now] - scene.length[behind_now],
        np.inf,
    )
    old_after = model.accel(
        scene.speed[behind_now], scene.speed[ahead_now], old_gap, take(params, behind_now)
    )
    return _Candidates(
        index=cand,
        x=x,
        speed=speed,
        lane=lane,
        road=road,
        room=room,
        urgent=urgent,
        old_follower_now=np.where(behind_now >= 0, scene.accel[behind_now], 0.0),
        old_follower_after=np.where(behind_now >= 0, old_after, 0.0),
    )


def _judge(drivers, scene, c: _Candidates, target, step, model, params, urge, emergency_decel):
    """MOBIL's incentive (k,) [m/s^2] of moving ``step`` into ``target``, and whether
    the move is safe (k,) bool; a driver with a strategic urgency ``urge`` (k,) >= 0
    accepts a new follower's braking up to ``safe_decel * (1 + urge)``, at most
    ``emergency_decel`` (never less than ``safe_decel``)."""
    ahead, behind = scene.occupancy.around(c.road, target, c.x)
    gap_ahead = np.where(ahead >= 0, scene.x[ahead] - c.x - scene.length[c.index], np.inf)
    gap_behind = np.where(behind >= 0, c.x - scene.x[behind] - scene.length[behind], np.inf)
    own = take(drivers.model, c.index)
    own_after = model.accel(c.speed, scene.speed[ahead], gap_ahead, own)
    follower_after = np.where(
        behind >= 0,
        model.accel(scene.speed[behind], c.speed, gap_behind, take(params, behind)),
        0.0,
    )
    follower_now = np.where(behind >= 0, scene.accel[behind], 0.0)
    mobil = drivers.mobil(c.index)
    accepted = mobil
    if np.any(urge > 0):  # never past what emergency braking is for
        relaxed = np.minimum(mobil.safe_decel * (1.0 + np.maximum(urge, 0.0)), emergency_decel)
        accepted = replace(mobil, safe_decel=np.maximum(relaxed, mobil.safe_decel))
    safe = (
        c.room
        & mobil_safe(follower_after, accepted)
        & (own_after >= -mobil.safe_decel)
        & (gap_ahead >= MIN_LANE_CHANGE_GAP)
        & (gap_behind >= MIN_LANE_CHANGE_GAP)
    )
    gain = mobil_incentive(
        scene.accel[c.index],
        own_after,
        follower_now,
        follower_after,
        c.old_follower_now,
        c.old_follower_after,
        np.full(c.index.size, step == RIGHT),
        mobil,
    )
    return gain, safe


def _start(drivers, scene, centre_x, index, choice, urgent, rng, config) -> None:
    """Start the changes of drivers ``index`` one lane ``choice`` (LEFT or RIGHT);
    ``urgent`` (k,) bool: strategic changes, on the short path."""
    low, high = config.lane_change_time
    duration = rng.uniform(low, high, index.size)
    drivers.lane_from[index] = drivers.lane[index]
    drivers.lane[index] = drivers.lane[index] + choice
    drivers.start_x[index] = centre_x[index]
    drivers.start_y[index] = scene.y[index]
    drivers.path_length[index] = path_length(scene.speed[index], duration, urgent)
    drivers.requested[index] = 0


def kept_out(zones, road, lane, x) -> np.ndarray:
    """(k,) bool: ``lane`` (k,) at ``x`` (k,) [m] on ``road`` lies in one of the
    keep-out ``zones``, (road, lane, x0, x1) each (half-open in x)."""
    x = np.asarray(x, dtype=np.float64)
    out = np.zeros(x.shape, dtype=bool)
    for z_road, z_lane, x0, x1 in zones:
        out |= (road == z_road) & (lane == z_lane) & (x >= x0) & (x < x1)
    return out


def hov_allows(drivers, cand, lane, target, x, openings) -> np.ndarray:
    """(k,) bool: the moves of drivers ``cand`` from ``lane`` to ``target`` at ``x`` keep
    the HOV rule (into the HOV lane only when eligible; across its line only inside
    one of the ``openings``, (x0, x1) road-frame ranges)."""
    crossing = (lane == HOV_LANE) | (target == HOV_LANE)
    opening = np.zeros(cand.size, dtype=bool)
    for x0, x1 in openings:
        opening |= (x >= x0) & (x <= x1)
    entering_ok = (target != HOV_LANE) | drivers.hov_eligible[cand]
    return entering_ok & (~crossing | opening)
