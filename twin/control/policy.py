"""Wave-dampening policies that run on numpy alone: a linear speed policy over what a
connected AV knows, its file format, and the controller that drives the ego with it.

The policy commands a speed every 0.1 s (the env's control step), tracked by the
baselines' speed loop (``accel = 1.0 (v_cmd - v)`` within the env's limits), with the
drivers' emergency braking beneath it as the baselines have (counted in
``safety_override_s``)::

    v_cmd = clip(w . f, 0, 35 m/s)

over the features :data:`FEATURES`: a bias, the ego's speed, its leader's speed, its
time gap, the recorded mean speed of its lane 0-200, 200-400 and 400-600 m ahead (what
a connected vehicle could be told; :func:`twin.control.env.ahead_speeds`), and its own
mean speed over the last 30 s (the memory PI with saturation keeps). A linear policy
is what Augmented Random Search trains (Mania, Guy, Recht 2018, "Simple random search
of static linear policies is competitive for reinforcement learning"), which
:mod:`twin.control.train` uses; the weights live in a small JSON file with how they
were trained.

The linear policy the twin ships (:data:`SHIPPED`, ``wave_ars``) was the default of
``twin.rl:policy`` until the MLP trained at scale (``wave_es_mlp``, then its fine-tuned
``wave_es_mlp_robust``, then that one fine-tuned for a margin under the time gap target,
``wave_es_mlp_margin``, :data:`DEFAULT`) replaced it; all stay, by name, for
comparison.
"""

import json
import math
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from twin.control.env import ACCEL_RANGE, CONTROL_DT, SPEED_GAIN, SPEED_RANGE, ahead_speeds
from twin.core.atomic import atomic_file
from twin.core.errors import TwinError
from twin.traffic.controller_api import EgoCommand, Observation
from twin.traffic.controller_api import leader as leader_of

FORMAT = "i24-twin-linear-speed-policy"
VERSION = 1
#: The features, in the order of the weights.
FEATURES = (
    "bias",
    "speed",
    "leader_speed",
    "time_gap",
    "ahead_0_200",
    "ahead_200_400",
    "ahead_400_600",
    "mean_speed_30s",
)
#: Each feature's unit of weight change in training (ARS explores w + nu * scale * delta).
SCALES = (1.0, 0.05, 0.05, 0.5, 0.05, 0.05, 0.05, 0.05)
#: Weights that follow the leader's speed: where training starts.
FOLLOW_LEADER = (0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0)
TIME_GAP_CAP = 10.0  # [s] the time gap feature is capped here (and is this with no leader)
MEMORY = 30.0  # [s] of the mean-speed feature
POLICIES = Path(__file__).with_name("policies")  # the policies the twin ships, by name
SHIPPED = POLICIES / "wave_ars.json"  # the linear policy the twin ships (``wave_ars``)
#: The default of ``twin.rl:policy``: the MLP trained by ``twin train --algorithm es``
#: (:mod:`twin.control.mlp`), fine-tuned under observation noise and latency with a
#: memory, on the morning and two other mornings (``wave_es_mlp_robust``), then again
#: for a time gap p90 under 3.5 s, a margin under the 4 s comfort target
#: (``wave_es_mlp_margin``: it keeps every comfort and safety target, at some economy);
#: the MLPs it started from stay as ``wave_es_mlp_robust`` and ``wave_es_mlp``, the
#: linear one as ``wave_ars``.
DEFAULT = POLICIES / "wave_es_mlp_margin.json"


def shipped_policy(name: str) -> Path:
    """The file of the policy the twin ships as ``name`` (``wave_ars``, ...).

    Raises:
        PolicyError: no such policy, naming those there are.
    """
    path = POLICIES / f"{name}.json"
    if not path.is_file() or "/" in name or name.startswith("."):
        names = ", ".join(sorted(p.stem for p in POLICIES.glob("*.json")))
        raise PolicyError(f"no policy named {name!r}: the twin ships {names} (or give a path)")
    return path


class PolicyError(TwinError):
    """A policy file cannot be read or holds something else."""


@dataclass(frozen=True)
class LinearSpeedPolicy:
    """``v_cmd = clip(weights . features, 0, 35)`` (see the module doc).

    Attributes:
        weights: (len(FEATURES),) one per feature.
        about: how it was trained (free-form, kept in the file).
    """

    weights: tuple[float, ...]
    about: dict = field(default_factory=dict, compare=False)

    def __post_init__(self):
        weights = tuple(float(w) for w in self.weights)
        if len(weights) != len(FEATURES) or not all(math.isfinite(w) for w in weights):
            raise PolicyError(
                f"a linear speed policy has {len(FEATURES)} finite weights "
                f"({', '.join(FEATURES)}), got {self.weights!r}"
            )
        object.__setattr__(self, "weights", weights)

    def speed_command(self, values: np.ndarray) -> float:
        """[m/s] the commanded speed for the feature values (in :data:`FEATURES` order)."""
        return float(np.clip(np.dot(self.weights, values), *SPEED_RANGE))

    def save(self, path: str | Path) -> Path:
        """Write the policy as JSON, atomically."""
        return write_policy_document(path, {
            "format": FORMAT,
            "version": VERSION,
            "features": list(FEATURES),
            "weights": list(self.weights),
            "about": self.about,
        })  # fmt: skip

    @classmethod
    def load(cls, path: str | Path) -> "LinearSpeedPolicy":
        """Read a policy file.

        Raises:
            PolicyError: no such file, not JSON, or not a policy of this format.
        """
        path = Path(path)
        document = checked_document(path, FORMAT, VERSION)
        if document.get("features") != list(FEATURES):
            raise PolicyError(f"{path}: features {document.get('features')!r} are not {FEATURES}")
        weights = document.get("weights")
        if not is_numbers(weights):
            raise PolicyError(f"{path}: weights must be a list of numbers, got {weights!r}")
        try:
            return cls(tuple(weights), document["about"])
        except PolicyError as error:
            raise PolicyError(f"{path}: {error}") from None


def policy_document(path: str | Path) -> dict:
    """A policy file's JSON object (any format).

    Raises:
        PolicyError: no such file, or not a JSON object.
    """
    try:
        document = json.loads(Path(path).read_text())
    except FileNotFoundError:
        raise PolicyError(f"no policy file at {path}") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as error:
        raise PolicyError(f"{path} is not a policy file: {error}") from None
    if not isinstance(document, dict):
        raise PolicyError(f"{path} is not a policy file (not a JSON object)")
    return document


def checked_document(path: Path, form: str, version: int) -> dict:
    """A policy file's JSON object, of format ``form`` and ``version``, its ``about``
    a table (``{}`` where missing).

    Raises:
        PolicyError: no such file, not JSON, or of another format or version.
    """
    document = policy_document(path)
    if document.get("format") != form:
        raise PolicyError(f"{path} is not a {form} file")
    if document.get("version") != version:
        raise PolicyError(f"{path}: version {document.get('version')!r} is not {version}")
    about = document.get("about") or {}
    if not isinstance(about, dict):
        raise PolicyError(f"{path}: about must be a table, got {about!r}")
    return {**document, "about": about}


def is_numbers(values) -> bool:
    """Whether ``values`` is a list of numbers (not booleans)."""
    return isinstance(values, list) and all(
        isinstance(v, int | float) and not isinstance(v, bool) for v in values
    )


def write_policy_document(path: str | Path, document: dict) -> Path:
    """Write a policy file's ``document`` as JSON, atomically."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_file(path) as tmp:
        tmp.write_text(json.dumps(document, indent=1, allow_nan=False) + "\n")
    return path


def policy_features(
    obs: Observation, ahead: list[float], mean_speed: float, lane_index: int
) -> np.ndarray:
    """The feature values (:data:`FEATURES`) of an observation.

    Args:
        obs: what the traffic manager shows the ego's controller.
        ahead: the recorded speeds ahead (:func:`twin.control.env.ahead_speeds`: 3 bins
            per lane, lanes -1..-4).
        mean_speed: [m/s] the ego's mean speed over the last :data:`MEMORY` seconds.
        lane_index: the ego's lane's index in the lanes (0 for -1 ... 3 for -4).
    """
    gap, leader = leader_of(obs)
    if not math.isfinite(gap):
        leader, time_gap = obs.speed, TIME_GAP_CAP
    else:
        time_gap = min(max(gap, 0.0) / max(obs.speed, 1.0), TIME_GAP_CAP)
    own = ahead[3 * lane_index : 3 * lane_index + 3]
    return np.array([1.0, obs.speed, leader, time_gap, *own, mean_speed], dtype=np.float64)


class PolicyDriver:
    """A :class:`LinearSpeedPolicy` as the ego's controller: it decides every
    :data:`~twin.control.env.CONTROL_DT` and holds its speed command between, with the
    drivers' emergency braking beneath it (``emergency_braking``).

    Needs ``bind(sim)`` (the cosimulator calls it) for the recorded traffic ahead.
    """

    emergency_braking = True

    def __init__(self, policy: LinearSpeedPolicy):
        self.policy = policy
        self._sim = None
        self._every = 1
        self._calls = 0
        self._history: deque = deque()
        self._command = 0.0

    def bind(self, sim) -> None:
        """Called by the cosimulator: the recorded traffic and the clock."""
        self._sim = sim
        self._every = max(1, round(CONTROL_DT / sim.config.dt))
        self._history = deque(maxlen=max(1, round(MEMORY / CONTROL_DT)))

    def __call__(self, obs: Observation) -> EgoCommand:
        sim = self._sim
        if sim is None:
            raise PolicyError("PolicyDriver needs bind(sim) before it drives")
        if self._calls % self._every == 0:
            self._history.append(obs.speed)
            ahead = ahead_speeds(sim.traffic, sim.road, sim.t, obs.x, sim.config.vel_default)
            mean = float(np.mean(self._history))
            values = policy_features(obs, ahead, mean, obs.lanes.lanes.index(obs.lane))
            self._command = self.policy.speed_command(values)
        self._calls += 1
        accel = np.clip(SPEED_GAIN * (self._command - obs.speed), *ACCEL_RANGE)
        return EgoCommand(accel=float(accel))
