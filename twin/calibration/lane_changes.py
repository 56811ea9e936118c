"""Lane changes in a recording: their rates, and the MOBIL threshold at which MOBIL,
judging the recorded scenes with the calibrated drivers' model, starts as many."""

from dataclasses import dataclass, replace

import numpy as np

from twin.calibration.following import SPEED_BIN_NAMES, GridTraffic, LaneChanges
from twin.core.i24 import HOV_LANE, LANES
from twin.traffic.config import TrafficConfig
from twin.traffic.drivers import CLIP_SD
from twin.traffic.judge import Scenes, judge_scenes
from twin.traffic.mobil import MOBILParams
from twin.traffic.models.base import CarFollowingModel, take

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
    traffic: TrafficConfig | None = None,
) -> Incentives:
    """MOBIL's incentives on the recorded scenes every ``every`` seconds, and no
    threshold (:meth:`Incentives.changes` applies it): with the same driver
    (``model``'s parameters ``driver``, scalars) for everyone, or with ``drivers``,
    (tids sorted, ``model``'s parameters as arrays of their length): one driver per
    recorded vehicle (:func:`drawn_drivers`).

    The scenes are judged by the traffic kernels' own lane-change rule
    (:func:`twin.traffic.judge.judge_scenes`: MOBIL with the room to reach the middle
    of a change, the new follower's room behind, the gaps, the HOV rule), with the
    settings of ``traffic`` (default: a run's, :class:`TrafficConfig`) and ``mobil``'s
    politeness, safe deceleration and keep-right bias, so that the threshold fitted is
    the one the twin's drivers drive by. A vehicle may use the HOV lane where the
    recording shows it there."""
    stride = max(1, round(every / grid.dt))
    rows = np.flatnonzero((grid.lane != 0) & (grid.k % stride == 0))
    rows = rows[np.lexsort((grid.x[rows], grid.k[rows]))]
    if rows.size == 0:
        return Incentives(*(np.zeros(0) for _ in range(7)))
    if drivers is None:
        params = take_rows(driver, np.zeros(rows.size, np.int64), model)
    else:
        params = take_rows(drivers[1], np.searchsorted(drivers[0], grid.tid[rows]), model)
    in_hov = np.unique(grid.tid[grid.lane == HOV_LANE])
    config = replace(traffic or TrafficConfig(), car_following=model.name,
                     mobil=replace(mobil, threshold=0.0))  # fmt: skip
    scenes = Scenes(
        scene=grid.k[rows] // stride, x=grid.x[rows], speed=grid.speed[rows],
        lane=grid.lane[rows].astype(np.int64), length=grid.length[rows], cf=params,
        hov_eligible=np.isin(grid.tid[rows], in_hov),
    )  # fmt: skip
    gain, possible = judge_scenes(scenes, config)
    tid, lane, x = grid.tid[rows], grid.lane[rows], grid.x[rows]
    decision = (grid.k[rows] // stride).astype(np.int64)
    columns = {
        "tid": np.concatenate([tid, tid]),
        "decision": np.concatenate([decision, decision]),
        "direction": np.repeat(np.array([1, -1], np.int8), rows.size),
        "gain": np.concatenate([gain[:, 0], gain[:, 1]]),
        "possible": np.concatenate([possible[:, 0], possible[:, 1]]),
        "x": np.concatenate([x, x]),
        "lane": np.concatenate([lane, lane]),
    }
    order = np.lexsort((columns["decision"], columns["direction"], columns["tid"]))
    return Incentives(**{name: values[order] for name, values in columns.items()})


def take_rows(params, index: np.ndarray, model: CarFollowingModel) -> np.ndarray:
    """(len(index), k) ``model``'s parameters ``params`` (arrays or scalars) of the
    drivers at ``index``, one row each in the model's order, as the kernels hold them."""
    chosen = take(params, index) if index.size else params
    return np.column_stack(
        [np.broadcast_to(np.asarray(getattr(chosen, name), float), index.shape)
         for name in model.names]
    )  # fmt: skip


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
