"""The batched vector env as a stable-baselines3 ``VecEnv`` (the ``rl`` extra), so that
PPO, A2C, SAC and the others collect their rollouts from N episodes stepped in one
kernel call::

    from stable_baselines3 import PPO
    from twin.control.sb3_vec_env import Sb3VecEnv

    envs = Sb3VecEnv(num_envs=64, duration=60.0, seed=0)   # VectorWaveDampeningEnv's arguments
    model = PPO("MlpPolicy", envs, n_steps=256, batch_size=1024, device="cpu")
    model.learn(total_timesteps=200_000)

stable-baselines3 resets an ended episode in the step that ends it: the adapter runs
the vector env with ``autoreset_mode="same_step"`` and hands the ended episode's last
observation over as ``infos[i]["terminal_observation"]``, with
``infos[i]["TimeLimit.truncated"]`` true where the episode ran out of time rather than
ended in a collision (so value bootstrapping is right), and its figures as
``infos[i]["metrics"]`` (:func:`twin.control.observe.metrics`).
"""

from typing import Any

import numpy as np

from twin.control.rl import _sb3
from twin.control.vector_env import VectorWaveDampeningEnv

_VecEnv = _sb3().common.vec_env.VecEnv


class Sb3VecEnv(_VecEnv):
    """``VectorWaveDampeningEnv(num_envs, **settings)`` for stable-baselines3 (module doc).

    Args:
        num_envs: N, the episodes stepped together.
        settings: the vector env's other arguments (``data``, ``duration``, ``action``,
            ``seed``, ...); ``autoreset_mode`` is the adapter's.

    Raises:
        RLError: the ``rl`` extra is missing. ValueError: a setting is impossible.
    """

    def __init__(self, num_envs: int = 1, **settings):
        if "autoreset_mode" in settings:
            raise ValueError("Sb3VecEnv sets autoreset_mode itself (same_step)")
        self.venv = VectorWaveDampeningEnv(num_envs, autoreset_mode="same_step", **settings)
        self._seed = int(settings.get("seed", 0))
        self._actions: np.ndarray | None = None
        super().__init__(
            num_envs, self.venv.single_observation_space, self.venv.single_action_space
        )

    def reset(self) -> np.ndarray:
        seeds = self._seeds
        seed = [int(s) for s in seeds] if all(s is not None for s in seeds) else None
        obs, info = self.venv.reset(seed=seed)
        self.reset_infos = [{"episode": int(info["episode"][i])} for i in range(self.num_envs)]
        self._reset_seeds()
        self._reset_options()
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions, dtype=np.float32).reshape(self.num_envs, -1)

    def step_wait(self):
        if self._actions is None:
            raise RuntimeError("step_wait without step_async")
        obs, reward, terminated, truncated, info = self.venv.step(self._actions)
        self._actions = None
        done = terminated | truncated
        infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        for i in np.flatnonzero(done):
            infos[i]["terminal_observation"] = info["final_obs"][i]
            infos[i]["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
            infos[i]["metrics"] = {k: v[i] for k, v in info["metrics"].items()}
        return obs, reward.astype(np.float32), done, infos

    def close(self) -> None:
        self.venv.close()

    def _indices(self, indices) -> list[int]:
        if indices is None:
            return list(range(self.num_envs))
        if isinstance(indices, int):
            return [indices]
        return list(indices)

    def get_attr(self, attr_name: str, indices=None) -> list[Any]:
        """The vector env's attribute, once per sub-env asked (they share it)."""
        value = None if attr_name == "render_mode" else getattr(self.venv, attr_name)
        return [value for _ in self._indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices=None) -> None:
        raise AttributeError(f"the sub-envs of the batched env share their settings: "
                             f"{attr_name} cannot be set per sub-env")  # fmt: skip

    def env_method(self, method_name: str, *method_args, indices=None, **method_kwargs):
        raise AttributeError(f"the batched env has no per-sub-env method {method_name}")

    def env_is_wrapped(self, wrapper_class, indices=None) -> list[bool]:
        return [False for _ in self._indices(indices)]
