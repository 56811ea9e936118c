"""``twin bench fidelity`` (twin/perf/fidelity.py): days calibrated on their first half
and evaluated on their second, tabled per day and judged over the days."""

import json
import shutil
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from tests.conftest import built_once
from twin.cli import main
from twin.core.i24 import SCENARIO_TIME, Road
from twin.data.synth import PRESET_A, PRESET_B, synthesize, write_i24_json
from twin.perf.fidelity_outputs import FIRST_COLUMNS

PNG = b"\x89PNG"


@pytest.fixture(scope="module")
def family(tmp_path_factory, wave_store):
    """A family folder of two days, as ``twin data sumo --family`` lays one out: the
    wave day (calibratable: its first half holds the wave) with its parameters, and a
    free-flowing westbound minute of preset A (no wave to calibrate on)."""
    folder = tmp_path_factory.mktemp("family")
    shutil.copy(wave_store.path.parent / "wave.json", folder / "day_0000.json")
    light = replace(PRESET_A, road=Road.WESTBOUND, start=SCENARIO_TIME, minutes=1.0)
    write_i24_json(synthesize(light), folder / "day_0001.json")
    params = {"seed": 0, "demand": {"scale": 1.1}, "lanes": [-1, -2]}
    (folder / "day_0000.params.json").write_text(json.dumps(params))
    (folder / "family.json").write_text(json.dumps({"family": 0, "days": 2}))
    return folder


@pytest.fixture
def session_calibration(monkeypatch, calibrated_wave_store):
    """The wave day's calibration taken from the session's calibration of the same day
    (made once for the whole suite) instead of made again on its first half: a
    calibration is seconds of the fast tier. Other days are calibrated for real (a day
    without a wave fails within a second)."""
    from twin.calibration import calibrate as module
    from twin.calibration.calibrate import read_calibration

    real = module.calibrate

    def calibrate(store, roads=None, t_from=None, t_until=None, *args, **kwargs):
        if store.path.parent.name == "day_0000":
            return read_calibration(calibrated_wave_store), {}
        return real(store, roads, t_from, t_until, *args, **kwargs)

    monkeypatch.setattr(module, "calibrate", calibrate)


def _bench(days: list, out, *more: str) -> list[str]:
    argv = ["bench", "fidelity", "--days", *map(str, days), "--episodes", "2"]
    argv += ["--duration", "10", "--physics-episodes", "0", "--workers", "1", "--quiet"]
    return [*argv, "--out", str(out), *more]


def test_bench_fidelity_tables_each_day_and_records_a_day_it_cannot_calibrate(
    family, session_calibration, tmp_path, capsys, monkeypatch
):
    out = tmp_path / "bench"
    assert main(_bench([family], out)) == 0
    line = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert line["bench"] == "fidelity"
    assert (line["days"], line["days_evaluated"], line["days_not_evaluated"]) == (2, 1, 1)
    assert set(line["calibrated"]["ego_speed_rmse_median_mps"]) == {"median", "worst"}
    assert line["targets"]["calibrated.ego_speed_rmse_median_mps.worst"] == "<= 1"
    assert line["targets_met"] is False  # a day was not evaluated

    days = pd.read_parquet(out / "days.parquet")
    assert list(days.columns[: len(FIRST_COLUMNS)]) == list(FIRST_COLUMNS)
    assert len(days) == 4 and set(days["behaviour"]) == {"calibrated", "paper"}
    wave, light = days[days["day"] == "day_0000"], days[days["day"] == "day_0001"]
    assert (wave["status"] == "evaluated").all() and (wave["episodes_run"] == 2).all()
    assert np.isfinite(wave["ego_speed_rmse_median_mps"]).all()
    assert np.isfinite(wave["speed_field_rmse_worst_lane_mps"]).all()
    lanes = wave[[f"speed_field_rmse_lane_{lane}_mps" for lane in (-1, -2, -3, -4)]]
    assert (wave["speed_field_rmse_worst_lane_mps"] == lanes.max(axis=1)).all()
    for column in ("lane_changes_out_of_lane_-2_recorded", "collisions_rear_end", "stalled"):
        assert column in days
    zones = ("before_drop", "weave", "elsewhere")
    for who in ("simulated", "recorded"):
        in_zones = sum(wave[f"lane_changes_{z}_{who}"] for z in zones)
        assert (in_zones == wave[f"lane_changes_{who}"]).all(), who
    assert (wave["collisions"] == 0).all() and wave["physics_collisions"].isna().all()
    assert (wave["param_seed"] == 0).all() and (wave["param_demand_scale"] == 1.1).all()
    assert (wave["param_lanes"] == "[-1, -2]").all() and light["param_seed"].isna().all()
    assert (light["status"] == "not calibrated").all()
    assert light["reason"].str.contains("not enough following").all()
    assert light["ego_speed_rmse_median_mps"].isna().all()

    summary = json.loads((out / "summary.json").read_text())
    assert summary["days_not_evaluated"][0]["day"] == "day_0001"
    assert summary["families"] == {str(family): {"family": 0, "days": 2}}
    targets = summary["by_behaviour"]["calibrated"]["targets"]
    assert targets["collisions"]["met"] is True and targets["collisions"]["days_judged"] == 1
    assert targets["physics_collisions"]["met"] is None  # no physics episode asked
    assert summary["calibration"]["target"]["met"] is None  # a 3.5 min window: not judged
    page = (out / "days.md").read_text()
    assert "| day_0000 | calibrated |" in page and "day_0001: not calibrated: " in page
    assert (out / "fidelity.png").read_bytes()[:4] == PNG

    # a rerun does no day again, and one with other settings is refused
    def never(*args, **kwargs):
        raise AssertionError("a day done was done again")

    monkeypatch.setattr("twin.calibration.calibrate.calibrate", never)
    monkeypatch.setattr("twin.runners.evaluation.evaluate", never)
    assert main(_bench([family], out)) == 0
    again = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert again["calibrated"] == line["calibrated"]
    assert main(_bench([family], out, "--seed", "1")) == 2
    assert "other settings" in capsys.readouterr().err


def test_bench_fidelity_names_what_it_cannot_take(family, tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    assert main(_bench([tmp_path / "empty"], tmp_path / "out")) == 2
    assert "holds no day file" in capsys.readouterr().err
    (tmp_path / "two").mkdir()
    shutil.copy(family / "day_0001.json", tmp_path / "two" / "day_0001.json")
    assert main(_bench([family, tmp_path / "two"], tmp_path / "out")) == 2
    assert "two days are named day_0001" in capsys.readouterr().err
    assert main(_bench([family], tmp_path / "out", "--physics-episodes", "3")) == 2
    assert "--physics-episodes (3) must be at most --episodes (2)" in capsys.readouterr().err


@pytest.fixture(scope="module")
def three_days(tmp_path_factory):
    """Three 5-minute days of preset B, seeds 1 to 3, each with the wave in its first
    half (100 s in), made once."""

    def build(folder):
        for seed in (1, 2, 3):
            config = replace(PRESET_B, start=SCENARIO_TIME - 100.0, minutes=5.0, seed=seed)
            write_i24_json(synthesize(config), folder / f"day_{seed:04d}.json")

    return built_once(tmp_path_factory, "fidelity_days", build)


@pytest.mark.slow
def test_bench_fidelity_keeps_the_twin_within_loose_bounds_on_three_days(
    three_days, tmp_path, capsys
):
    """Slow: three calibrations (about 14 s each on 2 cores) and 8 kinematic episodes of
    60 s per day and behaviour. A guard against gross regressions, not the issue's
    targets: measured at its writing, the calibrated drivers' ego speed RMSE medians
    were 0.6 to 0.9 m/s, the worst lane's field RMSE 1.0 to 1.1 m/s and the lane
    changes 32 simulated for 15 recorded over the three days (day by day 1.5 to 3.0)."""
    argv = ["bench", "fidelity", "--days", str(three_days), "--episodes", "8"]
    argv += ["--duration", "60", "--physics-episodes", "0", "--workers", "1", "--quiet"]
    assert main([*argv, "--out", str(tmp_path / "bench")]) == 0
    line = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert (line["days"], line["days_evaluated"]) == (3, 3)
    days = pd.read_parquet(tmp_path / "bench" / "days.parquet")
    calibrated = days[days["behaviour"] == "calibrated"]
    assert (calibrated["episodes_run"] == 8).all() and (days["episodes_failed"] == 0).all()
    assert (days["collisions"] == 0).all() and (days["stalled"] == 0).all()
    assert calibrated["ego_speed_rmse_median_mps"].median() < 3.0
    assert (calibrated["speed_field_rmse_worst_lane_mps"] < 3.0).all()
    ratio = calibrated["lane_changes_simulated"].sum() / calibrated["lane_changes_recorded"].sum()
    assert 0.25 <= ratio <= 4.0
