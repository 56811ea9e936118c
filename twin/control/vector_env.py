"""``i24twin/WaveDampening-v0`` as a batched Gymnasium vector env: N episodes of the
kinematic world stepped in one kernel call of the batched core (:mod:`twin.control.engine`),
with the single env's spaces, observation, reward and metrics
(:mod:`twin.control.env`).

::

    import gymnasium, twin.env
    envs = gymnasium.make_vec("i24twin/WaveDampening-v0", num_envs=256,
                              vectorization_mode="vector_entry_point", world="kinematic")
    obs, info = envs.reset(seed=0)          # sub-env i draws its episodes from seed 0 + i
    obs, reward, terminated, truncated, info = envs.step(actions)   # actions (256, 1)

Gymnasium's next-step autoreset by default: the step after an episode ended resets
that sub-env (its observation is the new episode's first, its reward 0, neither flag
set) while the others step. With ``autoreset_mode="same_step"`` the step that ends an
episode resets it at once: its observation is the new episode's first, and the ended
episode's last is ``info["final_obs"]`` (masked by ``info["_final_obs"]``), the loop
stable-baselines3 and most RL libraries expect (:class:`twin.control.rl.Sb3VecEnv`).
At an episode's end ``info["metrics"]`` holds each sub-env's figures (a dict of (N,)
arrays, the sub-envs that did not end masked out by ``info["_metrics"]``).

Sub-env i is the single env with the seed ``s + i``: the same episodes, and an episode's
steps are the same bytes alone or at any place in a batch of any size.
"""

from typing import ClassVar

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from twin.control.engine import check_actions, noisy
from twin.control.env import OBS_HIGH, OBS_LOW, SCENARIO_B, EnvSetup


class VectorWaveDampeningEnv(VectorEnv):
    """``num_envs`` episodes of the wave-dampening env stepped together (module doc).

    Args:
        num_envs: N.
        world: must be ``kinematic`` (the physics world runs one episode at a time: use
            ``gymnasium.vector.AsyncVectorEnv`` of single envs there).
        autoreset_mode: ``"next_step"`` (default) or ``"same_step"`` (module doc).
        data: as :class:`~twin.control.env.WaveDampeningEnv`'s.
        split: as :class:`~twin.control.env.WaveDampeningEnv`'s.
        split_time: as :class:`~twin.control.env.WaveDampeningEnv`'s.
        duration: as :class:`~twin.control.env.WaveDampeningEnv`'s.
        action: as :class:`~twin.control.env.WaveDampeningEnv`'s.
        reward: as :class:`~twin.control.env.WaveDampeningEnv`'s.
        obs_noise: as :class:`~twin.control.env.WaveDampeningEnv`'s.
        latency_steps: as :class:`~twin.control.env.WaveDampeningEnv`'s.
        cosim: as :class:`~twin.control.env.WaveDampeningEnv`'s.
        seed: as :class:`~twin.control.env.WaveDampeningEnv`'s.
        safety: as :class:`~twin.control.env.WaveDampeningEnv`'s.
        ego: ``agent`` (the actions drive it) or ``human``: it drives as
            ``twin.controllers:human`` and the actions are ignored, the baseline of the
            same episodes for paired figures.

    Raises:
        ValueError: a setting is impossible (named).
    """

    metadata: ClassVar[dict] = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}

    def __init__(self, num_envs: int = 1, data: str | None = None, *, split="train",
                 split_time=None, duration=120.0, action="accel", reward=None, obs_noise=0.0,
                 latency_steps=0, cosim=SCENARIO_B, world: str | None = "kinematic",
                 seed=0, autoreset_mode: str = "next_step", safety=False,
                 ego: str = "agent"):  # fmt: skip
        if not (isinstance(num_envs, int) and num_envs >= 1):
            raise ValueError(f"num_envs must be an integer >= 1, got {num_envs!r}")
        modes = {"next_step": AutoresetMode.NEXT_STEP, "same_step": AutoresetMode.SAME_STEP}
        mode = modes.get(getattr(autoreset_mode, "value", autoreset_mode))
        if mode is None:
            raise ValueError(
                f"autoreset_mode must be 'next_step' or 'same_step', got {autoreset_mode!r}"
            )
        self.metadata = {**self.metadata, "autoreset_mode": mode}
        self._same_step = mode == AutoresetMode.SAME_STEP
        setup = EnvSetup.make(
            data, split=split, split_time=split_time, duration=duration, action=action,
            reward=reward, obs_noise=obs_noise, latency_steps=latency_steps, cosim=cosim,
            world=world, seed=seed, safety=safety,
        )  # fmt: skip
        if setup.cosim.world != "kinematic":
            raise ValueError(
                "the vector env steps the kinematic world (world='kinematic'); for the "
                "physics world use gymnasium.vector.AsyncVectorEnv of single envs"
            )
        self.setup = setup
        self.num_envs = num_envs
        self.obs_noise, self.latency_steps = obs_noise, latency_steps
        self.single_action_space = setup.action_space()
        self.single_observation_space = gym.spaces.Box(OBS_LOW, OBS_HIGH, dtype=np.float32)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        if ego not in ("agent", "human"):
            raise ValueError(f"ego must be 'agent' or 'human', got {ego!r}")
        self.episodes = setup.episodes(num_envs, human=ego == "human")
        self._rngs = [np.random.default_rng(seed + i) for i in range(num_envs)]
        self._ended = np.zeros(num_envs, dtype=bool)  # done at the last step: reset next
        # the observations of the last latency_steps + 1 control steps, oldest first
        self._history = np.zeros((latency_steps + 1, num_envs, len(OBS_LOW)), np.float32)

    def reset(self, *, seed=None, options: dict | None = None):
        """Every sub-env starts a new episode: with ``seed`` (an int), sub-env i draws
        from ``seed + i`` (a list gives each its own); ``options={"episode": [...]}``
        picks them."""
        if seed is not None:
            seeds = (
                seed
                if isinstance(seed, list | tuple | np.ndarray)
                else [seed + i for i in range(self.num_envs)]
            )
            if len(seeds) != self.num_envs:
                raise ValueError(f"{len(seeds)} seeds for {self.num_envs} sub-envs")
            self._rngs = [np.random.default_rng(int(s)) for s in seeds]
        chosen = (options or {}).get("episode")
        episodes = self.episodes
        for b in range(self.num_envs):
            episodes.reset(b, self._rngs[b], None if chosen is None else chosen[b])
        self._ended[:] = False
        obs = self._observation(np.ones(self.num_envs, dtype=bool))
        return obs, {"episode": episodes.episode.copy(),
                     "ego_record_id": np.array(episodes.record_id, dtype=object)}  # fmt: skip

    def step(self, actions):
        episodes = self.episodes
        restart = np.flatnonzero(self._ended)
        running = ~self._ended
        low, high = float(self.single_action_space.low[0]), float(self.single_action_space.high[0])
        actions = check_actions(actions, low, high, running)
        if actions.size != self.num_envs:
            raise ValueError(f"{actions.size} actions for {self.num_envs} sub-envs")
        episodes.step(actions)
        reward = np.where(running, episodes.reward, 0.0)
        terminated = running & episodes.collided
        truncated = running & episodes.done & ~terminated
        info: dict = {}
        ended = np.flatnonzero(terminated | truncated)
        if ended.size:
            figures = [episodes.metrics(int(b)) for b in ended]
            info["metrics"] = {
                name: _column([f[name] for f in figures], ended, self.num_envs)
                for name in figures[0]
            }
            info["_metrics"] = np.isin(np.arange(self.num_envs), ended)
        for b in restart:
            episodes.reset(int(b), self._rngs[b])
        fresh = np.isin(np.arange(self.num_envs), restart)
        if not self._same_step:
            self._ended = terminated | truncated
            return self._observation(fresh), reward, terminated, truncated, info
        final = self._observation(fresh)
        for b in ended:
            episodes.reset(int(b), self._rngs[b])
        if ended.size:
            mask = np.isin(np.arange(self.num_envs), ended)
            info["final_obs"] = np.full(self.num_envs, None, dtype=object)
            info["final_obs"][ended] = list(final[ended])
            info["_final_obs"] = mask
            obs = final.copy()
            obs[ended] = self._observation(mask, only=mask)[ended]
            return obs, reward, terminated, truncated, info
        return final, reward, terminated, truncated, info

    def close_extras(self, **kwargs):
        self.episodes.close()

    def _observation(self, fresh: np.ndarray, only: np.ndarray | None = None) -> np.ndarray:
        """The observations the agent sees now, ``latency_steps`` old; a sub-env whose
        episode is ``fresh`` (just reset) sees its first observation until it has as
        many. ``only``: update these sub-envs alone (a same-step reset; the others have
        had this step's)."""
        rows = slice(None) if only is None else only
        rngs = self._rngs if only is None else [self._rngs[b] for b in np.flatnonzero(only)]
        obs = noisy(self.episodes.obs[rows], self.obs_noise, rngs, OBS_LOW, OBS_HIGH)
        history = self._history
        if only is None:
            history[:-1] = history[1:]
            history[-1] = obs
        else:
            history[-1, only] = obs
        history[:, fresh] = history[-1, fresh]
        return history[0].copy()


def _column(values: list, rows: np.ndarray, n: int) -> np.ndarray:
    """(n,) with ``values`` at ``rows`` (NaN or None elsewhere)."""
    numeric = all(v is None or isinstance(v, int | float) for v in values)
    out = np.full(n, np.nan) if numeric else np.full(n, None, dtype=object)
    for row, value in zip(rows, values, strict=True):
        out[row] = np.nan if value is None and numeric else value
    return out
