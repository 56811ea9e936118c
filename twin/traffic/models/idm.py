"""The Intelligent Driver Model (Treiber, Hennecke, Helbing 2000), vectorised.

Two models of the registry (:mod:`twin.traffic.models`) come from here:

* ``idm``, :data:`IDM`: the twin's drivers. IDM with its free-road term braking at no
  more than the comfortable deceleration b above the desired speed
  (:func:`bounded_free_road_term`), so that a driver whose desired speed is lowered
  (the paper's lane leads take their ghost's speed) slows comfortably, as in Treiber
  and Kesting's IIDM. The traffic manager drives it and the calibration fits it.
* ``idm-textbook``, :data:`TEXTBOOK_IDM`: IDM exactly as published, which the
  synthetic I-24 days are made with (their bottleneck lowers the desired speed and
  the drivers brake toward it as IDM says).
"""

from dataclasses import dataclass, replace

import numpy as np

from twin.traffic.drivers import DriverTraits
from twin.traffic.models.base import CarFollowingModel, Parameter


@dataclass(frozen=True)
class IDMParams(DriverTraits):
    """Per-vehicle IDM parameters as struct-of-arrays; each field (n,) float64 or a scalar.
    They are a driver's traits read as IDM reads them (the fields of
    :class:`~twin.traffic.drivers.DriverTraits`).

    Attributes:
        desired_speed: v0 [m/s].
        time_headway: T [s].
        min_gap: s0 [m], bumper to bumper at standstill.
        max_accel: a [m/s^2].
        comfortable_decel: b [m/s^2], positive.
        delta: acceleration exponent [-].
    """


def desired_gap(v: np.ndarray, v_lead: np.ndarray, params: IDMParams) -> np.ndarray:
    """IDM desired gap s* [m] = s0 + max(0, v T + v (v - v_lead) / (2 sqrt(a b)))."""
    dynamic = v * params.time_headway + v * (v - v_lead) / (
        2.0 * np.sqrt(params.max_accel * params.comfortable_decel)
    )
    return params.min_gap + np.maximum(dynamic, 0.0)


def free_road_term(v: np.ndarray, params: IDMParams) -> np.ndarray:
    """IDM free-road acceleration a (1 - (v / v0)^delta) [m/s^2]."""
    return params.max_accel * (1.0 - _speed_ratio(v, params))


def interaction_term(
    v: np.ndarray, v_lead: np.ndarray, gap: np.ndarray, params: IDMParams
) -> np.ndarray:
    """IDM interaction -a (s* / s)^2 [m/s^2]; 0 where ``gap`` is inf (no leader)."""
    return -params.max_accel * _gap_ratio(v, v_lead, gap, params)


def idm_acceleration(
    v: np.ndarray, v_lead: np.ndarray, gap: np.ndarray, params: IDMParams
) -> np.ndarray:
    """IDM acceleration [m/s^2] of followers behind their leaders: the sum of
    :func:`free_road_term` and :func:`interaction_term`.

    Args:
        v: (n,) [m/s] follower speeds, >= 0.
        v_lead: (n,) [m/s] leader speeds (ignored where ``gap`` is inf).
        gap: (n,) [m] bumper-to-bumper gap to the leader; ``inf`` for a free road.
            A gap <= 0 (overlap) gives a very large deceleration; callers clip.
        params: per-vehicle parameters (see :class:`IDMParams`). A desired speed of 0
            (which IDM leaves undefined) brakes at b and holds the stop, as the twin's
            IDM does.

    Returns:
        (n,) float64 acceleration, unclipped.
    """
    stopping = np.asarray(params.desired_speed) <= 0
    if np.any(stopping):
        moving = replace(params, desired_speed=np.where(stopping, 1.0, params.desired_speed))
        accel = idm_acceleration(v, v_lead, gap, moving)
        stop = -np.asarray(params.comfortable_decel) + interaction_term(v, v_lead, gap, params)
        return np.where(stopping, stop, accel)
    return params.max_accel * (1.0 - _speed_ratio(v, params) - _gap_ratio(v, v_lead, gap, params))


def bounded_free_road_term(v: np.ndarray, params: IDMParams) -> np.ndarray:
    """The free-road term braking at no more than b above the desired speed (so a
    lowered desired speed is followed comfortably, as in Treiber and Kesting's IIDM);
    a desired speed of 0 brakes at b to a stop and holds it."""
    stopping = np.asarray(params.desired_speed) <= 0
    moving = replace(params, desired_speed=np.where(stopping, 1.0, params.desired_speed))
    free = np.maximum(free_road_term(v, moving), -np.asarray(params.comfortable_decel))
    return np.where(stopping, -np.asarray(params.comfortable_decel), free)


def twin_idm_acceleration(
    v: np.ndarray, v_lead: np.ndarray, gap: np.ndarray, params: IDMParams
) -> np.ndarray:
    """The IDM the twin's drivers use: :func:`bounded_free_road_term` plus the
    interaction term (the calibration fits this model, the traffic manager drives it)."""
    return bounded_free_road_term(v, params) + interaction_term(v, v_lead, gap, params)


def _speed_ratio(v, params: IDMParams) -> np.ndarray:
    """(v / v0)^delta."""
    return (np.asarray(v, dtype=np.float64) / params.desired_speed) ** params.delta


def _gap_ratio(v, v_lead, gap, params: IDMParams) -> np.ndarray:
    """(s* / s)^2, 0 where ``gap`` is inf."""
    v = np.asarray(v, dtype=np.float64)
    gap = np.asarray(gap, dtype=np.float64)
    finite = np.isfinite(gap)
    v_lead = np.where(finite, v_lead, v)
    s_star = desired_gap(v, v_lead, params)
    ratio = np.divide(s_star, np.maximum(gap, 1e-3), out=np.zeros_like(v), where=finite)
    return ratio**2


def equilibrium_gap(v: np.ndarray, params: IDMParams) -> np.ndarray:
    """Steady-state gap s*(v) = (s0 + v T) / sqrt(1 - (v / v0)^delta) [m] for speed v < v0."""
    v = np.asarray(v, dtype=np.float64)
    return (params.min_gap + v * params.time_headway) / np.sqrt(
        1.0 - (v / params.desired_speed) ** params.delta
    )


#: IDM's parameters: calibration bounds [m/s, s, m, m/s^2, m/s^2] wide enough for every
#: driver in the literature's I-24, NGSIM and highD fits, narrow enough to reject
#: nonsense; fits start from a typical passenger-car driver; delta is held at 4.
PARAMETERS = (
    Parameter("desired_speed", "m/s", "v0", (5.0, 45.0), 30.0),
    Parameter("time_headway", "s", "T", (0.3, 4.0), 1.2),
    Parameter("min_gap", "m", "s0", (0.3, 10.0), 2.0),
    Parameter("max_accel", "m/s^2", "a", (0.2, 5.0), 1.2),
    Parameter("comfortable_decel", "m/s^2", "b", (0.3, 6.0), 1.7),
    Parameter("delta", "-", "delta", (1.0, 10.0), 4.0, fitted=False),
)


def _from_traits(traits) -> IDMParams:
    """IDM's parameters are the drivers' traits (:class:`~twin.traffic.drivers.DriverTraits`)."""
    return IDMParams(
        traits.desired_speed,
        traits.time_headway,
        traits.min_gap,
        traits.max_accel,
        traits.comfortable_decel,
        traits.delta,
    )


IDM = CarFollowingModel(
    name="idm",
    reference="Treiber, Hennecke, Helbing 2000, with a bounded free-road term",
    params=IDMParams,
    parameters=PARAMETERS,
    accel=twin_idm_acceleration,
    from_traits=_from_traits,
)

TEXTBOOK_IDM = replace(
    IDM,
    name="idm-textbook",
    reference="Treiber, Hennecke, Helbing 2000, Phys. Rev. E 62, 1805",
    accel=idm_acceleration,
)
