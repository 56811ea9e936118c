"""The vehicles a user's controller drives instead of the traffic manager's drivers:
what each controller is shown (:class:`~twin.traffic.controller_api.Observation`), and
how its answer becomes the vehicle's command."""

import numpy as np

from twin.core.errors import ControllerError
from twin.core.i24 import LANES
from twin.traffic.controller_api import (
    NEIGHBOUR_RANGE,
    EgoController,
    LaneView,
    Observation,
    parse_command,
)


class Controllers:
    """The user's controllers of a traffic manager, by vehicle id, with what they did.

    Attributes:
        safety_overrides: controller steps overridden by emergency braking.
        refused_requests: lane changes asked for that the rules refused.
    """

    def __init__(self):
        self.by_id: dict[int, EgoController] = {}
        self.safety_overrides = 0
        self.refused_requests = 0

    def __bool__(self) -> bool:
        return bool(self.by_id)

    def apply(self, drivers, scene, command, need, emergency, time, request):
        """The commands with the controllers' answers in; and (n,) bool, controlled.

        A controller with a true ``emergency_braking`` attribute is overridden by the
        drivers' emergency braking (``need`` where ``emergency``), as a production
        vehicle's safety layer would; the others get what they ask. A lane change asked
        for is passed to ``request(vehicle_id, direction)``, which raises ValueError
        when the rules refuse it.

        Raises:
            ControllerError: a controller raised or answered with something that is not
                a command, naming it, its vehicle and the time.
        """
        command = command.copy()
        controlled = np.zeros(len(drivers), dtype=bool)
        for vehicle_id, controller in self.by_id.items():
            i = int(np.searchsorted(drivers.id, vehicle_id))
            controlled[i] = True
            name = getattr(controller, "__name__", type(controller).__name__)
            who = f"the controller {name} of vehicle {vehicle_id} at t = {time:.2f} s"
            try:
                answer = controller(observe(drivers, i, scene, float(command[i]), time))
            except Exception as error:
                raise ControllerError(f"{who} raised {error!r}") from error
            accel, lane_change = parse_command(answer, who)
            if emergency[i] and getattr(controller, "emergency_braking", False):
                if -need[i] < accel:
                    self.safety_overrides += 1
                accel = min(accel, -float(need[i]))
            command[i] = accel
            idle = drivers.lane_from[i] == drivers.lane[i] and drivers.requested[i] == 0
            if lane_change and idle:
                try:
                    request(vehicle_id, lane_change)
                except ValueError:
                    self.refused_requests += 1
        return command, controlled


def observe(drivers, i: int, scene, default_accel: float, time: float) -> Observation:
    """What the controller of managed vehicle ``i`` sees in ``scene``."""
    n = scene.n
    x = float(scene.x[i])
    lanes = np.array(LANES, dtype=np.int64)
    road = np.full(lanes.size, drivers.road[i])
    ahead, behind = scene.occupancy.around(road, lanes, np.full(lanes.size, x))
    view = LaneView(
        lanes=LANES,
        leader_gap=np.where(ahead >= 0, scene.x[ahead] - x - drivers.length[i], np.inf),
        leader_speed=np.where(ahead >= 0, scene.speed[ahead], np.nan),
        follower_gap=np.where(behind >= 0, x - scene.x[behind] - scene.length[behind], np.inf),
        follower_speed=np.where(behind >= 0, scene.speed[behind], np.nan),
    )
    same_road = scene.road == drivers.road[i]
    near = np.flatnonzero(same_road & (np.abs(scene.x - x) <= NEIGHBOUR_RANGE))
    near = near[near != i]
    return Observation(
        time=time,
        id=int(drivers.id[i]),
        road=int(drivers.road[i]),
        lane=int(drivers.lane[i]),
        changing=bool(drivers.lane_from[i] != drivers.lane[i]),
        x=x,
        y=float(scene.y[i]),
        speed=float(scene.speed[i]),
        desired_speed=float(drivers.desired_speed[i]),
        default_accel=default_accel,
        lanes=view,
        neighbours={
            "id": np.where(near < n, drivers.id[np.minimum(near, n - 1)], -1),
            "dx": scene.x[near] - x,
            "y": scene.y[near],
            "speed": scene.speed[near],
        },
    )
