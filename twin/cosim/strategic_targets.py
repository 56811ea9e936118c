"""The strategic targets the cosimulator gives its visible vehicles
(:mod:`twin.traffic.strategic`: a lane to leave by a place, wanted with a growing
urgency, with the target lane's drivers making room):

- ``calibrated``: drawn from the recording's strategic lane-change flows
  (:mod:`twin.calibration.lane_flows`): a vehicle in a lane passes the position bins
  ahead of it and, in each, leaves its lane that way with the probability the
  recording shows there; its target is the first bin drawn, wanted from half a bin
  before it to the bin's end. Once it has changed, it draws again in its new lane
  (a vehicle two lanes from a lane that continues changes twice, as in the
  recording). Discretionary changes stay MOBIL's;
- ``recorded``: each vehicle's own recorded changes, one after the other, each wanted
  from its recorded place to :data:`RECORDED_SPAN` past it, then retried to
  :data:`~twin.traffic.strategic.GIVE_UP` beyond;
- ``paper``, and a store without strategic flows: none.

The draws use a random stream of their own per vehicle (the run's seed and the
vehicle's record), so they do not depend on the order vehicles are spawned in.
"""

import contextlib

import numpy as np

STREAM = 0x737472  # the draws' own random stream
RECORDED_SPAN = 100.0  # [m] a recorded change's urgency grows over this distance


class StrategicTargets:
    """The targets of one episode's vehicles (module doc).

    Args:
        behaviour: the episode's :class:`~twin.cosim.behaviour.Behaviour`.
        manager: the :class:`~twin.traffic.manager.TrafficManager` driving them.
        seed: the run's seed.
    """

    def __init__(self, behaviour, manager, seed: int):
        self.behaviour = behaviour
        self.manager = manager
        self.seed = int(seed)
        flows = behaviour.strategic_flows
        self.on = behaviour.name == "recorded" or flows is not None
        self._tid: dict[int, int] = {}  # world id -> recorded tid
        self._lane: dict[int, int] = {}  # world id -> the lane its target was set in
        self._draws: dict[int, int] = {}  # world id -> targets drawn so far
        self._plan: dict[int, list] = {}  # world id -> recorded changes ahead (recorded)
        if flows is not None:
            self._edges = np.asarray(flows["x_edges"], dtype=np.float64)
            self._p = _probabilities(flows, self._edges.size - 1)

    def added(self, ids, tids, lanes, x) -> None:
        """Vehicles spawned (world ids, recorded tids, lanes, back x [m]): their first
        targets."""
        if not self.on:
            return
        for i, tid, lane, xi in zip(ids, tids, lanes, x, strict=True):
            i, tid = int(i), int(tid)
            self._tid[i] = tid
            self._draws[i] = 0
            if self.behaviour.name == "recorded":
                self._plan[i] = self.behaviour.changes_of(tid, float(xi))
            self._next(i, int(lane), float(xi))

    def removed(self, ids) -> None:
        """Vehicles despawned, or given a controller (the ego, AVs): no targets."""
        for i in np.atleast_1d(ids).tolist():
            if self._tid.pop(int(i), None) is not None and int(i) in self.manager.ids:
                self.manager.set_strategic([i], 0, np.nan, np.nan)
            self._lane.pop(int(i), None)
            self._draws.pop(int(i), None)
            self._plan.pop(int(i), None)

    def update(self, states) -> None:
        """At a decision step: the next target of each vehicle whose target is done
        (its change started and finished) or given up."""
        if not self._tid:
            return
        ids = np.array(sorted(self._tid), dtype=np.int64)
        free = (self.manager.strategic(ids) == 0) & ~self.manager.changing(ids)
        if not free.any():
            return
        ids = ids[free]
        lanes = self.manager.lanes(ids)
        if self.behaviour.name == "recorded":  # those with recorded changes left
            due = np.array([bool(self._plan.get(i)) for i in ids.tolist()], dtype=bool)
        else:  # those in a lane not drawn for yet (they changed lanes)
            drawn = np.array([self._lane[i] for i in ids.tolist()], dtype=lanes.dtype)
            due = lanes != drawn
        ids, lanes = ids[due], lanes[due]
        x = states.x[np.searchsorted(states.id, ids)]
        for i, lane, xi in zip(ids.tolist(), lanes.tolist(), x.tolist(), strict=True):
            self._next(i, int(lane), float(xi))

    def _next(self, i: int, lane: int, x: float) -> None:
        if self.behaviour.name == "recorded":
            target = self._recorded(i, lane, x)
        else:
            target = self._draw(i, lane, x)
        self._lane[i] = lane
        if target is not None:
            # a change off the road or against the HOV rule is not made: the twin's rules stay
            with contextlib.suppress(ValueError):
                self.manager.set_strategic([i], *target)

    def _draw(self, i: int, lane: int, x: float):
        """(direction, x_from, x_by) drawn from the flows for vehicle ``i`` in ``lane``
        at ``x``, or None."""
        self._draws[i] += 1
        edges, (left, right) = self._edges, self._p.get(lane, (None, None))
        if left is None:
            return None
        rng = np.random.default_rng([self.seed, self._tid[i], STREAM, self._draws[i]])
        first = int(np.searchsorted(edges, x, side="right"))  # bins starting ahead of x
        half = 0.5 * (edges[1] - edges[0])
        for j in range(first, edges.size - 1):
            u = rng.random()
            if u < left[j] + right[j]:
                direction = 1 if u < left[j] else -1
                return direction, edges[j] - half, edges[j + 1]
        return None

    def _recorded(self, i: int, lane: int, x: float):
        """The next recorded change of vehicle ``i`` that starts from ``lane`` and is
        not already far behind it, as a target, or None."""
        plan = self._plan.get(i, [])
        while plan:
            x_change, lane_from, lane_to = plan.pop(0)
            if lane_from == lane and x <= x_change + RECORDED_SPAN:
                return (1 if lane_to > lane_from else -1), x_change, x_change + RECORDED_SPAN
        return None


def _probabilities(flows: dict, n_bins: int) -> dict:
    """{lane: (p_left, p_right)}, (bins,) each: the probability that a vehicle passing a
    bin in the lane leaves it that way for a strategic reason."""
    out = {}
    for name, s in flows["strategic"].items():
        a, b = (int(v) for v in name.split(">"))
        p = np.asarray(s["probability"], dtype=np.float64)
        left, right = out.setdefault(a, (np.zeros(n_bins), np.zeros(n_bins)))
        (left if b > a else right)[:] += p
    for left, right in out.values():  # never more than certainty between the two
        total = left + right
        scale = np.where(total > 1.0, 1.0 / np.maximum(total, 1e-12), 1.0)
        left *= scale
        right *= scale
    return out
