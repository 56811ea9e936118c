"""How fast the recording's ramp vehicles drive on an on-ramp's acceleration lane
(lane -5) with nothing close ahead: per on-ramp, the free-flow speeds of its lane, found
as :func:`~twin.calibration.following.free_flow_speeds` finds the through lanes'
(``calibration.json``'s ``ramp_speeds``).

A ramp driver wants these while it is on the acceleration lane, and its own desired
speed once it has merged (:func:`twin.cosim.core.drivers.ramp_speed`). Without them a
ramp driver wanted its through-lane speed on an empty ramp: on SUMO's on-ramp morning
(a ramp signed for 16.7 m/s, its drivers cruising at it) a ramp vehicle the twin had
spawned behind no other ran up to 33 m/s, passed its recording by 140 m, found no gap
at that speed and stopped at the taper's end in front of the ego. Where the recording's
ramp drivers accelerate along the lane rather than cruise (no driver's free speeds stay
within :data:`~twin.calibration.following.FREE_SPREAD` for 5 s), too few are free and
the ramp keeps its drivers' own desired speeds.
"""

import numpy as np

from twin.calibration.distributions import speed_summary
from twin.calibration.following import CalibrationDataError, free_flow_speeds, ramp_grid
from twin.calibration.merge_positions import ramp_entries, ramp_of, road_ramps
from twin.core.i24 import Road
from twin.core.ramps import RAMP_LANE, ramp_spans

MIN_FREE = 5  # fewer free ramp vehicles leave the ramp's drivers their own desired speeds
MAX_RAMP_SPEED = 60.0  # [m/s] no spawn is faster (twin.cosim.core.handover.MAX_SPEED)


def ramp_speed_section(store, road: Road | str, samples: dict, t0: float) -> list[dict]:
    """``calibration.json``'s ``ramp_speeds`` of ``road``: per on-ramp (by x) its name
    and taper's end [m], how many of its vehicles were free on its acceleration lane,
    and, with at least :data:`MIN_FREE`, the summary of their free-flow speeds
    (``free_speed``: count, mean, sd, p10, p50, p90 [m/s]; ``None`` otherwise).
    ``samples``: the store's samples with the ramps' (sorted by (tid, t)), ``t0`` [s]
    the grid's start."""
    road = Road.parse(road)
    ramps = road_ramps(road)
    lane = np.asarray(samples["lane"])
    which = ramp_of(np.asarray(samples["x"], np.float64), ramp_spans(road, ramps))
    out = []
    for k, ramp in enumerate(ramps):
        keep = (lane == RAMP_LANE) & (which == k)
        on = {name: np.asarray(column)[keep] for name, column in samples.items()}
        free = free_flow_speeds(ramp_grid(store, road, on, t0))
        out.append({
            "ramp": ramp.name,
            "end_m": round(float(ramp.x_end), 3),
            "free": len(free),
            "free_speed": speed_summary(free.speed) if len(free) >= MIN_FREE else None,
        })  # fmt: skip
    return out


def ramp_speed_table(section: list[dict] | None) -> np.ndarray:
    """(k, 3) of a road's ``ramp_speeds`` section for the core: per ramp with free-flow
    speeds, its taper's end [m], their mean and sd [m/s]; (0, 3) where none has them
    (a calibration made before ramp speeds were measured). A taper's end that matches no
    ramp of the map (the core matches them within a metre) is not used.

    Raises:
        CalibrationDataError: the section is not as :func:`ramp_speed_section` writes it.
    """
    rows = []
    for entry in ramp_entries(section, "ramp_speeds"):
        speed = entry.get("free_speed") if isinstance(entry, dict) else None
        if isinstance(entry, dict) and speed is None:
            continue  # too few free to say
        try:
            values = [entry["end_m"], speed["mean"], speed["sd"]]
        except (KeyError, TypeError):
            values = None
        if values is None or not all(_number(v) for v in values):
            row = None
        else:
            row = np.array(values, dtype=np.float64)
        if (
            row is None or not np.all(np.isfinite(row))
            or not 0.0 < row[1] <= MAX_RAMP_SPEED or row[2] < 0.0
        ):  # fmt: skip
            raise CalibrationDataError(
                "calibration.json: a ramp_speeds entry needs a number end_m and a free_speed "
                f"with a mean in (0, {MAX_RAMP_SPEED:.0f}] m/s and an sd >= 0 (or null), got "
                f"{entry!r:.200} (calibrate again)"
            )
        rows.append(row)
    return np.array(rows, np.float64).reshape(-1, 3)


def _number(value) -> bool:
    """Whether ``value`` is a real number as JSON writes one (not a bool, nor a string)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def describe_ramp_speeds(section: list[dict] | None) -> list[str]:
    """Lines for ``twin calibrate``'s and ``twin data info``'s summary of a road's
    ``ramp_speeds`` (an entry not as :func:`ramp_speed_section` writes it is said to
    be so)."""
    lines = []
    for r in [] if section is None else section if isinstance(section, list) else [section]:
        try:
            speed = r["free_speed"]
            if speed is None:
                lines.append(
                    f"    on-ramp {r['ramp']}: {r['free']} free on its lane, too few (need "
                    f"{MIN_FREE}): its drivers want their own desired speeds there"
                )
            else:
                lines.append(
                    f"    on-ramp {r['ramp']}: {speed['count']} free on its lane at "
                    f"{speed['p50']:.1f} m/s (10 to 90 %: {speed['p10']:.1f} to "
                    f"{speed['p90']:.1f}), wanted there"
                )
        except (KeyError, TypeError, IndexError, ValueError):
            lines.append(f"    on-ramp speeds: malformed entry {r!r:.120} (calibrate again)")
    return lines
