"""The cosimulation in the kinematic world: deterministic, and beside the physics
world on the same episode (the recorded wave reaching the ego)."""

import hashlib
from dataclasses import replace

import numpy as np
import pytest

from twin.cosim.config import SCENARIO_B, switch_world
from twin.cosim.cosimulator import Cosimulator
from twin.data.empirical import EmpiricalTraffic


def _run(store, bundle, world, seconds=20.0):
    config = replace(switch_world(SCENARIO_B, world), t_max=seconds, behaviour="paper")
    with Cosimulator(config, EmpiricalTraffic(store), bundle) as sim:
        sim.run()
        vehicles = sim.log.vehicles()
        return vehicles, sim.counters


def _digest(frame) -> str:
    return hashlib.sha256(frame.to_numpy().tobytes()).hexdigest()


@pytest.fixture(scope="module")
def runs(wave_store, built_map):
    return {world: _run(wave_store, built_map, world) for world in ("physics", "kinematic")}


def test_the_kinematic_world_gives_the_same_rows_for_the_same_seed(wave_store, built_map, runs):
    again, _ = _run(wave_store, built_map, "kinematic")
    assert _digest(again) == _digest(runs["kinematic"][0])


def test_the_ego_drives_the_same_wave_in_both_worlds(runs):
    (physics, p_counts), (kinematic, k_counts) = runs["physics"], runs["kinematic"]
    ego_p = physics[physics["role"] == 0].set_index("time")["speed"]
    ego_k = kinematic[kinematic["role"] == 0].set_index("time")["speed"]
    seconds = np.arange(0.0, 20.5, 1.0)
    p = np.interp(seconds, ego_p.index, ego_p.to_numpy())
    k = np.interp(seconds, ego_k.index, ego_k.to_numpy())
    assert p.max() - p.min() > 5.0  # the wave reaches the ego
    assert np.sqrt(np.mean((p - k) ** 2)) < 0.5
    assert kinematic["time"].diff().max() == pytest.approx(0.1)  # one row a control step
    assert not p_counts.collisions and not k_counts.collisions
    # the same recorded vehicles entered the window (spawn order by the recording)
    assert abs(p_counts.spawned - k_counts.spawned) <= 2
