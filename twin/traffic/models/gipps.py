"""Gipps' car-following model (Gipps 1981), vectorised: the registry's ``gipps``, unlike
the twin's IDM.

Each driver's speed after its reaction time ``tau`` is the lesser of what free
acceleration gives and what lets it stop behind its leader should the leader brake
as hard as the driver itself would::

    v_free = v + 2.5 a tau (1 - v / V) sqrt(0.025 + v / V)
    v_safe = -b tau + sqrt(b^2 tau^2 + b (2 (s - s0) - v tau + v_lead^2 / b))

with ``s`` the gap and ``b`` the driver's most severe braking. Gipps gives the driver
a separate estimate of the leader's braking; here it is the driver's own ``b`` (the two
cannot be told apart from following data, and the synthetic Gipps days set them
equal). Simulated with a step shorter than ``tau``, the driver relaxes toward that
speed over ``tau``: acceleration ``(min(v_free, v_safe) - v) / tau``. A desired speed
of 0 makes the free speed 0: the driver stops.

A driver with the class table's traits (:mod:`twin.traffic.drivers`) reacts in 2/3 of
its time headway and brakes at most at twice its comfortable deceleration, with the
same desired speed, acceleration and minimum gap.
"""

from dataclasses import dataclass

import numpy as np

from twin.traffic.models.base import CarFollowingModel, Parameter


@dataclass(frozen=True)
class GippsParams:
    """Per-vehicle Gipps parameters, each (n,) or a scalar.

    Attributes:
        desired_speed: V [m/s]. max_accel: a [m/s^2]. decel: b [m/s^2], positive, the
        most severe braking (also the leader's, as the driver believes).
        reaction_time: tau [s]. min_gap: s0 [m], kept at a standstill.
    """

    desired_speed: np.ndarray | float
    max_accel: np.ndarray | float
    decel: np.ndarray | float
    reaction_time: np.ndarray | float
    min_gap: np.ndarray | float


def gipps_acceleration(
    v: np.ndarray, v_lead: np.ndarray, gap: np.ndarray, params: GippsParams
) -> np.ndarray:
    """[m/s^2] Gipps' acceleration of followers; ``gap`` inf for a free road."""
    v = np.asarray(v, dtype=np.float64)
    tau, b = params.reaction_time, params.decel
    desired = np.asarray(params.desired_speed, dtype=np.float64)
    stopping = desired <= 0
    ratio = np.clip(v / np.where(stopping, 1.0, desired), 0.0, None)
    v_free = v + 2.5 * params.max_accel * tau * (1.0 - ratio) * np.sqrt(0.025 + ratio)
    v_free = np.where(stopping, 0.0, v_free)
    gap = np.asarray(gap, dtype=np.float64)
    finite = np.isfinite(gap)
    lead = np.where(finite, v_lead, 0.0)
    room = np.where(finite, 2.0 * (gap - params.min_gap), 0.0)
    under = b * b * tau * tau + b * (room - v * tau + lead * lead / b)
    v_safe = np.where(finite, -b * tau + np.sqrt(np.maximum(under, 0.0)), np.inf)
    target = np.maximum(np.minimum(v_free, v_safe), 0.0)
    return (target - v) / tau


def from_traits(traits) -> GippsParams:
    """Gipps drivers with the traits ``traits`` (:class:`~twin.traffic.drivers.DriverTraits`):
    reaction time 2/3
    of the time headway, most severe braking twice the comfortable deceleration."""
    return GippsParams(
        desired_speed=traits.desired_speed,
        max_accel=traits.max_accel,
        decel=2.0 * np.asarray(traits.comfortable_decel, dtype=np.float64),
        reaction_time=np.asarray(traits.time_headway, dtype=np.float64) * (2.0 / 3.0),
        min_gap=traits.min_gap,
    )


GIPPS = CarFollowingModel(
    name="gipps",
    reference="Gipps 1981, Transportation Research Part B 15, 105-111",
    params=GippsParams,
    parameters=(
        Parameter("desired_speed", "m/s", "V", (5.0, 45.0), 30.0),
        Parameter("max_accel", "m/s^2", "a", (0.2, 5.0), 1.2),
        Parameter("decel", "m/s^2", "b", (0.5, 10.0), 3.4),
        Parameter("reaction_time", "s", "tau", (0.2, 3.0), 0.8),
        Parameter("min_gap", "m", "s0", (0.3, 10.0), 2.0),
    ),
    accel=gipps_acceleration,
    from_traits=from_traits,
)
