"""Lane occupancy and the leader search: who is ahead of whom in each lane, vectorised.

A vehicle occupies every lane it is in: its own, and during a lane change the lane it
leaves as well, so followers in both lanes see it. Entries are sorted by (road, lane,
x); the leader of an entry is the next entry of the same lane. Positions are the
I-24 MOTION reference, the back centre, so a vehicle covers ``[x, x + length]``.

This is the synthesiser's neighbour search (:mod:`twin.data.synth`), in numpy, with its
own MOBIL (:mod:`twin.traffic.mobil`): test data made apart from the twin's traffic. The
twin's traffic and its calibration find neighbours with the kernels'
(:mod:`twin.traffic.kernels.neighbours`), whose sort key this shares.
"""

from dataclasses import dataclass

import numpy as np

from twin.core.i24 import N_LANES
from twin.traffic.kernels.neighbours import LANE_KEY


def lane_group(road: np.ndarray, lane: np.ndarray) -> np.ndarray:
    """Small integer per (road, lane): 0..3 westbound lanes -1..-4, 4..7 eastbound."""
    return (np.asarray(road) > 0) * N_LANES + (-np.asarray(lane, dtype=np.int64) - 1)


@dataclass(frozen=True, eq=False)
class Occupancy:
    """Lane entries sorted by lane then x.

    Attributes:
        owner: (m,) int index of the vehicle each entry belongs to.
        group: (m,) int :func:`lane_group` of the entry.
        key: (m,) float sort key ``group * LANE_KEY + x``, increasing.
        same_lane_ahead: (m,) bool, the next entry is in the same lane.
    """

    owner: np.ndarray
    group: np.ndarray
    key: np.ndarray
    same_lane_ahead: np.ndarray

    @classmethod
    def build(
        cls, road: np.ndarray | list[np.ndarray], x: np.ndarray, lanes: list[np.ndarray]
    ) -> "Occupancy":
        """Entries of vehicles ``0..n-1`` in each of the lane arrays in ``lanes``.

        Args:
            road: (n,) directions +1 / -1; or one such array per lane array (a lane
                array's entries on the road its own array names: the synthesiser keeps
                an on-ramp's lane apart this way).
            x: (n,) [m] back centres.
            lanes: arrays (n,) of lane ids; a vehicle gets one entry per distinct lane id
                in -1..-4 across them (0 or a repeated id adds nothing).
        """
        n = x.size
        roads = road if isinstance(road, (list, tuple)) else [road] * len(lanes)
        owners, groups = [], []
        for k, (lane, road) in enumerate(zip(lanes, roads, strict=True)):
            new = (lane <= -1) & (lane >= -N_LANES)
            for earlier in lanes[:k]:
                new &= lane != earlier
            rows = np.arange(n) if new.all() else np.flatnonzero(new)
            owners.append(rows)
            groups.append(lane_group(road[rows], lane[rows]))
        owner = np.concatenate(owners)
        group = np.concatenate(groups)
        key = group * LANE_KEY + x[owner]
        order = np.argsort(key, kind="stable")
        owner, group, key = owner[order], group[order], key[order]
        same = np.empty(owner.size, dtype=bool)
        same[:-1] = group[1:] == group[:-1]
        same[-1:] = False
        return cls(owner, group, key, same)

    def leaders(self, x: np.ndarray, length: np.ndarray):
        """Leader of every entry in its lane.

        Returns:
            gap: (m,) [m] bumper-to-bumper gap to the leader, ``inf`` where none.
            leader: (m,) index of the leading vehicle, -1 where none.
        """
        leader = np.full(self.owner.size, -1)
        leader[:-1] = self.owner[1:]
        leader[~self.same_lane_ahead] = -1
        gap = np.where(self.same_lane_ahead, x[leader] - x[self.owner] - length[self.owner], np.inf)
        return gap, leader

    def around(self, road: np.ndarray, lane: np.ndarray, x: np.ndarray):
        """The vehicles just ahead of and just behind points ``x`` in lanes ``lane``.

        A vehicle exactly at a query point (the asking vehicle itself) is neither.

        Returns:
            ahead, behind: (k,) vehicle indices, -1 where the lane is empty that way.
        """
        group = lane_group(road, lane)
        if self.key.size == 0:
            return np.full(group.shape, -1), np.full(group.shape, -1)
        query = group * LANE_KEY + x
        after = np.searchsorted(self.key, query, side="right")
        before = np.searchsorted(self.key, query, side="left") - 1
        last = self.key.size - 1
        ahead_ok = (after <= last) & (self.group[np.minimum(after, last)] == group)
        behind_ok = (before >= 0) & (self.group[np.maximum(before, 0)] == group)
        ahead = np.where(ahead_ok, self.owner[np.minimum(after, last)], -1)
        behind = np.where(behind_ok, self.owner[np.maximum(before, 0)], -1)
        return ahead, behind
