"""Training a wave-dampening policy in the kinematic world: Augmented Random Search of
a linear speed policy (:mod:`twin.control.policy`) on the benchmark's own objective.

Why this and not PPO: the targets are episode figures (the fuel economy of the AV and
its 5 followers against ``human`` on the same episode, the window's economy, the time
gap's 90th percentile, collisions), which a random search optimises as they are, while
a per-step reward only stands in for them; and ARS of linear policies matches PPO on
continuous-control benchmarks at a fraction of its cost (Mania, Guy, Recht 2018). The
weights are a handful of numbers that run on numpy alone.

One iteration (ARS V1-t, their Algorithm 1):

1. draw ``episodes`` training episodes (congested cells of the recording before
   ``split_time``, as the env's ``train`` split; new ones each iteration) and run
   ``human`` on each once (kept, for the paired figures);
2. draw ``directions`` perturbations ``delta`` (standard normal, times each feature's
   :data:`~twin.control.policy.SCALES`); run the policy ``w + nu delta`` and
   ``w - nu delta`` on every episode of the iteration;
3. keep the ``top`` directions by ``max(J+, J-)`` and step
   ``w += alpha / (top sigma) sum (J+ - J-) delta`` (sigma: the standard deviation of
   their 2 x top objectives).

The objective of a run, :func:`objective`, is the paired change of the AV and its
followers' economy against ``human`` [%], minus penalties: 50 per collision of the AV, 5 per
second of time gap p90 over 4 s, 2 per percent of the window's economy below -1 %.
Every run is a cosimulation of the kinematic world (``world``) with the run's
behaviour (calibrated drivers where the store is calibrated).

Progress is printed each iteration (runs, steps, steps per second, objective, mean
change); ``OUT/curve.csv`` and ``OUT/curve.png`` are the learning curve,
``OUT/policy.json`` the weights after each iteration (atomic), so an interrupted
training keeps what it learnt. Deterministic: the same settings and seed give the same
weights (the runs are; the pool only changes their order, not the results).
"""

import csv
import math
import time
from dataclasses import asdict, dataclass
from functools import cache
from pathlib import Path

import numpy as np

from twin.control.policy import FOLLOW_LEADER, SCALES, LinearSpeedPolicy, PolicyDriver
from twin.core.atomic import atomic_file
from twin.core.errors import TwinError

CURVE = ("iteration", "runs", "env_steps", "steps_per_s", "objective_mean", "economy_pct_mean")


class TrainingError(TwinError):
    """Training cannot run: a bad setting, no episodes to train on."""


@dataclass(frozen=True)
class TrainConfig:
    """Settings of a training (see the module doc).

    Attributes:
        iterations: ARS iterations.
        directions: perturbations per iteration (N); top: the best kept (b <= N).
        episodes: training episodes per iteration (every run of an iteration on them).
        duration: [s] each episode.
        step_size: alpha; noise: nu (times each feature's scale).
        world: the world the runs are in (``kinematic`` for speed; ``physics`` works).
        road: the carriageway; split_time: [s unix] episodes end before it (default:
            the recording's middle).
        seed: the episodes' and the perturbations' seed.
        start: the weights training starts from (default: follow the leader's speed).
    """

    iterations: int = 30
    directions: int = 8
    top: int = 4
    episodes: int = 4
    duration: float = 120.0
    step_size: float = 0.3
    noise: float = 0.5
    world: str = "kinematic"
    road: str = "westbound"
    split_time: float | None = None
    seed: int = 0
    start: tuple[float, ...] = FOLLOW_LEADER

    def __post_init__(self):
        counts = {
            "iterations": self.iterations,
            "directions": self.directions,
            "top": self.top,
            "episodes": self.episodes,
        }
        for name, value in counts.items():
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise TrainingError(f"{name} must be an integer >= 1, got {value!r}")
        if self.top > self.directions:
            raise TrainingError(f"top ({self.top}) must be at most directions ({self.directions})")
        for name in ("duration", "step_size", "noise"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise TrainingError(f"{name} must be a positive number, got {value!r}")
        if len(self.start) != len(SCALES):
            raise TrainingError(f"start must hold {len(SCALES)} weights, got {self.start!r}")


def objective(run: dict, human: dict) -> tuple[float, float]:
    """(objective, the economy change [%]) of a run's figures against ``human``'s on
    the same episode (see the module doc); runs without figures score -100."""
    mine, base = run.get("ego_and_followers_mpg"), human.get("ego_and_followers_mpg")
    if mine is None or base is None or base <= 0:
        return -100.0, math.nan
    economy = 100.0 * (mine - base) / base
    window, window_base = run.get("window_mpg"), human.get("window_mpg")
    window_change = 100.0 * (window - window_base) / window_base if window and window_base else 0.0
    gap_p90 = run.get("time_gap_p90_s") or 0.0
    value = (
        economy
        - 50.0 * (run.get("collisions") or 0)
        - 5.0 * max(0.0, gap_p90 - 4.0)
        - 2.0 * max(0.0, -1.0 - window_change)
    )
    return value, economy


def train(
    store, out: str | Path, config: TrainConfig, *, workers: int = 1, progress: bool = True
) -> LinearSpeedPolicy:
    """Train (see the module doc) on ``store`` into folder ``out``; returns the policy.

    Raises:
        TrainingError: a bad setting or no training episodes.
    """
    from mapgen.build import default_map
    from twin.control.env import CONTROL_DT, ENV_ID
    from twin.runners.engines import run_jobs, where
    from twin.runners.episodes import draw_episode

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    bundle = default_map(progress=False)
    cells, sampling = _training_cells(store, bundle, config)
    location = where(store, bundle)
    rng = np.random.default_rng([config.seed, 0x415253])
    weights = np.array(config.start, dtype=np.float64)
    scales = np.array(SCALES)
    rows, start = [], time.perf_counter()
    steps_per_run = config.duration / CONTROL_DT
    for iteration in range(1, config.iterations + 1):
        tick = time.perf_counter()
        specs = [
            draw_episode(cells, sampling, config.seed, (iteration - 1) * config.episodes + e)
            for e in range(config.episodes)
        ]
        deltas = rng.standard_normal((config.directions, weights.size)) * scales
        arms = [None] + [weights + s * config.noise * d for d in deltas for s in (1, -1)]
        jobs = [(location, spec, arm, config) for arm in arms for spec in specs]
        results: dict[int, dict] = {}
        run_jobs(
            _rollout,
            jobs,
            workers=workers,
            on_done=results.__setitem__,
            describe=lambda job: f"episode {job[1].index}",
            error_type=TrainingError,
        )
        n = len(specs)
        human = [results[e] for e in range(n)]
        scores = np.array(
            [
                [objective(results[(1 + a) * n + e], human[e]) for e in range(n)]
                for a in range(2 * config.directions)
            ]
        )  # (2 directions, episodes, 2)
        mean = scores[..., 0].mean(axis=1).reshape(config.directions, 2)  # (+, -)
        best = np.argsort(-mean.max(axis=1), kind="stable")[: config.top]
        sigma = mean[best].std() or 1.0
        # deltas are in each feature's scale: the step is ARS's in scaled coordinates
        weights = weights + config.step_size / (config.top * sigma) * (
            (mean[best, 0] - mean[best, 1])[:, None] * deltas[best]
        ).sum(axis=0)
        runs = len(jobs)
        seconds = time.perf_counter() - tick
        rows.append(
            {
                "iteration": iteration,
                "runs": runs,
                "env_steps": int(runs * steps_per_run),
                "steps_per_s": round(runs * steps_per_run / seconds, 1),
                "objective_mean": round(float(mean.mean()), 3),
                "economy_pct_mean": round(float(np.nanmean(scores[..., 1])), 3),
            }
        )
        policy = LinearSpeedPolicy(
            tuple(weights),
            about={
                "trained_by": "twin.control.train (Augmented Random Search, V1-t)",
                "env": ENV_ID,
                "data": str(store.path),
                "config": {k: v for k, v in asdict(config).items()},
                "iterations_done": iteration,
                "wall_s": round(time.perf_counter() - start, 1),
            },
        )
        policy.save(out / "policy.json")
        write_curve(out, rows)
        if progress:
            r = rows[-1]
            print(
                f"iteration {iteration}/{config.iterations}: {runs} runs, "
                f"{r['env_steps']} steps at {r['steps_per_s']:.0f}/s, objective "
                f"{r['objective_mean']:+.2f}, economy vs human {r['economy_pct_mean']:+.2f} %",
                flush=True,
            )
    _plot_curve(out, rows)
    return policy


def _training_cells(store, bundle, config: TrainConfig):
    from twin.core.i24 import Road
    from twin.cosim.windows import road_limits
    from twin.data.empirical import EmpiricalTraffic
    from twin.runners.episodes import EpisodeSampling, measure_cells
    from twin.runners.evaluation import CONGESTED_TRAVEL

    road = Road.parse(config.road)
    first, last = store.time_range(road)
    split = 0.5 * (first + last) if config.split_time is None else float(config.split_time)
    if not first < split < last:
        raise TrainingError(f"split_time {split:.0f} must lie inside the recording")
    sampling = EpisodeSampling(roads=(road.value,), congested_share=1.0)
    limits = {road: road_limits(bundle, EmpiricalTraffic(store), road)}
    cells = measure_cells(
        store, sampling, limits, config.duration, window=(None, split),
        room_speed=CONGESTED_TRAVEL,
    )  # fmt: skip
    return cells, sampling


def _rollout(location, spec, weights, config: TrainConfig) -> dict:
    """One run of episode ``spec`` in the training world: ``human`` where ``weights`` is
    None, else the policy; the figures the objective reads."""
    from twin.cosim.config import SCENARIO_B, switch_world
    from twin.cosim.cosimulator import Cosimulator
    from twin.metrics.measure import control_sections
    from twin.metrics.table import flatten
    from twin.runners.engines import worker_data
    from twin.runners.episodes import episode_config, reset_or_skip
    from twin.traffic.baselines import Human

    _, bundle = worker_data(location)
    cosim = episode_config(
        switch_world(SCENARIO_B, config.world), spec, scenario="train", t_max=config.duration
    )
    driver = Human() if weights is None else PolicyDriver(LinearSpeedPolicy(tuple(weights)))
    with Cosimulator(cosim, _traffic(location), bundle, controller=driver) as sim:
        if reset_or_skip(sim) is not None:
            return {}
        sim.run(progress=False)
        row = flatten(control_sections(sim))
        ego = sim.ego_id  # the AV's own collisions: the window's others are not its doing
        collisions = sum(ego in (a, b) for _, a, b in sim.counters.collisions)
    keep = ("ego_and_followers_mpg", "window_mpg", "time_gap_p90_s")
    return {**{k: row.get(k) for k in keep}, "collisions": collisions}


@cache
def _traffic(location):
    """The recorded traffic of a worker, kept between its runs (the runs of an
    iteration share their episodes: their recording is read once)."""
    from twin.data.empirical import EmpiricalTraffic
    from twin.runners.engines import worker_data

    return EmpiricalTraffic(worker_data(location)[0])


def write_curve(out: Path, rows: list[dict], columns=CURVE) -> None:
    """``OUT/curve.csv``: a row per iteration (or generation) of ``columns``, atomically;
    a figure a row lacks is left empty."""
    with atomic_file(out / "curve.csv") as tmp, tmp.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=columns, restval="")
        writer.writeheader()
        writer.writerows(rows)


def _plot_curve(out: Path, rows: list[dict]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    steps = np.cumsum([r["env_steps"] for r in rows])
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(steps, [r["objective_mean"] for r in rows], label="objective (mean of the runs)")
    ax.plot(steps, [r["economy_pct_mean"] for r in rows], label="economy vs human [%]")
    ax.axhline(0.0, color="grey", lw=0.8)
    ax.set_xlabel("env steps (0.1 s each)")
    ax.set_ylabel("[%]")
    ax.set_title("ARS training of the linear speed policy")
    ax.legend()
    fig.tight_layout()
    with atomic_file(out / "curve.png") as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    plt.close(fig)
