"""The seam of the ghost-cell boundary, measured: how far and how fast a vehicle jumps
in the step it is handed from the visible window to its recording (a ghost), or from
its recording to the visible window (a spawn), the ``handover`` section of
``metrics.json``.

A simulated vehicle (not the ego) whose last row is at step k, in an episode that goes
on, was removed at step k + 1. Where it went (``visible_to_ghost``):

* ``left_road``: it drove off the road (its position carried on one step lies beyond
  the road's limits, where the windows end at the end of the map): nothing is handed
  over;
* ``count``: its recording at step k + 1 lies in a ghost cell, on it: it was handed
  back and became that ghost. The jump is the recording's position at step k + 1
  against the simulated vehicle's at step k carried on at its speed for one step, and
  the difference of the speeds;
* ``anchored``: in a run with anchors, its recording lies anywhere on the road more
  than :data:`ON_RECORDING_M` from it: the body ended at the simulated region's edge
  and its recording is drawn where it was, the offset decaying
  (:mod:`twin.cosim.core.anchor`);
  ``anchor_offset_m`` summarises those offsets (what the paper's hand-over would have
  jumped; what is drawn is judged in the ``continuity`` section,
  :mod:`twin.metrics.continuity`);
* ``into_visible_window``: it was inside the windows and its recording lies in the
  visible window, where a recording is neither drawn nor simulated while its vehicle
  was: it vanished;
* ``left_windows``: it drove out of the windows, or its recording is absent or outside
  them: it left the scene.

Vehicles relax in the ghost cells (:mod:`twin.cosim.core.relax`, on by default): a
simulated vehicle outside the visible window is relaxing. ``relaxing`` gives how many
vehicles relaxed, their measured accelerations' range [m/s^2] (over the steps that
began with the vehicle relaxing: the step it leaves the visible window was commanded
inside it), their lowest speed [m/s], and their distance along the road from their
recordings at the same time [m] (median, p90, max).

A vehicle spawned after the start (its first row at step k > 0) whose recording lay
in the ghost cells at step k - 1 was a ghost before: its jump is its spawn position
against the recording at step k - 1 carried on at the recorded speed, and the
difference of the speeds.

Position jumps are signed along travel (a positive one moves the vehicle forward)
and summarised by their size; ``backwards`` counts the jumps of more than
:data:`BACKWARDS_M` against travel.
"""

import numpy as np
import pandas as pd

from twin.core.i24 import Road

BACKWARDS_M = 0.5  # [m] a jump against travel larger than this is counted as backwards
#: [m] a vehicle this close to its recording one step on was handed back on it (the
#: hand-back's 0.3 m, twin.cosim.core.relax.HAND_BACK_X, and a step's braking)
ON_RECORDING_M = 0.35
EDGE_M = 0.05  # [m] a vehicle carried on this close to the windows' end may have left them


def handover_section(vehicles: pd.DataFrame, windows: pd.DataFrame, traffic, road: Road,
                     t0: float, dt: float, limits=(-np.inf, np.inf),
                     anchors: bool = False) -> dict:  # fmt: skip
    """The ``handover`` section of an episode's metrics (module doc).

    Args:
        vehicles: the log's vehicle rows (``time`` [s from t0], ``id``, ``tid``,
            ``role``, ``x`` [m], ``speed`` [m/s], and ``accel`` [m/s^2] where measured).
        windows: the log's windows per step (``time``, ``g0``, ``x0``, ``x1``, ``g1``).
        traffic: the recorded traffic (``EmpiricalTraffic``).
        road: the episode's carriageway. t0: [s unix] its start. dt: [s] its step.
        limits: [m] the road's x range the windows are clipped to.
        anchors: the run's vehicles relax, and a body ending off its recording is
            anchored to it (``anchored``; else every such end is a jump, the paper's).
    """
    if windows.empty:  # nothing was stepped: nobody was handed over
        return _empty()
    steps = np.round(windows["time"].to_numpy() / dt).astype(np.int64)
    edges = np.full((int(steps.max(initial=-1)) + 1, 4), np.nan)
    edges[steps] = windows[["g0", "x0", "x1", "g1"]].to_numpy()
    others = vehicles[vehicles["role"] != 0]
    step = np.round(others["time"].to_numpy() / dt).astype(np.int64)
    frame = pd.DataFrame({
        "id": others["id"].to_numpy(), "tid": others["tid"].to_numpy(), "step": step,
        "x": others["x"].to_numpy(), "speed": others["speed"].to_numpy(),
        "accel": others["accel"].to_numpy() if "accel" in others else np.nan,
    }).sort_values(["id", "step"], kind="stable")  # fmt: skip
    first = frame.groupby("id", sort=True).head(1)
    last = frame.groupby("id", sort=True).tail(1)
    removed = last[last["step"] < edges.shape[0] - 1]  # the episode went on after them
    spawned = first[first["step"].between(1, edges.shape[0] - 1)]  # after the start
    relaxing = _place(frame["x"].to_numpy(), edges[frame["step"].to_numpy()]) != 0
    # a step's measured acceleration (on its last row) was commanded at the row before:
    # a relaxing vehicle's steps are those that began with it relaxing
    ids = frame["id"].to_numpy()
    began = np.zeros(len(frame), bool)
    began[1:] = relaxing[:-1] & (ids[1:] == ids[:-1])
    accel = frame["accel"].to_numpy(float)[began]
    return {
        "visible_to_ghost": _to_recording(removed, edges, traffic, road, t0, dt, limits, anchors),
        "ghost_to_visible": _from_recording(spawned, edges, traffic, road, t0, dt),
        "relaxing": _relaxing(frame[relaxing], accel, traffic, road, t0, dt),
    }


def _to_recording(rows, edges, traffic, road, t0, dt, limits, anchors) -> dict:
    """The simulated vehicles removed: where their recordings put them one step later."""
    after = rows["step"].to_numpy() + 1
    present, x, speed = _recorded(traffic, road, rows["tid"].to_numpy(), t0 + after * dt)
    place = _place(x, edges[after])
    carried = rows["x"].to_numpy() + rows["speed"].to_numpy() * dt
    off_road = (carried < limits[0]) | (carried > limits[1])
    jump = x - carried
    in_cell = present & (place == 1) & ~off_road
    # the core anchors every body that ends off its recording, wherever the recording
    # is (counts.anchored is the core's own count; counts.anchors_full, those it could
    # not anchor)
    anchored = present & ~off_road & (np.abs(jump) > ON_RECORDING_M) & anchors
    ghost = in_cell & ~anchored
    g0, g1 = edges[after, 0], edges[after, 3]  # it was still inside them (one step's
    inside = (carried >= g0 + EDGE_M) & (carried <= g1 - EDGE_M)  # braking aside)
    vanished = present & (place == 0) & ~off_road & inside
    return {
        "count": int(ghost.sum()),
        **_jumps(jump[ghost], speed[ghost] - rows["speed"].to_numpy()[ghost]),
        "anchored": int(anchored.sum()),
        "anchor_offset_m": spread(np.abs(jump[anchored])),
        "into_visible_window": int(vanished.sum()),
        "left_windows": int((~(ghost | vanished | anchored) & ~off_road).sum()),
        "left_road": int(off_road.sum()),
    }


def _relaxing(rows, accel, traffic, road, t0, dt) -> dict:
    """The rows of the vehicles outside the visible window (relaxing): how many
    vehicles, their measured accelerations' range, their lowest speed, their distance
    from their recordings."""
    present, x, _ = _recorded(traffic, road, rows["tid"].to_numpy(), t0 + rows["step"] * dt)
    distance = np.abs(rows["x"].to_numpy() - x)[present]
    measured = accel[np.isfinite(accel)]
    return {
        "vehicles": int(rows["id"].nunique()),
        "accel_min_mps2": round(float(measured.min()), 4) if measured.size else None,
        "accel_max_mps2": round(float(measured.max()), 4) if measured.size else None,
        "speed_min_mps": round(float(rows["speed"].min()), 4) if len(rows) else None,
        "distance_m": spread(distance),
    }


def _from_recording(rows, edges, traffic, road, t0, dt) -> dict:
    """The vehicles spawned from the ghost cells: their spawn against their ghost."""
    before = rows["step"].to_numpy() - 1
    present, x, speed = _recorded(traffic, road, rows["tid"].to_numpy(), t0 + before * dt)
    ghost = present & (_place(x, edges[before]) == 1)
    carried = x + speed * dt
    return {
        "count": int(ghost.sum()),
        **_jumps(
            rows["x"].to_numpy()[ghost] - carried[ghost],
            rows["speed"].to_numpy()[ghost] - speed[ghost],
        ),
    }


def _empty() -> dict:
    none = _jumps(np.zeros(0), np.zeros(0))
    return {
        "visible_to_ghost": {
            "count": 0,
            **none,
            "anchored": 0,
            "anchor_offset_m": spread(np.zeros(0)),
            "into_visible_window": 0,
            "left_windows": 0,
            "left_road": 0,
        },
        "ghost_to_visible": {"count": 0, **none},
        "relaxing": {
            "vehicles": 0,
            "accel_min_mps2": None,
            "accel_max_mps2": None,
            "speed_min_mps": None,
            "distance_m": spread(np.zeros(0)),
        },
    }


def _recorded(traffic, road, tids, times):
    """(present, x [m], speed [m/s]) of recorded vehicles ``tids`` at unix ``times``."""
    present, x, _, speed = traffic.recorded_states(road, tids, times)
    return np.asarray(present, bool), x, speed


def _place(x, edges) -> np.ndarray:
    """Per position, 0 in the visible window, 1 in a ghost cell, -1 outside the windows
    (``edges``: g0, x0, x1, g1 per row)."""
    g0, x0, x1, g1 = edges.T
    inside = (x >= g0) & (x <= g1)
    visible = (x >= x0) & (x <= x1)
    return np.where(visible, 0, np.where(inside, 1, -1))


def _jumps(position: np.ndarray, speed: np.ndarray) -> dict:
    """Median, p90 and max of the jumps' sizes, and the backward ones."""
    return {
        "position_jump_m": spread(np.abs(position)),
        "speed_jump_mps": spread(np.abs(speed)),
        "backwards": int((position < -BACKWARDS_M).sum()),
    }


def spread(values: np.ndarray) -> dict:
    """Median, p90 and max of ``values`` rounded to 0.1 mm (None where there are none):
    how the boundary's jumps and distances are summarised (here and in
    :mod:`twin.metrics.continuity`)."""
    if values.size == 0:
        return {"median": None, "p90": None, "max": None}
    return {
        "median": round(float(np.median(values)), 4),
        "p90": round(float(np.percentile(values, 90)), 4),
        "max": round(float(values.max()), 4),
    }
