"""The batched vector env (``gymnasium.make_vec(..., vectorization_mode="vector_entry_point")``):
the single env's spaces, its sub-envs the single env with the seed s + i, an episode's
steps the same bytes at any place in a batch of any size, Gymnasium's next-step
autoreset, bad actions named, and Gymnasium's own vector wrappers on it."""

import gymnasium as gym
import numpy as np
import pytest

import twin.env  # registers the environments
from twin.control.vector_env import VectorWaveDampeningEnv

STEPS = 25


@pytest.fixture(scope="module")
def data(calibrated_wave_store) -> str:
    return str(calibrated_wave_store.path)


def _vector(data, n, **settings):
    return gym.make_vec(
        twin.env.ENV_ID, num_envs=n, vectorization_mode="vector_entry_point", data=data,
        world="kinematic", duration=settings.pop("duration", 6.0), **settings,
    )  # fmt: skip


def _actions(k: int, n: int) -> np.ndarray:
    """A different action per sub-env and step, inside the Box."""
    return np.array([[np.sin(0.3 * k + i) * 1.2] for i in range(n)], np.float32)


def _trace(env, n, seed, steps=STEPS, columns=None):
    obs, _ = env.reset(seed=seed)
    rows = [obs]
    for k in range(steps):
        actions = _actions(k, n) if columns is None else _actions(k, max(columns) + 1)[columns]
        obs, reward, terminated, truncated, _ = env.step(actions)
        rows.append(np.c_[obs.astype(np.float64), reward, terminated, truncated])
    return rows


def test_make_vec_gives_the_batched_env_with_the_single_envs_spaces(data):
    envs = _vector(data, 3)
    single = gym.make(twin.env.ENV_ID, data=data, world="kinematic", duration=6.0)
    assert isinstance(envs.unwrapped, VectorWaveDampeningEnv)
    assert envs.single_observation_space == single.observation_space
    assert envs.single_action_space == single.action_space
    obs, info = envs.reset(seed=0)
    assert obs.shape == (3, len(twin.env.OBSERVATION)) and obs.dtype == np.float32
    assert envs.observation_space.contains(obs) and info["episode"].shape == (3,)
    envs.close()
    single.close()


def test_sub_env_i_is_the_single_env_with_seed_s_plus_i(data):
    envs = _vector(data, 3)
    batched = _trace(envs, 3, seed=11)
    envs.close()
    for i in range(3):
        single = gym.make(twin.env.ENV_ID, data=data, world="kinematic", duration=6.0)
        obs, _ = single.reset(seed=11 + i)
        np.testing.assert_array_equal(obs, batched[0][i])
        for k in range(STEPS):
            obs, reward, terminated, truncated, _ = single.step(_actions(k, 3)[i])
            row = np.r_[obs.astype(np.float64), reward, terminated, truncated]
            assert row.tobytes() == batched[k + 1][i].tobytes()
        single.close()


def test_an_episode_is_the_same_bytes_at_any_place_in_a_batch_of_any_size(data):
    """Sub-env seeds [9], [5, 9] and [7, 8, 9, 2]: seed 9's episode byte for byte."""
    alone = _vector(data, 1)
    reference = _trace(alone, 1, seed=[9], columns=[0])
    alone.close()
    for seeds, place in (([5, 9], 1), ([7, 8, 9, 2], 2)):
        envs = _vector(data, len(seeds))
        obs, _ = envs.reset(seed=seeds)
        assert obs[place].tobytes() == reference[0][0].tobytes()
        for k in range(STEPS):
            actions = np.repeat(_actions(k, 1), len(seeds), axis=0)
            obs, reward, terminated, truncated, _ = envs.step(actions)
            row = np.c_[obs.astype(np.float64), reward, terminated, truncated][place]
            assert row.tobytes() == reference[k + 1][0].tobytes()
        envs.close()


def test_the_next_step_after_an_episode_ends_resets_that_sub_env(data):
    envs = _vector(data, 2, duration=2.0)  # 20 control steps
    envs.reset(seed=3)
    for _ in range(20):
        obs, reward, terminated, truncated, info = envs.step(np.zeros((2, 1), np.float32))
    assert truncated.all() and not terminated.any()
    assert info["_metrics"].all() and np.all(info["metrics"]["simulated_s"] == 2.0)
    obs, reward, terminated, truncated, info = envs.step(np.zeros((2, 1), np.float32))
    assert not (terminated | truncated).any() and np.all(reward == 0.0)  # the new episodes
    assert "metrics" not in info
    obs, reward, *_ = envs.step(np.zeros((2, 1), np.float32))
    assert np.all(reward < 0.0)  # they run: fuel is burnt
    envs.close()


def test_a_nan_or_infinite_action_names_the_sub_env_an_out_of_range_one_is_clipped(data):
    envs = _vector(data, 3)
    envs.reset(seed=0)
    with pytest.raises(ValueError, match=r"sub-env 2: the action inf is not a finite number"):
        envs.step(np.array([[0.0], [0.0], [np.inf]], np.float32))
    obs, *_ = envs.step(np.array([[99.0], [-99.0], [0.0]], np.float32))  # the Box's ends
    assert np.isfinite(obs).all()
    envs.close()


def test_the_physics_world_is_refused_with_what_to_use_instead(data):
    with pytest.raises(ValueError, match="AsyncVectorEnv"):
        VectorWaveDampeningEnv(2, data, world="physics")


def test_gymnasiums_vector_wrappers_run_on_it(data):
    """A standard training loop's plumbing: episode statistics and normalised
    observations from Gymnasium's own vector wrappers."""
    envs = gym.wrappers.vector.RecordEpisodeStatistics(_vector(data, 2, duration=2.0))
    envs = gym.wrappers.vector.NormalizeObservation(envs)
    envs.reset(seed=1)
    returns = []
    for _ in range(22):
        _, _, terminated, truncated, info = envs.step(envs.action_space.sample() * 0)
        if "episode" in info:
            returns.extend(info["episode"]["r"][info["_episode"]])
    assert len(returns) == 2 and all(r < 0 for r in returns)
    envs.close()
