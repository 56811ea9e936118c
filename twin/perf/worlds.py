"""The kinematic world against the physics world: the same evaluation in both, compared.

``twin bench worlds`` runs ``twin eval`` (with ``--controller``: the paired benchmark)
twice on the same episodes and seeds, once per world, into ``OUT/physics`` and
``OUT/kinematic`` (each resumable as any evaluation), and writes ``OUT/worlds.json``
and ``OUT/worlds.md``:

- **the ego between worlds**: per (episode, arm) the RMS difference of the ego's speed,
  each second (``ego_speeds`` of the rows), between the two worlds; median and p90;
- **fidelity against the recording**: per arm, each fidelity figure of the table
  (:data:`FIDELITY`: medians, and the sum of the lane changes) in each world and their
  relative difference;
- **the controllers** (with ``--controller``): each paired metric's mean change against
  ``human`` in each world, whether the signs agree and whether the controllers rank in
  the same order;
- the wall time of each evaluation.

The targets (issue 29) are checked in the output (``targets``): the ego's speed
differs by a median RMSE <= 0.5 m/s, each fidelity figure within 10 %, the same signs
and ranking.
"""

import json
import math
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from twin.core.atomic import atomic_file

WORLD_ORDER = ("physics", "kinematic")
#: Fidelity figures compared between worlds: (metric, how the arm's episodes combine).
FIDELITY = (
    ("ego_speed_rmse_mps", "median"),
    ("ego_position_error_end_m", "median_abs"),
    ("speed_field_rmse_mps", "median"),
    ("lane_changes_simulated", "sum"),
)
SPEED_RMSE_TARGET = 0.5  # [m/s] median over runs of the ego's speed RMSE between worlds
FIDELITY_TOLERANCE = 0.10  # relative


def worlds_bench(store, out, config, *, workers: int = 1, progress: bool = False) -> dict:
    """Run ``config`` (an :class:`~twin.runners.evaluation.EvalConfig`) in both worlds
    into ``out`` and compare them (see the module doc); returns what ``worlds.json``
    holds.

    Raises:
        EvaluationError: what the evaluations raise (a bad setting, a folder holding
            another evaluation).
    """
    from twin.control.benchmark import benchmark
    from twin.cosim.config import switch_world
    from twin.runners.evaluation import evaluate

    out = Path(out)
    run = benchmark if config.controllers else evaluate
    frames, summaries, seconds = {}, {}, {}
    for world in WORLD_ORDER:
        world_config = replace(config, cosim=switch_world(config.cosim, world))
        start = time.perf_counter()
        result = run(store, out / world, world_config, workers=workers, progress=progress)
        seconds[world] = round(time.perf_counter() - start, 1)
        summaries[world] = result.summary
        frames[world] = _rows(out / world)
    figures = compare(frames, summaries, config)
    figures["wall_s"] = seconds
    figures["workers"] = workers
    with atomic_file(out / "worlds.json") as tmp:
        tmp.write_text(json.dumps(figures, indent=1, allow_nan=False) + "\n")
    with atomic_file(out / "worlds.md") as tmp:
        tmp.write_text(markdown(figures))
    return figures


def compare(frames: dict, summaries: dict, config) -> dict:
    """The comparison of the two worlds' rows (``frames``: world -> the evaluation's
    ``episodes.parquet``) and summaries."""
    from twin.runners.failures import ran_rows

    physics, kinematic = (frames[w] for w in WORLD_ORDER)
    key = ["episode", "arm"]
    both = ran_rows(physics).merge(ran_rows(kinematic), on=key, suffixes=("_p", "_k"))
    rmse = np.array(
        [speed_rmse(a, b) for a, b in zip(both["ego_speeds_p"], both["ego_speeds_k"], strict=True)]
    )
    rmse = rmse[np.isfinite(rmse)]
    ego = {
        "runs": int(rmse.size),
        "median_mps": _r(np.median(rmse)) if rmse.size else None,
        "p90_mps": _r(np.percentile(rmse, 90)) if rmse.size else None,
        "max_mps": _r(rmse.max()) if rmse.size else None,
    }
    fidelity = {}
    for arm in sorted(both["arm"].unique()):
        rows = both[both["arm"] == arm]
        fidelity[arm] = {
            metric: _figure(rows[f"{metric}_p"], rows[f"{metric}_k"], how)
            for metric, how in FIDELITY
        }
    controllers = _controllers(summaries) if config.controllers else {}
    return {
        "episodes": config.episodes,
        "duration_s": config.duration,
        "ego_speed_between_worlds": ego,
        "fidelity": fidelity,
        "controllers": controllers,
        "targets": _targets(ego, fidelity, controllers),
    }


def speed_rmse(a, b) -> float:
    """RMS difference [m/s] of two speed traces (lists, None where absent), over the
    seconds both have; NaN when none."""
    a = np.array([math.nan if v is None else v for v in a], dtype=float)
    b = np.array([math.nan if v is None else v for v in b], dtype=float)
    n = min(a.size, b.size)
    diff = a[:n] - b[:n]
    diff = diff[np.isfinite(diff)]
    return float(np.sqrt(np.mean(diff**2))) if diff.size else math.nan


def _figure(physics, kinematic, how: str) -> dict:
    p, k = physics.to_numpy(float), kinematic.to_numpy(float)
    if how == "sum":
        a, b = float(np.nansum(p)), float(np.nansum(k))
    else:
        if how == "median_abs":
            p, k = np.abs(p), np.abs(k)
        a, b = float(np.nanmedian(p)), float(np.nanmedian(k))
    relative = abs(b - a) / abs(a) if a != 0 else (0.0 if b == 0 else math.inf)
    return {
        "how": how,
        "physics": _r(a),
        "kinematic": _r(b),
        "relative_difference": _r(relative) if math.isfinite(relative) else None,
    }


def _controllers(summaries: dict) -> dict:
    """Per paired metric: each controller's mean change in each world, whether the
    signs agree and whether the ranking (best first) is the same."""
    paired = {w: summaries[w].get("paired_vs_human", {}) for w in WORLD_ORDER}
    names = sorted(paired["physics"])
    if not names:
        return {}
    metrics = sorted(paired["physics"][names[0]]["metrics"])
    out = {}
    for metric in metrics:
        means = {
            w: {c: paired[w][c]["metrics"][metric]["mean"] for c in names} for w in WORLD_ORDER
        }
        better = paired["physics"][names[0]]["metrics"][metric]["more_is_better"]
        ranks = {w: _ranking(means[w], better) for w in WORLD_ORDER}
        signs = all(_sign(means["physics"][c]) == _sign(means["kinematic"][c]) for c in names)
        out[metric] = {
            "mean_change_pct": means,
            "ranking": ranks,
            "same_signs": signs,
            "same_ranking": ranks["physics"] == ranks["kinematic"],
        }
    return out


def _ranking(means: dict, more_is_better: bool) -> list[str]:
    """Controllers best first by their mean change (None last)."""
    known = [c for c in means if means[c] is not None]
    order = sorted(known, key=lambda c: means[c], reverse=more_is_better)
    return order + [c for c in means if means[c] is None]


def _sign(value) -> int:
    return 0 if value is None or value == 0 else (1 if value > 0 else -1)


def _targets(ego: dict, fidelity: dict, controllers: dict) -> dict:
    median = ego["median_mps"]
    differences = [f["relative_difference"] for arm in fidelity.values() for f in arm.values()]
    return {
        "ego_speed_median_rmse_le_0_5": median is not None and median <= SPEED_RMSE_TARGET,
        "fidelity_within_10pct": all(
            d is not None and d <= FIDELITY_TOLERANCE for d in differences
        ),
        "controllers_same_signs": all(c["same_signs"] for c in controllers.values())
        if controllers
        else None,
        "controllers_same_ranking": all(c["same_ranking"] for c in controllers.values())
        if controllers
        else None,
    }


def markdown(figures: dict) -> str:
    """``worlds.md``: the comparison as tables."""
    ego = figures["ego_speed_between_worlds"]
    lines = [
        f"# Kinematic world against physics world ({figures['episodes']} episodes of "
        f"{figures['duration_s']:g} s)",
        "",
        f"Ego speed between worlds, RMSE over {ego['runs']} runs: median {ego['median_mps']} "
        f"m/s, p90 {ego['p90_mps']} m/s, max {ego['max_mps']} m/s.",
        "",
        "| arm | figure | physics | kinematic | difference |",
        "|---|---|---|---|---|",
    ]
    for arm, metrics in figures["fidelity"].items():
        for metric, f in metrics.items():
            d = f["relative_difference"]
            lines.append(
                f"| {arm} | {metric} ({f['how']}) | {f['physics']} | {f['kinematic']} | "
                f"{'n/a' if d is None else f'{100 * d:.1f} %'} |"
            )
    if figures["controllers"]:
        lines += ["", "| paired metric | physics ranking | kinematic ranking | signs | ranking |"]
        lines.append("|---|---|---|---|---|")
        for metric, c in figures["controllers"].items():
            ranked = {
                w: ", ".join(f"{n} {c['mean_change_pct'][w][n]:+.1f} %" for n in c["ranking"][w])
                for w in WORLD_ORDER
                if all(c["mean_change_pct"][w][n] is not None for n in c["ranking"][w])
            }
            lines.append(
                f"| {metric} | {ranked.get('physics', 'n/a')} | {ranked.get('kinematic', 'n/a')} "
                f"| {'same' if c['same_signs'] else 'differ'} "
                f"| {'same' if c['same_ranking'] else 'differs'} |"
            )
    lines += ["", "Targets: " + json.dumps(figures["targets"]), ""]
    lines.append(f"Wall time: {json.dumps(figures.get('wall_s', {}))}")
    return "\n".join(lines) + "\n"


def _rows(folder: Path):
    import pandas as pd

    return pd.read_parquet(folder / "episodes.parquet")


def _r(value: float) -> float:
    return round(float(value), 4)
