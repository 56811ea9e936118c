"""``twin calibrate --model auto`` (the default): the car-following model whose drawn
drivers replay the recording's followers best drives it
(:mod:`twin.calibration.model_choice`), and runs drive the model their store's
calibration chose."""

import json
from dataclasses import replace

import numpy as np
import pytest

from twin.calibration.calibrate import calibrate, read_calibration, write_calibration
from twin.calibration.distributions import ParameterDistribution
from twin.calibration.following import load_grid
from twin.calibration.model_choice import AUTO, choose, replay_score
from twin.cli import main
from twin.cosim.behaviour import car_following_of
from twin.data import synth
from twin.data.ingest import ingest
from twin.data.store import TrajectoryStore
from twin.traffic.models import GIPPS, IDM


def _day(folder, car_following: str) -> TrajectoryStore:
    """Six minutes of the westbound wave driven by the synthesiser's other drivers with
    ``car_following``, ingested."""
    config = replace(
        synth.PRESET_B, minutes=6.0, seed=3, drivers=synth.OTHER_DRIVERS,
        car_following=car_following,
    )  # fmt: skip
    day = synth.write_i24_json(synth.synthesize(config), folder / "day.json")
    ingest([day], folder / "store", progress=False)
    return TrajectoryStore(folder / "store")


@pytest.fixture(scope="module")
def days(tmp_path_factory):
    """{the model that drove it: its day calibrated with --model auto}."""
    out = {}
    for made_by, name in (("idm-textbook", "idm"), ("gipps", "gipps")):
        store = _day(tmp_path_factory.mktemp(name), made_by)
        doc, fits = calibrate(store, ["westbound"], model=AUTO)
        write_calibration(store, doc, fits)
        out[name] = store
    return out


def test_auto_keeps_the_model_that_drove_the_recording(days):
    for truth, store in days.items():
        doc = read_calibration(store)
        choice = doc["model_choice"]
        other = "gipps" if truth == "idm" else "idm"
        scores = {n: c["run_rmse_m"]["median"] for n, c in choice["candidates"].items()}
        assert choice["chosen"] == doc["car_following_model"] == truth, scores
        assert scores[truth] < scores[other]
        # the other model's drivers are kept, for a morning that takes them
        section = doc["roads"]["westbound"]
        assert set(section["car_following_candidates"]) == {other}
        assert section["car_following_candidates"][other]["accepted"] >= 10


def test_a_run_drives_the_model_its_store_was_calibrated_with(days, tmp_path, capsys):
    store = days["gipps"]
    assert car_following_of("auto", store, "calibrated", "westbound") == "gipps"
    assert car_following_of("auto", store, "auto", "westbound") == "gipps"
    assert car_following_of("idm", store, "calibrated", "westbound") == "idm"
    # the paper's drivers are IDM drivers, and a road not calibrated has the paper's
    assert car_following_of("auto", store, "paper", "westbound") == "idm"
    assert car_following_of("auto", store, "auto", "eastbound") == "idm"
    run = ["run", "--data", str(store.path), "--behaviour", "calibrated", "--duration", "2",
           "--time", "2022-11-30T06:43:00-06:00", "--world", "kinematic", "--quiet",
           "--out"]  # fmt: skip
    assert main([*run, str(tmp_path / "auto")]) == 0
    assert "behaviour calibrated" in capsys.readouterr().out
    # another model named by the run is refused, naming what to do
    assert main([*run, str(tmp_path / "idm"), "--set", "traffic.car_following=idm"]) == 2
    assert "traffic.car_following=gipps" in capsys.readouterr().err


def test_a_store_without_a_calibration_drives_idm(wave_store):
    assert car_following_of("auto", wave_store, "auto", "westbound") == "idm"


def test_an_evaluation_keeps_the_model_auto_means_so_older_folders_resume(days, wave_store):
    """eval.json holds the model ``auto`` stands for on the store, as folders made
    before ``auto`` existed hold it (``idm``)."""
    from twin.runners.evaluation import EvalConfig, _identity

    class Bundle:
        key = "map"

    for store, model in ((wave_store, "idm"), (days["gipps"], "gipps")):
        identity = _identity(EvalConfig(), store, Bundle())
        assert identity["config"]["cosim"]["traffic"]["car_following"] == model


def test_a_morning_without_waves_chooses_among_the_drivers_another_calibration_kept(
    tmp_path, light_result, days, capsys
):
    """A window with no waves fits no model; taking the drivers of a morning calibrated
    with --model auto, it still chooses between both models on its own followers."""
    day = synth.write_i24_json(light_result, tmp_path / "light.json")
    ingest([day], tmp_path / "light", progress=False)
    other = read_calibration(days["gipps"])
    other["roads"] = {"eastbound": other["roads"]["westbound"]}  # the light day's road
    path = tmp_path / "other.json"
    path.write_text(json.dumps(other))
    light = str(tmp_path / "light")
    assert (
        main(
            ["calibrate", light, "--quiet", "--check-episodes", "0", "--following-from", str(path)]
        )
        == 0
    )
    doc = read_calibration(TrajectoryStore(tmp_path / "light"))
    candidates = doc["model_choice"]["candidates"]
    assert all(c["run_rmse_m"]["median"] > 0 for c in candidates.values()), candidates
    assert set(candidates) == {"idm", "gipps"}
    car = doc["roads"]["eastbound"]["car_following"]
    assert "taken_from" in car
    chosen = doc["car_following_model"]
    theirs = other["roads"]["eastbound"]
    theirs = (
        theirs["car_following"]
        if chosen == other["car_following_model"]
        else theirs["car_following_candidates"][chosen]
    )
    assert car["distributions"] == theirs["distributions"]
    # one model named: taken where that calibration kept it
    one = [
        "calibrate",
        light,
        "--quiet",
        "--check-episodes",
        "0",
        "--following-from",
        str(path),
        "--model",
        "idm",
    ]
    assert main(one) == 0
    assert read_calibration(TrajectoryStore(tmp_path / "light"))["car_following_model"] == "idm"
    # a calibration of one model offers no other
    del other["roads"]["eastbound"]["car_following_candidates"]
    path.write_text(json.dumps(other))
    capsys.readouterr()
    assert main(["calibrate", light, "--following-from", str(path), "--model", "idm"]) == 2
    assert "fitted gipps, this one idm" in capsys.readouterr().err


def test_the_lowest_median_run_error_is_chosen():
    def c(median):
        return {"spacing_rmse_m": 1.0, "run_rmse_m": {"median": median, "p90": 1.0}}

    assert choose({"idm": c(3.0), "gipps": c(2.0)}) == "gipps"
    assert choose({"gipps": c(2.0), "idm": c(2.0)}) == "idm"  # a tie: the first candidate
    assert choose({"idm": c(None), "gipps": c(9.0)}) == "gipps"
    with pytest.raises(ValueError, match="no candidate"):
        choose({"idm": c(None)})


def test_a_replay_is_deterministic_and_refuses_another_models_drivers(days):
    from twin.calibration.following import following_runs

    store = days["idm"]
    section = read_calibration(store)["roads"]["westbound"]
    car = section["car_following"]
    distributions = {g: ParameterDistribution.from_dict(d) for g, d in car["distributions"].items()}
    runs = following_runs(load_grid(store, "westbound"))
    first = replay_score(runs, IDM, distributions, section["desired_speed"], car)
    again = replay_score(runs, IDM, distributions, section["desired_speed"], car)
    assert first.runs == len(runs) > 0 and first.steps == int(runs.valid.sum())
    assert np.array_equal(first.run_rmse, again.run_rmse) and first.sum_squares > 0
    with pytest.raises(ValueError, match="not gipps's parameters"):
        replay_score(runs, GIPPS, distributions, section["desired_speed"], car)
