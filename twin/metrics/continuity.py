"""Continuity of every recorded vehicle's track, whatever it is drawn as: the
``continuity`` section of ``metrics.json`` (issue 76).

A recorded vehicle is drawn in the log as the ego, a simulated body (``visible``
inside the visible window, ``relaxing`` outside it) or its recording (a ``ghost``),
and changes between them at the boundary. A user who follows one ``record_id`` through
the log, or a dataset's instance through the frames, sees one vehicle: each of its
logged states must follow from the one before.

Definitions (one place; :func:`continuity_section` applies them):

* the rows of one record (ego, bodies and ghosts together, by time; a body and its
  ghost at one time, ``doubled``, by the body's) form **tracks**: a row more than
  :data:`TRACK_GAP_S`, or one and a half log periods of the ghosts, after the one
  before begins a new track;
* each consecutive pair of rows of a track is judged: its **position jump** is how far
  the second row lies from the first carried on at their mean speed,
  ``|x1 - x0 - (v0 + v1) / 2 * dt|`` along travel (exact under any constant
  acceleration), and its **speed jump** how much the speed changed beyond what
  :data:`ACCEL_LIMIT` allows in the pair's time, ``max(|v1 - v0| - ACCEL_LIMIT * dt, 0)``;
  a pair is **continuous** within :data:`JUMP_M` and :data:`SPEED_JUMP_MPS`;
* a track **begins** and **ends** somewhere: at the episode's first or last logged
  time (``episode``); at or beyond the drawn region's edge, the rear and front ghost
  windows' outer ends, within how far it and the edge (which moves with the ego) move
  in one log period, and :data:`EDGE_SLACK_M` (``edge``); at the road's end
  (``road``); where its recording begins or ends or leaves the lanes (``recording``:
  the data's own);
  anywhere else is a seam (``inside``);
* a record drawn twice at one time (a body and its ghost) is counted (``doubled``).

Bodies beyond the drawn region are counted too (``beyond_region``): how many bodies
were ever more than :data:`REGION_MARGIN_M` behind the rear ghost window or ahead of
the front one, and the farthest any was [m].
"""

import numpy as np
import pandas as pd

from twin.core.i24 import LANE_WIDTH
from twin.core.ramps import RAMP_LANE
from twin.metrics.handover import spread

TRACK_GAP_S = 0.25  # [s] rows of one record further apart than this are two tracks
JUMP_M = 0.5  # [m] the largest position jump of a continuous pair
SPEED_JUMP_MPS = 0.5  # [m/s] the largest speed jump of a continuous pair
ACCEL_LIMIT = 9.81  # [m/s^2] no tyre changes a speed faster (1 g)
EDGE_SLACK_M = 1.0  # [m] added to one log period's travel where a track meets an edge
REGION_MARGIN_M = 50.0  # [m] the margin beyond the ghost windows a body may be in
ROLE_NAMES = ("ego", "visible", "relaxing", "ghost")
PLACES = ("episode", "edge", "road", "recording", "inside")


def continuity_section(vehicles: pd.DataFrame, ghosts: pd.DataFrame, windows: pd.DataFrame,
                       traffic, road, t0: float, dt: float, ghost_period: float,
                       limits=(-np.inf, np.inf), record_ids=None) -> dict:  # fmt: skip
    """The ``continuity`` section of an episode's metrics (module doc).

    Args:
        vehicles: the log's body rows (``time`` [s from t0], ``tid``, ``role`` 0 ego
            or 1, ``x`` [m], ``speed`` [m/s]).
        ghosts: the log's ghost rows (``time``, ``tid``, ``x``, ``speed``).
        windows: per step ``time``, ``g0``, ``x0``, ``x1``, ``g1`` [m].
        traffic: the recording (``EmpiricalTraffic``), for where recordings begin and end.
        road: the carriageway. t0: [s unix] the episode's start.
        dt: [s] the step. ghost_period: [s] the ghosts' log period.
        limits: [m] the road's x range.
        record_ids: the I-24 ``_id`` per store tid, to name the worst pair's record.
    """
    frame = _rows(vehicles, ghosts, windows, dt)
    if frame.empty:
        return _empty()
    # a record drawn twice at one time (a body and its ghost) is judged by its body
    # (the rows sort the body first); the rows dropped are counted
    tid, time = frame["tid"].to_numpy(), frame["time"].to_numpy()
    doubled = np.r_[False, (tid[1:] == tid[:-1]) & (np.diff(time) <= 1e-9)]
    frame = frame[~doubled].reset_index(drop=True)
    tid, time = frame["tid"].to_numpy(), frame["time"].to_numpy()
    x, speed, role = frame["x"].to_numpy(), frame["speed"].to_numpy(), frame["role"].to_numpy()
    period = max(dt, ghost_period)
    same = np.r_[False, tid[1:] == tid[:-1]]
    gap = np.r_[np.inf, np.diff(time)]
    pair = same & (gap <= max(TRACK_GAP_S, 1.5 * period))
    k = np.flatnonzero(pair)
    step = gap[k]
    position = np.abs(x[k] - x[k - 1] - 0.5 * (speed[k] + speed[k - 1]) * step)
    speed_jump = np.maximum(np.abs(speed[k] - speed[k - 1]) - ACCEL_LIMIT * step, 0.0)
    begins = np.flatnonzero(~pair)
    ends = np.r_[begins[1:] - 1, len(frame) - 1]
    edges = _edges_at(windows, time, dt)
    t_last = float(windows["time"].iloc[-1]) if not windows.empty else 0.0
    t_first = float(windows["time"].iloc[0]) if not windows.empty else 0.0
    return {
        "pairs": int(k.size),
        "position_jump_m": spread(position),
        "speed_jump_mps": spread(speed_jump),
        "discontinuous": int(np.count_nonzero((position > JUMP_M) | (speed_jump > SPEED_JUMP_MPS))),
        "by_roles": _by_roles(role[k - 1], role[k], position, speed_jump),
        "worst": _worst(frame, k, position, speed_jump, record_ids),
        "tracks": {
            "count": int(begins.size),
            "begin": _places(
                frame, begins, -1, edges, windows, dt, t_first, period, traffic, road, t0, limits
            ),
            "end": _places(
                frame, ends, 1, edges, windows, dt, t_last, period, traffic, road, t0, limits
            ),
        },
        "doubled": int(np.count_nonzero(doubled)),
        "beyond_region": _beyond(frame, edges),
    }


def _rows(vehicles, ghosts, windows, dt) -> pd.DataFrame:
    """Bodies and ghosts as one frame sorted by record and time: ``tid``, ``time``,
    ``x``, ``speed``, ``role`` (an index into :data:`ROLE_NAMES`)."""
    bodies = vehicles[["tid", "time", "x", "speed", "role"]].copy()
    bodies["tid"] = bodies["tid"].astype(np.int64)
    edges = _edges_at(windows, bodies["time"].to_numpy(), dt)
    outside = (bodies["x"].to_numpy() < edges[:, 1]) | (bodies["x"].to_numpy() > edges[:, 2])
    role = np.where(bodies["role"].to_numpy() == 0, 0, np.where(outside, 2, 1))
    bodies["role"] = role.astype(np.int8)
    drawn = pd.DataFrame({
        "tid": ghosts["tid"].to_numpy().astype(np.int64), "time": ghosts["time"].to_numpy(),
        "x": ghosts["x"].to_numpy(), "speed": ghosts["speed"].to_numpy(),
        "role": np.full(len(ghosts), 3, np.int8),
    }) if len(ghosts) else bodies.iloc[:0]  # fmt: skip
    frame = pd.concat([bodies, drawn], ignore_index=True)
    frame = frame.astype({"tid": np.int64, "time": float, "x": float, "speed": float,
                          "role": np.int8})  # fmt: skip
    frame = frame[frame["tid"] >= 0]
    return frame.sort_values(["tid", "time", "role"], kind="stable").reset_index(drop=True)


def _edges_at(windows: pd.DataFrame, time: np.ndarray, dt: float) -> np.ndarray:
    """(n, 4) the windows' ``g0``, ``x0``, ``x1``, ``g1`` [m] in force at each ``time``
    (the last step at or before it)."""
    if windows.empty:
        return np.full((len(time), 4), np.nan)
    at = windows["time"].to_numpy()
    k = np.clip(np.searchsorted(at, np.asarray(time) + 1e-9 * dt, side="right") - 1, 0, len(at) - 1)
    return windows[["g0", "x0", "x1", "g1"]].to_numpy()[k]


def _by_roles(before, after, position, speed_jump) -> dict:
    """Per kind of pair (``visible>ghost``, ``ghost>ghost``, ...): how many, the largest
    position and speed jumps and how many are not continuous."""
    out = {}
    for a, b in sorted(set(zip(before.tolist(), after.tolist(), strict=True))):
        m = (before == a) & (after == b)
        out[f"{ROLE_NAMES[a]}>{ROLE_NAMES[b]}"] = {
            "pairs": int(m.sum()),
            "position_jump_max_m": round(float(position[m].max()), 4),
            "speed_jump_max_mps": round(float(speed_jump[m].max()), 4),
            "discontinuous": int(np.count_nonzero(
                (position[m] > JUMP_M) | (speed_jump[m] > SPEED_JUMP_MPS))),
        }  # fmt: skip
    return out


def _worst(frame, k, position, speed_jump, record_ids) -> dict | None:
    """The pair of the largest position jump: its record (``record_id`` where
    ``record_ids`` are given, and store tid), time [s], roles, x before [m], jumps."""
    if k.size == 0:
        return None
    j = int(np.argmax(position))
    row = k[j]
    role, x = frame["role"].to_numpy(), frame["x"].to_numpy()
    tid = int(frame["tid"].to_numpy()[row])
    return {
        "record_id": str(record_ids[tid]) if record_ids is not None else None,
        "tid": tid,
        "time": round(float(frame["time"].to_numpy()[row]), 3),
        "roles": f"{ROLE_NAMES[role[row - 1]]}>{ROLE_NAMES[role[row]]}",
        "x": round(float(x[row - 1]), 3),
        "position_jump_m": round(float(position[j]), 4),
        "speed_jump_mps": round(float(speed_jump[j]), 4),
    }


def _places(frame, rows, side, edges, windows, dt, t_bound, period, traffic, road, t0,
            limits) -> dict:  # fmt: skip
    """Where the tracks of ``rows`` (their first rows, ``side`` -1, or last, +1)
    begin or end: counts per place of :data:`PLACES` (module doc)."""
    counts = dict.fromkeys(PLACES, 0)
    if rows.size == 0:
        return counts
    time, x = frame["time"].to_numpy()[rows], frame["x"].to_numpy()[rows]
    speed = frame["speed"].to_numpy()[rows]
    e = edges[rows]
    # the edges move with the ego: where they were a log period before (after) too
    other = _edges_at(windows, time + side * period, dt)
    episode = np.abs(time - t_bound) <= period + 1e-9
    slack = np.abs(speed) * period + EDGE_SLACK_M
    near_rear = x <= np.maximum(e[:, 0], other[:, 0]) + slack
    near_front = x >= np.minimum(e[:, 3], other[:, 3]) - slack
    edge = near_rear | near_front
    road_end = (x <= limits[0] + slack) | (x >= limits[1] - slack)
    present, _, y, _ = traffic.recorded_states(road, frame["tid"].to_numpy()[rows],
                                               t0 + time + side * period)  # fmt: skip
    # the recording is absent, or off the lanes (a body is removed then too)
    recording = ~np.asarray(present, bool) | _off_lanes(np.asarray(y, float))
    place = np.select([episode, edge, road_end, recording], [0, 1, 2, 3], default=4)
    for p, name in enumerate(PLACES):
        counts[name] = int(np.count_nonzero(place == p))
    return counts


def _off_lanes(y: np.ndarray) -> np.ndarray:
    """Where road-frame ``y`` [m] lies outside the five lane bands (lanes -1 to -5, as
    :func:`twin.core.ramps.lane_of_y` reads them), or is NaN."""
    band = y / LANE_WIDTH + 1e-9
    return ~((band >= 1.0) & (band < -RAMP_LANE + 1.0))


def _beyond(frame, edges) -> dict:
    """Bodies more than :data:`REGION_MARGIN_M` beyond the ghost windows' outer ends:
    how many vehicles, and the farthest [m] any body was beyond them."""
    body = frame["role"].to_numpy() != 3
    x = frame["x"].to_numpy()
    beyond = np.maximum(edges[:, 0] - x, x - edges[:, 3])
    beyond = np.where(body, beyond, -np.inf)
    out = beyond > REGION_MARGIN_M
    return {
        "margin_m": REGION_MARGIN_M,
        "vehicles": int(np.unique(frame["tid"].to_numpy()[out]).size),
        "farthest_m": round(float(max(beyond.max(initial=0.0), 0.0)), 3),
    }


def _empty() -> dict:
    """The section of an episode that logged nothing."""
    places = dict.fromkeys(PLACES, 0)
    return {
        "pairs": 0,
        "position_jump_m": spread(np.zeros(0)),
        "speed_jump_mps": spread(np.zeros(0)),
        "discontinuous": 0,
        "by_roles": {},
        "worst": None,
        "tracks": {"count": 0, "begin": dict(places), "end": dict(places)},
        "doubled": 0,
        "beyond_region": {"margin_m": REGION_MARGIN_M, "vehicles": 0, "farthest_m": 0.0},
    }
