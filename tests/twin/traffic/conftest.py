"""Helpers for traffic tests: vehicles on the I-24 physics world driven by the manager,
and vehicles as point masses (the manager only needs their road-frame states)."""

from dataclasses import dataclass

import numpy as np
import pytest

from twin.core.i24 import lane_center
from twin.core.vehicle_classes import vehicle_classes
from twin.physics.states import SpawnStates
from twin.physics.vehicle import VehicleParams
from twin.physics.world import PhysicsWorld
from twin.traffic.config import TrafficConfig
from twin.traffic.controller_api import LaneView, Observation
from twin.traffic.manager import TrafficManager


def class_sizes(vehicle_class):
    table = vehicle_classes()
    vehicle_class = np.atleast_1d(vehicle_class)
    return [table.column(c)[vehicle_class] for c in ("length_m", "width_m", "height_m")]


@pytest.fixture
def world(built_map):
    with PhysicsWorld(built_map) as world:
        yield world


def make_manager(bundle, **settings) -> TrafficManager:
    return TrafficManager(TrafficConfig(**settings), {r: bundle.road.heading(r) for r in (1, -1)})


def spawn(world, manager, road, lane, x, speed, vehicle_class=0, y=None, **add):
    """Spawn vehicles (class means for sizes) and hand them to the manager."""
    x, lane, vehicle_class = np.broadcast_arrays(
        np.atleast_1d(np.asarray(x, dtype=float)), lane, vehicle_class
    )
    y = lane_center(lane) if y is None else y
    ids = world.spawn(
        SpawnStates.make(road, x, y, speed, vehicle_class, *class_sizes(vehicle_class))
    )
    manager.add(ids, np.full(x.size, road), lane, world.params_of(ids), **add)
    return ids


@dataclass
class Recording:
    """Per step (steps, n) arrays of a run with a fixed set of vehicles."""

    time: np.ndarray
    x: np.ndarray
    y: np.ndarray
    speed: np.ndarray
    lane: np.ndarray  # the manager's lane (driven to)
    changing: np.ndarray
    accel: np.ndarray  # commanded
    contacts: int  # vehicle-vehicle contacts seen


def run(world, manager, seconds, obstacles=None, each_step=None) -> Recording:
    """Drive the world with the manager for ``seconds``; ``obstacles(t)`` gives the
    ghosts of each step; ``each_step(states)`` is called before each decision."""
    rows = {k: [] for k in ("time", "x", "y", "speed", "lane", "changing", "accel")}
    contacts = 0
    for _ in range(round(seconds / world.dt)):
        states = world.states()
        if each_step is not None:
            each_step(states)
        ghosts = obstacles(world.time) if obstacles is not None else None
        commands = manager.step(states, ghosts)
        world.set_controls(commands.id, accel=commands.accel, steer=commands.steer)
        world.step()
        contacts += len(world.vehicle_contacts())
        for name, value in (
            ("time", world.time),
            ("x", states.x),
            ("y", states.y),
            ("speed", states.speed),
            ("lane", commands.lane),
            ("changing", commands.changing),
            ("accel", commands.accel),
        ):
            rows[name].append(value)
    return Recording(**{k: np.array(v) for k, v in rows.items()}, contacts=contacts)


@dataclass
class PointMasses:
    """Road-frame states of point-mass vehicles on a straight lane, what
    :meth:`TrafficManager.step` reads."""

    id: np.ndarray
    x: np.ndarray
    y: np.ndarray
    lane: np.ndarray
    speed: np.ndarray
    heading: np.ndarray


def point_mass_manager(lane, vehicle_class, heading=0.0, **settings):
    """A manager and the parameters of sedans for point-mass tests on road +1."""
    manager = TrafficManager(TrafficConfig(**settings), {1: heading, -1: heading + np.pi})
    lane = np.atleast_1d(lane)
    vehicle_class = np.broadcast_to(vehicle_class, lane.shape)
    params = VehicleParams.from_classes(
        vehicle_classes(), vehicle_class, *class_sizes(vehicle_class)
    )
    return manager, params


def observation(
    speed, gap=np.inf, leader_speed=np.nan, lane=-2, *, time=0.0, x=0.0, y=0.0, neighbours=None
) -> Observation:
    """What a controller sees: its own ``lane``'s leader ``gap`` [m] ahead at
    ``leader_speed`` [m/s] (none in the other lanes), at ``speed`` [m/s]."""
    lanes = (-1, -2, -3, -4)
    k = lanes.index(lane)
    leader_gap = np.full(4, np.inf)
    leader = np.full(4, np.nan)
    leader_gap[k], leader[k] = gap, leader_speed
    view = LaneView(lanes, leader_gap, leader, np.full(4, np.inf), np.full(4, np.nan))
    return Observation(
        time=time, id=0, road=-1, lane=lane, changing=False, x=x, y=y, speed=speed,
        desired_speed=30.0, default_accel=0.0, lanes=view, neighbours=neighbours,
    )  # fmt: skip
