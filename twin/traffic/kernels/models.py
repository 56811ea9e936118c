"""The car-following models as compiled scalar functions: one vehicle's acceleration
behind one leader, the kernels' counterpart of :mod:`twin.traffic.models` (which keeps
the vectorised numpy forms the calibration fits with, and the parameters' names,
units and bounds).

A driver's parameters are a row of a (..., :data:`N_PARAMS`) float array in the
model's parameter order (``CarFollowingModel.names``): IDM ``desired_speed,
time_headway, min_gap, max_accel, comfortable_decel, delta``; Gipps ``desired_speed,
max_accel, decel, reaction_time, min_gap`` (the last column unused). The model is an
integer of :data:`MODEL_IDS`.
"""

import math

from twin.core.jit import kernel

N_PARAMS = 6  # columns of a driver's parameter row (the largest model's count)
IDM, TEXTBOOK_IDM, GIPPS = 0, 1, 2
#: The kernels' model numbers by the names of :data:`twin.traffic.models.MODELS`.
MODEL_IDS = {"idm": IDM, "idm-textbook": TEXTBOOK_IDM, "gipps": GIPPS}
#: The column of ``max_accel`` in each model's row.
MAX_ACCEL_COLUMN = {IDM: 3, TEXTBOOK_IDM: 3, GIPPS: 1}


@kernel(inline=True)
def idm_accel(v, v_lead, gap, v0, time_headway, s0, a, b, delta, bounded):
    """[m/s^2] IDM behind a leader ``gap`` [m] ahead (``inf``: none) at ``v_lead``;
    ``bounded``: the twin's free-road term, braking at no more than ``b`` above the
    desired speed (:func:`twin.traffic.models.idm.twin_idm_acceleration`), else as
    published. A desired speed of 0 brakes at ``b`` and holds the stop."""
    interaction = 0.0
    if math.isfinite(gap):
        dynamic = v * time_headway + v * (v - v_lead) / (2.0 * math.sqrt(a * b))
        ratio = (s0 + max(dynamic, 0.0)) / max(gap, 1e-3)
        interaction = -a * ratio * ratio
    if v0 <= 0.0:
        return -b + interaction
    free = a * (1.0 - (v / v0) ** delta)
    if bounded:
        free = max(free, -b)
    return free + interaction


@kernel(inline=True)
def gipps_accel(v, v_lead, gap, desired, a, b, tau, s0):
    """[m/s^2] Gipps (1981), relaxed toward its speed over the reaction time
    (:func:`twin.traffic.models.gipps.gipps_acceleration`)."""
    ratio = max(v / (desired if desired > 0.0 else 1.0), 0.0)
    v_free = v + 2.5 * a * tau * (1.0 - ratio) * math.sqrt(0.025 + ratio)
    if desired <= 0.0:
        v_free = 0.0
    v_safe = math.inf
    if math.isfinite(gap):
        under = b * b * tau * tau + b * (2.0 * (gap - s0) - v * tau + v_lead * v_lead / b)
        v_safe = -b * tau + math.sqrt(max(under, 0.0))
    return (max(min(v_free, v_safe), 0.0) - v) / tau


@kernel(inline=True)
def follow_accel(model, v, v_lead, gap, p0, p1, p2, p3, p4, p5):
    """[m/s^2] the ``model``'s acceleration at speed ``v`` [m/s] behind a leader ``gap``
    [m] ahead (``inf`` for a free road; ``v_lead`` is then ignored) with the driver's
    parameter row ``p0..p5``."""
    if model == GIPPS:
        return gipps_accel(v, v_lead, gap, p0, p1, p2, p3, p4)
    return idm_accel(v, v_lead, gap, p0, p1, p2, p3, p4, p5, model == IDM)


@kernel(inline=True)
def from_traits(model, row, v0, time_headway, min_gap, max_accel, decel, delta):
    """Write into ``row`` (N_PARAMS,) the ``model``'s parameters of a driver with these
    traits (desired speed [m/s], time headway [s], minimum gap [m], maximum
    acceleration and comfortable deceleration [m/s^2], IDM's exponent): the kernels'
    form of each model's ``from_traits`` (:mod:`twin.traffic.models`; Gipps: reaction
    time 2/3 of the headway, most severe braking twice the comfortable deceleration)."""
    if model == GIPPS:
        row[0], row[1], row[2] = v0, max_accel, 2.0 * decel
        row[3], row[4], row[5] = time_headway * (2.0 / 3.0), min_gap, 0.0
    else:
        row[0], row[1], row[2] = v0, time_headway, min_gap
        row[3], row[4], row[5] = max_accel, decel, delta
