"""Pictures of camera frames for people: RGB alone, or RGB, depth, semantic and
instance labels side by side."""

from pathlib import Path

import cv2
import numpy as np

from mapgen.semantics import semantic_classes
from sensors.camera import Frame
from twin.core.atomic import atomic_file

DEPTH_RANGE = (1.0, 150.0)  # [m] of the depth colour map (log scale)


def frame_vehicles(frame: Frame) -> np.ndarray:
    """Twin ids of the vehicles with at least one pixel in the frame."""
    ids = np.unique(frame.instance)
    return ids[ids >= 0]


def frame_picture(frame: Frame, out: Path, *, labels: bool = False) -> Path:
    """Write ``frame`` as a PNG (written whole, then renamed): RGB, or with ``labels``
    a 2 x 2 panel of RGB, depth, semantic classes and instances.

    Returns:
        ``out``.
    """
    picture = frame.rgb
    if labels:
        top = np.concatenate([frame.rgb, colour_depth(frame.depth)], axis=1)
        bottom = np.concatenate(
            [colour_semantic(frame.semantic), colour_instance(frame.instance)], axis=1
        )
        picture = np.concatenate([top, bottom], axis=0)
    with atomic_file(out) as tmp:
        if not cv2.imwrite(str(tmp), cv2.cvtColor(picture, cv2.COLOR_RGB2BGR)):
            raise OSError(f"could not write {out}")
    return Path(out)


def colour_depth(depth: np.ndarray) -> np.ndarray:
    """(h, w, 3) uint8 RGB: near yellow to far purple (log scale), black where nothing."""
    lo, hi = np.log(DEPTH_RANGE)
    with np.errstate(divide="ignore", invalid="ignore"):
        scaled = (np.log(np.clip(depth, *DEPTH_RANGE)) - lo) / (hi - lo)
    grey = np.nan_to_num(255.0 * (1.0 - scaled)).astype(np.uint8)
    rgb = cv2.cvtColor(cv2.applyColorMap(grey, cv2.COLORMAP_PLASMA), cv2.COLOR_BGR2RGB)
    rgb[~np.isfinite(depth)] = 0
    return rgb


def colour_semantic(semantic: np.ndarray) -> np.ndarray:
    """(h, w, 3) uint8 RGB in the class table's label colours."""
    palette = np.zeros((256, 3), dtype=np.uint8)
    for c in semantic_classes():
        palette[c.class_id] = c.color
    return palette[semantic]


def colour_instance(instance: np.ndarray) -> np.ndarray:
    """(h, w, 3) uint8 RGB: a colour per vehicle id, black where no vehicle."""
    hashed = (instance.astype(np.uint64) * np.uint64(2654435761)) & np.uint64(0xFFFFFF)
    rgb = np.stack([(hashed >> np.uint64(s)) & np.uint64(255) for s in (16, 8, 0)], axis=-1)
    rgb = (rgb.astype(np.uint8) // 2) + 96
    rgb[instance < 0] = 0
    return rgb
