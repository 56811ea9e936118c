"""The wave-dampening environment's episodes on the batched core: B episodes whose ego
an agent drives (its ``ctrl`` ACTION), drawn from the congested cells of a recording,
stepped together at the control step, observed and rewarded by compiled kernels
(:mod:`twin.control.observe`). The single env (:mod:`twin.control.env`) is one of them,
the vector env (:mod:`twin.control.vector_env`) many.

In the kinematic world a control step is one kernel call for every episode; the
physics world (one episode) runs the cosimulator's facade, pybullet integrating ten
steps of 0.01 s under the kernels' decisions.
"""

import time
from dataclasses import replace

import numpy as np

from twin.control import observe
from twin.cosim.core.batch import Batch, Shared
from twin.cosim.core.step import PHASES, phase_batch, step_batch
from twin.traffic.kernels import state as kinds

CONTROL_DT = 0.1  # [s] the agent's step


class Episodes:
    """``count`` episodes of the env (see the module doc).

    Args:
        store, bundle: the recording and the map (opened once per process).
        cosim: the episodes' configuration (world, behaviour, windows, ...).
        cells, sampling: where episodes start (:func:`twin.runners.episodes.measure_cells`).
        count: B, the episodes stepped together (1 in the physics world).
        duration: [s] each episode.
        action: ``accel`` or ``speed`` (what the agent's number is).
        weights: the reward's (fuel, gap, gap_max, ttc, ttc_min).
        low, high: the observation's bounds.
        base_seed: episode ``k`` is the same for every env with this seed.
        safety: the drivers' emergency braking beneath the agent's command (the
            baselines' safety layer; its time counted in ``safety_override_s``).
        human: the ego drives as ``twin.controllers:human`` (its driver's command), the
            actions ignored: the baseline of the same episodes.
    """

    def __init__(self, store, bundle, cosim, cells, sampling, *, count: int, duration: float,
                 action: str, weights, low, high, base_seed: int, traffic=None,
                 safety: bool = False, human: bool = False):  # fmt: skip
        self.cosim, self.cells, self.sampling = cosim, cells, sampling
        self.count, self.duration, self.base_seed = int(count), float(duration), int(base_seed)
        self.kinematic = cosim.world == "kinematic"
        if not self.kinematic and count != 1:
            raise ValueError("the physics world runs one episode at a time")
        self.substeps = max(1, round(CONTROL_DT / cosim.dt))
        self.shared = Shared.make(store, bundle, cosim, traffic=traffic, action=action)
        self.agent = kinds.HUMAN if human else kinds.ACTION + (kinds.GUARDED if safety else 0)
        self.shared = self.shared.with_controllers(self.agent)
        self.bundle = bundle
        self.sim = None
        if self.kinematic:
            self.batch = Batch(replace(self.shared, config=replace(cosim, t_max=duration)),
                               count, log=False)  # fmt: skip
            self.state, self.core = self.batch.state, self.batch.core
        n = self.count
        self.obs = np.zeros((n, observe.N_OBS))
        self.reward = np.zeros(n)
        self.collided = np.zeros(n, dtype=bool)
        self.stats = np.zeros((n, len(observe.STATS)))
        self.weights = np.asarray(weights, dtype=np.float64)
        self.low, self.high = np.asarray(low, np.float64), np.asarray(high, np.float64)
        self.first = np.zeros(n, dtype=bool)
        self.episode = np.full(n, -1, np.int64)
        self.record_id = [""] * n
        self.specs: list = [None] * n
        self._work = observe.work_arrays()

    @property
    def done(self) -> np.ndarray:
        """(B,) bool: the episode is over (or was never reset)."""
        return self.state.episodes.done

    def reset(self, b: int, rng: np.random.Generator, index: int | None = None) -> int:
        """A new episode ``b``: episode ``index``, or one drawn from ``rng`` (an episode
        whose ego cannot be placed is drawn again, up to 20 times). Returns its number.

        Raises:
            RuntimeError: no episode could be placed in 20 draws.
            ScenarioError, NoVehicleNearError: the episode ``index`` cannot be placed.
        """
        from twin.runners.episodes import PLACEMENT_ERRORS, draw_episode

        for _ in range(20):
            k = int(rng.integers(0, 2**31 - 1)) if index is None else int(index)
            spec = draw_episode(self.cells, self.sampling, self.base_seed, k)
            try:
                self._start(b, spec)
                self.specs[b] = spec
                break
            except PLACEMENT_ERRORS:
                if index is not None:
                    raise
        else:
            raise RuntimeError("no episode could be placed in 20 draws")
        self.episode[b] = k
        self.first[b] = True  # observed alone: the others are left as they are
        self._observe(np.ones(self.count, dtype=bool))
        self.first[b] = False
        return k

    def _start(self, b: int, spec) -> None:
        if self.kinematic:
            placed = self.batch.reset(b, lane=spec.lane, x=spec.x, time=spec.time,
                                      seed=spec.seed, t_max=self.duration)  # fmt: skip
            tid = placed.tid
        else:
            from twin.cosim.cosimulator import Cosimulator
            from twin.runners.episodes import episode_config

            if self.sim is not None:
                self.sim.close()
                self.sim = None
            config = episode_config(
                self.cosim, spec, scenario="env", t_max=self.duration, ego_controller="",
                camera=replace(self.cosim.camera, enabled=False),
            )  # fmt: skip
            sim = Cosimulator(config, self.shared.traffic, self.bundle,
                              shared=replace(self.shared, config=config), ego_kind=self.agent,
                              log=False)  # fmt: skip
            try:
                sim.reset()
            except Exception:
                sim.close()
                raise
            self.sim, self.state, self.core = sim, sim.state, sim.core
            tid = sim.ego.tid
        self.record_id[b] = str(self.shared.store.trajectory_arrays["id"][tid])

    def step(self, actions: np.ndarray, times: np.ndarray | None = None) -> None:
        """One control step of every running episode with the agents' ``actions`` (B,);
        with ``times`` (len(PHASES) + 1,) [s], the kinematic world's step runs phase by
        phase (the same bytes) and each phase's wall time, then the observation's, is
        added to it (``twin bench env --profile``)."""
        before = self.done.copy()
        self.state.actions[:] = actions
        if self.kinematic and times is not None:
            for k in range(len(PHASES)):
                start = time.perf_counter()
                phase_batch(self.core, k)
                times[k] += time.perf_counter() - start
            self.batch.check_all()
            start = time.perf_counter()
            self._observe(before)
            times[-1] += time.perf_counter() - start
            return
        if self.kinematic:
            step_batch(self.core)
            self.batch.check_all()
        else:
            for _ in range(self.substeps):
                if self.sim.done:
                    break
                self.sim.step()
        self._observe(before)

    def _observe(self, before: np.ndarray) -> None:
        observe.observe_batch(
            self.core, before, self.obs, self.reward, self.collided, self.stats, self.weights,
            self.low, self.high, CONTROL_DT, self.first, *self._work,
        )  # fmt: skip

    def config(self, b: int):
        """Episode ``b``'s cosimulation configuration (to run it again, in either world,
        with any controller)."""
        from twin.runners.episodes import episode_config

        return episode_config(
            self.cosim, self.specs[b], scenario="env", t_max=self.duration, ego_controller="",
            camera=replace(self.cosim.camera, enabled=False),
        )  # fmt: skip

    def metrics(self, b: int) -> dict:
        """Episode ``b``'s figures so far (:func:`twin.control.observe.metrics`)."""
        return observe.metrics(self.stats, self.state, b, self.cosim.dt)

    def close(self) -> None:
        if self.sim is not None:
            self.sim.close()
            self.sim = None


def check_actions(actions: np.ndarray, low: float, high: float, running: np.ndarray) -> np.ndarray:
    """The actions clipped to the action space ``[low, high]`` (as its Box says it may
    be); a NaN or infinite one of a running episode is refused.

    Raises:
        ValueError: naming the sub-env and the value.
    """
    actions = np.asarray(actions, dtype=np.float64).reshape(-1)
    bad = np.flatnonzero(~np.isfinite(actions) & running)
    if bad.size:
        raise ValueError(
            f"sub-env {bad[0]}: the action {float(actions[bad[0]])} is not a finite number"
        )
    return np.clip(np.nan_to_num(actions), low, high)


def noisy(obs: np.ndarray, noise: float, rngs, low, high) -> np.ndarray:
    """``obs`` (B, N_OBS) with multiplicative Gaussian noise of sd ``noise`` from each
    episode's generator, clipped to the bounds, as float32."""
    if noise > 0:
        draws = np.stack([rng.standard_normal(obs.shape[1]) for rng in rngs])
        obs = obs * (1.0 + noise * draws)
    return np.clip(obs, low, high).astype(np.float32)
