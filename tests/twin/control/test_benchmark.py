"""The wave-dampening benchmark: controllers on the same episodes, each paired with
``human``; the paired changes and their bootstrap interval."""

import json

import pandas as pd
import pytest

from twin.control import benchmark
from twin.runners.evaluation import EvalConfig, EvaluationError


def _config(**changes) -> EvalConfig:
    return EvalConfig(episodes=2, duration=8.0, behaviours=("calibrated",), seed=3, **changes)


def test_the_controller_benchmark_pairs_each_controller_with_human(
    calibrated_wave_store, built_map, tmp_path
):
    calibrated = calibrated_wave_store
    config = _config(controllers=("human", "follower_stopper"), av_share=0.3)
    assert config.controllers == ("twin.controllers:human", "twin.controllers:follower_stopper")
    out = tmp_path / "bench"
    benchmark.benchmark(calibrated, out, config, workers=1, bundle=built_map, progress=False)
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
    with pytest.raises(EvaluationError, match="give --controller"):
        benchmark.benchmark(calibrated, tmp_path / "none", _config(), bundle=built_map)


def test_paired_changes_and_their_interval():
    changes = benchmark.paired_changes([11.0, 22.0, float("nan"), 5.0], [10.0, 20.0, 5.0, 0.0])
    assert list(changes) == pytest.approx([10.0, 10.0])  # NaN and a zero reference dropped
    flat = benchmark.mean_with_ci(changes)
    assert flat["mean"] == 10.0 and flat["ci95"] == [10.0, 10.0] and flat["episodes"] == 2
    spread = benchmark.mean_with_ci(list(range(40)))
    assert spread["ci95"][0] < 19.5 < spread["ci95"][1]
    assert spread == benchmark.mean_with_ci(list(range(40)))  # seeded: deterministic
    assert benchmark.mean_with_ci([])["mean"] is None


def test_the_terminal_line_gives_the_window_and_the_paired_changes():
    def medians(**values):
        metrics = {name: {"median": value} for name, value in values.items()}
        metrics["collisions"] = {"sum": 0}
        return {"metrics": metrics}

    figures = dict(ego_and_followers_mpg=90.0, window_mpg=84.0, speed_std_window_mps=3.07,
                   speed_std_behind_mps=3.2, min_ttc_s=18.0)  # fmt: skip
    change = {"mean": -6.0, "ci95": [-7.2, -4.7]}
    summary = {
        "controllers": {"human": medians(**figures), "policy": medians(**figures)},
        "paired_vs_human": {"policy": {"metrics": {"speed_std_window_mps": change}}},
    }
    human, policy = benchmark.lines(summary)
    assert "window 84.00 mpg, speed std 3.07 m/s;" in human and "vs human" not in human
    assert "speed std 3.07 m/s (vs human -6.0 % [-7.2, -4.7])" in policy
