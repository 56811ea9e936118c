"""The baseline controllers against their definitions (CONTROL.md), and driving the ego
from the command line with their parameters from the configuration."""

import json
import math

import numpy as np
import pandas as pd
import pytest

from tests.twin.cosim.scenes import EGO_X, make_store, vehicle
from tests.twin.traffic.conftest import observation
from twin.cli import main
from twin.cosim.config import ConfigError, CosimConfig, from_toml, load_config, to_toml
from twin.traffic import baselines as c

FS = c.FollowerStopperParams()


def test_follower_stopper_commands_its_four_regions():
    # no closing speed: dx_1, dx_2, dx_3 = 4.5, 5.25, 6 m; w = min(v_lead, U) = 10
    at = [4.0, 4.875, 5.625, 10.0]
    speeds = [c.follower_stopper_speed(gap, 10.0, 10.0, 20.0, FS) for gap in at]
    np.testing.assert_allclose(speeds, [0.0, 5.0, 15.0, 20.0])
    # closing at 5 m/s widens dx_1 by 5^2 / (2 x 1.5): 12.83 m
    assert c.follower_stopper_speed(12.8, 15.0, 10.0, 20.0, FS) == 0.0
    assert c.follower_stopper_speed(12.9, 15.0, 10.0, 20.0, FS) > 0.0
    # a leader faster than U: w is U; no leader: U
    assert c.follower_stopper_speed(5.25, 10.0, 30.0, 20.0, FS) == pytest.approx(20.0)
    assert c.follower_stopper_speed(math.inf, 10.0, math.nan, 20.0, FS) == 20.0


def test_pi_with_saturation_blends_target_and_leader_by_the_gap():
    p = c.PISaturationParams()
    # far behind: alpha 1, beta 1/2: half the target (U + v_catch), half the last command
    far = c.pi_saturation_speed(40.0, 20.0, 20.0, 18.0, 16.0, p)
    assert far == pytest.approx(0.5 * (18.0 + 1.0) + 0.5 * 16.0)
    # inside the safe gap max(2 (v_lead - v), 4 m): alpha 0, beta 1: the leader's speed
    assert c.pi_saturation_speed(4.0, 20.0, 12.0, 18.0, 16.0, p) == pytest.approx(12.0)
    assert c.pi_saturation_speed(9.0, 10.0, 15.0, 18.0, 16.0, p) == pytest.approx(15.0)
    # half-way through gamma (dx_s 4 m, gap 5 m): alpha 1/2, beta 3/4; below g_l, target U
    half = c.pi_saturation_speed(5.0, 20.0, 12.0, 18.0, 16.0, p)
    assert half == pytest.approx(0.75 * (0.5 * 18.0 + 0.5 * 12.0) + 0.25 * 16.0)


def test_pi_with_saturation_sets_u_from_the_last_38_seconds_of_its_own_speed():
    controller = c.PISaturation(c.PISaturationParams(gap_low=7.0, catch_up=0.0))
    for k in range(600):  # 60 s: 10 m/s for 20 s, then 20 m/s
        speed = 10.0 if k < 200 else 20.0
        command = controller(_observation(0.1 * k, speed, gap=math.inf))
    # with no leader the command is the target, U, the mean of the last 38 s (all 20)
    assert command.accel == pytest.approx(0.0, abs=1e-9)
    early = c.PISaturation(c.PISaturationParams(catch_up=0.0))
    for k in range(300):  # 30 s: the first 20 s at 10 m/s are still in the window
        speed = 10.0 if k < 200 else 20.0
        command = early(_observation(0.1 * k, speed, gap=math.inf))
    mean = (200 * 10.0 + 100 * 20.0) / 300
    assert command.accel == pytest.approx(max(mean - 20.0, -3.0))


def test_acc_is_the_constant_time_gap_law_within_its_limits():
    p = c.ACCParams()
    # k1 (dx - s0 - h v) + k2 (v_lead - v) = 0.23 (33 - 2 - 30) + 0.07 (18 - 20) = 0.09
    assert c.acc_accel(33.0, 20.0, 18.0, 30.0, p) == pytest.approx(0.09)
    assert c.acc_accel(40.0, 20.0, 18.0, 30.0, p) == 1.5  # 1.70, above the comfort limit
    assert c.acc_accel(10.0, 20.0, 18.0, 30.0, p) == -3.0
    # without a leader: speed keeping toward U
    assert c.acc_accel(math.inf, 28.0, math.nan, 30.0, p) == pytest.approx(0.8)


def test_impossible_parameters_are_named_errors():
    with pytest.raises(ConfigError, match="dx0"):
        from_toml("[controller.follower_stopper]\ndx0 = [6.0, 5.0, 4.0]\n")
    with pytest.raises(ConfigError, match="gap_high"):
        from_toml("[controller.pi_saturation]\ngap_high = 5.0\n")
    with pytest.raises(ConfigError, match="time_gap"):
        from_toml("[controller.acc]\ntime_gap = -1.0\n")
    config = from_toml("[controller.follower_stopper]\ndesired_speed = 25\n")
    assert config.controller.follower_stopper.desired_speed == 25.0
    assert from_toml(to_toml(config)) == config


@pytest.fixture(scope="module")
def follow_store(tmp_path_factory):
    """The ego at 20 m/s, 30 m behind a leader at 20 m/s in lane -2."""
    docs = [vehicle(1, -2, EGO_X, 20.0), vehicle(2, -2, EGO_X + 35.0, 20.0)]
    return make_store(tmp_path_factory.mktemp("follow"), docs)


def _run(store, out, *extra):
    return main([
        "run", "--data", str(store.path), "--road", "westbound", "--lane", "-2",
        "--x", str(EGO_X), "--time", "2022-11-30T06:45:50-06:00", "--duration", "6",
        "--vel-default", "20", "--out", str(out), "--quiet", *extra,
    ])  # fmt: skip


@pytest.mark.parametrize("name", ["human", "follower_stopper", "pi_saturation", "acc"])
def test_each_baseline_drives_the_ego_from_the_command_line(follow_store, tmp_path, name):
    out = tmp_path / name
    spec = f"twin.controllers:{name}"
    assert _run(follow_store, out, "--ego-controller", spec) == 0
    ego = pd.read_parquet(out / "trajectories.parquet").query("role == 'ego'")
    # following (PI with saturation closes a gap over g_u = 30 m at v_catch), no crash
    assert ego["speed"].min() > 15.0 and ego["speed"].max() < 23.0
    assert json.loads((out / "metrics.json").read_text())["physics"]["collisions"] == 0
    assert load_config(out / "config.toml").ego_controller == spec


def test_a_parameter_from_the_configuration_reaches_the_controller(follow_store, tmp_path):
    """FollowerStopper with U = 12 m/s behind a 20 m/s leader slows to 12 m/s."""
    out = tmp_path / "fs"
    args = ["--ego-controller", "twin.controllers:follower_stopper",
            "--set", "controller.follower_stopper.desired_speed=12"]  # fmt: skip
    assert _run(follow_store, out, *args) == 0
    ego = pd.read_parquet(out / "trajectories.parquet").query("role == 'ego'")
    assert ego["speed"].iloc[-1] == pytest.approx(12.0, abs=0.5)
    assert load_config(out / "config.toml").controller.follower_stopper.desired_speed == 12.0


@pytest.mark.parametrize("name", ["follower_stopper", "pi_saturation", "acc"])
def test_the_safety_layer_is_on_unless_the_configuration_turns_it_off(name):
    on = getattr(c, name)(CosimConfig())
    off_config = from_toml("[controller]\nemergency_braking = false\n")
    assert on.emergency_braking is True
    assert getattr(c, name)(off_config).emergency_braking is False


@pytest.mark.parametrize("share", [0.0, 1.0])
def test_av_share_puts_the_controller_on_the_visible_vehicles_too(follow_store, tmp_path, share):
    out = tmp_path / str(share)
    args = ["--ego-controller", "twin.controllers:acc", "--set", f"av_share={share}"]
    assert _run(follow_store, out, *args) == 0
    avs = json.loads((out / "metrics.json").read_text())["energy"]["avs"]
    assert len(avs["ids"]) == (2 if share else 1)  # the ego, and the leader with share 1
    assert avs["mpg"] > 0


def test_av_share_is_checked():
    with pytest.raises(ConfigError, match="av_share needs an ego_controller"):
        CosimConfig(av_share=0.2)
    with pytest.raises(ConfigError, match=r"av_share must be a share in \[0, 1\]"):
        CosimConfig(av_share=1.5, ego_controller="twin.controllers:acc")


def test_bad_controller_output_stops_the_run_naming_controller_and_time(
    follow_store, tmp_path, capsys
):
    spec = "tests.twin.traffic.test_baselines:gives_nan"
    assert _run(follow_store, tmp_path / "nan", "--ego-controller", spec) == 2
    err = capsys.readouterr().err
    assert "the controller gives_nan of vehicle" in err and "at t = 1.00 s" in err
    assert "returned accel nan" in err
    assert not (tmp_path / "nan").exists()


def gives_nan(obs):
    """A controller that fails one second in."""
    return 0.0 if obs.time < 0.995 else float("nan")


def _observation(time, speed, gap, leader_speed=math.nan, lane=-2):
    return observation(speed, gap, leader_speed, lane, time=time, neighbours={})


def test_configuration_defaults_are_control_md_values():
    settings = CosimConfig().controller
    assert settings.follower_stopper.dx0 == (4.5, 5.25, 6.0)
    assert settings.follower_stopper.decel == (1.5, 1.0, 0.5)
    p = settings.pi_saturation
    assert (p.window, p.gap_low, p.gap_high, p.catch_up, p.safe_gap_min, p.gamma) == (
        38.0, 7.0, 30.0, 1.0, 4.0, 2.0,
    )  # fmt: skip
    a = settings.acc
    assert (a.time_gap, a.min_gap, a.k1, a.k2) == (1.5, 2.0, 0.23, 0.07)
