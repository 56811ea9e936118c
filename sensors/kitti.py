"""KITTI object-benchmark files: label lines, calibration, depth maps.

Field order and units as the KITTI object development kit's readme gives them.
A label line has 15 fields::

    type truncated occluded alpha left top right bottom h w l x y z rotation_y

``type`` one of KITTI's classes (this twin's classes map to them through
``assets/dataset_categories.csv``); ``truncated`` 0..1; ``occluded`` 0 fully visible,
1 partly occluded, 2 largely occluded, 3 unknown; ``alpha`` and ``rotation_y`` [rad]
in [-pi, pi]; the 2D box in 0-based pixel coordinates; dimensions height, width,
length [m]; location the bottom centre of the 3D box in camera coordinates [m].
Vehicles left out by the dataset's filters are written as ``DontCare`` regions
(their visible box; the other fields -1, -10 and -1000 as in KITTI's own labels).

A calibration file holds ``P0`` to ``P3`` (3x4 projections of the rectified
cameras; here all four are the camera's ``[K | 0]``), ``R0_rect`` (identity: the
images are rectified) and ``Tr_velo_to_cam`` (3x4). The twin has no lidar: the
"velodyne" frame is the ego's vehicle frame (x forward, y left, z up, on the ground
below the centre of its box; the axes KITTI's Velodyne frame has), so
``Tr_velo_to_cam`` maps ego coordinates to camera coordinates. ``Tr_imu_to_velo`` is
the identity.

Depth maps follow KITTI's depth benchmark: 16-bit PNG, depth [m] = value / 256,
0 where there is no depth (the sky, or beyond 255.99 m).
"""

from dataclasses import dataclass
from functools import cache
from pathlib import Path

import numpy as np
import pandas as pd

from sensors import writer
from sensors.labels import VehicleLabels
from twin.core.errors import TwinError
from twin.core.i24 import VEHICLE_CLASSES
from twin.core.paths import asset

CATEGORIES_CSV = "dataset_categories.csv"
KITTI_TYPES = ("Car", "Van", "Truck", "Pedestrian", "Person_sitting", "Cyclist", "Tram", "Misc")
DEPTH_UNITS = 256.0  # [values per m] of KITTI's depth PNGs


@dataclass(frozen=True)
class Category:
    """How one I-24 vehicle class is labelled in the datasets."""

    vehicle_class: int
    name: str
    kitti_type: str
    coco_id: int


@cache
def categories(path: Path | None = None) -> tuple[Category, ...]:
    """The dataset categories, one per I-24 vehicle class, in class order.

    Raises:
        TwinError: the file is missing a column or a class, or names a type KITTI
            does not have.
    """
    path = Path(path) if path is not None else asset(CATEGORIES_CSV)
    try:
        frame = pd.read_csv(path)
    except (OSError, pd.errors.ParserError, pd.errors.EmptyDataError) as error:
        raise TwinError(f"cannot read dataset categories {path}: {error}") from None
    columns = ["vehicle_class", "name", "kitti_type", "coco_id"]
    missing = [c for c in columns if c not in frame.columns]
    if missing:
        raise TwinError(f"{path}: missing columns {missing}")
    frame = frame.sort_values("vehicle_class")
    if frame["vehicle_class"].tolist() != list(range(len(VEHICLE_CLASSES))):
        raise TwinError(f"{path}: needs one row per vehicle class 0..{len(VEHICLE_CLASSES) - 1}")
    if frame["coco_id"].duplicated().any() or (frame["coco_id"] < 1).any():
        raise TwinError(f"{path}: coco_id must be unique integers >= 1")
    wrong = sorted(set(frame["kitti_type"]) - set(KITTI_TYPES))
    if wrong:
        raise TwinError(f"{path}: {wrong} are not KITTI object types {KITTI_TYPES}")
    return tuple(
        Category(int(r.vehicle_class), str(r.name), str(r.kitti_type), int(r.coco_id))
        for r in frame.itertuples()
    )


def label_lines(labels: VehicleLabels, kept: np.ndarray, width: int, height: int) -> list[str]:
    """KITTI label lines: the kept vehicles, then the others as ``DontCare``.

    The image box of a kept vehicle is its amodal box (the projected 3D box) clipped
    to the image, as KITTI's boxes cover occluded parts too.
    """
    types = [c.kitti_type for c in categories()]
    lines = []
    for i in np.flatnonzero(kept).tolist():
        left, top, right, bottom = labels.amodal_box[i]
        box = (
            min(max(left, 0.0), width - 1.0),
            min(max(top, 0.0), height - 1.0),
            min(max(right, 0.0), width - 1.0),
            min(max(bottom, 0.0), height - 1.0),
        )
        fields = [
            labels.truncation[i],
            labels.occlusion_level[i],
            labels.alpha[i],
            *box,
            *labels.dimensions[i],
            *labels.location[i],
            labels.rotation_y[i],
        ]
        text = " ".join(_number(v) for v in fields)
        lines.append(f"{types[labels.vehicle_class[i]]} {text}")
    for i in np.flatnonzero(~kept).tolist():
        box = " ".join(_number(float(v)) for v in labels.visible_box[i])
        lines.append(f"DontCare -1 -1 -10 {box} -1 -1 -1 -1000 -1000 -1000 -10")
    return lines


def calibration_text(K: np.ndarray, camera_from_ego: np.ndarray) -> str:
    """A KITTI calibration file for one camera with intrinsics ``K`` (3x3) mounted at
    ``camera_from_ego`` (4x4)."""
    P = np.zeros((3, 4))
    P[:, :3] = K
    matrices = {
        "P0": P,
        "P1": P,
        "P2": P,
        "P3": P,
        "R0_rect": np.eye(3),
        "Tr_velo_to_cam": camera_from_ego[:3, :4],
        "Tr_imu_to_velo": np.eye(4)[:3],
    }
    return "".join(
        f"{name}: {' '.join(f'{v:.12e}' for v in m.reshape(-1))}\n" for name, m in matrices.items()
    )


def encode_depth(depth: np.ndarray) -> np.ndarray:
    """(h, w) uint16 KITTI depth map of planar depth [m]: value = depth * 256, 0 where
    there is no depth (+inf) or the depth does not fit (255.99 m or more)."""
    return writer.encode_depth(depth, DEPTH_UNITS, too_far=0)


def decode_depth(image: np.ndarray) -> np.ndarray:
    """Planar depth [m] (float32) of a KITTI depth map; +inf where the value is 0."""
    return writer.decode_depth(image, DEPTH_UNITS)


def _number(value) -> str:
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    return f"{float(value):.2f}"
