import numpy as np
import pytest

from tests.conftest import make_doc, write_day
from twin.core.errors import NoVehicleNearError
from twin.core.i24 import SCENARIO_TIME
from twin.data.empirical import EmpiricalTraffic
from twin.data.ingest import ingest
from twin.data.store import TrajectoryStore


def _reference(store, road, t, x_min, x_max):
    """Independent answer: np.interp on each trajectory's raw samples.

    Returns {tid: (x, bound)}: resampling the 25 Hz polyline onto another 25 Hz grid
    and interpolating again departs from it by at most a quarter of the polyline's
    largest second difference near t (the chord across one kink), so ``bound`` is that.
    """
    s = store.samples(road, t - 2.0, t + 2.0)
    out = {}
    for tid in np.unique(s["tid"]):
        rows = s["tid"] == tid
        ts, xs = s["t"][rows], s["x"][rows]
        if ts[0] <= t <= ts[-1]:
            x = float(np.interp(t, ts, xs))
            if x_min <= x <= x_max:
                near = np.abs(ts - t) <= 0.1
                kinks = np.abs(np.diff(xs[near], 2)) if near.sum() >= 3 else np.zeros(1)
                out[int(tid)] = (x, 0.25 * float(kinks.max()) + 1e-4)
    return out


def test_snapshots_agree_with_interpolating_the_raw_samples(wave_store):
    traffic = EmpiricalTraffic(wave_store)
    rng = np.random.default_rng(7)
    for t in SCENARIO_TIME + rng.uniform(-200.0, 150.0, 25):
        snap = traffic.snapshot("westbound", float(t), 300.0, 700.0)
        reference = _reference(wave_store, "westbound", float(t), 300.0, 700.0)
        got = dict(zip(snap.tid.tolist(), snap.x.tolist(), strict=True))
        # Vehicles within a few cm of the window edges may fall either side.
        inner = {k for k, (x, _) in reference.items() if 300.05 < x < 699.95}
        assert inner <= set(got)
        assert set(got) <= set(reference) | {
            k for k, x in got.items() if min(x - 300, 700 - x) < 0.05
        }
        common = sorted(set(got) & set(reference))
        errors = np.array([abs(got[k] - reference[k][0]) for k in common])
        bounds = np.array([reference[k][1] for k in common])
        assert np.all(errors <= bounds)  # exact at samples, chord error between them
        assert errors.max() < 0.1  # m: 3 cm tracking noise
        assert np.all(np.diff(snap.x) >= 0)
        assert np.all(np.isin(snap.lane, [-1, -2, -3, -4]))


def test_snapshot_is_exact_on_a_smooth_trajectory_and_absent_outside_its_span(tmp_path):
    doc = make_doc("a" * 24, mm=61.5, speed=25.0, n=100)
    ingest([write_day(tmp_path / "d.json", [doc])], tmp_path / "s", progress=False)
    traffic = EmpiricalTraffic(tmp_path / "s")
    t0, t1 = doc["timestamp"][0], doc["timestamp"][-1]
    for t in np.linspace(t0, t1, 37):
        snap = traffic.snapshot("westbound", float(t), -1e4, 1e4)
        assert len(snap) == 1
        assert snap.x[0] == pytest.approx(160.9344 + 25.0 * (t - t0), abs=1e-5)
        assert snap.speed[0] == pytest.approx(25.0, abs=1e-3)
    assert len(traffic.snapshot("westbound", t0 - 0.005, -1e4, 1e4)) == 0
    assert len(traffic.snapshot("westbound", t1 + 0.005, -1e4, 1e4)) == 0
    with pytest.raises(ValueError, match="reversed"):
        traffic.snapshot("westbound", t0, 10.0, 0.0)
    with pytest.raises(ValueError, match="finite"):
        traffic.snapshot("westbound", float("nan"), 0.0, 10.0)


def test_closest_is_the_papers_ego_selection(wave_store):
    traffic = EmpiricalTraffic(wave_store)
    ego = traffic.closest("westbound", -1, 700.0, SCENARIO_TIME)
    assert ego.lane == -1 and ego.road.value == "westbound"
    snap = traffic.snapshot("westbound", SCENARIO_TIME, 600.0, 800.0)
    in_lane = snap.lane == -1
    nearest = np.min(np.abs(snap.x[in_lane] - 700.0))
    assert abs(ego.x - 700.0) <= nearest + 1e-9 or abs(ego.t - SCENARIO_TIME) > 0
    assert np.hypot(ego.x - 700.0, 10.0 * (ego.t - SCENARIO_TIME)) <= nearest + 1e-9
    with pytest.raises(NoVehicleNearError, match=r"lane -1 of westbound within 50 m of x = 700"):
        traffic.closest("westbound", -1, 700.0, SCENARIO_TIME + 3600.0)


def test_store_without_the_road_is_a_clear_error(tmp_path):
    ingest([write_day(tmp_path / "d.json", [make_doc()])], tmp_path / "s", progress=False)
    traffic = EmpiricalTraffic(TrajectoryStore(tmp_path / "s"))
    with pytest.raises(Exception, match="no eastbound data"):
        traffic.snapshot("eastbound", SCENARIO_TIME, 0.0, 100.0)


def test_many_trajectories_in_one_read_equal_each_read_alone(tmp_path):
    docs = [
        make_doc("6386d89efb3ff533c12d0001", direction=-1, mm=61.5, n=60),
        make_doc("6386d89efb3ff533c12d0002", direction=-1, mm=61.2, n=40, t0=SCENARIO_TIME + 3),
        make_doc("6386d89efb3ff533c12d0003", direction=1, mm=60.7, y_ft=-30.0, n=50),
    ]
    ingest([write_day(tmp_path / "day.json", docs)], tmp_path / "store", progress=False)
    store = TrajectoryStore(tmp_path / "store")
    together = store.trajectory_samples([2, 0, 1, 0])
    assert sorted(together) == [0, 1, 2]
    for tid, arrays in together.items():
        alone = store.trajectory(tid)
        assert arrays.keys() == alone.keys()
        for name in alone:
            np.testing.assert_array_equal(arrays[name], alone[name])
    assert store.trajectory_samples([]) == {}
    with pytest.raises(KeyError, match="no trajectory with tid 3"):
        store.trajectory_samples([1, 3])
