"""A family of held-out days made by SUMO with other drivers (twin/data/sumo_family.py):
each day drawn from its seed alone within the published ranges, its parameters file what
SUMO was given, each road read back by the ingest, the same bytes whatever the workers,
a rerun keeping the days made, and the command line's errors named."""

import json
import shutil
import xml.etree.ElementTree as ET
from functools import partial
from pathlib import Path

import numpy as np
import pytest

from twin.cli import EXIT_USER_ERROR, main
from twin.core import i24
from twin.core.sumo import sumo_version
from twin.data import sumo_family
from twin.data.ingest import ingest
from twin.data.sumo_day import STEP, SumoDayError, SumoDrivers
from twin.data.sumo_family import (
    CELLS,
    FAMILY_INDEX,
    GEOMETRIES,
    MODELS,
    RANGES,
    SOURCES,
    STEPPED,
    FamilyError,
    day_path,
    draw_day,
    make_day,
    make_family,
    params_path,
)

pytest.importorskip("sumo", reason="SUMO-made test data needs eclipse-sumo (the test extra)")

#: tiny days: a minute recorded after a minute of warm-up
TINY = {"minutes": 1.0, "warmup": 60.0}
#: a day of each road, each with another pair of SUMO's models
ROADS = {
    0: ("plain", ("Krauss", "LC2013")),
    5: ("drop_one", ("Krauss", "SL2015")),
    10: ("drop_two", ("IDM", "LC2013")),
    15: ("on_ramp", ("EIDM", "LC2013")),
}
#: the first seed of the two-day family the tests make (drop_two, IDM and EIDM: quick)
FAMILY_SEED = 10


@pytest.fixture(scope="module")
def roads(tmp_path_factory):
    """{seed: (its parameters, its parameters file's content, SUMO's folder)}."""
    folder = tmp_path_factory.mktemp("roads")
    days = {}
    for seed in ROADS:
        params = draw_day(seed)
        work = folder / f"work_{seed}"
        days[seed] = (params, make_day(params, folder, keep=work, **TINY), work)
    return days


@pytest.fixture(scope="module")
def family(tmp_path_factory):
    """The family of two days from FAMILY_SEED, made by one worker and by two."""
    one, two = tmp_path_factory.mktemp("one"), tmp_path_factory.mktemp("two")
    paths = make_family(2, FAMILY_SEED, one, workers=1, **TINY)
    make_family(2, FAMILY_SEED, two, workers=2, **TINY)
    return one, two, paths


def _files(folder):
    return {path.name: path.read_bytes() for path in sorted(folder.iterdir())}


def test_a_day_is_drawn_from_its_seed_alone():
    assert draw_day(7) == draw_day(7) and draw_day(7).seed == 7
    development = [draw_day(seed) for seed in range(20)]
    test = [draw_day(seed) for seed in range(1000, 1020)]
    assert len({repr(day) for day in development + test}) == 40
    for seed, (geometry, models) in ROADS.items():
        day = draw_day(seed)
        assert day.geometry == geometry
        assert (day.drivers.car_following, day.drivers.lane_changing) == models
    for bad in (-1, 1.5, True, "3"):
        with pytest.raises(FamilyError, match="non-negative integer"):
            draw_day(bad)


def test_every_drawn_number_lies_in_its_published_range():
    assert all(r.low < r.high and r.source in SOURCES for r in RANGES.values())
    seen = set()
    for seed in [*range(3 * CELLS), *range(1000, 1020)]:
        day = draw_day(seed)
        drivers = day.drivers
        models = (drivers.car_following, drivers.lane_changing)
        assert models in MODELS and day.geometry in GEOMETRIES
        seen.add((models, day.geometry))
        drawn = {name: getattr(drivers, name) for name in RANGES if hasattr(drivers, name)}
        drawn |= {"load": day.load, "hov_flow": day.flow[0], "drop_x": day.drop_x,
                  "ramp_flow": day.ramp_flow, "stretch_x": day.stretch_x,
                  "stretch_length": day.stretch_length, "stretch_speed": day.stretch_speed,
                  "heavy_scale": day.heavy_factor[1]}  # fmt: skip
        if drivers.car_following not in STEPPED:  # IDM and EIDM decide every step
            assert drivers.action_step == STEP and drivers.lane_changing == "LC2013"
            del drawn["action_step"]
        assert (drivers.sigma is None) == (drivers.car_following != "Krauss")
        for name, value in drawn.items():
            if value is not None:
                r = RANGES[name]
                assert r.low <= value <= r.high, (seed, name, value)
                assert value == round(value, r.decimals)
        assert (day.drop_x is not None) == day.geometry.startswith("drop")
        assert (day.ramp_flow is not None) == (day.geometry == "on_ramp")
        assert (day.stretch_x is not None) == (day.geometry == "plain")
        assert day.flow[1] == day.flow[2] == day.flow[3] and 0 < day.flow[1] <= 3000
        day.config()  # a road and demand the synthesiser's configuration takes
    assert len(seen) == CELLS  # every pair of models on every road
    assert {(draw_day(s).drivers.car_following, draw_day(s).geometry)
            for s in range(1000, 1000 + CELLS)} == {(m[0], g) for m in MODELS
                                                     for g in GEOMETRIES}  # fmt: skip


def test_the_documentation_gives_every_range():
    page = Path(__file__).parents[3] / "docs" / "data" / "synthetic.md"
    rows = [line for line in page.read_text().splitlines() if line.startswith("| `")]
    for name, r in RANGES.items():
        row = next(line for line in rows if f"`{name}`" in line.split("|")[1])
        assert f"{r.low:g} to {r.high:g}" in row, (name, row)


def _vtypes(work):
    return [t for t in ET.parse(work / "i24.rou.xml").getroot().iter("vType") if t.get("vClass")]


def test_the_parameters_file_is_what_sumo_was_given(roads):
    for seed, (params, record, work) in roads.items():
        assert (
            record["params"]
            == params.to_dict()
            == json.loads(params_path(work.parent, seed).read_text())["params"]
        )
        assert record["seed"] == seed and record["sumo_version"] == sumo_version()
        assert (record["minutes"], record["warmup"]) == (TINY["minutes"], TINY["warmup"])
        drivers = params.drivers
        expected = {"carFollowModel": drivers.car_following,
                    "laneChangeModel": drivers.lane_changing, "tau": drivers.tau,
                    "minGap": drivers.min_gap, "actionStepLength": drivers.action_step,
                    "lcStrategic": drivers.lc_strategic,
                    "lcCooperative": drivers.lc_cooperative,
                    "lcSpeedGain": drivers.lc_speed_gain, "lcKeepRight": drivers.lc_keep_right,
                    "lcAssertive": drivers.lc_assertive}  # fmt: skip
        for vtype in _vtypes(work):
            for name, value in expected.items():
                given = vtype.get(name)
                assert (given if isinstance(value, str) else float(given)) == value, name
            assert (vtype.get("sigma") is None) == (drivers.sigma is None)
            if drivers.sigma is not None:
                assert float(vtype.get("sigma")) == drivers.sigma
            heavy = vtype.get("vClass") in ("truck", "trailer")  # keep SUMO's own
            assert (vtype.get("accel") is None) == heavy == (vtype.get("decel") is None)
            if not heavy:
                assert float(vtype.get("accel")) == drivers.accel
                assert float(vtype.get("decel")) == drivers.decel
            spread = float(vtype.get("speedFactor").split(",")[1])
            assert spread == pytest.approx(drivers.speed_dev, abs=5e-5)
        flows = {f.get("id"): 3600.0 * float(f.get("period")[4:-1])
                 for f in ET.parse(work / "i24.rou.xml").getroot().iter("flow")}  # fmt: skip
        for lane, flow in zip(i24.LANES, params.flow, strict=True):
            assert flows[f"lane{lane}"] == pytest.approx(flow, abs=0.01)
        assert ("ramp" in flows) == (params.ramp_flow is not None)
        if params.ramp_flow is not None:
            assert flows["ramp"] == pytest.approx(params.ramp_flow, abs=0.01)
        stats = ET.parse(work / "statistics.xml").getroot()
        assert int(stats.find("vehicles").get("inserted")) == record["sumo"]["departed"]


def test_a_day_of_each_road_reads_back_through_the_ingest(roads, tmp_path):
    for seed, (params, record, work) in roads.items():
        path = day_path(work.parent, seed)
        docs = json.loads(path.read_text())
        assert record["sumo"]["trajectories"] == len(docs) > 50
        assert record["sumo"]["lane_changes"] > 0
        side = i24.lane_center(-4) + 0.5 * i24.LANE_WIDTH  # right of it: the ramp's lane
        on_ramp_only = sum(bool((i24.road_y(np.array(d["y_position"])) > side).all())
                           for d in docs)  # fmt: skip
        # the ingest keeps every vehicle but those seen on the ramp only (not yet merged
        # when the minute ended), which the segment's lanes never held
        report = ingest([path], tmp_path / f"store_{seed}", progress=False)
        assert report.documents_kept == len(docs) - on_ramp_only
        assert sum(report.documents_rejected.values()) == on_ramp_only
        assert not on_ramp_only or params.geometry == "on_ramp"
        x = np.concatenate([i24.road_x(np.array(d["x_position"]), i24.Road.WESTBOUND)
                            for d in docs])  # fmt: skip
        y = np.concatenate([i24.road_y(np.array(d["y_position"])) for d in docs])
        lane = i24.lane_of(y)
        ramp = y > side  # on an acceleration lane
        # every sample in a lane, on the sublane model too, near its centre
        assert np.isin(lane[~ramp], i24.LANES).all()
        assert ramp.any() == (params.geometry == "on_ramp")
        centre = np.array([i24.lane_center(k) for k in lane[~ramp]])
        assert np.median(np.abs(y[~ramp] - centre)) < 0.2
        if params.drop_x is not None:  # nobody in the lanes that ended, past their end
            ended = (-4,) if params.geometry == "drop_one" else (-3, -4)
            past = x > params.drop_x + 1.0
            assert past.any() and not np.isin(lane[past & ~ramp], ended).any()


def test_a_family_is_the_same_bytes_whatever_the_workers(family):
    one, two, paths = family
    assert paths == [day_path(one, FAMILY_SEED), day_path(one, FAMILY_SEED + 1)]
    assert _files(one) == _files(two)
    assert sorted(_files(one)) == [
        "day_0010.json", "day_0010.params.json", "day_0011.json", "day_0011.params.json",
        FAMILY_INDEX,
    ]  # fmt: skip
    index = json.loads((one / FAMILY_INDEX).read_text())
    assert index["arguments"] == {"days": 2, "seed": FAMILY_SEED, **TINY}
    assert [d["seed"] for d in index["days"]] == [FAMILY_SEED, FAMILY_SEED + 1]
    for k, day in enumerate(index["days"]):
        record = json.loads(params_path(one, day["seed"]).read_text())
        assert day["params"] == record["params"] == draw_day(FAMILY_SEED + k).to_dict()
        assert record["family"] == {"seed": FAMILY_SEED, "index": k}
        assert set(record["sumo"]) == {"trajectories", "departed", "lane_changes",
                                       "collisions", "waiting"}  # fmt: skip


def test_a_rerun_keeps_the_days_made_and_makes_what_is_missing(family, tmp_path):
    one, _, _ = family
    folder = tmp_path / "family"
    shutil.copytree(one, folder)
    before = _files(folder)
    stamps = {path.name: path.stat().st_mtime_ns for path in folder.iterdir()}
    days = []
    make_family(2, FAMILY_SEED, folder, workers=1, on_day=days.append, **TINY)
    assert [day.seconds for day in days] == [None, None]  # kept, not made again
    assert _files(folder) == before
    assert all(path.stat().st_mtime_ns == stamps[path.name] for path in folder.iterdir()
               if path.name != FAMILY_INDEX)  # fmt: skip
    # a day without its parameters file was not finished: it is made again, the same
    params_path(folder, FAMILY_SEED + 1).unlink()
    (folder / f".day_{FAMILY_SEED + 1:04d}.partial-1.json").write_text("[")  # a killed write
    days.clear()
    make_family(2, FAMILY_SEED, folder, workers=1, on_day=days.append, **TINY)
    assert [day.seconds is None for day in sorted(days, key=lambda d: d.index)] == [True, False]
    assert {n: b for n, b in _files(folder).items() if not n.startswith(".")} == before


def test_a_folder_of_other_days_is_refused_and_bad_values_named(family, tmp_path):
    one, _, _ = family
    folder = tmp_path / "family"
    shutil.copytree(one, folder)
    with pytest.raises(FamilyError, match="holds the family of seed 10"):
        make_family(2, FAMILY_SEED + 1, folder, **TINY)
    (folder / FAMILY_INDEX).unlink()
    with pytest.raises(FamilyError, match=r"day_0010.params.json .* made otherwise \(minutes"):
        make_family(2, FAMILY_SEED, folder, minutes=2.0, warmup=TINY["warmup"])
    file = tmp_path / "file"
    file.write_text("")
    for bad, message in (
        ({"n": 0}, "at least 1 day"),
        ({"seed": -1}, "seed must be >= 0"),
        ({"minutes": 0.5}, "record 1 to 60 minutes, got 0.5"),
        ({"minutes": 61.0}, "record 1 to 60 minutes, got 61"),
        ({"workers": 0}, "workers must be >= 1"),
        ({"out": file}, "a file, not a folder"),
    ):
        arguments = {"n": 1, "seed": 0, "out": tmp_path / "new"} | bad
        with pytest.raises(FamilyError, match=message):
            make_family(arguments.pop("n"), arguments.pop("seed"), arguments.pop("out"),
                        **arguments)  # fmt: skip
    assert not (tmp_path / "new").exists()
    with pytest.raises(SumoDayError, match="sigma None: Krauss needs one"):
        SumoDrivers(**{**draw_day(0).drivers.__dict__, "sigma": None})
    with pytest.raises(SumoDayError, match=r"action_step is out of its range: 0\.25"):
        SumoDrivers(**{**draw_day(0).drivers.__dict__, "action_step": 0.25})


def test_the_command_line_makes_a_family_and_names_its_errors(family, tmp_path, monkeypatch,
                                                               capsys):  # fmt: skip
    one, _, _ = family
    folder = tmp_path / "family"
    shutil.copytree(one, folder)
    monkeypatch.setattr(sumo_family, "make_family",
                        partial(sumo_family.make_family, warmup=TINY["warmup"]))  # fmt: skip
    argv = ["data", "sumo", "--family", "2", "--seed", str(FAMILY_SEED), "--minutes", "1",
            "--out", str(folder), "--workers", "1", "--quiet"]  # fmt: skip
    assert main(argv) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("day_0010.json: drop_two, IDM + LC2013, tau ")
    assert out[0].endswith("(kept (made before))") and out[1].startswith("day_0011.json:")
    assert out[2].startswith(f"wrote 0 of 2 days (seeds 10 to 11, 1 min each) to {folder}")
    assert "2 kept from before: 2 drop_two; 1 EIDM+LC2013, 1 IDM+LC2013" in out[2]
    file = tmp_path / "file.json"
    file.write_text("")
    for args, message in (
        (["--minutes", "0.5"], "--minutes must be 1 to 60 for a family, got 0.5"),
        (["--minutes", "61"], "--minutes must be 1 to 60 for a family, got 61"),
        (["--out", str(file)], f"--out {file} is a file: a family is written to a folder"),
        (["--keep", "k"], "--keep is for --preset: a family's days set their own"),
        (["--workers", "0"], "--workers must be >= 1, got 0"),
    ):
        options = {"--out": str(tmp_path / "new"), args[0]: args[1]}
        command = ["data", "sumo", "--family", "2", *(a for kv in options.items() for a in kv)]
        assert main(command) == EXIT_USER_ERROR
        assert capsys.readouterr().err == f"twin: error: {message}\n"
    assert main(["data", "sumo", "--preset", "D", "--out", "d.json", "--workers", "2"]) == 2
    assert "--workers is for --family" in capsys.readouterr().err
    for command, message in (
        (["--family", "0", "--out", "x"], "argument --family: must be >= 1, got 0"),
        (["--family", "2", "--preset", "D", "--out", "x"], "not allowed with argument"),
        (["--out", "x"], "one of the arguments --preset --family is required"),
    ):
        with pytest.raises(SystemExit) as exit_:
            main(["data", "sumo", *command])
        assert exit_.value.code == 2 and message in capsys.readouterr().err
    assert not (tmp_path / "new").exists()
