"""What the traffic manager works on each step: the obstacles it must respect, the
scene of vehicles and obstacles with their lane occupancy, and the commands it gives."""

from dataclasses import dataclass

import numpy as np

from twin.core.i24 import LANE_WIDTH, N_LANES
from twin.traffic.lanes import Occupancy


@dataclass(frozen=True, eq=False)
class Obstacles:
    """Vehicles the manager does not drive but its drivers must respect (the ghosts).

    Struct-of-arrays (k,): ``road`` directions, ``lane`` ids, ``x`` [m] back centre,
    ``length`` [m], ``speed`` [m/s] and ``accel`` [m/s^2] along the road.
    """

    road: np.ndarray
    lane: np.ndarray
    x: np.ndarray
    length: np.ndarray
    speed: np.ndarray
    accel: np.ndarray

    @classmethod
    def make(cls, road, lane, x, length, speed, accel=0.0) -> "Obstacles":
        """Coerce to (k,) arrays and check them.

        Raises:
            ValueError: naming the field that is non-finite or of the wrong length.
        """
        x = np.atleast_1d(np.asarray(x, dtype=np.float64))
        values = {
            name: np.broadcast_to(np.asarray(value, dtype=dtype), x.shape).copy()
            for name, value, dtype in (
                ("road", road, np.int8),
                ("lane", lane, np.int8),
                ("length", length, np.float64),
                ("speed", speed, np.float64),
                ("accel", accel, np.float64),
            )
        }
        for name, value in {"x": x, **values}.items():
            if not np.all(np.isfinite(value)):
                raise ValueError(f"obstacle field {name} holds a non-finite value")
        if not np.all(np.isin(values["road"], (-1, 1))):
            raise ValueError("obstacle road must be +1 (eastbound) or -1 (westbound)")
        lane = values["lane"]
        if np.any((lane > -1) | (lane < -N_LANES)):
            raise ValueError(f"obstacle lanes must be in -1..-{N_LANES}: {np.unique(lane)}")
        return cls(x=x, **values)

    def __len__(self) -> int:
        return self.x.size


NO_OBSTACLES = Obstacles.make([], [], [], [], [])


@dataclass(frozen=True, eq=False)
class Commands:
    """What the manager asks of the vehicles, (n,) in the order of the states given.

    ``accel`` [m/s^2] for the vehicle model's acceleration tracking, ``steer`` [rad]
    front-wheel angle, ``lane`` the lane each vehicle is driving to (its own when not
    changing), ``changing`` whether it is mid-lane-change (until it is centred in the
    new lane), ``path_y`` [m] the lateral position its path asks for now.
    """

    id: np.ndarray
    accel: np.ndarray
    steer: np.ndarray
    lane: np.ndarray
    changing: np.ndarray
    path_y: np.ndarray


@dataclass(frozen=True, eq=False)
class Scene:
    """One step's managed vehicles (rows 0..n-1) followed by the obstacles, (n + k,).

    Attributes:
        n: managed vehicles. road, x [m], y [m], length [m], speed [m/s]: of all.
        accel: [m/s^2] the vehicles' last commands and the obstacles' accelerations;
            the manager puts its new car-following accelerations in once the
            emergency test has read the old ones.
        occupancy: every vehicle in its lane, the lane it leaves while changing and
            the lane its body is in; obstacles in their lane.
    """

    n: int
    road: np.ndarray
    x: np.ndarray
    y: np.ndarray
    length: np.ndarray
    speed: np.ndarray
    accel: np.ndarray
    occupancy: Occupancy

    @classmethod
    def build(cls, drivers, states, speed: np.ndarray, obstacles: Obstacles) -> "Scene":
        """The scene of the managed ``drivers`` (their state, by increasing id) whose
        bodies are at ``states`` moving at ``speed`` (n,) [m/s] >= 0, and ``obstacles``."""
        k = len(obstacles)

        def join(mine, theirs):
            return np.concatenate([mine, theirs]) if k else mine

        none = np.zeros(k, np.int8)
        road, x = join(drivers.road, obstacles.road), join(states.x, obstacles.x)
        lanes = [join(drivers.lane, obstacles.lane), join(drivers.lane_from, none)]
        occupancy = Occupancy.build(road, x, [*lanes, join(states.lane, none)])
        return cls(
            n=len(drivers),
            road=road,
            x=x,
            y=join(states.y, centre_y(obstacles.lane)),
            length=join(drivers.length, obstacles.length),
            speed=join(speed, obstacles.speed),
            accel=join(drivers.accel, obstacles.accel).copy(),
            occupancy=occupancy,
        )


def centre_y(lane: np.ndarray) -> np.ndarray:
    """Road-frame y [m] of lane centres, for lanes already checked."""
    return (0.5 - lane) * LANE_WIDTH
