"""Levels of detail of the vehicle models: fewer triangles past a distance, the same
silhouette within a pixel (rendered against the full model), and the errors they are
switched by measured from the models themselves."""

import cv2
import numpy as np
import pytest

from mapgen.vehicles import hausdorff, point_triangle_distance
from sensors.camera import CameraRig, CameraSpec
from sensors.replay import Replayed
from tests.sensors.test_camera import EGO_X, spawn
from twin.core.i24 import VEHICLE_CLASSES, Road, lane_center
from twin.core.vehicle_classes import vehicle_classes
from twin.physics.world import PhysicsWorld


def test_levels_have_fewer_triangles_and_measured_errors(built_map):
    for name in VEHICLE_CLASSES:
        levels = built_map.vehicle_lods[name]
        assert levels[0].error_m == 0.0
        triangles = [level.triangles for level in levels]
        errors = [level.error_m for level in levels]
        assert triangles == sorted(triangles, reverse=True) and len(set(triangles)) == 3
        assert errors == sorted(errors) and 0.05 < errors[1] < 0.3 and errors[2] < 1.0
    # a sedan's square wheels are at most r (1 - cos 45 deg) = 0.094 m inside its round
    # ones, and without wheels its body is 0.3 m above the ground: within the bound's
    # 5 cm of slack above those
    sedan = built_map.vehicle_lods["sedan"]
    assert 0.09 <= sedan[1].error_m <= 0.145 and 0.30 <= sedan[2].error_m <= 0.355


def test_point_triangle_distance_and_hausdorff_against_dense_samples():
    rng = np.random.default_rng(3)
    triangles = rng.normal(size=(6, 3, 3))
    points = rng.normal(size=(300, 3)) * 2.0
    uv = rng.random((100_000, 2))
    uv = uv[uv.sum(axis=1) <= 1.0]
    dense = np.concatenate(
        [t[0] + uv[:, :1] * (t[1] - t[0]) + uv[:, 1:] * (t[2] - t[0]) for t in triangles]
    )
    nearest = np.sqrt(((points[:, None] - dense[None]) ** 2).sum(-1)).min(axis=1)
    exact = point_triangle_distance(points, triangles)
    assert np.all(exact <= nearest + 1e-9) and np.all(nearest - exact < 0.05)
    assert hausdorff(triangles, triangles, 0.05) == pytest.approx(0.05)  # the slack only
    moved = triangles + np.array([0.0, 0.0, 0.3])
    assert 0.3 <= hausdorff(triangles, moved, 0.05) <= 0.35 + 1e-9


def _mask(frame, vehicle_id):
    return (frame.instance == vehicle_id).astype(np.uint8)


def _farthest_miss(a: np.ndarray, b: np.ndarray) -> float:
    """[px] the farthest pixel of either mask from the other mask."""
    far = 0.0
    for one, other in ((a, b), (b, a)):
        miss = (one > 0) & (other == 0)
        if miss.any():
            distance = cv2.distanceTransform(1 - other, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
            far = max(far, float(distance[miss].max()))
    return far


class _Recorded:
    """Recorded vehicles for ``CameraRig.capture``: fixed boxes, all eastbound."""

    def __init__(self, replayed: Replayed):
        self.fixed = replayed

    def replayed(self) -> Replayed:
        return self.fixed

    def record_of(self, ids):
        return np.full(len(ids), "", dtype=object), np.ones(len(ids), np.int64)

    def tids_of(self, ids):
        return np.full(len(ids), -1, np.int64)  # the simulated ones have no recording


def _broadside(built_map, classes, x, y, turn) -> Replayed:
    """Vehicles of ``classes`` at their classes' mean sizes on the eastbound road at
    ``x``, ``y`` [m], turned ``turn`` [rad] from the road's heading."""
    table = vehicle_classes()
    size = np.array(
        [[table.column(c)[k] for c in ("length_m", "width_m", "height_m")] for k in classes]
    )
    position, heading, _ = built_map.road.to_world(Road.EASTBOUND, np.asarray(x), np.asarray(y))
    yaw = heading + np.asarray(turn)
    rotation = np.zeros((len(classes), 3, 3))
    rotation[:, 0, 0], rotation[:, 0, 1] = np.cos(yaw), -np.sin(yaw)
    rotation[:, 1, 0], rotation[:, 1, 1] = np.sin(yaw), np.cos(yaw)
    rotation[:, 2, 2] = 1.0
    n = len(classes)
    return Replayed(
        tid=np.arange(n), record_id=np.full(n, "", dtype=object), road=np.ones(n, np.int64),
        vehicle_class=np.asarray(classes, np.int64), size=size, position=position,
        rotation=rotation, speed=np.zeros(n),
    )  # fmt: skip


@pytest.mark.parametrize("vehicle_class", range(len(VEHICLE_CLASSES)))
def test_a_level_is_drawn_from_its_distance_on_with_the_full_silhouette(built_map, vehicle_class):
    """Each class just past the distance its levels 1 and 2 begin (lanes -3 and -1,
    seen from lane -2, broadside where it fits across two lanes so that its wheels
    show): the level is chosen there and not where an error e at distance d would be
    more than a pixel (e * f / (d - e) > 1), and its pixels lie within a pixel of the
    full model's (rendered the same without levels)."""
    camera = CameraSpec()
    name = VEHICLE_CLASSES[vehicle_class]
    levels = built_map.vehicle_lods[name]
    with PhysicsWorld(built_map) as world:
        ego, ego_size = spawn(world, EGO_X, -2, 0)
        world.step()
        rig = CameraRig(world, built_map, (camera,), renderer="tiny", sun="noon")
        view = rig.view
        eye, margin = rig._eye(ego, rig.cameras)
        camera_x = EGO_X + ego_size[0] + camera.mount[0]
        turn = 0.5 * np.pi if levels[0].size_m[0] < 7.0 else 0.0
        placed = []  # (level, x, y)
        for level, lane in ((1, -3), (2, -1)):
            start = levels[level].error_m * (view.lod_focal + 1.0) * 1.15 + margin + 12.0
            if start < camera.far - 30.0:  # (a semi or truck without wheels: never)
                placed.append((level, camera_x + start, float(lane_center(lane))))
        assert placed
        recorded = _broadside(
            built_map, [vehicle_class] * len(placed), [x for _, x, _ in placed],
            [y for _, _, y in placed], turn,
        )  # fmt: skip
        centre = recorded.position + [0.0, 0.0, 0.5] * recorded.size[:, 2:3]
        chosen = view.levels(recorded.vehicle_class, recorded.size, centre, eye, margin)
        assert chosen.tolist() == [level for level, _, _ in placed]
        for (level, _, _), at in zip(placed, centre, strict=True):
            # where the cameras are 2 % nearer than the level needs: the level below
            error = levels[level].error_m
            needs = error * (view.lod_focal + 1.0) + 0.5 * np.linalg.norm(levels[0].size_m)
            direction = (at - eye) / np.linalg.norm(at - eye)
            nearer = eye + direction * (needs + margin - 0.02 * error * view.lod_focal)
            size = recorded.size[:1]
            assert view.levels([vehicle_class], size, nearer[None], eye, margin)[0] == level - 1
        (detailed,) = rig.capture(ego, traffic=_Recorded(recorded))
        view.lod_focal = 0.0
        (full,) = rig.capture(ego, traffic=_Recorded(recorded))
        drawn = full.vehicles
        for k, (level, _, _) in enumerate(placed):
            vehicle = int(drawn.id[drawn.replayed][k])
            a, b = _mask(detailed, vehicle), _mask(full, vehicle)
            assert b.sum() >= 4, (name, level, int(b.sum()))  # a motorcycle at 200 m: 4
            assert _farthest_miss(a, b) <= 1.0, (name, level)
        rig.close()


def test_the_silhouette_check_sees_a_level_drawn_too_near(built_map):
    """The comparison above can fail: a sedan 12 m ahead drawn without its wheels."""
    camera = CameraSpec()
    with PhysicsWorld(built_map) as world:
        ego, ego_size = spawn(world, EGO_X, -2, 0)
        vehicle, _ = spawn(world, EGO_X + ego_size[0] + camera.mount[0] + 12.0, -3, 0)
        world.step()
        rig = CameraRig(world, built_map, (camera,), renderer="tiny", sun="noon")
        (full,) = rig.capture(ego)
        rig.view._level_error[:, 1:] = 0.0  # every level "exact": the coarsest everywhere
        (coarse,) = rig.capture(ego)
        assert rig.view._proxies[vehicle][1][1] == 2
        assert _farthest_miss(_mask(coarse, vehicle), _mask(full, vehicle)) > 5.0
        rig.close()


def test_vehicles_beside_the_cameras_get_the_full_model(built_map):
    """A vehicle nearer than the cameras' reach (alongside the ego, where the side
    cameras look) is drawn in full, not at the coarsest level."""
    with PhysicsWorld(built_map) as world:
        ego, _ = spawn(world, EGO_X, -2, 0)
        world.step()
        rig = CameraRig(world, built_map, (CameraSpec(),), renderer="tiny", sun="noon")
        eye, margin = rig._eye(ego, rig.cameras)
        table = vehicle_classes()
        size = [[table.column(c)[0] for c in ("length_m", "width_m", "height_m")]]
        beside = eye + np.array([0.0, 3.66, 0.0])
        for distance in (0.0, 3.66, margin):
            at = eye + np.array([distance, 0.0, 0.0])
            assert rig.view.levels([0], size, at[None], eye, margin)[0] == 0
        assert rig.view.levels([0], size, beside[None], eye, margin)[0] == 0
        far = eye + np.array([250.0, 0.0, 0.0])
        assert rig.view.levels([0], size, far[None], eye, margin)[0] == 2
        rig.close()
