"""``i24twin/WaveDampening-v0``: Gymnasium's checker, determinism, the vector env, the
train/test split, termination on a collision, bad settings named."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import twin.env  # registers the environment
from twin.control.env import OBSERVATION, WaveDampeningEnv
from twin.core.errors import TwinError


@pytest.fixture(scope="module")
def data(calibrated_wave_store) -> str:
    return str(calibrated_wave_store.path)


def _env(data, **settings):
    return gym.make(twin.env.ENV_ID, data=data, duration=settings.pop("duration", 6.0), **settings)


def test_the_environment_passes_gymnasiums_checker(data):
    env = _env(data)
    check_env(env.unwrapped, skip_render_check=True)
    obs, info = env.reset(seed=0)
    assert obs.shape == (len(OBSERVATION),) and obs.dtype == np.float32
    assert env.observation_space.contains(obs) and "ego_record_id" in info
    env.close()


@pytest.mark.parametrize("world", ["physics", "kinematic"])
def test_same_seed_same_episode_bit_for_bit(data, world):
    runs = []
    for _ in range(2):
        env = _env(data, world=world)
        obs, _ = env.reset(seed=7)
        trace = [obs]
        for k in range(15):
            obs, reward, *_ = env.step(np.array([0.5 if k % 2 else -1.0], np.float32))
            trace.append(np.r_[obs, reward])
        runs.append(np.concatenate(trace))
        env.close()
    np.testing.assert_array_equal(runs[0], runs[1])


@pytest.mark.parametrize("world", ["physics", "kinematic"])
def test_an_episode_ends_truncated_with_the_benchmarks_metrics(data, world):
    env = _env(data, split="test", world=world)
    env.reset(seed=1)
    assert env.unwrapped.cosim.world == world
    split = 0.5 * sum(env.unwrapped.store.time_range("westbound"))
    assert env.unwrapped.t0 >= split  # test episodes lie after the split
    steps, done = 0, False
    while not done:
        _, reward, terminated, truncated, info = env.step(np.array([0.0], np.float32))
        steps += 1
        done = terminated or truncated
    assert truncated and not terminated and steps == 60  # 6 s at 10 Hz
    assert info["metrics"]["ego_and_followers_mpg"] is not None
    assert np.isfinite(reward) and reward < 0  # fuel is burnt
    assert 0 < info["fuel_g"] <= -reward  # the step's fuel, the reward's main term
    env.close()


@pytest.mark.parametrize("world", ["physics", "kinematic"])
def test_ramming_the_leader_terminates_the_episode(data, world):
    env = _env(data, duration=60.0, world=world)
    env.reset(seed=2)
    terminated = truncated = False
    while not (terminated or truncated):
        *_, terminated, truncated, info = env.step(np.array([1.5], np.float32))
    assert terminated and info["metrics"]["collisions"] >= 1
    env.close()


def test_the_vector_env_runs_one_env_per_process(data):
    envs = gym.vector.AsyncVectorEnv([lambda: _env(data), lambda: _env(data)])
    obs, _ = envs.reset(seed=[0, 1])
    assert obs.shape == (2, len(OBSERVATION))
    for _ in range(3):
        obs, reward, *_ = envs.step(np.zeros((2, 1), np.float32))
    assert np.isfinite(obs).all() and reward.shape == (2,)
    envs.close()


def test_bad_settings_are_named(data):
    with pytest.raises(ValueError, match="split must be"):
        WaveDampeningEnv(data, split="validation")
    with pytest.raises(ValueError, match="action must be"):
        WaveDampeningEnv(data, action="steer")
    with pytest.raises(ValueError, match="split_time"):
        WaveDampeningEnv(data, split_time=0.0)
    with pytest.raises(TwinError, match="world must be one of physics, kinematic"):
        WaveDampeningEnv(data, world="mujoco")
    env = _env(data)
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"sub-env 0: the action nan is not a finite number"):
        env.step(np.array([np.nan], np.float32))
    env.close()


def test_the_package_declares_its_environments_entry_point():
    from importlib.metadata import entry_points

    (point,) = [e for e in entry_points(group="gymnasium.envs") if e.name == "i24twin"]
    point.load()()  # registering twice is harmless
    assert twin.env.ENV_ID in gym.registry


@pytest.mark.parametrize("world", ["physics", "kinematic"])
def test_with_the_speed_action_the_ego_holds_its_speed_until_the_agent_acts(data, world):
    env = _env(data, action="speed", world=world)
    first, _ = env.reset(seed=3)
    spawned = float(first[0])  # the ego's speed: spawned at its recorded one
    obs, *_ = env.step(np.array([spawned], np.float32))
    assert obs[0] == pytest.approx(spawned, abs=0.1)  # not braked at -3 m/s^2 first
    env.close()
