"""The recorded traffic the cameras see beyond the simulated window: drawn where the
recording has it (checked by projecting the recording with OpenCV), labelled with its
record id, on both carriageways."""

import cv2
import numpy as np
import pytest

from sensors.writer import frame_meta
from twin.core.i24 import Road
from twin.cosim.config import SCENARIO_B, override
from twin.data.empirical import EmpiricalTraffic
from twin.physics.render import REPLAY_BASE


@pytest.fixture(scope="module")
def store():
    """The embedded data: both carriageways."""
    from twin.runners.run import open_data

    return open_data(None, progress=False)


@pytest.fixture(scope="module")
def frame(store, built_map):
    """Scenario B's front camera 12 s in, under the noon sun. (Straight ahead the
    westbound recording beyond the window hides behind the leader 15 m ahead, as it
    would; the eastbound carriageway's is in view.)"""
    from twin.runners.run import render_at

    config = override(SCENARIO_B, {"camera": {"sun": "noon"}})
    return render_at(config, store, 12.0, bundle=built_map)


def test_replayed_vehicles_are_drawn_where_the_recording_has_them(frame, store, built_map):
    """Each replayed vehicle's recorded position (the store's, found by its record id)
    projected with OpenCV falls inside the pixels of its instance id."""
    traffic = EmpiricalTraffic(store)
    meta = frame_meta(frame)
    replayed = [v for v in meta["vehicles"] if v["source"] == "replayed" and v["pixels"] >= 20]
    assert len(replayed) >= 3
    camera_from_world = np.linalg.inv(frame.world_from_camera)
    rvec, _ = cv2.Rodrigues(camera_from_world[:3, :3])
    checked = 0
    for vehicle in replayed:
        road = Road.parse(vehicle["road"])
        lo, hi = built_map.road.x_range(road)
        snap = traffic.snapshot(road, frame.time, lo, hi)
        (row,) = np.flatnonzero(snap.id == vehicle["record_id"])
        x = snap.x[row] + 0.5 * snap.length[row]
        ground, _, _ = built_map.road.to_world(road, [x], [snap.y[row]])
        centre = ground[0] + [0.0, 0.0, 0.5 * snap.height[row]]
        (uv,), _ = cv2.projectPoints(centre[None], rvec, camera_from_world[:3, 3], frame.K, None)
        ys, xs = np.nonzero(frame.instance == vehicle["id"])
        u, v = uv[0]
        height, width = frame.instance.shape
        if xs.min() == 0 or ys.min() == 0 or xs.max() == width - 1 or ys.max() == height - 1:
            continue  # cut by the image's edge: its centre may lie outside
        # inside the box of its pixels (a pixel of slack for the mask's edges)
        assert xs.min() - 1.5 <= u <= xs.max() + 1.5 and ys.min() - 1.5 <= v <= ys.max() + 1.5
        checked += 1
    assert checked >= 2


def test_replayed_ids_map_back_to_their_records_on_both_roads(frame):
    meta = frame_meta(frame)
    sources = {v["source"] for v in meta["vehicles"]}
    assert sources == {"simulated", "replayed"}
    for vehicle in meta["vehicles"]:
        assert vehicle["record_id"] and len(vehicle["record_id"]) == 24
        # every vehicle of the recording, simulated or replayed, has its record's
        # instance id (the same all episode long: tests/twin/cosim/test_camera_continuity)
        assert vehicle["id"] >= REPLAY_BASE
        assert vehicle["road"] in ("eastbound", "westbound") and vehicle["distance_m"] > 0
    ids = [v["record_id"] for v in meta["vehicles"]]
    assert len(set(ids)) == len(ids)  # a record is drawn once: simulated or replayed
    assert len({v["id"] for v in meta["vehicles"]}) == len(ids)  # with an id of its own
    roads = {v["road"] for v in meta["vehicles"]}
    assert roads == {"eastbound", "westbound"}  # the other carriageway's traffic too
    assert max(v["distance_m"] for v in meta["vehicles"]) > 200.0  # past the window
    assert len(meta["vehicles"]) >= 12
