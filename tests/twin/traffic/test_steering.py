"""The lateral controller on the physics world and the kinematic world (10 Hz): lane
keeping and lane-change paths."""

import numpy as np
import pytest

from tests.twin.traffic.conftest import make_manager, run, spawn
from twin.core.i24 import LANE_WIDTH, lane_center
from twin.physics.kinematic import KinematicWorld
from twin.traffic.kernels.steering import path_shape, stanley


def test_stanley_steers_toward_the_path():
    def steer(error, heading_error=0.0, curvature=0.0):
        return stanley(error, heading_error, 25.0, curvature, 2.7, 1.0, 0.5)

    assert steer(1.0) > 0 > steer(-1.0)  # right of the path (positive y): steer left
    assert steer(0.0) == 0.0
    assert steer(0.0, heading_error=0.1) == pytest.approx(-0.1)  # yawed left: undo it
    # on a left-turning path the steer is the kinematic bicycle's, atan(L kappa)
    assert steer(0.0, curvature=0.01) == pytest.approx(np.arctan(0.027))


def test_stanley_turns_a_yawed_body_back_beyond_the_lateral_limit():
    """The lateral-acceleration limit bounds how hard a body is steered toward its
    path, not how far a yawed body is turned back: a body braking hard at 48 m/s
    (limit 0.005 rad) that yawed 0.05 rad off its path is steered back by that much;
    clamped to the limit it went on yawing and left the road (physics world)."""
    limit = np.arctan(2.8 * 4.0 / 48.0**2)

    def steer(error, heading_error):
        return stanley(error, heading_error, 48.0, 0.0, 2.8, 1.0, limit)

    assert steer(0.0, 0.05) == pytest.approx(-0.05)
    assert steer(0.0, -0.05) == pytest.approx(0.05)
    assert steer(2.0, 0.0) == pytest.approx(limit)  # toward the path: within the limit
    assert steer(-2.0, 0.0) == pytest.approx(-limit)
    assert abs(steer(0.0, 2.0)) == pytest.approx(0.5)  # never beyond MAX_STEER


def test_lane_change_path_is_a_smooth_blend_with_consistent_derivatives():
    x = np.linspace(-10.0, 110.0, 12001)
    y, slope, bend = np.array([path_shape(xi, 0.0, 1.0, 4.0, 100.0) for xi in x]).T
    assert y[0] == 1.0 and y[-1] == 4.0 and y[6000] == pytest.approx(2.5)
    assert np.all(np.diff(y) >= 0)
    h = x[1] - x[0]
    assert np.allclose(np.gradient(y, h)[5:-5], slope[5:-5], atol=1e-3)
    assert np.allclose(np.gradient(slope, h)[5:-5], bend[5:-5], atol=1e-3)
    assert slope[0] == slope[-1] == 0.0


@pytest.mark.parametrize("road", [1, -1])
def test_lane_keeping_settles_within_015_m_without_oscillation(world, built_map, road):
    manager = make_manager(built_map, auto_lane_change=False)
    speeds = np.array([5.0, 15.0, 25.0, 35.0])
    lanes = np.array([-1, -2, -3, -4])
    offsets = np.array([0.8, -0.8, 0.8, -0.8])  # [m] off the lane centre at spawn
    spawn(
        world,
        manager,
        road,
        lanes,
        -380.0,
        speeds,
        y=lane_center(lanes) + offsets,
        desired_speed=speeds,
    )
    rec = run(world, manager, 40.0)
    error = rec.y - lane_center(lanes)
    steady = error[1000:]  # after 10 s
    assert np.abs(steady).max() <= 0.15
    assert np.abs(error[-500:]).max() <= 0.02
    # no oscillation: the error crosses zero at most once and overshoots little
    for k in range(lanes.size):
        e = error[:, k] * np.sign(offsets[k])
        overshoot = -e.min()
        assert overshoot < 0.1, (k, overshoot)
        crossings = np.count_nonzero(np.diff(np.sign(e[np.abs(e) > 0.01])) != 0)
        assert crossings <= 1, (k, crossings)


def test_forced_lane_change_is_a_smooth_manoeuvre_of_seconds(world, built_map):
    manager = make_manager(built_map, auto_lane_change=False)
    (vehicle,) = spawn(world, manager, 1, -3, -300.0, 25.0, desired_speed=25.0)
    run(world, manager, 2.0)
    manager.force_lane_change(int(vehicle), "right")
    rec = run(world, manager, 12.0)
    y = rec.y[:, 0]
    assert rec.lane[-1, 0] == -4 and not rec.changing[-1, 0]
    assert y[-1] == pytest.approx(lane_center(-4), abs=0.05)
    lateral_speed = np.abs(np.diff(y)) / world.config.dt
    assert lateral_speed.max() < 2.0  # no teleport: a lane (3.66 m) takes seconds
    moving = np.flatnonzero(np.abs(y - lane_center(-3)) > 0.05)
    arrived = np.flatnonzero(np.abs(y - lane_center(-4)) < 0.15)
    duration = (arrived[0] - moving[0]) * world.config.dt
    assert 2.5 < duration < 7.0
    assert y.max() < lane_center(-4) + 0.15  # overshoot well inside the lane
    assert np.all(np.diff(y[moving[0] : arrived[0]]) > -1e-3)  # one way across
    assert abs(y[-1] - y[0]) == pytest.approx(LANE_WIDTH, abs=0.05)


@pytest.fixture
def kinematic(built_map):
    with KinematicWorld(built_map, 0.1) as world:
        yield world


@pytest.mark.parametrize("road", [1, -1])
def test_lane_keeping_at_10_hz_in_the_kinematic_world_settles_short_vehicles_too(
    kinematic, built_map, road
):
    """At 10 Hz a 2.2 m vehicle at 35 m/s moves v dt / L = 2.3 wheelbases a step, where
    Stanley alone would swing from side to side; the per-step limit settles it."""
    manager = make_manager(built_map, auto_lane_change=False, dt=0.1)
    speeds = np.array([5.0, 35.0, 25.0, 35.0])
    lanes = np.array([-1, -2, -3, -4])
    classes = np.array([0, 6, 0, 0])  # class 6: the shortest wheelbase (1.5 m)
    offsets = np.array([0.8, -0.8, 0.8, -0.8])
    spawn(kinematic, manager, road, lanes, -380.0 if road < 0 else 300.0, speeds, classes,
          y=lane_center(lanes) + offsets, desired_speed=speeds)  # fmt: skip
    rec = run(kinematic, manager, 40.0)
    error = rec.y - lane_center(lanes)
    assert np.abs(error[100:]).max() <= 0.15  # after 10 s
    assert np.abs(error[-50:]).max() <= 0.02
    for k in range(lanes.size):
        e = error[:, k] * np.sign(offsets[k])
        assert -e.min() < 0.1, k
        assert np.count_nonzero(np.diff(np.sign(e[np.abs(e) > 0.01])) != 0) <= 1, k


def test_a_lane_change_in_the_kinematic_world_follows_the_same_path(kinematic, built_map):
    manager = make_manager(built_map, auto_lane_change=False, dt=0.1)
    (vehicle,) = spawn(kinematic, manager, 1, -3, 300.0, 25.0, desired_speed=25.0)
    run(kinematic, manager, 2.0)
    manager.force_lane_change(int(vehicle), "right")
    rec = run(kinematic, manager, 12.0)
    y = rec.y[:, 0]
    assert rec.lane[-1, 0] == -4 and not rec.changing[-1, 0]
    assert y[-1] == pytest.approx(lane_center(-4), abs=0.05)
    moving = np.flatnonzero(np.abs(y - lane_center(-3)) > 0.05)
    arrived = np.flatnonzero(np.abs(y - lane_center(-4)) < 0.15)
    assert 2.5 < (arrived[0] - moving[0]) * kinematic.dt < 7.0
    assert y.max() < lane_center(-4) + 0.15
    assert np.all(np.diff(y[moving[0] : arrived[0]]) > -1e-3)
