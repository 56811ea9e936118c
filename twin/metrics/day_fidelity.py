"""A day's fidelity, read from its evaluation, and the issue's targets judged over many
days (``twin bench fidelity``, :mod:`twin.perf.fidelity`).

A day is calibrated on its first half and evaluated (``twin eval``) on its second.
:func:`day_figures` reads one behaviour's entry of that evaluation's ``summary.json``
(:func:`twin.runners.evaluation.summarise`) into the day's figures, one flat row;
:func:`safety_figures` reads the collisions and stalls of another world's evaluation
of the same day. :func:`over_days` takes the rows of many days and gives each figure's
median and worst over the days and the verdict on each of :data:`TARGETS`.

What a day's figure is:

* the ego's speed RMSE and its end error: the median and the p90 over the day's
  episodes of each episode's figure (the end error is the distance between the ego and
  its recording at the episode's end);
* the speed field's RMSE: per lane, the median over the episodes of the lane's RMSE
  (Edie cells of the moving window); the worst lane is the largest of the four;
* the lane changes: simulated and recorded, summed over the episodes (the counts
  ``twin eval`` gives, and their ratio); per lane, the changes out of that lane as
  :mod:`twin.metrics.lane_flow_fidelity` counts them (held 1 s, between the through
  lanes), so that the lanes' counts need not add up to the overall ones;
* collisions (by cause, :mod:`twin.metrics.collisions`) and vehicles stalled across a
  lane line, summed over the episodes.
"""

import math
from dataclasses import dataclass

import numpy as np

from twin.metrics.collisions import COLUMNS as COLLISION_CAUSES
from twin.metrics.lane_change_zones import ZONES
from twin.metrics.lane_flow_fidelity import LANES, pair_key

#: The lane-change ratio the issue asks of most days, and the one it asks of every day.
RATIO_BAND = (0.75, 1.33)
RATIO_LIMITS = (0.5, 2.0)
RATIO_SHARE = 0.8  # of the days judged, at least this share within RATIO_BAND
CALIBRATION_WINDOW_S = 900.0  # [s] the recording the calibration's time target is set on
WINDOW_SLACK_S = 1.0  # [s] a window this much shorter counts: its samples start a step late


@dataclass(frozen=True)
class Target:
    """One target of the issue, judged over the days.

    Attributes:
        name: its key in ``summary.json``.
        figure: the column of the days' rows it judges.
        bound: [the figure's unit] the largest value allowed.
        over: ``every day`` (each day's value at most ``bound``: the worst day is
            judged) or ``sum`` (the sum over the days at most ``bound``).
        text: the target in the issue's words.
    """

    name: str
    figure: str
    bound: float
    over: str
    text: str

    def __post_init__(self):
        if self.over not in ("every day", "sum"):
            raise ValueError(f"target {self.name}: over must be 'every day' or 'sum'")


TARGETS = (
    Target("ego_speed_median", "ego_speed_rmse_median_mps", 1.0, "every day",
           "ego speed RMSE, median over the episodes, <= 1.0 m/s"),
    Target("ego_speed_p90", "ego_speed_rmse_p90_mps", 2.0, "every day",
           "ego speed RMSE, p90 over the episodes, <= 2.0 m/s"),
    Target("end_error_median", "end_error_median_m", 15.0, "every day",
           "end error, median over the episodes, <= 15 m"),
    Target("end_error_p90", "end_error_p90_m", 50.0, "every day",
           "end error, p90 over the episodes, <= 50 m"),
    Target("speed_field", "speed_field_rmse_worst_lane_mps", 1.5, "every day",
           "speed field RMSE <= 1.5 m/s in every lane"),
    Target("collisions", "collisions", 0.0, "sum", "no collision of any cause (kinematic)"),
    Target("stalled", "stalled", 0.0, "sum", "no vehicle stalled (kinematic)"),
    Target("physics_collisions", "physics_collisions", 0.0, "sum",
           "no collision of any cause (physics)"),
    Target("physics_stalled", "physics_stalled", 0.0, "sum", "no vehicle stalled (physics)"),
)  # fmt: skip
#: The calibration's time, a figure of the day rather than of a behaviour.
CALIBRATION_TARGET = Target(
    "calibrate_time", "calibrate_15_min_s", 60.0, "every day",
    "twin calibrate on a window of 15 minutes (or more) <= 60 s",
)  # fmt: skip

#: The figures over days in ``summary.json``, ``days.md`` and the benchmark's line.
MAIN_FIGURES = (
    "ego_speed_rmse_median_mps",
    "ego_speed_rmse_p90_mps",
    "end_error_median_m",
    "end_error_p90_m",
    "speed_field_rmse_worst_lane_mps",
    "lane_change_ratio",
)


def day_figures(entry: dict) -> dict:
    """A day's figures for one behaviour: ``entry`` is the behaviour's entry of its
    evaluation's ``summary.json`` (``summary["behaviours"][name]``). Figures the
    evaluation could not measure (no episode ran, no cell of a lane compared) are NaN."""
    metrics = entry["metrics"]
    row = {
        "episodes_run": int(entry["episodes_run"]),
        "episodes_skipped": int(entry["episodes_skipped"]),
        "episodes_failed": int(entry.get("episodes_failed", 0)),
        "ego_speed_rmse_median_mps": _stat(metrics, "ego_speed_rmse_mps", "median"),
        "ego_speed_rmse_p90_mps": _stat(metrics, "ego_speed_rmse_mps", "p90"),
        "end_error_median_m": _stat(metrics, "ego_position_error_end_m", "median"),
        "end_error_p90_m": _stat(metrics, "ego_position_error_end_m", "p90"),
        "speed_field_rmse_median_mps": _stat(metrics, "speed_field_rmse_mps", "median"),
    }
    lanes = {
        f"speed_field_rmse_lane_{lane}_mps": _stat(
            metrics, f"speed_field_rmse_lane_{lane}_mps", "median"
        )
        for lane in LANES
    }
    measured = [value for value in lanes.values() if math.isfinite(value)]
    row["speed_field_rmse_worst_lane_mps"] = max(measured) if measured else math.nan
    row.update(lanes)
    simulated = metrics["lane_changes_simulated"]["sum"]
    recorded = metrics["lane_changes_recorded"]["sum"]
    row["lane_changes_simulated"] = int(simulated)
    row["lane_changes_recorded"] = int(recorded)
    row["lane_change_ratio"] = _ratio(simulated, recorded)
    row.update(lane_changes_by_lane(entry.get("lane_flows")))
    row.update(lane_changes_by_zone(entry.get("lane_changes_by_zone")))
    row.update(safety_figures(entry))
    return row


def lane_changes_by_lane(flows: dict | None) -> dict:
    """The changes out of each lane, simulated and recorded, and their ratio, from the
    ``lane_flows`` sums of an evaluation's entry (NaN where there are none)."""
    row = {}
    for lane in LANES:
        pairs = [
            flows["pairs"][pair_key(lane, other)]
            for other in (lane - 1, lane + 1)
            if flows is not None and pair_key(lane, other) in flows["pairs"]
        ]
        simulated = sum(p["simulated"] for p in pairs) if flows is not None else math.nan
        recorded = sum(p["recorded"] for p in pairs) if flows is not None else math.nan
        row[f"lane_changes_out_of_lane_{lane}_simulated"] = simulated
        row[f"lane_changes_out_of_lane_{lane}_recorded"] = recorded
        row[f"lane_change_ratio_lane_{lane}"] = _ratio(simulated, recorded)
    return row


def lane_changes_by_zone(counts: dict | None) -> dict:
    """The changes in each zone (:mod:`twin.metrics.lane_change_zones`), simulated and
    recorded, and their ratio (NaN where not counted or none recorded)."""
    row = {}
    for zone in ZONES:
        c = (counts or {}).get(zone) or {}
        simulated, recorded = c.get("simulated"), c.get("recorded")
        simulated = math.nan if simulated is None else simulated
        recorded = math.nan if recorded is None else recorded
        row[f"lane_changes_{zone}_simulated"] = simulated
        row[f"lane_changes_{zone}_recorded"] = recorded
        row[f"lane_change_ratio_{zone}"] = _ratio(simulated, recorded)
    return row


def safety_figures(entry: dict | None, prefix: str = "") -> dict:
    """Collisions (all, and by cause) and vehicles stalled across a lane line, summed
    over an evaluation's episodes, with the episodes run, as ``PREFIX + name``; NaN for
    each where ``entry`` is None (that world was not run)."""
    names = ["collisions", *(f"collisions_{cause}" for cause in COLLISION_CAUSES)]
    metrics = entry["metrics"] if entry is not None else None
    row = {
        prefix + name: (metrics[name]["sum"] if metrics is not None else math.nan) for name in names
    }
    row[prefix + "stalled"] = (
        metrics["stalled_across_lines"]["sum"] if metrics is not None else math.nan
    )
    if prefix:
        row[prefix + "episodes_run"] = entry["episodes_run"] if entry is not None else 0
    return row


def over_days(rows) -> dict:
    """Each main figure's median and worst over the days of ``rows`` (one behaviour's
    rows of evaluated days: a DataFrame of :func:`day_figures` columns with ``day``),
    the lane changes' share of days within :data:`RATIO_BAND` and days outside
    :data:`RATIO_LIMITS`, and the verdict on every target.

    A figure's worst is its largest; the lane-change ratio's is the one farthest from 1
    (by factor). Days without a value of a figure are left out of it (``days`` says how
    many had one); a target with no day to judge is ``met: null``.
    """
    figures = {name: _over(rows, name) for name in MAIN_FIGURES if name in rows}
    ratios = rows["lane_change_ratio"].to_numpy(dtype=float) if len(rows) else np.array([])
    ratios = ratios[np.isfinite(ratios)]
    within = int(np.count_nonzero((ratios >= RATIO_BAND[0]) & (ratios <= RATIO_BAND[1])))
    outside = int(np.count_nonzero((ratios < RATIO_LIMITS[0]) | (ratios > RATIO_LIMITS[1])))
    share = within / ratios.size if ratios.size else None
    targets = {t.name: judge(rows, t) for t in TARGETS if t.figure in rows}
    targets["lane_changes_band"] = {
        "target": f"lane changes simulated / recorded in [{RATIO_BAND[0]}, {RATIO_BAND[1]}] "
        f"on >= {RATIO_SHARE:.0%} of days",
        "value": None if share is None else round(share, 4),
        "bound": f">= {RATIO_SHARE}",
        "days_judged": int(ratios.size),
        "met": None if share is None else share >= RATIO_SHARE,
    }
    targets["lane_changes_limits"] = {
        "target": f"lane changes simulated / recorded never outside [{RATIO_LIMITS[0]}, "
        f"{RATIO_LIMITS[1]}]",
        "value": outside,
        "bound": "<= 0",
        "days_judged": int(ratios.size),
        "met": None if not ratios.size else outside == 0,
    }
    judged = [t["met"] for t in targets.values() if t["met"] is not None]
    return {
        "figures": figures,
        "lane_change_days_within_share": None if share is None else round(share, 4),
        "lane_change_days_outside": outside if ratios.size else None,
        "targets": targets,
        "targets_met": bool(judged) and all(judged),
    }


def _over(rows, name: str) -> dict:
    """Median and worst of column ``name`` over the days that have it."""
    values = rows[name].to_numpy(dtype=float)
    days = rows["day"].to_numpy()
    have = np.isfinite(values)
    if not have.any():
        return {"median": None, "worst": None, "worst_day": None, "days": 0}
    values, days = values[have], days[have]
    with np.errstate(divide="ignore"):  # a ratio of 0 is the farthest from 1
        badness = np.abs(np.log(values)) if name == "lane_change_ratio" else values
    worst = int(np.argmax(badness))
    return {
        "median": _r(np.median(values)),
        "worst": _r(values[worst]),
        "worst_day": str(days[worst]),
        "days": int(values.size),
    }


def calibration_figures(seconds: float, window_s: float) -> dict:
    """A day's calibration figures: its wall time [s] over a window of ``window_s`` [s],
    and that time again as ``calibrate_15_min_s`` where the window is at least
    :data:`CALIBRATION_WINDOW_S` (the target's; a longer one is a stricter test), else
    NaN (not judged)."""
    long_enough = window_s >= CALIBRATION_WINDOW_S - WINDOW_SLACK_S
    return {
        "calibrate_s": round(seconds, 2),
        "calibration_window_s": round(window_s, 1),
        "calibrate_15_min_s": round(seconds, 2) if long_enough else math.nan,
    }


def judge(rows, target: Target) -> dict:
    """The verdict on ``target`` over the days of ``rows`` (a DataFrame) that have its
    figure: its value (the worst day's, or the sum), the bound, the days judged and
    met, and ``met`` (None where no day has the figure)."""
    values = rows[target.figure].to_numpy(dtype=float)
    values = values[np.isfinite(values)]
    verdict = {"target": target.text, "figure": target.figure, "over": target.over}
    if not values.size:
        return {
            **verdict,
            "value": None,
            "bound": f"<= {target.bound:g}",
            "days_judged": 0,
            "met": None,
        }
    value = values.sum() if target.over == "sum" else values.max()
    return {
        **verdict,
        "value": _r(value),
        "bound": f"<= {target.bound:g}",
        "days_judged": int(values.size),
        "days_met": int(np.count_nonzero(values <= target.bound)),
        "met": bool(value <= target.bound),
    }


def _stat(metrics: dict, name: str, which: str) -> float:
    value = metrics[name][which]
    return math.nan if value is None else float(value)


def _ratio(simulated: float, recorded: float) -> float:
    """``simulated / recorded``, NaN where nothing was recorded."""
    if not (math.isfinite(recorded) and recorded > 0):
        return math.nan
    return round(float(simulated) / float(recorded), 4)


def _r(value) -> float:
    return round(float(value), 4)
