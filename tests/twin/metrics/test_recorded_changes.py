"""The recording's lane changes (``twin/metrics/recorded_changes.py``): found once per
store and kept beside its cached recording (in the twin's cache for a read-only
store); a later process reads the same arrays; a damaged file is found again, an
unwritable place costs only time, a store written again leaves no stale file and
spares the other roads' and the recordings' files; a run's window selects them by
time."""

from dataclasses import fields

import numpy as np
import pytest

from tests.conftest import read_only_store, store_written_again
from twin.calibration.following import lane_changes, load_grid
from twin.data import recording
from twin.data.store import TrajectoryStore
from twin.metrics import recorded_changes as rc


@pytest.fixture
def store(private_wave_store):
    """A private copy of the session's wave store (the tests write into it)."""
    rc.clear_loaded()
    yield private_wave_store
    rc.clear_loaded()


def _same(a, b):
    for f in fields(a):
        va, vb = getattr(a, f.name), getattr(b, f.name)
        assert va.dtype == vb.dtype and va.shape == vb.shape, f.name
        np.testing.assert_array_equal(va, vb, err_msg=f.name)


def _found(store):
    first, last = store.time_range("westbound")
    return lane_changes(load_grid(store, "westbound", first, last))


def test_the_changes_are_found_once_kept_beside_the_recording_and_read_again(store, monkeypatch):
    first = rc.whole_recording(store, "westbound")
    path = rc.changes_path(store, "westbound")
    assert path.parent == store.path / ".recording" and path.is_file()
    assert first.tid.size > 0
    _same(first, _found(store))
    rc.clear_loaded()  # a new process: read from the file, never found again
    monkeypatch.setattr(rc, "load_grid", lambda *a, **k: pytest.fail("found again"))
    _same(rc.whole_recording(TrajectoryStore(store.path), "westbound"), first)


@pytest.mark.parametrize("damage", ["not an npz file", "truncated", "arrays of other lengths"])
def test_a_damaged_file_is_found_again_and_replaced(store, damage):
    expected = rc.whole_recording(store, "westbound")
    path = rc.changes_path(store, "westbound")
    if damage == "not an npz file":
        path.write_bytes(b"not an npz file")
    elif damage == "truncated":
        path.write_bytes(path.read_bytes()[:300])
    else:
        arrays = {f.name: getattr(expected, f.name) for f in fields(expected)}
        np.savez(path, **{**arrays, "tid": arrays["tid"][:-1]})
    rc.clear_loaded()
    _same(rc.whole_recording(store, "westbound"), expected)
    rc.clear_loaded()
    _same(rc._read(path), expected)


def test_a_read_only_store_keeps_them_in_the_twins_cache(store, monkeypatch, tmp_path):
    read_only_store(store, monkeypatch, tmp_path / "cache")
    rc.whole_recording(store, "westbound")
    path = rc.changes_path(store, "westbound")
    assert path.parent == tmp_path / "cache" and path.is_file()
    assert not (store.path / ".recording").exists()


def test_a_place_that_cannot_be_written_costs_only_time(store, monkeypatch, tmp_path):
    blocked = tmp_path / "blocked"
    blocked.write_text("a file where the cache folder would be")
    monkeypatch.setattr(rc, "changes_path", lambda s, r: blocked / "x.lane-changes-v1.npz")
    _same(rc.whole_recording(store, "westbound"), _found(store))


def test_a_store_written_again_leaves_no_stale_file(store):
    rc.whole_recording(store, "westbound")
    old = rc.changes_path(store, "westbound")
    cache = store.path / ".recording"
    other_road = cache / old.name.replace("westbound-", "eastbound-")
    other_road.write_bytes(b"")
    (cache / old.name.split(".")[0]).mkdir()  # a cached recording's folder
    (cache / old.name.split(".")[0] / "recording.json").write_text("{}")
    again = store_written_again(store)
    rc.whole_recording(again, "westbound")
    new = rc.changes_path(again, "westbound")
    assert new != old and new.is_file() and not old.exists()
    assert recording.store_key(again) in new.name
    assert other_road.exists() and (cache / old.name.split(".")[0] / "recording.json").exists()


def test_a_window_keeps_the_changes_inside_it(store):
    every = rc.whole_recording(store, "westbound")
    t0, t1 = np.quantile(every.time, [0.25, 0.75])
    inside = rc.recorded_lane_changes(store, "westbound", t0, t1)
    keep = (every.time >= t0) & (every.time <= t1)
    assert 0 < inside.tid.size < every.tid.size
    np.testing.assert_array_equal(inside.tid, every.tid[keep])
    np.testing.assert_array_equal(inside.x, every.x[keep])
    np.testing.assert_array_equal(inside.exposure_km, every.exposure_km)
