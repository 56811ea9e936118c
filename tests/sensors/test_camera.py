"""Ego cameras against independent oracles: OpenCV's projection, Bullet's ray tests,
the road ahead and a vehicle at a known distance."""

import math

import cv2
import numpy as np
import pybullet as p
import pytest

from mapgen.build import MapBundle
from sensors.camera import CameraError, CameraRig, CameraSettings, CameraSpec
from twin.core.i24 import VEHICLE_CLASSES, Road, lane_center
from twin.core.vehicle_classes import vehicle_classes
from twin.physics.states import SpawnStates
from twin.physics.world import PhysicsWorld

EGO_X = 300.0  # [m] back of the ego, eastbound lane -2
AHEAD = 20.0  # [m] from the camera to the rear face of the vehicle ahead
ROAD_CLASS, MARKING_CLASS = 1, 3


def spawn(world, x, lane, vehicle_class, y_offset=0.0):
    table = vehicle_classes()
    size = [float(table.column(c)[vehicle_class]) for c in ("length_m", "width_m", "height_m")]
    states = SpawnStates.make(
        Road.EASTBOUND, [x], float(lane_center(lane)) + y_offset, 0.0, vehicle_class, *size
    )
    return int(world.spawn(states)[0]), size


@pytest.fixture(scope="module")
def scene(built_map: MapBundle):
    """An ego with a sedan 20 m ahead of its camera and four more vehicles around."""
    with PhysicsWorld(built_map) as world:
        ego, ego_size = spawn(world, EGO_X, -2, 0)
        camera = CameraSpec()
        camera_x = EGO_X + ego_size[0] + camera.mount[0]
        ahead, ahead_size = spawn(world, camera_x + AHEAD, -2, 0)
        others = [
            spawn(world, EGO_X + 14.0, -3, 1)[0],
            spawn(world, EGO_X + 35.0, -1, 2)[0],
            spawn(world, EGO_X + 60.0, -4, 4)[0],
            spawn(world, EGO_X + 9.0, -1, 3)[0],
        ]
        world.step()
        rig = CameraRig(world, built_map, (camera,), renderer="tiny")
        (frame,) = rig.capture(ego, time=1.0, sim_time=0.0)
        yield {
            "world": world,
            "rig": rig,
            "frame": frame,
            "ego": ego,
            "ahead": ahead,
            "ahead_size": ahead_size,
            "others": others,
            "bundle": built_map,
        }
        rig.close()


def test_frame_holds_images_calibration_and_poses(scene):
    frame = scene["frame"]
    h, w = frame.camera.height, frame.camera.width
    assert frame.rgb.shape == (h, w, 3) and frame.rgb.dtype == np.uint8
    assert frame.depth.shape == (h, w) and frame.depth.dtype == np.float32
    assert frame.semantic.dtype == np.uint8 and frame.instance.dtype == np.int64
    f = 0.5 * w / math.tan(math.radians(40.0))
    np.testing.assert_allclose(frame.K, [[f, 0, 319.5], [0, f, 239.5], [0, 0, 1]])
    # the camera sits 1.65 m above the ground, 1.9 m behind the ego's front, looking ahead
    np.testing.assert_allclose(
        frame.ego_from_camera[:3, 3], [0.5 * 4.7 - 1.9, 0.0, 1.65], atol=0.03
    )
    optical_axis = frame.ego_from_camera[:3, 2]
    np.testing.assert_allclose(optical_axis, [1.0, 0.0, 0.0], atol=1e-12)
    ego_world = frame.world_from_camera @ np.linalg.inv(frame.ego_from_camera)
    heading = math.atan2(ego_world[1, 0], ego_world[0, 0])
    road_heading = scene["bundle"].road.to_world(Road.EASTBOUND, [EGO_X], [5.0])[1][0]
    assert abs(heading - road_heading) < 1e-3
    assert scene["ego"] not in frame.vehicles.id  # the ego does not see itself
    assert not (frame.instance == scene["ego"]).any()


def test_projection_agrees_with_opencv_and_masks_lie_in_their_boxes(scene):
    frame = scene["frame"]
    camera_from_world = np.linalg.inv(frame.world_from_camera)
    rvec, _ = cv2.Rodrigues(camera_from_world[:3, :3])
    tvec = camera_from_world[:3, 3]
    vehicles = frame.vehicles
    unit = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (0.0, 1.0)])
    checked = 0
    for i, twin_id in enumerate(vehicles.id.tolist()):
        corners = vehicles.position[i] + (unit * vehicles.size[i]) @ vehicles.rotation[i].T
        in_camera = corners @ camera_from_world[:3, :3].T + tvec
        if (in_camera[:, 2] <= 1.0).any():
            continue
        ours = in_camera @ frame.K.T
        ours = ours[:, :2] / ours[:, 2:]
        theirs, _ = cv2.projectPoints(corners, rvec, tvec, frame.K, None)
        np.testing.assert_allclose(ours, theirs[:, 0, :], atol=1e-6)
        rows, cols = np.nonzero(frame.instance == twin_id)
        if rows.size == 0:
            continue
        assert cols.min() >= ours[:, 0].min() - 1.0 and cols.max() <= ours[:, 0].max() + 1.0
        assert rows.min() >= ours[:, 1].min() - 1.0 and rows.max() <= ours[:, 1].max() + 1.0
        checked += 1
    assert checked >= 4


def test_depth_equals_bullet_ray_tests_within_one_percent(scene):
    """Independent oracle: Bullet's ray-triangle tests on the same OBJ files as
    collision meshes (map tiles and vehicle models at their drawn poses)."""
    frame, bundle = scene["frame"], scene["bundle"]
    client = p.connect(p.DIRECT)
    try:
        flags = p.GEOM_FORCE_CONCAVE_TRIMESH
        for tile in bundle.tiles:
            shape = p.createCollisionShape(
                p.GEOM_MESH, fileName=str(tile.visual), flags=flags, physicsClientId=client
            )
            p.createMultiBody(0, shape, -1, physicsClientId=client)
        v = frame.vehicles
        for i in range(len(v.id)):
            name = VEHICLE_CLASSES[int(v.vehicle_class[i])]
            shape = p.createCollisionShape(
                p.GEOM_MESH,
                fileName=str(bundle.vehicles[name]),
                meshScale=v.size[i].tolist(),
                flags=flags,
                physicsClientId=client,
            )
            pose = v.position[i].tolist(), _quaternion(v.rotation[i])
            p.createMultiBody(0, shape, -1, *pose, physicsClientId=client)
        rng = np.random.default_rng(0)
        u = rng.integers(2, frame.camera.width - 2, 3000)
        r = rng.integers(2, frame.camera.height - 2, 3000)
        window = np.stack([frame.depth[r + dr, u + du] for dr in (-1, 0, 1) for du in (-1, 0, 1)])
        finite = np.all(np.isfinite(window), axis=0)
        window[:, ~finite] = 0.0
        smooth = finite & (np.ptp(window, axis=0) < 0.02 * frame.depth[r, u])  # no edges
        u, r = u[smooth], r[smooth]
        rays = np.stack([u, r, np.ones_like(u)], axis=1) @ np.linalg.inv(frame.K).T
        origin = frame.world_from_camera[:3, 3]
        far = frame.camera.far
        ends = origin + (rays * far) @ frame.world_from_camera[:3, :3].T
        hits = p.rayTestBatch(
            np.tile(origin, (len(u), 1)).tolist(), ends.tolist(), physicsClientId=client
        )
    finally:
        p.disconnect(client)
    fraction = np.array([hit[2] for hit in hits])
    hit = np.array([h[0] >= 0 for h in hits])
    ray_depth = fraction[hit] * far  # planar: the rays' ends lie on the far plane
    rendered = frame.depth[r[hit], u[hit]].astype(np.float64)
    error = np.abs(rendered / ray_depth - 1.0)
    assert hit.sum() > 1000
    # the bound; the few pixels above it see the road at grazing angles, where
    # depth changes by more than 1 % within a pixel (measured: 99.9 % within, max 1.5 %)
    assert np.mean(error < 0.01) >= 0.99
    assert np.median(error) < 0.005


def test_road_covers_the_lower_middle_and_the_car_ahead_is_centred_at_its_size(scene):
    frame = scene["frame"]
    h, w = frame.semantic.shape
    lower_middle = frame.semantic[int(0.75 * h) : int(0.95 * h), int(0.4 * w) : int(0.6 * w)]
    assert np.mean(lower_middle == ROAD_CLASS) > 0.95
    rows, cols = np.nonzero(frame.instance == scene["ahead"])
    f = frame.K[0, 0]
    width = cols.max() - cols.min() + 1
    expected = f * scene["ahead_size"][1] / AHEAD  # the rear face, 20 m from the camera
    assert abs(width - expected) <= 2.0, (width, expected)
    assert abs(0.5 * (cols.min() + cols.max()) - frame.K[0, 2]) <= 1.5
    assert np.all(frame.semantic[rows, cols] == 9)  # sedan
    height = rows.max() - rows.min() + 1
    length, _, tall = scene["ahead_size"]
    assert f * tall / (AHEAD + length) - 2 <= height <= f * tall / AHEAD + 2
    assert abs(np.median(frame.depth[rows, cols]) - AHEAD) < 1.5


def test_same_scene_same_frames_bit_for_bit(built_map):
    """Two worlds built alike give the same frame sequence. (Within one world, a second
    capture of an unchanged scene may differ in a pixel or two of RGB where coplanar
    faces tie: TinyRenderer's draw order follows the last visual changes.)"""
    sequences = []
    for _ in range(2):
        with PhysicsWorld(built_map) as world:
            ego, _ = spawn(world, EGO_X, -2, 0)
            spawn(world, EGO_X + 25.0, -2, 4)
            world.step()
            rig = CameraRig(world, built_map, (CameraSpec(width=160, height=120),), "tiny")
            sequences.append([rig.capture(ego)[0] for _ in range(2)])
            rig.close()
    for a, b in zip(*sequences, strict=True):
        for name in ("rgb", "depth", "semantic", "instance"):
            assert np.array_equal(getattr(a, name), getattr(b, name)), name


def test_vehicles_are_class_shaped_and_painted_not_one_grey_box(scene):
    frame = scene["frame"]
    colours = {
        tuple(np.median(frame.rgb[frame.instance == i], axis=0).astype(int))
        for i in frame.vehicles.id
        if (frame.instance == i).sum() > 200
    }
    assert len(colours) >= 3
    classes = set(np.unique(frame.semantic).tolist())
    assert {9, 10, 11} <= classes  # sedan, midsize, pickup in view


def test_camera_settings_reject_impossible_values():
    with pytest.raises(CameraError, match="near < far"):
        CameraSpec(near=5.0, far=1.0)
    with pytest.raises(CameraError, match="hfov_deg"):
        CameraSpec(hfov_deg=180.0)
    with pytest.raises(CameraError, match="reference"):
        CameraSpec(reference="roof")
    with pytest.raises(CameraError, match="unknown camera"):
        CameraSettings(cameras=("nose",))
    with pytest.raises(CameraError, match="renderer"):
        CameraSettings(renderer="opengl")
    assert [c.name for c in CameraSettings(cameras=("front", "rear")).rig()] == ["front", "rear"]


def test_a_rear_camera_looks_backwards():
    rear = CameraSettings(cameras=("rear",)).rig()[0]
    pose = rear.vehicle_from_camera(4.7)
    assert pose[0, 3] < -2.0 and pose[:3, 2] @ [-1.0, 0.0, 0.0] > 0.99


def _quaternion(rotation):
    """(x, y, z, w) of a rotation matrix (trace method; fine away from 180 degrees)."""
    w = 0.5 * math.sqrt(max(0.0, 1.0 + np.trace(rotation)))
    return [
        (rotation[2, 1] - rotation[1, 2]) / (4 * w),
        (rotation[0, 2] - rotation[2, 0]) / (4 * w),
        (rotation[1, 0] - rotation[0, 1]) / (4 * w),
        w,
    ]


def test_vehicles_outside_the_view_are_skipped_without_changing_the_frame(built_map, monkeypatch):
    """A vehicle behind the front camera is hidden from the renderer (TinyRenderer does
    not clip: it would scan it); the frame is the same as when nothing is skipped."""
    from twin.physics.render import SceneView

    frames = []
    for cull in (True, False):
        if not cull:
            monkeypatch.setattr(SceneView, "_cull_vehicles", lambda self, clip: None)
        with PhysicsWorld(built_map) as world:
            ego, _ = spawn(world, EGO_X, -2, 0)
            behind, _ = spawn(world, EGO_X - 30.0, -2, 4)
            spawn(world, EGO_X + 25.0, -3, 1)
            world.step()
            rig = CameraRig(world, built_map, (CameraSpec(width=160, height=120),), "tiny")
            frames.append(rig.capture(ego, time=1.0)[0])
            if cull:
                body = rig.view._proxies[behind][0]
                assert body in rig.view._hidden
            rig.close()
    for name in ("rgb", "depth", "semantic", "instance"):
        assert np.array_equal(getattr(frames[0], name), getattr(frames[1], name)), name
