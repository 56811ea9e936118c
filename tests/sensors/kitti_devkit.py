"""A reader of KITTI object files, written from the KITTI object development kit's
readme (``devkit_object/readme.txt``) and its ``computeBox3D.m``, not from the twin's
writer. The label fields, in order::

    #Values  Name        Description
       1     type        'Car', 'Van', 'Truck', 'Pedestrian', 'Person_sitting',
                         'Cyclist', 'Tram', 'Misc' or 'DontCare'
       1     truncated   Float from 0 (non-truncated) to 1 (truncated), where
                         truncated refers to the object leaving image boundaries
       1     occluded    Integer (0,1,2,3) indicating occlusion state:
                         0 = fully visible, 1 = partly occluded
                         2 = largely occluded, 3 = unknown
       1     alpha       Observation angle of object, ranging [-pi..pi]
       4     bbox        2D bounding box of object in the image (0-based index):
                         contains left, top, right, bottom pixel coordinates
       3     dimensions  3D object dimensions: height, width, length (in meters)
       3     location    3D object location x,y,z in camera coordinates (in meters)
       1     rotation_y  Rotation ry around Y-axis in camera coordinates [-pi..pi]
       1     score       Only for results: Float, indicating confidence in
                         detection, needed for p/r curves, higher is better.

Calibration files hold ``P0``..``P3`` (3x4), ``R0_rect`` (3x3), ``Tr_velo_to_cam`` and
``Tr_imu_to_velo`` (3x4), one per line as ``name: v1 v2 ...``.
"""

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

TYPES = {"Car", "Van", "Truck", "Pedestrian", "Person_sitting", "Cyclist", "Tram", "Misc"}
CALIBRATION_SHAPES = {
    "P0": (3, 4),
    "P1": (3, 4),
    "P2": (3, 4),
    "P3": (3, 4),
    "R0_rect": (3, 3),
    "Tr_velo_to_cam": (3, 4),
    "Tr_imu_to_velo": (3, 4),
}


@dataclass
class KittiObject:
    type: str
    truncated: float
    occluded: int
    alpha: float
    bbox: tuple[float, float, float, float]
    dimensions: tuple[float, float, float]  # h, w, l
    location: tuple[float, float, float]
    rotation_y: float
    score: float | None


def read_label(path: Path) -> list[KittiObject]:
    """Parse a label file; raise ValueError on any line that breaks the readme."""
    objects = []
    for number, line in enumerate(Path(path).read_text().splitlines(), 1):
        fields = line.split(" ")
        if len(fields) not in (15, 16):
            raise ValueError(f"{path}:{number}: {len(fields)} fields, expected 15 (or 16)")
        kind = fields[0]
        values = [float(v) for v in fields[1:]]
        if not all(math.isfinite(v) for v in values):
            raise ValueError(f"{path}:{number}: a field is not finite")
        obj = KittiObject(
            type=kind,
            truncated=values[0],
            occluded=int(fields[2]),
            alpha=values[2],
            bbox=tuple(values[3:7]),
            dimensions=tuple(values[7:10]),
            location=tuple(values[10:13]),
            rotation_y=values[13],
            score=values[14] if len(values) == 15 else None,
        )
        if kind == "DontCare":
            _check_dont_care(obj, path, number)
        else:
            _check_object(obj, path, number)
        objects.append(obj)
    return objects


def _check_object(obj: KittiObject, path, number) -> None:
    if obj.type not in TYPES:
        raise ValueError(f"{path}:{number}: unknown type {obj.type!r}")
    if not 0.0 <= obj.truncated <= 1.0:
        raise ValueError(f"{path}:{number}: truncated {obj.truncated} outside [0, 1]")
    if obj.occluded not in (0, 1, 2, 3):
        raise ValueError(f"{path}:{number}: occluded {obj.occluded} not in 0..3")
    for name, angle in (("alpha", obj.alpha), ("rotation_y", obj.rotation_y)):
        if not -math.pi - 0.005 <= angle <= math.pi + 0.005:  # written to 2 decimals
            raise ValueError(f"{path}:{number}: {name} {angle} outside [-pi, pi]")
    left, top, right, bottom = obj.bbox
    if not (0 <= left <= right and 0 <= top <= bottom):
        raise ValueError(f"{path}:{number}: bbox {obj.bbox} is not left<=right, top<=bottom")
    if not all(v > 0 for v in obj.dimensions):
        raise ValueError(f"{path}:{number}: dimensions {obj.dimensions} must be positive")


def _check_dont_care(obj: KittiObject, path, number) -> None:
    if (obj.truncated, obj.occluded, obj.alpha) != (-1.0, -1, -10.0):
        raise ValueError(f"{path}:{number}: DontCare needs truncated -1, occluded -1, alpha -10")


def read_calibration(path: Path) -> dict[str, np.ndarray]:
    """Parse a calibration file into its matrices."""
    matrices = {}
    for line in Path(path).read_text().splitlines():
        if not line.strip():
            continue
        name, _, values = line.partition(":")
        if name not in CALIBRATION_SHAPES:
            raise ValueError(f"{path}: unknown matrix {name!r}")
        numbers = np.array([float(v) for v in values.split()])
        shape = CALIBRATION_SHAPES[name]
        if numbers.size != shape[0] * shape[1]:
            raise ValueError(f"{path}: {name} has {numbers.size} values, expected {shape}")
        matrices[name] = numbers.reshape(shape)
    missing = set(CALIBRATION_SHAPES) - set(matrices)
    if missing:
        raise ValueError(f"{path}: missing {sorted(missing)}")
    return matrices


def box_corners(obj: KittiObject) -> np.ndarray:
    """(8, 3) corners of the 3D box in camera coordinates (``computeBox3D.m``)."""
    h, w, length = obj.dimensions
    ry = obj.rotation_y
    R = np.array([[math.cos(ry), 0, math.sin(ry)], [0, 1, 0], [-math.sin(ry), 0, math.cos(ry)]])
    half = length / 2
    x = [half, half, -half, -half, half, half, -half, -half]
    y = [0, 0, 0, 0, -h, -h, -h, -h]
    z = [w / 2, -w / 2, -w / 2, w / 2, w / 2, -w / 2, -w / 2, w / 2]
    return (R @ np.array([x, y, z])).T + np.array(obj.location)


def project(P: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(n, 2) image points of (n, 3) camera points (``projectToImage.m``)."""
    homogeneous = np.c_[points, np.ones(len(points))] @ P.T
    return homogeneous[:, :2] / homogeneous[:, 2:3]
