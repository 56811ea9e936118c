"""The physics world: one pybullet client, the map, and a pool of vehicle bodies.

This is the only module that creates or moves pybullet bodies. The rest of the twin
names vehicles by the twin's own ids (int64, never reused); bodies are created once
per size and recycled (``docs/physics.md``, what is known about pybullet: removing and
re-creating bodies leaks memory, and a removed body's id is handed to the next new
body).

Collision groups: rays see only the road; vehicle bodies collide with each other and
with the barrier and overpass, never with the road (the wheels' rays carry them).
"""

import itertools
from dataclasses import dataclass

import numpy as np

from mapgen.build import MapBundle
from twin.core.ramps import body_lanes
from twin.core.vehicle_classes import vehicle_classes
from twin.physics.bullet import pybullet as p
from twin.physics.map_bodies import load_map_bodies
from twin.physics.states import (
    ActiveVehicles,
    SpawnStates,
    VehicleStates,
    quaternion_of,
    rotation_matrices,
    write_controls,
)
from twin.physics.vehicle import Controls, VehicleParams, ray_ends, vehicle_forces

_chain = itertools.chain.from_iterable
RAY_GROUP = 1  # pybullet's default group of a ray
ROAD_GROUP = 2
VEHICLE_GROUP = 4
OBSTACLE_GROUP = 8
SIZE_STEP = 0.05  # [m] body sizes are rounded to this for the pool's shapes
PARK_DEPTH = -1000.0  # [m] where idle bodies wait, frozen


@dataclass(frozen=True)
class PhysicsConfig:
    """Settings of the physics world.

    Attributes:
        dt: [s] fixed step.
        ray_threads: threads for the wheels' ray batch (0: Bullet decides). One by
            default: Bullet's threads cost more than they save for a window's few
            hundred rays (measured in the env: 0.75 ms a batch with 0, 0.23 ms with 1,
            the hits the same).
        solver_iterations: contact solver iterations (vehicle-vehicle and barrier hits).
    """

    dt: float = 0.01
    ray_threads: int = 1
    solver_iterations: int = 10

    def __post_init__(self):
        if not 0.0 < self.dt <= 0.02:
            raise ValueError(f"dt must be in (0, 0.02] s, got {self.dt}")
        if self.ray_threads < 0 or self.solver_iterations < 1:
            raise ValueError("ray_threads must be >= 0 and solver_iterations >= 1")


class PhysicsWorld(ActiveVehicles):
    """A pybullet world (DIRECT) with the map's road and a pool of vehicle bodies.

    Raises:
        RuntimeError: pybullet cannot connect or cannot load the map.
    """

    def __init__(self, bundle: MapBundle, config: PhysicsConfig = PhysicsConfig()):
        self.config = config
        self.road = bundle.road
        self.classes = vehicle_classes()
        self.client = p.connect(p.DIRECT)
        if self.client < 0:
            raise RuntimeError("pybullet could not start a physics client")
        p.setTimeStep(config.dt, physicsClientId=self.client)
        p.setGravity(0.0, 0.0, -9.81, physicsClientId=self.client)
        p.setPhysicsEngineParameter(
            numSolverIterations=config.solver_iterations,
            deterministicOverlappingPairs=1,
            physicsClientId=self.client,
        )
        self.map_bodies = load_map_bodies(self.client, bundle, visual=False)
        self._group(self.map_bodies.collision["road"], ROAD_GROUP, RAY_GROUP)
        self._group(self.map_bodies.collision["obstacles"], OBSTACLE_GROUP, VEHICLE_GROUP)
        self.time = 0.0
        self._next_id = itertools.count()
        self._shapes: dict[tuple, int] = {}
        self._free: dict[tuple, list[int]] = {}
        self._ids = np.empty(0, dtype=np.int64)
        self._bodies = np.empty(0, dtype=np.int64)
        self._keys: list[tuple] = []
        self._params = VehicleParams.from_classes(self.classes, [], [], [], [])
        self._controls = {k: np.empty(0) for k in ("accel", "drive", "brake", "steer")}
        self._spin = np.empty((0, 4))
        self._impulse = np.empty((0, 3))
        self._read = None  # (position, quaternion, velocity, angular velocity) of now
        self._states: VehicleStates | None = None  # states() of now, while _read holds
        self._load = np.empty((0, 4))  # [N] per wheel, from the last step
        self._contact = np.empty((0, 4), dtype=bool)
        self._drive_power = np.empty(0)  # [W] per vehicle, from the last step

    # -- lifecycle --------------------------------------------------------------------

    def close(self) -> None:
        if self.client is not None:
            p.disconnect(self.client)
            self.client = None

    @property
    def dt(self) -> float:
        """[s] the fixed step."""
        return self.config.dt

    def vehicle_contacts(self) -> np.ndarray:
        """(m, 2) twin ids of the pairs of vehicles whose bodies touch now (after the
        last step), each pair once, smaller id first."""
        body_to_id = dict(zip(self._bodies.tolist(), self._ids.tolist(), strict=True))
        pairs = set()
        for contact in p.getContactPoints(physicsClientId=self.client):
            a, b = body_to_id.get(contact[1]), body_to_id.get(contact[2])
            if a is not None and b is not None:
                pairs.add((min(a, b), max(a, b)))
        return np.array(sorted(pairs), dtype=np.int64).reshape(-1, 2)

    @property
    def body_count(self) -> int:
        """Bodies ever created for vehicles (the pool's size)."""
        return sum(len(v) for v in self._free.values()) + len(self._bodies)

    # -- spawn and despawn ------------------------------------------------------------

    def spawn(self, states: SpawnStates) -> np.ndarray:
        """Place vehicles on the road at their road-frame pose, at rest on their
        suspension, and give each its speed along the lane by an impulse applied in the
        next step (J = m v along the heading; wheels spun up to v / r).

        Returns:
            (n,) the new vehicles' twin ids.

        Raises:
            ValueError: a state is invalid or lies beyond the map.
        """
        n = len(states)
        if n == 0:
            return np.empty(0, dtype=np.int64)
        params = VehicleParams.from_classes(
            self.classes, states.vehicle_class, states.length, states.width, states.height
        )
        center_x = states.x + 0.5 * states.length
        ground, heading, pitch = self.road.to_world(states.road, center_x, states.y)
        normal = np.stack(
            [
                -np.sin(pitch) * np.cos(heading),
                -np.sin(pitch) * np.sin(heading),
                np.cos(pitch),
            ],
            axis=1,
        )
        position = ground + normal * params.cg_height[:, None]
        quaternion = quaternion_of(heading, pitch)
        direction = np.stack(
            [np.cos(pitch) * np.cos(heading), np.cos(pitch) * np.sin(heading), np.sin(pitch)],
            axis=1,
        )
        ids = np.fromiter(itertools.islice(self._next_id, n), dtype=np.int64, count=n)
        bodies, keys = [], []
        for i in range(n):
            key = _size_key(params.box_half[i], params.box_center[i])
            body = self._acquire(key)
            p.changeDynamics(
                body,
                -1,
                mass=float(params.mass[i]),
                localInertiaDiagonal=params.inertia[i].tolist(),
                physicsClientId=self.client,
            )
            p.resetBasePositionAndOrientation(
                body, position[i].tolist(), quaternion[i].tolist(), physicsClientId=self.client
            )
            p.resetBaseVelocity(body, [0, 0, 0], [0, 0, 0], physicsClientId=self.client)
            bodies.append(body)
            keys.append(key)
        self._ids = np.concatenate([self._ids, ids])
        self._bodies = np.concatenate([self._bodies, np.asarray(bodies, dtype=np.int64)])
        self._keys += keys
        self._params = VehicleParams.concatenate([self._params, params])
        for name, default in (("accel", 0.0), ("drive", 0.0), ("brake", 0.0), ("steer", 0.0)):
            self._controls[name] = np.concatenate([self._controls[name], np.full(n, default)])
        self._load = np.concatenate([self._load, np.zeros((n, 4))])  # until the first step
        self._contact = np.concatenate([self._contact, np.zeros((n, 4), dtype=bool)])
        self._drive_power = np.concatenate([self._drive_power, np.zeros(n)])
        self._spin = np.concatenate(
            [self._spin, (states.speed / params.wheel_radius)[:, None].repeat(4, 1)]
        )
        self._impulse = np.concatenate([self._impulse, direction * states.speed[:, None]])
        self._read = self._states = None
        return ids

    def clear(self) -> None:
        """Remove every vehicle and start the ids and the clock from 0 again: a new
        episode in the same world (the bodies stay pooled for its spawns)."""
        if self._ids.size:
            self.despawn(self._ids.copy())
        self._next_id = itertools.count()
        self.time = 0.0

    def despawn(self, ids: np.ndarray) -> None:
        """Return the vehicles' bodies to the pool.

        Raises:
            KeyError: an id is not an active vehicle.
        """
        remove = self._index(ids)
        keep = np.ones(self._ids.size, dtype=bool)
        keep[remove] = False
        for i in remove:
            self._release(int(self._bodies[i]), self._keys[i])
        self._ids = self._ids[keep]
        self._bodies = self._bodies[keep]
        self._keys = [k for k, kept in zip(self._keys, keep, strict=True) if kept]
        self._params = self._params.take(np.flatnonzero(keep))
        for name in self._controls:
            self._controls[name] = self._controls[name][keep]
        self._spin = self._spin[keep]
        self._load = self._load[keep]
        self._contact = self._contact[keep]
        self._drive_power = self._drive_power[keep]
        self._impulse = self._impulse[keep]
        self._read = self._states = None

    # -- controls ---------------------------------------------------------------------

    def set_controls(self, ids=None, *, accel=None, steer=None, drive=None, brake=None) -> None:
        """Set inputs of vehicles ``ids`` (default: all active ones); unset ones stay.

        ``accel`` [m/s^2] selects acceleration tracking; ``drive``/``brake`` (0..1)
        select raw control (``accel`` is then cleared for those vehicles). ``steer``
        [rad] is the front wheels' angle.

        Raises:
            KeyError: an id is not active. ValueError: a value is out of range.
        """
        index = slice(None) if ids is None else self._index(ids)
        write_controls(self._controls, index, accel=accel, steer=steer, drive=drive, brake=brake)

    # -- stepping ---------------------------------------------------------------------

    def step(self) -> None:
        """Advance the world by dt: wheel rays, vehicle forces, one engine step."""
        dt = self.config.dt
        if self._ids.size:
            position, _, velocity, angular, rotation = self._state()
            start, end = ray_ends(self._params, position, rotation)
            # numpy arrays go in faster than lists (measured: 0.28 against 0.37 ms)
            hits = p.rayTestBatch(
                start.reshape(-1, 3),
                end.reshape(-1, 3),
                numThreads=self.config.ray_threads,
                collisionFilterMask=ROAD_GROUP,
                physicsClientId=self.client,
            )
            rays = len(hits)
            fraction = np.fromiter((h[2] for h in hits), np.float64, rays).reshape(-1, 4)
            point = np.fromiter(_chain(h[4] for h in hits), np.float64, 3 * rays)
            forces = vehicle_forces(
                self._params,
                Controls(**self._controls),
                position,
                rotation,
                velocity + self._impulse,
                angular,
                self._spin,
                fraction,
                point.reshape(-1, 4, 3),
                dt,
            )
            force = forces.force + self._params.mass[:, None] * self._impulse / dt
            # positional arguments: pybullet parses keywords noticeably slower
            client, world_frame = self.client, p.WORLD_FRAME
            apply_force, apply_torque = p.applyExternalForce, p.applyExternalTorque
            for body, f, t, at in zip(
                self._bodies.tolist(),
                force.tolist(),
                forces.torque.tolist(),
                position.tolist(),
                strict=True,
            ):
                apply_force(body, -1, f, at, world_frame, client)
                apply_torque(body, -1, t, world_frame, client)
            self._spin = forces.wheel_spin
            self._impulse = np.zeros_like(self._impulse)
            self._load, self._contact = forces.load, forces.contact
            self._drive_power = forces.drive_power
        p.stepSimulation(physicsClientId=self.client)
        self.time += dt
        self._read = self._states = None

    def states(self) -> VehicleStates:
        """The active vehicles now (after the last step). A vehicle spawned since then
        is reported at its spawn speed: its impulse is applied in the next step.

        Built once per change of the world (step, spawn, despawn) and shared by the
        callers until the next: treat it as read-only."""
        if self._read is not None and self._states is not None:
            return self._states
        position, quaternion, velocity, angular, rotation = self._state()
        velocity = velocity + self._impulse
        coords = self.road.to_road(position)
        self._states = VehicleStates(
            id=self._ids.copy(),
            position=position,
            orientation=quaternion,
            velocity=velocity,
            angular_velocity=angular,
            speed=np.einsum("nj,nj->n", velocity, rotation[:, :, 0]),
            yaw_rate=angular[:, 2],
            heading=np.arctan2(rotation[:, 1, 0], rotation[:, 0, 0]),
            road=coords.road,
            x=coords.x - 0.5 * self._params.length,
            y=coords.y,
            # by its band, as the kinematic world does: a body on an acceleration lane's
            # taper, narrower than the band, is still on lane -5 (not off the road)
            lane=body_lanes(coords.road, coords.x, coords.y, self.road.ramps),
            wheel_spin=self._spin.copy(),
            load=self._load.copy(),
            contact=self._contact.copy(),
            drive_power=self._drive_power.copy(),
        )
        return self._states

    # -- internals --------------------------------------------------------------------

    def _state(self):
        """(position, quaternion, velocity, angular velocity, rotation) of the active
        vehicles now, read once per step."""
        if self._read is None:
            client, bodies = self.client, self._bodies.tolist()
            get_pose, get_twist = p.getBasePositionAndOrientation, p.getBaseVelocity
            poses = [get_pose(b, client) for b in bodies]
            twists = [get_twist(b, client) for b in bodies]
            n = len(bodies)
            # flattened by fromiter: half the time of building tuples for np.array
            pose = np.fromiter(_chain(_chain(poses)), np.float64, 7 * n).reshape(n, 7)
            twist = np.fromiter(_chain(_chain(twists)), np.float64, 6 * n).reshape(n, 6)
            quaternion = pose[:, 3:]
            self._read = (
                pose[:, :3],
                quaternion,
                twist[:, :3],
                twist[:, 3:],
                rotation_matrices(quaternion),
            )
        return self._read

    def _group(self, body: int, group: int, mask: int) -> None:
        p.setCollisionFilterGroupMask(body, -1, group, mask, physicsClientId=self.client)

    def _acquire(self, key: tuple) -> int:
        free = self._free.setdefault(key, [])
        if free:
            body = free.pop()
        else:
            if key not in self._shapes:
                half = [key[0] * SIZE_STEP, key[1] * SIZE_STEP, key[2] * SIZE_STEP]
                self._shapes[key] = p.createCollisionShape(
                    p.GEOM_BOX, halfExtents=half, physicsClientId=self.client
                )
            body = p.createMultiBody(
                baseMass=1.0,
                baseCollisionShapeIndex=self._shapes[key],
                baseVisualShapeIndex=-1,
                baseInertialFramePosition=[0.0, 0.0, -key[3] * SIZE_STEP],
                useMaximalCoordinates=False,
                physicsClientId=self.client,
            )
            p.changeDynamics(
                body, -1, linearDamping=0.0, angularDamping=0.0, physicsClientId=self.client
            )
            # drawn by twin.physics.render's models; the box itself is never seen
            p.changeVisualShape(body, -1, rgbaColor=[1, 1, 1, 0], physicsClientId=self.client)
        self._group(body, VEHICLE_GROUP, VEHICLE_GROUP | OBSTACLE_GROUP)
        return body

    def _release(self, body: int, key: tuple) -> None:
        p.changeDynamics(body, -1, mass=0.0, physicsClientId=self.client)
        self._group(body, 0, 0)
        p.resetBasePositionAndOrientation(
            body, [10.0 * body, 0.0, PARK_DEPTH], [0, 0, 0, 1], physicsClientId=self.client
        )
        p.resetBaseVelocity(body, [0, 0, 0], [0, 0, 0], physicsClientId=self.client)
        self._free[key].append(body)


def _size_key(half: np.ndarray, center: np.ndarray) -> tuple:
    """Pool key: box half extents and the box centre's height in the body frame, in
    SIZE_STEP units (bodies of one key share a collision shape)."""
    return (*(max(1, round(v / SIZE_STEP)) for v in half), round(center[2] / SIZE_STEP))
