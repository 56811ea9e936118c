"""The traffic manager's drivers: per-vehicle state as struct-of-arrays sorted by id."""

from dataclasses import dataclass, fields

import numpy as np

from twin.traffic.mobil import MOBILParams
from twin.traffic.models import base

MOBIL_FIELDS = ("politeness", "threshold", "safe_decel", "keep_right")


@dataclass(eq=False)
class DriverState:
    """Per-vehicle state of the manager, (n,) each, sorted by id.

    ``model`` holds the car-following model's parameters (its parameter dataclass of
    (n,) arrays); the rest is the same for every model.
    """

    id: np.ndarray
    road: np.ndarray
    vehicle_class: np.ndarray
    length: np.ndarray
    wheelbase: np.ndarray
    tyre_decel: np.ndarray  # [m/s^2] mu g, the limit of emergency braking
    model: object  # the car-following model's parameters
    politeness: np.ndarray
    threshold: np.ndarray
    safe_decel: np.ndarray
    keep_right: np.ndarray
    hov_eligible: np.ndarray
    auto_lane_change: np.ndarray
    lane: np.ndarray  # lane driven to
    lane_from: np.ndarray  # lane left while changing, else == lane
    start_x: np.ndarray  # [m] path start (centre x) of the current change
    start_y: np.ndarray  # [m]
    path_length: np.ndarray  # [m]
    next_decision: np.ndarray  # [s]
    requested: np.ndarray  # pending forced lane change: LEFT, RIGHT or 0
    strategic: np.ndarray  # strategic target's direction: LEFT, RIGHT or 0 (strategic.py)
    strategic_from: np.ndarray  # [m] centre x where its urgency starts (nan: none)
    strategic_by: np.ndarray  # [m] centre x by which it must have changed (nan: none)
    accel: np.ndarray  # [m/s^2] last command

    @classmethod
    def empty(cls, params: type) -> "DriverState":
        """No drivers, whose model has the parameter dataclass ``params``."""
        model = params(*(np.empty(0) for _ in fields(params)))
        return cls(
            **{
                f.name: model if f.name == "model" else np.empty(0, dtype=_dtype(f.name))
                for f in fields(cls)
            }
        )

    def __len__(self) -> int:
        return self.id.size

    @property
    def desired_speed(self) -> np.ndarray:
        """(n,) [m/s] the model's desired speeds (the array itself: writes stick)."""
        return self.model.desired_speed

    @property
    def max_accel(self) -> np.ndarray:
        """(n,) [m/s^2] the model's acceleration limits."""
        return self.model.max_accel

    def take(self, index) -> "DriverState":
        return DriverState(
            *(
                base.take(self.model, index) if f.name == "model" else getattr(self, f.name)[index]
                for f in fields(self)
            )
        )

    @staticmethod
    def concatenate(a: "DriverState", b: "DriverState") -> "DriverState":
        return DriverState(
            *(
                base.concatenate(a.model, b.model)
                if f.name == "model"
                else np.concatenate([getattr(a, f.name), getattr(b, f.name)])
                for f in fields(a)
            )
        )

    def mobil(self, index) -> MOBILParams:
        return MOBILParams(*(getattr(self, name)[index] for name in MOBIL_FIELDS))


def _dtype(name: str):
    if name in ("id", "vehicle_class"):
        return np.int64
    if name in ("road", "lane", "lane_from", "requested", "strategic"):
        return np.int8
    if name in ("hov_eligible", "auto_lane_change"):
        return bool
    return np.float64
