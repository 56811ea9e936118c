"""The dataset runner: ``twin dataset`` from the episodes to the finished folder.

:func:`generate` draws the episodes, claims the folder, renders the episodes not yet
complete with an engine, and assembles KITTI, COCO and the manifest
(:mod:`twin.runners.dataset` for what is written). Engines (:mod:`twin.runners.engines`, shared
with ``twin eval``):

* ``local``: this process (one worker) or a pool of processes started fresh
  (``spawn``: no forked threads or pybullet state), each writing its episodes
  straight into the dataset folder, atomically;
* ``ray``: the same episodes as Ray tasks on a local Ray instance or a cluster; a
  task renders into a scratch folder on its node and returns the files, which the
  driver writes atomically, so the nodes share no file system.
"""

import json
import os
import shutil
import tempfile
import time
from dataclasses import dataclass, replace
from pathlib import Path

from twin.core.atomic import AtomicFolder, remove_stale
from twin.core.locks import output_lock
from twin.cosim.behaviour import with_car_following
from twin.data.store import TrajectoryStore
from twin.runners.dataset.assemble import assemble
from twin.runners.dataset.config import (
    EPISODE,
    EPISODES,
    DatasetConfig,
    DatasetError,
    resolved_renderer,
)
from twin.runners.dataset.episode import render_episode
from twin.runners.dataset.folder import claim_folder, draw_episodes, episode_folder, is_episode
from twin.runners.engines import ENGINES, run_jobs, tick, where, worker_data


@dataclass(frozen=True)
class DatasetResult:
    """What :func:`generate` made and measured.

    Attributes:
        folder: the dataset. manifest: its ``manifest.json``.
        episodes_rendered, samples_rendered: in this run (complete episodes are skipped).
        render_s: [s] wall time of the rendering; total_s: of the whole run.
    """

    folder: Path
    manifest: dict
    episodes_rendered: int
    samples_rendered: int
    render_s: float
    total_s: float


def generate(
    config: DatasetConfig,
    store: TrajectoryStore,
    out: str | os.PathLike,
    episodes: int,
    *,
    workers: int = 1,
    engine: str = "local",
    ray_address: str | None = None,
    bundle=None,
    progress: bool = True,
) -> DatasetResult:
    """Make (or complete) the dataset ``out`` of ``episodes`` episodes on the map
    ``bundle`` (default: the default map).

    Raises:
        DatasetError: bad arguments, ``out`` holds something else or a dataset made
            with other settings, Ray is missing, or an episode failed (the complete
            episodes are kept; rerun to resume).
        SamplingError: episodes cannot be drawn from the data.
    """
    from mapgen.build import default_map
    from twin.core.progress import progress_bar

    start = time.perf_counter()
    if not isinstance(episodes, int) or isinstance(episodes, bool) or episodes < 1:
        raise DatasetError(f"--episodes must be an integer >= 1, got {episodes!r}")
    if not isinstance(workers, int) or isinstance(workers, bool) or workers < 1:
        raise DatasetError(f"--workers must be an integer >= 1, got {workers!r}")
    if engine not in ENGINES:
        raise DatasetError(f"--engine must be one of {ENGINES}, got {engine!r}")
    out = Path(out)
    config = resolved_renderer(config)
    # auto: the model the store's calibration fitted, kept as such in config.toml
    config = replace(config, cosim=with_car_following(config.cosim, store))
    bundle = bundle or default_map(progress=progress)
    specs = draw_episodes(config, store, bundle, episodes)
    claim_folder(out, config, store, bundle)  # checks --out before anything is made beside it
    with output_lock(out, "twin dataset"):
        remove_stale(out / EPISODES)
        todo = [s for s in specs if not is_episode(episode_folder(out, s.index))]
        cameras = len(config.cosim.camera.cameras)
        render_start = time.perf_counter()
        with progress_bar(
            progress=progress,
            total=len(todo) * config.frames_per_episode * cameras,
            unit="frame",
            desc=f"dataset {out.name}: {len(todo)} of {episodes} episodes to render",
        ) as bar:
            frames_done = _Progress(bar, config.frames_per_episode * cameras)
            if not todo:
                rendered = 0
            elif engine == "ray":
                rendered = _run_ray(
                    config, todo, store, bundle, out, workers, ray_address, frames_done
                )
            else:
                rendered = _run_local(config, todo, store, bundle, out, workers, frames_done)
        render_s = time.perf_counter() - render_start
        manifest = assemble(out, config, specs)
        return DatasetResult(
            folder=out,
            manifest=manifest,
            episodes_rendered=len(todo),
            samples_rendered=rendered,
            render_s=render_s,
            total_s=time.perf_counter() - start,
        )


# -- engines (twin.runners.engines) ----------------------------------------------------------


def _write_episode(config, spec, store, bundle, out: Path, on_frames=None) -> int:
    """Render episode ``spec`` into ``out``'s episodes, atomically; its sample count."""
    target = episode_folder(out, spec.index)
    folder = AtomicFolder(target, recognise=is_episode, kind="dataset episode")
    with folder:
        description = render_episode(config, spec, store, bundle, folder.tmp, on_frames)
    return len(description["samples"])


class _Progress:
    """The bar over frames: frames as they are taken; the frames an episode did not
    take (it ended early, or was skipped) come off the total when it is done."""

    def __init__(self, bar, per_episode: int):
        self.bar = bar
        self.per_episode = per_episode

    def frames(self, n: int) -> None:
        self.bar.update(n)

    def episode(self, samples: int) -> int:
        if samples < self.per_episode:
            self.bar.total -= self.per_episode - samples
            self.bar.refresh()
        return samples


def _describe(job) -> str:
    spec = job[1]
    return (
        f"episode {spec.index} ({spec.road} lane {spec.lane} x {spec.x:g} m, unix {spec.time:.2f})"
    )


def _run_local(config, specs, store, bundle, out: Path, workers: int, bar: _Progress) -> int:
    """Render ``specs`` in this process (one worker) or a pool of processes, each
    writing its episodes straight into the dataset folder."""
    rendered = []
    run_jobs(
        _pool_episode,
        [(config, spec, where(store, bundle), str(out)) for spec in specs],
        workers=workers,
        on_done=lambda k, samples: rendered.append(bar.episode(samples)),
        on_tick=bar.frames,
        describe=_describe,
        error_type=DatasetError,
    )
    return sum(rendered)


def _pool_episode(config, spec, location, out: str) -> int:
    store, bundle = worker_data(location)
    return _write_episode(config, spec, store, bundle, Path(out), tick)


def _episode_files(config, spec, location) -> dict[str, bytes]:
    """A Ray task: render episode ``spec`` in a scratch folder; its files by path."""
    store, bundle = worker_data(location)
    scratch = Path(tempfile.mkdtemp(prefix="i24-twin-episode-"))
    try:
        render_episode(config, spec, store, bundle, scratch)
        return {
            str(path.relative_to(scratch)): path.read_bytes()
            for path in sorted(scratch.rglob("*"))
            if path.is_file()
        }
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


def _run_ray(config, specs, store, bundle, out: Path, workers: int, address, bar: _Progress) -> int:
    """Render ``specs`` as Ray tasks (a local Ray instance of ``workers`` CPUs, or the
    cluster at ``address``); the driver writes each episode's files atomically."""
    rendered = []

    def write(k: int, files: dict) -> None:
        spec = specs[k]
        target = episode_folder(out, spec.index)
        with AtomicFolder(target, recognise=is_episode, kind="dataset episode") as folder:
            for name, content in files.items():
                path = folder.tmp / name
                path.parent.mkdir(parents=True, exist_ok=True)
                path.write_bytes(content)
        samples = len(json.loads(files[EPISODE])["samples"])
        bar.frames(samples)
        rendered.append(bar.episode(samples))

    run_jobs(
        _episode_files,
        [(config, spec, where(store, bundle)) for spec in specs],
        engine="ray",
        workers=workers,
        ray_address=address,
        on_done=write,
        describe=_describe,
        error_type=DatasetError,
    )
    return sum(rendered)


def summary(result: DatasetResult) -> str:
    """A few lines for the terminal: what was rendered, how fast, what the dataset holds."""
    stats = result.manifest["statistics"]
    per_class = ", ".join(f"{name} {n}" for name, n in stats["per_class"].items() if n)
    levels = stats["occlusion_levels"]
    lines = [
        f"dataset folder: {result.folder}",
        f"episodes: {stats['episodes']} ({stats['episodes_congested']} congested, "
        f"{stats['episodes_skipped']} skipped, {stats['episodes_ended_early']} ended early); "
        f"rendered now: {result.episodes_rendered}",
        f"samples: {stats['samples']}; vehicles kept {stats['vehicles_kept']} "
        f"({stats['kept_per_sample']} a sample), DontCare {stats['vehicles_dont_care']}",
        f"kept by class: {per_class or 'none'}; occlusion levels 0/1/2: "
        f"{levels['0']}/{levels['1']}/{levels['2']}; truncated {stats['truncated']}",
        "kept by distance: "
        + ", ".join(f"{band} m {n}" for band, n in stats["distance_bands"].items()),
    ]
    if stats["distance_m"]:
        d, h = stats["distance_m"], stats["height_px"]
        lines.append(
            f"distance median {d['median']} m (max {d['max']}), box height median {h['median']} px"
        )
    motion = stats.get("motion")  # absent in a manifest written before the check
    if motion and motion["pairs"]:
        lines.append(
            f"motion: {motion['violations']} of {motion['pairs']} frame-to-frame moves beyond "
            f"what the speed allows (largest excess {motion['max_excess_m']} m)"
        )
    if result.samples_rendered:
        lines.append(
            f"rendered {result.samples_rendered} samples in {result.render_s:.1f} s: "
            f"{result.samples_rendered / result.render_s:.1f} labelled frames/s "
            f"({result.total_s:.1f} s in all)"
        )
    return "\n".join(lines)
