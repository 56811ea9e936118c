"""``i24twin/WaveDampening-v0``: one AV (the ego) in recorded I-24 waves, as a
Gymnasium environment, single or batched.

The ego is driven by the agent; the visible vehicles around it by the traffic manager
with the run's behaviour (calibrated drivers where the store is calibrated), the
recording beyond them as the ghost-cell boundary (:mod:`twin.cosim`). Both the single
env (:class:`WaveDampeningEnv`) and the vector env
(:class:`twin.control.vector_env.VectorWaveDampeningEnv`, many episodes stepped in one
kernel call) run on the batched core (:mod:`twin.control.engine`). Importing this
module registers both: ``gymnasium.make("i24twin/WaveDampening-v0")`` after ``import
twin.env`` (or ``gymnasium.make("twin.env:i24twin/WaveDampening-v0")``), and
``gymnasium.make_vec("i24twin/WaveDampening-v0", num_envs=N,
vectorization_mode="vector_entry_point", world="kinematic")``.

Episodes are drawn from the congested cells of the store (:mod:`twin.runners.episodes`;
the embedded morning, preset C, by default), split by time: ``train`` episodes lie
before ``split_time`` (default: the middle of the recording), ``test`` episodes after.

**Action** (10 Hz; the physics world runs at 100 Hz under it, the kinematic world,
``world="kinematic"``, one step per action): ``accel`` (default), a Box
[-3.0, 1.5] m/s^2, the ego's commanded acceleration; or ``speed``, a Box [0, 35] m/s,
a desired speed the ego tracks with a speed loop (a = 1.0 (v_cmd - v), within the
same limits). An action outside the Box is clipped to it; a NaN or infinite one is
refused with a ValueError naming the sub-env and the value.

**Observation** (Box, float32, :data:`OBSERVATION`, bounds :data:`OBS_LOW` and
:data:`OBS_HIGH`, values clipped to them), of the state after the step
(:mod:`twin.control.observe`): own speed [m/s] and acceleration [m/s^2] (measured over
the step); gap [m] to the leader in the own lane (bumper to bumper, 200 when none
within 200 m) and its speed (the own speed when none); the same of the follower; and
the recorded speeds ahead [m/s], per lane -1..-4, the mean of the recording 0-200,
200-400 and 400-600 m downstream of the ego (what a connected vehicle could know; the
run's default desired speed ``vel_default`` where nobody is recorded). Optional
Gaussian noise (``obs_noise``, sd as a fraction of each value) and latency
(``latency_steps``, control steps).

**Reward** per control step (:class:`Reward`; weights settable): minus the fuel [g] of
the AV and its 5 followers over the step (RAV4 model, :mod:`twin.physics.energy`), minus
``gap_weight`` when the AV's time gap exceeds ``gap_max`` s (it would invite cut-ins),
minus ``ttc_weight`` when its time to collision is under ``ttc_min`` s.

``terminated``: the AV collided; ``truncated``: the episode's end (or it left the map
and data). At the end ``info["metrics"]`` holds the episode's figures
(:func:`twin.control.observe.metrics`: the AV and its followers' economy, the ego's
speed error against its recording, collisions, lane changes, least time to collision,
acceleration and jerk, the safety layer's time, the return).
"""

import math
from dataclasses import dataclass
from typing import ClassVar

import gymnasium as gym
import numpy as np

from twin.control import observe
from twin.control.engine import CONTROL_DT, Episodes, check_actions, noisy
from twin.core.i24 import LANES
from twin.cosim.config import SCENARIO_B, CosimConfig, switch_world
from twin.traffic.controller_api import Observation

ENV_ID = "i24twin/WaveDampening-v0"
VECTOR_ENTRY_POINT = "twin.control.vector_env:VectorWaveDampeningEnv"
ACCEL_RANGE = (-3.0, 1.5)  # [m/s^2] the action's bounds
SPEED_RANGE = (0.0, 35.0)  # [m/s] the action's bounds as a desired speed
SPEED_GAIN = 1.0  # [1/s] of the speed loop under the speed action
GAP_CAP = observe.GAP_CAP  # [m] gaps are reported up to this
AHEAD_BINS = ((0.0, 200.0), (200.0, 400.0), (400.0, 600.0))  # [m] downstream of the ego
#: The observation's entries, in order.
OBSERVATION = (
    "speed",
    "accel",
    "leader_gap",
    "leader_speed",
    "follower_gap",
    "follower_speed",
    *(f"ahead_lane_{lane}_{int(a)}_{int(b)}" for lane in LANES for a, b in AHEAD_BINS),
)

#: The observation's bounds: speeds [-5, 60] m/s (a body may creep back at rest),
#: acceleration [-20, 20] m/s^2, gaps [-50, 200] m (negative: overlapping, a collision).
OBS_LOW = np.array([-5.0, -20.0, -50.0, -5.0, -50.0, -5.0] + [-5.0] * 12, dtype=np.float32)
OBS_HIGH = np.array([60.0, 20.0, GAP_CAP, 60.0, GAP_CAP, 60.0] + [60.0] * 12, dtype=np.float32)


@dataclass(frozen=True)
class Reward:
    """The reward's terms (see the module doc).

    Attributes:
        fuel_weight: [1/g] per gram of fuel of the AV and its followers.
        gap_weight: per control step with a time gap over ``gap_max`` [s].
        ttc_weight: per control step with a time to collision under ``ttc_min`` [s].
    """

    fuel_weight: float = 1.0
    gap_weight: float = 0.1
    gap_max: float = 4.0
    ttc_weight: float = 1.0
    ttc_min: float = 4.0


class WaveDampeningEnv(gym.Env):
    """See the module doc.

    Args:
        data: a store folder or ``embedded:NAME`` (default ``embedded:morning``).
        split: ``train`` or ``test``.
        split_time: [s unix] between train and test episodes (default: the middle).
        duration: [s] each episode.
        action: ``accel`` or ``speed``.
        reward: the reward's weights.
        obs_noise: sd of multiplicative observation noise (0: none).
        latency_steps: control steps the observation lags behind.
        cosim: the other settings of each episode's cosimulation.
        world: ``physics`` or ``kinematic`` (:mod:`twin.physics.worlds`; the step
            switches with it, see :func:`twin.cosim.config.switch_world`); default:
            ``cosim``'s (physics).
        seed: the episodes' seed (episode ``i`` is the same for any ``reset`` order).
        safety: the drivers' emergency braking beneath the agent's command, as the
            baseline controllers have it (its time in ``metrics["safety_override_s"]``;
            off by default: the agent's command is applied as it is).

    Raises:
        ValueError: a setting is impossible (named).
    """

    metadata: ClassVar[dict] = {"render_modes": []}

    def __init__(
        self,
        data: str | None = None,
        *,
        split: str = "train",
        split_time: float | None = None,
        duration: float = 120.0,
        action: str = "accel",
        reward: Reward | None = None,
        obs_noise: float = 0.0,
        latency_steps: int = 0,
        cosim: CosimConfig = SCENARIO_B,
        world: str | None = None,
        seed: int = 0,
        safety: bool = False,
    ):
        setup = EnvSetup.make(
            data, split=split, split_time=split_time, duration=duration, action=action,
            reward=reward, obs_noise=obs_noise, latency_steps=latency_steps, cosim=cosim,
            world=world, seed=seed, safety=safety,
        )  # fmt: skip
        self.setup = setup
        self.store, self.bundle, self.cosim = setup.store, setup.bundle, setup.cosim
        self.traffic = setup.traffic
        self.road, self.duration, self.action_kind = setup.cosim.road, setup.duration, action
        self.reward_weights = setup.reward
        self.obs_noise, self.latency_steps, self.base_seed = obs_noise, latency_steps, seed
        self.action_space = setup.action_space()
        self.observation_space = gym.spaces.Box(OBS_LOW, OBS_HIGH, dtype=np.float32)
        self.episodes = setup.episodes(1)
        self.episode = -1
        self._history: list[np.ndarray] = []

    @property
    def sim(self):
        """The running episode's cosimulation facade (the physics world), or None."""
        return self.episodes.sim

    def episode_config(self) -> CosimConfig:
        """The running episode's cosimulation configuration (to run it again in the
        cosimulator, with any controller)."""
        return self.episodes.config(0)

    @property
    def t0(self) -> float:
        """[s unix] the running episode's start."""
        return float(self.episodes.state.episodes.t0[0])

    # -- Gymnasium ----------------------------------------------------------------------

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """A new episode: ``options={"episode": i}`` picks one, else drawn."""
        super().reset(seed=seed)
        index = (options or {}).get("episode")
        k = self.episodes.reset(0, self.np_random, index)
        self.episode = k
        self._history = []
        obs = self._observation()
        return obs, {"episode": k, "ego_record_id": self.episodes.record_id[0]}

    def step(self, action):
        if self.episode < 0:
            raise RuntimeError("call reset() before step()")
        action = np.asarray(action, dtype=np.float64).reshape(-1)
        if action.size != 1:
            raise ValueError(f"the action must be one number, got {action!r}")
        low, high = float(self.action_space.low[0]), float(self.action_space.high[0])
        actions = check_actions(action, low, high, np.ones(1, dtype=bool))
        episodes = self.episodes
        fuel_before = float(episodes.stats[0, observe.FUEL_SEEN])
        episodes.step(actions)
        obs = self._observation()
        terminated = bool(episodes.collided[0])
        truncated = bool(episodes.done[0]) and not terminated
        info = {"fuel_g": float(episodes.stats[0, observe.FUEL_SEEN]) - fuel_before}
        if terminated or truncated:
            info["metrics"] = episodes.metrics(0)
        return obs, float(episodes.reward[0]), terminated, truncated, info

    def close(self):
        self.episodes.close()

    # -- inside -------------------------------------------------------------------------

    def _observation(self) -> np.ndarray:
        obs = noisy(self.episodes.obs, self.obs_noise, [self.np_random], OBS_LOW, OBS_HIGH)[0]
        self._history.append(obs)
        del self._history[: -(self.latency_steps + 1)]
        return self._history[0].copy()  # never the object returned before


@dataclass(frozen=True)
class EnvSetup:
    """What an env (single or vector) is made of: the recording and the map, opened
    once per process; the episodes' configuration and where they start; the spaces'
    settings. :meth:`make` checks every setting."""

    store: object
    bundle: object
    traffic: object
    cosim: CosimConfig
    cells: object
    sampling: object
    duration: float
    action: str
    reward: Reward
    seed: int
    safety: bool = False

    @classmethod
    def make(cls, data=None, *, split="train", split_time=None, duration=120.0, action="accel",
             reward=None, obs_noise=0.0, latency_steps=0, cosim=SCENARIO_B, world=None,
             seed=0, safety=False) -> "EnvSetup":  # fmt: skip
        """Raises: ValueError naming an impossible setting."""
        from twin.cosim.windows import road_limits
        from twin.runners.episodes import EpisodeSampling, measure_cells
        from twin.runners.evaluation import CONGESTED_TRAVEL

        if split not in ("train", "test"):
            raise ValueError(f"split must be 'train' or 'test', got {split!r}")
        if action not in ("accel", "speed"):
            raise ValueError(f"action must be 'accel' or 'speed', got {action!r}")
        if not (math.isfinite(duration) and duration >= 1.0):
            raise ValueError(f"duration must be at least 1 s, got {duration!r}")
        if not (math.isfinite(obs_noise) and obs_noise >= 0):
            raise ValueError(f"obs_noise must be >= 0, got {obs_noise!r}")
        if not (isinstance(latency_steps, int) and latency_steps >= 0):
            raise ValueError(f"latency_steps must be an integer >= 0, got {latency_steps!r}")
        store, bundle, traffic = opened(data or "embedded:morning")
        if world is not None:
            cosim = switch_world(cosim, world)
        steps = CONTROL_DT / cosim.dt
        if abs(steps - round(steps)) > 1e-9:
            raise ValueError(f"the step {cosim.dt} s must divide the control step {CONTROL_DT} s")
        road = cosim.road
        first, last = store.time_range(road)
        split_time = 0.5 * (first + last) if split_time is None else float(split_time)
        if not first < split_time < last:
            raise ValueError(
                f"split_time {split_time:.0f} must lie inside the recording ({first:.0f} to "
                f"{last:.0f})"
            )
        window = (None, split_time) if split == "train" else (split_time, None)
        sampling = EpisodeSampling(roads=(road.value,), congested_share=1.0)
        key = (id(store), road.value, float(duration), window)
        if key not in _CELLS:
            limits = {road: road_limits(bundle, traffic, road)}
            _CELLS[key] = measure_cells(store, sampling, limits, float(duration), window=window,
                                        room_speed=CONGESTED_TRAVEL)  # fmt: skip
        return cls(store, bundle, traffic, cosim, _CELLS[key], sampling, float(duration), action,
                   reward or Reward(), int(seed), bool(safety))  # fmt: skip

    def action_space(self) -> gym.spaces.Box:
        low, high = ACCEL_RANGE if self.action == "accel" else SPEED_RANGE
        return gym.spaces.Box(low, high, shape=(1,), dtype=np.float32)

    def episodes(self, count: int, human: bool = False) -> Episodes:
        """``count`` episodes of this setup on the batched core (``human``: the ego
        driven as ``twin.controllers:human``, the actions ignored)."""
        w = self.reward
        return Episodes(
            self.store, self.bundle, self.cosim, self.cells, self.sampling, count=count,
            duration=self.duration, action=self.action,
            weights=(w.fuel_weight, w.gap_weight, w.gap_max, w.ttc_weight, w.ttc_min),
            low=OBS_LOW, high=OBS_HIGH, base_seed=self.seed, traffic=self.traffic,
            safety=self.safety, human=human,
        )  # fmt: skip


_OPENED: dict = {}
_CELLS: dict = {}


def opened(data: str):
    """(store, map, recorded traffic) of ``data``, opened once per process."""
    if data not in _OPENED:
        from mapgen.build import default_map
        from twin.data.empirical import EmpiricalTraffic
        from twin.runners.run import open_data

        store = open_data(data, progress=False)
        _OPENED[data] = (store, default_map(progress=False), EmpiricalTraffic(store))
    return _OPENED[data]


def action_accel(kind: str, command: float, speed: float) -> float:
    """The ego's acceleration [m/s^2] for an action: ``accel`` is it; ``speed`` [m/s] a
    desired speed tracked by the speed loop from ``speed`` [m/s]."""
    if kind == "accel":
        return command
    return float(np.clip(SPEED_GAIN * (command - speed), *ACCEL_RANGE))


def features(obs: Observation, accel: float, ahead: list[float]) -> np.ndarray:
    """The observation's values (see :data:`OBSERVATION`), before noise and clipping.

    Args:
        obs: what the traffic manager shows the ego's controller.
        accel: [m/s^2] the ego's measured acceleration.
        ahead: the recorded speeds ahead (:func:`ahead_speeds`).
    """
    k = obs.lanes.lanes.index(obs.lane)

    def gap(value):
        return GAP_CAP if not math.isfinite(value) else min(float(value), GAP_CAP)

    def speed_or_own(value):
        return obs.speed if not math.isfinite(value) else float(value)

    values = [
        obs.speed,
        accel,
        gap(obs.lanes.leader_gap[k]),
        speed_or_own(obs.lanes.leader_speed[k]),
        gap(obs.lanes.follower_gap[k]),
        speed_or_own(obs.lanes.follower_speed[k]),
        *ahead,
    ]
    return np.asarray(values, dtype=np.float64)


def ahead_speeds(traffic, road, t: float, x: float, free_speed: float) -> list[float]:
    """Recorded mean speeds [m/s] ahead of road-frame ``x`` [m] at unix time ``t``, per
    lane -1..-4 and bin of :data:`AHEAD_BINS`; ``free_speed`` where nobody is recorded.

    Args:
        traffic: the recorded traffic (``EmpiricalTraffic``). road: the carriageway.
    """
    snap = traffic.snapshot(road, t, x, x + AHEAD_BINS[-1][1])
    out = []
    for lane in LANES:
        for a, b in AHEAD_BINS:
            rows = (snap.lane == lane) & (snap.x >= x + a) & (snap.x < x + b)
            out.append(float(snap.speed[rows].mean()) if rows.any() else free_speed)
    return out


def register_envs() -> None:
    """Register ``i24twin/WaveDampening-v0`` with Gymnasium (done on import): the single
    env, and the batched vector env for ``gymnasium.make_vec(...,
    vectorization_mode="vector_entry_point")``."""
    if ENV_ID not in gym.registry:
        gym.register(
            id=ENV_ID,
            entry_point="twin.control.env:WaveDampeningEnv",
            vector_entry_point=VECTOR_ENTRY_POINT,
        )


register_envs()
