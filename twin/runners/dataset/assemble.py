"""A dataset from its complete episodes: the KITTI layout numbered across them, the COCO
file and the manifest with its statistics."""

import json
import math
import os
import shutil
from collections import Counter
from pathlib import Path

import numpy as np

from sensors.coco import coco_bbox
from sensors.kitti import categories
from twin import __version__
from twin.core.atomic import AtomicFolder, atomic_file
from twin.runners.dataset.config import (
    COCO,
    EPISODE,
    FORMAT,
    FORMAT_VERSION,
    KINDS,
    MANIFEST,
    SPLIT,
    DatasetConfig,
    DatasetError,
)
from twin.runners.dataset.folder import episode_folder, is_episode
from twin.runners.dataset.motion import motion_check
from twin.runners.episodes import (
    EpisodeSpec,
)


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
        "motion": motion_check(labels),
    }
