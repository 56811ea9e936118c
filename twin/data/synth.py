"""Synthetic I-24 MOTION days: a multi-lane microsimulation with real stop-and-go waves.

The real I-24 MOTION files cannot be downloaded on the twin's machines, so the twin
ships a stand-in in exactly their JSON layout. Heterogeneous IDM drivers
(:mod:`twin.traffic.models.idm`, parameters per vehicle class from ``assets/``) with
acceleration noise drive four lanes of a road longer than the recorded range;
MOBIL-style lane changes take several seconds; the HOV lane (-1) is entered by
nobody and left by nobody (the double line of this corridor). Waves are started
the way they start on a freeway, by a driver braking hard downstream
(:class:`Slowdown`); in dense traffic the braking propagates upstream as a
stop-and-go wave at the congested wave speed of the drivers, about
(s0 + length) / T, i.e. 4.5 to 5.5 m/s as measured on I-24.

Vehicle positions are recorded at the simulation step and resampled to the
camera rate (25 Hz) with a per-vehicle phase and small tracking noise.
"""

import math
import os
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import orjson
from tqdm import tqdm

from twin.core import i24
from twin.core.i24 import SCENARIO_TIME, Road
from twin.core.vehicle_classes import vehicle_classes
from twin.traffic.drivers import DriverDistribution
from twin.traffic.lanes import Occupancy
from twin.traffic.mobil import MOBILParams, mobil_incentive, mobil_safe
from twin.traffic.models import MODELS, car_following_model
from twin.traffic.models.base import take
from twin.traffic.models.idm import IDMParams

HOUR = 3600.0  # [s]
MAX_DECEL = 9.0  # [m/s^2] full braking on dry asphalt
COMFORT_DECEL = 1.7  # [m/s^2] IDM b
MIN_GAP = 2.0  # [m] IDM s0 mean
DRIVERS = DriverDistribution(min_gap=MIN_GAP, comfortable_decel=COMFORT_DECEL)
IDM_NAMES = ("desired_speed", "time_headway", "min_gap", "max_accel", "comfortable_decel", "delta")


@dataclass(frozen=True)
class Slowdown:
    """A driver who brakes to ``speed`` and holds it for ``duration``: the seed of a wave.

    Attributes:
        t: [s] when, relative to the configuration's ``anchor``.
        x: [m] road-frame position; the nearest vehicle upstream of it in each lane brakes.
        lanes: the lanes in which a driver brakes.
        speed: [m/s] speed held.
        duration: [s] how long it is held after it is reached.
        decel: [m/s^2] braking used to reach it.
    """

    t: float
    x: float
    lanes: tuple[int, ...]
    speed: float
    duration: float
    decel: float = 3.0


@dataclass(frozen=True)
class Bottleneck:
    """A stretch downstream of the recorded range that drivers take more slowly (a merge,
    a curve, a lane drop's friction): where demand exceeds what it discharges, a queue
    grows upstream of it and, with drivers that differ and accelerate unevenly, breaks
    into stop-and-go waves that travel upstream through the recorded range.

    Attributes:
        x: [m] road-frame start of the stretch.
        length: [m] its length.
        speed: [m/s] the mean of the drivers' speeds through it (each driver's own,
            drawn once: some hold up the queue more than others, so it discharges
            unevenly).
        speed_sd: [m/s] their spread.
        slow_share: [-] the share of drivers who take it hesitantly (a driver merging
            late, a truck pulling in), at ``slow_speed``: each holds up the lane behind
            it for a while, and the queue it leaves travels upstream as a wave. They are
            spread evenly over each lane's drivers (from one to the next 0.5 to 1.5 times
            ``1 / slow_share`` drivers, uniformly), so that a short day is not left with
            one wave in a lane, or ten, by chance.
        slow_speed: [m/s] their speed through it.
    """

    x: float
    length: float
    speed: float
    speed_sd: float = 0.0
    slow_share: float = 0.0
    slow_speed: float = 3.0


@dataclass(frozen=True)
class SynthConfig:
    """A synthetic recording of one road.

    Attributes:
        road: the carriageway simulated.
        anchor: [s] unix reference time of the scenario (slowdown times are relative to it).
        start: [s] unix time of the first recorded sample.
        minutes: [min] recorded duration.
        flow: [veh/h] demand entering lanes -1, -2, -3, -4.
        slowdowns: the braking events that seed waves.
        bottleneck: a stretch downstream that discharges less than the demand (waves
            that arise from the drivers), or None.
        x_record: [m] road-frame range recorded (the instrument's field of view).
        upstream, downstream: [m] road simulated beyond the recorded range.
        warmup: [s] simulated before ``start`` so the road is in steady traffic.
        dt: [s] simulation step.
        sample_rate: [Hz] recording rate.
        position_noise: [m] sd of the tracking noise on x and y.
        accel_noise: [m/s^2] sd of the drivers' acceleration noise per step.
        heavy_factor: [-] factors on the class table's share of heavy vehicles (the
            classes kept out of the HOV lane) in lanes -2, -3 and -4.
        drivers: how each vehicle's traits (IDM's parameters) are drawn (data made by
            other drivers than the twin's defaults, e.g. to test a calibration).
        car_following: the drivers' model, by its name in :mod:`twin.traffic.models`:
            ``"idm-textbook"`` (IDM as published, the default), ``"idm"`` (the twin's
            own drivers) or ``"gipps"`` (a model the twin's defaults do not drive with:
            reaction time 2/3 of the drawn time headway, most severe braking twice the
            drawn comfortable deceleration, the same desired speed, acceleration and
            minimum gap). Their lane changes judge accelerations by the same model.
        lane_change_duration: [s] range of lane-change manoeuvre durations.
        politeness, change_threshold, keep_right, safe_decel: MOBIL parameters
            ([-], [m/s^2], [m/s^2], [m/s^2]).
        decision_interval: [s] mean time between a driver's lane-change decisions.
        seed: random seed.
    """

    road: Road
    anchor: float
    start: float
    flow: tuple[float, float, float, float]
    slowdowns: tuple[Slowdown, ...] = ()
    bottleneck: Bottleneck | None = None
    minutes: float = 16.0
    x_record: tuple[float, float] = (-600.0, i24.SEGMENT_LENGTH + 600.0)
    upstream: float = 800.0
    downstream: float = 900.0
    warmup: float = 200.0
    dt: float = 0.1
    sample_rate: float = 25.0
    position_noise: float = 0.03
    accel_noise: float = 0.15
    heavy_factor: tuple[float, float, float] = (0.3, 1.0, 1.6)
    drivers: DriverDistribution = DRIVERS
    car_following: str = "idm-textbook"
    lane_change_duration: tuple[float, float] = (3.0, 6.0)
    politeness: float = 0.2
    change_threshold: float = 0.3
    keep_right: float = 0.1
    safe_decel: float = 3.0
    decision_interval: float = 2.0
    seed: int = 0

    def __post_init__(self):
        object.__setattr__(self, "road", Road.parse(self.road))
        checks = {
            "minutes": self.minutes > 0,
            "dt": 0 < self.dt <= 0.5,
            "sample_rate": self.sample_rate > 0,
            "warmup": self.warmup >= 0,
            "upstream": self.upstream >= 0,
            "downstream": self.downstream >= 0,
            "x_record": self.x_record[0] < self.x_record[1],
            "flow": len(self.flow) == 4 and all(0 <= q <= 3000 for q in self.flow),
            "heavy_factor": len(self.heavy_factor) == 3
            and all(0 <= f <= 5 for f in self.heavy_factor),
            "car_following": self.car_following in MODELS,
            "lane_change_duration": 0
            < self.lane_change_duration[0]
            <= self.lane_change_duration[1],
            "politeness": 0 <= self.politeness <= 10,
            "change_threshold": 0 <= self.change_threshold <= 10,
            "decision_interval": 0 < self.decision_interval <= 600,
        }
        for name, ok in checks.items():
            if not ok:
                raise ValueError(f"SynthConfig.{name} is invalid: {getattr(self, name)!r}")
        b = self.bottleneck
        if b is not None and not (
            self.x_record[1] <= b.x
            and b.x + b.length <= self.x_record[1] + self.downstream
            and b.length > 0
            and b.speed > 0
            and b.speed_sd >= 0
            and 0 <= b.slow_share <= 1
            and b.slow_speed > 0
        ):
            raise ValueError(
                f"invalid bottleneck {b!r}: it must lie downstream of the recorded range, "
                f"within the {self.downstream:g} m simulated beyond it"
            )
        for s in self.slowdowns:
            if not (
                set(s.lanes) <= set(i24.LANES) and s.speed >= 0 and s.duration >= 0 and s.decel > 0
            ):
                raise ValueError(f"invalid slowdown {s!r}")

    @property
    def end(self) -> float:
        """[s] unix time of the last recorded sample."""
        return self.start + 60.0 * self.minutes


#: Scenario A of the paper: eastbound, light free-flowing traffic (I-24 eastbound is
#: free-flowing in the morning, 59 to 80 mph).
PRESET_A = SynthConfig(
    road=Road.EASTBOUND,
    anchor=SCENARIO_TIME,
    start=SCENARIO_TIME - 380.0,
    flow=(450.0, 900.0, 850.0, 650.0),
)

#: Scenario B of the paper: westbound (inbound), a stop-and-go wave arriving in the HOV
#: lane: the vehicle at x = 700 m in lane -1 at 06:45:50 is at cruise speed, meets the
#: wave's front a few seconds later and is stopped within the 30 s episode, while lanes
#: -3 and -4 are only mildly disturbed.
PRESET_B = SynthConfig(
    road=Road.WESTBOUND,
    anchor=SCENARIO_TIME,
    start=SCENARIO_TIME - 380.0,
    flow=(2300.0, 2100.0, 1600.0, 1300.0),
    slowdowns=(
        Slowdown(t=-560.0, x=2500.0, lanes=(-1, -2), speed=3.0, duration=15.0),
        Slowdown(t=-285.0, x=2450.0, lanes=(-1,), speed=0.0, duration=20.0),
        Slowdown(t=-285.0, x=2450.0, lanes=(-2,), speed=6.0, duration=10.0),
        Slowdown(t=-285.0, x=2450.0, lanes=(-3, -4), speed=22.0, duration=8.0),
        Slowdown(t=0.0, x=2500.0, lanes=(-1, -2), speed=2.0, duration=15.0),
        Slowdown(t=200.0, x=2450.0, lanes=(-1,), speed=4.0, duration=12.0),
    ),
)

PRESETS = {"A": PRESET_A, "B": PRESET_B}  # the embedded default data

#: Test data unlike the default data, for calibration and fidelity (issue 17; preset
#: "S", for its slowdowns): twenty minutes westbound, the HOV lane closed, stop-and-go in
#: the three other lanes (a driver brakes nearly to a stop downstream every 150 s).
PRESET_S = SynthConfig(
    road=Road.WESTBOUND,
    anchor=SCENARIO_TIME,
    start=SCENARIO_TIME - 600.0,
    minutes=20.0,
    flow=(0.0, 2000.0, 1900.0, 1700.0),
    slowdowns=tuple(
        Slowdown(t=-700.0 + 150.0 * k, x=2450.0, lanes=(-2, -3, -4), speed=2.0, duration=12.0)
        for k in range(13)
    ),
)

#: Drivers unlike the class table's: longer headways, harder acceleration, larger
#: standstill gaps, firmer and varied braking.
OTHER_DRIVERS = DriverDistribution(
    min_gap=3.0,
    min_gap_sd=0.5,
    comfortable_decel=2.5,
    comfortable_decel_sd=0.4,
    time_headway_scale=1.4,
    max_accel_scale=1.5,
)

#: Lane changing unlike the default data's: more polite, a higher threshold, decisions
#: half as often.
OTHER_LANE_CHANGES = {"politeness": 0.5, "change_threshold": 0.6, "decision_interval": 4.0}

#: The drivers of preset C: the other drivers with time gaps x 1.35 (not 1.4): longer
#: than the class table's, firmer acceleration (x 1.5), larger standstill gaps (3 +- 0.5
#: m) and varied braking (2.5 +- 0.4 m/s^2). With them the queue behind the
#: bottleneck carries its waves upstream at 4.5 to 5 m/s, the corridor's measured front
#: speeds.
MORNING_DRIVERS = replace(OTHER_DRIVERS, time_headway_scale=1.35)

#: Preset C, a westbound morning whose waves are like the real 2022-11-22 morning's
#: (issue 18; ``twin data waves`` compares them): 30 minutes from 06:35:50, traffic in
#: every lane near what its drivers can carry, and 1.2 km downstream of the recorded
#: range a 200 m stretch (a merge) that drivers take at their own speed (26 +- 2 m/s),
#: a few of them (1 in 200, spread evenly) hesitantly at 4.5 m/s. Each hesitant driver
#: holds up its lane; the queue behind it leaves as a stop-and-go wave that travels
#: upstream through the recorded range. No driver is made to brake: the waves come from
#: the drivers. Heavy vehicles are a third of the class table's whole-day share in lanes
#: -2 to -4 (a commuter peak; with the table's share, their slow starts break lanes -3
#: and -4 into short shallow waves: front to tail 14 to 18 s against the real 29 to
#: 32 s). Lane changes are rarer than in the other presets (threshold 1.5 m/s^2,
#: decisions every 4 s) and gentler (into gaps the new follower takes braking at most
#: 1 m/s^2), and the HOV lane is closed by its double line, as everywhere.
PRESET_C = SynthConfig(
    road=Road.WESTBOUND,
    anchor=SCENARIO_TIME,
    start=SCENARIO_TIME - 600.0,
    minutes=30.0,
    flow=(1900.0, 1900.0, 1850.0, 1800.0),
    warmup=900.0,
    downstream=2500.0,
    bottleneck=Bottleneck(
        x=i24.SEGMENT_LENGTH + 600.0 + 1200.0,
        length=200.0,
        speed=26.0,
        speed_sd=2.0,
        slow_share=0.005,
        slow_speed=4.5,
    ),
    heavy_factor=(0.3, 0.3, 0.3),
    drivers=MORNING_DRIVERS,
    change_threshold=1.5,
    decision_interval=4.0,
    safe_decel=1.0,
)

#: Every preset ``twin data synth`` offers.
ALL_PRESETS = {**PRESETS, "C": PRESET_C, "S": PRESET_S}


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

    def __len__(self) -> int:
        return len(self.vid)

    def keep(self, mask: np.ndarray) -> None:
        for name, value in vars(self).items():
            setattr(self, name, value[mask])

    def extend(self, other: "_Vehicles") -> None:
        for name, value in vars(self).items():
            setattr(self, name, np.concatenate([value, getattr(other, name)]))

    @property
    def traits(self) -> IDMParams:
        """The drivers' traits (the class table's terms: IDM's parameters)."""
        return IDMParams(self.v0, self.T, self.s0, self.a, self.b, self.delta)


@dataclass
class SynthResult:
    """Recorded trajectories (struct-of-arrays per vehicle) and counters."""

    config: SynthConfig
    vid: np.ndarray  # (m,) vehicle ids
    tracks: list  # per vehicle: (t, x, y) arrays at the recording rate, noise added
    vehicle_class: np.ndarray
    dimensions: np.ndarray  # (m, 3) [m]
    drivers: IDMParams  # (m,) each: the traits each vehicle drove with (its model's from_traits)
    lane_changes: int
    collisions: int


class _Simulation:
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
        self.registry_class: list[np.ndarray] = []  # vehicle class by vid, per creation batch
        self.registry_dims: list[np.ndarray] = []  # (n, 3) [m] by vid
        self.registry_drivers: list[IDMParams] = []  # by vid
        self.vehicles = self._new_vehicles(np.zeros(0, np.int8), np.zeros(0), np.zeros(0))

    # -- creation ---------------------------------------------------------------------
    def _class_weights(self, lane: int) -> np.ndarray:
        share = self.classes.column("share").astype(float).copy()
        heavy = self.classes.column("hov_allowed") == 0
        if lane == i24.HOV_LANE:
            share[heavy] = 0.0
        else:
            share[heavy] *= self.cfg.heavy_factor[i24.LANES.index(lane) - 1]
        return share / share.sum()

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
        return _Vehicles(
            vid=vid,
            x=np.asarray(x, float),
            v=np.minimum(np.asarray(v, float), drivers.desired_speed),
            lane=lanes,
            lane_from=lanes.copy(),
            change_start=np.zeros(n),
            change_duration=np.ones(n),
            next_decision=self.t + rng.uniform(0, self.cfg.decision_interval, n),
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
            bottleneck_speed=self._bottleneck_speeds(lanes),
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
                k = i24.LANES.index(int(lane))
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

    def _traits(self) -> IDMParams:
        """The drivers' traits, with the bottleneck's speeds for those in it."""
        veh, b = self.vehicles, self.cfg.bottleneck
        if b is None:
            return veh.traits
        inside = (veh.x + veh.length >= b.x) & (veh.x <= b.x + b.length)
        v0 = np.where(inside, np.minimum(veh.v0, veh.bottleneck_speed), veh.v0)
        return IDMParams(v0, veh.T, veh.s0, veh.a, veh.b, veh.delta)

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
            lanes.append(new)
            self.next_arrival[k] = self.t + self._headway(q)
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
            in_lane = (veh.lane == lane) | (veh.lane_from == lane)
            if in_lane.any():
                last = np.flatnonzero(in_lane)[np.argmin(veh.x[in_lane])]
                gap, v_last = veh.x[last] - self.x_in, veh.v[last]
            else:
                gap, v_last = np.inf, 30.0
            if self.waiting[k] is None:
                self.waiting[k] = self._new_vehicles(
                    np.array([lane]), np.array([self.x_in]), np.array([30.0])
                )
            new = self.waiting[k]
            v_in = min(v_last, new.v0[0])
            if gap < new.length[0] + MIN_GAP + v_in * new.T[0]:
                continue
            new.v[:] = v_in
            new.next_decision[:] = self.t + self.rng.uniform(0, self.cfg.decision_interval)
            self.waiting[k] = None
            self.pending[k] -= 1
            veh.extend(new)

    # -- one step ---------------------------------------------------------------------
    def _occupancy(self) -> Occupancy:
        """Lane occupancy: each vehicle in its lane, and a changing vehicle in its origin lane."""
        veh = self.vehicles
        return Occupancy.build(np.ones(len(veh)), veh.x, [veh.lane, veh.lane_from])

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

        forced = ~np.isnan(veh.forced_speed)
        if forced.any():
            release = forced & (self.t > veh.forced_until)
            veh.forced_speed[release] = np.nan
            forced &= ~release
            track = np.clip(0.8 * (veh.forced_speed - veh.v), -veh.forced_decel, 0.5)
            acc = np.where(forced, np.minimum(acc, track), acc)

        acc += cfg.accel_noise * self.rng.standard_normal(len(veh))
        acc = np.clip(acc, -MAX_DECEL, veh.a * 1.5)
        self._change_lanes(occupancy, acc)

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

    def _change_lanes(self, occupancy: Occupancy, acc: np.ndarray) -> None:
        """MOBIL decisions for the drivers due to decide; start the chosen manoeuvres.

        The drivers judge the change by their own model's accelerations and weigh the
        new follower's loss only (their old follower's gain counts for nothing)."""
        cfg, veh = self.cfg, self.vehicles
        due = np.flatnonzero(
            (veh.next_decision <= self.t)
            & (veh.lane == veh.lane_from)
            & (veh.lane != i24.HOV_LANE)
            & np.isnan(veh.forced_speed)
        )
        if len(due) == 0:
            return
        veh.next_decision[due] = self.t + self.rng.exponential(cfg.decision_interval, len(due))
        drivers = self.model.from_traits(veh.traits)
        best_incentive = np.zeros(len(due))
        best_lane = veh.lane[due].copy()
        for step_dir in (+1, -1):
            target = veh.lane[due] + step_dir
            allowed = (target <= -2) & (target >= -4)
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
        movers = due[chosen]
        if len(movers) == 0:
            return
        low, high = cfg.lane_change_duration
        veh.lane_from[movers] = veh.lane[movers]
        veh.lane[movers] = best_lane[chosen]
        veh.change_start[movers] = self.t
        veh.change_duration[movers] = self.rng.uniform(low, high, len(movers))
        self.lane_changes += len(movers)

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
        y_to = i24.lane_center(veh.lane)
        y_from = i24.lane_center(veh.lane_from)
        progress = np.clip((self.t - veh.change_start) / veh.change_duration, 0.0, 1.0)
        blend = 0.5 - 0.5 * np.cos(np.pi * progress)
        return np.where(veh.lane_from == veh.lane, y_to, y_from + (y_to - y_from) * blend)


def synthesize(config: SynthConfig, *, progress: bool = False) -> SynthResult:
    """Run the microsimulation and return the recorded tracks (deterministic by seed)."""
    rng = np.random.default_rng(config.seed)
    sim = _Simulation(config, rng)
    t0 = config.start - config.warmup
    sim.populate()
    n_steps = math.ceil((config.end - t0) / config.dt) + 1
    events = sorted(config.slowdowns, key=lambda s: s.t)
    lo, hi = config.x_record
    rec_vid, rec_step, rec_x, rec_y = [], [], [], []
    record_from = math.floor((config.start - t0) / config.dt) - 1
    for k in tqdm(
        range(n_steps),
        desc=f"synth {config.road.value}",
        disable=None if progress else True,
        leave=False,
    ):
        sim.t = t0 + k * config.dt
        while events and config.anchor + events[0].t <= sim.t:
            sim.trigger(events.pop(0))
        if k >= record_from:
            veh = sim.vehicles
            seen = (veh.x >= lo) & (veh.x <= hi)
            rec_vid.append(veh.vid[seen])
            rec_step.append(np.full(int(seen.sum()), k, np.int32))
            rec_x.append(veh.x[seen])
            rec_y.append(sim.lateral()[seen].astype(np.float32))
        sim.step()
    vid = np.concatenate(rec_vid)
    order = np.argsort(vid, kind="stable")
    vid, step = vid[order], np.concatenate(rec_step)[order]
    x, y = np.concatenate(rec_x)[order], np.concatenate(rec_y)[order]
    return _resample(config, sim, rng, t0, vid, step, x, y)


def _resample(config, sim, rng, t0, vid, step, x, y) -> SynthResult:
    """Tracks at the recording rate with a per-vehicle phase and tracking noise."""
    period = 1.0 / config.sample_rate
    starts = np.flatnonzero(np.r_[True, vid[1:] != vid[:-1]])
    ends = np.r_[starts[1:], len(vid)]
    ids, tracks = [], []
    for a, b in zip(starts, ends, strict=True):
        v = int(vid[a])
        t_steps = t0 + step[a:b] * config.dt
        phase = rng.uniform(0, period)
        first = math.ceil((max(t_steps[0], config.start) - config.start - phase) / period)
        last = math.floor((min(t_steps[-1], config.end) - config.start - phase) / period)
        if last - first < 1:
            continue
        t = config.start + phase + np.arange(first, last + 1) * period
        xs = np.interp(t, t_steps, x[a:b]) + config.position_noise * rng.standard_normal(len(t))
        ys = np.interp(t, t_steps, y[a:b]) + config.position_noise * rng.standard_normal(len(t))
        ids.append(v)
        tracks.append((t, xs, ys))
    ids = np.array(ids, dtype=np.int64)
    drivers = IDMParams(
        *(
            np.concatenate([getattr(batch, name) for batch in sim.registry_drivers])[ids]
            for name in IDM_NAMES
        )
    )
    return SynthResult(
        config=config,
        vid=ids,
        tracks=tracks,
        vehicle_class=np.concatenate(sim.registry_class)[ids],
        dimensions=np.concatenate(sim.registry_dims)[ids],
        drivers=drivers,
        lane_changes=sim.lane_changes,
        collisions=sim.collisions,
    )


def write_i24_json(result: SynthResult, path: str | os.PathLike, *, progress: bool = False) -> Path:
    """Write the tracks as an I-24 MOTION day file (a JSON array of documents).

    Written to a temporary file beside ``path`` and renamed, so an interrupted write
    never leaves a truncated file under the final name.
    """
    cfg = result.config
    road = cfg.road
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.partial-{os.getpid()}")
    order = np.argsort([track[0][0] for track in result.tracks], kind="stable")
    prefix = f"{int(cfg.anchor) & 0xFFFFFFFF:08x}{road.code:02x}"
    try:
        with open(tmp, "wb") as out:
            out.write(b"[\n")
            for n, i in enumerate(
                tqdm(order, desc="write", disable=None if progress else True, leave=False)
            ):
                t, x, y = result.tracks[i]
                x_ft = np.round(i24.x_feet(x, road), 2)
                y_ft = np.round(i24.y_feet(y, road), 2)
                t = np.round(t, 3)
                length, width, height = (result.dimensions[i] / i24.FT).round(3).tolist()
                doc = {
                    "_id": {"$oid": f"{prefix}{int(result.vid[i]):014x}"},
                    "timestamp": t.tolist(),
                    "first_timestamp": float(t[0]),
                    "last_timestamp": float(t[-1]),
                    "x_position": x_ft.tolist(),
                    "y_position": y_ft.tolist(),
                    "starting_x": float(x_ft[0]),
                    "ending_x": float(x_ft[-1]),
                    "length": length,
                    "width": width,
                    "height": height,
                    "coarse_vehicle_class": int(result.vehicle_class[i]),
                    "fine_vehicle_class": int(result.vehicle_class[i]),
                    "direction": road.direction,
                    "merged_ids": [],
                    "fragment_ids": [],
                    "compute_node_id": 0,
                    "local_fragment_id": int(result.vid[i]),
                    "road_segment_ids": [],
                    "configuration_id": 0,
                    "flags": ["synthetic"],
                    "x_score": 0.0,
                    "y_score": 0.0,
                    "feasibility": 1.0,
                }
                if n:
                    out.write(b",\n")
                out.write(orjson.dumps(doc))
            out.write(b"\n]\n")
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path
