"""The segment's meshes, built with trimesh in world coordinates.

Every part is a plain triangle mesh with outward (or upward) faces: the pavement
(lanes, the on-ramps' acceleration lanes and shoulders), the lane markings, the median
barrier, the terrain, the camera poles, the 0.1-mile posts and the Old Franklin Rd
overpass. Pavement-bound meshes (pavement, markings, barrier, terrain edge) put a
vertex at every profile point of the road, so they follow the elevation profile exactly
rather than as a chord, and at every point where an acceleration lane's width changes
slope, so that its opening and taper are exact. Where an acceleration lane runs, the
shoulder, the edge line and the terrain lie beyond it.
"""

import math
from dataclasses import dataclass

import numpy as np
import trimesh

from mapgen.params import MapParams, Terrain
from mapgen.road import RoadModel, mile_marker_of, station_of
from mapgen.sources import Sources
from twin.core.i24 import LANE_WIDTH, N_LANES, Road, lane_center

INNER_EDGE = LANE_WIDTH  # [m] the yellow line: 12 ft from the median centre line
LANES_OUTER_EDGE = (N_LANES + 1) * LANE_WIDTH  # [m] the white edge line
FACE_OFFSET = 0.05  # [m] between faces of touching solids that would otherwise be coplanar


@dataclass(frozen=True, eq=False)
class SceneMeshes:
    """What :func:`build_meshes` makes.

    Attributes:
        parts: part name -> visual mesh (names and classes as in ``map.toml``).
        collision: ``road`` (the drivable pavement, both carriageways and the median)
            and ``obstacles`` (barrier and overpass) for the physics.
        objects: JSON-ready positions of the poles, posts and overpass.
    """

    parts: dict[str, trimesh.Trimesh]
    collision: dict[str, trimesh.Trimesh]
    objects: dict


def build_meshes(
    model: RoadModel, params: MapParams, sources: Sources, rng: np.random.Generator
) -> SceneMeshes:
    """Build every part of the scene; ``rng`` shapes the terrain and nothing else."""
    knots = _stations(model)
    terrain, terrain_height = _terrain(model, params.terrain, rng)
    poles, pole_objects = _poles(model, params, sources, terrain_height)
    posts, post_objects = _posts(model, params, terrain_height)
    overpass, overpass_object = _overpass(model, params, sources)
    barrier = _barrier(model, params)
    shoulder = params.cross_section.outer_shoulder
    road, shoulders = [], [_strip(model, knots, -INNER_EDGE, INNER_EDGE, 0.0)]
    for side in (1.0, -1.0):
        lanes_edge = LANES_OUTER_EDGE + _ramp_width(model, side, knots)
        road.append(_side_strip(model, knots, side, INNER_EDGE, LANES_OUTER_EDGE))
        road += _ramp_strips(model, side)
        shoulders.append(_side_strip(model, knots, side, lanes_edge, lanes_edge + shoulder))
    parts = {
        "road": _concatenate(road),
        "shoulder": _concatenate(shoulders),
        **_markings(model, params),
        "barrier": barrier,
        "terrain": terrain,
        "pole": poles,
        "post": posts,
        "overpass": overpass,
    }
    unknown = set(parts) ^ set(params.parts)
    if unknown:
        raise ValueError(f"map.toml [parts] and the built parts differ: {sorted(unknown)}")
    inner = -LANE_WIDTH * np.arange(N_LANES + 1, 0, -1)
    eastbound, westbound = (_outer_edge(model, side, knots) for side in (1.0, -1.0))
    laterals = np.concatenate(
        [
            -westbound[:, None],
            np.broadcast_to(np.concatenate([inner, [0.0], -inner[::-1]]), (knots.size, 11)),
            eastbound[:, None],
        ],
        axis=1,
    )
    collision = {
        "road": _grid(
            model, knots, laterals, np.repeat(model.surface_z(knots)[:, None], laterals.shape[1], 1)
        ),
        "obstacles": _concatenate([barrier, overpass]),
    }
    objects = {"poles": pole_objects, "posts": post_objects, "overpass": overpass_object}
    return SceneMeshes(parts=parts, collision=collision, objects=objects)


# -- pavement and markings ------------------------------------------------------------


def _stations(model: RoadModel) -> np.ndarray:
    """(n,) [m] the stations pavement-bound meshes put vertices at: the profile's points
    and the acceleration lanes' breakpoints (but where one lies within a millimetre of a
    profile point, which is kept: no sliver between them)."""
    knots, extra = model.profile_s, model.ramp_stations()
    near = np.abs(extra[:, None] - knots[None, :]).min(axis=1, initial=np.inf) < 1e-3
    return np.union1d(knots, extra[~near])


def _road_x(model: RoadModel, side: float, stations: np.ndarray) -> tuple[Road, np.ndarray]:
    """The carriageway on ``side`` (+1 eastbound, to the right of the reference line)
    and the road-frame x of eastbound ``stations`` on it."""
    road = Road.EASTBOUND if side > 0 else Road.WESTBOUND
    return road, model.station(road, stations)  # its own inverse


def _ramp_width(model: RoadModel, side: float, stations: np.ndarray) -> np.ndarray:
    """(n,) [m] the acceleration lane's width at ``stations`` on ``side``."""
    return model.ramp_width(*_road_x(model, side, stations))


def _outer_edge(model: RoadModel, side: float, stations: np.ndarray) -> np.ndarray:
    """(n,) [m] |lateral| of the paved shoulder's outer edge at ``stations`` on ``side``."""
    return model.outer_edge_at(*_road_x(model, side, stations))


def _side_strip(model, stations: np.ndarray, side: float, lo, hi, lift: float = 0.0):
    """A band between |laterals| ``lo`` < ``hi`` (scalars or (n,) per station) on ``side``."""
    lo, hi = (np.broadcast_to(np.asarray(v, dtype=np.float64), stations.shape) for v in (lo, hi))
    bounds = np.stack([lo, hi], axis=-1) * side
    return _strip(model, stations, np.sort(bounds, axis=-1), None, lift)


def _ramp_strips(model: RoadModel, side: float) -> list[trimesh.Trimesh]:
    """The acceleration lanes' pavement on ``side``, from their opening to their end."""
    road, _ = _road_x(model, side, np.zeros(1))
    strips = []
    for ramp in model.ramps:
        if ramp.road is not road:
            continue
        ends = np.sort(model.station(road, ramp.breakpoints[[0, -1]]))
        s0, s1 = model.station_range
        lo, hi = max(ends[0], s0), min(ends[1], s1)
        if hi <= lo:
            continue
        knots = _stations(model)  # its ends among them, or within a millimetre
        stations = knots[(knots >= lo - 1e-3) & (knots <= hi + 1e-3)]
        width = _ramp_width(model, side, stations)
        strip = _side_strip(model, stations, side, LANES_OUTER_EDGE, LANES_OUTER_EDGE + width)
        strips.append(_without_slivers(strip))
    return strips


def _without_slivers(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """``mesh`` without its zero-area faces (where a lane's width comes to nothing)."""
    tri = mesh.vertices[mesh.faces]
    area = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    return trimesh.Trimesh(vertices=mesh.vertices, faces=mesh.faces[area > 1e-9], process=False)


def _grid(model: RoadModel, stations: np.ndarray, laterals: np.ndarray, z: np.ndarray):
    """Upward-facing grid mesh over (stations (n,), laterals (m,) increasing), heights (n, m).

    ``stations`` may be (b, n) and ``z`` (b, n, m) for b separate grids in one mesh;
    ``laterals`` may be given per station, (n, m) or (b, n, m).
    """
    stations = np.atleast_2d(stations)
    m = laterals.shape[-1]
    laterals = np.broadcast_to(laterals, (*stations.shape, m))
    z = z.reshape((*stations.shape, m))
    b, n = stations.shape
    xy = (
        stations[..., None, None] * model.direction_vector
        + laterals[..., None] * model.right_vector
    )
    vertices = np.concatenate([xy, z[..., None]], axis=-1).reshape(-1, 3)
    index = np.arange(b * n * m).reshape(b, n, m)
    a, side, ahead, corner = (
        index[:, :-1, :-1],
        index[:, :-1, 1:],
        index[:, 1:, :-1],
        index[:, 1:, 1:],
    )
    # (r, d, up) is right-handed, so (a, side, ahead) faces up.
    faces = np.concatenate(
        [
            np.stack([a, side, ahead], -1).reshape(-1, 3),
            np.stack([side, corner, ahead], -1).reshape(-1, 3),
        ]
    )
    return trimesh.Trimesh(vertices=vertices, faces=faces, process=False)


def _strip(model: RoadModel, stations: np.ndarray, lo, hi, lift: float):
    """A band of pavement (or a marking lifted by ``lift``) between laterals lo < hi;
    with ``hi`` None, ``lo`` holds both per station, (n, 2)."""
    stations = np.atleast_2d(stations)
    laterals = np.array([lo, hi]) if hi is not None else np.asarray(lo)
    z = model.surface_z(stations)[..., None] + lift
    return _grid(model, stations, laterals, np.repeat(z, 2, axis=-1))


def _markings(model: RoadModel, params: MapParams) -> dict[str, trimesh.Trimesh]:
    """US freeway markings: yellow inner edge, white outer edge (beyond an acceleration
    lane where there is one), a solid double white line closing the HOV lane, broken
    white lines between the other lanes and between lane -4 and an acceleration lane
    (from its gore to its end; lane -4's solid edge line goes on along its opening),
    HOV diamonds."""
    m = params.markings
    knots = _stations(model)
    half = m.width / 2.0
    yellow, white = [], []
    dashes = _dash_stations(knots, m.dash, m.gap)
    for side in (1.0, -1.0):

        def line(center, stations: np.ndarray = knots, side: float = side):
            return _side_strip(model, stations, side, center - half, center + half, m.lift)

        yellow.append(line(INNER_EDGE))
        white.append(line(LANES_OUTER_EDGE + _ramp_width(model, side, knots)))
        hov_edge = 2.0 * LANE_WIDTH
        offset = (m.double_gap + m.width) / 2.0
        white += [line(hov_edge - offset), line(hov_edge + offset)]
        white += [line(k * LANE_WIDTH, dashes) for k in range(3, N_LANES + 1)]
        road, _ = _road_x(model, side, knots)
        for ramp in model.ramps:
            if ramp.road is road:
                lo, hi = np.sort(model.station(road, np.array([ramp.x_start, ramp.x_end])))
                beside = dashes[(dashes[:, 0] >= lo) & (dashes[:, -1] <= hi)]
                if beside.size:
                    white.append(line(LANES_OUTER_EDGE, beside))
                # lane -4's edge line goes on along the opening, up to the gore
                ends = model.station(road, ramp.breakpoints[:2])
                a, b = max(ends.min(), knots[0]), min(ends.max(), knots[-1])
                if b > a:  # its ends are among the knots (or within a millimetre)
                    white.append(
                        line(LANES_OUTER_EDGE, knots[(knots >= a - 1e-3) & (knots <= b + 1e-3)])
                    )
        white.append(_diamonds(model, m, side * float(lane_center(-1))))
    return {"marking_white": _concatenate(white), "marking_yellow": _concatenate(yellow)}


def _dash_stations(knots: np.ndarray, dash: float, gap: float) -> np.ndarray:
    """(k, 3) stations of each dash: its ends and, between them, the profile point it
    spans (or its middle), so that it lies on the pavement across a grade change."""
    period = dash + gap
    starts = knots[0] + period * np.arange(math.floor((knots[-1] - knots[0] - dash) / period) + 1)
    ends = starts + dash
    inside = np.searchsorted(knots, starts, side="right")  # the first point past its start
    knot = knots[np.clip(inside, 0, knots.size - 1)]
    middle = np.where((knot > starts) & (knot < ends), knot, (starts + ends) / 2.0)
    return np.stack([starts, middle, ends], axis=1)


def _diamonds(model: RoadModel, m, center: float) -> trimesh.Trimesh:
    """Outlined HOV diamonds centred on lateral ``center``, each between two profile points."""
    knots = model.profile_s
    s = (knots[:-1] + knots[1:])[m.diamond_every // 2 :: m.diamond_every] / 2.0
    a, b = m.diamond_length / 2.0, m.diamond_width / 2.0
    hyp = math.hypot(a, b)
    a_in, b_in = a - m.width * hyp / b, b - m.width * hyp / a
    # outer and inner rings: ahead, right, behind, left
    ring = np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0]])
    outer = ring * [a, b]
    inner = ring * [a_in, b_in]
    local = np.concatenate([outer, inner])  # (8, 2) (ds, dl)
    stations = s[:, None] + local[None, :, 0]
    laterals = center + np.broadcast_to(local[:, 1], stations.shape)
    vertices = np.empty((*stations.shape, 3))
    vertices[..., :2] = (
        stations[..., None] * model.direction_vector + laterals[..., None] * model.right_vector
    )
    vertices[..., 2] = model.surface_z(stations) + m.lift
    quad = [[k, (k + 1) % 4, 4 + (k + 1) % 4, 4 + k] for k in range(4)]
    faces = np.array([[q[0], q[1], q[2]] for q in quad] + [[q[0], q[2], q[3]] for q in quad])
    faces = (faces[None] + 8 * np.arange(len(s))[:, None, None]).reshape(-1, 3)
    return _upward(trimesh.Trimesh(vertices=vertices.reshape(-1, 3), faces=faces, process=False))


def _upward(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """Flip the faces of a flat mesh whose normals point down."""
    tri = mesh.vertices[mesh.faces]
    up = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])[:, 2]
    faces = mesh.faces.copy()
    faces[up < 0] = faces[up < 0][:, ::-1]
    return trimesh.Trimesh(vertices=mesh.vertices, faces=faces, process=False)


# -- solids ---------------------------------------------------------------------------


def _barrier(model: RoadModel, params: MapParams) -> trimesh.Trimesh:
    """The concrete median barrier: its profile lofted along the profile points."""
    y = np.asarray(params.barrier.profile_y)
    z = np.asarray(params.barrier.profile_z)
    # closed outline from the top of one face down and back up the other face
    right = np.stack([y[1:], z[1:]], axis=1)
    left = right[::-1] * [-1.0, 1.0]
    outline = np.concatenate([right, left])
    return _loft(model, model.profile_s, outline)


def _loft(model: RoadModel, stations: np.ndarray, outline: np.ndarray) -> trimesh.Trimesh:
    """Closed solid sweeping a convex (lateral, height) outline along ``stations``."""
    n, m = stations.size, len(outline)
    xy = (
        stations[:, None, None] * model.direction_vector
        + outline[None, :, 0, None] * model.right_vector
    )
    z = model.surface_z(stations)[:, None] + outline[None, :, 1]
    vertices = np.concatenate([xy, z[..., None]], axis=-1).reshape(-1, 3)
    index = np.arange(n * m).reshape(n, m)
    a = index[:-1]
    b = np.roll(index, -1, axis=1)[:-1]
    sides = np.concatenate(
        [np.stack([a, b, a + m], -1).reshape(-1, 3), np.stack([b, b + m, a + m], -1).reshape(-1, 3)]
    )
    fan = np.array([[0, k, k + 1] for k in range(1, m - 1)])
    caps = np.concatenate([fan[:, ::-1], fan + (n - 1) * m])
    mesh = trimesh.Trimesh(vertices=vertices, faces=np.concatenate([sides, caps]), process=False)
    if mesh.volume < 0:
        mesh.invert()
    return mesh


def _frame(model: RoadModel, station: float, lateral: float, z: float) -> np.ndarray:
    """4x4 transform: local x along the lateral, y along the station, z up."""
    d, r = model.direction_vector, model.right_vector
    origin = station * d + lateral * r
    return np.array(
        [
            [r[0], d[0], 0.0, origin[0]],
            [r[1], d[1], 0.0, origin[1]],
            [0.0, 0.0, 1.0, z],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def _box(model, station, lateral, z0, z1, length, width) -> trimesh.Trimesh:
    """Box aligned with the road: ``length`` along the station, ``width`` across."""
    frame = _frame(model, station, lateral, (z0 + z1) / 2.0)
    return trimesh.creation.box(extents=(width, length, z1 - z0), transform=frame)


def _poles(model, params, sources, terrain_height):
    """The I-24 MOTION camera poles within the map: tapered masts with a camera head."""
    p = params.poles
    s0, s1 = model.station_range
    inside = []
    for pole_id, lat, lon in zip(sources.pole_id, sources.pole_lat, sources.pole_lon, strict=True):
        try:
            point = model.from_geodetic(lat, lon)[0]
        except ValueError:
            continue  # beyond the posts, so far outside the map
        station = float(point[:2] @ model.direction_vector)
        if s0 + p.base_radius <= station <= s1 - p.base_radius:
            inside.append(
                (
                    int(pole_id),
                    float(lat),
                    float(lon),
                    station,
                    float(point[:2] @ model.right_vector),
                )
            )
    meshes, objects = [], []
    mast = trimesh.creation.revolve(
        [[0.0, 0.0], [p.base_radius, 0.0], [p.top_radius, p.height], [0.0, p.height]], sections=8
    )
    for pole_id, lat, lon, station, lateral in sorted(inside):
        side = math.copysign(1.0, lateral)
        minimum = float(_outer_edge(model, side, np.array([station]))[0]) + p.min_offset
        placed = math.copysign(max(abs(lateral), minimum), lateral)
        base = terrain_height(station, placed) - 1.0
        frame = _frame(model, station, placed, base)
        head = _box(
            model,
            station,
            placed,
            base + p.height,
            base + p.height + p.head[2],
            p.head[1],
            p.head[0],
        )
        meshes += [mast.copy().apply_transform(frame), head]
        mm = float(mile_marker_of(station))
        objects.append(
            {
                "pole": pole_id,
                "lat_deg": lat,
                "lon_deg": lon,
                "mm": round(mm, 4),
                "station_m": station,
                "lateral_m": placed,
                "moved_m": abs(placed - lateral),
                "height_m": p.height,
            }
        )
    return _concatenate(meshes), objects


def _posts(model, params, terrain_height):
    """Green 0.1-mile demarcation posts beside both carriageways, plates facing traffic."""
    p = params.posts
    s0, s1 = model.station_range
    first = math.ceil(round(float(mile_marker_of(s0)) / p.spacing_mi, 6))
    last = math.floor(round(float(mile_marker_of(s1)) / p.spacing_mi, 6))
    meshes, objects = [], []
    for k in range(first, last + 1):
        mm = round(k * p.spacing_mi, 6)
        station = float(station_of(mm))
        for side, road in ((1.0, "eastbound"), (-1.0, "westbound")):
            lateral = float(_outer_edge(model, side, np.array([station]))[0]) + p.offset
            base = terrain_height(station, side * lateral) - 0.5
            top = model.surface_z(station) + p.height
            meshes.append(_box(model, station, side * lateral, base, top, p.size, p.size))
            plate_station = station - side * (p.size / 2 + 0.015)
            meshes.append(
                _box(model, plate_station, side * lateral, top - p.plate[1], top, 0.03, p.plate[0])
            )
            objects.append(
                {"mm": mm, "road": road, "station_m": station, "lateral_m": side * lateral}
            )
    return _concatenate(meshes), objects


def _overpass(model, params, sources):
    """Old Franklin Rd: a deck square to the interstate with parapets, three bents
    (median and both outer sides) and two abutments, at the landmarks' mile markers."""
    o = params.overpass
    stations = []
    for name in o.landmarks:
        if name not in sources.landmarks:
            raise ValueError(f"landmark {name!r} not in {sorted(sources.landmarks)}")
        stations.append(float(station_of(sources.landmarks[name][1])))
    center = float(np.mean(stations))
    half = o.deck_width / 2.0
    below = np.concatenate([[center - half, center + half], model.profile_s])
    below = below[(below >= center - half) & (below <= center + half)]
    bottom = float(model.surface_z(below).max()) + o.clearance
    top = bottom + o.deck_depth
    # The deck ends on the abutments' centre lines; parapets and abutments stand a few
    # centimetres off the deck's faces, so that no two faces are coplanar (depth fighting).
    deck = np.array([center - half, center + half])
    edge = max(float(_outer_edge(model, side, deck).max()) for side in (1.0, -1.0))
    reach = edge + o.abutment_offset
    road_z = float(model.surface_z(center))
    parts = [_box(model, center, 0.0, bottom, top, o.deck_width, 2.0 * reach)]
    inset = half - o.parapet_width / 2 - FACE_OFFSET
    for s in (center - inset, center + inset):
        parts.append(
            _box(model, s, 0.0, top, top + o.parapet_height, o.parapet_width, 2.0 * reach - 0.1)
        )
    columns = center + o.pier_spacing * np.array([-1.0, 0.0, 1.0])
    for s in columns:
        parts.append(
            _box(
                model,
                s,
                0.0,
                float(model.surface_z(s)),
                bottom,
                o.median_pier_size,
                o.median_pier_size,
            )
        )
        for side in (1.0, -1.0):
            lateral = side * (edge + o.outer_pier_offset + o.pier_size / 2)
            parts.append(_box(model, s, lateral, road_z - 1.5, bottom, o.pier_size, o.pier_size))
    for side in (1.0, -1.0):
        lateral = side * (edge + o.abutment_offset)
        parts.append(
            _box(
                model,
                center,
                lateral,
                road_z - o.abutment_depth,
                top - 0.2,
                o.deck_width + 1.0,
                1.5,
            )
        )
    description = {
        "name": "Old Franklin Rd overpass",
        "landmarks": list(o.landmarks),
        "station_m": center,
        "mm": round(float(mile_marker_of(center)), 4),
        "deck_stations_m": [center - half, center + half],
        "deck_bottom_z_m": bottom,
        "clearance_m": bottom - float(model.surface_z(below).max()),
    }
    return _concatenate(parts), description


# -- terrain --------------------------------------------------------------------------


def _terrain(model: RoadModel, t: Terrain, rng: np.random.Generator):
    """Ground on both sides beyond the shoulders: a drainage ditch, then seeded relief.

    Returns the mesh and a function (station, lateral) -> the lowest terrain height
    of the grid cell there (to plant poles and posts without leaving them floating).
    """
    base = model.outer_edge
    s0, s1 = model.station_range
    lattices = _noise_lattices(rng, t, (s0, s1), base + LANE_WIDTH + t.width)
    columns = np.asarray(t.columns)
    stations = _stations(model)
    edges = {side: _outer_edge(model, side, stations) for side in (1.0, -1.0)}

    def height(station, lateral, edge):
        offset = np.abs(lateral) - edge
        ramp = _smoothstep(np.clip((offset - t.ditch_offset[-1]) / t.relief_ramp, 0.0, 1.0))
        ditch = np.interp(offset, t.ditch_offset, t.ditch_depth)
        relief = (
            t.relief
            * ramp
            * _noise(lattices, t, station - s0, lateral + base + LANE_WIDTH + t.width)
        )
        return model.surface_z(station) + ditch + relief

    meshes, grids = [], {}
    for side in (1.0, -1.0):
        edge = edges[side][:, None]
        laterals = side * (edge + (columns if side > 0 else columns[::-1]))
        z = height(stations[:, None], laterals, edge)
        meshes.append(_grid(model, stations, laterals, z))
        grids[side] = (laterals, z)

    def lowest(station: float, lateral: float) -> float:
        laterals, z = grids[1.0 if lateral >= 0 else -1.0]
        i = int(np.clip(np.searchsorted(stations, station) - 1, 0, stations.size - 2))
        row = laterals[i : i + 2].min(axis=0) if lateral >= 0 else laterals[i : i + 2].max(axis=0)
        j = int(np.clip(np.searchsorted(row, lateral) - 1, 0, row.size - 2))
        return float(z[i : i + 2, j : j + 2].min())

    return _concatenate(meshes), lowest


def _noise_lattices(rng, t: Terrain, stations: tuple[float, float], half_width: float):
    lattices = []
    for octave in range(t.octaves):
        cell = t.wavelength / 2**octave
        shape = (
            math.ceil((stations[1] - stations[0]) / cell) + 2,
            math.ceil(2.0 * half_width / cell) + 2,
        )
        lattices.append(rng.standard_normal(shape))
    return lattices


def _noise(lattices, t: Terrain, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Fractal value noise of about unit spread at (u, v) >= 0 metres from the lattice corner."""
    total, norm = 0.0, 0.0
    for octave, lattice in enumerate(lattices):
        cell = t.wavelength / 2**octave
        x, y = np.asarray(u) / cell, np.asarray(v) / cell
        i = np.clip(np.floor(x).astype(int), 0, lattice.shape[0] - 2)
        j = np.clip(np.floor(y).astype(int), 0, lattice.shape[1] - 2)
        fx, fy = _smoothstep(x - i), _smoothstep(y - j)
        near = lattice[i, j] * (1 - fx) + lattice[i + 1, j] * fx
        far = lattice[i, j + 1] * (1 - fx) + lattice[i + 1, j + 1] * fx
        amplitude = 0.5**octave
        total = total + amplitude * (near * (1 - fy) + far * fy)
        norm += amplitude**2
    return total / math.sqrt(norm)


def _smoothstep(x: np.ndarray) -> np.ndarray:
    return x * x * (3.0 - 2.0 * x)


def _concatenate(meshes: list[trimesh.Trimesh]) -> trimesh.Trimesh:
    vertices, faces, offset = [], [], 0
    for mesh in meshes:
        vertices.append(np.asarray(mesh.vertices))
        faces.append(np.asarray(mesh.faces) + offset)
        offset += len(mesh.vertices)
    return trimesh.Trimesh(
        vertices=np.concatenate(vertices), faces=np.concatenate(faces), process=False
    )
