"""The on-ramp merges of a run, measured: the ``merges`` section of ``metrics.json``.

A simulated vehicle on an on-ramp's acceleration lane (lane -5, :mod:`twin.core.ramps`)
must merge into lane -4 before the lane's taper ends; one that cannot slows and waits
at the end (:mod:`twin.traffic.kernels.longitudinal`). From the run's log, per vehicle
seen in lane -5 inside the visible window (a recorded vehicle, by its store ``tid``,
however many times it was spawned):

* ``merged``: its first row in a through lane after lane -5, seen: within
  ``SEEN_GAP`` s of its row before, on lane -5; ``before_taper_end`` of them where its
  front was short of the taper's end then (the ramp under it: the one whose end is the
  first at or beyond its back);
* ``entered_past_end``: it merged, but the stretch of rows it merged in (rows no more
  than ``SEEN_GAP`` s apart) began on lane -5 with its front already past the taper's
  end: spawned there from a recording whose merge was that late, its merge was not the
  twin's to make in time; counted apart, in neither ``merged`` nor the shares;
* ``waiting``: it never merged and stands (below ``STANDING`` m/s) on lane -5 at its
  last row: waiting for a gap, at the lane's end or beside a standing queue;
  ``waiting_at_end`` of them first in its lane (no vehicle on lane -5 ahead of it and
  short of the taper's end then) with its front within ``AT_END`` m of the taper's end:
  it reached the end of its lane without merging (a driver waits short of the end by
  half an urgent change's path and its standstill gap, ``min_gap`` up to 10 m; the
  others stand short of it, in the ramp's queue or beside lane -4's, their outcome not
  yet seen);
* ``unfinished``: it left the visible window or the episode ended while it was on its
  way, before the end: its outcome is not seen (one that left the window on lane -5
  and came back into it in a through lane merged out of sight: unfinished too).

``completed_share`` is ``before_taper_end / (merged + waiting)``, the share of the
merges whose outcome is seen that were done in time, counting every vehicle standing on
the ramp at the end of the run as one that failed (None where none is seen).
``in_time_share`` is ``before_taper_end / (merged + waiting_at_end)``: of the vehicles
that merged or reached the lane's end, the share that merged before it; a vehicle
queued on the ramp when the run ends (as the recording's are in a jam) counts in
neither part.
"""

import numpy as np
import pandas as pd

from twin.core.i24 import N_LANES
from twin.core.ramps import RAMP_LANE

STANDING = 1.0  # [m/s] a ramp vehicle slower than this waits for a gap
#: [m] the first waiting vehicle with its front this near its lane's end waits at the
#: end (where one waits: 7.5 m, half the default urgent path, and its standstill gap
#: short of it, up to 17.5 m)
AT_END = 20.0
SEEN_GAP = 0.5  # [s] a merge is seen where its rows before and after are this close


def merge_section(vehicles: pd.DataFrame, lengths: np.ndarray, ends) -> dict | None:
    """The ``merges`` section (module doc) of a run's log ``vehicles`` (columns ``tid``,
    ``time``, ``x`` (back), ``lane``, ``speed``; ``lengths`` [m] by store tid) on a road
    whose on-ramps' acceleration lanes end at ``ends`` [m]; None where the road has
    none.

    Raises:
        ValueError: ``vehicles`` lacks a column this needs (named).
    """
    ends = np.sort(np.asarray(ends, dtype=np.float64))
    if ends.size == 0:
        return None
    missing = [c for c in ("tid", "time", "x", "lane", "speed") if c not in vehicles]
    if missing:
        raise ValueError(f"the merges need the log's columns {missing}")
    lane = vehicles["lane"].to_numpy()
    on_ramp = np.unique(vehicles["tid"].to_numpy()[lane == RAMP_LANE])
    rows = vehicles[vehicles["tid"].isin(on_ramp)].sort_values(["tid", "time"], kind="stable")
    ramp_time = vehicles["time"].to_numpy(dtype=np.float64)[lane == RAMP_LANE]
    ramp_x = vehicles["x"].to_numpy(dtype=np.float64)[lane == RAMP_LANE]
    merged = before_end = waiting = at_end = unfinished = entered_late = 0
    for _, own in rows.groupby("tid", sort=True):
        lanes = own["lane"].to_numpy()
        x = own["x"].to_numpy(dtype=np.float64)
        front = x + np.asarray(lengths, dtype=np.float64)[own["tid"].to_numpy()]
        first_ramp = int(np.argmax(lanes == RAMP_LANE))
        through = (lanes[first_ramp:] <= -1) & (lanes[first_ramp:] >= -N_LANES)
        end = ends[min(int(np.searchsorted(ends, x[first_ramp])), ends.size - 1)]
        if through.any():
            k = first_ramp + int(np.argmax(through))
            times = own["time"].to_numpy(dtype=np.float64)
            if times[k] - times[k - 1] > SEEN_GAP:  # out of the window as it merged
                unfinished += 1
                continue
            breaks = np.flatnonzero(np.diff(times[:k]) > SEEN_GAP)
            start = breaks[-1] + 1 if breaks.size else 0  # where this stretch began
            if lanes[start] == RAMP_LANE and front[start] > end:
                entered_late += 1
                continue
            merged += 1
            before_end += bool(front[k] <= end)
            continue
        last = np.flatnonzero(lanes == RAMP_LANE)[-1]
        speed = own["speed"].to_numpy(dtype=np.float64)[last]
        if speed < STANDING:
            waiting += 1
            others_x = ramp_x[ramp_time == own["time"].to_numpy(dtype=np.float64)[last]]
            first = not np.any((others_x > x[last]) & (others_x < end))
            at_end += bool(first and front[last] >= end - AT_END)
        else:
            unfinished += 1
    seen, reached = merged + waiting, merged + at_end
    return {
        "ramp_vehicles": int(on_ramp.size),
        "merged": merged,
        "before_taper_end": before_end,
        "waiting": waiting,
        "waiting_at_end": at_end,
        "unfinished": unfinished,
        "entered_past_end": entered_late,
        "completed_share": round(before_end / seen, 6) if seen else None,
        "in_time_share": round(before_end / reached, 6) if reached else None,
    }
