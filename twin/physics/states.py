"""What every world takes and gives: the vehicles to spawn and the vehicles' states,
struct-of-arrays in the twin's frames (pybullet-free, shared by the physics and the
kinematic world).

Frames: world east-north-up (the map's); road frame x along travel from the segment
entry, y from the median centre line outward (:mod:`mapgen.road`).
"""

from dataclasses import dataclass

import numpy as np

from twin.core.i24 import Road
from twin.physics.vehicle import VehicleParams

MAX_SPEED = 60.0  # [m/s] spawn speeds above this are refused
MAX_STEER = 0.7  # [rad] front-wheel angles beyond this are refused


@dataclass(frozen=True, eq=False)
class SpawnStates:
    """Vehicles to spawn, struct-of-arrays (n,).

    ``road`` holds directions (+1 eastbound, -1 westbound); ``x`` [m] is the back
    centre along the road as in I-24 MOTION, ``y`` [m] the centre from the median;
    ``speed`` [m/s] along the lane; sizes [m].
    """

    road: np.ndarray
    x: np.ndarray
    y: np.ndarray
    speed: np.ndarray
    vehicle_class: np.ndarray
    length: np.ndarray
    width: np.ndarray
    height: np.ndarray

    @classmethod
    def make(cls, road, x, y, speed, vehicle_class, length, width, height) -> "SpawnStates":
        """Coerce and check: every array the same length, values finite and in range.

        Raises:
            ValueError: naming the bad field.
        """
        x = np.atleast_1d(np.asarray(x, dtype=np.float64))
        n = x.size
        if np.ndim(road) == 0:
            road = np.full(n, Road.parse(road).direction)
        values = {
            "road": np.asarray(road, dtype=np.int8),
            "x": x,
            "y": np.broadcast_to(np.asarray(y, dtype=np.float64), (n,)).copy(),
            "speed": np.broadcast_to(np.asarray(speed, dtype=np.float64), (n,)).copy(),
            "vehicle_class": np.broadcast_to(
                np.asarray(vehicle_class, dtype=np.int64), (n,)
            ).copy(),
            "length": np.broadcast_to(np.asarray(length, dtype=np.float64), (n,)).copy(),
            "width": np.broadcast_to(np.asarray(width, dtype=np.float64), (n,)).copy(),
            "height": np.broadcast_to(np.asarray(height, dtype=np.float64), (n,)).copy(),
        }
        for name, value in values.items():
            if value.shape != (n,):
                raise ValueError(f"spawn field {name} has shape {value.shape}, expected ({n},)")
            if not np.all(np.isfinite(value)):
                raise ValueError(f"spawn field {name} holds a non-finite value")
        if not np.all(np.isin(values["road"], (-1, 1))):
            raise ValueError("spawn road must be +1 (eastbound) or -1 (westbound)")
        if np.any(values["speed"] < 0) or np.any(values["speed"] > MAX_SPEED):
            raise ValueError(f"spawn speeds must be in 0..{MAX_SPEED} m/s")
        return cls(**values)

    def __len__(self) -> int:
        return self.x.size


@dataclass(frozen=True, eq=False)
class VehicleStates:
    """The active vehicles after the last step, struct-of-arrays.

    Attributes:
        id: (n,) twin ids.
        position: (n, 3) [m] centre of mass, world frame.
        orientation: (n, 4) quaternion (x, y, z, w).
        velocity: (n, 3) [m/s] world frame.
        angular_velocity: (n, 3) [rad/s] world frame.
        speed: (n,) [m/s] along the body's heading.
        yaw_rate: (n,) [rad/s] about the world's up axis.
        heading: (n,) [rad] world yaw.
        road: (n,) road frame: the carriageway, +1 eastbound, -1 westbound.
        x: (n,) [m] road frame, of the back centre (as the data's x).
        y: (n,) [m] road frame, from the median centre line.
        lane: (n,) lane id, -1 to -4, -5 on an on-ramp's acceleration lane (0 off the
            lanes).
        wheel_spin: (n, 4) [rad/s].
        load: (n, 4) [N] wheel loads.
        contact: (n, 4) bool, the wheel touches the road.
        drive_power: (n,) [W] what the powertrain delivered at the wheels in the last
            step (drive torque times wheel spin; braking and coasting deliver none).
    """

    id: np.ndarray
    position: np.ndarray
    orientation: np.ndarray
    velocity: np.ndarray
    angular_velocity: np.ndarray
    speed: np.ndarray
    yaw_rate: np.ndarray
    heading: np.ndarray
    road: np.ndarray
    x: np.ndarray
    y: np.ndarray
    lane: np.ndarray
    wheel_spin: np.ndarray
    load: np.ndarray
    contact: np.ndarray
    drive_power: np.ndarray


def quaternion_of(yaw: np.ndarray, pitch: np.ndarray) -> np.ndarray:
    """(n, 4) quaternions (x, y, z, w) of a yaw about z then a nose-up pitch.

    Body x forward and z up: nose-up is a negative rotation about the body's y (left).
    """
    cy, sy = np.cos(yaw / 2), np.sin(yaw / 2)
    cp, sp = np.cos(-pitch / 2), np.sin(-pitch / 2)
    return np.stack([-sy * sp, cy * sp, sy * cp, cy * cp], axis=1)


def rotation_matrices(q: np.ndarray) -> np.ndarray:
    """(n, 3, 3) rotation matrices (body to world) of (n, 4) quaternions (x, y, z, w)."""
    x, y, z, w = q.T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=1,
    )


def write_controls(controls: dict, index, *, accel=None, steer=None, drive=None, brake=None):
    """Check inputs and write them into ``controls`` (arrays ``accel``, ``drive``,
    ``brake``, ``steer``) at ``index``: a world's ``set_controls``. ``accel`` [m/s^2]
    selects acceleration tracking; ``drive``/``brake`` (0..1) select raw control
    (``accel`` is then cleared, NaN, for those vehicles); ``steer`` [rad] is the front
    wheels' angle.

    Raises:
        ValueError: a value is out of range (named).
    """
    if accel is not None:
        accel = np.asarray(accel, dtype=np.float64)
        if not np.all(np.isfinite(accel)):
            raise ValueError("accel must be finite")
        controls["accel"][index] = accel
    for name, value in (("drive", drive), ("brake", brake)):
        if value is not None:
            value = np.asarray(value, dtype=np.float64)
            if np.any((value < 0) | (value > 1)) or not np.all(np.isfinite(value)):
                raise ValueError(f"{name} must be in 0..1")
            controls[name][index] = value
            controls["accel"][index] = np.nan
    if steer is not None:
        steer = np.asarray(steer, dtype=np.float64)
        if not np.all(np.isfinite(steer)) or np.any(np.abs(steer) > MAX_STEER):
            raise ValueError(f"steer must be finite and within +/- {MAX_STEER} rad")
        controls["steer"][index] = steer


class ActiveVehicles:
    """What every world keeps of its active vehicles and answers alike: their twin ids
    (sorted) in ``_ids`` and their physical parameters in ``_params``, in that order;
    a world is a context manager that ``close()``s."""

    _ids: np.ndarray
    _params: VehicleParams

    def close(self) -> None:
        """Release what the world holds (nothing by default)."""

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    @property
    def ids(self) -> np.ndarray:
        """(n,) twin ids of the active vehicles, in the order of ``states()``."""
        return self._ids.copy()

    @property
    def params(self) -> VehicleParams:
        """Physical parameters of the active vehicles, in the order of ``states()``."""
        return self._params

    def params_of(self, ids) -> VehicleParams:
        """Physical parameters of vehicles ``ids``.

        Raises:
            KeyError: an id is not an active vehicle.
        """
        return self._params.take(self._index(ids))

    def _index(self, ids) -> np.ndarray:
        """Positions of ``ids`` in the active arrays (which are sorted by id)."""
        return index_of(self._ids, ids)


def index_of(active: np.ndarray, ids) -> np.ndarray:
    """Positions of ``ids`` in a world's sorted array of ``active`` ids.

    Raises:
        KeyError: an id is not active.
    """
    ids = np.atleast_1d(np.asarray(ids, dtype=np.int64))
    where = np.searchsorted(active, ids)
    found = where < active.size
    found[found] = active[where[found]] == ids[found]
    if not found.all():
        raise KeyError(f"not an active vehicle: {ids[~found].tolist()}")
    return where
