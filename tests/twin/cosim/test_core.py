"""The batched core (``twin/cosim/core``): an episode is the same bytes alone or at any
place in a batch, a full slot table refuses spawns and counts them without touching a
vehicle, a capacity outgrown is named, and no kernel reads or writes out of bounds."""

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from tests.twin.cosim.scenes import EGO_X, T0, make_store, vehicle
from twin.core.paths import cache_dir
from twin.cosim.config import CosimConfig
from twin.cosim.core.batch import Batch, CoreError, Shared

SECONDS = 8.0


def _docs():
    """The ego in lane -2 at EGO_X and 30 vehicles around it in four lanes, some slower
    than their neighbours (lane changes), all within the visible window."""
    docs = [vehicle(0, -2, EGO_X, 25.0, seconds=60.0)]
    for k in range(30):
        lane = -1 - k % 4
        x = EGO_X - 240.0 + 16.0 * k + 3.0 * (k % 3)
        if lane == -2 and abs(x - EGO_X) < 12.0:
            x += 14.0
        docs.append(vehicle(k + 1, lane, x, 22.0 + (k * 7) % 9, seconds=60.0))
    return docs


@pytest.fixture(scope="module")
def shared(built_map, tmp_path_factory):
    store = make_store(tmp_path_factory.mktemp("core"), _docs())
    config = CosimConfig(
        road="westbound", lane=-2, x=EGO_X, time=T0, vel_default=30.0, world="kinematic",
        t_max=SECONDS,
    )  # fmt: skip
    return Shared.make(store, built_map, config)


def _run(shared, episodes, seeds, **capacities):
    batch = Batch(shared, len(episodes), **capacities)
    for b, (x, seed) in enumerate(zip(episodes, seeds, strict=True)):
        batch.reset(b, lane=-2, x=x, time=T0, seed=seed)
    while not batch.done.all():
        batch.step()
    return batch


def _rows(batch, b):
    log = batch.state.log
    return b"".join(
        np.ascontiguousarray(getattr(log, f)[b]).tobytes()
        for f in ("id", "r", "lane", "x", "y", "z", "speed", "accel_cmd", "yaw")
    )


def test_an_episode_is_the_same_bytes_alone_or_anywhere_in_a_batch(shared):
    alone = _run(shared, [EGO_X], [5])
    assert alone.state.episodes.spawned_initially[0] > 12
    batched = _run(shared, [EGO_X - 40.0, EGO_X + 30.0, EGO_X, EGO_X], [1, 2, 5, 9])
    assert _rows(batched, 2) == _rows(alone, 0)
    assert _rows(batched, 3) != _rows(alone, 0)  # another seed, other draws
    again = _run(shared, [EGO_X], [5])
    assert _rows(again, 0) == _rows(alone, 0)


def test_the_steps_phases_in_turn_over_every_episode_are_the_step(shared):
    """twin bench env --profile times the phases apart: the same bytes as the step."""
    from twin.cosim.core.step import PHASES, phase_batch

    stepped = _run(shared, [EGO_X, EGO_X - 50.0], [5, 6])
    phased = Batch(shared, 2)
    for b, (x, seed) in enumerate(((EGO_X, 5), (EGO_X - 50.0, 6))):
        phased.reset(b, lane=-2, x=x, time=T0, seed=seed)
    while not phased.done.all():
        for k in range(len(PHASES)):
            phase_batch(phased.core, k)
    for b in range(2):
        assert _rows(phased, b) == _rows(stepped, b)


def test_a_full_slot_table_refuses_and_counts_spawns(shared):
    full = _run(shared, [EGO_X], [5], slots=12)
    ep, st = full.state.episodes, full.state
    assert ep.skipped_full[0] > 0
    valid = st.bodies.valid[0]
    assert valid.sum() <= 12
    assert len(set(st.slots.r[0][valid])) == valid.sum()  # nobody overwritten
    # every slot's log keeps one vehicle's identity from its spawn to its removal
    ids = st.log.id[0]
    for slot in range(ids.shape[1]):
        seen = ids[:, slot][ids[:, slot] >= 0]
        changes = np.flatnonzero(np.diff(ids[:, slot]) != 0)
        assert all(ids[c, slot] == -1 or ids[c + 1, slot] == -1 for c in changes), seen


def test_an_outgrown_capacity_is_named(shared):
    with pytest.raises(CoreError, match=r"episode 0 outgrew the batch: more than 4 recorded"):
        _run(shared, [EGO_X], [5], snapshot=4)


def test_an_action_that_is_not_finite_names_the_episode(shared):
    batch = Batch(shared, 2)
    batch.reset(0, lane=-2, x=EGO_X, time=T0, seed=1)
    batch.reset(1, lane=-2, x=EGO_X, time=T0, seed=2)
    with pytest.raises(CoreError, match=r"episode 1: the action nan is not finite"):
        batch.step(np.array([0.0, np.nan]))


def test_the_kernels_called_from_python_release_the_struct(shared):
    """Kernels run without reference counting (twin.core.jit.register_struct); those
    Python calls with the packed struct count it, so that it is released: a leak would
    keep every array of every batch alive for the life of the process."""
    from twin.cosim.core.step import PHASES, phase_batch

    batch = Batch(shared, 2)
    held = batch.core._meminfo.refcount
    batch.reset(0, lane=-2, x=EGO_X, time=T0, seed=1)
    for _ in range(3):
        batch.step()
        phase_batch(batch.core, len(PHASES) - 1)
    assert batch.core._meminfo.refcount == held


def test_a_kernel_without_counting_refuses_the_struct_from_python(shared):
    from twin.cosim.core.step import move

    batch = Batch(shared, 1)
    held = batch.core._meminfo.refcount
    with pytest.raises(TypeError, match=r"needs reference counting: compile it with "
                       r"@kernel\(nrt=True\)"):  # fmt: skip
        move(0, batch.core)
    assert batch.core._meminfo.refcount == held


@pytest.mark.slow
def test_no_kernel_reads_or_writes_out_of_bounds(tmp_path):
    """Whole episodes with Numba's bounds checking on (its own compile cache): an
    out-of-bounds access raises IndexError and fails the child."""
    script = textwrap.dedent(
        f"""
        import numpy as np
        from mapgen.build import default_map
        from tests.twin.cosim.scenes import EGO_X, T0, make_store
        from tests.twin.cosim.test_core import _docs
        from twin.cosim.config import CosimConfig
        from twin.cosim.core.batch import Batch, Shared

        store = make_store(__import__("pathlib").Path({str(tmp_path)!r}), _docs())
        config = CosimConfig(road="westbound", lane=-2, x=EGO_X, time=T0,
                             vel_default=30.0, world="kinematic", t_max={SECONDS})
        shared = Shared.make(store, default_map(), config)
        for slots in (256, 12):
            batch = Batch(shared, 3, slots=slots)
            for b in range(3):
                batch.reset(b, lane=-2, x=EGO_X - 30.0 * b, time=T0, seed=b)
            while not batch.done.all():
                batch.step()
        print("spawned", batch.state.episodes.spawned.tolist())
        """
    )
    # a cache of its own (a checked build is never loaded by, or loads, unchecked code),
    # kept in the twin's cache folder: compiled once a machine, as the unchecked kernels
    checked = cache_dir() / "kernels-boundscheck"
    env = dict(os.environ, NUMBA_BOUNDSCHECK="1", NUMBA_CACHE_DIR=str(checked))
    done = subprocess.run(
        [sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=900,
        cwd=os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(__file__)))),
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-3000:]
    assert "spawned" in done.stdout


def test_an_episode_reset_in_a_used_slot_is_the_same_bytes_as_in_a_new_batch():
    """Everything an episode counts or carries starts afresh at its reset: on the
    embedded morning (relaxing vehicles, yields, contacts with ghosts) an episode run
    after another in the same slot is the one a new batch runs."""
    from mapgen.build import default_map
    from twin.data.embedded import embedded_store

    store = embedded_store("morning")
    shared = Shared.make(store, default_map(), CosimConfig(world="kinematic", t_max=60.0))
    t_first, _ = store.time_range("westbound")

    def run(batch, offset):
        batch.reset(0, lane=-2, x=700.0, time=t_first + offset, seed=3)
        while not batch.done.all():
            batch.step()
        ep, log = batch.state.episodes, batch.state.log
        on = log.id[0] >= 0  # the rows of the slots in use
        rows = [log.id[0].tobytes()] + [getattr(log, f)[0][on].tobytes() for f in ("x", "speed")]
        counts = {f: getattr(ep, f)[0].item() for f in ep._fields if getattr(ep, f)[0].size == 1}
        return rows, counts

    used = Batch(shared, 1)
    first = run(used, 380.0)
    again = run(used, 300.0)
    new = run(Batch(shared, 1), 300.0)
    assert first[1]["yielded"] > 0 and first[1] != new[1]
    assert again[0] == new[0]
    assert again[1] == new[1]
