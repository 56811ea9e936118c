"""Training the MLP wave-dampening policy (:mod:`twin.control.mlp`) with an evolution
strategy on the batched vector env (:class:`twin.control.vector_env.
VectorWaveDampeningEnv`): every member of a generation's population drives its own
sub-envs, all stepped together by one kernel call of the batched core.

Why an evolution strategy and not PPO: the targets are episode figures (the economy of
the AV and its followers, time gaps, time to collision, jerk, the safety layer's time,
collisions), which a strategy optimises as they are, where a per-step reward only
stands in for them; it needs no gradient of the twin, runs on numpy alone (no extra),
and its cost is env steps, which the batched core makes cheap. OpenAI's evolution
strategy (Salimans, Ho, Chen, Sidor, Sutskever 2017, "Evolution Strategies as a
Scalable Alternative to Reinforcement Learning") with its antithetic pairs, centred
ranks, Adam and weight decay.

One generation:

1. draw ``episodes`` training episodes (congested cells of the recording before
   ``split_time``, the env's ``train`` split) and ``population`` perturbations
   ``eps`` of the weights (standard normal); with other mornings (``also``) the
   episodes are dealt out over ``data`` and them in turn (morning ``k`` of ``n`` gives
   as many as ``range(k, episodes, n)`` holds: 4 over 3 mornings are 2, 1 and 1);
2. run the weights ``theta + sigma eps`` and ``theta - sigma eps`` of every pair on
   every episode of the generation: ``2 population episodes`` sub-envs of one vector
   env per morning (the same episodes for every member: their differences are the
   policy's);
3. score each run (:func:`score`), rank the members per episode (centred ranks in
   [-0.5, 0.5]) and average over the episodes;
4. step ``theta`` with Adam along ``sum (rank+ - rank-) eps / (population sigma)``,
   less ``weight_decay theta``.

The score of a run puts the targets in the objective: the AV and its followers' fuel
economy against the generation's median run of the same episode [%], minus
:data:`PENALTIES`: per collision, per second of time gap p10 under 1 s, of p90 over 4 s
(or over the training's ``time_gap_p90_max``),
of minimum time to collision under 5 s, per m/s^3 of jerk RMS over 0.5, per percent of
the episode with the safety layer active. The env runs with the safety layer (the
drivers' emergency braking) beneath the policy, as the twin drives it, and its time
counts.

Every ``heldout_every`` generations (and at the last) the current weights drive
``heldout_episodes`` fixed episodes of the ``test`` split of ``data`` (not of
``also``: the held-out score stays comparable between trainings); the score is their
economy against ``human``'s on the same episodes [%] (the vector env's ``ego="human"``,
the benchmark's pairing), with their comfort and safety figures.

Progress is printed each generation (env steps, steps per second, score, economy,
held-out); ``OUT/curve.csv`` and ``OUT/curve.png`` are the learning curve (env steps
and wall time on the x-axes; the picture is drawn at each held-out score);
``OUT/policy.json`` the weights and
``OUT/checkpoint.npz`` the whole state (weights, Adam's moments, the random generator,
the curve) after each generation, written atomically, so an interrupted training
resumes where it stopped (the same command again) and ends with the same weights as
one that was not interrupted.
"""

import hashlib
import json
import math
import time
import zipfile
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from twin.control.mlp import HIDDEN, Actor, MLPPolicy, check_memory, initial_weights, n_weights
from twin.control.train import TrainingError, write_curve
from twin.core.atomic import atomic_file

#: The score's penalties (see the module doc), per unit of each excess.
PENALTIES = {
    "collision": 50.0,
    "time_gap_p10_under_1s": 10.0,
    "time_gap_p90_over_max": 20.0,
    "min_ttc_under_5s": 2.0,
    "jerk_rms_over_0_5": 10.0,
    "safety_percent": 2.0,
}
CURVE = (
    "generation", "env_steps", "wall_s", "steps_per_s", "score_mean", "economy_pct_mean",
    "heldout_economy_pct", "heldout_time_gap_p10_s", "heldout_min_ttc_s",
    "heldout_jerk_rms_mps3", "heldout_safety_pct", "heldout_collisions",
)  # fmt: skip
TIME_GAP_CAP = 10.0  # [s] time gaps are counted up to this (and are this with no leader)
#: [s] the time gap's p90 the score penalises runs over by default: the target's 4 s. A
#: training may ask for a margin below it (``time_gap_p90_max``): an episode of the
#: training is shorter than the evaluation's, and the target is on the median episode.
TIME_GAP_P90_MAX = 4.0
HELDOUT_TRIES = 1000  # held-out episodes are the first that can be placed among these


@dataclass(frozen=True)
class EvolveConfig:
    """Settings of a training (see the module doc).

    Attributes:
        generations: how many.
        population: antithetic pairs per generation.
        episodes: training episodes per generation (every member runs each).
        duration: [s] each episode.
        sigma: the perturbations' standard deviation.
        learning_rate: Adam's step size; weight_decay: per generation, times theta.
        hidden: the MLP's hidden layers.
        heldout_every: generations between held-out scores; heldout_episodes: how many.
        obs_noise, latency_steps: the env's (train under noise and latency).
        smoothing, jerk_from: the policy's memory (:class:`twin.control.mlp.Actor`).
        start: a policy file whose weights it starts from (its hidden layers must be
            these; its smoothing and jerk_from are replaced by these) instead of drawn
            weights that follow the leader.
        data: the store (``embedded:morning`` by default): its training split, and
            its test split for the held-out scores.
        also: other stores whose training splits it trains on too (other mornings;
            ``episodes`` must be at least one per morning).
        seed: the episodes', perturbations' and initial weights' seed.
        time_gap_p90_max: [s] the time gap p90 the score penalises a run over (the 4 s
            target by default; lower: a margin under it).
    """

    generations: int = 100
    population: int = 32
    episodes: int = 4
    duration: float = 60.0
    sigma: float = 0.05
    learning_rate: float = 0.01
    weight_decay: float = 0.005
    hidden: tuple[int, ...] = HIDDEN
    heldout_every: int = 5
    heldout_episodes: int = 16
    obs_noise: float = 0.0
    latency_steps: int = 0
    smoothing: float = 0.0
    jerk_from: str = "measured"
    start: str | None = None
    data: str = "embedded:morning"
    also: tuple[str, ...] = ()
    seed: int = 0
    time_gap_p90_max: float = TIME_GAP_P90_MAX

    def __post_init__(self):
        object.__setattr__(self, "hidden", tuple(self.hidden))
        object.__setattr__(self, "data", str(self.data))  # a Path too
        if isinstance(self.also, str | bytes):
            raise TrainingError(f"also must be a list of stores, got {self.also!r}")
        object.__setattr__(self, "also", tuple(str(a) for a in self.also))
        for name in ("generations", "population", "episodes", "heldout_every",
                     "heldout_episodes"):  # fmt: skip
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise TrainingError(f"{name} must be an integer >= 1, got {value!r}")
        for name in ("duration", "sigma", "learning_rate", "time_gap_p90_max"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise TrainingError(f"{name} must be a positive number, got {value!r}")
        if not (math.isfinite(self.weight_decay) and self.weight_decay >= 0):
            raise TrainingError(f"weight_decay must be >= 0, got {self.weight_decay!r}")
        if not self.hidden or not all(isinstance(h, int) and h >= 1 for h in self.hidden):
            raise TrainingError(f"hidden must be layer sizes >= 1, got {self.hidden!r}")
        try:
            check_memory(self.smoothing, self.jerk_from)
        except ValueError as error:
            raise TrainingError(str(error)) from None
        if self.start is not None:
            object.__setattr__(self, "start", str(self.start))  # a Path too
        if self.episodes < len(self.mornings):
            raise TrainingError(
                f"episodes ({self.episodes}) must be at least one per morning "
                f"({len(self.mornings)}: data and also)"
            )
        if len({_same_file(m) for m in self.mornings}) < len(self.mornings):
            raise TrainingError(f"a morning is named twice in data and also: {self.mornings}")

    @property
    def num_envs(self) -> int:
        """Sub-envs of the vector envs together: every member on every episode."""
        return 2 * self.population * self.episodes

    @property
    def mornings(self) -> tuple[str, ...]:
        """The stores it trains on: ``data``, then ``also``."""
        return (self.data, *self.also)

    def per_morning(self) -> list[int]:
        """How many of a generation's episodes each morning gives (module doc)."""
        n = len(self.mornings)
        return [len(range(k, self.episodes, n)) for k in range(n)]


def _same_file(store: str) -> str:
    """``store`` as the file it names (a link or another spelling of one path the
    same), an embedded name as it is."""
    return store if store.startswith("embedded:") else str(Path(store).resolve())


def score(figures: dict, time_gap_p90_max: float = TIME_GAP_P90_MAX) -> tuple[float, float]:
    """(score, economy [%]) of a run's ``figures``: ``economy_pct`` against the median
    run of its episode and the comfort and safety figures (:func:`rollout`), the time
    gap's p90 penalised over ``time_gap_p90_max`` [s]; see the module doc."""
    p = PENALTIES
    economy = figures["economy_pct"]
    value = (
        economy
        - p["collision"] * figures["collisions"]
        - p["time_gap_p10_under_1s"] * max(0.0, 1.0 - figures["time_gap_p10_s"])
        - p["time_gap_p90_over_max"] * max(0.0, figures["time_gap_p90_s"] - time_gap_p90_max)
        - p["min_ttc_under_5s"] * max(0.0, 5.0 - figures["min_ttc_s"])
        - p["jerk_rms_over_0_5"] * max(0.0, figures["jerk_rms_mps3"] - 0.5)
        - p["safety_percent"] * figures["safety_pct"]
    )
    return value, economy


def rollout(env, thetas: np.ndarray, episodes: list[int], actor: Actor, seed: int) -> list[dict]:
    """Run sub-env ``b`` of vector ``env`` on episode ``episodes[b]`` with weights
    ``thetas[b]`` to its end, deciding with a fresh ``actor`` (its memory: one row per
    sub-env), the sub-envs' generators (observation noise) seeded from
    ``seed``; each one's figures: the env's metrics with the time gap's p10 and p90 [s]
    (over every step; one with no leader within the gap cap counts as 10 s), the safety
    layer's share of the time [%], collisions and ``mpg`` (NaN where there is none)."""
    n = env.num_envs
    obs, _ = env.reset(seed=int(seed), options={"episode": list(episodes)})
    done = np.zeros(n, dtype=bool)
    figures: list[dict | None] = [None] * n
    gaps: list[list[np.ndarray]] = []
    while not done.all():
        actions = actor(thetas, obs)
        obs_before = obs
        obs, _, terminated, truncated, info = env.step(actions[:, None])
        speed, gap = obs_before[:, 0].astype(np.float64), obs_before[:, 2].astype(np.float64)
        gaps.append(np.where(done, np.nan, np.minimum(np.maximum(gap, 0.0) / np.maximum(speed, 1.0),
                                                      TIME_GAP_CAP)))  # fmt: skip
        ended = np.flatnonzero((terminated | truncated) & ~done)
        for b in ended:
            metrics = {name: values[b] for name, values in info["metrics"].items()}
            figures[b] = metrics
        done |= terminated | truncated
    series = np.array(gaps)  # (steps, n)
    out = []
    for b in range(n):
        m = figures[b]
        g = series[:, b][np.isfinite(series[:, b])]
        seconds = max(float(m["simulated_s"]), 1e-9)
        ttc, mpg = m["min_ttc_s"], m["ego_and_followers_mpg"]
        out.append({
            "mpg": np.nan if mpg is None else float(mpg),
            "collisions": int(m["collisions"]),
            "time_gap_p10_s": float(np.quantile(g, 0.1)) if g.size else TIME_GAP_CAP,
            "time_gap_p90_s": float(np.quantile(g, 0.9)) if g.size else TIME_GAP_CAP,
            "min_ttc_s": 1e3 if ttc is None or not math.isfinite(ttc) else float(ttc),
            "jerk_rms_mps3": float(m["jerk_rms_mps3"]),
            "safety_pct": 100.0 * float(m["safety_override_s"]) / seconds,
        })  # fmt: skip
    return out


def centred_ranks(values: np.ndarray) -> np.ndarray:
    """Ranks of ``values`` (n,) scaled to [-0.5, 0.5] (ties by order: deterministic; a
    NaN lowest)."""
    n = values.size
    values = np.where(np.isfinite(values), values, -np.inf)  # NaN ranks lowest
    ranks = np.empty(n)
    ranks[np.argsort(values, kind="stable")] = np.arange(n)
    return ranks / max(n - 1, 1) - 0.5


def evolve(out: str | Path, config: EvolveConfig, *, progress: bool = True) -> MLPPolicy:
    """Train (see the module doc) into folder ``out`` (resuming what it holds); returns
    the policy.

    Raises:
        TrainingError: a bad setting, or ``out`` holds a training with other settings.
    """
    from twin.control.vector_env import VectorWaveDampeningEnv

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    settings = _identity(config)
    state = _resume(out, settings, config.start) or _fresh(config)
    envs = {}
    held = config.heldout_episodes
    kinds = {"test": (config.data, "test", held, "agent"),
             "human": (config.data, "test", held, "human")}  # fmt: skip
    for k, (data, count) in enumerate(zip(config.mornings, config.per_morning(), strict=True)):
        kinds[("train", k)] = (data, "train", 2 * config.population * count, "agent")
    for name, (data, split, count, ego) in kinds.items():
        envs[name] = VectorWaveDampeningEnv(
            count, data, split=split, duration=config.duration, action="accel",
            obs_noise=config.obs_noise, latency_steps=config.latency_steps,
            seed=config.seed, safety=True, ego=ego,
        )  # fmt: skip
    try:
        return _generations(out, config, settings, state, envs, progress)
    finally:
        for env in envs.values():
            env.close()


def _generations(out, config, settings, state, envs, progress) -> MLPPolicy:
    rng = state["rng"]
    theta, m, v = state["theta"], state["m"], state["v"]
    rows = state["rows"]
    pairs, per = config.population, config.episodes
    steps_per_run = round(config.duration / 0.1)
    heldout = _placeable(envs["test"], iter(range(HELDOUT_TRIES)), config.heldout_episodes)
    start = initial_weights(config.seed, config.hidden)  # any: human ignores the actions
    baseline = _heldout(envs["human"], start, heldout, config)
    for generation in range(state["generation"] + 1, config.generations + 1):
        tick = time.perf_counter()
        drawn = [
            _placeable(envs[("train", k)], (int(e) for e in rng.integers(0, 2**31 - 1, 64)), count)
            for k, count in enumerate(config.per_morning())
        ]
        eps = rng.standard_normal((pairs, theta.size))
        members = np.concatenate([theta + config.sigma * eps, theta - config.sigma * eps])
        runs = _train_runs(envs, members, drawn, config)
        # a run with no economy (no fuel, a figure missing) ranks lowest
        mpg = np.nan_to_num([r["mpg"] for r in runs], nan=0.0).reshape(2 * pairs, per)
        median = np.median(mpg, axis=0)
        scores = np.empty((2 * pairs, per))
        economy = np.empty((2 * pairs, per))
        for k, run in enumerate(runs):
            i, e = divmod(k, per)
            run["economy_pct"] = 100.0 * (mpg[i, e] / median[e] - 1.0) if median[e] > 0 else 0.0
            scores[i, e], economy[i, e] = score(run, config.time_gap_p90_max)
        utility = np.mean([centred_ranks(scores[:, e]) for e in range(per)], axis=0)
        gradient = (utility[:pairs] - utility[pairs:]) @ eps / (pairs * config.sigma)
        theta, m, v = _adam(theta, m, v, gradient, generation, config)
        seconds = time.perf_counter() - tick
        row = {
            "generation": generation,
            "env_steps": (rows[-1]["env_steps"] if rows else 0) + len(runs) * steps_per_run,
            "wall_s": round((rows[-1]["wall_s"] if rows else 0.0) + seconds, 1),
            "steps_per_s": round(len(runs) * steps_per_run / seconds, 1),
            "score_mean": round(float(scores.mean()), 3),
            "economy_pct_mean": round(float(economy.mean()), 3),
        }
        if generation % config.heldout_every == 0 or generation == config.generations:
            held = _heldout(envs["test"], theta, heldout, config)
            row.update(_heldout_row(held, baseline))
            row["wall_s"] = round(row["wall_s"] + held["seconds"], 1)
        rows.append(row)
        policy = MLPPolicy(theta, config.hidden, config.smoothing, config.jerk_from,
                           about=_about(config, row))  # fmt: skip
        policy.save(out / "policy.json")
        _save(out, settings, theta, m, v, generation, rng, rows)
        write_curve(out, rows, CURVE)
        if "heldout_economy_pct" in row:
            _plot_curve(out, rows)
        if progress:
            _print(row, config)
    return MLPPolicy(theta, config.hidden, config.smoothing, config.jerk_from,
                     about=_about(config, rows[-1]))  # fmt: skip


def _train_runs(envs, members: np.ndarray, drawn: list[list[int]], config) -> list[dict]:
    """Every member (row of ``members``) on every episode drawn (``drawn[k]``: morning
    ``k``'s), each morning's in one rollout of its vector env; the runs member by
    member, each member's episodes morning by morning (run ``i per + e``: member ``i``,
    episode ``e``)."""
    by_morning = []
    for k, episodes in enumerate(drawn):
        thetas = np.repeat(members, len(episodes), axis=0)  # sub-env b: member b // count
        runs = rollout(envs[("train", k)], thetas, list(np.tile(episodes, len(members))),
                       _actor(config), seed=episodes[0])  # fmt: skip
        by_morning.append([runs[i * len(episodes) : (i + 1) * len(episodes)]
                           for i in range(len(members))])  # fmt: skip
    return [run for i in range(len(members)) for runs in by_morning for run in runs[i]]


def _placeable(env, candidates, count: int) -> list[int]:
    """The first ``count`` episodes of ``candidates`` whose ego can be placed (tried
    on ``env``'s first sub-env).

    Raises:
        TrainingError: too few of them can be.
    """
    from twin.runners.episodes import PLACEMENT_ERRORS

    found = []
    for k in candidates:
        try:
            env.episodes.reset(0, None, k)
        except PLACEMENT_ERRORS:
            continue
        found.append(k)
        if len(found) == count:
            return found
    raise TrainingError(f"only {len(found)} of the episodes drawn could be placed (need {count})")


def _actor(config: EvolveConfig) -> Actor:
    return Actor(config.hidden, config.smoothing, config.jerk_from)


def _heldout(env, theta, episodes: list[int], config: EvolveConfig) -> dict:
    """The held-out ``episodes``' figures with weights ``theta`` (one per run)."""
    start = time.perf_counter()
    thetas = np.repeat(theta[None], env.num_envs, axis=0)
    runs = rollout(env, thetas, episodes, _actor(config), seed=episodes[0])
    return {"runs": runs, "seconds": time.perf_counter() - start}


def _heldout_row(held: dict, baseline: dict) -> dict:
    mine = np.array([r["mpg"] for r in held["runs"]])
    base = np.array([r["mpg"] for r in baseline["runs"]])
    both = np.isfinite(mine) & np.isfinite(base)  # paired: the episodes both have
    total = base[both].sum()
    change = 100.0 * (mine[both].sum() / total - 1.0) if total > 0 else 0.0

    def median(name):
        return round(float(np.median([r[name] for r in held["runs"]])), 3)

    return {
        "heldout_economy_pct": round(float(change), 3),
        "heldout_time_gap_p10_s": median("time_gap_p10_s"),
        "heldout_min_ttc_s": median("min_ttc_s"),
        "heldout_jerk_rms_mps3": median("jerk_rms_mps3"),
        "heldout_safety_pct": median("safety_pct"),
        "heldout_collisions": int(sum(r["collisions"] for r in held["runs"])),
    }


def _adam(theta, m, v, gradient, t, config, beta1=0.9, beta2=0.999, tiny=1e-8):
    """One Adam ascent step along ``gradient`` with weight decay (module doc)."""
    g = gradient - config.weight_decay * theta
    m = beta1 * m + (1 - beta1) * g
    v = beta2 * v + (1 - beta2) * g * g
    step = config.learning_rate * (m / (1 - beta1**t)) / (np.sqrt(v / (1 - beta2**t)) + tiny)
    return theta + step, m, v


def _settings(config: EvolveConfig) -> dict:
    """What a checkpoint must share to be resumed: every setting but the generations."""
    out = asdict(config)
    out.pop("generations")
    out["hidden"] = list(config.hidden)
    out["also"] = list(config.also)
    if config.time_gap_p90_max == TIME_GAP_P90_MAX:  # trainings from before the setting resume
        out.pop("time_gap_p90_max")
    return out


def _identity(config: EvolveConfig) -> dict:
    """:func:`_settings` as a checkpoint keeps them: the start file by its weights (a
    SHA-256 of their bytes), not by the path it was given as (the same file named
    relative to another folder resumes; another file's weights do not)."""
    out = _settings(config)
    if out.pop("start") is not None:
        out["start_sha256"] = hashlib.sha256(_start_weights(config).tobytes()).hexdigest()
    return out


def _fresh(config: EvolveConfig) -> dict:
    theta = initial_weights(config.seed, config.hidden)
    if config.start is not None:
        theta = _start_weights(config)
    return {
        "theta": theta, "m": np.zeros_like(theta), "v": np.zeros_like(theta),
        "generation": 0, "rng": np.random.default_rng([config.seed, 0x4553]), "rows": [],
    }  # fmt: skip


def _start_weights(config: EvolveConfig) -> np.ndarray:
    """The weights of the policy file ``config.start``.

    Raises:
        TrainingError: it cannot be read, or is a policy of another network.
    """
    from twin.control.policy import PolicyError

    try:
        policy = MLPPolicy.load(config.start)
    except PolicyError as error:
        raise TrainingError(f"--start: {error}") from None
    if policy.hidden != config.hidden:
        raise TrainingError(
            f"--start {config.start} is a policy with hidden layers {policy.hidden}, not the "
            f"training's {config.hidden}"
        )
    return policy.weights.copy()


def _resume(out: Path, settings: dict, start: str | None = None) -> dict | None:
    """The state a checkpoint in ``out`` holds, or None where there is none. A
    checkpoint from before ``start_sha256`` named its start file by path: it resumes
    where that path is the same file as ``start``.

    Raises:
        TrainingError: it is damaged, or of a training with other settings.
    """
    path = out / "checkpoint.npz"
    if not path.exists():
        return None
    try:
        with np.load(path, allow_pickle=False) as data:
            # a training from before these settings had them at their defaults
            saved = {"smoothing": 0.0, "jerk_from": "measured", "also": []}
            saved |= json.loads(str(data["settings"]))
            old = saved.pop("start", None)  # its path, before start_sha256
            if old is not None:
                same = start is not None and Path(old).resolve() == Path(start).resolve()
                saved["start_sha256"] = settings.get("start_sha256") if same else old
            rng = np.random.default_rng()
            rng.bit_generator.state = json.loads(str(data["rng"]))
            state = {
                "theta": data["theta"].copy(), "m": data["m"].copy(), "v": data["v"].copy(),
                "generation": int(data["generation"]), "rng": rng,
                "rows": json.loads(str(data["rows"])),
            }  # fmt: skip
    except (OSError, EOFError, KeyError, ValueError, TypeError, zipfile.BadZipFile) as error:
        raise TrainingError(
            f"{path} is damaged ({error}): remove it to start the training again"
        ) from None
    if saved != settings:
        differ = sorted(k for k in set(saved) | set(settings) if saved.get(k) != settings.get(k))
        raise TrainingError(
            f"{out} holds a training with other settings ({', '.join(differ)}): use another "
            "--out, or the same settings to resume it"
        )
    if state["theta"].size != n_weights(tuple(settings["hidden"])):
        raise TrainingError(f"{path} holds weights of another network: remove it")
    return state


def _save(out: Path, settings, theta, m, v, generation, rng, rows) -> None:
    with atomic_file(out / "checkpoint.npz") as tmp, tmp.open("wb") as f:
        np.savez(
            f, theta=theta, m=m, v=v, generation=np.int64(generation),
            settings=json.dumps(settings, sort_keys=True), rng=json.dumps(rng.bit_generator.state),
            rows=json.dumps(rows),
        )  # fmt: skip


def _about(config: EvolveConfig, row: dict) -> dict:
    return {
        "trained_by": "twin.control.evolve (OpenAI evolution strategy, Salimans et al. 2017)",
        "env": "i24twin/WaveDampening-v0 (vector, kinematic, action accel, safety layer)",
        "config": _settings(config) | {"generations": config.generations},
        "generations_done": row["generation"],
        "env_steps": row["env_steps"],
        "wall_s": row["wall_s"],
    }


def _print(row: dict, config: EvolveConfig) -> None:
    held = ""
    if "heldout_economy_pct" in row:
        held = (
            f"; held out {row['heldout_economy_pct']:+.2f} % vs human, "
            f"gap p10 {row['heldout_time_gap_p10_s']:.2f} s, jerk "
            f"{row['heldout_jerk_rms_mps3']:.2f} m/s^3, {row['heldout_collisions']} collisions"
        )
    print(
        f"generation {row['generation']}/{config.generations}: {row['env_steps']:,} steps at "
        f"{row['steps_per_s']:,.0f}/s, score {row['score_mean']:+.2f}, economy vs the "
        f"median {row['economy_pct_mean']:+.2f} %{held}",
        flush=True,
    )


def _plot_curve(out: Path, rows: list[dict]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    held = [r for r in rows if "heldout_economy_pct" in r]
    for ax, x, label in ((axes[0], "env_steps", "env steps (0.1 s each)"),
                         (axes[1], "wall_s", "wall time [s]")):  # fmt: skip
        ax.plot([r[x] for r in rows], [r["score_mean"] for r in rows], label="score (train)")
        ax.plot(
            [r[x] for r in held], [r["heldout_economy_pct"] for r in held], "o-",
            label="held-out economy vs human [%]",
        )  # fmt: skip
        ax.axhline(0.0, color="grey", lw=0.8)
        ax.set_xlabel(label)
    axes[0].set_ylabel("[%]")
    axes[0].legend(fontsize=8)
    fig.suptitle("Evolution strategy training of the MLP speed policy")
    fig.tight_layout()
    with atomic_file(out / "curve.png") as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    plt.close(fig)
