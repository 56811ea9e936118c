"""``twin run``: one cosimulation episode written as a run folder.

The folder (written under a temporary name and renamed when complete)::

    <out>/
      config.toml            the resolved configuration (loads back with --config)
      trajectories.parquet   every simulated vehicle every step, ghosts at a lower rate
      metrics.json           fidelity, counts, physical checks, timing
      timespace.png          recorded traffic with the simulated ego over it
      boundary.png           the visible window's edges zoomed (relaxing vehicles, ghosts)
      bev.png                bird's-eye view of the windows at ``bev_time``
      bev.mp4                the same for the whole episode (``bev_video``)
      cameras/               the ego's camera frames (``camera.enabled``; see
                             :mod:`sensors.writer` for the layout)
"""

import hashlib
import json
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sensors.camera import CameraRig, Frame
from sensors.replay import FrameTraffic
from sensors.writer import FrameWriter
from twin import __version__
from twin.calibration.calibrate import CALIBRATION
from twin.core.atomic import AtomicFolder, marked_as
from twin.core.errors import StoreError
from twin.core.locks import build_lock
from twin.core.paths import cache_dir
from twin.core.timeutil import steps_per_sample
from twin.cosim import plots
from twin.cosim.behaviour import AUTO, Behaviour
from twin.cosim.config import ConfigError, CosimConfig, to_toml
from twin.cosim.cosimulator import Cosimulator
from twin.cosim.log import write_parquet
from twin.data.empirical import EmpiricalTraffic
from twin.data.store import TrajectoryStore, is_store, open_store
from twin.metrics.measure import RUN_FORMAT, measure
from twin.traffic.controller_api import EgoController

METRICS = "metrics.json"
CAMERAS = "cameras"


class Cameras:
    """The ego's camera rig during a run: frames at each camera's rate, written by a
    :class:`FrameWriter`; called with the cosimulator after every step."""

    def __init__(self, sim: Cosimulator, bundle, folder: Path):
        settings = sim.config.camera
        self.rig = CameraRig(
            sim.world,
            bundle,
            settings.rig(),
            renderer=settings.renderer,
            dt=sim.config.dt,
            sun=settings.sun,
            shadows=settings.shadows,
            seed=sim.config.seed,
        )
        self.writer = FrameWriter(folder, self.rig.cameras, video=settings.video)
        self.render_s = 0.0
        self.frames = 0
        self.traffic: FrameTraffic | None = None

    def __call__(self, sim: Cosimulator) -> None:
        due = self.rig.due(sim.step_index)
        if due:
            start = time.perf_counter()
            if self.traffic is None:  # after the reset: the episode's time is known
                far = max(c.far for c in self.rig.cameras)
                self.traffic = FrameTraffic(sim, sim.world.road, far)
            frames = self.rig.capture(
                sim.ego_id,
                due,
                time=sim.t,
                sim_time=sim.sim_time,
                traffic=self.traffic,
            )
            self.render_s += time.perf_counter() - start
            for frame in frames:
                self.writer.write(frame)
            self.frames += len(frames)

    def summary(self) -> dict:
        return {
            "renderer": self.rig.view.renderer.value,
            "cameras": [c.name for c in self.rig.cameras],
            "frames": self.frames,
            "render_s": round(self.render_s, 3),
            "frames_per_s": round(self.frames / self.render_s, 2) if self.render_s else None,
        }

    def __enter__(self) -> "Cameras":
        return self

    def __exit__(self, *exc) -> None:
        try:
            self.writer.close()
        finally:
            self.rig.close()


@dataclass(frozen=True)
class RunResult:
    """What ``run_episode`` wrote and measured."""

    folder: Path
    metrics: dict
    ego_speed: np.ndarray  # [m/s] the simulated ego, one value per second
    ego_controller: str = ""  # what drove the ego ("": the traffic manager, as the others)
    behaviour_note: str = ""  # why ``auto`` chose a calibrated behaviour, and how not to


#: What each entry of a run folder holds, in the order ``twin run`` lists them.
FOLDER_CONTENTS = {
    "config.toml": "the resolved settings (twin run --config repeats the run)",
    "trajectories.parquet": "the ego and simulated vehicles every step, ghosts at the log rate",
    "metrics.json": "fidelity to the recording, counts, energy, control figures, timing",
    "timespace.png": "time-space diagram: recorded traffic, simulated vehicles, the ego",
    "boundary.png": "the visible window's edges zoomed: vehicles relaxing, ghosts, any jump",
    "bev.png": "bird's-eye view of the visible window and ghost cells",
    "bev.mp4": "the bird's-eye view over the whole episode",
    CAMERAS: "the ego's camera frames and labels",
}


def open_data(data: str | os.PathLike | None, *, progress: bool = True) -> TrajectoryStore:
    """The trajectory data of a run: the embedded default store (``None``), another
    embedded store (``embedded:morning``, see :mod:`twin.data.embedded`), a store folder,
    or an I-24 MOTION JSON day file (ingested once into the cache).

    Raises:
        StoreError: the path does not exist, is neither a store folder nor a JSON
            file, or names an unknown embedded store.
    """
    from twin.data.embedded import default_store, embedded_name, embedded_store
    from twin.data.ingest import ingest

    if data is None:
        return default_store(progress=progress)
    if (name := embedded_name(data)) is not None:
        return embedded_store(name, progress=progress)
    path = Path(data)
    if not path.exists():
        raise StoreError(f"--data {path}: no such file or folder")
    if path.is_dir():
        if not is_store(path) and not (path / "metadata.json").exists():
            raise StoreError(f"--data {path} is a folder but not an i24-twin store")
        return open_store(path)  # a damaged store's error names the file
    if path.suffix.lower() != ".json":
        raise StoreError(f"--data {path}: expected a store folder or an I-24 MOTION .json file")
    digest = hashlib.sha256()
    with path.open("rb") as f:
        for block in iter(lambda: f.read(1 << 22), b""):
            digest.update(block)
    folder = cache_dir() / f"store-{digest.hexdigest()[:16]}"
    if not is_store(folder):
        with build_lock(folder):  # another process may be ingesting it
            if not is_store(folder):
                ingest([path], folder, progress=progress)
    return open_store(folder)


def run_episode(
    config: CosimConfig,
    store: TrajectoryStore,
    out: str | os.PathLike,
    *,
    bundle=None,
    controller: EgoController | None = None,
    progress: bool = True,
) -> RunResult:
    """Run one episode and write its run folder ``out`` (replacing an earlier run there).

    Raises:
        NoVehicleNearError, ScenarioError: the scenario cannot start on these data.
        ControllerError: the ego controller cannot be loaded or fails.
        TwinError: ``out`` exists and is not a run folder.
    """
    from mapgen.build import default_map

    bundle = bundle or default_map(progress=progress)
    traffic = EmpiricalTraffic(store)
    folder = AtomicFolder(Path(out), recognise=is_run, kind="run folder")
    folder.check_replaceable()
    with Cosimulator(config, traffic, bundle, controller=controller) as sim, folder:
        note = _behaviour_note(config, sim.behaviour)
        setup = time.perf_counter()
        sim.reset()
        start = time.perf_counter()
        cameras = None
        if config.camera.enabled:
            with Cameras(sim, bundle, folder.tmp / CAMERAS) as cameras:
                cameras(sim)
                sim.run(progress=progress, on_step=cameras)
        else:
            sim.run(progress=progress)
        loop_s = time.perf_counter() - start
        figures = _write_folder(folder.tmp, sim, store, bundle, loop_s, start - setup, cameras)
    ego = figures.pop("_ego_speed")
    name = config.ego_controller
    if controller is not None:
        kind = (
            controller
            if callable(controller) and hasattr(controller, "__qualname__")
            else (type(controller))
        )
        name = f"{kind.__module__}:{kind.__qualname__}"
    return RunResult(folder.out, figures, ego, name, note)


def _behaviour_note(config: CosimConfig, behaviour: Behaviour) -> str:
    """Where ``auto`` took the store's calibration, which one (the one the run drives
    by) and how to run without it: calibrating a store changes what ``twin run`` on it
    does from then on."""
    if config.behaviour != AUTO or behaviour.name == "paper":
        return ""
    return (
        f"auto chose {behaviour.name}: the data hold a calibration ({CALIBRATION} "
        f"made {behaviour.calibrated_at}); --behaviour paper drives as the paper does"
    )


def render_at(
    config: CosimConfig,
    store: TrajectoryStore,
    t: float,
    *,
    camera: str | None = None,
    bundle=None,
) -> Frame:
    """One frame of the ego's camera ``camera`` (default: the rig's first) ``t`` seconds
    after t0 of ``config``'s episode; nothing is written.

    Raises:
        ConfigError: ``t`` outside the episode or an unknown camera.
        NoVehicleNearError, ScenarioError: the scenario cannot start on these data.
    """
    from mapgen.build import default_map

    rig = config.camera.rig()
    chosen = [c for c in rig if camera is None or c.name == camera]
    if not chosen:
        raise ConfigError(f"no camera {camera!r} in the rig {[c.name for c in rig]}")
    if not 0.0 <= t <= config.t_max:
        raise ConfigError(f"--t must be in [0, t_max = {config.t_max}] s, got {t}")
    bundle = bundle or default_map()
    with Cosimulator(config, EmpiricalTraffic(store), bundle) as sim:
        sim.reset()
        while sim.step_index < round(t / config.dt) and not sim.done:
            sim.step()
        cameras = CameraRig(
            sim.world,
            bundle,
            tuple(chosen[:1]),
            config.camera.renderer,
            config.dt,
            sun=config.camera.sun,
            shadows=config.camera.shadows,
            seed=config.seed,
        )
        try:
            traffic = FrameTraffic(sim, bundle.road, chosen[0].far)
            (frame,) = cameras.capture(
                sim.ego_id,
                time=sim.t,
                sim_time=sim.sim_time,
                traffic=traffic,
            )
        finally:
            cameras.close()
    return frame


def is_run(path: Path) -> bool:
    return marked_as(path, METRICS, RUN_FORMAT)


def _write_folder(
    tmp: Path, sim: Cosimulator, store, bundle, loop_s: float, reset_s: float, cameras=None
):
    cfg, log = sim.config, sim.log
    arrays = store.trajectory_arrays
    table = log.table(arrays["id"], bundle.road, arrays)
    write_parquet(
        table,
        tmp / "trajectories.parquet",
        {
            "i24_twin": json.dumps(
                {"t0": sim.t0, "road": cfg.road.value, "ego_id": sim.ego_id,
                 "ego_record_id": sim.ego.id, "dt": cfg.dt, "version": __version__},
            ),
        },
    )  # fmt: skip
    (tmp / "config.toml").write_text(to_toml(cfg))

    figures, frames = measure(sim, store, loop_s, reset_s)
    vehicles, windows, ghosts, recorded_ego, ego_rows = frames
    sim_s = sim.sim_time
    if cameras is not None:
        figures["cameras"] = cameras.summary()
    (tmp / METRICS).write_text(json.dumps(figures, indent=2) + "\n")

    title = (
        f"scenario {cfg.scenario}: {cfg.road.value}, ego {sim.ego.id} from lane {sim.ego.lane}, "
        f"x = {sim.ego.x:.0f} m"
    )
    recorded = store.samples(cfg.road, sim.t0, sim.t0 + sim_s, ramps=True)
    plots.timespace_plot(
        recorded, vehicles, windows, recorded_ego, sim.t0, title, tmp / "timespace.png"
    )
    plots.boundary_plot(vehicles, ghosts, windows, sim.t0, title, tmp / "boundary.png")
    bev_time = cfg.bev_time if cfg.bev_time is not None else 0.5 * sim_s
    if len(ghosts):
        ghost_times = np.unique(ghosts["time"].to_numpy())
    else:  # no ghost logged: the vehicles' steps, at the rate ghosts would have been
        every = steps_per_sample(cfg.ghost_log_rate, cfg.dt)
        ghost_times = np.unique(vehicles["time"].to_numpy())[::every]
    at = float(ghost_times[np.argmin(np.abs(ghost_times - min(bev_time, sim_s)))])
    scene = _bev_scene(vehicles, ghosts, windows, arrays, at)
    plots.bev_plot(scene, cfg.road, sim.t0, title, tmp / "bev.png")
    if cfg.bev_video:
        plots.bev_video(
            (_bev_scene(vehicles, ghosts, windows, arrays, t) for t in ghost_times),
            cfg.road, sim.t0, title, tmp / "bev.mp4", fps=cfg.ghost_log_rate,
        )  # fmt: skip
    per_second = max(1, round(1.0 / cfg.dt))
    figures["_ego_speed"] = ego_rows["speed"].to_numpy()[::per_second]
    return figures


def _bev_scene(vehicles, ghosts, windows, arrays, at: float) -> plots.BevScene:
    def near(frame):
        return frame[np.abs(frame["time"].to_numpy() - at) < 1e-6]

    sim = near(vehicles).copy()
    ghost = near(ghosts).copy()
    for frame in (sim, ghost):
        tid = frame["tid"].to_numpy().astype(np.int64)
        frame["length"] = arrays["length"][tid]
        frame["width"] = arrays["width"][tid]
    window = windows.iloc[int(np.argmin(np.abs(windows["time"].to_numpy() - at)))]
    return plots.BevScene(sim, ghost, window, at)


def _seam_line(handover: dict, continuity: dict | None = None) -> str:
    """The ghost-cell boundary in one line: hand-overs each way with their largest jump,
    the bodies anchored, the relaxing vehicles, and every record's largest jump in the
    log (``continuity``)."""
    out, back, relaxing = (handover["visible_to_ghost"], handover["ghost_to_visible"],
                           handover["relaxing"])  # fmt: skip

    def largest(section):
        jump = section["position_jump_m"]["max"]
        return "-" if jump is None else f"{jump:.2f}"

    line = (f"boundary: {out['count']} handed to their recordings (largest jump "
            f"{largest(out)} m), {out['into_visible_window']} vanished, {back['count']} "
            f"spawned from ghosts (largest jump {largest(back)} m)")  # fmt: skip
    if out.get("anchored"):
        line += f", {out['anchored']} anchored where their bodies ended"
    if relaxing["vehicles"]:
        low, high = relaxing["accel_min_mps2"], relaxing["accel_max_mps2"]
        far = relaxing["distance_m"]["max"]
        line += (f"; {relaxing['vehicles']} relaxed (acceleration "
                 f"{_figure(low)} to {_figure(high)} m/s^2, up to {_figure(far)} m from the "
                 "recording)")  # fmt: skip
    if continuity and continuity["pairs"]:
        line += (f"; every record's largest jump in the log "
                 f"{_figure(continuity['position_jump_m']['max'])} m")  # fmt: skip
    return line


def _figure(value) -> str:
    return "-" if value is None else f"{value:.2f}"


def summary(result: RunResult) -> str:
    """A few lines for the terminal: ego speed profile, counts, fidelity, speed."""
    m = result.metrics
    ego, counts, physics = m["ego"], m["counts"], m["physics"]
    profile = " ".join(f"{round(v):d}" for v in result.ego_speed)
    lines = [
        f"scenario {m['scenario']}, behaviour {m['behaviour']}, the ego driven by "
        f"{result.ego_controller or 'the traffic manager'}",
        *([result.behaviour_note] if result.behaviour_note else []),
        f"ego {ego['record_id']} (lane {ego['selected']['lane']}, x {ego['selected']['x_m']:.0f} m)"
        f" speed each second [m/s]: {profile}",
        f"ego vs recording: speed RMSE {ego.get('speed_rmse_mps', float('nan')):.2f} m/s, "
        f"position RMSE {ego.get('position_rmse_m', float('nan')):.2f} m, min speed "
        f"{ego.get('min_speed_sim_mps', float('nan')):.2f} (recorded "
        f"{ego.get('min_speed_recorded_mps', float('nan')):.2f}) m/s",
        f"vehicles: {counts['visible_at_start']} visible at start, {counts['spawned']} spawned, "
        f"{counts['despawned']} despawned, {counts['spawns_skipped_overlap']} refused for lack "
        "of room; "
        f"{physics['collisions']} collisions, {physics['vehicles_off_road']} off the road",
        _seam_line(m["handover"], m.get("continuity")),
        f"simulated {m['simulated_s']:.1f} s in {m['timing']['loop_s']:.1f} s: "
        f"{m['timing']['real_time_factor']:.1f} x real time",
    ]
    if m["ended_early"]:
        lines.append(f"ended early: {m['ended_early']}")
    lines.append(f"wrote {result.folder}:")
    for name, holds in FOLDER_CONTENTS.items():
        path = result.folder / name
        if path.exists():
            shown = f"{name}/" if path.is_dir() else name
            lines.append(f"  {shown:<22}{holds}")
    return "\n".join(lines)
