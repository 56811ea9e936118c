"""The worlds a cosimulation can run in, and the one interface the cosimulator uses.

``physics`` (:class:`twin.physics.world.PhysicsWorld`) is the reference: rigid bodies
on ray-cast wheels in pybullet at 100 Hz, the only world cameras can render.
``kinematic`` (:class:`twin.physics.kinematic.KinematicWorld`) integrates the same
vehicles as point masses on kinematic bicycles in numpy at the control step, for
training and large sweeps. The cosimulator, the traffic manager, the metrics and the
env reach the vehicles only through :class:`World`.
"""

from typing import Protocol

import numpy as np

from mapgen.build import MapBundle
from mapgen.road import RoadModel
from twin.physics.states import SpawnStates, VehicleStates
from twin.physics.vehicle import VehicleParams

#: The worlds by name, with each one's default step [s].
DEFAULT_DT = {"physics": 0.01, "kinematic": 0.1}
WORLDS = tuple(DEFAULT_DT)


class World(Protocol):
    """What a world offers the cosimulator: vehicles named by twin ids (int64, never
    reused, sorted in every array), spawned with a speed, driven by controls, stepped
    by a fixed dt, read back as :class:`VehicleStates`."""

    road: RoadModel
    time: float  # [s] since the world began

    @property
    def dt(self) -> float: ...

    @property
    def ids(self) -> np.ndarray: ...

    @property
    def params(self) -> VehicleParams: ...

    def params_of(self, ids) -> VehicleParams: ...

    def spawn(self, states: SpawnStates) -> np.ndarray: ...

    def despawn(self, ids) -> None: ...

    def set_controls(self, ids=None, *, accel=None, steer=None, drive=None, brake=None): ...

    def step(self) -> None: ...

    def states(self) -> VehicleStates: ...

    def vehicle_contacts(self) -> np.ndarray: ...

    def close(self) -> None: ...


def check_world(world: str, dt: float) -> None:
    """Raise ValueError naming the problem when ``world`` is unknown or ``dt`` [s] is out
    of its range."""
    from twin.physics.kinematic import MAX_DT
    from twin.physics.world import PhysicsConfig

    if world not in DEFAULT_DT:
        raise ValueError(f"world must be one of {', '.join(WORLDS)}, got {world!r}")
    if world == "physics":
        try:
            PhysicsConfig(dt=dt)
        except ValueError as error:
            raise ValueError(f"the physics world's {error}") from None
    elif not 0.0 < dt <= MAX_DT:
        raise ValueError(f"the kinematic world's dt must be in (0, {MAX_DT}] s, got {dt}")


def make_world(world: str, bundle: MapBundle, dt: float) -> World:
    """A new world of kind ``world`` over the map, stepping by ``dt`` [s].

    Raises:
        ValueError: an unknown world or a bad step.
    """
    check_world(world, dt)
    if world == "physics":
        from twin.physics.world import PhysicsConfig, PhysicsWorld

        return PhysicsWorld(bundle, PhysicsConfig(dt=dt))
    from twin.physics.kinematic import KinematicWorld

    return KinematicWorld(bundle, dt)
