"""A small multilayer perceptron wave-dampening policy that runs on numpy alone: what it
sees, what it commands, its file, and the controller that drives the ego with it.

It sees the env's observation (:data:`twin.control.env.OBSERVATION`: own speed and
acceleration, leader's and follower's gaps and speeds, the recorded speeds ahead per
lane) as :data:`INPUTS` scaled features: speeds relative to its own, gaps and its time
gap to the leader, each of order one (:func:`inputs`). The recorded speeds ahead carry
what is coming; a policy may keep a memory of what it saw (:class:`Actor`): its
observations smoothed (``smoothing``, against observation noise) and its jerk limit
counted from its own previous command (``jerk_from``).

It commands a speed every 0.1 s, tracked by the baselines' speed loop (``1.0 (v_cmd -
v)`` within the env's limits) whose acceleration changes by at most :data:`JERK_LIMIT`
(the action is smoothed: jerk limited, from the acceleration it measured over the last
step, or, ``jerk_from="command"``, from its own previous command)::

    v_cmd = clip(leader_speed + SPAN tanh(MLP(inputs)), 0, 35 m/s)
    accel = a_measured + clip(clip(v_cmd - v, -3, 1.5) - a_measured, -J dt, J dt)

with two tanh hidden layers (:data:`HIDDEN`); the env's action is that acceleration
(``accel``). With a zero output layer it follows its
leader's speed (the linear policy's starting point), whatever the hidden weights, so
training starts from a driver that is safe with the safety layer beneath it: the
drivers' emergency braking overrides it where the room is used up (counted in
``safety_override_s``), in training (the env's ``safety``) as in the twin
(:class:`MLPDriver`).

Its weights are one flat vector (:func:`unpack` gives the layers), kept in a JSON file
with how they were trained (:class:`MLPPolicy`). :func:`forward` evaluates many sets of
weights at once, one per row of observations: the population of an evolution strategy
(:mod:`twin.control.evolve`).
"""

import itertools
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from twin.control.env import (
    ACCEL_RANGE,
    CONTROL_DT,
    OBS_HIGH,
    OBS_LOW,
    SPEED_GAIN,
    SPEED_RANGE,
    ahead_speeds,
    features,
)
from twin.control.policy import PolicyError, checked_document, is_numbers, write_policy_document
from twin.traffic.baselines import check_perturbation
from twin.traffic.controller_api import EgoCommand, Observation

FORMAT = "i24-twin-mlp-speed-policy"
VERSION = 1
HIDDEN = (32, 32)  # units of the hidden layers
SPAN = 5.0  # [m/s] the command's reach around the leader's speed
JERK_LIMIT = 2.0  # [m/s^3] the most its commanded acceleration changes per second
SPEED_SCALE = 10.0  # [m/s] speed differences are inputs in these units
GAP_SCALE = 100.0  # [m] gaps likewise
TIME_GAP_CAP = 10.0  # [s] the time gap input is capped here (and is this with no leader)
#: What its jerk limit counts from (:class:`Actor`).
JERK_FROM = ("measured", "command")
#: [m/s^2] a measured acceleration this far from its own last command was another's
#: decision (the safety layer's): its jerk limit then counts from the measured one.
OVERRIDDEN = 1.0
#: How many of its last commands a measured acceleration is compared with (observations
#: up to this many control steps late still match their command).
COMMANDS_KEPT = 10
#: A filtered gap restarts from the observation where the two differ by more than this
#: share of the gap (4 sd of 5 % observation noise; a cut-in or a new leader)...
GATE = 0.2
#: [m] ... and by more than this.
GATE_FLOOR = 2.0
#: A leader's or follower's speed that jumps by more than this share of itself (6 sd of
#: 5 % noise: a wrong restart lets the noise in) ...
SPEED_GATE = 0.3
#: [m/s] ... and by more than this is another vehicle's too (one appearing far ahead).
SPEED_GATE_FLOOR = 3.0
#: The inputs, in order (:func:`inputs`).
INPUTS = (
    "speed",
    "accel",
    "leader_gap",
    "leader_speed_diff",
    "follower_gap",
    "follower_speed_diff",
    "time_gap",
    *(f"ahead_{k}_diff" for k in range(12)),
)
N_INPUTS = len(INPUTS)


def n_weights(hidden: tuple[int, ...] = HIDDEN) -> int:
    """The length of the flat weight vector of a network with these hidden layers."""
    sizes = (N_INPUTS, *hidden, 1)
    return sum(a * b + b for a, b in itertools.pairwise(sizes))


def unpack(
    theta: np.ndarray, hidden: tuple[int, ...] = HIDDEN
) -> list[tuple[np.ndarray, np.ndarray]]:
    """The layers ``[(W (..., out, in), b (..., out)), ...]`` of flat weights ``theta``
    (..., :func:`n_weights`): any leading axes are kept (one network per row)."""
    sizes = (N_INPUTS, *hidden, 1)
    lead = theta.shape[:-1]
    layers, at = [], 0
    for a, b in itertools.pairwise(sizes):
        w = theta[..., at : at + a * b].reshape(*lead, b, a)
        at += a * b
        layers.append((w, theta[..., at : at + b]))
        at += b
    return layers


def initial_weights(seed: int, hidden: tuple[int, ...] = HIDDEN) -> np.ndarray:
    """Hidden layers drawn (scaled by 1/sqrt(fan-in), from ``seed``), the output layer
    zero: the network starts by following its leader's speed."""
    rng = np.random.default_rng([seed, 0x6D6C70])
    sizes = (N_INPUTS, *hidden, 1)
    parts = []
    for k, (a, b) in enumerate(itertools.pairwise(sizes)):
        last = k == len(sizes) - 2
        parts.append(np.zeros(a * b) if last else rng.standard_normal(a * b) / math.sqrt(a))
        parts.append(np.zeros(b))
    return np.concatenate(parts)


def inputs(obs: np.ndarray) -> np.ndarray:
    """(..., N_INPUTS) scaled features of env observations ``obs`` (..., 18)."""
    obs = np.asarray(obs, dtype=np.float64)
    speed, accel = obs[..., 0], obs[..., 1]
    leader_gap, leader_speed = obs[..., 2], obs[..., 3]
    follower_gap, follower_speed = obs[..., 4], obs[..., 5]
    time_gap = np.minimum(np.maximum(leader_gap, 0.0) / np.maximum(speed, 1.0), TIME_GAP_CAP)
    columns = [
        speed / 30.0,
        accel / 3.0,
        leader_gap / GAP_SCALE,
        (leader_speed - speed) / SPEED_SCALE,
        follower_gap / GAP_SCALE,
        (follower_speed - speed) / SPEED_SCALE,
        time_gap / TIME_GAP_CAP,
        *((obs[..., 6 + k] - speed) / SPEED_SCALE for k in range(12)),
    ]
    return np.stack(columns, axis=-1)


def forward(theta: np.ndarray, obs: np.ndarray, hidden: tuple[int, ...] = HIDDEN) -> np.ndarray:
    """[m/s] the speed commands (...,) of observations ``obs`` (..., 18), each row with
    its own weights ``theta`` (..., :func:`n_weights`) or all with one (``theta``
    (n_weights,))."""
    x = inputs(obs)
    layers = unpack(np.asarray(theta, dtype=np.float64), hidden)
    for k, (w, b) in enumerate(layers):
        x = np.einsum("...oi,...i->...o", w, x) + b
        if k < len(layers) - 1:
            x = np.tanh(x)
    leader_speed = np.asarray(obs, dtype=np.float64)[..., 3]
    return np.clip(leader_speed + SPAN * np.tanh(x[..., 0]), *SPEED_RANGE)


def accel_command(speed_command: np.ndarray, obs: np.ndarray) -> np.ndarray:
    """[m/s^2] the accelerations (...,) that track ``speed_command`` (...,) from
    observations ``obs`` (..., 18): the speed loop's, changed by at most
    ``JERK_LIMIT dt`` from the acceleration measured over the last step."""
    obs = np.asarray(obs, dtype=np.float64)
    wanted = np.clip(SPEED_GAIN * (speed_command - obs[..., 0]), *ACCEL_RANGE)
    measured = np.clip(obs[..., 1], *ACCEL_RANGE)
    step = JERK_LIMIT * CONTROL_DT
    return measured + np.clip(wanted - measured, -step, step)


def act(theta: np.ndarray, obs: np.ndarray, hidden: tuple[int, ...] = HIDDEN) -> np.ndarray:
    """[m/s^2] the env's ``accel`` actions (...,) of observations ``obs`` (..., 18),
    as :func:`forward` takes ``theta``: a policy with no memory (no smoothing, its jerk
    limit from the measured acceleration)."""
    return accel_command(forward(theta, obs, hidden), obs)


class Actor:
    """A policy's decisions over one drive, for ``n`` vehicles at once (one row of
    observations each): what it remembers between control steps.

    * ``smoothing`` [s] > 0: it decides on a filtered estimate of its observations
      instead of each one as it comes (against observation noise), every value but its
      measured acceleration. Each step the estimate is first carried forward by what it
      knows moved (:func:`predicted`: its own speed by its measured acceleration, the
      gaps by the speed differences), then moved towards the new observation by
      ``dt / (smoothing + dt)``: an exponential moving average of time constant
      ``smoothing`` with no lag behind its own acceleration, so its speed loop is not
      slowed by the filter (its safety layer's braking included). A leader or
      follower gap that jumps by more than :data:`GATE` of itself (at least
      :data:`GATE_FLOOR`), or whose speed does by :data:`SPEED_GATE` (at least
      :data:`SPEED_GATE_FLOOR`), as at a cut-in, a lane change or a leader appearing
      far ahead, is another vehicle: that gap and its speed restart from the
      observation. The first observation starts it.
    * ``jerk_from="command"``: its jerk limit counts from its own previous command
      (which it knows exactly) instead of the acceleration it measured (which noise and
      latency blur); the first decision counts from the measured one, and so does one
      where the measured acceleration is more than :data:`OVERRIDDEN` from every
      command of its last :data:`COMMANDS_KEPT` (the safety layer braked instead: it goes
      on from what the vehicle did; a late measurement matches an older command).

    With neither (``smoothing=0``, ``jerk_from="measured"``) it is :func:`act`, bit for
    bit.
    """

    def __init__(self, hidden: tuple[int, ...] = HIDDEN, smoothing: float = 0.0,
                 jerk_from: str = "measured"):  # fmt: skip
        check_memory(smoothing, jerk_from)
        self.hidden, self.smoothing, self.jerk_from = tuple(hidden), float(smoothing), jerk_from
        self._estimate: np.ndarray | None = None  # the filtered observations
        self._commands: list[np.ndarray] = []  # the last COMMANDS_KEPT commands, newest last

    def __call__(self, theta: np.ndarray, obs: np.ndarray) -> np.ndarray:
        """[m/s^2] the ``accel`` actions (n,) for observations ``obs`` (n, 18) with
        weights ``theta`` (as :func:`forward` takes them)."""
        obs = np.asarray(obs, dtype=np.float64)
        seen = obs
        if self.smoothing > 0:
            if self._estimate is None:
                self._estimate = obs.copy()
            else:
                self._estimate = filtered(self._estimate, obs, self.smoothing)
            seen = self._estimate  # its measured acceleration is the observation's
        speed_command = forward(theta, seen, self.hidden)
        if self.jerk_from == "command" and self._commands:
            wanted = np.clip(SPEED_GAIN * (speed_command - seen[..., 0]), *ACCEL_RANGE)
            step = JERK_LIMIT * CONTROL_DT
            # its own command, unless what it measured matches none it gave lately
            # (the safety layer braked): then from what it measured
            measured = np.clip(obs[..., 1], *ACCEL_RANGE)
            off = np.min([np.abs(measured - c) for c in self._commands], axis=0)
            reference = np.where(off > OVERRIDDEN, measured, self._commands[-1])
            command = reference + np.clip(wanted - reference, -step, step)
        else:
            command = accel_command(speed_command, seen)
        self._commands.append(command)
        del self._commands[:-COMMANDS_KEPT]
        return command


def predicted(estimate: np.ndarray) -> np.ndarray:
    """Filtered observations ``estimate`` (..., 18) carried one control step forward by
    what they say moves: its own speed by its measured acceleration, the leader's gap
    by the leader's speed less its own, the follower's by its own less the
    follower's (the other values held). Its own speed is carried by the acceleration
    as measured, the safety layer's braking too, and not below 0."""
    ahead = estimate.copy()
    speed, accel = estimate[..., 0], estimate[..., 1]
    ahead[..., 0] = np.maximum(speed + accel * CONTROL_DT, 0.0)  # the safety layer's too
    ahead[..., 2] += (estimate[..., 3] - speed) * CONTROL_DT
    ahead[..., 4] += (speed - estimate[..., 5]) * CONTROL_DT
    return ahead


def filtered(estimate: np.ndarray, obs: np.ndarray, smoothing: float) -> np.ndarray:
    """The filtered observations after observation ``obs`` (..., 18): ``estimate``
    carried forward (:func:`predicted`, with the new measured acceleration) and moved
    ``dt / (smoothing + dt)`` towards ``obs`` (the measured acceleration is ``obs``'s);
    a gap (and its vehicle's speed) that jumped past the gate (:class:`Actor`), or whose
    vehicle's speed did, restarts from ``obs``."""
    estimate = estimate.copy()
    estimate[..., 1] = obs[..., 1]
    ahead = predicted(estimate)
    out = ahead + CONTROL_DT / (smoothing + CONTROL_DT) * (obs - ahead)
    for gap, speed in ((2, 3), (4, 5)):
        jumped = (
            np.abs(obs[..., gap] - ahead[..., gap])
            > np.maximum(GATE * np.abs(ahead[..., gap]), GATE_FLOOR)
        ) | (
            np.abs(obs[..., speed] - ahead[..., speed])
            > np.maximum(SPEED_GATE * np.abs(ahead[..., speed]), SPEED_GATE_FLOOR)
        )
        out[..., gap] = np.where(jumped, obs[..., gap], out[..., gap])
        out[..., speed] = np.where(jumped, obs[..., speed], out[..., speed])
    out[..., 1] = obs[..., 1]  # the measured acceleration as it comes
    return out


def check_memory(smoothing, jerk_from) -> None:
    """Raises ValueError naming a bad ``smoothing`` (a number >= 0 [s]) or
    ``jerk_from`` (one of :data:`JERK_FROM`)."""
    if (
        isinstance(smoothing, bool)
        or not isinstance(smoothing, int | float)
        or not (math.isfinite(smoothing) and smoothing >= 0)
    ):
        raise ValueError(f"smoothing must be a number of seconds >= 0, got {smoothing!r}")
    if jerk_from not in JERK_FROM:
        raise ValueError(f"jerk_from must be one of {JERK_FROM}, got {jerk_from!r}")


@dataclass(frozen=True)
class MLPPolicy:
    """An MLP speed policy (see the module doc).

    Attributes:
        weights: (:func:`n_weights`,) the flat weights.
        hidden: the hidden layers' units.
        smoothing: [s] its observations' smoothing (:class:`Actor`; 0: none).
        jerk_from: what its jerk limit counts from (:class:`Actor`).
        about: how it was trained (free-form, kept in the file).
    """

    weights: np.ndarray
    hidden: tuple[int, ...] = HIDDEN
    smoothing: float = 0.0
    jerk_from: str = "measured"
    about: dict = field(default_factory=dict, compare=False)

    def __post_init__(self):
        hidden = tuple(int(h) for h in self.hidden)
        weights = np.asarray(self.weights, dtype=np.float64).reshape(-1)
        if not hidden or min(hidden) < 1:
            raise PolicyError(
                f"an MLP policy needs hidden layers of >= 1 unit, got {self.hidden!r}"
            )
        if weights.size != n_weights(hidden) or not np.all(np.isfinite(weights)):
            raise PolicyError(
                f"an MLP policy with hidden layers {hidden} has {n_weights(hidden)} finite "
                f"weights, got {weights.size}"
                + ("" if np.all(np.isfinite(weights)) else " with non-finite values")
            )
        try:
            check_memory(self.smoothing, self.jerk_from)
        except ValueError as error:
            raise PolicyError(f"an MLP policy's {error}") from None
        object.__setattr__(self, "hidden", hidden)
        object.__setattr__(self, "weights", weights)
        object.__setattr__(self, "smoothing", float(self.smoothing))

    def actor(self) -> Actor:
        """A fresh :class:`Actor` of this policy: its memory for one drive."""
        return Actor(self.hidden, self.smoothing, self.jerk_from)

    def speed_command(self, obs: np.ndarray) -> float:
        """[m/s] the commanded speed for one env observation (18,)."""
        return float(forward(self.weights, np.asarray(obs), self.hidden))

    def accel(self, obs: np.ndarray) -> float:
        """[m/s^2] the env's ``accel`` action for one env observation (18,), decided
        with no memory (as a drive's first decision is; :meth:`actor` remembers)."""
        return float(self.actor()(self.weights, np.asarray(obs)))

    def predict(self, observation, state: "Actor | None" = None, episode_start=None,
                deterministic: bool = True):  # fmt: skip
        """stable-baselines3's ``predict``, as its recurrent policies have it: (``accel``
        action (1,), state) for one observation, where the state is the policy's memory
        (:class:`Actor`). Pass it back with the next observation to decide with the
        memory (``state=None``, or ``episode_start`` true, starts a fresh one); a policy
        with no memory decides the same either way."""
        if state is None or (episode_start is not None and bool(np.any(episode_start))):
            state = self.actor()
        action = state(self.weights, np.asarray(observation, dtype=np.float64))
        return np.array([float(action)], dtype=np.float32), state

    def save(self, path: str | Path) -> Path:
        """Write the policy as JSON, atomically."""
        return write_policy_document(path, {
            "format": FORMAT,
            "version": VERSION,
            "inputs": list(INPUTS),
            "hidden": list(self.hidden),
            **({"smoothing_s": self.smoothing} if self.smoothing else {}),
            **({"jerk_from": self.jerk_from} if self.jerk_from != "measured" else {}),
            "weights": [float(w) for w in self.weights],
            "about": self.about,
        })  # fmt: skip

    @classmethod
    def load(cls, path: str | Path) -> "MLPPolicy":
        """Read a policy file.

        Raises:
            PolicyError: no such file, not JSON, or not a policy of this format.
        """
        path = Path(path)
        document = checked_document(path, FORMAT, VERSION)
        if document.get("inputs") != list(INPUTS):
            raise PolicyError(f"{path}: inputs {document.get('inputs')!r} are not {INPUTS}")
        weights, hidden = document.get("weights"), document.get("hidden")
        if not is_numbers(weights) or not isinstance(hidden, list):
            raise PolicyError(f"{path}: weights and hidden must be lists of numbers")
        smoothing = document.get("smoothing_s", 0.0)
        jerk_from = document.get("jerk_from", "measured")
        try:
            return cls(np.array(weights, dtype=np.float64), tuple(hidden), smoothing, jerk_from,
                       document.get("about", {}))  # fmt: skip
        except (PolicyError, TypeError, ValueError) as error:
            raise PolicyError(f"{path}: {error}") from None


class MLPDriver:
    """An :class:`MLPPolicy` as the ego's controller: it decides every
    :data:`~twin.control.env.CONTROL_DT` from what the env's agent would see (its
    acceleration measured over that step) and holds its command between, with the
    drivers' emergency braking beneath it (``emergency_braking``), as in training.

    ``obs_noise`` and ``latency_steps`` put the env's observation noise and latency
    (:class:`~twin.control.env.WaveDampeningEnv`) between the twin and the policy: every
    value of its observation multiplied by ``1 + obs_noise N(0, 1)`` (clipped to the
    observation's bounds; the draws from ``seed`` and the vehicle's id), and the
    observation it decides on ``latency_steps`` control steps old.

    Needs ``bind(sim)`` (the cosimulator calls it) for the recorded traffic ahead.
    """

    emergency_braking = True

    def __init__(
        self, policy: MLPPolicy, obs_noise: float = 0.0, latency_steps: int = 0, seed: int = 0
    ):
        try:
            check_perturbation(obs_noise, latency_steps)
        except ValueError as error:
            raise PolicyError(str(error)) from None
        self.policy = policy
        self.obs_noise, self.latency_steps, self.seed = obs_noise, latency_steps, seed
        self._rng: np.random.Generator | None = None  # drawn for the vehicle it drives
        self._seen: list[np.ndarray] = []  # the last latency_steps + 1 observations
        self._actor = policy.actor()
        self._sim = None
        self._every = 1
        self._calls = 0
        self._at_decision: float | None = None  # its speed at the last decision
        self._command = 0.0

    def bind(self, sim) -> None:
        """Called by the cosimulator: the recorded traffic and the clock."""
        self._sim = sim
        self._every = max(1, round(CONTROL_DT / sim.config.dt))

    def __call__(self, obs: Observation) -> EgoCommand:
        sim = self._sim
        if sim is None:
            raise PolicyError("MLPDriver needs bind(sim) before it drives")
        if self._calls % self._every == 0:
            # the env's measured acceleration: over the last control step
            before = self._at_decision
            measured = 0.0 if before is None else (obs.speed - before) / CONTROL_DT
            ahead = ahead_speeds(sim.traffic, sim.road, sim.t, obs.x, sim.config.vel_default)
            vector = features(obs, measured, ahead)
            if self.obs_noise > 0:
                if self._rng is None:
                    self._rng = np.random.default_rng([self.seed, obs.id])
                vector = vector * (1.0 + self.obs_noise * self._rng.standard_normal(vector.size))
            vector = np.clip(vector, OBS_LOW, OBS_HIGH).astype(np.float32)  # as the env's
            self._seen.append(vector)
            del self._seen[: -(self.latency_steps + 1)]
            self._command = float(self._actor(self.policy.weights, self._seen[0]))
            self._at_decision = obs.speed
        self._calls += 1
        return EgoCommand(accel=float(self._command))
