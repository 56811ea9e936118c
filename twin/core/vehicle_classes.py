"""The vehicle class table shipped in ``assets/vehicle_classes.csv`` (one row per I-24 class)."""

from dataclasses import dataclass
from functools import cache

import numpy as np
import pandas as pd

from twin.core.i24 import VEHICLE_CLASSES
from twin.core.paths import asset

COLUMNS = (
    "class_id",
    "name",
    "share",
    "length_m",
    "length_sd_m",
    "width_m",
    "width_sd_m",
    "height_m",
    "height_sd_m",
    "desired_speed_mps",
    "desired_speed_sd_mps",
    "max_accel_mps2",
    "time_headway_s",
    "hov_allowed",
    # physics (twin.physics.vehicle): sizes scale with each vehicle's recorded size
    "mass_kg",
    "wheelbase_ratio",  # of the body length
    "track_ratio",  # of the body width
    "wheel_radius_m",
    "cg_height_ratio",  # centre of mass above the ground, of the body height
    "ground_clearance_m",
    "max_power_kw",
    "drag_coefficient",
    "frontal_area_ratio",  # of width x height
    "rolling_resistance",
    "tyre_friction",
    "cornering_stiffness_per_load",  # [1/rad] lateral force per unit load and slip angle
    "slip_stiffness_per_load",  # longitudinal force per unit load and slip ratio
    "suspension_hz",
    "damping_ratio",
    "roll_gyration_ratio",  # radius of gyration, of the body width
    "pitch_gyration_ratio",  # of the body length
    "yaw_gyration_ratio",  # of the body length
    "wheel_inertia_kgm2",
    "drive_axle",  # 0 front, 1 rear
    "brake_front_share",
)


@dataclass(frozen=True)
class VehicleClassTable:
    """Class properties as arrays indexed by I-24 class id (0 sedan ... 6 motorcycle)."""

    frame: pd.DataFrame

    def column(self, name: str) -> np.ndarray:
        return self.frame[name].to_numpy()

    def sample_dimensions(self, classes: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """(n, 3) [m] length, width, height drawn per class, clipped to +/- 2 sd."""
        out = np.empty((len(classes), 3))
        for k, name in enumerate(("length", "width", "height")):
            mean = self.column(f"{name}_m")[classes]
            sd = self.column(f"{name}_sd_m")[classes]
            out[:, k] = mean + sd * np.clip(rng.standard_normal(len(classes)), -2.0, 2.0)
        return out


@cache
def vehicle_classes() -> VehicleClassTable:
    """Load and check ``assets/vehicle_classes.csv``.

    Raises:
        ValueError: naming the file and the problem (missing column, wrong classes,
            non-positive sizes, shares that do not sum to 1).
    """
    path = asset("vehicle_classes.csv")
    frame = pd.read_csv(path)
    missing = [c for c in COLUMNS if c not in frame.columns]
    if missing:
        raise ValueError(f"{path}: missing columns {missing}")
    if list(frame["class_id"]) != list(range(len(VEHICLE_CLASSES))) or list(frame["name"]) != list(
        VEHICLE_CLASSES
    ):
        raise ValueError(f"{path}: rows must be the I-24 classes {VEHICLE_CLASSES} in id order")
    numeric = frame[list(COLUMNS[2:])].to_numpy(dtype=float)
    if not np.all(np.isfinite(numeric)) or np.any(numeric < 0):
        raise ValueError(f"{path}: values must be finite and non-negative")
    positive = ["mass_kg", "wheelbase_ratio", "track_ratio", "wheel_radius_m", "tyre_friction"]
    if np.any(frame[positive].to_numpy() <= 0):
        raise ValueError(f"{path}: {positive} must be positive")
    if not frame["drive_axle"].isin([0, 1]).all() or (frame["brake_front_share"] > 1).any():
        raise ValueError(f"{path}: drive_axle must be 0 or 1, brake_front_share at most 1")
    if abs(frame["share"].sum() - 1.0) > 1e-6:
        raise ValueError(f"{path}: shares sum to {frame['share'].sum()}, not 1")
    return VehicleClassTable(frame.set_index("class_id", drop=False))


@cache
def vehicle_paints() -> tuple[np.ndarray, ...]:
    """Paint colours per class from ``assets/vehicle_paints.csv``: a (k, 3) float array
    of RGB in 0..1 for each class id, in id order.

    Raises:
        ValueError: naming the file and the problem (missing column, unknown class, a
            class without paint, a colour outside 0..255).
    """
    path = asset("vehicle_paints.csv")
    frame = pd.read_csv(path)
    missing = {"vehicle_class", "r", "g", "b"} - set(frame.columns)
    if missing:
        raise ValueError(f"{path}: missing columns {sorted(missing)}")
    unknown = set(frame["vehicle_class"]) - set(VEHICLE_CLASSES)
    if unknown:
        raise ValueError(f"{path}: unknown vehicle classes {sorted(unknown)}")
    rgb = frame[["r", "g", "b"]].to_numpy(dtype=float)
    if not np.all(np.isfinite(rgb)) or (rgb < 0).any() or (rgb > 255).any():
        raise ValueError(f"{path}: colours must be in 0..255")
    paints = []
    for name in VEHICLE_CLASSES:
        rows = (frame["vehicle_class"] == name).to_numpy()
        if not rows.any():
            raise ValueError(f"{path}: no paint for class {name!r}")
        paints.append(rgb[rows] / 255.0)
    return tuple(paints)
