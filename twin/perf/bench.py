"""Benchmarks behind ``twin bench``: each returns a dict of figures (medians of repeats).

The command line prints each as one JSON line with the commit, so results can be
compared between commits. Targets live here, not in timed unit tests.
"""

import json
import math
import os
import platform
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from twin.data import synth
from twin.data.empirical import EmpiricalTraffic


def query(store, *, repeats: int = 5, calls: int = 2000) -> dict:
    """Snapshot latency on a 400 m window in the densest traffic (scenario B's wave)."""
    traffic = EmpiricalTraffic(store)
    t0 = synth.SCENARIO_TIME
    x_min, x_max = 500.0, 900.0
    times = t0 + np.arange(calls) * 0.01
    traffic.snapshot("westbound", t0, x_min, x_max)  # build the frame table once
    medians = []
    for _ in range(repeats):
        latency = np.empty(calls)
        for i, t in enumerate(times):
            start = time.perf_counter()
            traffic.snapshot("westbound", float(t), x_min, x_max)
            latency[i] = time.perf_counter() - start
        medians.append(float(np.median(latency)))
    vehicles = len(traffic.snapshot("westbound", t0, x_min, x_max))
    return {
        "snapshot_median_us": round(1e6 * float(np.median(medians)), 2),
        "target_us": 200,
        "vehicles_in_window": vehicles,
        "window_m": x_max - x_min,
        "repeats": repeats,
        "calls_per_repeat": calls,
    }


def synth_bench(*, minutes: float = 10.0, repeats: int = 3) -> dict:
    """Time to simulate and write ``minutes`` of preset B (one direction) as I-24 JSON."""
    seconds, sizes = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(repeats):
            config = replace(synth.PRESET_B, minutes=minutes, seed=seed)
            start = time.perf_counter()
            result = synth.synthesize(config)
            path = synth.write_i24_json(result, Path(tmp) / "day.json")
            seconds.append(time.perf_counter() - start)
            sizes.append(path.stat().st_size)
    return {
        "minutes": minutes,
        "median_s": round(float(np.median(seconds)), 2),
        "target_s": 60,
        "file_mb": round(float(np.median(sizes)) / 1e6, 1),
        "repeats": repeats,
    }


def map_bench(*, repeats: int = 5) -> dict:
    """Time of a full map build (sources to files on disk, no cache) and its size."""
    from mapgen.build import build_map

    seconds = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(repeats):
            start = time.perf_counter()
            bundle = build_map(Path(tmp) / "map", seed=seed)
            seconds.append(time.perf_counter() - start)
        glb_mb = (bundle.folder / "scene.glb").stat().st_size / 1e6
    return {
        "median_s": round(float(np.median(seconds)), 3),
        "target_s": 10,
        "triangles_visual": bundle.description["triangles"]["visual"],
        "triangles_collision": bundle.description["triangles"]["collision"],
        "triangles_per_part": {part.name: part.triangles for part in bundle.parts},
        "glb_mb": round(glb_mb, 2),
        "repeats": repeats,
    }


def physics_bench(*, counts=(100, 200), steps: int = 500, repeats: int = 3) -> dict:
    """Wall time of one physics step (rays, vehicle model, engine step, state read-back)
    with n vehicles of the corridor's class mix in the four lanes of both carriageways
    of the I-24 mesh, holding their speed (a vehicle collision would make the engine's
    contact solver part of the figure)."""
    from mapgen.build import default_map
    from twin.core.i24 import LANE_WIDTH
    from twin.core.vehicle_classes import vehicle_classes
    from twin.physics.world import PhysicsWorld, SpawnStates

    table = vehicle_classes()
    bundle = default_map()
    figures = {}
    for n in counts:
        medians = []
        for repeat in range(repeats):
            rng = np.random.default_rng(repeat)
            lane = np.arange(n) % 4
            classes = rng.choice(7, n, p=table.column("share"))
            sizes = [table.column(c)[classes] for c in ("length_m", "width_m", "height_m")]
            states = SpawnStates.make(
                np.where(np.arange(n) % 8 < 4, 1, -1),
                -350.0 + (np.arange(n) // 8) * (1900.0 / max(1, n // 8)),
                (1.5 + lane) * LANE_WIDTH,
                np.array([24.0, 27.0, 30.0, 33.0])[lane],  # one speed per lane: no crashes
                classes,
                *sizes,
            )
            with PhysicsWorld(bundle) as world:
                world.spawn(states)
                world.set_controls(accel=np.zeros(n))
                for _ in range(20):
                    world.step()
                    world.states()
                seconds = np.empty(steps)
                for k in range(steps):
                    start = time.perf_counter()
                    world.step()
                    world.states()
                    seconds[k] = time.perf_counter() - start
                medians.append(float(np.median(seconds)))
        step = float(np.median(medians))
        figures[f"vehicles_{n}"] = {
            "step_ms": round(1e3 * step, 3),
            "real_time_factor": round(0.01 / step, 2),
        }
    figures["targets"] = {"vehicles_100": ">= 10 x (<= 1 ms)", "vehicles_200": ">= 5 x"}
    figures.update({"dt": 0.01, "steps": steps, "repeats": repeats})
    return figures


def traffic_bench(*, vehicles: int = 100, steps: int = 3000, repeats: int = 3) -> dict:
    """The traffic manager's decision step and the closed loop (manager, controls,
    physics, state read-back) for ``vehicles`` on the I-24 mesh, in a circuit.

    Each repeat runs ``steps`` closed-loop steps after 2 s of settling; the figures
    are medians over steps, then over repeats. The decision step is also given as a
    mean and 99th percentile, since MOBIL runs only on the steps where a driver is
    due to decide.
    """
    from mapgen.build import default_map
    from twin.physics.world import PhysicsWorld
    from twin.traffic.circuit import Circuit, CircuitSpec
    from twin.traffic.manager import TrafficConfig, TrafficManager

    bundle = default_map()
    headings = {r: bundle.road.heading(r) for r in (1, -1)}
    decision, loop, means, p99 = [], [], [], []
    for repeat in range(repeats):
        with PhysicsWorld(bundle) as world:
            manager = TrafficManager(TrafficConfig(seed=repeat), headings)
            circuit = Circuit(world, manager, CircuitSpec(vehicles=vehicles, seed=repeat))
            manager_s, loop_s = np.empty(steps), np.empty(steps)
            for k in range(-200, steps):
                start = time.perf_counter()
                states = world.states()
                middle = time.perf_counter()
                commands = manager.step(states)
                end = time.perf_counter()
                world.set_controls(commands.id, accel=commands.accel, steer=commands.steer)
                world.step()
                circuit.recycle(states)
                if k >= 0:
                    manager_s[k] = end - middle
                    loop_s[k] = time.perf_counter() - start
        decision.append(float(np.median(manager_s)))
        means.append(float(np.mean(manager_s)))
        p99.append(float(np.percentile(manager_s, 99)))
        loop.append(float(np.median(loop_s)))
    step = float(np.median(loop))
    return {
        "vehicles": vehicles,
        "decision_ms": round(1e3 * float(np.median(decision)), 3),
        "decision_mean_ms": round(1e3 * float(np.median(means)), 3),
        "decision_p99_ms": round(1e3 * float(np.median(p99)), 3),
        "closed_loop_ms": round(1e3 * step, 3),
        "real_time_factor": round(0.01 / step, 2),
        "lane_changes_per_repeat": manager.lane_changes,
        "targets": {"decision_ms": "<= 0.3", "real_time_factor": ">= 5"},
        "dt": 0.01,
        "steps": steps,
        "repeats": repeats,
    }


def run_bench(store=None, *, scenario: str = "B", repeats: int = 3) -> dict:
    """The whole cosimulation loop of a paper scenario on the embedded data, without
    cameras or output files: data queries, desired speeds, traffic manager, physics,
    despawns, spawns, ghost reload and the trajectory log, per step (medians of the
    repeats' means, each repeat a fresh episode with its own seed)."""
    from mapgen.build import default_map
    from twin.cosim.config import PRESETS
    from twin.cosim.cosimulator import Cosimulator
    from twin.data.embedded import default_store

    traffic = EmpiricalTraffic(store if store is not None else default_store(progress=False))
    bundle = default_map()
    figures = []
    for repeat in range(repeats):
        config = replace(PRESETS[scenario], seed=repeat)
        with Cosimulator(config, traffic, bundle) as sim:
            sim.reset()
            start = time.perf_counter()
            sim.run()
            wall = time.perf_counter() - start
            per_step = sim.times.per_step()
            per_step["real_time_factor"] = sim.sim_time / wall
            per_step["vehicles_mean"] = float(np.mean(sim.log.vehicles().groupby("time").size()))
        figures.append(per_step)

    def median(name):
        return float(np.median([f[name] for f in figures]))

    step = median("step_ms")
    return {
        "scenario": scenario,
        "step_ms": round(step, 3),
        "real_time_factor": round(median("real_time_factor"), 2),
        "ghost_reload_ms": round(median("ghost_reload_ms"), 4),
        "ghost_reload_share": round(median("ghost_reload_ms") / step, 4),
        "physics_ms": round(median("physics_ms"), 3),
        "manager_ms": round(median("manager_ms"), 3),
        "vehicles_mean": round(median("vehicles_mean"), 1),
        "targets": {"real_time_factor": ">= 3", "ghost_reload_share": "<= 0.05"},
        "dt": 0.01,
        "repeats": repeats,
    }


def camera_bench(
    store=None,
    *,
    renderer: str = "tiny",
    vehicles: int = 100,
    frames: int = 30,
    repeats: int = 3,
    replay: bool = True,
) -> dict:
    """Frames per second of the default front camera (640x480 RGB, depth, semantic and
    instance) on an ego in the middle of ``vehicles`` vehicles (the ego included) in
    the four eastbound lanes, nose to tail over about 300 m, at 27 m/s; 0.1 s of physics
    between frames, so the camera sees the scene from a new place each frame.

    With ``replay``, the recorded traffic of ``store`` (default: the embedded data)
    from the scenarios' time on is drawn too, as in ``twin run --camera``: every
    recorded vehicle within the far plane on both carriageways (the westbound wave
    across the barrier, the eastbound traffic past the bench's own vehicles), but
    the eastbound ones where the bench's vehicles drive.

    Two passes of ``frames`` frames each repeat: the capture alone (renderer, labels,
    depth, poses), then the whole pipeline with the files written (PNGs, JSON, MP4; the
    writer runs on a thread, so it is measured as throughput: wall time including the
    final flush, over frames). Each pass also times the raw renderer
    (``getCameraImage``) on its own frames, and the overhead of labels and writing is
    the pipeline's time over the raw renderer's in the same pass. Means per frame
    within a pass, medians over the repeats.
    """
    from mapgen.build import default_map
    from sensors.camera import CameraRig, CameraSpec
    from sensors.writer import FrameWriter
    from twin.core.i24 import LANE_WIDTH
    from twin.core.vehicle_classes import vehicle_classes
    from twin.data.embedded import default_store
    from twin.physics.world import PhysicsWorld, SpawnStates

    table = vehicle_classes()
    bundle = default_map()
    recording = None
    if replay:
        recording = EmpiricalTraffic(store if store is not None else default_store(progress=False))
    capture, pipeline, replayed, triangles = [], [], [], []
    for repeat in range(repeats):
        rng = np.random.default_rng(repeat)
        lane = np.arange(vehicles) % 4
        classes = rng.choice(7, vehicles, p=table.column("share"))
        ego = (vehicles // 2) // 4 * 4 + 1  # lane -2, in the middle of its lane
        classes[ego] = 0
        sizes = [table.column(c)[classes] for c in ("length_m", "width_m", "height_m")]
        x = np.empty(vehicles)
        for k in range(4):  # nose to tail with 4 to 8 m gaps, centred on x = 400 m
            mine = np.flatnonzero(lane == k)
            room = sizes[0][mine] + rng.uniform(4.0, 8.0, mine.size)
            x[mine] = np.concatenate([[0.0], np.cumsum(room)[:-1]])  # backs
        x += 400.0 - x[ego]
        speed = np.full(vehicles, 27.0)  # one speed: the scene drives with the ego
        states = SpawnStates.make(1, x, (1.5 + lane) * LANE_WIDTH, speed, classes, *sizes)
        with (
            PhysicsWorld(bundle) as world,
            tempfile.TemporaryDirectory(prefix="twin-bench-camera-") as tmp,
        ):
            ids = world.spawn(states)
            world.set_controls(accel=np.zeros(vehicles))
            rig = CameraRig(world, bundle, (CameraSpec(),), renderer=renderer)
            traffic = None
            if recording is not None:
                traffic = _BenchRecording(recording, world, bundle.road, frames)
            try:
                for with_files in (False, True):
                    writer = FrameWriter(Path(tmp), rig.cameras) if with_files else None
                    rig.view.raw_s = 0.0
                    busy = 0.0
                    for k in range(frames):
                        for _ in range(10):
                            world.step()
                        start = time.perf_counter()
                        at = synth.SCENARIO_TIME + 0.1 * k  # the morning sun of the scenarios
                        if traffic is not None:
                            traffic.t = at
                        (frame,) = rig.capture(
                            int(ids[ego]), time=at, sim_time=0.1 * k, traffic=traffic
                        )
                        replayed.append(int(np.count_nonzero(frame.vehicles.replayed)))
                        triangles.append(rig.view.vehicle_triangles())
                        if writer is not None:
                            writer.write(frame)
                        busy += time.perf_counter() - start
                    if writer is None:
                        capture.append((busy / frames, rig.view.raw_s / frames))
                    else:
                        start = time.perf_counter()
                        writer.close()
                        busy += time.perf_counter() - start
                        pipeline.append((busy / frames, rig.view.raw_s / frames))
            finally:
                rig.close()
    capture = np.median(np.array(capture), axis=0)  # (capture, raw) per frame [s]
    pipeline = np.median(np.array(pipeline), axis=0)  # (pipeline, raw) per frame [s]
    return {
        "renderer": renderer,
        "vehicles": vehicles,
        "size": "640x480",
        "frames": frames,
        "repeats": repeats,
        "replayed_vehicles_median": float(np.median(replayed)),
        # vehicle model triangles a frame: at their levels of detail, and full models
        "vehicle_triangles_median": float(np.median([t[0] for t in triangles])),
        "vehicle_triangles_full_median": float(np.median([t[1] for t in triangles])),
        "raw_ms": round(float(pipeline[1]) * 1e3, 2),
        "raw_fps": round(1.0 / float(pipeline[1]), 2),
        "capture_ms": round(float(capture[0]) * 1e3, 2),
        "capture_raw_ms": round(float(capture[1]) * 1e3, 2),
        "pipeline_ms": round(float(pipeline[0]) * 1e3, 2),
        "pipeline_fps": round(1.0 / float(pipeline[0]), 2),
        "labels_and_writing_overhead_percent": round(
            100.0 * float(pipeline[0] / pipeline[1] - 1), 1
        ),
    }


class _BenchRecording:
    """The recording drawn around the camera bench's scene (for ``CameraRig.capture``):
    the recorded vehicles within the far plane of the ego at time ``t`` (set before each
    capture), but the eastbound ones among the bench's own vehicles (their stations
    and 10 m either side), which are not recorded."""

    def __init__(self, recording, world, road_model, frames: int):
        from sensors.camera import CameraSpec
        from sensors.replay import HEADING_LEAD, RecordedView

        self.world, self.road_model = world, road_model
        self.t = synth.SCENARIO_TIME
        self.view = RecordedView(recording, road_model, CameraSpec.far)
        self.view.preload(self.t, self.t + 0.1 * frames + HEADING_LEAD)
        self.none = np.zeros(len(recording.store.trajectory_arrays["id"]), dtype=bool)

    def replayed(self):
        states = self.world.states()
        station = self.road_model.station(1, states.x)
        replayed = self.view.around(self.t, float(np.median(station)), self.none)
        own = self.road_model.to_road(replayed.position).x if len(replayed) else np.empty(0)
        among = (replayed.road > 0) & (own >= station.min() - 10.0) & (own <= station.max() + 10.0)
        return replayed.take(~among)

    def record_of(self, ids):
        ids = np.asarray(ids, np.int64)
        records = np.array([f"bench-{i}" for i in ids.tolist()], dtype=object)
        return records, np.ones(ids.size, np.int64)


def dataset_bench(
    store=None,
    *,
    episodes: int = 16,
    frames: int = 20,
    workers: tuple[int, ...] | None = None,
    repeats: int = 3,
) -> dict:
    """Labelled frames per second of ``twin dataset`` with the local engine, by the
    number of workers (default 1 up to the cores available).

    Each repeat makes a fresh dataset of ``episodes`` episodes of ``frames`` frames
    (the default front camera, 640x480, labels and every KITTI/COCO file) from
    ``store`` (default: the embedded data), drawn from all its roads. Two rates: over
    the rendering (pool start, episodes, files) and over the whole command (also
    drawing the episodes and assembling KITTI, COCO and the manifest). Also the
    cores kept busy (CPU seconds of this process and its workers over the wall time;
    one worker already keeps more than one core busy, as its files are encoded on a
    thread) and the frames per busy core. Medians over the repeats; scaling is the
    rendering rate of the most workers over that of one.
    """
    from dataclasses import replace as with_values

    from twin.runners.dataset import DatasetConfig
    from twin.runners.dataset_runner import generate
    from twin.runners.run import open_data

    store = store or open_data(None, progress=False)
    cores = len(os.sched_getaffinity(0))
    workers = workers or tuple(range(1, cores + 1))
    config = DatasetConfig()
    roads = tuple(road.value for road in store.roads)
    config = with_values(
        config, frames_per_episode=frames, sampling=with_values(config.sampling, roads=roads)
    )
    figures = {}
    for count in workers:
        render, total, cores = [], [], []
        for _ in range(repeats):
            with tempfile.TemporaryDirectory(prefix="twin-bench-dataset-") as tmp:
                cpu = _cpu_seconds()
                result = generate(
                    config, store, Path(tmp) / "ds", episodes, workers=count, progress=False
                )
                cpu = _cpu_seconds() - cpu
            render.append(result.samples_rendered / result.render_s)
            total.append(result.samples_rendered / result.total_s)
            cores.append(cpu / result.total_s)
        figures[str(count)] = {
            "render_fps": round(float(np.median(render)), 2),
            "overall_fps": round(float(np.median(total)), 2),
            "render_fps_runs": [round(v, 2) for v in render],
            "cores_busy": round(float(np.median(cores)), 2),
            "fps_per_busy_core": round(float(np.median(np.divide(total, cores))), 2),
        }
    most = str(max(workers))
    return {
        "size": "640x480",
        "camera_rate_hz": config.cosim.camera.rate_hz,
        "episodes": episodes,
        "frames_per_episode": frames,
        "repeats": repeats,
        "by_workers": figures,
        "scaling": round(figures[most]["render_fps"] / figures["1"]["render_fps"], 2)
        if "1" in figures and most != "1"
        else None,
    }


def eval_bench(
    store=None,
    *,
    episodes: int = 4,
    duration: float = 60.0,
    behaviours: tuple[str, ...] = ("paper",),
    workers: tuple[int, ...] | None = None,
    repeats: int = 1,
) -> dict:
    """Wall time of ``twin eval`` by the number of workers (default 1 up to the cores):
    ``episodes`` episodes of ``duration`` seconds from congested cells of ``store``'s
    westbound data (default: the embedded data), each with ``behaviours``. Medians over
    the repeats; scaling is the episodes per second of the most workers over one's."""
    from twin.runners.evaluation import EvalConfig, evaluate
    from twin.runners.run import open_data

    store = store or open_data(None, progress=False)
    cores = len(os.sched_getaffinity(0))
    workers = workers or tuple(range(1, cores + 1))
    config = EvalConfig(episodes=episodes, duration=duration, behaviours=tuple(behaviours))
    runs = episodes * len(behaviours)
    figures = {}
    for count in workers:
        walls = []
        for _ in range(repeats):
            with tempfile.TemporaryDirectory(prefix="twin-bench-eval-") as tmp:
                start = time.perf_counter()
                evaluate(store, Path(tmp) / "eval", config, workers=count, progress=False)
                walls.append(time.perf_counter() - start)
        wall = float(np.median(walls))
        figures[str(count)] = {
            "wall_s": round(wall, 2),
            "runs_per_min": round(60.0 * runs / wall, 3),
            "simulated_s_per_wall_s": round(runs * duration / wall, 2),
        }
    most = str(max(workers))
    return {
        "episodes": episodes,
        "duration_s": duration,
        "behaviours": list(behaviours),
        "repeats": repeats,
        "by_workers": figures,
        "scaling": round(figures["1"]["wall_s"] / figures[most]["wall_s"], 2)
        if "1" in figures and most != "1"
        else None,
    }


def env_bench(
    data: str | None = None, *, steps: int = 200, workers: int | None = None, repeats: int = 3
) -> dict:
    """Env steps per second of ``i24twin/WaveDampening-v0`` (10 Hz control, 0.01 s
    physics, the default windows, no cameras) on ``data`` (default: the embedded
    morning): one env, and an ``AsyncVectorEnv`` of ``workers`` envs (default: the
    cores), each stepping ``steps`` times with a zero action after a reset (not timed).
    Medians over the repeats; scaling is the vector env's steps per second over one's."""
    import gymnasium as gym

    from twin.control.env import ENV_ID

    workers = workers or len(os.sched_getaffinity(0))

    def make():
        return gym.make(ENV_ID, data=data, duration=steps * 0.1 + 1.0)

    def rate(env, n_envs: int, seed) -> float:
        env.reset(seed=seed)
        action = np.zeros((n_envs, 1) if n_envs > 1 else (1,), np.float32)
        start = time.perf_counter()
        for _ in range(steps):
            env.step(action)
        return n_envs * steps / (time.perf_counter() - start)

    one, vector = [], []
    for k in range(repeats):
        env = make()
        one.append(rate(env, 1, k))
        env.close()
        envs = gym.vector.AsyncVectorEnv([make] * workers)
        vector.append(rate(envs, workers, [k * workers + i for i in range(workers)]))
        envs.close()
    single, many = float(np.median(one)), float(np.median(vector))
    return {
        "steps": steps,
        "repeats": repeats,
        "env_steps_per_s": round(single, 2),
        "vector_workers": workers,
        "vector_env_steps_per_s": round(many, 2),
        "scaling": round(many / single, 2),
    }


def calibrate_bench(store=None, *, road: str = "westbound", repeats: int = 3) -> dict:
    """Wall time of ``twin calibrate`` on ``road`` of ``store`` (default: the embedded
    data; nothing is written), median of the repeats, with what it fitted."""
    from twin.calibration.calibrate import calibrate
    from twin.runners.run import open_data

    store = store or open_data(None, progress=False)
    walls = []
    for _ in range(repeats):
        start = time.perf_counter()
        doc, _ = calibrate(store, [road])
        walls.append(time.perf_counter() - start)
    section = doc["roads"][road]
    return {
        "road": road,
        "trajectories": section["trajectories"],
        "minutes": round((section["window"]["until"] - section["window"]["from"]) / 60.0, 2),
        "followers_fitted": section["car_following"]["fitted"],
        "repeats": repeats,
        "wall_s": round(float(np.median(walls)), 2),
        "wall_s_runs": [round(w, 2) for w in walls],
    }


def _cpu_seconds() -> float:
    """CPU seconds of this process and of its children that have ended."""
    import resource

    own = resource.getrusage(resource.RUSAGE_SELF)
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def ingest_bench(*, size_mb: float = 300.0, repeats: int = 3) -> dict:
    """Ingest throughput and peak memory on a synthetic day of at least ``size_mb``.

    Peak memory is the resident set of a fresh process running only the ingest; it is
    measured on the full file and on a quarter of it, to show it does not grow with
    file size.
    """
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        files = {}
        for label, mb in (("quarter", size_mb / 4), ("full", size_mb)):
            minutes = math.ceil(mb / 10.5)  # preset B writes about 10.9 MB per minute
            result = synth.synthesize(replace(synth.PRESET_B, minutes=minutes))
            files[label] = synth.write_i24_json(result, tmp / f"{label}.json")
            del result
        figures = {}
        for label, path in files.items():
            seconds, peaks = [], []
            for _ in range(repeats if label == "full" else 1):
                elapsed, peak = _ingest_in_child(path, tmp / f"store-{label}")
                seconds.append(elapsed)
                peaks.append(peak)
            mb = path.stat().st_size / 1e6
            figures[label] = {
                "file_mb": round(mb, 1),
                "median_s": round(float(np.median(seconds)), 2),
                "throughput_mb_s": round(mb / float(np.median(seconds)), 1),
                "peak_rss_mb": round(max(peaks), 1),
            }
    return {**figures["full"], "quarter_file": figures["quarter"], "repeats": repeats}


def _ingest_in_child(path: Path, out: Path) -> tuple[float, float]:
    """Ingest in a fresh process; return its seconds and peak resident memory [MB].

    The peak is the child's VmHWM: ru_maxrss would include the parent's peak, which
    a forked child inherits on Linux.
    """
    code = (
        "import sys, time, json\n"
        "from twin.data.ingest import ingest\n"
        "start = time.perf_counter()\n"
        "ingest([sys.argv[1]], sys.argv[2], progress=False)\n"
        "elapsed = time.perf_counter() - start\n"
        "status = open('/proc/self/status').read().split('VmHWM:')[1].split()[0]\n"
        "print(json.dumps([elapsed, int(status) / 1024]))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code, str(path), str(out)],
        capture_output=True,
        text=True,
        check=True,
    )
    elapsed, peak = json.loads(done.stdout.strip().splitlines()[-1])
    return elapsed, peak


def context() -> dict:
    """Commit and machine, printed with every benchmark line."""
    try:
        commit = (
            subprocess.run(
                ["git", "rev-parse", "--short", "HEAD"],
                capture_output=True,
                text=True,
                cwd=Path(__file__).parent,
            ).stdout.strip()
            or None
        )
    except OSError:
        commit = None
    return {
        "commit": commit,
        "python": platform.python_version(),
        "cpus": len(os.sched_getaffinity(0)),
    }
