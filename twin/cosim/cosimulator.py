"""The cosimulator: the paper's ghost-cell loop around an ego (steps 1 to 8 of ``docs/design.md``).

The ego and the recorded vehicles near it (the visible window, ``w_visible`` each side)
are simulated; the recorded vehicles beyond them (the ghost windows, ``w_ghost``
further each side) are never spawned: they are reloaded from the recording every step
and are the boundary condition of the visible traffic. The lead visible vehicle of
each lane ahead of the ego takes the speed of the ghost ahead of it, and every visible
vehicle respects the ghosts as obstacles, so a recorded wave reaches the ego through
the simulated vehicles.

Lifecycle::

    sim = Cosimulator(config, traffic, map_bundle)
    sim.reset()              # steps 1 and 2: choose the ego, spawn ego and visible set
    while not sim.done:
        sim.step()           # steps 3 to 7
    log = sim.log            # every simulated vehicle every step, ghosts at a lower rate
    sim.close()

One traffic logic for both worlds: the loop itself (hand-overs, ghost replay, desired
speeds, the traffic manager's decisions, the controllers the core knows) is the batched
core's compiled kernels (:mod:`twin.cosim.core`) with one episode. The kinematic world
is the core's own integration; in the physics world pybullet integrates what the
kernels decide (:class:`twin.physics.world.PhysicsWorld`, reached through
:class:`twin.physics.worlds.World`): every step the bodies' commands go to pybullet,
its states come back into the core, and the core's spawns and removals become bodies.
A user's Python controller is called between the decision and the world's step.

Over 500 lines: the loop, the pybullet bridge, the log's conversion and the views the
runners read; issue 78 splits it along those lines.
"""

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from mapgen.build import MapBundle
from twin.core.i24 import HOV_LANE, N_LANES
from twin.cosim.behaviour import with_car_following
from twin.cosim.config import CosimConfig
from twin.cosim.core import layout
from twin.cosim.core import step as core_step
from twin.cosim.core.batch import Batch, Shared, controller_kind
from twin.cosim.core.drawn import Drawn, drawn
from twin.cosim.core.room import CLEARANCE_SPEED
from twin.cosim.log import TrajectoryLog
from twin.cosim.windows import Ghosts, Windows
from twin.data.empirical import EmpiricalTraffic, RecordedVehicle
from twin.physics.states import SpawnStates, VehicleStates, quaternion_of
from twin.traffic.controlled import apply_controllers
from twin.traffic.controller_api import load_controller
from twin.traffic.kernels import state as kinds


@dataclass
class Counters:
    """What happened in a run (the summary and ``metrics.json``)."""

    spawned: int = 0  # visible vehicles spawned after t0 (ghosts entering, new tracks)
    spawned_initially: int = 0  # the visible set at t0, ego excluded
    despawned: int = 0
    skipped_overlap: int = 0  # vehicles refused a spawn: a body was in the way (each is
    # tried again every step while inside the visible window)
    skipped_invalid: int = 0  # spawns refused: recorded state outside the lanes or too fast
    skipped_full: int = 0  # spawns refused: every vehicle slot of the episode was taken
    yielded: int = 0  # recorded vehicles made relaxing bodies behind one they crowded
    held: int = 0  # recorded vehicles held back from appearing as ghosts on bodies
    anchored: int = 0  # bodies ended and drawn on as their recordings anchored (anchor)
    anchors_full: int = 0  # bodies ended unanchored: the episode's anchor list was full
    ghosts_braked: int = 0  # ghosts drawn braking for a body they could not stop behind
    spawn_speed_error: list = field(default_factory=list)  # [-] relative, per spawn
    collisions: list = field(default_factory=list)  # the new contacts (layout.CONTACT_COLUMNS)
    # kept (a collision is a pair: twin.metrics.collisions counts them)
    contacts: int = 0  # new contacts, also past the first COLLISIONS_KEPT listed above
    collisions_unlisted: int = 0  # contacts past those listed, of pairs not listed
    off_road: int = 0  # vehicles ever outside the four lanes
    ended: str = ""  # why the run ended before t_max ("" when it did not)


@dataclass
class StepTimes:
    """Wall time [s] of the loop's parts, summed over steps (for ``twin bench run``)."""

    steps: int = 0
    total: float = 0.0
    ghosts: float = 0.0  # steps 5 to 7: the hand-overs and the ghost reload
    physics: float = 0.0
    manager: float = 0.0  # the traffic's decisions (and the controllers)

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
        shared: what the core shares between episodes of this configuration (made
            here when not given; a runner of many episodes makes it once).
        ego_kind: who drives the ego, as a ``ctrl`` kind of
            :mod:`twin.traffic.kernels.state` (the env's agent: ACTION); default: from
            the controller.
        log: keep the trajectory log (the env keeps none).

    Raises:
        ControllerError: ``config.ego_controller`` cannot be imported.
        BehaviourError: the behaviour needs a calibration the store lacks.
    """

    def __init__(
        self,
        config: CosimConfig,
        traffic: EmpiricalTraffic,
        bundle: MapBundle,
        *,
        controller=None,
        shared: Shared | None = None,
        ego_kind: int | None = None,
        log: bool = True,
    ):
        config = with_car_following(config, traffic.store)  # auto: the calibration's model
        self.config = config
        self.traffic = traffic
        self.road = config.road
        self.direction = config.road.direction
        compiled = controller is None and config.ego_controller in _compiled_specs()
        self.controller = (
            None if compiled else (controller or load_controller(config.ego_controller, config))
        )
        kind = (
            controller_kind(config.ego_controller, config.controller.emergency_braking)
            if compiled
            else (kinds.PYTHON if self.controller is not None else kinds.DRIVER)
        )
        if ego_kind is not None:
            kind, self.controller = ego_kind, None
        self.shared = shared or Shared.make(traffic.store, bundle, config, traffic=traffic)
        self.shared = self.shared.with_controllers(kind)
        self.behaviour = self.shared.behaviour
        self.batch = Batch(self.shared, 1, log=log)
        self.keeps_log = log
        self.state, self.core = self.batch.state, self.batch.core
        if config.world == "physics":
            from twin.physics.world import PhysicsConfig, PhysicsWorld

            self.world = PhysicsWorld(bundle, PhysicsConfig(dt=config.dt))
        else:
            self.world = CoreWorld(self, bundle)
        self._heading = {r: bundle.road.heading(r) for r in (1, -1)}
        self.manager = TrafficView(self)
        self.limits = self.shared.limits
        self.counters = Counters()
        self.times = StepTimes()
        self.log: TrajectoryLog | None = None
        self.ego: RecordedVehicle | None = None
        self.ego_id = -1
        self.t0 = math.nan
        self.windows: Windows | None = None
        self._controllers: dict[int, object] = {}  # world id -> Python controller
        self._bodies = np.empty(0, np.int64)  # ids of the pybullet bodies
        self._body_slots = np.empty(0, np.int64)
        self._core_key: np.ndarray | None = None  # the core's slot ids at the last mirror
        self._last_collisions = 0

    # -- lifecycle --------------------------------------------------------------------

    def close(self) -> None:
        self.world.close()

    def __enter__(self) -> "Cosimulator":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    @property
    def step_index(self) -> int:
        """Steps taken since the reset."""
        return int(self.state.episodes.step[0])

    @property
    def done(self) -> bool:
        """True when the episode is over (t_max reached, or ended early)."""
        return self.log is not None and bool(self.state.episodes.done[0])

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
        """(trajectories,) bool by store index: the recorded vehicles simulated now."""
        out = np.zeros(len(self.traffic.store.trajectory_arrays["id"]), dtype=bool)
        bo = self.state.bodies
        out[self.state.slots.tid[0][bo.valid[0]]] = True
        return out

    @property
    def drawn(self) -> Drawn:
        """How the recording is drawn now beside its replay (:mod:`twin.cosim.core.drawn`:
        anchored vehicles' offsets, those held undrawn inside the windows), for the
        cameras."""
        trajectories = len(self.traffic.store.trajectory_arrays["id"])
        return drawn(self.state, np.asarray(self.shared.recording.tid), 0, trajectories)

    @property
    def av_ids(self) -> set[int]:
        """World ids of the vehicles other than the ego driven by the AV controller
        (``config.av_share``), kept after they leave the window."""
        return set(self._av_ids)

    def records_of(self, ids) -> np.ndarray:
        """The I-24 MOTION ``_id`` of each simulated vehicle ``ids`` (twin ids)."""
        return np.asarray(self.traffic.store.trajectory_arrays["id"])[self.tids_of(ids)]

    def tids_of(self, ids) -> np.ndarray:
        """(k,) the store tids of the simulated vehicles ``ids`` (twin ids).

        Raises:
            KeyError: an id that is not simulated now.
        """
        slots = self._slots_of(ids)
        return self.state.slots.tid[0][slots]

    @property
    def ghosts(self) -> Ghosts:
        """The ghost set now (store tids, lanes, x, y, speeds, lengths; by x)."""
        g = self.state.ghosts
        k = int(g.count[0])
        rec = self.shared.recording
        return Ghosts(
            np.asarray(rec.tid)[g.r[0, :k]].astype(np.int32), g.lane[0, :k].astype(np.int8),
            g.x[0, :k].copy(), g.y[0, :k].copy(), g.speed[0, :k].copy(), g.length[0, :k].copy(),
        )  # fmt: skip

    @property
    def tids(self) -> np.ndarray:
        """(n,) the store tids of the simulated vehicles, in the order of their ids
        (``world.ids``)."""
        return self.tids_of(self.manager.ids)

    def base_speeds(self, ids) -> np.ndarray:
        """(k,) [m/s] the own desired speeds of vehicles ``ids`` (before step 3's rule)."""
        return self.state.slots.base_speed[0][self._slots_of(ids)].copy()

    def spawn_speeds(self, ids) -> np.ndarray:
        """(k,) [m/s] the speeds vehicles ``ids`` were spawned at (their recordings')."""
        return self.state.slots.spawn_speed[0][self._slots_of(ids)].copy()

    def set_base_speeds(self, ids, speed) -> None:
        """Set the own desired speeds [m/s] of vehicles ``ids`` (experiments, tests)."""
        self.state.slots.base_speed[0][self._slots_of(ids)] = speed

    def rules(self, **changes) -> None:
        """Change settings of the loop the behaviour set (``lead_chases_ghost``, ...;
        the fields of :data:`twin.cosim.core.step.CoreSettings`), for experiments and
        tests: the core is packed again with them."""
        from dataclasses import replace

        self.shared = replace(self.shared, settings=self.shared.settings._replace(**changes))
        self.core = self.batch.core = layout.pack(
            self.state, self.shared.settings, self.shared.traffic_settings,
            self.shared.recording, self.shared.params, self.shared.behaviour_arrays,
        )  # fmt: skip

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
        placed = self.batch.reset(0, lane=cfg.lane, x=cfg.x, time=cfg.time, seed=cfg.seed)
        self.t0 = placed.t0
        self.ego = _placed_ego(self.shared, placed, self.road)
        self.ego_id = int(self.state.episodes.ego_id[0])
        self._av_ids: list[int] = []
        self.log = TrajectoryLog(self.t0, self.direction, cfg.dt)
        self._controllers.clear()
        if self.config.world == "physics" and self._bodies.size:
            self.world.clear()  # a second episode: the core numbers its vehicles from 0
        self._bodies = np.empty(0, np.int64)
        self._core_key = None
        self._mirror_bodies()
        self._take_controllers()
        self._synced = -1
        self._sync()

    def step(self) -> None:
        """Steps 3 to 7: desired speeds, one physics step, despawn, spawn, ghost reload."""
        if self.log is None:
            raise RuntimeError("call reset() before step()")
        if self.done:
            return
        start = time.perf_counter()
        core = self.core
        kinematic = self.config.world != "physics"
        if kinematic and not self._controllers:
            core_step.step_batch(core)
            tick = time.perf_counter()
            self.times.physics += tick - start
        else:
            core_step.before_world(0, core)
            self._apply_controllers()
            tick = time.perf_counter()
            self.times.manager += tick - start
            if kinematic:
                from twin.physics.kernels import integrate

                sh = self.shared
                accel = self.state.drivers.accel
                integrate(0, self.state.bodies, accel, self.state.scratch.steer, accel, accel,
                          sh.settings.profile, sh.settings.dt)  # fmt: skip
            else:
                self._physics_step()
            tock = time.perf_counter()
            self.times.physics += tock - tick
            core_step.after_world(0, core)
            self.times.ghosts += time.perf_counter() - tock
        self.batch.check(0)
        self._mirror_bodies()
        self._take_controllers()
        self._sync()
        self.times.steps += 1
        self.times.total += time.perf_counter() - start

    def run(self, progress: bool = False, on_step: Callable[["Cosimulator"], None] | None = None):
        """Reset (if not done yet) and step to the end, with a progress bar if asked;
        ``on_step(self)`` is called after each step (and after a reset made here). In
        the kinematic world with no Python controller and no ``on_step``, the core runs
        the episode's steps back to back and the log is read once at the end."""
        from twin.core.progress import progress_bar

        if self.log is None:
            self.reset()
            if on_step is not None:
                on_step(self)
        fast = self.config.world != "physics" and on_step is None and not self._python_kinds()
        with progress_bar(
            progress=progress,
            total=self.config.steps,
            initial=self.step_index,
            unit="step",
            desc=f"scenario {self.config.scenario}",
        ) as bar:
            if fast and not self.done:
                start = time.perf_counter()
                before = self.step_index
                while not self.state.episodes.done[0]:
                    core_step.step_batch(self.core)
                self.times.physics += time.perf_counter() - start
                self.times.total += time.perf_counter() - start
                self.times.steps += self.step_index - before
                self.batch.check(0)
                self._take_controllers()
                self._sync()
                bar.update(self.step_index - before)
            while not self.done:
                self.step()
                if on_step is not None:
                    on_step(self)
                bar.update(1)

    def _python_kinds(self) -> bool:
        """Whether a vehicle may be driven by a Python controller (the ego's, an AV's)."""
        cs = self.shared.settings
        kinds_used = (cs.ego_controller, cs.av_controller)
        return any(k % kinds.GUARDED == kinds.PYTHON for k in kinds_used)

    # -- the controllers a user wrote ---------------------------------------------------

    def _take_controllers(self) -> None:
        """A Python controller for every vehicle the core gives one and has none yet
        (the ego's is the run's; an AV's a fresh one of the same specification)."""
        bo, dr = self.state.bodies, self.state.drivers
        python = bo.valid[0] & (dr.ctrl[0] % kinds.GUARDED == kinds.PYTHON)
        for i in np.flatnonzero(python):
            vid = int(bo.id[0, i])
            if vid in self._controllers:
                continue
            if vid == self.ego_id:
                controller = self.controller
            else:
                controller = load_controller(self.config.ego_controller, self.config)
            self._controllers[vid] = controller
            bind = getattr(controller, "bind", None)
            if callable(bind):
                bind(self)
        for i in np.flatnonzero(bo.valid[0] & self.state.slots.av[0]):
            vid = int(bo.id[0, i])
            if vid not in self._av_ids:
                self._av_ids.append(vid)
        gone = [vid for vid in self._controllers if vid not in set(bo.id[0][bo.valid[0]].tolist())]
        for vid in gone:
            del self._controllers[vid]

    def _apply_controllers(self) -> None:
        """The Python controllers' commands (and lane changes asked for)
        (:func:`twin.traffic.controlled.apply_controllers`)."""
        if not self._controllers:
            return
        st = self.state
        slots = self._slots_of(list(self._controllers))
        relaxing = self.state.slots.relaxing[0]  # a relaxing vehicle tracks its recording
        by_slot = {s: c for s, c in zip(slots.tolist(), self._controllers.values(), strict=True)
                   if not relaxing[s]}  # fmt: skip
        traffic = kinds.Traffic(st.vehicles, st.obstacles, st.drivers, st.scratch,
                                self.shared.traffic_settings, st.counters, st.actions)  # fmt: skip
        overrides, refused = apply_controllers(
            by_slot, traffic, 0, st.bodies.id, st.ghosts.y, self.direction, self.sim_time,
            self._may_change,
        )  # fmt: skip
        st.counters.safety_overrides[0] += overrides
        st.counters.refused_requests[0] += refused

    def _may_change(self, i: int, step: int) -> bool:
        """Whether slot ``i`` may ever change one lane ``step`` (on the road, the HOV
        rule)."""
        dr = self.state.drivers
        lane = int(dr.lane[0, i])
        target = lane + step
        if not -N_LANES <= target <= -1:
            return False
        if target == HOV_LANE and not dr.hov_eligible[0, i]:
            return False
        return not (HOV_LANE in (target, lane) and not self.config.traffic.hov_openings)

    # -- the physics world under the kernels --------------------------------------------

    def _physics_step(self) -> None:
        """pybullet integrates the kernels' commands; its states come back into the core,
        its body contacts become the core's pairs."""
        st = self.state
        bo = st.bodies
        slots = self._body_slots
        self.world.set_controls(self._bodies, accel=st.drivers.accel[0, slots],
                                steer=st.scratch.steer[0, slots])  # fmt: skip
        self.world.step()
        states = self.world.states()
        same = np.array_equal(states.id, self._bodies)
        at = slots if same else self._slots_of(states.id)
        bo.x[0, at], bo.y[0, at] = states.x, states.y
        bo.speed[0, at], bo.yaw_rate[0, at] = states.speed, states.yaw_rate
        bo.yaw[0, at] = _wrap(states.heading - self._heading[self.direction])
        bo.drive_power[0, at] = states.drive_power
        from twin.physics.kernels import place_slots

        place_slots(0, at, bo, self.shared.settings.profile)  # the map's grade under them
        bo.z[0, at] = states.position[:, 2]  # the body's, not the map's
        bo.lane[0, at] = states.lane
        pairs = self.world.vehicle_contacts()
        k = min(len(pairs), st.pairs.shape[1])
        if len(pairs):
            st.pairs[0, :k, 0] = self._slots_of(pairs[:k, 0])
            st.pairs[0, :k, 1] = self._slots_of(pairs[:k, 1])
        st.episodes.pair_count[0] = k

    def _mirror_bodies(self) -> None:
        """Make the physics world's bodies the core's vehicles: remove those the core
        removed, spawn those it spawned (in id order, so the ids agree)."""
        if self.config.world != "physics":
            return
        bo = self.state.bodies
        valid = bo.valid[0]
        key = np.where(valid, bo.id[0], -1)
        if self._core_key is not None and np.array_equal(key, self._core_key):
            return  # the same vehicles in the same slots as at the last step
        ids = bo.id[0][valid]
        gone = np.setdiff1d(self._bodies, ids)
        if gone.size:
            self.world.despawn(gone)
        new = np.setdiff1d(ids, self._bodies)
        if new.size:
            slots = self._slots_of(new)
            made = self.world.spawn(
                SpawnStates.make(
                    self.direction, bo.x[0, slots], bo.y[0, slots], bo.speed[0, slots],
                    bo.vehicle_class[0, slots], bo.length[0, slots], bo.width[0, slots],
                    bo.height[0, slots],
                )
            )  # fmt: skip
            if not np.array_equal(made, new):
                raise RuntimeError(
                    f"the physics world named its bodies {made} where the core has {new}"
                )
        self._bodies = np.sort(ids)
        self._body_slots = self._slots_of(self._bodies)  # their slots in the core
        self._core_key = key

    # -- bookkeeping ------------------------------------------------------------------

    def _slots_of(self, ids) -> np.ndarray:
        """The core's slots of the simulated vehicles ``ids``.

        Raises:
            KeyError: an id that is not simulated now.
        """
        ids = np.atleast_1d(np.asarray(ids, dtype=np.int64))
        bo = self.state.bodies
        valid = np.flatnonzero(bo.valid[0])
        order = np.argsort(bo.id[0, valid])
        sorted_ids = bo.id[0, valid][order]
        where = np.searchsorted(sorted_ids, ids)
        found = where < sorted_ids.size
        found[found] = sorted_ids[where[found]] == ids[found]
        if not found.all():
            raise KeyError(f"not a simulated vehicle: {ids[~found].tolist()}")
        return valid[order][where]

    def _sync(self) -> None:
        """The log rows, windows and counters of the steps the core took since the last
        call."""
        st, ep = self.state, self.state.episodes
        k = self.step_index
        lo, hi = ep.windows[0, 0], ep.windows[0, 3]
        self.windows = Windows(
            ghost_back=(float(lo), float(ep.windows[0, 1])),
            visible=(float(ep.windows[0, 1]), float(ep.windows[0, 2])),
            ghost_front=(float(ep.windows[0, 2]), float(hi)),
        )
        if self.keeps_log and k > self._synced:
            append_steps(self.log, self.shared, st, 0, self._synced + 1, k, self.config.dt,
                         self._heading[self.direction])  # fmt: skip
        self._synced = k
        counters_of(self.counters, st, 0, self.sim_time)


def _compiled_specs() -> set[str]:
    from twin.cosim.core.batch import COMPILED

    return set(COMPILED)


def _placed_ego(shared: Shared, placed, road) -> RecordedVehicle:
    """The recorded vehicle an episode's placement chose as its ego."""
    rec, meta = shared.recording, shared.store.trajectory_arrays
    return RecordedVehicle(
        tid=placed.tid, id=str(meta["id"][placed.tid]), road=road, t=placed.t0,
        x=placed.x, y=placed.y, lane=_lane(placed.y), speed=placed.speed,
        length=float(rec.length[placed.r]), width=float(rec.width[placed.r]),
        height=float(rec.height[placed.r]), vehicle_class=int(rec.vehicle_class[placed.r]),
    )  # fmt: skip


def _lane(y: float) -> int:
    from twin.core.i24 import lane_of

    return int(lane_of(np.array([y]))[0])


def _wrap(angle: np.ndarray) -> np.ndarray:
    return (angle + np.pi) % (2.0 * np.pi) - np.pi


def append_steps(log: TrajectoryLog, shared: Shared, state, b: int, k0: int, k1: int,
                 dt: float, road_heading: float) -> None:  # fmt: skip
    """Append episode ``b``'s log rows of steps ``k0`` to ``k1`` (the core's log) to
    ``log``: the vehicles of each step in id order, the windows, the ghosts at their
    rate."""
    lg = state.log
    rec_tid = np.asarray(shared.recording.tid)
    ids = lg.id[b, k0 : k1 + 1]
    step, slot = np.nonzero(ids >= 0)
    order = np.lexsort((ids[step, slot], step))
    step, slot = step[order], slot[order]
    k = step + k0
    ego = int(state.episodes.ego_id[b])
    log.add_rows(
        time=k * dt, id=ids[step, slot], tid=rec_tid[lg.r[b, k, slot]].astype(np.int64),
        ego_id=ego, lane=lg.lane[b, k, slot], x=lg.x[b, k, slot], y=lg.y[b, k, slot],
        z=lg.z[b, k, slot], speed=lg.speed[b, k, slot], accel_cmd=lg.accel_cmd[b, k, slot],
        heading=road_heading + lg.yaw[b, k, slot], drive_power=lg.drive_power[b, k, slot],
    )  # fmt: skip
    for j in range(k0, k1 + 1):
        log.add_window_bounds(j * dt, *lg.windows[b, j])
    every = lg.ghost_every
    for j in range((k0 + every - 1) // every * every, k1 + 1, every):
        row = j // every
        n = int(lg.ghost_count[b, row])
        log.add_ghost_rows(
            j * dt, rec_tid[lg.ghost_r[b, row, :n]].astype(np.int32), lg.ghost_lane[b, row, :n],
            lg.ghost_x[b, row, :n], lg.ghost_y[b, row, :n], lg.ghost_speed[b, row, :n],
        )  # fmt: skip


def counters_of(c: Counters, state, b: int, sim_time: float) -> Counters:
    """``c`` with episode ``b``'s counts from the core."""
    ep = state.episodes
    c.spawned, c.spawned_initially = int(ep.spawned[b]), int(ep.spawned_initially[b])
    c.despawned = int(ep.despawned[b])
    c.skipped_overlap, c.skipped_invalid = int(ep.skipped_overlap[b]), int(ep.skipped_invalid[b])
    c.skipped_full, c.off_road = int(ep.skipped_full[b]), int(ep.off_road[b])
    c.yielded, c.held = int(ep.yielded[b]), int(ep.held[b])
    c.anchored, c.anchors_full = int(ep.anchored[b]), int(ep.anchors_full[b])
    c.ghosts_braked = int(ep.ghosts_braked[b])
    n = min(int(ep.spawn_error_count[b]), ep.spawn_errors.shape[1])
    c.spawn_speed_error = ep.spawn_errors[b, :n].tolist()
    c.contacts = int(ep.collisions[b])
    c.collisions_unlisted = int(ep.collisions_unlisted[b])
    m = min(c.contacts, layout.COLLISIONS_KEPT)
    c.collisions = [
        (float(row[0]), int(row[1]), int(row[2]), int(row[3]), int(row[4]), int(row[5]),
         float(row[6]))
        for row in ep.collision_log[b, :m]
    ]  # fmt: skip
    if ep.ended[b] == layout.EGO_LEFT and not c.ended:
        c.ended = (
            f"the ego left the range of map and data (x = {ep.ended_x[b]:.1f} m) at "
            f"{sim_time:.2f} s"
        )
    return c


class TrafficView:
    """What the traffic manager of a cosimulation answers (its counts, the drivers'
    lanes and settings), read from the core."""

    def __init__(self, sim: Cosimulator):
        self._sim = sim

    @property
    def lane_changes(self) -> int:
        """Lane changes started between the through lanes."""
        return int(self._sim.state.counters.lane_changes[0])

    @property
    def merges(self) -> int:
        """Merges started from an on-ramp's acceleration lane into lane -4."""
        return int(self._sim.state.counters.merges[0])

    @property
    def safety_overrides(self) -> int:
        """Controller steps overridden by emergency braking."""
        return int(self._sim.state.counters.safety_overrides[0])

    @property
    def emergency_steps(self) -> int:
        return int(self._sim.state.counters.emergency_steps[0])

    @property
    def refused_requests(self) -> int:
        return int(self._sim.state.counters.refused_requests[0])

    @property
    def model(self):
        """The drivers' car-following model (:mod:`twin.traffic.models`)."""
        from twin.traffic.models import car_following_model

        return car_following_model(self._sim.config.traffic.car_following)

    @property
    def decision_steps(self) -> int:
        return int(self._sim.shared.traffic_settings.decision_steps)

    @property
    def ids(self) -> np.ndarray:
        bo = self._sim.state.bodies
        return np.sort(bo.id[0][bo.valid[0]])

    def _column(self, name, ids):
        return getattr(self._sim.state.drivers, name)[0][self._sim._slots_of(ids)].copy()

    def auto_lane_change(self, ids) -> np.ndarray:
        """(k,) bool: vehicles ``ids`` change lanes by MOBIL."""
        return self._column("auto", ids)

    def lanes(self, ids) -> np.ndarray:
        """(k,) the lanes vehicles ``ids`` drive in or are changing to."""
        return self._column("lane", ids)

    def changing(self, ids) -> np.ndarray:
        """(k,) bool: vehicles ``ids`` are changing lanes now."""
        return self._column("lane_from", ids) != self._column("lane", ids)

    def strategic(self, ids) -> np.ndarray:
        """(k,) the strategic directions of vehicles ``ids`` (0: none)."""
        return self._column("strategic", ids)

    def desired_speed(self, ids) -> np.ndarray:
        """(k,) [m/s] the desired speeds of vehicles ``ids`` now."""
        slots = self._sim._slots_of(ids)
        return self._sim.state.drivers.cf[0, slots, 0].copy()

    def params(self, ids) -> dict[str, np.ndarray]:
        """The driver parameters of vehicles ``ids`` (the model's, MOBIL's, HOV)."""
        sim = self._sim
        slots = sim._slots_of(ids)
        dr = sim.state.drivers
        model = self.model
        out = {name: dr.cf[0, slots, j].copy() for j, name in enumerate(model.names)}
        for name in ("politeness", "threshold", "safe_decel", "keep_right", "hov_eligible"):
            out[name] = getattr(dr, name)[0, slots].copy()
        return out

    def force_lane_change(self, vehicle_id: int, direction) -> None:
        """Ask vehicle ``vehicle_id`` to change one lane (``'left'``/+1, ``'right'``/-1).

        Raises:
            KeyError: not simulated. ValueError: off the road or against the HOV rule.
        """
        from twin.traffic.controller_api import lane_change_direction

        sim = self._sim
        step = lane_change_direction(direction)
        (i,) = sim._slots_of([vehicle_id])
        if step and not sim._may_change(int(i), step):
            raise ValueError(f"vehicle {vehicle_id} may not change one lane {step:+d} here")
        sim.state.drivers.requested[0, i] = step


class CoreWorld:
    """The kinematic world of a cosimulation: the core's bodies seen through the
    :class:`~twin.physics.worlds.World` interface's reading side (states, parameters,
    contacts, the road)."""

    def __init__(self, sim: Cosimulator, bundle: MapBundle):
        self._sim = sim
        self.road = bundle.road
        self.dt = sim.config.dt

    @property
    def time(self) -> float:
        return self._sim.sim_time

    @property
    def ids(self) -> np.ndarray:
        return self._sim.manager.ids

    def _slots(self) -> np.ndarray:
        return self._sim._slots_of(self.ids)

    @property
    def params(self):
        return self.params_of(self.ids)

    def params_of(self, ids):
        from twin.core.vehicle_classes import vehicle_classes
        from twin.physics.vehicle import VehicleParams

        bo = self._sim.state.bodies
        s = self._sim._slots_of(ids)
        return VehicleParams.from_classes(
            vehicle_classes(), bo.vehicle_class[0, s], bo.length[0, s], bo.width[0, s],
            bo.height[0, s],
        )  # fmt: skip

    def states(self) -> VehicleStates:
        """The vehicles now, by increasing id (a fresh copy)."""
        bo = self._sim.state.bodies
        s = self._slots()
        n = s.size
        heading = self._sim._heading[self._sim.direction] + bo.yaw[0, s]
        pitch = np.arctan(bo.grade[0, s])
        cos_p = np.cos(pitch)
        forward = np.stack([cos_p * np.cos(heading), cos_p * np.sin(heading), np.sin(pitch)], 1)
        centre = bo.x[0, s] + 0.5 * bo.length[0, s]
        ground, _, _ = self.road.to_world(self._sim.direction, centre, bo.y[0, s])
        position = ground.copy()
        position[:, 2] = bo.z[0, s]
        mass = bo.mass[0, s]
        return VehicleStates(
            id=bo.id[0, s].copy(), position=position, orientation=quaternion_of(heading, pitch),
            velocity=forward * bo.speed[0, s, None],
            angular_velocity=np.stack([np.zeros(n), np.zeros(n), bo.yaw_rate[0, s]], 1),
            speed=bo.speed[0, s].copy(), yaw_rate=bo.yaw_rate[0, s].copy(), heading=heading,
            road=np.full(n, self._sim.direction, np.int8), x=bo.x[0, s].copy(),
            y=bo.y[0, s].copy(), lane=bo.lane[0, s].astype(np.int8),
            wheel_spin=(bo.speed[0, s] / bo.wheel_radius[0, s])[:, None].repeat(4, 1),
            load=(mass * 9.81 * cos_p / 4.0)[:, None].repeat(4, 1),
            contact=np.ones((n, 4), bool), drive_power=bo.drive_power[0, s].copy(),
        )  # fmt: skip

    def vehicle_contacts(self) -> np.ndarray:
        st = self._sim.state
        k = int(st.episodes.pair_count[0])
        return st.pairs[0, :k].copy()

    def close(self) -> None:
        """Nothing to release: the core holds the bodies."""


def spawn_room(cfg: CosimConfig, rear_speed: np.ndarray, closing: np.ndarray) -> np.ndarray:
    """[m] bumper-to-bumper room a spawn needs to a body in its lane: the clearance,
    ``spawn_clearance_at_rest`` for a rear vehicle at rest growing to ``spawn_clearance``
    at ``CLEARANCE_SPEED`` and above (a standing queue is spawned as recorded, its gaps
    are often under 2 m), plus the difference of braking distances at ``spawn_decel``
    (``closing`` = v_rear^2 - v_front^2). The kernel
    :func:`twin.cosim.core.room.spawn_room` decides with it."""
    share = np.clip(np.asarray(rear_speed) / CLEARANCE_SPEED, 0.0, 1.0)
    clearance = cfg.spawn_clearance_at_rest + share * (
        cfg.spawn_clearance - cfg.spawn_clearance_at_rest
    )
    return clearance + np.maximum(closing, 0.0) / (2.0 * cfg.spawn_decel)


class Finished:
    """A finished episode of a batch, as the metrics read a cosimulation
    (:func:`twin.metrics.measure.measure`): its configuration, log, ego, counts and
    timing.

    Args:
        shared: the batch's shared part. batch: the batch. b: the episode.
        config: the episode's configuration (its place, time and seed).
        times: the wall time of its loop (:class:`StepTimes`).
    """

    def __init__(self, shared: Shared, batch: Batch, b: int, config: CosimConfig, times):
        st = batch.state
        self.config, self.traffic, self.behaviour = config, shared.traffic, shared.behaviour
        self.road, self.direction = config.road, config.road.direction
        self.limits = shared.limits
        self.world = _RoadOnly(shared.bundle.road)
        self.times = times
        placed = batch.placements[b]
        self.t0 = placed.t0
        self.step_index = int(st.episodes.step[b])
        self.ego_id = int(st.episodes.ego_id[b])
        self.ego = _placed_ego(shared, placed, self.road)
        self.log = TrajectoryLog(self.t0, self.direction, config.dt)
        heading = shared.bundle.road.heading(self.direction)
        append_steps(self.log, shared, st, b, 0, self.step_index, config.dt, heading)
        self.counters = counters_of(Counters(), st, b, self.sim_time)
        self.manager = _Counts(st.counters, b)
        self.av_ids: set[int] = set()
        if config.av_share > 0:  # the AVs are the vehicles whose record draws one
            from twin.core.jit import uniforms
            from twin.cosim.core.drivers import AV_STREAM

            rows = self.log.vehicles()[["id", "tid"]].drop_duplicates()
            draw = uniforms(int(st.episodes.seed[b]), AV_STREAM, rows["tid"].to_numpy(np.int64), 0)
            chosen = rows["id"].to_numpy()[draw < config.av_share]
            self.av_ids = {int(i) for i in chosen if i != self.ego_id}

    @property
    def sim_time(self) -> float:
        return self.step_index * self.config.dt


class _RoadOnly:
    """A finished episode's world: the road it ran on."""

    def __init__(self, road):
        self.road = road


class _Counts:
    """A finished episode's traffic-manager counts."""

    def __init__(self, counters, b: int):
        self.lane_changes = int(counters.lane_changes[b])
        self.safety_overrides = int(counters.safety_overrides[b])
        self.emergency_steps = int(counters.emergency_steps[b])
        self.merges = int(counters.merges[b])
