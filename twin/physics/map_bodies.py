"""The map's static bodies in a pybullet client: collision meshes and visual parts.

Meshes come from the map's OBJ files, never from in-memory vertices: with the EGL
renderer loaded, in-memory meshes crash ``createMultiBody`` (``docs/physics.md``). A
collision mesh from a file is a convex hull unless ``GEOM_FORCE_CONCAVE_TRIMESH`` is
set, and triangle internal edges give sliding bodies bogus contact normals unless
``GEOM_CONCAVE_INTERNAL_EDGE`` is set: both flags are always set here.
"""

from dataclasses import dataclass

from mapgen.build import MapBundle
from twin.physics.bullet import pybullet as p

CONCAVE_FLAGS = p.GEOM_FORCE_CONCAVE_TRIMESH | p.GEOM_CONCAVE_INTERNAL_EDGE


@dataclass(frozen=True)
class MapBodies:
    """Body ids of the map in one client.

    Attributes:
        collision: ``road`` / ``obstacles`` -> static collision body (no visual shape).
        visual: part name -> static visual body (no collision shape).
        semantic: visual body id -> semantic class id, for segmentation labels.
    """

    collision: dict[str, int]
    visual: dict[str, int]
    semantic: dict[int, int]


def load_map_bodies(
    client: int, bundle: MapBundle, *, collision: bool = True, visual: bool = True
) -> MapBodies:
    """Create the map's static bodies in pybullet client ``client``.

    Raises:
        RuntimeError: pybullet could not load one of the map's OBJ files.
    """
    collision_bodies, visual_bodies, semantic = {}, {}, {}
    if collision:
        for name, path in bundle.collision.items():
            shape = p.createCollisionShape(
                p.GEOM_MESH, fileName=str(path), flags=CONCAVE_FLAGS, physicsClientId=client
            )
            _check(shape, path)
            body = p.createMultiBody(
                baseMass=0.0,
                baseCollisionShapeIndex=shape,
                baseVisualShapeIndex=-1,
                physicsClientId=client,
            )
            # A body with no visual shape is drawn from its collision shape; the visual
            # parts already show the map, so the collision bodies are made invisible.
            p.changeVisualShape(body, -1, rgbaColor=[1, 1, 1, 0], physicsClientId=client)
            collision_bodies[name] = body
    if visual:
        for part in bundle.parts:
            body = visual_body(client, part.visual, part.color)
            visual_bodies[part.name] = body
            semantic[body] = part.class_id
    return MapBodies(collision=collision_bodies, visual=visual_bodies, semantic=semantic)


def visual_body(client: int, path, color) -> int:
    """A static body drawn from the OBJ file ``path`` in ``color`` (RGBA), without
    collision.

    Raises:
        RuntimeError: pybullet could not load the file.
    """
    shape = p.createVisualShape(
        p.GEOM_MESH,
        fileName=str(path),
        rgbaColor=list(color),
        specularColor=[0.05, 0.05, 0.05],
        physicsClientId=client,
    )
    _check(shape, path)
    return p.createMultiBody(
        baseMass=0.0,
        baseCollisionShapeIndex=-1,
        baseVisualShapeIndex=shape,
        physicsClientId=client,
    )


def _check(shape: int, path) -> None:
    if shape < 0:
        raise RuntimeError(f"pybullet could not load the map mesh {path}")
