"""The dataset's motion check (twin.runners.dataset.motion) on hand-made labels."""

import numpy as np

from twin.runners.dataset.motion import motion_check


def _record(time, vehicles, camera_x=0.0, episode=0):
    world_from_camera = np.eye(4)
    world_from_camera[0, 3] = camera_x  # the camera moves with the ego
    return {"episode": episode, "camera": "front", "sim_time": time,
            "world_from_camera": world_from_camera.tolist(), "vehicles": vehicles}  # fmt: skip


def _vehicle(record_id, x, speed):
    return {"record_id": record_id, "location_m": [x, 0.0, 10.0], "speed_mps": speed}


def test_a_vehicle_moving_at_its_speed_passes_and_a_jump_is_a_violation():
    labels = [
        _record(0.0, [_vehicle("a", 0.0, 10.0), _vehicle("b", 5.0, 10.0)], camera_x=0.0),
        # 1 s later the camera moved 10 m; "a" moved 10 m in the world, "b" 30 m
        _record(1.0, [_vehicle("a", 0.0, 10.0), _vehicle("b", 25.0, 10.0)], camera_x=10.0),
    ]
    out = motion_check(labels)
    assert out["pairs"] == 2 and out["violations"] == 1
    # b: moved 30 m where 10 + 5 + 0.1 were allowed
    assert np.isclose(out["max_excess_m"], 30.0 - 15.1)


def test_episodes_cameras_and_unrecorded_vehicles_are_kept_apart():
    labels = [
        _record(0.0, [_vehicle("a", 0.0, 10.0), _vehicle(None, 0.0, 0.0)], episode=0),
        _record(0.5, [_vehicle("a", 500.0, 10.0), _vehicle(None, 900.0, 0.0)], episode=1),
    ]
    assert motion_check(labels) == {"pairs": 0, "violations": 0, "max_excess_m": None}
