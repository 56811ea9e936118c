"""``twin dataset``: labelled camera datasets from many cosimulation episodes.

Episodes are drawn from the recorded traffic (:mod:`twin.runners.episodes`); each is a
cosimulation whose ego cameras take ``frames_per_episode`` frames at the camera
rate after ``warmup_s``. Every frame of every camera is one sample, labelled by
:mod:`sensors.labels` and written in KITTI's object layout and as COCO instances;
:mod:`twin.runners.dataset_runner` runs the episodes (a process pool or Ray) and assembles them.

The dataset folder::

    DIR/
      dataset.json            what the dataset is made of: configuration, data, version
                              (a rerun with other settings is refused)
      config.toml             the resolved configuration (loads back with --config)
      manifest.json           episodes, samples, statistics; written last
      coco.json               COCO instances of the kept vehicles (images are
                              training/image_2/NNNNNN.png)
      training/               KITTI object layout, samples numbered 000000, 000001, ...
        image_2/NNNNNN.png    8-bit RGB
        label_2/NNNNNN.txt    KITTI labels (sensors.kitti)
        calib/NNNNNN.txt      KITTI calibration
        depth_2/NNNNNN.png    KITTI depth map: uint16, metres x 256, 0: none
        semantic_2/NNNNNN.png 8-bit semantic class ids (assets/semantic_classes.csv)
        instance_2/NNNNNN.png 16-bit twin vehicle id + 1, 0: no vehicle
        labels/NNNNNN.json    every visible vehicle with all its labels (sensors.labels)
      episodes/EEEEEE/        one folder per episode, written under a temporary name
                              and renamed when complete: episode.json and the same
                              sub-folders, samples numbered within the episode

The ``training/`` files are hard links to the episodes' files (copies where the
file system has no links), numbered in episode order; ``training/``, ``coco.json``
and ``manifest.json`` are rebuilt from the complete episodes at the end of a run.
A rerun of the same command skips the complete episodes, so an interrupted run
resumes where it stopped and ends with the same dataset as an uninterrupted one.
"""

import json
import math
import os
import shutil
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import cv2
import numpy as np

from sensors.camera import CameraRig, CameraSettings, Frame
from sensors.coco import coco_bbox, rle_counts, rle_string
from sensors.kitti import calibration_text, categories, encode_depth, label_lines
from sensors.labels import VehicleLabels, frame_labels, model_triangles
from sensors.replay import FrameTraffic
from sensors.writer import BackgroundWriter, encode_instance, vehicle_source, write_pngs
from twin import __version__
from twin.core.atomic import AtomicFolder, atomic_file, marked_as
from twin.core.errors import TwinError
from twin.cosim.config import ConfigError, CosimConfig, to_toml
from twin.data.store import TrajectoryStore
from twin.runners.episodes import (
    EpisodeSampling,
    EpisodeSpec,
    SamplingError,
    check_roads,
    draw_episode,
    episode_config,
    reset_or_skip,
)
from twin.runners.episodes import measure_cells as _measure_cells
from twin.runners.folders import claim

FORMAT = "i24-twin-dataset"
FORMAT_VERSION = 1
EPISODE_FORMAT = "i24-twin-dataset-episode"
IDENTITY = "dataset.json"
MANIFEST = "manifest.json"
EPISODE = "episode.json"
COCO = "coco.json"
EPISODES = "episodes"
SPLIT = "training"
# sub-folder -> file suffix of each sample's files
KINDS = {
    "image_2": ".png",
    "label_2": ".txt",
    "calib": ".txt",
    "depth_2": ".png",
    "semantic_2": ".png",
    "instance_2": ".png",
    "labels": ".json",
}


class DatasetError(TwinError):
    """A dataset cannot be made as asked, or its folder holds something else."""


@dataclass(frozen=True)
class LabelFilters:
    """Which labelled vehicles a dataset keeps (``[filters]``); the others become
    KITTI ``DontCare`` regions and are left out of COCO.

    Attributes:
        min_height_px: [px] least height of the visible 2D box.
        max_occlusion: highest KITTI occlusion level kept (0, 1 or 2).
        max_distance_m: [m] farthest distance from the camera to the box centre.
    """

    min_height_px: float = 10.0
    max_occlusion: int = 2
    max_distance_m: float = 150.0

    def __post_init__(self):
        if not (math.isfinite(self.min_height_px) and self.min_height_px >= 0):
            raise DatasetError(f"min_height_px must be >= 0, got {self.min_height_px!r}")
        if self.max_occlusion not in (0, 1, 2) or isinstance(self.max_occlusion, bool):
            raise DatasetError(f"max_occlusion must be 0, 1 or 2, got {self.max_occlusion!r}")
        if not self.max_distance_m > 0:
            raise DatasetError(f"max_distance_m must be > 0, got {self.max_distance_m!r}")

    def keep(self, labels: VehicleLabels) -> np.ndarray:
        """(n,) bool: the vehicles that pass every filter."""
        return (
            (labels.height_px >= self.min_height_px)
            & (labels.occlusion_level <= self.max_occlusion)
            & (labels.distance <= self.max_distance_m)
        )


def _dataset_cosim() -> CosimConfig:
    return CosimConfig(
        scenario="dataset", camera=CameraSettings(enabled=True, rate_hz=5.0, video=False)
    )


@dataclass(frozen=True)
class DatasetConfig:
    """What a dataset is made of (a dataset's TOML).

    Attributes:
        seed: the dataset's seed: episode ``i`` is drawn and simulated from
            ``(seed, i)`` alone.
        frames_per_episode: frames each camera takes per episode (at the camera rate).
        warmup_s: [s] simulated before the first frame.
        sampling: where episodes start (``[sampling]``).
        filters: which vehicles are kept (``[filters]``).
        cosim: the cosimulation of every episode (``[cosim]``, ``[cosim.camera]``, ...);
            its road, lane, x, time, seed and t_max are set per episode.
    """

    seed: int = 0
    frames_per_episode: int = 20
    warmup_s: float = 0.5
    sampling: EpisodeSampling = field(default_factory=EpisodeSampling)
    filters: LabelFilters = field(default_factory=LabelFilters)
    cosim: CosimConfig = field(default_factory=_dataset_cosim)

    def __post_init__(self):
        if not isinstance(self.seed, int) or isinstance(self.seed, bool) or self.seed < 0:
            raise DatasetError(f"seed must be a non-negative integer, got {self.seed!r}")
        k = self.frames_per_episode
        if not isinstance(k, int) or isinstance(k, bool) or k < 1:
            raise DatasetError(f"frames_per_episode must be an integer >= 1, got {k!r}")
        if not (math.isfinite(self.warmup_s) and self.warmup_s >= 0):
            raise DatasetError(f"warmup_s must be >= 0, got {self.warmup_s!r}")
        object.__setattr__(
            self, "cosim", replace(self.cosim, camera=replace(self.cosim.camera, enabled=True))
        )

    @property
    def warmup_steps(self) -> int:
        return round(self.warmup_s / self.cosim.dt)

    @property
    def frame_every(self) -> int:
        """Steps between two frames."""
        return self.cosim.camera_every

    @property
    def last_step(self) -> int:
        """The step of the last frame."""
        return self.warmup_steps + (self.frames_per_episode - 1) * self.frame_every

    @property
    def duration(self) -> float:
        """[s] simulated per episode."""
        return self.last_step * self.cosim.dt

    def episode_config(self, spec: EpisodeSpec) -> CosimConfig:
        """The cosimulation of episode ``spec``."""
        return episode_config(
            self.cosim,
            spec,
            scenario=f"dataset-{spec.index:06d}",
            t_max=max(self.duration, self.cosim.dt),
            bev_time=None,
        )

    def to_toml(self) -> str:
        return to_toml(self, header="dataset")


# -- the dataset folder ------------------------------------------------------------


def resolved_renderer(config: DatasetConfig) -> DatasetConfig:
    """``config`` with its renderer named: ``auto`` is decided once, here, so every
    episode of a dataset (on any worker or node) is drawn by the same renderer."""
    from twin.physics.render import resolve_renderer

    camera = config.cosim.camera
    if camera.renderer != "auto":
        return config
    named = replace(camera, renderer=resolve_renderer("auto").value)
    return replace(config, cosim=replace(config.cosim, camera=named))


def draw_episodes(config: DatasetConfig, store: TrajectoryStore, bundle, n: int):
    """The first ``n`` episodes of the dataset ``config`` on ``store``.

    Raises:
        SamplingError: no cell of the data can hold an episode.
    """
    from twin.core.i24 import Road
    from twin.cosim.cosimulator import road_limits
    from twin.data.empirical import EmpiricalTraffic

    check_roads(store, config.sampling)
    traffic = EmpiricalTraffic(store)
    roads = [Road.parse(r) for r in config.sampling.roads]
    try:
        limits = {r: road_limits(bundle, traffic, r) for r in roads}
    except TwinError as error:
        raise SamplingError(str(error)) from None
    cells = _measure_cells(store, config.sampling, limits, config.duration)
    return [draw_episode(cells, config.sampling, config.seed, i) for i in range(n)]


def episode_folder(out: Path, index: int) -> Path:
    return Path(out) / EPISODES / f"{index:06d}"


def is_episode(path: Path) -> bool:
    return marked_as(path, EPISODE, EPISODE_FORMAT)


def is_dataset(path: Path) -> bool:
    return marked_as(path, IDENTITY, FORMAT)


def _identity(config: DatasetConfig, store: TrajectoryStore, bundle) -> dict:
    data = {k: v for k, v in store.metadata.items() if k in ("format", "version", "roads")}
    data["sources"] = [
        {k: s.get(k) for k in ("name", "bytes")} for s in store.metadata.get("sources", [])
    ]
    return {
        "format": FORMAT,
        "version": FORMAT_VERSION,
        "software": __version__,
        "config": config.to_toml(),
        "data": data,
        "map": bundle.key,
    }


def claim_folder(out: Path, config: DatasetConfig, store: TrajectoryStore, bundle) -> None:
    """Make ``out`` this dataset's folder, or check that it already is
    (:func:`twin.runners.folders.claim`; its ``config.toml`` loads back with --config)."""
    identity = _identity(config, store, bundle)
    claim(
        out, IDENTITY, identity, kind="i24-twin dataset", noun="dataset", error=DatasetError,
        files={"config.toml": identity["config"]}, toml=("config",),
        hint=f" ({Path(out) / 'config.toml'} loads back with --config)",
    )  # fmt: skip


# -- one episode ---------------------------------------------------------------------


def render_episode(
    config: DatasetConfig,
    spec: EpisodeSpec,
    store: TrajectoryStore,
    bundle,
    folder: Path,
    on_frames: Callable[[int], None] | None = None,
) -> dict:
    """Simulate episode ``spec`` and write its samples and ``episode.json`` into
    ``folder`` (which must exist); ``on_frames(n)`` is called as frames are taken.

    An episode whose ego cannot be placed (no recorded vehicle near the request) is
    written with no samples and the reason in ``skipped``.

    Returns:
        the content of ``episode.json``.
    """
    from twin.cosim.cosimulator import Cosimulator
    from twin.data.empirical import EmpiricalTraffic

    cosim = config.episode_config(spec)
    cameras = cosim.camera.rig()
    for kind in KINDS:
        (folder / kind).mkdir()
    samples: list[dict] = []
    description = {
        "format": EPISODE_FORMAT,
        "version": __version__,
        "episode": spec.to_dict(),
        "cameras": [c.name for c in cameras],
        "skipped": None,
        "ended_early": None,
        "ego": None,
        "samples": samples,
    }
    writer = BackgroundWriter(lambda item: _write_sample(folder, *item), what="dataset samples")
    try:
        with Cosimulator(cosim, EmpiricalTraffic(store), bundle) as sim:
            description["skipped"] = reset_or_skip(sim)
            if description["skipped"] is None:
                ego = sim.ego
                description["ego"] = {
                    "record_id": ego.id,
                    "lane": ego.lane,
                    "x_m": round(ego.x, 3),
                    "time": ego.t,
                    "speed_mps": round(ego.speed, 3),
                }
                rig = CameraRig(
                    sim.world,
                    bundle,
                    cameras,
                    cosim.camera.renderer,
                    cosim.dt,
                    sun=cosim.camera.sun,
                    shadows=cosim.camera.shadows,
                    seed=cosim.seed,
                )
                description["light"] = rig.light_at(sim.t)[1]  # at the episode's start
                try:
                    _take_frames(
                        config, sim, rig, model_triangles(bundle), spec, samples, writer, on_frames
                    )
                finally:
                    rig.close()
                description["ended_early"] = sim.counters.ended or None
    finally:
        writer.close()
    (folder / EPISODE).write_text(json.dumps(description, indent=1) + "\n")
    return description


def _take_frames(config, sim, rig, models, spec, samples, writer, on_frames) -> None:
    warmup, every = config.warmup_steps, config.frame_every
    frames, traffic = 0, None
    while frames < config.frames_per_episode:
        step = sim.step_index
        if step >= warmup and (step - warmup) % every == 0:
            if traffic is None:
                traffic = FrameTraffic(sim, sim.world.road, max(c.far for c in rig.cameras))
            captured = rig.capture(
                sim.ego_id,
                time=sim.t,
                sim_time=sim.sim_time,
                traffic=traffic,
            )
            for frame in captured:
                labels = frame_labels(frame, models)
                kept = config.filters.keep(labels)
                stem = f"{len(samples):06d}"
                samples.append(
                    {
                        "sample": len(samples),
                        "frame": frame.index,
                        "camera": frame.camera.name,
                        "time": frame.time,
                        "sim_time": round(frame.sim_time, 9),
                        "vehicles": len(labels),
                        "kept": int(np.count_nonzero(kept)),
                    }
                )
                writer.put((stem, spec.index, frame, labels, kept))
            frames += 1
            if on_frames is not None:
                on_frames(len(rig.cameras))
        if sim.done or frames >= config.frames_per_episode:
            return
        sim.step()


def _write_sample(
    folder: Path, stem: str, episode: int, frame: Frame, labels: VehicleLabels, kept: np.ndarray
) -> None:
    camera = frame.camera
    images = {
        "image_2": cv2.cvtColor(frame.rgb, cv2.COLOR_RGB2BGR),
        "depth_2": encode_depth(frame.depth),
        "semantic_2": frame.semantic,
        "instance_2": encode_instance(frame.instance),
    }
    write_pngs(folder, stem, images)
    lines = label_lines(labels, kept, camera.width, camera.height)
    (folder / "label_2" / f"{stem}.txt").write_text("".join(f"{line}\n" for line in lines))
    camera_from_ego = np.linalg.inv(frame.ego_from_camera)
    (folder / "calib" / f"{stem}.txt").write_text(calibration_text(frame.K, camera_from_ego))
    record = sample_labels(frame, labels, kept, episode)
    (folder / "labels" / f"{stem}.json").write_text(json.dumps(record) + "\n")


def sample_labels(frame: Frame, labels: VehicleLabels, kept: np.ndarray, episode: int) -> dict:
    """The JSON record of one sample: its frame, calibration and vehicles."""
    camera = frame.camera
    names = [c.name for c in categories()]
    kitti = [c.kitti_type for c in categories()]
    coco = [c.coco_id for c in categories()]
    vehicles = []
    where = {int(v): k for k, v in enumerate(frame.vehicles.id.tolist())}
    for i in range(len(labels)):
        left, top, right, bottom = labels.visible_box[i].tolist()
        crop = frame.instance[top : bottom + 1, left : right + 1] == labels.id[i]
        counts = rle_counts(crop, top, left, camera.height, camera.width)
        k = int(labels.vehicle_class[i])
        vehicles.append(
            {
                "id": int(labels.id[i]),
                **vehicle_source(frame.vehicles, where[int(labels.id[i])]),
                "class": names[k],
                "kitti_type": kitti[k],
                "category_id": coco[k],
                "kept": bool(kept[i]),
                "pixels": int(labels.pixels[i]),
                "visible_box": labels.visible_box[i].tolist(),
                "amodal_box": _rounded(labels.amodal_box[i], 3),
                "location_m": _rounded(labels.location[i], 4),
                "dimensions_m": _rounded(labels.dimensions[i], 4),
                "rotation_y": round(float(labels.rotation_y[i]), 5),
                "alpha": round(float(labels.alpha[i]), 5),
                "truncation": round(float(labels.truncation[i]), 4),
                "occlusion": round(float(labels.occlusion[i]), 4),
                "occlusion_level": int(labels.occlusion_level[i]),
                "distance_m": round(float(labels.distance[i]), 3),
                "speed_mps": round(float(labels.speed[i]), 3),
                "mask": {"size": [camera.height, camera.width], "counts": rle_string(counts)},
            }
        )
    return {
        "episode": episode,
        "camera": camera.name,
        "frame": frame.index,
        "time": frame.time,
        "sim_time": round(frame.sim_time, 9),
        "renderer": frame.renderer,
        "light": frame.light,
        "width": camera.width,
        "height": camera.height,
        "K": frame.K.tolist(),
        "world_from_camera": frame.world_from_camera.tolist(),
        "ego_from_camera": frame.ego_from_camera.tolist(),
        "ego_id": frame.ego_id,
        "vehicles": vehicles,
    }


def _rounded(values: np.ndarray, digits: int) -> list[float]:
    return [round(float(v), digits) for v in values]


# -- the dataset from its episodes ---------------------------------------------------


def assemble(out: Path, config: DatasetConfig, specs: list[EpisodeSpec]) -> dict:
    """Number the samples of the episodes ``specs`` (all complete) in order and write
    ``training/``, ``coco.json`` and ``manifest.json``; returns the manifest.

    Raises:
        DatasetError: an episode is missing or was made from another draw.
    """
    out = Path(out)
    episodes, records = [], []
    for spec in specs:
        folder = episode_folder(out, spec.index)
        if not is_episode(folder):
            raise DatasetError(f"episode {spec.index} is not complete in {out}")
        description = json.loads((folder / EPISODE).read_text())
        if description["episode"] != spec.to_dict():
            raise DatasetError(
                f"{folder} was drawn as {description['episode']}, not {spec.to_dict()}: the "
                "dataset folder was changed by hand; remove the episode to render it again"
            )
        episodes.append(description)
        for sample in description["samples"]:
            records.append((folder, sample))
    with AtomicFolder(out / SPLIT, recognise=Path.is_dir, kind="dataset split") as split:
        for kind in KINDS:
            (split.tmp / kind).mkdir()
        for index, (folder, sample) in enumerate(records):
            for kind, suffix in KINDS.items():
                source = folder / kind / f"{sample['sample']:06d}{suffix}"
                _link(source, split.tmp / kind / f"{index:06d}{suffix}")
    labels = [
        json.loads((out / SPLIT / "labels" / f"{i:06d}.json").read_text())
        for i in range(len(records))
    ]
    with atomic_file(out / COCO) as tmp:
        tmp.write_text(json.dumps(coco_document(labels, config)) + "\n")
    manifest = {
        "format": FORMAT,
        "version": FORMAT_VERSION,
        "software": __version__,
        "config": config.to_toml(),
        "layout": {
            "kitti": f"{SPLIT}/ (image_2, label_2, calib, depth_2, semantic_2, instance_2)",
            "coco": COCO,
            "labels": f"{SPLIT}/labels/NNNNNN.json",
        },
        "statistics": statistics(episodes, labels),
        "episodes": [
            {
                **e["episode"],
                "skipped": e["skipped"],
                "ended_early": e["ended_early"],
                "ego": e["ego"],
                "light": e.get("light"),
                "samples": len(e["samples"]),
            }
            for e in episodes
        ],
        "samples": [
            {
                "sample": i,
                "episode": label["episode"],
                "camera": label["camera"],
                "frame": label["frame"],
                "time": label["time"],
            }
            for i, label in enumerate(labels)
        ],
    }
    with atomic_file(out / MANIFEST) as tmp:
        tmp.write_text(json.dumps(manifest, indent=1) + "\n")
    return manifest


def _link(source: Path, target: Path) -> None:
    try:
        os.link(source, target)
    except OSError:
        shutil.copyfile(source, target)


def coco_document(labels: list[dict], config: DatasetConfig) -> dict:
    """The COCO instances document of the samples ``labels`` (kept vehicles only)."""
    images, annotations = [], []
    for index, record in enumerate(labels):
        images.append(
            {
                "id": index,
                "file_name": f"{SPLIT}/image_2/{index:06d}.png",
                "width": record["width"],
                "height": record["height"],
                "episode": record["episode"],
                "camera": record["camera"],
                "frame": record["frame"],
                "time": record["time"],
            }
        )
        for vehicle in record["vehicles"]:
            if not vehicle["kept"]:
                continue
            annotations.append(
                {
                    "id": len(annotations) + 1,
                    "image_id": index,
                    "category_id": vehicle["category_id"],
                    "bbox": coco_bbox(vehicle["visible_box"]),
                    "area": vehicle["pixels"],
                    "iscrowd": 0,
                    "segmentation": vehicle["mask"],
                    "track_id": vehicle["id"],
                    "record_id": vehicle.get("record_id"),
                    "source": vehicle.get("source"),
                    "road": vehicle.get("road"),
                    "occlusion_level": vehicle["occlusion_level"],
                    "truncation": vehicle["truncation"],
                    "distance_m": vehicle["distance_m"],
                    "speed_mps": vehicle["speed_mps"],
                }
            )
    return {
        "info": {
            "description": "i24-twin synthetic camera dataset of I-24 (MM 60.6-61.6)",
            "version": __version__,
            "seed": config.seed,
        },
        "licenses": [],
        "images": images,
        "annotations": annotations,
        "categories": [
            {"id": c.coco_id, "name": c.name, "supercategory": "vehicle"} for c in categories()
        ],
    }


#: distance bands [m] of the statistics, (name, upper bound)
DISTANCE_BANDS = (
    ("0-30", 30.0),
    ("30-60", 60.0),
    ("60-100", 100.0),
    ("100-200", 200.0),
    ("200+", math.inf),
)
#: truncation levels (share of the amodal box outside the image), (name, upper bound)
TRUNCATION_LEVELS = (("none", 0.0), ("up_to_0.3", 0.3), ("up_to_0.6", 0.6), ("over_0.6", math.inf))


def _distance_band(distance: float) -> str:
    return next(name for name, upper in DISTANCE_BANDS if distance < upper)


def _truncation_level(truncation: float) -> str:
    return next(name for name, upper in TRUNCATION_LEVELS if truncation <= upper)


def statistics(episodes: list[dict], labels: list[dict]) -> dict:
    """Counts and distributions of a dataset's episodes and labelled vehicles."""
    vehicles = [v for record in labels for v in record["vehicles"]]
    kept = [v for v in vehicles if v["kept"]]

    def quantiles(values) -> dict | None:
        if not values:
            return None
        q = np.quantile(np.asarray(values, dtype=np.float64), [0.0, 0.5, 0.9, 1.0])
        return dict(
            zip(("min", "median", "p90", "max"), [round(float(v), 2) for v in q], strict=True)
        )

    levels = Counter(v["occlusion_level"] for v in kept)
    bands = Counter(_distance_band(v["distance_m"]) for v in kept)
    per_sample = [sum(v["kept"] for v in record["vehicles"]) for record in labels]
    truncation = Counter(_truncation_level(v["truncation"]) for v in kept)
    return {
        "episodes": len(episodes),
        "episodes_congested": sum(e["episode"]["congested"] for e in episodes),
        "episodes_skipped": sum(e["skipped"] is not None for e in episodes),
        "episodes_ended_early": sum(e["ended_early"] is not None for e in episodes),
        "samples": len(labels),
        "vehicles_visible": len(vehicles),
        "vehicles_kept": len(kept),
        "vehicles_dont_care": len(vehicles) - len(kept),
        "kept_per_sample": round(len(kept) / len(labels), 3) if labels else None,
        "per_class": {c.name: sum(v["class"] == c.name for v in kept) for c in categories()},
        "occlusion_levels": {str(k): levels.get(k, 0) for k in (0, 1, 2)},
        "truncated": sum(v["truncation"] > 0 for v in kept),
        "truncation_levels": {name: truncation.get(name, 0) for name, _ in TRUNCATION_LEVELS},
        "distance_bands": {name: bands.get(name, 0) for name, _ in DISTANCE_BANDS},
        "kept_per_sample_quantiles": quantiles(per_sample),
        "distance_m": quantiles([v["distance_m"] for v in kept]),
        "height_px": quantiles([v["visible_box"][3] - v["visible_box"][1] + 1 for v in kept]),
        "speed_mps": quantiles([v["speed_mps"] for v in kept]),
    }


def load_dataset_config(
    text: str, *, source: str = "dataset configuration", base: DatasetConfig | None = None
) -> DatasetConfig:
    """Parse a dataset's TOML over ``base`` (default: the defaults).

    Raises:
        ConfigError: malformed TOML, an unknown key or an impossible value.
    """
    import tomllib

    from twin.cosim.config import override

    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise ConfigError(f"{source} is not valid TOML: {error}") from None
    try:
        return override(base or DatasetConfig(), data, source=source)
    except (DatasetError, SamplingError) as error:
        raise ConfigError(f"{source}: {error}") from None
