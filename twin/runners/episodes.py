"""Where dataset episodes start: drawn from the recorded traffic, congested and free.

The data of each road are cut into cells of ``cell_s`` seconds by ``cell_m`` metres
per lane, and each cell's Edie mean speed is measured (:mod:`twin.data.speed_field`). A cell
is *congested* when that speed is under ``congested_below_mps``, else *free*. An
episode is drawn from the congested cells with probability ``congested_share`` (from
the free ones otherwise; from whichever kind exists when the data hold only one),
the cell with probability proportional to its samples (busier cells are drawn
more, as a random recorded vehicle would be), then x and time uniformly inside it.
The cosimulator makes the recorded vehicle closest to that lane, x and time the ego.

Episode ``i`` of a dataset with seed ``S`` draws from
``numpy.random.SeedSequence(S, spawn_key=(i,))`` alone, and its cosimulation seed
comes from the same sequence, so an episode is the same whatever the number of
episodes, the workers or the order they run in.
"""

import math
from dataclasses import asdict, dataclass, replace

import numpy as np

from twin.core import i24
from twin.core.errors import NoVehicleNearError, TwinError
from twin.core.i24 import Road
from twin.cosim.config import CosimConfig
from twin.cosim.windows import ScenarioError
from twin.data.speed_field import speed_field
from twin.data.store import TrajectoryStore
from twin.physics.states import MAX_SPEED

READ_CHUNK = 120.0  # [s] of samples read from the store at a time
MIN_CELL_SAMPLES = 25  # a cell with fewer samples is too thin to measure


class SamplingError(TwinError):
    """Episodes cannot be drawn from these data with these settings."""


@dataclass(frozen=True)
class EpisodeSampling:
    """How episodes are drawn from the data (``[sampling]`` of a dataset's TOML).

    Attributes:
        roads: the carriageways to draw from.
        congested_share: probability that an episode starts in a congested cell.
        congested_below_mps: [m/s] a cell's mean speed under which it is congested
            (13.4 m/s = 30 mph).
        cell_s: [s] and cell_m: [m] the size of a cell.
    """

    roads: tuple[str, ...] = ("eastbound", "westbound")
    congested_share: float = 0.5
    congested_below_mps: float = 13.4
    cell_s: float = 10.0
    cell_m: float = 50.0

    def __post_init__(self):
        try:
            roads = tuple(Road.parse(road).value for road in self.roads)
        except ValueError as error:
            raise SamplingError(f"roads: {error}") from None
        if not roads or len(set(roads)) != len(roads):
            raise SamplingError(f"roads must name distinct carriageways, got {list(self.roads)}")
        object.__setattr__(self, "roads", roads)
        if not 0.0 <= self.congested_share <= 1.0:
            raise SamplingError(f"congested_share must be in [0, 1], got {self.congested_share}")
        for name in ("congested_below_mps", "cell_s", "cell_m"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise SamplingError(f"{name} must be a positive number, got {value!r}")


@dataclass(frozen=True)
class EpisodeSpec:
    """One episode of a dataset: where and when its ego starts, and its seed.

    Attributes:
        index: the episode's number in the dataset.
        seed: seed of its cosimulation.
        road, lane, x, time: the requested ego lane, road-frame x [m], unix time [s].
        congested: drawn from a congested cell; cell_speed: [m/s] that cell's speed.
    """

    index: int
    seed: int
    road: str
    lane: int
    x: float
    time: float
    congested: bool
    cell_speed: float

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class Cells:
    """The cells episodes are drawn from, struct-of-arrays.

    Attributes:
        road: (n,) +1 / -1. lane: (n,) -1..-4. t0, x0: (n,) [s], [m] the cells'
        lower corners. speed: (n,) [m/s] Edie mean speed. samples: (n,) counts.
        cell_s, cell_m: the cells' size.
    """

    road: np.ndarray
    lane: np.ndarray
    t0: np.ndarray
    x0: np.ndarray
    speed: np.ndarray
    samples: np.ndarray
    cell_s: float
    cell_m: float


def check_roads(store: TrajectoryStore, sampling: EpisodeSampling) -> None:
    """Raise :class:`SamplingError` unless ``store`` holds every road of ``sampling``."""
    have = [road.value for road in store.roads]
    missing = [road for road in sampling.roads if road not in have]
    if missing:
        raise SamplingError(
            f"the data hold no {' or '.join(missing)} traffic (roads: {have}); "
            "choose others with sampling.roads"
        )


def measure_cells(
    store: TrajectoryStore,
    sampling: EpisodeSampling,
    limits: dict[Road, tuple[float, float]],
    duration: float,
    *,
    window: tuple[float | None, float | None] = (None, None),
    room_speed: float = MAX_SPEED,
) -> Cells:
    """The cells of ``store`` in which an episode of ``duration`` [s] can start: inside
    ``limits`` (per road, the x range where map and data exist) with room to drive
    ``duration`` at ``room_speed`` (default the top speed), and ending before the
    road's data do and inside ``window`` (unix seconds, either end open).

    Raises:
        SamplingError: a road has no data, or no cell has enough samples.
    """
    check_roads(store, sampling)
    parts = []
    for name in sampling.roads:
        road = Road.parse(name)
        t_first, t_last = store.time_range(road)
        if window[0] is not None:
            t_first = max(t_first, float(window[0]))
        if window[1] is not None:
            t_last = min(t_last, float(window[1]))
        lo, hi = limits[road]
        hi -= duration * room_speed  # room to drive the episode without leaving the data
        t_edges = np.arange(t_first, t_last - duration - sampling.cell_s, sampling.cell_s)
        x_edges = np.arange(lo, hi - sampling.cell_m + 1e-9, sampling.cell_m)
        if t_edges.size < 2 or x_edges.size < 2:
            continue
        t_edges = np.append(t_edges, t_edges[-1] + sampling.cell_s)
        x_edges = np.append(x_edges, x_edges[-1] + sampling.cell_m)
        shape = (len(i24.LANES), t_edges.size - 1, x_edges.size - 1)
        total, count = np.zeros(shape), np.zeros(shape, dtype=np.int64)
        for start in np.arange(t_edges[0], t_edges[-1], READ_CHUNK):
            end = min(start + READ_CHUNK, t_edges[-1])
            s = store.samples(road, start, end)
            inside = (s["t"] >= start) & ((s["t"] < end) | (end == t_edges[-1]))
            for k, lane in enumerate(i24.LANES):
                rows = inside & (s["lane"] == lane)
                cells = speed_field(
                    s["t"][rows], s["x"][rows], s["speed"][rows].astype(np.float64),
                    t_edges, x_edges,
                )  # fmt: skip
                count[k] += cells.count
                total[k] += np.nan_to_num(cells.speed) * cells.count
        lane_k, ti, xi = np.nonzero(count >= MIN_CELL_SAMPLES)
        parts.append(
            (
                np.full(ti.size, road.direction, np.int64),
                np.asarray(i24.LANES)[lane_k],
                t_edges[ti],
                x_edges[xi],
                total[lane_k, ti, xi] / count[lane_k, ti, xi],
                count[lane_k, ti, xi],
            )
        )
    if not parts or sum(part[0].size for part in parts) == 0:
        raise SamplingError(
            f"no {sampling.cell_s:g} s x {sampling.cell_m:g} m cell of {list(sampling.roads)} "
            f"holds {MIN_CELL_SAMPLES} samples with room for a {duration:g} s episode"
            + ("" if window == (None, None) else f" between unix {window[0]} and {window[1]}")
        )
    columns = [np.concatenate(column) for column in zip(*parts, strict=True)]
    return Cells(*columns, cell_s=sampling.cell_s, cell_m=sampling.cell_m)


def draw_episode(cells: Cells, sampling: EpisodeSampling, seed: int, index: int) -> EpisodeSpec:
    """Episode ``index`` of a dataset with ``seed`` (see the module doc)."""
    sequence = np.random.SeedSequence(seed, spawn_key=(index,))
    cosim_seed = int(sequence.generate_state(1, np.uint32)[0] & 0x7FFFFFFF)
    rng = np.random.default_rng(sequence)
    congested = cells.speed < sampling.congested_below_mps
    want_congested = bool(rng.random() < sampling.congested_share)
    if not congested.any() or congested.all():
        pool = np.ones(congested.size, dtype=bool)
    else:
        pool = congested if want_congested else ~congested
    candidates = np.flatnonzero(pool)
    weights = cells.samples[candidates].astype(np.float64)
    cell = int(candidates[rng.choice(candidates.size, p=weights / weights.sum())])
    x, t = rng.random(2)
    return EpisodeSpec(
        index=index,
        seed=cosim_seed,
        road=Road.parse(int(cells.road[cell])).value,
        lane=int(cells.lane[cell]),
        x=round(float(cells.x0[cell] + x * cells.cell_m), 3),
        time=round(float(cells.t0[cell] + t * cells.cell_s), 3),
        congested=bool(congested[cell]),
        cell_speed=round(float(cells.speed[cell]), 3),
    )


#: Why an episode's ego cannot be placed: no recorded vehicle near the request, or no
#: room for the episode in the map and data. Such an episode is skipped (and said so).
PLACEMENT_ERRORS = (NoVehicleNearError, ScenarioError)


def episode_config(
    base: CosimConfig, spec: EpisodeSpec, *, scenario: str, t_max: float, **changes
) -> CosimConfig:
    """The cosimulation of episode ``spec``: ``base`` with the spec's road, lane, x, time
    and seed, labelled ``scenario``, ``t_max`` [s] long, and the runner's ``changes``."""
    return replace(
        base,
        scenario=scenario,
        road=spec.road,
        lane=spec.lane,
        x=spec.x,
        time=spec.time,
        seed=spec.seed,
        t_max=t_max,
        **changes,
    )


def reset_or_skip(sim) -> str | None:
    """Reset the cosimulation ``sim`` of an episode: None, or why its ego cannot be
    placed (:data:`PLACEMENT_ERRORS`; the episode is then skipped)."""
    try:
        sim.reset()
    except PLACEMENT_ERRORS as error:
        return str(error)
    return None
