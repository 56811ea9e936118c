"""Vehicle labels against oracles: OpenCV's projection, the vehicle at a known place,
and the same scene rendered without the occluder."""

import math

import cv2
import numpy as np
import pytest

from sensors.camera import CameraRig, CameraSpec
from sensors.labels import LARGELY_OCCLUDED, PARTLY_OCCLUDED, frame_labels, model_triangles
from tests.sensors.test_camera import AHEAD, EGO_X, spawn
from twin.physics.world import PhysicsWorld

CAMERA = CameraSpec()


def corners_of(frame, i):
    """(8, 3) world corners of drawn vehicle ``i`` of ``frame``."""
    v = frame.vehicles
    k = np.array([[(c >> a) & 1 for a in range(3)] for c in range(8)], float) - [0.5, 0.5, 0.0]
    return (k * v.size[i]) @ v.rotation[i].T + v.position[i]


def projected_box(frame, world_points):
    """The image box of points (all in front of the camera), by OpenCV."""
    camera_from_world = np.linalg.inv(frame.world_from_camera)
    rvec, _ = cv2.Rodrigues(camera_from_world[:3, :3])
    uv, _ = cv2.projectPoints(world_points, rvec, camera_from_world[:3, 3], frame.K, None)
    uv = uv.reshape(-1, 2)
    return np.r_[uv.min(0), uv.max(0)]


@pytest.fixture(scope="module")
def street(built_map):
    """The ego; a sedan AHEAD m in front of its camera; a pickup farther on, partly
    behind the sedan; a box truck close in the next lane, partly out of the picture; a
    sedan mostly behind a van; a sedan behind the ego. Frames with and without the
    sedan ahead and the van."""
    with PhysicsWorld(built_map) as world:
        ego, ego_size = spawn(world, EGO_X, -2, 0)
        camera_x = EGO_X + ego_size[0] + CAMERA.mount[0]
        ahead, ahead_size = spawn(world, camera_x + AHEAD, -2, 0)
        behind, _ = spawn(world, camera_x + AHEAD + 14.0, -2, 2, y_offset=1.2)
        alongside, _ = spawn(world, camera_x + 4.0, -3, 5)
        van, _ = spawn(world, camera_x + 30.0, -1, 3)
        behind_van, _ = spawn(world, camera_x + 35.6, -1, 0)
        out_of_view, _ = spawn(world, EGO_X - 20.0, -2, 0)
        world.step()
        rig = CameraRig(world, built_map, (CAMERA,), renderer="tiny")
        (frame,) = rig.capture(ego)
        world.despawn([ahead, van])
        (without,) = rig.capture(ego)
        rig.close()
    return {
        "frame": frame,
        "without": without,
        "ids": {
            "ahead": ahead,
            "behind": behind,
            "alongside": alongside,
            "van": van,
            "behind_van": behind_van,
        },
        "out_of_view": out_of_view,
        "ahead_size": ahead_size,
        "models": model_triangles(built_map),
    }


def row(labels, twin_id):
    (i,) = np.flatnonzero(labels.id == twin_id)
    return i


def test_every_vehicle_with_pixels_is_labelled_once(street):
    frame = street["frame"]
    labels = frame_labels(frame, street["models"])
    ids, counts = np.unique(frame.instance[frame.instance >= 0], return_counts=True)
    assert labels.id.tolist() == ids.tolist()
    assert labels.pixels.tolist() == counts.tolist()
    assert street["out_of_view"] not in labels.id  # behind the camera: no pixel, no label
    for i, twin_id in enumerate(labels.id):
        rows, cols = np.nonzero(frame.instance == twin_id)
        assert labels.visible_box[i].tolist() == [cols.min(), rows.min(), cols.max(), rows.max()]


def test_vehicle_ahead_has_its_place_size_and_heading(street):
    frame = street["frame"]
    labels = frame_labels(frame, street["models"])
    i = row(labels, street["ids"]["ahead"])
    length, width, height = frame.vehicles.size[frame.vehicles.id == labels.id[i]][0]
    assert labels.dimensions[i].tolist() == [height, width, length]
    x, y, z = labels.location[i]
    assert abs(x) < 0.1  # same lane, centred
    assert abs(y - CAMERA.mount[2]) < 0.1  # its bottom lies 1.4 m below the camera
    assert abs(z - (AHEAD + 0.5 * length)) < 0.15  # the box centre along the axis
    assert abs(labels.rotation_y[i] + math.pi / 2) < 0.01  # drives away from the camera
    assert abs(labels.alpha[i] - labels.rotation_y[i]) < 0.01  # straight ahead: alpha = ry
    centre_height = y - 0.5 * height
    assert labels.distance[i] == pytest.approx(math.hypot(x, centre_height, z), abs=1e-9)
    assert labels.truncation[i] == 0.0
    assert labels.occlusion[i] == 0.0 and labels.occlusion_level[i] == 0
    assert abs(labels.speed[i]) < 0.5  # spawned at rest


def test_amodal_boxes_are_the_projected_3d_boxes(street):
    frame = street["frame"]
    labels = frame_labels(frame, street["models"])
    checked = 0
    for i, twin_id in enumerate(labels.id):
        if labels.truncation[i] > 0:
            continue
        j = int(np.flatnonzero(frame.vehicles.id == twin_id)[0])
        expected = projected_box(frame, corners_of(frame, j))
        np.testing.assert_allclose(labels.amodal_box[i], expected, atol=1e-6)
        left, top, right, bottom = labels.visible_box[i]
        a = labels.amodal_box[i]
        assert a[0] - 1 <= left <= right <= a[2] + 1 and a[1] - 1 <= top <= bottom <= a[3] + 1
        checked += 1
    assert checked >= 3


def test_truncation_is_the_share_of_the_box_outside_the_image(street):
    frame = street["frame"]
    labels = frame_labels(frame, street["models"])
    i = row(labels, street["ids"]["alongside"])
    j = int(np.flatnonzero(frame.vehicles.id == labels.id[i])[0])
    corners = corners_of(frame, j)
    camera_from_world = np.linalg.inv(frame.world_from_camera)
    assert (corners @ camera_from_world[:3, :3].T + camera_from_world[:3, 3])[:, 2].min() > 0.5
    left, top, right, bottom = projected_box(frame, corners)
    w, h = CAMERA.width, CAMERA.height
    inside = (min(right, w - 0.5) - max(left, -0.5)) * (min(bottom, h - 0.5) - max(top, -0.5))
    expected = 1.0 - inside / ((right - left) * (bottom - top))
    assert 0.05 < expected < 0.95  # the test scene puts it across the edge
    assert labels.truncation[i] == pytest.approx(expected, abs=1e-9)


@pytest.mark.parametrize(("name", "low", "high"), [("behind", 0.2, 0.5), ("behind_van", 0.5, 1.0)])
def test_occlusion_matches_the_scene_rendered_without_the_occluder(street, name, low, high):
    labels = frame_labels(street["frame"], street["models"])
    alone = frame_labels(street["without"], street["models"])
    twin_id = street["ids"][name]
    i, k = row(labels, twin_id), row(alone, twin_id)
    assert alone.occlusion[k] == 0.0  # nothing in front of it any more
    # the share of its silhouette the occluder hides, counted in rendered pixels
    true_share = 1.0 - labels.pixels[i] / alone.pixels[k]
    assert low < true_share < high  # the scene is built for these
    assert labels.occlusion[i] == pytest.approx(true_share, abs=0.05)
    expected_level = int(np.digitize(true_share, [PARTLY_OCCLUDED, LARGELY_OCCLUDED]))
    assert labels.occlusion_level[i] == expected_level
    assert labels.occlusion_level[row(labels, street["ids"]["ahead"])] == 0
