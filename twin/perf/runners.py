"""Benchmarks of the runners by the number of workers: ``twin dataset`` and
``twin eval``."""

import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

from twin.perf.common import cpu_seconds, median, scaling, store_or_default, timed, worker_counts


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
    from twin.runners.dataset import DatasetConfig

    store = store_or_default(store)
    config = DatasetConfig()
    roads = tuple(road.value for road in store.roads)
    config = replace(
        config, frames_per_episode=frames, sampling=replace(config.sampling, roads=roads)
    )
    figures = {
        str(count): _dataset_figures(config, store, episodes, count, repeats)
        for count in worker_counts(workers)
    }
    return {
        "size": "640x480",
        "camera_rate_hz": config.cosim.camera.rate_hz,
        "episodes": episodes,
        "frames_per_episode": frames,
        "repeats": repeats,
        "by_workers": figures,
        "scaling": scaling(figures, "render_fps"),
    }


def _dataset_figures(config, store, episodes: int, workers: int, repeats: int) -> dict:
    """The dataset bench's figures for one number of ``workers``."""
    from twin.runners.dataset import generate

    render, total, busy = [], [], []
    for _ in range(repeats):
        with tempfile.TemporaryDirectory(prefix="twin-bench-dataset-") as tmp:
            cpu = cpu_seconds()
            result = generate(
                config, store, Path(tmp) / "ds", episodes, workers=workers, progress=False
            )
            cpu = cpu_seconds() - cpu
        render.append(result.samples_rendered / result.render_s)
        total.append(result.samples_rendered / result.total_s)
        busy.append(cpu / result.total_s)
    return {
        "render_fps": round(median(render), 2),
        "overall_fps": round(median(total), 2),
        "render_fps_runs": [round(v, 2) for v in render],
        "cores_busy": round(median(busy), 2),
        "fps_per_busy_core": round(median(np.divide(total, busy)), 2),
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

    store = store_or_default(store)
    config = EvalConfig(episodes=episodes, duration=duration, behaviours=tuple(behaviours))
    runs = episodes * len(behaviours)
    figures = {}
    for count in worker_counts(workers):
        walls = []
        for _ in range(repeats):
            with tempfile.TemporaryDirectory(prefix="twin-bench-eval-") as tmp:
                _, wall = timed(
                    evaluate, store, Path(tmp) / "eval", config, workers=count, progress=False
                )
            walls.append(wall)
        wall = median(walls)
        figures[str(count)] = {
            "wall_s": round(wall, 2),
            "runs_per_min": round(60.0 * runs / wall, 3),
            "simulated_s_per_wall_s": round(runs * duration / wall, 2),
        }
    return {
        "episodes": episodes,
        "duration_s": duration,
        "behaviours": list(behaviours),
        "repeats": repeats,
        "by_workers": figures,
        "scaling": scaling(figures, "wall_s", lower_is_better=True),
    }
