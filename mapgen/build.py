"""Build the map's files, cache them, and load them back.

A map folder::

    MAP/
      road.json                 geometry parameters, geo-reference, semantic classes,
                                parts, roadside objects, sources and their hashes
      scene.glb                 the whole scene for people (glTF 2.0, +Y up, metres)
      visual/<part>.obj         one mesh per part for the renderer (world frame, +Z up)
      collision/road.obj        the drivable pavement for the physics (concave)
      collision/obstacles.obj   median barrier and overpass for the physics (concave)
      tiles/<part>-<k>.obj      the visual parts cut into 100 m tiles along the road,
                                so the cameras skip what lies behind or beyond them
      vehicles/<class>.obj      a model per vehicle class for the cameras, unit box
                                (mapgen.vehicles), with its material and palette
      vehicles/<class>-lod<k>.obj  the same with fewer triangles, for distant vehicles

All meshes are in the world frame of :mod:`mapgen.road` (east-north-up metres); the
GLB alone turns it to glTF's +Y up. The folder is written whole (temporary name,
then rename). :func:`default_map` keeps one per input hash under the twin's cache,
so a second run does not rebuild.
"""

import hashlib
import importlib.metadata
import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from mapgen import sources as sources_module
from mapgen.params import MAP_TOML, MapParams, load_params
from mapgen.road import RoadModel
from mapgen.semantics import SEMANTIC_CSV, class_id, semantic_classes
from mapgen.vehicles import ModelLevel, write_vehicle_models
from twin.core import i24, ramps
from twin.core.atomic import AtomicFolder, marked_as
from twin.core.errors import MapError
from twin.core.locks import build_lock
from twin.core.paths import asset, cache_dir

if TYPE_CHECKING:  # trimesh (and scipy under it) is imported only to build a map: a
    import trimesh  # process that loads one (every twin run and worker) starts faster

    from mapgen.meshes import SceneMeshes

FORMAT = "i24-twin-map"
FORMAT_VERSION = 3  # 3: the on-ramps' acceleration lanes (road.json's ramps)
ROAD_JSON = "road.json"
VEHICLE_CSV = "vehicle_classes.csv"  # the vehicle models take the classes' mean sizes
SCENE_GLB = "scene.glb"
DEFAULT_SEED = 0
TILE_LENGTH = 100.0  # [m] along the road
SMOOTH_PARTS = ("terrain",)  # shaded with shared vertex normals; the rest is flat
CITATION = (
    "Gloudemans, D., Wang, Y., Ji, J., Zachar, G., Barbour, W., Hall, E., Cebelak, M., "
    "Smith, L. and Work, D.B., 2023. I-24 MOTION: An instrument for freeway traffic "
    "science. Transportation Research Part C: Emerging Technologies, 155, p.104311."
)
# glTF is +Y up: (east, north, up) -> (east, up, -north)
Z_UP_TO_Y_UP = np.array(
    [[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, -1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
)


@dataclass(frozen=True)
class MapPart:
    name: str
    semantic_class: str
    class_id: int
    color: tuple[float, float, float, float]
    visual: Path  # OBJ file
    triangles: int


@dataclass(frozen=True)
class MapTile:
    """A piece of a visual part: the faces whose centres lie in one tile of the road.

    Attributes:
        part: the part it belongs to (class and colour are the part's).
        visual: OBJ file (world frame).
        bounds: (2, 3) [m] its axis-aligned box in the world, min then max corner.
    """

    part: MapPart
    visual: Path
    bounds: np.ndarray


@dataclass(frozen=True, eq=False)
class MapBundle:
    """A built map folder, loaded.

    Attributes:
        folder: the map folder.
        road: the road model (transforms between road frame and world).
        parts: the visual parts, in a fixed order.
        collision: ``road`` and ``obstacles`` OBJ paths.
        vehicles: vehicle class name -> OBJ path of its model (unit box).
        vehicle_lods: vehicle class name -> its levels of detail, the full model
            first (:class:`mapgen.vehicles.ModelLevel`, ``file`` an absolute path);
            only the full model in maps built before levels of detail.
        tiles: the visual parts in tiles, for the cameras.
        description: the whole of ``road.json``.
    """

    folder: Path
    road: RoadModel
    parts: tuple[MapPart, ...]
    collision: dict[str, Path]
    vehicles: dict[str, Path]
    vehicle_lods: dict[str, tuple[ModelLevel, ...]]
    tiles: tuple[MapTile, ...]
    description: dict

    @property
    def key(self) -> str:
        return self.description["key"]


def map_key(seed: int = DEFAULT_SEED) -> str:
    """Hash of everything a map is made from: the mapgen code and the road frame's and
    on-ramps' (``twin/core/i24.py``, ``ramps.py``), the parameter and class tables, the
    I-24 sources, the trimesh version and the seed."""
    digest = hashlib.sha256()
    code = [*sorted(Path(__file__).parent.glob("*.py")), Path(i24.__file__), Path(ramps.__file__)]
    for path in code:
        digest.update(path.name.encode() + path.read_bytes())
    inputs = (asset(MAP_TOML), asset(SEMANTIC_CSV), asset(VEHICLE_CSV))
    for path in (*inputs, *sources_module.source_paths()):
        digest.update(path.name.encode() + path.read_bytes())
    digest.update(f"{FORMAT_VERSION}:{importlib.metadata.version('trimesh')}:{int(seed)}".encode())
    return digest.hexdigest()[:16]


def is_map(path: Path) -> bool:
    """True when ``path`` is a folder holding a map's ``road.json``."""
    return marked_as(path, ROAD_JSON, FORMAT)


def default_map(seed: int = DEFAULT_SEED, *, progress: bool = False) -> MapBundle:
    """The map for ``seed``, built on first use and cached under the twin's cache folder."""
    folder = cache_dir() / f"map-{map_key(seed)}"
    if not is_map(folder):
        with build_lock(folder):  # another process may be building it
            if not is_map(folder):
                if progress:
                    print(f"building the map (seed {seed}) into {folder}")
                return build_map(folder, seed=seed)
    return load_map(folder)


def build_map(out: Path, *, seed: int = DEFAULT_SEED) -> MapBundle:
    """Build the map into ``out`` (replacing a map there, never anything else).

    Raises:
        MapError: a source or parameter file is malformed, or ``out`` exists and is
            not a map folder.
        MapError: ``seed`` is negative.
    """
    if int(seed) != seed or seed < 0:
        raise MapError(f"seed must be a non-negative integer, got {seed!r}")
    params = load_params()
    sources = sources_module.load_sources()
    road = RoadModel.from_sources(sources, params)
    from mapgen.meshes import build_meshes

    meshes = build_meshes(road, params, sources, np.random.default_rng(int(seed)))
    tiles = _tiles(meshes, road)
    description = _describe(road, params, meshes, int(seed), tiles)
    with AtomicFolder(out, recognise=is_map, kind="map", error=MapError) as folder:
        (folder.tmp / "visual").mkdir()
        (folder.tmp / "collision").mkdir()
        (folder.tmp / "tiles").mkdir()
        for name, mesh in meshes.parts.items():
            _write_obj(_shaded(name, mesh), folder.tmp / "visual" / f"{name}.obj", normals=True)
        for entry, mesh in tiles:
            _write_obj(mesh, folder.tmp / entry["visual"], normals=True)
        for name, mesh in meshes.collision.items():
            _write_obj(mesh, folder.tmp / "collision" / f"{name}.obj", normals=False)
        levels = write_vehicle_models(folder.tmp / "vehicles")
        description["vehicle_lods"] = {
            name: [{**asdict(level), "file": f"vehicles/{level.file}"} for level in models]
            for name, models in levels.items()
        }
        (folder.tmp / SCENE_GLB).write_bytes(_glb(meshes, params, description))
        (folder.tmp / ROAD_JSON).write_text(json.dumps(description, indent=1) + "\n")
    return load_map(out)


def load_map(folder: Path) -> MapBundle:
    """Load a built map folder.

    Raises:
        MapError: the folder is not a map, is of another format version, or lacks a file.
    """
    folder = Path(folder)
    if not is_map(folder):
        raise MapError(
            f"{folder} is not an i24-twin map folder (no {ROAD_JSON}); build one "
            "with `twin map build --out DIR`"
        )
    description = json.loads((folder / ROAD_JSON).read_text())
    if description.get("version") != FORMAT_VERSION:
        raise MapError(
            f"{folder}: map format version {description.get('version')}, this twin reads "
            f"{FORMAT_VERSION}; rebuild it with `twin map build`"
        )
    parts = tuple(
        MapPart(
            name=p["name"],
            semantic_class=p["semantic_class"],
            class_id=p["class_id"],
            color=tuple(p["color"]),
            visual=folder / p["visual"],
            triangles=p["triangles"],
        )
        for p in description["parts"]
    )
    collision = {name: folder / path for name, path in description["collision"].items()}
    vehicles = {name: folder / path for name, path in description["vehicles"].items()}
    vehicle_lods = {
        name: tuple(
            ModelLevel(
                file=str(folder / level["file"]),
                triangles=int(level["triangles"]),
                error_m=float(level["error_m"]),
                size_m=tuple(level["size_m"]),
            )
            for level in description.get("vehicle_lods", {}).get(name, [])
        )
        or (ModelLevel(file=str(path), triangles=0, error_m=0.0, size_m=(1.0, 1.0, 1.0)),)
        for name, path in vehicles.items()
    }
    by_name = {part.name: part for part in parts}
    tiles = tuple(
        MapTile(part=by_name[t["part"]], visual=folder / t["visual"], bounds=np.array(t["bounds"]))
        for t in description["tiles"]
    )
    files = [p.visual for p in parts] + [*collision.values(), *vehicles.values()]
    files += [Path(level.file) for levels in vehicle_lods.values() for level in levels]
    files += [t.visual for t in tiles]
    for path in [*files, folder / SCENE_GLB]:
        if not path.is_file():
            raise MapError(f"map {folder} lacks {path.relative_to(folder)}; rebuild it")
    return MapBundle(
        folder=folder,
        road=RoadModel.from_dict(description["road"]),
        parts=parts,
        collision=collision,
        vehicles=vehicles,
        vehicle_lods=vehicle_lods,
        tiles=tiles,
        description=description,
    )


def _tiles(meshes: "SceneMeshes", road: RoadModel) -> "list[tuple[dict, trimesh.Trimesh]]":
    """Each visual part cut by face centre into TILE_LENGTH tiles of road station, as
    (description entry, shaded mesh) pairs in part then station order."""
    tiles = []
    for name, mesh in meshes.parts.items():
        shaded = _shaded(name, mesh)
        station = shaded.triangles_center[:, :2] @ road.direction_vector[:2]
        index = np.floor(station / TILE_LENGTH).astype(np.int64)
        for k in np.unique(index):
            piece = shaded.submesh([np.flatnonzero(index == k)], append=True, repair=False)
            entry = {
                "part": name,
                "visual": f"tiles/{name}-{int(k) - int(index.min()):03d}.obj",
                "bounds": np.round(piece.bounds, 3).tolist(),
            }
            tiles.append((entry, piece))
    return tiles


def _describe(
    road: RoadModel, params: MapParams, meshes: "SceneMeshes", seed: int, tiles: list
) -> dict:
    lane_width = i24.LANE_WIDTH
    return {
        "format": FORMAT,
        "version": FORMAT_VERSION,
        "key": map_key(seed),
        "seed": seed,
        "frame": (
            "world: east-north-up metres, origin on the median centre line at MM 60.6, "
            "z = 0 at the road there; eastbound station s = (MM - 60.6) * 1609.344 m "
            "along the bearing; road frame per carriageway as in docs/design.md"
        ),
        "road": road.to_dict(),
        "cross_section": {
            "lane_width_m": lane_width,
            "lanes": list(i24.LANES),
            "hov_lane": i24.HOV_LANE,
            "lane_y_m": {str(k): [-k * lane_width, (-k + 1) * lane_width] for k in i24.LANES},
            "yellow_edge_line_y_m": lane_width,
            "white_edge_line_y_m": (i24.N_LANES + 1) * lane_width,
            "hov_double_line_y_m": 2 * lane_width,
            "broken_lines_y_m": [k * lane_width for k in range(3, i24.N_LANES + 1)],
            "outer_shoulder_m": params.cross_section.outer_shoulder,
            "outer_edge_y_m": road.outer_edge,
            # beside an on-ramp's acceleration lane (road.ramps) the white edge line and
            # the outer edge lie further out by its width (RoadModel.outer_edge_at)
            "ramp_lane": {
                "lane": -5,
                "y_m": [(i24.N_LANES + 1) * lane_width, (i24.N_LANES + 2) * lane_width],
                "where": f"road.ramps: an opening of {ramps.OPENING} m before x_start_m, "
                f"full width to a taper of {ramps.TAPER} m that ends at x_end_m",
            },
            "barrier_profile": {
                "y_m": list(params.barrier.profile_y),
                "z_m": list(params.barrier.profile_z),
            },
            "markings": params.markings.__dict__,
            "cross_slope": 0.0,
        },
        "semantic_classes": [
            {"id": c.class_id, "name": c.name, "color": list(c.color)} for c in semantic_classes()
        ],
        "parts": [
            {
                "name": name,
                "semantic_class": params.parts[name].semantic_class,
                "class_id": class_id(params.parts[name].semantic_class),
                "color": list(params.parts[name].color),
                "visual": f"visual/{name}.obj",
                "triangles": len(mesh.faces),
            }
            for name, mesh in meshes.parts.items()
        ],
        "collision": {name: f"collision/{name}.obj" for name in meshes.collision},
        "vehicles": {name: f"vehicles/{name}.obj" for name in i24.VEHICLE_CLASSES},
        "tiles": [entry for entry, _ in tiles],
        "triangles": {
            "visual": sum(len(m.faces) for m in meshes.parts.values()),
            "collision": sum(len(m.faces) for m in meshes.collision.values()),
        },
        "objects": meshes.objects,
        "sources": {
            "files": {
                path.name: hashlib.sha256(path.read_bytes()).hexdigest()
                for path in (*sources_module.source_paths(), asset(MAP_TOML), asset(SEMANTIC_CSV))
            },
            "citation": CITATION,
        },
    }


def _shaded(name: str, mesh: "trimesh.Trimesh") -> "trimesh.Trimesh":
    """Flat parts get a vertex per face corner, so their normals are the face normals."""
    if name in SMOOTH_PARTS:
        return mesh
    flat = mesh.copy()
    flat.unmerge_vertices()
    return flat


def _write_obj(mesh: "trimesh.Trimesh", path: Path, *, normals: bool) -> None:
    import trimesh

    path.write_text(
        trimesh.exchange.obj.export_obj(
            mesh, include_normals=normals, include_color=False, include_texture=False, digits=6
        )
    )


def _glb(meshes: "SceneMeshes", params: MapParams, description: dict) -> bytes:
    import trimesh
    from trimesh.visual.material import PBRMaterial

    scene = trimesh.Scene()
    for name, mesh in meshes.parts.items():
        part = params.parts[name]
        shaded = _shaded(name, mesh).copy()
        shaded.apply_transform(Z_UP_TO_Y_UP)
        shaded.visual = trimesh.visual.TextureVisuals(
            material=PBRMaterial(
                name=name,
                baseColorFactor=list(part.color),
                metallicFactor=0.0,
                roughnessFactor=0.9,
            )
        )
        shaded.metadata = {
            "semantic_class": part.semantic_class,
            "class_id": class_id(part.semantic_class),
        }
        scene.add_geometry(shaded, node_name=name, geom_name=name)
    scene.metadata = {
        "i24_twin_map_key": description["key"],
        "seed": description["seed"],
        "frame": "glTF +Y up; +X east, -Z north; origin on the median centre line at MM 60.6",
        "citation": CITATION,
    }
    return scene.export(file_type="glb", include_normals=True)
