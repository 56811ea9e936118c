"""``traffic.calibrated_yielding``: the calibrated behaviours drive lane -4's yielding
to merges as the calibration measured it, only where asked."""

import json
import shutil
from dataclasses import replace

import pytest

from twin.calibration.following import CalibrationDataError
from twin.cosim.config import CosimConfig
from twin.cosim.core.batch import Shared
from twin.data.store import TrajectoryStore

YIELDING = {
    "merges": 40, "steps": 900, "yielding_steps": 300, "identified": True,
    "yield_from": 0.6, "courtesy": 0.4, "agreement": 0.8, "cooperative_decel": 1.2,
}  # fmt: skip


@pytest.fixture(scope="module")
def store(calibrated_wave_store, tmp_path_factory):
    """The calibrated wave store with a measured yielding on westbound."""
    folder = tmp_path_factory.mktemp("yielding") / "store"
    shutil.copytree(calibrated_wave_store.path, folder)
    path = folder / "calibration.json"
    doc = json.loads(path.read_text())
    doc["roads"]["westbound"]["yielding"] = YIELDING
    path.write_text(json.dumps(doc))
    return TrajectoryStore(folder)


def _settings(store, built_map, asked: bool, behaviour="calibrated"):
    config = CosimConfig(world="kinematic", t_max=10.0, behaviour=behaviour)
    config = replace(config, traffic=replace(config.traffic, calibrated_yielding=asked))
    return Shared.make(store, built_map, config).traffic_settings


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
    folder = tmp_path / "store"
    shutil.copytree(store.path, folder)
    path = folder / "calibration.json"
    doc = json.loads(path.read_text())
    doc["roads"]["westbound"]["yielding"] = {**YIELDING, "courtesy": 3.0}
    path.write_text(json.dumps(doc))
    with pytest.raises(CalibrationDataError, match="yielding needs"):
        _settings(TrajectoryStore(folder), built_map, True)
