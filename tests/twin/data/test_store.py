"""The store's reads: samples sorted by (tid, t) exactly as a full sort sorts them."""

import numpy as np
import pytest

from twin.data.store import _by_tid_then_t


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
