"""``twin eval``: the twin's fidelity measured over many episodes, per behaviour.

Episodes are drawn from the recorded traffic as a dataset's are
(:mod:`twin.runners.episodes`: congested and free cells, episode ``i`` from ``(seed, i)``
alone), restricted to the window given; every behaviour runs the same episodes. Each
(episode, behaviour) is one cosimulation, measured as ``twin run`` measures a run
(:func:`twin.metrics.measure.measure`), on the engines the dataset runner uses
(:mod:`twin.runners.engines`: a local process pool by default, Ray as an option; same results).
The output folder::

    OUT/
      eval.json            what was evaluated (settings, data and map identity)
      results/             one JSON per (episode, behaviour), written as each finishes
      episodes.parquet     one row per (episode, behaviour) with every metric
      summary.json         median, p90 and mean of each metric per behaviour, and sums
      summary.md           the same as a Markdown table
      fidelity.png         each metric's distribution per behaviour, side by side

A run that is interrupted keeps its finished results; the same command resumes it.

Over 500 lines: the configuration, the jobs, the summary and the report of one command;
issue 78 splits them into modules of their own.
"""

import json
import math
import os
import time
import traceback
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from twin import __version__
from twin.calibration.calibrate import read_calibration
from twin.core.atomic import atomic_file, remove_stale
from twin.core.errors import StoreError, TwinError
from twin.core.i24 import Road
from twin.core.locks import output_lock
from twin.cosim.behaviour import BEHAVIOURS, Behaviour, car_following_of
from twin.cosim.config import SCENARIO_B, CosimConfig
from twin.data.store import TrajectoryStore
from twin.metrics import lane_change_zones, lane_flow_fidelity
from twin.metrics.table import SUMMARISED, flatten
from twin.runners.engines import run_jobs, where, worker_data
from twin.runners.episodes import (
    EpisodeSampling,
    EpisodeSpec,
    check_roads,
    draw_episode,
    episode_config,
    measure_cells,
    reset_or_skip,
)
from twin.runners.failures import done, ran_rows, repeat_command, repeat_path
from twin.runners.folders import claim
from twin.traffic.baselines import BASELINES
from twin.traffic.models import AUTO as AUTO_MODEL

FORMAT = "i24-twin-eval"
VERSION = 1
IDENTITY = "eval.json"
RESULTS = "results"
CONGESTED_TRAVEL = 13.4  # [m/s] room is kept ahead of an episode's ego for this speed

#: Baseline controllers named without their module (``--controller human,acc``).


class EvaluationError(TwinError):
    """An evaluation cannot run: bad settings, a folder holding something else."""


@dataclass(frozen=True)
class EvalConfig:
    """What ``twin eval`` evaluates.

    Attributes:
        road: the carriageway.
        episodes: how many episodes.
        duration: [s] each episode's length.
        behaviours: the behaviours run on every episode.
        congested_share: probability an episode starts in a congested cell.
        t_from, t_until: [s unix] episodes start and end inside this window (None: open).
        seed: the evaluation's seed (episode ``i`` draws from ``(seed, i)``).
        cosim: the other settings of each episode's cosimulation.
        controllers: ego controllers run on every episode (each with every behaviour):
            ``module:function`` or a baseline of :data:`BASELINES`; empty: the traffic
            manager drives the ego (a fidelity evaluation).
        av_share: [-] share of the visible vehicles given the controller as well as
            the ego (``--av-share``; the same vehicles for every controller of an
            episode); needs ``controllers``.
    """

    road: str = "westbound"
    episodes: int = 40
    duration: float = 120.0
    behaviours: tuple[str, ...] = BEHAVIOURS
    congested_share: float = 1.0
    t_from: float | None = None
    t_until: float | None = None
    seed: int = 0
    cosim: CosimConfig = SCENARIO_B
    controllers: tuple[str, ...] = ()
    av_share: float = 0.0

    def __post_init__(self):
        try:
            object.__setattr__(self, "road", Road.parse(self.road).value)
        except ValueError as error:
            raise EvaluationError(f"--road: {error}") from None
        if (
            not isinstance(self.episodes, int)
            or isinstance(self.episodes, bool)
            or self.episodes < 1
        ):
            raise EvaluationError(f"--episodes must be an integer >= 1, got {self.episodes!r}")
        if not (math.isfinite(self.duration) and self.duration > 0):
            raise EvaluationError(f"--duration must be a positive number, got {self.duration!r}")
        behaviours = tuple(self.behaviours)
        unknown = [b for b in behaviours if b not in BEHAVIOURS]
        if unknown or not behaviours or len(set(behaviours)) != len(behaviours):
            raise EvaluationError(
                f"--behaviour must list distinct behaviours of {', '.join(BEHAVIOURS)}, "
                f"got {','.join(behaviours) or 'none'}"
            )
        object.__setattr__(self, "behaviours", behaviours)
        controllers = tuple(controller_spec(c) for c in self.controllers)
        labels = [controller_label(c) for c in controllers]
        bad = [c for c in controllers if c.count(":") != 1 or not all(c.split(":"))]
        if bad or len(set(labels)) != len(labels):
            raise EvaluationError(
                f"--controller must list distinct controllers, each 'module:function' or one "
                f"of {', '.join(BASELINES)}, got {','.join(self.controllers)}"
            )
        object.__setattr__(self, "controllers", controllers)
        if not (isinstance(self.av_share, int | float) and 0.0 <= self.av_share <= 1.0):
            raise EvaluationError(f"--av-share must be a share in [0, 1], got {self.av_share!r}")
        if self.av_share > 0 and not controllers:
            raise EvaluationError("--av-share needs --controller (the controllers to put on)")
        if not 0.0 <= self.congested_share <= 1.0:
            raise EvaluationError(
                f"--congested-share must be in [0, 1], got {self.congested_share}"
            )
        if self.t_from is not None and self.t_until is not None and not self.t_from < self.t_until:
            raise EvaluationError(f"--from ({self.t_from}) must be before --until ({self.t_until})")

    @property
    def arms(self) -> list[tuple[str, str, str]]:
        """What runs on every episode: (label, behaviour, controller spec) each; the
        label is the behaviour's name, or the controller's (``behaviour+controller``
        with several behaviours)."""
        if not self.controllers:
            return [(b, b, "") for b in self.behaviours]
        return [
            (
                controller_label(c) if len(self.behaviours) == 1 else f"{b}+{controller_label(c)}",
                b,
                c,
            )
            for b in self.behaviours
            for c in self.controllers
        ]

    @property
    def arms_key(self) -> str:
        """``summary.json``'s key of the arms: ``controllers`` or ``behaviours``."""
        return "controllers" if self.controllers else "behaviours"

    @property
    def sampling(self) -> EpisodeSampling:
        return EpisodeSampling(roads=(self.road,), congested_share=self.congested_share)


#: ``extension(out, frame, config, summary) -> markdown``: more of an evaluation's
#: outputs, called once its rows (``frame``) are assembled. It may add to ``summary``
#: (written after it) and write files into ``out``; its Markdown is appended to
#: ``summary.md``.
Extension = Callable[[Path, object, "EvalConfig", dict], str]


@dataclass(frozen=True)
class EvalResult:
    """What :func:`evaluate` ran and wrote."""

    folder: Path
    summary: dict
    runs_done_now: int  # episode runs (an episode under one controller) made now
    total_s: float


def evaluate(
    store: TrajectoryStore,
    out: str | os.PathLike,
    config: EvalConfig,
    *,
    workers: int = 1,
    engine: str = "local",
    ray_address: str | None = None,
    bundle=None,
    progress: bool = True,
    extension: "Extension | None" = None,
    zones: "lane_change_zones.Zones | None" = None,
) -> EvalResult:
    """Run (or resume) the evaluation ``config`` into the folder ``out``; ``extension``
    adds to its outputs once the rows are in (the paired benchmark's,
    :mod:`twin.control.benchmark`). ``zones``: where the lane changes are counted by
    zone (default: the road's on-ramps and the lanes the recording shows ending,
    :func:`twin.metrics.lane_change_zones.store_zones`).

    Raises:
        EvaluationError: bad arguments, ``out`` holds something else or another
            evaluation, an episode failed (finished ones are kept; rerun to resume).
        BehaviourError: a behaviour needs a calibration the store lacks.
        SamplingError: no episode can be drawn from the data in the window.
    """
    from mapgen.build import default_map
    from twin.core.progress import progress_bar

    start = time.perf_counter()
    if not isinstance(workers, int) or isinstance(workers, bool) or workers < 1:
        raise EvaluationError(f"--workers must be an integer >= 1, got {workers!r}")
    out = Path(out)
    road, model = Road.parse(config.road), config.cosim.traffic.car_following
    for behaviour in config.behaviours:  # fails early, naming 'twin calibrate'
        Behaviour(
            behaviour, store, road, config.seed, car_following_of(model, store, behaviour, road)
        )
    bundle = bundle or default_map(progress=progress)
    specs = draw_specs(config, store, bundle)
    _claim(out, config, store, bundle)  # checks --out before anything is made beside it
    with output_lock(out, "twin eval"):
        results = out / RESULTS
        results.mkdir(exist_ok=True)
        remove_stale(results)
        jobs = _jobs(config, specs, out, where(store, bundle), workers)
        todo = sum(len(job[1]) for job in jobs)
        with progress_bar(
            progress=progress,
            total=todo,
            unit="episode",
            desc=f"eval {out.name}: {todo} of {len(specs) * len(config.arms)} to run",
        ) as bar:

            def save(k: int, rows: list[dict]) -> None:
                _, chunk, arm, _ = jobs[k]
                for spec, row in zip(chunk, rows, strict=True):
                    repeat = repeat_path(out, spec.index, arm[0])
                    if row.get("failed"):
                        cosim, _ = _episode(config, spec, arm)
                        row["repeat"] = repeat_command(repeat, cosim, store)
                    else:
                        repeat.unlink(missing_ok=True)  # a retry that ran
                    with atomic_file(_result_path(out, spec.index, arm[0])) as tmp:
                        tmp.write_text(json.dumps(row, allow_nan=False) + "\n")
                bar.update(len(rows))

            run_jobs(
                _run_chunk,
                jobs,
                engine=engine,
                workers=workers,
                ray_address=ray_address,
                on_done=save,
                describe=lambda job: (
                    f"episode{'s' if len(job[1]) > 1 else ''} "
                    f"{', '.join(str(s.index) for s in job[1])} ({job[2][0]})"
                ),
                error_type=EvaluationError,
            )
        zones = zones or lane_change_zones.store_zones(store, road)
        summary = assemble(out, config, specs, extension, zones)
        return EvalResult(out, summary, todo, time.perf_counter() - start)


def draw_specs(config: EvalConfig, store: TrajectoryStore, bundle) -> list[EpisodeSpec]:
    """The evaluation's episodes (see the module doc)."""
    from twin.cosim.windows import road_limits
    from twin.data.empirical import EmpiricalTraffic

    sampling = config.sampling
    check_roads(store, sampling)
    road = Road.parse(config.road)
    limits = {road: road_limits(bundle, EmpiricalTraffic(store), road)}
    cells = measure_cells(
        store,
        sampling,
        limits,
        config.duration,
        window=(config.t_from, config.t_until),
        room_speed=CONGESTED_TRAVEL,
    )
    return [draw_episode(cells, sampling, config.seed, i) for i in range(config.episodes)]


BATCH = 8  # episodes of an arm a worker runs together in the batched core


def _jobs(config: EvalConfig, specs, out: Path, location, workers: int) -> list[tuple]:
    """The jobs of the episodes not done yet: per arm, chunks of episodes the batched
    core runs together (kinematic world, controllers it has kernels for; at most
    :data:`BATCH`, and enough chunks to keep the workers busy), else one per job."""
    jobs = []
    for arm in config.arms:
        todo = [s for s in specs if not done(_result_path(out, s.index, arm[0]))]
        size = BATCH if _batched(config, arm) else 1
        if size > 1:
            size = max(1, min(size, -(-len(todo) // max(workers, 1))))
        for k in range(0, len(todo), size):
            jobs.append((config, todo[k : k + size], arm, location))
    return jobs


def _batched(config: EvalConfig, arm: tuple) -> bool:
    """Whether an arm's episodes run in the batched core together."""
    from twin.cosim.core.batch import COMPILED

    return config.cosim.world == "kinematic" and arm[2] in COMPILED


def _episode(config: EvalConfig, spec: EpisodeSpec, arm: tuple):
    """The cosimulation configuration of episode ``spec`` in ``arm``, and its row's
    identity columns."""
    label, behaviour, controller = arm
    cosim = episode_config(
        config.cosim,
        spec,
        scenario="eval",
        t_max=config.duration,
        behaviour=behaviour,
        camera=replace(config.cosim.camera, enabled=False),
        ego_controller=controller,
        av_share=config.av_share if controller else 0.0,
    )
    columns = {k: v for k, v in spec.to_dict().items() if k != "index"}
    row = {
        "episode": spec.index,
        "arm": label,
        "behaviour": behaviour,
        "controller": controller_label(controller) if controller else None,
        **columns,
    }
    return cosim, row


def episode_cosim(config: EvalConfig, spec: EpisodeSpec, behaviour: str):
    """The cosimulation configuration of episode ``spec`` driven by ``behaviour``, no
    controller: what ``twin eval`` runs (:func:`_episode`)."""
    return _episode(config, spec, (behaviour, behaviour, ""))[0]


def _run_chunk(config: EvalConfig, chunk: list, arm: tuple, location) -> list[dict]:
    """Episodes ``chunk`` of ``arm``: their cosimulations and metrics as flat rows, with
    the ego's and its followers' speeds each second (for the pictures); in the batched
    core together where it can (:func:`_batched`), else one by one."""
    if _batched(config, arm):
        try:
            return _run_batch(config, chunk, arm, location)
        except StoreError:
            raise
        except Exception as error:  # which episode failed: each alone, each recorded
            rows = [_failsafe(config, spec, arm, location) for spec in chunk]
            if len(chunk) > 1 and all(row.get("failed") for row in rows):
                raise EvaluationError(  # the same for every episode: not one episode's
                    f"every episode of a batch failed ({rows[0]['failed']}); the batch: "
                    f"{type(error).__name__}: {error}"
                ) from error
            return rows
    return [_failsafe(config, spec, arm, location) for spec in chunk]


def _failsafe(config: EvalConfig, spec: EpisodeSpec, arm: tuple, location) -> dict:
    """:func:`_run_one`, or the episode's row marked ``failed`` with the error (a
    controller's non-finite command, a bug): one episode does not end a sweep."""
    try:
        return _run_one(config, spec, arm, location)
    except StoreError:
        raise  # the data are gone or damaged: every episode would fail the same way
    except Exception as error:
        _, row = _episode(config, spec, arm)
        where = traceback.extract_tb(error.__traceback__)[-1]
        return {
            **row,
            "skipped": None,
            "failed": f"{type(error).__name__}: {error} (at {where.filename}:{where.lineno})",
        }


def _run_one(config: EvalConfig, spec: EpisodeSpec, arm: tuple, location) -> dict:
    """One (episode, arm) in the cosimulator (either world, any controller)."""
    from twin.cosim.cosimulator import Cosimulator
    from twin.data.empirical import EmpiricalTraffic
    from twin.metrics.measure import measure

    store, bundle = worker_data(location)
    cosim, row = _episode(config, spec, arm)
    with Cosimulator(cosim, EmpiricalTraffic(store), bundle) as sim:
        setup = time.perf_counter()
        skipped = reset_or_skip(sim)
        if skipped is not None:
            return {**row, "skipped": skipped}
        begin = time.perf_counter()
        sim.run(progress=False)
        loop_s = time.perf_counter() - begin
        figures, frames = measure(sim, store, loop_s, begin - setup)
    return _row(row, figures, frames, sim.ego_id, cosim.dt)


def _run_batch(config: EvalConfig, chunk: list, arm: tuple, location) -> list[dict]:
    """Episodes ``chunk`` of ``arm`` stepped together in the batched core; each
    measured as the cosimulator's run is (:class:`twin.cosim.cosimulator.Finished`)."""
    from twin.cosim.core.batch import Batch
    from twin.cosim.core.step import step_batch
    from twin.cosim.cosimulator import Finished, StepTimes
    from twin.metrics.measure import measure
    from twin.runners.episodes import PLACEMENT_ERRORS

    store, _ = worker_data(location)
    episodes = [_episode(config, spec, arm) for spec in chunk]
    shared = _shared(location, episodes[0][0])
    batch = Batch(shared, len(chunk), log=True)
    rows: list[dict | None] = [None] * len(chunk)
    setup = time.perf_counter()
    for b, (cosim, row) in enumerate(episodes):
        try:
            batch.reset(b, lane=cosim.lane, x=cosim.x, time=cosim.time, seed=cosim.seed)
        except PLACEMENT_ERRORS as error:
            rows[b] = {**row, "skipped": str(error)}
    begin = time.perf_counter()
    while not batch.done.all():
        step_batch(batch.core)
    batch.check_all()
    loop_s = (time.perf_counter() - begin) / len(chunk)  # each episode's share
    reset_s = (begin - setup) / len(chunk)
    for b, (cosim, row) in enumerate(episodes):
        if rows[b] is not None:
            continue
        times = StepTimes(steps=int(batch.state.episodes.step[b]), total=loop_s, physics=loop_s)
        finished = Finished(shared, batch, b, cosim, times)
        figures, frames = measure(finished, store, loop_s, reset_s)
        rows[b] = _row(row, figures, frames, finished.ego_id, cosim.dt)
    return rows


_SHARED: dict = {}


def _shared(location, cosim):
    """What a worker's batches of one configuration share (made once per process)."""
    from twin.cosim.core.batch import Shared
    from twin.data.empirical import EmpiricalTraffic

    key = (location, repr(replace(cosim, lane=-1, x=0.0, time=SCENARIO_B.time, seed=0)))
    if key not in _SHARED:
        store, bundle = worker_data(location)
        _SHARED[key] = Shared.make(store, bundle, cosim, traffic=EmpiricalTraffic(store))
    return _SHARED[key]


def _row(row: dict, figures: dict, frames, ego_id: int, dt: float) -> dict:
    traces = speed_traces(frames[0], ego_id, figures["control"]["followers"], dt)
    return {
        **row,
        "skipped": None,
        **flatten(figures),
        **traces,
        "lane_flows": figures["lane_flows"],
    }


def speed_traces(vehicles, ego_id: int, followers: list[int], dt: float) -> dict:
    """The ego's and each follower's speed [m/s] each second (NaN where absent)."""
    every = max(1, round(1.0 / dt))
    step = np.round(vehicles["time"].to_numpy() / dt).astype(np.int64)
    rows = vehicles[step % every == 0]
    seconds = np.unique(np.round(rows["time"].to_numpy()).astype(np.int64))

    def trace(vid: int) -> list:
        mine = rows[rows["id"] == vid]
        at = dict(zip(np.round(mine["time"]).astype(np.int64), mine["speed"], strict=True))
        return [round(float(at[t]), 3) if t in at else None for t in seconds]

    return {"ego_speeds": trace(ego_id), "follower_speeds": [trace(f) for f in followers]}


def _result_path(out: Path, index: int, label: str) -> Path:
    return out / RESULTS / f"{index:06d}-{label}.json"


def controller_spec(name: str) -> str:
    """``module:function`` of a controller named on the command line."""
    return f"twin.controllers:{name}" if name in BASELINES else name


def controller_label(spec: str) -> str:
    """A controller's short name: its function's."""
    return spec.rpartition(":")[2]


def _identity(config: EvalConfig, store: TrajectoryStore, bundle) -> dict:
    calibration = read_calibration(store)
    settings = _config_identity(config)
    traffic = settings["cosim"]["traffic"]
    if traffic["car_following"] == AUTO_MODEL:  # kept as the model it means here
        traffic["car_following"] = car_following_of(AUTO_MODEL, store, "calibrated", config.road)
    return {
        "format": FORMAT,
        "version": VERSION,
        "config": settings,
        "data": {
            "store": str(store.path),
            "roads": store.metadata.get("roads"),
            "calibration": calibration["created"] if calibration else None,
        },
        "map": bundle.key,
    }


def _config_identity(config: EvalConfig) -> dict:
    """The settings of an evaluation as they are kept in ``eval.json``."""
    return json.loads(json.dumps(asdict(config), default=str))


def _claim(out: Path, config: EvalConfig, store: TrajectoryStore, bundle) -> None:
    """Make ``out`` this evaluation's folder, or check that it already is
    (:func:`twin.runners.folders.claim`)."""
    claim(
        out, IDENTITY, _identity(config, store, bundle), kind="evaluation",
        noun="evaluation", error=EvaluationError,
        defaults={"config": _config_identity(EvalConfig())},
    )  # fmt: skip


def assemble(
    out: Path, config: EvalConfig, specs: list[EpisodeSpec], extension: "Extension | None" = None,
    zones: "lane_change_zones.Zones | None" = None,
) -> dict:  # fmt: skip
    """Write episodes.parquet, summary.json, summary.md and fidelity.png from the
    results of ``specs`` (and what ``extension`` adds); returns the summary. ``zones``:
    the road's (:mod:`twin.metrics.lane_change_zones`) the lane changes are counted by
    (default: its on-ramps' weaves, no drop)."""
    import pandas as pd
    import pyarrow as pa
    import pyarrow.parquet as pq

    rows, flows = [], {label: [] for label, _, _ in config.arms}
    for spec in specs:
        for label, _, _ in config.arms:
            row = _read_result(_result_path(out, spec.index, label))
            flows[label].append(row.pop("lane_flows", None))  # nested: summed, not a column
            rows.append(row)
    frame = pd.DataFrame(rows)
    for name in SUMMARISED:
        if name not in frame:
            frame[name] = np.nan
        frame[name] = pd.to_numeric(frame[name], errors="coerce")
    with atomic_file(out / "episodes.parquet") as tmp:
        pq.write_table(pa.Table.from_pandas(frame, preserve_index=False), tmp)
    summary = summarise(frame, config)
    lane_flows = {label: lane_flow_fidelity.sum_episodes(f) for label, f in flows.items()}
    zones = zones or lane_change_zones.road_zones(config.road)
    summary["lane_change_zones"] = zones.to_dict()
    by_zone = {}
    for label, summed in lane_flows.items():
        summary[config.arms_key][label]["lane_flows"] = summed
        by_zone[label] = lane_change_zones.by_zone(summed and summed.get("changes"), zones)
        summary[config.arms_key][label]["lane_changes_by_zone"] = by_zone[label]
    more = extension(out, frame, config, summary) if extension is not None else ""
    with atomic_file(out / "summary.json") as tmp:
        tmp.write_text(json.dumps(summary, indent=1, allow_nan=False) + "\n")
    with atomic_file(out / "summary.md") as tmp:
        tmp.write_text(
            markdown(summary) + lane_flow_fidelity.markdown(lane_flows)
            + lane_change_zones.markdown(by_zone, zones) + more
        )  # fmt: skip
    with atomic_file(out / "fidelity.png") as tmp:
        _plot(frame, config, tmp, lane_flows)
    return summary


def _read_result(path: Path) -> dict:
    """One episode's row, as it was written.

    Raises:
        EvaluationError: naming the file when it is not the JSON object it was written
            as (damaged after it was written: the twin writes it whole or not at all).
    """
    try:
        row = json.loads(path.read_text())
        problem = None if isinstance(row, dict) else "not a JSON object"
    except ValueError as error:
        problem = str(error)
    if problem is not None:
        raise EvaluationError(
            f"{path} is damaged ({problem}); remove it and run the same command again to "
            "redo that episode"
        )
    return row


def summarise(frame, config: EvalConfig) -> dict:
    """Per arm (behaviour, or controller): median, p90 and mean of each metric over the
    episodes that ran, sums of the counts, and the episodes skipped."""
    out = {
        "format": FORMAT,
        "version": __version__,
        "road": config.road,
        "episodes": config.episodes,
        "duration_s": config.duration,
        config.arms_key: {},
    }
    for label, _, _ in config.arms:
        rows = frame[frame["arm"] == label]
        ran = ran_rows(rows)
        failed = rows[rows["failed"].notna()] if "failed" in rows else rows.iloc[:0]
        entry = {
            "episodes_run": len(ran),
            "episodes_skipped": len(rows) - len(ran) - len(failed),
            "metrics": {},
        }
        if len(failed):
            entry["episodes_failed"] = len(failed)
            entry["failures"] = [
                {"episode": int(r.episode), "error": r.failed, "repeat": r.repeat}
                for r in failed.itertuples()
            ]
        for name, kind in SUMMARISED.items():
            values = ran[name].to_numpy(dtype=np.float64)
            values = values[np.isfinite(values)]
            if kind == "sum":
                entry["metrics"][name] = {"sum": float(values.sum()), "count": int(values.size)}
            else:
                entry["metrics"][name] = {
                    "median": _r(np.median(values)) if values.size else None,
                    "p90": _r(np.quantile(values, 0.9)) if values.size else None,
                    "mean": _r(values.mean()) if values.size else None,
                    "min": _r(values.min()) if values.size else None,
                    "max": _r(values.max()) if values.size else None,
                    "count": int(values.size),
                }
        recorded = entry["metrics"]["lane_changes_recorded"]["sum"]
        simulated = entry["metrics"]["lane_changes_simulated"]["sum"]
        entry["lane_changes_ratio"] = _r(simulated / recorded) if recorded else None
        out[config.arms_key][label] = entry
    return out


def _r(value) -> float:
    return round(float(value), 4)


def markdown(summary: dict) -> str:
    """The summary as a Markdown table: one row per metric, a column per arm."""
    key = "controllers" if "controllers" in summary else "behaviours"
    behaviours = list(summary[key])
    lines = [
        f"# twin eval: {summary['road']}, {summary['episodes']} episodes of "
        f"{summary['duration_s']:g} s",
        "",
        "| metric | " + " | ".join(behaviours) + " |",
        "|---|" + "---|" * len(behaviours),
    ]
    for name, kind in SUMMARISED.items():
        cells = []
        for b in behaviours:
            m = summary[key][b]["metrics"][name]
            if kind == "sum":
                cells.append(f"{m['sum']:g}")
            elif m["median"] is None:
                cells.append("-")
            else:
                cells.append(f"{m['median']:.2f} / {m['p90']:.2f}")
        label = name if kind == "sum" else f"{name} (median / p90)"
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    ratio = [summary[key][b]["lane_changes_ratio"] for b in behaviours]
    lines.append(
        "| lane changes simulated / recorded | "
        + " | ".join("-" if r is None else f"{r:.2f}" for r in ratio)
        + " |"
    )
    runs = [summary[key][b] for b in behaviours]
    lines.append(
        "| episodes run (skipped) | "
        + " | ".join(f"{e['episodes_run']} ({e['episodes_skipped']})" for e in runs)
        + " |"
    )
    failures = [(b, f) for b in behaviours for f in summary[key][b].get("failures", [])]
    if failures:
        lines += ["", f"## Failed episodes ({len(failures)}): not in the figures above", ""]
        lines += [
            f"- episode {f['episode']} ({b}): {f['error']}; repeat: `{f['repeat']}`"
            for b, f in failures
        ]
    return "\n".join(lines) + "\n"


def _plot(frame, config: EvalConfig, path: Path, lane_flows: dict | None = None) -> None:
    """``fidelity.png``: each fidelity metric's distribution per arm (top row); the lane
    changes by lane pair and the net flow out of each lane by position, summed over the
    episodes, simulated against recorded (bottom row)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    shown = [
        ("ego_speed_rmse_mps", "ego speed RMSE", "m/s"),
        ("ego_position_error_end_m", "ego position error at the end", "m"),
        ("speed_field_rmse_mps", "speed-field RMSE, all lanes", "m/s"),
        ("slow_spell_end_difference_s", "slow spell end, simulated - recorded", "s"),
        ("lane_changes_simulated", "lane changes simulated per episode", "count"),
    ]
    fig, axes = plt.subplots(2, len(shown), figsize=(4.2 * len(shown), 8.4))
    arms = [label for label, _, _ in config.arms]
    for ax, (name, title, unit) in zip(axes[0], shown, strict=True):
        data = []
        for arm in arms:
            values = frame.loc[frame["arm"] == arm, name].to_numpy(dtype=float)
            data.append(values[np.isfinite(values)])
        ax.boxplot(data, showfliers=True)
        ax.set_xticks(range(1, len(arms) + 1), arms)
        ax.set_title(title, fontsize=10)
        ax.set_ylabel(f"{title} [{unit}]", fontsize=9)
        ax.grid(axis="y", alpha=0.3)
    lane_flow_fidelity.draw(axes[1][0], axes[1][1:], lane_flows or {})
    fig.suptitle(f"twin eval: {config.road}, {config.episodes} x {config.duration:g} s episodes")
    fig.tight_layout()
    fig.savefig(path, dpi=110, format="png")
    plt.close(fig)


def folder_line(result: EvalResult) -> str:
    """The terminal's first line: where the evaluation is and what ran now."""
    return (
        f"evaluation folder: {result.folder} (ran {result.runs_done_now} now, "
        f"{result.total_s:.0f} s)"
    )


def summary_lines(result: EvalResult) -> str:
    """A few lines for the terminal: each behaviour's fidelity."""
    s = result.summary
    lines = [folder_line(result)]
    for behaviour, entry in s["behaviours"].items():
        m = entry["metrics"]
        speed, end = _stat(m, "ego_speed_rmse_mps"), _stat(m, "ego_position_error_end_m")
        ratio = entry["lane_changes_ratio"]
        lines.append(
            f"{behaviour:<11} ego speed RMSE {speed} m/s, end error {end} m, field RMSE "
            f"{_stat(m, 'speed_field_rmse_mps')} m/s (median / p90); lane changes "
            f"{m['lane_changes_simulated']['sum']:g} vs {m['lane_changes_recorded']['sum']:g} "
            f"recorded ({'-' if ratio is None else f'{ratio:.2f}'}); collisions "
            f"{m['collisions']['sum']:g}, stalled {m['stalled_across_lines']['sum']:g}"
            + _as_recorded(m)
            + _merge_words(m)
            + _flow_words(entry.get("lane_flows"))
            + _zone_words(entry.get("lane_changes_by_zone"))
            + _seam_words(m)
        )
    return "\n".join(lines)


def _as_recorded(m: dict) -> str:
    """How many of the stalled vehicles stood across the line with their recordings
    (absent from folders written before the split was measured)."""
    entry = m.get("stalled_as_recorded")
    return "" if entry is None else f" ({entry['sum']:g} as recorded)"


def _merge_words(m: dict) -> str:
    """The on-ramp's merges over the episodes, where there were any: how many ramp
    vehicles merged before the taper's end, of those whose outcome was seen (merged or
    waiting for a gap) and of those that merged or reached the lane's end
    (:mod:`twin.metrics.merges`)."""
    if "ramp_vehicles" not in m or not m["ramp_vehicles"]["sum"]:
        return ""
    seen = m["merges"]["sum"] + m["merges_waiting"]["sum"]
    reached = m["merges"]["sum"] + m["merges_waiting_at_end"]["sum"]
    entered = m.get("merges_entered_past_end", {}).get("sum") or 0
    late = f" ({entered:g} more spawned past the end)" if entered else ""
    return (f"; merges before the taper's end {m['merges_before_taper_end']['sum']:g} of "
            f"{seen:g} (ramp vehicles {m['ramp_vehicles']['sum']:g}, waiting "
            f"{m['merges_waiting']['sum']:g}), of {reached:g} that merged or reached the "
            f"lane's end{late}")  # fmt: skip


def _seam_words(m: dict) -> str:
    """The ghost-cell boundary's figures over the episodes: hand-overs to ghosts and their
    largest jump, vehicles that vanished, the relaxing vehicles' range of acceleration
    and largest distance from their recordings."""
    words = (f"; hand-overs to ghosts {m['handovers_to_ghost']['sum']:g} (largest jump "
             f"{_extreme(m, 'handover_to_ghost_jump_max_m', 'max')} m), vanished "
             f"{m['handovers_into_visible_window']['sum']:g}")  # fmt: skip
    if m["relaxing_vehicles"]["sum"]:
        words += (f"; relaxing {m['relaxing_vehicles']['sum']:g} (acceleration "
                  f"{_extreme(m, 'relaxing_accel_min_mps2', 'min')} to "
                  f"{_extreme(m, 'relaxing_accel_max_mps2', 'max')} m/s^2, up to "
                  f"{_extreme(m, 'relaxing_distance_max_m', 'max')} m from its "
                  "recording)")  # fmt: skip
    return words


def _extreme(metrics: dict, name: str, which: str) -> str:
    value = metrics[name][which]
    return "-" if value is None else f"{value:.2f}"


def _flow_words(flows: dict | None) -> str:
    if not flows or flows["net_flow_error"] is None:
        return ""
    return (
        f"; net lane flow error {flows['net_flow_error']:.2f} "
        f"({flows['bins_within']} of {flows['bins_judged']} bins within "
        f"{lane_flow_fidelity.WITHIN:.0%})"
    )


def _zone_words(counts: dict | None) -> str:
    words = lane_change_zones.describe(counts or {})
    return f"; lane changes by zone {words}" if words else ""


def _stat(metrics: dict, name: str) -> str:
    m = metrics[name]
    return "-" if m["median"] is None else f"{m['median']:.2f} / {m['p90']:.2f}"
