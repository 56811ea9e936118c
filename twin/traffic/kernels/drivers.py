"""A driver drawn from its vehicle's class, compiled: the batched core's draw at a
spawn (:mod:`twin.cosim.core.drivers`) and the traffic manager's
(:class:`twin.traffic.manager.TrafficManager`, through :func:`draw_drivers`), so that a
driver of a given seed, key and class is the same in both paths.
(:meth:`twin.traffic.drivers.DriverDistribution.draw` is the distribution's numpy form,
the same law with other draws, for the synthesiser and for analysis.)

The traits are the class table's (:class:`twin.traffic.drivers.DriverDistribution`
describes the spreads): desired speed and its spread, a log-normal time headway and
maximum acceleration around the class's, a normal minimum gap, a comfortable
deceleration; each standard normal is clipped to +/- CLIP_SD. Every draw comes from a
counter (:mod:`twin.core.jit`): the run's seed, the driver's key and the trait's
number, so a driver is the same whenever and in whatever slot it is made.

``table`` is any struct with the class table's trait fields by the names of
:data:`DriverTable` (the core's :data:`twin.cosim.core.drivers.BehaviourArrays` holds
them by the same names).
"""

import math
from collections import namedtuple

import numpy as np

from twin.core.jit import kernel, normal, uniform
from twin.traffic.drivers import CLIP_SD
from twin.traffic.kernels.lane_change import FIRST_DECISION_STREAM
from twin.traffic.kernels.models import from_traits

#: What a driver's draw reads: the class table's traits by class (desired speed and its
#: spread, time headway, maximum acceleration), the distribution's spreads and scales
#: (:class:`twin.traffic.drivers.DriverDistribution`), the share of HOV-eligible
#: drivers and the decision interval [s] (:func:`driver_table`).
DriverTable = namedtuple(
    "DriverTable",
    "class_v0 class_v0_sd class_time_headway class_max_accel time_headway_sd_log min_gap "
    "min_gap_sd max_accel_sd_log decel decel_sd delta v0_scale time_headway_scale "
    "max_accel_scale hov_share decision_interval",
)


def driver_table(distribution, classes, hov_share: float, decision_interval: float) -> DriverTable:
    """The :data:`DriverTable` of a :class:`~twin.traffic.drivers.DriverDistribution`
    over a :class:`~twin.core.vehicle_classes.VehicleClassTable`."""
    d = distribution
    return DriverTable(
        class_v0=classes.column("desired_speed_mps").astype(float),
        class_v0_sd=classes.column("desired_speed_sd_mps").astype(float),
        class_time_headway=classes.column("time_headway_s").astype(float),
        class_max_accel=classes.column("max_accel_mps2").astype(float),
        time_headway_sd_log=float(d.time_headway_sd_log), min_gap=float(d.min_gap),
        min_gap_sd=float(d.min_gap_sd), max_accel_sd_log=float(d.max_accel_sd_log),
        decel=float(d.comfortable_decel), decel_sd=float(d.comfortable_decel_sd),
        delta=float(d.delta), v0_scale=float(d.desired_speed_scale),
        time_headway_scale=float(d.time_headway_scale),
        max_accel_scale=float(d.max_accel_scale), hov_share=float(hov_share),
        decision_interval=float(decision_interval),
    )  # fmt: skip


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


@kernel
def draw_drivers(table, model, seed, keys, classes, desired, cf, lucky, first):
    """The drivers ``keys`` (n,) of vehicles of ``classes`` (n,) as the core draws them
    at a spawn: each one's ``model`` parameter row into ``cf`` (n, N_PARAMS), whether it
    is among the HOV-lucky into ``lucky`` (n,) and its first decision's delay [s] into
    ``first`` (n,). A finite ``desired`` [m/s] (n,) replaces the drawn desired speed."""
    for j in range(keys.size):
        draw_driver(table, model, cf[j], seed, keys[j], classes[j])
        if not math.isnan(desired[j]):
            cf[j, 0] = desired[j]  # every model's first parameter
        lucky[j] = hov_lucky(table, seed, keys[j])
        first[j] = first_decision(table, seed, keys[j])
