"""Strategic lane changes and cooperation (twin.traffic.strategic)."""

import numpy as np
import pytest

from tests.twin.traffic.conftest import make_manager, point_mass_manager, run, spawn
from tests.twin.traffic.test_manager import point_states
from twin.core.i24 import LANE_WIDTH, lane_center
from twin.physics.kinematic import KinematicWorld
from twin.traffic.kernels.lane_change import GIVE_UP
from twin.traffic.kernels.longitudinal import urgency

SPEED = 15.0  # [m/s]


@pytest.fixture
def kinematic(built_map):
    with KinematicWorld(built_map, 0.1) as world:
        yield world


def _dense_lane_beside_a_merger(world, built_map, merger_class=0, **settings):
    """Lane -2 a platoon at 15 m/s with 16 m from back to back (no gap a car can take
    without its new follower braking hard); one car (or a vehicle of ``merger_class``)
    beside it in lane -3, alone there, whose target is to move left within 250 m."""
    manager = make_manager(built_map, dt=0.1, decision_period=0.1, seed=1, **settings)
    platoon = spawn(world, manager, 1, -2, 100.0 + 16.0 * np.arange(10), SPEED)
    merger = spawn(world, manager, 1, -3, 172.0, SPEED, vehicle_class=merger_class)
    everyone = np.r_[platoon, merger]
    manager.set_desired_speed(everyone, np.full(everyone.size, SPEED))
    centre = 172.0 + 0.5 * world.params_of(merger).length[0]
    manager.set_strategic(merger, 1, centre, centre + 250.0)
    return manager, int(merger[0]), centre


def test_a_strategic_driver_changes_by_its_place_because_a_follower_makes_room(
    kinematic, built_map
):
    manager, merger, centre = _dense_lane_beside_a_merger(kinematic, built_map)
    record = run(kinematic, manager, 18.0)
    column = int(np.flatnonzero(kinematic.states().id == merger)[0])
    into_lane_2 = np.flatnonzero(record.lane[:, column] == -2)
    assert into_lane_2.size, "the merger never changed lane"
    x_then = record.x[into_lane_2[0], column]
    assert x_then < centre + 250.0  # before its place
    assert record.contacts == 0
    assert manager.strategic([merger])[0] == 0  # the target is cleared once it starts
    assert record.speed.min() > 5.0  # room made by dropping back, nobody stopped


def test_without_cooperation_the_same_driver_finds_no_gap(kinematic, built_map):
    # urgency never reaches it
    manager, merger, _ = _dense_lane_beside_a_merger(kinematic, built_map, cooperate_from=2.0)
    record = run(kinematic, manager, 18.0)
    column = int(np.flatnonzero(kinematic.states().id == merger)[0])
    assert np.all(record.lane[:, column] == -3)


def test_with_no_one_to_make_room_and_no_gap_to_fall_into_it_drives_on(kinematic, built_map):
    # a semi (20.5 m) beside a crawling queue whose drivers do not make room: no gap
    # behind the one beside it is long enough, so it drives on along its lane (to a
    # gap further on, or its lane's end) rather than braking to fall back gap after gap
    manager = make_manager(built_map, dt=0.1, decision_period=0.1, seed=1, courtesy=0.0)
    queue = spawn(kinematic, manager, 1, -2, 100.0 + 9.0 * np.arange(20), 3.0)
    manager.set_desired_speed(queue, np.full(queue.size, 3.0))
    semi = spawn(kinematic, manager, 1, -3, 180.0, 3.0, vehicle_class=4)
    manager.set_desired_speed(semi, np.full(1, 10.0))
    centre = 180.0 + 0.5 * kinematic.params_of(semi).length[0]
    manager.set_strategic(semi, 1, centre - 100.0, centre + 200.0)  # urgency 0.33
    record = run(kinematic, manager, 10.0)
    column = int(np.flatnonzero(kinematic.states().id == semi[0])[0])
    assert record.speed[:, column].min() >= 3.0 - 1e-6
    assert record.x[-1, column] - record.x[0, column] > 50.0


def _follower_beside_an_urgent_merger(world, built_map, **settings):
    """Lane -2 one car 10 m behind the back of a merger in lane -3 that must move left,
    on a free road at 15 m/s, the merger's urgency 0.8 at the start and growing 0.06 a
    second. Returns (the follower's speeds, whether the merger changed) over 6 s, and
    whether it changed behind the follower."""
    manager = make_manager(built_map, dt=0.1, decision_period=0.1, seed=1, **settings)
    follower = spawn(world, manager, 1, -2, 162.0, SPEED)
    merger = spawn(world, manager, 1, -3, 172.0, SPEED)
    manager.set_desired_speed(np.r_[follower, merger], np.full(2, SPEED))
    centre = 172.0 + 0.5 * world.params_of(merger).length[0]
    manager.set_strategic(merger, 1, centre - 200.0, centre + 50.0)
    record = run(world, manager, 6.0)
    ids = world.states().id
    f_column = int(np.flatnonzero(ids == follower[0])[0])
    m_column = int(np.flatnonzero(ids == merger[0])[0])
    behind = record.speed[:, f_column]
    into = np.flatnonzero(record.lane[:, m_column] == -2)
    changed = into.size > 0
    behind_it = changed and record.x[into[0], m_column] < record.x[into[0], f_column]
    return behind, changed, behind_it


@pytest.mark.parametrize("courtesy", [1.0, 0.0])
def test_only_a_courteous_driver_drops_back_for_an_urgent_change(kinematic, built_map, courtesy):
    # a courteous follower brakes to open the gap and the merger takes it, in front of
    # it; one that is not keeps its speed, and the merger, with no room in front of it,
    # drops back and takes the gap behind it (LC2013's speed adaptation)
    behind, changed, behind_it = _follower_beside_an_urgent_merger(
        kinematic, built_map, courtesy=courtesy
    )
    if courtesy == 1.0:
        assert behind.min() < SPEED - 1.5 and changed and not behind_it
    else:
        assert behind.min() == pytest.approx(SPEED) and changed and behind_it


def test_the_driver_behind_drops_back_only_from_yield_from(kinematic, built_map):
    # the merger's urgency reaches 0.9 after about 1.7 s: until then its follower keeps
    # its speed, then it drops back
    behind, changed, behind_it = _follower_beside_an_urgent_merger(
        kinematic, built_map, yield_from=0.9
    )
    assert behind[:12].min() == pytest.approx(SPEED)
    assert behind.min() < SPEED - 1.0 and changed and not behind_it


def test_courtesy_is_a_share_of_the_drivers_drawn_once_each():
    from twin.core.jit import uniform
    from twin.traffic.kernels.longitudinal import COURTESY_STREAM

    draws = np.array([uniform(np.int64(7), COURTESY_STREAM, np.int64(k), 0) for k in range(4000)])
    assert abs((draws < 0.3).mean() - 0.3) < 0.03  # the share asked for
    again = [uniform(np.int64(7), COURTESY_STREAM, np.int64(k), 0) for k in range(5)]
    assert draws[:5].tolist() == again  # one draw per driver: the same at every step


def test_urgency_grows_from_its_start_to_its_place_and_targets_expire():
    manager, params = point_mass_manager(np.full(2, -3), 0)
    manager.add([0, 1], 1, -3, params)
    manager.set_strategic([0, 1], [1, -1], [100.0, 100.0], [300.0, 300.0])
    d = manager._d  # the kernels' arrays: eastbound vehicles are episode 1

    def u(i, x):
        return urgency(d.strategic, d.strategic_from, d.strategic_by, 1, i, x)

    assert [u(0, 50.0), u(0, 200.0), u(0, 400.0), u(1, 300.0)] == [-1.0, 0.5, 1.0, 1.0]
    # a driver GIVE_UP past its place stops trying; one yet to reach its start keeps
    # its target
    length = params.length[0]
    x = np.array([300.0 + GIVE_UP + 1.0, 50.0]) - 0.5 * length
    manager.step(point_states([0, 1], x, [-3, -3], [0.0, 0.0]))
    assert manager.strategic([0, 1]).tolist() == [0, -1]


def test_strategic_targets_are_checked():
    manager, params = point_mass_manager(np.full(1, -3), 0)
    manager.add([0], 1, -3, params)
    with pytest.raises(ValueError, match="directions must be"):
        manager.set_strategic([0], 2, 0.0, 10.0)
    with pytest.raises(ValueError, match="x_from < x_by"):
        manager.set_strategic([0], 1, 10.0, 10.0)
    with pytest.raises(KeyError):
        manager.set_strategic([7], 1, 0.0, 10.0)
    manager.set_strategic([0], 1, 0.0, 10.0)
    manager.set_strategic([0], 0, np.nan, np.nan)  # cleared
    assert manager.strategic([0]).tolist() == [0]


def _overtaker(x_from):
    """A fast car in lane -3 behind a slow one (which keeps its lane), lanes -2 and -4
    free: MOBIL moves it right, by the keep-right bias (checked without a target); its
    target is left from ``x_from``."""
    manager, params = point_mass_manager(np.full(2, -3), 0)
    manager.add([0, 1], 1, -3, params, desired_speed=[30.0, 10.0])
    manager.set_auto_lane_change([1], False)
    if x_from is not None:
        manager.set_strategic([0], 1, x_from, x_from + 200.0)
    for _ in range(300):  # 3 s: every driver has decided at least once
        commands = manager.step(point_states([0, 1], [100.0, 190.0], [-3, -3], [25.0, 10.0]))
        if commands.changing[0]:
            break
    return int(commands.lane[0])


def test_a_target_ahead_does_not_stop_discretionary_changes_until_it_starts():
    assert _overtaker(x_from=None) == -4  # MOBIL's choice
    assert _overtaker(x_from=5000.0) == -4  # still MOBIL's, the target far ahead
    assert _overtaker(x_from=0.0) == -2  # the target's way once it has started


def test_a_target_the_vehicle_may_never_reach_is_refused():
    manager, params = point_mass_manager(np.full(2, -2), 0)
    manager.add([0, 1], 1, [-2, -4], params)
    with pytest.raises(ValueError, match="HOV"):
        manager.set_strategic([0], 1, 0.0, 100.0)  # across the closed HOV line
    with pytest.raises(ValueError, match="no lane -5"):
        manager.set_strategic([1], -1, 0.0, 100.0)
    with pytest.raises(ValueError, match="directions must be"):
        manager.set_strategic([1], 0.5, 0.0, 100.0)  # not silently truncated to 0


def _queues_side_by_side(world, built_map, **settings):
    """Lanes -2 and -3 two queues crawling at 2 m/s, 4 m bumper to bumper; one car in
    lane -3 must move left within 60 m."""
    manager = make_manager(built_map, dt=0.1, decision_period=0.1, seed=2, **settings)
    spacing = 4.0 + 4.6  # gap plus about a car's length
    left = spawn(world, manager, 1, -2, 100.0 + spacing * np.arange(8), 2.0)
    right = spawn(world, manager, 1, -3, 104.0 + spacing * np.arange(8), 2.0)
    everyone = np.r_[left, right]
    manager.set_desired_speed(everyone, np.full(everyone.size, 2.0))
    # the class's mean driver all round: how fast a gap opens is the scene's, not the
    # draws' (a long-headway driver ahead of the merger opens one sooner)
    same = np.ones(everyone.size)
    manager.set_params(everyone, time_headway=1.1 * same, min_gap=2.0 * same, max_accel=1.2 * same)
    merger = int(right[3])
    centre = 104.0 + spacing * 3 + 0.5 * world.params_of([merger]).length[0]
    manager.set_strategic([merger], 1, centre, centre + 60.0)
    return manager, merger


def _merges_in_the_queue(world, built_map, seconds=40.0, **settings) -> bool:
    manager, merger = _queues_side_by_side(world, built_map, **settings)
    record = run(world, manager, seconds)
    column = int(np.flatnonzero(world.states().id == merger)[0])
    assert record.contacts == 0
    return bool(np.any(record.lane[:, column] == -2))


def test_an_urgent_change_gets_across_a_crawling_queue(kinematic, built_map):
    assert _merges_in_the_queue(kinematic, built_map)


def test_with_a_path_made_for_5_m_s_the_same_change_finds_no_room(kinematic, built_map):
    # 5 m/s x 6 s, as a discretionary change's. The urgent path gets across in about
    # 17 s; this one not while the queue is packed (it did after 36 s, once the merger,
    # braking towards the end of its 60 m, had opened 13 m ahead of itself)
    assert not _merges_in_the_queue(kinematic, built_map, seconds=30.0, urgent_path=30.0)


def _sweep_of_an_urgent_semi(world, built_map, **settings):
    """A semi (20.5 m) crawling at 2 m/s alone in lane -3 that must move left within
    60 m, lane -2 empty: how far its footprint reaches past lane -2's far line [m] (> 0
    into lane -1), and whether it got into lane -2."""
    manager = make_manager(built_map, dt=0.1, decision_period=0.1, seed=2, **settings)
    semi = spawn(world, manager, 1, -3, 150.0, 2.0, vehicle_class=4)
    manager.set_desired_speed(semi, np.full(1, 2.0))
    params = world.params_of(semi)
    centre = 150.0 + 0.5 * params.length[0]
    manager.set_strategic(semi, 1, centre, centre + 60.0)
    road = built_map.road.heading(1)
    reach = []

    def each_step(states):
        yaw = np.angle(np.exp(1j * (states.heading[0] - road)))
        half = 0.5 * params.length[0] * abs(np.sin(yaw)) + 0.5 * params.width[0] * np.cos(yaw)
        reach.append(lane_center(-2) - 0.5 * LANE_WIDTH - (states.y[0] - half))

    record = run(world, manager, 30.0, each_step=each_step)
    assert record.contacts == 0
    return max(reach), bool(record.lane[-1, 0] == -2)


def test_a_long_vehicles_urgent_change_keeps_its_front_inside_the_target_lane(kinematic, built_map):
    # its shortest path is 2.5 of its lengths (51 m), not a car's 15 m: along that its
    # yawed front swept 0.46 m into lane -1
    reach, changed = _sweep_of_an_urgent_semi(kinematic, built_map)
    assert changed
    assert reach < 0.0


def _overtaker_kept_out(zones, x_from=None):
    manager, params = point_mass_manager(np.full(2, -3), 0)
    manager.add([0, 1], 1, -3, params, desired_speed=[30.0, 10.0])
    manager.set_auto_lane_change([1], False)
    manager.set_keep_out(1, zones)
    if x_from is not None:
        manager.set_strategic([0], 1, x_from, x_from + 200.0)
    for _ in range(300):
        commands = manager.step(point_states([0, 1], [100.0, 190.0], [-3, -3], [25.0, 10.0]))
        if commands.changing[0]:
            break
    return int(commands.lane[0])


def test_no_discretionary_change_into_a_lane_kept_out_of():
    assert _overtaker_kept_out([]) == -4  # MOBIL's choice, right (keeping right)
    lane_4 = {"lane": -4, "x0": 0.0, "x1": 500.0}
    lane_2 = {**lane_4, "lane": -2}
    assert _overtaker_kept_out([lane_4]) == -2  # kept out of -4: its other choice
    assert _overtaker_kept_out([lane_4, lane_2]) == -3  # both: stays behind the slow car
    assert _overtaker_kept_out([{**lane_4, "x0": 200.0}]) == -4  # the zone is ahead of it
    assert _overtaker_kept_out([lane_4, lane_2], x_from=0.0) == -2  # a strategic one goes
    with pytest.raises(ValueError, match="keep-out zone"):
        _overtaker_kept_out([{"lane": -5, "x0": 0.0, "x1": 1.0}])
    with pytest.raises(ValueError, match="keep-out zone"):
        _overtaker_kept_out([{"lane": -2, "x0": 5.0, "x1": 1.0}])


def _overtaker_beside_a_recording(gap, clearance=None, accel=0.0):
    """The lane the overtaker of :func:`_overtaker_kept_out` ends in with a recording
    (an obstacle) in lane -2 ``gap`` [m] behind it at 15 m/s (it overtakes at 25 m/s, so
    the recording would not have to brake for it); ``clearance``: the room
    a change leaves in front of a recording (the cosimulation's spawn clearance);
    ``accel`` [m/s^2]: the recording's acceleration (its recorded one, to come)."""
    from twin.traffic.scene import Obstacles

    manager, params = point_mass_manager(np.full(2, -3), 0)
    manager.add([0, 1], 1, -3, params, desired_speed=[30.0, 10.0])
    if clearance is not None:
        manager._settings[1] = manager._settings[1]._replace(
            obstacle_clearance=clearance, obstacle_clearance_at_rest=0.3
        )
    # and one alongside it in lane -4, so that left is its only way past
    ghost = Obstacles.make(1, [-2, -4], [100.0 - gap - 4.5, 100.0], 4.5, 15.0, [accel, 0.0])
    for _ in range(300):
        states = point_states([0, 1], [100.0, 190.0], [-3, -3], [25.0, 10.0])
        commands = manager.step(states, ghost)
        if commands.changing[0]:
            break
    return int(commands.lane[0])


def test_a_change_in_front_of_a_recording_leaves_it_the_room_to_be_made_a_body():
    # a recording cannot brake for the change: it needs the room in which it can be made
    # a simulated vehicle behind it (a ramp vehicle crossed 1.4 m ahead of one, slowed,
    # and was run through); a driver would brake, so 1 m does for it
    assert _overtaker_beside_a_recording(1.5) == -2  # the default: any new neighbour's 1 m
    assert _overtaker_beside_a_recording(1.5, clearance=2.0) == -3
    assert _overtaker_beside_a_recording(2.5, clearance=2.0) == -2


def test_a_change_in_front_of_a_recording_foresees_it_speeding_up():
    # a ramp vehicle left a recording at 9.9 m/s the 2.0 m that speed asked for; the
    # recording went on speeding up at 0.6 m/s^2 and ran into it (SUMO's on-ramp
    # morning): a recording is judged at the speed it reaches FORESEEN (3 s) later
    assert _overtaker_beside_a_recording(2.5, clearance=2.0, accel=3.0) == -2  # 24 < 25 m/s
    assert _overtaker_beside_a_recording(2.5, clearance=2.0, accel=4.0) == -3  # 27 > 25 m/s
    assert _overtaker_beside_a_recording(20.0, clearance=2.0, accel=4.0) == -2  # room for it
    # one braking is judged at its speed now, not at the crawl it will reach (where the
    # room at rest, 0.3 m, would let the change in 1.5 m ahead of it)
    assert _overtaker_beside_a_recording(1.5, clearance=2.0, accel=-5.0) == -3


def _overtaker_beside(ghost_x):
    """The lane the overtaker of :func:`_overtaker_kept_out` ends in with lane -2 kept
    out of, the slow car staying in its lane and a recording (an obstacle) at back x
    ``ghost_x`` [m] in lane -4 (None: none), the overtaker's back at 100 m."""
    from twin.traffic.scene import Obstacles

    manager, params = point_mass_manager(np.full(2, -3), 0)
    manager.add([0, 1], 1, -3, params, desired_speed=[30.0, 10.0])
    manager.set_auto_lane_change([1], False)
    manager.set_keep_out(1, [{"lane": -2, "x0": 0.0, "x1": 500.0}])
    ghost = None if ghost_x is None else Obstacles.make(1, -4, ghost_x, 4.5, 25.0)
    for _ in range(300):
        commands = manager.step(point_states([0, 1], [100.0, 190.0], [-3, -3], [25.0, 10.0]),
                                ghost)  # fmt: skip
        if commands.changing[0]:
            break
    return int(commands.lane[0])


def test_a_recording_level_with_a_driver_blocks_its_change():
    # an entry exactly at the asking driver's x was taken for its own, so a recording
    # level with it in the lane it moved to was neither ahead nor behind: it changed
    # into it (the scene the recordings' tests above set up)
    assert _overtaker_beside(None) == -4  # lane -4 free: it goes
    assert _overtaker_beside(100.0) == -3  # level with it: it stays
    assert _overtaker_beside(99.0) == -3 and _overtaker_beside(101.0) == -3
