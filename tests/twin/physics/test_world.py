"""The physics world: spawn, despawn and the body pool, controls, outputs, stability."""

import resource

import numpy as np
import pytest

from twin.core.i24 import LANE_WIDTH, SEGMENT_LENGTH
from twin.core.vehicle_classes import vehicle_classes
from twin.physics.states import SpawnStates
from twin.physics.world import PhysicsConfig, PhysicsWorld


@pytest.fixture
def world(built_map):
    with PhysicsWorld(built_map) as world:
        yield world


def sedans(n, road="eastbound", x=0.0, speed=25.0, y=2.5 * LANE_WIDTH):
    return SpawnStates.make(road, np.broadcast_to(x, (n,)), y, speed, 0, 4.7, 1.83, 1.45)


def test_outputs_in_the_road_frame(world):
    ids = world.spawn(sedans(1, "westbound", x=300.0, speed=20.0))
    world.step()
    state = world.states()
    assert state.id.tolist() == ids.tolist()
    assert state.road[0] == -1 and state.lane[0] == -2
    assert state.x[0] == pytest.approx(300.0 + 20.0 * 0.01, abs=0.02)  # back centre, as the data
    assert state.y[0] == pytest.approx(2.5 * LANE_WIDTH, abs=0.01)
    assert state.speed[0] == pytest.approx(20.0, rel=1e-3)
    heading = world.road.heading("westbound")
    assert np.cos(state.heading[0] - heading) == pytest.approx(1.0, abs=1e-6)
    assert state.position.shape == (1, 3) and state.orientation.shape == (1, 4)
    assert state.contact.all()


def test_bodies_are_recycled_and_ids_never_reused(world):
    first = world.spawn(sedans(5, x=np.arange(5) * 30.0))
    world.step()
    bodies = world.body_count
    world.despawn(first[:3])
    second = world.spawn(sedans(3, x=200.0 + np.arange(3) * 30.0))
    assert world.body_count == bodies  # the three freed bodies were reused
    assert not set(first) & set(second)
    assert world.ids.tolist() == [*first[3:], *second]
    with pytest.raises(KeyError, match="not an active vehicle"):
        world.despawn(first[:1])
    world.step()
    assert np.all(np.isfinite(world.states().position))


def test_empty_world_steps_and_reports_nothing(world):
    world.step()
    state = world.states()
    assert state.id.size == 0 and state.position.shape == (0, 3) and state.load.shape == (0, 4)


def test_wheel_loads_follow_their_vehicles_through_despawn_and_spawn(world):
    light, heavy = world.spawn(sedans(2, x=[0.0, 100.0]))
    world.step()
    world.despawn([light])
    truck = world.spawn(SpawnStates.make("eastbound", [300.0], 9.0, 25.0, 4, 20.5, 2.59, 4.0))
    state = world.states()
    assert state.id.tolist() == [heavy, truck[0]]
    assert state.load[0].sum() > 1000.0  # the remaining sedan keeps its loads
    assert not state.contact[1].any()  # the new truck has no contact before its first step
    world.step()
    assert world.states().load[1].sum() > 20 * world.states().load[0].sum() / 2


def test_bad_spawns_and_controls_are_refused(world):
    with pytest.raises(ValueError, match="beyond the map"):
        world.spawn(sedans(1, x=5000.0))
    with pytest.raises(ValueError, match="non-finite"):
        world.spawn(sedans(1, speed=float("nan")))
    with pytest.raises(ValueError, match="speeds must be in"):
        world.spawn(sedans(1, speed=-3.0))
    with pytest.raises(ValueError, match="positive and finite"):
        world.spawn(SpawnStates.make("eastbound", [0.0], 5.0, 20.0, 0, 0.0, 1.8, 1.4))
    with pytest.raises(ValueError, match="vehicle classes"):
        world.spawn(SpawnStates.make("eastbound", [0.0], 5.0, 20.0, 9, 4.0, 1.8, 1.4))
    ids = world.spawn(sedans(1))
    with pytest.raises(ValueError, match="brake must be in"):
        world.set_controls(ids, brake=[2.0])
    with pytest.raises(ValueError, match="steer"):
        world.set_controls(ids, steer=[1.5])
    with pytest.raises(ValueError, match="dt must be"):
        PhysicsConfig(dt=0.5)


def test_same_inputs_same_trajectories(built_map):
    def simulate():
        with PhysicsWorld(built_map) as world:
            ids = world.spawn(sedans(6, x=np.arange(6) * 25.0, speed=np.linspace(15, 35, 6)))
            world.set_controls(ids, accel=np.linspace(-1, 1, 6), steer=np.linspace(-0.01, 0.01, 6))
            for _ in range(200):
                world.step()
            return world.states().position

    np.testing.assert_array_equal(simulate(), simulate())


def test_gravity_not_a_written_speed_slows_a_coasting_car_uphill(world):
    uphill, downhill = (
        world.spawn(sedans(1, road, x=0.0, speed=20.0))[0] for road in ("eastbound", "westbound")
    )
    world.set_controls([uphill, downhill], drive=[0.0, 0.0], brake=[0.0, 0.0])
    for _ in range(300):
        world.step()
    speed = dict(zip(world.ids.tolist(), world.states().speed, strict=True))
    assert speed[uphill] < speed[downhill] - 0.5


def test_acceleration_commands_are_tracked(world):
    ids = world.spawn(sedans(3, x=[0.0, 60.0, 120.0], speed=20.0, y=[5.5, 9.1, 12.8]))
    world.step()
    world.set_controls(ids, accel=[-2.0, 0.0, 1.0])
    before = world.states().speed
    for _ in range(200):
        world.step()
    gained = (world.states().speed - before) / 2.0
    np.testing.assert_allclose(gained, [-2.0, 0.0, 1.0], atol=0.05)


def lane_keeping_steer(state, lanes, road_heading):
    """A proportional-derivative lane keeper (the traffic manager's job; here for tests)."""
    heading_error = np.angle(np.exp(1j * (state.heading - road_heading)))
    steer = 0.03 * (state.y - lanes) - 0.6 * heading_error
    return np.clip(steer, -0.1, 0.1)


@pytest.mark.slow
def test_stability_200_vehicles_60_seconds(built_map):
    rng = np.random.default_rng(3)
    n = 200
    road = np.where(np.arange(n) % 2 == 0, 1, -1)
    lane = (np.arange(n) // 2) % 4
    lanes = (1.5 + lane) * LANE_WIDTH
    per_lane = n // 8
    slot = np.arange(n) // 8
    x = -380.0 + slot * (2300.0 / per_lane)
    speed = np.array([20.0, 26.0, 33.0, 40.0])[lane]  # one speed per lane: no rear-ending
    # heavy trucks only in the 20 and 26 m/s lanes: they lack the power for 40 m/s uphill
    cars = np.array([0, 1, 2, 3, 6])
    classes = np.where(lane < 2, rng.integers(0, 7, n), cars[rng.integers(0, 5, n)])
    table = vehicle_classes()
    sizes = [table.column(c)[classes] for c in ("length_m", "width_m", "height_m")]
    with PhysicsWorld(built_map) as world:
        ids = world.spawn(SpawnStates.make(road, x, lanes, speed, classes, *sizes))
        info = {
            int(i): (int(r), float(y), float(v), int(c))
            for i, r, y, v, c in zip(ids, road, lanes, speed, classes, strict=True)
        }
        world.set_controls(ids, accel=np.zeros(n))
        respawned = 0
        for step in range(6000):
            state = world.states()
            headings = np.where(
                state.road > 0, world.road.heading("eastbound"), world.road.heading("westbound")
            )
            lane_y = np.array([info[int(i)][1] for i in state.id])
            world.set_controls(state.id, steer=lane_keeping_steer(state, lane_y, headings))
            world.step()
            if step % 10:
                continue
            state = world.states()
            assert np.all(np.isfinite(state.position)) and np.all(np.isfinite(state.velocity))
            up = _up_axis(state.orientation)
            assert up[:, 2].min() > 0.95, "a vehicle tipped"
            coords = world.road.to_road(state.position)
            assert np.nanmin(coords.height) > 0.2, "a vehicle sank below the road"
            assert state.contact.all(), "a wheel lost the road"
            assert np.abs(state.y - lane_y).max() < 1.0
            # vehicles reaching the map's end go back to its start (exercising the pool)
            done = state.x > SEGMENT_LENGTH + 380.0
            for vid in state.id[done]:
                r, y, v, c = info.pop(int(vid))
                world.despawn([vid])
                new = world.spawn(
                    SpawnStates.make(
                        r,
                        [-390.0],
                        y,
                        v,
                        c,
                        *(
                            s[c]
                            for s in (
                                table.column("length_m"),
                                table.column("width_m"),
                                table.column("height_m"),
                            )
                        ),
                    )
                )
                world.set_controls(new, accel=[0.0])
                info[int(new[0])] = (r, y, v, c)
                respawned += 1
        assert respawned > 100
        state = world.states()
        wanted = np.array([info[int(i)][2] for i in state.id])
        assert np.abs(state.speed - wanted).max() < 0.5  # nobody crashed or stalled
        assert world.body_count <= n + 30


def _up_axis(q):
    x, y, z, w = q.T
    return np.stack([2 * (x * z + y * w), 2 * (y * z - x * w), 1 - 2 * (x * x + y * y)], axis=1)


def _rss_mb() -> float:
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


@pytest.mark.slow
def test_memory_flat_over_20000_spawn_despawn_cycles(built_map):
    rng = np.random.default_rng(0)
    table = vehicle_classes()
    with PhysicsWorld(built_map) as world:

        def cycle(k):
            c = int(k % 7)
            ids = world.spawn(
                SpawnStates.make(
                    "eastbound",
                    [rng.uniform(0, 1500)],
                    9.0,
                    25.0,
                    c,
                    table.column("length_m")[c],
                    table.column("width_m")[c],
                    table.column("height_m")[c],
                )
            )
            if k % 100 == 0:
                world.step()
            world.despawn(ids)

        for k in range(500):  # warm the pool and the allocator
            cycle(k)
        before = _rss_mb()
        for k in range(20_000):
            cycle(k)
        growth = _rss_mb() - before
        assert growth <= 20.0, f"resident memory grew {growth:.1f} MB"
        assert world.body_count <= 7
