"""The traffic manager's API: adding and removing vehicles, settings, overrides, the
ego controller hook, validation, determinism."""

import numpy as np
import pytest

from tests.twin.traffic.conftest import PointMasses, make_manager, point_mass_manager, run, spawn
from twin.core.errors import ControllerError
from twin.core.i24 import lane_center
from twin.traffic.config import TrafficConfig
from twin.traffic.controller_api import EgoCommand
from twin.traffic.scene import Obstacles


def point_states(ids, x, lane, speed):
    lane = np.asarray(lane)
    return PointMasses(
        np.asarray(ids),
        np.asarray(x, float),
        lane_center(lane),
        lane,
        np.asarray(speed, float),
        np.zeros(len(ids)),
    )


def test_the_ego_controller_sees_leaders_and_followers_per_lane():
    manager, params = point_mass_manager(np.full(5, -2), 0)
    ids = np.arange(5)
    lanes = np.array([-2, -2, -1, -3, -3])
    x = np.array([100.0, 150.0, 130.0, 60.0, 300.0])
    manager.add(ids, 1, lanes, params, hov_eligible=lanes == -1)
    seen = []
    manager.set_controller(0, lambda obs: seen.append(obs) or 0.5)
    ghost = Obstacles.make(1, -4, 120.0, 10.0, 20.0)
    commands = manager.step(point_states(ids, x, lanes, [20.0, 21, 22, 23, 24]), ghost)
    obs = seen[0]
    length = params.length[0]
    assert obs.id == 0 and obs.lane == -2 and obs.x == 100.0 and obs.speed == 20.0
    assert obs.lanes.lanes == (-1, -2, -3, -4)
    assert obs.lanes.leader_gap == pytest.approx(
        [30.0 - length, 50.0 - length, 200.0 - length, 20.0 - length]
    )
    assert obs.lanes.leader_speed == pytest.approx([22.0, 21.0, 24.0, 20.0])
    assert obs.lanes.follower_gap[2] == pytest.approx(40.0 - length)
    assert np.isinf(obs.lanes.follower_gap[[0, 1, 3]]).all()
    assert sorted(obs.neighbours["id"].tolist()) == [-1, 1, 2, 3]  # -1: the ghost
    assert commands.accel[0] == 0.5  # the controller's, not the IDM's
    assert obs.default_accel != 0.5


def test_an_ego_controller_lane_change_request_is_executed_when_safe():
    manager, params = point_mass_manager(np.full(1, -3), 0)
    manager.add([0], 1, -3, params, desired_speed=25.0)
    manager.set_controller(0, lambda obs: EgoCommand(accel=0.0, lane_change=-1))
    commands = None
    for k in range(20):
        commands = manager.step(point_states([0], [25.0 * k * 0.01], [-3], [25.0]))
    assert commands.lane[0] == -4 and commands.changing[0]


@pytest.mark.parametrize(
    "answer, match",
    [
        ("fast", "not an acceleration"),
        (float("nan"), "accel nan"),
        (EgoCommand(0.0, 3), "direction"),
    ],
)
def test_bad_controller_answers_are_named(answer, match):
    manager, params = point_mass_manager(np.full(1, -2), 0)
    manager.add([0], 1, -2, params)
    manager.set_controller(0, lambda obs: answer)
    with pytest.raises(ControllerError, match=match):
        manager.step(point_states([0], [0.0], [-2], [20.0]))


def test_a_controller_that_raises_is_named():
    manager, params = point_mass_manager(np.full(1, -2), 0)
    manager.add([0], 1, -2, params)
    manager.set_controller(0, lambda obs: 1 / 0)
    named = r"the controller <lambda> of vehicle 0 at t = 0.00 s raised ZeroDivisionError"
    with pytest.raises(ControllerError, match=named):
        manager.step(point_states([0], [0.0], [-2], [20.0]))


def test_settings_and_overrides_are_checked():
    manager, params = point_mass_manager(np.full(2, -2), 0)
    manager.add([3, 4], 1, [-2, -1], params, hov_eligible=[False, True])
    manager.set_params([3], time_headway=2.0, politeness=0.6)
    assert manager.params([3])["time_headway"][0] == 2.0
    assert manager.params([3])["politeness"][0] == 0.6
    manager.set_desired_speed([3, 4], [10.0, 0.0])
    assert manager.desired_speed([3, 4]).tolist() == [10.0, 0.0]
    with pytest.raises(ValueError, match="unknown driver parameter 'headway'"):
        manager.set_params([3], headway=2.0)
    with pytest.raises(ValueError, match="time_headway must be finite"):
        manager.set_params([3], time_headway=-1.0)
    with pytest.raises(ValueError, match="desired speeds"):
        manager.set_desired_speed([3], np.nan)
    with pytest.raises(ValueError, match="HOV lane cannot be made non-eligible"):
        manager.set_params([4], hov_eligible=False)
    with pytest.raises(KeyError, match="not a managed vehicle: \\[9\\]"):
        manager.set_desired_speed([9], 10.0)
    with pytest.raises(ValueError, match="increasing"):
        manager.add([2], 1, -2, _one(params))
    with pytest.raises(ValueError, match="must be HOV-eligible"):
        manager.add([5], 1, -1, _one(params), hov_eligible=False)
    with pytest.raises(ValueError, match="lanes must be in"):
        manager.add([5], 1, -5, _one(params))
    with pytest.raises(ValueError, match="exactly the managed vehicles"):
        manager.step(point_states([3], [0.0], [-2], [20.0]))
    manager.remove([3])
    assert manager.ids.tolist() == [4]


def _one(params):
    return params.take(np.array([0]))


@pytest.mark.parametrize(
    "settings, match",
    [
        (dict(dt=0.0), "dt must be positive"),
        (dict(hov_share=1.5), "hov_share"),
        (dict(lane_change_time=(5.0, 2.0)), "lane_change_time"),
        (dict(decision_period=0.015), "decision_period"),
        (dict(hov_openings=((5.0, 1.0),)), "hov_openings"),
        (dict(brake_limit=0.0), "brake_limit"),
    ],
)
def test_impossible_configurations_are_named(settings, match):
    with pytest.raises(ValueError, match=match):
        TrafficConfig(**settings)


def test_obstacles_are_checked():
    with pytest.raises(ValueError, match="obstacle field speed"):
        Obstacles.make(1, -2, 0.0, 4.0, np.nan)
    with pytest.raises(ValueError, match="obstacle lanes"):
        Obstacles.make(1, 0, 0.0, 4.0, 10.0)


def test_same_seed_same_drivers_and_decisions(built_map):
    from twin.physics.world import PhysicsWorld

    runs = []
    for _ in range(2):
        with PhysicsWorld(built_map) as world:
            manager = make_manager(built_map, seed=5)
            lanes = np.array([-2, -3, -4, -2, -3, -4])
            spawn(world, manager, 1, lanes, np.repeat([-300.0, -220.0], 3), 15.0)
            rec = run(world, manager, 8.0)
            runs.append((manager.params(manager.ids), rec))
    (p1, r1), (p2, r2) = runs
    assert all(np.array_equal(p1[k], p2[k]) for k in p1)
    assert np.array_equal(r1.x, r2.x) and np.array_equal(r1.lane, r2.lane)


def test_a_driver_is_its_seeds_keys_and_classes_whatever_is_added_with_it():
    # the core's draw (twin.traffic.kernels.drivers): keyed, not a stream, so the
    # vehicles around a driver, and the order they come in, do not change it
    crowd, params = point_mass_manager(np.full(3, -3), [0, 4, 1], seed=7)
    crowd.add([0, 1, 2], 1, -3, params, keys=[11, 12, 13])
    alone, one = point_mass_manager(np.full(1, -3), [4], seed=7)
    alone.add([5], 1, -3, one, keys=[12])
    drawn, single = crowd.params([1]), alone.params([5])
    assert all(np.array_equal(drawn[k], single[k]) for k in drawn)
    assert crowd._d.next_decision[0, 1] == alone._d.next_decision[0, 0]
    other, _ = point_mass_manager(np.full(1, -3), [4], seed=8)
    other.add([5], 1, -3, one, keys=[12])
    assert other.params([5])["time_headway"][0] != single["time_headway"][0]


def test_the_managers_drivers_follow_the_class_tables_law():
    # the same law as the distribution's numpy draw (DriverDistribution.draw), other
    # draws: 4,000 sedans' traits agree with 4,000 of the numpy draw's within 4 standard
    # errors, and every first decision comes within one decision interval
    n = 4000
    manager, params = point_mass_manager(np.full(n, -3), 0, seed=3)
    manager.add(np.arange(n), 1, -3, params)
    cfg = manager.config
    ours = manager.params(np.arange(n))
    theirs = cfg.drivers.draw(manager.classes, np.zeros(n, np.int64), np.random.default_rng(3))
    for name, log in (("desired_speed", False), ("time_headway", True), ("min_gap", False),
                      ("max_accel", True)):  # fmt: skip
        a, b = ours[name], getattr(theirs, name)
        a, b = (np.log(a), np.log(b)) if log else (a, b)
        standard_error = np.sqrt((a.var() + b.var()) / n)
        assert abs(a.mean() - b.mean()) < 4 * standard_error, name
        assert a.std() == pytest.approx(b.std(), rel=0.1), name
    first = manager._d.next_decision[0]
    assert np.all((first >= 0) & (first < cfg.decision_interval))
    assert first.std() == pytest.approx(cfg.decision_interval / np.sqrt(12), rel=0.1)
