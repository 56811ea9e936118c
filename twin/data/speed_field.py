"""Traffic-flow measurements on trajectory samples: Edie speed fields and wave speeds."""

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class SpeedField:
    """Space-mean speed per (time, x) cell (Edie's definition on equal-time samples).

    Attributes:
        t_edges: (nt + 1,) [s] cell edges in time.
        x_edges: (nx + 1,) [m] cell edges in road-frame x.
        speed: (nt, nx) [m/s] total distance / total time travelled in the cell;
            nan where no vehicle was.
        count: (nt, nx) samples in the cell.
    """

    t_edges: np.ndarray
    x_edges: np.ndarray
    speed: np.ndarray
    count: np.ndarray


def speed_field(
    t: np.ndarray, x: np.ndarray, speed: np.ndarray, t_edges: np.ndarray, x_edges: np.ndarray
) -> SpeedField:
    """Edie speed field from samples taken at a fixed rate.

    With samples at a fixed rate each stands for the same time, so the cell's total
    distance over total time is the mean of its sample speeds.

    Args:
        t, x, speed: (n,) sample time [s], road-frame x [m] and speed [m/s].
        t_edges, x_edges: increasing cell edges.
    """
    ti = np.searchsorted(t_edges, t, side="right") - 1
    xi = np.searchsorted(x_edges, x, side="right") - 1
    nt, nx = len(t_edges) - 1, len(x_edges) - 1
    inside = (ti >= 0) & (ti < nt) & (xi >= 0) & (xi < nx)
    flat = ti[inside] * nx + xi[inside]
    count = np.bincount(flat, minlength=nt * nx).reshape(nt, nx)
    total = np.bincount(flat, weights=speed[inside], minlength=nt * nx).reshape(nt, nx)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(count > 0, total / count, np.nan)
    return SpeedField(np.asarray(t_edges), np.asarray(x_edges), mean, count)


@dataclass(frozen=True)
class WaveFit:
    """A wave front tracked through a speed field.

    Attributes:
        speed: [m/s] front velocity along the road (negative: moving upstream).
        x: (k,) [m] centres of the cells where the front was found.
        t: (k,) [s] times at which the speed first dropped below the threshold there.
        r2: coefficient of determination of the straight-line fit t(x).
    """

    speed: float
    x: np.ndarray
    t: np.ndarray
    r2: float


def wave_front_speed(field: SpeedField, threshold: float, t_after: float) -> WaveFit:
    """Fit the velocity of the first congestion front after ``t_after``.

    For every x cell, the front arrives at the first time cell after ``t_after`` whose
    speed is below ``threshold``; the front's velocity is the slope dx/dt of a least
    squares line through those arrival times.

    Raises:
        ValueError: when fewer than three cells see the front.
    """
    t_mid = 0.5 * (field.t_edges[1:] + field.t_edges[:-1])
    x_mid = 0.5 * (field.x_edges[1:] + field.x_edges[:-1])
    later = t_mid >= t_after
    slow = (field.speed < threshold) & later[:, None]
    seen = slow.any(axis=0)
    if np.count_nonzero(seen) < 3:
        raise ValueError(f"a congestion front below {threshold} m/s reaches fewer than 3 cells")
    arrival = t_mid[np.argmax(slow, axis=0)][seen]
    xs = x_mid[seen]
    slope, intercept = np.polyfit(xs, arrival, 1)
    residual = arrival - (slope * xs + intercept)
    r2 = 1.0 - residual.var() / arrival.var() if arrival.var() > 0 else 0.0
    return WaveFit(speed=float(1.0 / slope), x=xs, t=arrival, r2=float(r2))
