"""``twin calibrate``: a store's calibration written beside its data, shown by ``twin data
info``, and clear errors for stores and windows that cannot be calibrated."""

import hashlib
import json
import shutil

import pytest

from twin.calibration.calibrate import CALIBRATION, FITS, read_calibration, read_fits
from twin.cli import main
from twin.core.errors import StoreError
from twin.data import synth
from twin.data.ingest import ingest
from twin.data.store import TrajectoryStore


@pytest.fixture
def store(tmp_path, wave_store) -> TrajectoryStore:
    """A copy of the session's westbound-wave store (calibration writes into it)."""
    shutil.copytree(wave_store.path, tmp_path / "store")
    return TrajectoryStore(tmp_path / "store")


def _digests(folder):
    """The store's files (its folders, such as the recording cache, are derived data)."""
    files = [p for p in folder.iterdir() if p.is_file()]
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in files}


def test_calibrate_writes_beside_the_data_and_never_changes_them(
    store, calibrated_wave_store, capsys
):
    before = _digests(store.path)
    assert main(["calibrate", str(store.path), "--road", "westbound", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "car following:" in out and "accepted of" in out and "MOBIL threshold" in out
    after = _digests(store.path)
    assert {name: after[name] for name in before} == before
    assert set(after) - set(before) == {CALIBRATION, FITS, "lane_flows_westbound.png"}

    doc = read_calibration(store)
    # the calibrated twin checked on its own window: lane changes out of each lane and
    # by zone, simulated against recorded
    assert "checked in the twin (20 kinematic episodes" in out and "by zone:" in out
    check = doc["roads"]["westbound"].pop("lane_change_check")
    assert sum(c["recorded"] for c in check["by_lane"].values()) == check["recorded"]
    assert sum(c["simulated"] for c in check["by_lane"].values()) == check["simulated"]
    placed = sum(z["recorded"] for z in check["by_zone"].values())
    assert placed >= check["recorded"] > 0  # a two-lane jump is placed, not paired
    # deterministic: the session's calibration, made apart of another copy of the same
    # data (twin.calibration.calibrate), is this one but for the time it was made
    session = read_calibration(calibrated_wave_store)
    assert {**doc, "created": None} == {**session, "created": None}
    section = doc["roads"]["westbound"]
    car = section["car_following"]
    assert "not_calibrated" not in car and car["accepted"] >= 10
    assert car["accepted"] + car["rejected_poor"] + car["rejected_at_bound"] == car["fitted"]
    assert car["fitted"] + car["uninformative"] == car["followers"]
    # the embedded data's drivers (the class table, b = 1.7 m/s^2, s0 = 2 m) come back
    median = car["distributions"]["all"]["median"]
    assert median["min_gap"] == pytest.approx(2.0, rel=0.1)
    assert median["comfortable_decel"] == pytest.approx(synth.COMFORT_DECEL, rel=0.25)
    assert section["lane_changes"]["count"] >= 0 and section["mobil"]["threshold"] >= 0
    fits = read_fits(store)
    assert len(fits) == car["fitted"] and fits["accepted"].sum() == car["accepted"]

    assert main(["data", "info", str(store.path)]) == 0
    assert "calibration" in capsys.readouterr().out


def test_a_window_is_given_in_unix_or_iso_time_and_must_hold_data(store, capsys):
    t0, t1 = store.time_range("westbound")
    mid = 0.5 * (t0 + t1)
    assert (
        main(
            [
                "calibrate",
                str(store.path),
                "--until",
                f"{mid:.0f}",
                "--quiet",
                "--check-episodes",
                "0",
            ]
        )
        == 0
    )
    window = read_calibration(store)["roads"]["westbound"]["window"]
    assert window["until"] <= mid + 0.1
    capsys.readouterr()
    assert main(["calibrate", str(store.path), "--from", "2031-01-01T08:00:00-06:00"]) == 2
    assert "no westbound data between" in capsys.readouterr().err
    assert main(["calibrate", str(store.path), "--from", f"{mid}", "--until", f"{t0}"]) == 2
    assert "must be before" in capsys.readouterr().err
    assert main(["calibrate", str(store.path), "--road", "eastbound"]) == 2
    assert "no eastbound data" in capsys.readouterr().err


def test_a_store_without_enough_following_is_a_clear_error(tmp_path, light_result, capsys):
    # two minutes of light eastbound traffic: nobody stops, so nobody crossed a wave
    day = synth.write_i24_json(light_result, tmp_path / "light.json")
    ingest([day], tmp_path / "light", progress=False)
    assert main(["calibrate", str(tmp_path / "light"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "not enough following" in err and "never crossed a wave" in err
    assert not (tmp_path / "light" / CALIBRATION).exists()


def test_a_window_without_waves_takes_its_car_following_from_another_calibration(
    tmp_path, light_result, calibrated_wave_store, capsys
):
    day = synth.write_i24_json(light_result, tmp_path / "light.json")
    ingest([day], tmp_path / "light", progress=False)
    other = read_calibration(calibrated_wave_store)
    other["roads"] = {"eastbound": other["roads"]["westbound"]}  # the light day's road
    # a calibration of one model (--model idm): its drivers are the only ones to take
    other["roads"]["eastbound"].pop("car_following_candidates", None)
    assert other["car_following_model"] == "idm"
    path = tmp_path / "other.json"
    path.write_text(json.dumps(other))
    light = str(tmp_path / "light")
    assert (
        main(
            ["calibrate", light, "--quiet", "--check-episodes", "0", "--following-from", str(path)]
        )
        == 0
    )
    assert "car following: taken from another calibration" in capsys.readouterr().out
    section = read_calibration(TrajectoryStore(tmp_path / "light"))["roads"]["eastbound"]
    car, theirs = section["car_following"], other["roads"]["eastbound"]
    assert "not_calibrated" not in car and car["accepted"] == 0  # its own fits: none
    assert car["distributions"] == theirs["car_following"]["distributions"]
    assert "never crossed a wave" in car["taken_from"]["why"]
    assert car["taken_from"]["window"] == theirs["window"]
    # the lane changes and the threshold are still this window's
    assert section["window"] != theirs["window"]
    assert section["mobil"]["threshold"] >= 0 and "lane_flows" in section
    capsys.readouterr()
    # another model's drivers, a missing file, a file of something else: named
    assert main(["calibrate", light, "--following-from", str(path), "--model", "gipps"]) == 2
    assert "fitted idm, this one gipps" in capsys.readouterr().err
    assert main(["calibrate", light, "--following-from", str(tmp_path / "none.json")]) == 2
    assert "no such calibration file" in capsys.readouterr().err
    assert main(["calibrate", light, "--following-from", str(day)]) == 2
    assert "not an i24-twin calibration" in capsys.readouterr().err


def test_a_damaged_calibration_is_named_not_used(store):
    (store.path / CALIBRATION).write_text("{not json")
    with pytest.raises(StoreError, match="not valid JSON"):
        read_calibration(store)
    (store.path / CALIBRATION).write_text(
        json.dumps({"format": "i24-twin-calibration", "version": 99})
    )
    with pytest.raises(StoreError, match="version 99"):
        read_calibration(store)
