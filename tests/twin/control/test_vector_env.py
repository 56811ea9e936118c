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
        _obs, reward, terminated, truncated, info = envs.step(np.zeros((2, 1), np.float32))
    assert truncated.all() and not terminated.any()
    assert info["_metrics"].all() and np.all(info["metrics"]["simulated_s"] == 2.0)
    _obs, reward, terminated, truncated, info = envs.step(np.zeros((2, 1), np.float32))
    assert not (terminated | truncated).any() and np.all(reward == 0.0)  # the new episodes
    assert "metrics" not in info
    _, reward, *_ = envs.step(np.zeros((2, 1), np.float32))
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
        *_, info = envs.step(envs.action_space.sample() * 0)
        if "episode" in info:
            returns.extend(info["episode"]["r"][info["_episode"]])
    assert len(returns) == 2 and all(r < 0 for r in returns)
    envs.close()


def _single_through_two_episodes(data, seed, steps, **settings):
    """The single env with ``seed``: its observations over ``steps`` steps, reset
    (without a seed) where its episode ends, as an agent's loop does."""
    single = gym.make(twin.env.ENV_ID, data=data, world="kinematic", duration=2.0, **settings)
    obs, _ = single.reset(seed=seed)
    seen, finals = [obs], {}
    for k in range(steps):
        obs, _, terminated, truncated, _ = single.step(_actions(k, 1)[0])
        if terminated or truncated:
            finals[k] = obs
            obs, _ = single.reset()
        seen.append(obs)
    single.close()
    return seen, finals


@pytest.mark.parametrize("settings", [{}, {"latency_steps": 2, "obs_noise": 0.05}])
def test_same_step_autoreset_gives_the_new_episode_and_the_last_observation(data, settings):
    """autoreset_mode="same_step": the step that ends an episode returns the next
    episode's first observation and the ended one's last in info["final_obs"]: sub-env i
    is still the single env with seed s + i, latency and noise included."""
    envs = VectorWaveDampeningEnv(2, data, duration=2.0, autoreset_mode="same_step", **settings)
    assert envs.metadata["autoreset_mode"] == gym.vector.AutoresetMode.SAME_STEP
    obs, _ = envs.reset(seed=4)
    rows, finals = [obs], {}
    for k in range(26):
        obs, reward, terminated, truncated, info = envs.step(np.repeat(_actions(k, 1), 2, 0))
        if "final_obs" in info:
            assert info["_final_obs"].all() and truncated.all() and not terminated.any()
            assert np.all(reward < 0)
            finals[k] = np.stack(info["final_obs"])
        rows.append(obs)
    envs.close()
    for i in range(2):
        seen, single_finals = _single_through_two_episodes(data, 4 + i, 26, **settings)
        assert sorted(finals) == sorted(single_finals) == [19]
        assert finals[19][i].tobytes() == single_finals[19].tobytes()
        for k, obs in enumerate(seen):
            assert rows[k][i].tobytes() == obs.tobytes(), k


def test_next_step_autoreset_keeps_latency_and_noise_per_sub_env(data):
    settings = {"latency_steps": 2, "obs_noise": 0.05}
    envs = VectorWaveDampeningEnv(2, data, duration=2.0, **settings)
    obs, _ = envs.reset(seed=6)
    rows = [obs]
    for k in range(27):
        j = k if k < 20 else k - 1  # the step after the end resets: no action taken
        obs, *_ = envs.step(np.repeat(_actions(j, 1), 2, 0))
        rows.append(obs)
    envs.close()
    for i in range(2):
        seen, finals = _single_through_two_episodes(data, 6 + i, 26, **settings)
        assert rows[20][i].tobytes() == finals[19].tobytes()  # the ended episode's last
        vector = rows[:20] + rows[21:]  # then the reset step shows what reset gave
        for k, obs in enumerate(seen):
            assert vector[k][i].tobytes() == obs.tobytes(), k


def test_stable_baselines3_trains_on_it(data, tmp_path):
    """The adapter (twin.control.sb3_vec_env): PPO's rollouts from the batched env, the
    ended episodes' last observations and time limits handed over as SB3 expects."""
    pytest.importorskip("stable_baselines3", reason="the rl extra is not installed")
    from stable_baselines3 import PPO

    from twin.control.rl import train_ppo
    from twin.control.sb3_vec_env import Sb3VecEnv

    envs = Sb3VecEnv(2, data=data, duration=2.0, seed=3)
    envs.seed(3)
    first = envs.reset()
    assert first.shape == (2, len(twin.env.OBSERVATION))
    for _ in range(20):
        obs, reward, done, infos = envs.step(np.zeros((2, 1), np.float32))
    assert done.all() and reward.dtype == np.float32
    assert all(info["TimeLimit.truncated"] for info in infos)
    assert all(info["terminal_observation"].shape == first.shape[1:] for info in infos)
    assert all(info["metrics"]["simulated_s"] == 2.0 for info in infos)
    assert not np.array_equal(obs, np.stack([i["terminal_observation"] for i in infos]))
    model = PPO("MlpPolicy", envs, n_steps=16, batch_size=32, seed=0, device="cpu")
    model.learn(total_timesteps=64)
    envs.close()
    saved = train_ppo(tmp_path / "ppo", steps=64, n_steps=16, data=data, duration=2.0,
                      num_envs=4)  # fmt: skip
    assert saved.is_file()


def test_with_the_safety_layer_an_agent_that_only_accelerates_is_held_back(data):
    # full throttle for 20 s: without the safety layer the AV runs into its leader (or
    # its followers brake for nothing); with it, the drivers' emergency braking steps
    # in, counted in safety_override_s, and it does not collide
    figures = {}
    for safety in (False, True):
        envs = VectorWaveDampeningEnv(2, data, duration=20.0, safety=safety, seed=2)
        envs.reset(seed=2)
        metrics = None
        for _ in range(200):
            _, _, terminated, truncated, info = envs.step(np.full((2, 1), 1.5, np.float32))
            if "metrics" in info:
                metrics = metrics or info["metrics"]
            if (terminated | truncated).all():
                break
        envs.close()
        figures[safety] = metrics
    assert np.nansum(figures[False]["safety_override_s"]) == 0.0
    assert np.nansum(figures[True]["safety_override_s"]) > 0.0
    assert np.nansum(figures[True]["collisions"]) == 0


def test_with_ego_human_the_actions_are_ignored_the_driver_drives(data):
    runs = []
    for throttle in (1.5, -3.0):
        envs = VectorWaveDampeningEnv(2, data, duration=3.0, ego="human", seed=4)
        obs, _ = envs.reset(seed=4)
        rows = [obs]
        for _ in range(20):
            obs, *_ = envs.step(np.full((2, 1), throttle, np.float32))
            rows.append(obs)
        envs.close()
        runs.append(np.array(rows))
    assert np.array_equal(runs[0], runs[1])
    with pytest.raises(ValueError, match="ego must be"):
        VectorWaveDampeningEnv(1, data, duration=3.0, ego="robot")
