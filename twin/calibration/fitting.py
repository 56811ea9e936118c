"""Driver behaviour calibrated from a recording: car following, desired speeds and
lane-change rates (the fitting, on arrays; :mod:`twin.calibration.following` finds what
the recording shows).

**Car following.** Each recorded follower's IDM parameters (desired speed, time
headway, minimum gap, maximum acceleration, comfortable deceleration; delta fixed) are
fitted by replaying its recorded leader open-loop: the follower starts at its recorded
position and speed and is driven by the twin's IDM (:func:`twin_idm_acceleration`,
ballistic steps of the grid's ``dt``, as the synthetic data and the paper's drivers are
integrated), and the parameters minimise the squared error of the simulated spacing
against the recorded one, over all the runs of that follower. Spacing is the goodness
of fit the field recommends: Punzo and Montanino (2016) and Punzo, Ciuffo and
Montanino (2012) found that calibrating on spacing (not speed) gives parameters that
reproduce trajectories without drift, because errors in speed integrate into spacing
but not the other way round. The fit's quality is its normalised RMSE, the spacing
RMSE over the mean recorded spacing.

The minimiser is Levenberg-Marquardt, batched over all followers at once (numpy,
finite-difference Jacobians); parameters live in a log-logistic transform of their
bounds, so every step stays inside them. Fits whose NRMSE exceeds a limit, or with a
parameter (other than the desired speed) at a bound, are rejected and counted. The
desired speed is identified only by vehicles that come near it while following; where
it sits at a bound the fit is kept and the desired speed is taken from free flow.
"""

import itertools
from dataclasses import dataclass, replace

import numpy as np

from twin.calibration.following import (
    SPEED_BIN_NAMES,
    FollowingRuns,
    FreeFlow,
    GridTraffic,
    LaneChanges,
)
from twin.core.i24 import HOV_LANE, LANES
from twin.traffic.lanes import Occupancy
from twin.traffic.mobil import MOBILParams, mobil_incentive, mobil_safe
from twin.traffic.models.idm import IDMParams, twin_idm_acceleration

MIN_LANE_CHANGE_GAP = 1.0  # [m] as the traffic manager: to each new neighbour

PARAMS = ("desired_speed", "time_headway", "min_gap", "max_accel", "comfortable_decel")
#: Fitting bounds [m/s, s, m, m/s^2, m/s^2]: wide enough for every driver in the
#: literature's I-24, NGSIM and highD fits, narrow enough to reject nonsense.
BOUNDS = {
    "desired_speed": (5.0, 45.0),
    "time_headway": (0.3, 4.0),
    "min_gap": (0.3, 10.0),
    "max_accel": (0.2, 5.0),
    "comfortable_decel": (0.3, 6.0),
}
#: Where the fit starts: a typical passenger-car driver.
START = {
    "desired_speed": 30.0,
    "time_headway": 1.2,
    "min_gap": 2.0,
    "max_accel": 1.2,
    "comfortable_decel": 1.7,
}
MAX_DECEL = 9.0  # [m/s^2] the replayed follower brakes at most this hard (tyre limit)
AT_BOUND = 0.01  # a parameter within this share of its (log) range of a bound is at it
#: Class groups whose drivers are described separately (coarse I-24 MOTION classes).
CLASS_GROUPS = {"car": (0, 1, 2, 3, 6), "truck": (4, 5)}

_LOW = np.log([BOUNDS[name][0] for name in PARAMS])
_SPAN = np.log([BOUNDS[name][1] for name in PARAMS]) - _LOW


def to_params(u: np.ndarray) -> np.ndarray:
    """(..., 5) unconstrained values -> parameters inside :data:`BOUNDS`."""
    return np.exp(_LOW + _SPAN / (1.0 + np.exp(-np.clip(u, -30.0, 30.0))))


def to_unconstrained(p: np.ndarray) -> np.ndarray:
    """The inverse of :func:`to_params` (parameters clipped just inside the bounds)."""
    share = np.clip((np.log(p) - _LOW) / _SPAN, 1e-6, 1 - 1e-6)
    return np.log(share / (1.0 - share))


def bound_share(p: np.ndarray) -> np.ndarray:
    """(..., 5) where each parameter lies in its log range: 0 at the lower bound, 1 at
    the upper."""
    return (np.log(p) - _LOW) / _SPAN


def replay(runs: FollowingRuns, params: np.ndarray, *, delta: float = 4.0) -> np.ndarray:
    """The followers of ``runs`` driven by the twin's IDM behind their recorded leaders.

    Args:
        runs: R runs, padded to N steps.
        params: (R, 5) parameters in :data:`PARAMS` order.

    Returns:
        (R, N) [m] simulated bumper-to-bumper gap (meaningful where ``runs.valid``).
    """
    r, n = runs.x.shape
    valid = runs.valid
    last = np.maximum(runs.steps - 1, 0)
    rows = np.arange(r)

    def held(a):  # padded steps hold the run's last value (finite, ignored)
        return np.where(valid, a, a[rows, last][:, None])

    x_lead, v_lead = held(runs.x_lead), held(runs.speed_lead)
    idm = IDMParams(*(params[:, j] for j in range(5)), delta)
    dt, length = runs.dt, runs.length
    x, v = runs.x[:, 0].copy(), np.maximum(runs.speed[:, 0], 0.0)
    gap = np.empty((r, n))
    gap[:, 0] = x_lead[:, 0] - x - length
    for j in range(n - 1):
        acc = twin_idm_acceleration(v, v_lead[:, j], gap[:, j], idm)
        acc = np.maximum(acc, -MAX_DECEL)
        v_new = v + acc * dt
        stopping = v_new < 0.0
        x = x + np.where(
            stopping, v * v / (2.0 * np.maximum(-acc, 1e-9)), v * dt + 0.5 * acc * dt * dt
        )
        v = np.maximum(v_new, 0.0)
        gap[:, j + 1] = x_lead[:, j + 1] - x - length
    return gap


@dataclass(frozen=True)
class FitSettings:
    """How the car-following fit is run and judged.

    Attributes:
        delta: IDM exponent, fixed.
        max_nrmse: fits with a larger spacing NRMSE are rejected.
        max_iterations: Levenberg-Marquardt iterations at most.
        step: finite-difference step in the unconstrained parameters.
        tolerance: a vehicle stops when a step improves its cost by less than this share.
        chunk: followers fitted together (bounds the memory: ~6 x chunk x N floats).
        stop_speed, moving_speed: [m/s] a follower is fitted only if its runs go below
            the first and above the second: it crossed a wave. Following at a steady
            speed identifies the time headway alone; the minimum gap needs a stop and
            the acceleration and deceleration need the speed to change. (On synthetic
            data with known drivers, followers that did not cross a wave end with
            their minimum gap at a bound four times in ten, those that did almost never;
            6 m/s rather than a stop recovers the drivers as well and admits waves
            that do not stop, as Gipps drivers' rarely do.)
    """

    delta: float = 4.0
    max_nrmse: float = 0.15
    max_iterations: int = 60
    step: float = 1e-4
    tolerance: float = 1e-6
    chunk: int = 600
    stop_speed: float = 6.0
    moving_speed: float = 12.0

    def __post_init__(self):
        if not (self.delta > 0 and self.max_nrmse > 0 and self.max_iterations >= 1):
            raise ValueError(f"invalid fit settings {self}")


@dataclass(frozen=True)
class FollowerFits:
    """One fit per follower.

    Attributes:
        tid: (m,) follower; vehicle_class: (m,) its class; runs, seconds: (m,) how many
            runs and seconds of following the fit used.
        params: (m, 5) fitted parameters, :data:`PARAMS` order.
        rmse: (m,) [m] spacing RMSE; nrmse: (m,) RMSE over mean recorded spacing.
        at_bound: (m, 5) bool, the parameter ended at a bound.
        accepted: (m,) bool: nrmse within the limit and no parameter but the desired
            speed at a bound.
        iterations: (m,) iterations used.
        uninformative: followers not fitted: their runs did not cross a wave.
    """

    tid: np.ndarray
    vehicle_class: np.ndarray
    runs: np.ndarray
    seconds: np.ndarray
    params: np.ndarray
    rmse: np.ndarray
    nrmse: np.ndarray
    at_bound: np.ndarray
    accepted: np.ndarray
    iterations: np.ndarray
    uninformative: int = 0

    def __len__(self) -> int:
        return self.tid.size

    @property
    def poor(self) -> np.ndarray:
        """(m,) bool, rejected for the NRMSE."""
        return ~self.accepted & ~self.at_bound[:, 1:].any(axis=1)

    def desired_speed_identified(self) -> np.ndarray:
        """(m,) bool, the desired speed is not at a bound."""
        return ~self.at_bound[:, 0]


def fit_followers(
    runs: FollowingRuns, settings: FitSettings = FitSettings(), *, progress=None
) -> FollowerFits:
    """Fit IDM parameters per follower over all its runs (see the module doc).

    Args:
        progress: optional callable ``progress(done, total)`` after each chunk.
    """
    everyone = np.unique(runs.tid)
    low = np.full(everyone.size, np.inf)
    high = np.full(everyone.size, -np.inf)
    at = np.searchsorted(everyone, runs.tid)
    np.minimum.at(low, at, np.nanmin(runs.speed, axis=1, initial=np.inf))
    np.maximum.at(high, at, np.nanmax(runs.speed, axis=1, initial=-np.inf))
    informative = (low <= settings.stop_speed) & (high >= settings.moving_speed)
    runs = runs.take(np.flatnonzero(informative[at]))
    followers, run_vehicle = np.unique(runs.tid, return_inverse=True)
    if progress is not None:
        progress(0, followers.size)
    order = np.argsort(-np.bincount(run_vehicle, weights=runs.steps), kind="stable")
    params = np.zeros((followers.size, 5))
    stats = np.zeros((followers.size, 3))
    for start in range(0, followers.size, settings.chunk):
        chosen = np.sort(order[start : start + settings.chunk])
        rows = np.flatnonzero(np.isin(run_vehicle, chosen))
        local = np.searchsorted(chosen, run_vehicle[rows])
        params[chosen], stats[chosen] = _fit_chunk(runs.take(rows), local, chosen.size, settings)
        if progress is not None:
            progress(min(start + settings.chunk, followers.size), followers.size)
    seconds = np.bincount(run_vehicle, weights=runs.steps, minlength=followers.size) * runs.dt
    n_runs = np.bincount(run_vehicle, minlength=followers.size)
    first_run = np.searchsorted(run_vehicle, np.arange(followers.size)) if runs.tid.size else []
    vehicle_class = runs.vehicle_class[np.argsort(run_vehicle, kind="stable")][first_run]
    share = bound_share(params)
    at_bound = (share < AT_BOUND) | (share > 1 - AT_BOUND)
    rmse, nrmse, iterations = stats[:, 0], stats[:, 1], stats[:, 2].astype(np.int64)
    accepted = (nrmse <= settings.max_nrmse) & ~at_bound[:, 1:].any(axis=1)
    return FollowerFits(
        tid=followers,
        vehicle_class=np.asarray(vehicle_class, dtype=np.int64),
        runs=n_runs,
        seconds=seconds,
        params=params,
        rmse=rmse,
        nrmse=nrmse,
        at_bound=at_bound,
        accepted=accepted,
        iterations=iterations,
        uninformative=int(np.count_nonzero(~informative)),
    )


def _fit_chunk(runs: FollowingRuns, vehicle: np.ndarray, m: int, settings: FitSettings):
    """Levenberg-Marquardt for ``m`` followers whose runs are ``runs`` (``vehicle`` maps
    each run to its follower). Returns ((m, 5) params, (m, 3) rmse, nrmse, iterations)."""
    valid = runs.valid
    recorded = np.where(valid, runs.gap, 0.0)
    samples = np.bincount(vehicle, weights=valid.sum(axis=1), minlength=m)
    mean_gap = np.bincount(vehicle, weights=recorded.sum(axis=1), minlength=m) / samples

    def residuals(u_vehicle: np.ndarray, which: np.ndarray) -> np.ndarray:
        # (k, R, N) residuals of parameter sets u_vehicle (k, m, 5), runs where `which`
        k = u_vehicle.shape[0]
        sub = runs.take(which)
        p = to_params(u_vehicle[:, vehicle[which], :]).reshape(-1, 5)
        tiled = FollowingRuns(
            **{
                name: np.concatenate([getattr(sub, name)] * k)
                if isinstance(getattr(sub, name), np.ndarray)
                else getattr(sub, name)
                for name in sub.__dataclass_fields__
            }
        )
        simulated = replay(tiled, p, delta=settings.delta).reshape(k, which.size, -1)
        width = simulated.shape[2]
        return np.where(valid[which, :width], simulated - recorded[which, :width], 0.0)

    def costs(res: np.ndarray, which: np.ndarray) -> np.ndarray:
        return np.bincount(vehicle[which], weights=(res**2).sum(axis=1), minlength=m)

    u = np.tile(to_unconstrained(np.array([START[name] for name in PARAMS])), (m, 1))
    all_runs = np.arange(len(runs))
    res = residuals(u[None], all_runs)[0]
    cost = costs(res, all_runs)
    lam = np.full(m, 1e-2)
    active = np.ones(m, dtype=bool)
    iterations = np.zeros(m)
    h = settings.step
    for _ in range(settings.max_iterations):
        which = np.flatnonzero(active[vehicle])
        if which.size == 0:
            break
        iterations[active] += 1
        width = int(runs.steps[which].max())
        base = res[which, :width]
        shifted = np.repeat(u[None], 5, axis=0) + h * np.eye(5)[:, None, :]
        jac = (residuals(shifted, which) - base[None]) / h  # (5, r, N)
        jtj_run = np.einsum("irn,jrn->rij", jac, jac)
        jtr_run = np.einsum("irn,rn->ri", jac, base)
        jtj = np.zeros((m, 5, 5))
        jtr = np.zeros((m, 5))
        np.add.at(jtj, vehicle[which], jtj_run)
        np.add.at(jtr, vehicle[which], jtr_run)
        diag = np.einsum("mii->mi", jtj) + 1e-9
        a = jtj + lam[:, None, None] * diag[:, :, None] * np.eye(5)[None]
        step = np.zeros((m, 5))
        step[active] = -np.linalg.solve(a[active], jtr[active][:, :, None])[:, :, 0]
        trial = np.clip(u + step, -30.0, 30.0)
        res_trial = residuals(trial[None], which)[0]
        cost_trial = costs(res_trial, which)
        better = active & (cost_trial < cost)
        gain = np.where(better, (cost - cost_trial) / np.maximum(cost, 1e-12), 0.0)
        u[better] = trial[better]
        cost[better] = cost_trial[better]
        moved = which[better[vehicle[which]]]
        res[moved, :width] = res_trial[np.searchsorted(which, moved)]
        lam = np.where(better, lam / 3.0, lam * 4.0)
        active &= ~((better & (gain < settings.tolerance)) | (lam > 1e7))
    rmse = np.sqrt(cost / samples)
    return to_params(u), np.c_[rmse, rmse / mean_gap, iterations]


@dataclass(frozen=True)
class ParameterDistribution:
    """IDM parameters of one class group, log-normal with correlations.

    Attributes:
        mean_log, sd_log: (5,) mean and sd of log(parameter).
        correlation: (5, 5) correlation of the log parameters.
        median, p10, p90: (5,) quantiles of the fitted values.
        count: fits it is made of.
    """

    mean_log: np.ndarray
    sd_log: np.ndarray
    correlation: np.ndarray
    median: np.ndarray
    p10: np.ndarray
    p90: np.ndarray
    count: int

    @classmethod
    def of(cls, params: np.ndarray) -> "ParameterDistribution":
        logs = np.log(params)
        corr = np.corrcoef(logs.T) if len(params) > 2 else np.eye(5)
        corr = np.where(np.isfinite(corr), corr, 0.0)
        np.fill_diagonal(corr, 1.0)
        return cls(
            mean_log=logs.mean(axis=0),
            sd_log=logs.std(axis=0, ddof=1) if len(params) > 1 else np.zeros(5),
            correlation=corr,
            median=np.median(params, axis=0),
            p10=np.quantile(params, 0.1, axis=0),
            p90=np.quantile(params, 0.9, axis=0),
            count=len(params),
        )

    def draw(self, n: int, rng: np.random.Generator, clip_sd: float = 2.0) -> np.ndarray:
        """(n, 5) parameters: correlated log-normal draws clipped at ``clip_sd``."""
        cov = self.correlation * np.outer(self.sd_log, self.sd_log)
        # eigen-decomposition (a fitted correlation may be only semi-definite)
        w, vectors = np.linalg.eigh(cov)
        z = np.clip(rng.standard_normal((n, 5)), -clip_sd, clip_sd)
        logs = self.mean_log + (z * np.sqrt(np.maximum(w, 0.0))) @ vectors.T
        low, high = self.mean_log - clip_sd * self.sd_log, self.mean_log + clip_sd * self.sd_log
        return np.exp(np.clip(logs, low, high))

    def to_dict(self) -> dict:
        return {
            "count": self.count,
            "median": _named(self.median),
            "p10": _named(self.p10),
            "p90": _named(self.p90),
            "mean_log": _named(self.mean_log),
            "sd_log": _named(self.sd_log),
            "correlation": np.round(self.correlation, 4).tolist(),
        }

    @classmethod
    def from_dict(cls, d: dict) -> "ParameterDistribution":
        def vector(key):
            return np.array([float(d[key][name]) for name in PARAMS])

        return cls(
            mean_log=vector("mean_log"),
            sd_log=vector("sd_log"),
            correlation=np.array(d["correlation"], dtype=float).reshape(5, 5),
            median=vector("median"),
            p10=vector("p10"),
            p90=vector("p90"),
            count=int(d["count"]),
        )


def _named(values: np.ndarray) -> dict:
    return {name: round(float(v), 4) for name, v in zip(PARAMS, values, strict=True)}


def class_group(vehicle_class: np.ndarray) -> np.ndarray:
    """(n,) names of the class groups of coarse classes."""
    out = np.full(np.shape(vehicle_class), "car", dtype=object)
    for name, members in CLASS_GROUPS.items():
        out[np.isin(vehicle_class, members)] = name
    return out


def group_distributions(fits: FollowerFits, min_count: int = 5) -> dict:
    """{group: ParameterDistribution} of the accepted fits of each class group with at
    least ``min_count`` of them (a group with fewer takes the pooled one, "all")."""
    ok = fits.accepted
    out = {}
    if ok.sum() >= min_count:
        out["all"] = ParameterDistribution.of(fits.params[ok])
    groups = class_group(fits.vehicle_class)
    for name in CLASS_GROUPS:
        rows = ok & (groups == name)
        if rows.sum() >= min_count:
            out[name] = ParameterDistribution.of(fits.params[rows])
    return out


def median_relative_error(estimate: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """(5,) median over vehicles of |estimate - truth| / truth, per parameter."""
    return np.median(np.abs(estimate - truth) / truth, axis=0)


# -- desired speeds -------------------------------------------------------------------


def speed_summary(speeds: np.ndarray) -> dict:
    """Count, mean, sd and quantiles [m/s] of a set of speeds."""
    speeds = np.asarray(speeds, dtype=np.float64)
    return {
        "count": int(speeds.size),
        "mean": round(float(speeds.mean()), 3),
        "sd": round(float(speeds.std(ddof=1)) if speeds.size > 1 else 0.0, 3),
        "p10": round(float(np.quantile(speeds, 0.1)), 3),
        "p50": round(float(np.median(speeds)), 3),
        "p90": round(float(np.quantile(speeds, 0.9)), 3),
    }


def desired_speeds(free: FreeFlow, min_count: int = 5) -> dict:
    """Desired speeds from the free-flow speeds: per lane where at least ``min_count``
    vehicles were free in it, and pooled ("all"); {} when fewer were free anywhere."""
    out = {}
    if len(free) < min_count:
        return out
    out["all"] = speed_summary(free.speed)
    for lane in LANES:
        rows = free.lane == lane
        if rows.sum() >= min_count:
            out[str(lane)] = speed_summary(free.speed[rows])
    return out


# -- lane changes ---------------------------------------------------------------------


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
    """

    tid: np.ndarray
    decision: np.ndarray
    direction: np.ndarray
    gain: np.ndarray
    possible: np.ndarray

    def changes(self, threshold: float) -> int:
        """Lane changes MOBIL would start with ``threshold``: one each time a vehicle's
        incentive to move one way beats it where it did not at the previous decision."""
        want = self.possible & (self.gain > threshold)
        previous = np.zeros_like(want)
        same = (
            (self.tid[1:] == self.tid[:-1])
            & (self.direction[1:] == self.direction[:-1])
            & (self.decision[1:] == self.decision[:-1] + 1)
        )
        previous[1:] = want[:-1] & same
        return int(np.count_nonzero(want & ~previous))


def recorded_incentives(
    grid: GridTraffic, idm: IDMParams, mobil: MOBILParams, every: float = 1.0
) -> Incentives:
    """MOBIL's incentives on the recorded scenes every ``every`` seconds, with the same
    IDM for every driver (and no threshold: :meth:`Incentives.changes` applies it)."""
    stride = max(1, round(every / grid.dt))
    rows_all = np.flatnonzero((grid.lane != 0) & (grid.k % stride == 0))
    rows_all = rows_all[np.argsort(grid.k[rows_all], kind="stable")]
    bounds = np.flatnonzero(np.r_[True, np.diff(grid.k[rows_all]) != 0, True])
    out = {name: [] for name in ("tid", "decision", "direction", "gain", "possible")}
    road = np.int8(grid.road.direction)
    for a, b in itertools.pairwise(bounds):
        rows = rows_all[a:b]
        x, v, lane, length = grid.x[rows], grid.speed[rows], grid.lane[rows], grid.length[rows]
        roads = np.full(rows.size, road)
        occupancy = Occupancy.build(roads, x, [lane])
        ahead_now, behind_now = occupancy.around(roads, lane.astype(np.int64), x)

        def accel(i, j, gap, v=v):  # IDM of vehicles i behind j (j = -1: free road)
            return _accel_behind(v, i, j, gap, idm)

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
    if not out["tid"]:
        return Incentives(*(np.zeros(0) for _ in range(5)))
    columns = {name: np.concatenate(parts) for name, parts in out.items()}
    order = np.lexsort((columns["decision"], columns["direction"], columns["tid"]))
    return Incentives(**{name: values[order] for name, values in columns.items()})


def _accel_behind(v, i, j, gap, idm: IDMParams) -> np.ndarray:
    """IDM acceleration of vehicles ``i`` behind vehicles ``j`` (-1: a free road)."""
    lead_speed = np.where(j >= 0, v[np.maximum(j, 0)], 0.0)
    return twin_idm_acceleration(v[i], lead_speed, np.where(j >= 0, gap, np.inf), idm)


def fit_threshold(incentives: Incentives, recorded: int, *, high: float = 8.0) -> dict:
    """The MOBIL threshold [m/s^2] at which the recorded scenes would start as many lane
    changes as the recording has: the lowest at which they start no more (bisection: the
    count falls as the threshold rises). With no recorded change that is just above the
    largest incentive the recorded drivers resisted, not the top of the range: they
    would have changed for more. Where even ``high`` starts more, it is ``high``; where
    0 starts fewer, 0."""
    low_count, high_count = incentives.changes(0.0), incentives.changes(high)
    if low_count <= recorded:
        threshold = 0.0
    elif high_count > recorded:
        threshold = high
    else:
        lo, hi = 0.0, high
        for _ in range(40):
            mid = 0.5 * (lo + hi)
            if incentives.changes(mid) > recorded:
                lo = mid
            else:
                hi = mid
        threshold = hi
    return {
        "threshold": round(threshold, 4),
        "recorded": int(recorded),
        "predicted": incentives.changes(threshold),
        "at_zero_threshold": low_count,
    }
