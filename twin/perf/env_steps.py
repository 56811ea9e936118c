"""The benchmark of the control layer: steps per second of the wave-dampening env, one
env and vectorised (the batched core's vector env in the kinematic world; one env per
process in the physics world), its reset, and what compiling the core's kernels costs
(cold: an empty cache; warm: a new process loading the cache)."""

import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

from twin.perf.common import cores, median

CONTROL_PERIOD = 0.1  # [s] one env step (10 Hz control)
TAIL = 1.0  # [s] of episode past the last timed step, so that none is truncated
NUM_ENVS = 256  # episodes of the batched vector env
RESETS = 50  # resets timed per repeat
_FIRST_CALL = """
import json, sys, time
start = time.perf_counter()
import gymnasium, numpy
import twin.env
imported = time.perf_counter()
env = gymnasium.make(twin.env.ENV_ID, data=sys.argv[1], world=sys.argv[2], duration=5.0)
env.reset(seed=0)
env.step(numpy.zeros(1, numpy.float32))
done = time.perf_counter()
print(json.dumps({"import_s": imported - start, "first_step_s": done - imported}))
"""


def env_bench(
    data: str | None = None,
    *,
    steps: int = 200,
    workers: int | None = None,
    repeats: int = 3,
    world: str = "physics",
    num_envs: int = NUM_ENVS,
    resets: int | None = None,
    compile_times: bool = False,
    profile: bool = False,
) -> dict:
    """Env steps per second of ``i24twin/WaveDampening-v0`` (10 Hz control over the
    ``world``'s default step: 0.01 s physics, 0.1 s kinematic; the default windows, no
    cameras) on ``data`` (default: the embedded morning), each env stepping ``steps``
    times with a small varying action after a reset (not timed):

    * one env, and its reset [ms] (the mean of ``resets`` resets, default 50);
    * vectorised: in the kinematic world the batched vector env of ``num_envs``
      episodes (one kernel call a step; with the vehicles it updated per second), in
      the physics world an ``AsyncVectorEnv`` of ``workers`` envs (default: the cores);
    * ``compile_times``: the first reset and step of a new process with an empty kernel
      cache (the cold compile) and with this machine's cache (the warm start);
    * ``profile`` (kinematic): where the vector env's step goes, phase by phase of the
      core's step and the observation, in microseconds per episode step.

    Medians over the repeats; scaling is the vector env's steps per second over one's."""
    import gymnasium as gym

    from twin.control.env import ENV_ID

    data = data or "embedded:morning"
    duration = steps * CONTROL_PERIOD + TAIL

    def make():
        return gym.make(ENV_ID, data=data, duration=duration, world=world)

    resets = RESETS if resets is None else resets
    one, reset_ms, vector, updates = [], [], [], []
    kinematic = world == "kinematic"
    n = num_envs if kinematic else workers or cores()
    for k in range(repeats):
        env = make()
        one.append(_steps_per_second(env, 1, k, steps)[0])
        start = time.perf_counter()
        for j in range(resets):
            env.reset(seed=1000 * k + j)
        reset_ms.append(1e3 * (time.perf_counter() - start) / resets)
        env.close()
        if kinematic:
            envs = gym.make_vec(ENV_ID, num_envs=n, vectorization_mode="vector_entry_point",
                                data=data, duration=duration, world=world)  # fmt: skip
        else:
            envs = gym.vector.AsyncVectorEnv([make] * n)
        rate, vehicles = _steps_per_second(envs, n, k * n, steps)
        vector.append(rate)
        updates.append(vehicles)
        envs.close()
    single, many = median(one), median(vector)
    out = {
        "world": world,
        "steps": steps,
        "repeats": repeats,
        "env_steps_per_s": round(single, 2),
        "reset_ms": round(median(reset_ms), 3),
        "resets": resets,
        "vector": "batched core" if kinematic else "AsyncVectorEnv",
        "vector_envs": n,
        "vector_env_steps_per_s": round(many, 2),
        "scaling": round(many / single, 2),
    }
    if kinematic:
        out["vector_vehicle_updates_per_s"] = round(median(updates), 0)
    if kinematic and profile:
        out["profile_us_per_episode_step"] = step_profile(data, n, steps, duration)
    if compile_times:
        out.update(first_call_times(data, world))
    return out


def step_profile(data: str, num_envs: int, steps: int, duration: float) -> dict:
    """[us per episode step] each phase of the batched core's step
    (:data:`twin.cosim.core.step.PHASES`) and the observation, over ``steps`` steps of
    a vector env of ``num_envs`` episodes (each phase over every episode in turn: the
    same bytes as the step), and their total."""
    import gymnasium as gym

    from twin.control.env import ENV_ID
    from twin.cosim.core.step import PHASES

    envs = gym.make_vec(ENV_ID, num_envs=num_envs, vectorization_mode="vector_entry_point",
                        data=data, duration=duration, world="kinematic")  # fmt: skip
    envs.reset(seed=0)
    episodes = envs.unwrapped.episodes
    episodes.step(np.zeros(num_envs), np.zeros(len(PHASES) + 1))  # compiled, not timed
    times = np.zeros(len(PHASES) + 1)
    episode_steps = 0
    for k in range(steps):
        running = int((~episodes.done).sum())
        episodes.step(np.full(num_envs, 0.3 * np.sin(0.1 * k)), times)
        episode_steps += running
    envs.close()
    us = 1e6 * times / max(episode_steps, 1)
    out = {name: round(float(v), 2) for name, v in zip((*PHASES, "observe"), us, strict=True)}
    out["total"] = round(float(us.sum()), 2)
    return out


def _steps_per_second(env, n_envs: int, seed, steps: int) -> tuple[float, float]:
    """(env steps a second, vehicle updates a second) of ``env`` (``n_envs`` envs,
    vectorised where more than one) over ``steps`` steps, after a reset with ``seed``
    and one step (not timed: a process's first step loads the kernels it calls from
    their cache); the vehicles are counted for the batched core's env only."""
    env.reset(seed=seed)
    shape = (n_envs, 1) if n_envs > 1 else (1,)
    actions = [np.full(shape, 0.3 * np.sin(0.1 * k), np.float32) for k in range(steps)]
    env.step(actions[0])
    core_state = getattr(getattr(env.unwrapped, "episodes", None), "state", None)
    vehicles = 0
    start = time.perf_counter()
    for k in range(steps):
        env.step(actions[k])
        if core_state is not None:
            vehicles += int(core_state.bodies.valid.sum())
    elapsed = time.perf_counter() - start
    return n_envs * steps / elapsed, vehicles / elapsed


def first_call_times(data: str, world: str, script: str = _FIRST_CALL) -> dict:
    """[s] a new process's import and first reset and step of the env, with an empty
    kernel cache (``cold_*``: every kernel compiled) and with the machine's cache
    (``warm_*``: loaded). ``script`` is what the process runs (with ``data`` and
    ``world`` as its arguments; it prints ``import_s`` and ``first_step_s`` as JSON)."""
    out = {}
    with tempfile.TemporaryDirectory(prefix="twin-cold-cache-") as cold:
        for name, env in (("cold", {"NUMBA_CACHE_DIR": cold}), ("warm", {})):
            result = subprocess.run(
                [sys.executable, "-c", script, data, world],
                env={**os.environ, **env}, capture_output=True, text=True, check=True,
            )  # fmt: skip
            times = json.loads(result.stdout.strip().splitlines()[-1])
            out[f"{name}_import_s"] = round(times["import_s"], 2)
            out[f"{name}_first_step_s"] = round(times["first_step_s"], 2)
    return out
