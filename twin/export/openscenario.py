"""A twin run as an ASAM OpenSCENARIO 1.0 scenario, for CARLA ScenarioRunner, esmini and
the other tools that read the standard.

``twin export RUN --format openscenario --out DIR`` writes into ``DIR``:

- ``i24.xodr``: the segment (:mod:`mapgen.opendrive`), which the scenario's road
  network names (a path relative to the scenario, as the players resolve it);
- ``i24.xosc``: the episode. Its entities are the ego (``hero``, CARLA's name for the
  vehicle a user drives) and every recorded vehicle of the run (the visible vehicles and
  the ghosts, named by their I-24 MOTION ``_id``), each a ``Vehicle`` of its class and
  its recorded size. Each follows its trajectory with a ``FollowTrajectoryAction``: a
  polyline of timed world positions (``WorldPosition`` in the map's east-north-up
  frame, :mod:`mapgen.road`), followed in ``position`` mode on absolute simulation time,
  so that a player puts every vehicle where the run had it, when it had it. A vehicle
  that is not on the map at time 0 is removed in the ``Init`` and added
  (``AddEntityAction``) when it appears; one that leaves before the end is deleted
  (``DeleteEntityAction``). With ``late="omit"`` only the vehicles on the map at time 0
  are written, each for its first stay, so that nothing is added: CARLA ScenarioRunner
  cannot load a file whose vehicles are added (``docs/export.md``).

The trajectories are the run's (``simulated``: the twin's for the ego and the visible
vehicles, the recording for the ghosts, as the run had them) or the recording's
(``recorded``: every vehicle as I-24 MOTION recorded it, read from the data the run was
made from). Vertices are taken from the rows at ``rate`` per second (each a row of the
source, never an interpolation).

With ``ego="external"`` the ego has no trajectory: it starts where and as fast as the
run's ego did, with a controller assigned and activated that leaves it to the user's
stack (``module=external_control`` for CARLA ScenarioRunner,
``esminiController=ExternalController`` for esmini), inside the recorded traffic.

Conventions of the file (the standard's): a vehicle's position is its reference point,
the centre of its rear axle on the road surface; its ``BoundingBox`` centre is given from
there. Headings are world yaw counter-clockwise from east; pitch is positive nose down
(ISO 8855), so an uphill grade is a negative pitch. Times are seconds since the run's t0.
OpenSCENARIO 1.0 is written by default because CARLA ScenarioRunner reads no other
version; ``minor`` chooses 1.1 to 1.3.
"""

import math
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pandas as pd

from mapgen.opendrive import write_opendrive
from twin import __version__
from twin.core.atomic import AtomicFolder
from twin.core.i24 import VEHICLE_CLASSES, Road
from twin.core.vehicle_classes import vehicle_classes
from twin.export.episode import Episode, ExportError, read_episode
from twin.traffic.kernels.steering import MAX_STEER

EGO = "hero"  # CARLA's role name of the vehicle a user drives; esmini takes any name
SCENARIO, NETWORK = "i24.xosc", "i24.xodr"
TRAJECTORIES = ("simulated", "recorded")
EGO_MODES = ("trajectory", "external")
LATE = ("add", "omit")
MINORS = (0, 1, 2, 3)  # OpenSCENARIO 1.0 to 1.3 (scenariogeneration writes each)
DEFAULT_RATE = 10.0  # [Hz] trajectory vertices per second
GAP = 0.5  # [s] a pause this long or longer in a vehicle's rows splits its trajectory (it left
# and came back)
#: OpenSCENARIO 1.0 vehicle categories of the I-24 classes (the twin drives a semi as one
#: rigid body, so it is a truck, not a tractor with a semitrailer entity)
CATEGORY = {"sedan": "car", "midsize": "car", "pickup": "car", "van": "van", "semi": "truck",
            "truck": "truck", "motorcycle": "motorbike"}  # fmt: skip
#: Performance limits above any recorded or simulated driving (players such as esmini may
#: clamp the motion they give an entity to these). A hand-over between the twin and the
#: recording can move a vehicle metres within one step; that jump is the run's, kept as a
#: short segment between two vertices, not driving.
MAX_SPEED, MAX_ACCEL, MAX_DECEL = 70.0, 15.0, 15.0  # [m/s], [m/s^2], [m/s^2]
#: The controller the external ego gets: each player reads its own property
EXTERNAL = {"module": "external_control", "esminiController": "ExternalController"}
DIGITS = 3  # positions to the millimetre, times to the millisecond
CHORD = 0.005  # [m] a vertex is added where the kept ones' chord misses a row by more
MAX_REFINE = 20  # rounds of adding vertices (each halves the worst stretches)


def scenariogeneration():
    """The ``scenariogeneration`` package's ``xosc`` module.

    Raises:
        ExportError: it is not installed.
    """
    try:
        from scenariogeneration import xosc
    except ImportError:
        raise ExportError(
            "exporting to OpenSCENARIO needs scenariogeneration: "
            "python3 -m pip install 'i24-twin[openscenario]'"
        ) from None
    return xosc


def export_openscenario(
    run: Path,
    out: Path,
    bundle,
    *,
    trajectories: str = "simulated",
    ego: str = "trajectory",
    rate: float = DEFAULT_RATE,
    data=None,
    minor: int = 0,
    late: str = "add",
) -> dict:
    """Write run folder ``run`` as OpenSCENARIO into ``out`` (atomically).

    Args:
        run: a run folder (``twin run --out``).
        out: the folder to write (replaced if it is an earlier export, else refused).
        bundle: the map (``mapgen.build.default_map()``).
        trajectories: ``simulated`` (the run's) or ``recorded`` (the recording's).
        ego: ``trajectory`` (the ego follows its trajectory too) or ``external`` (left
            to the user's controller).
        rate: [Hz] trajectory vertices per second (above the source's rate: every row).
        data: the recorded data the run was made from (``--data`` of ``twin run``;
            None: the embedded store), read only for ``recorded``.
        minor: the OpenSCENARIO version 1.``minor`` to write (0 to 3).
        late: ``add`` (vehicles that are not on the map at time 0 are added when they
            appear) or ``omit`` (only the vehicles on the map at time 0, each for its
            first stay: a file CARLA ScenarioRunner can load).

    Returns:
        What was written: folder, vehicles (in the file), of_vehicles (of the run),
        vertices, duration_s and the options.

    Raises:
        ExportError: not a run folder, an unknown option, the run's vehicles are not in
            ``data``, or scenariogeneration is missing.
    """
    if trajectories not in TRAJECTORIES:
        raise ExportError(f"--trajectories {trajectories!r}: choose one of {TRAJECTORIES}")
    if ego not in EGO_MODES:
        raise ExportError(f"--ego {ego!r}: choose one of {EGO_MODES}")
    if late not in LATE:
        raise ExportError(f"--late-vehicles {late!r}: choose one of {LATE}")
    if minor not in MINORS:
        raise ExportError(f"OpenSCENARIO 1.{minor}: the export writes 1.0 to 1.{MINORS[-1]}")
    if not (math.isfinite(rate) and rate > 0.0):
        raise ExportError(f"--rate {rate}: must be a positive number of vertices per second")
    xosc = scenariogeneration()
    episode = read_episode(run)
    road_model = bundle.road
    vehicles = _vehicles(episode)
    if trajectories == "simulated":
        tracks = _simulated(episode, road_model)
    else:
        tracks = _recorded(episode, vehicles, road_model, data)
    tracks = _decimate(tracks, rate)
    tracks = _reference_points(tracks, vehicles, episode.road, road_model)
    options = {"trajectories": trajectories, "ego": ego, "rate": rate, "late": late,
               "minor": minor}  # fmt: skip
    scenario, written, vertices = _scenario(xosc, episode, vehicles, tracks, options)
    recognise = lambda p: (p / SCENARIO).is_file()  # noqa: E731
    kind = "OpenSCENARIO export"
    with AtomicFolder(Path(out), recognise=recognise, kind=kind, error=ExportError) as folder:
        write_opendrive(bundle, folder.tmp / NETWORK)
        scenario.write_xml(str(folder.tmp / SCENARIO))
    return {"folder": str(out), "vehicles": written, "of_vehicles": len(vehicles),
            "vertices": vertices, "duration_s": episode.duration, **options}  # fmt: skip


# -- the vehicles and their trajectories ------------------------------------------------


def _vehicles(episode: Episode) -> pd.DataFrame:
    """One row per recorded vehicle of the run, indexed by ``record_id``: its entity
    name, class, size, role (``ego``, ``simulated`` if the twin ever drove it, else
    ``ghost``) and the distance from its body centre back to its rear axle."""
    rows = episode.rows
    first = rows.groupby("record_id", sort=False, observed=True).head(1).set_index("record_id")
    roles = rows.groupby("record_id", observed=True)["role"].agg(lambda r: set(r.astype(str)))
    table = first[["vehicle_class", "length", "width", "height"]].astype(
        {"length": np.float64, "width": np.float64, "height": np.float64}
    )
    table["role"] = [
        "ego" if rid == episode.ego_record_id else "simulated" if "visible" in roles[rid]
        else "ghost"
        for rid in table.index
    ]  # fmt: skip
    table["name"] = [EGO if rid == episode.ego_record_id else rid for rid in table.index]
    classes = vehicle_classes()
    k = table["vehicle_class"].to_numpy().astype(np.int64)
    # the twin's bodies have their axles half a wheelbase either side of the centre
    table["rear_axle"] = 0.5 * classes.column("wheelbase_ratio")[k] * table["length"]
    table["wheel_radius"] = classes.column("wheel_radius_m")[k]
    table["track"] = classes.column("track_ratio")[k] * table["width"]
    table["mass"] = classes.column("mass_kg")[k]
    order = np.argsort(table["name"] != EGO, kind="stable")  # the ego first
    return table.iloc[order]


def _simulated(episode: Episode, road_model) -> pd.DataFrame:
    """The run's own rows on the map: ``record_id``, ``time``, ``x`` (body centre),
    ``y``, ``heading``, ``pitch`` (nose up), ``speed``, ``role``."""
    rows = episode.rows
    tracks = pd.DataFrame({
        "record_id": rows["record_id"].astype(str).to_numpy(),
        "time": rows["time"].to_numpy(),
        "x": rows["x"].to_numpy() + 0.5 * rows["length"].to_numpy(np.float64),
        "y": rows["y"].to_numpy(),
        "heading": rows["heading"].to_numpy(),
        "pitch": np.arctan(rows["grade"].to_numpy()),
        "speed": rows["speed"].to_numpy(),
        "role": rows["role"].astype(str).to_numpy(),
    })  # fmt: skip
    lo, hi = road_model.x_range(episode.road)
    return tracks[(tracks["x"] >= lo) & (tracks["x"] <= hi)]


def _recorded(episode: Episode, vehicles: pd.DataFrame, road_model, data) -> pd.DataFrame:
    """The recording of the run's vehicles over the episode (same columns as
    :func:`_simulated`), on the map only."""
    from twin.runners.run import open_data

    store = open_data(data, progress=False)
    ids = store.trajectory_arrays["id"]
    tid_of = {rid: tid for tid, rid in enumerate(ids)}
    missing = [rid for rid in vehicles.index if rid not in tid_of]
    if missing:
        source = data if data is not None else "the embedded data"
        raise ExportError(
            f"{len(missing)} of the run's {len(vehicles)} vehicles (e.g. {missing[0]}) are not "
            f"in {source}: was the run made from other data? Pass its --data"
        )
    tids = np.array([tid_of[rid] for rid in vehicles.index])
    road = episode.road
    s = store.samples(road, episode.t0, episode.t0 + episode.duration, tids)
    length = np.zeros(len(ids))
    length[tids] = vehicles["length"].to_numpy()
    centre = s["x"] + 0.5 * length[s["tid"]]
    lo, hi = road_model.x_range(road)
    on_map = (centre >= lo) & (centre <= hi)
    _, heading, pitch = road_model.to_world(road, centre[on_map], s["y"][on_map].astype(float))
    return pd.DataFrame({
        "record_id": ids[s["tid"][on_map]].astype(str),
        "time": s["t"][on_map] - episode.t0,
        "x": centre[on_map],
        "y": s["y"][on_map].astype(np.float64),
        "heading": heading,
        "pitch": pitch,
        "speed": s["speed"][on_map].astype(np.float64),
        "role": "recorded",
    })  # fmt: skip


def _decimate(tracks: pd.DataFrame, rate: float) -> pd.DataFrame:
    """Each vehicle's rows at ``rate`` per second: of each piece of its trajectory (split
    where it pauses: it left and came back), the row nearest each tick ``start + k /
    rate``, its last row, and the rows either side of a hand-over between the twin and the
    recording (where the run has the vehicle jump from where the twin drove it to where
    it was recorded, within one step), and, where a player following those linearly
    would miss a row by more than :data:`CHORD`, the rows that keep it within
    (:func:`_refine`). Adds a ``piece`` column (0, 1, ... per vehicle)."""
    tracks = tracks.sort_values(["record_id", "time"], kind="stable").reset_index(drop=True)
    rid, time = tracks["record_id"].to_numpy(), tracks["time"].to_numpy()
    new_vehicle = np.r_[True, rid[1:] != rid[:-1]]
    new_piece = new_vehicle | np.r_[False, np.diff(time) >= GAP - 1e-9]
    piece = np.cumsum(new_piece) - 1
    start = time[np.flatnonzero(new_piece)][piece]
    tick = np.round((time - start) * rate)
    miss = np.abs(time - start - tick / rate)
    order = np.lexsort((miss, tick, piece))  # per (piece, tick), the nearest row first
    first_of_tick = np.r_[True, (np.diff(piece[order]) != 0) | (np.diff(tick[order]) != 0)]
    keep = np.zeros(len(tracks), dtype=bool)
    keep[order[first_of_tick]] = True
    keep[np.r_[piece[1:] != piece[:-1], True]] = True  # each piece's last row
    role = tracks["role"].to_numpy()
    handed = (role[1:] != role[:-1]) & (piece[1:] == piece[:-1])
    keep[np.r_[handed, False] | np.r_[False, handed]] = True
    _refine(keep, piece, time, tracks["x"].to_numpy(), tracks["y"].to_numpy())
    tracks["piece"] = piece - piece[np.flatnonzero(new_vehicle)][np.cumsum(new_vehicle) - 1]
    return tracks[keep].reset_index(drop=True)


def _refine(keep, piece, time, x, y) -> None:
    """Add to ``keep`` the rows a player following the kept ones linearly would miss by
    more than :data:`CHORD` (hard braking bends a 0.1 s chord by a centimetre): the row
    furthest from the chord of each such stretch, until none is left. Rows sorted by
    (vehicle, time); ``piece`` numbers each vehicle's pieces."""
    for _ in range(MAX_REFINE):
        kept = np.flatnonzero(keep)
        after = np.searchsorted(kept, np.arange(keep.size))  # the next kept row at or after
        after = np.minimum(after, kept.size - 1)
        before = np.maximum(after - 1, 0)
        a, b = kept[before], kept[after]
        inside = (
            ~keep & (piece[a] == piece[b]) & (a < np.arange(keep.size)) & (b > np.arange(keep.size))
        )
        if not inside.any():
            return
        w = np.where(inside, (time - time[a]) / np.maximum(time[b] - time[a], 1e-12), 0.0)
        miss = np.hypot(x - (x[a] + w * (x[b] - x[a])), y - (y[a] + w * (y[b] - y[a])))
        miss = np.where(inside, miss, 0.0)
        bad = miss > CHORD
        if not bad.any():
            return
        # per stretch (its kept row after), the worst row
        rows = np.flatnonzero(bad)
        order = np.lexsort((-miss[rows], b[rows]))
        rows = rows[order]
        first = np.r_[True, b[rows][1:] != b[rows][:-1]]
        keep[rows[first]] = True


def _reference_points(
    tracks: pd.DataFrame, vehicles: pd.DataFrame, road: Road, road_model
) -> pd.DataFrame:
    """Add the world pose of each row's reference point (its rear axle's centre on the
    road): ``wx``, ``wy``, ``wz`` [m], ``h`` [rad] yaw in [0, 2 pi), ``p`` [rad]
    OpenSCENARIO's pitch (nose down)."""
    centre, _, _ = road_model.to_world(road, tracks["x"].to_numpy(), tracks["y"].to_numpy())
    yaw = tracks["heading"].to_numpy()
    back = vehicles.loc[tracks["record_id"], "rear_axle"].to_numpy()
    wx = centre[:, 0] - back * np.cos(yaw)
    wy = centre[:, 1] - back * np.sin(yaw)
    station = np.stack([wx, wy], axis=1) @ road_model.direction_vector
    return tracks.assign(
        wx=wx, wy=wy, wz=road_model.surface_z(station), h=np.mod(yaw, 2.0 * np.pi),
        p=-tracks["pitch"].to_numpy(),
    )  # fmt: skip


# -- the scenario -----------------------------------------------------------------------


def _scenario(xosc, episode: Episode, vehicles, tracks, options: dict):
    """The OpenSCENARIO document (scenariogeneration objects), the number of vehicles
    and of trajectory vertices in it. ``options``: trajectories, ego, rate, late, minor
    (as the export's)."""
    minor, slack = options["minor"], 0.5 / options["rate"]  # half a vertex period
    entities, init = xosc.Entities(), xosc.Init()
    act = xosc.Act("episode", _at(xosc, "episode starts", 0.0))
    written = vertices = 0
    stays = {rid: [p for _, p in group.groupby("piece", sort=True)]
             for rid, group in tracks.groupby("record_id", sort=False)}  # fmt: skip
    for rid, v in vehicles.iterrows():
        name = v["name"]
        pieces = stays.get(rid, [])
        at_start = bool(pieces) and pieces[0]["time"].iloc[0] <= slack
        if options["late"] == "omit":  # only vehicles on the map at time 0, one stay each
            if not at_start:
                continue
            pieces = pieces[:1]
        entities.add_scenario_object(name, _vehicle(xosc, rid, v, minor))
        written += 1
        if not at_start:  # on the map later (or never, recorded: outside it throughout)
            init.add_global_action(xosc.DeleteEntityAction(name))
        if not pieces:
            continue
        if name == EGO and options["ego"] == "external":
            _external_ego(xosc, init, pieces[0].iloc[0], minor)
            continue
        if at_start:
            init.add_init_action(name, xosc.TeleportAction(_position(xosc, pieces[0].iloc[0])))
        vertices += sum(len(piece) for piece in pieces)
        group = xosc.ManeuverGroup(f"{name} drives")
        group.add_actor(name)
        maneuver = xosc.Maneuver(f"{name} trajectory")
        for k, piece in enumerate(pieces):
            added = k > 0 or not at_start
            leaves = piece["time"].iloc[-1] < episode.duration - slack
            _piece_events(xosc, maneuver, name, k, piece, added=added, leaves=leaves)
        group.add_maneuver(maneuver)
        act.add_maneuver_group(group)
    story = xosc.Story("episode")
    story.add_act(act)
    board = xosc.StoryBoard(init, _at(xosc, "episode ends", episode.duration, trigger="stop"))
    board.add_story(story)
    when = datetime.fromtimestamp(episode.t0, UTC)
    description = (
        f"i24-twin run {episode.folder.name}: scenario {episode.config.scenario}, "
        f"{episode.road.value}, I-24 MOTION at {when:%Y-%m-%d %H:%M:%S} UTC + "
        f"{episode.duration:g} s; trajectories {options['trajectories']}; ego "
        f"{'external' if options['ego'] == 'external' else 'follows its trajectory'}"
        f"{'; only the vehicles on the map at time 0' if options['late'] == 'omit' else ''}"
    )
    scenario = xosc.Scenario(
        description, f"i24-twin {__version__}", xosc.ParameterDeclarations(), entities,
        board, xosc.RoadNetwork(roadfile=NETWORK), xosc.Catalog(), osc_minor_version=minor,
        creation_date=when.replace(tzinfo=None),  # the recording's time: same run, same file
    )  # fmt: skip
    return scenario, written, vertices


def _vehicle(xosc, rid: str, v, minor: int):
    """The ``Vehicle`` of one recorded vehicle: its class, recorded size and the twin's
    axles (the reference point on the rear one)."""
    name = VEHICLE_CLASSES[int(v["vehicle_class"])]
    mm = lambda value: round(float(value), DIGITS)  # noqa: E731
    box = xosc.BoundingBox(
        mm(v["width"]), mm(v["length"]), mm(v["height"]), mm(v["rear_axle"]), 0.0,
        mm(0.5 * v["height"]),
    )  # fmt: skip
    radius, track = mm(v["wheel_radius"]), mm(v["track"])
    front = xosc.Axle(MAX_STEER, 2.0 * radius, track, mm(2.0 * v["rear_axle"]), radius)
    rear = xosc.Axle(0.0, 2.0 * radius, track, 0.0, radius)
    vehicle = xosc.Vehicle(
        name, getattr(xosc.VehicleCategory, CATEGORY[name]), box, front, rear,
        MAX_SPEED, MAX_ACCEL, MAX_DECEL, mass=float(v["mass"]) if minor >= 1 else None,
    )  # fmt: skip
    vehicle.add_property("type", "ego_vehicle" if v["role"] == "ego" else "simulation")  # CARLA
    vehicle.add_property("record_id", rid)  # the I-24 MOTION _id
    vehicle.add_property("role", v["role"])  # ego, simulated (by the twin) or ghost
    if minor == 0:  # a Vehicle has a mass from 1.1
        vehicle.add_property("mass_kg", f"{v['mass']:g}")
    return vehicle


def _position(xosc, row):
    """A row's reference point as a ``WorldPosition`` (mm, 0.1 mrad; never -0)."""
    x, y, z = (round(float(row[k]), DIGITS) + 0.0 for k in ("wx", "wy", "wz"))
    h = round(float(row["h"]), 4) % round(2.0 * math.pi, 4) + 0.0  # in [0, 2 pi) once rounded
    return xosc.WorldPosition(x, y, z, h, round(float(row["p"]), 4) + 0.0, 0.0)


def _at(xosc, name: str, time: float, *, trigger: str = "start"):
    """A trigger when the simulation time passes ``time``."""
    condition = xosc.SimulationTimeCondition(round(time, DIGITS), xosc.Rule.greaterThan)
    return xosc.ValueTrigger(name, 0.0, xosc.ConditionEdge.rising, condition, trigger)


def _after(xosc, name: str, action: str):
    """A trigger when the action named ``action`` has ended."""
    condition = xosc.StoryboardElementStateCondition(
        xosc.StoryboardElementType.action, action, xosc.StoryboardElementState.endTransition
    )
    return xosc.ValueTrigger(name, 0.0, xosc.ConditionEdge.rising, condition)


def _piece_events(
    xosc, maneuver, name: str, k: int, piece: pd.DataFrame, *, added: bool, leaves: bool
) -> None:
    """The events of one stay of a vehicle on the map: added at its first vertex (if it
    was not there at time 0, or came back), following its polyline, deleted after its
    last vertex (if it leaves before the end). A stay of one row (a ghost first drawn
    in the run's last step) is the vehicle added there, with no polyline to follow
    (one needs two vertices)."""
    times = piece["time"].to_numpy()
    event = None
    if len(times) > 1:
        trajectory = xosc.Trajectory(f"{name} {k}", False)
        trajectory.add_shape(
            xosc.Polyline(
                [round(float(t), DIGITS) for t in times],
                [_position(xosc, row) for _, row in piece.iterrows()],
            )
        )
        follow = xosc.FollowTrajectoryAction(
            trajectory, xosc.FollowingMode.position, xosc.ReferenceContext.absolute, 1.0, 0.0
        )
        event = xosc.Event(f"{name} follows {k}", xosc.Priority.parallel)
        event.add_action(f"{name} follow {k}", follow)
    if added:
        appear = xosc.Event(f"{name} appears {k}", xosc.Priority.parallel)
        appear.add_action(
            f"{name} add {k}", xosc.AddEntityAction(name, _position(xosc, piece.iloc[0]))
        )
        appear.add_trigger(_at(xosc, f"{name} on the map {k}", float(times[0])))
        maneuver.add_event(appear)
        if event is not None:
            event.add_trigger(_after(xosc, f"{name} added {k}", f"{name} add {k}"))
    elif event is not None:
        event.add_trigger(_at(xosc, f"{name} starts {k}", 0.0))
    if event is not None:
        maneuver.add_event(event)
    if leaves:
        leave = xosc.Event(f"{name} leaves {k}", xosc.Priority.parallel)
        leave.add_action(f"{name} delete {k}", xosc.DeleteEntityAction(name))
        leave.add_trigger(_at(xosc, f"{name} off the map {k}", float(times[-1])))
        maneuver.add_event(leave)


def _external_ego(xosc, init, start, minor: int) -> None:
    """The ego where and as fast as the run's ego at time 0, left to the user's
    controller (assigned and activated: by the assignment itself from 1.2, where
    ``ActivateControllerAction`` is deprecated)."""
    init.add_init_action(EGO, xosc.TeleportAction(_position(xosc, start)))
    step = xosc.TransitionDynamics(xosc.DynamicsShapes.step, xosc.DynamicsDimension.time, 0.0)
    init.add_init_action(EGO, xosc.AbsoluteSpeedAction(round(float(start["speed"]), DIGITS), step))
    controller = xosc.Controller("external", _properties(xosc, EXTERNAL))
    if minor >= 3:  # 1.3 assigns an ObjectController
        controller = xosc.ObjectController("external", controller=controller)
    assign = xosc.AssignControllerAction(controller)
    if minor == 0:  # 1.0 wraps it in a ControllerAction, with overrides (none active)
        override = xosc.OverrideControllerValueAction()
        for pedal in ("throttle", "brake", "clutch", "parkingbrake", "steeringwheel", "gear"):
            getattr(override, f"set_{pedal}")(False)
        assign = xosc.ControllerAction(assign, override)
    init.add_init_action(EGO, assign)
    if minor < 2:
        init.add_init_action(EGO, xosc.ActivateControllerAction(lateral=True, longitudinal=True))


def _properties(xosc, values: dict):
    properties = xosc.Properties()
    for key, value in values.items():
        properties.add_property(key, value)
    return properties
