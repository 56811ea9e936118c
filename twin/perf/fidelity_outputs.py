"""What ``twin bench fidelity`` (:mod:`twin.perf.fidelity`) writes from the days' rows:
``days.parquet``, ``days.md``, ``summary.json`` and ``fidelity.png``, and the figures
of its JSON line."""

import json
import math
from dataclasses import asdict
from pathlib import Path

import numpy as np

from twin import __version__
from twin.core.atomic import atomic_file
from twin.metrics.day_fidelity import (
    CALIBRATION_TARGET,
    MAIN_FIGURES,
    RATIO_BAND,
    RATIO_LIMITS,
    RATIO_SHARE,
    TARGETS,
    judge,
    over_days,
)
from twin.metrics.lane_change_zones import ZONES
from twin.metrics.lane_flow_fidelity import LANES
from twin.metrics.table import section_head

#: The twin's behaviour the targets are set for; the others are shown beside it.
JUDGED = "calibrated"
#: A day's status in its rows: evaluated, or why not.
EVALUATED, NOT_CALIBRATED, NOT_EVALUATED = "evaluated", "not calibrated", "not evaluated"
#: Sums over the days of the benchmark's line, per behaviour.
TOTALS = ("collisions", "stalled", "physics_collisions", "physics_stalled", "episodes_failed")
#: Each main figure's title and unit in ``days.md`` and ``fidelity.png``.
TITLES = {
    "ego_speed_rmse_median_mps": ("ego speed RMSE, median", "m/s"),
    "ego_speed_rmse_p90_mps": ("ego speed RMSE, p90", "m/s"),
    "end_error_median_m": ("end error, median", "m"),
    "end_error_p90_m": ("end error, p90", "m"),
    "speed_field_rmse_worst_lane_mps": ("speed field RMSE, worst lane", "m/s"),
    "lane_change_ratio": ("lane changes simulated / recorded", "-"),
}
RATIOS = ("lane_change_ratio",)  # figures drawn on a log axis, around 1
#: The columns a row of ``days.parquet`` starts with.
FIRST_COLUMNS = ("day", "behaviour", "status", "reason")


def write_outputs(out: Path, rows: list[dict], settings, families: dict) -> dict:
    """Write the benchmark's tables, summary and figure into ``out`` from the days'
    ``rows`` (each whole or not at all); return the figures of its JSON line."""
    import pandas as pd

    frame = pd.DataFrame(rows)
    for column in ("reason", "car_following_model"):
        if column not in frame:
            frame[column] = None
    frame = frame[[*FIRST_COLUMNS, *(c for c in frame.columns if c not in FIRST_COLUMNS)]]
    with atomic_file(out / "days.parquet") as tmp:
        frame.to_parquet(tmp, index=False)
    summary = summarise(frame, settings, families)
    with atomic_file(out / "summary.json") as tmp:
        tmp.write_text(json.dumps(summary, indent=1, allow_nan=False) + "\n")
    with atomic_file(out / "days.md") as tmp:
        tmp.write_text(markdown(frame, summary))
    with atomic_file(out / "fidelity.png") as tmp:
        plot(frame, summary, tmp)
    return line_figures(summary, out)


def evaluated(frame):
    """The rows of the days that were calibrated and evaluated."""
    return frame[frame["status"] == EVALUATED]


def summarise(frame, settings, families: dict) -> dict:
    """``summary.json``: the days, what was not calibrated or evaluated and why, the
    time a day took, the calibration's time against its target, and per behaviour each
    figure over the days with the targets judged
    (:func:`twin.metrics.day_fidelity.over_days`). ``targets_met``: every day was
    evaluated, and every target that had a day to judge it by is met (those of
    :data:`JUDGED`, and the calibration's)."""
    days = frame.drop_duplicates("day")
    done = evaluated(days)
    behaviours = list(dict.fromkeys(frame["behaviour"]))
    by_behaviour = {}
    for behaviour in behaviours:
        rows = evaluated(frame[frame["behaviour"] == behaviour])
        entry = over_days(rows)
        entry["totals"] = {name: _total(rows, name) for name in TOTALS}
        by_behaviour[behaviour] = entry
    calibration = {
        "calibrate_15_min_s": _median_worst(done, "calibrate_15_min_s"),
        "target": judge(done, CALIBRATION_TARGET),
    }
    verdicts = [by_behaviour.get(JUDGED, {}).get("targets_met", False)]
    if calibration["target"]["met"] is not None:
        verdicts.append(calibration["target"]["met"])
    return {
        "format": "i24-twin-fidelity-bench",
        "version": __version__,
        "settings": asdict(settings),
        "behaviours": behaviours,
        "judged": JUDGED,
        "days": len(days),
        "days_evaluated": len(done),
        "days_not_evaluated": [
            {"day": r.day, "status": r.status, "reason": r.reason}
            for r in days.itertuples()
            if r.status != EVALUATED
        ],
        "seconds_per_day": {
            name: _median_worst(done, name)
            for name in ("calibrate_s", "eval_s", "physics_s")
            if name in done
        },
        "calibration": calibration,
        "families": families,
        "by_behaviour": by_behaviour,
        "targets_met": len(done) == len(days) and all(verdicts),
    }


def line_figures(summary: dict, out: Path) -> dict:
    """The benchmark's JSON line: the days, the time a day took, per behaviour each main
    figure's median and worst over the days and the totals, the targets of
    :data:`JUDGED`'s figures, and whether they are all met."""
    figures = {
        "days": summary["days"],
        "days_evaluated": summary["days_evaluated"],
        "days_not_evaluated": len(summary["days_not_evaluated"]),
        "seconds_per_day": summary["seconds_per_day"],
        "calibration": {"calibrate_15_min_s": summary["calibration"]["calibrate_15_min_s"]},
    }
    for behaviour, entry in summary["by_behaviour"].items():
        figures[behaviour] = {
            **{
                name: {k: f[k] for k in ("median", "worst")} for name, f in entry["figures"].items()
            },
            "lane_change_days_within_share": entry["lane_change_days_within_share"],
            "lane_change_days_outside": entry["lane_change_days_outside"],
            **entry["totals"],
        }
    targets = {
        f"{JUDGED}.{t.figure}.worst"
        if t.over == "every day"
        else f"{JUDGED}.{t.figure}": f"<= {t.bound:g}"
        for t in TARGETS
    }
    targets[f"{JUDGED}.lane_change_days_within_share"] = f">= {RATIO_SHARE:g}"
    targets[f"{JUDGED}.lane_change_days_outside"] = "<= 0"
    targets["calibration.calibrate_15_min_s.worst"] = f"<= {CALIBRATION_TARGET.bound:g}"
    return {**figures, "targets": targets, "targets_met": summary["targets_met"], "out": str(out)}


def _total(rows, name: str) -> int | None:
    """The count ``name`` summed over the days that have it (None where none has)."""
    if name not in rows:
        return None
    values = rows[name].to_numpy(dtype=float)
    values = values[np.isfinite(values)]
    return int(values.sum()) if values.size else None


def _median_worst(rows, name: str) -> dict:
    values = rows[name].to_numpy(dtype=float)
    values = values[np.isfinite(values)]
    if not values.size:
        return {"median": None, "worst": None}
    return {"median": round(float(np.median(values)), 2), "worst": round(float(values.max()), 2)}


def markdown(frame, summary: dict) -> str:
    """``days.md``: the targets judged per behaviour, then one row per day and
    behaviour, the days not evaluated with the reason, and the days' parameters."""
    s = summary["settings"]
    behaviours = summary["behaviours"]
    lines = [
        f"# twin bench fidelity: {summary['days']} days, {summary['days_evaluated']} evaluated",
        "",
        f"Each day calibrated on its first half, evaluated on its second: {s['episodes']} "
        f"kinematic episodes of {s['duration']:g} s ({s['physics_episodes']} of them also in "
        f"the physics world), seed {s['seed']}, {s['road']}. Targets are judged on "
        f"{JUDGED}; a figure's value is its worst day (sums: over the days).",
        *section_head("Targets over the days", "target", behaviours),
    ]
    names = list(summary["by_behaviour"][behaviours[0]]["targets"]) if behaviours else []
    for name in names:
        verdicts = [summary["by_behaviour"][b]["targets"][name] for b in behaviours]
        cells = [_verdict(v) for v in verdicts]
        lines.append(f"| {verdicts[0]['target']} | " + " | ".join(cells) + " |")
    calibration = summary["calibration"]["target"]
    lines += ["", f"Calibration: {calibration['target']}: {_verdict(calibration)}."]
    lines += section_head(
        "Days",
        "day",
        [
            "behaviour",
            "ego speed RMSE median / p90 [m/s]",
            "end error median / p90 [m]",
            "speed field RMSE worst lane; lanes " + " / ".join(map(str, LANES)) + " [m/s]",
            "lane changes sim / rec (ratio); out of lanes " + " / ".join(map(str, LANES)),
            "lane changes sim / rec by zone: " + " / ".join(z.replace("_", " ") for z in ZONES),
            "collisions kinematic; physics",
            "stalled kinematic; physics",
            "calibrate [s]",
            "eval kinematic; physics [s]",
        ],
    )
    for r in evaluated(frame).to_dict("records"):
        lanes = " / ".join(_f(r.get(f"speed_field_rmse_lane_{lane}_mps")) for lane in LANES)
        by_lane = " / ".join(_f(r.get(f"lane_change_ratio_lane_{lane}")) for lane in LANES)
        cells = [
            r["behaviour"],
            f"{_f(r['ego_speed_rmse_median_mps'])} / {_f(r['ego_speed_rmse_p90_mps'])}",
            f"{_f(r['end_error_median_m'], 1)} / {_f(r['end_error_p90_m'], 1)}",
            f"{_f(r['speed_field_rmse_worst_lane_mps'])}; {lanes}",
            f"{_n(r['lane_changes_simulated'])} / {_n(r['lane_changes_recorded'])} "
            f"({_f(r['lane_change_ratio'])}); {by_lane}",
            " / ".join(
                f"{_n(r.get(f'lane_changes_{z}_simulated'))}:{_n(r.get(f'lane_changes_{z}_recorded'))}"
                for z in ZONES
            ),
            f"{_collisions(r, '')}; {_collisions(r, 'physics_')}",
            f"{_n(r['stalled'])}; {_n(r.get('physics_stalled'))}",
            _f(r["calibrate_s"], 1),
            f"{_f(r['eval_s'], 0)}; {_f(r.get('physics_s'), 0)}",
        ]
        lines.append(f"| {r['day']} | " + " | ".join(cells) + " |")
    if summary["days_not_evaluated"]:
        lines += ["", f"## Days not evaluated ({len(summary['days_not_evaluated'])})", ""]
        lines += [
            f"- {d['day']}: {d['status']}: {d['reason']}" for d in summary["days_not_evaluated"]
        ]
    params = [c for c in frame.columns if c.startswith("param_")]
    if params:
        days = frame.drop_duplicates("day")
        lines += section_head("Parameters of the days", "day", params)
        for r in days.to_dict("records"):
            lines.append(f"| {r['day']} | " + " | ".join(_cell(r.get(p)) for p in params) + " |")
    return "\n".join(lines) + "\n"


def _verdict(v: dict) -> str:
    if v["met"] is None:
        return "- (no day judged)"
    return f"{v['value']:g} {v['bound']}: {'met' if v['met'] else '**not met**'}"


def _collisions(row: dict, prefix: str) -> str:
    """Collisions and their causes (those with any), e.g. ``2 (rear_end 2)``."""
    total = row.get(prefix + "collisions")
    if total is None or not math.isfinite(total):
        return "-"
    causes = [
        f"{k.removeprefix(prefix + 'collisions_')} {_n(v)}"
        for k, v in row.items()
        if k.startswith(prefix + "collisions_") and v and math.isfinite(v)
    ]
    return _n(total) + (f" ({', '.join(causes)})" if causes else "")


def _f(value, digits: int = 2) -> str:
    if value is None or not math.isfinite(value):
        return "-"
    return f"{value:.{digits}f}"


def _n(value) -> str:
    if value is None or not math.isfinite(value):
        return "-"
    return f"{value:g}"


def _cell(value) -> str:
    return "-" if value is None else str(value).replace("|", "\\|")


def plot(frame, summary: dict, path: Path) -> None:
    """``fidelity.png``: each main figure's distribution over the days, per behaviour
    (a box and the days as points), with its target; the collisions and stalls summed
    over the days in both worlds."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    bounds = {t.figure: t.bound for t in TARGETS}
    behaviours = summary["behaviours"]
    rows = evaluated(frame)
    fig, axes = plt.subplots(2, 4, figsize=(17.0, 8.4))
    for ax, name in zip(axes.flat, MAIN_FIGURES, strict=False):
        title, unit = TITLES[name]
        for k, behaviour in enumerate(behaviours, start=1):
            _days(ax, k, rows.loc[rows["behaviour"] == behaviour, name], log=name in RATIOS)
        ax.set_xticks(range(1, len(behaviours) + 1), behaviours)
        ax.set_xlim(0.4, len(behaviours) + 0.6)
        if name in RATIOS:
            shown = rows[name].to_numpy(dtype=float)
            shown = shown[np.isfinite(shown) & (shown > 0)]
            ax.set_yscale("log")
            ax.set_ylim(min([*shown, RATIO_LIMITS[0]]) / 1.3, max([*shown, RATIO_LIMITS[1]]) * 1.3)
            ax.axhspan(*RATIO_BAND, color="green", alpha=0.15, label="target band (80 % of days)")
            for limit in RATIO_LIMITS:
                ax.axhline(limit, color="red", ls="--", lw=1)
        else:
            _target(ax, bounds[name], "target, every day")
        _finish(ax, title, unit)
    ax = axes.flat[len(MAIN_FIGURES)]
    _days(ax, 1, rows.drop_duplicates("day")["calibrate_s"], log=False)
    ax.set_xticks([1], ["days"])
    ax.set_xlim(0.4, 1.6)
    _target(ax, CALIBRATION_TARGET.bound, "target, on a 15-minute window")
    _finish(ax, "calibration's wall time", "s")
    _safety(axes.flat[-1], summary)
    fig.suptitle(
        f"twin bench fidelity: {summary['days_evaluated']} of {summary['days']} days evaluated, "
        f"{summary['settings']['episodes']} x {summary['settings']['duration']:g} s each"
    )
    fig.tight_layout()
    fig.savefig(path, dpi=100, format="png")
    plt.close(fig)


def _days(ax, position: int, values, *, log: bool) -> None:
    """The days' ``values`` at ``position``: a box and each day as a point (a ratio of
    0 left out on a ``log`` axis)."""
    values = values.to_numpy(dtype=float)
    values = values[np.isfinite(values) & ((values > 0) if log else True)]
    if values.size:
        ax.boxplot([values], positions=[position], widths=0.5, showfliers=False)
        ax.plot(position + np.linspace(-0.15, 0.15, values.size), values, "o", ms=4,
                color=f"C{position - 1}", alpha=0.7)  # fmt: skip


def _target(ax, bound: float, label: str) -> None:
    """The target ``bound`` as a dashed line, on a y axis from 0 with room above the
    days and the bound."""
    ax.set_ylim(0.0, 1.15 * max(ax.get_ylim()[1], bound))
    ax.axhline(bound, color="red", ls="--", lw=1, label=label)


def _finish(ax, title: str, unit: str) -> None:
    ax.set_title(title, fontsize=10)
    ax.set_ylabel(f"{title} [{unit}]", fontsize=9)
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize=7, loc="best")


def _safety(ax, summary: dict) -> None:
    """Collisions and stalls over the days, per behaviour and world (target 0)."""
    names = ("collisions", "stalled", "physics_collisions", "physics_stalled")
    behaviours = summary["behaviours"]
    width = 0.8 / max(len(behaviours), 1)
    x = np.arange(len(names))
    for k, behaviour in enumerate(behaviours):
        totals = summary["by_behaviour"][behaviour]["totals"]
        ax.bar(
            x + k * width, [totals[n] or 0.0 for n in names], width, label=behaviour, color=f"C{k}"
        )
    ax.set_xticks(x + 0.4 - width / 2, [n.replace("_", "\n") for n in names], fontsize=8)
    ax.axhline(0.0, color="red", ls="--", lw=1)
    ax.set_ylim(0.0, max(1.0, ax.get_ylim()[1]))
    ax.set_title("collisions and stalls over the days (target 0)", fontsize=10)
    ax.set_ylabel("count")
    ax.legend(fontsize=7)
