"""Vehicle models for the cameras: one low-poly body per I-24 class, as OBJ files.

Each class is a few convex prisms (lower body, glasshouse, cab, trailer or box) and
its wheels, drawn in metres at the class's mean size (``assets/vehicle_classes.csv``)
and then scaled to the unit box: x in [-0.5, 0.5] (front at +0.5), y in [-0.5, 0.5]
(left at +0.5), z in [0, 1] (ground at 0). The renderer scales a model by each
vehicle's length, width and height, so the model's bounding box is the vehicle's
3D box exactly. Colours come from a small palette texture: the paint entry is white
and takes the vehicle's paint colour (pybullet multiplies the texture by the
shape's colour); glass, tyres and trim are dark whatever the paint.

Levels of detail: the wheels are most of a model's triangles (36 of a sedan's 40 + 144),
so level 1 draws each wheel as a square (12 triangles) and level 2 draws none. Each
level's error is the largest distance between its surface and the full model's
(their Hausdorff distance, bounded from above on points 5 cm apart), so that past
``error * f`` metres (f the camera's focal length in pixels) its silhouette is within
a pixel of the full model's; the renderer picks the level per vehicle and camera rig.
"""

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from twin.core.i24 import VEHICLE_CLASSES
from twin.core.vehicle_classes import vehicle_classes

PALETTE = np.array(
    [
        [255, 255, 255],  # paint, tinted per vehicle
        [48, 58, 70],  # glass
        [24, 24, 24],  # tyres
        [70, 70, 72],  # trim: bumpers, rider, chassis
    ],
    dtype=np.uint8,
)
PAINT, GLASS, TYRE, TRIM = range(4)
PALETTE_PNG = "palette.png"
MATERIAL = "vehicles.mtl"
WHEEL_WIDTH = 0.24  # [m]
WHEEL_SECTIONS = 10
LOD_WHEEL_SECTIONS = (WHEEL_SECTIONS, 4, 0)  # by level of detail; 0: no wheels
LOD_SPACING = 0.05  # [m] of the points the levels' errors are measured on


@dataclass(frozen=True)
class Prism:
    """A convex side profile (x forward, z up) [m] extruded across ``y0..y1`` [m]."""

    profile: tuple[tuple[float, float], ...]
    y0: float
    y1: float
    palette: int


@dataclass(frozen=True)
class ModelLevel:
    """One level of detail of a class's model.

    Attributes:
        file: OBJ file name. triangles: its triangle count.
        error_m: [m] the largest distance between its surface and the full model's at
            the class's mean size (0 for the full model).
        size_m: [m] (length, width, height) of the model at the class's mean size,
            which the unit box stands for.
    """

    file: str
    triangles: int
    error_m: float
    size_m: tuple[float, float, float]


def write_vehicle_models(folder: Path) -> dict[str, list[ModelLevel]]:
    """Write every class's model at each level of detail (``<class>.obj``,
    ``<class>-lod1.obj``, ...), their material and palette into ``folder``.

    Returns:
        class name -> its levels of detail, the full model first.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    texture = np.repeat(np.repeat(PALETTE[None, :, ::-1], 16, axis=0), 16, axis=1)
    if not cv2.imwrite(str(folder / PALETTE_PNG), texture):
        raise OSError(f"could not write {folder / PALETTE_PNG}")
    (folder / MATERIAL).write_text(
        f"newmtl vehicle\nKa 1 1 1\nKd 1 1 1\nKs 0.1 0.1 0.1\nmap_Kd {PALETTE_PNG}\n"
    )
    levels = {}
    for name in VEHICLE_CLASSES:
        full = _triangles(vehicle_prisms(name))
        low, high = full.reshape(-1, 3).min(axis=0), full.reshape(-1, 3).max(axis=0)
        size = tuple(float(v) for v in high - low)
        levels[name] = []
        for level, sections in enumerate(LOD_WHEEL_SECTIONS):
            prisms = vehicle_prisms(name, wheel_sections=sections)
            file = f"{name}.obj" if level == 0 else f"{name}-lod{level}.obj"
            (folder / file).write_text(_obj(prisms, (low, high)))
            mine = _triangles(prisms)
            error = 0.0 if level == 0 else hausdorff(full, mine, LOD_SPACING)
            levels[name].append(ModelLevel(file, len(mine), round(error, 4), size))
    return levels


def hausdorff(a: np.ndarray, b: np.ndarray, spacing: float) -> float:
    """[m] Hausdorff distance between the surfaces of triangles ``a`` and ``b`` ((n, 3, 3)
    each): the exact distances to the other surface of points at most ``spacing``
    apart on each, plus ``spacing`` (an upper bound). Triangles the two share are at
    distance 0 and need no points (the levels of detail differ in their wheels only)."""

    def directed(p: np.ndarray, q: np.ndarray) -> float:
        q_low, q_high = q.min(axis=1), q.max(axis=1)
        far = 0.0
        for tri in p[~_rows_in(p, q)]:
            # only the triangles of q that may hold the nearest point of one of tri's:
            # none is farther than the nearest to a corner plus tri's size
            reach = point_triangle_distance(tri, q).max() + 2.0 * np.ptp(tri, axis=0).max()
            gap = np.maximum(q_low - tri.max(axis=0), tri.min(axis=0) - q_high).max(axis=1)
            points = _surface_points(tri[None], spacing)
            far = max(far, float(point_triangle_distance(points, q[gap <= reach]).max()))
        return far

    return max(directed(a, b), directed(b, a)) + spacing


def point_triangle_distance(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(n,) [m] distance of each of ``points`` (n, 3) to the nearest of ``triangles``
    (m, 3, 3): the closest point on each triangle by its Voronoi regions (Ericson,
    Real-Time Collision Detection, 5.1.5), all pairs at once."""
    p = points[:, None, :]
    a, b, c = (triangles[None, :, k, :] for k in range(3))
    ab, ac, ap, bp, cp = b - a, c - a, p - a, p - b, p - c

    def dot(u, v):
        return np.einsum("...k,...k->...", u, v)

    d1, d2, d3, d4, d5, d6 = (
        dot(ab, ap),
        dot(ac, ap),
        dot(ab, bp),
        dot(ac, bp),
        dot(ab, cp),
        dot(ac, cp),
    )
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        on_ab = a + (d1 / (d1 - d3))[..., None] * ab
        on_ac = a + (d2 / (d2 - d6))[..., None] * ac
        on_bc = b + ((d4 - d3) / ((d4 - d3) + (d5 - d6)))[..., None] * (c - b)
        inside = 1.0 / (va + vb + vc)
        on_face = a + (vb * inside)[..., None] * ab + (vc * inside)[..., None] * ac
    regions = [
        (d1 <= 0) & (d2 <= 0),
        (d3 >= 0) & (d4 <= d3),
        (vc <= 0) & (d1 >= 0) & (d3 <= 0),
        (d6 >= 0) & (d5 <= d6),
        (vb <= 0) & (d2 >= 0) & (d6 <= 0),
        (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0),
    ]
    choices = [a, b, on_ab, c, on_ac, on_bc]
    closest = np.select([r[..., None] for r in regions], choices, on_face)
    return np.sqrt(dot(p - closest, p - closest)).min(axis=1)


def _rows_in(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(n,) bool: each triangle of ``p`` is (to 1e-9 m) one of ``q``'s."""
    keys = {tuple(np.round(t, 9).ravel()) for t in q}
    return np.array([tuple(np.round(t, 9).ravel()) in keys for t in p], dtype=bool)


def _surface_points(triangles: np.ndarray, spacing: float) -> np.ndarray:
    """Points on each triangle on a barycentric grid whose steps are at most ``spacing``."""
    points = []
    for tri in triangles:
        edge = np.linalg.norm(tri - np.roll(tri, 1, axis=0), axis=1).max()
        n = max(1, int(np.ceil(edge / spacing)))
        i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1))
        keep = i + j <= n
        u, v = i[keep, None] / n, j[keep, None] / n
        points.append(tri[0] + u * (tri[1] - tri[0]) + v * (tri[2] - tri[0]))
    return np.concatenate(points)


def vehicle_prisms(name: str, *, wheel_sections: int = WHEEL_SECTIONS) -> list[Prism]:
    """The parts of class ``name`` in metres at its mean size, before normalising, with
    wheels of ``wheel_sections`` sides (0: none)."""
    table = vehicle_classes()
    row = table.frame[table.frame["name"] == name]
    if row.empty:
        raise ValueError(f"unknown vehicle class {name!r}; known: {list(VEHICLE_CLASSES)}")
    row = row.iloc[0]
    length, width, height = row["length_m"], row["width_m"], row["height_m"]
    radius = float(row["wheel_radius_m"])
    half_base = 0.5 * row["wheelbase_ratio"] * length
    half_track = 0.5 * width
    f, b = 0.5 * length, -0.5 * length  # front and back
    w = 0.5 * width
    body = SHAPES[name](f, b, w, height)
    axles = AXLES.get(name, lambda f, b, hb: (hb, -hb))(f, b, half_base)
    if name == "motorcycle":  # one narrow wheel on the centre line
        sides = [(-0.25 * WHEEL_WIDTH, 0.25 * WHEEL_WIDTH)]
    else:  # the tyres' outer faces flush with the body's sides
        sides = [(-half_track, WHEEL_WIDTH - half_track), (half_track - WHEEL_WIDTH, half_track)]
    wheels = []
    for x in axles if wheel_sections else ():
        circle = tuple(
            (x + radius * np.cos(a), radius + radius * np.sin(a))
            for a in np.linspace(0.0, 2.0 * np.pi, wheel_sections, endpoint=False)
        )
        wheels += [Prism(circle, y0, y1, TYRE) for y0, y1 in sides]
    return body + wheels


def _sedan(f, b, w, h):
    return [
        Prism(((b, 0.45), (f, 0.45), (f, 0.62), (f - 0.35, 0.8), (b, 0.86)), -w, w, PAINT),
        Prism(
            ((b + 0.75, 0.82), (f - 1.3, 0.8), (f - 2.05, h), (b + 1.15, h)),
            -w + 0.1,
            w - 0.1,
            GLASS,
        ),
        Prism(((b, 0.3), (f, 0.3), (f, 0.45), (b, 0.45)), -w, w, TRIM),
    ]


def _midsize(f, b, w, h):
    return [
        Prism(((b, 0.52), (f, 0.52), (f, 0.8), (f - 0.5, 1.02), (b, 1.05)), -w, w, PAINT),
        Prism(
            ((b + 0.15, 1.02), (f - 1.2, 1.0), (f - 1.9, h), (b + 0.3, h)), -w + 0.1, w - 0.1, GLASS
        ),
        Prism(((b, 0.36), (f, 0.36), (f, 0.52), (b, 0.52)), -w, w, TRIM),
    ]


def _pickup(f, b, w, h):
    return [
        Prism(((b, 0.62), (f, 0.62), (f, 1.0), (f - 0.6, 1.15), (b, 1.15)), -w, w, PAINT),
        Prism(
            ((b + 2.2, 1.12), (f - 1.45, 1.12), (f - 2.0, h), (b + 2.25, h)),
            -w + 0.1,
            w - 0.1,
            GLASS,
        ),
        Prism(((b, 0.45), (f, 0.45), (f, 0.62), (b, 0.62)), -w, w, TRIM),
    ]


def _van(f, b, w, h):
    return [
        Prism(((b, 0.35), (f, 0.35), (f, 1.05), (f - 0.8, 1.3), (b, 1.3)), -w, w, PAINT),
        Prism(
            ((b + 0.1, 1.28), (f - 0.8, 1.28), (f - 1.3, 1.9), (b + 0.1, 1.9)),
            -w + 0.04,
            w - 0.04,
            GLASS,
        ),
        Prism(((b, 1.88), (f - 1.3, 1.88), (f - 1.4, h), (b, h)), -w + 0.02, w - 0.02, PAINT),
    ]


def _semi(f, b, w, h):
    cab_back = f - 2.6
    return [
        Prism(((b, 1.2), (cab_back - 0.6, 1.2), (cab_back - 0.6, h), (b, h)), -w, w, PAINT),
        Prism(((b, 0.55), (f, 0.55), (f, 1.05), (b, 1.05)), -0.45 * w, 0.45 * w, TRIM),
        Prism(((cab_back, 0.6), (f, 0.6), (f, 2.1), (cab_back, 2.4)), -w + 0.12, w - 0.12, PAINT),
        Prism(
            ((cab_back + 0.3, 2.1), (f - 0.25, 2.1), (f - 0.5, 2.95), (cab_back + 0.4, 2.95)),
            -w + 0.16,
            w - 0.16,
            GLASS,
        ),
        Prism(
            (
                (cab_back - 0.5, 2.4),
                (cab_back + 0.4, 2.4),
                (cab_back + 0.4, 3.4),
                (cab_back - 0.5, 3.4),
            ),
            -w + 0.2,
            w - 0.2,
            PAINT,
        ),
    ]


def _truck(f, b, w, h):
    cab_back = f - 2.3
    return [
        Prism(((b, 0.95), (cab_back - 0.15, 0.95), (cab_back - 0.15, h), (b, h)), -w, w, PAINT),
        Prism(((b, 0.5), (f, 0.5), (f, 0.95), (b, 0.95)), -0.45 * w, 0.45 * w, TRIM),
        Prism(
            ((cab_back, 0.6), (f, 0.6), (f, 1.55), (f - 0.2, 1.6), (cab_back, 1.6)),
            -w + 0.1,
            w - 0.1,
            PAINT,
        ),
        Prism(
            ((cab_back + 0.2, 1.6), (f - 0.2, 1.6), (f - 0.55, 2.65), (cab_back + 0.2, 2.65)),
            -w + 0.14,
            w - 0.14,
            GLASS,
        ),
    ]


def _motorcycle(f, b, w, h):
    return [
        Prism(
            ((b + 0.2, 0.45), (f - 0.25, 0.45), (f - 0.35, 0.95), (b + 0.35, 0.85)),
            -0.16,
            0.16,
            PAINT,
        ),
        Prism(((b + 0.7, 0.85), (b + 1.25, 0.9), (b + 1.15, h), (b + 0.85, h)), -0.22, 0.22, TRIM),
        Prism(((f - 0.5, 0.9), (f - 0.35, 0.95), (f - 0.4, 1.2), (f - 0.55, 1.2)), -w, w, TRIM),
    ]


SHAPES = {
    "sedan": _sedan,
    "midsize": _midsize,
    "pickup": _pickup,
    "van": _van,
    "semi": _semi,
    "truck": _truck,
    "motorcycle": _motorcycle,
}
AXLES = {  # x of the axles [m] from front, back and half wheelbase
    "semi": lambda f, b, hb: (f - 1.1, f - 4.8, f - 6.1, b + 2.4, b + 1.2),
    "truck": lambda f, b, hb: (f - 1.2, b + 2.0),
    "motorcycle": lambda f, b, hb: (f - 0.35, b + 0.35),
}


def _prism_mesh(prism: Prism) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (n, 3) [m] and triangles (m, 3) of one prism, outward faces, flat-shaded
    (three vertices per face, so each face has its own normal)."""
    xz = np.asarray(prism.profile, dtype=np.float64)
    if _signed_area(xz) < 0:
        xz = xz[::-1]
    n = len(xz)
    left = np.column_stack([xz[:, 0], np.full(n, prism.y1), xz[:, 1]])
    right = np.column_stack([xz[:, 0], np.full(n, prism.y0), xz[:, 1]])
    triangles = []
    for k in range(1, n - 1):  # caps: counter-clockwise in (x, z) faces -y
        triangles.append((right[0], right[k], right[k + 1]))
        triangles.append((left[0], left[k + 1], left[k]))
    for k in range(n):
        j = (k + 1) % n
        triangles.append((right[k], left[k], left[j]))
        triangles.append((right[k], left[j], right[j]))
    vertices = np.asarray(triangles).reshape(-1, 3)
    return vertices, np.arange(len(vertices)).reshape(-1, 3)


def _signed_area(xz: np.ndarray) -> float:
    x, z = xz[:, 0], xz[:, 1]
    return 0.5 * float(np.sum(x * np.roll(z, -1) - np.roll(x, -1) * z))


def _triangles(prisms: list[Prism]) -> np.ndarray:
    """(n, 3, 3) [m] triangles of the prisms."""
    return np.concatenate([v[t] for v, t in map(_prism_mesh, prisms)])


def _obj(prisms: list[Prism], bounds: tuple[np.ndarray, np.ndarray]) -> str:
    """Wavefront OBJ of the prisms, the box ``bounds`` (low and high corners [m]: the
    full model's) normalised to the unit box, textured by the palette.

    Normals stay those of the model at its mean size: the renderer rotates normals
    but does not rescale them.
    """
    meshes = [_prism_mesh(prism) for prism in prisms]
    low, high = bounds
    scale = high - low
    offset = np.array([low[0] + 0.5 * scale[0], low[1] + 0.5 * scale[1], low[2]])
    lines = [f"mtllib {MATERIAL}", "usemtl vehicle"]
    lines += [f"vt {(k + 0.5) / len(PALETTE):.6f} 0.5" for k in range(len(PALETTE))]
    faces = []
    for (v, triangles), prism in zip(meshes, prisms, strict=True):
        corners = v[triangles]
        normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        lines += [f"vn {x:.6f} {y:.6f} {z:.6f}" for x, y, z in normals]
        lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in (v - offset) / scale]
        first_vertex, first_normal = len(faces) * 3 + 1, len(faces) + 1
        for t, triangle in enumerate(triangles):
            corner = " ".join(
                f"{first_vertex + i}/{prism.palette + 1}/{first_normal + t}" for i in triangle
            )
            faces.append(f"f {corner}")
    return "\n".join(lines + faces) + "\n"
