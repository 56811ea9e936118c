"""What the traffic kernels work on: struct-of-arrays with a leading episode axis ``B``,
fixed vehicle slots ``N`` with a validity mask, and the obstacles (the ghosts) of each
episode, ``G`` at most.

The kernels never allocate: every array below is made once (:func:`drivers`,
:func:`scratch`) and reused step after step. A slot's values mean something only
while the vehicles' ``valid`` is true.

* ``Vehicles`` (B, N), what the traffic reads of the bodies (the world's arrays,
  shared): ``valid``, and ``top`` (B,) one past the highest valid slot (the kernels
  look no further); ``x`` [m] back centre and ``y`` [m] in the road frame; ``yaw``
  [rad] against the direction of travel; ``speed`` [m/s]; ``lane``, the lane the body
  is in (0 off the lanes); ``length``, ``width``, ``wheelbase`` [m]; ``mu``, the tyres' grip.
* ``Obstacles``: ``count`` (B,), and (B, G) ``lane``, ``x``, ``length``, ``speed``,
  ``accel`` [m/s^2] (a recording's: its mean over the next
  :data:`~twin.traffic.kernels.longitudinal.FORESEEN` seconds, what a lane change in
  front of it foresees), ``reach``, the next lane its footprint reaches into as a
  body's would make it occupy it (0: none; :mod:`twin.traffic.kernels.neighbours`).
* ``Drivers`` (B, N): the traffic manager's state of each vehicle (module
  :mod:`twin.traffic.kernels.decide` says what each field is); ``mandatory``, whether
  the driver's last lane change was one it had to make (toward its strategic target,
  inside that target's zone: a lane ending, a merge; what a collision calls merging);
  ``offset`` [m], how far from its lane's centre (along road-frame y) the vehicle's path
  runs while it is not changing lanes (0 for the traffic manager's own drivers; a
  relaxing vehicle keeps its recording's place across the lane,
  :func:`twin.cosim.core.relax.path_offset`).
* ``Scratch``: the sorted lane entries and the step's outputs.
* ``Traffic``: all of them with the :class:`~twin.traffic.kernels.decide.TrafficSettings`,
  the per-episode ``Counters`` and the ACTION vehicles' ``actions`` (B,), packed into
  one struct for the kernels (:func:`pack`: the same arrays).
"""

from collections import namedtuple

import numpy as np
from numba.core.extending import overload
from numba.experimental import structref

from twin.core.jit import StructType, kernel, packing, register_struct
from twin.traffic.kernels.models import N_PARAMS
from twin.traffic.kernels.neighbours import N_GROUPS

Vehicles = namedtuple("Vehicles", "valid top x y yaw speed lane length width wheelbase mu")
Obstacles = namedtuple("Obstacles", "count lane x length speed accel reach")
Drivers = namedtuple(
    "Drivers",
    "key cf politeness threshold safe_decel keep_right hov_eligible auto lane lane_from "
    "start_x start_y path_length next_decision decisions changes requested strategic "
    "strategic_from strategic_by accel ctrl mandatory offset",
)
Scratch = namedtuple(
    "Scratch",
    "entry_count entry_owner entry_group entry_key order_count order_owner order_lane "
    "marks sx slength sspeed saccel cf_accel need emergency command steer path_y",
)
Counters = namedtuple(
    "Counters", "lane_changes emergency_steps safety_overrides refused_requests merges"
)
Traffic = namedtuple("Traffic", "vehicles obstacles drivers scratch settings counters actions")

#: ``Drivers.ctrl``: who decides a vehicle's acceleration.
DRIVER = 0  # the traffic manager's driver (its car-following model, MOBIL)
ACTION = 1  # an action given each step (the env's agent)
HUMAN = 2  # a controller that answers the driver's command (``twin.controllers:human``)
FOLLOWER_STOPPER = 3
PI_SATURATION = 4
ACC = 5
PYTHON = 6  # a Python callable, applied between the kernels (one episode)
GUARDED = 8  # added to a kind: emergency braking overrides the controller (safety layer)


def drivers(b: int, n: int) -> Drivers:
    """Empty driver state of ``b`` episodes with ``n`` slots each."""

    def f(fill=0.0):
        return np.full((b, n), fill)

    return Drivers(
        key=np.zeros((b, n), np.int64), cf=np.zeros((b, n, N_PARAMS)), politeness=f(),
        threshold=f(), safe_decel=f(), keep_right=f(), hov_eligible=np.zeros((b, n), bool),
        auto=np.zeros((b, n), bool), lane=np.zeros((b, n), np.int64),
        lane_from=np.zeros((b, n), np.int64), start_x=f(), start_y=f(), path_length=f(1.0),
        next_decision=f(), decisions=np.zeros((b, n), np.int64),
        changes=np.zeros((b, n), np.int64), requested=np.zeros((b, n), np.int64),
        strategic=np.zeros((b, n), np.int64), strategic_from=f(np.nan),
        strategic_by=f(np.nan), accel=f(), ctrl=np.zeros((b, n), np.int64),
        mandatory=np.zeros((b, n), bool), offset=f(),
    )  # fmt: skip


def scratch(b: int, n: int, g: int) -> Scratch:
    """The working arrays of ``b`` episodes of ``n`` slots and ``g`` obstacles."""
    e = N_GROUPS * n + 2 * g  # an obstacle occupies its lane and at most one more
    return Scratch(
        entry_count=np.zeros(b, np.int64), entry_owner=np.zeros((b, e), np.int64),
        entry_group=np.zeros((b, e), np.int64), entry_key=np.zeros((b, e)),
        order_count=np.zeros(b, np.int64), order_owner=np.zeros((b, N_GROUPS * n), np.int64),
        order_lane=np.zeros((b, N_GROUPS * n), np.int64), marks=np.zeros((b, n), np.int64),
        sx=np.zeros((b, n + g)), slength=np.zeros((b, n + g)), sspeed=np.zeros((b, n + g)),
        saccel=np.zeros((b, n + g)), cf_accel=np.zeros((b, n)), need=np.zeros((b, n)),
        emergency=np.zeros((b, n), bool), command=np.zeros((b, n)), steer=np.zeros((b, n)),
        path_y=np.zeros((b, n)),
    )  # fmt: skip


def counters(b: int) -> Counters:
    """Zeroed per-episode counts of ``b`` episodes."""
    return Counters(*(np.zeros(b, np.int64) for _ in Counters._fields))


class TrafficType(StructType):
    """The kernels' type of a packed :data:`Traffic`."""


class TrafficStruct(structref.StructRefProxy):
    """A packed :data:`Traffic` as Python holds it (pass it to the kernels)."""


register_struct(TrafficType, TrafficStruct)


def _pack(group):
    raise NotImplementedError  # compiled only


@overload(_pack)
def _pack_overload(group):
    return packing(TrafficType, group)


@kernel(nrt=True)
def _pack_kernel(group):
    return _pack(group)


def pack(group: Traffic) -> TrafficStruct:
    """``group`` as one struct for the kernels (its arrays shared, not copied)."""
    return _pack_kernel(group)
