"""The vehicles a user's Python controller drives instead of the traffic manager's
drivers: what each controller is shown (:class:`~twin.traffic.controller_api.Observation`,
read from the kernels' sorted lane entries), and how its answer becomes the vehicle's
command. The kernels leave such vehicles (``ctrl`` PYTHON) their driver's command; one
episode's are answered here between the decision and the world's step."""

import numpy as np

from twin.core.errors import ControllerError
from twin.core.i24 import LANES
from twin.physics.vehicle import GRAVITY
from twin.traffic.controller_api import NEIGHBOUR_RANGE, LaneView, Observation, parse_command
from twin.traffic.kernels.decide import driver_limit
from twin.traffic.kernels.neighbours import LANE_KEY


def observation(t, b: int, i: int, ids: np.ndarray, obstacle_y: np.ndarray, road: int,
                default_accel: float, time: float) -> Observation:  # fmt: skip
    """What the controller of slot ``i`` of episode ``b`` sees.

    Args:
        t: the episode's :data:`~twin.traffic.kernels.state.Traffic` arrays, after the
            kernels' decision (their sorted entries are this step's).
        ids: (B, N) the slots' twin ids; obstacle_y: (B, G) [m] the obstacles' y.
        road: +1 or -1. default_accel: [m/s^2] the driver's command.
        time: [s] the manager's clock.
    """
    sc, dr, veh = t.scratch, t.drivers, t.vehicles
    n = veh.valid.shape[1]
    count = int(sc.entry_count[b])
    key, group, owner = (
        sc.entry_key[b, :count],
        sc.entry_group[b, :count],
        sc.entry_owner[b, :count],
    )
    sx, sspeed, slength = sc.sx[b], sc.sspeed[b], sc.slength[b]
    x = float(sx[i])
    lanes = np.array(LANES, dtype=np.int64)
    groups = -lanes - 1
    query = groups * LANE_KEY + x
    after = np.searchsorted(key, query, side="right")
    before = np.searchsorted(key, query, side="left") - 1
    last = max(count - 1, 0)
    ahead_ok = (after < count) & (group[np.minimum(after, last)] == groups) if count else after < 0
    behind_ok = (before >= 0) & (group[np.maximum(before, 0)] == groups) if count else before < -1
    ahead = np.where(ahead_ok, owner[np.minimum(after, last)] if count else 0, -1)
    behind = np.where(behind_ok, owner[np.maximum(before, 0)] if count else 0, -1)
    view = LaneView(
        lanes=LANES,
        leader_gap=np.where(ahead >= 0, sx[ahead] - x - slength[i], np.inf),
        leader_speed=np.where(ahead >= 0, sspeed[ahead], np.nan),
        follower_gap=np.where(behind >= 0, x - sx[behind] - slength[behind], np.inf),
        follower_speed=np.where(behind >= 0, sspeed[behind], np.nan),
    )
    owners = np.unique(owner)
    near = owners[(np.abs(sx[owners] - x) <= NEIGHBOUR_RANGE) & (owners != i)]
    vehicle = near < n
    y = np.where(vehicle, veh.y[b, np.minimum(near, n - 1)], obstacle_y[b, np.maximum(near - n, 0)])
    return Observation(
        time=time,
        id=int(ids[b, i]),
        road=int(road),
        lane=int(dr.lane[b, i]),
        changing=bool(dr.lane_from[b, i] != dr.lane[b, i]),
        x=x,
        y=float(veh.y[b, i]),
        speed=float(sspeed[i]),
        desired_speed=float(dr.cf[b, i, 0]),
        default_accel=default_accel,
        lanes=view,
        neighbours={
            "id": np.where(vehicle, ids[b, np.minimum(near, n - 1)], -1),
            "dx": sx[near] - x,
            "y": y,
            "speed": sspeed[near],
        },
    )


def apply_controllers(controllers: dict, t, b: int, ids, obstacle_y, road: int, time: float,
                      may_change) -> tuple[int, int]:  # fmt: skip
    """The Python controllers' answers as their vehicles' commands (``drivers.accel``)
    and lane changes (``drivers.requested``).

    A controller with a true ``emergency_braking`` attribute is overridden by the
    drivers' emergency braking where it asks for less (a production vehicle's safety
    layer); the others get what they ask, within the tyres' grip. A lane change asked
    for is kept where ``may_change(slot, direction)`` allows it.

    Args:
        controllers: {slot: controller} of episode ``b``.

    Returns:
        (steps overridden by emergency braking, lane changes refused).

    Raises:
        ControllerError: a controller raised or answered with something that is not a
            command, naming it, its vehicle and the time.
    """
    sc, dr, veh = t.scratch, t.drivers, t.vehicles
    overrides = refused = 0
    for i, controller in controllers.items():
        vid = int(ids[b, i])
        name = getattr(controller, "__name__", type(controller).__name__)
        who = f"the controller {name} of vehicle {vid} at t = {time:.2f} s"
        # what the driver would do, as its vehicle would apply it (finite: the raw
        # command is -inf where the room to the leader is used up)
        default = float(
            driver_limit(
                sc.command[b, i], sc.emergency[b, i], float(veh.mu[b, i]) * GRAVITY,
                t.settings.brake_limit, dr.cf[b, i, t.settings.max_accel_column],
            )
        )  # fmt: skip
        try:
            answer = controller(observation(t, b, i, ids, obstacle_y, road, default, time))
        except Exception as error:
            raise ControllerError(f"{who} raised {error!r}") from error
        accel, lane_change = parse_command(answer, who)
        if sc.emergency[b, i] and getattr(controller, "emergency_braking", False):
            if -sc.need[b, i] < accel:
                overrides += 1
            accel = min(accel, -float(sc.need[b, i]))
        tyre = float(veh.mu[b, i]) * GRAVITY
        dr.accel[b, i] = min(max(accel, -tyre), tyre)
        idle = dr.lane_from[b, i] == dr.lane[b, i] and dr.requested[b, i] == 0
        if lane_change and idle:
            if may_change(i, lane_change):
                dr.requested[b, i] = lane_change
            else:
                refused += 1
    return overrides, refused
