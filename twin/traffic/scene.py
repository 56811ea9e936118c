"""What the traffic manager works on each step: the obstacles it must respect and the
commands it gives."""

from dataclasses import dataclass

import numpy as np

from twin.core.i24 import N_LANES


@dataclass(frozen=True, eq=False)
class Obstacles:
    """Vehicles the manager does not drive but its drivers must respect (the ghosts).

    Struct-of-arrays (k,): ``road`` directions, ``lane`` ids, ``x`` [m] back centre,
    ``length`` [m], ``speed`` [m/s] and ``accel`` [m/s^2] along the road: what the
    obstacle will do, its mean acceleration over the next
    :data:`~twin.traffic.kernels.longitudinal.FORESEEN` seconds (a lane change in front
    of it judges it at the speed it reaches then, where it speeds up), or its
    acceleration now where nothing better is known.
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
