"""Labels of the vehicles a camera frame shows: 2D boxes, 3D boxes, truncation, occlusion.

Every vehicle with at least one pixel in the frame's instance mask is labelled.
Conventions (the camera's, :mod:`sensors.camera`: x right, y down, z forward; pixel
(0, 0) is the centre of the top-left pixel):

* visible box: the extent of the vehicle's pixels, ``[left, top, right, bottom]`` as
  inclusive 0-based pixel indices (KITTI's image boxes);
* amodal box: the vehicle's whole 3D box projected into the image (its part in front
  of the near plane), ``[left, top, right, bottom]`` in continuous pixel coordinates,
  not clipped to the image;
* 3D box as KITTI gives it: ``location`` the bottom centre in the camera frame [m],
  ``dimensions`` (height, width, length) [m], ``rotation_y`` [rad] about the camera's
  y axis (0: the vehicle faces the camera's x axis; -pi/2: it drives straight away
  from the camera), ``alpha`` the observation angle ``rotation_y - atan2(x, z)``;
* truncation: the share of the amodal box outside the image, 0 to 1 (KITTI: "the
  object leaving image boundaries");
* occlusion: the share of the vehicle's silhouette in the image that something nearer
  hides. The silhouette is the vehicle's drawn model rasterised on its own (its
  triangles projected and filled); a pixel of it is hidden when it shows a vehicle,
  barrier, pole, post or overpass (not road or terrain) nearer than where the pixel's
  ray enters the vehicle's 3D box, and visible when it shows the vehicle. (A vehicle
  reaching behind the camera's near plane has the box's silhouette instead.) Levels
  as KITTI's: 0 fully visible (under ``PARTLY_OCCLUDED``), 1 partly occluded, 2
  largely occluded (``LARGELY_OCCLUDED`` or more);
* distance: [m] from the camera to the centre of the 3D box; speed: [m/s] along the
  vehicle's heading.
"""

from dataclasses import dataclass, fields
from functools import cache

import cv2
import numpy as np
import trimesh

from mapgen.build import MapBundle
from mapgen.semantics import class_id, semantic_classes
from sensors.camera import Frame
from twin.core.i24 import VEHICLE_CLASSES
from twin.physics.render import UNIT_BOX

PARTLY_OCCLUDED = 0.1  # hidden share from which a vehicle is "partly occluded" (level 1)
LARGELY_OCCLUDED = 0.5  # hidden share from which it is "largely occluded" (level 2)
DEPTH_TOLERANCE = 0.1  # [m] an occluder must lie this much nearer than the box
SUBPIXEL_BITS = 4  # fixed-point bits of the rasterised silhouettes
NOT_OCCLUDERS = ("sky", "road", "shoulder", "lane_marking", "terrain")
# the 12 edges of a box whose corners are numbered by bits (x, y, z)
BOX_EDGES = np.array(
    [(a, a | bit) for bit in (1, 2, 4) for a in range(8) if not a & bit], dtype=np.int64
)
BOX_CORNERS = UNIT_BOX


@dataclass(frozen=True, eq=False)
class VehicleLabels:
    """The labels of one frame's visible vehicles, struct-of-arrays (see the module doc).

    Attributes:
        id: (n,) int64 instance ids (those of the frame's mask: a recorded vehicle's
            own, :meth:`sensors.camera.CameraRig.capture`).
        vehicle_class: (n,) int64 I-24 class ids.
        pixels: (n,) int64 visible pixels.
        visible_box: (n, 4) int64 [left, top, right, bottom], inclusive pixel indices.
        amodal_box: (n, 4) float64 [left, top, right, bottom], continuous pixels.
        location: (n, 3) [m] bottom centre of the 3D box in the camera frame.
        dimensions: (n, 3) [m] height, width, length.
        rotation_y, alpha: (n,) [rad] in [-pi, pi].
        truncation: (n,) share of the amodal box outside the image.
        occlusion: (n,) hidden share of the silhouette; occlusion_level: (n,) 0, 1, 2.
        distance: (n,) [m] camera to box centre. speed: (n,) [m/s].
    """

    id: np.ndarray
    vehicle_class: np.ndarray
    pixels: np.ndarray
    visible_box: np.ndarray
    amodal_box: np.ndarray
    location: np.ndarray
    dimensions: np.ndarray
    rotation_y: np.ndarray
    alpha: np.ndarray
    truncation: np.ndarray
    occlusion: np.ndarray
    occlusion_level: np.ndarray
    distance: np.ndarray
    speed: np.ndarray

    def __len__(self) -> int:
        return self.id.size

    def take(self, index) -> "VehicleLabels":
        return VehicleLabels(**{f.name: getattr(self, f.name)[index] for f in fields(self)})

    @property
    def height_px(self) -> np.ndarray:
        """(n,) [px] height of the visible box."""
        return self.visible_box[:, 3] - self.visible_box[:, 1] + 1


def model_triangles(bundle: MapBundle) -> tuple[np.ndarray, ...]:
    """(m, 3, 3) triangles of each vehicle class's drawn model (in the unit box), by
    I-24 class id."""
    return tuple(_load_triangles(str(bundle.vehicles[name])) for name in VEHICLE_CLASSES)


@cache
def _load_triangles(path: str) -> np.ndarray:
    mesh = trimesh.load(path, force="mesh", process=False)
    return np.asarray(mesh.vertices, dtype=np.float64)[np.asarray(mesh.faces)]


def frame_labels(frame: Frame, models: tuple[np.ndarray, ...]) -> VehicleLabels:
    """Label every vehicle with at least one pixel in ``frame``, ordered by id.

    Args:
        frame: a camera frame.
        models: the vehicle models' triangles (:func:`model_triangles` of the map).
    """
    camera = frame.camera
    width, height = camera.width, camera.height
    counts = np.bincount(frame.instance.reshape(-1) + 1)
    vehicles = frame.vehicles
    ids = vehicles.id
    seen = (ids + 1 < counts.size) & (counts[np.minimum(ids + 1, counts.size - 1)] > 0)
    vehicles = vehicles.take(np.flatnonzero(seen)[np.argsort(ids[seen], kind="stable")])
    n = vehicles.id.size

    camera_from_world = np.linalg.inv(frame.world_from_camera)
    rotation = camera_from_world[:3, :3] @ vehicles.rotation  # (n, 3, 3) body to camera
    bottom = vehicles.position @ camera_from_world[:3, :3].T + camera_from_world[:3, 3]
    size = vehicles.size  # (n, 3) length, width, height
    local = (BOX_CORNERS - [0.5, 0.5, 0.0])[None] * size[:, None, :]  # (n, 8, 3)
    corners = np.einsum("nij,nkj->nki", rotation, local) + bottom[:, None, :]
    amodal = _amodal_boxes(corners, camera.K, camera.near)

    heading = rotation[:, :, 0]
    rotation_y = np.arctan2(-heading[:, 2], heading[:, 0])
    centre = bottom + rotation[:, :, 2] * (0.5 * size[:, 2:3])
    labels = VehicleLabels(
        id=vehicles.id.astype(np.int64),
        vehicle_class=vehicles.vehicle_class.astype(np.int64),
        pixels=counts[vehicles.id + 1].astype(np.int64),
        visible_box=np.zeros((n, 4), np.int64),
        amodal_box=amodal,
        location=bottom,
        dimensions=size[:, ::-1].copy(),
        rotation_y=rotation_y,
        alpha=_wrap(rotation_y - np.arctan2(bottom[:, 0], bottom[:, 2])),
        truncation=_truncation(amodal, width, height),
        occlusion=np.zeros(n),
        occlusion_level=np.zeros(n, np.int64),
        distance=np.linalg.norm(centre, axis=1),
        speed=vehicles.speed.astype(np.float64),
    )
    occluders = _occluder_classes()
    for i in range(n):
        model = models[labels.vehicle_class[i]] * size[i]  # (m, 3, 3) vehicle frame
        labels.visible_box[i], labels.occlusion[i] = _visible_and_hidden(
            frame, labels, i, camera_from_world, vehicles.rotation[i], vehicles.position[i],
            size[i], model, occluders,
        )  # fmt: skip
    labels.occlusion_level[:] = np.digitize(labels.occlusion, [PARTLY_OCCLUDED, LARGELY_OCCLUDED])
    return labels


def _amodal_boxes(corners: np.ndarray, K: np.ndarray, near: float) -> np.ndarray:
    """(n, 4) image box of each 3D box (corners (n, 8, 3), camera frame) clipped at the
    near plane: the corners in front of it and the points where edges cross it."""
    a, b = corners[:, BOX_EDGES[:, 0]], corners[:, BOX_EDGES[:, 1]]  # (n, 12, 3)
    za, zb = a[..., 2] - near, b[..., 2] - near
    crossing = za * zb < 0
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(crossing, za / (za - zb), 0.0)
    cut = a + s[..., None] * (b - a)
    points = np.concatenate([corners, cut], axis=1)  # (n, 20, 3)
    valid = np.concatenate([corners[..., 2] >= near, crossing], axis=1)
    z = np.where(valid, points[..., 2], 1.0)
    u = np.where(valid, K[0, 0] * points[..., 0] / z + K[0, 2], np.nan)
    v = np.where(valid, K[1, 1] * points[..., 1] / z + K[1, 2], np.nan)
    if corners.shape[0] == 0:
        return np.zeros((0, 4))
    return np.column_stack([np.nanmin(u, 1), np.nanmin(v, 1), np.nanmax(u, 1), np.nanmax(v, 1)])


def _truncation(boxes: np.ndarray, width: int, height: int) -> np.ndarray:
    """(n,) share of each box's area outside the image ``[-0.5, w - 0.5] x [-0.5, h - 0.5]``."""
    area = (boxes[:, 2] - boxes[:, 0]) * (boxes[:, 3] - boxes[:, 1])
    inside_w = np.clip(boxes[:, 2], -0.5, width - 0.5) - np.clip(boxes[:, 0], -0.5, width - 0.5)
    inside_h = np.clip(boxes[:, 3], -0.5, height - 0.5) - np.clip(boxes[:, 1], -0.5, height - 0.5)
    with np.errstate(divide="ignore", invalid="ignore"):
        share = 1.0 - inside_w * inside_h / area
    return np.clip(np.nan_to_num(share, nan=0.0), 0.0, 1.0)


def _visible_and_hidden(
    frame: Frame,
    labels: VehicleLabels,
    i: int,
    camera_from_world: np.ndarray,
    world_rotation: np.ndarray,
    world_bottom: np.ndarray,
    size: np.ndarray,
    model: np.ndarray,
    occluders: np.ndarray,
) -> tuple[np.ndarray, float]:
    """Visible box and hidden share of vehicle ``i``, looked for inside its amodal box."""
    camera = frame.camera
    width, height = camera.width, camera.height
    left, top, right, bottom = labels.amodal_box[i]
    c0, c1 = (
        int(np.clip(np.floor(left) - 1, 0, width - 1)),
        int(np.clip(np.ceil(right) + 1, 0, width - 1)),
    )
    r0, r1 = (
        int(np.clip(np.floor(top) - 1, 0, height - 1)),
        int(np.clip(np.ceil(bottom) + 1, 0, height - 1)),
    )
    twin_id = labels.id[i]
    mine = frame.instance[r0 : r1 + 1, c0 : c1 + 1] == twin_id
    if np.count_nonzero(mine) != labels.pixels[i]:  # pixels outside the amodal box
        r0, r1, c0, c1 = 0, height - 1, 0, width - 1
        mine = frame.instance == twin_id
    rows, cols = np.flatnonzero(mine.any(axis=1)), np.flatnonzero(mine.any(axis=0))
    box = np.array([c0 + cols[0], r0 + rows[0], c0 + cols[-1], r0 + rows[-1]], np.int64)

    # rays through the pixel centres (planar depth 1), in the vehicle's box frame
    K = camera.K
    u = (np.arange(c0, c1 + 1) - K[0, 2]) / K[0, 0]
    v = (np.arange(r0, r1 + 1) - K[1, 2]) / K[1, 1]
    rays = np.stack(np.broadcast_arrays(u[None, :], v[:, None], 1.0), axis=-1)
    world_from_box = np.eye(4)
    world_from_box[:3, :3], world_from_box[:3, 3] = world_rotation, world_bottom
    box_from_camera = np.linalg.inv(world_from_box) @ np.linalg.inv(camera_from_world)
    origin = box_from_camera[:3, 3]
    direction = rays @ box_from_camera[:3, :3].T
    direction = np.where(np.abs(direction) < 1e-12, 1e-12, direction)
    lo = np.array([-0.5 * size[0], -0.5 * size[1], 0.0])
    hi = np.array([0.5 * size[0], 0.5 * size[1], size[2]])
    t_lo, t_hi = (lo - origin) / direction, (hi - origin) / direction
    enter = np.minimum(t_lo, t_hi).max(axis=-1)
    leave = np.maximum(t_lo, t_hi).min(axis=-1)
    silhouette = (leave >= np.maximum(enter, 0.0)) & (leave > 0.0)  # the box's
    camera_from_box = np.linalg.inv(box_from_camera)
    points = model.reshape(-1, 3) @ camera_from_box[:3, :3].T + camera_from_box[:3, 3]
    if points[:, 2].min() > camera.near:  # the model's own silhouette
        u = K[0, 0] * points[:, 0] / points[:, 2] + K[0, 2] - c0
        v = K[1, 1] * points[:, 1] / points[:, 2] + K[1, 2] - r0
        corners = np.rint(np.column_stack([u, v]) * (1 << SUBPIXEL_BITS)).astype(np.int32)
        drawn = np.zeros(mine.shape, np.uint8)
        cv2.fillPoly(drawn, list(corners.reshape(-1, 3, 2)), 1, shift=SUBPIXEL_BITS)
        silhouette = drawn.view(bool)
    depth = frame.depth[r0 : r1 + 1, c0 : c1 + 1]
    semantic = frame.semantic[r0 : r1 + 1, c0 : c1 + 1]
    hidden = silhouette & ~mine & occluders[semantic] & (depth < enter - DEPTH_TOLERANCE)
    n_hidden = int(np.count_nonzero(hidden))
    return box, n_hidden / (n_hidden + int(labels.pixels[i]))


def _occluder_classes() -> np.ndarray:
    """(256,) bool by semantic class id: True for the classes that can hide a vehicle."""
    table = np.zeros(256, dtype=bool)
    for semantic in semantic_classes():
        table[semantic.class_id] = True
    for name in NOT_OCCLUDERS:
        table[class_id(name)] = False
    return table


def _wrap(angle: np.ndarray) -> np.ndarray:
    """Angles wrapped to [-pi, pi)."""
    return (angle + np.pi) % (2.0 * np.pi) - np.pi
