"""The cosimulator: the paper's ghost-cell loop around an ego (steps 1 to 8 of ``docs/design.md``).

The ego and the recorded vehicles near it (the visible window, ``w_visible`` each side)
are physics bodies driven by the traffic manager; the recorded vehicles beyond them
(the ghost windows, ``w_ghost`` further each side) are never spawned: they are reloaded
from the data every step and are the boundary condition of the visible traffic. The
lead visible vehicle of each lane ahead of the ego takes the speed of the ghost ahead
of it, and every visible vehicle respects the ghosts as obstacles, so a recorded wave
reaches the ego through the simulated vehicles.

Lifecycle::

    sim = Cosimulator(config, traffic, map_bundle)
    sim.reset()              # steps 1 and 2: choose the ego, spawn ego and visible set
    while not sim.done:
        sim.step()           # steps 3 to 7
    log = sim.log            # every simulated vehicle every step, ghosts at a lower rate
    sim.close()

The cosimulator orchestrates: the world owns the bodies (``config.world``: the physics
world or the kinematic one, reached only through :class:`twin.physics.worlds.World`),
the manager the drivers, the data layer the recording. Vehicles are named by the
world's ids; the recorded vehicle each one was spawned from is kept beside it (its
``tid``), for the metrics.
"""

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from mapgen.build import MapBundle
from twin.core.i24 import LANES, lane_of
from twin.cosim.behaviour import Behaviour, resolve
from twin.cosim.config import CosimConfig
from twin.cosim.log import TrajectoryLog
from twin.cosim.strategic_targets import StrategicTargets
from twin.cosim.windows import Ghosts, ScenarioError, Windows, no_ghosts, road_limits
from twin.data.empirical import EmpiricalTraffic, RecordedVehicle, Snapshot
from twin.physics.states import MAX_SPEED, SpawnStates
from twin.physics.worlds import make_world
from twin.traffic.controller_api import EgoController, load_controller
from twin.traffic.manager import TrafficManager
from twin.traffic.scene import Obstacles, centre_y

AV_STREAM = 0x41565F  # seeds the AV draws apart from the run's other random choices
LATERAL_MARGIN = 0.5  # [m] two bodies closer than their half widths plus this share a lane
CLEARANCE_SPEED = 5.0  # [m/s] from this speed of the rear vehicle a spawn needs the full clearance


@dataclass
class Counters:
    """What happened in a run (the summary and ``metrics.json``)."""

    spawned: int = 0  # visible vehicles spawned after t0 (ghosts entering, new tracks)
    spawned_initially: int = 0  # the visible set at t0, ego excluded
    despawned: int = 0
    skipped_overlap: int = 0  # vehicles refused a spawn: a body was in the way (each is
    # tried again every step while inside the visible window)
    skipped_invalid: int = 0  # spawns refused: recorded state outside the lanes or too fast
    spawn_speed_error: list = field(default_factory=list)  # [-] relative, per spawn
    collisions: list = field(default_factory=list)  # (time [s], id, id) of new contacts
    off_road: set = field(default_factory=set)  # ids ever outside the four lanes
    ended: str = ""  # why the run ended before t_max ("" when it did not)


@dataclass
class StepTimes:
    """Wall time [s] of the loop's parts, summed over steps (for ``twin bench run``)."""

    steps: int = 0
    total: float = 0.0
    ghosts: float = 0.0  # step 7 (and 6's lookup): the data reload
    physics: float = 0.0
    manager: float = 0.0

    def per_step(self) -> dict:
        n = max(self.steps, 1)
        return {
            "step_ms": 1e3 * self.total / n,
            "ghost_reload_ms": 1e3 * self.ghosts / n,
            "physics_ms": 1e3 * self.physics / n,
            "manager_ms": 1e3 * self.manager / n,
        }


class Cosimulator:
    """One episode of the ghost-cell cosimulation (see the module doc).

    Args:
        config: the run's configuration.
        traffic: the recorded traffic (``EmpiricalTraffic`` over a store).
        bundle: the map (``mapgen.build.default_map()``).
        controller: a user's ego controller; default: ``config.ego_controller`` if
            set, else the traffic manager drives the ego.

    Raises:
        ControllerError: ``config.ego_controller`` cannot be imported.
    """

    def __init__(
        self,
        config: CosimConfig,
        traffic: EmpiricalTraffic,
        bundle: MapBundle,
        *,
        controller: EgoController | None = None,
    ):
        self.config = config
        self.traffic = traffic
        self.road = config.road
        self.direction = config.road.direction
        self.behaviour = Behaviour(
            resolve(config.behaviour, traffic.store, config.road, config.traffic.car_following),
            traffic.store,
            config.road,
            config.seed,
            config.traffic.car_following,
        )
        self.controller = controller or load_controller(config.ego_controller, config)
        self.world = make_world(config.world, bundle, config.dt)
        headings = {r: bundle.road.heading(r) for r in (1, -1)}
        self.manager = TrafficManager(config.traffic, headings)
        self.targets = StrategicTargets(self.behaviour, self.manager, config.seed)
        self.manager.set_keep_out(self.direction, self.behaviour.keep_out)
        self.limits = road_limits(bundle, traffic, config.road)
        self.counters = Counters()
        self.times = StepTimes()
        self.log: TrajectoryLog | None = None
        self.ego: RecordedVehicle | None = None
        self.ego_id = -1
        self.t0 = math.nan
        self.step_index = 0
        self.windows: Windows | None = None
        self._tids = np.empty(0, dtype=np.int64)  # recorded tid of each body, by world id
        self._base_speed = np.empty(0)  # [m/s] each body's own desired speed, by world id
        self._ghosts = no_ghosts()
        self._obstacles_now: Obstacles | None = None
        # per store tid: simulated now / a ghost after the last reload (O(1) lookups)
        n_tids = len(traffic.store.trajectory_arrays["id"])
        self._is_sim = np.zeros(n_tids, dtype=bool)
        self._is_ghost = np.zeros(n_tids, dtype=bool)
        self._seen = np.zeros(n_tids, dtype=bool)  # in the windows at some step before
        self._waiting = np.zeros(n_tids, dtype=bool)  # refused a spawn for lack of room
        self._lead_speed = dict.fromkeys(LANES, math.nan)  # smoothed ghost speed per lane
        self._just_spawned = (np.empty(0, np.int64), np.empty(0))  # ids, spawn speeds
        self._touching: set = set()
        self.av_ids: set[int] = set()  # world ids of the vehicles other than the ego with
        # the AV controller (config.av_share), kept after they leave the window

    # -- lifecycle --------------------------------------------------------------------

    def close(self) -> None:
        self.world.close()

    def __enter__(self) -> "Cosimulator":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    @property
    def done(self) -> bool:
        """True when the episode is over (t_max reached, or ended early)."""
        return self.step_index >= self.config.steps or bool(self.counters.ended)

    @property
    def t(self) -> float:
        """[s] unix time now."""
        return self.t0 + self.step_index * self.config.dt

    @property
    def sim_time(self) -> float:
        """[s] since t0."""
        return self.step_index * self.config.dt

    @property
    def simulated(self) -> np.ndarray:
        """(trajectories,) bool by store index: the recorded vehicles simulated now
        (read-only)."""
        view = self._is_sim.view()
        view.flags.writeable = False
        return view

    def records_of(self, ids) -> np.ndarray:
        """The I-24 MOTION ``_id`` of each simulated vehicle ``ids`` (twin ids)."""
        states = self.world.states()
        tids = self._tids[np.searchsorted(states.id, np.asarray(ids, np.int64))]
        return np.asarray(self.traffic.store.trajectory_arrays["id"])[tids]

    def reset(self) -> None:
        """Steps 1 and 2: the ego is the recorded vehicle closest to the requested lane,
        x and time; it and the recorded vehicles of the visible window are spawned at
        their recorded speeds; the ghost set is loaded.

        Raises:
            NoVehicleNearError: no recorded vehicle near the request.
            ScenarioError: the data do not cover the episode, or the request lies
                outside the map and data.
        """
        cfg = self.config
        lo, hi = self.limits
        if not lo <= cfg.x <= hi:
            raise ScenarioError(
                f"x = {cfg.x:g} m is outside the range where map and data both exist on "
                f"{self.road.value} ({lo:.0f} to {hi:.0f} m)"
            )
        ego = self.traffic.closest(self.road, cfg.lane, cfg.x, cfg.time)
        t_last = self.traffic.store.time_range(self.road)[1]
        if ego.t + cfg.t_max > t_last:
            raise ScenarioError(
                f"the episode would run to unix {ego.t + cfg.t_max:.2f} but the data on "
                f"{self.road.value} end at {t_last:.2f}; start earlier or shorten t_max"
            )
        self.ego, self.t0 = ego, ego.t
        self.traffic.preload(self.road, self.t0, self.t0 + cfg.t_max)
        self.behaviour.plan(self.traffic.store, self.t0, self.t0 + cfg.t_max)
        self.log = TrajectoryLog(self.t0, self.direction, cfg.dt)
        ego_state = _recorded_states(
            self.direction, [ego.x], [ego.y], [ego.speed], [ego.vehicle_class], [ego.length],
            [ego.width], [ego.height], [ego.tid],
        )  # fmt: skip
        self.ego_id = int(self._spawn(ego_state, desired_speed=cfg.vel_default)[0])
        self.av_ids.discard(self.ego_id)  # the ego's controller is set next
        if self.controller is not None:
            self.manager.set_controller(self.ego_id, self.controller)
            self.targets.removed([self.ego_id])
            _bind(self.controller, self)
        self.windows = Windows.around(ego.x, cfg.w_visible, cfg.w_ghost, self.limits)
        snap = self._snapshot()
        bounds = self.windows.bounds(snap.x)
        visible = np.arange(bounds[1], bounds[2])
        visible = visible[snap.tid[visible] != ego.tid]
        self.counters.spawned_initially = self._spawn_recorded(snap, visible)
        self._seen[snap.tid] = True
        self._load_ghosts(snap, bounds)
        states = self.world.states()
        self._record(states, np.zeros(len(states.id)))

    def step(self) -> None:
        """Steps 3 to 7: desired speeds, one physics step, despawn, spawn, ghost reload."""
        if self.log is None:
            raise RuntimeError("call reset() before step()")
        cfg, start = self.config, time.perf_counter()
        states = self.world.states()

        # 3. desired speeds (and the recorded lane changes due); 4. one step of
        # manager and physics
        self._set_desired_speeds(states)
        if self.targets.on and self.step_index % self.manager.decision_steps == 0:
            self.targets.update(states)
        tick = time.perf_counter()
        commands = self.manager.step(states, self._obstacles_now)
        self.world.set_controls(commands.id, accel=commands.accel, steer=commands.steer)
        tock = time.perf_counter()
        self.world.step()
        self.times.physics += time.perf_counter() - tock
        self.times.manager += tock - tick
        self.step_index += 1
        states = self.world.states()
        self._check_spawn_speeds(states, commands)
        self._check_contacts(states)

        ego_x = float(states.x[states.id == self.ego_id][0])
        lo, hi = self.limits
        if not lo <= ego_x <= hi:
            self.counters.ended = (
                f"the ego left the range of map and data (x = {ego_x:.1f} m) at "
                f"{self.sim_time:.2f} s"
            )
        self.windows = Windows.around(ego_x, cfg.w_visible, cfg.w_ghost, self.limits)

        # 5. visible vehicles now outside the visible window are removed
        out = ~self.windows.in_visible(states.x) & (states.id != self.ego_id)
        if out.any():
            gone = states.id[out]
            self.manager.remove(gone)
            self.world.despawn(gone)
            keep = np.ones(self._tids.size, dtype=bool)
            keep[np.searchsorted(states.id, gone)] = False  # _tids follow the world's ids
            self._is_sim[self._tids[~keep]] = False
            self._tids = self._tids[keep]
            self._base_speed = self._base_speed[keep]
            self.targets.removed(gone)
            self.counters.despawned += gone.size

        # 6. ghosts now inside the visible window are spawned; 7. the ghost set reloaded
        tick = time.perf_counter()
        snap = self._snapshot()
        bounds = self.windows.bounds(snap.x)
        # (and the recorded vehicles that first appear inside it: an on-ramp's merges,
        # tracks that begin there; and those refused for lack of room, tried again
        # until they fit or leave the window, so that a refusal leaves no lasting hole)
        inside = snap.tid[bounds[1] : bounds[2]]
        first_seen = ~(self._seen[inside] | self._is_sim[inside])
        new = self._is_ghost[inside] | first_seen
        new |= self._waiting[inside] & ~self._is_sim[inside]
        entering = new.nonzero()[0] + bounds[1]
        # a track that begins inside the window and finds a body in its way is not tried
        # again: in real data it is most often the next fragment of that very vehicle
        retry = ~first_seen[new.nonzero()[0]]
        self._seen[snap.tid] = True
        self.times.ghosts += time.perf_counter() - tick
        if entering.size:
            self.counters.spawned += self._spawn_recorded(snap, entering, retry)
        tick = time.perf_counter()
        self._load_ghosts(snap, bounds)
        self.times.ghosts += time.perf_counter() - tick

        if out.any() or entering.size:
            states = self.world.states()
        self._record(states, self._accel_of(states, commands))
        self.times.steps += 1
        self.times.total += time.perf_counter() - start

    def run(self, progress: bool = False, on_step: Callable[["Cosimulator"], None] | None = None):
        """Reset (if not done yet) and step to the end, with a progress bar if asked;
        ``on_step(self)`` is called after each step (and after a reset made here)."""
        from twin.core.progress import progress_bar

        if self.log is None:
            self.reset()
            if on_step is not None:
                on_step(self)
        with progress_bar(
            progress=progress,
            total=self.config.steps,
            initial=self.step_index,
            unit="step",
            desc=f"scenario {self.config.scenario}",
        ) as bar:
            while not self.done:
                self.step()
                if on_step is not None:
                    on_step(self)
                bar.update(1)

    # -- the paper's steps, in parts --------------------------------------------------

    def _snapshot(self) -> Snapshot:
        x0, x1 = self.windows.span
        return self.traffic.snapshot(self.road, self.t, x0, x1)

    def _load_ghosts(self, snap: Snapshot, bounds: tuple[int, int, int, int]) -> None:
        """Step 7: the recorded vehicles in the ghost windows that are not simulated."""
        a, b, c, d = bounds
        rows = np.concatenate((np.arange(a, b), np.arange(c, d)))
        rows = rows[~self._is_sim[snap.tid[rows]] & (snap.lane[rows] != 0)]
        self._is_ghost[self._ghosts.tid] = False
        self._ghosts = Ghosts.take(snap, rows)
        self._is_ghost[self._ghosts.tid] = True
        self._obstacles_now = self._obstacles()
        if self.step_index % self.config.ghost_log_every == 0:
            self.log.add_ghosts(self.sim_time, self._ghosts)

    def _obstacles(self) -> Obstacles:
        """The ghosts as the manager's obstacles (built directly: the store's data were
        validated at ingest, and ``Obstacles.make``'s checks cost more than the reload)."""
        g = self._ghosts
        k = len(g)
        return Obstacles(
            road=np.full(k, self.direction, dtype=np.int8),
            lane=g.lane,
            x=g.x,
            length=g.length,
            speed=g.speed,
            accel=np.zeros(k),
        )

    def _set_desired_speeds(self, states) -> None:
        """Step 3: each vehicle's own desired speed (vel_default in the paper's
        behaviour) for all but the lead visible vehicle of each lane ahead of the ego,
        which takes the speed of the ghost ahead of it (its own if none; in the
        calibrated behaviours the larger of the two, see ``Behaviour.lead_chases_ghost``)."""
        desired = self._base_speed.copy()
        lanes = self.manager.lanes(states.id)
        ego_x = states.x[states.id == self.ego_id][0]
        ahead = (states.id != self.ego_id) & (states.x > ego_x)
        g = self._ghosts
        for lane in LANES:
            rows = np.flatnonzero(ahead & (lanes == lane))
            if rows.size == 0:
                self._lead_speed[lane] = math.nan
                continue
            lead = rows[np.argmax(states.x[rows])]
            beyond = np.flatnonzero((g.lane == lane) & (g.x > states.x[lead]))
            target = (
                float(g.speed[beyond[np.argmin(g.x[beyond])]])
                if beyond.size
                else float(desired[lead])
            )
            if self.behaviour.lead_chases_ghost:
                target = max(target, float(desired[lead]))
            desired[lead] = self._smooth(lane, target)
        self.manager.set_desired_speed(states.id, desired)

    def _smooth(self, lane: int, target: float) -> float:
        """The optional first-order lag on a lane lead's ghost speed."""
        tau, previous = self.config.ghost_smoothing, self._lead_speed[lane]
        if tau > 0 and math.isfinite(previous):
            target = previous + min(1.0, self.config.dt / tau) * (target - previous)
        self._lead_speed[lane] = target
        return target

    def _spawn_recorded(self, snap: Snapshot, rows: np.ndarray, retry=None) -> int:
        """Step 6 (and 2): spawn the recorded vehicles ``rows`` of ``snap`` where they
        fit; count the ones skipped, and mark those refused for lack of room to be tried
        again (where ``retry``, (k,) bool, says so; all by default). Returns how many
        were spawned."""
        if rows.size == 0:
            return 0
        retry = np.ones(rows.size, dtype=bool) if retry is None else np.asarray(retry, bool)
        order = np.argsort(snap.x[rows], kind="stable")
        rows, retry = rows[order], retry[order]
        valid = np.isin(snap.lane[rows], LANES) & (snap.speed[rows] <= MAX_SPEED)
        self.counters.skipped_invalid += int(np.count_nonzero(~valid))
        rows, retry = rows[valid], retry[valid]
        states = self.world.states()
        params = self.world.params
        body = {
            "x": states.x,
            "length": params.length,
            "y": states.y,
            "width": params.width,
            "speed": np.maximum(states.speed, 0.0),
        }
        # a body changing lanes holds its new lane too: nothing is spawned beside it there
        changing = self.manager.changing(states.id)
        if changing.any():
            body = {name: np.concatenate((v, v[changing])) for name, v in body.items()}
            body["y"][-int(changing.sum()) :] = centre_y(self.manager.lanes(states.id[changing]))
        accepted = []
        for i in rows:
            if self._fits(snap, i, body):
                accepted.append(i)
                for name in body:
                    body[name] = np.append(body[name], getattr(snap, name)[i])
        accepted = np.array(accepted, dtype=np.int64)
        refused_rows = ~np.isin(rows, accepted)
        refused = snap.tid[rows[refused_rows]]
        # counted once per vehicle, at its first refusal; tried again each step
        self.counters.skipped_overlap += int(np.count_nonzero(~self._waiting[refused]))
        self._waiting[refused[retry[refused_rows]]] = True
        if not accepted.size:
            return 0
        self._waiting[snap.tid[accepted]] = False
        new = _recorded_states(
            self.direction, snap.x[accepted], snap.y[accepted], snap.speed[accepted],
            snap.vehicle_class[accepted], snap.length[accepted], snap.width[accepted],
            snap.height[accepted], snap.tid[accepted],
        )  # fmt: skip
        self._spawn(new, desired_speed=self.config.vel_default)
        return accepted.size

    def _fits(self, snap: Snapshot, i: int, body: dict) -> bool:
        """Whether recorded vehicle ``i`` can be spawned among the bodies: no body within
        :func:`spawn_room` ahead or behind, among those that overlap it laterally."""
        cfg = self.config
        x, length, speed = snap.x[i], snap.length[i], snap.speed[i]
        side = np.abs(body["y"] - snap.y[i]) < 0.5 * (body["width"] + snap.width[i]) + (
            LATERAL_MARGIN
        )
        if not side.any():
            return True
        bx, bl, bv = body["x"][side], body["length"][side], body["speed"][side]
        ahead = bx >= x
        gap = np.where(ahead, bx - (x + length), x - (bx + bl))
        closing = np.where(ahead, speed**2 - bv**2, bv**2 - speed**2)
        rear_speed = np.where(ahead, speed, bv)
        return bool(np.all(gap >= spawn_room(cfg, rear_speed, closing)))

    def _spawn(self, new: "_Recorded", *, desired_speed: float) -> np.ndarray:
        ids = self.world.spawn(new.spawn)
        lanes = lane_of(new.spawn.y)
        self.manager.add(
            ids,
            np.full(ids.size, self.direction),
            lanes,
            self.world.params_of(ids),
            desired_speed=desired_speed,
        )
        drivers = self.behaviour.drivers(new.tid, new.spawn.vehicle_class, lanes)
        base = drivers.pop("desired_speed", np.full(ids.size, desired_speed))
        if drivers:
            self.manager.set_params(ids, **drivers)
        if not self.behaviour.auto_lane_change:
            self.manager.set_auto_lane_change(ids, False)
        self.targets.added(ids, new.tid, lanes, new.spawn.x)
        for i, tid in zip(ids.tolist(), new.tid.tolist(), strict=True):
            if self._is_av(tid):
                av = load_controller(self.config.ego_controller, self.config)
                self.manager.set_controller(i, av)
                _bind(av, self)
                self.av_ids.add(i)
                self.targets.removed([i])  # its controller decides its lane changes
        self._base_speed = np.concatenate([self._base_speed, base])
        self._tids = np.concatenate([self._tids, new.tid])
        self._is_sim[new.tid] = True
        ids_before, speeds_before = self._just_spawned
        self._just_spawned = (
            np.concatenate([ids_before, ids]),
            np.concatenate([speeds_before, new.spawn.speed]),
        )
        return ids

    def _is_av(self, tid: int) -> bool:
        """Whether recorded vehicle ``tid`` is driven by the AV controller
        (``config.av_share``): one draw from the seed and the record, whatever the
        spawn order."""
        share = self.config.av_share
        if share <= 0:
            return False
        draw = np.random.default_rng([self.config.seed, int(tid), AV_STREAM]).random()
        return bool(draw < share)

    # -- checks and records -----------------------------------------------------------

    def _check_spawn_speeds(self, states, commands) -> None:
        """Relative speed error of the vehicles spawned before this step, one step after
        the impulse: |v - max(v_spawn + a_commanded dt, 0)| / max(v_spawn, 1 m/s)."""
        ids, spawn_speed = self._just_spawned
        if ids.size == 0:
            return
        at = np.searchsorted(states.id, ids)
        accel = commands.accel[np.searchsorted(commands.id, ids)]
        expected = np.maximum(spawn_speed + accel * self.config.dt, 0.0)  # brakes hold at 0
        error = np.abs(states.speed[at] - expected) / np.maximum(spawn_speed, 1.0)
        self.counters.spawn_speed_error.extend(error.tolist())
        self._just_spawned = (np.empty(0, np.int64), np.empty(0))

    def _check_contacts(self, states) -> None:
        """New body contacts between vehicles are collisions; vehicles outside the four
        lanes (or on the other road) are off the road."""
        pairs = self.world.vehicle_contacts()
        touching = set(map(tuple, pairs.tolist()))
        for a, b in sorted(touching - self._touching):
            self.counters.collisions.append((self.sim_time, a, b))
        self._touching = touching
        off = (states.lane == 0) | (states.road != self.direction)
        if off.any():
            self.counters.off_road.update(states.id[off].tolist())

    def _accel_of(self, states, commands) -> np.ndarray:
        """The commanded accelerations in the order of ``states`` (0 for new vehicles)."""
        accel = np.zeros(states.id.size)
        if commands.id.size:
            at = np.minimum(np.searchsorted(commands.id, states.id), commands.id.size - 1)
            hit = commands.id[at] == states.id
            accel[hit] = commands.accel[at[hit]]
        return accel

    def _record(self, states, accel: np.ndarray) -> None:
        # _tids follow the world's ids, and so do the states
        self.log.add_vehicles(self.sim_time, states, self._tids, self.ego_id, accel)
        self.log.add_windows(self.sim_time, self.windows)


@dataclass(frozen=True)
class _Recorded:
    spawn: SpawnStates
    tid: np.ndarray


def _recorded_states(road, x, y, speed, vehicle_class, length, width, height, tid) -> _Recorded:
    return _Recorded(
        SpawnStates.make(road, x, y, speed, vehicle_class, length, width, height),
        np.asarray(tid, dtype=np.int64),
    )


def spawn_room(cfg: CosimConfig, rear_speed: np.ndarray, closing: np.ndarray) -> np.ndarray:
    """[m] bumper-to-bumper room a spawn needs to a body in its lane: the clearance,
    ``spawn_clearance_at_rest`` for a rear vehicle at rest growing to ``spawn_clearance``
    at ``CLEARANCE_SPEED`` and above (a standing queue is spawned as recorded, its gaps
    are often under 2 m), plus the difference of braking distances at ``spawn_decel``
    (``closing`` = v_rear^2 - v_front^2)."""
    share = np.clip(np.asarray(rear_speed) / CLEARANCE_SPEED, 0.0, 1.0)
    clearance = cfg.spawn_clearance_at_rest + share * (
        cfg.spawn_clearance - cfg.spawn_clearance_at_rest
    )
    return clearance + np.maximum(closing, 0.0) / (2.0 * cfg.spawn_decel)


def _bind(controller, sim: "Cosimulator") -> None:
    """Hand the simulation to a controller that asks for it with a ``bind(sim)``
    method (e.g. to read the recorded traffic ahead, as a connected vehicle could)."""
    bind = getattr(controller, "bind", None)
    if callable(bind):
        bind(sim)
