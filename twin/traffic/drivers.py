"""Heterogeneous drivers: each vehicle's traits drawn from its class.

A driver's traits are what the class table describes (desired speed, time headway,
maximum acceleration) with a minimum gap, a comfortable deceleration and IDM's
acceleration exponent; every car-following model turns them into its parameters
(``CarFollowingModel.from_traits``). Class means come from
``assets/vehicle_classes.csv`` (desired speed and its spread, maximum acceleration,
time headway); the spreads around them are settings here. Draws are standard normals
clipped to +/- 2 sd, so no driver is absurd.
"""

from dataclasses import dataclass

import numpy as np

from twin.core.vehicle_classes import VehicleClassTable
from twin.traffic.kernels.models import N_PARAMS

CLIP_SD = 2.0  # draws are clipped to this many standard deviations


@dataclass(frozen=True)
class DriverTraits:
    """Drivers' traits, struct-of-arrays; each field (n,) float64 or a scalar.

    Attributes:
        desired_speed: [m/s]. time_headway: [s]. min_gap: [m] at a standstill.
        max_accel: [m/s^2]. comfortable_decel: [m/s^2], positive.
        delta: [-] IDM's acceleration exponent.
    """

    desired_speed: np.ndarray | float
    time_headway: np.ndarray | float
    min_gap: np.ndarray | float
    max_accel: np.ndarray | float
    comfortable_decel: np.ndarray | float
    delta: np.ndarray | float = 4.0


@dataclass(frozen=True)
class DriverDistribution:
    """How drivers' traits are drawn per vehicle.

    Attributes:
        time_headway_sd_log: [-] log-normal spread of T around the class's T.
        min_gap: [m] mean s0, the gap kept at a standstill.
        min_gap_sd: [m] standard deviation of s0.
        max_accel_sd_log: [-] log-normal spread of a around the class's a.
        comfortable_decel: [m/s^2] mean b, the comfortable deceleration (positive).
        comfortable_decel_sd: [m/s^2] standard deviation of b (0: every driver the same).
        delta: [-] IDM exponent.
        desired_speed_scale, time_headway_scale, max_accel_scale: [-] factors on the
            class table's means (drivers unlike the table's, e.g. for test data).
    """

    time_headway_sd_log: float = 0.12
    min_gap: float = 2.0
    min_gap_sd: float = 0.3
    max_accel_sd_log: float = 0.15
    comfortable_decel: float = 1.7
    comfortable_decel_sd: float = 0.0
    delta: float = 4.0
    desired_speed_scale: float = 1.0
    time_headway_scale: float = 1.0
    max_accel_scale: float = 1.0

    def __post_init__(self):
        scales = (self.desired_speed_scale, self.time_headway_scale, self.max_accel_scale)
        if any(not (np.isfinite(s) and s > 0) for s in scales):
            raise ValueError(f"driver scales must be finite and positive, got {scales}")
        spreads = (
            self.time_headway_sd_log,
            self.min_gap_sd,
            self.max_accel_sd_log,
            self.comfortable_decel_sd,
        )
        if any(not np.isfinite(s) or s < 0 for s in spreads):
            raise ValueError(f"driver spreads must be finite and >= 0, got {spreads}")
        if not self.min_gap - CLIP_SD * self.min_gap_sd > 0:
            raise ValueError(f"min_gap {self.min_gap} m must stay positive at -2 sd")
        if not self.comfortable_decel - CLIP_SD * self.comfortable_decel_sd > 0:
            raise ValueError(
                f"comfortable_decel {self.comfortable_decel} m/s^2 must stay positive at -2 sd"
            )
        if not self.delta > 0:
            raise ValueError(f"delta must be positive, got {self.delta}")

    def draw(
        self, classes: VehicleClassTable, vehicle_class: np.ndarray, rng: np.random.Generator
    ) -> DriverTraits:
        """Traits (n,) of the drivers of vehicles of ``vehicle_class`` (n,) ints.

        The draws are made in the order v0, T, s0, a, b, each ``n`` at a time.
        """
        n = len(vehicle_class)

        def z():
            return np.clip(rng.standard_normal(n), -CLIP_SD, CLIP_SD)

        desired_speed = self.desired_speed_scale * (
            classes.column("desired_speed_mps")[vehicle_class]
            + classes.column("desired_speed_sd_mps")[vehicle_class] * z()
        )
        time_headway = (
            self.time_headway_scale
            * classes.column("time_headway_s")[vehicle_class]
            * np.exp(self.time_headway_sd_log * z())
        )
        min_gap = self.min_gap + self.min_gap_sd * z()
        max_accel = (
            self.max_accel_scale
            * classes.column("max_accel_mps2")[vehicle_class]
            * np.exp(self.max_accel_sd_log * z())
        )
        decel = np.full(n, self.comfortable_decel)
        if self.comfortable_decel_sd > 0:
            decel = decel + self.comfortable_decel_sd * z()
        return DriverTraits(
            desired_speed, time_headway, min_gap, max_accel, decel, np.full(n, self.delta)
        )


def mean_driver_row(drivers: DriverDistribution, model, classes: VehicleClassTable) -> np.ndarray:
    """(N_PARAMS,) the class table's mean driver (shares weighting the classes' desired
    speed, time headway and maximum acceleration; ``drivers``' minimum gap, comfortable
    deceleration and exponent) in the parameters of ``model`` (a
    :class:`~twin.traffic.models.base.CarFollowingModel`), padded with zeros: the row
    the kernels judge obstacles (the ghosts) by, as if they drove like one."""
    share = classes.column("share")
    traits = DriverTraits(
        desired_speed=float(share @ classes.column("desired_speed_mps")),
        time_headway=float(share @ classes.column("time_headway_s")),
        min_gap=drivers.min_gap,
        max_accel=float(share @ classes.column("max_accel_mps2")),
        comfortable_decel=drivers.comfortable_decel,
        delta=drivers.delta,
    )
    params = model.from_traits(traits)
    row = np.zeros(N_PARAMS)
    row[: len(model.names)] = [float(getattr(params, name)) for name in model.names]
    return row
