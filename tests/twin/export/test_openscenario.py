"""``twin export RUN --format openscenario``: scenario B's run as ASAM OpenSCENARIO,
checked by ASAM's Quality Checker and read back with scenariogeneration's own parser:
the entities, their sizes and every trajectory vertex equal the run's (1 cm, 10 ms)."""

import contextlib
import io
import math
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from tests.asam_qc import ERROR, WARNING, issues, run_checker
from twin.cli import main
from twin.core.i24 import VEHICLE_CLASSES
from twin.core.vehicle_classes import vehicle_classes

xosc = pytest.importorskip("scenariogeneration.xosc", reason="scenariogeneration is not installed")

CM, MS = 0.01, 0.01  # [m], [s]: the read-back's tolerances
#: what every checker of the bundle must have done with a 1.2 file: run (none skipped)
SEMANTIC = ("reference_control_resolvable_entity_references",
            "reference_control_resolvable_storyboard_element_reference",
            "reference_control_unique_element_names_on_same_level",
            "reference_control_uniquely_resolvable_entity_references",
            "reference_control_valid_actor_reference_in_private_actions")  # fmt: skip


@pytest.fixture(scope="module")
def road():
    from mapgen.build import default_map

    return default_map().road


def export(run: Path, out: Path, *options: str) -> Path:
    assert main(["export", str(run), "--format", "openscenario", "--out", str(out), *options]) == 0
    return out / "i24.xosc"


def parse(path: Path):
    with contextlib.redirect_stdout(io.StringIO()):  # the parser prints the version it found
        return xosc.ParseOpenScenario(str(path))


def trajectories(scenario) -> dict[str, list[pd.DataFrame]]:
    """Each entity's polylines from the parsed storyboard: time, world wx, wy, wz, h, p."""
    found = {}
    for group in scenario.storyboard.stories[0].acts[0].maneuvergroup:
        (actor,) = group.actors.actors
        for maneuver in group.maneuvers:
            for event in maneuver.events:
                for action in event.action:
                    follow = action.action
                    if not isinstance(follow, xosc.FollowTrajectoryAction):
                        continue
                    line = follow.trajectory.shapes
                    vertices = zip(line.time, line.positions, strict=True)
                    found.setdefault(actor.entity, []).append(
                        pd.DataFrame(
                            [(t, p.x, p.y, p.z, p.h, p.p) for t, p in vertices],
                            columns=["time", "wx", "wy", "wz", "h", "p"],
                        )
                    )
    return found


def body_centres(scenario, lines: dict[str, list[pd.DataFrame]]) -> pd.DataFrame:
    """Every vertex as the vehicle's body centre on the road: the reference point moved
    forward by the bounding box's centre, read back from the same file."""
    boxes = {o.name: o.entityobject.boundingbox for o in
             scenario.entities.scenario_objects}  # fmt: skip
    frames = []
    for name, pieces in lines.items():
        ahead = boxes[name].center.x
        for piece in pieces:
            frames.append(piece.assign(
                name=name,
                cx=piece["wx"] + ahead * np.cos(piece["h"]),
                cy=piece["wy"] + ahead * np.sin(piece["h"]),
            ))  # fmt: skip
    return pd.concat(frames, ignore_index=True)


def nearest_rows(got: pd.DataFrame, rows: pd.DataFrame) -> pd.DataFrame:
    """Each vertex with the row of the same vehicle nearest its time, if within 10 ms
    (the row's time as ``time_row``; NaN where there is none)."""
    rows = rows.assign(time_row=rows["time"]).sort_values("time")
    return pd.merge_asof(got.sort_values("time"), rows, on="time", by="name",
                         direction="nearest", tolerance=MS, suffixes=("", "_row"))  # fmt: skip


def expected_centres(rows: pd.DataFrame, road) -> np.ndarray:
    """(n, 3) the run's body centres on the road surface, world frame."""
    direction = rows["road"].to_numpy().astype(np.int64)
    centre = rows["x"].to_numpy() + 0.5 * rows["length"].to_numpy(np.float64)
    return road.to_world(direction, centre, rows["y"].to_numpy())[0]


def names_of(rows: pd.DataFrame, ego: str) -> np.ndarray:
    rid = rows["record_id"].astype(str).to_numpy()
    return np.where(rid == ego, "hero", rid)


def facts(run: Path) -> dict:
    """What the run's log says of itself (t0, ego_record_id, ...)."""
    import json

    import pyarrow.parquet as pq

    return json.loads(pq.read_schema(run / "trajectories.parquet").metadata[b"i24_twin"])


def test_the_scenario_passes_the_asam_quality_checker(run, tmp_path):
    # OpenSCENARIO 1.0 (the default: what CARLA ScenarioRunner reads): the XML and schema
    # checks (the checker's semantic rules are defined from 1.2 and skip a 1.0 file)
    report = run_checker("qc_openscenario", "xoscBundle", export(run, tmp_path / "a"), tmp_path)
    assert issues(report, ERROR) == [] and issues(report, WARNING) == []
    status = {c.get("checkerId"): c.get("status") for c in report.iter("Checker")}
    assert status["check_asam_xosc_xml_valid_schema"] == "completed"
    # the same episode as 1.2, with the ego left to a controller: every rule runs
    path = export(run, tmp_path / "b", "--osc-version", "1.2", "--ego", "external")
    report = run_checker("qc_openscenario", "xoscBundle", path, tmp_path)
    assert issues(report, ERROR) == [] and issues(report, WARNING) == []
    status = {c.get("checkerId"): c.get("status") for c in report.iter("Checker")}
    assert {status[f"check_asam_xosc_{rule}"] for rule in SEMANTIC} == {"completed"}
    assert "skipped" not in status.values()


def test_the_scenario_reads_back_as_the_run(run, road, tmp_path, capsys):
    path = export(run, tmp_path / "x")
    rows = pd.read_parquet(run / "trajectories.parquet")
    out = capsys.readouterr().out
    assert f"{rows['record_id'].nunique()} vehicles" in out and "i24.xosc" in out
    assert (tmp_path / "x" / "i24.xodr").is_file()
    scenario = parse(path)
    header = ET.parse(path).getroot().find("FileHeader")  # the parser keeps no version
    assert (header.get("revMajor"), header.get("revMinor")) == ("1", "0")
    assert scenario.roadnetwork.road_file == "i24.xodr"
    ego = facts(run)["ego_record_id"]
    rows["name"] = names_of(rows, ego)
    # the entities: the ego and every recorded vehicle of the run, of its class and size
    objects = {o.name: o.entityobject for o in scenario.entities.scenario_objects}
    assert set(objects) == set(rows["name"])
    first = rows.groupby("name").head(1).set_index("name")
    classes = vehicle_classes()
    for name, vehicle in objects.items():
        row = first.loc[name]
        assert vehicle.name == VEHICLE_CLASSES[int(row["vehicle_class"])]
        # the reference point on the rear axle, half the twin's wheelbase behind the centre
        base = classes.column("wheelbase_ratio")[int(row["vehicle_class"])] * row["length"]
        centre = vehicle.boundingbox.center
        assert centre.x == pytest.approx(0.5 * base, abs=1e-3)
        assert centre.z == pytest.approx(0.5 * row["height"], abs=1e-3)
        assert vehicle.axles.rearaxle.xpos == 0.0
        assert vehicle.axles.frontaxle.xpos == pytest.approx(base, abs=2e-3)
        size = vehicle.boundingbox.boundingbox  # its Dimensions
        assert size.length == pytest.approx(row["length"], abs=1e-3)
        assert size.width == pytest.approx(row["width"], abs=1e-3)
        assert size.height == pytest.approx(row["height"], abs=1e-3)
        props = dict(vehicle.properties.properties)
        assert props["record_id"] == row["record_id"]
        assert props["type"] == ("ego_vehicle" if name == "hero" else "simulation")
    # every vertex is a row of the run, at its time and place
    lines = trajectories(scenario)
    # each follows a trajectory, but a ghost first drawn in the run's last step (a stay
    # of one row: added there, a polyline needs two vertices)
    last = rows["time"].max()
    at_end_only = {n for n, g in rows.groupby("name") if (g["time"] >= last - 1e-9).all()}
    assert set(lines) == set(objects) - at_end_only
    got = body_centres(scenario, lines)
    joined = nearest_rows(got, rows)
    assert joined["time_row"].notna().all()  # a row of the run within 10 ms of every vertex
    want = expected_centres(joined, road)
    assert np.abs(joined["cx"].to_numpy() - want[:, 0]).max() < CM
    assert np.abs(joined["cy"].to_numpy() - want[:, 1]).max() < CM
    yaw = np.angle(np.exp(1j * (joined["h"].to_numpy() - joined["heading"].to_numpy())))
    assert np.abs(yaw).max() < 1e-3
    # on the road surface, pitched nose down where the road falls ahead (ISO 8855)
    ground = road.to_road(joined[["wx", "wy", "wz"]].to_numpy()).height
    assert np.abs(ground).max() < CM
    assert np.abs(joined["p"] + np.arctan(joined["grade"])).max() < 1e-3
    # and the vertices span each vehicle's rows at 10 per second: the row nearest each
    # 0.1 s tick, so never further apart than 0.1 s and the longest step between its rows
    for name, group in rows.groupby("name"):
        if name in at_end_only:
            continue
        times = [p["time"].to_numpy() for p in lines[name]]
        assert times[0][0] == pytest.approx(group["time"].min(), abs=MS)
        assert times[-1][-1] == pytest.approx(group["time"].max(), abs=MS)
        step = np.diff(np.sort(group["time"].to_numpy()))
        longest = max(np.diff(t).max(initial=0.0) for t in times)
        assert longest <= 0.1 + step[step < 0.5].max(initial=0.0) + MS


def test_between_vertices_the_trajectories_stay_within_a_centimetre_of_the_run(run, road, tmp_path):
    """Interpolated linearly (as a player follows a polyline), the 10 Hz vertices give
    the run's 100 Hz positions back to within a centimetre."""
    scenario = parse(export(run, tmp_path / "x"))
    rows = pd.read_parquet(run / "trajectories.parquet")
    rows["name"] = names_of(rows, facts(run)["ego_record_id"])
    got = body_centres(scenario, trajectories(scenario))
    want = expected_centres(rows, road)
    worst = 0.0
    for name, group in rows.groupby("name"):
        line = got[got["name"] == name].sort_values("time")
        if line.empty:  # seen in one row only (the run's last step): nothing between
            assert group["time"].nunique() == 1
            continue
        inside = group["time"].between(line["time"].min(), line["time"].max())
        t = group["time"].to_numpy()[inside]
        for axis, column in ((0, "cx"), (1, "cy")):
            error = np.interp(t, line["time"], line[column]) - want[group.index[inside], axis]
            worst = max(worst, float(np.abs(error).max()))
    assert worst < CM


def test_recorded_trajectories_are_the_recordings(run, road, wave_store, tmp_path):
    path = export(run, tmp_path / "r", "--trajectories", "recorded", "--data",
                  str(wave_store.path))  # fmt: skip
    scenario = parse(path)
    lines = trajectories(scenario)
    got = body_centres(scenario, lines)
    rows = pd.read_parquet(run / "trajectories.parquet")
    known = facts(run)
    ego, t0 = known["ego_record_id"], known["t0"]
    ids = wave_store.trajectory_arrays["id"]
    length = {str(r): float(v) for r, v in
              rows.groupby("record_id")["length"].first().items()}  # fmt: skip
    tids = [int(np.flatnonzero(ids == rid)[0]) for rid in length]
    samples = pd.DataFrame(wave_store.samples("westbound", t0, t0 + 8.0, tids))
    samples["record_id"] = ids[samples["tid"]].astype(str)
    samples["name"] = np.where(samples["record_id"] == ego, "hero", samples["record_id"])
    samples["length"] = samples["record_id"].map(length)
    samples["road"] = -1
    samples["time"] = samples["t"] - t0
    joined = nearest_rows(got, samples)
    assert joined["time_row"].notna().all()  # each vertex is a recorded sample
    want = expected_centres(joined.assign(y=joined["y"].astype(float)), road)
    assert np.abs(joined["cx"].to_numpy() - want[:, 0]).max() < CM
    assert np.abs(joined["cy"].to_numpy() - want[:, 1]).max() < CM
    # every vehicle of the run, and those on the map from the start are there at time 0
    # (recorded samples are not on the run's clock: the first is up to a sample late)
    assert set(lines) == set(names_of(rows, ego))
    teleported = set(scenario.storyboard.init.initactions)
    deleted = {a.entityref for a in scenario.storyboard.init.global_actions}
    for name, pieces in lines.items():
        assert (name in teleported) == (pieces[0]["time"].iloc[0] <= 0.05)
        assert (name in deleted) == (name not in teleported)
    assert "hero" in teleported


def test_an_external_ego_starts_as_the_run_and_is_left_to_its_controller(run, road, tmp_path):
    scenario = parse(export(run, tmp_path / "e", "--ego", "external"))
    assert "hero" not in trajectories(scenario)  # no trajectory: the user's stack drives
    actions = {type(a).__name__: a for a in scenario.storyboard.init.initactions["hero"]}
    assert {"TeleportAction", "AbsoluteSpeedAction", "ControllerAction",
            "ActivateControllerAction"} <= set(actions)  # fmt: skip
    rows = pd.read_parquet(run / "trajectories.parquet")
    start = rows[(rows["role"] == "ego") & (rows["time"] == 0.0)].iloc[0]
    assert actions["AbsoluteSpeedAction"].speed == pytest.approx(start["speed"], abs=1e-3)
    assign = actions["ControllerAction"].assignControllerAction
    props = dict(assign.controller.properties.properties)
    assert props == {"module": "external_control", "esminiController": "ExternalController"}
    position = actions["TeleportAction"].position
    box = {o.name: o.entityobject.boundingbox
           for o in scenario.entities.scenario_objects}["hero"]  # fmt: skip
    centre = (
        position.x + box.center.x * math.cos(position.h),
        position.y + box.center.x * math.sin(position.h),
    )
    want = expected_centres(pd.DataFrame([start]), road)[0]
    assert np.hypot(centre[0] - want[0], centre[1] - want[1]) < CM


def test_omitting_late_vehicles_leaves_a_file_without_added_ones(run, tmp_path):
    """--late-vehicles omit: what CARLA ScenarioRunner can load (it never spawns a vehicle
    deleted in the Init and does not drive one an AddEntityAction spawns)."""
    path = export(run, tmp_path / "o", "--late-vehicles", "omit")
    report = run_checker("qc_openscenario", "xoscBundle", path, tmp_path)
    assert issues(report, ERROR) == [] and issues(report, WARNING) == []
    scenario = parse(path)
    rows = pd.read_parquet(run / "trajectories.parquet")
    rows["name"] = names_of(rows, facts(run)["ego_record_id"])
    at_start = set(rows.loc[rows["time"] == 0.0, "name"])
    assert {o.name for o in scenario.entities.scenario_objects} == at_start
    assert set(scenario.storyboard.init.initactions) == at_start  # each placed there
    assert scenario.storyboard.init.global_actions == []  # none deleted in the Init
    text = path.read_text()
    assert "AddEntityAction" not in text
    lines = trajectories(scenario)
    assert all(len(pieces) == 1 for pieces in lines.values())  # the first stay only


def test_the_export_is_deterministic_and_replaces_only_its_own_kind(run, tmp_path):
    a = export(run, tmp_path / "a").read_bytes()
    assert export(run, tmp_path / "a").read_bytes() == a  # replaced, same bytes
    assert export(run, tmp_path / "b").read_bytes() == a
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("keep")
    assert main(["export", str(run), "--format", "openscenario",
                 "--out", str(tmp_path / "mine")]) == 2  # fmt: skip
    assert (tmp_path / "mine" / "notes.txt").read_text() == "keep"


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (["--format", "sumo", "--ego", "external"], "--ego: only for --format openscenario"),
        (["--format", "openscenario", "--data", "x"], "--data: only read with --trajectories"),
    ],
)
def test_options_of_the_other_format_are_named(run, tmp_path, capsys, options, message):
    assert main(["export", str(run), "--out", str(tmp_path / "o"), *options]) == 2
    assert message in capsys.readouterr().err


@pytest.mark.parametrize("damage", ["truncated", "no metadata", "no column"])
def test_a_damaged_run_log_is_a_named_error(run, tmp_path, capsys, damage):
    import shutil

    import pyarrow.parquet as pq

    copy = tmp_path / "run"
    shutil.copytree(run, copy)
    log = copy / "trajectories.parquet"
    table = pq.read_table(log)
    if damage == "truncated":
        log.write_bytes(log.read_bytes()[:1000])
    elif damage == "no metadata":
        pq.write_table(table.replace_schema_metadata(None), log)
    else:
        pq.write_table(table.drop(["grade"]), log)
    assert main(["export", str(copy), "--format", "openscenario",
                 "--out", str(tmp_path / "o")]) == 2  # fmt: skip
    err = capsys.readouterr().err
    assert str(log) in err and "run it again: twin run --config" in err
    assert {"truncated": "not a readable Parquet file", "no metadata": "lacks the twin's metadata",
            "no column": "lacks the columns grade"}[damage] in err  # fmt: skip
    assert "Traceback" not in err and not (tmp_path / "o").exists()


def test_recorded_trajectories_from_other_data_are_a_named_error(run, tmp_path, doc, capsys):
    from tests.conftest import write_day

    day = write_day(tmp_path / "day.json", [doc()])
    assert main(["export", str(run), "--format", "openscenario", "--trajectories", "recorded",
                 "--data", str(day), "--out", str(tmp_path / "o")]) == 2  # fmt: skip
    assert "was the run made from other data? Pass its --data" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_without_scenariogeneration_the_error_says_what_to_install(run, tmp_path, capsys,
                                                                  monkeypatch):  # fmt: skip
    monkeypatch.setitem(sys.modules, "scenariogeneration", None)
    assert main(["export", str(run), "--format", "openscenario",
                 "--out", str(tmp_path / "o")]) == 2  # fmt: skip
    assert "pip install 'i24-twin[openscenario]'" in capsys.readouterr().err
