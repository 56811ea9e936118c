"""The MLP speed policy (twin.control.mlp): what it sees, its start (follow the leader),
many networks at once, its file, and its controller in the twin with the safety layer."""

import json
from dataclasses import replace

import numpy as np
import pytest

from tests.twin.traffic.conftest import observation
from twin.control.env import OBS_HIGH, OBS_LOW
from twin.control.mlp import (
    INPUTS,
    JERK_LIMIT,
    OVERRIDDEN,
    Actor,
    MLPDriver,
    MLPPolicy,
    accel_command,
    act,
    filtered,
    forward,
    initial_weights,
    inputs,
    n_weights,
    unpack,
)
from twin.control.policy import PolicyError
from twin.cosim.config import SCENARIO_B, switch_world
from twin.cosim.cosimulator import Cosimulator
from twin.data.empirical import EmpiricalTraffic


def _obs(rng, n):
    return rng.uniform(OBS_LOW, OBS_HIGH, size=(n, OBS_LOW.size)).astype(np.float32)


def test_the_inputs_are_scaled_features_of_the_observation():
    obs = np.array([20.0, 1.5, 30.0, 18.0, 40.0, 22.0] + [25.0] * 12)
    x = dict(zip(INPUTS, inputs(obs), strict=True))
    assert x["speed"] == pytest.approx(20.0 / 30.0)
    assert x["time_gap"] == pytest.approx(1.5 / 10.0)  # 30 m at 20 m/s, over the cap
    assert x["leader_speed_diff"] == pytest.approx(-0.2)
    assert x["ahead_0_diff"] == pytest.approx(0.5)


def test_it_starts_by_following_its_leader_whatever_its_hidden_weights():
    obs = _obs(np.random.default_rng(0), 50)
    command = forward(initial_weights(3), obs)
    assert np.allclose(command, np.clip(obs[:, 3], 0.0, 35.0))


def test_its_acceleration_changes_by_at_most_the_jerk_limit():
    obs = np.array([[20.0, 0.0, 30.0, 25.0, 40.0, 20.0] + [25.0] * 12,
                    [20.0, 1.0, 30.0, 19.0, 40.0, 20.0] + [25.0] * 12])  # fmt: skip
    step = JERK_LIMIT * 0.1
    wanted = accel_command(np.array([25.0, 19.0]), obs)  # the loop wants 1.5 and -1
    assert wanted.tolist() == pytest.approx([step, 1.0 - step])
    assert accel_command(np.array([20.05, 20.0]), obs).tolist() == pytest.approx([0.05, 1.0 - step])
    assert act(initial_weights(0), obs).tolist() == pytest.approx([step, 1.0 - step])


def test_many_networks_at_once_are_each_one_alone():
    rng = np.random.default_rng(1)
    thetas = rng.standard_normal((6, n_weights())) * 0.3
    obs = _obs(rng, 6)
    together = forward(thetas, obs)
    alone = [forward(thetas[k], obs[k]) for k in range(6)]
    assert together.tolist() == [float(a) for a in alone]
    assert np.all((together >= 0.0) & (together <= 35.0))
    layers = unpack(thetas)
    assert [w.shape for w, _ in layers] == [(6, 32, 19), (6, 32, 32), (6, 1, 32)]


def _drift(rng, steps, n=3, noise=0.0):
    """``steps`` observations (n, 18) of a slowly changing scene, noisy by ``noise``."""
    base = np.array([20.0, 0.0, 30.0, 19.0, 40.0, 20.0] + [21.0] * 12)
    out = []
    for k in range(steps):
        clean = base + np.array([0.05 * k, 0.0, -0.1 * k, 0.08 * k, 0.0, 0.0] + [0.05 * k] * 12)
        clean = np.repeat(clean[None], n, axis=0)
        out.append(clean * (1.0 + noise * rng.standard_normal(clean.shape)))
    return out


def test_an_actor_with_no_memory_is_act_bit_for_bit():
    rng = np.random.default_rng(7)
    thetas = rng.standard_normal((3, n_weights())) * 0.3
    actor = Actor()
    for obs in _drift(rng, 20, noise=0.05):
        obs = obs.astype(np.float32)
        assert np.array_equal(actor(thetas, obs), act(thetas, obs))


def test_smoothing_averages_what_it_decides_on_and_its_first_decision_is_acts():
    rng = np.random.default_rng(8)
    theta = rng.standard_normal(n_weights()) * 0.3
    noisy = _drift(rng, 60, noise=0.05)
    smooth = Actor(smoothing=2.0)
    assert np.array_equal(smooth(theta, noisy[0]), act(theta, noisy[0]))
    # it decides on the filtered observations, but for the measured acceleration
    estimate = noisy[0].copy()
    for obs in noisy[1:]:
        estimate = filtered(estimate, obs, 2.0)
        seen = estimate.copy()
        seen[:, 1] = obs[:, 1]
        assert np.array_equal(smooth(theta, obs), accel_command(forward(theta, seen), seen))
    # the commanded speeds it decides on vary less than those of each noisy observation
    spread = np.std([forward(theta, o)[0] for o in noisy[30:]])
    means, m = [], noisy[0].copy()
    for obs in noisy[1:]:
        m = filtered(m, obs, 2.0)
        means.append(forward(theta, m)[0])
    assert np.std(means[29:]) < 0.5 * spread


def test_on_a_still_scene_the_filter_is_the_moving_average():
    rng = np.random.default_rng(10)
    still = np.array([20.0, 0.0, 30.0, 20.0, 40.0, 20.0] + [21.0] * 12)
    estimate = mean = still.copy()
    for _ in range(50):  # noise on everything but what moves the scene
        obs = still * (1.0 + 0.05 * rng.standard_normal(still.size))
        obs[[0, 1, 3, 5]] = still[[0, 1, 3, 5]]
        estimate = filtered(estimate, obs, 2.0)
        mean = mean + 0.1 / 2.1 * (obs - mean)
        assert np.allclose(estimate, mean, rtol=0, atol=1e-12)


def test_the_filter_does_not_lag_behind_its_own_acceleration():
    # speeding up at 1 m/s^2 between a leader at 25 m/s and a follower at 15: the
    # estimate is the truth, where a plain moving average would lag 2 m/s behind
    # (accel x smoothing)
    def scene(k):
        speeds = 15.0 + 0.1 * np.arange(k)
        gap = 60.0 + np.sum(25.0 - speeds) * 0.1
        follower_gap = 40.0 + np.sum(speeds - 15.0) * 0.1
        return np.array([15.0 + 0.1 * k, 1.0, gap, 25.0, follower_gap, 15.0] + [25.0] * 12)

    estimate = scene(0)
    for k in range(1, 60):
        estimate = filtered(estimate, scene(k), 2.0)
    assert np.allclose(estimate, scene(59), rtol=0, atol=1e-9)


def test_a_cut_in_or_a_new_follower_restarts_that_vehicles_estimate():
    rng = np.random.default_rng(11)
    steady = np.array([20.0, 0.0, 40.0, 20.0, 30.0, 20.0] + [21.0] * 12)
    estimate = steady.copy()
    for _ in range(30):  # noise of 5 % never passes the gate
        noisy = steady * (1.0 + 0.05 * rng.standard_normal(steady.size))
        noisy[[0, 1, 3, 5]] = steady[[0, 1, 3, 5]]
        estimate = filtered(estimate, noisy, 2.0)
        assert abs(estimate[2] - 40.0) < 4.0
    cut_in = steady.copy()
    cut_in[2:6] = [15.0, 17.0, 12.0, 23.0]  # a slower leader 15 m ahead, a new follower
    after = filtered(estimate, cut_in, 2.0)
    assert np.array_equal(after[2:6], cut_in[2:6])


def test_a_jerk_limit_from_its_own_command_holds_whatever_it_measures():
    rng = np.random.default_rng(9)
    theta = rng.standard_normal(n_weights())
    scenes = _drift(rng, 30)
    own, measured = Actor(jerk_from="command"), Actor()
    commands, jumps = [], []
    for obs in scenes:  # a measurement off its last command by up to 0.9 m/s^2
        if commands:
            obs[:, 1] = commands[-1] + rng.uniform(-0.9, 0.9, size=obs.shape[0])
        commands.append(own(theta, obs))
        jumps.append(measured(theta, obs))
    assert np.abs(np.diff(commands, axis=0)).max() <= JERK_LIMIT * 0.1 + 1e-12
    # from the measured acceleration, its commands jump with the measurement
    assert np.abs(np.diff(jumps, axis=0)).max() > 0.5
    # a measurement further off than OVERRIDDEN (the safety layer braked): from it
    obs = scenes[-1].copy()
    obs[:, 1] = commands[-1] - OVERRIDDEN - 1.0
    after = own(theta, obs)
    assert np.abs(after - obs[:, 1]).max() <= JERK_LIMIT * 0.1 + 1e-12


def test_a_late_measurement_of_an_earlier_command_is_not_an_override():
    theta = np.zeros(n_weights())  # commands its leader's speed: far below its own
    own = Actor(jerk_from="command")
    scene = np.array([[25.0, 0.0, 80.0, 5.0, 40.0, 25.0] + [5.0] * 12])
    commands = [own(theta, scene)]
    for _ in range(9):  # its command falls by the jerk limit each step
        obs = scene.copy()
        obs[:, 1] = commands[max(0, len(commands) - 8)]  # measured 8 steps late
        commands.append(own(theta, obs))
    assert commands[-9][0] - commands[-1][0] > OVERRIDDEN  # late by more than the rule
    assert np.allclose(np.diff(np.concatenate(commands)), -JERK_LIMIT * 0.1)
    obs = scene.copy()
    obs[:, 1] = commands[-9]
    assert np.isclose(own(theta, obs)[0] - commands[-1][0], -JERK_LIMIT * 0.1)


def test_a_policys_memory_is_in_its_file_and_bad_memory_is_named(tmp_path):
    weights = np.random.default_rng(3).standard_normal(n_weights((4,)))
    policy = MLPPolicy(weights, (4,), smoothing=1.5, jerk_from="command")
    back = MLPPolicy.load(policy.save(tmp_path / "p.json"))
    assert (back.smoothing, back.jerk_from) == (1.5, "command")
    plain = json.loads(MLPPolicy(weights, (4,)).save(tmp_path / "plain.json").read_text())
    assert "smoothing_s" not in plain and "jerk_from" not in plain  # files as before
    for change, message in (({"smoothing": -1.0}, "smoothing"), ({"smoothing": float("nan")},
                            "smoothing"), ({"jerk_from": "guess"}, "jerk_from")):  # fmt: skip
        with pytest.raises(PolicyError, match=message):
            MLPPolicy(weights, (4,), **change)


def test_a_policy_file_round_trips_and_bad_files_are_named(tmp_path):
    weights = np.random.default_rng(2).standard_normal(n_weights((8,)))
    policy = MLPPolicy(weights, (8,), about={"seed": 2})
    back = MLPPolicy.load(policy.save(tmp_path / "p.json"))
    assert np.array_equal(back.weights, policy.weights) and back.hidden == (8,)
    assert back.about == {"seed": 2}
    document = json.loads((tmp_path / "p.json").read_text())
    for change, message in (
        ({"weights": document["weights"][:-1]}, "finite weights"),
        ({"weights": [*document["weights"][:-1], "x"]}, "lists of numbers"),
        ({"format": "other"}, "is not a"),
        ({"inputs": ["speed"]}, "inputs"),
        ({"hidden": [0]}, ">= 1 unit"),
    ):
        (tmp_path / "bad.json").write_text(json.dumps({**document, **change}))
        with pytest.raises(PolicyError, match=message):
            MLPPolicy.load(tmp_path / "bad.json")
    (tmp_path / "bad.json").write_text("{")
    with pytest.raises(PolicyError, match="not a policy file"):
        MLPPolicy.load(tmp_path / "bad.json")
    with pytest.raises(PolicyError, match="no policy file"):
        MLPPolicy.load(tmp_path / "missing.json")
    with pytest.raises(PolicyError, match="finite"):
        MLPPolicy(np.full(n_weights(), np.nan))


def test_twin_rl_policy_drives_an_mlp_file_with_the_safety_layer(
    calibrated_wave_store, built_map, tmp_path
):
    from twin.control.rl import policy as policy_factory

    weights = np.random.default_rng(4).standard_normal(n_weights()) * 0.2
    path = MLPPolicy(weights).save(tmp_path / "mlp.json")
    config = replace(switch_world(SCENARIO_B, "kinematic"), t_max=6.0)
    config = replace(config, controller=replace(config.controller, policy=replace(
        config.controller.policy, model=str(path))))  # fmt: skip
    driver = policy_factory(config)
    assert isinstance(driver, MLPDriver) and driver.emergency_braking
    with Cosimulator(config, EmpiricalTraffic(calibrated_wave_store), built_map,
                     controller=driver) as sim:  # fmt: skip
        sim.run()
        assert driver._calls >= config.steps
        assert not sim.counters.collisions
    with pytest.raises(PolicyError, match="bind"):
        MLPDriver(MLPPolicy(weights))(observation(20.0, 30.0, 18.0, -2, x=500.0, y=5.5))


def test_a_policy_the_twin_ships_is_named_without_a_path():
    from twin.control.policy import PolicyDriver
    from twin.control.rl import policy as policy_factory

    config = SCENARIO_B
    named = replace(config, controller=replace(config.controller, policy=replace(
        config.controller.policy, model="wave_ars")))  # fmt: skip
    assert isinstance(policy_factory(named), PolicyDriver)
    unknown = replace(named, controller=replace(named.controller, policy=replace(
        named.controller.policy, model="no_such_policy")))  # fmt: skip
    with pytest.raises(PolicyError, match=r"the twin ships .*wave_ars"):
        policy_factory(unknown)


def test_the_default_policy_is_the_shipped_mlp_and_says_how_it_was_trained():
    from twin.control.policy import DEFAULT
    from twin.control.rl import policy as policy_factory

    shipped = MLPPolicy.load(DEFAULT)
    assert DEFAULT.stem == "wave_es_mlp_margin"
    # fine-tuned from wave_es_mlp_robust, itself from wave_es_mlp: over 20 million env
    # steps within the hour in all
    assert shipped.about["env_steps_in_all"] >= 20_000_000
    assert shipped.about["wall_s_in_all"] <= 3600.0
    assert "twin train --algorithm es" in shipped.about["command"]
    assert "--seed 3" in shipped.about["command"] and "--start" in shipped.about["command"]
    assert "--time-gap-p90-max 3.5" in shipped.about["command"]
    # the command written down is the one the trainer recorded, with no local paths
    config = shipped.about["config"]
    assert (config["time_gap_p90_max"], config["seed"]) == (3.5, 3)
    assert config["start"] == "twin/control/policies/wave_es_mlp_robust.json"
    assert "/work" not in json.dumps(shipped.about) and "/tmp" not in json.dumps(shipped.about)
    assert (shipped.smoothing, shipped.jerk_from) == (2.0, "command")
    assert (config["obs_noise"], config["latency_steps"]) == (0.05, 2)
    driver = policy_factory(SCENARIO_B)
    assert isinstance(driver, MLPDriver) and np.array_equal(driver.policy.weights, shipped.weights)
    assert driver._actor.smoothing == 2.0  # it drives with its memory
    robust = MLPPolicy.load(DEFAULT.with_name("wave_es_mlp_robust.json"))  # kept by name
    assert "--seed 1" in robust.about["command"]
    first = MLPPolicy.load(DEFAULT.with_name("wave_es_mlp.json"))
    assert first.about["env_steps"] >= 20_000_000 and "--seed 0" in first.about["command"]


class _Clock:
    """What MLPDriver reads of a cosimulation: one decision per call."""

    def __init__(self):
        from types import SimpleNamespace

        from twin.control.env import CONTROL_DT

        self.config = SimpleNamespace(dt=CONTROL_DT, vel_default=30.0)
        self.traffic = self.road = None
        self.t = 0.0


def _commands(driver, observations) -> list[float]:
    driver.bind(_Clock())
    return [driver(o).accel for o in observations]


def _drive(n=12):
    """Observations of an ego closing on a slower leader, speed and gap changing."""
    return [
        observation(20.0 + 0.03 * k, 40.0 - 0.5 * k, 19.0, -2, x=500.0 + 2.0 * k, y=5.5)
        for k in range(n)
    ]


@pytest.fixture
def flat_ahead(monkeypatch):
    """The recorded speeds ahead, 20 m/s everywhere (no recording needed)."""
    import twin.control.mlp as mlp

    monkeypatch.setattr(mlp, "ahead_speeds", lambda *args: [20.0] * 12)


class _Seen:
    """A policy that records the observations it decides on."""

    weights = None

    def __init__(self):
        self.seen = []

    def actor(self):
        return self

    def __call__(self, theta, obs):
        self.seen.append(np.array(obs))
        return np.float64(0.0)


def test_latency_decides_on_the_observation_of_steps_before(flat_ahead):
    now, late = _Seen(), _Seen()
    _commands(MLPDriver(now), _drive())
    _commands(MLPDriver(late, latency_steps=2), _drive())
    # the first decisions see the first observation; then two control steps late
    assert all(np.array_equal(o, now.seen[0]) for o in late.seen[:3])
    assert all(np.array_equal(a, b) for a, b in zip(late.seen[2:], now.seen[:-2], strict=True))
    assert not np.array_equal(now.seen[2], now.seen[0])  # the drive changes what it sees


def test_observation_noise_is_drawn_per_vehicle_and_seed(flat_ahead):
    weights = np.random.default_rng(6).standard_normal(n_weights()) * 0.3
    policy = MLPPolicy(weights)
    clean = _commands(MLPDriver(policy), _drive())
    assert _commands(MLPDriver(policy, obs_noise=0.0, seed=3), _drive()) == clean
    noisy = _commands(MLPDriver(policy, obs_noise=0.05, seed=3), _drive())
    assert noisy != clean and np.all(np.isfinite(noisy))
    assert _commands(MLPDriver(policy, obs_noise=0.05, seed=3), _drive()) == noisy
    assert _commands(MLPDriver(policy, obs_noise=0.05, seed=4), _drive()) != noisy
    other = [replace(o, id=o.id + 1) for o in _drive()]
    assert _commands(MLPDriver(policy, obs_noise=0.05, seed=3), other) != noisy


def test_noise_and_latency_are_settings_of_an_mlp_policy_only():
    from twin.control.rl import RLError
    from twin.control.rl import policy as policy_factory
    from twin.traffic.baselines import PolicySettings

    def with_policy(**settings):
        return replace(SCENARIO_B, controller=replace(
            SCENARIO_B.controller, policy=PolicySettings(**settings)))  # fmt: skip

    driver = policy_factory(with_policy(obs_noise=0.05, latency_steps=2))
    assert isinstance(driver, MLPDriver)
    assert (driver.obs_noise, driver.latency_steps) == (0.05, 2)
    with pytest.raises(RLError, match=r"apply to an MLP policy.*wave_ars"):
        policy_factory(with_policy(model="wave_ars", obs_noise=0.05))
    for bad in ({"obs_noise": -0.1}, {"obs_noise": float("nan")}, {"latency_steps": 1.5},
                {"latency_steps": -1}):  # fmt: skip
        with pytest.raises(ValueError, match=next(iter(bad))):
            PolicySettings(**bad)
    for bad in ({"latency_steps": -1}, {"latency_steps": True}, {"obs_noise": "0.1"}):
        with pytest.raises(PolicyError, match=next(iter(bad))):
            MLPDriver(MLPPolicy(np.zeros(n_weights())), **bad)


def test_the_twins_driver_decides_with_the_policys_memory(flat_ahead):
    weights = np.random.default_rng(12).standard_normal(n_weights()) * 0.3
    remembering = MLPPolicy(weights, smoothing=2.0, jerk_from="command")
    seen = _Seen()
    _commands(MLPDriver(seen), _drive(30))
    actor = remembering.actor()
    expected = [float(actor(weights, o)) for o in seen.seen]
    assert _commands(MLPDriver(remembering), _drive(30)) == expected
    assert _commands(MLPDriver(MLPPolicy(weights)), _drive(30)) != expected


def test_predict_keeps_the_policys_memory_in_its_state():
    rng = np.random.default_rng(13)
    policy = MLPPolicy(rng.standard_normal(n_weights()) * 0.3, smoothing=2.0, jerk_from="command")
    scenes = [o[0] for o in _drift(rng, 20, n=1, noise=0.05)]
    actor, state, actions = policy.actor(), None, []
    for obs in scenes:
        action, state = policy.predict(obs, state)
        assert action.shape == (1,) and action.dtype == np.float32
        actions.append(float(action[0]))
    assert actions == [float(np.float32(actor(policy.weights, o))) for o in scenes]
    # a fresh state (or an episode's start) decides as the first decision does
    assert policy.predict(scenes[5])[0][0] == np.float32(policy.accel(scenes[5]))
    restarted, _ = policy.predict(scenes[5], state, episode_start=np.array([True]))
    assert restarted[0] == np.float32(policy.accel(scenes[5]))


def test_the_filter_follows_the_safety_layers_hard_braking_and_stops_at_zero():
    # braking at 8 m/s^2 (the safety layer, beyond the policy's own -3) from 20 m/s
    def scene(k):  # the acceleration measured over the step before
        speed, before = max(20.0 - 0.8 * k, 0.0), max(20.0 - 0.8 * (k - 1), 0.0)
        return np.array([speed, (speed - before) / 0.1, 50.0, 20.0, 40.0, 20.0] + [20.0] * 12)

    estimate = scene(0)
    for k in range(1, 40):
        estimate = filtered(estimate, scene(k), 2.0)
        assert abs(estimate[0] - scene(k)[0]) < 0.5 and estimate[0] >= 0.0


def test_a_leader_appearing_far_ahead_restarts_its_estimate():
    none = np.array([20.0, 0.0, 200.0, 20.0, 200.0, 20.0] + [20.0] * 12)  # no leader
    estimate = filtered(none.copy(), none, 2.0)
    far = none.copy()
    far[2:4] = [180.0, 10.0]  # a slow leader 180 m ahead: the gap moved 10 %
    after = filtered(estimate, far, 2.0)
    assert np.array_equal(after[2:4], far[2:4])
