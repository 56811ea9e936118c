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
from twin.core.i24 import SEGMENT_LENGTH, lane_of
from twin.core.vehicle_classes import vehicle_classes
from twin.physics.states import (
    ActiveVehicles,
    SpawnStates,
    VehicleStates,
    quaternion_of,
    write_controls,
)
from twin.physics.vehicle import (
    GRAVITY,
    POWER_SPEED_MIN,
    VehicleParams,
    full_brake_torque,
    resistance,
)

MAX_DT = 0.1  # [s] the longest step (the control step)
_FIELDS = ("accel", "drive", "brake", "steer")


class KinematicWorld(ActiveVehicles):
    """Vehicles as point masses on kinematic bicycles along the map's road (see the
    module doc). Same interface as :class:`twin.physics.world.PhysicsWorld`
    (:class:`twin.physics.worlds.World`).

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
        self._x = np.empty(0)  # [m] centre along travel
        self._y = np.empty(0)  # [m] centre from the median, positive right of travel
        self._yaw = np.empty(0)  # [rad] against the direction of travel, positive left
        self._speed = np.empty(0)  # [m/s] >= 0
        self._yaw_rate = np.empty(0)  # [rad/s] over the last step
        self._drive_power = np.empty(0)  # [W] over the last step
        self._controls = {k: np.empty(0) for k in _FIELDS}
        self._states: VehicleStates | None = None
        self._headings = {r: self.road.heading(r) for r in (1, -1)}
        self._profile = (self.road.profile_s, self.road.profile_z)
        self._slopes = np.diff(self.road.profile_z) / np.diff(self.road.profile_s)
        self._pairs: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # n -> its triu indices
        self._under: tuple[np.ndarray, np.ndarray] | None = None  # _ground() of now

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
        self._ids = np.concatenate([self._ids, ids])
        self._params = VehicleParams.concatenate([self._params, params])
        self._road = np.concatenate([self._road, states.road.astype(np.int8)])
        self._x = np.concatenate([self._x, centre])
        self._y = np.concatenate([self._y, states.y])
        self._yaw = np.concatenate([self._yaw, np.zeros(n)])
        self._speed = np.concatenate([self._speed, states.speed])
        self._yaw_rate = np.concatenate([self._yaw_rate, np.zeros(n)])
        self._drive_power = np.concatenate([self._drive_power, np.zeros(n)])
        for name in _FIELDS:
            self._controls[name] = np.concatenate([self._controls[name], np.zeros(n)])
        self._states = self._under = None
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
        for name in ("_road", "_x", "_y", "_yaw", "_speed", "_yaw_rate", "_drive_power"):
            setattr(self, name, getattr(self, name)[keep])
        for name in _FIELDS:
            self._controls[name] = self._controls[name][keep]
        self._states = self._under = None

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
        write_controls(self._controls, index, accel=accel, steer=steer, drive=drive, brake=brake)

    # -- stepping ---------------------------------------------------------------------

    def step(self) -> None:
        """Advance the world by dt: the point masses along, the bicycles across."""
        dt = self.dt
        if self._ids.size:
            v0 = self._speed
            accel, self._drive_power = self._longitudinal(v0)
            v1 = np.maximum(v0 + accel * dt, 0.0)
            # a vehicle that stops inside the step travels to its stop and stays
            moving = np.where(v1 > 0.0, dt, np.minimum(dt, v0 / np.maximum(-accel, 1e-9)))
            distance = np.maximum(v0 * moving + 0.5 * accel * moving**2, 0.0)
            self._lateral(distance, dt)
            self._speed = v1
        self.time += dt
        self._states = self._under = None

    def states(self) -> VehicleStates:
        """The active vehicles now (after the last step). Built once per change of the
        world and shared by the callers until the next: treat it as read-only."""
        if self._states is not None:
            return self._states
        p = self._params
        ground, pitch = self._ground()
        heading = np.where(self._road > 0, self._headings[1], self._headings[-1]) + self._yaw
        cos_p = np.cos(pitch)
        forward = np.stack(
            [cos_p * np.cos(heading), cos_p * np.sin(heading), np.sin(pitch)], axis=1
        )
        normal = np.stack(
            [-np.sin(pitch) * np.cos(heading), -np.sin(pitch) * np.sin(heading), cos_p], axis=1
        )
        n = self._ids.size
        load = (p.mass * GRAVITY * cos_p / 4.0)[:, None].repeat(4, axis=1)
        self._states = VehicleStates(
            id=self._ids.copy(),
            position=ground + normal * p.cg_height[:, None],
            orientation=quaternion_of(heading, pitch),
            velocity=forward * self._speed[:, None],
            angular_velocity=np.stack([np.zeros(n), np.zeros(n), self._yaw_rate], axis=1),
            speed=self._speed.copy(),
            yaw_rate=self._yaw_rate.copy(),
            heading=heading,
            road=self._road.copy(),
            x=self._x - 0.5 * p.length,
            y=self._y.copy(),
            lane=lane_of(self._y),
            wheel_spin=(self._speed / p.wheel_radius)[:, None].repeat(4, axis=1),
            load=load,
            contact=np.ones((n, 4), dtype=bool),
            drive_power=self._drive_power.copy(),
        )
        return self._states

    def vehicle_contacts(self) -> np.ndarray:
        """(m, 2) twin ids of the pairs of vehicles whose footprints overlap now, each
        pair once, smaller id first (ids are sorted, so rows are too)."""
        n = self._ids.size
        if n not in self._pairs:
            self._pairs = {n: np.triu_indices(n, 1)}  # the last count's (it changes little)
        pairs = footprint_overlaps(
            self._road, self._x, self._y, self._yaw, self._params, self._pairs[n]
        )
        return self._ids[pairs]

    # -- internals --------------------------------------------------------------------

    def _longitudinal(self, speed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(acceleration [m/s^2], drive power [W]) of each vehicle over the step."""
        p, c = self._params, self._controls
        _, pitch = self._ground()
        sin_p, cos_p = np.sin(pitch), np.cos(pitch)
        resist = resistance(p, speed, sin_p)
        raw = np.isnan(c["accel"])
        wanted = p.effective_mass * np.nan_to_num(c["accel"]) + resist
        power_limit = p.max_power / np.maximum(speed, POWER_SPEED_MIN)
        weight = p.mass * GRAVITY * cos_p
        grip = p.mu * weight  # all four wheels: the brakes' limit
        driven_grip = grip * p.driven.sum(axis=1) / 4.0
        drive = np.where(raw, c["drive"] * power_limit, np.clip(wanted, 0.0, power_limit))
        drive = np.minimum(drive, driven_grip)
        full_brake = 4.0 * full_brake_torque(p) / p.wheel_radius
        brake = np.where(raw, c["brake"] * full_brake, np.maximum(-wanted, 0.0))
        brake = np.minimum(brake, grip)
        accel = (drive - brake - resist) / p.effective_mass
        # held at rest: the brakes (or a command to stay) keep a standing vehicle there
        held = (speed <= 0.0) & np.where(
            raw, (c["brake"] > 0) & (c["drive"] == 0), np.nan_to_num(c["accel"]) <= 0
        )
        accel = np.where(held, 0.0, accel)
        return accel, drive * speed

    def _lateral(self, distance: np.ndarray, dt: float) -> None:
        """Move each vehicle ``distance`` [m] along its bicycle's path over the step."""
        steer = self._controls["steer"]
        wheelbase = self._params.mounts[:, 0, 0] - self._params.mounts[:, 2, 0]
        # the centre of mass sits midway between the axles: slip angle and turn rate
        tan = np.tan(steer)
        slip = np.arctan(0.5 * tan)
        turn = distance * np.cos(slip) * tan / wheelbase  # [rad] over the step
        middle = self._yaw + 0.5 * turn + slip
        self._x = self._x + distance * np.cos(middle)
        self._y = self._y - distance * np.sin(middle)  # y grows to the right of travel
        self._yaw = self._yaw + turn
        self._yaw_rate = turn / dt

    def _ground(self) -> tuple[np.ndarray, np.ndarray]:
        """(n, 3) [m] the pavement under each vehicle's centre and (n,) [rad] its pitch
        along travel (the grade of the profile piece it drives onto, as
        :meth:`mapgen.road.RoadModel.to_world`; the map's ends extend flat beyond
        them). Computed once per change of the world."""
        if self._under is not None:
            return self._under
        stations, heights = self._profile
        eastbound = self._road > 0
        s = np.where(eastbound, self._x, SEGMENT_LENGTH - self._x)
        lateral = np.where(eastbound, self._y, -self._y)
        ground = np.empty((s.size, 3))
        ground[:, :2] = s[:, None] * self.road.direction_vector + lateral[:, None] * (
            self.road.right_vector
        )
        ground[:, 2] = np.interp(s, stations, heights)
        # eastbound drives onto the piece after a profile point, westbound the one before
        piece = np.where(
            eastbound,
            np.searchsorted(stations, s, side="right"),
            np.searchsorted(stations, s, side="left"),
        )
        slope = self._slopes[np.clip(piece - 1, 0, self._slopes.size - 1)]
        inside = (s >= stations[0]) & (s <= stations[-1])
        pitch = np.where(inside, np.arctan(np.where(eastbound, slope, -slope)), 0.0)
        self._under = (ground, pitch)
        return self._under


def footprint_overlaps(road, x, y, yaw, params: VehicleParams, pairs=None) -> np.ndarray:
    """(m, 2) index pairs (i < j) of the vehicles whose footprints overlap: rectangles
    of the body boxes' length and width centred at road-frame (x, y) [m], turned by
    ``yaw`` [rad] against travel, on the same road. A bounding-box test picks the
    candidates, the separating-axis test over the four edge directions decides.
    ``pairs``: ``np.triu_indices(n, 1)``, if the caller keeps it."""
    n = x.size
    if n < 2:
        return np.empty((0, 2), dtype=np.int64)
    half_l, half_w = params.box_half[:, 0], params.box_half[:, 1]
    cos, sin = np.cos(yaw), np.sin(yaw)
    reach_x = half_l * np.abs(cos) + half_w * np.abs(sin)
    reach_y = half_l * np.abs(sin) + half_w * np.abs(cos)
    i, j = np.triu_indices(n, 1) if pairs is None else pairs
    near = (
        (road[i] == road[j])
        & (np.abs(x[i] - x[j]) <= reach_x[i] + reach_x[j])
        & (np.abs(y[i] - y[j]) <= reach_y[i] + reach_y[j])
    )
    i, j = i[near], j[near]
    if i.size == 0:
        return np.empty((0, 2), dtype=np.int64)
    # each footprint's axes in the road frame (x along travel, y to the right)
    ax = np.stack([cos, -sin], axis=1)  # forward
    ay = np.stack([sin, cos], axis=1)  # right
    d = np.stack([x[j] - x[i], y[j] - y[i]], axis=1)
    apart = np.zeros(i.size, dtype=bool)
    for axis in (ax[i], ay[i], ax[j], ay[j]):
        reach_i = half_l[i] * np.abs((ax[i] * axis).sum(1)) + half_w[i] * np.abs(
            (ay[i] * axis).sum(1)
        )
        reach_j = half_l[j] * np.abs((ax[j] * axis).sum(1)) + half_w[j] * np.abs(
            (ay[j] * axis).sum(1)
        )
        apart |= np.abs((d * axis).sum(1)) > reach_i + reach_j
    keep = ~apart
    return np.stack([i[keep], j[keep]], axis=1)
