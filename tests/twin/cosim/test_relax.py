"""Relaxing vehicles (twin/cosim/core/relax.py): a vehicle leaving the visible window
stays simulated in the ghost cell and rejoins its recording without a jump, within
its limits; without relaxation the paper's hand-over jumps. Scenario B's wave on the
session's preset-B recording, kinematic world, 120 s."""

from dataclasses import replace

import pytest

from twin.core.errors import TwinError
from twin.cosim.config import SCENARIO_B, CosimConfig
from twin.cosim.core import relax
from twin.cosim.cosimulator import Cosimulator
from twin.data.empirical import EmpiricalTraffic
from twin.metrics.handover import handover_section


def _boundary(store, built_map, relaxes: bool) -> dict:
    config = replace(SCENARIO_B, world="kinematic", dt=0.1, t_max=120.0, relax=relaxes)
    traffic = EmpiricalTraffic(store)
    with Cosimulator(config, traffic, built_map) as sim:
        sim.reset()
        sim.run()
        return handover_section(sim.log.vehicles(), sim.log.windows(), traffic, config.road,
                                sim.t0, config.dt, sim.limits)  # fmt: skip


@pytest.fixture(scope="module")
def relaxed(wave_store, built_map):
    return _boundary(wave_store, built_map, True)


def test_vehicles_rejoin_their_recordings_without_a_jump(relaxed):
    out = relaxed["visible_to_ghost"]
    assert out["count"] >= 3  # handed to their recordings in the ghost cells
    assert out["position_jump_m"]["max"] <= relax.HAND_BACK_X + 0.05  # carried one step
    # its speed the step before, the last drawn, is within HAND_BACK_SPEED of its recording now
    assert out["speed_jump_mps"]["max"] <= relax.HAND_BACK_SPEED + 1e-9
    assert out["backwards"] == 0 and out["into_visible_window"] == 0


def test_relaxing_vehicles_stay_within_their_limits_and_never_reverse(relaxed):
    out = relaxed["relaxing"]
    assert out["vehicles"] > 0
    assert out["accel_min_mps2"] >= relax.ACCEL_LOW - 1e-6  # no emergency in this wave
    assert out["accel_max_mps2"] <= relax.ACCEL_HIGH + 1e-6
    assert out["speed_min_mps"] >= 0.0


def test_without_relaxation_the_papers_hand_over_jumps(wave_store, built_map, relaxed):
    out = _boundary(wave_store, built_map, False)
    assert out["relaxing"]["vehicles"] == 0
    assert out["visible_to_ghost"]["count"] > relaxed["visible_to_ghost"]["count"]
    assert out["visible_to_ghost"]["position_jump_m"]["max"] > 5.0  # the seam relaxation removes


def test_relax_must_be_true_or_false():
    with pytest.raises(TwinError, match="relax must be true or false"):
        CosimConfig(relax="yes")
