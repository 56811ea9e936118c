"""No gridlock: beside a moving lane, the vehicles of a standing queue either stay in
their lane or finish the change they start; none stops across a lane line."""

import numpy as np
import pytest

from tests.twin.cosim.scenes import EGO_X, T0, make_store, vehicle
from twin.cosim.config import CosimConfig
from twin.cosim.cosimulator import Cosimulator
from twin.data.empirical import EmpiricalTraffic
from twin.metrics import fidelity as metrics


@pytest.mark.slow
@pytest.mark.parametrize("spacing", [8.0, 14.0])  # tight: no room to change; looser: room
def test_a_standing_lane_beside_a_moving_one_does_not_gridlock(built_map, tmp_path, spacing):
    docs = []
    for k in range(60):  # lane -3 stands still around the ego
        docs.append(vehicle(1 + k, -3, EGO_X - 250.0 + spacing * k, 0.0, seconds=70.0))
    for k in range(40):  # lane -2 moves at 12 m/s
        docs.append(vehicle(100 + k, -2, EGO_X - 900.0 + 40.0 * k, 12.0, seconds=70.0))
    store = make_store(tmp_path, docs)
    config = CosimConfig(road="westbound", lane=-3, x=EGO_X, time=T0, t_max=25.0)
    with Cosimulator(config, EmpiricalTraffic(store), built_map) as sim:
        sim.reset()
        sim.run()
        rows = sim.log.vehicles()
        assert not sim.counters.collisions
        sampled = rows[np.round(rows["time"] / config.dt).astype(int) % 10 == 0]
        assert metrics.stalled_across_lines(sampled, 0.1) == 0
        # nobody even pauses across a line at a standstill
        y = sampled["y"].to_numpy()
        centre = (np.round(y / 3.6576 - 0.5) + 0.5) * 3.6576
        across = (np.abs(y - centre) > metrics.ACROSS_LINE) & (sampled["speed"] < 0.5)
        assert not across.any()
        if spacing > 10.0:
            assert sim.manager.lane_changes > 0  # the looser queue did change lanes
