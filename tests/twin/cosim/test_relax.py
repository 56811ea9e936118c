"""Relaxing vehicles (twin/cosim/core/relax.py): a vehicle leaving the visible window
stays simulated in the ghost cell and rejoins its recording without a jump, within
its limits; without relaxation the paper's hand-over jumps. Scenario B's wave on the
session's preset-B recording, kinematic world, 120 s, and a hand-built scene
(``tests/twin/cosim/scenes.py``)."""

from dataclasses import replace

import pytest

from tests.twin.cosim.scenes import EGO_X, tid_of, vehicle
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


def test_a_vehicle_far_ahead_of_its_recording_eases_off_without_stopping_in_its_lane(cosim):
    # SUMO's on-ramp morning, episode 17: a body drove on at its desired speed where its
    # recording crawled at 8 m/s, left the visible window 160 m ahead of it, braked to a
    # stand there to wait for it and stopped the visible traffic in its lane behind it.
    # Here the ego (lane -2) and two recordings in lane -3 crawl at 8 m/s; the bodies run free
    # toward 30 m/s, leave the window far ahead of their recordings and relax: each
    # slows toward its recording no further than EASE_SHARE of its speed (a little more
    # where its car following brakes it behind the other), and neither stops
    ahead, behind = vehicle(2, -3, EGO_X + 100.0, 8.0), vehicle(3, -3, EGO_X + 60.0, 8.0)
    sim = cosim([vehicle(1, -2, EGO_X, 8.0), ahead, behind], world="kinematic", dt=0.1,
                t_max=30.0)  # fmt: skip
    sim.run()
    frame = sim.log.vehicles()
    section = handover_section(frame, sim.log.windows(), sim.traffic, sim.config.road,
                               sim.t0, sim.config.dt, sim.limits)  # fmt: skip
    relaxing = section["relaxing"]
    assert relaxing["vehicles"] >= 1 and relaxing["distance_m"]["max"] > 50.0  # far ahead
    for n in (2, 3):
        rows = frame[frame["tid"] == tid_of(sim, n)]
        assert len(rows) > 0 and rows["speed"].min() >= relax.EASE_SHARE * 8.0 - 0.5, n
        assert rows["speed"].min() <= relax.EASE_SHARE * 8.0 + 0.1, n  # it did slow for it
    assert sim.counters.contacts == 0
