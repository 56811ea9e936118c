"""Every controller, baseline or learned, answers a finite command for any state the twin
can produce: a property over random and adversarial observations (zero, negative, huge
and unmeasured gaps, no leader, standing and fast leaders, a leader of unknown speed).
A zero or negative gap is a state to handle, not a division."""

import math
from dataclasses import replace
from types import SimpleNamespace
from unittest import mock

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.twin.traffic.conftest import observation
from twin.control import mlp as mlp_module
from twin.control import policy as policy_module
from twin.cosim.config import CosimConfig
from twin.rl import policy
from twin.traffic.baselines import BASELINES
from twin.traffic.controller_api import load_controller, parse_command
from twin.traffic.kernels.controllers import acc_accel, follower_stopper_speed, speed_loop
from twin.traffic.kernels.decide import driver_limit
from twin.traffic.kernels.models import gipps_accel, idm_accel

ADVERSARIAL_GAPS = [0.0, -0.0, 1e-12, -1e-12, -4.5, -1e9, 1e9, 1e300, math.inf, -math.inf, math.nan]
GAPS = st.one_of(st.sampled_from(ADVERSARIAL_GAPS), st.floats(-50.0, 1e4))
SPEEDS = st.one_of(st.sampled_from([0.0, -0.5, 45.0, 80.0]), st.floats(-1.0, 80.0))
LEADER_SPEEDS = st.one_of(
    st.sampled_from([0.0, 60.0, math.nan, math.inf, -math.inf]), st.floats(-1.0, 80.0)
)
STATE = st.tuples(
    SPEEDS,
    GAPS,
    LEADER_SPEEDS,
    st.floats(-12.0, 5.0),  # the driver's command: finite (decide.driver_limit)
    st.sampled_from([0.0, 0.1, 30.0, 45.0]),  # desired speed
)
#: the recorded speeds ahead a learned policy reads: adversarial ones too
AHEAD = st.lists(st.sampled_from([0.0, 0.5, 12.0, 33.0, 80.0]), min_size=12, max_size=12)


def _controllers():
    """A fresh controller of each baseline, of the shipped policy and of an MLP policy
    (weights drawn large: saturated layers), bound as the cosimulator binds them."""
    config = CosimConfig()
    out = {name: load_controller(f"twin.controllers:{name}", config) for name in BASELINES}
    out["twin.rl:policy"] = policy(config)
    weights = np.random.default_rng(0).standard_normal(mlp_module.n_weights()) * 3.0
    out["mlp"] = mlp_module.MLPDriver(mlp_module.MLPPolicy(weights))
    sim = SimpleNamespace(
        config=SimpleNamespace(dt=0.1, vel_default=30.0), traffic=None, road=None, t=0.0
    )
    for controller in out.values():
        if hasattr(controller, "bind"):
            controller.bind(sim)
    return out


@settings(max_examples=150, deadline=None)
@given(states=st.lists(STATE, min_size=1, max_size=25), ahead=AHEAD)
def test_every_controller_answers_a_finite_command_in_any_state(states, ahead):
    speeds = mock.patch.object(mlp_module, "ahead_speeds", lambda *args: list(ahead))
    with mock.patch.object(policy_module, "ahead_speeds", lambda *args: list(ahead)), speeds:
        controllers = _controllers()
        for step, (speed, gap, leader_speed, default, desired) in enumerate(states):
            obs = replace(
                observation(speed, gap, leader_speed, time=0.1 * step),
                default_accel=default,
                desired_speed=desired,
            )
            for name, controller in controllers.items():
                # parse_command raises ControllerError on a non-finite acceleration
                accel, _ = parse_command(controller(obs), f"{name} at step {step}")
                assert math.isfinite(accel)


@settings(max_examples=300, deadline=None)
@given(
    speed=st.floats(0.0, 80.0),
    gap=st.one_of(st.sampled_from([0.0, -1e9, 1e9, math.inf]), st.floats(-50.0, 1e4)),
    leader_speed=st.floats(0.0, 80.0),
)
def test_the_compiled_laws_are_finite_in_any_state(speed, gap, leader_speed):
    """The laws the core drives vehicles with (a leader there has a finite speed)."""
    dx0, decel = np.array([4.5, 5.25, 6.0]), np.array([1.5, 1.0, 0.5])
    v_cmd = follower_stopper_speed(gap, speed, leader_speed, 30.0, dx0, decel)
    answers = [
        v_cmd,
        speed_loop(v_cmd, speed, 1.0, 1.5, 3.0),
        acc_accel(gap, speed, leader_speed, 30.0, 1.5, 2.0, 0.23, 0.07, 0.4, 1.5, 3.0),
        idm_accel(speed, leader_speed, gap, 30.0, 1.5, 2.0, 1.5, 1.7, 4.0, True),
        idm_accel(speed, leader_speed, gap, 0.0, 1.5, 2.0, 1.5, 1.7, 4.0, False),
        gipps_accel(speed, leader_speed, gap, 30.0, 1.5, 3.0, 0.7, 2.0),
    ]
    assert all(math.isfinite(a) for a in answers), answers


def test_a_driver_with_no_room_left_brakes_with_all_the_grip_not_minus_infinity():
    # the emergency command is -need, and need is inf where the room is used up: the
    # driver's command a controller is shown (Observation.default_accel) is what the
    # vehicle applies, within the grip (before, human passed on -inf and a sweep died)
    assert driver_limit(-math.inf, True, 9.81, 0.8, 1.5) == -9.81
    assert driver_limit(-math.inf, False, 9.81, 0.8, 1.5) == -0.8 * 9.81
    assert driver_limit(3.0, False, 9.81, 0.8, 1.5) == 1.5
