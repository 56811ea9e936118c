"""ARS training: its objective, its settings, one deterministic iteration with its
learning curve."""

import math

import pytest

from twin.control.policy import FOLLOW_LEADER, LinearSpeedPolicy
from twin.control.train import TrainConfig, TrainingError, objective, train


def test_the_objective_is_the_paired_economy_less_its_penalties():
    human = {"ego_and_followers_mpg": 50.0, "window_mpg": 40.0}
    run = {"ego_and_followers_mpg": 55.0, "window_mpg": 40.0, "collisions": 0,
           "time_gap_p90_s": 3.0}  # fmt: skip
    assert objective(run, human) == (pytest.approx(10.0), pytest.approx(10.0))
    assert objective({**run, "collisions": 1}, human)[0] == pytest.approx(-40.0)
    assert objective({**run, "time_gap_p90_s": 6.0}, human)[0] == pytest.approx(0.0)
    worse_window = {**run, "window_mpg": 39.0}  # -2.5 %: 1.5 points past -1 %
    assert objective(worse_window, human)[0] == pytest.approx(10.0 - 3.0)
    value, economy = objective({}, human)
    assert value == -100.0 and math.isnan(economy)


@pytest.mark.parametrize(
    ("settings", "message"),
    [
        ({"iterations": 0}, "iterations must be an integer >= 1"),
        ({"top": 9}, r"top \(9\) must be at most directions \(8\)"),
        ({"noise": -1.0}, "noise must be a positive number"),
        ({"start": (1.0,)}, "start must hold 8 weights"),
    ],
)
def test_bad_settings_are_named(settings, message):
    with pytest.raises(TrainingError, match=message):
        TrainConfig(**settings)


@pytest.mark.slow
def test_one_iteration_is_deterministic_and_writes_its_curve(calibrated_wave_store, tmp_path):
    config = TrainConfig(iterations=1, directions=1, top=1, episodes=1, duration=8.0)
    first = train(calibrated_wave_store, tmp_path / "a", config, progress=False)
    again = train(calibrated_wave_store, tmp_path / "b", config, progress=False)
    assert first.weights == again.weights and first.weights != FOLLOW_LEADER
    assert LinearSpeedPolicy.load(tmp_path / "a" / "policy.json") == first
    curve = (tmp_path / "a" / "curve.csv").read_text().splitlines()
    assert curve[0].startswith("iteration,runs,env_steps") and len(curve) == 2
    assert (tmp_path / "a" / "curve.png").stat().st_size > 0


def test_the_search_climbs_toward_better_weights(calibrated_wave_store, tmp_path, monkeypatch):
    """With runs stubbed by a known objective (economy falls with the distance of the
    bias weight from 4 m/s), the update's signs and its arms' indexing take the bias
    there: a swapped + and - or a wrong arm would take it away."""
    import twin.control.train as train_module

    def rollout(location, spec, weights, config):
        if weights is None:
            return {"ego_and_followers_mpg": 50.0, "window_mpg": 40.0}
        mpg = 50.0 * (1.0 + 0.01 * (10.0 - (weights[0] - 4.0) ** 2))
        return {"ego_and_followers_mpg": mpg, "window_mpg": 40.0, "collisions": 0}

    monkeypatch.setattr(train_module, "_rollout", rollout)
    config = TrainConfig(iterations=12, directions=4, top=2, episodes=1, duration=8.0)
    policy = train(calibrated_wave_store, tmp_path, config, progress=False)
    assert abs(policy.weights[0] - 4.0) < 1.0  # from 0
    assert policy.weights[2] == pytest.approx(1.0, abs=0.3)  # the rest barely matters
