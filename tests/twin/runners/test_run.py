"""``twin run``: the run folder, its files as other tools read them, errors."""

import json

import cv2
import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

from tests.twin.cosim.scenes import EGO_X, T0, make_store, vehicle
from twin.cli import main
from twin.core.i24 import MILE
from twin.cosim import plots
from twin.cosim.config import load_config
from twin.data.empirical import EmpiricalTraffic
from twin.metrics import economy
from twin.metrics import fidelity as metrics
from twin.physics.energy import RAV4_2019

COLUMNS = [
    "time", "id", "record_id", "role", "road", "lane", "x", "y", "z", "speed", "accel",
    "accel_cmd", "heading", "grade", "drive_power", "fuel_rate", "fuel_feasible",
    "vehicle_class", "length", "width", "height",
]  # fmt: skip


@pytest.fixture(scope="module")
def scene_store(tmp_path_factory):
    docs = [
        vehicle(1, -2, EGO_X, 20.0),
        vehicle(2, -3, EGO_X - 158.0, 30.0),  # a ghost that enters from behind
        vehicle(3, -1, EGO_X + 60.0, 22.0),
        vehicle(4, -2, EGO_X + 175.0, 18.0),  # a ghost ahead
    ]
    return make_store(tmp_path_factory.mktemp("scene"), docs)


def run_args(store, out, *extra):
    return [
        "run", "--data", str(store.path), "--road", "westbound", "--lane", "-2",
        "--x", str(EGO_X), "--time", "2022-11-30T06:45:50-06:00", "--duration", "2",
        "--vel-default", "20", "--out", str(out), "--quiet", *extra,
    ]  # fmt: skip


@pytest.fixture(scope="module")
def run_folder(scene_store, tmp_path_factory):
    out = tmp_path_factory.mktemp("runs") / "scene"
    assert main(run_args(scene_store, out, "--bev-video", "--set", "traffic.hov_share=0.2")) == 0
    return out


def test_twin_run_names_the_egos_controller_and_lists_what_it_wrote(scene_store, tmp_path, capsys):
    out = tmp_path / "acc"
    world = ["--world", "kinematic", "--ego-controller", "twin.controllers:acc"]
    assert main(run_args(scene_store, out, *world)) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == "scenario B, behaviour paper, the ego driven by twin.controllers:acc"
    listed = lines[lines.index(f"wrote {out}:") + 1 :]
    names = [line.split()[0] for line in listed]
    assert names == ["config.toml", "trajectories.parquet", "metrics.json", "timespace.png",
                     "boundary.png", "bev.png"]  # fmt: skip
    assert all(len(line.split(maxsplit=1)) == 2 for line in listed)  # each says what it holds


def test_a_run_without_ghosts_still_has_its_birds_eye_video(tmp_path):
    """With no ghost ever logged, the pictures take the vehicles' steps at the ghost rate."""
    store = make_store(tmp_path / "alone", [vehicle(1, -2, EGO_X, 20.0)])
    out = tmp_path / "alone_run"
    assert main(run_args(store, out, "--bev-video", "--world", "kinematic")) == 0
    ghosts = pd.read_parquet(out / "trajectories.parquet").query("role == 'ghost'")
    assert ghosts.empty
    video = cv2.VideoCapture(str(out / "bev.mp4"))
    frames = int(video.get(cv2.CAP_PROP_FRAME_COUNT))
    video.release()
    assert frames == 21  # 2 s at 10 Hz, both ends


def test_the_run_folder_holds_every_output(run_folder):
    names = {p.name for p in run_folder.iterdir()}
    expected = {"config.toml", "trajectories.parquet", "metrics.json", "timespace.png",
                "boundary.png"}  # fmt: skip
    assert names == expected | {"bev.png", "bev.mp4"}


def test_trajectories_parquet_is_every_vehicle_every_step_and_ghosts_at_10_hz(run_folder):
    frame = pd.read_parquet(run_folder / "trajectories.parquet")
    assert list(frame.columns) == COLUMNS
    sim = frame[frame["role"] != "ghost"]
    ego = sim[sim["role"] == "ego"]
    assert len(ego) == 201 and ego["record_id"].iloc[0] == f"{1:024x}"
    assert np.allclose(np.diff(ego["time"]), 0.01)
    ghosts = frame[frame["role"] == "ghost"]
    assert np.allclose(np.unique(ghosts["time"]), np.arange(21) * 0.1)
    assert (ghosts["id"] == -1).all() and ghosts["accel"].isna().all()
    # vehicle 2 was a ghost, then simulated: one record id, two roles over time
    v2 = frame[frame["record_id"] == f"{2:024x}"]
    assert set(v2["role"]) == {"ghost", "visible"}
    assert v2[v2["role"] == "ghost"]["time"].max() < v2[v2["role"] == "visible"]["time"].min()
    meta = json.loads(pq.read_schema(run_folder / "trajectories.parquet").metadata[b"i24_twin"])
    assert meta["t0"] == pytest.approx(T0) and meta["road"] == "westbound"


def test_metrics_json_and_config_toml(run_folder):
    m = json.loads((run_folder / "metrics.json").read_text())
    assert m["format"] == "i24-twin-run" and m["simulated_s"] == pytest.approx(2.0)
    assert m["ego"]["speed_rmse_mps"] < 0.2  # recorded and simulated both at ~20 m/s
    assert m["counts"]["spawned"] == 1 and m["physics"]["collisions"] == 0
    assert m["physics"]["spawn_speed_error_max"] <= 0.005
    assert m["timing"]["real_time_factor"] > 0
    config = load_config(run_folder / "config.toml")
    assert (config.road.value, config.lane, config.x, config.t_max) == ("westbound", -2, 700, 2)
    assert config.time == pytest.approx(T0) and config.traffic.hov_share == 0.2


def test_metrics_json_follows_every_record_through_the_boundary(run_folder):
    # the ghost entering from behind is spawned where it is drawn, at its speed; every
    # body's own motion is continuous and no track begins or ends inside the region
    c = json.loads((run_folder / "metrics.json").read_text())["continuity"]
    assert c["by_roles"]["ghost>visible"]["pairs"] == 1
    assert c["discontinuous"] == 0 and c["position_jump_m"]["max"] <= 0.5
    assert c["tracks"]["begin"]["inside"] == 0 and c["tracks"]["end"]["inside"] == 0
    assert c["doubled"] == 0 and c["beyond_region"]["vehicles"] == 0


def test_energy_in_the_log_and_in_metrics_json(run_folder):
    frame = pd.read_parquet(run_folder / "trajectories.parquet")
    m = json.loads((run_folder / "metrics.json").read_text())["energy"]
    ego = frame[frame["role"] == "ego"]
    # the ego eases off from 20 m/s down the map's 1.1 % grade: the RAV4 model's rate
    # there, and its own powertrain still pushing against drag and rolling resistance
    assert ego["grade"].median() == pytest.approx(-0.011, abs=0.002)
    steady = RAV4_2019.rate(*(float(ego[name].median()) for name in ("speed", "accel", "grade")))
    assert ego["fuel_rate"].median() == pytest.approx(float(steady), rel=0.02)
    assert ego["fuel_feasible"].all() and ego["drive_power"].median() > 500.0  # [W]
    assert m["ego"]["fuel_g"] == pytest.approx(ego["fuel_rate"].sum() * 0.01, abs=1e-3)
    assert m["ego"]["mpg"] == pytest.approx(
        m["ego"]["distance_m"] / MILE / (m["ego"]["fuel_g"] / economy.GRAMS_PER_GALLON), rel=1e-3
    )
    simulated = frame[frame["role"] != "ghost"]
    assert m["window"]["vehicles"] == simulated["id"].nunique()
    ghosts = frame[frame["role"] == "ghost"]
    assert ghosts["fuel_rate"].isna().all() and ghosts["fuel_feasible"].isna().all()
    assert m["fuel_model"] == RAV4_2019.name


def test_pictures_open_in_opencv(run_folder):
    bev = cv2.imread(str(run_folder / "bev.png"))
    assert bev is not None and bev.shape[1] == round(plots.BEV_WIDTH * plots.BEV_DPI)
    video = cv2.VideoCapture(str(run_folder / "bev.mp4"))
    frames = int(video.get(cv2.CAP_PROP_FRAME_COUNT))
    video.release()
    assert frames == 21
    assert cv2.imread(str(run_folder / "timespace.png")) is not None
    assert cv2.imread(str(run_folder / "boundary.png")) is not None


def test_a_rerun_replaces_a_run_folder_but_never_other_data(scene_store, run_folder, tmp_path):
    precious = tmp_path / "precious"
    precious.mkdir()
    (precious / "notes.txt").write_text("mine")
    assert main(run_args(scene_store, precious)) == 2
    assert (precious / "notes.txt").read_text() == "mine"
    assert not list(tmp_path.glob(".precious.partial-*"))


def test_bad_inputs_are_named_errors(scene_store, tmp_path, capsys):
    assert main(run_args(scene_store, tmp_path / "r", "--ego-controller", "nosuch:f")) == 2
    assert "cannot import 'nosuch'" in capsys.readouterr().err
    assert main(["run", "--data", str(tmp_path / "missing"), "--quiet"]) == 2
    assert "no such file or folder" in capsys.readouterr().err
    assert main(["run", "--data", "embedded:nosuch", "--quiet"]) == 2
    assert "choose one of embedded:default, embedded:morning" in capsys.readouterr().err
    assert main(run_args(scene_store, tmp_path / "r", "--lane", "-4")) == 2
    assert "no recorded vehicle in lane -4" in capsys.readouterr().err
    assert main(run_args(scene_store, tmp_path / "r", "--time", "06:45")) == 2
    assert "neither unix seconds nor ISO 8601" in capsys.readouterr().err
    assert not (tmp_path / "r").exists()


def test_an_ego_controller_from_the_command_line_drives_the_ego(scene_store, tmp_path):
    out = tmp_path / "held"
    controller = "tests.twin.cosim.scenes:hold_speed"
    assert main(run_args(scene_store, out, "--ego-controller", controller)) == 0
    frame = pd.read_parquet(out / "trajectories.parquet")
    ego = frame[frame["role"] == "ego"]
    assert np.ptp(ego["speed"]) < 0.02  # held at its spawn speed
    assert load_config(out / "config.toml").ego_controller == controller


def test_metric_oracles(scene_store):
    traffic = EmpiricalTraffic(scene_store)
    recorded = scene_store.trajectory(scene_store.tid_of(f"{1:024x}"))
    time = np.arange(0.0, 2.0, 0.01)
    x_rec = np.interp(T0 + time, recorded["t"], recorded["x"])
    rows = pd.DataFrame({"time": time, "x": x_rec + 2.0, "speed": np.full(time.size, 20.5)})
    m = metrics.ego_metrics(rows, recorded, T0)
    assert m["position_rmse_m"] == pytest.approx(2.0, abs=1e-6)
    assert m["speed_rmse_mps"] == pytest.approx(0.5, abs=0.01)
    assert m["final_position_gap_m"] == pytest.approx(2.0, abs=1e-6)

    # the recording against itself: a zero speed field error in every compared cell
    times = np.arange(0.0, 4.0, metrics.SAMPLE_PERIOD)
    windows = pd.DataFrame({"time": times, "x0": EGO_X - 150.0, "x1": EGO_X + 150.0})
    snaps = [traffic.snapshot("westbound", T0 + t, EGO_X - 150.0, EGO_X + 150.0) for t in times]
    sim = pd.concat(
        pd.DataFrame({"time": t, "x": s.x, "lane": s.lane, "speed": s.speed, "tid": s.tid})
        for t, s in zip(times, snaps, strict=True)
    )
    field = metrics.speed_field_metrics(sim, windows, traffic, "westbound", T0, 4.0)
    assert field["all_lanes"]["cells_compared"] > 10
    assert field["all_lanes"]["rmse_mps"] == 0.0
    sim["speed"] += 1.0
    assert metrics.speed_field_metrics(sim, windows, traffic, "westbound", T0, 4.0)["all_lanes"][
        "bias_mps"
    ] == pytest.approx(1.0)
    assert metrics.traffic_speed_error(sim, traffic, T0, "westbound")[
        "speed_mae_mps"
    ] == pytest.approx(1.0)
