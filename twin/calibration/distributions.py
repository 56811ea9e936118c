"""Distributions of the calibrated drivers: a car-following model's fitted parameters
per class group (correlated, log-normal), and desired speeds per lane from free flow.
"""

from dataclasses import dataclass

import numpy as np

from twin.calibration.car_following import FollowerFits
from twin.calibration.following import FreeFlow
from twin.core.i24 import LANES

#: Class groups whose drivers are described separately (coarse I-24 MOTION classes).
CLASS_GROUPS = {"car": (0, 1, 2, 3, 6), "truck": (4, 5)}


@dataclass(frozen=True)
class ParameterDistribution:
    """A model's fitted parameters of one class group, log-normal with correlations.

    Attributes:
        names: the parameters (the model's fitted ones), in order.
        mean_log, sd_log: (k,) mean and sd of log(parameter).
        correlation: (k, k) correlation of the log parameters.
        median, p10, p90: (k,) quantiles of the fitted values.
        count: fits it is made of.
    """

    names: tuple[str, ...]
    mean_log: np.ndarray
    sd_log: np.ndarray
    correlation: np.ndarray
    median: np.ndarray
    p10: np.ndarray
    p90: np.ndarray
    count: int

    @classmethod
    def of(cls, names: tuple[str, ...], params: np.ndarray) -> "ParameterDistribution":
        """The distribution of fitted ``params`` (m, k) of parameters ``names``."""
        k = len(names)
        logs = np.log(params)
        corr = np.corrcoef(logs.T) if len(params) > 2 else np.eye(k)
        corr = np.where(np.isfinite(corr), corr, 0.0)
        np.fill_diagonal(corr, 1.0)
        return cls(
            names=tuple(names),
            mean_log=logs.mean(axis=0),
            sd_log=logs.std(axis=0, ddof=1) if len(params) > 1 else np.zeros(k),
            correlation=corr,
            median=np.median(params, axis=0),
            p10=np.quantile(params, 0.1, axis=0),
            p90=np.quantile(params, 0.9, axis=0),
            count=len(params),
        )

    def draw(self, n: int, rng: np.random.Generator, clip_sd: float = 2.0) -> np.ndarray:
        """(n, k) parameters: correlated log-normal draws clipped at ``clip_sd``."""
        cov = self.correlation * np.outer(self.sd_log, self.sd_log)
        # eigen-decomposition (a fitted correlation may be only semi-definite)
        w, vectors = np.linalg.eigh(cov)
        z = np.clip(rng.standard_normal((n, len(self.names))), -clip_sd, clip_sd)
        logs = self.mean_log + (z * np.sqrt(np.maximum(w, 0.0))) @ vectors.T
        low, high = self.mean_log - clip_sd * self.sd_log, self.mean_log + clip_sd * self.sd_log
        return np.exp(np.clip(logs, low, high))

    def to_dict(self) -> dict:
        return {
            "count": self.count,
            "median": self._named(self.median),
            "p10": self._named(self.p10),
            "p90": self._named(self.p90),
            "mean_log": self._named(self.mean_log),
            "sd_log": self._named(self.sd_log),
            "correlation": np.round(self.correlation, 4).tolist(),
        }

    def _named(self, values: np.ndarray) -> dict:
        return {name: round(float(v), 4) for name, v in zip(self.names, values, strict=True)}

    @classmethod
    def from_dict(cls, d: dict) -> "ParameterDistribution":
        """Read back :meth:`to_dict` (the parameters are the keys of its ``median``)."""
        names = tuple(d["median"])

        def vector(key):
            return np.array([float(d[key][name]) for name in names])

        return cls(
            names=names,
            mean_log=vector("mean_log"),
            sd_log=vector("sd_log"),
            correlation=np.array(d["correlation"], dtype=float).reshape(len(names), len(names)),
            median=vector("median"),
            p10=vector("p10"),
            p90=vector("p90"),
            count=int(d["count"]),
        )


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
        out["all"] = ParameterDistribution.of(fits.names, fits.params[ok])
    groups = class_group(fits.vehicle_class)
    for name in CLASS_GROUPS:
        rows = ok & (groups == name)
        if rows.sum() >= min_count:
            out[name] = ParameterDistribution.of(fits.names, fits.params[rows])
    return out


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


def draw_parameters(distributions: dict, vehicle_class: np.ndarray, rng) -> np.ndarray:
    """(n, k) fitted parameters for vehicles of coarse classes ``vehicle_class`` (n,),
    each drawn from its class group's distribution in ``distributions`` ({group:
    ParameterDistribution}; the pooled ``all`` where its group has none), the groups in
    sorted order (the draws of the calibrated twin, reproducible by ``rng``)."""
    names = next(iter(distributions.values())).names
    groups = class_group(vehicle_class)
    params = np.empty((len(groups), len(names)))
    for group in np.unique(groups):
        rows = groups == group
        dist = distributions.get(group) or distributions["all"]
        params[rows] = dist.draw(int(rows.sum()), rng)
    return params


def desired_speed_source(speeds: dict, car_following: dict, calibrated: bool) -> str:
    """Where a calibrated driver's desired speed comes from: ``free_flow`` (the lane's
    free-flow speeds, ``speeds`` of :func:`desired_speeds`), ``car_following`` (the drawn
    parameters, where the car-following fits identified it: ``car_following`` is the
    calibration's section, ``calibrated`` whether its distributions are driven) or
    ``paper``: whichever estimate more vehicles back."""
    free_count = speeds.get("all", {}).get("count", 0)
    fitted_count = car_following.get("desired_speed_identified", 0) if calibrated else 0
    if free_count >= fitted_count and free_count:
        return "free_flow"
    return "car_following" if fitted_count else "paper"


def draw_desired(speeds: dict, source: str, fitted: np.ndarray, lane: np.ndarray, rng):
    """(n,) [m/s] the desired speeds of drivers in ``lane`` (n,) whose drawn parameters
    hold the desired speeds ``fitted`` (n,), as a calibrated run gives them (``source``,
    of :func:`desired_speed_source`): ``free_flow``, the lanes' free-flow speeds
    (:func:`draw_desired_speeds`); ``car_following``, the fitted ones, but in a lane with
    free-flow speeds of its own (``speeds`` has an entry for it) those: they are what
    its free drivers were seen to drive, where a fitted desired speed extrapolates from
    followers that seldom drove free (SUMO's on-ramp morning: 40.8 m/s fitted, 29.3
    driven in its HOV lane, whose speed field the fitted speeds missed by 4.9 m/s);
    any other source, ``fitted`` as they are."""
    lane = np.asarray(lane, dtype=np.int64)
    if source == "free_flow":
        return draw_desired_speeds(speeds, lane, rng)
    out = np.array(fitted, dtype=np.float64)
    own = np.isin(_lane_row(lane), [-int(k) - 1 for k in speeds if k != "all"])
    if source == "car_following" and own.any():
        out[own] = draw_desired_speeds(speeds, lane[own], rng)
    return out


def draw_desired_speeds(speeds: dict, lane: np.ndarray, rng) -> np.ndarray:
    """(n,) [m/s] desired speeds for vehicles in ``lane`` (n,), drawn from the lane's
    free-flow speeds (``speeds`` of :func:`desired_speeds`; the pooled ``all`` where the
    lane has too few; an on-ramp's drivers lane -4's): normal, clipped at 2 sd, at least
    1 m/s."""
    z = np.clip(rng.standard_normal(len(lane)), -2.0, 2.0)
    summary = {k: speeds.get(str(k)) or speeds["all"] for k in LANES}
    mean = np.array([summary[k]["mean"] for k in LANES])
    sd = np.array([summary[k]["sd"] for k in LANES])
    at = _lane_row(lane)
    return np.maximum(mean[at] + sd[at] * z, 1.0)


def _lane_row(lane) -> np.ndarray:
    """Index into LANES of each ``lane`` (an on-ramp's driver, lane -5: lane -4's)."""
    return np.minimum(-np.asarray(lane, dtype=np.int64) - 1, len(LANES) - 1)
