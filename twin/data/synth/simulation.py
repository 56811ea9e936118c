"""The synthesiser's microsimulation: four lanes of drivers of any car-following
model, MOBIL lane changes that take several seconds, drivers braking for slowdowns
and a bottleneck, and lanes that end (a lane drop, an on-ramp; :mod:`lane_ends`)."""

import math
from dataclasses import dataclass

import numpy as np

from twin.core import i24
from twin.core.vehicle_classes import vehicle_classes
from twin.data.synth import lane_ends
from twin.data.synth.config import HOUR, MAX_DECEL, MIN_GAP, Slowdown, SynthConfig
from twin.data.synth.lane_ends import MERGE_ROOM, RAMP_LANE
from twin.traffic.drivers import DriverTraits
from twin.traffic.lanes import Occupancy
from twin.traffic.mobil import MOBILParams, mobil_incentive, mobil_safe
from twin.traffic.models import car_following_model
from twin.traffic.models.base import take


@dataclass
class _Vehicles:
    """The simulated vehicles, struct-of-arrays (n,) each."""

    vid: np.ndarray
    x: np.ndarray  # [m] back centre
    v: np.ndarray  # [m/s]
    lane: np.ndarray  # target lane
    lane_from: np.ndarray  # origin lane while changing, else == lane
    change_start: np.ndarray  # [s]
    change_duration: np.ndarray  # [s]
    next_decision: np.ndarray  # [s]
    length: np.ndarray
    width: np.ndarray
    height: np.ndarray
    vehicle_class: np.ndarray
    v0: np.ndarray
    T: np.ndarray
    s0: np.ndarray
    a: np.ndarray
    b: np.ndarray
    delta: np.ndarray
    forced_speed: np.ndarray  # [m/s], nan when not braking for a slowdown
    forced_until: np.ndarray  # [s]
    forced_decel: np.ndarray  # [m/s^2]
    bottleneck_speed: np.ndarray  # [m/s] the driver's speed through the bottleneck
    lookahead: np.ndarray  # [m] per lane to cross, before a lane's end (lane_ends)
    courteous: np.ndarray  # bool: opens a gap for a driver who must merge

    def __len__(self) -> int:
        return len(self.vid)

    def keep(self, mask: np.ndarray) -> None:
        for name, value in vars(self).items():
            setattr(self, name, value[mask])

    def extend(self, other: "_Vehicles") -> None:
        for name, value in vars(self).items():
            setattr(self, name, np.concatenate([value, getattr(other, name)]))

    @property
    def traits(self) -> DriverTraits:
        """The drivers' traits."""
        return DriverTraits(self.v0, self.T, self.s0, self.a, self.b, self.delta)


class Simulation:
    """The road's vehicles and their clock, stepped by :func:`~twin.data.synth.synthesize`."""

    def __init__(self, config: SynthConfig, rng: np.random.Generator):
        self.cfg = config
        self.rng = rng
        self.model = car_following_model(config.car_following)
        self.mobil = MOBILParams(
            politeness=config.politeness,
            threshold=config.change_threshold,
            safe_decel=config.safe_decel,
            keep_right=config.keep_right,
        )
        self.classes = vehicle_classes()
        self.x_in = config.x_record[0] - config.upstream
        self.x_out = config.x_record[1] + config.downstream
        self.t = config.start - config.warmup  # [s] unix, simulation clock
        self.next_vid = 0
        self.lane_changes = 0
        self.collisions = 0
        self.pending = np.zeros(4, dtype=int)
        # The arrival drawn for each lane, waiting for a gap to enter.
        self.waiting: list[_Vehicles | None] = [None] * 4
        self.next_arrival = np.full(4, np.inf)
        self.until_slow: list[int] | None = None  # drivers to each lane's next hesitant one
        self.lane_ends = lane_ends.any_lane_ends(config)
        self.ramp_pending = 0
        self.ramp_next = np.inf
        self.ramp_waiting: _Vehicles | None = None
        self.registry_class: list[np.ndarray] = []  # vehicle class by vid, per creation batch
        self.registry_dims: list[np.ndarray] = []  # (n, 3) [m] by vid
        self.registry_drivers: list[DriverTraits] = []  # by vid
        self.vehicles = self._new_vehicles(np.zeros(0, np.int8), np.zeros(0), np.zeros(0))

    # -- creation ---------------------------------------------------------------------
    def _class_weights(self, lane: int) -> np.ndarray:
        return class_weights(self.classes.frame, self.cfg.heavy_factor, lane)

    def _new_vehicles(self, lanes: np.ndarray, x: np.ndarray, v: np.ndarray) -> _Vehicles:
        n = len(lanes)
        rng = self.rng
        cls = np.empty(n, dtype=np.int8)
        for lane in np.unique(lanes):
            rows = lanes == lane
            cls[rows] = rng.choice(7, size=int(rows.sum()), p=self._class_weights(int(lane)))
        dims = self.classes.sample_dimensions(cls, rng)
        drivers = self.cfg.drivers.draw(self.classes, cls, rng)
        vid = np.arange(self.next_vid, self.next_vid + n)
        self.next_vid += n
        self.registry_class.append(cls)
        self.registry_dims.append(dims)
        self.registry_drivers.append(drivers)
        lanes = np.asarray(lanes, dtype=np.int8)
        next_decision = self.t + rng.uniform(0, self.cfg.decision_interval, n)
        bottleneck_speed = self._bottleneck_speeds(lanes)
        if self.lane_ends:  # drawn only then: the days without keep their data
            lookahead = rng.uniform(*self.cfg.merge_lookahead, n)
            courteous = rng.random(n) < self.cfg.courtesy
        else:
            lookahead, courteous = np.zeros(n), np.zeros(n, dtype=bool)
        return _Vehicles(
            vid=vid,
            x=np.asarray(x, float),
            v=np.minimum(np.asarray(v, float), drivers.desired_speed),
            lane=lanes,
            lane_from=lanes.copy(),
            change_start=np.zeros(n),
            change_duration=np.ones(n),
            next_decision=next_decision,
            length=dims[:, 0],
            width=dims[:, 1],
            height=dims[:, 2],
            vehicle_class=cls,
            v0=drivers.desired_speed,
            T=drivers.time_headway,
            s0=drivers.min_gap,
            a=drivers.max_accel,
            b=np.asarray(drivers.comfortable_decel, dtype=float),
            delta=np.asarray(drivers.delta, dtype=float),
            forced_speed=np.full(n, np.nan),
            forced_until=np.zeros(n),
            forced_decel=np.zeros(n),
            bottleneck_speed=bottleneck_speed,
            lookahead=lookahead,
            courteous=courteous,
        )

    def _bottleneck_speeds(self, lanes: np.ndarray) -> np.ndarray:
        b = self.cfg.bottleneck
        n = len(lanes)
        if b is None:  # drawn only with a bottleneck: the presets without keep their data
            return np.full(n, np.inf)
        speed = np.maximum(b.speed + b.speed_sd * self.rng.standard_normal(n), 2.0)
        slow = np.zeros(n, dtype=bool)
        if b.slow_share > 0:
            if self.until_slow is None:  # the first gap of each lane: a renewal in progress
                self.until_slow = [
                    math.ceil(self.rng.uniform(0.0, 1.0) * self._slow_gap()) for _ in i24.LANES
                ]
            for i, lane in enumerate(lanes):
                k = i24.LANES.index(max(int(lane), -i24.N_LANES))  # the ramp's: lane -4's
                self.until_slow[k] -= 1
                if self.until_slow[k] <= 0:
                    slow[i] = True
                    self.until_slow[k] = self._slow_gap()
        return np.where(slow, b.slow_speed, speed)

    def _slow_gap(self) -> int:
        """Drivers from one hesitant driver to the next in a lane: 0.5 to 1.5 times the
        mean (1 / slow_share), uniformly."""
        mean = 1.0 / self.cfg.bottleneck.slow_share
        return max(1, round(mean * self.rng.uniform(0.5, 1.5)))

    def _traits(self) -> DriverTraits:
        """The drivers' traits, with the bottleneck's speeds for those in it."""
        veh, b = self.vehicles, self.cfg.bottleneck
        if b is None:
            return veh.traits
        inside = (veh.x + veh.length >= b.x) & (veh.x <= b.x + b.length)
        v0 = np.where(inside, np.minimum(veh.v0, veh.bottleneck_speed), veh.v0)
        return DriverTraits(v0, veh.T, veh.s0, veh.a, veh.b, veh.delta)

    def populate(self) -> None:
        """Fill the road with traffic at each lane's demand, at free-flow spacing."""
        lanes = []
        for k, lane in enumerate(i24.LANES):
            q = self.cfg.flow[k] / HOUR
            if q <= 0:
                continue
            spacing = 30.0 / q  # [m] at 30 m/s
            n = math.ceil((self.x_out - self.x_in) / spacing)
            new = self._new_vehicles(np.full(n, lane), np.zeros(n), np.full(n, 30.0))
            # Rear to rear: the demand's spacing, but never closer than 30 m behind a vehicle.
            step = np.maximum(spacing, new.length[:-1] + 30.0)
            new.x = self.x_in + self.rng.uniform(0, spacing) + np.r_[0.0, np.cumsum(step)]
            new.keep(new.x < self.x_out - 25.0)
            if self.lane_ends:  # room to stop before a lane's end, at 30 m/s
                new.keep(new.x + new.length < lane_ends.lane_end(self.cfg, new.lane) - 250.0)
            lanes.append(new)
            self.next_arrival[k] = self.t + self._headway(q)
        ramp = self.cfg.on_ramp
        if ramp is not None and ramp.flow > 0:
            self.ramp_next = self.t + self._headway(ramp.flow / HOUR)
        self.vehicles = lanes[0]
        for new in lanes[1:]:
            self.vehicles.extend(new)

    def _headway(self, q: float) -> float:
        """[s] time to the next arrival: shifted exponential with a 1 s minimum."""
        mean = 1.0 / q
        return 1.0 + self.rng.exponential(max(mean - 1.0, 0.05))

    def _insert(self) -> None:
        """Let waiting arrivals enter each lane where the gap behind its last vehicle allows.

        An arrival keeps its drawn class and size while it waits, so long vehicles,
        which need longer gaps, are not under-represented.
        """
        veh = self.vehicles
        for k, lane in enumerate(i24.LANES):
            q = self.cfg.flow[k] / HOUR
            while q > 0 and self.t >= self.next_arrival[k]:
                self.pending[k] += 1
                self.next_arrival[k] += self._headway(q)
            if self.pending[k] == 0:
                continue
            gap, v_last = self._behind_last(
                (veh.lane == lane) | (veh.lane_from == lane), self.x_in, 30.0
            )
            if self.waiting[k] is None:
                self.waiting[k] = self._new_vehicles(
                    np.array([lane]), np.array([self.x_in]), np.array([30.0])
                )
            new = self.waiting[k]
            v_in = min(v_last, new.v0[0])
            if not _fits(new, gap, v_in):
                continue
            new.v[:] = v_in
            new.next_decision[:] = self.t + self.rng.uniform(0, self.cfg.decision_interval)
            self.waiting[k] = None
            self.pending[k] -= 1
            veh.extend(new)
        if self.cfg.on_ramp is not None:
            self._insert_ramp()

    def _insert_ramp(self) -> None:
        """Let the on-ramp's waiting arrival enter its lane where the gap allows."""
        ramp, veh = self.cfg.on_ramp, self.vehicles
        q = ramp.flow / HOUR
        while q > 0 and self.t >= self.ramp_next:
            self.ramp_pending += 1
            self.ramp_next += self._headway(q)
        if self.ramp_pending == 0:
            return
        on_ramp = (veh.lane == RAMP_LANE) | (veh.lane_from == RAMP_LANE)
        gap, v_last = self._behind_last(on_ramp, ramp.x_start, ramp.speed)
        if self.ramp_waiting is None:
            self.ramp_waiting = self._new_vehicles(
                np.array([RAMP_LANE]), np.array([ramp.x_start]), np.array([ramp.speed])
            )
        new = self.ramp_waiting
        v_in = min(v_last, ramp.speed, new.v0[0])
        if not _fits(new, gap, v_in):
            return
        new.v[:] = v_in
        self.ramp_waiting = None
        self.ramp_pending -= 1
        veh.extend(new)

    def _behind_last(self, occupied: np.ndarray, x_entry: float, v_free: float):
        """[m] the gap from ``x_entry`` to the last of the vehicles ``occupied`` (bool),
        and its speed [m/s] (``inf`` and ``v_free`` where there is none)."""
        veh = self.vehicles
        if not occupied.any():
            return np.inf, v_free
        last = np.flatnonzero(occupied)[np.argmin(veh.x[occupied])]
        return veh.x[last] - x_entry, veh.v[last]

    # -- one step ---------------------------------------------------------------------
    def _occupancy(self) -> Occupancy:
        """Lane occupancy: each vehicle in its lane, and a changing vehicle in its origin lane."""
        veh = self.vehicles
        return lane_ends.occupancy(veh.x, veh.lane, veh.lane_from)

    def step(self) -> None:
        cfg, veh, dt = self.cfg, self.vehicles, self.cfg.dt
        occupancy = self._occupancy()
        owner = occupancy.owner
        gap, leader = occupancy.leaders(veh.x, veh.length)
        drivers = take(self.model.from_traits(self._traits()), owner)
        acc_entry = self.model.accel(veh.v[owner], veh.v[leader], gap, drivers)
        acc = np.full(len(veh), np.inf)
        np.minimum.at(acc, owner, acc_entry)
        self.collisions += int(np.count_nonzero(gap < 0))
        seeking = None
        if self.lane_ends:
            seeking = lane_ends.seeking(
                cfg, veh.lane, veh.lane_from, veh.x, veh.length, veh.lookahead
            )
            acc = self._lane_end_accel(occupancy, acc, seeking)

        forced = ~np.isnan(veh.forced_speed)
        if forced.any():
            release = forced & (self.t > veh.forced_until)
            veh.forced_speed[release] = np.nan
            forced &= ~release
            track = np.clip(0.8 * (veh.forced_speed - veh.v), -veh.forced_decel, 0.5)
            acc = np.where(forced, np.minimum(acc, track), acc)

        acc += cfg.accel_noise * self.rng.standard_normal(len(veh))
        acc = np.clip(acc, -MAX_DECEL, veh.a * 1.5)
        self._change_lanes(occupancy, acc, seeking)
        if seeking is not None and seeking.any():
            self._merge(occupancy, acc, seeking)

        v_new = veh.v + acc * dt
        stopping = v_new < 0
        advance = np.where(
            stopping, -(veh.v**2) / (2 * np.minimum(acc, -1e-9)), veh.v * dt + 0.5 * acc * dt**2
        )
        veh.x = veh.x + advance
        veh.v = np.maximum(v_new, 0.0)
        done = (veh.lane_from != veh.lane) & (self.t + dt >= veh.change_start + veh.change_duration)
        veh.lane_from[done] = veh.lane[done]
        self.t += dt
        veh.keep(veh.x < self.x_out)
        self._insert()

    def _lane_end_accel(self, occupancy: Occupancy, acc, seeking) -> np.ndarray:
        """Accelerations with the lanes' ends: a driver brakes for its lane's end as for
        a standing vehicle; a courteous driver with a seeking driver ahead of it in the
        next lane opens a gap for it (:mod:`lane_ends`)."""
        cfg, veh = self.cfg, self.vehicles
        drivers = self.model.from_traits(veh.traits)
        end = lane_ends.lane_end(cfg, veh.lane)
        ending = np.flatnonzero(np.isfinite(end))
        if ending.size:
            gap = end[ending] - veh.x[ending] - veh.length[ending]
            wall = self.model.accel(
                veh.v[ending], np.zeros(ending.size), gap, take(drivers, ending)
            )
            acc[ending] = np.minimum(acc[ending], wall)
        # the courteous open gaps for mergers past half their seek, with room ahead
        merger = np.flatnonzero(seeking)
        distance = end[merger] - veh.x[merger] - veh.length[merger]
        seek = lane_ends.seek_distance(cfg, veh.lane[merger], veh.lookahead[merger])
        merger = merger[distance < 0.5 * seek]
        if merger.size:
            target = (veh.lane[merger] + 1).astype(np.int64)
            _, fol = occupancy.around(np.ones(merger.size), target, veh.x[merger])
            ok = fol >= 0
            merger, fol = merger[ok], fol[ok]
            ahead, _ = occupancy.around(np.ones(merger.size), target[ok], veh.x[merger])
            room = np.where(ahead >= 0, veh.x[ahead] - veh.x[merger] - veh.length[merger], np.inf)
            ok = (
                veh.courteous[fol]
                & (veh.x[merger] > veh.x[fol] + veh.length[fol])
                & (room > MERGE_ROOM)
            )
            merger, fol = merger[ok], fol[ok]
            if fol.size:
                gap = veh.x[merger] - veh.x[fol] - veh.length[fol]
                # only one who can still stop behind it braking comfortably drops back
                can = lane_ends.needed_decel(veh.v[fol], veh.v[merger], gap) <= veh.b[fol]
                merger, fol, gap = merger[can], fol[can], gap[can]
                yield_acc = self.model.accel(veh.v[fol], veh.v[merger], gap, take(drivers, fol))
                np.minimum.at(acc, fol, np.maximum(yield_acc, -veh.b[fol]))
        return acc

    def _change_lanes(self, occupancy: Occupancy, acc: np.ndarray, seeking=None) -> None:
        """MOBIL decisions for the drivers due to decide; start the chosen manoeuvres.

        The drivers judge the change by their own model's accelerations and weigh the
        new follower's loss only (their old follower's gain counts for nothing). Those
        seeking to leave a lane that ends (``seeking``) and the on-ramp's drivers do not
        decide by MOBIL (:meth:`_merge`), and nobody moves by choice into a lane that
        ends within its look-ahead."""
        cfg, veh = self.cfg, self.vehicles
        free = (
            (veh.next_decision <= self.t)
            & (veh.lane == veh.lane_from)
            & (veh.lane != i24.HOV_LANE)
            & np.isnan(veh.forced_speed)
        )
        if seeking is not None:
            free &= ~seeking & (veh.lane != RAMP_LANE)
        due = np.flatnonzero(free)
        if len(due) == 0:
            return
        veh.next_decision[due] = self.t + self.rng.exponential(cfg.decision_interval, len(due))
        drivers = self.model.from_traits(veh.traits)
        best_incentive = np.zeros(len(due))
        best_lane = veh.lane[due].copy()
        for step_dir in (+1, -1):
            target = veh.lane[due] + step_dir
            allowed = (target <= -2) & (target >= -4)
            if seeking is not None:
                allowed &= ~lane_ends.ends_within(cfg, target, veh.x[due], veh.lookahead[due])
            cand = due[allowed]
            if len(cand) == 0:
                continue
            tgt = target[allowed].astype(np.int64)
            lead, fol = occupancy.around(np.ones(len(cand)), tgt, veh.x[cand])
            has_lead, has_fol = lead >= 0, fol >= 0
            gap_lead = np.where(has_lead, veh.x[lead] - veh.x[cand] - veh.length[cand], np.inf)
            gap_fol = np.where(has_fol, veh.x[cand] - veh.x[fol] - veh.length[fol], np.inf)
            a_new = self.model.accel(veh.v[cand], veh.v[lead], gap_lead, take(drivers, cand))
            a_fol_new = self.model.accel(veh.v[fol], veh.v[cand], gap_fol, take(drivers, fol))
            a_fol_old = np.where(has_fol, acc[fol], 0.0)
            a_fol_new = np.where(has_fol, a_fol_new, 0.0)
            safe = mobil_safe(a_fol_new, self.mobil) & (gap_lead > 1.0) & (gap_fol > 1.0)
            none = np.zeros(len(cand))
            incentive = mobil_incentive(
                acc[cand], a_new, a_fol_old, a_fol_new, none, none,
                np.full(len(cand), step_dir < 0), self.mobil,
            )  # fmt: skip
            better = safe & (incentive > best_incentive[allowed])
            idx = np.flatnonzero(allowed)[better]
            best_incentive[idx] = incentive[better]
            best_lane[idx] = tgt[better]
        chosen = best_lane != veh.lane[due]
        self._start(due[chosen], best_lane[chosen])

    def _start(self, movers: np.ndarray, target: np.ndarray) -> None:
        """Start the lane changes of drivers ``movers`` into lanes ``target``."""
        if len(movers) == 0:
            return
        veh = self.vehicles
        low, high = self.cfg.lane_change_duration
        veh.lane_from[movers] = veh.lane[movers]
        veh.lane[movers] = target
        veh.change_start[movers] = self.t
        veh.change_duration[movers] = self.rng.uniform(low, high, len(movers))
        self.lane_changes += len(movers)

    def _merge(self, occupancy: Occupancy, acc: np.ndarray, seeking: np.ndarray) -> None:
        """The drivers seeking to leave a lane that ends take the first gap to their left
        in which neither they nor their new follower must brake harder than they
        accept to keep 1 m apart, a deceleration that grows as the end nears
        (:mod:`lane_ends`); they judge every step, not at MOBIL's decision times, by
        kinematics, not by a car-following model."""
        cfg, veh = self.cfg, self.vehicles
        cand = np.flatnonzero(seeking & (veh.lane == veh.lane_from))
        if cand.size == 0:
            return
        target = (veh.lane[cand] + 1).astype(np.int64)
        lead, fol = occupancy.around(np.ones(cand.size), target, veh.x[cand])
        has_lead, has_fol = lead >= 0, fol >= 0
        gap_lead = np.where(has_lead, veh.x[lead] - veh.x[cand] - veh.length[cand], np.inf)
        gap_fol = np.where(has_fol, veh.x[cand] - veh.x[fol] - veh.length[fol], np.inf)
        own = lane_ends.needed_decel(veh.v[cand], np.where(has_lead, veh.v[lead], 0.0), gap_lead)
        new_follower = np.where(
            has_fol, lane_ends.needed_decel(veh.v[fol], veh.v[cand], gap_fol), 0.0
        )
        end = lane_ends.lane_end(cfg, veh.lane[cand])
        seek = lane_ends.seek_distance(cfg, veh.lane[cand], veh.lookahead[cand])
        accept = lane_ends.accept_decel(cfg, end - veh.x[cand] - veh.length[cand], seek)
        take_gap = (gap_lead > 1.0) & (gap_fol > 1.0) & (new_follower <= accept) & (own <= accept)
        self._start(cand[take_gap], target[take_gap])

    def trigger(self, slowdown: Slowdown) -> None:
        """Make the nearest driver upstream of ``slowdown.x`` brake, in each of its lanes."""
        veh = self.vehicles
        for lane in slowdown.lanes:
            rows = np.flatnonzero(
                (veh.lane == lane) & (veh.lane_from == lane) & (veh.x <= slowdown.x)
            )
            if len(rows) == 0:
                continue
            i = rows[np.argmax(veh.x[rows])]
            veh.forced_speed[i] = slowdown.speed
            veh.forced_decel[i] = slowdown.decel
            time_to_reach = max(veh.v[i] - slowdown.speed, 0.0) / slowdown.decel
            veh.forced_until[i] = self.t + time_to_reach + slowdown.duration

    def lateral(self) -> np.ndarray:
        """[m] road-frame y of every vehicle: lane centre, or a smooth path while changing."""
        veh = self.vehicles
        y_to = lane_ends.lane_y(veh.lane)
        y_from = lane_ends.lane_y(veh.lane_from)
        progress = np.clip((self.t - veh.change_start) / veh.change_duration, 0.0, 1.0)
        blend = 0.5 - 0.5 * np.cos(np.pi * progress)
        return np.where(veh.lane_from == veh.lane, y_to, y_from + (y_to - y_from) * blend)


def class_weights(frame, heavy_factor, lane: int) -> np.ndarray:
    """Each vehicle class's probability in ``lane`` (the class table ``frame``): its
    share, no heavy vehicle in the HOV lane, heavy ones scaled by ``heavy_factor`` in
    lanes -2 to -4 (an on-ramp's traffic, lane < -4: lane -4's)."""
    share = frame["share"].to_numpy(float).copy()
    heavy = frame["hov_allowed"].to_numpy() == 0
    lane = max(lane, -i24.N_LANES)
    if lane == i24.HOV_LANE:
        share[heavy] = 0.0
    else:
        share[heavy] *= heavy_factor[i24.LANES.index(lane) - 1]
    return share / share.sum()


def _fits(new: _Vehicles, gap: float, v_in: float) -> bool:
    """Whether an arrival entering at ``v_in`` fits ``gap`` [m] behind the last vehicle."""
    return gap >= new.length[0] + MIN_GAP + v_in * new.T[0]
