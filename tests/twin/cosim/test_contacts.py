"""Contacts as the core records them (twin/cosim/core/step.py): a body on a ghost's
recorded box is a contact, found by footprints and kept with both vehicles' roles;
recorded vehicles that crowd a relaxing body become bodies behind it. The embedded
morning, kinematic world, six episodes of 60 s."""

import math

import numpy as np
import pytest

from mapgen.build import default_map
from twin.core.jit import kernel
from twin.cosim.config import CosimConfig
from twin.cosim.core import handover, layout
from twin.cosim.core.batch import Batch, Shared
from twin.data.embedded import embedded_store
from twin.data.recording import replay
from twin.physics.kernels import footprints_overlap

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


def _ghost_contacts(ep):
    for b in range(EPISODES):
        for row in ep.collision_log[b, : min(int(ep.collisions[b]), layout.COLLISIONS_KEPT)]:
            if int(row[4]) & layout.CONTACT_GHOST:
                yield b, row


def _touching(run, rec, dt, b, step, body, r) -> bool:
    """Whether body ``body``'s footprint overlaps recording ``r``'s box at ``step``."""
    log, ep = run.state.log, run.state.episodes
    slot = np.flatnonzero(log.id[b, step] == body)
    present, x, y, _ = replay(rec, r, float(ep.t0[b]) + step * dt)
    if not (present and slot.size):
        return False
    i = int(slot[0])
    half_length = 0.5 * run.state.bodies.length[b, i]
    half_width = 0.5 * run.state.bodies.width[b, i]
    return footprints_overlap(
        log.x[b, step, i] + half_length, log.y[b, step, i], log.yaw[b, step, i], half_length,
        half_width, x + 0.5 * rec.length[r], y, 0.0, 0.5 * rec.length[r], 0.5 * rec.width[r],
    )  # fmt: skip


def test_a_body_on_a_ghosts_recorded_box_is_a_new_contact(batch):
    run, shared, dt = batch
    rec = shared.recording
    r_of = {int(tid): r for r, tid in enumerate(rec.tid)}
    checked = 0
    for b, row in _ghost_contacts(run.state.episodes):
        time, body, key = float(row[0]), int(row[1]), int(row[2])
        assert key <= layout.GHOST_ID_BASE < 0 <= body  # the ghost second, below every body
        r = r_of[layout.GHOST_ID_BASE - key]
        assert _touching(run, rec, dt, b, round(time / dt), body, r)  # a true overlap
        assert row[5] in (-1, -2, -3, -4) and math.isfinite(row[6])  # the ghost's lane, speed
        checked += 1
    assert checked > 0  # this morning has them: lagging relaxing bodies overtaken


def test_recorded_vehicles_crowding_a_relaxing_body_become_bodies_behind_it(batch):
    run, _, _ = batch
    ep = run.state.episodes
    assert ep.yielded.sum() > 0
    # each became a relaxing body spawned at its recorded state: its speed checked
    errors = np.concatenate(
        [ep.spawn_errors[b, : ep.spawn_error_count[b]] for b in range(EPISODES)]
    )
    assert errors.max() <= 0.005


def test_contact_flags_say_who_was_relaxing(batch):
    run, _, _ = batch
    flags = [int(row[3]) for _, row in _ghost_contacts(run.state.episodes)]
    assert any(f & layout.CONTACT_RELAXING for f in flags)


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
