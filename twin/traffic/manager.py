"""The traffic manager: drives the twin's physics vehicles the way people drive.

Each step it reads the vehicles' states, finds every vehicle's leader in each lane it
occupies, and decides an acceleration (its car-following model, IDM by default, with
emergency braking on top: :mod:`twin.traffic.longitudinal`) and a lateral path (lane
keeping, or a MOBIL lane change under the HOV rule: :mod:`twin.traffic.lane_change`),
which the Stanley controller turns into a steering angle
(:mod:`twin.traffic.steering`). Any vehicle can be given a user's controller instead
(:mod:`twin.traffic.controller_api`, :mod:`twin.traffic.controlled`).

Lifecycle (the cosimulator's order)::

    manager.add(ids, road, lanes, world.params_of(ids))  # when bodies are spawned
    commands = manager.step(world.states(), ghosts)      # each step
    world.set_controls(commands.id, accel=commands.accel, steer=commands.steer)
    world.step()
    manager.remove(ids)                                  # when bodies are despawned

The manager never touches pybullet; it sees vehicles through the states and the
physical parameters the world gives it.
"""

from dataclasses import replace
from functools import cached_property

import numpy as np

from twin.core.i24 import HOV_LANE, N_LANES, lane_center
from twin.core.vehicle_classes import vehicle_classes
from twin.physics.vehicle import GRAVITY, VehicleParams
from twin.traffic import lane_change, longitudinal, steering, strategic
from twin.traffic.config import TrafficConfig
from twin.traffic.controlled import Controllers
from twin.traffic.controller_api import EgoController, lane_change_direction
from twin.traffic.driver_state import MOBIL_FIELDS, DriverState
from twin.traffic.drivers import DriverTraits
from twin.traffic.models import car_following_model
from twin.traffic.models.base import concatenate
from twin.traffic.scene import NO_OBSTACLES, Commands, Obstacles, Scene


class TrafficManager:
    """Drivers of the configured car-following model and MOBIL with the HOV rule, for
    the vehicles of a physics world.

    Args:
        config: settings; ``config.seed`` seeds every random draw of the manager.
        road_heading: {+1: yaw, -1: yaw} [rad] world yaw of travel on each road
            (``RoadModel.heading``), for the lateral controller.
    """

    def __init__(self, config: TrafficConfig, road_heading: dict[int, float]):
        self.config = config
        self.model = car_following_model(config.car_following)
        self.rng = np.random.default_rng(config.seed)
        self.classes = vehicle_classes()
        self.time = 0.0
        self._steps = 0
        self._decision_every = round(config.decision_period / config.dt)
        self._heading = np.array([road_heading[-1], road_heading[1]], dtype=np.float64)
        self._d = DriverState.empty(self.model.params)
        self._controllers = Controllers()
        self.lane_changes = 0
        self._keep_out: list[tuple[int, int, float, float]] = []  # (road, lane, x0, x1)
        self.emergency_steps = 0

    @property
    def safety_overrides(self) -> int:
        """Controller steps overridden by emergency braking."""
        return self._controllers.safety_overrides

    @property
    def refused_requests(self) -> int:
        """Lane changes controllers asked for that the rules refused."""
        return self._controllers.refused_requests

    @property
    def decision_steps(self) -> int:
        """Steps between two lane-change decision rounds (``decision_period / dt``)."""
        return self._decision_every

    # -- vehicles ---------------------------------------------------------------------

    @property
    def ids(self) -> np.ndarray:
        """(n,) ids of the managed vehicles, increasing."""
        return self._d.id.copy()

    def add(
        self,
        ids: np.ndarray,
        road: np.ndarray,
        lane: np.ndarray,
        params: VehicleParams,
        *,
        hov_eligible: np.ndarray | None = None,
        desired_speed: np.ndarray | float | None = None,
    ) -> None:
        """Take over vehicles just spawned in ``lane`` of ``road`` (each (n,)).

        Args:
            ids: (n,) twin ids, all larger than any managed id (the world's order).
            params: the vehicles' physical parameters (``PhysicsWorld.params_of``).
            hov_eligible: (n,) bool; by default drawn: the vehicles spawned in the HOV
                lane are eligible, others with the configured share where their class
                may use the lane.
            desired_speed: [m/s]; by default drawn from the class table.

        Raises:
            ValueError: ids out of order, lanes off the road, a non-eligible vehicle
                in the HOV lane, or sizes that do not match.
        """
        ids = np.atleast_1d(np.asarray(ids, dtype=np.int64))
        n = ids.size
        if n == 0:
            return
        road = np.broadcast_to(np.asarray(road, dtype=np.int8), (n,)).copy()
        lane = np.broadcast_to(np.asarray(lane, dtype=np.int8), (n,)).copy()
        self._check_new(ids, road, lane, params)
        cfg = self.config
        traits = cfg.drivers.draw(self.classes, params.vehicle_class, self.rng)
        allowed = self.classes.column("hov_allowed")[params.vehicle_class] == 1
        lucky = self.rng.random(n) < cfg.hov_share
        if hov_eligible is None:
            eligible = (lane == HOV_LANE) | (allowed & lucky)
        else:
            eligible = np.broadcast_to(np.asarray(hov_eligible, dtype=bool), (n,)).copy()
            if np.any(~eligible & (lane == HOV_LANE)):
                raise ValueError("a vehicle added in the HOV lane must be HOV-eligible")
        if desired_speed is not None:
            desired = np.broadcast_to(np.asarray(desired_speed, dtype=np.float64), (n,)).copy()
            _check_speed(desired)
            traits = replace(traits, desired_speed=desired)
        new = DriverState(
            id=ids,
            road=road,
            vehicle_class=np.asarray(params.vehicle_class, dtype=np.int64),
            length=params.length.copy(),
            wheelbase=params.mounts[:, 0, 0] - params.mounts[:, 2, 0],
            tyre_decel=params.mu * GRAVITY,
            model=self.model.from_traits(traits),
            **{
                name: np.full(n, float(getattr(cfg.mobil, name)), dtype=np.float64)
                for name in MOBIL_FIELDS
            },
            hov_eligible=eligible,
            auto_lane_change=np.full(n, cfg.auto_lane_change),
            lane=lane,
            lane_from=lane.copy(),
            start_x=np.zeros(n),
            start_y=lane_center(lane),
            path_length=np.ones(n),
            next_decision=self.time + self.rng.uniform(0.0, cfg.decision_interval, n),
            requested=np.zeros(n, dtype=np.int8),
            strategic=np.zeros(n, dtype=np.int8),
            strategic_from=np.full(n, np.nan),
            strategic_by=np.full(n, np.nan),
            accel=np.zeros(n),
        )
        self._d = DriverState.concatenate(self._d, new)

    def _check_new(self, ids, road, lane, params: VehicleParams) -> None:
        if len(params) != ids.size:
            raise ValueError(f"params describe {len(params)} vehicles, ids {ids.size}")
        if np.any(np.diff(ids) <= 0) or (len(self._d) and ids[0] <= self._d.id[-1]):
            raise ValueError("new ids must be increasing and above the managed ones")
        if not np.all(np.isin(road, (-1, 1))):
            raise ValueError("road must be +1 (eastbound) or -1 (westbound)")
        if np.any((lane > -1) | (lane < -N_LANES)):
            raise ValueError(f"lanes must be in -1..-{N_LANES}, got {np.unique(lane).tolist()}")

    def remove(self, ids: np.ndarray) -> None:
        """Forget vehicles (despawned ones).

        Raises:
            KeyError: an id is not managed.
        """
        index = self._index(ids)
        keep = np.ones(len(self._d), dtype=bool)
        keep[index] = False
        self._d = self._d.take(keep)
        for i in np.atleast_1d(ids):
            self._controllers.by_id.pop(int(i), None)

    # -- the API the cosimulator uses -------------------------------------------------

    def set_desired_speed(self, ids, speed) -> None:
        """Set the desired speed [m/s] (>= 0) of vehicles ``ids``."""
        speed = np.asarray(speed, dtype=np.float64)
        _check_speed(speed)
        self._d.desired_speed[self._index(ids)] = speed

    def desired_speed(self, ids) -> np.ndarray:
        """(k,) [m/s] the desired speeds of vehicles ``ids``."""
        return self._d.desired_speed[self._index(ids)].copy()

    def lanes(self, ids) -> np.ndarray:
        """(k,) the lanes vehicles ``ids`` drive in or are changing to."""
        return self._d.lane[self._index(ids)].copy()

    def changing(self, ids) -> np.ndarray:
        """(k,) bool: vehicles ``ids`` are changing lanes now."""
        index = self._index(ids)
        return self._d.lane_from[index] != self._d.lane[index]

    def set_auto_lane_change(self, ids, on) -> None:
        """Switch MOBIL lane changes on or off for vehicles ``ids``."""
        self._d.auto_lane_change[self._index(ids)] = np.asarray(on, dtype=bool)

    def force_lane_change(self, vehicle_id: int, direction: int | str) -> None:
        """Ask vehicle ``vehicle_id`` to change one lane ``'left'`` (+1, toward lane -1)
        or ``'right'`` (-1); 0 or ``'none'`` cancels a pending request.

        The change starts at the first step where it is safe (the MOBIL safety
        criterion), whatever its incentive.

        Raises:
            KeyError: not a managed vehicle.
            ValueError: the direction is unknown, leads off the road, or breaks the
                HOV rule (into the HOV lane for a non-eligible vehicle, or across the
                HOV line where the rule closes it).
        """
        step = lane_change_direction(direction)
        (i,) = self._index([vehicle_id])
        if step:
            self._check_change(i, vehicle_id, step)
        self._d.requested[i] = step

    def _check_change(self, i: int, vehicle_id: int, step: int) -> None:
        """Raise ValueError where vehicle ``i`` (index) may never change one lane
        ``step``: off the road, or against the HOV rule."""
        d = self._d
        target = int(d.lane[i]) + step
        if not -N_LANES <= target <= -1:
            raise ValueError(f"vehicle {vehicle_id} in lane {d.lane[i]}: no lane {target}")
        if target == HOV_LANE and not d.hov_eligible[i]:
            raise ValueError(f"vehicle {vehicle_id} is not HOV-eligible: lane -1 is HOV")
        if HOV_LANE in (target, int(d.lane[i])) and not self.config.hov_openings:
            raise ValueError(
                f"vehicle {vehicle_id}: the HOV line cannot be crossed (no hov_openings)"
            )

    def set_strategic(self, ids, direction, x_from, x_by) -> None:
        """Give vehicles ``ids`` a strategic target (:mod:`twin.traffic.strategic`): change
        one lane ``direction`` (+1 left, toward lane -1; -1 right; 0 clears the
        target), wanted from road-frame ``x_from`` [m] with an urgency that grows to
        ``x_by`` [m] (vehicle centres). Each (k,) or a scalar.

        Raises:
            KeyError: an id is not managed.
            ValueError: a direction other than -1, 0, +1; ``x_by`` not past ``x_from``;
                or a change the vehicle may never make (off the road, or against the
                HOV rule: :meth:`force_lane_change`'s checks).
        """
        index = self._index(ids)
        k = index.size
        asked = np.broadcast_to(np.asarray(direction), (k,))
        if not np.all(np.isin(asked, (-1, 0, 1))):
            raise ValueError(f"strategic directions must be -1, 0 or +1, got {asked!r}")
        direction = asked.astype(np.int64)
        x_from = np.broadcast_to(np.asarray(x_from, dtype=np.float64), (k,))
        x_by = np.broadcast_to(np.asarray(x_by, dtype=np.float64), (k,))
        on = direction != 0
        if not np.all(np.isfinite(x_from[on]) & (x_by[on] > x_from[on])):
            raise ValueError("a strategic target needs finite x_from < x_by")
        for i, step in zip(index[on].tolist(), direction[on].tolist(), strict=True):
            self._check_change(i, int(self._d.id[i]), step)
        d = self._d
        d.strategic[index] = direction
        d.strategic_from[index] = np.where(on, x_from, np.nan)
        d.strategic_by[index] = np.where(on, x_by, np.nan)

    def set_keep_out(self, road: int, zones) -> None:
        """Where drivers on ``road`` (+1 eastbound, -1 westbound) make no discretionary
        change into a lane: ``zones`` ``[{"lane", "x0", "x1"}, ...]`` [m, road frame]
        (:func:`twin.calibration.lane_flows.keep_out`: a lane they would have to leave
        ahead). Strategic and asked-for changes are not held back. Replaces the zones
        of that road.

        Raises:
            ValueError: a zone with no lane -1 to -4 or not x0 < x1.
        """
        checked = []
        for z in zones:
            lane, x0, x1 = int(z["lane"]), float(z["x0"]), float(z["x1"])
            if not (-N_LANES <= lane <= -1 and x0 < x1):
                raise ValueError(f"a keep-out zone needs a lane -1 to -{N_LANES} and x0 < x1: {z}")
            checked.append((int(road), lane, x0, x1))
        self._keep_out = [z for z in self._keep_out if z[0] != int(road)] + checked

    def strategic(self, ids) -> np.ndarray:
        """(k,) the strategic directions of vehicles ``ids`` (0: none)."""
        return self._d.strategic[self._index(ids)].copy()

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """What :meth:`set_params` and :meth:`params` know: the car-following model's
        parameters, MOBIL's and ``hov_eligible``."""
        return self.model.names + MOBIL_FIELDS + ("hov_eligible",)

    def set_params(self, ids, **values) -> None:
        """Override driver parameters of vehicles ``ids``, e.g.
        ``set_params([7], time_headway=2.0, politeness=0.5)``.

        Names: :attr:`parameter_names` (for IDM ``desired_speed``, ``time_headway``,
        ``min_gap``, ``max_accel``, ``comfortable_decel``, ``delta``; then
        ``politeness``, ``threshold``, ``safe_decel``, ``keep_right``,
        ``hov_eligible``).

        Raises:
            ValueError: an unknown name or an invalid value.
        """
        index = self._index(ids)
        for name, value in values.items():
            if name not in self.parameter_names:
                raise ValueError(
                    f"unknown driver parameter {name!r} of {self.model.name} drivers "
                    f"(known: {', '.join(self.parameter_names)})"
                )
            value = np.asarray(value, dtype=bool if name == "hov_eligible" else np.float64)
            if name != "hov_eligible":
                low = 0.0 if name in ("desired_speed", "politeness", "keep_right") else 1e-9
                if not np.all(np.isfinite(value)) or np.any(value < low):
                    raise ValueError(f"{name} must be finite and >= {low}, got {value!r}")
            elif np.any(~value & (self._d.lane[index] == HOV_LANE)):
                raise ValueError("a vehicle in the HOV lane cannot be made non-eligible")
            self._column(name)[index] = value

    def params(self, ids) -> dict[str, np.ndarray]:
        """The driver parameters (:attr:`parameter_names`) of vehicles ``ids``."""
        index = self._index(ids)
        return {name: self._column(name)[index].copy() for name in self.parameter_names}

    def _column(self, name: str) -> np.ndarray:
        """The (n,) array of driver parameter ``name`` (writes stick)."""
        return getattr(self._d.model if name in self.model.names else self._d, name)

    def set_controller(self, vehicle_id: int, controller: EgoController | None) -> None:
        """Drive vehicle ``vehicle_id`` by ``controller(observation) -> accel`` (or an
        :class:`~twin.traffic.controller_api.EgoCommand`) instead of the drivers; ``None``
        gives it back.

        The manager still steers it along its lane and executes the lane changes the
        controller asks for when they are safe; it does not brake for it (a user's
        controller owns its mistakes; the followers still brake for it).
        """
        self._index([vehicle_id])
        if controller is None:
            self._controllers.by_id.pop(int(vehicle_id), None)
        elif not callable(controller):
            raise ValueError(f"controller for vehicle {vehicle_id} is not callable")
        else:
            self._controllers.by_id[int(vehicle_id)] = controller

    # -- the step ---------------------------------------------------------------------

    def step(self, states, obstacles: Obstacles | None = None) -> Commands:
        """Decide the commands of all managed vehicles for the next physics step.

        Args:
            states: the world's :class:`~twin.physics.world.VehicleStates` (or any
                object with (n,) arrays ``id``, ``x``, ``y``, ``lane``, ``speed``,
                ``heading``) of exactly the managed vehicles, by increasing id.
            obstacles: vehicles to respect but not drive (the ghosts).

        Raises:
            ValueError: the states are not those of the managed vehicles.
            ControllerError: a user's controller raised or returned a bad command.
        """
        d, cfg = self._d, self.config
        if states.id.shape != d.id.shape or np.any(states.id != d.id):
            raise ValueError("states must hold exactly the managed vehicles, by increasing id")
        n = len(d)
        if n == 0:
            self._advance_clock()
            return Commands(*(np.empty(0) for _ in range(6)))
        obstacles = NO_OBSTACLES if obstacles is None else obstacles
        speed = np.maximum(states.speed, 0.0)
        centre_x = states.x + 0.5 * d.length
        steering.finish_changes(d, centre_x, states.y)
        scene = Scene.build(d, states, speed, obstacles)
        accel, need = longitudinal.follow(scene, d, states.lane, speed, self.model, cfg)
        accel = strategic.cooperate(scene, d, accel, centre_x, self.model)
        emergency = need > cfg.emergency_decel
        command = np.where(emergency, np.minimum(accel, -need), accel)
        self.emergency_steps += int(np.count_nonzero(emergency))
        scene.accel[:n] = accel
        if self._steps % self._decision_every == 0:
            strategic.expire(d, centre_x)
            self.lane_changes += lane_change.decide(
                d, scene, centre_x, time=self.time, rng=self.rng, model=self.model,
                params=self._with_obstacles(len(obstacles)), config=cfg,
                excluded=self._controllers.by_id.keys(), keep_out=self._keep_out,
            )  # fmt: skip
        d.accel = self._limits(scene, command, need, emergency)
        steer, path_y = steering.steer(d, states, speed, centre_x, self._heading, cfg)
        self._advance_clock()
        return Commands(
            id=d.id.copy(),
            accel=d.accel.copy(),
            steer=steer,
            lane=d.lane.copy(),
            changing=d.lane_from != d.lane,
            path_y=path_y,
        )

    def _limits(self, scene, command, need, emergency) -> np.ndarray:
        """The commands within the drivers' limits, with the controllers' answers in:
        normal braking to ``brake_limit`` of the tyres' grip, emergency braking and a
        user's controller to all of it; acceleration to the model's ``max_accel``."""
        d, cfg = self._d, self.config
        normal_limit = cfg.brake_limit * d.tyre_decel
        low, high = np.where(emergency, -d.tyre_decel, -normal_limit), d.max_accel
        if self._controllers:
            # a user's controller may use all the tyres give; the engine limits the rest
            command, controlled = self._controllers.apply(
                d, scene, command, need, emergency, self.time, self.force_lane_change
            )
            low = np.where(controlled, -d.tyre_decel, low)
            high = np.where(controlled, d.tyre_decel, high)
        return np.clip(command, low, high)

    def _advance_clock(self) -> None:
        self.time += self.config.dt
        self._steps += 1

    def _with_obstacles(self, k: int):
        """The drivers' model parameters followed by ``k`` obstacles with the mean
        driver's (obstacles are judged as if they drove like one)."""
        if k == 0:
            return self._d.model
        mean = self._mean_driver
        return concatenate(self._d.model, self.model.params(*(np.full(k, v) for v in mean)))

    @cached_property
    def _mean_driver(self) -> tuple:
        """The model's parameters of the class table's mean driver (for obstacles); read
        once: the table is fixed for a manager's life."""
        drivers = self.config.drivers
        share = self.classes.column("share")
        traits = DriverTraits(
            desired_speed=float(share @ self.classes.column("desired_speed_mps")),
            time_headway=float(share @ self.classes.column("time_headway_s")),
            min_gap=drivers.min_gap,
            max_accel=float(share @ self.classes.column("max_accel_mps2")),
            comfortable_decel=drivers.comfortable_decel,
            delta=drivers.delta,
        )
        params = self.model.from_traits(traits)
        return tuple(float(getattr(params, name)) for name in self.model.names)

    def _index(self, ids) -> np.ndarray:
        ids = np.atleast_1d(np.asarray(ids, dtype=np.int64))
        where = np.searchsorted(self._d.id, ids)
        found = where < self._d.id.size
        found[found] = self._d.id[where[found]] == ids[found]
        if not found.all():
            raise KeyError(f"not a managed vehicle: {ids[~found].tolist()}")
        return where


def _check_speed(speed: np.ndarray) -> None:
    if not np.all(np.isfinite(speed)) or np.any(speed < 0):
        raise ValueError(f"desired speeds must be finite and >= 0 m/s, got {speed!r}")
