"""The linear speed policy: its file, its features, its clipping, and driving the ego
(numpy alone, the drivers' emergency braking beneath it)."""

import json
from dataclasses import replace

import numpy as np
import pytest

from tests.twin.traffic.conftest import observation
from twin.control.policy import (
    FEATURES,
    FOLLOW_LEADER,
    SHIPPED,
    LinearSpeedPolicy,
    PolicyDriver,
    PolicyError,
    policy_features,
)
from twin.cosim.config import SCENARIO_B, switch_world
from twin.cosim.cosimulator import Cosimulator
from twin.data.empirical import EmpiricalTraffic
from twin.traffic.controller_api import Observation


def _obs(speed=20.0, gap=30.0, leader=18.0, lane=-2) -> Observation:
    return observation(speed, gap, leader, lane, x=500.0, y=5.5)


def test_features_read_the_own_lane_and_cap_the_time_gap():
    ahead = list(np.arange(12, dtype=float))  # lanes -1..-4, three bins each
    values = policy_features(_obs(lane=-2), ahead, mean_speed=17.0, lane_index=1)
    assert dict(zip(FEATURES, values, strict=True)) == {
        "bias": 1.0, "speed": 20.0, "leader_speed": 18.0, "time_gap": 1.5,
        "ahead_0_200": 3.0, "ahead_200_400": 4.0, "ahead_400_600": 5.0, "mean_speed_30s": 17.0,
    }  # fmt: skip
    alone = policy_features(_obs(gap=np.inf, leader=np.nan), ahead, 17.0, 1)
    assert alone[2] == 20.0 and alone[3] == 10.0  # no leader: own speed, the cap


def test_the_command_is_clipped_to_the_speed_range():
    policy = LinearSpeedPolicy(FOLLOW_LEADER)
    values = np.array([1, 20, 18, 1.5, 3, 4, 5, 17.0])
    assert policy.speed_command(values) == 18.0
    assert LinearSpeedPolicy((100.0, *FOLLOW_LEADER[1:])).speed_command(values) == 35.0
    assert LinearSpeedPolicy((-100.0, *FOLLOW_LEADER[1:])).speed_command(values) == 0.0


def test_a_policy_file_round_trips_and_bad_files_are_named(tmp_path):
    policy = LinearSpeedPolicy((0.5, *FOLLOW_LEADER[1:]), about={"by": "test"})
    path = policy.save(tmp_path / "p.json")
    back = LinearSpeedPolicy.load(path)
    assert back == policy and back.about == {"by": "test"}
    with pytest.raises(PolicyError, match="no policy file at"):
        LinearSpeedPolicy.load(tmp_path / "none.json")
    (tmp_path / "bad.json").write_text("{")
    with pytest.raises(PolicyError, match="is not a policy file"):
        LinearSpeedPolicy.load(tmp_path / "bad.json")
    document = json.loads(path.read_text())
    (tmp_path / "other.json").write_text(json.dumps({**document, "features": ["bias"]}))
    with pytest.raises(PolicyError, match="features"):
        LinearSpeedPolicy.load(tmp_path / "other.json")
    for weights in (None, 3, ["a"] * 8, [1.0] * 7):
        (tmp_path / "w.json").write_text(json.dumps({**document, "weights": weights}))
        with pytest.raises(PolicyError, match=r"w\.json: "):
            LinearSpeedPolicy.load(tmp_path / "w.json")
    with pytest.raises(PolicyError, match="8 finite weights"):
        LinearSpeedPolicy((1.0, float("nan"), 0, 0, 0, 0, 0, 0))


def test_the_shipped_policy_loads_and_says_how_it_was_trained():
    policy = LinearSpeedPolicy.load(SHIPPED)
    assert policy.about["trained_by"].startswith("twin.control.train")
    assert policy.about["iterations_done"] >= 1


@pytest.mark.parametrize("world", ["kinematic", "physics"])
def test_the_policy_drives_the_ego_every_control_step(calibrated_wave_store, built_map, world):
    config = replace(switch_world(SCENARIO_B, world), t_max=6.0)
    driver = PolicyDriver(LinearSpeedPolicy.load(SHIPPED))
    traffic = EmpiricalTraffic(calibrated_wave_store)
    with Cosimulator(config, traffic, built_map, controller=driver) as sim:
        sim.run()
        assert driver._calls == config.steps + 1 or driver._calls == config.steps
        assert len(driver._history) == min(60, -(-driver._calls // driver._every))
        assert not sim.counters.collisions
    with pytest.raises(PolicyError, match="bind"):
        PolicyDriver(LinearSpeedPolicy(FOLLOW_LEADER))(_obs())
