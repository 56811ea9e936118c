"""The ego-controller API: what a user's controller sees, what it answers, and how the
twin finds it. The one module a user writing a controller imports.

A controller is any callable ``controller(observation) -> accel`` (a float [m/s^2])
or ``-> EgoCommand`` (an acceleration and an optional lane change), given to the run
as ``--ego-controller module:function`` (``ego_controller`` in the TOML). A function
marked :func:`controller_factory` is called once per episode with the run's
configuration for a fresh controller (one that keeps state, such as a speed history).
A controller with a ``bind(sim)`` method is handed the cosimulation before the
episode starts (e.g. to read the recorded traffic ahead, as a connected vehicle could),
and one with a true ``emergency_braking`` attribute is overridden by the drivers'
emergency braking where it asks for less (a production vehicle's safety layer).

The baselines (:mod:`twin.traffic.baselines`, ``twin.controllers:NAME``) are written
against this module alone.
"""

import importlib
import math
import os
import sys
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from twin.core.errors import ControllerError

LEFT, RIGHT = 1, -1  # lane-change directions: toward lane -1, toward lane -4
NEIGHBOUR_RANGE = 150.0  # [m] along the road, for the ego's observation
FACTORY_MARK = "__twin_controller_factory__"


@dataclass(frozen=True, eq=False)
class LaneView:
    """Nearest vehicles in each lane of the ego's road, (4,) for lanes -1, -2, -3, -4.

    Gaps [m] are bumper to bumper from the ego (``inf`` where nobody is within the
    manager's knowledge); speeds [m/s] are ``nan`` there.
    """

    lanes: tuple[int, ...]
    leader_gap: np.ndarray
    leader_speed: np.ndarray
    follower_gap: np.ndarray
    follower_speed: np.ndarray


@dataclass(frozen=True, eq=False)
class Observation:
    """What a user's ego controller sees each step.

    Attributes:
        time: [s] manager time.
        id: the ego's twin id.
        road: +1 eastbound, -1 westbound.
        lane: lane the ego is in or changing to.
        changing: mid-lane-change.
        x: [m] back centre, road frame.
        y: [m] lateral position, road frame.
        speed: [m/s].
        desired_speed: [m/s] the ego's setting.
        default_accel: [m/s^2] what the traffic manager would command (its
            car-following model with emergency braking).
        lanes: leaders and followers per lane (:class:`LaneView`).
        neighbours: vehicles within ``NEIGHBOUR_RANGE`` on the ego's road as arrays
            ``id`` (-1 for obstacles), ``dx`` [m] (back to back), ``y`` [m] and ``speed``
            [m/s].
    """

    time: float
    id: int
    road: int
    lane: int
    changing: bool
    x: float
    y: float
    speed: float
    desired_speed: float
    default_accel: float
    lanes: LaneView
    neighbours: dict[str, np.ndarray]


@dataclass(frozen=True)
class EgoCommand:
    """A controller's answer: ``accel`` [m/s^2] and an optional lane change
    (``LEFT`` = +1 toward lane -1, ``RIGHT`` = -1, 0 none)."""

    accel: float
    lane_change: int = 0


EgoController = Callable[[Observation], "float | EgoCommand"]


def controller_factory(factory):
    """Mark ``factory(config) -> controller`` as building a controller per episode from
    the run's :class:`~twin.cosim.config.CosimConfig` (:func:`load_controller` calls it)."""
    setattr(factory, FACTORY_MARK, True)
    return factory


def is_factory(obj) -> bool:
    return bool(getattr(obj, FACTORY_MARK, False))


def load_controller(spec: str, config=None) -> EgoController | None:
    """Import ``"module:function"`` (``""``: ``None``, the traffic manager drives).
    The current directory is searched first, as ``python -m`` would (like uvicorn's
    app loading), so ``my_acc.py`` beside the user is found. A controller factory
    (:func:`controller_factory`) is called with ``config``, the run's configuration,
    for a fresh controller.

    Raises:
        ControllerError: the module cannot be imported, has no such callable, or its
            factory fails.
    """
    if not spec:
        return None
    module_name, _, name = spec.partition(":")
    if os.getcwd() not in sys.path:
        sys.path.insert(0, os.getcwd())
    try:
        module = importlib.import_module(module_name)
    except Exception as error:
        raise ControllerError(
            f"ego controller {spec!r}: cannot import {module_name!r} ({error})"
        ) from None
    controller = getattr(module, name, None)
    if not callable(controller):
        raise ControllerError(f"ego controller {spec!r}: {module_name} has no callable {name!r}")
    if is_factory(controller):
        try:
            controller = controller(config)
        except Exception as error:
            raise ControllerError(f"ego controller {spec!r} could not be built: {error}") from None
    return controller


def leader(obs: Observation) -> tuple[float, float]:
    """The gap [m] to the leader in the ego's lane and its speed [m/s], safe to compute
    with: ``(inf, nan)`` where there is none; a gap that is NaN is taken as 0 (touching)
    and the speed of a leader that is there but not finite as 0 (standing), the
    cautious readings. A gap may be negative (overlapping bodies): a state to handle."""
    k = obs.lanes.lanes.index(obs.lane)
    gap = float(obs.lanes.leader_gap[k])
    speed = float(obs.lanes.leader_speed[k])
    if math.isnan(gap):
        gap = 0.0
    if gap == math.inf:
        return math.inf, math.nan
    return max(gap, -1.0e6), speed if math.isfinite(speed) else 0.0


def lane_change_direction(direction: int | str) -> int:
    """``LEFT``, ``RIGHT`` or 0 from +1 / -1 / 0 or ``'left'`` / ``'right'`` / ``'none'``.

    Raises:
        ValueError: anything else, named.
    """
    named = {"left": LEFT, "right": RIGHT, "none": 0}
    if isinstance(direction, str):
        if direction.lower() not in named:
            raise ValueError(f"lane-change direction must be left, right or none: {direction!r}")
        return named[direction.lower()]
    if direction not in (LEFT, RIGHT, 0):
        raise ValueError(f"lane-change direction must be +1 (left), -1 (right) or 0: {direction!r}")
    return int(direction)


def parse_command(answer, who: str) -> tuple[float, int]:
    """``(accel, lane_change)`` of a controller's answer; ``who`` names the controller,
    its vehicle and the time in the errors.

    Raises:
        ControllerError: the answer is not a finite acceleration or an EgoCommand with
            a known lane change.
    """
    if isinstance(answer, EgoCommand):
        accel, lane_change = answer.accel, answer.lane_change
    else:
        accel, lane_change = answer, 0
    try:
        accel = float(accel)
    except (TypeError, ValueError):
        raise ControllerError(
            f"{who} returned {answer!r}, not an acceleration or an EgoCommand"
        ) from None
    if not math.isfinite(accel):
        raise ControllerError(f"{who} returned accel {accel}")
    try:
        return accel, lane_change_direction(lane_change)
    except ValueError as error:
        raise ControllerError(f"{who}: {error}") from None
