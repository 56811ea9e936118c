"""``traffic.calibrated_passing``: where the calibration found that the recording's
drivers do not pass on the right, the calibrated behaviours' drivers do not either."""

import math

import pytest

from tests.twin.cosim.sections import settings, with_section
from twin.calibration.following import CalibrationDataError

PASSING = {
    "judged": 9000, "free": 11000, "vehicles": 700, "passing": 0.01, "expected": 0.2, "ratio": 0.05,
    "identified": True, "no_pass_right_from": 16.6667,
}  # fmt: skip


def _store(source, folder, section):
    return with_section(source, folder, "passing_right", section)


@pytest.fixture(scope="module")
def store(calibrated_wave_store, tmp_path_factory):
    """The calibrated wave store whose westbound drivers do not pass on the right."""
    return _store(calibrated_wave_store, tmp_path_factory.mktemp("passing") / "store", PASSING)


def _settings(store, built_map, asked=True, behaviour="calibrated"):
    return settings(store, built_map, behaviour, calibrated_passing=asked)


@pytest.mark.parametrize("behaviour", ["calibrated", "recorded"])
def test_the_calibrated_behaviours_do_not_pass_where_the_recording_does_not(
    store, built_map, behaviour
):
    assert _settings(store, built_map, behaviour=behaviour).no_pass_right_from == 16.6667


def test_asked_not_to_and_in_paper_the_drivers_pass(store, built_map):
    for ts in (_settings(store, built_map, False), _settings(store, built_map, True, "paper")):
        assert ts.no_pass_right_from == math.inf


def test_a_calibration_whose_drivers_pass_or_that_has_no_section_leaves_them_passing(
    calibrated_wave_store, built_map, tmp_path
):
    passes = _store(calibrated_wave_store, tmp_path / "passes",
                    {**PASSING, "ratio": 0.9, "no_pass_right_from": None})  # fmt: skip
    assert _settings(passes, built_map).no_pass_right_from == math.inf
    older = _store(calibrated_wave_store, tmp_path / "older", None)
    assert _settings(older, built_map).no_pass_right_from == math.inf


def test_a_malformed_passing_section_is_named(calibrated_wave_store, built_map, tmp_path):
    bad = _store(calibrated_wave_store, tmp_path / "bad", {**PASSING, "no_pass_right_from": -3})
    with pytest.raises(CalibrationDataError, match="passing_right needs"):
        _settings(bad, built_map)
