"""Settings of the traffic manager (``[traffic]`` of a run's TOML)."""

import math
from dataclasses import dataclass, field

import numpy as np

from twin.traffic.drivers import DriverDistribution
from twin.traffic.mobil import MOBILParams
from twin.traffic.models import AUTO, car_following_model

MOBIL_FIELDS = ("politeness", "threshold", "safe_decel", "keep_right")


@dataclass(frozen=True)
class TrafficConfig:
    """Settings of the traffic manager.

    Attributes:
        dt: [s] step of the manager (the physics step).
        drivers: how the drivers' traits (the class table's terms) are drawn per
            vehicle.
        car_following: the drivers' model, by its name in :mod:`twin.traffic.models`
            (``idm``, ``gipps``, ...), or ``auto`` (the default): the model the store's
            calibration fitted where calibrated drivers drive, else ``idm`` (the paper's
            behaviour, a store without a calibration, a manager without a store).
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
        cooperate_from: [-] a strategic driver's urgency (0 at the place it starts to
            want its change, 1 where it must have made it) from which the driver behind
            it in the target lane drops back to make room (above 1: never).
        yield_from: [-] the urgency from which the driver behind drops back (where it
            is above ``cooperate_from``; the urgent driver settles from
            ``cooperate_from``).
        cooperative_decel: [m/s^2] the most a driver brakes to make that room.
        courtesy: [-] the share of drivers who make that room (drawn once per driver;
            the others keep to their own leader).
        calibrated_yielding: whether the ``calibrated`` and ``recorded`` behaviours set
            ``yield_from``, ``courtesy`` and ``cooperative_decel`` from how the
            recording's lane -4 yields to the on-ramps' merges (``calibration.json``'s
            ``yielding``, where identified). Off by default: the twin's merging drivers
            seek no gap of their own, and with the recording's yielding fewer merges
            were done in time (docs: Cooperation).
        no_pass_right_from: [m/s] from this speed of its own a driver does not pass a
            slower vehicle in the lane to its left: it follows the nearest one ahead
            there as a leader of its own, braking no harder than ``cooperative_decel``
            (the no-overtaking-on-the-right rule of European roads and of SUMO's
            LC2013, which applies it above 60 km/h, 16.7 m/s). In lanes -4 and -3 (the
            HOV lane, behind its double line, is passed); not while changing lanes,
            nor for a vehicle a controller drives. Off (inf) by default: drivers on US
            freeways pass on the right, as the twin's have always done.
        calibrated_passing: whether the ``calibrated`` and ``recorded`` behaviours set
            ``no_pass_right_from`` where the calibration found that the recording's
            drivers do not pass on the right (``calibration.json``'s
            ``passing_right``); on by default (docs: What it fits).
        urgent_path: [m] the shortest path of an urgent (strategic) lane change: a
            driver who must leave its lane noses across a queue in about three car
            lengths, where a discretionary change keeps a path made for 5 m/s. A
            longer vehicle's is at least 2.5 of its own lengths, so that its yawed
            front stays inside the target lane.
        seed: random seed of the drivers' draws.
    """

    dt: float = 0.01
    drivers: DriverDistribution = field(default_factory=DriverDistribution)
    car_following: str = AUTO
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
    cooperate_from: float = 0.3
    yield_from: float = 0.0
    cooperative_decel: float = 1.5
    courtesy: float = 1.0
    calibrated_yielding: bool = False
    no_pass_right_from: float = math.inf
    calibrated_passing: bool = True
    urgent_path: float = 15.0
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
            "cooperative_decel": self.cooperative_decel,
            "urgent_path": self.urgent_path,
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
        if not (math.isfinite(self.yield_from) and self.yield_from >= 0):
            raise ValueError(f"TrafficConfig.yield_from must be >= 0, got {self.yield_from!r}")
        if not 0 <= self.courtesy <= 1:
            raise ValueError(f"TrafficConfig.courtesy must be in 0..1, got {self.courtesy!r}")
        if math.isnan(self.no_pass_right_from) or self.no_pass_right_from < 0:
            raise ValueError(
                "TrafficConfig.no_pass_right_from must be a speed >= 0 [m/s] (inf: off), got "
                f"{self.no_pass_right_from!r}"
            )
        if not 0 <= self.hov_share <= 1:
            raise ValueError(f"hov_share must be in 0..1, got {self.hov_share}")
        if not 0 < self.brake_limit <= 1:
            raise ValueError(f"brake_limit must be in (0, 1], got {self.brake_limit}")
        if not (math.isfinite(self.cooperate_from) and self.cooperate_from >= 0):
            raise ValueError(
                f"TrafficConfig.cooperate_from must be >= 0, got {self.cooperate_from!r}"
            )
        if self.emergency_margin < 0 or self.reaction_time < 0 or self.path_preview < 0:
            raise ValueError("emergency_margin, reaction_time and path_preview must be >= 0")
        if any(len(o) != 2 or not o[0] < o[1] for o in self.hov_openings):
            raise ValueError(f"hov_openings must be (x0, x1) with x0 < x1: {self.hov_openings}")
        check_mobil(self.mobil)
        if self.car_following != AUTO:
            car_following_model(self.car_following)


def check_mobil(params: MOBILParams) -> None:
    """Raise ValueError naming a MOBIL parameter that is not finite and >= 0."""
    for name in MOBIL_FIELDS:
        value = np.asarray(getattr(params, name), dtype=np.float64)
        if not np.all(np.isfinite(value)) or np.any(value < 0):
            raise ValueError(f"MOBIL {name} must be finite and >= 0, got {value!r}")
