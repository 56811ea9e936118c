"""``twin export RUN --format sumo``: the run's vehicles and trajectories as SUMO
inputs, run by SUMO itself for the episode's length."""

import subprocess
import xml.etree.ElementTree as ET

import numpy as np
import pandas as pd
import pytest

from twin.cli import main


def test_sumo_runs_the_exported_episode_with_every_vehicle(run, tmp_path, capsys):
    sumo = pytest.importorskip("sumo", reason="eclipse-sumo is not installed")
    from pathlib import Path

    out = tmp_path / "sumo"
    assert main(["export", str(run), "--format", "sumo", "--out", str(out)]) == 0
    assert "vehicles in routes.rou.xml" in capsys.readouterr().out
    # the HOV lane's double solid line: nobody but emergency vehicles crosses it, on
    # every edge netconvert cut the carriageways into (where an on-ramp's lane runs
    # beside lane -4, an edge has seven lanes: the shoulder, that lane, four, the median)
    edges = [e for e in ET.parse(out / "i24.net.xml").getroot().findall("edge")
             if e.get("function") is None]  # fmt: skip
    assert sorted({len(e.findall("lane")) for e in edges}) == [6, 7]
    for edge in edges:
        lanes = edge.findall("lane")
        hov, second = lanes[-2], lanes[-3]
        assert second.get("changeLeft") == hov.get("changeRight") == "emergency"
    net_lanes = {lane.get("id") for edge in edges for lane in edge.findall("lane")}
    # each carriageway's chain in travel order, and the twin's lanes on every edge of
    # it: the HOV lane keeps trucks out, the acceleration lane (-5) is where one runs
    from mapgen.build import default_map
    from twin.core.i24 import LANE_WIDTH
    from twin.export.sumo import edges_of, sumo_lane

    road_model = default_map().road
    by_id = {e.get("id"): e for e in edges}
    for road, chain in edges_of(out / "i24.net.xml", road_model).items():
        assert len(chain) == len(
            [e for e in edges if (e.get("id")[0] == "-") == (road.direction > 0)]
        )
        starts = [e.x_start for e in chain]
        assert any(e.lanes == 7 for e in chain)  # each carriageway has its on-ramp
        assert starts == sorted(starts) and chain[0].x_start < road_model.x_range(road)[0] + 1
        for edge in chain:
            lanes = by_id[edge.id].findall("lane")
            assert "truck" not in lanes[sumo_lane(-1, edge.lanes)].get("allow", "truck")
            shape = lanes[sumo_lane(-4, edge.lanes)].get("shape").split()
            middle = np.array([[float(v) for v in shape[len(shape) // 2].split(",")]])
            assert road_model.to_road(middle).lane[0] == -4
            if edge.lanes == 7:  # beside lane -4, in the acceleration lane's band
                ramp = lanes[sumo_lane(-5, edge.lanes)].get("shape").split()
                point = np.array([[float(v) for v in ramp[len(ramp) // 2].split(",")]])
                y = road_model.to_road(point).y[0]
                assert 5 * LANE_WIDTH < y < 6 * LANE_WIDTH
    rows = pd.read_parquet(run / "trajectories.parquet")
    routes = ET.parse(out / "routes.rou.xml").getroot().findall("vehicle")
    recorded = set(rows.loc[rows["lane"].isin([-1, -2, -3, -4]), "record_id"])
    assert {v.get("id") for v in routes} <= recorded and len(routes) >= 0.95 * len(recorded)
    # the twin's trajectories: every vehicle of the log at 10 Hz
    fcd = ET.parse(out / "twin.fcd.xml").getroot().findall("timestep")
    assert len(fcd) == 81 and {v.get("id") for v in fcd[0]} == set(
        rows.loc[rows["time"] == 0.0, "record_id"]
    )
    # each on a lane of the edge under it
    on = {v.get("lane") for step in fcd for v in step} - {""}
    assert on and on <= net_lanes
    home = Path(sumo.SUMO_HOME)
    done = subprocess.run(
        [str(home / "bin" / "sumo"), "-c", str(out / "i24.sumocfg"),
         "--duration-log.statistics", "true", "--no-step-log", "true"],
        capture_output=True, text=True, env={"SUMO_HOME": str(home)},
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "Error" not in done.stderr
    assert "Simulation ended at time: 8.00" in done.stdout
    assert f"Inserted: {len(routes)}" in done.stdout  # every vehicle, none waiting


def test_exporting_what_is_not_a_run_is_a_named_error(tmp_path, capsys):
    pytest.importorskip("sumo", reason="eclipse-sumo is not installed")
    assert main(["export", str(tmp_path), "--out", str(tmp_path / "x")]) == 2
    assert "is not a run folder" in capsys.readouterr().err


def test_vehicles_depart_and_are_logged_on_the_edge_and_lane_under_them(built_map, tmp_path):
    """On netconvert's chain of edges: a westbound vehicle on the Old Hickory on-ramp's
    lane (-5) and one in lane -4 beside it depart on the seven-lane edge under their
    front bumpers, in SUMO's lanes 1 and 2; an eastbound one far from its ramp on a
    six-lane edge, in lane 1; the floating-car data name the same lanes."""
    pytest.importorskip("sumo", reason="eclipse-sumo is not installed")
    from mapgen.opendrive import write_opendrive
    from twin.core.i24 import LANE_WIDTH
    from twin.export import sumo as export

    xodr = write_opendrive(built_map, tmp_path / "i24.xodr")
    net = tmp_path / "i24.net.xml"
    subprocess.run(
        [str(export.sumo_home() / "bin" / "netconvert"), "--opendrive-files", str(xodr),
         "--output-file", str(net), "--offset.disable-normalization", "true",
         "--opendrive.import-all-lanes", "true"],
        check=True, capture_output=True, env={"SUMO_HOME": str(export.sumo_home())},
    )  # fmt: skip
    edges = export.edges_of(net, built_map.road)
    rows = pd.DataFrame(
        {"time": [0.0] * 3, "record_id": ["ramp", "lane4", "east"], "road": [-1, -1, 1],
         "lane": [-5, -4, -4], "x": [0.0, 50.0, 1000.0], "length": [4.5] * 3,
         "width": [1.8] * 3, "vehicle_class": [0] * 3, "speed": [20.0] * 3,
         "y": [5.5 * LANE_WIDTH, 4.5 * LANE_WIDTH, 4.5 * LANE_WIDTH], "heading": [0.0] * 3,
         "role": ["ghost"] * 3}
    )  # fmt: skip
    late = rows.iloc[[1]].assign(time=8.0, record_id="late")  # first seen as the run ends
    export._routes(pd.concat([rows, late]), edges, tmp_path / "routes.rou.xml", 8.0)
    root = ET.parse(tmp_path / "routes.rou.xml").getroot()
    routes = {r.get("id"): r.get("edges").split() for r in root.findall("route")}
    got = {}
    for vehicle in root.findall("vehicle"):
        first = routes[vehicle.get("route")][0]
        edge = next(e for chain in edges.values() for e in chain if e.id == first)
        got[vehicle.get("id")] = (edge.lanes, vehicle.get("departLane"))
        front = float(rows.set_index("record_id").loc[vehicle.get("id"), "x"]) + 4.5
        assert edge.x_start <= front <= edge.x_end
    assert got == {"ramp": (7, "1"), "lane4": (7, "2"), "east": (6, "1")}
    export._fcd(rows, built_map.road, edges, tmp_path / "fcd.xml")
    logged = {v.get("id"): v.get("lane") for v in ET.parse(tmp_path / "fcd.xml").iter("vehicle")}
    assert [logged[k].rsplit("_", 1)[1] for k in ("ramp", "lane4", "east")] == ["1", "2", "1"]
