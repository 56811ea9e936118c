"""The benchmark of the control layer: steps per second of the wave-dampening env,
alone and vectorised."""

import time

import numpy as np

from twin.perf.common import cores, median

CONTROL_PERIOD = 0.1  # [s] one env step (10 Hz control)
TAIL = 1.0  # [s] of episode past the last timed step, so that none is truncated


def env_bench(
    data: str | None = None,
    *,
    steps: int = 200,
    workers: int | None = None,
    repeats: int = 3,
    world: str = "physics",
) -> dict:
    """Env steps per second of ``i24twin/WaveDampening-v0`` (10 Hz control over the
    ``world``'s default step: 0.01 s physics, 0.1 s kinematic; the default windows, no
    cameras) on ``data`` (default: the embedded morning): one env, and an
    ``AsyncVectorEnv`` of ``workers`` envs (default: the cores), each stepping
    ``steps`` times with a zero action after a reset (not timed).
    Medians over the repeats; scaling is the vector env's steps per second over one's."""
    import gymnasium as gym

    from twin.control.env import ENV_ID

    workers = workers or cores()

    def make():
        return gym.make(ENV_ID, data=data, duration=steps * CONTROL_PERIOD + TAIL, world=world)

    one, vector = [], []
    for k in range(repeats):
        env = make()
        one.append(_steps_per_second(env, 1, k, steps))
        env.close()
        envs = gym.vector.AsyncVectorEnv([make] * workers)
        seeds = [k * workers + i for i in range(workers)]
        vector.append(_steps_per_second(envs, workers, seeds, steps))
        envs.close()
    single, many = median(one), median(vector)
    return {
        "world": world,
        "steps": steps,
        "repeats": repeats,
        "env_steps_per_s": round(single, 2),
        "vector_workers": workers,
        "vector_env_steps_per_s": round(many, 2),
        "scaling": round(many / single, 2),
    }


def _steps_per_second(env, n_envs: int, seed, steps: int) -> float:
    """Env steps a second of ``env`` (``n_envs`` envs, vectorised where more than one)
    over ``steps`` steps with a zero action, after a reset with ``seed`` (not timed)."""
    env.reset(seed=seed)
    action = np.zeros((n_envs, 1) if n_envs > 1 else (1,), np.float32)
    start = time.perf_counter()
    for _ in range(steps):
        env.step(action)
    return n_envs * steps / (time.perf_counter() - start)
