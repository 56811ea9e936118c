"""``twin eval``: the same episodes for every behaviour, the same results on one worker
or two, resumable, with its tables and picture; bad settings named."""

import json
import os

import pandas as pd
import pytest

from twin.cli import main
from twin.data.store import TrajectoryStore
from twin.runners.evaluation import EvalConfig, EvaluationError, evaluate


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


def test_the_controller_benchmark_pairs_each_controller_with_human(calibrated, built_map, tmp_path):
    config = _config(
        behaviours=("calibrated",), controllers=("human", "follower_stopper"), av_share=0.3
    )
    assert config.controllers == ("twin.controllers:human", "twin.controllers:follower_stopper")
    out = tmp_path / "bench"
    evaluate(calibrated, out, config, workers=1, bundle=built_map, progress=False)
    frame = pd.read_parquet(out / "episodes.parquet")
    assert sorted(set(frame["arm"])) == ["follower_stopper", "human"]
    by = frame.set_index(["episode", "arm"])
    for episode in (0, 1):  # the same episodes, the same seeds
        for column in ("x", "time", "lane", "seed", "ego_record_id"):
            assert (
                by.loc[(episode, "human"), column] == by.loc[(episode, "follower_stopper"), column]
            )
    assert frame["ego_and_followers_mpg"].notna().all() and (frame["collisions"] == 0).all()
    # --av-share: some visible vehicles drive with the controller too (human's are human)
    assert frame["avs_mpg"].notna().all() and frame["avs"].max() > 1
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary["controllers"]) == {"human", "follower_stopper"}
    paired = summary["paired_vs_human"]["follower_stopper"]["metrics"]["ego_and_followers_mpg"]
    human = frame[frame["arm"] == "human"].set_index("episode")["ego_and_followers_mpg"]
    mine = frame[frame["arm"] == "follower_stopper"].set_index("episode")["ego_and_followers_mpg"]
    assert paired["mean"] == pytest.approx(float((100 * (mine - human) / human).mean()), abs=1e-3)
    assert paired["ci95"][0] <= paired["mean"] <= paired["ci95"][1] and paired["episodes"] == 2
    assert "Paired change against human" in (out / "summary.md").read_text()
    assert (out / "waves.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(EvaluationError, match="--controller must list distinct controllers"):
        _config(controllers=("human", "twin.controllers:human"))
    with pytest.raises(EvaluationError, match="--av-share needs --controller"):
        _config(av_share=0.5)


def test_paired_changes_and_their_interval():
    from twin.control import benchmark

    changes = benchmark.paired_changes([11.0, 22.0, float("nan"), 5.0], [10.0, 20.0, 5.0, 0.0])
    assert list(changes) == pytest.approx([10.0, 10.0])  # NaN and a zero reference dropped
    flat = benchmark.mean_with_ci(changes)
    assert flat["mean"] == 10.0 and flat["ci95"] == [10.0, 10.0] and flat["episodes"] == 2
    spread = benchmark.mean_with_ci(list(range(40)))
    assert spread["ci95"][0] < 19.5 < spread["ci95"][1]
    assert spread == benchmark.mean_with_ci(list(range(40)))  # seeded: deterministic
    assert benchmark.mean_with_ci([])["mean"] is None
