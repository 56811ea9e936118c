"""One episode of a dataset: its cosimulation with the ego's cameras, every frame written
as a labelled sample."""

import json
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

from sensors.camera import CameraRig, Frame
from sensors.coco import rle_counts, rle_string
from sensors.kitti import calibration_text, categories, encode_depth, label_lines
from sensors.labels import VehicleLabels, frame_labels, model_triangles
from sensors.replay import FrameTraffic
from sensors.writer import BackgroundWriter, encode_instance, vehicle_source, write_pngs
from twin import __version__
from twin.data.store import TrajectoryStore
from twin.runners.dataset.config import EPISODE, EPISODE_FORMAT, KINDS, DatasetConfig
from twin.runners.episodes import (
    EpisodeSpec,
    reset_or_skip,
)


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
