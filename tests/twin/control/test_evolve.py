"""Training the MLP policy with an evolution strategy on the vector env
(twin.control.evolve): the score, the ranks, a generation's files, resuming, bad
settings."""

import numpy as np
import pytest

from twin.control.evolve import EvolveConfig, centred_ranks, evolve, score
from twin.control.mlp import MLPPolicy, n_weights
from twin.control.train import TrainingError


def _figures(**change):
    base = {
        "economy_pct": 3.0, "collisions": 0, "time_gap_p10_s": 1.2, "time_gap_p90_s": 3.0,
        "min_ttc_s": 8.0, "jerk_rms_mps3": 0.3, "safety_pct": 0.0,
    }  # fmt: skip
    return {**base, **change}


def test_the_score_is_the_economy_less_each_target_missed():
    assert score(_figures()) == (3.0, 3.0)
    assert score(_figures(collisions=1))[0] == pytest.approx(-47.0)
    assert score(_figures(time_gap_p10_s=0.5))[0] == pytest.approx(-2.0)
    assert score(_figures(time_gap_p90_s=5.0))[0] == pytest.approx(-17.0)
    assert score(_figures(min_ttc_s=4.0))[0] == pytest.approx(1.0)
    assert score(_figures(jerk_rms_mps3=0.8))[0] == pytest.approx(0.0)
    assert score(_figures(safety_pct=1.0))[0] == pytest.approx(1.0)


def test_a_training_may_ask_for_a_margin_under_the_time_gap_target():
    """A lower time_gap_p90_max penalises a run inside the 4 s target; the default
    settings still resume trainings made before the setting existed."""
    from twin.control.evolve import _settings

    assert score(_figures(time_gap_p90_s=3.8), 3.5)[0] == pytest.approx(3.0 - 20.0 * 0.3)
    assert score(_figures(time_gap_p90_s=3.8))[0] == pytest.approx(3.0)
    assert "time_gap_p90_max" not in _settings(EvolveConfig())
    assert _settings(EvolveConfig(time_gap_p90_max=3.5))["time_gap_p90_max"] == 3.5
    with pytest.raises(TrainingError, match="time_gap_p90_max must be a positive number"):
        EvolveConfig(time_gap_p90_max=float("nan"))


def test_centred_ranks_span_minus_to_plus_a_half_and_nan_ranks_lowest():
    assert centred_ranks(np.array([3.0, -1.0, 10.0])).tolist() == [0.0, -0.5, 0.5]
    assert centred_ranks(np.array([3.0, np.nan, -1.0])).tolist() == [0.5, -0.5, 0.0]


def test_a_damaged_checkpoint_is_named(tmp_path):
    from twin.control.evolve import _resume, _settings

    (tmp_path / "checkpoint.npz").write_bytes(b"PK\x03\x04 half a file")
    with pytest.raises(TrainingError, match="is damaged"):
        _resume(tmp_path, _settings(EvolveConfig()))


@pytest.mark.parametrize(
    "settings, message",
    [({"population": 0}, "population"), ({"sigma": -1.0}, "sigma"), ({"hidden": (0,)}, "hidden"),
     ({"weight_decay": float("nan")}, "weight_decay"), ({"smoothing": -1.0}, "smoothing"),
     ({"jerk_from": "guess"}, "jerk_from")],
)  # fmt: skip
def test_bad_settings_are_named(settings, message):
    with pytest.raises(TrainingError, match=message):
        EvolveConfig(**settings)


def _config(data, generations):
    return EvolveConfig(
        generations=generations, population=2, episodes=1, duration=3.0, hidden=(4,),
        heldout_every=2, heldout_episodes=2, data=data, seed=5, obs_noise=0.05,
    )  # fmt: skip


def test_an_interrupted_training_resumes_to_the_same_weights(calibrated_wave_store, tmp_path):
    data = str(calibrated_wave_store.path)
    whole = evolve(tmp_path / "whole", _config(data, 2), progress=False)
    first = evolve(tmp_path / "cut", _config(data, 1), progress=False)  # stopped after one
    assert not np.array_equal(first.weights, whole.weights)
    resumed = evolve(tmp_path / "cut", _config(data, 2), progress=False)
    assert np.array_equal(whole.weights, resumed.weights)
    assert np.array_equal(MLPPolicy.load(tmp_path / "cut" / "policy.json").weights, whole.weights)
    for name in ("policy.json", "curve.csv", "curve.png", "checkpoint.npz"):
        assert (tmp_path / "whole" / name).is_file()
    rows = [r.split(",") for r in (tmp_path / "whole" / "curve.csv").read_text().splitlines()]
    assert rows[0][:3] == ["generation", "env_steps", "wall_s"]
    assert [r[0] for r in rows[1:]] == ["1", "2"] and rows[2][6] != ""  # held out at the last
    cut = [r.split(",") for r in (tmp_path / "cut" / "curve.csv").read_text().splitlines()]
    assert [r[:2] for r in cut] == [r[:2] for r in rows]
    other = EvolveConfig(**{**_config(data, 3).__dict__, "seed": 6})
    with pytest.raises(TrainingError, match="other settings"):
        evolve(tmp_path / "whole", other, progress=False)


def test_twin_train_algorithm_es_from_the_command_line(calibrated_wave_store, tmp_path, capsys):
    from twin.cli import main

    args = ["train", "--algorithm", "es", "--data", str(calibrated_wave_store.path),
            "--generations", "1", "--population", "1", "--episodes", "1", "--duration", "2",
            "--hidden", "4", "--heldout-episodes", "1", "--out", str(tmp_path / "es")]  # fmt: skip
    assert main(args) == 0
    policy = MLPPolicy.load(tmp_path / "es" / "policy.json")
    assert policy.hidden == (4,) and policy.about["config"]["data"] == str(
        calibrated_wave_store.path
    )
    assert "generation 1/1" in capsys.readouterr().out
    assert main([*args[:-2], "--hidden", "4,x", "--out", str(tmp_path / "bad")]) != 0
    assert "--hidden" in capsys.readouterr().err
    missing = str(tmp_path / "no_such_morning")
    assert main([*args[:-2], "--also-data", missing, "--out", str(tmp_path / "bad")]) != 0
    assert "--also-data" in (err := capsys.readouterr().err) and "no_such_morning" in err
    assert main(["train", "--also-data", missing, "--out", str(tmp_path / "bad")]) != 0
    assert "--algorithm es" in capsys.readouterr().err


def test_a_training_starts_from_a_policy_files_weights(calibrated_wave_store, tmp_path):
    from twin.control.evolve import _fresh

    data = str(calibrated_wave_store.path)
    start = MLPPolicy(np.random.default_rng(1).standard_normal(n_weights((4,))), (4,))
    path = start.save(tmp_path / "start.json")
    config = EvolveConfig(hidden=(4,), data=data, start=path, smoothing=2.0, jerk_from="command")
    assert np.array_equal(_fresh(config)["theta"], start.weights)
    policy = evolve(tmp_path / "out", EvolveConfig(**{**_config(data, 1).__dict__,
                    "start": str(path), "smoothing": 2.0, "jerk_from": "command"}),
                    progress=False)  # fmt: skip
    assert (policy.smoothing, policy.jerk_from) == (2.0, "command")
    assert not np.array_equal(policy.weights, start.weights)  # one generation on from it
    saved = MLPPolicy.load(tmp_path / "out" / "policy.json")
    assert (saved.smoothing, saved.jerk_from) == (2.0, "command")
    with pytest.raises(TrainingError, match="hidden layers"):
        _fresh(EvolveConfig(hidden=(8,), data=data, start=path))
    with pytest.raises(TrainingError, match="--start"):
        _fresh(EvolveConfig(hidden=(4,), data=data, start=tmp_path / "missing.json"))


def test_a_training_from_a_file_resumes_by_its_weights_not_its_path(tmp_path, monkeypatch):
    import shutil

    from twin.control.evolve import _identity, _resume, _save

    start = MLPPolicy(np.random.default_rng(2).standard_normal(n_weights((4,))), (4,))
    path = start.save(tmp_path / "start.json")
    config = EvolveConfig(hidden=(4,), start=path)
    theta = start.weights
    rng = np.random.default_rng(0)
    _save(tmp_path, _identity(config), theta, theta, theta, 3, rng, [])
    monkeypatch.chdir(tmp_path)  # the same file, named relative to another folder
    assert _resume(tmp_path, _identity(EvolveConfig(hidden=(4,), start="start.json")))
    shutil.copy(path, tmp_path / "copy.json")  # or copied
    assert (
        _resume(tmp_path, _identity(EvolveConfig(hidden=(4,), start="copy.json")))["generation"]
        == 3
    )
    other = MLPPolicy(start.weights + 1.0, (4,)).save(tmp_path / "other.json")
    with pytest.raises(TrainingError, match="other settings \\(start_sha256\\)"):
        _resume(tmp_path, _identity(EvolveConfig(hidden=(4,), start=other)))
    with pytest.raises(TrainingError, match="start_sha256"):  # from scratch: another
        _resume(tmp_path, _identity(EvolveConfig(hidden=(4,))))


def test_a_checkpoint_that_named_its_start_by_path_resumes_with_that_file(tmp_path):
    from twin.control.evolve import _identity, _resume, _save, _settings

    start = MLPPolicy(np.random.default_rng(3).standard_normal(n_weights((4,))), (4,))
    path = start.save(tmp_path / "start.json")
    config = EvolveConfig(hidden=(4,), start=path)
    old = _settings(config)  # as checkpoints were written before start_sha256
    old.pop("also")
    theta = start.weights
    _save(tmp_path, old, theta, theta, theta, 2, np.random.default_rng(0), [])
    assert _resume(tmp_path, _identity(config), config.start)["generation"] == 2
    other = MLPPolicy(start.weights + 1.0, (4,)).save(tmp_path / "other.json")
    moved = EvolveConfig(hidden=(4,), start=other)
    with pytest.raises(TrainingError, match="start_sha256"):
        _resume(tmp_path, _identity(moved), moved.start)


def test_the_runs_are_member_by_member_each_members_episodes_morning_by_morning():
    import twin.control.evolve as evolve_module

    class Env:
        def __init__(self, morning):
            self.morning = morning

    def fake(env, thetas, episodes, actor, seed):
        return [{"member": float(t[0]), "morning": env.morning, "episode": e}
                for t, e in zip(thetas, episodes, strict=True)]  # fmt: skip

    config = EvolveConfig(population=2, episodes=3, also=("elsewhere",))
    members = np.arange(4, dtype=float)[:, None] * np.ones((4, 3))
    drawn = [[10, 11], [20]]  # morning 0 gives 2 episodes, morning 1 one
    envs = {("train", 0): Env(0), ("train", 1): Env(1)}
    original = evolve_module.rollout
    evolve_module.rollout = fake
    try:
        runs = evolve_module._train_runs(envs, members, drawn, config)
    finally:
        evolve_module.rollout = original
    assert [(r["member"], r["morning"], r["episode"]) for r in runs] == [
        (i, k, e) for i in range(4) for k, e in ((0, 10), (0, 11), (1, 20))
    ]


def test_a_training_deals_its_episodes_over_other_mornings(
    calibrated_wave_store, tmp_path, monkeypatch
):
    import twin.control.evolve as evolve_module

    data = str(calibrated_wave_store.path)
    import shutil

    other = tmp_path / "other_morning"  # a copy stands for another morning
    shutil.copytree(calibrated_wave_store.path, other)
    link = tmp_path / "link"
    link.symlink_to(calibrated_wave_store.path, target_is_directory=True)
    config = EvolveConfig(**{**_config(data, 1).__dict__, "episodes": 3, "also": (str(other),)})
    assert config.mornings == (data, str(other)) and config.per_morning() == [2, 1]
    seen = []
    rollout = evolve_module.rollout

    def spy(env, thetas, episodes, actor, seed):
        seen.append((env.num_envs, len(episodes)))
        return rollout(env, thetas, episodes, actor, seed)

    monkeypatch.setattr(evolve_module, "rollout", spy)
    policy = evolve(tmp_path / "out", config, progress=False)
    # held out (human, then the policy) on data's 2 episodes; training: 2 pairs x 2
    # episodes on data's vector env, 2 pairs x 1 on the other's
    assert sorted(seen) == sorted([(2, 2), (8, 8), (4, 4), (2, 2)])
    assert policy.about["config"]["also"] == [str(other)]
    assert policy.about["env_steps"] == 4 * 3 * 30
    with pytest.raises(TrainingError, match="at least one per morning"):
        EvolveConfig(episodes=1, also=("elsewhere",))
    with pytest.raises(TrainingError, match="named twice"):
        EvolveConfig(data="a", also=("a",))
    with pytest.raises(TrainingError, match="named twice"):  # the same store by a link
        EvolveConfig(data=data, episodes=2, also=(str(link),))
    with pytest.raises(TrainingError, match="list of stores"):
        EvolveConfig(also="elsewhere")
