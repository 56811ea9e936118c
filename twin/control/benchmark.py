"""The wave-dampening benchmark: controllers against ``human`` on the same episodes.

``twin eval --controller human,follower_stopper,...`` (:func:`benchmark`) runs every
controller on the same episodes (same seeds, the evaluation runner
:mod:`twin.runners.evaluation`) and compares them, pairing each episode's run with the
``human`` run of the same episode:

- per metric the table of metrics marks as paired (:data:`twin.metrics.table.PAIRED`),
  the change against ``human`` in percent, per episode
  (``100 (controller - human) / human``), its mean with a 95 % confidence interval
  (percentile bootstrap over episodes, 10,000 resamples, seeded: deterministic) and
  its median, over the episodes where both ran and both values exist;
- a Markdown table of those changes (appended to ``summary.md``);
- ``waves.png``: the followers' speeds through the episode with the largest wave
  behind ``human``, each controller beside ``human``.
"""

import math
import os
from pathlib import Path

import numpy as np

from twin.core.atomic import atomic_file
from twin.data.store import TrajectoryStore
from twin.metrics.table import PAIRED, section_head
from twin.runners.evaluation import (
    EvalConfig,
    EvalResult,
    EvaluationError,
    evaluate,
    folder_line,
)
from twin.runners.failures import ran_rows

REFERENCE = "human"
BOOTSTRAP = 10_000
CONFIDENCE = 0.95


def benchmark(
    store: TrajectoryStore, out: str | os.PathLike, config: EvalConfig, **options
) -> EvalResult:
    """Run (or resume) the controllers of ``config`` on its episodes into ``out`` with
    the paired comparison: :func:`~twin.runners.evaluation.evaluate` with
    :func:`extend` (``options`` are its).

    Raises:
        EvaluationError: ``config`` names no controller (and what ``evaluate`` raises).
    """
    if not config.controllers:
        raise EvaluationError("the benchmark compares controllers: give --controller")
    return evaluate(store, out, config, extension=extend, **options)


def extend(out: Path, frame, config: EvalConfig, summary: dict) -> str:
    """The benchmark's part of an evaluation's outputs: ``paired_vs_human`` in the
    summary, ``waves.png``, and the paired table for ``summary.md``."""
    summary["paired_vs_human"] = paired_vs_human(frame, config)
    with atomic_file(Path(out) / "waves.png") as tmp:
        plot_traces(frame, config, tmp)
    return markdown(summary)


def summary_lines(result: EvalResult) -> str:
    """A few lines for the terminal: each controller's medians and paired change."""
    return "\n".join([folder_line(result), *lines(result.summary)])


def paired_changes(ours: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Per episode, ``100 (ours - reference) / reference`` [%] where both are finite and
    the reference is not 0."""
    ours, reference = np.asarray(ours, float), np.asarray(reference, float)
    keep = np.isfinite(ours) & np.isfinite(reference) & (reference != 0)
    return 100.0 * (ours[keep] - reference[keep]) / reference[keep]


def mean_with_ci(values: np.ndarray, seed: int = 0) -> dict:
    """The mean of ``values`` with its 95 % percentile-bootstrap interval, and the
    median; None figures without values."""
    values = np.asarray(values, float)
    if values.size == 0:
        return {"mean": None, "ci95": None, "median": None, "episodes": 0}
    rng = np.random.default_rng(seed)
    means = values[rng.integers(0, values.size, (BOOTSTRAP, values.size))].mean(axis=1)
    tail = 100.0 * (1.0 - CONFIDENCE) / 2.0
    low, high = np.percentile(means, [tail, 100.0 - tail])
    return {
        "mean": _r(values.mean()),
        "ci95": [_r(low), _r(high)],
        "median": _r(np.median(values)),
        "episodes": int(values.size),
    }


def paired_vs_human(frame, config) -> dict:
    """Per controller other than ``human`` (and per behaviour): the paired changes of
    :data:`PAIRED` (see the module doc); empty without a ``human`` arm."""
    ran = ran_rows(frame)
    out = {}
    for behaviour in config.behaviours:
        rows = ran[ran["behaviour"] == behaviour]
        human = rows[rows["controller"] == REFERENCE].set_index("episode")
        if human.empty:
            continue
        for label, arm_behaviour, spec in config.arms:
            name = spec.rpartition(":")[2]
            if arm_behaviour != behaviour or name == REFERENCE:
                continue
            mine = rows[rows["arm"] == label].set_index("episode")
            both = mine.index.intersection(human.index)
            out[label] = {
                "against": REFERENCE if len(config.behaviours) == 1 else f"{behaviour}+human",
                "metrics": {
                    metric: {
                        "more_is_better": better,
                        **mean_with_ci(
                            paired_changes(
                                mine.loc[both, metric].to_numpy(float),
                                human.loc[both, metric].to_numpy(float),
                            )
                        ),
                    }
                    for metric, better in PAIRED.items()
                },
            }
    return out


def markdown(summary: dict) -> str:
    """The paired changes as a Markdown table ("" without any)."""
    paired = summary.get("paired_vs_human") or {}
    if not paired:
        return ""
    arms = list(paired)
    lines = section_head(
        "Paired change against human, % (mean [95 % CI]; episodes)", "metric", arms
    )
    for metric, better in PAIRED.items():
        cells = []
        for arm in arms:
            m = paired[arm]["metrics"][metric]
            if m["mean"] is None:
                cells.append("-")
            else:
                low, high = m["ci95"]
                cells.append(f"{m['mean']:+.1f} [{low:+.1f}, {high:+.1f}]; {m['episodes']}")
        arrow = "higher is better" if better else "lower is better"
        lines.append(f"| {metric} ({arrow}) | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def lines(summary: dict) -> list[str]:
    """Terminal lines: each controller's medians, with its paired changes against
    ``human`` in the AV and its followers' economy, the window's economy and the
    window's speed standard deviation."""
    out = []
    paired = summary.get("paired_vs_human") or {}
    for label, entry in summary["controllers"].items():
        m = entry["metrics"]
        changes = paired.get(label, {}).get("metrics", {})
        out.append(
            f"{label:<17} ego + followers {_median(m, 'ego_and_followers_mpg')} mpg"
            f"{_change(changes, 'ego_and_followers_mpg')}; window "
            f"{_median(m, 'window_mpg')} mpg{_change(changes, 'window_mpg')}, speed std "
            f"{_median(m, 'speed_std_window_mps')} m/s"
            f"{_change(changes, 'speed_std_window_mps')}; speed std behind "
            f"{_median(m, 'speed_std_behind_mps')} m/s; min TTC "
            f"{_median(m, 'min_ttc_s')} s; collisions {m['collisions']['sum']:g}"
        )
    return out


def _change(changes: dict, metric: str) -> str:
    """`` (vs human +x % [low, high])`` of a paired metric, "" where it has none."""
    change = changes.get(metric, {})
    if change.get("mean") is None:
        return ""
    low, high = change["ci95"]
    return f" (vs human {change['mean']:+.1f} % [{low:+.1f}, {high:+.1f}])"


def plot_traces(frame, config, path) -> None:
    """``waves.png``: followers' speeds through the episode with the largest wave
    amplitude behind ``human`` (else the first episode), one panel per controller,
    ``human`` in grey behind each."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ran = ran_rows(frame)
    human = ran[ran["controller"] == REFERENCE]
    amplitude = human["wave_amplitude_behind_mps"].to_numpy(float)
    if human.empty or not np.isfinite(amplitude).any():
        episode = int(ran["episode"].min()) if len(ran) else 0
    else:
        episode = int(human["episode"].iloc[int(np.nanargmax(amplitude))])
    labels = [label for label, _, _ in config.arms]
    fig, axes = plt.subplots(
        1, len(labels), figsize=(4.2 * len(labels), 3.6), sharey=True, squeeze=False
    )
    reference = human[human["episode"] == episode]
    for ax, label in zip(axes[0], labels, strict=True):
        rows = ran[(ran["arm"] == label) & (ran["episode"] == episode)]
        for who, color, width in ((reference, "0.7", 1.0), (rows, "C0", 1.2)):
            if who.empty:
                continue
            for trace in who["follower_speeds"].iloc[0]:
                ax.plot(_values(trace), color=color, lw=width)
            ax.plot(_values(who["ego_speeds"].iloc[0]), color="C3" if who is rows else "0.4", lw=2)
        ax.set_title(f"{label} (red: the AV; grey: human)", fontsize=9)
        ax.set_xlabel("time [s]")
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("speed [m/s]")
    fig.suptitle(f"episode {episode}: the AV and its followers through the wave")
    fig.tight_layout()
    fig.savefig(path, dpi=110, format="png")
    plt.close(fig)


def _values(trace) -> np.ndarray:
    return np.array([np.nan if v is None else v for v in trace], dtype=float)


def _median(metrics: dict, name: str) -> str:
    m = metrics[name]["median"]
    return "-" if m is None else f"{m:.2f}"


def _r(value) -> float | None:
    value = float(value)
    return round(value, 4) if math.isfinite(value) else None
