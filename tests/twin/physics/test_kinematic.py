"""The kinematic world: the World interface, the point mass against its own analytic
limits, the bicycle's geometry, footprint collisions, and agreement with the physics
world under the same commands."""

import inspect

import numpy as np
import pytest

from twin.core.i24 import lane_center
from twin.core.vehicle_classes import vehicle_classes
from twin.physics.kernels import footprints_overlap
from twin.physics.kinematic import KinematicWorld
from twin.physics.states import SpawnStates
from twin.physics.vehicle import GRAVITY, POWER_SPEED_MIN, resistance
from twin.physics.world import PhysicsWorld
from twin.physics.worlds import DEFAULT_DT, World, check_world, make_world

SEDAN = 0


def sizes(vehicle_class):
    table = vehicle_classes()
    k = np.atleast_1d(vehicle_class)
    return [table.column(c)[k] for c in ("length_m", "width_m", "height_m")]


def spawn(world, x, speed, lane=-2, vehicle_class=SEDAN, road=1, y=None):
    x = np.atleast_1d(np.asarray(x, dtype=float))
    k = np.full(x.size, vehicle_class)
    y = lane_center(lane) if y is None else y
    return world.spawn(SpawnStates.make(road, x, y, speed, k, *sizes(k)))


@pytest.fixture
def kinematic(built_map):
    with KinematicWorld(built_map, 0.1) as world:
        yield world


def test_both_worlds_offer_every_member_of_the_interface(built_map):
    members = [name for name, _ in inspect.getmembers(World) if not name.startswith("_")] + list(
        World.__annotations__
    )
    assert {"spawn", "despawn", "set_controls", "step", "states", "vehicle_contacts"} <= set(
        members
    )
    for world in (make_world("kinematic", built_map, 0.1), make_world("physics", built_map, 0.01)):
        with world:
            for name in members:
                assert hasattr(world, name), (type(world).__name__, name)


def test_unknown_worlds_and_steps_out_of_range_are_refused():
    assert DEFAULT_DT == {"physics": 0.01, "kinematic": 0.1}
    with pytest.raises(ValueError, match="world must be one of physics, kinematic"):
        check_world("mujoco", 0.1)
    with pytest.raises(ValueError, match=r"kinematic world's dt must be in \(0, 0.1\]"):
        check_world("kinematic", 0.2)
    with pytest.raises(ValueError, match="dt must be in"):
        check_world("physics", 0.1)  # pybullet's vehicle model needs <= 0.02 s


def test_a_commanded_acceleration_is_tracked_exactly_within_the_limits(kinematic):
    ids = spawn(kinematic, [300.0, 400.0], [20.0, 20.0])
    kinematic.set_controls(ids, accel=[1.0, -2.0], steer=[0.0, 0.0])
    x0 = kinematic.states().x.copy()
    for _ in range(20):
        kinematic.step()
    s = kinematic.states()
    np.testing.assert_allclose(s.speed, [22.0, 16.0], atol=1e-9)
    # the point mass moves as v t + a t^2 / 2 (the grade is fed forward, as in physics)
    np.testing.assert_allclose(s.x - x0, [20 * 2 + 0.5 * 1 * 4, 20 * 2 - 0.5 * 2 * 4], atol=1e-6)
    np.testing.assert_allclose(s.y, lane_center(-2), atol=1e-12)
    assert np.all(s.drive_power[0] > 0) and s.drive_power[1] == 0.0


def test_the_engine_power_limits_acceleration_at_speed(kinematic):
    ids = spawn(kinematic, 300.0, 30.0)
    s0 = kinematic.states()
    p = kinematic.params
    # the map's pitch at the spawn pose, as the step saw it
    _, _, pitch = kinematic.road.to_world(s0.road, s0.x + 0.5 * p.length, s0.y)
    kinematic.set_controls(ids, accel=[5.0], steer=[0.0])
    kinematic.step()
    power_limited = p.max_power / max(30.0, POWER_SPEED_MIN) - resistance(p, 30.0, np.sin(pitch))
    expected = power_limited / p.effective_mass
    assert kinematic.states().speed[0] == pytest.approx(30.0 + 0.1 * expected[0], rel=1e-9)
    assert expected[0] < 5.0
    assert kinematic.states().drive_power[0] == pytest.approx(p.max_power[0], rel=1e-9)


def test_braking_stops_a_vehicle_where_it_stops_and_holds_it(kinematic):
    ids = spawn(kinematic, 300.0, 0.3)  # stops 0.075 s into the 0.1 s step
    kinematic.set_controls(ids, accel=[-4.0], steer=[0.0])
    x0 = kinematic.states().x[0]
    kinematic.step()
    s = kinematic.states()
    assert s.speed[0] == 0.0
    assert s.x[0] - x0 == pytest.approx(0.3**2 / (2 * 4.0), rel=1e-9)  # not v dt / 2
    for _ in range(30):
        kinematic.step()
    assert kinematic.states().speed[0] == 0.0 and kinematic.states().x[0] == s.x[0]


def test_braking_is_limited_by_the_tyres_grip(kinematic):
    ids = spawn(kinematic, 300.0, 30.0)
    kinematic.set_controls(ids, accel=[-30.0], steer=[0.0])
    kinematic.step()
    mu = kinematic.params.mu[0]
    decel = (30.0 - kinematic.states().speed[0]) / 0.1
    assert mu * GRAVITY * 0.9 < decel < mu * GRAVITY * 1.1  # grip, give or take the grade


def test_a_steered_vehicle_turns_as_a_kinematic_bicycle(kinematic):
    ids = spawn(kinematic, 300.0, 10.0)
    kinematic.set_controls(ids, accel=[0.0], steer=[0.1])
    kinematic.step()
    p = kinematic.params
    wheelbase = p.mounts[0, 0, 0] - p.mounts[0, 2, 0]
    slip = np.arctan(0.5 * np.tan(0.1))
    s = kinematic.states()
    assert s.yaw_rate[0] == pytest.approx(10.0 * np.cos(slip) * np.tan(0.1) / wheelbase)
    assert s.y[0] < lane_center(-2)  # a left turn moves toward the median (y shrinks)
    heading = kinematic.road.heading(1)
    assert s.heading[0] == pytest.approx(heading + s.yaw_rate[0] * 0.1)


def test_states_put_vehicles_on_the_pavement_in_the_physics_worlds_frame(built_map, kinematic):
    with PhysicsWorld(built_map) as physics:
        for world in (kinematic, physics):
            spawn(world, [200.0, 900.0], 20.0, road=1)
            spawn(world, [500.0], 20.0, road=-1, lane=-3)
        a, b = kinematic.states(), physics.states()
        np.testing.assert_allclose(a.x, b.x, atol=0.05)
        np.testing.assert_allclose(a.y, b.y, atol=0.05)
        np.testing.assert_array_equal(a.lane, b.lane)
        np.testing.assert_allclose(a.heading, b.heading, atol=1e-3)
        np.testing.assert_allclose(a.position, b.position, atol=0.05)
        np.testing.assert_allclose(a.velocity, b.velocity, atol=0.05)


def test_overlapping_footprints_are_contacts_and_touching_ones_only_then(kinematic):
    length = sizes(SEDAN)[0][0]
    a = spawn(kinematic, [300.0, 300.0 + length - 0.1, 320.0], 10.0)  # first two overlap
    b = spawn(kinematic, 300.0, 10.0, lane=-3)  # beside the first, a lane over
    assert kinematic.vehicle_contacts().tolist() == [[a[0], a[1]]]
    kinematic.despawn(a[1])
    assert kinematic.vehicle_contacts().shape == (0, 2)
    del b


def test_footprints_turned_against_each_other_by_the_separating_axes(kinematic):
    def overlap(x, y, yaw):  # two 4 m x 2 m footprints: centres, yaws
        return footprints_overlap(0.0, 0.0, 0.0, 2.0, 1.0, x, y, yaw, 2.0, 1.0)

    # side by side 2.3 m apart: apart when straight; the second turned 0.5 rad reaches over
    assert not overlap(0.0, 2.3, 0.0)
    assert overlap(0.0, 2.3, 0.5)
    # corner to corner along a diagonal: bounding boxes overlap, footprints do not
    assert not overlap(3.9, 2.6, 0.6)
    # the other road never touches
    spawn(kinematic, 300.0, 10.0, road=1, y=5.0)
    spawn(kinematic, 300.0, 10.0, road=-1, y=5.0)
    assert kinematic.vehicle_contacts().shape == (0, 2)


def test_the_same_commands_give_the_same_motion_in_both_worlds(built_map):
    """An acceleration profile (speed up, cruise, brake hard, speed up), fed open-loop
    to both worlds: speeds and positions agree (steering in closed loop is
    tests/twin/traffic/test_steering.py's)."""
    profile = np.concatenate([np.full(30, 1.0), np.zeros(20), np.full(20, -3.0), np.full(30, 1.2)])
    records = {}
    for kind in ("kinematic", "physics"):
        with make_world(kind, built_map, DEFAULT_DT[kind]) as world:
            ids = spawn(world, 300.0, 20.0, vehicle_class=[0][0])
            per_step = round(0.1 / world.dt)
            rows = []
            for a in profile:
                world.set_controls(ids, accel=[a], steer=[0.0])
                for _ in range(per_step):
                    world.step()
                s = world.states()
                rows.append((s.speed[0], s.x[0]))
            records[kind] = np.array(rows)
    k, p = records["kinematic"], records["physics"]
    speed_rmse = np.sqrt(np.mean((k[:, 0] - p[:, 0]) ** 2))
    assert speed_rmse < 0.3, speed_rmse
    assert abs(k[-1, 1] - p[-1, 1]) < 3.0


def test_raw_drive_and_brake_act_as_in_the_physics_world(kinematic):
    ids = spawn(kinematic, [300.0, 400.0], [20.0, 20.0])
    kinematic.set_controls(ids, drive=[1.0, 0.0], brake=[0.0, 1.0], steer=[0.0, 0.0])
    kinematic.step()
    s, p = kinematic.states(), kinematic.params
    # full drive: the engine's power at this speed, or the driven wheels' grip (a sedan's
    # front axle holds half its weight: 6.6 kN, under 140 kW / 20 m/s = 7 kN)
    grip = p.mu[0] * p.mass[0] * GRAVITY * np.cos(kinematic.pitch()[0]) / 2
    assert s.drive_power[0] == pytest.approx(min(p.max_power[0], 20.0 * grip), rel=1e-3)
    # full brake: the tyres' grip, mu g, give or take the grade
    decel = (20.0 - s.speed[1]) / 0.1
    assert p.mu[1] * GRAVITY * 0.9 < decel < p.mu[1] * GRAVITY * 1.1
    with pytest.raises(ValueError, match=r"drive must be in 0\.\.1"):
        kinematic.set_controls(ids, drive=[2.0, 0.0])


def test_a_vehicle_at_rest_is_held_on_the_grade_and_never_rolls_back(kinematic):
    ids = spawn(kinematic, np.linspace(100.0, 1400.0, 14), 0.0)
    pitch = kinematic.pitch()
    assert np.abs(pitch).max() > 0.005  # the profile has grades here
    kinematic.set_controls(ids, accel=np.zeros(ids.size), steer=np.zeros(ids.size))
    x0 = kinematic.states().x.copy()
    for _ in range(20):
        kinematic.step()
    assert np.all(kinematic.states().speed == 0.0)
    np.testing.assert_array_equal(kinematic.states().x, x0)
    kinematic.set_controls(ids, accel=np.full(ids.size, 0.01))  # too little for an upgrade
    kinematic.step()
    assert np.all(kinematic.states().speed >= 0.0)
