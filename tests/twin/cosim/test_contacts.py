"""Contacts as the core records them (twin/cosim/core/step.py): a body on a ghost's
recorded box is a contact, found by footprints and kept with both vehicles' roles;
recorded vehicles that crowd a relaxing body become bodies behind it. The embedded
morning, kinematic world, six episodes of 60 s."""

import numpy as np
import pytest

from mapgen.build import default_map
from tests.twin.cosim.scenes import EGO_X, T0, tid_of, vehicle
from twin.core import i24
from twin.core.jit import kernel
from twin.cosim.config import CosimConfig
from twin.cosim.core import anchor, handover, layout, relax
from twin.cosim.core.batch import Batch, Shared
from twin.data.embedded import embedded_store
from twin.metrics.handover import handover_section

EPISODES = 6


@pytest.fixture(scope="module")
def batch():
    store = embedded_store("morning")
    config = CosimConfig(world="kinematic", t_max=60.0)
    shared = Shared.make(store, default_map(), config)
    t_first, _ = store.time_range(config.road)
    run = Batch(shared, episodes=EPISODES)
    for b in range(EPISODES):
        run.reset(b, lane=-2, x=700.0, time=t_first + 300.0 + 60.0 * b, seed=b)
    while not run.done.all():
        run.step()
    return run, shared, config.dt


def _cutting_in(n, lane_from, lane_to, x, speed, at, over=1.0, back_after=None):
    """A constant-speed document that moves from ``lane_from`` to ``lane_to`` over
    ``over`` seconds from T0 + ``at`` (and back, where ``back_after`` [s] is given,
    that long after it began)."""
    doc = vehicle(n, lane_from, x, speed)
    t = np.asarray(doc["timestamp"])
    y0, y1 = ((-lane + 0.5) * i24.LANE_WIDTH_FT for lane in (lane_from, lane_to))
    share = np.clip((t - (T0 + at)) / over, 0.0, 1.0)
    if back_after is not None:
        share -= np.clip((t - (T0 + at + back_after)) / over, 0.0, 1.0)
    doc["y_position"] = (y0 + share * (y1 - y0)).tolist()
    return doc


def test_a_ghost_cutting_in_onto_a_body_is_one_contact_with_its_roles(cosim):
    # a body at the visible window's front edge (150 m ahead of the ego, both at
    # 20 m/s) and a recorded vehicle just beyond it, a ghost, that swerves into its lane
    # and back (a recording that stays in the next lane becomes a body before it cuts
    # in, test below; one that swerves back does not announce a change). With the
    # paper's hand-over: where vehicles relax, a ghost holds its line beside a body
    # (the test after this one)
    sim = cosim(
        [vehicle(1, -2, EGO_X, 20.0), vehicle(2, -2, EGO_X + 147.0, 20.0),
         _cutting_in(3, -3, -2, EGO_X + 151.0, 20.0, at=1.0, back_after=1.5)],
        world="kinematic", t_max=4.0, relax=False,
    )  # fmt: skip
    sim.run()
    assert sim.counters.contacts == 1  # touching for many steps, one contact
    ((time, a, ghost, flags_a, flags_b, ghost_lane, ghost_speed),) = sim.counters.collisions
    body = sim.log.vehicles().query("tid == @tid_of(@sim, 2)")
    assert a == body["id"].iloc[0] and flags_a == 0  # a visible vehicle, following
    assert ghost == layout.GHOST_ID_BASE - tid_of(sim, 3) and flags_b == layout.CONTACT_GHOST
    assert 1.0 < time < 2.0 and ghost_lane in (-3, -2) and ghost_speed == pytest.approx(20.0)
    # the boxes overlap then: the ghost's recorded box and the body's logged one (both
    # 15 ft by 6 ft, near enough straight)
    row = body[np.isclose(body["time"], time)].iloc[0]
    present, x, y, _ = sim.traffic.recorded_states("westbound", [tid_of(sim, 3)], [sim.t0 + time])
    assert present[0]
    assert abs(row["x"] - x[0]) < 15 * i24.FT and abs(row["y"] - y[0]) < 6 * i24.FT


def test_a_ghost_swerving_toward_a_body_beside_it_holds_its_line(cosim):
    # the swerve above where vehicles relax (the default): the recording, which does not
    # know of the body, is drawn holding its line BESIDE_GAP across from it (anchored,
    # counted in ghosts_braked) and back on its recording once it swerves back; on the
    # SUMO test family recordings of sub-lane drivers drifting across toward a body
    # beside them were 4 of the 9 collisions left (kinematic, 16 x 120 s per day)
    sim = cosim(
        [vehicle(1, -2, EGO_X, 20.0), vehicle(2, -2, EGO_X + 147.0, 20.0),
         _cutting_in(3, -3, -2, EGO_X + 151.0, 20.0, at=1.0, back_after=1.5)],
        world="kinematic", t_max=5.0,
    )  # fmt: skip
    sim.run()
    assert sim.counters.contacts == 0 and sim.counters.ghosts_braked >= 1
    ghost = sim.log.ghosts().query("tid == @tid_of(@sim, 3)").set_index("time")
    body = sim.log.vehicles().query("tid == @tid_of(@sim, 2)").set_index("time")
    both = ghost.index.intersection(body.index)
    across = (ghost.loc[both, "y"] - body.loc[both, "y"]).abs()
    assert across.min() >= 6 * i24.FT + anchor.BESIDE_GAP - 0.05  # 6 ft wide, both
    assert np.all(np.abs(np.diff(ghost["y"].to_numpy())) <= 0.5)  # no jump across
    assert abs(ghost["y"].iloc[-1] - 3.5 * i24.LANE_WIDTH) < 0.05  # back on its recording


def test_recorded_vehicles_that_waited_are_not_drawn_on_bodies(batch):
    # on this morning, recorded vehicles refused a spawn in the visible window (a body
    # in their place) left it behind bodies; they are held back until there is room
    run, _, _ = batch
    ep = run.state.episodes
    assert ep.held.sum() > 0
    ghost_contacts = [
        row for b in range(EPISODES)
        for row in ep.collision_log[b, : min(int(ep.collisions[b]), layout.COLLISIONS_KEPT)]
        if int(row[4]) & layout.CONTACT_GHOST
    ]  # fmt: skip
    assert ghost_contacts == []


def test_recorded_vehicles_crowding_a_relaxing_body_become_bodies_behind_it(batch):
    run, _, _ = batch
    ep = run.state.episodes
    assert ep.yielded.sum() > 0
    # each became a relaxing body spawned at its recorded state: its speed checked
    errors = np.concatenate(
        [ep.spawn_errors[b, : ep.spawn_error_count[b]] for b in range(EPISODES)]
    )
    assert errors.max() <= 0.005


def test_no_body_is_spawned_beyond_the_maps_end():
    # an ego near the upstream end: the rear windows are clipped there, and recorded
    # vehicles behind the relaxing ones are read no further (the physics world has no
    # road beyond it)
    store = embedded_store("morning")
    config = CosimConfig(world="kinematic", t_max=60.0)
    shared = Shared.make(store, default_map(), config)
    lo = shared.settings.limit_lo
    t_first, _ = store.time_range(config.road)
    run = Batch(shared, episodes=4)
    for b in range(4):
        run.reset(b, lane=-2, x=lo + 210.0, time=t_first + 300.0 + 60.0 * b, seed=b)
    lookback = []
    while not run.done.all():
        run.step()
        lookback.append(run.state.episodes.lookback.copy())
    assert min(np.min(lookback), lo) == lo  # the recording is read no further back
    log = run.state.log
    assert (log.x[log.id >= 0] >= lo - 1e-9).all()


@kernel(nrt=True)  # called from Python with the struct
def _sort_bodies(b, core):
    return handover._sort_bodies(b, core)


@kernel(nrt=True)
def _both_crowding_tests(b, core, m, x, y, speed, length):
    return (
        handover._crowds_sorted(b, core, m, x, y, speed, length, 1.9),
        handover.crowds(b, core, x, y, speed, length, 1.9, np.int64(-1)),
    )


def test_the_sorted_crowding_test_agrees_with_the_scan_over_every_body(batch):
    """The yields' crowding test prunes the bodies by their back x and stopping points
    (handover._crowds_sorted); it must answer as the plain scan does, here for vehicles
    placed behind every body of every episode at speeds from rest to 40 m/s."""
    run, _, _ = batch
    bo = run.state.bodies
    rng = np.random.default_rng(7)
    asked = crowded = 0
    for b in range(EPISODES):
        m = _sort_bodies(b, run.core)
        order = run.state.slots.by_back[b, :m]
        assert m == int(bo.valid[b].sum())
        assert np.all(np.diff(bo.x[b, order]) >= 0.0)
        for j in order:
            for _ in range(4):
                x = bo.x[b, j] - rng.uniform(0.0, 120.0)
                y = bo.y[b, j] + rng.choice([0.0, 1.0, 3.7])
                speed, length = rng.uniform(0.0, 40.0), rng.uniform(3.5, 20.0)
                sorted_, scanned = _both_crowding_tests(b, run.core, m, x, y, speed, length)
                assert sorted_ == scanned, (b, j, x, y, speed, length)
                asked += 1
                crowded += bool(scanned)
    assert 0 < crowded < asked  # both answers occur


def test_a_recorded_queue_ahead_of_a_body_is_drawn_for_it_to_brake_for(cosim):
    # a body at 20 m/s 35 m behind a recorded vehicle crawling in the front ghost cell:
    # the recording appears (a spawn would not fit there, but the body can brake for
    # it, a ghost held back would leave the queue undrawn) and the body does not hit it
    sim = cosim(
        [vehicle(1, -2, EGO_X, 20.0), vehicle(2, -2, EGO_X + 140.0, 20.0),
         vehicle(3, -2, EGO_X + 180.0, 0.5, seconds=60.0)],
        world="kinematic", t_max=8.0,
    )  # fmt: skip
    sim.run()
    ghosts = sim.log.ghosts()
    assert tid_of(sim, 3) in set(ghosts[ghosts["time"] == 0.0]["tid"])  # drawn at once
    assert int(sim.state.episodes.held[0]) == 0
    assert sim.counters.contacts == 0  # the body braked for it (or went round it)


@pytest.mark.parametrize("crawl", [1.5, 1.0])
def test_a_crawling_recording_yields_to_a_standing_body_in_time(cosim, crawl):
    # a queue standing behind the (held) ego down to the visible window's rear edge,
    # its recordings crawling on, and in the ghost cell behind it recorded vehicles
    # crawling into its last body: each becomes a body behind it while it can still
    # stop there (the yield's room at rest is the crowding test's; at the whole
    # clearance a crawling vehicle crowding a body was always too close: a contact; at
    # 1 m/s the crowding room without the second it closes was crossed in a step, from
    # crowding to too close: a contact). Made bodies inside their car following's
    # standstill gap, they brake no harder than stopping short needs.
    queue = [vehicle(2 + k, -2, EGO_X - 6.6 * (k + 1), crawl, seconds=60.0) for k in range(23)]
    sim = cosim(
        [vehicle(1, -2, EGO_X, 0.0, seconds=60.0), *queue,
         vehicle(99, -2, EGO_X - 185.0, crawl, seconds=60.0)],
        world="kinematic", t_max=35.0,
    )  # fmt: skip
    sim.run()
    assert int(sim.state.episodes.yielded[0]) >= 1
    assert sim.counters.contacts == 0
    config = sim.config
    out = handover_section(sim.log.vehicles(), sim.log.windows(), sim.traffic, config.road,
                           sim.t0, config.dt, sim.limits)["relaxing"]  # fmt: skip
    assert out["vehicles"] >= 1
    assert out["accel_min_mps2"] >= relax.ACCEL_LOW - 1e-6


def test_a_recording_appears_ahead_of_a_body_only_where_the_body_can_stop_behind_it(cosim):
    # a recorded vehicle whose track begins (1 s in) in the front ghost cell 1 m ahead
    # of a body 8 m/s faster (a recording handed back long ago, or the next fragment of
    # a track): it is held back until the body has gone by or can stop behind it, not
    # drawn where the body must run into it
    body_x = EGO_X + 147.0
    sim = cosim(
        [vehicle(1, -2, EGO_X, 20.0), vehicle(2, -2, body_x, 20.0),
         vehicle(3, -2, body_x + 20.0 + 15 * i24.FT + 1.0 - 12.0, 12.0, start=1.0)],
        world="kinematic", t_max=6.0,
    )  # fmt: skip
    sim.run()
    assert int(sim.state.episodes.held[0]) >= 1
    assert sim.counters.contacts == 0


def test_a_recording_cutting_in_ahead_of_a_body_that_cannot_stop_becomes_a_body(cosim):
    # a recorded vehicle crawling in lane -3 in the front ghost cell cuts into lane -2
    # (over 3 s from 1 s in), crossing the line 10 m ahead of a body at 20 m/s there (a
    # contact): announced by its recording, it becomes a body before it cuts in, and
    # changes lanes when the traffic lets it, not in front of a body that cannot stop
    body_x = EGO_X + 147.0
    sim = cosim(
        [vehicle(1, -2, EGO_X, 20.0), vehicle(2, -2, body_x, 20.0),
         _cutting_in(3, -3, -2, body_x + 60.0, 2.0, at=1.0, over=3.0)],
        world="kinematic", t_max=6.0,
    )  # fmt: skip
    sim.run()
    assert int(sim.state.episodes.yielded[0]) >= 1
    assert sim.counters.contacts == 0


@kernel(nrt=True)
def _may_appear(b, core, x, y, speed, length, width):
    return handover.may_appear(b, core, x, y, speed, length, width)


def test_a_recording_does_not_appear_on_the_tail_of_a_yawed_body(batch):
    # physics, SUMO's on-ramp morning, episode 18: a body yawed 0.29 rad in a lane
    # change reached 1.6 m to the side of its centre; a recording appeared as a ghost
    # 2.4 m beside it, clear of it as if it drove straight, and on its tail
    run, _, _ = batch
    bo, b = run.state.bodies, 0
    length, width = 4.7, 1.83
    tried = 0
    for j in np.flatnonzero(bo.valid[b]):
        beside = bo.y[b, j] + 0.5 * (bo.width[b, j] + width) + handover.LATERAL_MARGIN + 0.05
        x = bo.x[b, j] - 2.0  # alongside its tail
        yaw = bo.yaw[b, j]
        try:
            bo.yaw[b, j] = 0.0
            if not _may_appear(b, run.core, x, beside, 4.7, length, width):
                continue  # another body there
            bo.yaw[b, j] = 0.29
            assert not _may_appear(b, run.core, x, beside, 4.7, length, width)
            tried += 1
        finally:
            bo.yaw[b, j] = yaw
    assert tried >= 5


@kernel(nrt=True)
def _hand_back(b, core):
    return handover.hand_back(b, core)


def test_a_body_is_not_handed_to_a_recording_that_would_crowd_the_body_ahead():
    # physics, preset D by other drivers, episode 3: a recording crawling at 0.84 m/s
    # 0.84 m behind a relaxing body at 0.63 m/s crowded it and became a body; braking
    # hard in its first step, to 0.80 m/s, it crowded no more, was handed back, and its
    # recording was taken back at the reload: spawned and handed back every step for
    # seconds, never holding back, until the recording was too close to yield and ran
    # into the body as a ghost. A relaxing body is handed back only where the ghost it
    # becomes, its recording, would not crowd the body ahead.
    store = embedded_store("morning")
    config = CosimConfig(world="kinematic", t_max=20.0)
    shared = Shared.make(store, default_map(), config)
    t_first, _ = store.time_range(config.road)
    run = Batch(shared, episodes=1)
    run.reset(0, lane=-2, x=700.0, time=t_first + 300.0, seed=0)
    for _ in range(50):
        run.step()
    state, b = run.state, 0
    bo, sl, dr, ep = state.bodies, state.slots, state.drivers, state.episodes
    others = [j for j in np.flatnonzero(bo.valid[b]) if j != ep.ego[b]]
    front, rear = others[0], others[1]
    for j in others[2:]:  # out of the way: the two are alone in their ghost cell
        bo.x[b, j] = ep.windows[b, 2] - 1.0
    sl.relaxing[b, others[2:]] = False
    lane, gap, length = -3, 0.84, float(bo.length[b, rear])
    x, y = ep.windows[b, 1] - 30.0, float(i24.lane_center(lane))  # the rear ghost cell
    for j, xj, v in ((rear, x, 0.80), (front, x + length + gap, 0.63)):
        bo.x[b, j], bo.y[b, j], bo.yaw[b, j], bo.speed[b, j] = xj, y, 0.0, v
        dr.lane[b, j] = dr.lane_from[b, j] = lane
    sl.relaxing[b, rear], sl.rec_on[b, rear] = True, True
    sl.rec_x[b, rear], sl.rec_y[b, rear] = x, y
    ep.speed_prev[b, rear] = 0.80
    # its recording 0.04 m/s faster than the body, as the body was a step ago: as a
    # ghost it would crowd the body ahead; it stays a body
    sl.rec_speed[b, rear] = 0.84
    _hand_back(b, run.core)
    assert bo.valid[b, rear] and sl.relaxing[b, rear]
    # its recording as slow as the body: clear of the body ahead, handed back
    sl.rec_speed[b, rear] = 0.80
    _hand_back(b, run.core)
    assert not bo.valid[b, rear]


def _speeding_up(n, lane, x, speed, accel, at, over):
    """A document at ``speed`` [m/s] whose recording speeds up at ``accel`` [m/s^2] for
    ``over`` seconds from T0 + ``at``."""
    doc = vehicle(n, lane, x, speed)
    t = np.asarray(doc["timestamp"]) - (T0 + at)
    busy = np.clip(t, 0.0, over)
    extra = 0.5 * accel * busy**2 + accel * over * np.maximum(t - over, 0.0)  # [m] ahead
    doc["x_position"] = (np.asarray(doc["x_position"]) - extra / i24.FT).tolist()
    return doc


def test_a_recording_drawn_at_the_clearance_behind_a_body_yields_once_it_closes_on_it(cosim):
    # SUMO's on-ramp morning, episode 17: a recording appeared as a ghost the whole
    # clearance (2 m) behind a body as fast as it, then sped up; crowding the body from
    # its first step of closing, it was already too close to yield at the whole
    # clearance, stayed a ghost and ran into the body. Here a queue of bodies reaches
    # the visible window's rear edge and a recording in the rear ghost cell, 2.05 m
    # behind the last, speeds up: it becomes a body behind it, and nothing is run into
    length = 15 * i24.FT
    queue = [vehicle(2 + k, -2, EGO_X - 37.0 * (k + 1), 20.0) for k in range(4)]
    last = EGO_X - 37.0 * 4
    closing = _speeding_up(9, -2, last - length - 2.05, 20.0, accel=1.5, at=0.5, over=3.0)
    sim = cosim([vehicle(1, -2, EGO_X, 20.0), *queue, closing], world="kinematic", t_max=6.0)
    sim.run()
    assert int(sim.state.episodes.yielded[0]) >= 1
    assert sim.counters.contacts == 0


def test_a_recording_is_not_made_a_body_on_the_recorded_vehicle_behind_it(cosim):
    # six of the seven collisions left on the SUMO test family with anchors were a
    # recording made a body (a yield) where a vehicle drawn behind it overlapped it:
    # recordings that overlap (day 1003 episode 0: 6 cm) or an anchored vehicle drawn
    # over the recording (up to 4.6 m). The test above, with a second recording 1 m into
    # the closing one's back, speeding up as it does: the closing one is not made a body
    # there (before, it was, on top of the other: a contact at once), and no body
    # touches anything
    length = 15 * i24.FT
    queue = [vehicle(2 + k, -2, EGO_X - 37.0 * (k + 1), 20.0) for k in range(4)]
    last = EGO_X - 37.0 * 4
    closing = _speeding_up(9, -2, last - length - 2.05, 20.0, accel=1.5, at=0.5, over=3.0)
    on_it = _speeding_up(10, -2, last - 2 * length - 2.05 + 1.0, 20.0, accel=1.5, at=0.5, over=3.0)
    sim = cosim([vehicle(1, -2, EGO_X, 20.0), *queue, closing, on_it], world="kinematic",
                t_max=6.0)  # fmt: skip
    sim.run()
    assert sim.counters.contacts == 0


def test_a_pair_touching_again_past_the_kept_contacts_is_one_collision():
    # a body beside a ghost that straddles the line touched and parted 81 times in one
    # test-family episode: each contact past the 64 kept was counted as a collision of
    # its own (19 collisions of 2 pairs); now only those of pairs not kept are
    from twin.control.observe import collision_pairs
    from twin.cosim.core.step import _new_contact

    state = layout.make_state(1, 4, 4, 8, 16, 0, 1)
    ep = state.episodes
    for k in range(layout.COLLISIONS_KEPT + 30):
        _new_contact(ep, 0, 0.1 * k, 3, -8, 0, layout.CONTACT_GHOST, -3, 0.0)
    _new_contact(ep, 0, 20.0, 1, 2, 0, 0, 0, np.nan)  # a pair the log has no room for
    assert ep.collisions[0] == layout.COLLISIONS_KEPT + 31
    assert ep.collisions_unlisted[0] == 1
    assert collision_pairs(state, 0) == 2
