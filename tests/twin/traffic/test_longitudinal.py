"""IDM on the physics world: analytic oracles for car following, stopping, cruising,
and emergency braking whatever the leader or the boundary does."""

import numpy as np
import pytest

from tests.twin.traffic.conftest import PointMasses, make_manager, point_mass_manager, run, spawn
from twin.core.i24 import LANE_WIDTH, lane_center
from twin.traffic.config import TrafficConfig
from twin.traffic.controller_api import EgoCommand
from twin.traffic.scene import Obstacles

DRIVER = dict(time_headway=1.2, min_gap=2.0, max_accel=1.0, comfortable_decel=1.5, delta=4.0)


def follower_gap(recording, length):
    return recording.x[:, 0] - recording.x[:, 1] - length


def test_follower_settles_at_the_idm_equilibrium_gap(world, built_map):
    manager = make_manager(built_map, auto_lane_change=False)
    ids = spawn(world, manager, 1, -2, [-250.0, -330.0], 20.0, desired_speed=[20.0, 30.0])
    manager.set_params(ids, **DRIVER)
    rec = run(world, manager, 90.0)
    length = world.params_of(ids[1:]).length[0]
    v = rec.speed[-1, 1]
    assert rec.speed[-1, 0] == pytest.approx(20.0, abs=0.1)
    assert v == pytest.approx(rec.speed[-1, 0], abs=0.02)  # steady
    # the IDM's steady state behind a leader at v: s*(v) = (s0 + v T) / sqrt(1 - (v/v0)^4)
    expected = (2.0 + v * 1.2) / np.sqrt(1.0 - (v / 30.0) ** 4)
    assert follower_gap(rec, length)[-1] == pytest.approx(expected, rel=0.01)
    assert rec.contacts == 0


def test_approach_to_a_stopped_vehicle_ends_stopped_at_the_minimum_gap(world, built_map):
    manager = make_manager(built_map, auto_lane_change=False)
    ids = spawn(world, manager, -1, -3, [400.0, 0.0], [0.0, 25.0], desired_speed=[0.0, 30.0])
    manager.set_params(ids[1:], **DRIVER)
    rec = run(world, manager, 60.0)
    gap = follower_gap(rec, world.params_of(ids[1:]).length[0])
    assert rec.speed[-1, 1] < 0.05 and abs(rec.speed[-1, 0]) < 0.01
    assert gap[-1] == pytest.approx(2.0, abs=0.3)  # s0
    assert gap.min() > 1.5
    assert rec.x[-1, 0] == pytest.approx(rec.x[0, 0], abs=0.05)  # the stopped one held
    assert rec.contacts == 0


@pytest.mark.parametrize("road", [1, -1])  # uphill and downhill
def test_free_road_cruise_reaches_the_desired_speed_within_a_tenth(world, built_map, road):
    manager = make_manager(built_map, auto_lane_change=False)
    classes = [0, 2, 4, 6]  # sedan, pickup, semi, motorcycle
    desired = [31.0, 29.0, 25.0, 33.0]
    spawn(world, manager, road, [-1, -2, -3, -4], -350.0, 22.0, classes, desired_speed=desired)
    rec = run(world, manager, 60.0)
    assert np.abs(rec.speed[-1] - desired).max() <= 0.1
    assert np.abs(rec.speed[-200:] - desired).max() <= 0.1  # steady over the last 2 s


def test_a_lowered_desired_speed_is_followed_at_the_comfortable_deceleration(world, built_map):
    manager = make_manager(built_map, auto_lane_change=False)
    ids = spawn(world, manager, 1, -2, -350.0, 30.0, desired_speed=30.0)
    manager.set_params(ids, **DRIVER)
    run(world, manager, 2.0)
    manager.set_desired_speed(ids, 10.0)
    rec = run(world, manager, 30.0)
    decel = -np.diff(rec.speed[:, 0]) / world.config.dt
    assert rec.speed[-1, 0] == pytest.approx(10.0, abs=0.1)
    assert decel.max() < 1.5 * 1.1  # b, not IDM's huge free-road braking above v0


def test_emergency_braking_stops_followers_behind_a_leader_that_brakes_at_the_limit(
    world, built_map
):
    manager = make_manager(built_map, auto_lane_change=False)
    # five cars at 30 m/s, 6 m apart (0.2 s): far shorter than the IDM would keep
    x = -100.0 - np.arange(5) * (6.0 + 4.7)
    ids = spawn(world, manager, 1, -3, x, 30.0, desired_speed=30.0)
    manager.set_controller(int(ids[0]), lambda obs: EgoCommand(accel=-12.0))
    rec = run(world, manager, 12.0)
    assert rec.speed[-1].max() < 0.1
    assert rec.contacts == 0
    gaps = rec.x[:, :-1] - rec.x[:, 1:] - 4.7
    assert gaps.min() >= 1.0  # the emergency margin (the IDM alone comes within 0.8 m)
    assert manager.emergency_steps > 0


class HoldSpeed:
    """A controller that keeps its speed whatever is ahead (PI with saturation does so
    until the gap is under 6 m)."""

    def __init__(self, emergency_braking: bool):
        self.emergency_braking = emergency_braking

    def __call__(self, obs):
        return EgoCommand(accel=0.0)


@pytest.mark.parametrize("braking", [True, False])
def test_a_controller_that_asks_for_it_is_overridden_by_emergency_braking(
    world, built_map, braking
):
    manager = make_manager(built_map, auto_lane_change=False)
    ids = spawn(world, manager, -1, -3, [300.0, 0.0], [0.0, 25.0], desired_speed=[0.0, 30.0])
    manager.set_controller(int(ids[1]), HoldSpeed(braking))
    rec = run(world, manager, 20.0)
    if braking:
        assert rec.contacts == 0 and rec.speed[-1, 1] < 0.1
        assert manager.safety_overrides > 0
    else:  # the controller gets what it asks: it runs into the standing car
        assert rec.contacts > 0 and manager.safety_overrides == 0


def test_no_collision_between_managed_vehicles_whatever_the_ghosts_do(world, built_map):
    manager = make_manager(built_map, auto_lane_change=False)
    x = 200.0 - np.arange(6) * 30.0
    ids = spawn(world, manager, -1, -2, x, 28.0, desired_speed=30.0)
    rng = np.random.default_rng(4)

    def ghosts(t):
        # a ghost that jumps around just ahead of the platoon, stopped or fast
        if t < 1.0:
            return None
        lead = world.states().x[0]
        return Obstacles.make(
            -1, -2, lead + rng.uniform(5.0, 40.0), 4.7, rng.choice([0.0, 35.0]), -9.0
        )

    def boundary(states):
        # and the desired speeds jump as ghost speeds do at a window edge
        manager.set_desired_speed(ids, rng.choice([0.0, 5.0, 35.0], size=ids.size))

    rec = run(world, manager, 20.0, obstacles=ghosts, each_step=boundary)
    assert rec.contacts == 0
    gaps = rec.x[:, :-1] - rec.x[:, 1:] - world.params_of(ids[1:]).length
    assert gaps.min() > 0.5


def _behind_a_body_reaching_across(reach):
    """The command of a car in lane -4 at 12 m/s, 45 m behind a car standing in lane -3,
    off its centre and yawed 0.17 rad toward lane -4 (a change it gave up), its
    footprint reaching ``reach`` [m] past the line into lane -4; and of the same car
    beside one standing straight at its lane's centre."""
    manager, params = point_mass_manager(np.array([-3, -4]), 0)
    manager.add([0, 1], 1, [-3, -4], params, desired_speed=30.0)
    length, width = params.length[0], params.width[0]
    yaw = 0.17
    half = 0.5 * (length * np.sin(yaw) + width * np.cos(yaw))
    line = lane_center(-3) + 0.5 * LANE_WIDTH
    y = np.array([line + reach - half, lane_center(-4)])
    states = PointMasses(np.array([0, 1]), np.array([150.0, 100.0]), y, np.array([-3, -4]),
                         np.array([0.0, 12.0]), np.array([yaw, 0.0]))  # fmt: skip
    return float(manager.step(states).accel[1])


def test_a_body_reaching_into_a_lane_is_ahead_of_that_lanes_drivers():
    # physics, SUMO's on-ramp morning, episode 30: a ramp car gave up its merge and
    # stood at the taper's end yawed, its tail 0.8 m into lane -4; the bus behind in
    # lane -4 saw no one ahead and drove into it
    assert _behind_a_body_reaching_across(0.8) < -1.0  # brakes for it
    assert _behind_a_body_reaching_across(0.3) > 0.0  # short of FOOTPRINT_REACH: free road


def _passing_command(lane, speed, left_speed, gap=20.0, left=1, **settings):
    """The command of a car in ``lane`` at ``speed`` [m/s] (wanting 33 m/s, its own lane
    open), with a car at ``left_speed`` in the lane to its left (``left`` 0: in its own
    lane) ``gap`` [m] ahead of its front."""
    lanes = np.array([lane, lane + left])
    manager, params = point_mass_manager(lanes, 0, auto_lane_change=False, **settings)
    manager.add([0, 1], 1, lanes, params, desired_speed=33.0)
    x = np.array([100.0, 100.0 + params.length[0] + gap])
    states = PointMasses(np.array([0, 1]), x, lane_center(lanes), lanes,
                         np.array([speed, left_speed]), np.zeros(2))  # fmt: skip
    return float(manager.step(states).accel[0])


def test_a_driver_who_may_not_pass_on_the_right_follows_the_slower_car_on_its_left():
    rule = dict(no_pass_right_from=60 / 3.6)
    assert _passing_command(-3, 30.0, 25.0) > 0.0  # by default it passes
    assert _passing_command(-3, 30.0, 25.0, **rule) < -0.5  # brakes to keep behind it
    assert _passing_command(-4, 30.0, 25.0, **rule) < -0.5
    # as if that car were its own lane's leader, braking no harder than cooperative_decel
    far = _passing_command(-3, 30.0, 25.0, gap=90.0, left=0)
    assert -1.5 < far < 0.0
    assert _passing_command(-3, 30.0, 25.0, gap=90.0, **rule) == far
    assert _passing_command(-3, 30.0, 25.0, **rule) == -1.5
    assert _passing_command(-3, 14.0, 10.0, **rule) > 0.0  # congested: passes
    assert _passing_command(-3, 30.0, 31.0, **rule) > 0.0  # not slower: its own road
    assert _passing_command(-2, 30.0, 25.0, **rule) > 0.0  # the HOV lane is passed


@pytest.mark.parametrize("speed", [float("nan"), -1.0])
def test_a_speed_from_which_not_to_pass_must_be_one(speed):
    with pytest.raises(ValueError, match="no_pass_right_from"):
        TrafficConfig(no_pass_right_from=speed)


def test_not_passing_on_the_right_keeps_a_driver_behind_the_left_lanes_car(world, built_map):
    manager = make_manager(built_map, auto_lane_change=False, no_pass_right_from=60 / 3.6)
    ids = spawn(world, manager, 1, [-2, -3], [-200.0, -240.0], [25.0, 30.0],
                desired_speed=[25.0, 33.0])  # fmt: skip
    rec = run(world, manager, 30.0)
    length = world.params_of(ids).length[1]
    ahead_of_front = rec.x[:, 0] - rec.x[:, 1] - length
    assert ahead_of_front.min() > 2.0  # never drew level
    assert rec.speed[-1, 1] == pytest.approx(25.0, abs=0.5)  # at the left car's speed
    assert rec.contacts == 0
