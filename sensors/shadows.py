"""Sun shadows drawn onto a rendered picture: a projected-shadow pass.

pybullet's TinyRenderer has a shadow map, but it looks at the world's origin from the
light with the camera's own projection, so on a mile of road it shades nothing near
the ego (``TinyRenderer::renderObjectDepth``: ``lookat(light_dir * distance, origin)``).
Here each caster's box (every drawn vehicle, the lighting poles, the overpass deck) is
projected along the sun onto the ground plane under it; the polygon is drawn into the
picture with OpenCV, and the ground pixels inside it (road, shoulder, markings,
terrain) are darkened to what the sky alone lights: the ambient share of the light.
Only the RGB picture changes; depth, semantic and instance images are the renderer's.
"""

from dataclasses import dataclass

import cv2
import numpy as np

from mapgen.params import load_params
from mapgen.semantics import class_id
from twin.physics.render import UNIT_BOX

#: the classes a shadow falls on (the flat ground); vehicles, barrier, poles and the
#: overpass in front of a shadow keep their pixels
GROUND_CLASSES = tuple(class_id(n) for n in ("road", "shoulder", "lane_marking", "terrain"))
_GROUND_LUT = np.isin(np.arange(256), GROUND_CLASSES).astype(np.uint8)
MIN_SUN_UP = 0.05  # [-] the sun's upward component below which no shadows are drawn


@dataclass(frozen=True)
class Casters:
    """Boxes that cast shadows, (n,) or (n, ...) arrays in the world frame.

    Attributes:
        bottom: (n, 3) [m] centre of each box's bottom face.
        rotation: (n, 3, 3) box-to-world (columns: length, width, up axes).
        size: (n, 3) [m] length, width, height.
        ground: (n,) [m] height of the ground the shadow falls on (a vehicle's: its
            bottom; a deck's: the road under it).
    """

    bottom: np.ndarray
    rotation: np.ndarray
    size: np.ndarray
    ground: np.ndarray

    @classmethod
    def on_ground(cls, bottom, rotation, size) -> "Casters":
        """Boxes standing on the ground (vehicles, poles)."""
        bottom = np.asarray(bottom, np.float64).reshape(-1, 3)
        return cls(bottom, rotation, size, bottom[:, 2].copy())

    @classmethod
    def join(cls, *parts: "Casters") -> "Casters":
        return cls(
            np.concatenate([p.bottom for p in parts]).reshape(-1, 3),
            np.concatenate([p.rotation for p in parts]).reshape(-1, 3, 3),
            np.concatenate([p.size for p in parts]).reshape(-1, 3),
            np.concatenate([p.ground for p in parts]).reshape(-1),
        )


def shadow_polygons(casters: Casters, sun: np.ndarray) -> np.ndarray:
    """(n, 8, 3) world points whose convex hull, per caster, is its shadow on the
    horizontal plane of its ground: the box's corners moved along the sun's rays down
    to that plane.

    Args:
        sun: toward the sun, world frame; its up component must be > 0.
    """
    sun = np.asarray(sun, np.float64)
    sun = sun / np.linalg.norm(sun)
    local = (UNIT_BOX - [0.5, 0.5, 0.0])[None] * casters.size[:, None, :]
    corners = np.einsum("nij,nkj->nki", casters.rotation, local) + casters.bottom[:, None, :]
    height = corners[..., 2] - casters.ground[:, None]  # above the caster's ground
    return corners - height[..., None] * (sun / sun[2])


def shadow_mask(
    casters: Casters,
    sun: np.ndarray,
    K: np.ndarray,
    camera_from_world: np.ndarray,
    width: int,
    height: int,
    near: float,
) -> np.ndarray:
    """(height, width) bool: the pixels that see the ground inside a caster's shadow
    (before the ground-class test), OpenCV camera axes (x right, y down, z forward)."""
    mask = np.zeros((height, width), np.uint8)
    sun = np.asarray(sun, np.float64)
    if len(casters.bottom) == 0 or sun[2] / np.linalg.norm(sun) < MIN_SUN_UP:
        return mask.view(bool)
    points = shadow_polygons(casters, sun)
    camera = points @ camera_from_world[:3, :3].T + camera_from_world[:3, 3]
    ahead = (camera[..., 2] >= near).any(axis=1)
    # those wholly in front of the camera and wholly off one side of the picture: none
    front = (camera[..., 2] >= near).all(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = (camera @ K.T)[..., :2] / np.maximum(camera[..., 2:3], near)
    off = (
        (uv[..., 0] < 0).all(1) | (uv[..., 0] >= width).all(1)
        | (uv[..., 1] < 0).all(1) | (uv[..., 1] >= height).all(1)
    )  # fmt: skip
    ahead &= ~(front & off)
    flat = points[ahead][..., :2].astype(np.float32)
    for k, polygon, whole in zip(range(len(flat)), camera[ahead], front[ahead], strict=True):
        # the points lie on a horizontal plane: their hull is the hull of their x, y
        hull = polygon[cv2.convexHull(flat[k], returnPoints=False).reshape(-1)]
        clipped = hull if whole else _clip_near(hull, near)  # whole: in front, in view
        if len(clipped) < 3:
            continue
        uv = uv_of(clipped, K)
        if not whole and (uv[:, 0].max() < 0 or uv[:, 0].min() >= width or uv[:, 1].max() < 0
                or uv[:, 1].min() >= height):  # fmt: skip
            continue
        uv = np.clip(uv, -4.0 * max(width, height), 4.0 * max(width, height))
        cv2.fillPoly(mask, [np.round(uv * 16).astype(np.int32)], 1, cv2.LINE_8, shift=4)
    return mask.view(bool)


def uv_of(points: np.ndarray, K: np.ndarray) -> np.ndarray:
    """(n, 2) pixel coordinates of (n, 3) camera-frame points in front of the camera."""
    pixels = points @ K.T
    return pixels[:, :2] / pixels[:, 2:3]


def map_casters(bundle) -> Casters:
    """The map's shadow casters: each lighting pole (mast and head as one box) and the
    overpass deck with its parapets (``road.json``'s objects and ``assets/map.toml``)."""
    road, objects = bundle.road, bundle.description["objects"]
    params = load_params()
    pole_width = params.poles.base_radius + params.poles.top_radius  # the mean diameter
    deck = params.overpass
    forward, right = road.direction_vector, road.right_vector
    axes = np.zeros((3, 3))
    axes[:2, 0], axes[:2, 1], axes[2, 2] = forward, right, 1.0

    def world(station: float, lateral: float, z: float) -> np.ndarray:
        return np.array([*(station * forward + lateral * right), z])

    bottoms, sizes, grounds = [], [], []
    for pole in objects.get("poles", []):
        z = float(road.surface_z(pole["station_m"]))
        bottoms.append(world(pole["station_m"], pole["lateral_m"], z))
        sizes.append([pole_width, pole_width, pole["height_m"]])
        grounds.append(z)
    overpass = objects.get("overpass")
    if overpass:
        s0, s1 = overpass["deck_stations_m"]
        centre = 0.5 * (s0 + s1)
        outer = bundle.description["cross_section"]["outer_edge_y_m"]
        bottoms.append(world(centre, 0.0, overpass["deck_bottom_z_m"]))
        sizes.append(
            [s1 - s0, 2.0 * (outer + deck.abutment_offset), deck.deck_depth + deck.parapet_height]
        )
        grounds.append(float(road.surface_z(centre)))
    n = len(bottoms)
    return Casters(
        np.array(bottoms).reshape(n, 3),
        np.broadcast_to(axes, (n, 3, 3)),
        np.array(sizes).reshape(n, 3),
        np.array(grounds).reshape(n),
    )


def _clip_near(polygon: np.ndarray, near: float) -> np.ndarray:
    """The part of a convex polygon (camera frame) in front of the plane z = near
    (Sutherland-Hodgman against one plane)."""
    out = []
    n = len(polygon)
    for k in range(n):
        a, b = polygon[k], polygon[(k + 1) % n]
        a_in, b_in = a[2] >= near, b[2] >= near
        if a_in:
            out.append(a)
        if a_in != b_in:
            t = (near - a[2]) / (b[2] - a[2])
            out.append(a + t * (b - a))
    return np.array(out).reshape(-1, 3)


def darken(rgb: np.ndarray, semantic: np.ndarray, mask: np.ndarray, factor: float) -> np.ndarray:
    """``rgb`` with the ground pixels inside ``mask`` scaled by ``factor`` (0..1)."""
    ground = (_GROUND_LUT[semantic] & mask.view(np.uint8)).astype(np.uint8)
    out = rgb.copy()
    if ground.any():
        cv2.copyTo(cv2.convertScaleAbs(rgb, alpha=factor), ground, out)  # 1 ms, numpy 3 ms
    return out


def shade_factor(ambient: float, diffuse: float, sun: np.ndarray) -> float:
    """Brightness of shaded flat ground relative to lit: the ambient light over ambient
    plus the sun's diffuse light on a horizontal surface."""
    up = float(sun[2] / np.linalg.norm(sun))
    return ambient / (ambient + diffuse * max(up, 0.0))
