import json

import pytest

from twin.cli import main
from twin.cosim.core.step import PHASES


def test_bench_query_prints_one_json_line(wave_store, capsys):
    assert main(["bench", "query", "--data", str(wave_store.path), "--repeats", "1"]) == 0
    line = json.loads(capsys.readouterr().out.strip())
    assert line["bench"] == "query" and line["snapshot_median_us"] > 0
    assert line["vehicles_in_window"] > 20


@pytest.mark.slow
def test_bench_run_prints_the_loop_figures(wave_store, capsys):
    argv = ["bench", "run", "--data", str(wave_store.path), "--repeats", "1", "--duration", "3"]
    assert main(argv) == 0
    line = json.loads(capsys.readouterr().out.strip())
    assert line["bench"] == "run" and line["real_time_factor"] > 0 and line["t_max"] == 3.0
    assert 0 < line["ghost_reload_ms"] < line["step_ms"] and line["vehicles_mean"] > 10


def test_bench_run_times_the_kinematic_world_beside_sumo(wave_store, capsys):
    """The same episode exported and run by SUMO, timed beside the twin's loop."""
    pytest.importorskip("sumo", reason="eclipse-sumo (the test extra) is not installed")
    argv = ["bench", "run", "--data", str(wave_store.path), "--repeats", "1", "--world",
            "kinematic", "--duration", "10", "--sumo"]  # fmt: skip
    assert main(argv) == 0
    line = json.loads(capsys.readouterr().out.strip())
    assert line["world"] == "kinematic" and line["t_max"] == 10.0 and line["loop_s"] > 0
    assert line["sumo_s"] > 0 and line["sumo_vehicles"] > 10
    assert line["sumo_over_twin"] == pytest.approx(line["sumo_s"] / line["loop_s"], rel=0.02)
    assert main(["bench", "run", "--duration", "-1"]) == 2


@pytest.mark.slow
def test_bench_dataset_prints_frames_per_second_by_workers(wave_store, capsys):
    argv = ["bench", "dataset", "--data", str(wave_store.path), "--episodes", "2"]
    assert main([*argv, "--frames", "2", "--workers", "1,2", "--repeats", "1"]) == 0
    line = json.loads(capsys.readouterr().out.strip())
    assert line["bench"] == "dataset" and line["size"] == "640x480"
    assert line["by_workers"]["1"]["render_fps"] > 0 and line["by_workers"]["2"]["render_fps"] > 0
    assert line["scaling"] > 0


@pytest.mark.slow
def test_bench_calibrate_and_eval_print_their_figures(wave_store, capsys):
    assert main(["bench", "calibrate", "--data", str(wave_store.path), "--repeats", "1"]) == 0
    line = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert line["bench"] == "calibrate" and line["wall_s"] > 0 and line["followers_fitted"] > 0
    argv = ["bench", "eval", "--data", str(wave_store.path), "--episodes", "1"]
    assert main([*argv, "--duration", "4", "--workers", "1"]) == 0
    line = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert line["bench"] == "eval" and line["by_workers"]["1"]["wall_s"] > 0


def test_bench_env_prints_steps_per_second_of_one_env_and_a_vector_env(wave_store, capsys):
    argv = ["bench", "env", "--data", str(wave_store.path), "--steps", "5", "--workers", "1"]
    assert main([*argv, "--repeats", "1", "--resets", "2"]) == 0  # compile times not by default
    line = json.loads(capsys.readouterr().out.strip())
    assert line["bench"] == "env" and line["env_steps_per_s"] > 0
    assert line["resets"] == 2 and line["reset_ms"] > 0
    assert line["vector"] == "AsyncVectorEnv" and line["vector_envs"] == 1
    assert line["vector_env_steps_per_s"] > 0 and "cold_first_step_s" not in line
    assert main(["bench", "env", "--steps", "0"]) == 2


def test_bench_env_times_the_kinematic_worlds_batched_vector_env(wave_store, capsys):
    argv = ["bench", "env", "--data", str(wave_store.path), "--steps", "5", "--num-envs", "3"]
    assert main([*argv, "--repeats", "1", "--world", "kinematic", "--no-compile-times",
                 "--profile"]) == 0  # fmt: skip
    line = json.loads(capsys.readouterr().out.strip())
    profile = line["profile_us_per_episode_step"]
    assert set(profile) == {*PHASES, "observe", "total"} and profile["decisions"] > 0
    assert profile["total"] == pytest.approx(sum(profile[k] for k in profile if k != "total"),
                                             abs=0.1)  # fmt: skip
    assert line["world"] == "kinematic" and line["env_steps_per_s"] > 0
    assert line["vector"] == "batched core" and line["vector_envs"] == 3
    assert line["vector_vehicle_updates_per_s"] > line["vector_env_steps_per_s"] > 0
    assert line["reset_ms"] > 0


def test_bench_env_times_a_new_process_with_an_empty_and_with_the_machines_kernel_cache():
    """The cold process gets a kernel cache of its own, empty; the warm one the
    machine's (a stand-in script reports what it was given: a whole compile of the
    core is a minute, which the README's first run and twin bench env show)."""
    from twin.perf.env_steps import first_call_times

    script = (
        "import json, os, sys\n"
        "cold = os.environ.get('NUMBA_CACHE_DIR', '')\n"
        "empty = bool(cold) and os.path.isdir(cold) and not os.listdir(cold)\n"
        "print(json.dumps({'import_s': 1.0 if empty else 0.5,\n"
        "                  'first_step_s': 2.0 if sys.argv[1:] == ['D', 'kinematic'] else -1}))\n"
    )
    times = first_call_times("D", "kinematic", script=script)
    assert times == {"cold_import_s": 1.0, "cold_first_step_s": 2.0, "warm_import_s": 0.5,
                     "warm_first_step_s": 2.0}  # fmt: skip


def test_bench_worlds_compares_the_same_evaluation_in_both_worlds(
    calibrated_wave_store, tmp_path, capsys
):
    argv = ["bench", "worlds", "--data", str(calibrated_wave_store.path), "--episodes", "1"]
    argv += ["--duration", "8", "--controller", "human,pi_saturation", "--workers", "1"]
    assert main([*argv, "--out", str(tmp_path / "w"), "--quiet"]) == 0
    line = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert line["bench"] == "worlds" and set(line["wall_s"]) == {"physics", "kinematic"}
    assert line["ego_speed_between_worlds"]["runs"] == 2
    assert line["ego_speed_between_worlds"]["median_mps"] < 0.5
    human = line["fidelity"]["human"]
    assert set(human) == {
        "ego_speed_rmse_mps",
        "ego_position_error_end_m",
        "speed_field_rmse_mps",
        "lane_changes_simulated",
    }
    mpg = line["controllers"]["ego_and_followers_mpg"]
    assert set(mpg["mean_change_pct"]) == {"physics", "kinematic"}
    for name in ("worlds.json", "worlds.md", "physics/episodes.parquet", "kinematic/summary.md"):
        assert (tmp_path / "w" / name).is_file()


def test_bench_camera_draws_the_recording_around_its_scene(doc, tmp_path, capsys, monkeypatch):
    """The recorded traffic within the far plane is drawn beside the bench's vehicles
    (here one car on each carriageway), and none of it where the bench's own vehicles
    drive (a recorded car among them, at MM 60.85, is left out)."""
    from sensors.camera import CameraRig
    from tests.conftest import write_day
    from twin.data.ingest import ingest

    docs = [
        doc("6386d89efb3ff533c12d0001", direction=1, mm=60.85, y_ft=-18.0, n=100),  # among
        doc("6386d89efb3ff533c12d0002", direction=1, mm=61.0, y_ft=-18.0, n=100),  # ahead
        doc("6386d89efb3ff533c12d0003", direction=-1, mm=60.9, n=100),  # across the barrier
    ]
    ingest([write_day(tmp_path / "day.json", docs)], tmp_path / "store", progress=False)
    drawn = []
    capture = CameraRig.capture

    def spy(self, ego_id, *args, traffic=None, **kwargs):
        frames = capture(self, ego_id, *args, traffic=traffic, **kwargs)
        vehicles = frames[0].vehicles
        drawn.append(sorted(vehicles.record_id[vehicles.replayed].tolist()))
        return frames

    monkeypatch.setattr(CameraRig, "capture", spy)
    argv = ["bench", "camera", "--data", str(tmp_path / "store"), "--frames", "2"]
    assert main([*argv, "--repeats", "1"]) == 0
    line = json.loads(capsys.readouterr().out.strip())
    assert line["bench"] == "camera" and line["pipeline_fps"] > 0 and line["raw_ms"] > 0
    assert line["replayed_vehicles_median"] == 2
    assert drawn and all(
        ids == ["6386d89efb3ff533c12d0002", "6386d89efb3ff533c12d0003"] for ids in drawn
    )
    assert main([*argv, "--repeats", "1", "--no-replay"]) == 0
    assert json.loads(capsys.readouterr().out.strip())["replayed_vehicles_median"] == 0
