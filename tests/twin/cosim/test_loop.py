"""Each step of the paper's loop on hand-built recordings (DESIGN.md, steps 1 to 8)."""

import numpy as np
import pytest

from tests.twin.cosim.scenes import EGO_X, T0, rows_of, step_until, tid_of, vehicle
from twin.core.errors import NoVehicleNearError
from twin.cosim.config import CosimConfig
from twin.cosim.cosimulator import Cosimulator
from twin.cosim.windows import ScenarioError
from twin.data.empirical import EmpiricalTraffic

EGO = 1  # the recorded ego of every scene: lane -2, x = 700 m at T0, 20 m/s


def ego_doc(speed=20.0):
    return vehicle(EGO, -2, EGO_X, speed)


def test_step1_the_ego_is_the_recorded_vehicle_closest_to_the_request(cosim):
    sim = cosim([vehicle(2, -2, EGO_X + 30.0, 20.0), ego_doc(), vehicle(3, -3, EGO_X, 20.0)])
    assert sim.ego.id == f"{EGO:024x}"
    assert sim.ego.lane == -2 and sim.ego.x == pytest.approx(EGO_X, abs=0.05)
    assert sim.t0 == pytest.approx(T0, abs=1e-6)
    states = sim.world.states()
    ego = states.id == sim.ego_id
    # spawned at its recorded pose and speed (the paper's ego started at 0 m/s)
    assert states.x[ego][0] == pytest.approx(EGO_X, abs=0.05)
    assert states.speed[ego][0] == pytest.approx(20.0, rel=1e-3)


def test_step1_no_recorded_vehicle_near_the_request_is_a_named_error(built_map, tmp_path):
    from tests.twin.cosim.scenes import make_store

    store = make_store(tmp_path, [ego_doc()])
    config = CosimConfig(road="westbound", lane=-4, x=EGO_X, time=T0)
    with (
        Cosimulator(config, EmpiricalTraffic(store), built_map) as sim,
        pytest.raises(NoVehicleNearError, match="lane -4 of westbound"),
    ):
        sim.reset()


def test_an_episode_past_the_end_of_the_data_is_refused(built_map, tmp_path):
    from tests.twin.cosim.scenes import make_store

    store = make_store(tmp_path, [ego_doc()])  # 40 s of data after T0
    config = CosimConfig(road="westbound", lane=-2, x=EGO_X, time=T0, t_max=60.0)
    with (
        Cosimulator(config, EmpiricalTraffic(store), built_map) as sim,
        pytest.raises(ScenarioError, match="data on westbound end"),
    ):
        sim.reset()


def test_step2_visible_vehicles_spawn_at_their_recorded_speed_ghosts_do_not(cosim):
    docs = [
        ego_doc(),
        vehicle(2, -1, EGO_X + 100.0, 23.0),  # visible ahead
        vehicle(3, -4, EGO_X - 120.0, 17.0),  # visible behind
        vehicle(4, -3, EGO_X + 175.0, 25.0),  # front ghost window
        vehicle(5, -3, EGO_X - 190.0, 21.0),  # rear ghost window
        vehicle(6, -3, EGO_X + 260.0, 25.0),  # beyond both windows
    ]
    sim = cosim(docs)
    states = sim.world.states()
    assert states.id.size == 3
    for n, speed in ((2, 23.0), (3, 17.0)):
        row = rows_of(sim, tid_of(sim, n))
        assert row["speed"].iloc[0] == pytest.approx(speed, rel=1e-3)
    assert sorted(sim.ghosts.tid.tolist()) == sorted([tid_of(sim, 4), tid_of(sim, 5)])


def test_step3_the_lane_lead_takes_its_ghosts_speed_the_others_vel_default(cosim):
    docs = [
        ego_doc(),
        vehicle(2, -2, EGO_X + 50.0, 20.0),  # visible, not the lead of lane -2
        vehicle(3, -2, EGO_X + 110.0, 20.0),  # the lead of lane -2 among visible ones
        vehicle(4, -2, EGO_X + 180.0, 12.0),  # its ghost
        vehicle(5, -3, EGO_X + 90.0, 20.0),  # lead of lane -3, no ghost: vel_default
        vehicle(6, -2, EGO_X - 60.0, 20.0),  # behind the ego: vel_default
    ]
    sim = cosim(docs)
    sim.step()
    ids = dict(zip(sim.tids.tolist(), sim.world.ids.tolist(), strict=True))
    desired = {n: float(sim.manager.desired_speed([ids[tid_of(sim, n)]])[0]) for n in (2, 3, 5, 6)}
    assert desired == {2: 30.0, 3: pytest.approx(12.0, abs=1e-6), 5: 30.0, 6: 30.0}
    # and it slows toward it while the ghost is ahead of it (it enters the visible
    # window after about 3.7 s, as the ego closes in on it)
    for _ in range(300):
        sim.step()
    lead = rows_of(sim, tid_of(sim, 3))
    assert np.all(np.diff(lead["speed"].iloc[1:]) < 0.0)
    assert lead["speed"].iloc[-1] < 18.0


def test_a_calibrated_lane_lead_keeps_its_speed_and_is_held_back_by_its_ghost(cosim):
    docs = [
        ego_doc(),
        vehicle(3, -2, EGO_X + 110.0, 20.0),  # the lead of lane -2
        vehicle(4, -2, EGO_X + 180.0, 12.0),  # its ghost, slower
        vehicle(5, -3, EGO_X + 90.0, 20.0),  # lead of lane -3
        vehicle(7, -3, EGO_X + 175.0, 26.0),  # its ghost, faster than the lead's own
    ]
    sim = cosim(docs)
    sim.rules(lead_chases_ghost=True)  # its drivers are the paper's here: only the rule
    sim.set_base_speeds(sim.manager.ids, 24.0)  # each vehicle's own desired speed
    sim.step()
    ids = dict(zip(sim.tids.tolist(), sim.world.ids.tolist(), strict=True))
    desired = {n: float(sim.manager.desired_speed([ids[tid_of(sim, n)]])[0]) for n in (3, 5)}
    assert desired == {3: 24.0, 5: pytest.approx(26.0, abs=1e-6)}
    # the slow ghost ahead is its leader: it still slows toward it
    for _ in range(300):
        sim.step()
    lead = rows_of(sim, tid_of(sim, 3))
    assert lead["speed"].iloc[-1] < 18.0


def test_ghost_smoothing_lags_the_lead_speed_when_asked(cosim):
    docs = [ego_doc(), vehicle(3, -2, EGO_X + 110.0, 20.0), vehicle(4, -2, EGO_X + 180.0, 12.0)]
    sim = cosim(docs, ghost_smoothing=2.0)
    lead = sim.world.ids[sim.tids == tid_of(sim, 3)]
    sim.step()
    first = float(sim.manager.desired_speed(lead)[0])
    assert first == pytest.approx(12.0)  # the first value is taken as is
    # a new ghost at a different speed is approached with the lag's time constant
    sim.state.episodes.lead_speed[0, 1] = 20.0  # lane -2's smoothed speed
    sim.step()
    assert float(sim.manager.desired_speed(lead)[0]) == pytest.approx(20.0 - 8.0 * 0.01 / 2.0)


def test_step5_a_vehicle_crossing_into_a_ghost_window_is_removed(cosim):
    # 10 m/s faster than the ego (held at 20 m/s): reaches the front ghost window at ~5 s
    sim = cosim([ego_doc(), vehicle(2, -3, EGO_X + 100.0, 30.0)])
    tid = tid_of(sim, 2)
    step_until(sim, lambda: tid not in sim.tids)
    rows = rows_of(sim, tid)
    ego = sim.log.vehicles().query("role == 0")
    gap = rows["x"].to_numpy() - ego["x"].to_numpy()[: len(rows)]
    assert gap.max() <= 150.0 + 30.0 * 0.01  # never simulated beyond the window
    assert gap[-1] > 149.0
    assert sim.counters.despawned == 1
    assert sim.world.ids.size == 1 and sim.manager.ids.size == 1
    sim.step()
    assert tid in sim.ghosts.tid  # its recording is now a ghost ahead


def test_step6_a_ghost_entering_the_visible_window_is_spawned_at_its_recorded_speed(cosim):
    # from the rear ghost window at 30 m/s: enters at ~3 s behind the ego
    sim = cosim([ego_doc(), vehicle(2, -3, EGO_X - 180.0, 30.0)])
    tid = tid_of(sim, 2)
    assert tid in sim.ghosts.tid
    step_until(sim, lambda: tid in sim.tids)
    row = rows_of(sim, tid).iloc[0]
    recorded_x = EGO_X - 180.0 + 30.0 * row["time"]
    assert row["speed"] == pytest.approx(30.0, rel=1e-3)
    assert row["x"] == pytest.approx(recorded_x, abs=0.05)
    ego_x = sim.log.vehicles().query("role == 0")["x"].iloc[-1]
    assert ego_x - 150.0 <= row["x"] <= ego_x - 149.0  # just inside the window's rear edge
    sim.step()
    error = np.array(sim.counters.spawn_speed_error)
    assert error.size == 2 and error.max() <= 0.005  # the initial ego too
    assert sim.counters.spawned == 1


def test_step6_a_vehicle_first_recorded_inside_the_visible_window_is_spawned(cosim):
    # an on-ramp merge as the data show it: the track begins in lane -4, 60 m ahead
    # of the ego, 2 s into the episode (before, it was neither simulated nor a ghost)
    sim = cosim([ego_doc(), vehicle(5, -4, EGO_X + 20.0, 20.0, start=2.0)])
    tid = tid_of(sim, 5)
    assert tid not in sim.tids and tid not in sim.ghosts.tid
    step_until(sim, lambda: tid in sim.tids)
    row = rows_of(sim, tid).iloc[0]
    assert row["time"] == pytest.approx(2.0, abs=0.011)
    assert row["x"] == pytest.approx(EGO_X + 20.0 + 20.0 * row["time"], abs=0.05)
    assert sim.counters.spawned == 1


def test_step6_a_ghost_is_not_spawned_where_a_body_is_in_the_way(cosim):
    docs = [
        ego_doc(),
        vehicle(2, -3, EGO_X - 140.0, 20.0),  # visible near the rear edge
        vehicle(3, -3, EGO_X - 155.0, 30.0),  # a ghost 10 m/s faster, close behind it
        vehicle(4, -4, EGO_X - 155.0, 30.0),  # the same in a free lane: spawned
    ]
    sim = cosim(docs)
    for _ in range(100):
        sim.step()
    assert tid_of(sim, 3) not in sim.tids
    assert tid_of(sim, 4) in sim.tids
    assert sim.counters.skipped_overlap == 1 and sim.counters.spawned == 1


def test_a_vehicle_refused_for_lack_of_room_is_spawned_once_it_fits(cosim):
    # 3 is recorded 1.4 m ahead of 2 at the start (too close to spawn) and pulls away
    # at 26 m/s; before, a refusal left it out for good: a hole in the window
    sim = cosim(
        [ego_doc(), vehicle(2, -3, EGO_X + 100.0, 20.0), vehicle(3, -3, EGO_X + 106.0, 26.0)]
    )
    tid = tid_of(sim, 3)
    assert tid not in sim.tids and sim.counters.skipped_overlap == 1
    step_until(sim, lambda: tid in sim.tids, limit=100)
    row = rows_of(sim, tid).iloc[0]
    assert row["x"] == pytest.approx(EGO_X + 106.0 + 26.0 * row["time"], abs=0.05)
    assert sim.counters.skipped_overlap == 1  # counted once, however often it was tried
    for _ in range(50):
        sim.step()
    assert not sim.counters.collisions


def test_a_track_that_begins_on_a_simulated_body_is_not_tried_again(cosim):
    # 3 begins 2 s in, 1 m ahead of where 2 then is (in real data: the next fragment of
    # the same car); it is refused and, unlike a ghost entering, not tried again
    sim = cosim([ego_doc(), vehicle(2, -3, EGO_X + 100.0, 20.0),
                 vehicle(3, -3, EGO_X + 141.0 - 52.0, 26.0, start=2.0)])  # fmt: skip
    tid = tid_of(sim, 3)
    for _ in range(400):  # 4 s
        sim.step()
    assert tid not in sim.tids
    assert sim.counters.skipped_overlap == 1


def test_nothing_is_spawned_beside_a_body_changing_into_its_lane(cosim):
    # 2, 2 m inside the window's rear edge and keeping pace with it, starts a change
    # from lane -3 into -4; 3, whose track begins 0.3 s in just behind the edge in lane
    # -4, 4 m/s faster, reaches the window beside it half a second later. Before, 2 was
    # judged by where its body was (still in lane -3) and 3 was spawned into the lane it
    # was moving into (a side collision in the physics world on preset D)
    sim = cosim([ego_doc(), vehicle(2, -3, EGO_X - 148.0, 20.0),
                 vehicle(3, -4, EGO_X - 152.2, 24.0, start=0.3)])  # fmt: skip
    changer = int(sim.world.states().id[sim.tids == tid_of(sim, 2)][0])
    sim.manager.force_lane_change(changer, "right")
    tid = tid_of(sim, 3)
    for _ in range(100):  # 1 s
        sim.step()
        assert sim.manager.changing([changer])[0]
        assert tid not in sim.tids
    assert sim.counters.skipped_overlap == 1


def test_step2_a_standing_queue_is_spawned_as_recorded_a_moving_one_with_room(cosim):
    length = 15.0 * 0.3048  # make_doc's default length
    docs = [ego_doc()]
    # lane -3: a queue at rest 1 m apart, all visible; lane -4: the same at 20 m/s
    for k in range(5):
        docs.append(vehicle(10 + k, -3, EGO_X + 20.0 + k * (length + 1.0), 0.0))
        docs.append(vehicle(20 + k, -4, EGO_X + 20.0 + k * (length + 1.0), 20.0))
    sim = cosim(docs)
    spawned = set(sim.tids.tolist())
    assert all(tid_of(sim, 10 + k) in spawned for k in range(5))
    # at speed the full clearance holds: every other vehicle of the moving queue
    assert sum(tid_of(sim, 20 + k) in spawned for k in range(5)) == 3
    assert sim.counters.skipped_overlap == 2
    for _ in range(100):
        sim.step()
    assert not sim.counters.collisions


def test_step7_the_ghosts_are_the_recording_now_and_the_managers_obstacles(cosim):
    sim = cosim([ego_doc(), vehicle(4, -3, EGO_X + 175.0, 25.0)])
    for _ in range(50):
        sim.step()
    # ego at 20 m/s, the ghost at 25: still in the front window, where the data put it
    (k,) = np.flatnonzero(sim.ghosts.tid == tid_of(sim, 4))
    assert sim.ghosts.x[k] == pytest.approx(EGO_X + 175.0 + 25.0 * 0.5, abs=0.02)
    ghosts = sim.ghosts
    assert ghosts.lane.tolist() == [-3] and ghosts.speed[0] == pytest.approx(25.0, abs=0.01)


def test_step8_the_episode_ends_at_t_max_and_every_step_is_logged(cosim):
    sim = cosim([ego_doc(), vehicle(2, -1, EGO_X + 40.0, 20.0)], t_max=0.5)
    sim.run()
    assert sim.done and sim.step_index == 50
    frame = sim.log.vehicles()
    assert np.allclose(np.unique(frame["time"]), np.arange(51) * 0.01)
    assert (frame.groupby("time").size() == 2).all()
    # measured acceleration: the speed change over each step
    ego = frame[frame["role"] == 0]
    assert np.isnan(ego["accel"].iloc[0])
    assert np.allclose(ego["accel"].iloc[1:], np.diff(ego["speed"]) / 0.01)
    ghosts = sim.log.ghosts()
    assert np.allclose(np.unique(ghosts["time"]) if len(ghosts) else [], [])  # none here
    assert sim.windows.visible[1] - ego["x"].iloc[-1] == pytest.approx(150.0)


def test_windows_are_clipped_to_the_data_and_the_map(cosim):
    sim = cosim([ego_doc(), vehicle(2, -3, EGO_X - 90.0, 20.0)])
    lo, hi = sim.limits
    assert lo == pytest.approx(EGO_X - 90.0 - 20.0 * 5.0, abs=0.01)  # where the data start
    assert hi == pytest.approx(EGO_X + 20.0 * 40.0, abs=0.01)  # where the data end
    assert hi < sim.world.road.x_range("westbound")[1] - 30.0  # inside the map
    assert sim.windows.ghost_back == pytest.approx((lo, EGO_X - 150.0), abs=0.01)
    assert sim.windows.visible == pytest.approx((EGO_X - 150.0, EGO_X + 150.0), abs=0.01)


def test_same_seed_same_run_bit_for_bit(cosim):
    docs = [
        ego_doc(),
        vehicle(2, -2, EGO_X + 60.0, 18.0),
        vehicle(3, -3, EGO_X - 180.0, 30.0),
        vehicle(4, -2, EGO_X + 170.0, 10.0),
    ]
    frames = []
    for _ in range(2):
        sim = cosim(docs, controller=None)
        for _ in range(300):
            sim.step()
        frames.append(sim.log.vehicles())
    assert frames[0].equals(frames[1])


def test_a_second_reset_starts_a_new_episode_in_the_same_physics_world(cosim):
    """The core numbers a new episode's vehicles from 0: the world's bodies of the
    first episode go and its ids start again, so both agree."""
    docs = [vehicle(2, -2, EGO_X + 40.0, 20.0), ego_doc(), vehicle(3, -3, EGO_X + 10.0, 20.0)]
    sim = cosim(docs)
    for _ in range(30):
        sim.step()
    first = np.sort(sim.world.states().id)
    sim.reset()
    states = sim.world.states()
    core = sim.state.bodies
    assert np.array_equal(np.sort(states.id), np.sort(core.id[0][core.valid[0]]))
    assert np.array_equal(np.sort(states.id), first)  # the same three vehicles, ids from 0
    assert sim.world.time == 0.0 and sim.step_index == 0
    for _ in range(30):
        sim.step()
    assert sim.counters.collisions == [] and len(sim.world.states().id) == 3
