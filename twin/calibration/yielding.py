"""How the recording's lane -4 drivers make room for the on-ramps' merging vehicles:
from which point of a ramp vehicle's approach to its merge place its new follower
treats it as its leader, and how hard it brakes for it (``calibration.json``'s
``yielding``), which the traffic core's cooperative layer takes
(``traffic.yield_from``, ``traffic.courtesy`` and ``traffic.cooperative_decel``,
:func:`twin.traffic.kernels.longitudinal.cooperate`).

For every recorded merge (:func:`~twin.calibration.merge_positions.recorded_merges`)
the new follower is the lane -4 vehicle just behind the merging one when it crosses.
Over the :data:`LOOK_BACK` seconds before, at each 0.1 s step where the follower is in
lane -4 behind the ramp vehicle, the road's median calibrated driver says what the
follower would do behind its own lane -4 leader (``own``) and behind the ramp vehicle
(``yield``). A step tells the two apart where yielding asks at least
:data:`DIFFERENCE` more braking; there the follower's recorded acceleration (its speed's
change over a second) is nearer one or the other.

The twin's courteous drivers (a share ``courtesy`` of them, drawn per driver) yield
from an urgency of the merging driver (0 where it starts to want the merge,
:data:`~twin.calibration.merge_positions.MERGE_LEAD` metres before its merge place, 1
at it); the others keep to their own leader. The fit takes the urgency
``yield_from`` (over 0, 0.05, ..., 1 and *never*, ``None``) and per merge whether its
follower is courteous (most of its steps from that urgency on yield) that classify the
most judged steps as the recording has them; ``courtesy`` is the share of courteous
followers among those judged from that urgency on. ``cooperative_decel`` is the
:data:`DECEL_QUANTILE` quantile of the courteous followers' braking in the yielding
steps from that urgency on (within :data:`DECEL_RANGE`; with fewer
than :data:`MIN_BRAKING` such steps the twin's default). A road with
fewer than :data:`MIN_MERGES` judged merges is not identified, and the twin keeps its
defaults there.
"""

import math

import numpy as np

from twin.calibration.following import CalibrationDataError, GridTraffic
from twin.calibration.merge_positions import MERGE_LEAD, ramp_of, recorded_merges
from twin.core.ramps import ramp_spans
from twin.traffic.models.base import CarFollowingModel

LOOK_BACK = 20.0  # [s] before a merge, the new follower's reaction is judged over this
ACCEL_SPAN = 0.5  # [s] the recorded acceleration: speed change from -this to +this
DIFFERENCE = 0.5  # [m/s^2] yielding must ask this much more braking than the own leader
MIN_MERGES = 10  # judged merges a road needs for its yielding to be identified
MIN_BRAKING = 50  # yielding steps with braking that cooperative_decel needs
DECEL_QUANTILE = 0.9
DECEL_RANGE = (0.3, 4.0)  # [m/s^2] cooperative_decel is kept within these
URGENCIES = tuple(round(0.05 * k, 2) for k in range(21))


def judged_steps(
    grid: GridTraffic, samples: dict, model: CarFollowingModel, driver
) -> dict[str, np.ndarray]:
    """The steps at which the recording tells yielding from car following behind the
    own leader (module doc): per step (n,) arrays ``merge`` (index of its merge),
    ``urgency`` of the merging vehicle [-], ``accel`` of the follower as recorded,
    ``own`` and ``yield`` as the model's ``driver`` would drive [m/s^2].

    ``grid``: the road's recording on a grid (:func:`~twin.calibration.following.
    load_grid`); ``samples``: its samples with the ramps' (sorted by (tid, t)).
    """
    spans = ramp_spans(grid.road)
    tid, x_merge, t_merge = recorded_merges(samples)
    which = ramp_of(x_merge, spans)
    out = {name: [] for name in ("merge", "urgency", "accel", "own", "yield")}
    if tid.size == 0 or len(grid) == 0:
        return {name: np.zeros(0, np.int64 if name == "merge" else np.float64) for name in out}
    first_row = np.r_[0, np.flatnonzero(np.diff(grid.tid)) + 1]
    tids, first_k = grid.tid[first_row], grid.k[first_row]
    last_row = np.r_[first_row[1:], len(grid)] - 1
    in_lane = np.flatnonzero(grid.lane == -4)
    by_step = in_lane[np.lexsort((grid.x[in_lane], grid.k[in_lane]))]
    step_of = grid.k[by_step]
    span = max(1, round(ACCEL_SPAN / grid.dt))
    back = round(LOOK_BACK / grid.dt)
    s_tid, s_t = samples["tid"], samples["t"]
    for m in range(tid.size):
        if which[m] < 0:
            continue
        ramp = spans[which[m]]
        gore, end = ramp[0], ramp[-1]
        a, b = np.searchsorted(s_tid, [tid[m], tid[m] + 1])
        km = round((t_merge[m] - grid.t0) / grid.dt)
        length = _length_of(grid, tids, first_row, tid[m])
        if b - a < 2 or length is None:
            continue
        t_r, x_r = s_t[a:b], samples["x"][a:b].astype(np.float64)
        v_r = samples["speed"][a:b].astype(np.float64)
        x_at = np.interp(grid.t0 + km * grid.dt, t_r, x_r)
        lo, hi = np.searchsorted(step_of, [km, km + 1])
        behind = by_step[lo:hi][grid.x[by_step[lo:hi]] + grid.length[by_step[lo:hi]] <= x_at]
        behind = behind[grid.tid[behind] != tid[m]]
        if behind.size == 0:
            continue
        f = behind[-1]  # the new follower: the nearest behind, by x
        j = np.searchsorted(tids, grid.tid[f])
        ks = np.arange(max(km - back, first_k[j] + span, math.ceil((t_r[0] - grid.t0) / grid.dt)),
                       min(km, first_k[j] + last_row[j] - first_row[j] - span) + 1)  # fmt: skip
        if ks.size == 0:
            continue
        rows = first_row[j] + ks - first_k[j]
        ts = grid.t0 + ks * grid.dt
        xr, vr = np.interp(ts, t_r, x_r), np.interp(ts, t_r, v_r)
        gap = xr - grid.x[rows] - grid.length[rows]
        keep = (grid.lane[rows] == -4) & (gap > 0.0)
        if not keep.any():
            continue
        rows, gap, xr, vr = rows[keep], gap[keep], xr[keep], vr[keep]
        v = grid.speed[rows]
        accel = (grid.speed[rows + span] - grid.speed[rows - span]) / (2 * span * grid.dt)
        leader = grid.leader[rows]
        has = leader >= 0
        v_lead = np.where(has, grid.speed[np.maximum(leader, 0)], v)
        own = model.accel(v, v_lead, np.where(has, grid.gap[rows], np.inf), driver)
        yielding = model.accel(v, vr, gap, driver)
        x_by = min(max(x_merge[m] + 0.5 * length, gore), end)
        x_from = max(x_by - MERGE_LEAD, gore)
        u = (xr + 0.5 * length - x_from) / max(x_by - x_from, 1.0)
        u = np.where(u < 0.0, -1.0, np.minimum(u, 1.0))  # -1: not yet wanting it
        out["merge"].append(np.full(rows.size, m, np.int64))
        out["urgency"].append(u)
        out["accel"].append(accel)
        out["own"].append(np.asarray(own, np.float64))
        out["yield"].append(np.asarray(yielding, np.float64))
    empty = {"merge": np.int64}
    steps = {
        name: np.concatenate(parts) if parts else np.zeros(0, empty.get(name, np.float64))
        for name, parts in out.items()
    }
    told = steps["yield"] < steps["own"] - DIFFERENCE
    return {name: values[told] for name, values in steps.items()}


def _length_of(grid, tids, first_row, tid) -> float | None:
    """The length [m] of trajectory ``tid`` (from the grid; None where it has no row)."""
    j = np.searchsorted(tids, tid)
    if j >= tids.size or tids[j] != tid:
        return None
    return float(grid.length[first_row[j]])


def fit_yielding(steps: dict[str, np.ndarray]) -> dict:
    """``calibration.json``'s ``yielding`` of one road from its :func:`judged_steps`
    (module doc): ``merges`` judged, ``steps`` judged and ``yielding_steps``,
    ``identified``, ``yield_from`` (``None``: never), ``courtesy`` (the share of
    the followers judged from it on who yield), ``agreement`` (the share of the judged
    steps the fit classifies as recorded) and ``cooperative_decel`` [m/s^2] (``None``
    with fewer than :data:`MIN_BRAKING` braking yielding steps of courteous followers
    from it)."""
    accel, u, merge = steps["accel"], steps["urgency"], steps["merge"]
    yielded = np.abs(accel - steps["yield"]) < np.abs(accel - steps["own"])
    ids, of = np.unique(merge, return_inverse=True)
    section = {
        "merges": int(ids.size),
        "steps": int(accel.size),
        "yielding_steps": int(yielded.sum()),
        "identified": ids.size >= MIN_MERGES,
        "yield_from": None,
        "courtesy": None,
        "agreement": None,
        "cooperative_decel": None,
    }
    if not section["identified"]:
        return section
    # never: every yielding step is an error
    best, best_errors, best_courteous = None, int(yielded.sum()), None
    for c in URGENCIES:
        errors, courteous, judged = _errors_from(c, u, yielded, of, ids.size)
        if errors < best_errors:
            best, best_errors, best_courteous = c, errors, (courteous, judged)
    section["agreement"] = round(1.0 - best_errors / max(accel.size, 1), 4)
    if best is None:
        return section
    courteous, judged = best_courteous
    section["yield_from"] = best
    section["courtesy"] = round(float(courteous.sum() / max(judged.sum(), 1)), 4)
    braking = -accel[yielded & (u >= best) & courteous[of]]
    braking = braking[braking > 0]
    if braking.size >= MIN_BRAKING:
        decel = float(np.quantile(braking, DECEL_QUANTILE))
        section["cooperative_decel"] = round(float(np.clip(decel, *DECEL_RANGE)), 3)
    return section


def _errors_from(c, u, yielded, of, merges) -> tuple[int, np.ndarray, np.ndarray]:
    """The judged steps misclassified by "courteous followers yield from urgency ``c``"
    with each merge's follower courteous where most of its steps from ``c`` yield (a
    yielding step before ``c``, a step from ``c`` unlike its follower), and per merge
    whether its follower is courteous and whether it has a step from ``c``."""
    late = u >= c
    yes = np.bincount(of[late & yielded], minlength=merges)
    no = np.bincount(of[late & ~yielded], minlength=merges)
    errors = int((yielded & ~late).sum() + np.minimum(yes, no).sum())
    return errors, yes > no, (yes + no) > 0


def yielding_section(grid: GridTraffic, samples: dict, model: CarFollowingModel, driver) -> dict:
    """``calibration.json``'s ``yielding`` of ``grid``'s road (:func:`fit_yielding` of
    :func:`judged_steps`)."""
    return fit_yielding(judged_steps(grid, samples, model, driver))


def describe_yielding(section: dict | None) -> list[str]:
    """Lines for ``twin calibrate``'s and ``twin data info``'s summary of a road's
    ``yielding``."""
    if not isinstance(section, dict):
        return [] if section is None else [f"    yielding: malformed {section!r:.120}"]
    try:
        judged = f"{section['merges']} merges, {section['steps']} steps judged"
        if not section["identified"]:
            return [
                f"    yielding to merges: not identified ({judged}, need {MIN_MERGES} "
                "merges): the twin's defaults"
            ]
        agreement = f"{section['yielding_steps']} yielding; agreement {section['agreement']:.0%}"
        if section["yield_from"] is None:
            return [f"    yielding to merges: lane -4 does not make room ({judged}, {agreement})"]
        decel = section["cooperative_decel"]
        decel = "the default" if decel is None else f"{decel:.2f} m/s^2"
        return [
            f"    yielding to merges: {section['courtesy']:.0%} of lane -4's drivers, from "
            f"urgency {section['yield_from']:.2f}, braking up to {decel} ({judged}, "
            f"{agreement})"
        ]
    except (KeyError, TypeError, ValueError):
        return [f"    yielding: malformed {section!r:.120} (calibrate again)"]


def cooperation(section: dict | None) -> dict[str, float]:
    """The traffic settings a road's ``yielding`` section sets: ``yield_from`` and
    ``courtesy`` (0 where lane -4 does not make room), and ``cooperative_decel`` where
    it was identified; ``{}`` where the section is missing or not identified.

    Raises:
        CalibrationDataError: the section is not as :func:`fit_yielding` writes it.
    """
    if section is None:
        return {}
    try:
        if not section["identified"]:
            return {}
        start, decel = section["yield_from"], section["cooperative_decel"]
        if start is None:
            out = {"courtesy": 0.0}
        else:
            out = {"yield_from": float(start), "courtesy": float(section["courtesy"])}
        if decel is not None:
            out["cooperative_decel"] = float(decel)
    except (KeyError, TypeError, ValueError):
        out = None
    if (
        out is None
        or not all(math.isfinite(v) and v >= 0 for v in out.values())
        or out.get("cooperative_decel", 1.0) <= 0
        or out["courtesy"] > 1
    ):
        raise CalibrationDataError(
            f"calibration.json: yielding needs identified, yield_from (>= 0 or null), "
            f"courtesy (0 to 1) and cooperative_decel (> 0 or null), got {section!r:.200} "
            "(calibrate again)"
        )
    return out
