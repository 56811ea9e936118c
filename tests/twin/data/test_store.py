"""The store's reads: samples sorted by (tid, t) exactly as a full sort sorts them, and
the store versions it reads."""

import json

import numpy as np
import pytest

from tests.conftest import make_doc, write_day
from twin.core.errors import StoreError
from twin.data.ingest import ingest
from twin.data.store import FORMAT_VERSION, TrajectoryStore, _by_tid_then_t


@pytest.mark.parametrize("seed", range(6))
def test_samples_are_ordered_as_the_full_sort_orders_them(seed):
    """The fast path (a stable sort by tid, where each trajectory's samples come in
    time order) and the fallback both give np.lexsort's order, ties included."""
    rng = np.random.default_rng(seed)
    for _ in range(100):
        n = int(rng.integers(0, 80))
        tid = rng.integers(0, 6, n).astype(np.int32)
        if seed % 2:  # each trajectory in time order, ties included: the fast path
            t = np.sort(rng.choice([0.0, 0.04, 0.08, 0.12], n))
        else:  # any order: the fallback
            t = rng.choice([0.0, 0.04, 0.08, 0.12], n)
        assert np.array_equal(_by_tid_then_t(tid, t), np.lexsort((t, tid)))


def test_a_version_1_store_is_read_and_an_unknown_version_is_refused(tmp_path):
    """Version 2 added the acceleration lanes' samples; a version 1 store (none of them)
    is read as written, a store of a version this twin does not know is refused."""
    ingest([write_day(tmp_path / "d.json", [make_doc()])], tmp_path / "s", progress=False)
    meta_path = tmp_path / "s" / "metadata.json"
    meta = json.loads(meta_path.read_text())
    assert meta["version"] == FORMAT_VERSION == 2
    for version in (1, 99):
        meta["version"] = version
        meta_path.write_text(json.dumps(meta))
        if version == 1:
            assert len(TrajectoryStore(tmp_path / "s").trajectories) == 1
        else:
            with pytest.raises(StoreError, match="store version 99, this twin reads versions 1, 2"):
                TrajectoryStore(tmp_path / "s")
