"""Energy of the twin's vehicles: fuel from a fitted powertrain model, and the tractive
energy of the twin's own powertrain.

**Fuel.** The CIRCLES consortium's polynomial fit of a 2019 Toyota RAV4 to Autonomie
powertrain simulations (model version 2.0; formula and coefficients from
``trajectory/env/energy_models.py`` of the CIRCLES trajectory-training code, its check
values in ``tests/twin/physics/test_energy.py``). Fuel rate [g/s] from the speed v
[m/s], the acceleration a [m/s^2] and the road grade g (rise over run)::

    f = C0 + C1 v + C2 v^2 + C3 v^3 + p0 a + p1 a v + p2 a v^2
        + q0 max(a, 0)^2 + q1 max(a, 0)^2 v + z0 g + z1 g v
    f = max(f, beta0)   where v <= vc   (the idle floor at low speed)
    f = max(f, 0)       above           (fuel cut when braking: never negative)

(the floor as the source code applies it: ``max(f, (v <= vc) * beta0)``).

An acceleration above ``b1 exp(-b2 v) + b3`` is more than the powertrain can deliver:
such samples are flagged (:meth:`FuelModel.feasible`), not clipped. The model is applied
to every vehicle (a RAV4 for all: a light-duty reference, as the CIRCLES benchmarks use
it); the tractive energy below is each vehicle's own.

**Tractive energy.** What the twin's powertrain delivers at the wheels: the drive torque
times the wheel spin, summed over the driven wheels (:mod:`twin.physics.vehicle`),
logged per step as ``drive_power`` [W].

A run's figures (fuel economy of the ego and its followers, tractive energy per
vehicle) are :mod:`twin.metrics.economy`'s.
"""

from dataclasses import dataclass

import numpy as np
import pandas as pd


@dataclass(frozen=True)
class FuelModel:
    """A polynomial fuel-rate model (see the module doc; units of the coefficients make
    ``f`` come out in g/s with v in m/s, a in m/s^2 and g a fraction)."""

    name: str
    c0: float
    c1: float
    c2: float
    c3: float
    p0: float
    p1: float
    p2: float
    q0: float
    q1: float
    z0: float
    z1: float
    beta0: float  # [g/s] idle floor
    idle_speed: float  # [m/s] vc: the floor holds at or below it
    b1: float  # [m/s^2] feasibility limit b1 exp(-b2 v) + b3
    b2: float  # [s/m]
    b3: float  # [m/s^2]
    mass: float  # [kg] the modelled vehicle's

    def rate(self, speed, accel, grade) -> np.ndarray:
        """Fuel rate [g/s] (n,) at speed [m/s], acceleration [m/s^2] and grade [-]
        (arrays of one shape, or scalars).

        Raises:
            ValueError: a value is not finite, or a speed is negative.
        """
        v, a, g = _finite(speed=speed, accel=accel, grade=grade)
        if np.any(v < 0):
            raise ValueError(f"speeds must be >= 0 m/s, got {v[v < 0][0]:g}")
        push = np.maximum(a, 0.0) ** 2
        f = (
            self.c0
            + self.c1 * v
            + self.c2 * v**2
            + self.c3 * v**3
            + self.p0 * a
            + self.p1 * a * v
            + self.p2 * a * v**2
            + self.q0 * push
            + self.q1 * push * v
            + self.z0 * g
            + self.z1 * g * v
        )
        return np.maximum(f, np.where(v <= self.idle_speed, self.beta0, 0.0))

    def max_accel(self, speed) -> np.ndarray:
        """[m/s^2] the most the powertrain can deliver at speed [m/s]."""
        (v,) = _finite(speed=speed)
        return self.b1 * np.exp(-self.b2 * v) + self.b3

    def feasible(self, speed, accel) -> np.ndarray:
        """(n,) bool: the acceleration is within :meth:`max_accel`."""
        (a,) = _finite(accel=accel)
        return a <= self.max_accel(speed)


#: The CIRCLES 2019 Toyota RAV4 fit (model version 2.0), coefficients as published.
RAV4_2019 = FuelModel(
    name="CIRCLES RAV4 2019 (v2.0)",
    c0=0.14631964767035743,
    c1=0.012179045946260292,
    c2=0.0,
    c3=2.7432588728174234e-05,
    p0=0.04553801347643801,
    p1=0.047436831067050676,
    p2=0.0018022443124799303,
    q0=0.0,
    q1=0.02609037187916979,
    z0=1.4940081773441736,
    z1=1.2718495543500672,
    beta0=0.013111753095302022,
    idle_speed=5.98,
    b1=7.1780386096154185,
    b2=0.053537268955100234,
    b3=0.27965662935753677,
    mass=1717.0,
)


def _finite(**values) -> list[np.ndarray]:
    arrays = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in values.values()))
    for name, array in zip(values, arrays, strict=True):
        if not np.all(np.isfinite(array)):
            raise ValueError(f"{name} must be finite, got {array[~np.isfinite(array)][0]}")
    return arrays


def per_step(rows: pd.DataFrame, grade: np.ndarray, model: FuelModel = RAV4_2019) -> pd.DataFrame:
    """Fuel rate and feasibility of each logged row of the simulated vehicles.

    Args:
        rows: the log's vehicle rows (``speed``, ``accel``: measured, NaN on a vehicle's
            first row).
        grade: (n,) [-] the road's grade under each row, along travel.

    Returns:
        ``fuel_rate`` [g/s] (NaN where the acceleration is not known yet) and
        ``feasible`` (bool; True there), indexed like ``rows``.
    """
    known = np.isfinite(rows["accel"].to_numpy())
    speed = np.maximum(rows["speed"].to_numpy(), 0.0)  # a body may creep back at rest
    accel = rows["accel"].to_numpy()
    rate = np.full(len(rows), np.nan)
    feasible = np.ones(len(rows), dtype=bool)
    rate[known] = model.rate(speed[known], accel[known], np.asarray(grade)[known])
    feasible[known] = model.feasible(speed[known], accel[known])
    return pd.DataFrame({"fuel_rate": rate, "feasible": feasible}, index=rows.index)


def log_rows(rows: pd.DataFrame, road_model, road: int, length: np.ndarray, model=RAV4_2019):
    """The energy columns of the log's simulated-vehicle rows: ``grade`` [-] under each
    vehicle's centre along travel (from the map: ``road_model``, the ``RoadModel``),
    ``fuel_rate`` [g/s] and ``feasible`` (see :func:`per_step`).

    Args:
        rows: the log's vehicle rows (``tid``, ``x`` back centre, ``y``, ``speed``,
            ``accel``).
        road: +1 or -1.
        length: [m] vehicle length per store tid.
    """
    if len(rows) == 0:
        return pd.DataFrame({"grade": [], "fuel_rate": [], "feasible": np.zeros(0, bool)})
    tid = rows["tid"].to_numpy().astype(np.int64)
    center = rows["x"].to_numpy() + 0.5 * length[tid]
    _, _, pitch = road_model.to_world(road, center, rows["y"].to_numpy())
    grade = np.tan(pitch)
    out = per_step(rows, grade, model)
    out.insert(0, "grade", grade)
    return out
