"""Training wave-dampening policies on ``i24twin/WaveDampening-v0`` and running them in
the twin (the optional ``rl`` extra: ``pip install -e '.[rl]'``, stable-baselines3 and
PyTorch).

- :func:`train_ppo` trains PPO (stable-baselines3's, an MLP policy) on the env's
  ``train`` episodes, one or many at once (:mod:`twin.control.sb3_vec_env`, the
  batched vector env as a stable-baselines3 ``VecEnv``), and saves the model,
  atomically.
- ``twin.rl:policy`` is a controller factory: by default the MLP speed policy the twin
  ships (trained by ``twin train --algorithm es``, :mod:`twin.control.evolve`; numpy
  alone; the linear one of :mod:`twin.control.train` is ``wave_ars``), or
  ``--set controller.policy.model=PATH`` for another: a ``.json`` of ``twin train`` or
  any saved stable-baselines3 model (``.zip``), which sees what the env's agent saw
  (:func:`twin.control.env.features`) and decides every 0.1 s, as in training.

:class:`PolicyController` needs only an object with stable-baselines3's
``predict(observation, deterministic=True)``, so it runs (and is tested) without the
extra.
"""

import math
from pathlib import Path

import numpy as np

from twin.control.env import (
    CONTROL_DT,
    OBS_HIGH,
    OBS_LOW,
    WaveDampeningEnv,
    action_accel,
    ahead_speeds,
    features,
)
from twin.control.mlp import FORMAT as MLP_FORMAT
from twin.control.mlp import MLPDriver, MLPPolicy
from twin.control.policy import (
    DEFAULT,
    LinearSpeedPolicy,
    PolicyDriver,
    policy_document,
    shipped_policy,
)
from twin.core.errors import TwinError
from twin.traffic.controller_api import EgoCommand, Observation, controller_factory

EXTRA = "the rl extra (pip install -e '.[rl]': stable-baselines3 with PyTorch)"
_MODELS: dict[str, object] = {}  # loaded models by path, one load per process


class RLError(TwinError):
    """Training or loading a policy cannot go on (the extra missing, a bad model)."""


def _sb3():
    try:
        import stable_baselines3
    except ImportError:
        raise RLError(f"training and loading policies needs {EXTRA}") from None
    return stable_baselines3


def train_ppo(
    out: str | Path,
    *,
    steps: int = 4096,
    data: str | None = None,
    duration: float = 60.0,
    action: str = "accel",
    seed: int = 0,
    n_steps: int = 512,
    num_envs: int = 1,
) -> Path:
    """Train PPO on the env's ``train`` episodes and save it to ``out`` (``.zip``).

    Args:
        out: the model's path (``.zip`` added if missing); written atomically.
        steps: env steps of training (0.1 s each).
        data: the store (``embedded:morning`` by default).
        duration: [s] each training episode.
        action: ``accel`` or ``speed`` (see :mod:`twin.control.env`).
        seed: seeds the episodes and PPO.
        n_steps: env steps per PPO update (per episode of the batch).
        num_envs: 1: the single env (the physics world); more: that many episodes of
            the kinematic world stepped together by the batched core
            (:class:`twin.control.sb3_vec_env.Sb3VecEnv`), ``steps`` counted over all.

    Raises:
        RLError: the extra is missing. ValueError: a bad setting.
    """
    sb3 = _sb3()
    if not (isinstance(steps, int) and steps >= 1):
        raise ValueError(f"steps must be an integer >= 1, got {steps!r}")
    out = Path(out)
    if out.suffix != ".zip":
        out = out.with_name(out.name + ".zip")
    if not (isinstance(num_envs, int) and num_envs >= 1):
        raise ValueError(f"num_envs must be an integer >= 1, got {num_envs!r}")
    if num_envs == 1:
        env = WaveDampeningEnv(data, split="train", duration=duration, action=action, seed=seed)
    else:
        from twin.control.sb3_vec_env import Sb3VecEnv

        env = Sb3VecEnv(num_envs, data=data, split="train", duration=duration, action=action,
                        seed=seed)  # fmt: skip
    rollout = max(1, min(n_steps, steps // num_envs))
    try:
        model = sb3.PPO(
            "MlpPolicy",
            env,
            n_steps=rollout,
            batch_size=64 if num_envs == 1 else min(64 * num_envs, rollout * num_envs),
            seed=seed,
            device="cpu",
            verbose=0,
        )
        model.learn(total_timesteps=steps)
    finally:
        env.close()
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.stem}.partial.zip")
    model.save(tmp)
    tmp.replace(out)
    return out


class PolicyController:
    """A trained policy as the ego's controller (see the module doc).

    Args:
        model: has ``predict(observation, deterministic=True) -> (action, state)``.
        action: the env's action kind the model was trained with.
    """

    def __init__(self, model, action: str = "accel"):
        self.model, self.action = model, action
        self._sim = None
        self._every = 1
        self._calls = 0
        self._speed: float | None = None
        self._command = 0.0

    def bind(self, sim) -> None:
        """Called by the cosimulator: the recorded traffic and the clock."""
        self._sim = sim
        self._every = max(1, round(CONTROL_DT / sim.config.dt))

    def __call__(self, obs: Observation) -> EgoCommand:
        sim = self._sim
        if sim is None:
            raise RLError("PolicyController needs bind(sim) before it drives")
        dt = sim.config.dt
        measured = 0.0 if self._speed is None else (obs.speed - self._speed) / dt
        if self._calls % self._every == 0:
            ahead = ahead_speeds(sim.traffic, sim.road, sim.t, obs.x, sim.config.vel_default)
            vector = np.clip(features(obs, measured, ahead), OBS_LOW, OBS_HIGH)
            action, _ = self.model.predict(vector.astype(np.float32), deterministic=True)
            command = float(np.asarray(action, dtype=np.float64).reshape(-1)[0])
            if not math.isfinite(command):
                raise RLError(f"the policy returned a non-finite action {command}")
            self._command = command
        self._calls += 1
        self._speed = obs.speed
        return EgoCommand(accel=action_accel(self.action, self._command, obs.speed))


def load_policy(path: str | Path):
    """A saved stable-baselines3 model (PPO, SAC, TD3, A2C or DDPG, by trying each),
    loaded once per process.

    Raises:
        RLError: no such file, the extra missing, or not a model of these.
    """
    key = str(Path(path).resolve())
    if key in _MODELS:
        return _MODELS[key]
    if not Path(path).is_file():
        raise RLError(f"no policy model at {path}")
    sb3 = _sb3()
    errors = []
    for name in ("PPO", "SAC", "TD3", "A2C", "DDPG"):
        try:
            model = getattr(sb3, name).load(path, device="cpu")
        except Exception as error:  # the wrong algorithm's loader raises anything
            errors.append(f"{name}: {error}")
            continue
        _MODELS[key] = model
        return model
    raise RLError(f"{path} is not a stable-baselines3 model ({'; '.join(errors)[:300]})")


@controller_factory
def policy(config):
    """The policy of ``[controller.policy] model`` driving the ego: a linear speed
    policy file (``.json``, :mod:`twin.control.policy`, numpy alone) or a
    stable-baselines3 model (``.zip``, the ``rl`` extra); by default the policy the
    twin ships (:data:`twin.control.policy.DEFAULT`, the MLP ``wave_es_mlp_margin``; the
    MLPs ``wave_es_mlp_robust`` and ``wave_es_mlp`` and the linear ``wave_ars`` by
    name); a name without a suffix is one of
    the policies the twin ships (``twin/control/policies/NAME.json``). A ``.json`` is a
    linear speed policy (:mod:`twin.control.policy`) or an MLP speed policy
    (:mod:`twin.control.mlp`, ``twin train --algorithm es``), by its format."""
    settings = config.controller.policy
    model = settings.model or str(DEFAULT)
    if Path(model).suffix == "" and not Path(model).exists():
        model = str(shipped_policy(model))  # a name: a policy the twin ships
    if model.endswith(".json"):
        key = str(Path(model).resolve())
        if key not in _MODELS:  # one read per process (av_share builds one per AV)
            document = policy_document(model)
            kind = MLPPolicy if document.get("format") == MLP_FORMAT else LinearSpeedPolicy
            _MODELS[key] = kind.load(model)
        loaded = _MODELS[key]
        if isinstance(loaded, MLPPolicy):
            return MLPDriver(loaded, settings.obs_noise, settings.latency_steps, config.seed)
        _without_perturbation(settings, model)
        return PolicyDriver(loaded)
    _without_perturbation(settings, model)
    return PolicyController(load_policy(model), settings.action)


def _without_perturbation(settings, model: str) -> None:
    """Observation noise and latency are an MLP policy's settings: refused for others
    rather than ignored."""
    if settings.obs_noise or settings.latency_steps:
        raise RLError(
            f"controller.policy.obs_noise and latency_steps apply to an MLP policy; {model} "
            "is not one (train one with twin train --algorithm es, or study noise and "
            "latency in the env: WaveDampeningEnv(obs_noise=, latency_steps=))"
        )
