"""What the recording shows about driving: leaders and gaps, following runs, free-flow
speeds and lane changes, on hand-made I-24 documents whose answers are known."""

import numpy as np
import pytest

from tests.conftest import make_doc, write_day
from twin.calibration import following
from twin.calibration.following import CalibrationDataError
from twin.core.i24 import SCENARIO_TIME
from twin.data.ingest import ingest
from twin.data.store import TrajectoryStore

FT = 0.3048


def _store(tmp_path, docs) -> TrajectoryStore:
    ingest([write_day(tmp_path / "day.json", docs)], tmp_path / "store", progress=False)
    return TrajectoryStore(tmp_path / "store")


def test_leaders_gaps_and_following_runs(tmp_path):
    # westbound, lane -2 (y 30 ft): a leader 40 m ahead of a follower, both at 20 m/s for
    # 60 s; a third vehicle in lane -3 beside them is nobody's leader
    n = 25 * 60
    leader = make_doc("a" * 24, mm=61.5, y_ft=30.0, speed=20.0, n=n, length_ft=15.0)
    follower = make_doc("b" * 24, mm=61.5 + 40.0 / 1609.344, y_ft=30.0, speed=20.0, n=n)
    beside = make_doc("c" * 24, mm=61.5 + 20.0 / 1609.344, y_ft=42.0, speed=20.0, n=n)
    store = _store(tmp_path, [leader, follower, beside])
    grid = following.load_grid(store, "westbound")
    tid = {store.tid_of(d["_id"]["$oid"]): d["_id"]["$oid"][0] for d in (leader, follower, beside)}
    names = np.array([tid[t] for t in grid.tid])
    rows_b = names == "b"
    assert set(names[grid.leader[rows_b]]) == {"a"}
    assert np.all(grid.leader[names != "b"] == -1)
    # gap = 40 m between back centres minus the follower's length
    length_b = 15.0 * FT
    assert np.allclose(grid.gap[rows_b], 40.0 - length_b, atol=0.05)
    assert np.all(grid.lane[names == "c"] == -3)

    runs = following.following_runs(grid, min_duration=20.0, max_duration=120.0, trim=2.0)
    assert len(runs) == 1
    assert tid[int(runs.tid[0])] == "b" and tid[int(runs.leader_tid[0])] == "a"
    assert runs.steps[0] * runs.dt == pytest.approx(60.0 - 0.04 - 4.0, abs=0.15)
    assert np.allclose(runs.gap[runs.valid], 40.0 - length_b, atol=0.05)
    # cut into pieces of at most max_duration
    pieces = following.following_runs(grid, min_duration=10.0, max_duration=20.0)
    assert len(pieces) == 3 and np.all(pieces.steps * pieces.dt <= 20.0 + 1e-9)
    assert len(following.following_runs(grid, min_duration=70.0)) == 0


def test_free_flow_speed_is_the_median_speed_with_nothing_close_ahead(tmp_path):
    n = 25 * 30
    alone = make_doc("a" * 24, mm=61.5, y_ft=18.0, speed=31.0, n=n)
    close = make_doc("b" * 24, mm=61.5, y_ft=30.0, speed=25.0, n=n)
    behind = make_doc("c" * 24, mm=61.5 + 15.0 / 1609.344, y_ft=30.0, speed=25.0, n=n)
    # alone in lane -3 but still accelerating, 12 -> 24 m/s: not at its desired speed
    leaving = make_doc("d" * 24, mm=61.5, y_ft=42.0, n=n)
    t = np.arange(n) / 25.0
    leaving["x_position"] = (61.5 * 5280.0 - (12.0 * t + 0.2 * t**2) / FT).tolist()
    store = _store(tmp_path, [alone, close, behind, leaving])
    free = following.free_flow_speeds(following.load_grid(store, "westbound"))
    # the vehicle alone in lane -1 and the leader of lane -2 are free; the one 15 m
    # behind it is not, nor the one accelerating
    assert sorted(free.lane.tolist()) == [-2, -1]
    assert free.speed[free.lane == -1][0] == pytest.approx(31.0, abs=0.05)
    assert free.speed[free.lane == -2][0] == pytest.approx(25.0, abs=0.05)
    assert np.all(free.seconds >= 25.0)


def test_a_lane_change_counts_once_and_flicker_on_the_line_does_not(tmp_path):
    n = 25 * 40
    changer = make_doc("a" * 24, mm=61.5, y_ft=30.0, speed=20.0, n=n)
    y = np.full(n, 30.0)
    y[25 * 20 :] = 42.0  # lane -2 -> -3 after 20 s
    y[25 * 10 : 25 * 10 + 10] = 42.0  # 0.4 s across the line at 10 s: not a change
    changer["y_position"] = y.tolist()
    other = make_doc("b" * 24, mm=61.4, y_ft=18.0, speed=20.0, n=n)
    store = _store(tmp_path, [changer, other])
    changes = following.lane_changes(following.load_grid(store, "westbound"))
    assert len(changes) == 1
    assert (changes.lane_from[0], changes.lane_to[0]) == (-2, -3)
    assert changes.time[0] - changer["timestamp"][0] == pytest.approx(20.0, abs=0.1)
    assert changes.speed_from[0] == pytest.approx(20.0, abs=0.1) or np.isnan(changes.speed_from[0])
    # exposure: two vehicles, 40 s at 20 m/s each, 1.6 km, in the 15-25 m/s bin
    assert changes.exposure_km.sum() == pytest.approx(1.6, rel=0.01)
    assert changes.exposure_km[:, following.SPEED_BIN_NAMES.index("15-25")].sum() == (
        pytest.approx(1.6, rel=0.01)
    )


def test_a_window_without_data_is_a_clear_error(tmp_path):
    store = _store(tmp_path, [make_doc("a" * 24, n=100)])
    with pytest.raises(CalibrationDataError, match="no westbound data between"):
        following.load_grid(store, "westbound", SCENARIO_TIME + 3600, SCENARIO_TIME + 7200)
