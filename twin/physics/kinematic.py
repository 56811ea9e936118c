"""The kinematic world: the physics world's vehicles integrated in numpy, without
pybullet, at the control step (0.1 s) or a configured one.

It keeps what the traffic, the controllers and the energy figures read of a vehicle
and drops what only the cameras and the physics-fidelity tests need (suspension,
tyres, wheel spin, body contacts):

* **longitudinal**: a point mass under the vehicle model's own limits and resistances
  (:mod:`twin.physics.vehicle`). The commanded acceleration is tracked as the physics
  world's feedforward tracks it (drive force = effective mass times the command plus
  drag, rolling resistance and grade), within the engine's power, the driven wheels'
  grip and the brakes' grip (``mu g``); raw drive and brake fractions act as they do
  there. A vehicle never rolls backwards: a braking or grade-held vehicle stops and
  stays at rest. The drive power is the drive force times the speed.
* **lateral**: a kinematic bicycle about the centre of mass (Rajamani, *Vehicle
  Dynamics and Control*, 2012, section 2.2) steered by the front-wheel angle the
  traffic manager commands, so a lane change follows the path its Stanley
  controller steers; the steer is held over the step and the heading is taken at
  the step's middle.
* **the map**: height and pitch from the road profile at each vehicle's centre
  (``mapgen``), so the grade acts on the point mass and reaches the fuel model.
* **collisions**: two vehicles collide when their footprints (the body boxes of the
  physics world, seen from above) overlap, by the separating-axis test.

The state lives in the road frame (x, y, yaw against the lane, speed); world poses are
made from it when the states are read.
"""

import itertools

import numpy as np

from mapgen.build import MapBundle
from twin.core.ramps import body_lanes
from twin.core.vehicle_classes import vehicle_classes
from twin.physics import kernels
from twin.physics.states import (
    ActiveVehicles,
    SpawnStates,
    VehicleStates,
    quaternion_of,
    write_controls,
)
from twin.physics.vehicle import GRAVITY, VehicleParams

MAX_DT = 0.1  # [s] the longest step (the control step)
_FIELDS = ("accel", "drive", "brake", "steer")
ROADS = (-1, 1)  # the kernels' episode of each carriageway


class KinematicWorld(ActiveVehicles):
    """Vehicles as point masses on kinematic bicycles along the map's road (see the
    module doc). Same interface as :class:`twin.physics.world.PhysicsWorld`
    (:class:`twin.physics.worlds.World`).

    The motion and the footprints are the batched core's kernels
    (:mod:`twin.physics.kernels`), one episode per carriageway: this class keeps the
    vehicles as their arrays, sorted by id, and checks what it is given.

    Args:
        bundle: the map.
        dt: [s] the step, in (0, 0.1].

    Raises:
        ValueError: ``dt`` out of range.
    """

    def __init__(self, bundle: MapBundle, dt: float = MAX_DT):
        if not 0.0 < dt <= MAX_DT:
            raise ValueError(f"the kinematic world's dt must be in (0, {MAX_DT}] s, got {dt}")
        self.dt = float(dt)
        self.road = bundle.road
        self.classes = vehicle_classes()
        self.time = 0.0
        self._next_id = itertools.count()
        self._ids = np.empty(0, dtype=np.int64)
        self._params = VehicleParams.from_classes(self.classes, [], [], [], [])
        self._road = np.empty(0, dtype=np.int8)
        self._bodies = kernels.bodies(len(ROADS), 0)
        self._controls = {k: np.empty((len(ROADS), 0)) for k in _FIELDS}
        self._profiles = {r: kernels.profile(self.road, r) for r in ROADS}
        self._headings = {r: self.road.heading(r) for r in ROADS}
        self._states: VehicleStates | None = None

    # -- spawn and despawn ------------------------------------------------------------

    def spawn(self, states: SpawnStates) -> np.ndarray:
        """Place vehicles at their road-frame pose, along their lane, at their speed.

        Returns:
            (n,) the new vehicles' twin ids.

        Raises:
            ValueError: a state lies beyond the map.
        """
        n = len(states)
        if n == 0:
            return np.empty(0, dtype=np.int64)
        params = VehicleParams.from_classes(
            self.classes, states.vehicle_class, states.length, states.width, states.height
        )
        centre = states.x + 0.5 * states.length
        self.road.to_world(states.road, centre, states.y)  # raises beyond the map
        ids = np.fromiter(itertools.islice(self._next_id, n), dtype=np.int64, count=n)
        columns = kernels.body_columns(params)
        values = {
            "valid": np.zeros(n, bool), "id": ids, "x": states.x.astype(float),
            "y": states.y.astype(float), "yaw": np.zeros(n), "speed": states.speed.astype(float),
            "yaw_rate": np.zeros(n), "z": np.zeros(n), "grade": np.zeros(n),
            "lane": np.zeros(n, np.int64), "drive_power": np.zeros(n), **columns,
        }  # fmt: skip
        old = self._bodies
        self._bodies = kernels.Bodies(
            **{
                name: old.top
                if name == "top"
                else np.concatenate(
                    [
                        getattr(old, name),
                        np.broadcast_to(values[name], (len(ROADS), n)).astype(
                            getattr(old, name).dtype
                        ),
                    ],
                    axis=1,
                )
                for name in kernels.Bodies._fields
            }
        )
        for name in _FIELDS:
            self._controls[name] = np.concatenate(
                [self._controls[name], np.zeros((len(ROADS), n))], 1
            )
        self._ids = np.concatenate([self._ids, ids])
        self._params = VehicleParams.concatenate([self._params, params])
        self._road = np.concatenate([self._road, states.road.astype(np.int8)])
        self._place()
        return ids

    def despawn(self, ids) -> None:
        """Remove the vehicles.

        Raises:
            KeyError: an id is not an active vehicle.
        """
        keep = np.ones(self._ids.size, dtype=bool)
        keep[self._index(ids)] = False
        self._ids = self._ids[keep]
        self._params = self._params.take(np.flatnonzero(keep))
        self._road = self._road[keep]
        b = self._bodies
        self._bodies = kernels.Bodies(
            **{name: b.top if name == "top" else getattr(b, name)[:, keep] for name in b._fields}
        )
        for name in _FIELDS:
            self._controls[name] = self._controls[name][:, keep]
        self._place()

    def _place(self) -> None:
        """Each vehicle valid in its road's row; the map under it; the order of the
        footprints' search anew."""
        b, n = self._bodies, self._ids.size
        b.valid[:] = False
        b.valid[(self._road > 0).astype(np.int64), np.arange(n)] = True
        b.top[:] = n
        for row, road in enumerate(ROADS):
            for i in np.flatnonzero(b.valid[row]):
                kernels.place(row, int(i), b, self._profiles[road])
        self._order = np.full((len(ROADS), n), -1, np.int64)
        self._listed = np.zeros((len(ROADS), n), bool)
        self._states = None

    # -- controls ---------------------------------------------------------------------

    def set_controls(self, ids=None, *, accel=None, steer=None, drive=None, brake=None) -> None:
        """Set inputs of vehicles ``ids`` (default: all active ones); unset ones stay.

        As :meth:`twin.physics.world.PhysicsWorld.set_controls`: ``accel`` [m/s^2]
        selects acceleration tracking, ``drive``/``brake`` (0..1) raw control, ``steer``
        [rad] the front wheels' angle.

        Raises:
            KeyError: an id is not active. ValueError: a value is out of range.
        """
        index = slice(None) if ids is None else self._index(ids)
        flat = {name: self._controls[name][0].copy() for name in _FIELDS}
        write_controls(flat, index, accel=accel, steer=steer, drive=drive, brake=brake)
        for name in _FIELDS:
            self._controls[name][:] = flat[name]

    # -- stepping ---------------------------------------------------------------------

    def step(self) -> None:
        """Advance the world by dt: the point masses along, the bicycles across."""
        c = self._controls
        for row, road in enumerate(ROADS):
            if self._bodies.valid[row].any():
                kernels.integrate(row, self._bodies, c["accel"], c["steer"], c["drive"],
                                  c["brake"], self._profiles[road], self.dt)  # fmt: skip
        self.time += self.dt
        self._states = None

    def states(self) -> VehicleStates:
        """The active vehicles now (after the last step). Built once per change of the
        world and shared by the callers until the next: treat it as read-only."""
        if self._states is not None:
            return self._states
        b, p = self._bodies, self._params
        n = self._ids.size
        rows, cols = (self._road > 0).astype(np.int64), np.arange(n)

        def get(name):
            return getattr(b, name)[rows, cols]

        pitch = np.arctan(get("grade"))
        heading = np.where(self._road > 0, self._headings[1], self._headings[-1]) + get("yaw")
        cos_p = np.cos(pitch)
        forward = np.stack(
            [cos_p * np.cos(heading), cos_p * np.sin(heading), np.sin(pitch)], axis=1
        )
        centre = get("x") + 0.5 * p.length
        ground = np.empty((n, 3))
        if n:
            ground, _, _ = self.road.to_world(self._road, centre, get("y"))
        position = ground.copy()
        position[:, 2] = get("z")
        speed = get("speed")
        load = (p.mass * GRAVITY * cos_p / 4.0)[:, None].repeat(4, axis=1)
        self._states = VehicleStates(
            id=self._ids.copy(),
            position=position,
            orientation=quaternion_of(heading, pitch),
            velocity=forward * speed[:, None],
            angular_velocity=np.stack([np.zeros(n), np.zeros(n), get("yaw_rate")], axis=1),
            speed=speed.copy(),
            yaw_rate=get("yaw_rate").copy(),
            heading=heading,
            road=self._road.copy(),
            x=get("x").copy(),
            y=get("y").copy(),
            lane=body_lanes(self._road, centre, get("y"), self.road.ramps),
            wheel_spin=(speed / p.wheel_radius)[:, None].repeat(4, axis=1),
            load=load,
            contact=np.ones((n, 4), dtype=bool),
            drive_power=get("drive_power").copy(),
        )
        return self._states

    def pitch(self) -> np.ndarray:
        """(n,) [rad] nose-up pitch of the road under each vehicle's centre now, along
        its travel (from the map's profile), in the order of ``states()``."""
        rows = (self._road > 0).astype(np.int64)
        return np.arctan(self._bodies.grade[rows, np.arange(self._ids.size)])

    def vehicle_contacts(self) -> np.ndarray:
        """(m, 2) twin ids of the pairs of vehicles whose footprints overlap now, each
        pair once, smaller id first (ids are sorted, so rows are too)."""
        found = []
        pairs = np.zeros((len(ROADS), max(4 * self._ids.size, 1), 2), np.int64)
        for row in range(len(ROADS)):
            if not self._bodies.valid[row].any():
                continue
            k = kernels.overlaps(row, self._bodies, self._order, self._listed, pairs)
            found.append(pairs[row, :k])
        if not found:
            return np.empty((0, 2), dtype=np.int64)
        slots = np.concatenate(found)
        out = np.sort(self._ids[slots], axis=1)
        return out[np.lexsort((out[:, 1], out[:, 0]))]
