"""``twin export RUN --format sumo``: the run's vehicles and trajectories as SUMO
inputs, run by SUMO itself for the episode's length."""

import subprocess
import xml.etree.ElementTree as ET

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
