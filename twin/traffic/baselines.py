"""Baseline ego controllers for wave dampening, ready for ``--ego-controller``.

Each is named ``twin.controllers:NAME`` on the command line (or ``ego_controller`` in
the TOML) and takes its parameters from the run configuration's ``[controller.NAME]``
table (``--set controller.follower_stopper.desired_speed=25``):

- ``human``: the driver the ego would have had (the traffic manager's IDM with its
  emergency braking, with the run's behaviour: calibrated drivers where the store is
  calibrated); the reference the others are compared with.
- ``follower_stopper``: FollowerStopper (Stern et al. 2018, "Dissipation of
  stop-and-go waves via control of autonomous vehicles: field experiments",
  Transportation Research Part C 89): a commanded speed from the gap to the leader,
  the leader's speed and a desired speed U, between three quadratic gap thresholds.
- ``pi_saturation``: the same paper's PI controller with saturation: U is the ego's
  own mean speed over the last 38 s, blended with the leader's speed by the gap.
- ``acc``: a constant time-gap adaptive cruise control (a common commercial law,
  string-unstable at short gaps).

FollowerStopper and PI with saturation command a speed; the ego tracks it with a
low-level speed loop (``accel = gain (v_cmd - v)``, within the comfort limits). Their
formulas and parameter values are Stern et al.'s (2018); the ACC's gains are of the
order Milanes and Shladover (2014) report.
Under each of the three sits a safety layer, the drivers' emergency braking
(``[controller] emergency_braking``, on by default): PI with saturation as defined
keeps its target speed until the gap is within ``dx_s + gamma`` (6 m when closing),
which at highway speeds into a wave is a collision without it.

A controller here is built fresh for each episode (it keeps state: the speed history,
the last commanded speed), by a factory marked :func:`controller_factory` that takes
the run's configuration.
"""

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from twin.traffic.controller_api import EgoCommand, Observation, controller_factory, leader

#: The baselines by their command-line names (``twin.controllers:NAME``).
BASELINES = ("human", "follower_stopper", "pi_saturation", "acc")


def _positive(params, *names: str) -> None:
    for name in names:
        value = getattr(params, name)
        if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be > 0, got {value!r}")


def _check_desired_speed(value: float | None) -> None:
    if value is not None and not (math.isfinite(value) and value > 0):
        raise ValueError(f"desired_speed must be > 0 m/s (or unset: the ego's), got {value}")


@dataclass(frozen=True)
class SpeedLoop:
    """The low-level loop that tracks a commanded speed.

    Attributes:
        gain: [1/s] acceleration per m/s of speed error.
        max_accel: [m/s^2] comfort limit speeding up.
        max_decel: [m/s^2] limit slowing down (positive).
    """

    gain: float = 1.0
    max_accel: float = 1.5
    max_decel: float = 3.0

    def __post_init__(self):
        _positive(self, "gain", "max_accel", "max_decel")

    def accel(self, v_cmd: float, speed: float) -> float:
        """[m/s^2] toward ``v_cmd`` [m/s] from ``speed`` [m/s]."""
        return float(np.clip(self.gain * (v_cmd - speed), -self.max_decel, self.max_accel))


@dataclass(frozen=True)
class FollowerStopperParams:
    """FollowerStopper (Stern et al. 2018; ``docs/control.md``).

    Attributes:
        desired_speed: [m/s] U; ``None``: the ego's desired speed (the run's
            ``vel_default``).
        dx0: [m] (dx_1, dx_2, dx_3) at zero closing speed: 4.5, 5.25, 6.0.
        decel: [m/s^2] (d_1, d_2, d_3): 1.5, 1.0, 0.5.
        loop: the speed loop.
    """

    desired_speed: float | None = None
    dx0: tuple[float, float, float] = (4.5, 5.25, 6.0)
    decel: tuple[float, float, float] = (1.5, 1.0, 0.5)
    loop: SpeedLoop = field(default_factory=SpeedLoop)

    def __post_init__(self):
        _check_desired_speed(self.desired_speed)
        if len(self.dx0) != 3 or not 0 < self.dx0[0] < self.dx0[1] < self.dx0[2]:
            raise ValueError(f"dx0 must be three increasing gaps > 0 m, got {self.dx0}")
        if len(self.decel) != 3 or not all(d > 0 and math.isfinite(d) for d in self.decel):
            raise ValueError(f"decel must be three decelerations > 0, got {self.decel}")


def follower_stopper_speed(
    gap: float, speed: float, leader_speed: float, desired_speed: float, p: FollowerStopperParams
) -> float:
    """FollowerStopper's commanded speed [m/s] (Stern et al. 2018; ``docs/control.md``).

    Args:
        gap: [m] to the leader (``inf``: none). speed, leader_speed: [m/s].
        desired_speed: [m/s] U.
    """
    if not math.isfinite(gap):
        return desired_speed
    closing = min(leader_speed - speed, 0.0)
    dx1, dx2, dx3 = (x + closing**2 / (2.0 * d) for x, d in zip(p.dx0, p.decel, strict=True))
    w = min(max(leader_speed, 0.0), desired_speed)
    if gap <= dx1:
        return 0.0
    if gap <= dx2:
        return w * (gap - dx1) / (dx2 - dx1)
    if gap <= dx3:
        return w + (desired_speed - w) * (gap - dx2) / (dx3 - dx2)
    return desired_speed


class FollowerStopper:
    """FollowerStopper driving the ego (see :func:`follower_stopper_speed`)."""

    def __init__(self, params: FollowerStopperParams):
        self.params = params

    def __call__(self, obs: Observation) -> EgoCommand:
        gap, leader_speed = leader(obs)
        desired = self.params.desired_speed or obs.desired_speed
        v_cmd = follower_stopper_speed(gap, obs.speed, leader_speed, desired, self.params)
        return EgoCommand(accel=self.params.loop.accel(v_cmd, obs.speed))


@dataclass(frozen=True)
class PISaturationParams:
    """PI with saturation (Stern et al. 2018; ``docs/control.md``).

    Attributes:
        window: [s] the own-speed average that sets U (38 s).
        gap_low: [m] g_l, the gap from which the target rises by ``catch_up`` (7).
        gap_high: [m] g_u, the gap by which it has risen by all of ``catch_up`` (30).
        catch_up: [m/s] v_catch (1).
        safe_gap_min: [m] the floor of dx_s = max(2 (v_lead - v), floor) (4).
        gamma: [m] the blending width (2).
        loop: the speed loop.
    """

    window: float = 38.0
    gap_low: float = 7.0
    gap_high: float = 30.0
    catch_up: float = 1.0
    safe_gap_min: float = 4.0
    gamma: float = 2.0
    loop: SpeedLoop = field(default_factory=SpeedLoop)

    def __post_init__(self):
        _positive(self, "window", "gap_low", "safe_gap_min", "gamma")
        if not self.gap_high > self.gap_low:
            raise ValueError(f"gap_high {self.gap_high} must exceed gap_low {self.gap_low}")
        if not (math.isfinite(self.catch_up) and self.catch_up >= 0):
            raise ValueError(f"catch_up must be >= 0 m/s, got {self.catch_up}")


def pi_saturation_speed(
    gap: float,
    speed: float,
    leader_speed: float,
    mean_speed: float,
    last_command: float,
    p: PISaturationParams,
) -> float:
    """PI with saturation's new commanded speed [m/s] (Stern et al. 2018; ``docs/control.md``).

    Args:
        gap: [m] to the leader (``inf``: none, the target alone). speed, leader_speed:
            [m/s]. mean_speed: [m/s] U, the ego's mean over the window.
        last_command: [m/s] the previous commanded speed.
    """
    target = mean_speed + p.catch_up * min(
        max((gap - p.gap_low) / (p.gap_high - p.gap_low), 0.0), 1.0
    )
    if not math.isfinite(gap):
        return target
    safe_gap = max(2.0 * (leader_speed - speed), p.safe_gap_min)
    alpha = min(max((gap - safe_gap) / p.gamma, 0.0), 1.0)
    beta = 1.0 - 0.5 * alpha
    return beta * (alpha * target + (1.0 - alpha) * leader_speed) + (1.0 - beta) * last_command


class PISaturation:
    """PI with saturation driving the ego (see :func:`pi_saturation_speed`)."""

    def __init__(self, params: PISaturationParams):
        self.params = params
        self._speeds: deque[tuple[float, float]] = deque()  # (time, speed)
        self._sum = 0.0
        self._command: float | None = None

    def __call__(self, obs: Observation) -> EgoCommand:
        p = self.params
        self._speeds.append((obs.time, obs.speed))
        self._sum += obs.speed
        while self._speeds[0][0] < obs.time - p.window:
            self._sum -= self._speeds.popleft()[1]
        mean = self._sum / len(self._speeds)
        gap, leader_speed = leader(obs)
        last = obs.speed if self._command is None else self._command
        self._command = max(pi_saturation_speed(gap, obs.speed, leader_speed, mean, last, p), 0.0)
        return EgoCommand(accel=p.loop.accel(self._command, obs.speed))


@dataclass(frozen=True)
class ACCParams:
    """Constant time-gap ACC: ``a = k1 (dx - s0 - h v) + k2 (v_lead - v)`` behind a
    leader, ``a = cruise_gain (U - v)`` without one, the smaller of the two where both
    apply, within the comfort limits.

    Attributes:
        time_gap: [s] h, the time gap kept (1.5).
        min_gap: [m] s0, the gap kept at a standstill (2).
        k1: [1/s^2] gain on the gap error (0.23).
        k2: [1/s] gain on the speed difference to the leader (0.07).
        desired_speed: [m/s] U; ``None``: the ego's desired speed.
        cruise_gain: [1/s] speed-keeping gain without a leader (0.4).
        max_accel: [m/s^2] comfort limit speeding up (1.5).
        max_decel: [m/s^2] comfort limit slowing down, positive (3.0).
    """

    time_gap: float = 1.5
    min_gap: float = 2.0
    k1: float = 0.23
    k2: float = 0.07
    desired_speed: float | None = None
    cruise_gain: float = 0.4
    max_accel: float = 1.5
    max_decel: float = 3.0

    def __post_init__(self):
        _positive(self, "time_gap", "k1", "cruise_gain", "max_accel", "max_decel")
        if not (math.isfinite(self.min_gap) and self.min_gap >= 0):
            raise ValueError(f"min_gap must be >= 0 m, got {self.min_gap}")
        if not (math.isfinite(self.k2) and self.k2 >= 0):
            raise ValueError(f"k2 must be >= 0 1/s, got {self.k2}")
        _check_desired_speed(self.desired_speed)


def acc_accel(gap: float, speed: float, leader_speed: float, desired_speed: float, p: ACCParams):
    """The ACC's acceleration [m/s^2] (see :class:`ACCParams`)."""
    accel = p.cruise_gain * (desired_speed - speed)
    if math.isfinite(gap):
        follow = p.k1 * (gap - p.min_gap - p.time_gap * speed) + p.k2 * (leader_speed - speed)
        accel = min(accel, follow)
    return float(np.clip(accel, -p.max_decel, p.max_accel))


class ACC:
    """Constant time-gap ACC driving the ego (see :func:`acc_accel`)."""

    def __init__(self, params: ACCParams):
        self.params = params

    def __call__(self, obs: Observation) -> EgoCommand:
        gap, leader_speed = leader(obs)
        desired = self.params.desired_speed or obs.desired_speed
        return EgoCommand(accel=acc_accel(gap, obs.speed, leader_speed, desired, self.params))


class Human:
    """The driver the ego would have had: the traffic manager's command for it."""

    def __call__(self, obs: Observation) -> EgoCommand:
        return EgoCommand(accel=obs.default_accel)


@dataclass(frozen=True)
class PolicySettings:
    """A trained policy driving the ego (``twin.rl:policy``, the ``rl`` extra).

    Attributes:
        model: path of a policy: a linear or MLP speed policy of ``twin train``
            (``.json``) or a stable-baselines3 model (``.zip``) trained on
            ``i24twin/WaveDampening-v0``; or the name of one the twin ships
            (``wave_es_mlp_margin``, ``wave_es_mlp_robust``, ``wave_es_mlp``, ``wave_ars``);
            empty: the default it ships (``wave_es_mlp_margin``).
        action: a stable-baselines3 model's action in the env: ``accel`` or ``speed``.
        obs_noise: [-] an MLP policy's observation noise, as the env's: every value it
            sees multiplied by ``1 + obs_noise N(0, 1)`` (0: none; robustness studies).
        latency_steps: [-] control steps (0.1 s) an MLP policy's observation lags, as the
            env's.
    """

    model: str = ""
    action: str = "accel"
    obs_noise: float = 0.0
    latency_steps: int = 0

    def __post_init__(self):
        if self.action not in ("accel", "speed"):
            raise ValueError(f"action must be 'accel' or 'speed', got {self.action!r}")
        check_perturbation(self.obs_noise, self.latency_steps)


def check_perturbation(obs_noise, latency_steps) -> None:
    """Raise ValueError naming ``obs_noise`` unless it is a finite number >= 0, or
    ``latency_steps`` unless it is an integer >= 0 (a policy's observation noise and
    latency, :class:`PolicySettings`)."""
    if not (
        isinstance(obs_noise, int | float | np.floating)
        and not isinstance(obs_noise, bool)
        and math.isfinite(obs_noise)
        and obs_noise >= 0
    ):
        raise ValueError(f"obs_noise must be a number >= 0, got {obs_noise!r}")
    if not (
        isinstance(latency_steps, int | np.integer)
        and not isinstance(latency_steps, bool)
        and latency_steps >= 0
    ):
        raise ValueError(f"latency_steps must be an integer >= 0, got {latency_steps!r}")


@dataclass(frozen=True)
class ControllerSettings:
    """The baseline controllers' parameters (the run configuration's ``[controller]``
    tables).

    Attributes:
        emergency_braking: the safety layer of FollowerStopper, PI with saturation and
            the ACC: where staying clear of the leader (if it keeps braking as it does)
            needs harder braking than the controller asks, the ego brakes as hard as
            needed, by the same test as the drivers' emergency braking
            (:func:`twin.traffic.kernels.longitudinal.required_decel`). ``False``: the
            controller's command alone (``human`` has the drivers' braking anyway).
        follower_stopper: FollowerStopper's parameters (``twin.controllers:follower_stopper``).
        pi_saturation: PI with saturation's parameters (``twin.controllers:pi_saturation``).
        acc: the constant time-gap ACC's parameters (``twin.controllers:acc``).
        policy: a trained policy's model (``twin.rl:policy``).
    """

    emergency_braking: bool = True
    follower_stopper: FollowerStopperParams = field(default_factory=FollowerStopperParams)
    pi_saturation: PISaturationParams = field(default_factory=PISaturationParams)
    acc: ACCParams = field(default_factory=ACCParams)
    policy: PolicySettings = field(default_factory=PolicySettings)


@controller_factory
def human(config) -> Human:
    """The ego's own driver (a reference for the others)."""
    return Human()


@controller_factory
def follower_stopper(config) -> FollowerStopper:
    """FollowerStopper with ``[controller.follower_stopper]``."""
    return _guarded(FollowerStopper(config.controller.follower_stopper), config)


@controller_factory
def pi_saturation(config) -> PISaturation:
    """PI with saturation with ``[controller.pi_saturation]``."""
    return _guarded(PISaturation(config.controller.pi_saturation), config)


@controller_factory
def acc(config) -> ACC:
    """Constant time-gap ACC with ``[controller.acc]``."""
    return _guarded(ACC(config.controller.acc), config)


def _guarded(controller, config):
    """``controller`` with the run's ``[controller] emergency_braking`` setting, which
    the traffic manager reads (see :class:`ControllerSettings`)."""
    controller.emergency_braking = config.controller.emergency_braking
    return controller
