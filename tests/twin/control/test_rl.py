"""``twin.control.rl``: a trained policy drives the twin's ego seeing what the env's agent saw;
the PPO example of docs/control.md (where the ``rl`` extra is installed)."""

import json

import numpy as np
import pytest

from twin.cli import main
from twin.control.env import OBS_HIGH, OBS_LOW, WaveDampeningEnv
from twin.control.rl import PolicyController
from twin.core.errors import ControllerError
from twin.cosim.cosimulator import Cosimulator


@pytest.fixture(scope="module")
def data(calibrated_wave_store) -> str:
    return str(calibrated_wave_store.path)


class Recorder:
    """stable-baselines3's ``predict`` interface: a fixed action; keeps what it saw."""

    def __init__(self, action: float):
        self.action, self.seen = action, []

    def predict(self, observation, deterministic=False):
        assert deterministic
        self.seen.append(np.array(observation))
        return np.array([self.action], np.float32), None


def test_a_policy_in_the_twin_sees_what_the_envs_agent_saw(data):
    """The same episode twice: the env stepped with a fixed action, and the cosimulator
    with a PolicyController giving it. Observations agree to within one physics step."""
    env = WaveDampeningEnv(data, duration=6.0)
    obs, _ = env.reset(seed=2)
    trained = [obs]
    done = False
    while not done:
        obs, _, terminated, truncated, _ = env.step(np.array([0.1], np.float32))
        trained.append(obs)
        done = terminated or truncated
    assert truncated and len(trained) == 61
    config = env.episode_config()
    env.close()

    model = Recorder(0.1)
    with Cosimulator(config, env.traffic, env.bundle, controller=PolicyController(model)) as sim:
        sim.run()
    seen = np.array(model.seen)
    assert len(seen) == 60  # one decision each 0.1 s of the 6 s
    assert np.all((seen >= OBS_LOW) & (seen <= OBS_HIGH))
    # the env observes after each 0.1 s; the controller at the next decision: compare the
    # speeds, gaps and recorded speeds ahead (not the acceleration: the env's is measured
    # over the last physics step before its observation, a step apart)
    env_obs, ctl_obs = np.array(trained[1:-1]), seen[1:]
    columns = [0, 2, 3, 4, 5, *range(6, 18)]
    # (measured: within 0.01 m and m/s, the recorded speeds ahead within 0.25 m/s)
    np.testing.assert_allclose(ctl_obs[:, columns], env_obs[:, columns], atol=0.3)


def test_without_a_model_the_shipped_policy_drives_and_missing_models_are_named(
    data, tmp_path, capsys
):
    args = ["run", "--data", data, "--road", "westbound", "--duration", "2", "--out",
            str(tmp_path / "run"), "--quiet", "--ego-controller", "twin.rl:policy"]  # fmt: skip
    assert main(args) == 0
    capsys.readouterr()
    missing = [*args, "--set", f"controller.policy.model={tmp_path / 'none.zip'}"]
    assert main(missing) == 2
    assert "no policy model at" in capsys.readouterr().err
    missing = [*args, "--set", f"controller.policy.model={tmp_path / 'none.json'}"]
    assert main(missing) == 2
    assert "no policy file at" in capsys.readouterr().err


def test_a_policy_that_returns_nan_stops_the_run(data):
    env = WaveDampeningEnv(data, duration=2.0)
    env.reset(seed=2)
    config = env.episode_config()
    env.close()
    controller = PolicyController(Recorder(float("nan")))
    sim = Cosimulator(config, env.traffic, env.bundle, controller=controller)
    with sim, pytest.raises(ControllerError, match="non-finite action"):
        sim.run()


@pytest.mark.slow
def test_the_readme_ppo_example_trains_and_evaluates(data, tmp_path):
    """docs/control.md's example, shortened: PPO for 128 steps, then twin eval against human
    on held-out episodes."""
    pytest.importorskip("stable_baselines3", reason="the rl extra is not installed")
    from twin.control.rl import train_ppo

    model = train_ppo(tmp_path / "ppo_wave", steps=128, n_steps=64, data=data, duration=6.0)
    assert model.name == "ppo_wave.zip" and model.is_file()
    out = tmp_path / "eval"
    args = ["eval", "--data", data, "--episodes", "1", "--duration", "6", "--workers", "1",
            "--controller", "human,twin.rl:policy", "--set",
            f"controller.policy.model={model}", "--out", str(out), "--quiet"]  # fmt: skip
    assert main(args) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary["controllers"]) == {"human", "policy"}
