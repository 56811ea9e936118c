"""Time-space diagrams of recorded traffic, one panel per lane, as in the paper's figures
(and one for an on-ramp's acceleration lane, lane -5, where vehicles were recorded on it)."""

import os
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.dates as mdates
import matplotlib.pyplot as plt
import numpy as np

from twin.core import i24
from twin.core.atomic import atomic_file
from twin.core.errors import StoreError
from twin.core.i24 import Road
from twin.core.ramps import RAMP_LANE
from twin.core.timeutil import CST, format_local
from twin.data.store import TrajectoryStore

SPEED_RANGE = (0.0, 35.0)  # [m/s] colour scale
#: Speed colours: lightness grows with speed, so they read in greyscale and to a
#: colour-blind reader (red-green scales do neither).
SPEED_CMAP = "cividis"
MAX_POINTS_PER_LANE = 400_000


def time_space_plot(
    store: TrajectoryStore, road: Road | str, start: float, minutes: float, out: str | os.PathLike
) -> Path:
    """Plot every lane's trajectories as points coloured by speed; mile markers on the y axis.
    Samples on an on-ramp's acceleration lane (lane -5) get a panel of their own below
    lane -4's, where there are any.

    Args:
        store: the data.
        road: the carriageway.
        start: [s] unix time of the left edge.
        minutes: [min] span plotted.
        out: PNG path (written to a temporary file and renamed).

    Raises:
        StoreError: when the window holds no samples (naming what the store covers).
    """
    road = Road.parse(road)
    end = start + 60.0 * minutes
    samples = store.samples(road, start, end, ramps=True)
    if len(samples["t"]) == 0:
        t_min, t_max = store.time_range(road)
        raise StoreError(
            f"no {road.value} samples between {format_local(start)} and {format_local(end)} CST "
            f"(unix {start:.0f} to {end:.0f}); the store covers {format_local(t_min)} to "
            f"{format_local(t_max)} CST on this road"
        )
    lanes = panel_lanes(samples["lane"])
    fig, axes = plt.subplots(
        len(lanes), 1, figsize=(12, 2.75 * len(lanes)), sharex=True, constrained_layout=True
    )
    points = None
    where = i24.mile_marker(samples["x"], road)
    span = (float(where.min()), float(where.max()))
    for ax, lane in zip(axes, lanes, strict=True):
        rows = np.flatnonzero(samples["lane"] == lane)
        step = max(1, len(rows) // MAX_POINTS_PER_LANE)
        rows = rows[::step]
        when = (samples["t"][rows] / 86400.0) + mdates.date2num(np.datetime64("1970-01-01"))
        points = ax.scatter(
            when,
            i24.mile_marker(samples["x"][rows], road),
            c=samples["speed"][rows],
            s=0.4,
            cmap=SPEED_CMAP,
            vmin=SPEED_RANGE[0],
            vmax=SPEED_RANGE[1],
            rasterized=True,
            linewidths=0,
        )
        for mm in (i24.SEGMENT_START_MM, i24.SEGMENT_END_MM):
            ax.axhline(mm, color="0.4", lw=0.6, ls="--")
        ax.set_ylabel(f"{lane_name(lane)}\nmile marker")
        # one scale for every panel; travel goes up the page either way
        ax.set_ylim(span[::-1] if road is Road.WESTBOUND else span)
        ax.grid(alpha=0.2)
    axes[-1].xaxis.set_major_locator(mdates.MinuteLocator(interval=max(1, round(minutes / 8))))
    axes[-1].xaxis.set_major_formatter(mdates.DateFormatter("%H:%M", tz=CST))
    axes[-1].set_xlabel("local time (CST)")
    fig.colorbar(points, ax=axes, label="speed [m/s]", shrink=0.6)
    fig.suptitle(f"I-24 {road.value}, {len(np.unique(samples['tid'])):,} trajectories")
    return save_figure(fig, out, dpi=110)


def panel_lanes(lanes: np.ndarray) -> tuple[int, ...]:
    """The lanes a time-space figure gives a panel: the four, and an on-ramp's
    acceleration lane (-5) where ``lanes`` (the samples') hold it."""
    return i24.LANES + ((RAMP_LANE,) if np.any(lanes == RAMP_LANE) else ())


def lane_name(lane: int) -> str:
    """``lane -1 (HOV)``, ``lane -2``, ..., ``lane -5 (on-ramp)``."""
    return f"lane {lane}" + {i24.HOV_LANE: " (HOV)", RAMP_LANE: " (on-ramp)"}.get(lane, "")


def clock(t: float) -> str:
    """``YYYY-MM-DD HH:MM:SS.s CST`` of unix seconds ``t`` (I-24 local time), for labels."""
    return f"{format_local(t, tenths=True)} CST"


def save_figure(fig, out: str | os.PathLike, *, dpi: int = 100) -> Path:
    """Save a matplotlib figure as ``out`` (temporary name, then renamed) and close it."""
    try:
        with atomic_file(out) as tmp:
            fig.savefig(tmp, dpi=dpi)
    finally:
        plt.close(fig)
    return Path(out)
