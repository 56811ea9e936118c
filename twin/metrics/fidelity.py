"""Fidelity as numbers: the simulated run against the recording (``metrics.json``).

- Ego: the simulated ego against the recorded vehicle it was spawned from, over the
  episode while the recording has it: position and speed RMSE, the minimum speed of
  each, the final position gap.
- Ego position error at 30, 60 and 120 s and at the end; the slow spells (below
  15 mph) of the recorded ego against the simulated ego's: when each begins and ends.
- Lane changes: the simulated vehicles' against the recorded vehicles' in the same
  moving visible window; vehicles stalled across a lane line (straddling it at a
  standstill for ``STALL_TIME``).
- Traffic: the mean absolute speed error of every simulated vehicle against its own
  recording while both exist; and the Edie speed field (cells of ``CELL_X`` m by
  ``CELL_T`` s) of simulated and recorded traffic, both seen through the same moving
  visible window, compared cell by cell where both have enough samples.
"""

import numpy as np
import pandas as pd

from twin.core.i24 import LANE_WIDTH, LANES
from twin.data.empirical import EmpiricalTraffic
from twin.data.speed_field import speed_field

CELL_X = 20.0  # [m]
CELL_T = 2.0  # [s]
SAMPLE_PERIOD = 0.1  # [s] the speed field and the traffic error are sampled this often
MIN_CELL_TIME = 0.5  # [s] vehicle-seconds a cell needs in both fields to be compared
SLOW = 15.0 * 0.44704  # [m/s] 15 mph: below it the ego is in a slow spell
MIN_SPELL = 1.0  # [s] a slow spell lasts at least this long
ERROR_TIMES = (30.0, 60.0, 120.0)  # [s] the ego's position error is reported at these
ACROSS_LINE = 0.9  # [m] a body centre this far from every lane centre straddles a line
STALL_SPEED = 0.5  # [m/s] ...and below this speed it is at a standstill
STALL_TIME = 5.0  # [s] ...and this long, it is stalled across the line


def ego_metrics(ego_rows: pd.DataFrame, recorded: dict, t0: float) -> dict:
    """The simulated ego (its log rows) against its recording (its path: t, x, speed;
    :meth:`~twin.data.empirical.EmpiricalTraffic.track`)."""
    t = t0 + ego_rows["time"].to_numpy()
    valid = (t >= recorded["t"][0]) & (t <= recorded["t"][-1])
    if not valid.any():
        return {"compared_s": 0.0}
    t = t[valid]
    x_sim, v_sim = ego_rows["x"].to_numpy()[valid], ego_rows["speed"].to_numpy()[valid]
    x_rec = np.interp(t, recorded["t"], recorded["x"])
    v_rec = np.interp(t, recorded["t"], recorded["speed"].astype(np.float64))
    return {
        "compared_s": round(float(t[-1] - t[0]), 3),
        "position_rmse_m": _r(np.sqrt(np.mean((x_sim - x_rec) ** 2))),
        "speed_rmse_mps": _r(np.sqrt(np.mean((v_sim - v_rec) ** 2))),
        "min_speed_sim_mps": _r(v_sim.min()),
        "min_speed_recorded_mps": _r(v_rec.min()),
        "min_speed_difference_mps": _r(abs(v_sim.min() - v_rec.min())),
        "final_position_gap_m": _r(x_sim[-1] - x_rec[-1]),
        "final_speed_sim_mps": _r(v_sim[-1]),
        "final_speed_recorded_mps": _r(v_rec[-1]),
    }


def ego_position_errors(ego_rows: pd.DataFrame, recorded: dict, t0: float) -> dict:
    """|x_sim - x_recorded| [m] at ``ERROR_TIMES`` (where the episode and the recording
    reach them) and at the end."""
    time = ego_rows["time"].to_numpy()
    x_sim = ego_rows["x"].to_numpy()
    out = {}
    for at in (*ERROR_TIMES, float(time[-1])):
        key = "end" if at == float(time[-1]) and at not in ERROR_TIMES else f"{at:g}s"
        if at > time[-1] + 1e-9 or not recorded["t"][0] <= t0 + at <= recorded["t"][-1]:
            out[key] = None
            continue
        k = int(np.argmin(np.abs(time - at)))
        out[key] = _r(abs(x_sim[k] - np.interp(t0 + at, recorded["t"], recorded["x"])))
    if "end" not in out:
        out["end"] = out[f"{float(time[-1]):g}s"]
    return out


def slow_spells(time: np.ndarray, speed: np.ndarray) -> list[tuple[float, float]]:
    """[(begin, end)] [s] of the stretches below ``SLOW`` lasting ``MIN_SPELL`` or more."""
    slow = speed < SLOW
    edges = np.flatnonzero(np.diff(np.r_[False, slow, False].astype(np.int8)))
    spells = []
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        begin, end = float(time[a]), float(time[b - 1])
        if end - begin >= MIN_SPELL:
            spells.append((round(begin, 3), round(end, 3)))
    return spells


def slow_spell_timing(ego_rows: pd.DataFrame, recorded: dict, t0: float) -> dict:
    """The recorded ego's slow spells and the simulated ego's, paired by overlap (else
    the nearest begin), with the differences of their begins and ends [s, sim - rec]."""
    time = ego_rows["time"].to_numpy()
    inside = (t0 + time >= recorded["t"][0]) & (t0 + time <= recorded["t"][-1])
    time = time[inside]
    v_rec = np.interp(t0 + time, recorded["t"], recorded["speed"].astype(np.float64))
    rec = slow_spells(time, v_rec)
    sim = slow_spells(time, ego_rows["speed"].to_numpy()[inside])
    pairs = []
    for begin, end in rec:
        match = None
        if sim:
            overlap = [min(end, e) - max(begin, b) for b, e in sim]
            k = int(np.argmax(overlap))
            if overlap[k] < 0:
                k = int(np.argmin([abs(b - begin) for b, _ in sim]))
            match = sim[k]
        pairs.append(
            {
                "recorded": [begin, end],
                "simulated": list(match) if match else None,
                "begin_difference_s": round(match[0] - begin, 3) if match else None,
                "end_difference_s": round(match[1] - end, 3) if match else None,
            }
        )
    ends = [abs(p["end_difference_s"]) for p in pairs if p["end_difference_s"] is not None]
    begins = [abs(p["begin_difference_s"]) for p in pairs if p["begin_difference_s"] is not None]
    return {
        "threshold_mps": round(SLOW, 4),
        "recorded_spells": len(rec),
        "simulated_spells": len(sim),
        "spells": pairs,
        "max_abs_begin_difference_s": max(begins) if begins else None,
        "max_abs_end_difference_s": max(ends) if ends else None,
    }


def stalled_across_lines(rows: pd.DataFrame, dt: float) -> int:
    """Vehicles that straddled a lane line at a standstill for ``STALL_TIME`` or more
    (``rows`` sampled every ``dt`` [s])."""
    stuck = _stuck(rows["y"].to_numpy(), rows["speed"].to_numpy())
    return _stalled(rows["id"].to_numpy(), stuck, dt)


def stalled_as_recorded(rows: pd.DataFrame, dt: float, traffic: EmpiricalTraffic, t0: float,
                        road) -> int:  # fmt: skip
    """Of :func:`stalled_across_lines`, the vehicles whose own recording stood across a
    line with them, as long: stalled as recorded, not left with no move by the twin (on
    SUMO's days, sub-lane drivers jam across the lines for minutes and a vehicle spawned
    at its recorded place stands there as its recording does). ``rows``: simulated
    vehicles' log rows (``tid`` the recording each was spawned from, < 0 for none;
    ``t0`` [s] unix time of the log's 0)."""
    rows = rows[rows["tid"].to_numpy() >= 0]
    if rows.empty:
        return 0
    tids = rows["tid"].to_numpy().astype(np.int64)
    present, _, y_rec, v_rec = traffic.recorded_states(road, tids, t0 + rows["time"].to_numpy())
    stuck = _stuck(rows["y"].to_numpy(), rows["speed"].to_numpy()) & present
    stuck &= _stuck(y_rec, v_rec)
    return _stalled(rows["id"].to_numpy(), stuck, dt)


def _stuck(y: np.ndarray, speed: np.ndarray) -> np.ndarray:
    """Whether each state straddles a lane line (its centre :data:`ACROSS_LINE` from
    every lane's) at a standstill."""
    centre = (np.round(y / LANE_WIDTH - 0.5) + 0.5) * LANE_WIDTH
    return (np.abs(y - centre) > ACROSS_LINE) & (speed < STALL_SPEED)


def _stalled(ids: np.ndarray, stuck: np.ndarray, dt: float) -> int:
    """How many ``ids`` are ``stuck`` in rows ``dt`` [s] apart for ``STALL_TIME``."""
    counts = pd.Series(ids[stuck]).value_counts()
    return int(np.count_nonzero(counts.to_numpy() * dt >= STALL_TIME))


def recorded_lane_changes_in_window(
    changes_time: np.ndarray, changes_x: np.ndarray, windows: pd.DataFrame, t0: float
) -> int:
    """Recorded lane changes that happened inside the moving visible window."""
    return int(
        np.count_nonzero(in_moving_window(np.asarray(changes_time) - t0, changes_x, windows))
    )


def in_moving_window(time: np.ndarray, x: np.ndarray, windows: pd.DataFrame) -> np.ndarray:
    """(k,) bool: events at ``time`` [s since t0] and ``x`` [m] lie inside the moving
    visible window (``windows``: ``time`` [s since t0], ``x0``, ``x1``) at their time."""
    time, x = np.asarray(time, dtype=np.float64), np.asarray(x, dtype=np.float64)
    if time.size == 0:
        return np.zeros(0, dtype=bool)
    at = windows["time"].to_numpy()
    inside_episode = (time >= at[0]) & (time <= at[-1])
    k = np.clip(np.searchsorted(at, time), 0, len(at) - 1)
    x0, x1 = windows["x0"].to_numpy()[k], windows["x1"].to_numpy()[k]
    return inside_episode & (x >= x0) & (x <= x1)


def traffic_speed_error(rows: pd.DataFrame, traffic: EmpiricalTraffic, t0: float,
                        road) -> dict:  # fmt: skip
    """Mean absolute speed error of simulated vehicles (``rows``: their log rows, sampled)
    against the recorded vehicle each was spawned from, while both exist (the recording
    in memory: :meth:`EmpiricalTraffic.recorded_speeds`)."""
    tids = rows["tid"].to_numpy().astype(np.int64)
    present, v_rec = traffic.recorded_speeds(road, tids, t0 + rows["time"].to_numpy())
    if not present.any():
        return {"vehicles_compared": 0}
    errors = np.abs(rows["speed"].to_numpy()[present] - v_rec[present])
    return {
        "vehicles_compared": int(np.unique(tids[present]).size),
        "speed_mae_mps": _r(errors.mean()),
        "speed_error_p95_mps": _r(np.percentile(errors, 95)),
    }


def speed_field_metrics(
    sim_rows: pd.DataFrame,
    windows: pd.DataFrame,
    traffic: EmpiricalTraffic,
    road,
    t0: float,
    t_max: float,
) -> dict:
    """Edie speed fields of simulated and recorded traffic in the moving visible window.

    Args:
        sim_rows: simulated vehicles' log rows (time, x, lane, speed) at the sample times.
        windows: per sample time, ``time`` and the visible window ``x0``, ``x1``.
        traffic: the recording.
        t0, t_max: [s] the episode.
    """
    times = windows["time"].to_numpy()
    snaps = traffic.snapshots(road, t0 + times, windows["x0"].to_numpy(), windows["x1"].to_numpy())
    recorded = pd.DataFrame({"time": times[snaps["query"]], "x": snaps["x"],
                             "lane": snaps["lane"], "speed": snaps["speed"]})  # fmt: skip
    lo = np.floor(windows["x0"].min() / CELL_X) * CELL_X
    hi = np.ceil(windows["x1"].max() / CELL_X) * CELL_X
    x_edges = np.arange(lo, hi + CELL_X / 2, CELL_X)
    t_edges = np.arange(0.0, t_max + 1e-9, CELL_T)
    if t_edges[-1] < t_max - 1e-9:
        t_edges = np.append(t_edges, t_max)
    min_count = MIN_CELL_TIME / SAMPLE_PERIOD

    def fields(lane_rows):
        out = []
        for frame in (sim_rows, recorded):
            rows = frame[lane_rows(frame)]
            out.append(
                speed_field(
                    rows["time"].to_numpy(),
                    rows["x"].to_numpy(),
                    rows["speed"].to_numpy(dtype=np.float64),
                    t_edges,
                    x_edges,
                )
            )
        return out

    result = {"cell_m": CELL_X, "cell_s": CELL_T, "min_cell_vehicle_s": MIN_CELL_TIME}
    diffs = []
    for lane in LANES:
        sim, rec = fields(lambda frame, lane=lane: frame["lane"].to_numpy() == lane)
        both = (sim.count >= min_count) & (rec.count >= min_count)
        diff = (sim.speed - rec.speed)[both]
        diffs.append(diff)
        result[f"lane_{lane}"] = _field_summary(diff, both.sum())
    result["all_lanes"] = _field_summary(np.concatenate(diffs), sum(d.size for d in diffs))
    return result


def _field_summary(diff: np.ndarray, cells: int) -> dict:
    if diff.size == 0:
        return {"cells_compared": 0}
    return {
        "cells_compared": int(cells),
        "rmse_mps": _r(np.sqrt(np.mean(diff**2))),
        "mae_mps": _r(np.mean(np.abs(diff))),
        "bias_mps": _r(np.mean(diff)),
    }


def _r(value: float) -> float:
    return round(float(value), 4)
