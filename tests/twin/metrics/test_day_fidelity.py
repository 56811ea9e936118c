"""A day's fidelity from its evaluation's summary, and the targets over days
(twin.metrics.day_fidelity)."""

import math

import pandas as pd
import pytest

from twin.metrics import day_fidelity as df
from twin.metrics.collisions import COLUMNS
from twin.metrics.lane_flow_fidelity import PAIRS, pair_key
from twin.metrics.table import SUMMARISED


def _entry(**stats) -> dict:
    """An arm's entry of twin eval's summary.json: every metric None or 0, but
    ``stats`` (name: (median, p90) or a sum)."""
    metrics = {}
    for name, kind in SUMMARISED.items():
        given = stats.get(name)
        if kind == "sum":
            metrics[name] = {"sum": float(given or 0), "count": 4}
        else:
            median, p90 = given if given is not None else (None, None)
            metrics[name] = {"median": median, "p90": p90, "mean": median, "count": 4}
    pairs = {pair_key(a, b): {"simulated": 0, "recorded": 0} for a, b in PAIRS}
    pairs["-2>-3"] = {"simulated": 3, "recorded": 2}
    pairs["-2>-1"] = {"simulated": 1, "recorded": 2}
    pairs["-4>-3"] = {"simulated": 5, "recorded": 0}
    return {"episodes_run": 4, "episodes_skipped": 0, "metrics": metrics,
            "lane_flows": {"pairs": pairs}}  # fmt: skip


def test_a_days_figures_are_its_episodes_medians_and_p90s_and_its_sums():
    entry = _entry(
        ego_speed_rmse_mps=(0.8, 1.9),
        ego_position_error_end_m=(12.0, 40.0),
        **{"speed_field_rmse_lane_-1_mps": (0.5, 0.9), "speed_field_rmse_lane_-3_mps": (1.7, 2.0)},
        lane_changes_simulated=9,
        lane_changes_recorded=6,
        collisions=2,
        collisions_rear_end=2,
        stalled_across_lines=1,
    )
    row = df.day_figures(entry)
    assert (row["ego_speed_rmse_median_mps"], row["ego_speed_rmse_p90_mps"]) == (0.8, 1.9)
    assert (row["end_error_median_m"], row["end_error_p90_m"]) == (12.0, 40.0)
    assert row["speed_field_rmse_worst_lane_mps"] == 1.7  # the lanes' largest; -2, -4 unmeasured
    assert math.isnan(row["speed_field_rmse_lane_-2_mps"])
    assert row["lane_change_ratio"] == 1.5
    # per lane: the changes out of it, both ways
    assert row["lane_changes_out_of_lane_-2_simulated"] == 4
    assert row["lane_changes_out_of_lane_-2_recorded"] == 4
    assert row["lane_change_ratio_lane_-2"] == 1.0
    assert math.isnan(row["lane_change_ratio_lane_-4"])  # 5 simulated, none recorded
    assert row["collisions"] == 2 and row["collisions_rear_end"] == 2 and row["stalled"] == 1
    assert {f"collisions_{cause}" for cause in COLUMNS} <= set(row)


def test_another_worlds_safety_is_prefixed_and_empty_where_it_did_not_run():
    ran = df.safety_figures(_entry(collisions=1, collisions_spawn=1), "physics_")
    assert ran["physics_collisions_spawn"] == 1 and ran["physics_episodes_run"] == 4
    missing = df.safety_figures(None, "physics_")
    assert math.isnan(missing["physics_collisions"]) and missing["physics_episodes_run"] == 0


def _days(**columns) -> pd.DataFrame:
    n = len(next(iter(columns.values())))
    return pd.DataFrame({"day": [f"day_{k:04d}" for k in range(n)], **columns})


def test_every_day_targets_judge_the_worst_day_and_sum_targets_the_sum():
    rows = _days(
        ego_speed_rmse_median_mps=[0.5, 0.9, 1.2, 0.7],
        collisions=[0, 0, 0, 0],
        stalled=[0, 1, 0, 0],
        lane_change_ratio=[1.0, 1.1, 0.8, 1.2],
    )
    verdict = df.over_days(rows)
    speed = verdict["figures"]["ego_speed_rmse_median_mps"]
    assert (speed["median"], speed["worst"], speed["worst_day"]) == (0.8, 1.2, "day_0002")
    target = verdict["targets"]["ego_speed_median"]
    assert (target["value"], target["met"], target["days_met"]) == (1.2, False, 3)
    assert verdict["targets"]["collisions"]["met"] is True
    assert verdict["targets"]["stalled"]["value"] == 1 and not verdict["targets"]["stalled"]["met"]
    assert verdict["targets_met"] is False


@pytest.mark.parametrize(
    ("ratios", "share", "outside", "band_met", "limits_met", "worst"),
    [
        ([1.0, 1.2, 0.8, 0.9, 1.3], 1.0, 0, True, True, 1.3),
        ([1.0, 1.2, 0.8, 0.9, 1.5], 0.8, 0, True, True, 1.5),  # 4 of 5: 80 % is enough
        ([1.0, 1.2, 0.7, 1.5, 1.1], 0.6, 0, False, True, 1.5),
        ([1.0, 1.0, 1.0, 1.0, 0.4], 0.8, 1, True, False, 0.4),  # 0.4 is farther than 2.1
        ([1.0, 0.0, 2.1, math.nan], 1 / 3, 2, False, False, 0.0),  # no change made: the worst
    ],
)
def test_the_lane_change_targets_judge_the_days_with_a_ratio(
    ratios, share, outside, band_met, limits_met, worst
):
    verdict = df.over_days(_days(lane_change_ratio=ratios))
    assert verdict["lane_change_days_within_share"] == pytest.approx(share, abs=1e-4)
    assert verdict["lane_change_days_outside"] == outside
    assert verdict["targets"]["lane_changes_band"]["met"] is band_met
    assert verdict["targets"]["lane_changes_limits"]["met"] is limits_met
    assert verdict["figures"]["lane_change_ratio"]["worst"] == worst


def test_a_target_without_a_day_to_judge_it_by_is_neither_met_nor_missed():
    verdict = df.over_days(_days(physics_collisions=[math.nan], lane_change_ratio=[math.nan]))
    assert verdict["targets"]["physics_collisions"]["met"] is None
    assert verdict["targets"]["lane_changes_band"]["met"] is None
    assert verdict["lane_change_days_outside"] is None and verdict["targets_met"] is False


def test_the_calibrations_time_is_judged_on_windows_of_15_minutes_or_more():
    assert df.calibration_figures(40.0, 899.5)["calibrate_15_min_s"] == 40.0
    assert df.calibration_figures(40.0, 1800.0)["calibrate_15_min_s"] == 40.0
    assert math.isnan(df.calibration_figures(8.0, 360.0)["calibrate_15_min_s"])
