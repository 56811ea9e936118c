"""What a synthetic I-24 day is made of: its road, demand, drivers and the events that
seed its waves (:class:`SynthConfig`)."""

from dataclasses import dataclass

from twin.core import i24
from twin.core.i24 import Road
from twin.traffic.drivers import DriverDistribution
from twin.traffic.models import MODELS

HOUR = 3600.0  # [s]
MAX_DECEL = 9.0  # [m/s^2] full braking on dry asphalt
COMFORT_DECEL = 1.7  # [m/s^2] IDM b
MIN_GAP = 2.0  # [m] IDM s0 mean
DRIVERS = DriverDistribution(min_gap=MIN_GAP, comfortable_decel=COMFORT_DECEL)


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
class LaneDrop:
    """Lanes that end: the outermost ``lanes`` (e.g. (-3, -4): four lanes become two)
    end at ``x``. Their drivers must leave them before it, whatever their gain: a
    driver starts to seek a gap its own look-ahead distance per lane still to cross
    before the end, accepts harsher gaps as the end nears, and stops at the end if it
    finds none (see :mod:`twin.data.synth.lane_ends`).

    Attributes:
        x: [m] road-frame position where the lanes end.
        lanes: the lanes that end: (-4,) or (-3, -4) (their drivers move toward the
            HOV lane, which the synthesiser's drivers never enter, so two lanes
            continue).
    """

    x: float
    lanes: tuple[int, ...]


@dataclass(frozen=True)
class OnRamp:
    """An on-ramp's acceleration lane beside lane -4, from ``x_start`` to ``x_end``
    (where the merge ends): vehicles arrive on it at ``flow`` and merge into lane -4.
    The recording sees them in the acceleration lane's band (|y| 60 to 72 ft), which
    ``twin data ingest`` keeps as lane -5 where the map has an on-ramp's lane.

    Attributes:
        x_start, x_end: [m] road-frame ends of the acceleration lane.
        flow: [veh/h] demand arriving on the ramp.
        speed: [m/s] speed at which they arrive.
    """

    x_start: float
    x_end: float
    flow: float
    speed: float = 20.0


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
        lane_drop: lanes that end inside the simulated road, or None.
        on_ramp: an on-ramp merging into lane -4, or None.
        merge_lookahead: [m] range (uniform) of the drivers' look-ahead: how far before
            their lane's end, per lane still to cross, they start to leave it.
        courtesy: [-] share of drivers who open a gap for a driver who must merge in
            front of them (decelerating no harder than their comfortable deceleration).
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
    lane_drop: LaneDrop | None = None
    on_ramp: OnRamp | None = None
    merge_lookahead: tuple[float, float] = (150.0, 600.0)
    courtesy: float = 0.5
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
            "merge_lookahead": 0 < self.merge_lookahead[0] <= self.merge_lookahead[1],
            "courtesy": 0 <= self.courtesy <= 1,
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
        self._check_lane_ends()
        for s in self.slowdowns:
            if not (
                set(s.lanes) <= set(i24.LANES) and s.speed >= 0 and s.duration >= 0 and s.decel > 0
            ):
                raise ValueError(f"invalid slowdown {s!r}")

    def _check_lane_ends(self) -> None:
        x_in = self.x_record[0] - self.upstream
        x_out = self.x_record[1] + self.downstream
        d = self.lane_drop
        if d is not None:
            lanes = sorted(d.lanes, reverse=True)
            if not (
                lanes and set(lanes) <= {-3, -4} and -4 in lanes and x_in + 300.0 <= d.x < x_out
            ):
                raise ValueError(
                    f"invalid lane_drop {d!r}: its lanes must be the outermost, (-4,) or "
                    "(-3, -4), ending inside the simulated road "
                    "at least 300 m past its start"
                )
        r = self.on_ramp
        if r is not None and not (
            x_in <= r.x_start < r.x_end <= x_out
            and r.x_end - r.x_start >= 50.0
            and 0 <= r.flow <= 2000
            and 0 < r.speed <= 40
        ):
            raise ValueError(
                f"invalid on_ramp {r!r}: it must lie inside the simulated road, at least "
                "50 m long, with a flow of 0 to 2000 veh/h and a speed of 0 to 40 m/s"
            )
        if d is not None and r is not None and d.x < r.x_end:
            raise ValueError("the on-ramp must end before the lane drop")

    @property
    def end(self) -> float:
        """[s] unix time of the last recorded sample."""
        return self.start + 60.0 * self.minutes
