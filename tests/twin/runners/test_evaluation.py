"""``twin eval``: the same episodes for every behaviour, the same results on one worker
or two, resumable, with its tables and picture; bad settings named."""

import json
import os

import pandas as pd
import pytest

from twin.cli import main
from twin.data.store import TrajectoryStore
from twin.runners.evaluation import EvalConfig, EvaluationError, evaluate
from twin.traffic.controller_api import controller_factory


@pytest.fixture
def calibrated(calibrated_wave_store) -> TrajectoryStore:
    return calibrated_wave_store


def _config(**changes):
    settings = {"episodes": 2, "duration": 8.0, "behaviours": ("paper", "calibrated"), "seed": 3}
    return EvalConfig(**{**settings, **changes})


@pytest.mark.slow
def test_eval_runs_every_behaviour_on_the_same_episodes_and_resumes(
    calibrated, built_map, tmp_path
):
    out = tmp_path / "eval"
    result = evaluate(calibrated, out, _config(), workers=1, bundle=built_map, progress=False)
    assert result.runs_done_now == 4
    frame = pd.read_parquet(out / "episodes.parquet")
    assert len(frame) == 4
    by = frame.set_index(["episode", "behaviour"])
    for episode in (0, 1):
        # the same ego, start and seed for both behaviours
        paper, calibrated_row = by.loc[(episode, "paper")], by.loc[(episode, "calibrated")]
        for column in ("x", "time", "lane", "seed", "ego_record_id"):
            assert paper[column] == calibrated_row[column]
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary["behaviours"]) == {"paper", "calibrated"}
    assert summary["behaviours"]["paper"]["metrics"]["ego_speed_rmse_mps"]["median"] is not None
    assert "| ego_speed_rmse_mps (median / p90) |" in (out / "summary.md").read_text()
    # the lane changes by zone: every change placed, once
    for entry in summary["behaviours"].values():
        places = entry["lane_flows"]["changes"]
        by_zone = entry["lane_changes_by_zone"]
        for who in ("simulated", "recorded"):
            assert sum(z[who] for z in by_zone.values()) == len(places[f"{who}_x"])
    assert summary["lane_change_zones"]["weaves"]  # the road's on-ramp
    assert "## Lane changes by zone" in (out / "summary.md").read_text()
    assert (out / "fidelity.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    # resumed: nothing runs again; two workers give the same rows
    again = evaluate(calibrated, out, _config(), workers=1, bundle=built_map, progress=False)
    assert again.runs_done_now == 0
    other = tmp_path / "eval2"
    evaluate(calibrated, other, _config(), workers=2, bundle=built_map, progress=False)
    second = pd.read_parquet(other / "episodes.parquet").drop(columns=["loop_s"])
    pd.testing.assert_frame_equal(frame.drop(columns=["loop_s"]), second)
    try:
        import ray  # noqa: F401
    except ImportError:
        if os.environ.get("CI"):
            raise
        return
    by_ray = tmp_path / "eval3"
    evaluate(
        calibrated, by_ray, _config(), workers=2, engine="ray", bundle=built_map, progress=False
    )
    third = pd.read_parquet(by_ray / "episodes.parquet").drop(columns=["loop_s"])
    pd.testing.assert_frame_equal(frame.drop(columns=["loop_s"]), third)


def test_eval_settings_and_folders_are_checked(calibrated, wave_store, built_map, tmp_path):
    with pytest.raises(EvaluationError, match="--behaviour must list distinct behaviours"):
        _config(behaviours=("paper", "wild"))
    with pytest.raises(EvaluationError, match="--episodes must be an integer"):
        _config(episodes=0)
    with pytest.raises(EvaluationError, match="must be before"):
        _config(t_from=2.0, t_until=1.0)
    (tmp_path / "busy").mkdir()
    (tmp_path / "busy" / "notes.txt").write_text("mine")
    with pytest.raises(EvaluationError, match="not an evaluation folder"):
        evaluate(calibrated, tmp_path / "busy", _config(), bundle=built_map, progress=False)
    assert (tmp_path / "busy" / "notes.txt").read_text() == "mine"
    # a store without a calibration cannot run the calibrated behaviour
    assert main(["eval", "--data", str(wave_store.path), "--episodes", "1", "--behaviour",
                 "calibrated", "--out", str(tmp_path / "e"), "--quiet"]) == 2  # fmt: skip
    assert not (tmp_path / "e").exists()


def test_fidelity_png_titles_each_panel_by_its_metric_with_units(tmp_path, monkeypatch):
    import matplotlib.pyplot as plt

    from twin.runners import evaluation

    drawn = []
    monkeypatch.setattr(plt, "close", lambda fig: drawn.append(fig))
    config = _config()
    frame = pd.DataFrame(
        {
            "arm": ["paper", "calibrated"],
            "ego_speed_rmse_mps": [1.0, 0.5],
            "ego_position_error_end_m": [10.0, 3.0],
            "speed_field_rmse_mps": [2.0, 1.0],
            "slow_spell_end_difference_s": [float("nan"), 1.0],
            "lane_changes_simulated": [5, 4],
        }
    )
    evaluation._plot(frame, config, tmp_path / "fidelity.png", {"paper": None, "calibrated": None})
    top = drawn[0].axes[:5]
    # before, every panel was titled by the last arm ("calibrated") and had no y label
    assert [ax.get_title() for ax in top] == [
        "ego speed RMSE",
        "ego position error at the end",
        "speed-field RMSE, all lanes",
        "slow spell end, simulated - recorded",
        "lane changes simulated per episode",
    ]
    assert top[0].get_ylabel() == "ego speed RMSE [m/s]"
    assert all(ax.get_ylabel() for ax in drawn[0].axes)


@pytest.mark.slow
def test_kinematic_episodes_run_in_batches_and_are_counted_one_by_one(
    calibrated, built_map, tmp_path
):
    """The kinematic world's episodes run in batches of the core (one job holds several):
    the runs made now are counted by episode, and the rows are those of one batch or
    another (two workers split the episodes differently)."""
    from dataclasses import replace

    from twin.cosim.config import switch_world

    config = _config(episodes=3, duration=4.0, behaviours=("paper",))
    config = replace(config, cosim=switch_world(config.cosim, "kinematic"))
    one = evaluate(calibrated, tmp_path / "one", config, workers=1, bundle=built_map,
                   progress=False)  # fmt: skip
    assert one.runs_done_now == 3
    two = evaluate(calibrated, tmp_path / "two", config, workers=2, bundle=built_map,
                   progress=False)  # fmt: skip
    assert two.runs_done_now == 3
    columns = ["episode", "ego_speed_rmse_mps", "speed_field_rmse_mps", "lane_changes_simulated"]
    rows_one = pd.read_parquet(tmp_path / "one" / "episodes.parquet")[columns]
    rows_two = pd.read_parquet(tmp_path / "two" / "episodes.parquet")[columns]
    pd.testing.assert_frame_equal(rows_one, rows_two)


_MADE: list[int] = []  # the episodes' controllers made in this process, in order


@controller_factory
def fails_in_its_second_episode(config):
    """A controller whose second episode (in this process) answers NaN."""
    _MADE.append(config.seed)
    broken = len(_MADE) == 2

    def controller(obs):
        return float("nan") if broken and obs.time > 2.0 else obs.default_accel

    return controller


def test_a_failing_episode_is_recorded_and_the_sweep_goes_on(calibrated, built_map, tmp_path):
    from twin.runners.failures import failure_lines

    name = f"{__name__}:fails_in_its_second_episode"
    config = _config(episodes=3, behaviours=("calibrated",), controllers=(name,))
    out = tmp_path / "eval"
    _MADE.clear()
    result = evaluate(calibrated, out, config, workers=1, bundle=built_map, progress=False)
    frame = pd.read_parquet(out / "episodes.parquet")
    assert result.runs_done_now == 3 and len(frame) == 3
    failed = frame[frame["failed"].notna()]
    assert failed["episode"].tolist() == [1]  # the second; the first and third ran
    assert "returned accel nan" in failed["failed"].iloc[0]
    assert "controller_api.py:" in failed["failed"].iloc[0]  # where it was raised
    ran = frame[frame["failed"].isna()]
    assert ran["ego_speed_rmse_mps"].notna().all() and failed["ego_speed_rmse_mps"].isna().all()
    entry = result.summary["controllers"]["fails_in_its_second_episode"]
    assert entry["episodes_run"] == 2 and entry["episodes_failed"] == 1
    assert entry["episodes_skipped"] == 0
    assert entry["metrics"]["ego_speed_rmse_mps"]["count"] == 2
    # the command that repeats it: twin run with the episode's settings
    repeat = entry["failures"][0]["repeat"]
    toml = out / "failed" / "000001-fails_in_its_second_episode.toml"
    assert repeat == f"twin run --data {calibrated.path.resolve()} --config {toml.resolve()}"
    assert f'ego_controller = "{name}"' in toml.read_text()
    lines = failure_lines(result.summary)
    assert "1 episode run failed" in lines[0] and "returned accel nan" in lines[1]
    assert "Failed episodes (1)" in (out / "summary.md").read_text()
    # resumed: the failed episode runs again (here it no longer fails), the rest are kept
    _MADE.clear()
    again = evaluate(calibrated, out, config, workers=1, bundle=built_map, progress=False)
    assert again.runs_done_now == 1
    assert "failed" not in pd.read_parquet(out / "episodes.parquet")
    assert not failure_lines(again.summary) and not toml.exists()
