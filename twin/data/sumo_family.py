"""A family of held-out days made on demand by Eclipse SUMO with other drivers.

The calibrated twin is tuned on the SUMO days of presets D and E
(:mod:`twin.data.sumo_day`), so their figures are training figures. :func:`make_family`
draws N days whose SUMO drivers, demand and road vary within published ranges
(:data:`RANGES`) and writes each as an I-24 MOTION day file with every drawn parameter
beside it. Day k of the family from seed S is drawn from seed S + k alone and is
identified by it (:func:`draw_day`): the development family is seeds 0 to 19, the test
family 1000 to 1019, and the two never share a day whatever the workers.

Each day's drivers follow one of SUMO's car-following models and change lanes by one of
its lane-changing models: Krauss with LC2013 or with SL2015 (on the sublane model), IDM
or EIDM with LC2013 (:data:`MODELS`; :data:`STEPPED` says why SL2015 only with Krauss);
their time headway, dawdling, standstill gap, acceleration, braking, speed spread,
reaction time and lane-changing eagerness are drawn for the day
(:class:`~twin.data.sumo_drivers.SumoDrivers`). The pair of models and the road are the
seed's (every 16 consecutive seeds hold each pair on each road once, :data:`CELLS`), the
numbers drawn. Each road has one bottleneck, so that its followers cross stop-and-go
waves, which the calibration fits drivers on (``twin calibrate`` needs followers that
stopped and moved):

* ``plain``: four lanes throughout; downstream of the recorded range a slow stretch (an
  incident, a work zone's lane shift) that drivers pass at 9 to 18 mph;
* ``drop_one``, ``drop_two``: lane -4, or lanes -3 and -4, end between the middle of the
  segment and 500 m past its end;
* ``on_ramp``: the westbound Old Hickory Blvd on-ramp of preset E, with its own demand.

The general lanes' demand is drawn as a *load*: the most the bottleneck could carry with
the day's drivers (:func:`lane_capacity`), times 1 to 1.3. SUMO's drivers carry less,
so the demand exceeds what the bottleneck discharges and a queue grows upstream of it
through the recorded range, whatever the drivers' headway.

Why one module of about 600 lines: a fifth of it is the table of ranges with their
sources (:data:`SOURCES`, :data:`RANGES`), which the draw reads and the docs are tested
against, and the rest is one job, a family from its seed: the draw of a day
(:func:`draw_day`), the day made and its parameters written beside it
(:func:`make_day`), and the family made, resumed and summed up (:func:`make_family`).
SUMO's drivers themselves are :mod:`twin.data.sumo_drivers`, the run
:mod:`twin.data.sumo_day`.
"""

import json
import multiprocessing
import os
import time
from collections import Counter
from collections.abc import Callable
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from twin.core import i24
from twin.core.atomic import atomic_file
from twin.core.errors import TwinError
from twin.core.progress import progress_bar
from twin.core.sumo import sumo_version
from twin.core.vehicle_classes import vehicle_classes
from twin.data.sumo_day import sumo_day
from twin.data.sumo_drivers import DAWDLING, STEP, SumoDrivers
from twin.data.synth.config import Bottleneck, LaneDrop, SynthConfig
from twin.data.synth.presets import PRESET_C, PRESET_E
from twin.data.synth.simulation import class_weights

MINUTES = 12.0  # [min] recorded per day, by default
MINUTES_RANGE = (1.0, 60.0)  # [min] what a family's days may record
WARMUP = 300.0  # [s] simulated before the recording: the bottleneck's queue has formed
UPSTREAM = 200.0  # [m] road simulated before the recorded range (vehicles settle)
PAST_BOTTLENECK = 200.0  # [m] road simulated past the bottleneck (or the recorded range)
#: The lanes' vehicles enter at their lane's mean speed: entering at the fastest safe
#: speed, SUMO admitted 815 of seed 0's 1,253 vehicles in 11 minutes (at the lane's mean
#: speed 1,041), fewer than its slow stretch discharges, and no queue reached the
#: cameras (on 4 such days 0 followers stopped; entering at the mean speed, 32 to 47 %).
DEPART_SPEED = "avg"
MAX_FLOW = 3000.0  # [veh/h] the most a lane's demand may be (SynthConfig's limit)
#: the roads a day may have: where its bottleneck is
GEOMETRIES = ("plain", "drop_one", "drop_two", "on_ramp")
#: The car-following models that decide at their drawn action step, and the only one
#: SL2015 changes lanes with. IDM and EIDM decide every 0.1 s step: with longer action
#: steps EIDM's drivers collide (on a lane-drop day at 0.7 s, 1,175 pairs with LC2013
#: and 918 with SL2015; none at 0.1 s) and IDM's brake in emergency (39,354 times), and
#: at 0.1 s steps SUMO's sublane model takes six times LC2013's time (212 s against
#: 35 s for that 12-minute day): a family of 20 would not be made in 15 minutes on 2
#: cores.
STEPPED = ("Krauss",)
#: SUMO's (car-following, lane-changing) models a day may have
MODELS = (("Krauss", "LC2013"), ("Krauss", "SL2015"), ("IDM", "LC2013"), ("EIDM", "LC2013"))
#: Each pair of models on each road, once in every CELLS consecutive seeds: day ``seed``
#: has the models ``MODELS[seed % 4]`` on the road ``GEOMETRIES[seed // 4 % 4]``, so that
#: a family of 16 or more days holds them all, and one of 20 is balanced.
CELLS = len(MODELS) * len(GEOMETRIES)
FAMILY_INDEX = "family.json"
_SEGMENT = i24.SEGMENT_LENGTH  # [m]
_RECORDED_END = PRESET_C.x_record[1]  # [m] road-frame x where the recorded range ends


class FamilyError(TwinError):
    """A family cannot be made as asked, or its folder holds days made otherwise."""


@dataclass(frozen=True)
class Range:
    """Where a drawn number lies: uniform on [``low``, ``high``] in ``unit``, rounded to
    ``decimals`` (what SUMO is given), its bounds from ``source`` (a key of
    :data:`SOURCES`)."""

    low: float
    high: float
    unit: str
    decimals: int
    source: str


#: Where the ranges come from.
SOURCES = {
    "wang2024": "Wang, de Souza and Karbowski (2024), 'Calibrating microscopic traffic "
    "models with macroscopic data', arXiv:2409.19090: the bounds of their SUMO calibration "
    "of I-24 westbound (tau 0.5 to 2 s, minGap 1 to 3 m, accel 1 to 4 and decel 1 to 3 "
    "m/s^2; lcStrategic, lcSpeedGain, lcKeepRight 0 to 5, lcCooperative 0 to 1, "
    "lcAssertive 1e-4 to 5), calibrated tau 1.5 s, minGap 1.0 m, accel 2.4, decel 1.6 m/s^2",
    "sumo": "SUMO's documentation, 'Definition of Vehicles, Vehicle Types, and Routes' and "
    "'Car-Following Models': Krauss's sigma in 0 to 1 (default 0.5), a passenger car's "
    "accel 2.6, decel 4.5 m/s^2 and speedDev 0.1; actionStepLength as a reaction time",
    "issue75": "issue 75, what the twin fails on: LC2013 with a stronger speed gain and "
    "weaker cooperation, Krauss with sigma 0.5 to 0.6",
    "presets": "the twin's presets (twin/data/synth/presets.py): C's bottleneck 200 m long, "
    "1.2 km past the recorded range; D's lane drop 300 m past the segment; E's on-ramp "
    "600 veh/h; HOV lanes of 450 to 1,900 veh/h; C's heavy vehicles a third of the class "
    "table's whole-day share",
    "design": "this module: the demand exceeds the bottleneck's capacity (lane_capacity), "
    "so its queue's waves cross the recorded range",
}

# fmt: off
#: Every number :func:`draw_day` draws, uniformly in its range. The models are drawn
#: by the seed (:data:`CELLS`).
RANGES: dict[str, Range] = {
    # -- car following --
    # Wang et al.'s 0.5 to 2 s, from 0.8: below it a lane of SUMO's drivers carries over
    # 4,000 veh/h (a freeway lane 2,400, HCM 6th ed.) and no demand the synthesiser takes
    # (3,000 veh/h a lane at most) queues behind a lane drop
    "tau": Range(0.8, 2.0, "s", 3, "wang2024"),
    # SUMO's default 0.5 inside; issue 75's 0.5 to 0.6 at the top (Krauss only)
    "sigma": Range(0.2, 0.6, "-", 3, "sumo"),
    "min_gap": Range(1.0, 3.0, "m", 1, "wang2024"),
    "accel": Range(1.0, 4.0, "m/s^2", 3, "wang2024"),
    # Wang et al.'s calibrated 1.6 to SUMO's default 4.5
    "decel": Range(1.5, 4.5, "m/s^2", 3, "sumo"),
    # SUMO's 0.1, halved and half again (the class table's spreads: 0.04 to 0.08)
    "speed_dev": Range(0.05, 0.15, "-", 3, "sumo"),
    # a reaction time (Krauss only, see STEPPED); at most tau's lower bound, so that no
    # driver decides less often than its headway (it also spares SUMO most of its work)
    "action_step": Range(0.3, 0.8, "s", 1, "sumo"),
    # -- lane changing, LC2013 and SL2015 alike (issue 75's case inside) --
    "lc_strategic": Range(0.0, 5.0, "-", 3, "wang2024"),
    "lc_cooperative": Range(0.0, 1.0, "-", 3, "wang2024"),
    "lc_speed_gain": Range(0.0, 5.0, "-", 3, "wang2024"),
    "lc_keep_right": Range(0.0, 5.0, "-", 3, "wang2024"),
    # Wang et al.'s 1e-4 to 5, from 0.5: below it a driver wants twice the gap, and one
    # whose lane ends may never find it (no teleports here): a jam, not a day
    "lc_assertive": Range(0.5, 5.0, "-", 3, "wang2024"),
    # -- demand --
    # the general lanes' demand over the bottleneck's equilibrium capacity under the
    # day's drivers; SUMO's drivers carry less, so a queue grows behind it
    "load": Range(1.0, 1.3, "-", 3, "design"),
    "hov_flow": Range(800.0, 1600.0, "veh/h", 0, "presets"),
    "ramp_flow": Range(400.0, 900.0, "veh/h", 0, "presets"),
    # heavy vehicles from C's commuter peak to the class table's whole day; lanes -2, -3
    # and -4 take 0.3, 1 and 1.6 times it (SynthConfig's default)
    "heavy_scale": Range(0.3, 1.0, "-", 3, "presets"),
    # -- the road --
    # where the lanes end: from the segment's middle to 500 m past its end, 100 m inside
    # the recorded range, whose cameras then see the merge (past it they see a queue
    # too thin to stop: 0 of 873 followers stopped behind a drop 340 m past it)
    "drop_x": Range(round(0.5 * _SEGMENT, 1), round(_SEGMENT + 500.0, 1), "m", 1, "presets"),
    # the slow stretch past the recorded range: an incident or a work zone's lane shift
    # passed at 9 to 18 mph; the queue behind it moves as slowly, so its drivers stop
    # and go (behind stretches passed at 27 to 45 mph, on 7 of 8 days no follower stopped)
    "stretch_x": Range(_RECORDED_END + 100.0, _RECORDED_END + 600.0, "m", 1, "presets"),
    "stretch_length": Range(200.0, 500.0, "m", 1, "presets"),
    "stretch_speed": Range(4.0, 8.0, "m/s", 2, "design"),
}
# fmt: on


@dataclass(frozen=True)
class DayParams:
    """Everything drawn for one day of a family (:func:`draw_day`).

    Attributes:
        seed: the day's seed: what it is drawn from, SUMO's seed and the tracking
            noise's. It names the day.
        drivers: SUMO's drivers for every vehicle type (models and parameters).
        geometry: where the bottleneck is, one of :data:`GEOMETRIES`.
        load: [-] the general lanes' demand over the most the bottleneck could carry
            (:func:`lane_capacity`).
        flow: [veh/h] demand entering lanes -1 (HOV), -2, -3 and -4.
        heavy_factor: [-] factors on the class table's share of heavy vehicles in lanes
            -2, -3 and -4 (SynthConfig's ``heavy_factor``).
        drop_x: [m] road-frame x where the lanes end (``drop_one``: lane -4;
            ``drop_two``: lanes -3 and -4), else None.
        ramp_flow: [veh/h] the on-ramp's demand (``on_ramp``), else None.
        stretch_x, stretch_length: [m] road-frame start and length of the slow stretch
            (``plain``), else None.
        stretch_speed: [m/s] the drivers' mean speed through it (``plain``), else None.
    """

    seed: int
    drivers: SumoDrivers
    geometry: str
    load: float
    flow: tuple[float, float, float, float]
    heavy_factor: tuple[float, float, float]
    drop_x: float | None = None
    ramp_flow: float | None = None
    stretch_x: float | None = None
    stretch_length: float | None = None
    stretch_speed: float | None = None

    def config(self, minutes: float = MINUTES, warmup: float = WARMUP) -> SynthConfig:
        """The day's road and demand, ``minutes`` [min] recorded after ``warmup`` [s]
        (preset C's westbound morning and times, with this day's bottleneck and demand)."""
        lane_drop = on_ramp = bottleneck = None
        end = _RECORDED_END  # [m] where the bottleneck's road ends
        if self.geometry == "drop_one":
            lane_drop = LaneDrop(x=self.drop_x, lanes=(-4,))
            end = max(end, self.drop_x)
        elif self.geometry == "drop_two":
            lane_drop = LaneDrop(x=self.drop_x, lanes=(-3, -4))
            end = max(end, self.drop_x)
        elif self.geometry == "on_ramp":
            on_ramp = replace(PRESET_E.on_ramp, flow=self.ramp_flow)
        else:
            bottleneck = Bottleneck(x=self.stretch_x, length=self.stretch_length,
                                    speed=self.stretch_speed)  # fmt: skip
            end = self.stretch_x + self.stretch_length
        # the road ends soon past the bottleneck: SUMO's time goes with the vehicles
        # on it, and those past the bottleneck only leave
        downstream = round(end + PAST_BOTTLENECK - _RECORDED_END, 1)
        return replace(PRESET_C, seed=self.seed, minutes=float(minutes), warmup=float(warmup),
                       upstream=UPSTREAM, downstream=downstream, flow=self.flow,
                       heavy_factor=self.heavy_factor, bottleneck=bottleneck,
                       lane_drop=lane_drop, on_ramp=on_ramp)  # fmt: skip

    def to_dict(self) -> dict:
        """The parameters as JSON writes and reads them (tuples as lists)."""
        return json.loads(json.dumps(asdict(self)))


def lane_capacity(drivers: SumoDrivers, speed: float, length: float) -> float:
    """[veh/h] The most one lane of these drivers can carry at ``speed``: each keeps its
    time headway and standstill gap behind its leader, ``3600 v / (v tau + min_gap +
    length)`` (Krauss's equilibrium without dawdling). SUMO's drivers carry less
    (Krauss's dawdling, IDM's gap growing near its desired speed, the lane changes at a
    bottleneck), so a demand of this much queues behind the bottleneck whatever the
    model.

    Args:
        speed: [m/s] the drivers' mean speed there.
        length: [m] the vehicles' mean length.
    """
    return 3600.0 * speed / (speed * drivers.tau + drivers.min_gap + length)


def draw_day(seed: int) -> DayParams:
    """The day of seed ``seed``: its models and road by the seed (:data:`CELLS`), its
    drivers' parameters, demand and bottleneck's place drawn from :data:`RANGES` with
    ``numpy.random.default_rng(seed)``, rounded to what SUMO is given.

    Raises:
        FamilyError: ``seed`` is not a non-negative integer.
    """
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise FamilyError(f"a day's seed must be a non-negative integer, got {seed!r}")
    seed = int(seed)
    rng = np.random.default_rng(seed)

    def draw(name: str) -> float:
        r = RANGES[name]
        return round(float(rng.uniform(r.low, r.high)), r.decimals)

    car_following, lane_changing = MODELS[seed % len(MODELS)]
    geometry = GEOMETRIES[seed // len(MODELS) % len(GEOMETRIES)]
    # every number is drawn whatever the models, so that each has its place in the stream
    sigma = draw("sigma")
    drivers = SumoDrivers(
        car_following=car_following,
        lane_changing=lane_changing,
        tau=draw("tau"),
        sigma=sigma if car_following in DAWDLING else None,
        min_gap=draw("min_gap"),
        accel=draw("accel"),
        decel=draw("decel"),
        speed_dev=draw("speed_dev"),
        lc_strategic=draw("lc_strategic"),
        lc_cooperative=draw("lc_cooperative"),
        lc_speed_gain=draw("lc_speed_gain"),
        lc_keep_right=draw("lc_keep_right"),
        lc_assertive=draw("lc_assertive"),
        action_step=draw("action_step") if car_following in STEPPED else STEP,
    )
    load, hov_flow, ramp_flow = draw("load"), draw("hov_flow"), draw("ramp_flow")
    heavy_scale = draw("heavy_scale")
    drop_x, stretch = draw("drop_x"), (draw("stretch_x"), draw("stretch_length"),
                                       draw("stretch_speed"))  # fmt: skip
    heavy_factor = tuple(round(heavy_scale * f, 3) for f in (0.3, 1.0, 1.6))
    frame = vehicle_classes().frame
    weights = class_weights(frame, heavy_factor, -3)  # a general lane's mix
    length = float(weights @ frame["length_m"].to_numpy(float))
    desired = float(weights @ frame["desired_speed_mps"].to_numpy(float))
    desired *= PRESET_C.drivers.desired_speed_scale
    if geometry == "plain":  # every lane through the slower stretch
        general = load * lane_capacity(drivers, stretch[2], length)
    else:
        general = load * lane_capacity(drivers, desired, length)
        if geometry == "drop_one":  # three lanes into two
            general *= 2.0 / 3.0
        elif geometry == "drop_two":  # three lanes into one
            general /= 3.0
        else:  # lane -4 takes the ramp's demand too
            general -= ramp_flow / 3.0
    general = float(min(round(general), MAX_FLOW))
    return DayParams(
        seed=seed,
        drivers=drivers,
        geometry=geometry,
        load=load,
        flow=(hov_flow, general, general, general),
        heavy_factor=heavy_factor,
        drop_x=drop_x if geometry in ("drop_one", "drop_two") else None,
        ramp_flow=ramp_flow if geometry == "on_ramp" else None,
        stretch_x=stretch[0] if geometry == "plain" else None,
        stretch_length=stretch[1] if geometry == "plain" else None,
        stretch_speed=stretch[2] if geometry == "plain" else None,
    )


# -- the days' files --------------------------------------------------------------------------


def day_path(folder: Path, seed: int) -> Path:
    """The day file of seed ``seed`` in a family's ``folder``."""
    return Path(folder) / f"day_{seed:04d}.json"


def params_path(folder: Path, seed: int) -> Path:
    """The parameters file beside the day file of seed ``seed``."""
    return Path(folder) / f"day_{seed:04d}.params.json"


@dataclass(frozen=True)
class FamilyDay:
    """One day of a family, as :func:`make_family` reports it.

    Attributes:
        index: its place in the family (its seed less the family's first).
        path: the day file.
        record: what its parameters file holds (``params``, ``sumo``'s counts, ...).
        seconds: [s] how long it took to make, or None when it was made before.
    """

    index: int
    path: Path
    record: dict
    seconds: float | None


def _head(params: DayParams, minutes: float, warmup: float, family_seed: int, index: int,
          version: str) -> dict:  # fmt: skip
    """What a day's parameters file says of how it was made (all but SUMO's counts)."""
    return {
        "seed": params.seed,
        "family": {"seed": family_seed, "index": index},
        "minutes": minutes,
        "warmup": warmup,
        "depart_speed": DEPART_SPEED,
        "sumo_version": version,
        "params": params.to_dict(),
    }


def make_day(params: DayParams, folder: Path, *, minutes: float = MINUTES,
             warmup: float = WARMUP, family: tuple[int, int] | None = None,
             keep: Path | None = None) -> dict:  # fmt: skip
    """Make one day of a family in ``folder``: its day file, then its parameters file
    (written whole or not at all, last: a day without one is not made).

    Args:
        params: the day's parameters (:func:`draw_day`).
        minutes: [min] recorded.
        warmup: [s] simulated before the recording.
        family: (the family's first seed, the day's index), default (its seed, 0).
        keep: a folder to keep SUMO's inputs and outputs in (default: none kept).

    Returns:
        The parameters file's content.

    Raises:
        SumoDayError: SUMO is missing or failed.
    """
    family_seed, index = family if family is not None else (params.seed, 0)
    record = _head(params, float(minutes), float(warmup), family_seed, index, sumo_version())
    result = sumo_day(params.config(minutes, warmup), day_path(folder, params.seed),
                      drivers=params.drivers, depart_speed=DEPART_SPEED, keep=keep)  # fmt: skip
    record["sumo"] = {
        "trajectories": result.trajectories,
        "departed": result.departed,
        "lane_changes": result.lane_changes,
        "collisions": result.collisions,
        "waiting": result.waiting,
    }
    _write_json(params_path(folder, params.seed), record)
    return record


def _timed_day(params: DayParams, folder: Path, minutes: float, warmup: float,
               family: tuple[int, int]):  # fmt: skip
    start = time.perf_counter()
    record = make_day(params, folder, minutes=minutes, warmup=warmup, family=family)
    return record, time.perf_counter() - start


def _write_json(path: Path, content: dict) -> None:
    with atomic_file(path) as tmp:
        tmp.write_text(json.dumps(content, indent=2) + "\n")


def _read_json(path: Path) -> dict:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError) as error:
        raise FamilyError(f"{path} cannot be read ({error}); remove it to make it again") from None


# -- the family -------------------------------------------------------------------------------


def make_family(n: int, seed: int, out, *, minutes: float = MINUTES, warmup: float = WARMUP,
                workers: int | None = None, progress: bool = False,
                on_day: Callable[[FamilyDay], None] | None = None) -> list[Path]:  # fmt: skip
    """Make the family of ``n`` days drawn from seeds ``seed`` to ``seed + n - 1`` in the
    folder ``out``: ``day_SEED.json`` (the I-24 MOTION day), ``day_SEED.params.json``
    (every drawn parameter, the SUMO version, the family's seed and the day's index, and
    SUMO's counts) and ``family.json`` (the index: each day's seed, file and parameters,
    and the arguments). A day already made in ``out`` the same way is kept (an
    interrupted run resumes where it stopped); the bytes are the same whatever the
    workers.

    Args:
        minutes: [min] recorded per day, 1 to 60.
        warmup: [s] simulated before each day's recording (the bottleneck's queue forms).
        workers: processes making days at once (default: the cores available).
        progress: draw a progress bar over the days.
        on_day: called with each day as it is made or found made.

    Returns:
        The day files, in the family's order.

    Raises:
        FamilyError: a value out of its range, ``out`` a file, or ``out`` holding another
            family's index or a day made otherwise (other minutes, another SUMO).
        SumoDayError: SUMO is missing or failed (the days made are kept).
    """
    for name, value in (("days", n), ("seed", seed)):
        if isinstance(value, bool) or not isinstance(value, int | np.integer):
            raise FamilyError(f"the family's {name} must be an integer, got {value!r}")
    if n < 1:
        raise FamilyError(f"a family needs at least 1 day, got {n}")
    if seed < 0:
        raise FamilyError(f"the family's seed must be >= 0, got {seed}")
    if not MINUTES_RANGE[0] <= minutes <= MINUTES_RANGE[1]:
        raise FamilyError(
            f"a family's days record {MINUTES_RANGE[0]:g} to {MINUTES_RANGE[1]:g} minutes, "
            f"got {minutes:g}"
        )
    if not warmup >= 0:
        raise FamilyError(f"warmup must be >= 0 s, got {warmup}")
    if workers is not None and workers < 1:
        raise FamilyError(f"workers must be >= 1, got {workers}")
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise FamilyError(f"--out {out}: a file, not a folder (a family is a folder of days)")
    minutes, warmup = float(minutes), float(warmup)
    arguments = {"days": int(n), "seed": int(seed), "minutes": minutes, "warmup": warmup}
    index_path = out / FAMILY_INDEX
    if index_path.exists():
        made = _read_json(index_path).get("arguments", {})
        if [made.get(key) for key in ("seed", "minutes", "warmup")] != [seed, minutes, warmup]:
            raise FamilyError(
                f"{out} holds the family of seed {made.get('seed')} recording "
                f"{made.get('minutes')} min after {made.get('warmup')} s, not seed {seed} "
                f"recording {minutes:g} min after {warmup:g} s; choose another --out"
            )
    version = sumo_version()
    out.mkdir(parents=True, exist_ok=True)
    days: dict[int, FamilyDay] = {}
    jobs = []
    bar = progress_bar(total=n, desc="days", unit="day", progress=progress)

    def done(day: FamilyDay) -> None:
        days[day.index] = day
        bar.update(1)
        if on_day is not None:
            on_day(day)

    for k in range(n):
        params = draw_day(int(seed) + k)
        head = _head(params, minutes, warmup, int(seed), k, version)
        made = _made(out, params.seed, head)
        if made is not None:
            done(FamilyDay(k, day_path(out, params.seed), made, None))
        else:
            jobs.append((k, params))
    try:
        _run(jobs, out, minutes, warmup, int(seed), workers, done)
    finally:
        bar.close()
    records = [days[k].record for k in range(n)]
    _write_json(index_path, {
        "arguments": arguments,
        "sumo_version": version,
        "days": [{"seed": r["seed"], "day": day_path(out, r["seed"]).name,
                  "params": r["params"], "sumo": r["sumo"]} for r in records],
    })  # fmt: skip
    return [days[k].path for k in range(n)]


def _made(folder: Path, seed: int, head: dict) -> dict | None:
    """The parameters file of the day ``seed`` if it was made as ``head`` says, None if
    it was not made (or not finished).

    Raises:
        FamilyError: it was made otherwise.
    """
    path = params_path(folder, seed)
    if not path.is_file() or not day_path(folder, seed).is_file():
        return None
    record = _read_json(path)
    differs = [key for key in head if record.get(key) != head[key]]
    if differs:
        raise FamilyError(
            f"{path.name} in {folder} was made otherwise ({', '.join(differs)} differ: "
            + "; ".join(
                f"{key} {record.get(key)!r}, now {head[key]!r}"
                for key in differs
                if key != "params"
            )
            + "); choose another --out, or remove the day to make it again"
        )
    return record


def _run(jobs, out: Path, minutes: float, warmup: float, seed: int, workers: int | None,
         done) -> None:  # fmt: skip
    """Make the days of ``jobs`` ((index, params) each), in a pool of ``workers``
    processes when there are more than one; ``done`` gets each as it is made."""

    def finished(k, params, result):
        record, seconds = result
        done(FamilyDay(k, day_path(out, params.seed), record, seconds))

    workers = workers if workers is not None else len(os.sched_getaffinity(0))
    if workers == 1 or len(jobs) <= 1:
        for k, params in jobs:
            future = Future()
            try:
                future.set_result(_timed_day(params, out, minutes, warmup, (seed, k)))
            except TwinError as error:
                future.set_exception(error)
            finished(k, params, _result(future, out, params.seed))
        return
    context = multiprocessing.get_context("spawn")  # SUMO runs as a process: nothing to fork
    pool = ProcessPoolExecutor(max_workers=min(workers, len(jobs)), mp_context=context)
    try:
        futures = {pool.submit(_timed_day, params, out, minutes, warmup, (seed, k)): (k, params)
                   for k, params in jobs}  # fmt: skip
        pending = set(futures)
        while pending:
            complete, pending = wait(pending, return_when=FIRST_COMPLETED)
            for future in complete:
                k, params = futures[future]
                finished(k, params, _result(future, out, params.seed))
    except BaseException:
        # the days running finish (each is written whole or not at all), the others
        # are cancelled; the days made are kept for a rerun to resume from
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    pool.shutdown(wait=True)


def _result(future, out: Path, seed: int):
    try:
        return future.result()
    except TwinError as error:
        raise type(error)(
            f"{day_path(out, seed).name} (seed {seed}): {error}; the days made are kept, "
            "rerun the same command to resume"
        ) from error


def summary(days: list[FamilyDay]) -> str:
    """One line on a family's days: how many of each road and of each pair of models."""
    roads = Counter(day.record["params"]["geometry"] for day in days)
    models = Counter(
        f"{day.record['params']['drivers']['car_following']}+"
        f"{day.record['params']['drivers']['lane_changing']}"
        for day in days
    )
    return (
        ", ".join(f"{roads[g]} {g}" for g in GEOMETRIES if roads[g])
        + "; "
        + ", ".join(f"{count} {name}" for name, count in sorted(models.items()))
    )
