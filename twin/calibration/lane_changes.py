"""Lane changes in a recording: their rates, and the MOBIL threshold at which MOBIL,
judging the recorded scenes with the calibrated drivers' model, starts as many."""

import itertools
from dataclasses import dataclass, replace

import numpy as np

from twin.calibration.following import SPEED_BIN_NAMES, GridTraffic, LaneChanges
from twin.core.i24 import HOV_LANE, LANES
from twin.traffic.drivers import CLIP_SD
from twin.traffic.lanes import Occupancy
from twin.traffic.mobil import MOBILParams, mobil_incentive, mobil_safe
from twin.traffic.models.base import CarFollowingModel, take

MIN_LANE_CHANGE_GAP = 1.0  # [m] as the traffic manager: to each new neighbour
DRIVERS_SEED = 0x6D6F62  # the drivers drawn for the threshold's fit: one fixed draw


def lane_change_rates(changes: LaneChanges) -> dict:
    """The recording's lane-change rates [per vehicle-km]: overall, by lane pair (per km
    driven in the lane left) and by the speed of the lane left."""
    exposure = changes.exposure_km
    total_km = float(exposure.sum())

    def rate(count, km):
        return round(count / km, 5) if km > 0 else None

    pairs = {}
    for lane_from in LANES:
        for lane_to in (lane_from - 1, lane_from + 1):
            if lane_to not in LANES:
                continue
            count = int(
                np.count_nonzero((changes.lane_from == lane_from) & (changes.lane_to == lane_to))
            )
            km = float(exposure[-lane_from - 1].sum())
            pairs[f"{lane_from}>{lane_to}"] = {"count": count, "per_km": rate(count, km)}
    bins = changes.speed_bin
    by_speed = {}
    for j, name in enumerate(SPEED_BIN_NAMES):
        count = int(np.count_nonzero(bins == j))
        km = float(exposure[:, j].sum())
        by_speed[name] = {"count": count, "km": round(km, 3), "per_km": rate(count, km)}
    return {
        "count": len(changes),
        "vehicle_km": round(total_km, 3),
        "per_km": rate(len(changes), total_km),
        "pairs": pairs,
        "by_lane_speed": by_speed,
        "exposure_km": np.round(exposure, 3).tolist(),
    }


@dataclass(frozen=True)
class Incentives:
    """MOBIL's view of the recorded scenes, at each decision time, for each vehicle and
    each way it could move (left, right).

    Attributes:
        tid, decision: (e,) who and at which decision (index of the decision time).
        direction: (e,) +1 left (toward lane -1), -1 right.
        gain: (e,) [m/s^2] MOBIL incentive before the threshold.
        possible: (e,) bool: the target lane exists, the HOV rule allows it and the
            change is safe.
        x: (e,) [m] where the vehicle is (its back) at the decision.
        lane: (e,) the lane it is in.
    """

    tid: np.ndarray
    decision: np.ndarray
    direction: np.ndarray
    gain: np.ndarray
    possible: np.ndarray
    x: np.ndarray
    lane: np.ndarray

    def changes(self, threshold: float, where: np.ndarray | None = None) -> int:
        """Lane changes MOBIL would start with ``threshold``: one each time a vehicle's
        incentive to move one way beats it where it did not at the previous decision;
        only the decisions ``where`` (e,) bool, if given, are counted."""
        want = self.possible & (self.gain > threshold)
        previous = np.zeros_like(want)
        same = (
            (self.tid[1:] == self.tid[:-1])
            & (self.direction[1:] == self.direction[:-1])
            & (self.decision[1:] == self.decision[:-1] + 1)
        )
        previous[1:] = want[:-1] & same
        onset = want & ~previous
        return int(np.count_nonzero(onset if where is None else onset & where))


def recorded_incentives(
    grid: GridTraffic,
    model: CarFollowingModel,
    driver,
    mobil: MOBILParams,
    every: float = 1.0,
    drivers: tuple[np.ndarray, object] | None = None,
) -> Incentives:
    """MOBIL's incentives on the recorded scenes every ``every`` seconds, and no
    threshold (:meth:`Incentives.changes` applies it): with the same driver
    (``model``'s parameters ``driver``, scalars) for everyone, or with ``drivers``,
    (tids sorted, ``model``'s parameters as arrays of their length): one driver per
    recorded vehicle (:func:`drawn_drivers`)."""
    stride = max(1, round(every / grid.dt))
    rows_all = np.flatnonzero((grid.lane != 0) & (grid.k % stride == 0))
    rows_all = rows_all[np.argsort(grid.k[rows_all], kind="stable")]
    bounds = np.flatnonzero(np.r_[True, np.diff(grid.k[rows_all]) != 0, True])
    out = {name: [] for name in ("tid", "decision", "direction", "gain", "possible", "x", "lane")}
    road = np.int8(grid.road.direction)
    for a, b in itertools.pairwise(bounds):
        rows = rows_all[a:b]
        x, v, lane, length = grid.x[rows], grid.speed[rows], grid.lane[rows], grid.length[rows]
        roads = np.full(rows.size, road)
        occupancy = Occupancy.build(roads, x, [lane])
        ahead_now, behind_now = occupancy.around(roads, lane.astype(np.int64), x)
        own = None
        if drivers is not None:  # the drivers of this time's vehicles
            own = take(drivers[1], np.searchsorted(drivers[0], grid.tid[rows]))

        def accel(i, j, gap, v=v, own=own):  # the model's, of vehicles i behind j (j = -1: free)
            return _accel_behind(v, i, j, gap, model, driver if own is None else take(own, i))

        me = np.arange(rows.size)
        gap_now = np.where(ahead_now >= 0, x[np.maximum(ahead_now, 0)] - x - length, np.inf)
        own_now = accel(me, ahead_now, gap_now)
        behind = np.maximum(behind_now, 0)
        old_now = np.where(behind_now >= 0, own_now[behind], 0.0)
        old_gap = x[np.maximum(ahead_now, 0)] - x[behind] - length[behind]
        old_after = np.where(behind_now >= 0, accel(behind, ahead_now, old_gap), 0.0)
        k = int(grid.k[rows[0]] // stride)
        for direction in (1, -1):
            target = lane.astype(np.int64) + direction
            exists = (target <= -1) & (target >= -4) & (target != HOV_LANE) & (lane != HOV_LANE)
            ahead, behind_new = occupancy.around(roads, np.clip(target, -4, -1), x)
            gap_ahead = np.where(ahead >= 0, x[np.maximum(ahead, 0)] - x - length, np.inf)
            new_f = np.maximum(behind_new, 0)
            gap_behind = np.where(behind_new >= 0, x - x[new_f] - length[new_f], np.inf)
            own_after = accel(me, ahead, gap_ahead)
            new_after = np.where(behind_new >= 0, accel(new_f, me, gap_behind), 0.0)
            new_now = np.where(behind_new >= 0, own_now[new_f], 0.0)
            gain = mobil_incentive(
                own_now, own_after, new_now, new_after, old_now, old_after,
                np.full(rows.size, direction < 0), replace(mobil, threshold=0.0),
            )  # fmt: skip
            safe = (
                mobil_safe(new_after, mobil)
                & (own_after >= -mobil.safe_decel)
                & (gap_ahead >= MIN_LANE_CHANGE_GAP)
                & (gap_behind >= MIN_LANE_CHANGE_GAP)
            )
            out["tid"].append(grid.tid[rows])
            out["decision"].append(np.full(rows.size, k))
            out["direction"].append(np.full(rows.size, direction, dtype=np.int8))
            out["gain"].append(gain)
            out["possible"].append(exists & safe)
            out["x"].append(x)
            out["lane"].append(lane)
    if not out["tid"]:
        return Incentives(*(np.zeros(0) for _ in range(7)))
    columns = {name: np.concatenate(parts) for name, parts in out.items()}
    order = np.lexsort((columns["decision"], columns["direction"], columns["tid"]))
    return Incentives(**{name: values[order] for name, values in columns.items()})


def drawn_drivers(tids: np.ndarray, distribution, model: CarFollowingModel):
    """One driver per recorded vehicle ``tids``, drawn from ``distribution`` (a
    :class:`~twin.calibration.distributions.ParameterDistribution` of ``model``'s
    fitted parameters, all drivers'; the twin draws by class group and takes desired
    speeds from free flow, which barely move the fit) with a fixed seed: (tids sorted
    and unique, ``model``'s parameters as arrays of their length).

    MOBIL's threshold fitted with these (``CalibrationSettings.threshold_drivers =
    "drawn"``, the default) rather than one median driver for everyone sees the
    drivers' spread of headways, gaps and accelerations, which changes their
    incentives, as it changes the twin's drivers': on SUMO's on-ramp morning (Gipps
    drivers) 3.06 m/s^2 against the median's 1.99, and the calibrated twin made 66 lane
    changes against 49 recorded where the median's made 277 against 51; on a
    stop-and-go morning of the synthesiser's other drivers 2.37 against 2.15, 54
    against 87 where the median's made 108 (docs/calibration.md, "The MOBIL
    threshold")."""
    tids = np.unique(np.asarray(tids))
    draws = distribution.draw(tids.size, np.random.default_rng(DRIVERS_SEED), clip_sd=CLIP_SD)
    order = [distribution.names.index(p.name) for p in model.fitted]
    return tids, model.from_fitted(draws[:, order])


def _accel_behind(v, i, j, gap, model: CarFollowingModel, driver) -> np.ndarray:
    """The model's acceleration of vehicles ``i`` behind vehicles ``j`` (-1: a free road)."""
    lead_speed = np.where(j >= 0, v[np.maximum(j, 0)], 0.0)
    return model.accel(v[i], lead_speed, np.where(j >= 0, gap, np.inf), driver)


def fit_threshold(
    incentives: Incentives, recorded: int, *, high: float = 8.0, where: np.ndarray | None = None
) -> dict:
    """The MOBIL threshold [m/s^2] at which the recorded scenes would start as many lane
    changes as the recording has: the lowest at which they start no more (bisection: the
    count falls as the threshold rises). With no recorded change that is just above the
    largest incentive the recorded drivers resisted, not the top of the range: they
    would have changed for more. Where even ``high`` starts more, it is ``high``; where
    0 starts fewer, 0. With ``where`` (e,) bool, only those decisions are judged
    (``recorded`` then counts the changes made where they are)."""
    low_count, high_count = incentives.changes(0.0, where), incentives.changes(high, where)
    if low_count <= recorded:
        threshold = 0.0
    elif high_count > recorded:
        threshold = high
    else:
        lo, hi = 0.0, high
        for _ in range(40):
            mid = 0.5 * (lo + hi)
            if incentives.changes(mid, where) > recorded:
                lo = mid
            else:
                hi = mid
        threshold = hi
    return {
        "threshold": round(threshold, 4),
        "recorded": int(recorded),
        "predicted": incentives.changes(threshold, where),
        "at_zero_threshold": low_count,
    }
