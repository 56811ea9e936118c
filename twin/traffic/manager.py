"""The traffic manager: drives the twin's physics vehicles the way people drive.

Each step it reads the vehicles' states, finds every vehicle's leader in each lane it
occupies, and decides an acceleration (IDM, with emergency braking on top) and a
lateral path (lane keeping, or a MOBIL lane change under the HOV rule), which the
controllers of :mod:`twin.traffic.control` turn into the accel and steer inputs of
the vehicle model. One vehicle (the ego) can be given a user's controller instead.

Lifecycle (the cosimulator's order)::

    manager.add(ids, world.params_of(ids), lanes)      # when bodies are spawned
    commands = manager.step(world.states(), ghosts)    # each step
    world.set_controls(commands.id, accel=commands.accel, steer=commands.steer)
    world.step()
    manager.remove(ids)                                # when bodies are despawned

The manager never touches pybullet; it sees vehicles through the states and the
physical parameters the world gives it.
"""

import math
from collections.abc import Callable
from dataclasses import dataclass, field, fields
from functools import cached_property

import numpy as np

from twin.core.errors import ControllerError
from twin.core.i24 import HOV_LANE, LANE_WIDTH, LANES, N_LANES, lane_center
from twin.core.vehicle_classes import vehicle_classes
from twin.physics.vehicle import GRAVITY, VehicleParams
from twin.traffic.control import path_shape, required_decel, stanley_steer
from twin.traffic.drivers import DriverDistribution
from twin.traffic.lanes import Occupancy
from twin.traffic.mobil import MOBILParams, mobil_incentive, mobil_safe
from twin.traffic.models.idm import (
    IDMParams,
    bounded_free_road_term,
    interaction_term,
    twin_idm_acceleration,
)

MIN_SPEED_PATH = 5.0  # [m/s] lane-change paths are at least this speed times their time
MIN_LANE_CHANGE_GAP = 1.0  # [m] bumper to bumper, to each of the new neighbours
SETTLED = 0.1  # [m] from the new lane's centre, a lane change is over
MAX_STEER = 0.5  # [rad] front-wheel angle limit of the lateral controller
NEIGHBOUR_RANGE = 150.0  # [m] along the road, for the ego's observation
IDM_FIELDS = ("desired_speed", "time_headway", "min_gap", "max_accel", "comfortable_decel", "delta")
MOBIL_FIELDS = ("politeness", "threshold", "safe_decel", "keep_right")
LEFT, RIGHT = 1, -1  # lane-change directions: toward lane -1, toward lane -4


@dataclass(frozen=True)
class TrafficConfig:
    """Settings of the traffic manager.

    Attributes:
        dt: [s] step of the manager (the physics step).
        drivers: how IDM parameters are drawn per vehicle.
        mobil: MOBIL parameters every driver starts with.
        decision_interval: [s] mean time between a driver's lane-change decisions.
        decision_period: [s] lane-change decisions (MOBIL and forced changes) are taken
            on this grid, for the drivers due then; a multiple of ``dt``.
        lane_change_time: [s] (low, high) range of a manoeuvre's duration.
        auto_lane_change: whether new vehicles change lanes by MOBIL.
        hov_share: [-] share of HOV-eligible vehicles among those whose eligibility is
            not given and whose class may use the HOV lane.
        hov_openings: [m] (x0, x1) road-frame ranges where HOV-eligible vehicles may
            cross the HOV line; none by default (the double solid line of this corridor).
        emergency_decel: [m/s^2] when staying clear of the leader (if it keeps braking
            as it does) needs more than this, the manager brakes as hard as needed.
        emergency_margin: [m] gap kept by emergency braking.
        reaction_time: [s] travel before emergency braking bites.
        brake_limit: [-] deceleration limit of normal driving as a share of mu g (the
            tyre limit); emergency braking uses all of mu g.
        lateral_gain: [1/s] cross-track gain of the lateral (Stanley) controller.
        path_preview: [s] the path's direction and curvature are taken this far ahead
            (at the current speed), against the body's yaw lag.
        max_lateral_accel: [m/s^2] limit of the lateral controller.
        seed: random seed of the drivers' draws.
    """

    dt: float = 0.01
    drivers: DriverDistribution = field(default_factory=DriverDistribution)
    mobil: MOBILParams = field(default_factory=MOBILParams)
    decision_interval: float = 1.0
    decision_period: float = 0.1
    lane_change_time: tuple[float, float] = (3.0, 6.0)
    auto_lane_change: bool = True
    hov_share: float = 0.15
    hov_openings: tuple[tuple[float, float], ...] = ()
    emergency_decel: float = 4.0
    emergency_margin: float = 1.0
    reaction_time: float = 0.1
    brake_limit: float = 0.9
    lateral_gain: float = 1.0
    path_preview: float = 0.1
    max_lateral_accel: float = 4.0
    seed: int = 0

    def __post_init__(self):
        object.__setattr__(self, "lane_change_time", tuple(self.lane_change_time))
        object.__setattr__(
            self, "hov_openings", tuple(tuple(map(float, o)) for o in self.hov_openings)
        )
        positive = {
            "dt": self.dt,
            "decision_interval": self.decision_interval,
            "decision_period": self.decision_period,
            "emergency_decel": self.emergency_decel,
            "lateral_gain": self.lateral_gain,
            "max_lateral_accel": self.max_lateral_accel,
        }
        for name, value in positive.items():
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"TrafficConfig.{name} must be positive, got {value!r}")
        ratio = self.decision_period / self.dt
        if abs(ratio - round(ratio)) > 1e-9 or self.decision_period > self.decision_interval:
            raise ValueError(
                f"decision_period {self.decision_period} s must be a multiple of dt {self.dt} s"
                f" and at most decision_interval {self.decision_interval} s"
            )
        low, high = self.lane_change_time
        if not 0 < low <= high:
            raise ValueError(f"lane_change_time must be 0 < low <= high, got {(low, high)}")
        if not 0 <= self.hov_share <= 1:
            raise ValueError(f"hov_share must be in 0..1, got {self.hov_share}")
        if not 0 < self.brake_limit <= 1:
            raise ValueError(f"brake_limit must be in (0, 1], got {self.brake_limit}")
        if self.emergency_margin < 0 or self.reaction_time < 0 or self.path_preview < 0:
            raise ValueError("emergency_margin, reaction_time and path_preview must be >= 0")
        if any(len(o) != 2 or not o[0] < o[1] for o in self.hov_openings):
            raise ValueError(f"hov_openings must be (x0, x1) with x0 < x1: {self.hov_openings}")
        _check_mobil(self.mobil)


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
class LaneView:
    """Nearest vehicles in each lane of the ego's road, (4,) for lanes -1, -2, -3, -4.

    Gaps [m] are bumper to bumper from the ego (``inf`` where nobody is within the
    manager's knowledge); speeds [m/s] are ``nan`` there.
    """

    lanes: tuple[int, ...]
    leader_gap: np.ndarray
    leader_speed: np.ndarray
    follower_gap: np.ndarray
    follower_speed: np.ndarray


@dataclass(frozen=True, eq=False)
class Observation:
    """What a user's ego controller sees each step.

    Attributes:
        time: [s] manager time. id: the ego's twin id. road: +1 / -1.
        lane: lane the ego is in or changing to. changing: mid-lane-change.
        x: [m] back centre; y: [m] lateral position; speed: [m/s].
        desired_speed: [m/s] the ego's setting. default_accel: [m/s^2] what the
        traffic manager would command (IDM with emergency braking).
        lanes: leaders and followers per lane (:class:`LaneView`).
        neighbours: vehicles within ``NEIGHBOUR_RANGE`` on the ego's road as arrays
        ``id`` (-1 for obstacles), ``dx`` [m] (back to back), ``y`` [m], ``speed``, ``lane``.
    """

    time: float
    id: int
    road: int
    lane: int
    changing: bool
    x: float
    y: float
    speed: float
    desired_speed: float
    default_accel: float
    lanes: LaneView
    neighbours: dict[str, np.ndarray]


@dataclass(frozen=True)
class EgoCommand:
    """A controller's answer: ``accel`` [m/s^2] and an optional lane change
    (``LEFT`` = +1 toward lane -1, ``RIGHT`` = -1, 0 none)."""

    accel: float
    lane_change: int = 0


EgoController = Callable[[Observation], "float | EgoCommand"]


@dataclass(frozen=True, eq=False)
class _Scene:
    """One step's managed vehicles (rows 0..n-1) followed by the obstacles, (n + k,)."""

    n: int
    road: np.ndarray
    x: np.ndarray
    y: np.ndarray
    length: np.ndarray
    speed: np.ndarray
    accel: np.ndarray  # [m/s^2] now: the IDM's for vehicles, the given one for obstacles
    occupancy: Occupancy


@dataclass(eq=False)
class _Drivers:
    """Per-vehicle state of the manager, struct-of-arrays sorted by id."""

    id: np.ndarray
    road: np.ndarray
    vehicle_class: np.ndarray
    length: np.ndarray
    wheelbase: np.ndarray
    tyre_decel: np.ndarray  # [m/s^2] mu g, the limit of emergency braking
    desired_speed: np.ndarray
    time_headway: np.ndarray
    min_gap: np.ndarray
    max_accel: np.ndarray
    comfortable_decel: np.ndarray
    delta: np.ndarray
    politeness: np.ndarray
    threshold: np.ndarray
    safe_decel: np.ndarray
    keep_right: np.ndarray
    hov_eligible: np.ndarray
    auto_lane_change: np.ndarray
    lane: np.ndarray  # lane driven to
    lane_from: np.ndarray  # lane left while changing, else == lane
    start_x: np.ndarray  # [m] path start (centre x) of the current change
    start_y: np.ndarray  # [m]
    path_length: np.ndarray  # [m]
    next_decision: np.ndarray  # [s]
    requested: np.ndarray  # pending forced lane change: LEFT, RIGHT or 0
    accel: np.ndarray  # [m/s^2] last command

    def __len__(self) -> int:
        return self.id.size

    def take(self, index) -> "_Drivers":
        return _Drivers(*(getattr(self, f.name)[index] for f in fields(self)))

    @staticmethod
    def concatenate(a: "_Drivers", b: "_Drivers") -> "_Drivers":
        return _Drivers(
            *(np.concatenate([getattr(a, f.name), getattr(b, f.name)]) for f in fields(a))
        )

    def idm(self, index=slice(None)) -> IDMParams:
        return IDMParams(*(getattr(self, name)[index] for name in IDM_FIELDS))

    def mobil(self, index) -> MOBILParams:
        return MOBILParams(*(getattr(self, name)[index] for name in MOBIL_FIELDS))


class TrafficManager:
    """IDM and MOBIL drivers with the HOV rule, for the vehicles of a physics world.

    Args:
        config: settings; ``config.seed`` seeds every random draw of the manager.
        road_heading: {+1: yaw, -1: yaw} [rad] world yaw of travel on each road
            (``RoadModel.heading``), for the lateral controller.
    """

    def __init__(self, config: TrafficConfig, road_heading: dict[int, float]):
        self.config = config
        self.rng = np.random.default_rng(config.seed)
        self.classes = vehicle_classes()
        self.time = 0.0
        self._steps = 0
        self._decision_every = round(config.decision_period / config.dt)
        self._heading = np.array([road_heading[-1], road_heading[1]], dtype=np.float64)
        self._d = _Drivers(*(np.empty(0, dtype=_dtype(f.name)) for f in fields(_Drivers)))
        self._controllers: dict[int, EgoController] = {}
        self.lane_changes = 0
        self.emergency_steps = 0
        self.safety_overrides = 0  # controller steps overridden by emergency braking
        self.refused_requests = 0

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
        if len(params) != n:
            raise ValueError(f"params describe {len(params)} vehicles, ids {n}")
        if np.any(np.diff(ids) <= 0) or (len(self._d) and ids[0] <= self._d.id[-1]):
            raise ValueError("new ids must be increasing and above the managed ones")
        if not np.all(np.isin(road, (-1, 1))):
            raise ValueError("road must be +1 (eastbound) or -1 (westbound)")
        if np.any((lane > -1) | (lane < -N_LANES)):
            raise ValueError(f"lanes must be in -1..-{N_LANES}, got {np.unique(lane).tolist()}")
        cfg = self.config
        drawn = cfg.drivers.draw(self.classes, params.vehicle_class, self.rng)
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
        else:
            desired = drawn.desired_speed
        center = lane_center(lane)
        new = _Drivers(
            id=ids,
            road=road,
            vehicle_class=np.asarray(params.vehicle_class, dtype=np.int64),
            length=params.length.copy(),
            wheelbase=params.mounts[:, 0, 0] - params.mounts[:, 2, 0],
            tyre_decel=params.mu * GRAVITY,
            desired_speed=desired,
            time_headway=drawn.time_headway,
            min_gap=drawn.min_gap,
            max_accel=drawn.max_accel,
            comfortable_decel=drawn.comfortable_decel,
            delta=drawn.delta,
            **{
                name: np.full(n, float(getattr(cfg.mobil, name)), dtype=np.float64)
                for name in MOBIL_FIELDS
            },
            hov_eligible=eligible,
            auto_lane_change=np.full(n, cfg.auto_lane_change),
            lane=lane,
            lane_from=lane.copy(),
            start_x=np.zeros(n),
            start_y=center,
            path_length=np.ones(n),
            next_decision=self.time + self.rng.uniform(0.0, cfg.decision_interval, n),
            requested=np.zeros(n, dtype=np.int8),
            accel=np.zeros(n),
        )
        self._d = _Drivers.concatenate(self._d, new)

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
            self._controllers.pop(int(i), None)

    # -- the API the cosimulator uses -------------------------------------------------

    def set_desired_speed(self, ids, speed) -> None:
        """Set the IDM desired speed [m/s] (>= 0) of vehicles ``ids``."""
        speed = np.asarray(speed, dtype=np.float64)
        _check_speed(speed)
        self._d.desired_speed[self._index(ids)] = speed

    def desired_speed(self, ids) -> np.ndarray:
        """(k,) [m/s] the desired speeds of vehicles ``ids``."""
        return self._d.desired_speed[self._index(ids)].copy()

    def lanes(self, ids) -> np.ndarray:
        """(k,) the lanes vehicles ``ids`` drive in or are changing to."""
        return self._d.lane[self._index(ids)].copy()

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
        step = _direction(direction)
        (i,) = self._index([vehicle_id])
        if step:
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
        self._d.requested[i] = step

    def set_params(self, ids, **values) -> None:
        """Override IDM or MOBIL parameters of vehicles ``ids``, e.g.
        ``set_params([7], time_headway=2.0, politeness=0.5)``.

        Names: ``desired_speed``, ``time_headway``, ``min_gap``, ``max_accel``,
        ``comfortable_decel``, ``delta``, ``politeness``, ``threshold``, ``safe_decel``,
        ``keep_right``, ``hov_eligible``.

        Raises:
            ValueError: an unknown name or an invalid value.
        """
        index = self._index(ids)
        for name, value in values.items():
            if name not in IDM_FIELDS + MOBIL_FIELDS + ("hov_eligible",):
                raise ValueError(f"unknown driver parameter {name!r}")
            value = np.asarray(value, dtype=bool if name == "hov_eligible" else np.float64)
            if name != "hov_eligible":
                low = 0.0 if name in ("desired_speed", "politeness", "keep_right") else 1e-9
                if not np.all(np.isfinite(value)) or np.any(value < low):
                    raise ValueError(f"{name} must be finite and >= {low}, got {value!r}")
            elif np.any(~value & (self._d.lane[index] == HOV_LANE)):
                raise ValueError("a vehicle in the HOV lane cannot be made non-eligible")
            getattr(self._d, name)[index] = value

    def params(self, ids) -> dict[str, np.ndarray]:
        """The IDM and MOBIL parameters and HOV eligibility of vehicles ``ids``."""
        index = self._index(ids)
        return {
            name: getattr(self._d, name)[index].copy()
            for name in IDM_FIELDS + MOBIL_FIELDS + ("hov_eligible",)
        }

    def set_controller(self, vehicle_id: int, controller: EgoController | None) -> None:
        """Drive vehicle ``vehicle_id`` by ``controller(observation) -> accel`` (or an
        :class:`EgoCommand`) instead of IDM and MOBIL; ``None`` gives it back.

        The manager still steers it along its lane and executes the lane changes the
        controller asks for when they are safe; it does not brake for it (a user's
        controller owns its mistakes; the followers still brake for it).
        """
        self._index([vehicle_id])
        if controller is None:
            self._controllers.pop(int(vehicle_id), None)
        elif not callable(controller):
            raise ValueError(f"controller for vehicle {vehicle_id} is not callable")
        else:
            self._controllers[int(vehicle_id)] = controller

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
            self.time += cfg.dt
            self._steps += 1
            return Commands(*(np.empty(0) for _ in range(6)))
        obstacles = NO_OBSTACLES if obstacles is None else obstacles
        speed = np.maximum(states.speed, 0.0)
        x, length = states.x, d.length
        center = x + 0.5 * length
        # a change is over when its path has ended and the vehicle is centred in its lane
        changing = d.lane_from != d.lane
        done = (
            changing
            & (center >= d.start_x + d.path_length)
            & (np.abs(states.y - _lane_center(d.lane)) < SETTLED)
        )
        d.lane_from[done] = d.lane[done]

        # leaders in every lane each vehicle occupies, obstacles after the vehicles
        k = len(obstacles)

        def join(mine, theirs):
            return np.concatenate([mine, theirs]) if k else mine

        none = np.zeros(k, np.int8)
        road_all, x_all = join(d.road, obstacles.road), join(x, obstacles.x)
        occupancy = Occupancy.build(
            road_all,
            x_all,
            [join(d.lane, obstacles.lane), join(d.lane_from, none), join(states.lane, none)],
        )
        scene = _Scene(
            n=n,
            road=road_all,
            x=x_all,
            y=join(states.y, _lane_center(obstacles.lane)),
            length=join(length, obstacles.length),
            speed=join(speed, obstacles.speed),
            accel=join(d.accel, obstacles.accel).copy(),
            occupancy=occupancy,
        )
        driven = occupancy.owner < n
        owner = occupancy.owner[driven]
        gap, leader = occupancy.leaders(scene.x, scene.length)
        gap, leader = gap[driven], leader[driven]
        # a slow vehicle past the middle of its lane change no longer follows the leader
        # of the lane it leaves (its followers there still see it): it finishes the
        # change rather than stopping across the line behind a queue it is leaving
        entry_lane = -(occupancy.group[driven] % N_LANES) - 1
        left_behind = (
            (entry_lane == d.lane_from[owner])
            & (d.lane_from[owner] != d.lane[owner])
            & (states.lane[owner] == d.lane[owner])
            & (speed[owner] < MIN_SPEED_PATH)  # slow: its path is made for this speed
        )
        gap = np.where(left_behind, np.inf, gap)
        leader = np.where(left_behind, owner, leader)
        v_lead = scene.speed[leader]

        idm = d.idm()
        free = bounded_free_road_term(speed, idm)
        interaction = np.zeros(n)
        np.minimum.at(
            interaction, owner, interaction_term(speed[owner], v_lead, gap, idm.take(owner))
        )
        accel = free + interaction
        need_entry = required_decel(
            gap,
            speed[owner],
            v_lead,
            np.maximum(-scene.accel[leader], 0.0),
            cfg.emergency_margin,
            cfg.reaction_time,
        )
        need = np.zeros(n)
        np.maximum.at(need, owner, need_entry)
        emergency = need > cfg.emergency_decel
        command = np.where(emergency, np.minimum(accel, -need), accel)
        self.emergency_steps += int(np.count_nonzero(emergency))
        scene.accel[:n] = accel

        if self._steps % self._decision_every == 0:
            self._decide_lane_changes(scene, center)
        normal_limit = cfg.brake_limit * d.tyre_decel
        low, high = np.where(emergency, -d.tyre_decel, -normal_limit), d.max_accel
        if self._controllers:
            # a user's controller may use all the tyres give; the engine limits the rest
            command, controlled = self._ask_controllers(scene, command, need, emergency)
            low = np.where(controlled, -d.tyre_decel, low)
            high = np.where(controlled, d.tyre_decel, high)
        command = np.clip(command, low, high)
        d.accel = command

        # lateral: the lane centre or the lane-change path, by the Stanley controller
        # Stanley on the path's cross-track error here, with the path's direction and
        # curvature taken a little ahead to make up for the body's yaw lag
        path = _lane_center(d.lane)
        slope, bend = np.zeros(n), np.zeros(n)
        moving = np.flatnonzero(d.lane_from != d.lane)
        if moving.size:
            start_x, start_y = d.start_x[moving], d.start_y[moving]
            end_y, length = path[moving], d.path_length[moving]
            path[moving] = path_shape(center[moving], start_x, start_y, end_y, length)[0]
            ahead = center[moving] + cfg.path_preview * speed[moving]
            _, slope[moving], bend[moving] = path_shape(ahead, start_x, start_y, end_y, length)
        heading_error = _wrap(states.heading - self._heading[(d.road > 0) * 1] + np.arctan(slope))
        max_steer = np.minimum(
            MAX_STEER,
            np.arctan(d.wheelbase * cfg.max_lateral_accel / np.maximum(speed, 1.0) ** 2),
        )
        steer = stanley_steer(
            states.y - path,
            heading_error,
            speed,
            -bend / (1.0 + slope**2) ** 1.5,
            d.wheelbase,
            cfg.lateral_gain,
            max_steer,
        )
        self.time += cfg.dt
        self._steps += 1
        return Commands(
            id=d.id.copy(),
            accel=command.copy(),
            steer=steer,
            lane=d.lane.copy(),
            changing=d.lane_from != d.lane,
            path_y=path,
        )

    # -- lane changes -----------------------------------------------------------------

    def _decide_lane_changes(self, scene: _Scene, center: np.ndarray) -> None:
        """MOBIL for the drivers due to decide, and forced requests; start the changes."""
        d, cfg, n = self._d, self.config, scene.n
        auto = d.auto_lane_change
        if self._controllers:
            auto = auto & ~np.isin(d.id, list(self._controllers))
        due = (d.lane_from == d.lane) & (
            ((d.next_decision <= self.time) & auto) | (d.requested != 0)
        )
        cand = np.flatnonzero(due)
        if cand.size == 0:
            return
        timed = d.next_decision[cand] <= self.time
        d.next_decision[cand[timed]] = self.time + cfg.decision_interval * self.rng.uniform(
            0.5, 1.5, int(timed.sum())
        )
        x = scene.x[cand]
        speed = scene.speed[cand]
        lane = d.lane[cand].astype(np.int64)
        road = d.road[cand]
        own = d.idm(cand)
        idm_all = self._idm_with_defaults(scene.x.size - n)
        occupancy, x_all, length_all = scene.occupancy, scene.x, scene.length
        speed_all, accel_all = scene.speed, scene.accel

        # the old follower's acceleration once the candidate has left its lane
        ahead_now, behind_now = occupancy.around(road, lane, x)
        # room to reach the middle of the change behind the leader it still follows
        # until then (a vehicle in a standing queue cannot get across)
        low, high = cfg.lane_change_time
        half_path = 0.5 * np.maximum(speed, MIN_SPEED_PATH) * high
        gap_now = np.where(ahead_now >= 0, x_all[ahead_now] - x - length_all[cand], np.inf)
        lead_now = np.where(ahead_now >= 0, speed_all[ahead_now], 0.0)
        room = gap_now + lead_now * 0.5 * high >= half_path + MIN_LANE_CHANGE_GAP
        old_gap = np.where(
            (behind_now >= 0) & (ahead_now >= 0),
            x_all[ahead_now] - x_all[behind_now] - length_all[behind_now],
            np.inf,
        )
        old_follower_now = np.where(behind_now >= 0, accel_all[behind_now], 0.0)
        old_follower_after = np.where(
            behind_now >= 0,
            twin_idm_acceleration(
                speed_all[behind_now], speed_all[ahead_now], old_gap, idm_all.take(behind_now)
            ),
            0.0,
        )

        best = np.zeros(cand.size)
        choice = np.zeros(cand.size, dtype=np.int8)
        requested = d.requested[cand]
        for step in (LEFT, RIGHT):
            target = lane + step
            allowed = (
                (target <= -1) & (target >= -N_LANES) & self._hov_allows(cand, lane, target, x)
            )
            allowed &= (requested == 0) | (requested == step)
            if not allowed.any():
                continue
            ahead, behind = occupancy.around(road, target, x)
            gap_ahead = np.where(ahead >= 0, x_all[ahead] - x - length_all[cand], np.inf)
            gap_behind = np.where(behind >= 0, x - x_all[behind] - length_all[behind], np.inf)
            own_after = twin_idm_acceleration(speed, speed_all[ahead], gap_ahead, own)
            follower_after = np.where(
                behind >= 0,
                twin_idm_acceleration(speed_all[behind], speed, gap_behind, idm_all.take(behind)),
                0.0,
            )
            follower_now = np.where(behind >= 0, accel_all[behind], 0.0)
            params = d.mobil(cand)
            safe = (
                room
                & mobil_safe(follower_after, params)
                & (own_after >= -params.safe_decel)
                & (gap_ahead >= MIN_LANE_CHANGE_GAP)
                & (gap_behind >= MIN_LANE_CHANGE_GAP)
            )
            gain = mobil_incentive(
                accel_all[cand],
                own_after,
                follower_now,
                follower_after,
                old_follower_now,
                old_follower_after,
                np.full(cand.size, step == RIGHT),
                params,
            )
            gain = np.where(requested == step, np.inf, gain)
            better = allowed & safe & (gain > best)
            best[better] = gain[better]
            choice[better] = step
        movers = choice != 0
        if not movers.any():
            return
        index = cand[movers]
        duration = self.rng.uniform(low, high, index.size)
        d.lane_from[index] = d.lane[index]
        d.lane[index] = d.lane[index] + choice[movers]
        d.start_x[index] = center[index]
        d.start_y[index] = scene.y[index]
        d.path_length[index] = np.maximum(scene.speed[index], MIN_SPEED_PATH) * duration
        d.requested[index] = 0
        self.lane_changes += index.size

    def _hov_allows(self, cand, lane, target, x) -> np.ndarray:
        """(k,) bool: the move from ``lane`` to ``target`` keeps the HOV rule."""
        d = self._d
        crossing = (lane == HOV_LANE) | (target == HOV_LANE)
        opening = np.zeros(cand.size, dtype=bool)
        for x0, x1 in self.config.hov_openings:
            opening |= (x >= x0) & (x <= x1)
        entering_ok = (target != HOV_LANE) | d.hov_eligible[cand]
        return entering_ok & (~crossing | opening)

    def _idm_with_defaults(self, k: int) -> IDMParams:
        """IDM parameters of the vehicles followed by ``k`` obstacles with the mean
        driver's (obstacles are judged as if they drove like one)."""
        idm = self._d.idm()
        if k == 0:
            return idm
        return IDMParams(
            *(
                np.concatenate([getattr(idm, name), np.full(k, value)])
                for name, value in zip(IDM_FIELDS, self._mean_driver, strict=True)
            )
        )

    @cached_property
    def _mean_driver(self) -> tuple:
        """The IDM parameters of the class table's mean driver (for obstacles); read
        once: the table is fixed for a manager's life."""
        drivers = self.config.drivers
        share = self.classes.column("share")
        return (
            float(share @ self.classes.column("desired_speed_mps")),
            float(share @ self.classes.column("time_headway_s")),
            drivers.min_gap,
            float(share @ self.classes.column("max_accel_mps2")),
            drivers.comfortable_decel,
            drivers.delta,
        )

    # -- user controllers -------------------------------------------------------------

    def _ask_controllers(
        self, scene: _Scene, command: np.ndarray, need: np.ndarray, emergency: np.ndarray
    ):
        """The commands with the controllers' answers in; and (n,) bool, controlled.

        A controller with a true ``emergency_braking`` attribute is overridden by the
        drivers' emergency braking (``need`` where ``emergency``), as a production
        vehicle's safety layer would; the others get what they ask.
        """
        d = self._d
        command = command.copy()
        controlled = np.zeros(len(d), dtype=bool)
        for vehicle_id, controller in self._controllers.items():
            i = int(np.searchsorted(d.id, vehicle_id))
            controlled[i] = True
            name = getattr(controller, "__name__", type(controller).__name__)
            who = f"the controller {name} of vehicle {vehicle_id} at t = {self.time:.2f} s"
            try:
                answer = controller(self._observe(i, scene, float(command[i])))
            except Exception as error:
                raise ControllerError(f"{who} raised {error!r}") from error
            accel, lane_change = _parse_command(answer, who)
            if emergency[i] and getattr(controller, "emergency_braking", False):
                if -need[i] < accel:
                    self.safety_overrides += 1
                accel = min(accel, -float(need[i]))
            command[i] = accel
            if lane_change and d.lane_from[i] == d.lane[i] and d.requested[i] == 0:
                try:
                    self.force_lane_change(vehicle_id, lane_change)
                except ValueError:
                    self.refused_requests += 1
        return command, controlled

    def _observe(self, i: int, scene: _Scene, default_accel: float) -> Observation:
        d, n = self._d, scene.n
        x = float(scene.x[i])
        lanes = np.array(LANES, dtype=np.int64)
        road = np.full(lanes.size, d.road[i])
        ahead, behind = scene.occupancy.around(road, lanes, np.full(lanes.size, x))
        view = LaneView(
            lanes=LANES,
            leader_gap=np.where(ahead >= 0, scene.x[ahead] - x - d.length[i], np.inf),
            leader_speed=np.where(ahead >= 0, scene.speed[ahead], np.nan),
            follower_gap=np.where(behind >= 0, x - scene.x[behind] - scene.length[behind], np.inf),
            follower_speed=np.where(behind >= 0, scene.speed[behind], np.nan),
        )
        near = np.flatnonzero((scene.road == d.road[i]) & (np.abs(scene.x - x) <= NEIGHBOUR_RANGE))
        near = near[near != i]
        return Observation(
            time=self.time,
            id=int(d.id[i]),
            road=int(d.road[i]),
            lane=int(d.lane[i]),
            changing=bool(d.lane_from[i] != d.lane[i]),
            x=x,
            y=float(scene.y[i]),
            speed=float(scene.speed[i]),
            desired_speed=float(d.desired_speed[i]),
            default_accel=default_accel,
            lanes=view,
            neighbours={
                "id": np.where(near < n, d.id[np.minimum(near, n - 1)], -1),
                "dx": scene.x[near] - x,
                "y": scene.y[near],
                "speed": scene.speed[near],
            },
        )

    # -- helpers ----------------------------------------------------------------------

    def _index(self, ids) -> np.ndarray:
        ids = np.atleast_1d(np.asarray(ids, dtype=np.int64))
        where = np.searchsorted(self._d.id, ids)
        found = where < self._d.id.size
        found[found] = self._d.id[where[found]] == ids[found]
        if not found.all():
            raise KeyError(f"not a managed vehicle: {ids[~found].tolist()}")
        return where


def _wrap(angle: np.ndarray) -> np.ndarray:
    """Angles [rad] into [-pi, pi)."""
    return (angle + np.pi) % (2.0 * np.pi) - np.pi


def _lane_center(lane: np.ndarray) -> np.ndarray:
    """Road-frame y [m] of lane centres, for lanes already checked."""
    return (0.5 - lane) * LANE_WIDTH


def _check_speed(speed: np.ndarray) -> None:
    if not np.all(np.isfinite(speed)) or np.any(speed < 0):
        raise ValueError(f"desired speeds must be finite and >= 0 m/s, got {speed!r}")


def _check_mobil(params: MOBILParams) -> None:
    for name in MOBIL_FIELDS:
        value = np.asarray(getattr(params, name), dtype=np.float64)
        if not np.all(np.isfinite(value)) or np.any(value < 0):
            raise ValueError(f"MOBIL {name} must be finite and >= 0, got {value!r}")


def _direction(direction: int | str) -> int:
    named = {"left": LEFT, "right": RIGHT, "none": 0}
    if isinstance(direction, str):
        if direction.lower() not in named:
            raise ValueError(f"lane-change direction must be left, right or none: {direction!r}")
        return named[direction.lower()]
    if direction not in (LEFT, RIGHT, 0):
        raise ValueError(f"lane-change direction must be +1 (left), -1 (right) or 0: {direction!r}")
    return int(direction)


def _parse_command(answer, who: str) -> tuple[float, int]:
    """``(accel, lane_change)`` of a controller's answer; ``who`` names the controller,
    its vehicle and the time in the errors."""
    if isinstance(answer, EgoCommand):
        accel, lane_change = answer.accel, answer.lane_change
    else:
        accel, lane_change = answer, 0
    try:
        accel = float(accel)
    except (TypeError, ValueError):
        raise ControllerError(
            f"{who} returned {answer!r}, not an acceleration or an EgoCommand"
        ) from None
    if not math.isfinite(accel):
        raise ControllerError(f"{who} returned accel {accel}")
    try:
        return accel, _direction(lane_change)
    except ValueError as error:
        raise ControllerError(f"{who}: {error}") from None


def _dtype(name: str):
    if name in ("id", "vehicle_class"):
        return np.int64
    if name in ("road", "lane", "lane_from", "requested"):
        return np.int8
    if name in ("hov_eligible", "auto_lane_change"):
        return bool
    return np.float64
