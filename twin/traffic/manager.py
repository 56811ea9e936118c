"""The traffic manager: drives the twin's physics vehicles the way people drive.

Each step it reads the vehicles' states, finds every vehicle's leader in each lane it
occupies, and decides an acceleration (its car-following model, IDM by default, with
emergency braking on top) and a lateral path (lane keeping, or a MOBIL lane change
under the HOV rule, or a strategic change and the cooperation it asks of others),
which the Stanley controller turns into a steering angle. Any vehicle can be given a
user's controller instead (:mod:`twin.traffic.controller_api`,
:mod:`twin.traffic.controlled`).

The decisions are the compiled kernels of :mod:`twin.traffic.kernels` (the batched
core's, so that a standalone manager and the cosimulation can never drive apart):
this class keeps the drivers' state as their arrays, with one kernel episode per
carriageway, and checks what it is given.

Lifecycle::

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

from twin.core.i24 import HOV_LANE, LANE_WIDTH, N_LANES
from twin.core.vehicle_classes import vehicle_classes
from twin.physics.vehicle import VehicleParams
from twin.traffic.config import MOBIL_FIELDS, TrafficConfig
from twin.traffic.controlled import apply_controllers
from twin.traffic.controller_api import EgoController, lane_change_direction
from twin.traffic.drivers import mean_driver_row
from twin.traffic.kernels import state
from twin.traffic.kernels.decide import decide_from_python
from twin.traffic.kernels.decide import settings as kernel_settings
from twin.traffic.kernels.drivers import DriverTable, draw_drivers, driver_table
from twin.traffic.kernels.models import MODEL_IDS, N_PARAMS
from twin.traffic.models import AUTO, UNCALIBRATED, car_following_model
from twin.traffic.scene import NO_OBSTACLES, Commands, Obstacles

ROADS = (-1, 1)  # the kernels' episode of each carriageway: row 0 westbound, row 1 eastbound


class TrafficManager:
    """Drivers of the configured car-following model and MOBIL with the HOV rule, for
    the vehicles of a physics world.

    Args:
        config: settings; ``config.seed`` seeds every random draw of the manager.
        road_heading: {+1: yaw, -1: yaw} [rad] world yaw of travel on each road
            (``RoadModel.heading``), for the lateral controller.
    """

    def __init__(self, config: TrafficConfig, road_heading: dict[int, float]):
        if config.car_following == AUTO:  # no store here, so no calibration to follow
            config = replace(config, car_following=UNCALIBRATED)
        self.config = config
        self.model = car_following_model(config.car_following)
        self.classes = vehicle_classes()
        self.time = 0.0
        self._steps = 0
        self._heading = np.array([road_heading[-1], road_heading[1]], dtype=np.float64)
        self._ids = np.empty(0, np.int64)
        self._row = np.empty(0, np.int64)  # the kernels' episode of each vehicle
        self._length = np.empty(0)
        self._width = np.empty(0)
        self._wheelbase = np.empty(0)
        self._mu = np.empty(0)
        self._d = state.drivers(len(ROADS), 0)
        self._counters = state.counters(len(ROADS))
        self._controllers: dict[int, EgoController] = {}
        self._keep_out: list[tuple[int, int, float, float]] = []  # (road, lane, x0, x1)
        self._settings = {r: self._kernel_settings(r) for r in ROADS}
        self._order_valid = False

    # -- counts -----------------------------------------------------------------------

    @property
    def lane_changes(self) -> int:
        """Lane changes started."""
        return int(self._counters.lane_changes.sum())

    @property
    def emergency_steps(self) -> int:
        """Vehicle steps with emergency braking."""
        return int(self._counters.emergency_steps.sum())

    @property
    def safety_overrides(self) -> int:
        """Controller steps overridden by emergency braking."""
        return int(self._counters.safety_overrides.sum())

    @property
    def refused_requests(self) -> int:
        """Lane changes controllers asked for that the rules refused."""
        return int(self._counters.refused_requests.sum())

    @property
    def decision_steps(self) -> int:
        """Steps between two lane-change decision rounds (``decision_period / dt``)."""
        return round(self.config.decision_period / self.config.dt)

    # -- vehicles ---------------------------------------------------------------------

    @property
    def ids(self) -> np.ndarray:
        """(n,) ids of the managed vehicles, increasing."""
        return self._ids.copy()

    def add(
        self,
        ids: np.ndarray,
        road: np.ndarray,
        lane: np.ndarray,
        params: VehicleParams,
        *,
        hov_eligible: np.ndarray | None = None,
        desired_speed: np.ndarray | float | None = None,
        keys: np.ndarray | None = None,
    ) -> None:
        """Take over vehicles just spawned in ``lane`` of ``road`` (each (n,)).

        Args:
            ids: (n,) twin ids, all larger than any managed id (the world's order).
            params: the vehicles' physical parameters (``PhysicsWorld.params_of``).
            hov_eligible: (n,) bool; by default drawn: the vehicles spawned in the HOV
                lane are eligible, others with the configured share where their class
                may use the lane.
            desired_speed: [m/s]; by default drawn from the class table.
            keys: (n,) non-negative integers the drivers' random draws are keyed by
                (their decisions' times, their manoeuvres' durations); default: the ids.

        Raises:
            ValueError: ids out of order, lanes off the road, a non-eligible vehicle
                in the HOV lane, or sizes that do not match.
        """
        ids = np.atleast_1d(np.asarray(ids, dtype=np.int64))
        n = ids.size
        if n == 0:
            return
        road = np.broadcast_to(np.asarray(road, dtype=np.int8), (n,)).copy()
        lane = np.broadcast_to(np.asarray(lane, dtype=np.int64), (n,)).copy()
        self._check_new(ids, road, lane, params)
        cfg = self.config
        keys = ids if keys is None else np.broadcast_to(np.asarray(keys, np.int64), (n,))
        desired = np.full(n, np.nan)
        if desired_speed is not None:
            desired = np.broadcast_to(np.asarray(desired_speed, dtype=np.float64), (n,)).copy()
            _check_speed(desired)
        cf, lucky, first = np.zeros((n, N_PARAMS)), np.zeros(n, bool), np.zeros(n)
        draw_drivers(
            self._driver_table, MODEL_IDS[cfg.car_following], np.int64(cfg.seed),
            np.ascontiguousarray(keys, np.int64),
            np.ascontiguousarray(params.vehicle_class, np.int64), desired, cf, lucky, first,
        )  # fmt: skip
        allowed = self.classes.column("hov_allowed")[params.vehicle_class] == 1
        if hov_eligible is None:
            eligible = (lane == HOV_LANE) | (allowed & lucky)
        else:
            eligible = np.broadcast_to(np.asarray(hov_eligible, dtype=bool), (n,)).copy()
            if np.any(~eligible & (lane == HOV_LANE)):
                raise ValueError("a vehicle added in the HOV lane must be HOV-eligible")
        values = {
            "key": keys, "cf": cf, "hov_eligible": eligible,
            "auto": np.full(n, cfg.auto_lane_change), "lane": lane, "lane_from": lane,
            "start_x": np.zeros(n), "start_y": (0.5 - lane) * LANE_WIDTH, "path_length": np.ones(n),
            "next_decision": self.time + first,
            "decisions": np.zeros(n, np.int64), "changes": np.zeros(n, np.int64),
            "requested": np.zeros(n, np.int64), "strategic": np.zeros(n, np.int64),
            "strategic_from": np.full(n, np.nan), "strategic_by": np.full(n, np.nan),
            "accel": np.zeros(n), "ctrl": np.zeros(n, np.int64), "mandatory": np.zeros(n, bool),
            "offset": np.zeros(n),
            **{name: np.full(n, float(getattr(cfg.mobil, name))) for name in MOBIL_FIELDS},
        }  # fmt: skip
        self._d = state.Drivers(
            *(
                np.concatenate(
                    [
                        old,
                        np.broadcast_to(values[f], (len(ROADS), *values[f].shape)).astype(
                            old.dtype
                        ),
                    ],
                    axis=1,
                )
                for f, old in zip(state.Drivers._fields, self._d, strict=True)
            )
        )
        self._ids = np.concatenate([self._ids, ids])
        self._row = np.concatenate([self._row, (road > 0).astype(np.int64)])
        self._length = np.concatenate([self._length, params.length])
        self._width = np.concatenate([self._width, params.width])
        self._wheelbase = np.concatenate(
            [self._wheelbase, params.mounts[:, 0, 0] - params.mounts[:, 2, 0]]
        )
        self._mu = np.concatenate([self._mu, params.mu])
        self._order_valid = False

    def _check_new(self, ids, road, lane, params: VehicleParams) -> None:
        if len(params) != ids.size:
            raise ValueError(f"params describe {len(params)} vehicles, ids {ids.size}")
        if np.any(np.diff(ids) <= 0) or (self._ids.size and ids[0] <= self._ids[-1]):
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
        keep = np.ones(self._ids.size, dtype=bool)
        keep[self._index(ids)] = False
        self._d = state.Drivers(*(field[:, keep] for field in self._d))
        for name in ("_ids", "_row", "_length", "_width", "_wheelbase", "_mu"):
            setattr(self, name, getattr(self, name)[keep])
        for i in np.atleast_1d(ids):
            self._controllers.pop(int(i), None)
        self._order_valid = False

    # -- the API the cosimulator uses -------------------------------------------------

    def _get(self, name: str, ids) -> np.ndarray:
        """(k,) field ``name`` of the drivers of vehicles ``ids`` (their road's row)."""
        index = self._index(ids)
        return getattr(self._d, name)[self._row[index], index].copy()

    def _set(self, name: str, ids, value) -> None:
        index = self._index(ids)
        getattr(self._d, name)[:, index] = value

    def set_desired_speed(self, ids, speed) -> None:
        """Set the desired speed [m/s] (>= 0) of vehicles ``ids``."""
        speed = np.asarray(speed, dtype=np.float64)
        _check_speed(speed)
        self._d.cf[:, self._index(ids), 0] = speed

    def desired_speed(self, ids) -> np.ndarray:
        """(k,) [m/s] the desired speeds of vehicles ``ids``."""
        index = self._index(ids)
        return self._d.cf[self._row[index], index, 0].copy()

    def lanes(self, ids) -> np.ndarray:
        """(k,) the lanes vehicles ``ids`` drive in or are changing to."""
        return self._get("lane", ids).astype(np.int8)

    def changing(self, ids) -> np.ndarray:
        """(k,) bool: vehicles ``ids`` are changing lanes now."""
        return self._get("lane_from", ids) != self._get("lane", ids)

    def set_auto_lane_change(self, ids, on) -> None:
        """Switch MOBIL lane changes on or off for vehicles ``ids``."""
        self._set("auto", ids, np.asarray(on, dtype=bool))

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
        self._d.requested[:, i] = step

    def _check_change(self, i: int, vehicle_id: int, step: int) -> None:
        """Raise ValueError where vehicle ``i`` (index) may never change one lane
        ``step``: off the road, or against the HOV rule."""
        r = self._row[i]
        lane = int(self._d.lane[r, i])
        target = lane + step
        if not -N_LANES <= target <= -1:
            raise ValueError(f"vehicle {vehicle_id} in lane {lane}: no lane {target}")
        if target == HOV_LANE and not self._d.hov_eligible[r, i]:
            raise ValueError(f"vehicle {vehicle_id} is not HOV-eligible: lane -1 is HOV")
        if HOV_LANE in (target, lane) and not self.config.hov_openings:
            raise ValueError(
                f"vehicle {vehicle_id}: the HOV line cannot be crossed (no hov_openings)"
            )

    def set_strategic(self, ids, direction, x_from, x_by) -> None:
        """Give vehicles ``ids`` a strategic target: change one lane ``direction`` (+1
        left, toward lane -1; -1 right; 0 clears the target), wanted from road-frame
        ``x_from`` [m] with an urgency that grows to ``x_by`` [m] (vehicle centres);
        past ``x_by`` it is tried until GIVE_UP beyond, the target lane's drivers
        making room (:mod:`twin.traffic.strategic`). Each (k,) or a scalar.

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
            self._check_change(i, int(self._ids[i]), step)
        self._d.strategic[:, index] = direction
        self._d.strategic_from[:, index] = np.where(on, x_from, np.nan)
        self._d.strategic_by[:, index] = np.where(on, x_by, np.nan)

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
        self._settings[int(road)] = self._kernel_settings(int(road))

    def strategic(self, ids) -> np.ndarray:
        """(k,) the strategic directions of vehicles ``ids`` (0: none)."""
        return self._get("strategic", ids).astype(np.int8)

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
            elif np.any(~value & (self._d.lane[self._row[index], index] == HOV_LANE)):
                raise ValueError("a vehicle in the HOV lane cannot be made non-eligible")
            if name in self.model.names:
                self._d.cf[:, index, self.model.names.index(name)] = value
            else:
                getattr(self._d, name)[:, index] = value

    def params(self, ids) -> dict[str, np.ndarray]:
        """The driver parameters (:attr:`parameter_names`) of vehicles ``ids``."""
        index = self._index(ids)
        rows = self._row[index]
        out = {name: self._d.cf[rows, index, j].copy() for j, name in enumerate(self.model.names)}
        for name in (*MOBIL_FIELDS, "hov_eligible"):
            out[name] = getattr(self._d, name)[rows, index].copy()
        return out

    def set_controller(self, vehicle_id: int, controller: EgoController | None) -> None:
        """Drive vehicle ``vehicle_id`` by ``controller(observation) -> accel`` (or an
        :class:`~twin.traffic.controller_api.EgoCommand`) instead of the drivers; ``None``
        gives it back.

        The manager still steers it along its lane and executes the lane changes the
        controller asks for when they are safe; it does not brake for it (a user's
        controller owns its mistakes; the followers still brake for it).
        """
        (i,) = self._index([vehicle_id])
        if controller is None:
            self._controllers.pop(int(vehicle_id), None)
            self._d.ctrl[:, i] = state.DRIVER
        elif not callable(controller):
            raise ValueError(f"controller for vehicle {vehicle_id} is not callable")
        else:
            self._controllers[int(vehicle_id)] = controller
            self._d.ctrl[:, i] = state.PYTHON

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
        if states.id.shape != self._ids.shape or np.any(states.id != self._ids):
            raise ValueError("states must hold exactly the managed vehicles, by increasing id")
        n = self._ids.size
        if n == 0:
            self._advance_clock()
            return Commands(*(np.empty(0) for _ in range(6)))
        obstacles = NO_OBSTACLES if obstacles is None else obstacles
        traffic = self._traffic(states, obstacles)
        for b, road in enumerate(ROADS):
            if not traffic.vehicles.valid[b].any():
                continue
            t = traffic._replace(settings=self._settings[road])
            decide_from_python(b, self._steps, self.time, self.config.seed, state.pack(t))
            if self._controllers:
                mine = {
                    int(i): self._controllers[int(self._ids[i])]
                    for i in np.flatnonzero(self._row == b)
                    if int(self._ids[i]) in self._controllers
                }
                if mine:
                    overrides, refused = apply_controllers(
                        mine, t, b, self._ids[None, :].repeat(len(ROADS), 0), self._obstacle_y,
                        road, self.time, self._may_change,
                    )  # fmt: skip
                    self._counters.safety_overrides[b] += overrides
                    self._counters.refused_requests[b] += refused
        self._order_valid = True
        rows, cols = self._row, np.arange(n)
        sc = traffic.scratch
        lane = self._d.lane[rows, cols]
        commands = Commands(
            id=self._ids.copy(),
            accel=self._d.accel[rows, cols].copy(),
            steer=sc.steer[rows, cols].copy(),
            lane=lane.astype(np.int8),
            changing=self._d.lane_from[rows, cols] != lane,
            path_y=sc.path_y[rows, cols].copy(),
        )
        self._advance_clock()
        return commands

    def _may_change(self, i: int, step: int) -> bool:
        try:
            self._check_change(i, int(self._ids[i]), step)
        except ValueError:
            return False
        return True

    def _traffic(self, states, obstacles: Obstacles) -> state.Traffic:
        """The kernels' arrays of this step: the vehicles in their road's row, the
        obstacles by road, the drivers, the scratch (kept while the vehicles are)."""
        n, rows = self._ids.size, len(ROADS)
        valid = np.zeros((rows, n), bool)
        valid[self._row, np.arange(n)] = True
        heading = self._heading[self._row]
        yaw = (states.heading - heading + np.pi) % (2.0 * np.pi) - np.pi

        def both(values, dtype=float):
            return np.broadcast_to(np.asarray(values, dtype), (rows, n)).copy()

        vehicles = state.Vehicles(
            valid=valid, top=np.full(rows, n, np.int64), x=both(states.x), y=both(states.y),
            yaw=both(yaw),
            speed=both(states.speed), lane=both(states.lane, np.int64), length=both(self._length),
            width=both(self._width), wheelbase=both(self._wheelbase), mu=both(self._mu),
        )  # fmt: skip
        by_road = [np.flatnonzero(obstacles.road == road) for road in ROADS]
        g = max(1, max(k.size for k in by_road))
        count = np.array([k.size for k in by_road], np.int64)
        ob = state.Obstacles(
            count=count, lane=np.zeros((rows, g), np.int64), x=np.zeros((rows, g)),
            length=np.zeros((rows, g)), speed=np.zeros((rows, g)), accel=np.zeros((rows, g)),
            reach=np.zeros((rows, g), np.int64),  # a scene's obstacles: their lanes alone
        )  # fmt: skip
        self._obstacle_y = np.zeros((rows, g))
        for b, index in enumerate(by_road):
            order = index[np.argsort(obstacles.x[index], kind="stable")]
            k = order.size
            ob.lane[b, :k], ob.x[b, :k] = obstacles.lane[order], obstacles.x[order]
            ob.length[b, :k], ob.speed[b, :k] = obstacles.length[order], obstacles.speed[order]
            ob.accel[b, :k] = obstacles.accel[order]
            self._obstacle_y[b, :k] = (0.5 - obstacles.lane[order]) * LANE_WIDTH
        scratch = self._scratch_for(n, g)
        return state.Traffic(vehicles, ob, self._d, scratch, None, self._counters,
                             np.zeros(rows))  # fmt: skip

    def _scratch_for(self, n: int, g: int) -> state.Scratch:
        """The kernels' scratch for ``n`` vehicles and ``g`` obstacles: last step's, with
        its sorted entries, while the vehicles are the same; a new one otherwise."""
        sc = getattr(self, "_sc", None)
        if sc is None or sc.marks.shape[1] != n or sc.sx.shape[1] < n + g or not self._order_valid:
            sc = state.scratch(len(ROADS), n, max(g, 1))
        self._sc = sc
        return sc

    def _advance_clock(self) -> None:
        self.time += self.config.dt
        self._steps += 1

    def _kernel_settings(self, road: int):
        zones = [(lane, x0, x1) for r, lane, x0, x1 in self._keep_out if r == road]
        return kernel_settings(self.config, self._mean_driver, keep_out=zones)

    @cached_property
    def _driver_table(self) -> DriverTable:
        """What the drivers are drawn from (the core's draw); read once: fixed."""
        cfg = self.config
        return driver_table(cfg.drivers, self.classes, cfg.hov_share, cfg.decision_interval)

    @cached_property
    def _mean_driver(self) -> np.ndarray:
        """The model's parameter row of the class table's mean driver (obstacles are
        judged as if they drove like one); read once: the table is fixed."""
        return mean_driver_row(self.config.drivers, self.model, self.classes)

    def _index(self, ids) -> np.ndarray:
        ids = np.atleast_1d(np.asarray(ids, dtype=np.int64))
        where = np.searchsorted(self._ids, ids)
        found = where < self._ids.size
        found[found] = self._ids[where[found]] == ids[found]
        if not found.all():
            raise KeyError(f"not a managed vehicle: {ids[~found].tolist()}")
        return where


def _check_speed(speed: np.ndarray) -> None:
    if not np.all(np.isfinite(speed)) or np.any(speed < 0):
        raise ValueError(f"desired speeds must be finite and >= 0 m/s, got {speed!r}")
