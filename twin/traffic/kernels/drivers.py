"""A driver drawn from its vehicle's class, compiled: the batched core's draw at a
spawn (:mod:`twin.cosim.core.drivers`), in the traffic layer so that every path that
makes drivers can share it. The traffic manager
(:class:`twin.traffic.manager.TrafficManager`) still draws its own with numpy
(:meth:`twin.traffic.drivers.DriverDistribution.draw`, the same distribution, other
draws): its tests' scenes were built on those draws' decision phases.

The traits are the class table's (:class:`twin.traffic.drivers.DriverDistribution`
describes the spreads): desired speed and its spread, a log-normal time headway and
maximum acceleration around the class's, a normal minimum gap, a comfortable
deceleration; each standard normal is clipped to +/- CLIP_SD. Every draw comes from a
counter (:mod:`twin.core.jit`): the run's seed, the driver's key and the trait's
number, so a driver is the same whenever and in whatever slot it is made.

``table`` is any struct with the class table's trait fields by the names of
:data:`twin.cosim.core.drivers.BehaviourArrays` (``class_v0``, ``class_v0_sd``,
``class_time_headway``, ``class_max_accel``, ``time_headway_sd_log``, ``min_gap``,
``min_gap_sd``, ``max_accel_sd_log``, ``decel``, ``decel_sd``, ``delta``, the three
scales, ``hov_share``, ``decision_interval``).
"""

import math

import numpy as np

from twin.core.jit import kernel, normal, uniform
from twin.traffic.drivers import CLIP_SD
from twin.traffic.kernels.lane_change import FIRST_DECISION_STREAM
from twin.traffic.kernels.models import from_traits

# The random streams of the draws made for a new driver (numpy integers: a kernel called
# with a Python int constant is compiled once per value)
TRAIT_STREAM = np.int64(0x54)
HOV_STREAM = np.int64(0x48)


@kernel(inline=True)
def clipped_normal(seed, stream, key, event):
    """A standard normal draw clipped to +/- CLIP_SD (no driver is absurd)."""
    return min(max(normal(seed, stream, key, event), -CLIP_SD), CLIP_SD)


@kernel(inline=True)
def draw_driver(table, model, row, seed, key, c):
    """Write into ``row`` (N_PARAMS,) the ``model``'s parameters of the driver ``key``
    of a vehicle of class ``c`` drawn from ``table`` (module doc)."""
    v0 = table.v0_scale * (
        table.class_v0[c] + table.class_v0_sd[c] * clipped_normal(seed, TRAIT_STREAM, key,
                                                                  np.int64(0))
    )  # fmt: skip
    headway = (
        table.time_headway_scale * table.class_time_headway[c]
        * math.exp(table.time_headway_sd_log * clipped_normal(seed, TRAIT_STREAM, key,
                                                              np.int64(1)))
    )  # fmt: skip
    min_gap = table.min_gap + table.min_gap_sd * clipped_normal(seed, TRAIT_STREAM, key,
                                                                np.int64(2))  # fmt: skip
    max_accel = (
        table.max_accel_scale * table.class_max_accel[c]
        * math.exp(table.max_accel_sd_log * clipped_normal(seed, TRAIT_STREAM, key,
                                                           np.int64(3)))
    )  # fmt: skip
    decel = table.decel
    if table.decel_sd > 0.0:
        decel += table.decel_sd * clipped_normal(seed, TRAIT_STREAM, key, np.int64(4))
    from_traits(model, row, v0, headway, min_gap, max_accel, decel, table.delta)


@kernel(inline=True)
def hov_lucky(table, seed, key):
    """Whether driver ``key`` is among the ``hov_share`` of HOV-eligible drivers (where
    its class may use the lane)."""
    return uniform(seed, HOV_STREAM, key, np.int64(0)) < table.hov_share


@kernel(inline=True)
def first_decision(table, seed, key):
    """[s] after it is made, driver ``key``'s first lane-change decision: uniform over
    one ``decision_interval``."""
    return table.decision_interval * uniform(seed, FIRST_DECISION_STREAM, key, np.int64(0))
