"""Camera frames to files, encoded on a background thread.

Layout under the writer's folder (one sub-folder per camera)::

    rig.json                      the cameras, the label encodings, the classes
    <camera>/rgb/000000.png       8-bit RGB
    <camera>/depth/000000.png     16-bit planar depth in millimetres: 0 where nothing
                                  lies within the far plane (sky), 65535 at 65.535 m
                                  or farther
    <camera>/semantic/000000.png  8-bit semantic class ids (rig.json "classes")
    <camera>/instance/000000.png  16-bit vehicle instance id + 1 (one per recorded
                                  vehicle all episode long); 0 where no vehicle
    <camera>/meta/000000.json     time, K, poses, the vehicles in view and their pixels
    <camera>/rgb.mp4              the RGB stream (OpenCV, mp4v) at the camera's rate

OpenCV's PNG encoder releases the GIL, so encoding on a thread overlaps with the
next frame's rendering on a second core. Frames are written in the order given;
the first error stops the writer and is raised by the next call.
"""

import json
import queue
import threading
from pathlib import Path

import cv2
import numpy as np

from mapgen.semantics import semantic_classes
from sensors.camera import CameraSpec, Frame
from twin.core.i24 import VEHICLE_CLASSES

DEPTH_SCALE = 1000.0  # [units per m] of the depth PNGs: millimetres
UINT16_MAX = 65535
PNG = [cv2.IMWRITE_PNG_COMPRESSION, 1]  # fast; PNG is lossless at every level
QUEUE_FRAMES = 8


class BackgroundWriter:
    """Calls ``write(item)`` for every item put, in order, on one background thread.

    The first error stops the writing (later items are dropped) and is raised, as an
    ``OSError`` naming ``what``, by the next :meth:`put` or by :meth:`close`.
    """

    def __init__(self, write, *, what: str, maxsize: int = QUEUE_FRAMES):
        self._write = write
        self._what = what
        self._queue: queue.Queue = queue.Queue(maxsize=maxsize)
        self._error: BaseException | None = None
        self.written = 0
        self._thread = threading.Thread(target=self._work, name=what, daemon=True)
        self._thread.start()

    def put(self, item) -> None:
        """Queue ``item`` (blocks while the queue is full).

        Raises:
            OSError: an earlier item could not be written.
        """
        self._raise()
        self._queue.put(item)

    def close(self) -> None:
        """Write what is queued and raise the first error."""
        if self._thread.is_alive():
            self._queue.put(None)
            self._thread.join()
        self._raise()

    def _raise(self) -> None:
        if self._error is not None:
            error, self._error = self._error, None
            raise OSError(f"{self._what} could not be written: {error}") from error

    def _work(self) -> None:
        while True:
            item = self._queue.get()
            if item is None:
                return
            if self._error is not None:
                continue  # drain; the error is raised on the caller's thread
            try:
                self._write(item)
                self.written += 1
            except Exception as error:
                self._error = error


class FrameWriter:
    """Writes frames under ``folder`` (see the module's layout), in a thread.

    Args:
        folder: where the camera folders go (created).
        cameras: the rig (for ``rig.json``).
        video: also write each camera's RGB stream as MP4.

    Use as a context manager, or call :meth:`close`; both wait for the last frame.
    """

    def __init__(self, folder: Path, cameras: tuple[CameraSpec, ...], *, video: bool = True):
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.video = video
        self._videos: dict[str, cv2.VideoWriter] = {}
        for camera in cameras:
            for kind in ("rgb", "depth", "semantic", "instance", "meta"):
                (self.folder / camera.name / kind).mkdir(parents=True, exist_ok=True)
        (self.folder / "rig.json").write_text(json.dumps(rig_description(cameras), indent=1))
        self._background = BackgroundWriter(self._write, what="camera frames")

    @property
    def frames_written(self) -> int:
        return self._background.written

    def write(self, frame: Frame) -> None:
        """Queue ``frame`` for writing (blocks while the queue is full).

        Raises:
            OSError: an earlier frame could not be written.
        """
        self._background.put(frame)

    def close(self) -> None:
        """Write what is queued, finish the videos, and raise the first error."""
        try:
            self._background.close()
        finally:
            for video in self._videos.values():
                video.release()
            self._videos.clear()

    def __enter__(self) -> "FrameWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _write(self, frame: Frame) -> None:
        camera = frame.camera
        folder = self.folder / camera.name
        stem = f"{frame.index:06d}"
        bgr = cv2.cvtColor(frame.rgb, cv2.COLOR_RGB2BGR)
        images = {
            "rgb": bgr,
            "depth": encode_depth(frame.depth),
            "semantic": frame.semantic,
            "instance": encode_instance(frame.instance),
        }
        write_pngs(folder, stem, images)
        (folder / "meta" / f"{stem}.json").write_text(json.dumps(frame_meta(frame), indent=1))
        if self.video:
            video = self._videos.get(camera.name)
            if video is None:
                path = folder / "rgb.mp4"
                fourcc = cv2.VideoWriter_fourcc(*"mp4v")
                video = cv2.VideoWriter(
                    str(path), fourcc, camera.rate_hz, (camera.width, camera.height)
                )
                if not video.isOpened():
                    raise OSError(f"OpenCV cannot write MP4 video to {path}")
                self._videos[camera.name] = video
            video.write(bgr)


def write_pngs(folder: Path, stem: str, images: dict[str, np.ndarray]) -> None:
    """Write each image as ``folder/<kind>/<stem>.png`` (fast, lossless).

    Raises:
        OSError: OpenCV could not write one.
    """
    for kind, image in images.items():
        path = folder / kind / f"{stem}.png"
        if not cv2.imwrite(str(path), image, PNG):
            raise OSError(f"OpenCV could not write {path}")


def encode_depth(
    depth: np.ndarray, units: float = DEPTH_SCALE, too_far: int = UINT16_MAX
) -> np.ndarray:
    """(h, w) uint16 planar depth [m] in ``units`` per metre (millimetres by default):
    0 where +inf (nothing), ``too_far`` where the value does not fit 16 bits (by
    default clipped to 65535, 65.535 m)."""
    values = np.rint(depth * units)
    values[values > UINT16_MAX] = too_far
    values[~np.isfinite(depth)] = 0
    return values.astype(np.uint16)


def decode_depth(image: np.ndarray, units: float = DEPTH_SCALE) -> np.ndarray:
    """Planar depth [m] (float32) of a depth PNG in ``units`` per metre; +inf where 0
    (nothing)."""
    depth = image.astype(np.float32) / units
    depth[image == 0] = np.inf
    return depth


def encode_instance(instance: np.ndarray) -> np.ndarray:
    """(h, w) uint16 twin id + 1 (0: no vehicle).

    Raises:
        ValueError: an id above 65534 (a run that spawned that many vehicles).
    """
    if instance.size and int(instance.max()) >= UINT16_MAX:
        raise ValueError(f"vehicle id {int(instance.max())} does not fit a 16-bit instance PNG")
    return (instance + 1).astype(np.uint16)


def vehicle_source(vehicles, i: int) -> dict:
    """Where drawn vehicle ``i`` comes from: ``source`` (``simulated``, a physics body,
    or ``replayed`` from the recording), its ``record_id`` (I-24 MOTION ``_id``) and
    its ``road``."""
    road = int(vehicles.road[i])
    return {
        "source": "replayed" if vehicles.replayed[i] else "simulated",
        "record_id": str(vehicles.record_id[i]) or None,
        "road": {1: "eastbound", -1: "westbound"}.get(road),
    }


def _centre(vehicles, i: int) -> np.ndarray:
    """World centre of drawn vehicle ``i``'s box."""
    return vehicles.position[i] + vehicles.rotation[i][:, 2] * 0.5 * vehicles.size[i, 2]


def frame_meta(frame: Frame) -> dict:
    """The JSON-ready description of a frame: time, calibration, poses, vehicles."""
    counts = np.bincount(frame.instance.reshape(-1) + 1)
    vehicles = frame.vehicles
    origin = frame.world_from_camera[:3, 3]
    in_view = [
        {
            "id": int(twin_id),
            "class": VEHICLE_CLASSES[int(vehicles.vehicle_class[i])],
            "pixels": int(counts[twin_id + 1]),
            **vehicle_source(vehicles, i),
            "distance_m": round(float(np.linalg.norm(_centre(vehicles, i) - origin)), 3),
        }
        for i, twin_id in enumerate(vehicles.id.tolist())
        if twin_id + 1 < counts.size and counts[twin_id + 1] > 0
    ]
    camera = frame.camera
    return {
        "camera": camera.name,
        "frame": frame.index,
        "time": frame.time,
        "sim_time": round(frame.sim_time, 9),
        "ego_id": frame.ego_id,
        "renderer": frame.renderer,
        "light": frame.light,
        "width": camera.width,
        "height": camera.height,
        "K": frame.K.tolist(),
        "near_m": camera.near,
        "far_m": camera.far,
        "world_from_camera": frame.world_from_camera.tolist(),
        "ego_from_camera": frame.ego_from_camera.tolist(),
        "vehicles": in_view,
    }


def rig_description(cameras: tuple[CameraSpec, ...]) -> dict:
    """What ``rig.json`` holds: cameras, encodings, frames and classes."""
    return {
        "cameras": [
            {
                "name": c.name,
                "reference": c.reference,
                "mount_m": list(c.mount),
                "yaw_deg": c.yaw_deg,
                "pitch_deg": c.pitch_deg,
                "roll_deg": c.roll_deg,
                "width": c.width,
                "height": c.height,
                "hfov_deg": c.hfov_deg,
                "near_m": c.near,
                "far_m": c.far,
                "rate_hz": c.rate_hz,
                "K": c.K.tolist(),
            }
            for c in cameras
        ],
        "encodings": {
            "rgb": "8-bit RGB PNG",
            "depth": "16-bit PNG, planar depth in millimetres; 0: nothing within the far "
            "plane; 65535: 65.535 m or farther",
            "semantic": "8-bit PNG of class ids",
            "instance": "16-bit PNG of vehicle instance id + 1 (one per recorded vehicle "
            "all episode long, simulated or replayed); 0: no vehicle",
        },
        "frames": {
            "camera": "OpenCV: x right, y down, z forward; pixel (0, 0) is the centre of "
            "the top-left pixel",
            "vehicle": "origin on the ground below the centre of the vehicle's box, x "
            "forward, y left, z up",
            "world": "east-north-up metres, origin on the median at MM 60.6",
        },
        "classes": [
            {"id": c.class_id, "name": c.name, "color": c.color} for c in semantic_classes()
        ],
    }
