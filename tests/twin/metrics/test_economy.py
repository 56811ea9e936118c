"""A run's energy figures: a group's economy is its total distance over its total fuel."""

import numpy as np
import pandas as pd
import pytest

from twin.core.i24 import MILE
from twin.metrics import economy


def test_group_economy_is_total_distance_over_total_fuel():
    rows = pd.DataFrame(
        {
            "id": [1, 1, 2, 2],
            "speed": [10.0, 10.0, 30.0, 30.0],
            "fuel_rate": [np.nan, 0.5, 1.0, 1.0],  # id 1's first row: no acceleration yet
            "feasible": [True, True, True, False],
            "drive_power": [1000.0, -50.0, 2000.0, 2000.0],
        }
    )
    vehicles = economy.per_vehicle(rows, dt=2.0)
    assert vehicles.loc[1, "fuel_g"] == 1.0 and vehicles.loc[1, "tractive_j"] == 2000.0
    both = economy.group_figures(vehicles, [1, 2, 99])  # 99: not simulated, ignored
    assert both["vehicles"] == 2 and both["distance_m"] == 160.0 and both["fuel_g"] == 5.0
    gallons = 5.0 / economy.GRAMS_PER_GALLON
    assert both["mpg"] == pytest.approx(160.0 / MILE / gallons, rel=1e-3)
    assert both["infeasible_s"] == 2.0 and both["tractive_kj"] == 10.0
