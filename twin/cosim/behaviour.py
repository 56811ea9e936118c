"""How the visible vehicles drive: the paper's rules, or drivers calibrated from the
recording (``twin calibrate``).

- ``paper``: the paper's rules: drivers drawn from the traffic manager's default
  distribution, every visible vehicle wanting ``vel_default`` (the lane leads ahead of
  the ego take their ghost's speed), MOBIL with the default threshold.
- ``calibrated``: drivers drawn from the store's calibrated distributions: the
  car-following model's parameters from the class group's fitted (correlated,
  log-normal) distribution,
  desired speeds from the calibrated desired speeds of the vehicle's lane, MOBIL with
  the calibrated threshold for discretionary changes, and the strategic changes the
  recording's lane-change flows show (a lane left near a place for a reason beyond
  the window), drawn per vehicle (:mod:`twin.cosim.strategic_targets`). A driver on
  an on-ramp's acceleration lane wants the speed the recording's free ramp drivers
  drove there, where enough were free (:mod:`twin.calibration.ramp_speeds`), in
  ``calibrated`` and ``recorded`` alike.
  With ``traffic.calibrated_yielding``, the cooperative layer's drivers who make room
  for an urgent change (``traffic.yield_from``, ``traffic.courtesy``,
  ``traffic.cooperative_decel``) yield as the recording's lane -4 drivers yield to the
  on-ramps' merging vehicles, where the calibration identified it
  (:mod:`twin.calibration.yielding`), in ``calibrated`` and ``recorded`` alike.
  Where the recording's drivers do not pass a slower vehicle on their left
  (:mod:`twin.calibration.passing`), the twin's do not either from the speed the
  calibration gives (``traffic.no_pass_right_from``; ``traffic.calibrated_passing``,
  on by default), in ``calibrated`` and ``recorded`` alike.
- ``recorded``: each vehicle gets the parameters fitted to its own recording (a
  calibrated draw where its fit is missing or was rejected), and makes the lane
  changes its recording makes, where its recording makes them (target lane and place),
  as strategic targets: wanted from the place with a growing urgency, the target
  lane's drivers making room, retried until well past it; it makes no others.

In ``calibrated`` and ``recorded``, where the calibration gives desired speeds, a
driver's desired speed is the larger of its draw and the speed its recording shows
where it is spawned: a driver seen cruising at 33 m/s wants at least that, whatever
its lane's drivers want on average. Not for a driver spawned on an on-ramp's lane, nor
for the ego (``vel_default``). The figures are in the calibration page's "What it
fits".

A road whose car following could not be calibrated keeps the paper's drivers for it
(its desired speeds and lane-change threshold are still calibrated where they were).
The calibrated behaviours drive the model the calibration fitted (``twin calibrate
--model``; by default the one that replays the recording best), which the run's
``traffic.car_following`` follows by default (``auto``, :func:`car_following_of`); a
model named there must be the calibration's.

``auto`` (the default of ``twin run``) is :data:`AUTO_CHOICE` where the store has a
calibration of the road for the run's car-following model, else ``paper``: the
behaviour ``twin eval`` found most faithful on data it was not calibrated on
(``docs/results/behaviours_held_out.md`` gives the figures).
"""

from dataclasses import dataclass, replace

import numpy as np

from twin.calibration import following
from twin.calibration.calibrate import calibration_model, read_calibration, read_fits
from twin.calibration.distributions import (
    ParameterDistribution,
    desired_speed_source,
    draw_desired,
    draw_desired_speeds,
    draw_parameters,
)
from twin.calibration.passing import no_pass_right
from twin.calibration.yielding import cooperation
from twin.core.errors import TwinError
from twin.core.i24 import Road
from twin.core.ramps import RAMP_LANE
from twin.data.store import TrajectoryStore
from twin.traffic.models import AUTO as AUTO_MODEL
from twin.traffic.models import UNCALIBRATED

BEHAVIOURS = ("paper", "calibrated", "recorded")
AUTO = "auto"
#: What ``auto`` means on a calibrated road: on the held-out halves of recordings made by
#: drivers unlike the twin's (IDM with other parameters, Gipps) it beat ``paper`` on
#: speeds, positions and the speed field, and matched ``recorded`` there
#: (``docs/results/behaviours_held_out.md``).
AUTO_CHOICE = "calibrated"
SEED_STREAM = 0x6265686176  # the behaviour's random draws use their own stream
PLANNED_LATE = 100.0  # [m] a recorded lane change not started this far past its place is dropped


class BehaviourError(TwinError):
    """A behaviour cannot be used with these data (unknown, or the store is not calibrated)."""


def resolve(name: str, store: TrajectoryStore, road: Road | str, car_following: str = "idm") -> str:
    """The behaviour ``name`` stands for: ``auto`` is :data:`AUTO_CHOICE` where ``store``
    has a calibration of ``road`` fitted for the run's ``car_following`` model, else
    ``paper``; others are themselves."""
    if name != AUTO:
        return check_behaviour(name)
    doc = read_calibration(store)
    calibrated = (
        doc is not None
        and Road.parse(road).value in doc["roads"]
        and calibration_model(doc).name == car_following
    )
    return AUTO_CHOICE if calibrated else "paper"


def car_following_of(name: str, store: TrajectoryStore, behaviour: str, road: Road | str) -> str:
    """The car-following model ``traffic.car_following`` = ``name`` stands for in a run
    of ``behaviour`` on ``road`` of ``store``: ``auto`` is the model the store's
    calibration of the road fitted (``twin calibrate`` chooses the one that replays the
    recording best) where the behaviour drives calibrated drivers, else ``idm`` (the
    paper's drivers; ``paper`` never reads the calibration); others are themselves."""
    if name != AUTO_MODEL:
        return name
    if behaviour == "paper":
        return UNCALIBRATED
    doc = read_calibration(store)
    if doc is None or Road.parse(road).value not in doc["roads"]:
        return UNCALIBRATED
    return calibration_model(doc).name


def with_car_following(config, store: TrajectoryStore):
    """``config`` (a :class:`~twin.cosim.config.CosimConfig`) with its
    ``traffic.car_following`` resolved on ``store`` (:func:`car_following_of`)."""
    name = car_following_of(config.traffic.car_following, store, config.behaviour, config.road)
    if name == config.traffic.car_following:
        return config
    return replace(config, traffic=replace(config.traffic, car_following=name))


def check_behaviour(name: str) -> str:
    if name not in BEHAVIOURS:
        raise BehaviourError(f"unknown behaviour {name!r}: choose one of {', '.join(BEHAVIOURS)}")
    return name


@dataclass(frozen=True)
class PlannedChanges:
    """The recorded lane changes of the vehicles of an episode, by recorded tid."""

    tid: np.ndarray
    x: np.ndarray
    lane_from: np.ndarray
    lane_to: np.ndarray


class Behaviour:
    """The drivers of one episode's visible vehicles (see the module doc).

    Args:
        name: one of :data:`BEHAVIOURS`.
        store: the recording (its calibration is read for the non-paper modes).
        road: the episode's road.
        seed: the run's seed.
        car_following: the drivers' model (``traffic.car_following``).

    Raises:
        BehaviourError: unknown name, a non-paper mode on a store with no calibration
            of ``road``, or with a calibration of another car-following model.
    """

    def __init__(
        self, name: str, store: TrajectoryStore, road: Road, seed: int, car_following: str = "idm"
    ):
        self.name = check_behaviour(name)
        self.road = Road.parse(road)
        self.rng = np.random.default_rng([seed, SEED_STREAM])
        self.distributions: dict[str, ParameterDistribution] = {}
        self.speeds: dict = {}
        self.speed_source = ""
        self.threshold: float | None = None
        self.politeness: float | None = None
        self._fits = None
        self.planned: PlannedChanges | None = None
        self.strategic_flows: dict | None = None
        self.keep_out: list = []  # lanes kept out of (calibrated): lane_flows.keep_out
        self.merges: list | None = None  # where the on-ramps' vehicles merge (merge_positions)
        self.ramp_speeds: list | None = None  # the on-ramps' free speeds (ramp_speeds.py)
        self.cooperation: dict[str, float] = {}  # lane -4's yielding to merges (yielding.py)
        self.passing: dict[str, float] = {}  # no passing on the right (passing.py)
        self.calibrated_at: str | None = None  # when the calibration driven by was made
        if self.name == "paper":
            return
        doc = read_calibration(store)
        if doc is None or self.road.value not in doc["roads"]:
            raise BehaviourError(
                f"behaviour {self.name!r} needs drivers calibrated on {self.road.value}: run "
                f"'twin calibrate {store.path} --road {self.road.value}' first (or use "
                "--behaviour paper)"
            )
        fitted = calibration_model(doc).name
        if fitted != car_following:
            raise BehaviourError(
                f"behaviour {self.name!r}: {store.path}'s calibration fitted {fitted} drivers, "
                f"the run drives {car_following}: add --set traffic.car_following={fitted} "
                f"(or calibrate again with --model {car_following})"
            )
        self.calibrated_at = doc["created"]
        section = doc["roads"][self.road.value]
        car = section["car_following"]
        if not car.get("not_calibrated"):
            self.distributions = {
                group: ParameterDistribution.from_dict(d)
                for group, d in car["distributions"].items()
            }
        self.speeds = section["desired_speed"]
        self.speed_source = desired_speed_source(self.speeds, car, bool(self.distributions))
        flows = section.get("lane_flows")
        if self.name == "calibrated" and flows and flows.get("identified"):
            self.strategic_flows = flows
            self.keep_out = list(flows.get("keep_out", []))
        self.merges = section.get("merges")
        self.ramp_speeds = section.get("ramp_speeds")
        self.cooperation = cooperation(section.get("yielding"))
        self.passing = no_pass_right(section.get("passing_right"))
        self.threshold = float(section["mobil"]["threshold"])
        self.politeness = float(section["mobil"]["politeness"])
        if self.name == "recorded":
            fits = read_fits(store)
            if len(fits):
                fits = fits[(fits["road"] == self.road.value) & fits["accepted"]]
                self._fits = fits.set_index("tid")

    @property
    def lead_chases_ghost(self) -> bool:
        """Whether a lane's lead visible vehicle keeps its own desired speed where the
        ghost ahead is slower (not in ``paper``). IDM only approaches its desired speed
        (by a (1 - (v/v0)^4)), so a lead whose desired speed is the ghost's lags the
        ghost, and the lane behind it lags the recording, the more the smaller its
        maximum acceleration; the ghost is the lead's leader in any case and holds it
        back where it is slower. Measured on a Gipps recording (fitted a 0.82 m/s^2):
        the ego 49 m behind its recording after 120 s with the ghost's speed as the
        lead's desired speed, 4.6 m with this."""
        return self.name != "paper"

    @property
    def auto_lane_change(self) -> bool:
        """Whether vehicles change lanes by MOBIL (not in ``recorded``)."""
        return self.name != "recorded"

    def plan(self, store: TrajectoryStore, t0: float, t1: float) -> None:
        """Read the recorded lane changes of the episode's window (``recorded`` only)."""
        if self.name != "recorded":
            return
        grid = following.load_grid(store, self.road, t0, t1)
        changes = following.lane_changes(grid)
        order = np.lexsort((changes.x, changes.tid))
        self.planned = PlannedChanges(
            tid=changes.tid[order],
            x=changes.x[order],
            lane_from=changes.lane_from[order],
            lane_to=changes.lane_to[order],
        )

    def changes_of(self, tid: int, x_now: float) -> list[tuple[float, int, int]]:
        """The recorded lane changes of ``tid`` still ahead of ``x_now`` (x, from, to)."""
        p = self.planned
        if p is None:
            return []
        a, b = np.searchsorted(p.tid, [tid, tid + 1])
        return [
            (float(p.x[i]), int(p.lane_from[i]), int(p.lane_to[i]))
            for i in range(a, b)
            if p.x[i] > x_now - PLANNED_LATE * 0.5
        ]

    def drivers(
        self, tid: np.ndarray, vehicle_class: np.ndarray, lane: np.ndarray, speed=None
    ) -> dict:
        """Parameters for vehicles spawned from recorded ``tid`` (each (n,)): a dict of
        the traffic manager's parameter names to (n,) arrays, ``{}`` in ``paper``.
        ``speed`` (n,) [m/s]: their recorded speeds at the spawn; a driver off an
        on-ramp's lane wants no less than that (the module's docstring); None: the draws
        alone."""
        n = len(tid)
        if self.name == "paper" or n == 0:
            return {}
        out = {}
        if self.distributions:
            names = next(iter(self.distributions.values())).names
            params = draw_parameters(self.distributions, vehicle_class, self.rng)
            own = np.zeros(n, bool)  # vehicles with a fit of their own (recorded)
            if self._fits is not None:
                own = np.isin(tid, self._fits.index.to_numpy())
                if own.any():
                    rows = self._fits.loc[tid[own], list(names)].to_numpy()
                    params[own] = rows
            for j, name in enumerate(names):
                if name != "desired_speed":
                    out[name] = params[:, j]
            if self.speed_source == "car_following":  # a lane's own free flow aside
                fitted = params[:, names.index("desired_speed")]
                drawn = draw_desired(self.speeds, self.speed_source, fitted, lane, self.rng)
                out["desired_speed"] = np.where(own, fitted, drawn)
        if self.speed_source == "free_flow":
            out["desired_speed"] = draw_desired_speeds(self.speeds, lane, self.rng)
        if speed is not None and "desired_speed" in out:  # not where the source is paper
            off_ramp = np.asarray(lane) != RAMP_LANE
            seen = np.where(off_ramp, np.asarray(speed, dtype=np.float64), 0.0)
            out["desired_speed"] = np.fmax(out["desired_speed"], seen)  # as the kernel
        if self.threshold is not None:
            out["threshold"] = np.full(n, self.threshold)
            out["politeness"] = np.full(n, self.politeness)
        return out

    def describe(self) -> str:
        if self.name == "paper":
            return "paper (default drivers, vel_default)"
        car = "calibrated" if self.distributions else "paper (not calibrated)"
        threshold = "" if self.threshold is None else f", MOBIL threshold {self.threshold:.2f}"
        return (
            f"{self.name} (car following {car}, desired speed from {self.speed_source}{threshold})"
        )
