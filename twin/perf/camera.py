"""The camera benchmark: frames per second of the default front camera in dense
eastbound traffic, with the recorded traffic drawn around the scene."""

import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from twin.core.i24 import SCENARIO_TIME
from twin.data.empirical import EmpiricalTraffic
from twin.perf.common import class_mix, dimensions, median, ms, store_or_default

FRAME_INTERVAL = 0.1  # [s] of simulated time between frames
STEPS_PER_FRAME = 10  # physics steps of 0.01 s between frames
SPEED = 27.0  # [m/s] every vehicle's, so that the scene drives with the ego
EGO_STATION = 400.0  # [m] where the scene is centred
GAPS = (4.0, 8.0)  # [m] least and most gap between a vehicle's nose and the next's back
MARGIN = 10.0  # [m] either side of the bench's vehicles where no recording is drawn


@dataclass
class _Drawn:
    """What the camera bench's frames drew, one entry a frame: the recorded vehicles,
    and the vehicle model triangles (at their levels of detail, and as full models)."""

    replayed: list[int] = field(default_factory=list)
    triangles: list[tuple[int, int]] = field(default_factory=list)


def camera_bench(
    store=None,
    *,
    renderer: str = "tiny",
    vehicles: int = 100,
    frames: int = 30,
    repeats: int = 3,
    replay: bool = True,
) -> dict:
    """Frames per second of the default front camera (640x480 RGB, depth, semantic and
    instance) on an ego in the middle of ``vehicles`` vehicles (the ego included) in
    the four eastbound lanes, nose to tail over about 300 m, at 27 m/s; 0.1 s of physics
    between frames, so the camera sees the scene from a new place each frame.

    With ``replay``, the recorded traffic of ``store`` (default: the embedded data)
    from the scenarios' time on is drawn too, as in ``twin run --camera``: every
    recorded vehicle within the far plane on both carriageways (the westbound wave
    across the barrier, the eastbound traffic past the bench's own vehicles), but
    the eastbound ones where the bench's vehicles drive.

    Two passes of ``frames`` frames each repeat: the capture alone (renderer, labels,
    depth, poses), then the whole pipeline with the files written (PNGs, JSON, MP4; the
    writer runs on a thread, so it is measured as throughput: wall time including the
    final flush, over frames). Each pass also times the raw renderer
    (``getCameraImage``) on its own frames, and the overhead of labels and writing is
    the pipeline's time over the raw renderer's in the same pass. Means per frame
    within a pass, medians over the repeats.
    """
    from mapgen.build import default_map
    from twin.core.vehicle_classes import vehicle_classes

    table = vehicle_classes()
    bundle = default_map()
    recording = EmpiricalTraffic(store_or_default(store)) if replay else None
    drawn = _Drawn()
    capture, pipeline = [], []
    for repeat in range(repeats):
        states, ego = _eastbound_scene(table, np.random.default_rng(repeat), vehicles)
        times = _time_repeat(bundle, states, ego, renderer, recording, frames, drawn)
        capture.append(times[0])
        pipeline.append(times[1])
    return {
        "renderer": renderer,
        "vehicles": vehicles,
        "size": "640x480",
        "frames": frames,
        "repeats": repeats,
        **_camera_figures(capture, pipeline, drawn),
    }


def _eastbound_scene(table, rng: np.random.Generator, vehicles: int):
    """Spawn states of ``vehicles`` vehicles nose to tail in the four eastbound lanes,
    centred on the ego at 400 m, and the index of the ego."""
    from twin.core.i24 import LANE_WIDTH
    from twin.physics.states import SpawnStates

    lane = np.arange(vehicles) % 4
    classes = class_mix(table, rng, vehicles)
    ego = (vehicles // 2) // 4 * 4 + 1  # lane -2, in the middle of its lane
    classes[ego] = 0
    sizes = dimensions(table, classes)
    x = np.empty(vehicles)
    for k in range(4):  # nose to tail with 4 to 8 m gaps
        mine = np.flatnonzero(lane == k)
        room = sizes[0][mine] + rng.uniform(*GAPS, mine.size)
        x[mine] = np.concatenate([[0.0], np.cumsum(room)[:-1]])  # backs
    x += EGO_STATION - x[ego]
    speed = np.full(vehicles, SPEED)
    return SpawnStates.make(1, x, (1.5 + lane) * LANE_WIDTH, speed, classes, *sizes), ego


def _time_repeat(bundle, states, ego: int, renderer: str, recording, frames: int, drawn):
    """One repeat of the camera bench on the scene ``states``: the (capture, raw renderer)
    and (pipeline, raw renderer) seconds per frame of its two passes."""
    from sensors.camera import CameraRig, CameraSpec
    from sensors.writer import FrameWriter
    from twin.physics.world import PhysicsWorld

    with (
        PhysicsWorld(bundle) as world,
        tempfile.TemporaryDirectory(prefix="twin-bench-camera-") as tmp,
    ):
        ids = world.spawn(states)
        world.set_controls(accel=np.zeros(states.x.size))
        rig = CameraRig(world, bundle, (CameraSpec(),), renderer=renderer)
        traffic = None
        if recording is not None:
            traffic = _BenchRecording(recording, world, bundle.road, frames)
        try:
            ego_id = int(ids[ego])
            capture = _time_frames(world, rig, ego_id, traffic, frames, None, drawn)
            writer = FrameWriter(Path(tmp), rig.cameras)
            pipeline = _time_frames(world, rig, ego_id, traffic, frames, writer, drawn)
        finally:
            rig.close()
    return capture, pipeline


def _time_frames(world, rig, ego_id: int, traffic, frames: int, writer, drawn: _Drawn):
    """One pass of ``frames`` frames: the wall time [s] a frame of the capture (with the
    files written, and the writer's final flush, where ``writer`` is given) and of the
    raw renderer within it."""
    rig.view.raw_s = 0.0
    busy = 0.0
    for k in range(frames):
        for _ in range(STEPS_PER_FRAME):
            world.step()
        start = time.perf_counter()
        at = SCENARIO_TIME + FRAME_INTERVAL * k  # the morning sun of the scenarios
        if traffic is not None:
            traffic.t = at
        (frame,) = rig.capture(ego_id, time=at, sim_time=FRAME_INTERVAL * k, traffic=traffic)
        drawn.replayed.append(int(np.count_nonzero(frame.vehicles.replayed)))
        drawn.triangles.append(rig.view.vehicle_triangles())
        if writer is not None:
            writer.write(frame)
        busy += time.perf_counter() - start
    if writer is not None:
        start = time.perf_counter()
        writer.close()
        busy += time.perf_counter() - start
    return busy / frames, rig.view.raw_s / frames


def _camera_figures(capture: list, pipeline: list, drawn: _Drawn) -> dict:
    """The camera bench's figures from the passes' (time, raw renderer time) a frame
    [s], one pair a repeat, and what the frames drew."""
    capture = np.median(np.array(capture), axis=0)  # (capture, raw) per frame [s]
    pipeline = np.median(np.array(pipeline), axis=0)  # (pipeline, raw) per frame [s]
    return {
        "replayed_vehicles_median": median(drawn.replayed),
        # vehicle model triangles a frame: at their levels of detail, and full models
        "vehicle_triangles_median": median([t[0] for t in drawn.triangles]),
        "vehicle_triangles_full_median": median([t[1] for t in drawn.triangles]),
        "raw_ms": ms(pipeline[1], 2),
        "raw_fps": round(1.0 / float(pipeline[1]), 2),
        "capture_ms": ms(capture[0], 2),
        "capture_raw_ms": ms(capture[1], 2),
        "pipeline_ms": ms(pipeline[0], 2),
        "pipeline_fps": round(1.0 / float(pipeline[0]), 2),
        "labels_and_writing_overhead_percent": round(
            100.0 * float(pipeline[0] / pipeline[1] - 1), 1
        ),
    }


class _BenchRecording:
    """The recording drawn around the camera bench's scene (for ``CameraRig.capture``):
    the recorded vehicles within the far plane of the ego at time ``t`` (set before each
    capture), but the eastbound ones among the bench's own vehicles (their stations
    and 10 m either side), which are not recorded."""

    def __init__(self, recording, world, road_model, frames: int):
        from sensors.camera import CameraSpec
        from sensors.replay import HEADING_LEAD, RecordedView

        self.world, self.road_model = world, road_model
        self.t = SCENARIO_TIME
        self.view = RecordedView(recording, road_model, CameraSpec.far)
        self.view.preload(self.t, self.t + FRAME_INTERVAL * frames + HEADING_LEAD)
        self.none = np.zeros(len(recording.store.trajectory_arrays["id"]), dtype=bool)

    def replayed(self):
        states = self.world.states()
        station = self.road_model.station(1, states.x)
        replayed = self.view.around(self.t, float(np.median(station)), self.none)
        own = self.road_model.to_road(replayed.position).x if len(replayed) else np.empty(0)
        lo, hi = station.min() - MARGIN, station.max() + MARGIN
        among = (replayed.road > 0) & (own >= lo) & (own <= hi)
        return replayed.take(~among)

    def record_of(self, ids):
        ids = np.asarray(ids, np.int64)
        records = np.array([f"bench-{i}" for i in ids.tolist()], dtype=object)
        return records, np.ones(ids.size, np.int64)

    def tids_of(self, ids):
        """The bench's simulated vehicles stand for no recorded vehicle: their twin ids."""
        return np.full(len(ids), -1, np.int64)
