"""Calibrated pinhole cameras mounted on a vehicle, rendered off-screen.

Frames and conventions:

* vehicle frame: origin on the ground below the centre of the vehicle's box, x
  forward, y left, z up (the drawn model's box is ``[-L/2, L/2] x [-W/2, W/2] x
  [0, H]`` in it);
* a mount is given from a reference point of the vehicle (its front bumper, centre
  or rear bumper, on the ground), so one rig fits a sedan and a semi alike;
* camera frame: OpenCV's, x right, y down, z forward (the optical axis); poses are
  4x4 ``world_from_camera`` and ``ego_from_camera`` matrices in metres;
* pixels: OpenCV's, (u, v) = (0, 0) is the centre of the top-left pixel; ``K`` is
  ``[[f, 0, cx], [0, f, cy], [0, 0, 1]]`` with square pixels and the principal point
  at the image centre, ``cx = (width - 1) / 2``;
* depth: planar (along the optical axis), metres, float32; +inf where nothing lies
  within the far plane (the sky).
"""

import math
from dataclasses import dataclass, field, replace
from functools import cache
from pathlib import Path

import numpy as np
import pandas as pd

from mapgen.build import MapBundle
from sensors.shadows import Casters, darken, map_casters, shade_factor, shadow_mask
from sensors.sun import SUN_MODES, episode_light
from twin.core.errors import TwinError
from twin.core.paths import asset
from twin.core.timeutil import steps_per_sample
from twin.physics.render import REPLAY_BASE, DrawnVehicles, SceneView, resolve_renderer
from twin.physics.world import PhysicsWorld

SUN_STREAM = 0x53554E  # seeds an episode's random sun apart from its other draws
MAX_INSTANCE_ID = 65534  # instance images hold id + 1 in 16 bits

MOUNTS_CSV = "camera_mounts.csv"
REFERENCES = {"front": 0.5, "centre": 0.0, "rear": -0.5}  # of the vehicle's length
# OpenCV camera axes in a camera body frame that looks along its x (y left, z up)
CV_IN_BODY = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
GL_FROM_CV = np.diag([1.0, -1.0, -1.0, 1.0])  # OpenGL cameras look down their -z, y up


class CameraError(TwinError, ValueError):
    """A camera or rig setting is impossible."""


@dataclass(frozen=True)
class CameraSpec:
    """One camera of a rig.

    Attributes:
        name: folder name of its frames (letters, digits, ``_`` and ``-``).
        reference: ``front``, ``centre`` or ``rear`` of the vehicle, on the ground.
        mount: [m] position from the reference: forward (negative: behind it), left,
            up.
        yaw_deg, pitch_deg, roll_deg: [deg] orientation in the vehicle frame: yaw to
            the left, pitch up, roll clockwise as seen from behind, applied in that
            order; all zero looks straight ahead.
        width, height: [px] image size.
        hfov_deg: [deg] horizontal field of view.
        near, far: [m] clipping planes; depth is measured within them.
        rate_hz: [Hz] frames per simulated second.
    """

    name: str = "front"
    reference: str = "front"
    mount: tuple[float, float, float] = (-1.9, 0.0, 1.65)  # on the roof, KITTI's height
    yaw_deg: float = 0.0
    pitch_deg: float = 0.0
    roll_deg: float = 0.0
    width: int = 640
    height: int = 480
    hfov_deg: float = 80.0
    near: float = 0.5
    far: float = 300.0
    rate_hz: float = 10.0

    def __post_init__(self):
        if not self.name or not all(c.isalnum() or c in "_-" for c in self.name):
            raise CameraError(f"camera name must be letters, digits, _ or -, got {self.name!r}")
        if self.reference not in REFERENCES:
            raise CameraError(
                f"camera {self.name}: reference must be one of {sorted(REFERENCES)}, "
                f"got {self.reference!r}"
            )
        mount = tuple(float(v) for v in self.mount)
        if len(mount) != 3 or not all(math.isfinite(v) for v in mount):
            raise CameraError(f"camera {self.name}: mount must be 3 finite numbers [m]")
        object.__setattr__(self, "mount", mount)
        for name in ("yaw_deg", "pitch_deg", "roll_deg", "hfov_deg", "near", "far", "rate_hz"):
            value = getattr(self, name)
            if isinstance(value, bool) or not math.isfinite(value):
                raise CameraError(f"camera {self.name}: {name} must be finite, got {value!r}")
        for name in ("width", "height"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or not 16 <= value <= 4096:
                raise CameraError(f"camera {self.name}: {name} must be 16..4096 px, got {value!r}")
        if not 1.0 <= self.hfov_deg <= 170.0:
            raise CameraError(
                f"camera {self.name}: hfov_deg must be in 1..170, got {self.hfov_deg}"
            )
        if not 0.0 < self.near < self.far:
            raise CameraError(
                f"camera {self.name}: need 0 < near < far, got near {self.near}, far {self.far}"
            )
        if not self.rate_hz > 0:
            raise CameraError(f"camera {self.name}: rate_hz must be > 0, got {self.rate_hz}")

    @property
    def focal(self) -> float:
        """[px] focal length (square pixels)."""
        return 0.5 * self.width / math.tan(math.radians(0.5 * self.hfov_deg))

    @property
    def K(self) -> np.ndarray:
        """(3, 3) intrinsic matrix (OpenCV conventions)."""
        f = self.focal
        return np.array(
            [[f, 0.0, 0.5 * (self.width - 1)], [0.0, f, 0.5 * (self.height - 1)], [0, 0, 1.0]]
        )

    def vehicle_from_camera(self, length: float) -> np.ndarray:
        """(4, 4) pose of the camera (OpenCV axes) in the frame of a vehicle ``length``
        [m] long."""
        yaw, pitch, roll = (math.radians(v) for v in (self.yaw_deg, self.pitch_deg, self.roll_deg))
        body = _rot_z(yaw) @ _rot_y(-pitch) @ _rot_x(roll)
        pose = np.eye(4)
        pose[:3, :3] = body @ CV_IN_BODY
        pose[:3, 3] = [REFERENCES[self.reference] * length + self.mount[0], *self.mount[1:]]
        return pose

    def projection_matrix(self) -> list[float]:
        """OpenGL projection of ``K`` with this camera's near and far planes, as the 16
        column-major floats pybullet takes."""
        n, f = self.near, self.far
        k = self.K
        projection = np.zeros((4, 4))
        projection[0, 0] = 2.0 * k[0, 0] / self.width
        projection[0, 2] = 1.0 - 2.0 * (k[0, 2] + 0.5) / self.width
        projection[1, 1] = 2.0 * k[1, 1] / self.height
        projection[1, 2] = 2.0 * (k[1, 2] + 0.5) / self.height - 1.0
        projection[2, 2] = -(f + n) / (f - n)
        projection[2, 3] = -2.0 * f * n / (f - n)
        projection[3, 2] = -1.0
        return projection.T.reshape(-1).tolist()

    def depth_from_buffer(self, buffer: np.ndarray) -> np.ndarray:
        """Planar metric depth [m] (float32, +inf where nothing) of a depth buffer."""
        n, f = self.near, self.far
        with np.errstate(divide="ignore"):
            depth = (f * n) / (f - (f - n) * buffer.astype(np.float64))
        depth[buffer >= 1.0] = np.inf
        return depth.astype(np.float32)


def view_matrix(world_from_camera: np.ndarray) -> list[float]:
    """The OpenGL view matrix of a camera pose (OpenCV axes), 16 column-major floats."""
    view = GL_FROM_CV @ np.linalg.inv(world_from_camera)
    return view.T.reshape(-1).tolist()


@cache
def camera_mounts(path: Path | None = None) -> dict[str, CameraSpec]:
    """Named mounts (``assets/camera_mounts.csv`` or ``path``) as cameras with the
    default image settings.

    Raises:
        CameraError: naming the file and the bad row or column.
    """
    path = Path(path) if path is not None else asset(MOUNTS_CSV)
    try:
        frame = pd.read_csv(path)
    except (OSError, pd.errors.ParserError, pd.errors.EmptyDataError) as error:
        raise CameraError(f"cannot read camera mounts {path}: {error}") from None
    columns = ["name", "reference", "x_m", "y_m", "z_m", "yaw_deg", "pitch_deg", "roll_deg"]
    missing = [c for c in columns if c not in frame.columns]
    if missing:
        raise CameraError(f"{path}: missing columns {missing}")
    if frame["name"].duplicated().any():
        raise CameraError(f"{path}: camera names must be unique")
    mounts = {}
    for row in frame.itertuples():
        try:
            mounts[str(row.name)] = CameraSpec(
                name=str(row.name),
                reference=str(row.reference),
                mount=(float(row.x_m), float(row.y_m), float(row.z_m)),
                yaw_deg=float(row.yaw_deg),
                pitch_deg=float(row.pitch_deg),
                roll_deg=float(row.roll_deg),
            )
        except (CameraError, ValueError) as error:
            raise CameraError(f"{path}: row {row.Index + 2}: {error}") from None
    return mounts


@dataclass(frozen=True, eq=False)
class Frame:
    """One camera frame with its labels and calibration.

    Attributes:
        camera: the camera.
        index: frame number of this camera's stream (0, 1, ...).
        time: [s] unix time; sim_time: [s] since the episode began.
        rgb: (h, w, 3) uint8. depth: (h, w) float32 [m] planar, +inf: nothing.
        semantic: (h, w) uint8 class ids. instance: (h, w) int64 instance ids (twin
            ids; with recorded traffic, each recorded vehicle's own), -1: none.
        world_from_camera, ego_from_camera: (4, 4) poses (OpenCV camera axes).
        ego_id: the twin id of the vehicle carrying the camera.
        vehicles: the other vehicles as drawn (3D boxes in the world).
        renderer: ``tiny`` or ``egl``.
        light: the light it was taken in (:func:`sensors.sun.episode_light`'s record).
    """

    camera: CameraSpec
    index: int
    time: float
    sim_time: float
    rgb: np.ndarray
    depth: np.ndarray
    semantic: np.ndarray
    instance: np.ndarray
    world_from_camera: np.ndarray
    ego_from_camera: np.ndarray
    ego_id: int
    vehicles: DrawnVehicles
    renderer: str
    light: dict = field(default_factory=dict)

    @property
    def K(self) -> np.ndarray:
        return self.camera.K


@dataclass
class CameraRig:
    """Cameras on one vehicle of a physics world, rendered through its scene view.

    Args:
        world: the physics world (its client renders).
        bundle: the map (visual parts and vehicle models).
        cameras: the rig.
        renderer: ``auto``, ``tiny`` or ``egl`` (see :func:`resolve_renderer`).
        dt: [s] the simulation step; each camera's rate must divide its rate.
        sun: the light (see :class:`CameraSettings`).
        shadows: the sun casts shadows (see :class:`CameraSettings`).
        seed: draws the episode's sun when ``sun`` is ``random``.

    Raises:
        CameraError: no camera, repeated names, or a rate that does not divide 1/dt.
        RuntimeError: the renderer cannot start.
    """

    world: PhysicsWorld
    bundle: MapBundle
    cameras: tuple[CameraSpec, ...] = (CameraSpec(),)
    renderer: str = "auto"
    dt: float = 0.01
    sun: str = "recorded"
    shadows: bool = True
    seed: int = 0
    view: SceneView = field(init=False)
    _counts: dict[str, int] = field(init=False)
    _drawn_light: tuple | None = field(init=False, default=None)
    _map_casters: Casters = field(init=False)
    _replay_ids: dict = field(init=False, default_factory=dict)

    def __post_init__(self):
        self.cameras = tuple(self.cameras)
        check_rig(self.cameras, self.dt)
        try:
            kind = resolve_renderer(self.renderer)
        except ValueError as error:
            raise CameraError(str(error)) from None
        if self.sun not in SUN_MODES:
            raise CameraError(f"sun must be one of {', '.join(SUN_MODES)}, got {self.sun!r}")
        if self.sun == "random":  # one sun for the episode
            rng = np.random.default_rng([self.seed, SUN_STREAM])
            self._drawn_light = episode_light("random", 0.0, shadows=self.shadows, rng=rng)
        self.view = SceneView(self.world, self.bundle, kind)
        self.view.lod_focal = max(max(c.K[0][0], c.K[1][1]) for c in self.cameras)
        self._counts = {c.name: 0 for c in self.cameras}
        self._map_casters = map_casters(self.bundle)

    def _eye(self, ego_id: int, cameras) -> tuple[np.ndarray | None, float]:
        """The centre of vehicle ``ego_id`` [m, world] and how far from it its
        ``cameras`` are at most [m], for the levels of detail; (None, 0) where it is not
        active (``capture`` says so)."""
        states = self.world.states()
        at = np.flatnonzero(states.id == ego_id)
        if at.size == 0:
            return None, 0.0
        params = self.world.params
        length, height = float(params.length[at[0]]), float(params.height[at[0]])
        reach = max(np.linalg.norm(c.vehicle_from_camera(length)[:3, 3]) for c in cameras)
        return states.position[at[0]], reach + height

    def _pose_replayed(self, replayed, eye=None, margin: float = 0.0) -> DrawnVehicles:
        """Pose the replayed vehicles (none: release them); their drawn boxes."""
        if replayed is None or len(replayed) == 0:
            self.view.pose_replayed(np.empty(0, np.int64), [], np.empty((0, 3)), [], [])
            return _no_vehicles()
        ids = np.array([self._replay_id(int(t)) for t in replayed.tid.tolist()], np.int64)
        sizes = self.view.pose_replayed(
            ids,
            replayed.vehicle_class,
            replayed.size,
            replayed.position,
            replayed.rotation,
            eye=eye,
            margin=margin,
        )
        n = ids.size
        return DrawnVehicles(
            id=ids,
            vehicle_class=np.asarray(replayed.vehicle_class, np.int64),
            size=sizes,
            position=replayed.position,
            rotation=replayed.rotation,
            speed=replayed.speed,
            shown=np.ones(n, bool),
            replayed=np.ones(n, bool),
            record_id=np.asarray(replayed.record_id, object),
            road=np.asarray(replayed.road, np.int64),
        )

    def _by_record(self, drawn: DrawnVehicles, traffic) -> tuple[DrawnVehicles, np.ndarray]:
        """The simulated vehicles of ``drawn`` relabelled with their records' instance
        ids (those their recordings have when replayed): one id per recorded vehicle all
        episode long, whether it is simulated or replayed at the frame, so that a
        dataset's track of it goes on through the ghost-cell boundary. Returns the
        relabelled vehicles and the lookup from the rendered ids to the labelled ones."""
        simulated = np.flatnonzero(~drawn.replayed)
        tids = np.asarray(traffic.tids_of(drawn.id[simulated]), np.int64)
        simulated = simulated[tids >= 0]  # a vehicle with no recording keeps its twin id
        ids = drawn.id.copy()
        ids[simulated] = [self._replay_id(int(t)) for t in tids[tids >= 0].tolist()]
        relabel = np.arange(MAX_INSTANCE_ID + 1, dtype=np.int64)
        relabel[drawn.id[simulated]] = ids[simulated]
        return replace(drawn, id=ids), relabel

    def _replay_id(self, tid: int) -> int:
        """The instance id of recorded trajectory ``tid`` in this episode."""
        known = self._replay_ids.get(tid)
        if known is None:
            known = REPLAY_BASE + len(self._replay_ids)
            if known >= MAX_INSTANCE_ID:
                raise CameraError(
                    f"more than {MAX_INSTANCE_ID - REPLAY_BASE} recorded vehicles seen in one "
                    "episode: the 16-bit instance images cannot tell them apart"
                )
            self._replay_ids[tid] = known
        return known

    def light_at(self, time: float):
        """(Light, its record) of a frame at unix ``time`` [s]."""
        if self._drawn_light is not None:
            return self._drawn_light
        return episode_light(self.sun, time, shadows=self.shadows)

    def close(self) -> None:
        self.view.close()

    def due(self, step: int) -> tuple[CameraSpec, ...]:
        """The cameras that take a frame at simulation step ``step`` (0 at reset)."""
        return tuple(c for c in self.cameras if step % steps_per_sample(c.rate_hz, self.dt) == 0)

    def capture(
        self,
        ego_id: int,
        cameras: tuple[CameraSpec, ...] | None = None,
        *,
        time: float = 0.0,
        sim_time: float = 0.0,
        traffic=None,
    ) -> list[Frame]:
        """Render ``cameras`` (default: all) of the rig on vehicle ``ego_id`` now.

        Args:
            traffic: the recording around a cosimulation
                (:class:`sensors.replay.FrameTraffic`): its recorded vehicles are drawn
                beside the simulated ones, and every vehicle of a recording,
                simulated or replayed, has its record's instance id from
                ``REPLAY_BASE`` up (the same all episode long: a track of it goes on
                through the ghost-cell boundary) and its record. ``None``: only the
                physics world's vehicles, with their twin ids.

        Raises:
            KeyError: ``ego_id`` is not an active vehicle.
            CameraError: more replayed vehicles in an episode than instance ids.
        """
        cameras = self.cameras if cameras is None else cameras
        eye, margin = self._eye(ego_id, cameras)
        everyone = self.view.vehicles(hide=[ego_id], eye=eye, margin=margin)
        replayed, relabel = None, None
        if traffic is not None:
            records, roads = traffic.record_of(everyone.id)
            everyone = replace(everyone, record_id=np.asarray(records, object), road=roads)
            replayed = traffic.replayed()
        drawn = DrawnVehicles.join(
            everyone.take(everyone.shown), self._pose_replayed(replayed, eye, margin)
        )
        if traffic is not None:
            drawn, relabel = self._by_record(drawn, traffic)
        ego = np.flatnonzero(everyone.id == ego_id)
        if ego.size == 0:
            raise KeyError(f"vehicle {ego_id} is not active in the physics world")
        world_from_ego = np.eye(4)
        world_from_ego[:3, :3] = everyone.rotation[ego[0]]
        world_from_ego[:3, 3] = everyone.position[ego[0]]
        length = float(everyone.size[ego[0], 0])
        light, light_record = self.light_at(time)
        casters = Casters.join(
            self._map_casters,
            Casters.on_ground(everyone.position, everyone.rotation, everyone.size),
            Casters.on_ground(
                drawn.position[drawn.replayed],
                drawn.rotation[drawn.replayed],
                drawn.size[drawn.replayed],
            ),
        )  # the ego's own shadow too: it is hidden from its cameras, not from the sun
        frames = []
        for camera in cameras:
            ego_from_camera = camera.vehicle_from_camera(length)
            world_from_camera = world_from_ego @ ego_from_camera
            picture, rgb = self._render(camera, world_from_camera, light, casters)
            instance = picture.instance
            if relabel is not None:
                instance = np.where(instance >= 0, relabel[np.maximum(instance, 0)], -1)
            frames.append(
                Frame(
                    camera=camera,
                    index=self._counts[camera.name],
                    time=time,
                    sim_time=sim_time,
                    rgb=rgb,
                    depth=camera.depth_from_buffer(picture.depth_buffer),
                    semantic=picture.semantic,
                    instance=instance,
                    world_from_camera=world_from_camera,
                    ego_from_camera=ego_from_camera,
                    ego_id=int(ego_id),
                    vehicles=drawn,
                    renderer=self.view.renderer.value,
                    light=light_record,
                )
            )
            self._counts[camera.name] += 1
        return frames

    def _render(self, camera: CameraSpec, world_from_camera, light, casters):
        """One camera's picture (its buffers) and its RGB in the light, shadows cast by
        ``casters`` where the light has them."""
        picture = self.view.render(
            view_matrix(world_from_camera),
            camera.projection_matrix(),
            camera.width,
            camera.height,
            light,
        )
        if not light.shadows:
            return picture, picture.rgb
        mask = shadow_mask(
            casters,
            np.asarray(light.direction),
            camera.K,
            np.linalg.inv(world_from_camera),
            camera.width,
            camera.height,
            camera.near,
        )
        shade = shade_factor(light.ambient, light.diffuse, np.asarray(light.direction))
        return picture, darken(picture.rgb, picture.semantic, mask, shade)


def _no_vehicles() -> DrawnVehicles:
    empty = np.empty(0, np.int64)
    return DrawnVehicles(
        empty, empty, np.empty((0, 3)), np.empty((0, 3)), np.empty((0, 3, 3)), np.empty(0),
        np.empty(0, bool),
    )  # fmt: skip


def check_rig(cameras: tuple[CameraSpec, ...], dt: float) -> None:
    """Raise :class:`CameraError` unless the rig has cameras with unique names whose
    rates divide the step rate ``1 / dt``."""
    if not cameras:
        raise CameraError("a camera rig needs at least one camera")
    names = [c.name for c in cameras]
    if len(set(names)) != len(names):
        raise CameraError(f"camera names must be unique, got {names}")
    for camera in cameras:
        try:
            steps_per_sample(camera.rate_hz, dt)
        except ValueError as error:
            raise CameraError(f"camera {camera.name}: rate {error}") from None


def _rot_x(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _rot_y(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _rot_z(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


@dataclass(frozen=True)
class CameraSettings:
    """The cameras of a run (``[camera]`` in a run's TOML).

    Attributes:
        enabled: render and write frames (``twin run --camera``).
        renderer: ``auto`` (EGL when a GPU is present, else TinyRenderer), ``tiny``
            or ``egl``.
        cameras: names of mounts in ``mounts`` making up the rig.
        mounts: CSV of named mounts; empty: ``assets/camera_mounts.csv``.
        width, height: [px] image size, the same for every camera of the rig (as the
            settings below).
        hfov_deg: [deg] horizontal field of view.
        near, far: [m] clipping planes; depth is measured within them.
        rate_hz: [Hz] frames per simulated second.
        video: also write each camera's RGB stream as MP4.
        sun: the light: ``recorded`` (the sun over the segment at the frame's time,
            from its date and the segment's latitude and longitude), ``noon`` (the
            paper's high noon, no shadows) or ``random`` (drawn once per episode from
            the run's seed); see :mod:`sensors.sun`.
        shadows: the sun casts shadows (``recorded`` and ``random``).
    """

    enabled: bool = False
    renderer: str = "auto"
    cameras: tuple[str, ...] = ("front",)
    mounts: str = ""
    width: int = CameraSpec.width
    height: int = CameraSpec.height
    hfov_deg: float = CameraSpec.hfov_deg
    near: float = CameraSpec.near
    far: float = CameraSpec.far
    rate_hz: float = CameraSpec.rate_hz
    video: bool = True
    sun: str = "recorded"
    shadows: bool = True

    def __post_init__(self):
        if self.renderer not in ("auto", "tiny", "egl"):
            raise CameraError(f"renderer must be auto, tiny or egl, got {self.renderer!r}")
        if self.sun not in SUN_MODES:
            raise CameraError(f"sun must be one of {', '.join(SUN_MODES)}, got {self.sun!r}")
        self.rig()

    def rig(self) -> tuple[CameraSpec, ...]:
        """The cameras, mounts from the mounts file with these image settings.

        Raises:
            CameraError: an unknown camera name or an impossible setting.
        """
        mounts = camera_mounts(Path(self.mounts) if self.mounts else None)
        unknown = [name for name in self.cameras if name not in mounts]
        if unknown:
            raise CameraError(f"unknown camera(s) {unknown}; the mounts are {sorted(mounts)}")
        if not self.cameras:
            raise CameraError("the rig needs at least one camera")
        return tuple(
            replace(
                mounts[name],
                width=self.width,
                height=self.height,
                hfov_deg=self.hfov_deg,
                near=self.near,
                far=self.far,
                rate_hz=self.rate_hz,
            )
            for name in self.cameras
        )
