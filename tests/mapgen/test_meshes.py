"""The built meshes against the sources, measured with pybullet ray tests (an independent
engine) and with trimesh's own mesh analysis."""

import numpy as np
import pybullet as p
import pytest
import trimesh

from tests.mapgen import oracles
from twin.core import i24, ramps

CONCAVE = p.GEOM_FORCE_CONCAVE_TRIMESH | p.GEOM_CONCAVE_INTERNAL_EDGE


class RayWorld:
    """A pybullet client holding OBJ files as static concave meshes, for ray tests."""

    def __init__(self, paths):
        self.client = p.connect(p.DIRECT)
        self.bodies = {}
        for name, path in paths.items():
            shape = p.createCollisionShape(
                p.GEOM_MESH, fileName=str(path), flags=CONCAVE, physicsClientId=self.client
            )
            self.bodies[name] = p.createMultiBody(0, shape, physicsClientId=self.client)

    def cast(self, xy, z_from, z_to):
        """(n,) hit heights (NaN where nothing is hit) and hit body names of vertical rays."""
        xy = np.atleast_2d(xy)
        starts = np.column_stack([xy, np.full(len(xy), z_from)])
        ends = np.column_stack([xy, np.full(len(xy), z_to)])
        heights, names = np.full(len(xy), np.nan), []
        by_id = {v: k for k, v in self.bodies.items()}
        for first in range(0, len(xy), 4000):
            hits = p.rayTestBatch(
                starts[first : first + 4000].tolist(),
                ends[first : first + 4000].tolist(),
                physicsClientId=self.client,
            )
            for i, hit in enumerate(hits, start=first):
                names.append(by_id.get(hit[0]))
                if hit[0] >= 0:
                    heights[i] = hit[3][2]
        return heights, names

    def close(self):
        p.disconnect(self.client)


@pytest.fixture(scope="module")
def parts(built_map):
    return {part.name: part for part in built_map.parts}


@pytest.fixture(scope="module")
def meshes(parts):
    return {name: trimesh.load(part.visual, process=False) for name, part in parts.items()}


def _xy(road, name, x, y):
    return road.to_world(name, x, y)[0][:, :2]


def test_pavement_height_at_lane_centres_equals_the_grade_table(built_map, parts):
    road = built_map.road
    x = np.arange(-400.0, 2009.0, 7.3)
    for layer in (built_map.collision["road"], parts["road"].visual):
        world = RayWorld({"road": layer})
        try:
            for name in ("eastbound", "westbound"):
                expected = oracles.profile_height(i24.mile_marker(x, i24.Road.parse(name)))
                for lane in i24.LANES:
                    xy = _xy(road, name, x, np.full(x.size, float(i24.lane_center(lane))))
                    heights, _ = world.cast(xy, 60.0, -60.0)
                    assert np.abs(heights - expected).max() < 0.02, (layer.name, name, lane)
        finally:
            world.close()


def test_collision_mesh_loads_as_a_concave_mesh_not_a_hull(built_map):
    road = built_map.road
    world = RayWorld(dict(built_map.collision))
    try:
        x = np.array([200.0, 800.0, 1400.0])
        xy = _xy(road, "eastbound", x, np.full(3, float(i24.lane_center(-2))))
        surface = road.surface_z(x)
        # from below: a hull's underside is the chord of the crests, metres lower
        up, names = world.cast(xy, -80.0, 80.0)
        np.testing.assert_allclose(up, surface, atol=0.01)
        assert names == ["road"] * 3
        # from above, away from the overpass: nothing of the obstacles' hull is hit
        down, names = world.cast(xy, 80.0, -80.0)
        np.testing.assert_allclose(down, surface, atol=0.01)
        assert names == ["road"] * 3
    finally:
        world.close()


def test_lane_lines_are_one_lane_width_apart(built_map, meshes):
    coords = built_map.road.to_road(meshes["marking_white"].vertices)
    clear = (coords.x > 300.0) & (coords.x < 1300.0)  # beyond the acceleration lanes
    for direction in (1, -1):
        y = np.round(coords.y[(coords.road == direction) & clear], 4)
        edges = np.unique(y[y > 6.5])  # lines only: the HOV diamonds lie within lane -1
        # each line is a band of two edges; the HOV double line is two bands
        centres = (edges[0::2] + edges[1::2]) / 2
        widths = edges[1::2] - edges[0::2]
        lines = centres[(widths > 0.15) & (widths < 0.16)]
        line_y = lines[lines > 2.5 * i24.LANE_WIDTH]  # the broken lines and the edge line
        assert np.diff(line_y) == pytest.approx(i24.LANE_WIDTH, abs=1e-3)
        double = lines[lines < 2.5 * i24.LANE_WIDTH]
        assert double.mean() == pytest.approx(2 * i24.LANE_WIDTH, abs=1e-3)
    yellow = built_map.road.to_road(meshes["marking_yellow"].vertices)
    assert (yellow.y.min() + yellow.y.max()) / 2 == pytest.approx(i24.LANE_WIDTH, abs=1e-3)


def test_broken_lines_are_10_ft_dashes_with_30_ft_gaps(built_map, meshes):
    coords = built_map.road.to_road(meshes["marking_white"].vertices)
    on_line = (coords.road == 1) & (np.abs(coords.y - 3 * i24.LANE_WIDTH) < 0.1)
    x = np.unique(np.round(coords.x[on_line], 3))
    starts = x[np.r_[True, np.diff(x) > 5.0]]
    ends = x[np.r_[np.diff(x) > 5.0, True]]
    np.testing.assert_allclose(ends - starts, 10 * i24.FT, atol=1e-3)
    np.testing.assert_allclose(starts[1:] - ends[:-1], 30 * i24.FT, atol=1e-3)


def test_markings_lie_on_the_pavement(built_map, parts, meshes):
    road = built_map.road
    world = RayWorld({"road": parts["road"].visual, "shoulder": parts["shoulder"].visual})
    try:
        for name in ("marking_white", "marking_yellow"):
            mesh = meshes[name]
            points = np.concatenate([mesh.vertices, mesh.triangles_center])
            coords = road.to_road(points)
            # against the model's profile, at every vertex and face centre
            assert coords.height.min() > 0.0 and coords.height.max() <= 0.02
            # against the pavement mesh itself, at a sample
            sample = points[:: max(1, len(points) // 3000)]
            below, _ = world.cast(sample[:, :2], 60.0, -60.0)
            gap = sample[:, 2] - below
            assert np.nanmin(gap) > 0.0 and np.nanmax(gap) <= 0.02
            assert np.isfinite(below).all()
    finally:
        world.close()


def test_terrain_meets_the_shoulders_without_gaps_and_stays_off_the_road(built_map, meshes):
    road = built_map.road
    terrain = meshes["terrain"]
    coords = road.to_road(terrain.vertices)
    edge = road.outer_edge_at(coords.road, coords.x)  # beyond an acceleration lane
    inside = coords.y < edge - 1e-6
    assert not inside.any()  # no terrain within the road's footprint at all
    at_edge = np.abs(coords.y - edge) < 1e-6
    assert np.abs(coords.height[at_edge]).max() < 1e-6  # meets the pavement's edge height
    assert (edge[at_edge] > road.outer_edge + 1.0).any()  # also where a ramp widens it
    # the terrain's inner edge is exactly the shoulders' outer edge, vertex for vertex
    shoulder = road.to_road(meshes["shoulder"].vertices)
    shoulder_edge = meshes["shoulder"].vertices[
        np.abs(shoulder.y - road.outer_edge_at(shoulder.road, shoulder.x)) < 1e-6
    ]
    mine = {tuple(v) for v in np.round(terrain.vertices[at_edge], 5)}
    theirs = {tuple(v) for v in np.round(shoulder_edge, 5)}
    assert mine == theirs
    # no holes: two sheets, each a disk (Euler characteristic 1)
    merged = trimesh.Trimesh(terrain.vertices, terrain.faces, process=True)
    assert merged.body_count == 2
    assert merged.euler_number == 2


def test_terrain_seam_has_no_gap_for_rays(built_map, parts):
    road = built_map.road
    world = RayWorld({"terrain": parts["terrain"].visual, "shoulder": parts["shoulder"].visual})
    try:
        x = np.arange(-390.0, 2000.0, 13.7)
        for name in ("eastbound", "westbound"):
            for offset in (-0.01, 0.01):
                y = road.outer_edge_at(name, x) + offset
                heights, names = world.cast(_xy(road, name, x, y), 200.0, -200.0)
                assert np.isfinite(heights).all()
                expected = road.surface_z(road.station(name, x))
                assert np.abs(heights - expected).max() < 0.01
                assert set(names) == {"shoulder" if offset < 0 else "terrain"}
    finally:
        world.close()


def test_terrain_is_seeded(built_map, tmp_path):
    from mapgen.build import build_map

    a = built_map  # the session's, of seed 0
    b = build_map(tmp_path / "b", seed=2)
    terrain = {m.name: m.visual.read_bytes() for m in a.parts}
    other = {m.name: m.visual.read_bytes() for m in b.parts}
    assert terrain["terrain"] != other["terrain"]
    assert terrain["road"] == other["road"] and terrain["marking_white"] == other["marking_white"]


def test_overpass_is_at_old_franklin_rd_with_truck_clearance(built_map, parts):
    road = built_map.road
    world = RayWorld({"overpass": parts["overpass"].visual})
    try:
        landmarks = {"eastbound": 60.83, "westbound": 60.82}  # ramp_and_landmark_layer.csv
        for name, mm in landmarks.items():
            x = i24.road_x(np.array([mm * 5280.0]), i24.Road.parse(name))
            xy = _xy(road, name, np.repeat(x, 4), [float(i24.lane_center(k)) for k in i24.LANES])
            up, _ = world.cast(xy, road.surface_z(road.station(name, x))[0] + 0.1, 100.0)
            assert np.isfinite(up).all(), f"no deck over {name} at MM {mm}"
            # and no deck 30 m either side
            for dx in (-30.0, 30.0):
                clear = _xy(road, name, np.repeat(x + dx, 4), [5.0, 9.0, 12.0, 16.0])
                assert np.isnan(world.cast(clear, 0.0, 100.0)[0]).all()
        # clearance over every lane and shoulder, on a fine grid under the deck
        stations = np.arange(340.0, 385.0, 0.5)
        for name in ("eastbound", "westbound"):
            x = stations if name == "eastbound" else i24.SEGMENT_LENGTH - stations
            for y in np.arange(0.5, road.outer_edge, 0.5):
                xy = _xy(road, name, x, np.full(x.size, y))
                surface = road.surface_z(stations)
                up, _ = world.cast(xy, float(surface.min()) + 0.05, 100.0)
                hit = np.isfinite(up)
                if y > 0.4:  # the median piers stand inside the barrier, |y| < 0.3 m
                    assert (up[hit] - surface[hit]).min() >= 4.9
    finally:
        world.close()


def test_poles_from_the_pole_layer_stand_beside_the_road(built_map, meshes):
    road = built_map.road
    poles = built_map.description["objects"]["poles"]
    table = oracles.pd.read_csv(oracles.asset("i24_aux/pole_layer.csv"))
    points = road.from_geodetic(table.Y_WGS84.to_numpy(), table.X_WGS84.to_numpy())
    s0, s1 = road.station_range
    station = points[:, :2] @ road.direction_vector
    expected = set(table["pole-number"][(station > s0 + 1) & (station < s1 - 1)])
    assert {pole["pole"] for pole in poles} == expected
    assert len(expected) >= 10
    for pole in poles:
        assert abs(pole["lateral_m"]) > road.outer_edge
    coords = road.to_road(meshes["pole"].vertices)
    assert coords.y.min() > road.outer_edge  # no pole on the pavement
    assert coords.height.max() > 30.0  # the masts are tall


def test_tenth_mile_posts(built_map):
    posts = built_map.description["objects"]["posts"]
    mms = sorted({post["mm"] for post in posts})
    assert mms == pytest.approx([round(60.4 + 0.1 * k, 1) for k in range(15)])
    assert len(posts) == 2 * len(mms)


def test_triangle_counts_stay_renderer_friendly(built_map):
    assert 5_000 < built_map.description["triangles"]["visual"] < 50_000
    assert built_map.description["triangles"]["collision"] < 20_000


def test_every_part_carries_a_known_semantic_class(built_map):
    classes = {c["name"]: c["id"] for c in built_map.description["semantic_classes"]}
    for part in built_map.parts:
        assert classes[part.semantic_class] == part.class_id
    wanted = {"road", "lane_marking", "barrier", "terrain", "pole", "overpass", "sky"}
    assert wanted <= set(classes)


def test_the_on_ramps_lanes_are_pavement_beside_lane_4_with_a_300_ft_taper(built_map, parts):
    """Lane -5 where the landmark layer puts the two on-ramps' merges (ending at MM 60.70
    eastbound, 61.51 westbound): a full lane beside lane -4 up to the taper, half a lane
    half-way down it, nothing past its end, with the shoulder beyond it; the physics'
    road holds it too."""
    road = built_map.road
    world = RayWorld({"road": parts["road"].visual, "shoulder": parts["shoulder"].visual})
    physics = RayWorld({"road": built_map.collision["road"]})
    lanes_edge = (i24.N_LANES + 1) * i24.LANE_WIDTH
    w = i24.LANE_WIDTH
    try:
        for name, mm_end in (("eastbound", 60.70), ("westbound", 61.51)):
            x_end = float(
                i24.road_x(np.array([mm_end * i24.FEET_PER_MILE]), i24.Road.parse(name))[0]
            )
            full, middle, past = x_end - ramps.TAPER - 20.0, x_end - ramps.TAPER / 2, x_end + 5.0
            probes = [  # (x, y, the part hit)
                (full, lanes_edge + w / 2, "road"),
                (full, lanes_edge + w - 0.2, "road"),
                (full, lanes_edge + w + 0.2, "shoulder"),
                (full, lanes_edge + w + 2.8, "shoulder"),
                (middle, lanes_edge + w / 2 - 0.2, "road"),
                (middle, lanes_edge + w / 2 + 0.2, "shoulder"),
                (past, lanes_edge + 0.2, "shoulder"),
            ]
            x = np.array([p[0] for p in probes])
            y = np.array([p[1] for p in probes])
            heights, names = world.cast(_xy(road, name, x, y), 60.0, -60.0)
            assert names == [p[2] for p in probes], name
            np.testing.assert_allclose(heights, road.surface_z(road.station(name, x)), atol=0.01)
            lane = road.to_road(road.to_world(name, x, y)[0]).lane
            assert lane.tolist() == [-5, -5, 0, 0, -5, 0, 0]
            # the rigid bodies drive on it: the collision road reaches the shoulder's edge
            edge = road.outer_edge_at(name, x) - 0.1
            _, hit = physics.cast(_xy(road, name, x, edge), 60.0, -60.0)
            assert hit == ["road"] * len(x)
            assert road.outer_edge_at(name, [full])[0] == pytest.approx(road.outer_edge + w)
    finally:
        world.close()
        physics.close()


def test_a_broken_line_parts_lane_4_from_the_on_ramp_and_the_edge_line_follows_it(
    built_map, meshes
):
    coords = built_map.road.to_road(meshes["marking_white"].vertices)
    lanes_edge = (i24.N_LANES + 1) * i24.LANE_WIDTH
    for ramp in built_map.road.ramps:
        mine = coords.road == ramp.road.direction
        beside = mine & (coords.x > ramp.x_start + 15) & (coords.x < ramp.x_taper)
        at_line = beside & (np.abs(coords.y - lanes_edge) < 0.1)
        x = np.unique(np.round(coords.x[at_line], 3))
        starts = x[np.r_[True, np.diff(x) > 5.0]]
        assert len(starts) > 10 and np.diff(starts) == pytest.approx(40 * i24.FT, abs=1e-3)
        assert (beside & (np.abs(coords.y - lanes_edge - i24.LANE_WIDTH) < 0.1)).sum() > 4
        if ramp.x_start - ramps.OPENING > built_map.road.x_range(ramp.road)[0]:
            # lane -4's solid edge line goes on along the opening, to the gore
            opening = mine & (np.abs(coords.x - (ramp.x_start - ramps.OPENING / 2)) < 15.1)
            at_edge = opening & (np.abs(coords.y - lanes_edge) < 0.1)
            assert np.ptp(coords.x[at_edge]) == pytest.approx(ramps.OPENING, abs=0.01)
        after = mine & (coords.x > ramp.x_end + 1) & (coords.x < ramp.x_end + 100)
        assert (after & (np.abs(coords.y - lanes_edge) < 0.1)).any()
        assert not (after & (coords.y > lanes_edge + 0.2)).any()


def test_a_dash_across_a_profile_point_bends_at_it(built_map, meshes):
    """A 10 ft dash that spans a point where the grade changes has a vertex there, so it
    lies on both planes of the pavement rather than on a chord."""
    road = built_map.road
    coords = road.to_road(meshes["marking_white"].vertices)
    on_line = (coords.road == 1) & (np.abs(coords.y - 3 * i24.LANE_WIDTH) < 0.1)
    x = np.unique(np.round(coords.x[on_line], 4))
    starts = x[np.r_[True, np.diff(x) > 5.0]]
    ends = x[np.r_[np.diff(x) > 5.0, True]]
    knots = road.profile_s
    spanned = [
        k for a, b in zip(starts, ends, strict=True) for k in knots if a + 1e-3 < k < b - 1e-3
    ]
    assert len(spanned) > 10
    assert all(np.isclose(x, k, atol=1e-3).any() for k in spanned)
