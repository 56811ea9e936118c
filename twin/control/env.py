"""``i24twin/WaveDampening-v0``: one AV (the ego) in recorded I-24 waves, as a
Gymnasium environment.

The ego is driven by the agent; the visible vehicles around it by the traffic manager
with the run's behaviour (calibrated drivers where the store is calibrated), the
recording beyond them as the ghost-cell boundary (:mod:`twin.cosim`). Importing this
module registers the environment: ``gymnasium.make("i24twin/WaveDampening-v0")``
after ``import twin.control.env``, or ``gymnasium.make("twin.env:i24twin/WaveDampening-v0")``
(Gymnasium imports the module first).

Episodes are drawn from the congested cells of the store (:mod:`twin.runners.episodes`;
the embedded morning, preset C, by default), split by time: ``train`` episodes lie
before ``split_time`` (default: the middle of the recording), ``test`` episodes after.

**Action** (10 Hz; the physics world runs at 100 Hz under it, the kinematic world,
``world="kinematic"``, one step per action): ``accel`` (default), a Box
[-3.0, 1.5] m/s^2, the ego's commanded acceleration; or ``speed``, a Box [0, 35] m/s,
a desired speed the ego tracks with a speed loop (a = 1.0 (v_cmd - v), within the
same limits).

**Observation** (Box, float32, :data:`OBSERVATION`, bounds :data:`OBS_LOW` and
:data:`OBS_HIGH`, values clipped to them): own speed [m/s] and acceleration
[m/s^2]; gap [m] to the leader in the own lane (bumper to bumper, 200 when none within
200 m) and its speed (the own speed when none); the same of the follower; and the
recorded speeds ahead [m/s], per lane -1..-4, the mean of the recording 0-200, 200-400
and 400-600 m downstream of the ego (what a connected vehicle could know; the run's
default desired speed ``vel_default`` where nobody is recorded). Optional Gaussian
noise (``obs_noise``, sd as a fraction of each value) and latency (``latency_steps``,
control steps).

**Reward** per control step (:class:`Reward`; weights settable): minus the fuel [g] of
the AV and its 5 followers over the step (RAV4 model, :mod:`twin.physics.energy`), minus
``gap_weight`` when the AV's time gap exceeds ``gap_max`` s (it would invite cut-ins),
minus ``ttc_weight`` when its time to collision is under ``ttc_min`` s.

``terminated``: the AV collided; ``truncated``: the episode's end (or it left the map
and data). At the end ``info["metrics"]`` holds the benchmark's metrics
(:func:`twin.metrics.table.flatten`).
"""

import math
from dataclasses import dataclass, replace
from typing import ClassVar

import gymnasium as gym
import numpy as np

from twin.core.i24 import LANES
from twin.cosim.config import SCENARIO_B, CosimConfig, switch_world
from twin.metrics.economy import followers
from twin.physics import energy
from twin.traffic.controller_api import EgoCommand, Observation

ENV_ID = "i24twin/WaveDampening-v0"
CONTROL_DT = 0.1  # [s] the agent's step
ACCEL_RANGE = (-3.0, 1.5)  # [m/s^2] the action's bounds
SPEED_RANGE = (0.0, 35.0)  # [m/s] the action's bounds as a desired speed
SPEED_GAIN = 1.0  # [1/s] of the speed loop under the speed action
GAP_CAP = 200.0  # [m] gaps are reported up to this
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
    ):
        from mapgen.build import default_map
        from twin.cosim.windows import road_limits
        from twin.data.empirical import EmpiricalTraffic
        from twin.runners.episodes import EpisodeSampling, measure_cells
        from twin.runners.evaluation import CONGESTED_TRAVEL
        from twin.runners.run import open_data

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
        self.store = open_data(data or "embedded:morning", progress=False)
        self.traffic = EmpiricalTraffic(self.store)
        self.bundle = default_map(progress=False)
        if world is not None:
            cosim = switch_world(cosim, world)
        steps = CONTROL_DT / cosim.dt
        if abs(steps - round(steps)) > 1e-9:
            raise ValueError(f"the step {cosim.dt} s must divide the control step {CONTROL_DT} s")
        self.cosim = cosim
        # the reset's first step shows the controller the ego; where that step is a
        # whole control step (the kinematic world) the episode is that much longer, so
        # that the agent acts over all of ``duration`` in both worlds
        self._peek = cosim.dt if round(steps) == 1 else 0.0
        self.road = cosim.road
        self.duration, self.action_kind = float(duration), action
        self.reward_weights = reward or Reward()
        self.obs_noise, self.latency_steps, self.base_seed = obs_noise, latency_steps, seed
        first, last = self.store.time_range(self.road)
        split_time = 0.5 * (first + last) if split_time is None else float(split_time)
        if not first < split_time < last:
            raise ValueError(
                f"split_time {split_time:.0f} must lie inside the recording ({first:.0f} to "
                f"{last:.0f})"
            )
        window = (None, split_time) if split == "train" else (split_time, None)
        self.sampling = EpisodeSampling(roads=(self.road.value,), congested_share=1.0)
        limits = {self.road: road_limits(self.bundle, self.traffic, self.road)}
        self.cells = measure_cells(
            self.store, self.sampling, limits, self.duration, window=window,
            room_speed=CONGESTED_TRAVEL,
        )  # fmt: skip
        low, high = ACCEL_RANGE if action == "accel" else SPEED_RANGE
        self.action_space = gym.spaces.Box(low, high, shape=(1,), dtype=np.float32)
        self.observation_space = gym.spaces.Box(OBS_LOW, OBS_HIGH, dtype=np.float32)
        self.sim = None
        self.episode = -1
        self._command = 0.0
        self._last: Observation | None = None
        self._history: list[np.ndarray] = []
        self._followers: list[int] = []
        self._collisions = 0
        self._ego_accel = 0.0  # [m/s^2] measured over the last physics step
        self._states = None  # the world's states after the last physics step

    # -- Gymnasium ----------------------------------------------------------------------

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """A new episode: ``options={"episode": i}`` picks one, else drawn."""
        from twin.cosim.cosimulator import Cosimulator
        from twin.runners.episodes import PLACEMENT_ERRORS, draw_episode, episode_config

        super().reset(seed=seed)
        self.close()
        index = (options or {}).get("episode")
        for _ in range(20):  # an episode whose ego cannot be placed is drawn again
            k = int(self.np_random.integers(0, 2**31 - 1)) if index is None else int(index)
            spec = draw_episode(self.cells, self.sampling, self.base_seed, k)
            config = episode_config(
                self.cosim,
                spec,
                scenario="env",
                t_max=self.duration + self._peek,
                ego_controller="",
                camera=replace(self.cosim.camera, enabled=False),
            )
            self.sim = Cosimulator(config, self.traffic, self.bundle, controller=self._drive)
            try:
                self.sim.reset()
                break
            except PLACEMENT_ERRORS:
                self.sim.close()
                self.sim = None
                if index is not None:
                    raise
        if self.sim is None:
            raise RuntimeError("no episode could be placed in 20 draws")
        self.episode = k
        # before the agent's first action the ego holds its speed (a speed action of 0
        # would brake it at the full -3 m/s^2 through the step that shows it the ego)
        hold = self.sim.ego.speed if self.action_kind == "speed" else 0.0
        self._command, self._last, self._history = hold, None, []
        self._collisions, self._ego_accel, self._states = 0, 0.0, None
        self._advance()  # one world step: the controller sees the ego once
        rows = self.sim.log.vehicles()
        self._followers = followers(rows, self.sim.ego_id)
        return self._observation(), {"episode": k, "ego_record_id": self.sim.ego.id}

    def step(self, action):
        action = np.asarray(action, dtype=np.float64).reshape(-1)
        if action.size != 1 or not np.isfinite(action[0]):
            raise ValueError(f"the action must be one finite number, got {action!r}")
        low, high = float(self.action_space.low[0]), float(self.action_space.high[0])
        self._command = float(np.clip(action[0], low, high))
        fuel = 0.0
        steps = max(1, round(CONTROL_DT / self.sim.config.dt))
        for _ in range(steps):
            if self.sim.done:
                break
            fuel += self._advance()
        collided = len(self.sim.counters.collisions) > self._collisions and any(
            self.sim.ego_id in (a, b)
            for _, a, b in self.sim.counters.collisions[self._collisions :]
        )
        self._collisions = len(self.sim.counters.collisions)
        obs = self._observation()
        reward = self._reward(fuel)
        terminated = bool(collided)
        truncated = bool(self.sim.done) and not terminated
        info = {"fuel_g": fuel}
        if terminated or truncated:
            info["metrics"] = self._metrics()
        return obs, reward, terminated, truncated, info

    def close(self):
        if self.sim is not None:
            self.sim.close()
            self.sim = None

    # -- inside -------------------------------------------------------------------------

    def _drive(self, obs: Observation) -> EgoCommand:
        """The ego's controller: the agent's last action."""
        self._last = obs
        return EgoCommand(accel=action_accel(self.action_kind, self._command, obs.speed))

    def _advance(self) -> float:
        """One physics step; the fuel [g] of the AV and its followers in it (their
        measured acceleration over the step, as the run's energy figures)."""
        before = self._states if self._states is not None else self.sim.world.states()
        self.sim.step()
        states = self._states = self.sim.world.states()
        dt = self.sim.config.dt
        # ids are sorted in both; a vehicle new in this step has no acceleration yet
        where = np.minimum(np.searchsorted(before.id, states.id), max(before.id.size - 1, 0))
        known = before.id[where] == states.id if before.id.size else np.zeros(states.id.size, bool)
        accel = np.where(known, states.speed - before.speed[where], 0.0) / dt
        ego = states.id == self.sim.ego_id
        self._ego_accel = float(accel[ego][0]) if ego.any() else 0.0
        mine = np.isin(states.id, [self.sim.ego_id, *self._followers])
        if not mine.any():
            return 0.0
        _, _, pitch = self.sim.world.road.to_world(
            states.road[mine],
            states.x[mine] + 0.5 * self.sim.world.params.length[mine],
            states.y[mine],
        )
        speed = np.maximum(states.speed[mine], 0.0)
        return float(energy.RAV4_2019.rate(speed, accel[mine], np.tan(pitch)).sum() * dt)

    def _observation(self) -> np.ndarray:
        states = self._states
        x = float(states.x[states.id == self.sim.ego_id][0])
        ahead = ahead_speeds(self.traffic, self.road, self.sim.t, x, self.cosim.vel_default)
        vector = features(self._last, self._ego_accel, ahead)
        if self.obs_noise > 0:
            vector = vector * (1.0 + self.obs_noise * self.np_random.standard_normal(vector.size))
        vector = np.clip(vector, OBS_LOW, OBS_HIGH).astype(np.float32)
        self._history.append(vector)
        del self._history[: -(self.latency_steps + 1)]
        return self._history[0]

    def _reward(self, fuel: float) -> float:
        w = self.reward_weights
        obs = self._last
        k = obs.lanes.lanes.index(obs.lane)
        gap, lead = float(obs.lanes.leader_gap[k]), float(obs.lanes.leader_speed[k])
        reward = -w.fuel_weight * fuel
        if math.isfinite(gap) and obs.speed > 1.0 and gap / obs.speed > w.gap_max:
            reward -= w.gap_weight
        closing = obs.speed - lead if math.isfinite(gap) else 0.0
        if closing > 0 and gap / closing < w.ttc_min:
            reward -= w.ttc_weight
        return float(reward)

    def _metrics(self) -> dict:
        from twin.metrics.measure import measure
        from twin.metrics.table import flatten

        figures, _ = measure(self.sim, self.store, 0.0, 0.0)
        return flatten(figures)


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
    """Register ``i24twin/WaveDampening-v0`` with Gymnasium (done on import)."""
    if ENV_ID not in gym.registry:
        gym.register(id=ENV_ID, entry_point="twin.control.env:WaveDampeningEnv")


register_envs()
