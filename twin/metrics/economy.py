"""A run's energy figures: fuel and tractive energy per vehicle from the log, and the
economy of the ego, its followers, the window and the AVs (the fuel model and the
tractive power per step are :mod:`twin.physics.energy`'s).

**Economy.** Miles per US gallon and litres per 100 km of a vehicle or a group (total
distance over total fuel), with the CIRCLES source's conversion: 1 g/s of gasoline is
1.268 US gal/h. Tractive energy is integrated per vehicle in J (braking and coasting
deliver none).
"""

import math

import numpy as np
import pandas as pd

from twin.core import i24
from twin.physics.energy import RAV4_2019, log_rows

GALLONS_PER_HOUR_PER_GRAM_PER_S = 1.268  # [gal/h per g/s] the source's gasoline conversion
GRAMS_PER_GALLON = 3600.0 / GALLONS_PER_HOUR_PER_GRAM_PER_S  # [g/gal] about 2,839
LITRES_PER_GALLON = 3.785411784  # [L/gal] US
FOLLOWERS = 5  # K: followers of the ego counted together with it (the common choice)


def economy(distance_m: float, fuel_g: float) -> dict:
    """Fuel economy of ``distance_m`` driven on ``fuel_g`` grams: ``mpg`` (miles per US
    gallon) and ``l_per_100km``; None where it is undefined (no fuel, or no distance)."""
    gallons = fuel_g / GRAMS_PER_GALLON
    miles = distance_m / i24.MILE
    return {
        "mpg": miles / gallons if gallons > 0 else None,
        "l_per_100km": 100.0 * gallons * LITRES_PER_GALLON / (distance_m / 1000.0)
        if distance_m > 0
        else None,
    }


def per_vehicle(rows: pd.DataFrame, dt: float) -> pd.DataFrame:
    """Per vehicle id: ``fuel_g``, ``distance_m``, ``tractive_j``, ``infeasible_s`` and
    ``time_s`` over its rows (``id``, ``speed``, ``fuel_rate``, ``feasible``,
    ``drive_power``), each row standing for one step of ``dt`` seconds. A vehicle's
    first row, without a measured acceleration, adds no fuel."""
    frame = pd.DataFrame(
        {
            "id": rows["id"].to_numpy(),
            "fuel_g": np.nan_to_num(rows["fuel_rate"].to_numpy()) * dt,
            "distance_m": np.maximum(rows["speed"].to_numpy(), 0.0) * dt,
            "tractive_j": np.maximum(rows["drive_power"].to_numpy(), 0.0) * dt,
            "infeasible_s": (~rows["feasible"].to_numpy()) * dt,
            "time_s": np.full(len(rows), dt),
        }
    )
    return frame.groupby("id").sum()


def group_figures(vehicles: pd.DataFrame, ids) -> dict:
    """Energy figures of the vehicles ``ids`` together (rows of :func:`per_vehicle`)."""
    chosen = vehicles.loc[vehicles.index.intersection(list(ids))]
    fuel, distance = float(chosen["fuel_g"].sum()), float(chosen["distance_m"].sum())
    return {
        "vehicles": len(chosen),
        "distance_m": _r(distance, 3),
        "fuel_g": _r(fuel, 3),
        **{k: _r(v, 3) for k, v in economy(distance, fuel).items()},
        "tractive_kj": _r(float(chosen["tractive_j"].sum()) / 1000.0, 3),
        "tractive_kj_per_km": _r(float(chosen["tractive_j"].sum()) / distance, 3)
        if distance > 0
        else None,
        "infeasible_s": _r(float(chosen["infeasible_s"].sum()), 3),
    }


def _r(value, digits):
    return None if value is None or not math.isfinite(value) else round(float(value), digits)


def followers(rows: pd.DataFrame, ego_id: int, k: int = FOLLOWERS) -> list[int]:
    """The ``k`` simulated vehicles nearest behind the ego in its lane at the first
    logged time (fewer where the window holds fewer), nearest first."""
    first = rows[rows["time"] == rows["time"].min()]
    ego = first[first["id"] == ego_id]
    if ego.empty:
        raise ValueError(f"the ego {ego_id} is not in the log's first rows")
    lane, x = int(ego["lane"].iloc[0]), float(ego["x"].iloc[0])
    behind = first[(first["lane"] == lane) & (first["x"] < x) & (first["id"] != ego_id)]
    return [int(i) for i in behind.sort_values("x", ascending=False)["id"].head(k)]


def run_figures(
    rows: pd.DataFrame,
    ego_id: int,
    road_model,
    road: int,
    length: np.ndarray,
    dt: float,
    avs: list[int] | None = None,
) -> dict:
    """The energy figures of a run (``metrics.json`` ``energy``): the ego, its
    :data:`FOLLOWERS` followers, the two together, every simulated vehicle of the
    window, and the AVs (the ego and ``avs``, the other vehicles with its controller),
    each with distance, fuel, mpg, L/100 km, tractive energy and the seconds of
    infeasible acceleration (see :func:`group_figures`)."""
    fuel = log_rows(rows, road_model, road, length)
    with_fuel = rows.assign(fuel_rate=fuel["fuel_rate"], feasible=fuel["feasible"])
    vehicles = per_vehicle(with_fuel, dt)
    behind = followers(rows, ego_id)
    return {
        "fuel_model": RAV4_2019.name,
        "ego": group_figures(vehicles, [ego_id]),
        "followers": {"ids": behind, **group_figures(vehicles, behind)},
        "ego_and_followers": group_figures(vehicles, [ego_id, *behind]),
        "window": group_figures(vehicles, vehicles.index),
        "avs": {
            "ids": [ego_id, *sorted(avs or [])],
            **group_figures(vehicles, [ego_id, *sorted(avs or [])]),
        },
    }
