"""Fidelity as numbers: the simulated run against the recording (``metrics.json``).

- Ego: the simulated ego against the recorded vehicle it was spawned from, over the
  episode while the recording has it: position and speed RMSE, the minimum speed of
  each, the final position gap.
- Traffic: the mean absolute speed error of every simulated vehicle against its own
  recording while both exist; and the Edie speed field (cells of ``CELL_X`` m by
  ``CELL_T`` s) of simulated and recorded traffic, both seen through the same moving
  visible window, compared cell by cell where both have enough samples.
"""

import numpy as np
import pandas as pd

from twin.data.i24 import LANES
from twin.data.traffic import EmpiricalTraffic
from twin.data.waves import speed_field

CELL_X = 20.0  # [m]
CELL_T = 2.0  # [s]
SAMPLE_PERIOD = 0.1  # [s] the speed field and the traffic error are sampled this often
MIN_CELL_TIME = 0.5  # [s] vehicle-seconds a cell needs in both fields to be compared


def ego_metrics(ego_rows: pd.DataFrame, recorded: dict, t0: float) -> dict:
    """The simulated ego (its log rows) against its recording (``store.trajectory``)."""
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


def traffic_speed_error(rows: pd.DataFrame, traffic: EmpiricalTraffic, t0: float) -> dict:
    """Mean absolute speed error of simulated vehicles (``rows``: their log rows, sampled)
    against the recorded vehicle each was spawned from, while both exist."""
    errors, vehicles = [], 0
    recordings = traffic.store.trajectory_samples(rows["tid"].unique())
    for tid, group in rows.groupby("tid", sort=True):
        recorded = recordings[int(tid)]
        t = t0 + group["time"].to_numpy()
        valid = (t >= recorded["t"][0]) & (t <= recorded["t"][-1])
        if not valid.any():
            continue
        v_rec = np.interp(t[valid], recorded["t"], recorded["speed"].astype(np.float64))
        errors.append(np.abs(group["speed"].to_numpy()[valid] - v_rec))
        vehicles += 1
    if not errors:
        return {"vehicles_compared": 0}
    errors = np.concatenate(errors)
    return {
        "vehicles_compared": vehicles,
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
    recorded = []
    for time, x0, x1 in windows[["time", "x0", "x1"]].itertuples(index=False):
        snap = traffic.snapshot(road, t0 + time, x0, x1)
        recorded.append(
            pd.DataFrame({"time": time, "x": snap.x, "lane": snap.lane, "speed": snap.speed})
        )
    recorded = pd.concat(recorded, ignore_index=True)
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
