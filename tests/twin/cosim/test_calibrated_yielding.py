"""``traffic.calibrated_yielding``: the calibrated behaviours drive lane -4's yielding
to merges as the calibration measured it, only where asked."""

import pytest

from tests.twin.cosim.sections import settings, with_section
from twin.calibration.following import CalibrationDataError

YIELDING = {
    "merges": 40, "steps": 900, "yielding_steps": 300, "identified": True,
    "yield_from": 0.6, "courtesy": 0.4, "agreement": 0.8, "cooperative_decel": 1.2,
}  # fmt: skip


@pytest.fixture(scope="module")
def store(calibrated_wave_store, tmp_path_factory):
    """The calibrated wave store with a measured yielding on westbound."""
    folder = tmp_path_factory.mktemp("yielding") / "store"
    return with_section(calibrated_wave_store, folder, "yielding", YIELDING)


def _settings(store, built_map, asked: bool, behaviour="calibrated"):
    return settings(store, built_map, behaviour, calibrated_yielding=asked)


@pytest.mark.parametrize("behaviour", ["calibrated", "recorded"])
def test_asked_the_calibrated_behaviours_yield_as_the_calibration_measured(
    store, built_map, behaviour
):
    ts = _settings(store, built_map, True, behaviour)
    assert (ts.yield_from, ts.courtesy, ts.cooperative_decel) == (0.6, 0.4, 1.2)


def test_by_default_and_in_paper_the_settings_stand(store, built_map):
    for ts in (_settings(store, built_map, False), _settings(store, built_map, True, "paper")):
        assert (ts.yield_from, ts.courtesy, ts.cooperative_decel) == (0.0, 1.0, 1.5)


def test_a_malformed_yielding_is_named(store, built_map, tmp_path):
    bad = with_section(store, tmp_path / "store", "yielding", {**YIELDING, "courtesy": 3.0})
    with pytest.raises(CalibrationDataError, match="yielding needs"):
        _settings(bad, built_map, True)
