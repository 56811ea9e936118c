"""``twin calibrate`` by model: ``--model gipps`` is what runs drive, and a calibration
written before the model was named is read as IDM. (Apart from test_calibrate.py, whose
calibrations another worker makes meanwhile.)"""

import json
import shutil

import pytest

from twin.calibration.calibrate import CALIBRATION, FITS, read_calibration, read_fits
from twin.cli import main
from twin.data.store import TrajectoryStore


@pytest.fixture
def store(tmp_path, wave_store) -> TrajectoryStore:
    """A copy of the session's westbound-wave store (calibration writes into it)."""
    shutil.copytree(wave_store.path, tmp_path / "store")
    return TrajectoryStore(tmp_path / "store")


def test_calibrate_model_gipps_is_driven_by_the_runs(store, tmp_path, capsys):
    """``twin calibrate --model gipps``: the calibration says so, ``twin data info`` shows
    it, a calibrated run drives Gipps (``traffic.car_following`` auto, the default), and
    one that names IDM is refused, naming the model to set."""
    args = [
        "calibrate",
        str(store.path),
        "--road",
        "westbound",
        "--model",
        "gipps",
        "--quiet",
        "--check-episodes",
        "0",
    ]
    assert main(args) == 0
    assert read_calibration(store)["car_following_model"] == "gipps"
    assert "reaction_time" in read_fits(store).columns
    assert main(["data", "info", str(store.path)]) == 0
    info = capsys.readouterr().out
    assert "drivers gipps" in info and "tau " in info
    run = ["run", "--data", str(store.path), "--behaviour", "calibrated", "--duration", "2",
           "--quiet", "--out"]  # fmt: skip
    assert main([*run, str(tmp_path / "idm"), "--set", "traffic.car_following=idm"]) == 2
    assert "traffic.car_following=gipps" in capsys.readouterr().err
    assert main([*run, str(tmp_path / "auto")]) == 0
    assert "behaviour calibrated" in capsys.readouterr().out
    assert main([*run, str(tmp_path / "gipps"), "--set", "traffic.car_following=gipps"]) == 0
    assert "behaviour calibrated" in capsys.readouterr().out


def test_a_version_1_calibration_is_read_as_idm(store, calibrated_wave_store):
    """Calibrations written before the model was named are of IDM, and still drive."""
    from twin.calibration.calibrate import calibration_model

    doc = read_calibration(calibrated_wave_store)
    doc["version"] = 1
    del doc["car_following_model"]
    shutil.copy(calibrated_wave_store.path / FITS, store.path / FITS)
    (store.path / CALIBRATION).write_text(json.dumps(doc, indent=1) + "\n")
    assert calibration_model(read_calibration(store)).name == "idm"
