"""MOBIL's threshold fitted through the twin's own episodes
(twin/runners/lane_change_fit.py): the count it matches, what it writes, its trials."""

import json
import shutil

import pytest

from twin.calibration.calibrate import read_calibration
from twin.core.errors import TwinError
from twin.data.store import TrajectoryStore
from twin.runners.lane_change_fit import check_in_twin, check_store, fit_in_twin, refit_store


@pytest.fixture
def private_calibrated(calibrated_wave_store, tmp_path) -> TrajectoryStore:
    shutil.copytree(calibrated_wave_store.path, tmp_path / "store",
                    ignore=shutil.ignore_patterns(".recording"))  # fmt: skip
    return TrajectoryStore(tmp_path / "store")


def _westbound(store) -> tuple[dict, tuple[float, float]]:
    """The store's westbound calibration section and its window (unix [s])."""
    section = read_calibration(store)["roads"]["westbound"]
    return section, (section["window"]["from"], section["window"]["until"])


def test_the_threshold_is_fitted_to_the_recorded_count_through_the_twin(
    private_calibrated, built_map
):
    store = private_calibrated
    scenes, window = _westbound(store)
    fit = fit_in_twin(store, built_map, "westbound", window, episodes=6, duration=40.0)
    if "note" in fit:  # too few recorded changes: the scenes' threshold is kept
        assert fit["threshold"] == scenes["mobil"]["threshold"]
        pytest.fail(f"the wave store should hold lane changes to fit on: {fit['note']}")
    trials = fit["trials"]
    assert trials[0][0] == pytest.approx(scenes["mobil"]["threshold"], abs=1e-4)
    # the bracket's end kept is no farther from the recorded count than the last tried
    # (an end of the bracket)
    assert abs(fit["simulated"] - fit["recorded"]) <= abs(trials[-1][1] - fit["recorded"])
    # the count falls as the threshold rises (the same episodes at every threshold)
    ordered = sorted(trials)
    assert ordered[0][1] >= ordered[-1][1]
    again = fit_in_twin(store, built_map, "westbound", window, episodes=6, duration=40.0)
    assert again == fit  # deterministic
    doc = refit_store(store, built_map, episodes=6, duration=40.0)
    mobil = doc["roads"]["westbound"]["mobil"]
    assert mobil["threshold"] == fit["threshold"] and "scenes_threshold" in mobil
    assert mobil["scenes_threshold"] == scenes["mobil"]["threshold"]
    written = json.loads((store.path / "calibration.json").read_text())
    assert written["roads"]["westbound"]["mobil"]["twin_fit"]["trials"] == fit["trials"]


def test_a_store_without_a_calibration_is_named(private_wave_store, built_map):
    with pytest.raises(TwinError, match="no calibration to refit"):
        refit_store(private_wave_store, built_map)
    with pytest.raises(TwinError, match="no calibration to check"):
        check_store(private_wave_store, built_map)


def test_the_calibrated_twin_is_checked_on_its_window_by_lane_and_zone(
    private_calibrated, built_map
):
    store = private_calibrated
    _, window = _westbound(store)
    check = check_in_twin(store, built_map, "westbound", window, episodes=6, duration=40.0)
    assert check["episodes"] >= 3 and check["recorded"] > 0
    assert set(check["by_lane"]) == {"-1", "-2", "-3", "-4"}
    assert set(check["by_zone"]) == {"before_drop", "weave", "elsewhere"}
    assert sum(c["simulated"] for c in check["by_lane"].values()) == check["simulated"]
    assert check["zones"]["weaves"] and check["zones"]["drops"] == []  # no lane ends here
    again = check_in_twin(store, built_map, "westbound", window, episodes=6, duration=40.0)
    assert again == check  # deterministic
    doc = check_store(store, built_map, episodes=6, duration=40.0)
    assert doc["roads"]["westbound"]["lane_change_check"] == check
    written = json.loads((store.path / "calibration.json").read_text())
    assert written["roads"]["westbound"]["lane_change_check"] == check
    # a window holding no episode is said, not a failure
    late = (window[1] + 3600.0, window[1] + 7200.0)
    assert "note" in check_in_twin(store, built_map, "westbound", late, episodes=2)
