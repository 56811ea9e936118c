"""The recording in memory (``twin/data/recording.py``): a large road is cached inside
its store and memory-mapped, the same arrays as built in memory; a store written again
gets a new cache and the old one goes; a read-only store caches in the twin's cache
folder; the window index finds exactly the vehicles a scan of every trajectory finds."""

import numpy as np
import pytest

from tests.conftest import read_only_store, store_written_again
from twin.data import recording


@pytest.fixture
def store(private_wave_store):
    """A private copy of the session's wave store (the tests write into it)."""
    recording.clear_loaded()
    yield private_wave_store
    recording.clear_loaded()


def _same(a, b):
    for name in a._fields:
        va, vb = getattr(a, name), getattr(b, name)
        if isinstance(va, np.ndarray):
            np.testing.assert_array_equal(np.asarray(va), np.asarray(vb), err_msg=name)
        else:
            assert va == vb, name


def test_a_large_road_is_cached_inside_its_store_and_memory_mapped(store, monkeypatch):
    monkeypatch.setattr(recording, "IN_MEMORY_SAMPLES", 0)
    loaded = recording.load_recording(store, "westbound")
    folder = recording.cached_folder(store, "westbound")
    assert folder.parent == store.path / ".recording" and (folder / "recording.json").is_file()
    assert isinstance(loaded.x, np.memmap)
    _same(loaded, recording.build(store, "westbound"))
    recording.clear_loaded()
    assert recording.load_recording(store, "westbound").x.filename == loaded.x.filename


def test_a_store_written_again_gets_a_new_cache_and_the_old_one_goes(store, monkeypatch):
    monkeypatch.setattr(recording, "IN_MEMORY_SAMPLES", 0)
    recording.load_recording(store, "westbound")
    old = recording.cached_folder(store, "westbound")
    again = store_written_again(store)
    recording.load_recording(again, "westbound")
    new = recording.cached_folder(again, "westbound")
    assert new != old and new.is_dir() and not old.exists()


def test_a_read_only_store_caches_in_the_twins_cache_folder(store, monkeypatch, tmp_path):
    monkeypatch.setattr(recording, "IN_MEMORY_SAMPLES", 0)
    read_only_store(store, monkeypatch, tmp_path / "cache")
    recording.load_recording(store, "westbound")
    folder = recording.cached_folder(store, "westbound")
    assert folder.parent == tmp_path / "cache" and folder.is_dir()
    assert not (store.path / ".recording").exists()
    recording.remove_cached(store)
    assert not folder.exists()


def test_the_window_index_finds_what_a_scan_of_every_trajectory_finds(store):
    rec = recording.load_recording(store, "westbound")
    t0, t1 = store.time_range("westbound")
    rng = np.random.default_rng(3)
    out = tuple(np.empty(2048, t) for t in (np.int32, float, float, float))
    for t, x0 in zip(rng.uniform(t0, t1, 25), rng.uniform(0.0, 1500.0, 25), strict=True):
        n = recording.window(rec, t, x0, x0 + 300.0, *out)
        found = sorted(int(r) for r in out[0][:n])
        expected = []
        for r in range(rec.tid.size):
            present, x, _, _ = recording.replay(rec, r, t)
            if present and x0 <= x <= x0 + 300.0:
                expected.append(r)
        assert found == expected
        assert np.all(np.diff(out[1][:n]) >= 0)  # sorted by x


def test_a_memory_mapped_recording_has_the_in_memory_ones_kernel_types(store, monkeypatch):
    """Read-only maps are another Numba type: every kernel would compile twice."""
    import numba

    monkeypatch.setattr(recording, "IN_MEMORY_SAMPLES", 0)
    mapped = recording.load_recording(store, "westbound")
    assert isinstance(mapped.x, np.memmap)
    assert numba.typeof(mapped) == numba.typeof(recording.build(store, "westbound"))
    before = mapped.x[0]
    recording.clear_loaded()
    assert recording.load_recording(store, "westbound").x[0] == before  # the file unchanged


def test_a_replay_is_its_recorded_samples_interpolated(wave_store):
    """At any time a trajectory is where, and as fast as, the line between its two
    recorded samples around that time says, in the wave's braking and speeding up: a
    replay (every ghost, every spawn's speed) reads the frames around its time, not the
    next ones (one frame, 0.04 s, is 1 m at 25 m/s and up to 0.09 m/s in the wave).
    The tolerances are the recording's resampling to its 25 Hz grid (at most 0.045 m
    and 0.007 m/s on these trajectories)."""
    rec = recording.load_recording(wave_store, "westbound")
    rng = np.random.default_rng(7)
    changing = 0
    for r in rng.choice(rec.tid.size, 40, replace=False).tolist():
        samples = wave_store.trajectory(int(rec.tid[r]))
        t = samples["t"]
        times = rng.uniform(t[0], t[-1], 20)
        replayed = np.array([recording.replay(rec, r, s) for s in times], dtype=float)
        assert replayed[:, 0].all()  # present
        x = np.interp(times, t, samples["x"])
        speed = np.maximum(np.interp(times, t, samples["speed"].astype(np.float64)), 0.0)
        np.testing.assert_allclose(replayed[:, 1], x, rtol=0, atol=0.1)
        np.testing.assert_allclose(replayed[:, 3], speed, rtol=0, atol=0.01)
        changing += np.ptp(samples["speed"]) > 1.0
    assert changing >= 10  # the wave's: their speeds change between samples
