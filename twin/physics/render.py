"""What the cameras see of a physics world: the map's visual parts, a drawn model of
every vehicle, and pybullet's renderers (TinyRenderer on the CPU, EGL on a GPU).

The physics bodies of vehicles are boxes and stay invisible; each active vehicle is
drawn by a proxy body without collision that carries its class's model
(``mapgen.vehicles``) scaled to the vehicle's size, painted from the class's paints
(``assets/vehicle_paints.csv``), and posed at the vehicle's pose before each
picture. Proxies are pooled by class and size like the physics bodies. Body ids
never leave this module: a picture comes back with semantic classes and twin
vehicle ids per pixel.

EGL pitfalls (``docs/physics.md``), handled here: the plugin is found through
``pkgutil`` and loaded into this world's client before any visual body; every mesh
comes from an OBJ file (with the plugin loaded, in-memory meshes crash
``createMultiBody``); pictures are taken with ``ER_BULLET_HARDWARE_OPENGL``; the
plugin is unloaded on close.
"""

import pkgutil
import sys
import time
from contextlib import nullcontext
from dataclasses import dataclass, fields
from enum import StrEnum
from functools import cache
from pathlib import Path

import cv2
import numpy as np

from mapgen.build import MapBundle
from mapgen.semantics import class_id
from twin.core.i24 import VEHICLE_CLASSES
from twin.core.vehicle_classes import vehicle_paints
from twin.physics.bullet import filtered_native_output
from twin.physics.bullet import pybullet as p
from twin.physics.map_bodies import visual_body
from twin.physics.states import rotation_matrices
from twin.physics.world import PARK_DEPTH, SIZE_STEP, PhysicsWorld

SKY_TOP = np.array([118, 164, 214], dtype=np.float64)  # RGB
SKY_HORIZON = np.array([206, 222, 238], dtype=np.float64)


@dataclass(frozen=True)
class Light:
    """The light of a picture: the sun and the sky behind the scene.

    Attributes:
        direction: toward the sun, world frame (east, north, up); need not be unit.
        color: the sun's RGB, 0..1.
        ambient, diffuse, specular: the renderer's lighting coefficients.
        shadows: shadows cast from the sun (drawn by :mod:`sensors.shadows`).
        sky_top, sky_horizon: RGB 0..255 of the sky, at the top of the picture and
            at the horizon.
    """

    direction: tuple[float, float, float] = (0.25, -0.35, 1.0)
    color: tuple[float, float, float] = (1.0, 1.0, 1.0)
    ambient: float = 0.55
    diffuse: float = 0.55
    specular: float = 0.05
    shadows: bool = False
    sky_top: tuple[float, float, float] = tuple(SKY_TOP)
    sky_horizon: tuple[float, float, float] = tuple(SKY_HORIZON)

    def renderer_args(self) -> dict:
        """Keyword arguments of pybullet's ``getCameraImage``."""
        return {
            "lightDirection": list(self.direction),
            "lightColor": list(self.color),
            "lightAmbientCoeff": self.ambient,
            "lightDiffuseCoeff": self.diffuse,
            "lightSpecularCoeff": self.specular,
            # TinyRenderer's own shadow map looks at the world's origin: useless on a
            # mile of road, and it doubles the time (sensors.shadows draws them instead)
            "shadow": 0,
        }


#: The paper's "high noon": the sun high in the south, no shadows.
NOON = Light()
LIGHT = NOON.renderer_args()
SKY_CLASS = class_id("sky")
#: Ids of replayed vehicles start here: above any twin id of a run, and within the
#: 16-bit instance images (65534 at most)
REPLAY_BASE = 40000
NO_VEHICLE = -1
PAINT_HASH = 2654435761  # Knuth's multiplicative hash: paints spread over ids


class Renderer(StrEnum):
    TINY = "tiny"  # pybullet's TinyRenderer: CPU, no display, no GPU
    EGL = "egl"  # pybullet's EGL plugin: the GPU where one is, else Mesa's llvmpipe


def gpu_present() -> bool:
    """True when an NVIDIA GPU is visible to this process (a device node exists)."""
    return Path("/dev/nvidia0").exists() or any(Path("/proc/driver/nvidia/gpus").glob("*"))


def gl_renderer_of(driver_text: str) -> str:
    """The ``GL_RENDERER=...`` line the EGL plugin prints on loading ("" if absent)."""
    for line in driver_text.splitlines():
        if line.startswith("GL_RENDERER="):
            return line.removeprefix("GL_RENDERER=").strip()
    return ""


@cache
def _note_cpu_egl(gl_renderer: str) -> None:
    """Say once per process that EGL found a GPU device but renders on the CPU."""
    print(
        f"twin: note: a GPU is present but EGL renders on the CPU ({gl_renderer}); "
        "frames will be slow. Is the NVIDIA EGL library (libEGL_nvidia) installed?",
        file=sys.stderr,
    )


def resolve_renderer(name: str) -> Renderer:
    """``"auto"`` (EGL when a GPU is present, else TinyRenderer), ``"tiny"`` or ``"egl"``.

    Raises:
        ValueError: any other name.
    """
    if name == "auto":
        return Renderer.EGL if gpu_present() else Renderer.TINY
    try:
        return Renderer(name)
    except ValueError:
        raise ValueError(f"renderer must be auto, tiny or egl, got {name!r}") from None


@dataclass(frozen=True, eq=False)
class Picture:
    """One rendered picture.

    Attributes:
        rgb: (h, w, 3) uint8.
        depth_buffer: (h, w) float32, pybullet's non-linear depth in [0, 1] (1: nothing).
        semantic: (h, w) uint8 class ids (``assets/semantic_classes.csv``).
        instance: (h, w) int64 twin vehicle ids, -1 where no vehicle is.
    """

    rgb: np.ndarray
    depth_buffer: np.ndarray
    semantic: np.ndarray
    instance: np.ndarray


@dataclass(frozen=True, eq=False)
class DrawnVehicles:
    """The vehicles as drawn: their 3D boxes, struct-of-arrays.

    Attributes:
        id: (n,) twin ids. vehicle_class: (n,) I-24 class ids.
        size: (n, 3) [m] length, width, height of the drawn model (its bounding box).
        position: (n, 3) [m] world position of the box's bottom centre.
        rotation: (n, 3, 3) body-to-world rotation (x forward, y left, z up).
        speed: (n,) [m/s] along the vehicle's heading.
        shown: (n,) bool, False for the vehicles hidden from this picture.
        replayed: (n,) bool: drawn from the recording (never a physics body), with an
            id from :data:`REPLAY_BASE` up; else simulated, with its twin id.
        record_id: (n,) the I-24 MOTION ``_id`` of the recording it comes from ("" where
            not known).
        road: (n,) +1 eastbound, -1 westbound (0 where not known).
    """

    id: np.ndarray
    vehicle_class: np.ndarray
    size: np.ndarray
    position: np.ndarray
    rotation: np.ndarray
    speed: np.ndarray
    shown: np.ndarray
    replayed: np.ndarray | None = None
    record_id: np.ndarray | None = None
    road: np.ndarray | None = None

    def __post_init__(self):
        n = self.id.size
        if self.replayed is None:
            object.__setattr__(self, "replayed", np.zeros(n, bool))
        if self.record_id is None:
            object.__setattr__(self, "record_id", np.full(n, "", dtype=object))
        if self.road is None:
            object.__setattr__(self, "road", np.zeros(n, np.int64))

    def take(self, index) -> "DrawnVehicles":
        return DrawnVehicles(**{f.name: getattr(self, f.name)[index] for f in fields(self)})

    @classmethod
    def join(cls, *parts: "DrawnVehicles") -> "DrawnVehicles":
        return cls(
            **{f.name: np.concatenate([getattr(p, f.name) for p in parts]) for f in fields(cls)}
        )


class SceneView:
    """The visual scene of ``world`` (same client), rendered on demand.

    Raises:
        RuntimeError: the EGL plugin or a map or vehicle model cannot be loaded.
    """

    def __init__(self, world: PhysicsWorld, bundle: MapBundle, renderer: Renderer):
        self.world = world
        self.renderer = Renderer(renderer)
        self.client = world.client
        self._plugin = None
        self.gl_renderer = ""  # the GL driver's GL_RENDERER, with EGL
        if self.renderer is Renderer.EGL:
            loader = pkgutil.get_loader("eglRenderer")
            if loader is None:
                raise RuntimeError("pybullet's eglRenderer plugin is not installed")
            with filtered_native_output() as driver:
                plugin = p.loadPlugin(
                    loader.get_filename(), "_eglRendererPlugin", physicsClientId=self.client
                )
            if plugin < 0:
                said = " ".join(driver.text.split()) or "it printed nothing"
                raise RuntimeError(f"pybullet could not load its EGL renderer plugin: {said}")
            self._plugin = plugin
            self.gl_renderer = gl_renderer_of(driver.text)
            if gpu_present() and "llvmpipe" in self.gl_renderer.lower():
                _note_cpu_egl(self.gl_renderer)
        self._tiles = [visual_body(self.client, t.visual, t.part.color) for t in bundle.tiles]
        lo = np.array([t.bounds[0] for t in bundle.tiles])
        hi = np.array([t.bounds[1] for t in bundle.tiles])
        self._corners = box_corners(lo, hi)  # (tiles, 8, 4)
        self._shown = np.ones(len(self._tiles), dtype=bool)
        self._levels = [bundle.vehicle_lods[name] for name in VEHICLE_CLASSES]
        levels = max(len(models) for models in self._levels)
        self._level_error = np.zeros((len(VEHICLE_CLASSES), levels))  # [m] at model size
        self._level_error[:, 1:] = np.inf  # levels a map lacks are never drawn
        self._model_size = np.ones((len(VEHICLE_CLASSES), 3))  # [m] the models' own sizes
        for k, levels in enumerate(self._levels):
            self._level_error[k, : len(levels)] = [level.error_m for level in levels]
            self._model_size[k] = levels[0].size_m
        #: [px] focal length of the sharpest camera drawing the scene (0: full models
        #: always); set by the camera rig
        self.lod_focal = 0.0
        self._vehicle_semantic = np.array([class_id(n) for n in VEHICLE_CLASSES], np.uint8)
        self._paints = vehicle_paints()
        self._semantic_lut = np.full(1, SKY_CLASS, dtype=np.uint8)  # index: body + 1
        self._instance_lut = np.full(1, NO_VEHICLE, dtype=np.int64)
        for body, tile in zip(self._tiles, bundle.tiles, strict=True):
            self._label(body, tile.part.class_id, NO_VEHICLE)
        self._colors = [list(tile.part.color) for tile in bundle.tiles]
        self._shapes: dict[tuple, int] = {}
        self._free: dict[tuple, list[int]] = {}
        self._proxies: dict[int, tuple[int, tuple]] = {}  # twin id -> (body, key)
        self._paint_of: dict[int, list] = {}  # proxy body -> its paint (RGBA)
        self._hidden: set[int] = set()  # proxy bodies hidden as outside the frustum
        self.raw_s = 0.0  # [s] spent in pybullet's renderer, for benchmarks

    def close(self) -> None:
        if self._plugin is not None and self.world.client is not None:
            with filtered_native_output():  # the driver's "Destroy EGL OpenGL window."
                p.unloadPlugin(self._plugin, physicsClientId=self.client)
        self._plugin = None

    def levels(self, vehicle_class, size, position, eye=None, margin: float = 0.0) -> np.ndarray:
        """(n,) level of detail to draw each vehicle with ((n,) classes, (n, 3) sizes and
        positions [m]) for cameras within ``margin`` [m] of ``eye`` (world): the
        coarsest level whose error, scaled to the vehicle's size, stays within a pixel
        of the full model's silhouette at :attr:`lod_focal` (an error e at distance d
        is at most e * f / (d - e) pixels). Full models without an eye or focal length.
        """
        vehicle_class = np.asarray(vehicle_class, np.int64)
        n = vehicle_class.size
        if eye is None or self.lod_focal <= 0.0 or n == 0:
            return np.zeros(n, np.int64)
        size = np.asarray(size, np.float64).reshape(n, 3)
        stretch = (size / self._model_size[vehicle_class]).max(axis=1)
        # from any camera to the nearest point of the vehicle's box, at least
        distance = np.linalg.norm(np.asarray(position).reshape(n, 3) - eye, axis=1)
        # (none nearer than the cameras: the full model, whose error is 0, fits there)
        reach = np.maximum(distance - 0.5 * np.linalg.norm(size, axis=1) - margin, 0.0)
        error = self._level_error[vehicle_class] * stretch[:, None]  # (n, levels)
        within = error * (self.lod_focal + 1.0) <= reach[:, None]
        return (within.shape[1] - 1 - np.argmax(within[:, ::-1], axis=1)).astype(np.int64)

    def vehicles(self, hide=(), eye=None, margin: float = 0.0) -> DrawnVehicles:
        """Pose a proxy on every active vehicle of the world (those in ``hide`` are
        parked out of sight) and return all active vehicles with their drawn boxes.
        ``eye`` and ``margin``: where the cameras are, for the levels of detail
        (:meth:`levels`)."""
        states = self.world.states()
        params = self.world.params
        if states.id.size and int(states.id.max()) >= REPLAY_BASE:
            raise RuntimeError(f"twin ids reached {REPLAY_BASE}, where replayed ids begin")
        simulated = {i for i in self._proxies if i < REPLAY_BASE}
        for gone in simulated - set(states.id.tolist()):
            self._release(gone)
        sizes = np.column_stack([params.length, params.width, params.height])
        rotation = rotation_matrices(states.orientation)
        ground = states.position - rotation[:, :, 2] * params.cg_height[:, None]
        centre = _box_centres(ground, rotation, params.height)
        level = self.levels(params.vehicle_class, sizes, centre, eye, margin)
        keys = _keys(params.vehicle_class, level, sizes)
        hidden = set(np.atleast_1d(np.asarray(hide, dtype=np.int64)).tolist())
        shown = ~np.isin(states.id, list(hidden))
        for i, twin_id in enumerate(states.id.tolist()):
            body = self._proxy(twin_id, keys[i])
            place = ground[i].tolist() if shown[i] else [0.0, 0.0, PARK_DEPTH]
            p.resetBasePositionAndOrientation(
                body, place, states.orientation[i].tolist(), physicsClientId=self.client
            )
        size = np.asarray([k[2:] for k in keys], dtype=np.float64).reshape(-1, 3) * SIZE_STEP
        return DrawnVehicles(
            id=states.id,
            vehicle_class=params.vehicle_class.astype(np.int64),
            size=size,
            position=ground,
            rotation=rotation,
            speed=states.speed,
            shown=shown,
        )

    def pose_replayed(
        self,
        ids: np.ndarray,
        vehicle_class: np.ndarray,
        size: np.ndarray,
        position,
        rotation,
        eye=None,
        margin: float = 0.0,
    ) -> np.ndarray:
        """Pose a proxy on each replayed vehicle (``ids`` from :data:`REPLAY_BASE` up,
        (n,) classes, (n, 3) sizes, bottom centres and (n, 3, 3) rotations in the world);
        the replayed proxies not among ``ids`` go back to the pool. Returns the drawn
        sizes (n, 3) [m] (the models' sizes are rounded as the simulated ones').
        ``eye`` and ``margin``: where the cameras are (:meth:`levels`)."""
        ids = np.asarray(ids, np.int64)
        for gone in {i for i in self._proxies if i >= REPLAY_BASE} - set(ids.tolist()):
            self._release(gone)
        size = np.asarray(size, np.float64).reshape(-1, 3)
        rotation = np.asarray(rotation, np.float64).reshape(-1, 3, 3)
        centre = _box_centres(np.asarray(position, np.float64).reshape(-1, 3), rotation, size[:, 2])
        keys = _keys(vehicle_class, self.levels(vehicle_class, size, centre, eye, margin), size)
        quaternions = quaternions_of(rotation)
        for i, twin_id in enumerate(ids.tolist()):
            body = self._proxy(twin_id, keys[i])
            p.resetBasePositionAndOrientation(
                body, position[i].tolist(), quaternions[i].tolist(), physicsClientId=self.client
            )
        return np.asarray([k[2:] for k in keys], dtype=np.float64).reshape(-1, 3) * SIZE_STEP

    def vehicle_triangles(self) -> tuple[int, int]:
        """Triangles of the vehicle models posed now (in the frustum or not): at their
        levels of detail, and were they all full models."""
        keys = [key for _, key in self._proxies.values()]
        return (
            sum(self._levels[k][level].triangles for k, level, *_ in keys),
            sum(self._levels[k][0].triangles for k, *_ in keys),
        )

    def render(
        self, view: list, projection: list, width: int, height: int, light: Light = NOON
    ) -> Picture:
        """Render the scene as posed by the last :meth:`vehicles` call, in ``light``.

        ``view`` and ``projection`` are OpenGL column-major 4x4 matrices (16 floats).
        """
        renderer = (
            p.ER_BULLET_HARDWARE_OPENGL if self.renderer is Renderer.EGL else p.ER_TINY_RENDERER
        )
        clip_from_world = np.reshape(projection, (4, 4)).T @ np.reshape(view, (4, 4)).T
        self._cull(clip_from_world)
        self._cull_vehicles(clip_from_world)
        start = time.perf_counter()
        with filtered_native_output() if self._plugin is not None else nullcontext():
            _, _, rgba, depth, seg = p.getCameraImage(
                width,
                height,
                view,
                projection,
                renderer=renderer,
                physicsClientId=self.client,
                **light.renderer_args(),
            )
        self.raw_s += time.perf_counter() - start
        rgba = np.reshape(np.asarray(rgba, dtype=np.uint8), (height, width, 4))
        seg = np.reshape(np.asarray(seg, dtype=np.int32), (height, width)) + 1
        nothing = (seg == 0).view(np.uint8)
        rgb = cv2.cvtColor(rgba, cv2.COLOR_RGBA2RGB)
        sky = _sky(height, width, light.sky_top, light.sky_horizon)
        cv2.copyTo(sky, nothing, rgb)  # OpenCV: 0.1 ms, numpy: 4 ms
        # the cleared buffer reads a little under 1 (the far plane): mark it exactly
        depth = np.reshape(np.asarray(depth, dtype=np.float32), (height, width)).copy()
        depth[nothing.view(bool)] = 1.0
        return Picture(
            rgb=rgb,
            depth_buffer=depth,
            semantic=np.take(self._semantic_lut, seg),
            instance=np.take(self._instance_lut, seg),
        )

    def _cull(self, clip_from_world: np.ndarray) -> None:
        """Hide the map tiles whose boxes lie wholly outside the view frustum.

        TinyRenderer does not clip: a triangle behind the camera is still scanned over
        its screen box, so a whole map drawn from inside costs about twice as much.
        """
        outside = outside_frustum(self._corners, clip_from_world)
        for k in np.flatnonzero(outside == self._shown).tolist():
            color = [1.0, 1.0, 1.0, 0.0] if outside[k] else self._colors[k]
            p.changeVisualShape(self._tiles[k], -1, rgbaColor=color, physicsClientId=self.client)
        self._shown = ~outside

    def _cull_vehicles(self, clip_from_world: np.ndarray) -> None:
        """Hide the vehicle models whose boxes lie wholly outside the view frustum (half
        of a camera's neighbours are behind it), show them again when they come in."""
        if not self._proxies:
            return
        bodies = [body for body, _ in self._proxies.values()]
        boxes = np.array([p.getAABB(b, physicsClientId=self.client) for b in bodies])
        outside = outside_frustum(box_corners(boxes[:, 0], boxes[:, 1]), clip_from_world)
        for body, hide in zip(bodies, outside.tolist(), strict=True):
            if hide != (body in self._hidden):
                color = [1.0, 1.0, 1.0, 0.0] if hide else self._paint_of[body]
                p.changeVisualShape(body, -1, rgbaColor=color, physicsClientId=self.client)
                (self._hidden.add if hide else self._hidden.discard)(body)

    # -- proxies ----------------------------------------------------------------------

    def _proxy(self, twin_id: int, key: tuple) -> int:
        """The proxy body drawing vehicle ``twin_id`` with model ``key`` (class, level of
        detail, size in SIZE_STEP), taken from the pool on first use or when the key
        changes (a vehicle crossing to another level)."""
        held = self._proxies.get(twin_id)
        if held is not None:
            if held[1] == key:
                return held[0]
            self._release(twin_id)
        free = self._free.setdefault(key, [])
        if free:
            body = free.pop()
        else:
            if key not in self._shapes:
                model = self._levels[key[0]][key[1]].file
                shape = p.createVisualShape(
                    p.GEOM_MESH,
                    fileName=model,
                    meshScale=[v * SIZE_STEP for v in key[2:]],
                    physicsClientId=self.client,
                )
                if shape < 0:
                    raise RuntimeError(f"pybullet could not load {model}")
                self._shapes[key] = shape
            body = p.createMultiBody(
                baseMass=0.0,
                baseCollisionShapeIndex=-1,
                baseVisualShapeIndex=self._shapes[key],
                physicsClientId=self.client,
            )
        paints = self._paints[key[0]]
        paint = paints[(twin_id * PAINT_HASH) % 2**32 % len(paints)]
        self._paint_of[body] = [*paint, 1.0]
        self._hidden.discard(body)
        p.changeVisualShape(body, -1, rgbaColor=[*paint, 1.0], physicsClientId=self.client)
        self._label(body, self._vehicle_semantic[key[0]], twin_id)
        self._proxies[twin_id] = (body, key)
        return body

    def _release(self, twin_id: int) -> None:
        body, key = self._proxies.pop(twin_id)
        p.resetBasePositionAndOrientation(
            body, [0.0, 0.0, PARK_DEPTH], [0, 0, 0, 1], physicsClientId=self.client
        )
        self._label(body, SKY_CLASS, NO_VEHICLE)
        self._free[key].append(body)

    def _label(self, body: int, semantic: int, instance: int) -> None:
        if body + 1 >= self._semantic_lut.size:
            grow = body + 2 - self._semantic_lut.size + 64
            self._semantic_lut = np.concatenate(
                [self._semantic_lut, np.full(grow, SKY_CLASS, np.uint8)]
            )
            self._instance_lut = np.concatenate(
                [self._instance_lut, np.full(grow, NO_VEHICLE, np.int64)]
            )
        self._semantic_lut[body + 1] = semantic
        self._instance_lut[body + 1] = instance


def _box_centres(bottom: np.ndarray, rotation: np.ndarray, height: np.ndarray) -> np.ndarray:
    """(n, 3) centres of boxes from their (n, 3) bottom centres, (n, 3, 3) rotations and
    (n,) heights."""
    return bottom + rotation[:, :, 2] * (0.5 * np.asarray(height)[:, None])


def _keys(vehicle_class, level, size) -> list[tuple]:
    """The model key of each vehicle: (class, level of detail, length, width, height in
    SIZE_STEP): vehicles of one key share a model and a pool of proxies."""
    steps = np.maximum(1, np.round(np.asarray(size, np.float64) / SIZE_STEP)).astype(np.int64)
    return [
        (int(k), int(lv), *map(int, st))
        for k, lv, st in zip(vehicle_class, level, steps.reshape(-1, 3), strict=True)
    ]


#: corners of a unit box, numbered by bits (x, y, z): 0 is (0, 0, 0), 7 is (1, 1, 1)
UNIT_BOX = np.array([[(k >> axis) & 1 for axis in range(3)] for k in range(8)], np.float64)


def box_corners(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(n, 8, 4) homogeneous corners of axis-aligned boxes from (n, 3) ``lo``, ``hi``."""
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    corners = np.where(UNIT_BOX[None] > 0, hi[:, None, :], lo[:, None, :])
    return np.concatenate([corners, np.ones((*corners.shape[:2], 1))], axis=2)


def outside_frustum(corners: np.ndarray, clip_from_world: np.ndarray) -> np.ndarray:
    """(n,) bool: the boxes (homogeneous corners (n, 8, 4)) wholly on the outer side of
    one of the view frustum's planes."""
    clip = corners @ clip_from_world.T
    x, y, z, w = clip[..., 0], clip[..., 1], clip[..., 2], clip[..., 3]
    return (
        (x < -w).all(1) | (x > w).all(1) | (y < -w).all(1) | (y > w).all(1)
        | (z < -w).all(1) | (z > w).all(1)
    )  # fmt: skip


def quaternions_of(rotation: np.ndarray) -> np.ndarray:
    """(n, 4) quaternions (x, y, z, w, pybullet's order) of (n, 3, 3) rotations."""
    from scipy.spatial.transform import Rotation

    r = np.asarray(rotation, np.float64).reshape(-1, 3, 3)
    return Rotation.from_matrix(r).as_quat() if len(r) else np.empty((0, 4))


@cache
def _sky(height: int, width: int, top: tuple = tuple(SKY_TOP), horizon: tuple = tuple(SKY_HORIZON)):
    """(height, width, 3) uint8: a clear sky, ``top`` above, ``horizon`` at the horizon."""
    rows = np.minimum(np.linspace(0.0, 2.0, height), 1.0)[:, None]
    top, horizon = np.asarray(top, np.float64), np.asarray(horizon, np.float64)
    colour = (top + (horizon - top) * rows).astype(np.uint8)
    sky = np.ascontiguousarray(np.broadcast_to(colour[:, None, :], (height, width, 3)))
    sky.flags.writeable = False
    return sky
