"""Which car-following model drives a recording's vehicles: the one whose drivers, drawn
as the calibrated twin draws them, follow the recording's leaders most like its own
followers did (``twin calibrate --model auto``, the default).

Each candidate model is fitted to the window's followers as usual
(:mod:`twin.calibration.car_following`); its class groups' distributions are what a
calibrated run draws its drivers from. The choice replays every following run of the
window (:func:`~twin.calibration.following.following_runs`, not only those that crossed
a wave, which the fit needs): each follower gets a driver drawn from the candidate's
distributions, with its desired speed from where the twin takes it
(:func:`~twin.calibration.distributions.draw_desired`; without a run's floor at the
speed the twin spawns a vehicle at, :mod:`twin.cosim.behaviour`: a follower's run starts
wherever it began following, not where a window takes it over), and is driven behind its
recorded leader. The score is the median over the runs of each run's spacing RMSE: the
typical follower, as the fit's quality is its median NRMSE. Not the error pooled over
every step: a few drawn drivers whose desired speed the fits left loose fall back by
hundreds of metres over a two-minute run and would decide it alone (on a day the
synthesiser drove with Gipps drivers, pooled spacing RMSE 112 m for Gipps against 60 m
for IDM, the medians 7 m against 24 m). The lowest wins. A candidate whose car following
could not be calibrated on the window (nor taken from ``--following-from``) is not a
candidate.

Why a replay of drawn drivers, not the fit's own residual: a model is fitted on the
followers that stop and go, and its drivers then drive the whole window, calm stretches
included. On a lane-drop morning made by SUMO's Krauss drivers (a Gipps variant) in free
flow, IDM's drivers, whose equilibrium gap near their desired speed is twice their
desired gap, fall back from their leaders (median run 23 m against Gipps' 4 m) and the
calibrated twin's ego ended 77 m off its recording with IDM, 11 m with Gipps (medians,
physics world). On mornings made by the synthesiser's IDM drivers
the replay keeps IDM. The figures are in ``docs/calibration.md``.
"""

from dataclasses import dataclass

import numpy as np

from twin.calibration.car_following import replay
from twin.calibration.distributions import (
    ParameterDistribution,
    desired_speed_source,
    draw_desired,
    draw_parameters,
)
from twin.calibration.following import FollowingRuns
from twin.traffic.models import AUTO
from twin.traffic.models.base import CarFollowingModel

__all__ = [
    "AUTO",
    "CANDIDATES",
    "ReplayScore",
    "choose",
    "describe_model_choice",
    "replay_score",
    "score",
    "summary",
]

#: The models ``auto`` chooses among, by registry name.
CANDIDATES = ("idm", "gipps")
SEED_STREAM = 0x63686F696365  # the replay's draws: their own stream, fixed


@dataclass(frozen=True)
class ReplayScore:
    """How one model's drawn drivers replay one road's following runs.

    Attributes:
        runs: following runs replayed. steps: their steps.
        sum_squares: [m^2] summed squared spacing error over every step.
        run_rmse: (runs,) [m] each run's spacing RMSE.
        run_bias: (runs,) [m] each run's mean spacing error (simulated minus recorded:
            positive where the drivers fall back).
    """

    runs: int
    steps: int
    sum_squares: float
    run_rmse: np.ndarray
    run_bias: np.ndarray


def replay_score(
    runs: FollowingRuns,
    model: CarFollowingModel,
    distributions: dict[str, ParameterDistribution],
    speeds: dict,
    car_following: dict,
    seed: int = 0,
) -> ReplayScore:
    """Replay ``runs`` with drivers of ``model`` drawn from ``distributions`` (a
    calibration's class groups), desired speeds from ``speeds`` (the road's free-flow
    ``desired_speed`` section) where the twin takes them from there (``car_following``:
    the road's car-following section)."""
    names = tuple(p.name for p in model.fitted)
    drawn = next(iter(distributions.values())).names
    if tuple(drawn) != names:
        raise ValueError(f"distributions of {drawn} are not {model.name}'s parameters {names}")
    if len(runs) == 0:
        return ReplayScore(0, 0, 0.0, np.zeros(0), np.zeros(0))
    rng = np.random.default_rng([seed, SEED_STREAM])
    params = draw_parameters(distributions, runs.vehicle_class, rng)
    k = names.index("desired_speed")
    source = desired_speed_source(speeds, car_following, True)
    params[:, k] = draw_desired(speeds, source, params[:, k], runs.lane, rng)
    valid = runs.valid
    error = np.where(valid, replay(runs, params, model) - runs.gap, 0.0)
    steps = valid.sum(axis=1)
    squares = (error * error).sum(axis=1)
    return ReplayScore(
        runs=len(runs),
        steps=int(steps.sum()),
        sum_squares=float(squares.sum()),
        run_rmse=np.sqrt(squares / steps),
        run_bias=error.sum(axis=1) / steps,
    )


def pooled_rmse(scores: list[ReplayScore]) -> float | None:
    """[m] the spacing RMSE over every step of ``scores`` (None where there is none)."""
    steps = sum(s.steps for s in scores)
    return float(np.sqrt(sum(s.sum_squares for s in scores) / steps)) if steps else None


def _rounded(value: float | None) -> float | None:
    return None if value is None else round(value, 4)


def summary(scores: dict[str, ReplayScore]) -> dict:
    """The calibration's record of one model's replay: pooled and per road ({road:
    ReplayScore})."""
    runs = np.concatenate([s.run_rmse for s in scores.values()])
    bias = np.concatenate([s.run_bias for s in scores.values()])
    some = runs.size > 0
    return {
        "spacing_rmse_m": _rounded(pooled_rmse(list(scores.values()))),
        "runs": int(runs.size),
        "run_rmse_m": {
            "median": _rounded(float(np.median(runs)) if some else None),
            "p90": _rounded(float(np.quantile(runs, 0.9)) if some else None),
        },
        "run_bias_median_m": _rounded(float(np.median(bias)) if some else None),
        "roads": {road: _rounded(pooled_rmse([s])) for road, s in scores.items()},
    }


def choose(candidates: dict[str, dict]) -> str:
    """The name of the candidate ({name: :func:`summary`}) whose runs' median spacing
    RMSE is lowest (the first of :data:`CANDIDATES` on a tie)."""
    scored = {n: score(c) for n, c in candidates.items()}
    scored = {n: value for n, value in scored.items() if value is not None}
    if not scored:
        raise ValueError("no candidate model replayed any following run")
    order = {n: k for k, n in enumerate(CANDIDATES)}
    return min(scored, key=lambda n: (scored[n], order.get(n, len(order))))


def score(candidate: dict) -> float | None:
    """[m] what :func:`choose` compares: a :func:`summary`'s median run spacing RMSE."""
    return candidate.get("run_rmse_m", {}).get("median")


def describe_model_choice(choice: dict | None) -> list[str]:
    """Lines for ``twin data info``: which model was chosen and how each replayed."""
    if not choice:
        return []
    parts = []
    for name, c in choice["candidates"].items():
        if "not_calibrated" in c:
            parts.append(f"{name} not calibrated here")
        else:
            value = score(c)
            parts.append(f"{name} {value:.1f} m" if value is not None else f"{name} no runs")
    lines = [
        f"  model chosen: {choice['chosen']} (median spacing RMSE of its drawn drivers "
        f"replaying the window's followers: {', '.join(parts)})"
    ]
    return lines + ([f"    {choice['note']}"] if choice.get("note") else [])
