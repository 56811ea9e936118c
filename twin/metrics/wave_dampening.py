"""What a wave-dampening benchmark reports of one run (``metrics.json`` ``control``).

The words are the field's (the CIRCLES and Stern et al. wave-dampening benchmarks'):
fuel economy of the AV (the ego), of its K followers and of the window
(:mod:`twin.metrics.economy`); the speed standard deviation and the wave amplitude behind the
AV, and the speed standard deviation of every simulated vehicle (the window's, which a
fleet of AVs is meant to lower); throughput past the ego's starting point; safety
(minimum time to collision, the share of time under 4 s, time gaps); comfort
(acceleration and jerk RMS).

Gaps are measured from the log at :data:`SAMPLE_PERIOD`: the AV's leader is the
nearest vehicle ahead in its lane, simulated or ghost, bumper to bumper.
"""

import math

import numpy as np
import pandas as pd

SAMPLE_PERIOD = 0.1  # [s] the log is read at 10 Hz (the ghosts' rate)
TTC_ALERT = 4.0  # [s] time to collision counted as critical below this
MOVING = 1.0  # [m/s] time gaps are taken while the AV moves faster than this


def sample(rows: pd.DataFrame, dt: float, period: float = SAMPLE_PERIOD) -> pd.DataFrame:
    """The rows at whole multiples of ``period`` (steps of ``dt``)."""
    every = max(1, round(period / dt))
    step = np.round(rows["time"].to_numpy() / dt).astype(np.int64)
    return rows[step % every == 0]


def leader_gaps(
    ego: pd.DataFrame, others: pd.DataFrame, length: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Per row of ``ego`` (sampled): the bumper-to-bumper gap [m] to the nearest vehicle
    ahead in its lane among ``others`` (rows ``time``, ``lane``, ``x`` back centre,
    ``speed``, ``tid``) at the same time, and that vehicle's speed; ``inf`` and NaN
    where none.

    Args:
        length: [m] vehicle length per store tid.
    """
    gap = np.full(len(ego), math.inf)
    speed = np.full(len(ego), math.nan)
    if len(ego) == 0 or len(others) == 0:
        return gap, speed
    front = ego["x"].to_numpy() + length[ego["tid"].to_numpy().astype(np.int64)]
    # one sorted key (time, lane, x) for all the others; each ego row's query finds the
    # first vehicle at or past front - 1 m in its lane at its time
    times = np.unique(np.round(others["time"].to_numpy(), 6))
    t_other = np.searchsorted(times, np.round(others["time"].to_numpy(), 6))
    t_ego = np.searchsorted(times, np.round(ego["time"].to_numpy(), 6))
    t_ego_ok = (t_ego < times.size) & (
        times[np.minimum(t_ego, times.size - 1)] == np.round(ego["time"].to_numpy(), 6)
    )
    span = 1.0e5  # [m] beyond any road-frame x
    key_other = (t_other * 8 + (-others["lane"].to_numpy().astype(np.int64) + 3)) * span + (
        others["x"].to_numpy() + span / 2
    )
    order = np.argsort(key_other, kind="stable")
    key_other = key_other[order]
    group = (t_ego * 8 + (-ego["lane"].to_numpy().astype(np.int64) + 3)) * span
    query = group + front - 1.0 + span / 2
    at = np.searchsorted(key_other, query, side="right")
    inside = t_ego_ok & (at < key_other.size)
    at = np.minimum(at, key_other.size - 1)
    inside &= key_other[at] < group + span  # the same time and lane
    rows = order[at[inside]]
    gap[inside] = others["x"].to_numpy()[rows] - front[inside]
    speed[inside] = others["speed"].to_numpy()[rows]
    return gap, speed


def control_figures(
    vehicles: pd.DataFrame,
    ghosts: pd.DataFrame,
    ego_id: int,
    followers: list[int],
    length: np.ndarray,
    dt: float,
) -> dict:
    """The benchmark figures of one run (see the module doc).

    Args:
        vehicles: the log's simulated-vehicle rows (``time``, ``id``, ``tid``, ``lane``,
            ``x``, ``speed``). ghosts: the log's ghost rows.
        ego_id: the AV. followers: its followers' ids (:func:`twin.metrics.economy.followers`).
        length: [m] vehicle length per store tid. dt: [s] the log's step.
    """
    rows = sample(vehicles, dt)
    ego = rows[rows["id"] == ego_id].sort_values("time")
    others = pd.concat(
        [
            rows[rows["id"] != ego_id][["time", "lane", "x", "speed"]],
            ghosts[["time", "lane", "x", "speed"]],
        ]
    )
    gap, lead_speed = leader_gaps(ego, others, length)
    v = ego["speed"].to_numpy()
    closing = v - lead_speed
    with np.errstate(invalid="ignore", divide="ignore"):
        ttc = np.where((closing > 0) & np.isfinite(gap), np.maximum(gap, 0.0) / closing, np.inf)
        time_gap = np.where((v > MOVING) & np.isfinite(gap), gap / v, np.nan)
    accel = np.diff(v) / SAMPLE_PERIOD
    jerk = np.diff(accel) / SAMPLE_PERIOD
    behind = rows[rows["id"].isin(followers)]
    per_follower = behind.groupby("id")["speed"]
    gaps = time_gap[np.isfinite(time_gap)]
    duration = float(rows["time"].max() - rows["time"].min()) if len(rows) else 0.0
    return {
        "followers": [int(i) for i in followers],
        "speed_std_behind_mps": _r(per_follower.std(ddof=0).mean()) if len(behind) else None,
        "speed_std_window_mps": _window_speed_std(rows),
        "wave_amplitude_behind_mps": _r((per_follower.max() - per_follower.min()).mean())
        if len(behind)
        else None,
        "throughput_veh_per_h": _r(_crossings(rows, float(ego["x"].iloc[0])) / duration * 3600.0)
        if duration > 0 and len(ego)
        else None,
        "min_ttc_s": _r(np.min(ttc)) if np.isfinite(ttc).any() else None,
        "ttc_under_4s_share": _r(np.mean(ttc < TTC_ALERT)) if ttc.size else None,
        "time_gap_s": {
            "p10": _r(np.percentile(gaps, 10)) if gaps.size else None,
            "median": _r(np.median(gaps)) if gaps.size else None,
            "p90": _r(np.percentile(gaps, 90)) if gaps.size else None,
            "min": _r(gaps.min()) if gaps.size else None,
        },
        "accel_rms_mps2": _r(np.sqrt(np.mean(accel**2))) if accel.size else None,
        "jerk_rms_mps3": _r(np.sqrt(np.mean(jerk**2))) if jerk.size else None,
    }


def _window_speed_std(rows: pd.DataFrame) -> float | None:
    """Each simulated vehicle's speed standard deviation over its time in the log (10 Hz
    samples), averaged over the vehicles weighted by their samples: how much the
    window's traffic oscillates, whoever drives it."""
    per_vehicle = rows.groupby("id")["speed"].agg(["std", "count"])  # both skip NaN
    per_vehicle = per_vehicle[per_vehicle["count"] >= 2]
    if per_vehicle.empty:
        return None
    # std with ddof 0 from pandas' ddof 1: sqrt((n - 1) / n)
    n = per_vehicle["count"].to_numpy(float)
    std = per_vehicle["std"].to_numpy(float) * np.sqrt((n - 1.0) / n)
    return _r(np.sum(std * n) / np.sum(n))


def _crossings(rows: pd.DataFrame, x0: float) -> int:
    """Simulated vehicles that pass ``x0`` (from behind it to beyond it)."""
    first = rows.groupby("id")["x"].first()
    last = rows.groupby("id")["x"].last()
    return int(((first < x0) & (last >= x0)).sum())


def _r(value) -> float | None:
    value = float(value)
    return round(value, 4) if math.isfinite(value) else None
