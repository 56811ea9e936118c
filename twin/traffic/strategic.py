"""Strategic lane changes: a driver who must leave its lane by a place (a lane that
ends, a merge or an exit beyond the window, as the recording's flows say, or the
change its own recording makes), and the drivers who make room for it.

The idea of SUMO's LC2013 strategic and cooperative layers (Erdmann 2015), in the
twin's own form:

- a driver's strategic target is a direction, the place ``x_from`` where it starts to
  want the change and the place ``x_by`` by which it must have made it; its urgency
  grows from 0 at ``x_from`` to 1 at ``x_by`` (:func:`urgency`);
- from ``x_from`` it wants that change whatever MOBIL's incentive, judges it at every
  decision step (not at its random decision interval), makes no change the other way,
  and takes a gap whose new follower must brake up to ``safe_decel * (1 + urgency)``
  (at most the manager's ``emergency_decel``);
- past ``x_by`` it keeps trying, at full urgency, until :data:`GIVE_UP` metres past
  it (the retries the recorded behaviour needs: a change not safe when due is made at
  the next gap, as drivers do);
- cooperation (:func:`cooperate`): once its urgency is at least
  :data:`COOPERATE_FROM`, the urgent driver settles behind the target lane's vehicle
  ahead of it (or alongside it, when that one is more than half a length past its
  back), and the driver behind that one in the target lane drops back for it: each
  follows the other as if the change were made, braking no harder than
  :data:`COOPERATIVE_DECEL`, until the gap is safe;
- an urgent change takes a shorter path than a discretionary one
  (:data:`twin.traffic.lane_change.URGENT_PATH`), so that a driver can get across a
  crawling queue as real drivers do.

The targets are set by the cosimulator (:meth:`TrafficManager.set_strategic`) from the
calibrated flows or the recording; a target is cleared once its change starts.
"""

import numpy as np

from twin.core.i24 import N_LANES
from twin.traffic.models.base import take

GIVE_UP = 150.0  # [m] past x_by a strategic change is no longer tried
COOPERATE_FROM = 0.3  # urgency from which followers in the target lane make room
COOPERATIVE_DECEL = 1.5  # [m/s^2] the most a cooperating driver brakes to make room
MIN_ROOM = 0.1  # [m] the gap a cooperating driver judges when it overlaps the urgent one


def urgency(drivers, index, centre_x) -> np.ndarray:
    """(k,) urgency of drivers ``index`` at ``centre_x`` (k,) [m]: -1 where they have no
    target or have not reached its ``x_from``; 0 to 1 between ``x_from`` and ``x_by``,
    1 beyond."""
    x_from, x_by = drivers.strategic_from[index], drivers.strategic_by[index]
    active = (drivers.strategic[index] != 0) & (centre_x >= x_from)
    with np.errstate(invalid="ignore", divide="ignore"):
        u = np.clip((centre_x - x_from) / np.maximum(x_by - x_from, 1.0), 0.0, 1.0)
    return np.where(active, u, -1.0)


def expire(drivers, centre_x) -> None:
    """Clear the targets of drivers more than :data:`GIVE_UP` past their ``x_by``."""
    late = (drivers.strategic != 0) & (centre_x > drivers.strategic_by + GIVE_UP)
    if late.any():
        clear(drivers, np.flatnonzero(late))


def clear(drivers, index) -> None:
    drivers.strategic[index] = 0
    drivers.strategic_from[index] = np.nan
    drivers.strategic_by[index] = np.nan


def cooperate(scene, drivers, accel, centre_x, model) -> np.ndarray:
    """``accel`` (n,) with the cooperation of the drivers behind urgent ones in their
    target lanes (module doc); changed in place and returned."""
    n = scene.n
    if not np.any(drivers.strategic):
        return accel
    u = urgency(drivers, np.arange(n), centre_x)
    urgent = np.flatnonzero((u >= COOPERATE_FROM) & (drivers.lane == drivers.lane_from))
    target = drivers.lane[urgent].astype(np.int64) + drivers.strategic[urgent]
    on_road = (target <= -1) & (target >= -N_LANES)  # set_strategic checks it; kept safe
    urgent, target = urgent[on_road], target[on_road]
    if urgent.size == 0:
        return accel
    road = drivers.road[urgent]
    x = scene.x[urgent]
    ahead, behind = scene.occupancy.around(road, target, x)
    # a vehicle alongside (more than half the urgent driver's length past its back) is
    # the one to go behind: it cannot drop back far enough in time; the one behind it
    # drops back instead
    gap = np.where(behind >= 0, x - scene.x[behind] - scene.length[behind], np.inf)
    alongside = gap < -0.5 * scene.length[urgent]
    if alongside.any():
        ahead, behind = ahead.copy(), behind.copy()
        ahead[alongside] = behind[alongside]
        _, behind[alongside] = scene.occupancy.around(
            road[alongside], target[alongside], scene.x[behind[alongside]]
        )
    # the urgent driver settles behind the target lane's vehicle alongside or ahead
    aligns = ahead >= 0
    if aligns.any():
        i, a = urgent[aligns], ahead[aligns]
        room = scene.x[a] - x[aligns] - scene.length[i]
        behind_it = model.accel(scene.speed[i], scene.speed[a], room, take(drivers.model, i))
        accel[i] = np.minimum(accel[i], np.maximum(behind_it, -COOPERATIVE_DECEL))
    # and the driver behind it there drops back for it (one overlapping its back by
    # less than half its length too)
    gap = np.where(behind >= 0, x - scene.x[behind] - scene.length[behind], -np.inf)
    helps = (behind >= 0) & (behind < n) & (gap >= -0.5 * scene.length[urgent])
    if not helps.any():
        return accel
    i, f = urgent[helps], behind[helps]
    room = np.maximum(gap[helps], MIN_ROOM)
    drop_back = model.accel(scene.speed[f], scene.speed[i], room, take(drivers.model, f))
    np.minimum.at(accel, f, np.maximum(drop_back, -COOPERATIVE_DECEL))
    return accel
