"""The batched core's Python side: what a batch shares (:class:`Shared`: the recording,
the vehicles' parameters, the behaviour, the settings, made once per process and
configuration) and a batch of episodes stepped together in one kernel call
(:class:`Batch`).

::

    shared = Shared.make(store, bundle, config)        # once per process and config
    batch = Batch(shared, episodes=256)
    batch.reset(0, lane=-1, x=700.0, time=t, seed=3)    # steps 1 and 2 of episode 0
    while not batch.done.all():
        batch.step()                                     # steps 3 to 7 of every episode
    log = batch.log(0)                                   # its rows, for the metrics

The kernels are in :mod:`twin.cosim.core.step`; this module checks what it is given,
names what goes wrong, and turns an episode's arrays into the trajectory log the
metrics read.
"""

import math
from dataclasses import dataclass, replace

import numpy as np

from twin.core.errors import TwinError
from twin.core.i24 import Road
from twin.core.ramps import OPENING, RAMP_LANE
from twin.cosim.core import drivers as behaviour_kernels
from twin.cosim.core import layout, step
from twin.cosim.windows import ScenarioError, road_limits
from twin.data import recording as recording_module
from twin.physics import kernels as physics
from twin.traffic.kernels import state as kinds
from twin.traffic.kernels.decide import settings as traffic_settings

SLOTS = 256  # vehicles an episode can hold at once (the visible window's)
GHOSTS = 128  # ghosts an episode can hold at once
SNAPSHOT = 1024  # recorded vehicles in an episode's windows at once
TABLE = 4096  # recorded vehicles an episode can meet (a power of two)


class CoreError(TwinError):
    """The batched core cannot run what it was given (a controller it has no kernel
    for, an episode that outgrew a capacity, a bad action)."""


#: Controllers the core drives itself, by their ``module:function`` names.
COMPILED = {
    "": kinds.DRIVER,
    "twin.controllers:human": kinds.HUMAN,
    "twin.controllers:follower_stopper": kinds.FOLLOWER_STOPPER,
    "twin.controllers:acc": kinds.ACC,
}


def controller_kind(spec: str, guarded: bool) -> int:
    """The ``ctrl`` kind of controller ``spec`` (``""``: the traffic manager), with the
    safety layer where ``guarded`` and the controller has one; PYTHON where the core
    has no kernel for it."""
    kind = COMPILED.get(spec, kinds.PYTHON)
    if guarded and kind in (kinds.FOLLOWER_STOPPER, kinds.ACC):
        kind += kinds.GUARDED
    return kind


@dataclass(frozen=True, eq=False)
class Shared:
    """What every episode of a batch shares (see the module doc).

    Attributes:
        config: the cosimulation's configuration (its road, windows, behaviour,
            controller, traffic, step); episodes change only their place, time, seed
            and length.
        store, bundle, traffic: the recording's store, the map, the recorded traffic
            (``EmpiricalTraffic``, for the metrics).
        recording: the road's :class:`~twin.data.recording.RecordingArrays`.
        params: (R, 14) the physical parameters of every recorded trajectory's body.
        behaviour: the :class:`~twin.cosim.behaviour.Behaviour` and its arrays.
        settings: the kernels' :data:`~twin.cosim.core.step.CoreSettings`.
        traffic_settings: the traffic kernels' :data:`~twin.traffic.kernels.decide.
            TrafficSettings`.
        limits: [m] where map and data both exist on the road.
    """

    config: object
    store: object
    bundle: object
    traffic: object
    recording: object
    params: np.ndarray
    behaviour: object
    behaviour_arrays: object
    settings: object
    traffic_settings: object
    limits: tuple[float, float]

    @classmethod
    def make(cls, store, bundle, config, *, traffic=None, action: str = "accel") -> "Shared":
        """The shared part of batches of ``config`` on ``store`` and the map ``bundle``
        (``action``: what an env's action is, ``accel`` or ``speed``).

        Raises:
            BehaviourError: the behaviour needs a calibration the store lacks.
            ScenarioError: the map and the data do not overlap on the road.
        """
        from twin.cosim.behaviour import Behaviour, resolve, with_car_following
        from twin.data.empirical import EmpiricalTraffic
        from twin.traffic.models import car_following_model

        config = with_car_following(config, store)  # auto: the calibration's model
        traffic = traffic or EmpiricalTraffic(store)
        road = config.road
        name = resolve(config.behaviour, store, road, config.traffic.car_following)
        beh = Behaviour(name, store, road, config.seed, config.traffic.car_following)
        rec = recording_module.load_recording(store, road)
        params = vehicle_table(rec)
        plan = recorded_plan(store, road, rec) if name == "recorded" else None
        arrays = behaviour_kernels.behaviour_arrays(beh, config.traffic, rec, plan)
        limits = road_limits(bundle, traffic, road)
        model = car_following_model(config.traffic.car_following)
        mean = _mean_driver(config.traffic, model)
        guarded = config.controller.emergency_braking
        ego = controller_kind(config.ego_controller, guarded)
        cs = step.CoreSettings(
            dt=float(config.dt), limit_lo=float(limits[0]), limit_hi=float(limits[1]),
            w_visible=float(config.w_visible), w_ghost=float(config.w_ghost),
            vel_default=float(config.vel_default), ghost_smoothing=float(config.ghost_smoothing),
            clearance=float(config.spawn_clearance),
            clearance_at_rest=float(config.spawn_clearance_at_rest),
            spawn_decel=float(config.spawn_decel), av_share=float(config.av_share),
            av_controller=ego if config.av_share > 0 else kinds.DRIVER, ego_controller=ego,
            lead_chases_ghost=beh.lead_chases_ghost,
            targets=name == "recorded" or beh.strategic_flows is not None,
            kinematic=config.world == "kinematic",
            profile=physics.profile(bundle.road, road.direction),
            fuel=physics.fuel_coefficients(), relax=bool(config.relax), anchor=bool(config.anchor),
            merges=merges(bundle.road, road),
        )  # fmt: skip
        zones = [(z["lane"], z["x0"], z["x1"]) for z in beh.keep_out]
        # a driver who has not merged waits where a change from a stop (an urgent
        # change's shortest path) still crosses into lane -4 before the taper's end
        ends = [(RAMP_LANE, end - 0.5 * config.traffic.urgent_path) for *_, end in cs.merges]
        # lane -4's yielding to merges as the recording's drivers yield, where asked
        drive = config.traffic
        if drive.calibrated_yielding:
            drive = replace(drive, **beh.cooperation)
        # no passing on the right where the recording's drivers do not pass there
        if drive.calibrated_passing:
            drive = replace(drive, **beh.passing)
        # a lane change in front of a recording leaves it a spawn's room, so that the
        # recording can be made a body that brakes behind it
        ts = traffic_settings(
            drive, mean, keep_out=zones, lane_ends=ends, controller=config.controller,
            action=action, obstacle_clearance=config.spawn_clearance,
            obstacle_clearance_at_rest=config.spawn_clearance_at_rest,
        )  # fmt: skip
        return cls(config, store, bundle, traffic, rec, params, beh, arrays, cs, ts, limits)

    def with_controllers(self, kind: int) -> "Shared":
        """The same with the ego (and the AVs, where ``av_share`` > 0) driven by the
        controller ``kind`` (a ``ctrl`` kind)."""
        av = kind if self.config.av_share > 0 else kinds.DRIVER
        settings = self.settings._replace(ego_controller=kind, av_controller=av)
        return replace(self, settings=settings)


def _mean_driver(config, model) -> np.ndarray:
    """(N_PARAMS,) the class table's mean driver in the model's parameters (obstacles
    are judged as if they drove like one; :func:`twin.traffic.drivers.mean_driver_row`,
    as the traffic manager's)."""
    from twin.core.vehicle_classes import vehicle_classes
    from twin.traffic.drivers import mean_driver_row

    return mean_driver_row(config.drivers, model, vehicle_classes())


_TABLES: dict = {}


def merges(road_model, road) -> np.ndarray:
    """(k, 4) [m] the on-ramps of ``road`` in the map's ``road_model``, by x: where each
    acceleration lane's pavement opens, its gore, the start of its taper and its end
    (:data:`~twin.cosim.core.step.CoreSettings`' ``merges``)."""
    rows = sorted(
        (r.x_start - OPENING, r.x_start, r.x_taper, r.x_end)
        for r in road_model.ramps
        if r.road == road
    )
    return np.array(rows, dtype=np.float64).reshape(-1, 4)


def vehicle_table(rec) -> np.ndarray:
    """(R, 14) :data:`twin.physics.kernels.PARAMETERS` of every trajectory's body (the
    class table's, scaled to its recorded size), once per recording and process."""
    from twin.core.vehicle_classes import vehicle_classes
    from twin.physics.vehicle import VehicleParams

    key = id(rec.tid)
    if key not in _TABLES:
        params = VehicleParams.from_classes(
            vehicle_classes(), np.asarray(rec.vehicle_class), np.asarray(rec.length),
            np.asarray(rec.width), np.asarray(rec.height),
        )  # fmt: skip
        columns = physics.body_columns(params)
        _TABLES[key] = np.stack([np.asarray(columns[n], float) for n in physics.PARAMETERS], 1)
    return _TABLES[key]


_PLANS: dict = {}


def recorded_plan(store, road, rec) -> dict:
    """The recording's lane changes on ``road`` by trajectory (``recorded`` drives
    them): per recording index ``start`` offsets into ``x`` [m], ``time`` [s unix],
    ``lane_from`` and ``lane_to``, each trajectory's in x order. Once per process."""
    from twin.calibration import following

    key = (str(store.path), Road.parse(road).value)
    if key not in _PLANS:
        t0, t1 = store.time_range(road)
        changes = following.lane_changes(following.load_grid(store, road, t0, t1))
        local = np.full(int(max(rec.tid.max(initial=-1), changes.tid.max(initial=-1))) + 1, -1)
        local[np.asarray(rec.tid)] = np.arange(rec.tid.size)
        r = local[changes.tid]
        keep = r >= 0
        order = np.lexsort((changes.x[keep], r[keep]))
        r = r[keep][order]
        _PLANS[key] = {
            "start": np.searchsorted(r, np.arange(rec.tid.size + 1)).astype(np.int64),
            "x": changes.x[keep][order].astype(np.float64),
            "time": changes.time[keep][order].astype(np.float64),
            "lane_from": changes.lane_from[keep][order].astype(np.int64),
            "lane_to": changes.lane_to[keep][order].astype(np.int64),
            "merge_x": _merge_places(store, road, t0, t1, local, rec.tid.size),
        }
    return _PLANS[key]


def _merge_places(store, road, t0, t1, local, trajectories) -> np.ndarray:
    """(R,) [m] each recorded trajectory's merge place from an on-ramp (back x at its
    lane -4 sample after its last lane -5 one;
    :func:`twin.calibration.merge_positions.recorded_merges`), nan where it has none."""
    from twin.calibration.merge_positions import recorded_merges

    tid, x, _ = recorded_merges(store.samples(road, t0, t1, ramps=True))
    out = np.full(trajectories, np.nan)
    inside = tid < local.size
    r = local[tid[inside]]
    out[r[r >= 0]] = x[inside][r >= 0]
    return out


@dataclass(frozen=True)
class Placement:
    """Where an episode's ego was placed: the recorded vehicle closest to the request."""

    r: int
    tid: int
    t0: float
    x: float
    y: float
    speed: float


class Batch:
    """``episodes`` episodes of one :class:`Shared` configuration, stepped together.

    Args:
        shared: what the episodes share.
        episodes: how many (B).
        log: keep every step's rows (for the metrics; training keeps none).
        slots: vehicles an episode holds at once (:data:`SLOTS`).
        ghosts: ghosts an episode holds at once (:data:`GHOSTS`).
        snapshot: recorded vehicles in an episode's windows at once (:data:`SNAPSHOT`).
        table: recorded vehicles an episode can meet, a power of two (:data:`TABLE`).
    """

    def __init__(self, shared: Shared, episodes: int, *, log: bool = True, slots: int = SLOTS,
                 ghosts: int = GHOSTS, snapshot: int = SNAPSHOT, table: int = TABLE):  # fmt: skip
        self.shared = shared
        cfg = shared.config
        self.size = int(episodes)
        self.max_steps = cfg.steps
        self.state = layout.make_state(
            self.size, slots, ghosts, snapshot, table, cfg.steps if log else 0,
            cfg.ghost_log_every,
        )  # fmt: skip
        self.core = layout.pack(
            self.state, shared.settings, shared.traffic_settings, shared.recording,
            shared.params, shared.behaviour_arrays,
        )  # fmt: skip
        self.actions = self.state.actions
        self.placements: list[Placement | None] = [None] * self.size
        self._closest = tuple(np.empty(snapshot, t) for t in (np.int32, float, float, float))

    @property
    def done(self) -> np.ndarray:
        """(B,) bool: the episode is over (or was never reset)."""
        return self.state.episodes.done

    def place(self, lane: int, x: float, time: float, t_max: float) -> Placement:
        """Step 1: the recorded vehicle closest to ``lane``, ``x`` [m] and ``time`` [s].

        Raises:
            ScenarioError: ``x`` outside the map and data, or data ending before the
                episode would.
            NoVehicleNearError: no recorded vehicle near the request.
        """
        sh = self.shared
        lo, hi = sh.limits
        road = sh.config.road
        if not lo <= x <= hi:
            raise ScenarioError(
                f"x = {x:g} m is outside the range where map and data both exist on "
                f"{road.value} ({lo:.0f} to {hi:.0f} m)"
            )
        rec = sh.recording
        r, t0, ex, ey, ev = recording_module.closest_vehicle(
            sh.store, road, rec, lane, x, time, 50.0, 5.0, 10.0, self._closest
        )
        t_last = sh.store.time_range(road)[1]
        if t0 + t_max > t_last:
            raise ScenarioError(
                f"the episode would run to unix {t0 + t_max:.2f} but the data on "
                f"{road.value} end at {t_last:.2f}; start earlier or shorten t_max"
            )
        return Placement(int(r), int(rec.tid[r]), float(t0), float(ex), float(ey), float(ev))

    def reset(self, b: int, *, lane: int, x: float, time: float, seed: int,
              t_max: float | None = None) -> Placement:  # fmt: skip
        """Steps 1 and 2 of episode ``b``: its ego placed, the visible window spawned.

        Raises:
            ScenarioError, NoVehicleNearError: the ego cannot be placed (:meth:`place`).
            CoreError: ``b`` out of range, or ``t_max`` longer than the batch's log.
        """
        if not 0 <= b < self.size:
            raise CoreError(f"episode {b} is not in a batch of {self.size}")
        cfg = self.shared.config
        t_max = cfg.t_max if t_max is None else float(t_max)
        steps = math.ceil(t_max / cfg.dt - 1e-9)
        if self.state.log.on and steps > self.max_steps:
            raise CoreError(f"t_max {t_max} s is longer than the batch's log ({cfg.t_max} s)")
        placed = self.place(lane, x, time, t_max)
        step.reset_episode(b, self.core, int(seed), placed.t0, steps, placed.r, placed.x,
                           placed.y, placed.speed)  # fmt: skip
        self.placements[b] = placed
        self.check(b)
        return placed

    def step(self, actions: np.ndarray | None = None) -> None:
        """One step of every running episode; ``actions`` (B,) [m/s^2 or m/s] of the
        episodes whose ego an agent drives.

        Raises:
            CoreError: an action that is not finite (naming the episode and the value),
                or an episode that outgrew a capacity.
        """
        if actions is not None:
            actions = np.asarray(actions, dtype=np.float64).reshape(-1)
            if actions.size != self.size:
                raise CoreError(f"{actions.size} actions for a batch of {self.size}")
            bad = np.flatnonzero(~np.isfinite(actions) & ~self.done)
            if bad.size:
                raise CoreError(
                    f"episode {bad[0]}: the action {float(actions[bad[0]])} is not finite"
                )
            self.actions[:] = actions
        step.step_batch(self.core)
        if self.state.episodes.overflow.any():
            self.check(int(np.flatnonzero(self.state.episodes.overflow)[0]))

    def check_all(self) -> None:
        """Raise CoreError where an episode outgrew a capacity (the first, named)."""
        overflow = np.flatnonzero(self.state.episodes.overflow)
        if overflow.size:
            self.check(int(overflow[0]))

    def check(self, b: int) -> None:
        """Raise CoreError where episode ``b`` outgrew a capacity, naming which."""
        flags = int(self.state.episodes.overflow[b])
        if not flags:
            return
        what = [
            name
            for bit, name in (
                (
                    layout.SNAPSHOT_FULL,
                    f"more than {self.state.snap.r.shape[1]} recorded "
                    "vehicles in its windows (Batch snapshot=)",
                ),
                (
                    layout.TABLE_FULL,
                    f"more than {self.state.table.key.shape[1]} recorded "
                    "vehicles met (Batch table=)",
                ),
                (layout.PAIRS_FULL, "too many vehicles in contact at once"),
                (
                    layout.GHOSTS_FULL,
                    f"more than {self.state.ghosts.r.shape[1]} ghosts (Batch ghosts=)",
                ),
            )
            if flags & bit
        ]
        raise CoreError(f"episode {b} outgrew the batch: {'; '.join(what)}")
