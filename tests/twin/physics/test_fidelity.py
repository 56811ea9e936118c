"""Physics fidelity against analytic oracles: spawn speed, braking, coasting, cornering."""

import numpy as np
import pytest

from twin.core.i24 import LANE_WIDTH, VEHICLE_CLASSES
from twin.core.vehicle_classes import vehicle_classes
from twin.physics.states import SpawnStates
from twin.physics.vehicle import AIR_DENSITY, GRAVITY
from twin.physics.world import PhysicsWorld

LANE_2 = 2.5 * LANE_WIDTH  # [m] centre of lane -2


@pytest.fixture(scope="module")
def world(built_map):
    with PhysicsWorld(built_map) as world:
        yield world


def spawn(world, road, x, speed, classes, y=LANE_2):
    table = vehicle_classes()
    classes = np.atleast_1d(classes)
    n = classes.size
    return world.spawn(
        SpawnStates.make(
            road,
            np.broadcast_to(x, (n,)),
            y,
            np.broadcast_to(speed, (n,)),
            classes,
            table.column("length_m")[classes],
            table.column("width_m")[classes],
            table.column("height_m")[classes],
        )
    )


def run(world, seconds):
    for _ in range(round(seconds / world.config.dt)):
        world.step()


@pytest.mark.parametrize("road", ["eastbound", "westbound"])  # uphill and downhill
def test_spawn_speed_is_exact_one_step_after_spawn_and_after_holding(world, road):
    speeds = np.array([0.0, 5.0, 13.4, 25.0, 33.0, 40.0])
    classes = np.arange(len(VEHICLE_CLASSES))
    speed, cls = (a.ravel() for a in np.meshgrid(speeds, classes))
    # all at once, in the four lanes, 80 m apart (no two meet within the test)
    slot = np.arange(speed.size)
    x = -350.0 + 80.0 * (slot // 4)
    ids = spawn(world, road, x, speed, cls, y=(1.5 + slot % 4) * LANE_WIDTH)
    # before the impulse's step the state already tells the spawn speed (drivers see it)
    assert world.states().speed == pytest.approx(speed, abs=1e-9)
    world.set_controls(ids, accel=np.zeros(ids.size))
    world.step()
    error = np.abs(world.states().speed - speed) / np.maximum(speed, 1.0)
    assert error.max() <= 0.005, (speed[error.argmax()], VEHICLE_CLASSES[cls[error.argmax()]])
    run(world, 1.0)
    state = world.states()
    error = np.abs(state.speed - speed) / np.maximum(speed, 1.0)
    assert error.max() <= 0.005, (speed[error.argmax()], VEHICLE_CLASSES[cls[error.argmax()]])
    assert state.contact.all()
    world.despawn(ids)


@pytest.mark.parametrize("road", ["eastbound", "westbound"])
@pytest.mark.parametrize("vehicle_class", [0, 4])  # a sedan and a loaded semi
def test_full_brake_stopping_distance(world, road, vehicle_class):
    (vid,) = spawn(world, road, -200.0, 30.0, vehicle_class)
    world.step()  # the spawn impulse
    start = world.states().x[0]
    world.set_controls([vid], drive=[0.0], brake=[1.0])
    for _ in range(1500):
        world.step()
        if world.states().speed[0] < 0.01:
            break
    distance = world.states().x[0] - start
    mu = vehicle_classes().column("tyre_friction")[vehicle_class]
    assert distance == pytest.approx(30.0**2 / (2 * mu * GRAVITY), rel=0.05)
    world.despawn([vid])


@pytest.mark.parametrize("road", ["eastbound", "westbound"])
def test_coasting_deceleration_matches_grade_rolling_and_drag(world, road):
    (vid,) = spawn(world, road, 0.0, 28.0, 0)
    world.step()
    world.set_controls([vid], drive=[0.0], brake=[0.0])
    run(world, 0.5)  # settle
    v0 = world.states().speed[0]
    run(world, 2.0)
    v1 = world.states().speed[0]
    measured = (v0 - v1) / 2.0
    params = world.params
    mean = 0.5 * (v0 + v1)
    theta = np.arctan(0.01111856) * (1 if road == "eastbound" else -1)  # the 1.112 % grade
    expected = (
        GRAVITY * np.sin(theta)
        + params.rolling[0] * GRAVITY * np.cos(theta)
        + 0.5 * AIR_DENSITY * params.drag_area[0] * mean**2 / params.mass[0]
    )
    assert measured == pytest.approx(expected, rel=0.05)
    world.despawn([vid])


@pytest.mark.parametrize("steer", [0.005, -0.01, 0.02])
def test_steady_cornering_yaw_rate_matches_the_bicycle_model(world, steer):
    (vid,) = spawn(world, "eastbound", -300.0, 20.0, 0, y=3.5 * LANE_WIDTH)
    world.step()
    world.set_controls([vid], accel=[0.0], steer=[steer])
    run(world, 3.0)
    state = world.states()
    params = world.params
    v = state.speed[0]
    wheelbase = 2.0 * params.mounts[0, 0, 0]
    half = wheelbase / 2.0
    front, rear = state.load[0, :2].sum(), state.load[0, 2:].sum()
    c_front, c_rear = params.cornering[0] * front, params.cornering[0] * rear
    understeer = params.mass[0] / wheelbase * (half / c_front - half / c_rear)
    expected = v * steer / (wheelbase + understeer * v**2)
    assert state.yaw_rate[0] == pytest.approx(expected, rel=0.10)
    world.despawn([vid])


@pytest.mark.parametrize("steer", [0.0, 0.3])
def test_a_crawling_car_steering_back_to_its_lane_slows_as_commanded(world, steer):
    # spawned at 0.75 m/s 0.7 m off its lane's centre (a sub-lane driver's place), it
    # steers hard back while braking gently: the steered tyres' cornering force pulls
    # against travel, which the feedforward makes up (before: -1.60 m/s^2 for -0.92,
    # a spawn 0.7 % off after 10 ms)
    (vid,) = spawn(world, "westbound", -47.7, 0.75, 0, y=LANE_2 + 0.7)
    world.set_controls([vid], accel=[-0.92], steer=[steer])
    world.step()
    expected = 0.75 - 0.92 * world.config.dt
    assert abs(world.states().speed[0] - expected) <= 0.005 * 1.0  # the spawn check's bound
    world.despawn([vid])
