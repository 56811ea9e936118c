"""Driver behaviour calibrated from a recording: car following, desired speeds and
lane-change rates (the fitting, on arrays; :mod:`twin.data.following` finds what
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

from dataclasses import dataclass, field

import numpy as np

from twin.data.following import FollowingRuns
from twin.traffic.idm import IDMParams, twin_idm_acceleration

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
            their minimum gap at a bound four times in ten, those that did almost never.)
    """

    delta: float = 4.0
    max_nrmse: float = 0.15
    max_iterations: int = 60
    step: float = 1e-4
    tolerance: float = 1e-6
    chunk: int = 600
    stop_speed: float = 3.0
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
    order = np.argsort(-np.bincount(run_vehicle, weights=runs.steps), kind="stable")
    results = []
    for start in range(0, followers.size, settings.chunk):
        chosen = np.sort(order[start : start + settings.chunk])
        rows = np.flatnonzero(np.isin(run_vehicle, chosen))
        local = np.searchsorted(chosen, run_vehicle[rows])
        results.append(_fit_chunk(runs.take(rows), local, chosen.size, settings))
        if progress is not None:
            progress(min(start + settings.chunk, followers.size), followers.size)
    params = np.zeros((followers.size, 5))
    stats = np.zeros((followers.size, 3))
    for (chosen_params, chosen_stats), start in zip(
        results, range(0, followers.size, settings.chunk), strict=True
    ):
        chosen = np.sort(order[start : start + settings.chunk])
        params[chosen] = chosen_params
        stats[chosen] = chosen_stats
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
        names: parameter names (:data:`PARAMS`).
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
    names: tuple = field(default=PARAMS)

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
