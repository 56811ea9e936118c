"""What of the recording an episode draws now, for whoever draws it apart from the log
(the cameras, :mod:`sensors.replay`): which recorded vehicles are drawn off their
recordings (anchored: :mod:`twin.cosim.core.anchor`) and by how much, and which are
held undrawn inside the windows (a spawn waiting for room, a recording held back
from appearing on a body: :mod:`twin.cosim.core.handover`).

The log draws a recorded vehicle in the ghost cells where the core's ghost set has it;
a camera that replayed the recording itself drew an anchored vehicle at its
recording, metres from where its body ended, and a waiting one on the body that took
its place. Read after a step, at the step's time.
"""

from dataclasses import dataclass

import numpy as np

from twin.cosim.core.layout import ANCHORED, GHOST, SIMULATED


@dataclass(frozen=True, eq=False)
class Drawn:
    """Per store trajectory index (``tid``), (trajectories,) arrays.

    Attributes:
        hidden: held undrawn inside the windows (neither simulated nor a ghost there).
        off_x, off_y: [m] where an anchored vehicle is drawn from its recording, along
            the road and across it (0 for every other). off_v: [m/s] its speed's.
    """

    hidden: np.ndarray
    off_x: np.ndarray
    off_y: np.ndarray
    off_v: np.ndarray


def drawn(state, rec_tid: np.ndarray, b: int, trajectories: int) -> Drawn:
    """Episode ``b``'s :class:`Drawn` of a batch's ``state``
    (:data:`twin.cosim.core.layout.State`), its recording's store indices ``rec_tid``
    (by recording index) and a store of ``trajectories`` recorded vehicles."""
    hidden = np.zeros(trajectories, bool)
    off_x, off_y, off_v = (np.zeros(trajectories) for _ in range(3))
    table, ep, sn = state.table, state.episodes, state.snap
    keys, flags = table.key[b], table.flags[b]
    anchors = ep.anchors[b, : ep.anchor_count[b]]
    anchored = anchors[(flags[anchors] & ANCHORED != 0) & (flags[anchors] & SIMULATED == 0)]
    tid = rec_tid[keys[anchored]]
    off_x[tid], off_y[tid] = table.off_x[b, anchored], table.off_y[b, anchored]
    off_v[tid] = table.off_v[b, anchored]
    # the snapshot's rows inside the windows that are neither simulated nor ghosts
    n = int(sn.count[b])
    lo, hi = ep.windows[b, 0], ep.windows[b, 3]
    x, r = sn.x[b, :n], sn.r[b, :n]
    inside = (x >= lo) & (x <= hi)
    used = np.flatnonzero(keys >= 0)
    flag_of = dict(zip(keys[used].tolist(), flags[used].tolist(), strict=True))
    for k in np.flatnonzero(inside):
        if not flag_of.get(int(r[k]), 0) & (SIMULATED | GHOST):
            hidden[rec_tid[r[k]]] = True
    return Drawn(hidden=hidden, off_x=off_x, off_y=off_y, off_v=off_v)
