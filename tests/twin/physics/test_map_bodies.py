"""The map in a pybullet client: concave collision meshes, invisible; visual parts labelled."""

import numpy as np
import pybullet as p

from twin.physics.map_bodies import load_map_bodies


def test_collision_is_concave_and_invisible_and_parts_carry_classes(built_map):
    client = p.connect(p.DIRECT)
    try:
        bodies = load_map_bodies(client, built_map)
        road = built_map.road
        point = road.lane_center_line("westbound", -4, [1000.0])[0]
        above, below = point + np.array([0, 0, 30]), point - np.array([0, 0, 30])
        hit = p.rayTest(above.tolist(), below.tolist(), physicsClientId=client)[0]
        assert hit[0] == bodies.collision["road"]
        assert abs(hit[3][2] - point[2]) < 0.01

        eye = road.lane_center_line("eastbound", -2, [200.0])[0] + [0, 0, 1.4]
        ahead = road.lane_center_line("eastbound", -2, [260.0])[0]
        view = p.computeViewMatrix(eye.tolist(), ahead.tolist(), [0, 0, 1])
        projection = p.computeProjectionMatrixFOV(60, 4 / 3, 0.3, 2000)
        _, _, _, _, seg = p.getCameraImage(
            160, 120, view, projection, renderer=p.ER_TINY_RENDERER, physicsClientId=client
        )
        seen = set(np.unique(np.asarray(seg)).tolist()) - {-1}
        assert not seen & set(bodies.collision.values())  # physics-only bodies are not drawn
        classes = {bodies.semantic[body] for body in seen}
        names = {c["id"]: c["name"] for c in built_map.description["semantic_classes"]}
        assert {"road", "lane_marking", "barrier", "terrain"} <= {names[c] for c in classes}
        # the lower middle of a forward view is this lane's pavement
        lower_middle = np.asarray(seg).reshape(120, 160)[100:, 60:100]
        assert (lower_middle == bodies.visual["road"]).mean() > 0.9
    finally:
        p.disconnect(client)
