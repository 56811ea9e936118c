"""Whether the recording's drivers pass on the right: where a driver's own lane is open
and a vehicle drives a little ahead of it in the lane to its left, is it faster than
that vehicle as often as its free speed would make it (it passes), or does it keep to
that vehicle's speed (it does not; ``calibration.json``'s ``passing_right``, which sets
the traffic core's ``traffic.no_pass_right_from``,
:func:`twin.traffic.kernels.longitudinal.not_passing_right`).

US freeway drivers pass on the right; European drivers, and SUMO's LC2013 drivers, do
not above 60 km/h (LC2013 has them follow the slower vehicle on their left as a leader
unless the traffic is congested). A twin whose drivers pass where the recording's do
not makes the right-hand lanes too fast.

At every 0.1 s step of the calibration window where a vehicle of lane -4 or -3 drives at
:data:`FROM_SPEED` or faster with its own lane open :data:`OPEN_GAP` metres ahead, the
nearest vehicle ahead of its front in the lane to its left (the vehicle's ``left
leader``) is either at most :data:`NEAR` metres ahead and itself at :data:`FROM_SPEED`
or faster (a judged step: where the left lane crawls, passing it says nothing of the
rule) or not within :data:`CLEAR` (a free step). ``passing`` is the share of judged
steps in which the vehicle is :data:`FASTER` than its left leader; ``expected`` is the
share it would be, were its speed the free steps' (each judged left leader's speed
against the free steps' speeds). Drivers who pass freely give ``passing`` about
``expected`` (ratio 0.95 on the synthesiser's preset D, whose drivers are the twin's);
drivers who do not, much less (0.00 and 0.22 on SUMO's on-ramp and lane-drop mornings).
Where the ratio is under :data:`MAX_RATIO`, the twin's drivers do not pass on the right
from :data:`FROM_SPEED`. A road with fewer than :data:`MIN_STEPS` judged or free steps,
judged steps of fewer than :data:`MIN_VEHICLES` vehicles, or an ``expected`` under
:data:`MIN_EXPECTED` (left leaders that are seldom slower: nothing to tell), is not
identified, and the twin's drivers pass there as they always have.

The lane -2 drivers are not judged: the HOV lane to their left is behind its double
line, not a lane to move into to pass (SUMO's drivers pass it too).
"""

import math

import numpy as np

from twin.calibration.following import CalibrationDataError, GridTraffic

FROM_SPEED = 60.0 / 3.6  # [m/s] the rule holds from this speed (LC2013's congestion speed)
OPEN_GAP = 80.0  # [m] own lane open at least this far ahead
NEAR = 40.0  # [m] a judged step's left leader: at most this far ahead of the front
CLEAR = 60.0  # [m] a free step has no left leader within this of its front
FASTER = 1.0  # [m/s] passing: faster than the left leader by more than this
MAX_RATIO = 0.5  # passing under this share of expected: drivers do not pass on the right
MIN_STEPS = 500  # judged and free steps a road needs (0.1 s each)
MIN_VEHICLES = 20  # vehicles the judged steps must be of
MIN_EXPECTED = 0.05  # an expected share under this tells nothing
LANES = (-4, -3)  # the lanes judged: those whose left lane is one to pass in


def left_leaders(grid: GridTraffic) -> tuple[np.ndarray, np.ndarray]:
    """(n,) row of the nearest vehicle whose back is ahead of each row's front in the
    lane to its left at the same step, -1 where none (or the row has no lane), and
    (n,) [m] the gap from the front to it (inf where none)."""
    lane = grid.lane.astype(np.int64)
    k = grid.k - (grid.k.min() if grid.k.size else 0)
    span = float(np.ptp(grid.x)) + 2.0 * float(grid.length.max()) + 1.0 if grid.k.size else 1.0
    base = grid.x.min() - grid.length.max() if grid.k.size else 0.0
    on = lane != 0
    rows = np.flatnonzero(on)
    key = (k[rows] * 8 - lane[rows]) * span + (grid.x[rows] - base)
    order = np.argsort(key, kind="stable")
    sorted_key, sorted_rows = key[order], rows[order]
    asking = np.flatnonzero(on & (lane <= -2))
    front = grid.x[asking] + grid.length[asking]
    query = (k[asking] * 8 - (lane[asking] + 1)) * span + (front - base)
    at = np.searchsorted(sorted_key, query, side="right")
    found = at < sorted_rows.size
    row = np.full(len(grid), -1, dtype=np.int64)
    candidate = sorted_rows[np.minimum(at, sorted_rows.size - 1)] if sorted_rows.size else at
    same = found & (grid.k[candidate] == grid.k[asking]) & (lane[candidate] == lane[asking] + 1)
    row[asking[same]] = candidate[same]
    gap = np.full(len(grid), np.inf)
    has = row >= 0
    gap[has] = grid.x[row[has]] - grid.x[has] - grid.length[has]
    return row, gap


def passing_section(grid: GridTraffic) -> dict:
    """``calibration.json``'s ``passing_right`` of a road (module doc): ``judged`` and
    ``free`` steps, ``passing`` and ``expected`` shares and their ``ratio`` (None where
    not identified), ``identified``, and ``no_pass_right_from`` [m/s] (None: the
    drivers pass).

    Args:
        grid: the road's recording in the calibration window
            (:func:`~twin.calibration.following.load_grid`).
    """
    row, gap = left_leaders(grid)
    base = np.isin(grid.lane, LANES) & (grid.speed >= FROM_SPEED) & (grid.gap >= OPEN_GAP)
    left_speed = np.where(row >= 0, grid.speed[np.maximum(row, 0)], np.nan)
    judged = base & (row >= 0) & (gap <= NEAR) & (left_speed >= FROM_SPEED)
    free = base & ~((row >= 0) & (gap <= CLEAR))
    n_judged, n_free = int(judged.sum()), int(free.sum())
    vehicles = int(np.unique(grid.tid[judged]).size)
    out = {
        "judged": n_judged,
        "free": n_free,
        "vehicles": vehicles,
        "passing": None,
        "expected": None,
        "ratio": None,
        "identified": False,
        "no_pass_right_from": None,
    }
    if n_judged < MIN_STEPS or n_free < MIN_STEPS or vehicles < MIN_VEHICLES:
        return out
    v, v_left = grid.speed[judged], left_speed[judged]
    speeds = np.sort(grid.speed[free])
    passing = float(np.mean(v - v_left > FASTER))
    faster_free = 1.0 - np.searchsorted(speeds, v_left + FASTER, side="right") / speeds.size
    expected = float(np.mean(faster_free))
    out.update(passing=round(passing, 4), expected=round(expected, 4))
    if expected < MIN_EXPECTED:
        return out
    ratio = passing / expected
    out.update(ratio=round(ratio, 4), identified=True)
    if ratio < MAX_RATIO:
        out["no_pass_right_from"] = round(FROM_SPEED, 4)
    return out


def no_pass_right(section: dict | None) -> dict[str, float]:
    """The traffic settings a road's ``passing_right`` section sets:
    ``no_pass_right_from`` where the drivers were found not to pass on the right, ``{}``
    where they pass, or where the section is missing or not identified.

    Raises:
        CalibrationDataError: the section is not as :func:`passing_section` writes it.
    """
    if section is None:
        return {}
    try:
        identified, speed = section["identified"], section["no_pass_right_from"]
        speed = None if speed is None else float(speed)
    except (KeyError, TypeError, ValueError):
        identified, speed = None, math.nan
    if (
        not isinstance(identified, bool)
        or (speed is not None and not (math.isfinite(speed) and speed >= 0))
        or (speed is not None and not identified)
    ):
        raise CalibrationDataError(
            "calibration.json: passing_right needs identified (true or false) and "
            "no_pass_right_from (a speed >= 0 [m/s], or null; null where not identified), "
            f"got {section!r:.200} (calibrate again)"
        )
    if not identified or speed is None:
        return {}
    return {"no_pass_right_from": speed}


def describe_passing(section: dict | None) -> list[str]:
    """Lines for ``twin calibrate``'s summary of a road's ``passing_right``."""
    if not isinstance(section, dict):
        return [] if section is None else [f"    passing on the right: malformed {section!r:.120}"]
    try:
        steps = (
            f"{section['judged']} steps of {section['vehicles']} vehicles judged, "
            f"{section['free']} free"
        )
        if not section["identified"]:
            return [f"    passing on the right: not identified ({steps}): drivers pass"]
        shares = (
            f"{section['passing']:.0%} faster than their left leader where "
            f"{section['expected']:.0%} would be, ratio {section['ratio']:.2f}"
        )
        if section["no_pass_right_from"] is None:
            return [f"    passing on the right: drivers pass ({shares}; {steps})"]
        return [
            f"    passing on the right: drivers do not, from "
            f"{section['no_pass_right_from']:.1f} m/s ({shares}; {steps})"
        ]
    except (KeyError, TypeError, ValueError):
        return [f"    passing on the right: malformed {section!r:.120} (calibrate again)"]
