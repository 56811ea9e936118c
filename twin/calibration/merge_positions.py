"""Where the recording's ramp vehicles merge: for each on-ramp of a road, the places
(road-frame x of the vehicle's back) where the recorded vehicles on its acceleration
lane (lane -5) crossed into lane -4 (the last time, where a track wobbles), as
quantiles (``calibration.json``'s ``merges``).

The traffic core's ramp drivers merge where these say (a quantile drawn per vehicle,
or, ``recorded``, the vehicle's own merge): they want the merge from
:data:`MERGE_LEAD` metres before that place and must have made it by there
(:func:`twin.cosim.core.drivers.merge_target`); without them, by the taper's start.
Wanted from the gore instead (as before these), on a long acceleration lane in a queue
lane -4 made room for every ramp vehicle beside it for a kilometre, where the
recording's drivers merge near the taper.
"""

import numpy as np

from twin.calibration.following import CalibrationDataError
from twin.core.i24 import Road
from twin.core.ramps import RAMP_LANE, SPAN_MARGIN, Ramp, ramp_spans, segment_ramps

QUANTILES = 21  # 0, 5, ..., 100 %
MIN_MERGES = 10  # fewer merges on a ramp leave it to the default place (the taper's start)
MERGE_LEAD = 150.0  # [m] before its merge place a ramp driver starts to want the merge


def recorded_merges(samples: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The merges in ``samples`` (a store's samples with the ramps', sorted by (tid, t):
    :meth:`~twin.data.store.TrajectoryStore.samples` with ``ramps=True``): per
    trajectory whose lane -5 samples are followed by one in lane -4, its last such
    step's (tid, x [m] back, t [s]) at the lane -4 sample.
    """
    tid, lane = np.asarray(samples["tid"]), np.asarray(samples["lane"])
    step = np.nonzero((lane[:-1] == RAMP_LANE) & (lane[1:] == -4) & (tid[:-1] == tid[1:]))[0] + 1
    if step.size == 0:
        return np.zeros(0, np.int64), np.zeros(0), np.zeros(0)
    tids = tid[step]
    last = np.r_[tids[1:] != tids[:-1], True]  # samples sorted by tid: the last per tid
    k = step[last]
    return (
        tid[k].astype(np.int64),
        np.asarray(samples["x"])[k].astype(np.float64),
        np.asarray(samples["t"])[k].astype(np.float64),
    )


def ramp_of(x: np.ndarray, spans: np.ndarray) -> np.ndarray:
    """Index into ``spans`` (:func:`~twin.core.ramps.ramp_spans`, one road's, by x) of the
    ramp whose lane holds each merge place ``x``, within SPAN_MARGIN of its ends as
    :func:`~twin.core.ramps.on_ramp` judges; -1 where none does."""
    which = np.full(np.shape(x), -1, np.int64)
    for k in range(spans.shape[0]):
        inside = (x >= spans[k, 0] - SPAN_MARGIN) & (x <= spans[k, -1] + SPAN_MARGIN)
        which[inside & (which < 0)] = k
    return which


def road_ramps(road: Road | str) -> tuple[Ramp, ...]:
    """The segment's on-ramps joining ``road``, by x."""
    road = Road.parse(road)  # in ramp_spans' order
    return tuple(sorted((r for r in segment_ramps() if r.road == road), key=lambda r: r.x_start))


def merge_section(samples: dict, road: Road | str) -> list[dict]:
    """``calibration.json``'s ``merges`` of ``road``: per on-ramp (by x) its name, gore
    and taper's end [m], how many recorded vehicles merged from it, and, with at least
    :data:`MIN_MERGES`, the :data:`QUANTILES` quantiles of where (``x_quantiles``, back
    x [m]; ``None`` otherwise)."""
    ramps = road_ramps(road)
    _, x, _ = recorded_merges(samples)
    which = ramp_of(x, ramp_spans(road, ramps))
    out = []
    for k, ramp in enumerate(ramps):
        xs = x[which == k]
        q = np.quantile(xs, np.linspace(0.0, 1.0, QUANTILES)) if xs.size >= MIN_MERGES else None
        out.append({
            "ramp": ramp.name,
            "gore_m": round(float(ramp.x_start), 3),
            "end_m": round(float(ramp.x_end), 3),
            "merged": int(xs.size),
            "x_quantiles": None if q is None else [round(float(v), 3) for v in q],
        })  # fmt: skip
    return out


def ramp_entries(section: list | None, name: str) -> list:
    """A road's per-on-ramp section ``name`` of ``calibration.json`` (``merges``,
    ``ramp_speeds``) as its list of entries; [] where there is none.

    Raises:
        CalibrationDataError: the section is not a list.
    """
    if section is None:
        return []
    if not isinstance(section, list):
        raise CalibrationDataError(
            f"calibration.json: {name} must be a list of on-ramps, got "
            f"{type(section).__name__} (calibrate again)"
        )
    return section


def merge_table(section: list[dict] | None) -> np.ndarray:
    """(k, 1 + QUANTILES) [m] of a road's ``merges`` section for the core: per ramp with
    quantiles, its taper's end then its quantiles (:func:`merge_section`); (0, 1 +
    QUANTILES) where there are none. A taper's end that matches no ramp of the map
    (the core matches them within a metre) is not used.

    Raises:
        CalibrationDataError: the section is not as :func:`merge_section` writes it.
    """
    rows = []
    for entry in ramp_entries(section, "merges"):
        q = entry.get("x_quantiles") if isinstance(entry, dict) else None
        if isinstance(entry, dict) and q is None:
            continue  # too few merges to place
        try:
            row = np.array([entry["end_m"], *q], dtype=np.float64)
        except (KeyError, TypeError, ValueError):
            row = None
        if row is None or row.size != 1 + QUANTILES or not np.all(np.isfinite(row)):
            raise CalibrationDataError(
                f"calibration.json: a merges entry needs end_m and {QUANTILES} finite "
                f"x_quantiles (or null), got {entry!r:.200} (calibrate again)"
            )
        rows.append(row)
    return np.array(rows, np.float64).reshape(-1, 1 + QUANTILES)


def describe_merges(section: list[dict]) -> list[str]:
    """Lines for ``twin calibrate``'s and ``twin data info``'s summary of a road's
    ``merges`` (an entry not as :func:`merge_section` writes it is said to be so)."""
    lines = []
    for r in section if isinstance(section, list) else [section]:
        q = r.get("x_quantiles") if isinstance(r, dict) else None
        try:
            where = (
                f"median x {q[QUANTILES // 2]:.0f} m (10 to 90 %: {q[2]:.0f} to {q[-3]:.0f} m)"
                if q is not None
                else f"too few to place (need {MIN_MERGES}): merges by the taper's start"
            )
            lines.append(
                f"    on-ramp {r['ramp']}: {r['merged']} merges, {where}; taper ends at "
                f"x {r['end_m']:.0f} m"
            )
        except (KeyError, TypeError, IndexError, ValueError):
            lines.append(f"    on-ramp merges: malformed entry {r!r:.120} (calibrate again)")
    return lines
