"""Relaxing vehicles (twin/cosim/core/relax.py): a vehicle leaving the visible window
stays simulated in the ghost cell and rejoins its recording without a jump, within
its limits; without relaxation the paper's hand-over jumps. Scenario B's wave on the
session's preset-B recording, kinematic world, 120 s, and a hand-built scene
(``tests/twin/cosim/scenes.py``)."""

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from tests.twin.cosim.scenes import EGO_X, T0, tid_of, vehicle
from tests.twin.cosim.sections import with_section
from twin.core import i24
from twin.core.errors import TwinError
from twin.core.jit import kernel
from twin.cosim.config import SCENARIO_B, CosimConfig, from_toml, override
from twin.cosim.core import anchor, handover, layout, relax
from twin.cosim.core.batch import Batch, Shared
from twin.cosim.cosimulator import Cosimulator
from twin.data.empirical import EmpiricalTraffic
from twin.metrics.continuity import continuity_section
from twin.metrics.handover import handover_section


def _boundary(store, built_map, relaxes: bool, anchors: bool = False) -> dict:
    config = replace(SCENARIO_B, world="kinematic", dt=0.1, t_max=120.0, relax=relaxes,
                     anchor=anchors)  # fmt: skip
    traffic = EmpiricalTraffic(store)
    with Cosimulator(config, traffic, built_map) as sim:
        sim.reset()
        sim.run()
        vehicles, windows = sim.log.vehicles(), sim.log.windows()
        section = handover_section(vehicles, windows, traffic, config.road, sim.t0, config.dt,
                                   sim.limits, relaxes and anchors)  # fmt: skip
        section["continuity"] = continuity_section(
            vehicles, sim.log.ghosts(), windows, traffic, config.road, sim.t0, config.dt,
            1.0 / config.ghost_log_rate, sim.limits,
        )  # fmt: skip
        return section


@pytest.fixture(scope="module")
def relaxed(wave_store, built_map):
    return _boundary(wave_store, built_map, True)


@pytest.fixture(scope="module")
def anchored(wave_store, built_map):
    return _boundary(wave_store, built_map, True, anchors=True)


def test_vehicles_rejoin_their_recordings_without_a_jump(relaxed):
    out = relaxed["visible_to_ghost"]
    assert out["count"] >= 3  # handed to their recordings in the ghost cells
    assert out["position_jump_m"]["max"] <= relax.HAND_BACK_X + 0.05  # carried one step
    # its speed the step before, the last drawn, is within HAND_BACK_SPEED of its recording now
    assert out["speed_jump_mps"]["max"] <= relax.HAND_BACK_SPEED + 1e-9
    assert out["backwards"] == 0 and out["into_visible_window"] == 0


def test_with_anchors_every_record_goes_on_through_the_boundary_without_a_jump(anchored, relaxed):
    # issue 76 (anchor = true): bodies that end off their recordings (at the simulated
    # region's edge) are drawn as their recordings anchored where they were; nothing is
    # simulated beyond the region, no track ends or begins inside it. Relaxation alone
    # jumps where a relaxing body is removed off its recording, and keeps bodies far
    # beyond the windows
    assert relaxed["continuity"]["discontinuous"] > 0
    assert relaxed["continuity"]["beyond_region"]["vehicles"] > 0
    out, continuity = anchored["visible_to_ghost"], anchored["continuity"]
    assert out["anchored"] >= 1 and out["anchor_offset_m"]["max"] > 1.0  # they were off
    assert continuity["discontinuous"] == 0 and continuity["position_jump_m"]["max"] <= 0.5
    assert continuity["speed_jump_mps"]["max"] <= 0.5
    assert continuity["tracks"]["begin"]["inside"] == 0
    assert continuity["tracks"]["end"]["inside"] == 0
    assert continuity["beyond_region"]["vehicles"] == 0 and continuity["doubled"] == 0


def test_relaxing_vehicles_stay_within_their_limits_and_never_reverse(relaxed):
    out = relaxed["relaxing"]
    assert out["vehicles"] > 0
    assert out["accel_min_mps2"] >= relax.ACCEL_LOW - 1e-6  # no emergency in this wave
    assert out["accel_max_mps2"] <= relax.ACCEL_HIGH + 1e-6
    assert out["speed_min_mps"] >= 0.0


def test_without_relaxation_the_papers_hand_over_jumps(wave_store, built_map, relaxed):
    out = _boundary(wave_store, built_map, False)
    assert out["relaxing"]["vehicles"] == 0
    assert out["visible_to_ghost"]["count"] > relaxed["visible_to_ghost"]["count"]
    assert out["visible_to_ghost"]["anchored"] == 0
    assert out["continuity"]["discontinuous"] > 0
    assert out["visible_to_ghost"]["position_jump_m"]["max"] > 5.0  # the seam relaxation removes


@pytest.mark.parametrize("offset", [-40.0, -3.0, 0.25, 12.0])
def test_an_anchors_offset_closes_at_a_physical_rate_without_overshoot(offset):
    # the offset of a vehicle drawn where its body ended decays as a critically damped
    # spring: its acceleration within ACCEL, never past its recording, under 1 mm in
    # finite time
    x, v, dt, steps = offset, 0.0, 0.1, 0
    while max(abs(x), abs(v)) >= anchor.SETTLED:
        x_next, v_next = anchor._step(x, v, anchor.ACCEL, dt, -math.inf)
        assert abs(v_next - v) <= anchor.ACCEL * dt + 1e-12
        assert x_next * offset >= -1e-9  # it does not overshoot its recording
        x, v, steps = x_next, v_next, steps + 1
        assert steps < 2000
    assert steps * dt > abs(offset) / 20.0  # not at once


def test_an_anchored_vehicle_ahead_of_a_standing_recording_waits_for_it():
    # ahead of its recording by 30 m, the recording standing: the offset's rate never
    # drops below minus the recorded speed (0), so the vehicle drawn stands and waits
    x, v = 30.0, 0.0
    for _ in range(100):
        x, v = anchor._step(x, v, anchor.ACCEL, 0.1, -0.0)
        assert v >= 0.0 and x == 30.0
    x, v = anchor._step(x, v, anchor.ACCEL, 0.1, -5.0)  # the recording moves off at 5 m/s
    assert -5.0 <= v < 0.0 and x < 30.0


def test_relax_must_be_true_or_false():
    with pytest.raises(TwinError, match="relax must be true or false"):
        CosimConfig(relax="yes")
    with pytest.raises(TwinError, match="anchor must be true or false"):
        CosimConfig(anchor=1)
    with pytest.raises(TwinError, match="anchor needs relax"):
        CosimConfig(relax=False, anchor=True)


def test_anchors_follow_relax_unless_set():
    # anchored ghosts are the default wherever vehicles relax; the paper's hand-over
    # (--no-relax, relax = false in a file or --set) turns them off with relaxation
    # (before, the preset's resolved anchor = true made every such run an error)
    assert SCENARIO_B.anchor and CosimConfig().anchor
    assert not override(SCENARIO_B, {"relax": False}, source="command line").anchor
    assert not from_toml("relax = false").anchor
    assert not override(SCENARIO_B, {"anchor": False}).anchor  # relaxation alone
    paper = override(SCENARIO_B, {"relax": False})
    assert override(paper, {"relax": True}).anchor  # relaxing again: anchored again
    with pytest.raises(TwinError, match="anchor needs relax"):
        from_toml("relax = false\nanchor = true")
    with pytest.raises(TwinError, match="anchor must be bool"):
        override(SCENARIO_B, {"anchor": "yes"})


def test_a_vehicle_far_ahead_of_its_recording_eases_off_without_stopping_in_its_lane(cosim):
    # SUMO's on-ramp morning, episode 17: a body drove on at its desired speed where its
    # recording crawled at 8 m/s, left the visible window 160 m ahead of it, braked to a
    # stand there to wait for it and stopped the visible traffic in its lane behind it.
    # Here the ego (lane -2) and two recordings in lane -3 crawl at 8 m/s; the bodies run free
    # toward 30 m/s, leave the window far ahead of their recordings and relax: each
    # slows toward its recording no further than EASE_SHARE of its speed (a little more
    # where its car following brakes it behind the other), and neither stops
    ahead, behind = vehicle(2, -3, EGO_X + 100.0, 8.0), vehicle(3, -3, EGO_X + 60.0, 8.0)
    sim = cosim([vehicle(1, -2, EGO_X, 8.0), ahead, behind], world="kinematic", dt=0.1,
                t_max=30.0)  # fmt: skip
    sim.run()
    frame = sim.log.vehicles()
    section = handover_section(frame, sim.log.windows(), sim.traffic, sim.config.road,
                               sim.t0, sim.config.dt, sim.limits)  # fmt: skip
    relaxing = section["relaxing"]
    assert relaxing["vehicles"] >= 1 and relaxing["distance_m"]["max"] > 50.0  # far ahead
    for n in (2, 3):
        rows = frame[frame["tid"] == tid_of(sim, n)]
        assert len(rows) > 0 and rows["speed"].min() >= relax.EASE_SHARE * 8.0 - 0.5, n
        assert rows["speed"].min() <= relax.EASE_SHARE * 8.0 + 0.1, n  # it did slow for it
    assert sim.counters.contacts == 0


def _driven(doc: dict, speed) -> dict:
    """``doc`` (a westbound recording, sampled at T0) driven at ``speed(t)`` [m/s] (``t``
    [s] from T0, an array in and out) through where it is at T0."""
    t = np.asarray(doc["timestamp"]) - T0
    v = speed(t)
    travelled = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t))])
    at_t0 = int(np.argmin(np.abs(t)))
    x_ft = doc["x_position"][at_t0] - (travelled - travelled[at_t0]) / i24.FT
    return {**doc, "x_position": x_ft.tolist(), "starting_x": float(x_ft[0]),
            "ending_x": float(x_ft[-1])}  # fmt: skip


def test_a_vehicle_far_ahead_of_its_recording_keeps_up_with_it_as_it_speeds_up(cosim):
    # SUMO's on-ramp morning, seed 1, episode 1: bodies that had raced ahead of their
    # recordings in lane -3 braked behind its queue, moved back into lane -4 and, ahead of
    # their recordings, held 1.8 and 4.6 m/s for half a minute while their recordings sped
    # up to 9 m/s and the recorded traffic ahead of them drove at 18: lane -4 crawled
    # behind them and the ego ended 800 m short of its recording. Here the two recordings
    # of the test above crawl at 8 m/s, then speed up to 16; the bodies that eased off far
    # ahead of them speed up too, to EASE_SHARE of their recordings' speed (no recorded
    # traffic is ahead of them)
    docs = [vehicle(1, -2, EGO_X, 8.0, seconds=70.0)]
    starts = {2: EGO_X + 100.0, 3: EGO_X + 60.0}

    def speeding_up(t):  # [m/s] from 25 s, at 1 m/s^2
        return np.clip(8.0 + (t - 25.0), 8.0, 16.0)

    for n, x in starts.items():
        docs.append(_driven(vehicle(n, -3, x, 8.0, seconds=70.0), speeding_up))
    sim = cosim(docs, world="kinematic", dt=0.1, t_max=50.0)
    sim.run()
    frame = sim.log.vehicles()
    for n, x in starts.items():
        rows = frame[frame["tid"] == tid_of(sim, n)]
        # its recording: 8 m/s for 25 s, 96 m speeding up, then 16 m/s from 33 s
        rec_x = x + 8.0 * 25.0 + 96.0 + 16.0 * (rows["time"] - 33.0)
        late = rows[(rows["time"] >= 33.0) & (rows["x"] > rec_x)]  # still ahead of it
        assert len(late) > 0, n
        assert late["speed"].max() >= relax.EASE_SHARE * 16.0 - 1.0, n
    assert sim.counters.contacts == 0


def test_a_vehicle_far_ahead_of_its_recording_keeps_up_with_the_recorded_traffic_ahead(cosim):
    # The same episode: the recorded traffic ahead of those bodies drove 18 m/s where
    # their own recordings, far behind, crawled. Here a body's recording crawls at 4 m/s
    # in lane -3 while a stream of recordings drives 12 m/s through the ghost cell ahead
    # (each appearing 175 m ahead of the ego, 5 s apart); the body, leading its lane,
    # chases them into the ghost cell and, ahead of its recording, keeps up with them
    # rather than slowing to EASE_SHARE of its own recording's speed and holding the lane
    # there (on the old law it braked to 3.9 m/s, fell back into the visible window, chased
    # them again, and so on)
    docs = [vehicle(1, -2, EGO_X, 8.0, seconds=70.0), vehicle(2, -3, EGO_X + 100.0, 4.0)]
    for k in range(10):
        start = 5.0 * k
        docs.append(vehicle(10 + k, -3, EGO_X + 175.0 - 4.0 * start, 12.0, start=start))
    sim = cosim(docs, world="kinematic", dt=0.1, t_max=45.0)
    sim.run()
    frame = sim.log.vehicles()
    ego = frame[frame["tid"] == tid_of(sim, 1)].set_index("time")["x"]
    rows = frame[frame["tid"] == tid_of(sim, 2)]
    ahead = rows["x"].to_numpy() - ego.loc[rows["time"]].to_numpy()
    out = rows[ahead > sim.config.w_visible]  # relaxing in the ghost cell
    assert len(out) > 10  # it got there, far ahead of its recording
    # their speed less a tenth of its recording's (it still closes in on it a little),
    # but where one of them appears close ahead of it and its car following brakes it
    kept = 12.0 - (1.0 - relax.EASE_SHARE) * 4.0
    assert np.median(out["speed"]) >= kept - 0.1
    assert sim.counters.contacts == 0


def test_a_vehicle_a_little_ahead_of_its_recording_behind_recorded_traffic_is_handed_back(cosim):
    # A body a few metres ahead of its recording, behind recorded traffic driving as its
    # recording does, still closes in (at a tenth of its recording's speed) and becomes
    # its recording again, rather than keeping up with that traffic at its offset. Here
    # the body's recording dips from 8 to 6 m/s and falls 8 m behind a steady drive; the
    # body does not dip (it leads lane -3, behind a recording at 8 m/s in the ghost cell),
    # and leaves the slower ego's window 7 m ahead of its recording
    docs = [
        vehicle(1, -2, EGO_X, 6.0, seconds=70.0),
        vehicle(3, -3, EGO_X + 170.0, 8.0, seconds=70.0),
    ]
    dip = _driven(vehicle(2, -3, EGO_X + 120.0, 8.0, seconds=70.0),
                  lambda t: 8.0 - np.clip(np.minimum(t - 4.0, 10.0 - t), 0.0, 2.0))  # fmt: skip
    docs.append(dip)
    sim = cosim(docs, world="kinematic", dt=0.1, t_max=40.0)
    sim.run()
    frame, ghosts = sim.log.vehicles(), sim.log.ghosts()
    rows = frame[frame["tid"] == tid_of(sim, 2)]
    # of its recording, which is 8 m behind a steady 8 m/s past its dip
    ahead = rows["x"] - (EGO_X + 120.0 + 8.0 * rows["time"] - 8.0)
    assert ahead[(rows["time"] - 16.0).abs() < 1e-6].iloc[0] > 5.0  # a few metres, relaxing
    assert (ghosts["tid"] == tid_of(sim, 2)).any()  # handed back: a ghost again


def test_a_relaxing_vehicle_keeps_its_recordings_place_across_its_lane_and_is_handed_back(cosim):
    # SUMO's sub-lane drivers (SL2015) drive up to 1.6 m off their lane's centre. A body
    # relaxing toward such a recording kept the traffic core's centre line, so it was
    # never within HAND_BACK_Y of its recording (never handed back), and a body made of
    # such a recording steered back to the centre into another recording passing it
    # inside the lane (test family, day 1017 episode 15). Here the body of the test
    # above follows a recording 0.8 m off lane -3's centre (1.83 m wide, it stays inside
    # the lane): relaxing, it moves across to its recording's place and is handed back
    off = -0.8
    docs = [
        vehicle(1, -2, EGO_X, 6.0, seconds=70.0),
        vehicle(3, -3, EGO_X + 170.0, 8.0, seconds=70.0),
    ]
    dip = _driven(vehicle(2, -3, EGO_X + 120.0, 8.0, seconds=70.0),
                  lambda t: 8.0 - np.clip(np.minimum(t - 4.0, 10.0 - t), 0.0, 2.0))  # fmt: skip
    dip["y_position"] = [y + off / i24.FT for y in dip["y_position"]]
    docs.append(dip)
    sim = cosim(docs, world="kinematic", dt=0.1, t_max=40.0)
    sim.run()
    frame, ghosts = sim.log.vehicles(), sim.log.ghosts()
    rows = frame[frame["tid"] == tid_of(sim, 2)]
    centre = 3.5 * i24.LANE_WIDTH
    assert abs(rows["y"].iloc[0] - (centre + off)) < 0.05  # spawned at its recorded place
    in_window = rows[(rows["time"] - 10.0).abs() < 1e-6]
    assert abs(in_window["y"].iloc[0] - centre) < 0.1  # visible, it drove the lane's centre
    # the last step it was a body, relaxing in the front ghost cell
    assert abs(rows["y"].iloc[-1] - (centre + off)) <= relax.HAND_BACK_Y
    assert (ghosts["tid"] == tid_of(sim, 2)).any()  # handed back: a ghost again
    assert sim.counters.contacts == 0


@pytest.mark.parametrize(
    ("y", "want", "other", "expected"),
    [
        (0.0, 1.4, 5.0, 1.4),  # nothing near on that side: its recording's place
        (0.0, 1.4, 2.5, 0.3),  # one alongside 2.5 m across: 2.2 m from it
        (0.0, 1.4, 1.0, 0.0),  # already nearer than that: it moves no closer
        (0.0, 1.4, -2.5, 1.4),  # one on the other side: no matter
        (0.0, -1.4, -2.5, -0.3),
        (1.0, 0.0, 2.0, 0.0),  # moving away from one it is near: free to
    ],
)
def test_a_relaxing_vehicle_moves_across_no_nearer_a_vehicle_alongside(y, want, other, expected):
    assert relax.short_of(y, want, other, 2.2) == pytest.approx(expected)


def test_a_relaxing_driver_back_in_the_visible_window_draws_strategic_targets(
    calibrated_wave_store, built_map, tmp_path
):
    # SUMO development day 3 (twin data sumo --family): in stop-and-go most recorded
    # vehicles reach the visible window's rear as relaxing bodies (made bodies behind a
    # body they crowd in the ghost cell), and came in without strategic targets, which
    # relaxing clears: the recording's lane-change flows went undriven (178 lane changes
    # against the recording's 297 on 12 episodes; 201 drawing them). Every driver that
    # comes back into the window draws them, as a vehicle spawned there does.
    doc = json.loads((calibrated_wave_store.path / "calibration.json").read_text())
    flows = doc["roads"]["westbound"]["lane_flows"]
    bins = len(flows["x_edges"]) - 1
    flows["strategic"] = {"-2>-3": {"probability": [0.02] * bins},
                          "-3>-2": {"probability": [0.02] * bins}}  # fmt: skip
    store = with_section(calibrated_wave_store, tmp_path / "store", "lane_flows",
                         {**flows, "identified": True})  # fmt: skip
    config = CosimConfig(world="kinematic", t_max=60.0, behaviour="calibrated")
    shared = Shared.make(store, built_map, config)
    assert shared.settings.targets
    t_first, _ = store.time_range(config.road)
    run = Batch(shared, episodes=4)
    for b in range(4):
        run.reset(b, lane=-2, x=700.0, time=t_first + 60.0 + 60.0 * b, seed=b)
    state = run.state
    was_relaxing = state.slots.relaxing & state.bodies.valid
    entered, without = 0, 0
    while not run.done.all():
        run.step()
        bo, sl, ep = state.bodies, state.slots, state.episodes
        for b, i in zip(*np.nonzero(bo.valid & was_relaxing & ~sl.relaxing), strict=True):
            if i != ep.ego[b] and ep.windows[b, 1] <= bo.x[b, i] <= ep.windows[b, 2]:
                entered += 1
                without += state.drivers.ctrl[b, i] == 0 and not sl.tgt_on[b, i]
        was_relaxing = sl.relaxing & bo.valid
    assert entered > 0 and without == 0, (entered, without)


def test_a_ghost_that_cannot_stop_behind_a_body_ahead_is_drawn_braking_for_it(cosim):
    # a recording closing on a relaxing body faster than it could be made a body behind it
    # (a yield needs room to stop at a yield's braking) drove on into it: 9 of the 22
    # collisions on the SUMO test family (16 x 120 s per day, kinematic). Here three
    # recordings drive 15 m/s in lane -3 beyond the visible window's front edge, a ghost
    # each, and a body stands in their lane 10 m ahead of the middle one's back (the ego,
    # moved there): the middle one, which could not stop behind it braking as hard as
    # a yield may (so could not be made a body there), is anchored where it is and
    # drawn braking for it; the one far behind and the one ahead of the body are not
    sim = cosim(
        [vehicle(1, -2, EGO_X, 15.0), vehicle(2, -3, EGO_X + 152.0, 15.0),
         vehicle(3, -3, EGO_X + 185.0, 15.0), vehicle(4, -3, EGO_X + 197.0, 15.0)],
        world="kinematic", t_max=2.0,
    )  # fmt: skip
    state, core = sim.state, sim.core
    gh, bo, table, ep = state.ghosts, state.bodies, state.table, state.episodes
    rows = {int(gh.r[0, g]): g for g in range(gh.count[0])}
    middle = rows[tid_of(sim, 3)]
    assert len(rows) == 3
    ego = ep.ego[0]
    bo.x[0, ego], bo.y[0, ego], bo.lane[0, ego] = gh.x[0, middle] + 10.0, gh.y[0, middle], -3
    bo.speed[0, ego] = 0.0
    _brake_ghosts(0, core)
    anchored = {r for r, g in rows.items() if _flags(table, r) & layout.ANCHORED}
    assert anchored == {tid_of(sim, 3)} and ep.ghosts_braked[0] == 1
    h = int(np.flatnonzero(table.key[0] == tid_of(sim, 3))[0])
    assert (table.off_x[0, h], table.off_v[0, h]) == (0.0, 0.0)  # drawn where it was
    _decay(0, core)
    assert table.off_v[0, h] == pytest.approx(-anchor.BRAKE * sim.config.dt)  # braking


@kernel(nrt=True)  # called from Python with the struct
def _brake_ghosts(b, core):
    anchor.brake_ghosts(b, core, handover.YIELD_DECEL)


@kernel(nrt=True)
def _decay(b, core):
    anchor.decay(b, core)


def _flags(table, r):
    return int(table.flags[0][table.key[0] == r][0])


@kernel(nrt=True)
def _path_offset(b, core, i):
    return relax.path_offset(b, core, i)


def test_a_relaxing_vehicle_whose_recording_is_in_the_next_lane_keeps_to_that_side(cosim):
    # a motorcycle made a body 1.8 m off its lane's centre, its recording crossing into
    # the next lane, steered back to the centre (the offset was 0 wherever the recording
    # was in another lane) into a recording behind it (test family, day 1005 episode
    # 10). Its path keeps to the side of its lane toward its recording's, footprint
    # IN_LANE inside the line, where the change it asks for toward it begins
    sim = cosim([vehicle(1, -2, EGO_X, 20.0), vehicle(2, -3, EGO_X + 60.0, 20.0)],
                world="kinematic", t_max=1.0)  # fmt: skip
    state = sim.state
    bo, sl = state.bodies, state.slots
    i = int(
        np.flatnonzero(bo.valid[0] & (np.arange(bo.valid.shape[1]) != state.episodes.ego[0]))[0]
    )
    centre, half = 3.5 * i24.LANE_WIDTH, 0.5 * bo.width[0, i]
    inside = 0.5 * i24.LANE_WIDTH - half - relax.IN_LANE
    for rec_y, expected in ((centre + i24.LANE_WIDTH, inside), (centre - 0.3, -0.3),
                            (centre - 2 * i24.LANE_WIDTH, -inside)):  # fmt: skip
        sl.rec_on[0, i], sl.rec_y[0, i] = True, rec_y
        assert _path_offset(0, sim.core, i) == pytest.approx(expected), rec_y


@kernel(nrt=True)
def _ease_offset(b, core, i):
    relax.ease_offset(b, core, i)


def test_a_visible_vehicle_off_its_lanes_centre_goes_back_only_as_far_as_is_clear(cosim):
    # a body made of a sub-lane driver's recording 1 m off its lane's centre, visible
    # again, steered back to the centre at once (its offset was set to 0) into a recorded
    # bus passing beside it inside the lane (test family, day 1013 episode 0). It goes
    # back no nearer than BESIDE_GAP across to one alongside, and the rest of the way
    # once that one is past; changing lanes, it drives the change's path (offset 0)
    sim = cosim([vehicle(1, -2, EGO_X, 20.0), vehicle(2, -3, EGO_X + 60.0, 20.0)],
                world="kinematic", t_max=1.0)  # fmt: skip
    state = sim.state
    bo, dr, ep = state.bodies, state.drivers, state.episodes
    i = int(np.flatnonzero(bo.valid[0] & (np.arange(bo.valid.shape[1]) != ep.ego[0]))[0])
    ego, centre = ep.ego[0], 3.5 * i24.LANE_WIDTH
    bo.y[0, i], dr.offset[0, i] = centre - 1.0, -1.0
    # the ego moved beside it, 1.5 m off the centre on the other side, as the bus was
    bo.x[0, ego], bo.y[0, ego], bo.speed[0, ego] = bo.x[0, i] - 2.0, centre + 1.5, bo.speed[0, i]
    apart = 0.5 * (bo.width[0, i] + bo.width[0, ego]) + relax.BESIDE_GAP
    assert 1.5 < apart < 2.5  # back on the centre, it would be nearer than that
    _ease_offset(0, sim.core, i)
    assert dr.offset[0, i] == pytest.approx(1.5 - apart)  # toward the centre, no nearer
    bo.y[0, i] = centre - 1.0
    bo.y[0, ego] = centre + 1.0  # one nearer than that already: it moves no closer
    _ease_offset(0, sim.core, i)
    assert dr.offset[0, i] == pytest.approx(-1.0)
    bo.x[0, ego] = bo.x[0, i] + bo.length[0, i] + relax.BESIDE_AHEAD + 1.0  # past it
    _ease_offset(0, sim.core, i)
    assert dr.offset[0, i] == 0.0
    dr.offset[0, i], bo.x[0, ego] = -1.0, bo.x[0, i]
    dr.lane[0, i] = -2  # a change to lane -2 begun (lane_from -3)
    _ease_offset(0, sim.core, i)
    assert dr.offset[0, i] == 0.0


def test_anchored_vehicles_behind_the_windows_keep_behind_one_another(cosim):
    # anchored vehicles outside the ghost windows are in no ghost set: a row of them
    # behind the windows, each closing in on its recording far ahead, drew level and
    # came into the rear ghost cell on top of one another, where a recorded vehicle made
    # a body there ran into four of them (test family, day 1003 episode 8, anchored).
    # Here two are anchored some 400 m behind the windows in lane -3, standing, 20 m
    # apart; the one ahead is 20 m behind its standing recording, the one behind 400 m:
    # closing in faster, it brakes for the one ahead and keeps behind it
    sim = cosim(
        [vehicle(1, -2, EGO_X, 15.0), vehicle(2, -3, EGO_X + 152.0, 15.0),
         vehicle(3, -3, EGO_X + 185.0, 15.0)],
        world="kinematic", t_max=2.0,
    )  # fmt: skip
    state, core = sim.state, sim.core
    table, ep = state.table, state.episodes
    front, back = (int(np.flatnonzero(table.key[0] == tid_of(sim, k))[0]) for k in (2, 3))
    lane_y = 3.5 * i24.LANE_WIDTH
    for a, (h, drawn, recorded) in enumerate(((front, 120.0, 140.0), (back, 100.0, 500.0))):
        table.flags[0, h] |= layout.ANCHORED
        ep.anchors[0, a] = h
        table.rec_x[0, h], table.rec_y[0, h], table.rec_v[0, h] = recorded, lane_y, 0.0
        table.off_x[0, h], table.off_v[0, h] = drawn - recorded, 0.0
        table.off_y[0, h], table.off_vy[0, h] = 0.0, 0.0
    ep.anchor_count[0] = 2
    length = sim.traffic.recording("westbound").length[table.key[0, back]]
    assert ep.windows[0, 0] > 500.0
    gaps = []
    for _ in range(round(40.0 / sim.config.dt)):
        _decay(0, core)
        gaps.append(table.rec_x[0, front] + table.off_x[0, front]
                    - (table.rec_x[0, back] + table.off_x[0, back]) - length)  # fmt: skip
    assert min(gaps) >= anchor.FOLLOW_GAP - 0.5, min(gaps)


def test_a_ghost_holds_its_line_beside_a_body_changing_lanes_toward_it(cosim):
    # a relaxing car changing into lane -3 beside a recorded truck drifting toward it
    # from lane -4 (a sub-lane driver) was too far across for the truck to hold its line
    # until they touched (test family, day 1002 episode 14): where a body changes lanes
    # the ghost is judged beside it from the new lane's centre too
    truck = vehicle(3, -4, EGO_X + 151.0, 20.0)
    truck["y_position"] = [y - 1.46 / i24.FT for y in truck["y_position"]]  # 15.0 m
    sim = cosim([vehicle(1, -2, EGO_X, 20.0), vehicle(2, -2, EGO_X + 147.0, 20.0), truck],
                world="kinematic", t_max=1.0)  # fmt: skip
    state, core = sim.state, sim.core
    bo, dr, table, gh = state.bodies, state.drivers, state.table, state.ghosts
    i = int(
        np.flatnonzero(bo.valid[0] & (np.arange(bo.valid.shape[1]) != state.episodes.ego[0]))[0]
    )
    assert tid_of(sim, 3) in set(gh.r[0, : gh.count[0]].tolist())  # a ghost, alongside
    _brake_ghosts(0, core)
    assert not _flags(table, tid_of(sim, 3)) & layout.ANCHORED  # 5.9 m across: not beside
    dr.lane[0, i] = -3  # its change into lane -3 begun (lane_from -2)
    _brake_ghosts(0, core)
    assert _flags(table, tid_of(sim, 3)) & layout.ANCHORED  # it holds its line
