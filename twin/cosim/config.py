"""Configuration of a cosimulation run: the paper's settings, presets A and B, TOML.

A run is described by one frozen :class:`CosimConfig`. The command line builds it as
preset (``--scenario``) < TOML file (``--config``) < flags; the resolved configuration
is written with every run as ``config.toml``, which loads back to the same object.
"""

import math
import tomllib
from dataclasses import MISSING, dataclass, field, fields, is_dataclass, replace
from pathlib import Path
from typing import Any

from sensors.camera import CameraError, CameraSettings, check_rig
from twin.core import i24
from twin.core.errors import TwinError
from twin.core.i24 import SCENARIO_TIME, Road
from twin.core.timeutil import check_unix, steps_per_sample
from twin.cosim.behaviour import AUTO, BEHAVIOURS
from twin.physics.states import MAX_SPEED
from twin.physics.worlds import DEFAULT_DT, check_world
from twin.traffic.baselines import ControllerSettings
from twin.traffic.config import TrafficConfig

MPH = 0.44704  # [m/s per mph]
VEL_DEFAULT = 70.0 * MPH  # [m/s] the posted limit of this stretch (docs/data/i24-format.md)


class ConfigError(TwinError):
    """A configuration file or override is malformed or impossible."""


@dataclass(frozen=True)
class CosimConfig:
    """One cosimulation run: the paper's configuration, with its defaults.

    Attributes:
        scenario: a label for the run ("A", "B" for the presets, else "custom").
        road: carriageway of the ego.
        lane: the desired ego lane, -1 (the HOV lane) to -4; the ego is the recorded
            vehicle closest to ``lane``, ``x`` and ``time``.
        x: [m] the desired ego position, road-frame x (along the direction of travel
            from the segment's entry).
        time: [s] the desired ego time, unix (default 2022-11-30 06:45:50 CST, the time
            of the paper's scenarios).
        t_max: [s] episode length.
        dt: [s] step of the world and the cosimulation. Each world has its default
            (0.01 s physics, 0.1 s kinematic) that :func:`switch_world`, ``--world``,
            TOML and ``--set`` carry along; a configuration built directly with
            ``world="kinematic"`` keeps the 0.01 s it is given (valid, 10 x slower).
        world: where the vehicles move: ``physics`` (pybullet rigid bodies, the
            reference, the only world with cameras) or ``kinematic`` (point masses on
            kinematic bicycles in numpy, for training and sweeps); see
            :mod:`twin.physics.worlds`.
        vel_default: [m/s] desired speed of the ego and of the visible vehicles that
            do not lead their lane ahead of the ego.
        w_visible: [m] visible window each side of the ego.
        w_ghost: [m] ghost window beyond each end of the visible window.
        ghost_smoothing: [s] time constant of a first-order lag on the speed a lane's
            lead vehicle takes from its ghost (0: off, the paper's behaviour).
        relax: a visible vehicle leaving the visible window stays simulated in the
            ghost cell and closes in on its recording within physical limits before it
            becomes a ghost (no jump; :mod:`twin.cosim.core.relax`); false: the paper's
            hand-over, onto the recording at once.
        anchor: (with ``relax``) the simulated region ends ``REAR_MARGIN`` (50 m) behind
            the rear ghost window and at the front one's end, and a body that ends off
            its recording (there, or handed back within 0.3 m) is drawn on as its
            recording anchored where it was, the offset decaying
            (:mod:`twin.cosim.core.anchor`): every record's track continuous, nothing
            simulated beyond the region. By default as ``relax`` (on; off with
            ``relax = false``, the paper's hand-over): on the development days it
            leaves about as many collisions as relaxation alone (3 against 2 in 288
            episodes), and only it gives every record a continuous track and bounds the
            simulated region (``docs/cosim.md``, "The boundary without seams").
        spawn_clearance: [m] bumper-to-bumper room a spawned vehicle needs to any body
            it shares its lane's width with, plus the difference of their braking
            distances at ``spawn_decel`` when the one behind is faster.
        spawn_clearance_at_rest: [m] that room when the rear of the two is at rest; it
            grows to ``spawn_clearance`` at 5 m/s (recorded standing queues have gaps
            under 2 m, and a queue spawned with holes closes them and drifts).
        spawn_decel: [m/s^2] deceleration of the braking distances added to the spawn
            clearance.
        ego_controller: ``"module:function"`` driving the ego (see
            :mod:`twin.traffic.manager`, ``EgoController``), or a controller factory
            such as ``twin.controllers:follower_stopper`` (:mod:`twin.traffic.baselines`);
            empty: the traffic manager.
        av_share: [-] share of the visible vehicles driven by ``ego_controller`` as
            well as the ego (each recorded vehicle drawn once by the seed and its
            record, so the same vehicles in every run of an episode); 0 by default.
        ghost_log_rate: [Hz] rate at which the ghost set is written to the log.
        bev_time: [s] after t0 of the bird's-eye picture; unset (``None``): half the
            episode.
        bev_video: also write ``bev.mp4`` of the whole episode.
        seed: seed of every random choice of the run (drivers, HOV eligibility).
        behaviour: how the visible vehicles drive: ``paper`` (the paper's rules),
            ``calibrated`` (drivers drawn from the store's calibration), ``recorded``
            (each vehicle's own fitted drivers and recorded lane changes) or ``auto``
            (``calibrated`` where the store is calibrated, else ``paper``); see
            :mod:`twin.cosim.behaviour`.
        traffic: traffic-manager settings; its ``dt`` and ``seed`` are the run's.
        camera: the ego's cameras (off by default; ``twin run --camera``).
        controller: the baseline controllers' parameters (``[controller.NAME]``).
    """

    scenario: str = "custom"
    road: Road = Road.WESTBOUND
    lane: int = -1
    x: float = 700.0
    time: float = SCENARIO_TIME
    t_max: float = 30.0
    dt: float = 0.01
    world: str = "physics"
    vel_default: float = VEL_DEFAULT
    w_visible: float = 150.0
    w_ghost: float = 50.0
    ghost_smoothing: float = 0.0
    relax: bool = True
    anchor: bool | None = None  # None: as relax
    spawn_clearance: float = 2.0
    spawn_clearance_at_rest: float = 0.3
    spawn_decel: float = 4.0
    ego_controller: str = ""
    av_share: float = 0.0
    ghost_log_rate: float = 10.0
    bev_time: float | None = None
    bev_video: bool = False
    seed: int = 0
    behaviour: str = "auto"
    traffic: TrafficConfig = field(default_factory=TrafficConfig)
    camera: CameraSettings = field(default_factory=CameraSettings)
    controller: ControllerSettings = field(default_factory=ControllerSettings)

    def __post_init__(self):
        try:
            object.__setattr__(self, "road", Road.parse(self.road))
        except ValueError as error:
            raise ConfigError(f"road: {error}") from None
        if self.lane not in i24.LANES or isinstance(self.lane, bool):
            raise ConfigError(f"lane must be one of {i24.LANES}, got {self.lane!r}")
        numbers = {
            "x": self.x,
            "time": self.time,
            "t_max": self.t_max,
            "dt": self.dt,
            "vel_default": self.vel_default,
            "w_visible": self.w_visible,
            "w_ghost": self.w_ghost,
            "ghost_smoothing": self.ghost_smoothing,
            "spawn_clearance": self.spawn_clearance,
            "spawn_clearance_at_rest": self.spawn_clearance_at_rest,
            "spawn_decel": self.spawn_decel,
            "ghost_log_rate": self.ghost_log_rate,
        }
        for name, value in numbers.items():
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ConfigError(f"{name} must be a number, got {value!r}")
            if not math.isfinite(value):
                raise ConfigError(f"{name} must be finite, got {value!r}")
        try:
            check_unix(self.time)
        except ValueError as error:
            raise ConfigError(str(error)) from None
        positive = ("t_max", "w_visible", "w_ghost", "spawn_decel", "ghost_log_rate")
        for name in positive:
            if not numbers[name] > 0:
                raise ConfigError(f"{name} must be > 0, got {numbers[name]!r}")
        if not isinstance(self.relax, bool):
            raise ConfigError(f"relax must be true or false, got {self.relax!r}")
        if self.anchor is None and isinstance(self.relax, bool):
            object.__setattr__(self, "anchor", self.relax)
        if not isinstance(self.anchor, bool):
            raise ConfigError(f"anchor must be true or false, got {self.anchor!r}")
        if self.anchor and not self.relax:
            raise ConfigError(
                "anchor needs relax: a body is anchored where it ends relaxing "
                "(with relax = false, set anchor = false or leave it unset)"
            )
        if self.ghost_smoothing < 0 or self.spawn_clearance < 0:
            raise ConfigError("ghost_smoothing and spawn_clearance must be >= 0")
        if not 0 <= self.spawn_clearance_at_rest <= self.spawn_clearance:
            raise ConfigError(
                f"spawn_clearance_at_rest must be in [0, spawn_clearance = "
                f"{self.spawn_clearance}] m, got {self.spawn_clearance_at_rest}"
            )
        if not 0 < self.vel_default <= MAX_SPEED:
            raise ConfigError(
                f"vel_default must be in (0, {MAX_SPEED}] m/s, got {self.vel_default}"
            )
        try:
            check_world(self.world, self.dt)
        except ValueError as error:
            raise ConfigError(str(error)) from None
        if self.world != "physics" and self.camera.enabled:
            raise ConfigError(
                f"cameras need the physics world: the {self.world} world has no bodies to "
                'render (set world = "physics", or turn the camera off)'
            )
        try:
            steps_per_sample(self.ghost_log_rate, self.dt)
        except ValueError as error:
            raise ConfigError(f"ghost_log_rate {error}") from None
        if self.bev_time is not None and not 0 <= self.bev_time <= self.t_max:
            raise ConfigError(
                f"bev_time must be in [0, t_max = {self.t_max}] s, got {self.bev_time}"
            )
        if self.ego_controller and self.ego_controller.count(":") != 1:
            raise ConfigError(
                f"ego_controller must be 'module:function', got {self.ego_controller!r}"
            )
        if not (isinstance(self.av_share, int | float) and 0.0 <= self.av_share <= 1.0):
            raise ConfigError(f"av_share must be a share in [0, 1], got {self.av_share!r}")
        if self.av_share > 0 and not self.ego_controller:
            raise ConfigError(
                "av_share needs an ego_controller to put on the vehicles (e.g. "
                "twin.controllers:follower_stopper)"
            )
        if self.behaviour not in (*BEHAVIOURS, AUTO):
            raise ConfigError(
                f"behaviour must be one of {', '.join((*BEHAVIOURS, AUTO))}, got {self.behaviour!r}"
            )
        if not isinstance(self.seed, int) or isinstance(self.seed, bool) or self.seed < 0:
            raise ConfigError(f"seed must be a non-negative integer, got {self.seed!r}")
        try:
            traffic = replace(self.traffic, dt=self.dt, seed=self.seed)
        except ValueError as error:
            raise ConfigError(f"traffic: {error}") from None
        object.__setattr__(self, "traffic", traffic)
        try:
            check_rig(self.camera.rig(), self.dt)
        except CameraError as error:
            raise ConfigError(f"camera: {error}") from None

    @property
    def steps(self) -> int:
        """Physics steps in the episode."""
        return math.ceil(self.t_max / self.dt - 1e-9)

    @property
    def ghost_log_every(self) -> int:
        """Steps between two ghost-set records."""
        return steps_per_sample(self.ghost_log_rate, self.dt)

    @property
    def camera_every(self) -> int:
        """Steps between two frames of the cameras."""
        return steps_per_sample(self.camera.rate_hz, self.dt)


#: Scenario A of the paper: eastbound, lane -2, x = 300 m, light traffic.
SCENARIO_A = CosimConfig(scenario="A", road=Road.EASTBOUND, lane=-2, x=300.0)
#: Scenario B of the paper: westbound, HOV lane, x = 700 m, a stop-and-go wave arrives.
SCENARIO_B = CosimConfig(scenario="B", road=Road.WESTBOUND, lane=-1, x=700.0)
PRESETS = {"A": SCENARIO_A, "B": SCENARIO_B}


def switch_world(config: CosimConfig, world: str) -> CosimConfig:
    """``config`` in ``world``, its step carried along: a step at the old world's
    default becomes the new world's default (0.01 s physics, 0.1 s kinematic); a step
    set by hand is kept. ``--world`` and ``world = ...`` in a TOML file or ``--set``
    switch this way.

    Raises:
        ConfigError: an unknown world, a step out of its range, or cameras outside the
            physics world.
    """
    try:
        return override(config, {"world": world}, source="switching worlds")
    except ConfigError as error:
        if world in DEFAULT_DT and config.dt != DEFAULT_DT[config.world]:
            raise ConfigError(f"{error} (the step {config.dt} s was set by hand)") from None
        raise


def _with_world_step(config: CosimConfig, values: dict) -> dict:
    """``values`` with the step of a world they switch to (see :func:`switch_world`),
    unless they set the step themselves."""
    world = values.get("world")
    if "dt" in values or not isinstance(world, str) or world not in DEFAULT_DT:
        return values
    if config.dt != DEFAULT_DT[config.world]:
        return values
    return {**values, "dt": DEFAULT_DT[world]}


# -- TOML ----------------------------------------------------------------------------


def to_toml(config, *, header: str = "cosimulation") -> str:
    """A configuration dataclass as TOML (``None`` values are left out; they are the
    default), nested dataclasses as tables."""
    lines = [f"# i24-twin {header} configuration (resolved; loads back with --config)"]
    _table(config, [], lines)
    return "\n".join(lines) + "\n"


def from_toml(
    text: str, *, source: str = "configuration", base: CosimConfig | None = None
) -> CosimConfig:
    """Parse TOML into a configuration.

    Keys override the fields of ``base``; without a base, a top-level ``scenario = "A"``
    or ``"B"`` starts from that preset, anything else from the defaults. Nested
    settings go in ``[traffic]``, ``[traffic.drivers]``, ``[traffic.mobil]``,
    ``[camera]`` and ``[controller.NAME]`` tables.

    Raises:
        ConfigError: malformed TOML, an unknown key, a value of the wrong type or an
            impossible value, naming the key and ``source``.
    """
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise ConfigError(f"{source} is not valid TOML: {error}") from None
    if base is None:
        base = PRESETS.get(data.get("scenario"), CosimConfig())
    return override(base, data, source=source)


def load_config(path: str | Path, *, base: CosimConfig | None = None) -> CosimConfig:
    """Read a TOML configuration file (see :func:`from_toml`).

    Raises:
        ConfigError: the file cannot be read or is not a valid configuration.
    """
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as error:
        raise ConfigError(f"cannot read configuration {path}: {error.strerror}") from None
    except UnicodeDecodeError as error:
        raise ConfigError(f"{path} is not a TOML text file (not UTF-8: {error.reason})") from None
    return from_toml(text, source=str(path), base=base)


def parse_assignments(assignments: list[str]) -> dict:
    """``["traffic.hov_share=0.2", "road=eastbound"]`` as nested dicts; values in TOML
    syntax, bare words taken as strings.

    Raises:
        ConfigError: an assignment without ``=``.
    """
    values: dict = {}
    for item in assignments:
        key, sep, text = item.partition("=")
        if not sep or not key.strip():
            raise ConfigError(f"--set {item!r}: expected KEY=VALUE, e.g. traffic.hov_share=0.2")
        try:
            value = tomllib.loads(f"v = {text.strip()}")["v"]
        except tomllib.TOMLDecodeError:
            value = text.strip()
        *tables, name = key.strip().split(".")
        target = values
        for table in tables:
            target = target.setdefault(table, {})
        target[name] = value
    return values


def override(config: Any, values: dict, *, source: str = "override", prefix: str = "") -> Any:
    """``config`` (a configuration dataclass) with ``values`` (nested dicts) applied.

    Raises:
        ConfigError: an unknown key or a bad value, named as ``prefix.key``.
    """
    names = {f.name: f for f in fields(config)}
    changes = {}
    if isinstance(config, CosimConfig):
        values = _with_world_step(config, values)
    for key, value in values.items():
        where = f"{prefix}{key}"
        if key not in names:
            known = ", ".join(sorted(names))
            raise ConfigError(f"{source}: unknown setting {where!r} (known here: {known})")
        current = getattr(config, key)
        if is_dataclass(current):
            if not isinstance(value, dict):
                raise ConfigError(f"{source}: {where} must be a table")
            changes[key] = override(current, value, source=source, prefix=f"{where}.")
        else:
            changes[key] = _coerce(value, current, names[key], where, source)
    relax = changes.get("relax")
    follows = isinstance(config, CosimConfig) and "anchor" not in changes
    if follows and relax is not None and relax != config.relax:
        changes["anchor"] = None  # anchor follows relax again, unless set with it
    try:
        return replace(config, **changes)
    except ConfigError as error:
        raise ConfigError(f"{source}: {error}") from None
    except (ValueError, TypeError, TwinError) as error:  # CameraError is a ValueError
        raise ConfigError(f"{source}: {prefix.rstrip('.') or 'settings'}: {error}") from None


def _coerce(value, current, spec, where: str, source: str):
    """Check a TOML value against the field's current value and type."""
    default = spec.default if spec.default is not MISSING else current
    if isinstance(value, dict):
        raise ConfigError(f"{source}: {where} must be a value, not a table")
    takes_bool = isinstance(default, bool) or (default is None and "bool" in str(spec.type))
    if takes_bool or isinstance(value, bool):
        if not isinstance(value, bool) or not takes_bool:
            kind = "bool" if takes_bool else type(default).__name__
            raise ConfigError(f"{source}: {where} must be {kind}, got {value!r}")
        return value
    if isinstance(default, float) or (default is None and isinstance(value, (int, float))):
        if not isinstance(value, (int, float)):
            raise ConfigError(f"{source}: {where} must be a number, got {value!r}")
        return float(value)
    if isinstance(default, int):
        if not isinstance(value, int):
            raise ConfigError(f"{source}: {where} must be an integer, got {value!r}")
        return value
    if isinstance(default, str):
        if not isinstance(value, str):
            raise ConfigError(f"{source}: {where} must be a string, got {value!r}")
        return value
    if isinstance(default, tuple):
        if not isinstance(value, list):
            raise ConfigError(f"{source}: {where} must be an array, got {value!r}")
        return tuple(tuple(v) if isinstance(v, list) else v for v in value)
    return value


def _table(obj, path: list[str], lines: list[str]) -> None:
    nested = []
    for f in fields(obj):
        value = getattr(obj, f.name)
        if value is None:
            continue
        if is_dataclass(value):
            nested.append((f.name, value))
        else:
            lines.append(f"{f.name} = {_value(value)}")
    for name, value in nested:
        lines.append("")
        lines.append(f"[{'.'.join([*path, name])}]")
        _table(value, [*path, name], lines)


def _value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, Road):
        return f'"{value.value}"'
    if isinstance(value, (int, float)):
        if math.isnan(value):
            return "nan"
        return repr(value) if math.isfinite(value) else ("inf" if value > 0 else "-inf")
    if isinstance(value, str):
        escaped = value.replace("\\", "\\\\").replace('"', '\\"')
        return f'"{escaped}"'
    if isinstance(value, (tuple, list)):
        return "[" + ", ".join(_value(v) for v in value) + "]"
    raise TypeError(f"cannot write {value!r} as TOML")
