"""Gipps' car-following model (Gipps 1981), vectorised: a second driver model, unlike the
twin's IDM, for test data the calibration has not seen.

Each driver's speed after its reaction time ``tau`` is the lesser of what free
acceleration gives and what lets it stop behind its leader should the leader brake
as hard as the driver believes it can::

    v_free = v + 2.5 a tau (1 - v / V) sqrt(0.025 + v / V)
    v_safe = -b tau + sqrt(b^2 tau^2 + b (2 (s - s0) - v tau + v_lead^2 / b_lead))

with ``s`` the gap, ``b`` the driver's most severe braking and ``b_lead`` its estimate
of the leader's. Simulated with a step shorter than ``tau``, the driver relaxes toward
that speed over ``tau``: acceleration ``(min(v_free, v_safe) - v) / tau``.
"""

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class GippsParams:
    """Per-vehicle Gipps parameters, each (n,) or a scalar.

    Attributes:
        desired_speed: V [m/s]. max_accel: a [m/s^2]. decel: b [m/s^2], positive.
        leader_decel: b_lead [m/s^2], the leader's braking the driver assumes.
        reaction_time: tau [s]. min_gap: s0 [m], kept at a standstill.
    """

    desired_speed: np.ndarray | float
    max_accel: np.ndarray | float
    decel: np.ndarray | float
    leader_decel: np.ndarray | float
    reaction_time: np.ndarray | float
    min_gap: np.ndarray | float

    def take(self, index) -> "GippsParams":
        return GippsParams(
            *(v if np.ndim(v) == 0 else np.asarray(v)[index] for v in self.__dict__.values())
        )


def gipps_acceleration(
    v: np.ndarray, v_lead: np.ndarray, gap: np.ndarray, params: GippsParams
) -> np.ndarray:
    """[m/s^2] Gipps' acceleration of followers; ``gap`` inf for a free road."""
    v = np.asarray(v, dtype=np.float64)
    tau, b = params.reaction_time, params.decel
    ratio = np.clip(v / params.desired_speed, 0.0, None)
    v_free = v + 2.5 * params.max_accel * tau * (1.0 - ratio) * np.sqrt(0.025 + ratio)
    gap = np.asarray(gap, dtype=np.float64)
    finite = np.isfinite(gap)
    lead = np.where(finite, v_lead, 0.0)
    room = np.where(finite, 2.0 * (gap - params.min_gap), 0.0)
    under = b * b * tau * tau + b * (room - v * tau + lead * lead / params.leader_decel)
    v_safe = np.where(finite, -b * tau + np.sqrt(np.maximum(under, 0.0)), np.inf)
    target = np.maximum(np.minimum(v_free, v_safe), 0.0)
    return (target - v) / tau
