"""Contacts as the core records them (twin/cosim/core/step.py): a body on a ghost's
recorded box is a contact, found by footprints and kept with both vehicles' roles;
recorded vehicles that crowd a relaxing body become bodies behind it. The embedded
morning, kinematic world, six episodes of 60 s."""

import math

import numpy as np
import pytest

from mapgen.build import default_map
from twin.cosim.config import CosimConfig
from twin.cosim.core import layout
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
