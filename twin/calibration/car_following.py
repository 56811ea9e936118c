"""The car-following fit: each recorded follower's parameters of a car-following model
(:mod:`twin.traffic.models`; IDM by default) fitted by replaying its recorded leader
(the recording's side is :mod:`twin.calibration.following`).

The follower starts at its recorded position and speed and is driven by the model
(ballistic steps of the grid's ``dt``, as the synthetic data and the paper's drivers
are integrated), and its parameters minimise the squared error of the simulated
spacing against the recorded one, over all the runs of that follower. Spacing is the
goodness of fit the field recommends: Punzo and Montanino (2016) and Punzo, Ciuffo
and Montanino (2012) found that calibrating on spacing (not speed) gives parameters
that reproduce trajectories without drift, because errors in speed integrate into
spacing but not the other way round. The fit's quality is its normalised RMSE, the
spacing RMSE over the mean recorded spacing.

The minimiser is Levenberg-Marquardt, batched over all followers at once (numpy,
finite-difference Jacobians); parameters live in a log-logistic transform of their
bounds (:class:`Box`), so every step stays inside them. Fits whose NRMSE exceeds a
limit, or with a parameter (other than the desired speed) at a bound, are rejected and
counted. The desired speed is identified only by vehicles that come near it while
following; where it sits at a bound the fit is kept and the desired speed is taken
from free flow. A model's parameters that are not fitted (IDM's exponent) keep their
``start``.
"""

from dataclasses import dataclass, replace

import numpy as np

from twin.calibration.following import FollowingRuns
from twin.traffic.models.base import CarFollowingModel
from twin.traffic.models.idm import IDM

MAX_DECEL = 9.0  # [m/s^2] the replayed follower brakes at most this hard (tyre limit)
AT_BOUND = 0.01  # a parameter within this share of its (log) range of a bound is at it


@dataclass(frozen=True, eq=False)
class Box:
    """The fitted parameters' bounds of a model, and the transform that keeps a fit
    inside them.

    Attributes:
        model: the car-following model.
        low, span: (k,) log of the lower bounds, log range of each fitted parameter.
    """

    model: CarFollowingModel
    low: np.ndarray
    span: np.ndarray

    @classmethod
    def of(cls, model: CarFollowingModel) -> "Box":
        low = np.log([p.bounds[0] for p in model.fitted])
        return cls(model, low, np.log([p.bounds[1] for p in model.fitted]) - low)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.model.fitted)

    @property
    def start(self) -> np.ndarray:
        """(k,) where fits start."""
        return np.array([p.start for p in self.model.fitted])

    def to_params(self, u: np.ndarray) -> np.ndarray:
        """(..., k) unconstrained values -> parameters inside the bounds."""
        return np.exp(self.low + self.span / (1.0 + np.exp(-np.clip(u, -30.0, 30.0))))

    def to_unconstrained(self, p: np.ndarray) -> np.ndarray:
        """The inverse of :meth:`to_params` (parameters clipped just inside the bounds)."""
        share = np.clip((np.log(p) - self.low) / self.span, 1e-6, 1 - 1e-6)
        return np.log(share / (1.0 - share))

    def share(self, p: np.ndarray) -> np.ndarray:
        """(..., k) where each parameter lies in its log range: 0 at the lower bound,
        1 at the upper."""
        return (np.log(p) - self.low) / self.span


def replay(runs: FollowingRuns, params: np.ndarray, model: CarFollowingModel = IDM) -> np.ndarray:
    """The followers of ``runs`` driven by ``model`` behind their recorded leaders.

    Args:
        runs: R runs, padded to N steps.
        params: (R, k) the model's fitted parameters, in the order of ``model.fitted``.

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
    drivers = model.from_fitted(params)
    dt, length = runs.dt, runs.length
    x, v = runs.x[:, 0].copy(), np.maximum(runs.speed[:, 0], 0.0)
    gap = np.empty((r, n))
    gap[:, 0] = x_lead[:, 0] - x - length
    for j in range(n - 1):
        acc = model.accel(v, v_lead[:, j], gap[:, j], drivers)
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

    max_nrmse: float = 0.15
    max_iterations: int = 60
    step: float = 1e-4
    tolerance: float = 1e-6
    chunk: int = 600
    stop_speed: float = 6.0
    moving_speed: float = 12.0

    def __post_init__(self):
        if not (self.max_nrmse > 0 and self.max_iterations >= 1):
            raise ValueError(f"invalid fit settings {self}")


@dataclass(frozen=True)
class FollowerFits:
    """One fit per follower.

    Attributes:
        tid: (m,) follower; vehicle_class: (m,) its class; runs, seconds: (m,) how many
            runs and seconds of following the fit used.
        names: the fitted parameters' names (the model's ``fitted``), in column order.
        params: (m, k) fitted parameters.
        rmse: (m,) [m] spacing RMSE; nrmse: (m,) RMSE over mean recorded spacing.
        at_bound: (m, k) bool, the parameter ended at a bound.
        accepted: (m,) bool: nrmse within the limit and no parameter but the desired
            speed at a bound.
        iterations: (m,) iterations used.
        uninformative: followers not fitted: their runs did not cross a wave.
    """

    names: tuple[str, ...]
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
    def other_at_bound(self) -> np.ndarray:
        """(m,) bool, a parameter other than the desired speed ended at a bound."""
        return np.delete(self.at_bound, self.names.index("desired_speed"), axis=1).any(axis=1)

    @property
    def poor(self) -> np.ndarray:
        """(m,) bool, rejected for the NRMSE."""
        return ~self.accepted & ~self.other_at_bound

    def desired_speed_identified(self) -> np.ndarray:
        """(m,) bool, the desired speed is not at a bound."""
        return ~self.at_bound[:, self.names.index("desired_speed")]


def fit_followers(
    runs: FollowingRuns,
    settings: FitSettings = FitSettings(),
    *,
    model: CarFollowingModel = IDM,
    progress=None,
) -> FollowerFits:
    """Fit ``model``'s parameters per follower over all its runs (see the module doc).

    Args:
        progress: optional callable ``progress(done, total)`` after each chunk.
    """
    box = Box.of(model)
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
    params = np.zeros((followers.size, len(box.names)))
    stats = np.zeros((followers.size, 3))
    for start in range(0, followers.size, settings.chunk):
        chosen = np.sort(order[start : start + settings.chunk])
        rows = np.flatnonzero(np.isin(run_vehicle, chosen))
        local = np.searchsorted(chosen, run_vehicle[rows])
        params[chosen], stats[chosen] = _fit_chunk(
            runs.take(rows), local, chosen.size, settings, box
        )
        if progress is not None:
            progress(min(start + settings.chunk, followers.size), followers.size)
    seconds = np.bincount(run_vehicle, weights=runs.steps, minlength=followers.size) * runs.dt
    n_runs = np.bincount(run_vehicle, minlength=followers.size)
    first_run = np.searchsorted(run_vehicle, np.arange(followers.size)) if runs.tid.size else []
    vehicle_class = runs.vehicle_class[np.argsort(run_vehicle, kind="stable")][first_run]
    share = box.share(params)
    at_bound = (share < AT_BOUND) | (share > 1 - AT_BOUND)
    rmse, nrmse, iterations = stats[:, 0], stats[:, 1], stats[:, 2].astype(np.int64)
    fits = FollowerFits(
        names=box.names,
        tid=followers,
        vehicle_class=np.asarray(vehicle_class, dtype=np.int64),
        runs=n_runs,
        seconds=seconds,
        params=params,
        rmse=rmse,
        nrmse=nrmse,
        at_bound=at_bound,
        accepted=np.zeros(followers.size, dtype=bool),
        iterations=iterations,
        uninformative=int(np.count_nonzero(~informative)),
    )
    accepted = (nrmse <= settings.max_nrmse) & ~fits.other_at_bound
    return replace(fits, accepted=accepted)


def _fit_chunk(runs: FollowingRuns, vehicle: np.ndarray, m: int, settings: FitSettings, box: Box):
    """Levenberg-Marquardt for ``m`` followers whose runs are ``runs`` (``vehicle`` maps
    each run to its follower). Returns ((m, k) params, (m, 3) rmse, nrmse, iterations)."""
    k = len(box.names)
    valid = runs.valid
    recorded = np.where(valid, runs.gap, 0.0)
    samples = np.bincount(vehicle, weights=valid.sum(axis=1), minlength=m)
    mean_gap = np.bincount(vehicle, weights=recorded.sum(axis=1), minlength=m) / samples

    def residuals(u_vehicle: np.ndarray, which: np.ndarray) -> np.ndarray:
        # (s, R, N) residuals of parameter sets u_vehicle (s, m, k), runs where `which`
        sets = u_vehicle.shape[0]
        sub = runs.take(which)
        p = box.to_params(u_vehicle[:, vehicle[which], :]).reshape(-1, k)
        tiled = FollowingRuns(
            **{
                name: np.concatenate([getattr(sub, name)] * sets)
                if isinstance(getattr(sub, name), np.ndarray)
                else getattr(sub, name)
                for name in sub.__dataclass_fields__
            }
        )
        simulated = replay(tiled, p, box.model).reshape(sets, which.size, -1)
        width = simulated.shape[2]
        return np.where(valid[which, :width], simulated - recorded[which, :width], 0.0)

    def costs(res: np.ndarray, which: np.ndarray) -> np.ndarray:
        return np.bincount(vehicle[which], weights=(res**2).sum(axis=1), minlength=m)

    u = np.tile(box.to_unconstrained(box.start), (m, 1))
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
        shifted = np.repeat(u[None], k, axis=0) + h * np.eye(k)[:, None, :]
        jac = (residuals(shifted, which) - base[None]) / h  # (k, r, N)
        jtj_run = np.einsum("irn,jrn->rij", jac, jac)
        jtr_run = np.einsum("irn,rn->ri", jac, base)
        jtj = np.zeros((m, k, k))
        jtr = np.zeros((m, k))
        np.add.at(jtj, vehicle[which], jtj_run)
        np.add.at(jtr, vehicle[which], jtr_run)
        diag = np.einsum("mii->mi", jtj) + 1e-9
        a = jtj + lam[:, None, None] * diag[:, :, None] * np.eye(k)[None]
        step = np.zeros((m, k))
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
    return box.to_params(u), np.c_[rmse, rmse / mean_gap, iterations]


def median_relative_error(estimate: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """(k,) median over vehicles of |estimate - truth| / truth, per parameter."""
    return np.median(np.abs(estimate - truth) / truth, axis=0)
