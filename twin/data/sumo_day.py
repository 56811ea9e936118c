"""Test data from another simulator: I-24 MOTION days made by Eclipse SUMO's drivers.

The synthesiser (:mod:`twin.data.synth`) shares its car following, its lane changing
and its merging with the twin's own traffic manager, so a figure measured only on its
data proves little. :func:`sumo_day` drives the same road, lanes, lane drop, on-ramp,
bottleneck and demand as a synthesiser preset with SUMO's own drivers instead (Krauss
car following, LC2013 lane changing, SUMO's defaults for each vehicle class), records
what the cameras would see and writes it as an I-24 MOTION day file (the layout of
:func:`twin.data.day_files.write_day`).

SUMO's network of the road is its own, straight, in the road frame: SUMO's x is the
road frame's x less the start of the simulated road, its lanes count from the right
(index 0), the HOV lane (-1) is the leftmost, open to SUMO's ``hov`` class only. The
edges change where the lanes do:

* an on-ramp's acceleration lane is a fifth lane on the right from the ramp's start to
  its end, where it ends: its vehicles depart on it at the ramp's speed and must merge
  into lane -4 before its end (SUMO's strategic lane changing); the recording sees them
  on it until they are in lane -4 (ingested as lane -5 where they lie within the map's
  acceleration lane, which tapers from 53 m into the segment);
* a lane drop ends the preset's lanes (the right ones) at its position;
* a bottleneck is a stretch with the preset's lower speed limit.

The preset's scripted slowdowns and its bottleneck's slow drivers are not reproduced:
the waves come from SUMO's drivers at the merges and the bottleneck. SUMO runs at 0.1
s steps with continuous lane changes of ``lane_change_duration`` seconds, no
teleporting (a stuck vehicle waits) and collisions counted, not removed; it writes its
floating-car data as Parquet (SUMO's own Arrow support: no Python binding to SUMO is
loaded, whose Arrow build could clash with pyarrow's), which is resampled at the
camera rate with a per-vehicle phase and the preset's tracking noise, back centre, as
the synthesiser records.

:class:`SumoDrivers` gives every vehicle type other drivers than SUMO's defaults: another
car-following model (IDM, EIDM), another lane-changing model (SL2015, on SUMO's sublane
model), and the models' parameters (:mod:`twin.data.sumo_family` draws them for a family
of held-out days).
"""

import itertools
import os
import subprocess
import tempfile
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from twin.core import i24
from twin.core.sumo import SumoMissing, sumo_home, sumo_tool
from twin.core.vehicle_classes import vehicle_classes
from twin.data.day_files import write_day
from twin.data.sumo_drivers import STEP, SumoDayError, SumoDrivers
from twin.data.synth.config import SynthConfig
from twin.data.synth.recording import camera_track
from twin.data.synth.simulation import class_weights

SPEED_LIMIT = 70.0 * i24.MILE / 3600.0  # [m/s] the corridor's limit, 70 mph
#: SUMO's vehicle class of each I-24 class (sedan .. motorcycle)
SUMO_CLASSES = ("passenger", "passenger", "passenger", "delivery", "trailer", "truck",
                "motorcycle")  # fmt: skip
RAMP = "ramp"  # the ramp's edges' name prefix
#: how the lanes' vehicles enter the road (SUMO's departSpeed): at the fastest safe speed,
#: or at the mean speed of the vehicles on their lane
DEPART_SPEEDS = ("max", "avg")


@dataclass(frozen=True)
class SumoDayResult:
    """What :func:`sumo_day` wrote: the day file and SUMO's own counts."""

    path: Path
    trajectories: int
    lane_changes: int
    collisions: int
    departed: int
    waiting: int  # vehicles still waiting to depart at the end (demand above capacity)


@dataclass(frozen=True)
class _Piece:
    """One edge of SUMO's network: road-frame x from ``x0`` to ``x1`` [m]."""

    x0: float
    x1: float
    lanes: int  # how many, the acceleration lane included
    ramp: bool  # the rightmost lane is the on-ramp's acceleration lane
    speed: float  # [m/s] its limit


def sumo_day(config: SynthConfig, out, *, lane_change_duration: float = 3.0,
             keep: Path | None = None, drivers: SumoDrivers | None = None,
             depart_speed: str = "max", progress: bool = False) -> SumoDayResult:  # fmt: skip
    """Drive ``config``'s road and demand with SUMO's drivers and write the recording
    as an I-24 MOTION day file ``out`` (module doc). Deterministic by ``config.seed``.

    Args:
        config: the synthesiser preset whose road (lane drop, on-ramp, bottleneck),
            demand (per-lane flows, the ramp's), times, recorded range, sample rate and
            tracking noise are driven.
        lane_change_duration: [s] SUMO's continuous lane changes take this long.
        keep: a folder to keep SUMO's inputs and outputs in (default: a temporary one).
        drivers: SUMO's drivers for every vehicle type (default: SUMO's own, Krauss and
            LC2013 with SUMO's defaults for each class).
        depart_speed: how the lanes' vehicles enter the road, one of ``DEPART_SPEEDS``:
            ``"max"``, at the fastest speed that is safe there (an entry that admits no
            more than free flow does), or ``"avg"``, at the mean speed of the vehicles on
            their lane (a queue that reaches the road's start keeps being fed at the
            queue's pace, as the road upstream would feed it).

    Raises:
        SumoDayError: SUMO is missing or failed, the preset has no flow, or
            ``depart_speed`` is not one of ``DEPART_SPEEDS``.
    """
    if not sum(config.flow) and (config.on_ramp is None or config.on_ramp.flow <= 0):
        raise SumoDayError("the preset has no demand: every lane's flow is 0")
    if not lane_change_duration > 0:
        raise SumoDayError(f"lane_change_duration must be > 0 s, got {lane_change_duration}")
    if depart_speed not in DEPART_SPEEDS:
        raise SumoDayError(
            f"depart_speed {depart_speed!r}: expected one of {', '.join(DEPART_SPEEDS)}"
        )
    pieces = _pieces(config)
    if keep is not None:
        keep = Path(keep)
        if keep.exists() and not keep.is_dir():
            raise SumoDayError(f"--keep {keep}: a file, not a folder")
        keep.mkdir(parents=True, exist_ok=True)
        return _drive(config, pieces, Path(keep), Path(out), lane_change_duration, drivers,
                      depart_speed, progress)  # fmt: skip
    with tempfile.TemporaryDirectory(prefix="i24-sumo-") as folder:
        return _drive(config, pieces, Path(folder), Path(out), lane_change_duration, drivers,
                      depart_speed, progress)  # fmt: skip


def _drive(config, pieces, folder, out, lane_change_duration, drivers, depart_speed,
           progress) -> SumoDayResult:  # fmt: skip
    _network(pieces, folder)
    departures = _routes(config, pieces, folder, drivers, depart_speed)
    stats = _run(config, folder, lane_change_duration, drivers)
    vid, tracks, classes, dims = _record(config, pieces, folder, departures)
    if not tracks:
        raise SumoDayError("SUMO's vehicles never entered the recorded range")
    path = write_day(out, config.road, config.anchor, vid, tracks, classes, dims,
                     flag="sumo", progress=progress)  # fmt: skip
    return SumoDayResult(path=path, trajectories=len(tracks), **stats)


# -- the network ------------------------------------------------------------------------------


def _pieces(config: SynthConfig) -> list[_Piece]:
    """The edges: cut where the lanes or the speed limit change."""
    begin = config.x_record[0] - config.upstream
    end = config.x_record[1] + config.downstream
    cuts = {begin, end}
    ramp, drop, neck = config.on_ramp, config.lane_drop, config.bottleneck
    if ramp is not None:
        cuts |= {min(max(ramp.x_start, begin), end), min(max(ramp.x_end, begin), end)}
    if drop is not None:
        cuts.add(min(max(drop.x, begin), end))
    if neck is not None:
        cuts |= {min(max(neck.x, begin), end), min(max(neck.x + neck.length, begin), end)}
    edges = sorted(cuts)
    frame = vehicle_classes().frame
    weights = class_weights(frame, config.heavy_factor, -1 - i24.N_LANES // 2)
    mean_factor = float(weights @ frame["desired_speed_mps"].to_numpy(float))
    mean_factor *= config.drivers.desired_speed_scale / SPEED_LIMIT
    pieces = []
    for x0, x1 in itertools.pairwise(edges):
        if x1 - x0 < 1.0:
            continue
        middle = 0.5 * (x0 + x1)
        lanes = i24.N_LANES
        if drop is not None and middle > drop.x:
            lanes -= len(drop.lanes)
        on_ramp = ramp is not None and ramp.x_start < middle < ramp.x_end
        speed = SPEED_LIMIT
        if neck is not None and neck.x < middle < neck.x + neck.length:
            speed = min(speed, neck.speed / mean_factor)  # SUMO's drivers: limit x factor
        pieces.append(_Piece(x0, x1, lanes + on_ramp, on_ramp, speed))
    return pieces


def _edge(k: int) -> str:
    return f"e{k}"


def _network(pieces: list[_Piece], folder: Path) -> None:
    """SUMO's network: plain nodes, edges and connections, built by netconvert."""
    begin = pieces[0].x0
    nodes = ET.Element("nodes")
    for k in range(len(pieces) + 1):
        x = pieces[k].x0 if k < len(pieces) else pieces[-1].x1
        ET.SubElement(nodes, "node", id=f"n{k}", x=f"{x - begin:.3f}", y="0")
    edges = ET.Element("edges")
    for k, piece in enumerate(pieces):
        edge = ET.SubElement(edges, "edge", id=_edge(k), **{"from": f"n{k}", "to": f"n{k + 1}"},
                             numLanes=str(piece.lanes), speed=f"{piece.speed:.3f}",
                             width=f"{i24.LANE_WIDTH:.4f}", spreadType="right")  # fmt: skip
        # the HOV lane behind its double line: open to the hov class, left by nobody,
        # entered by nobody (SUMO's lane-change permissions; only emergency vehicles)
        ET.SubElement(edge, "lane", index=str(piece.lanes - 1), allow="hov emergency",
                      changeRight="emergency")  # fmt: skip
        ET.SubElement(edge, "lane", index=str(piece.lanes - 2), changeLeft="emergency")
    connections = ET.Element("connections")
    for k in range(len(pieces) - 1):
        a, b = pieces[k], pieces[k + 1]
        # the lanes are aligned on the left (the HOV lane): lane i from the left
        # continues as lane i from the left; lanes beyond the next edge's end there
        for left in range(min(a.lanes - a.ramp, b.lanes - b.ramp)):
            ET.SubElement(connections, "connection", **{"from": _edge(k), "to": _edge(k + 1)},
                          fromLane=str(a.lanes - 1 - left),
                          toLane=str(b.lanes - 1 - left))  # fmt: skip
        if a.ramp and b.ramp:
            ET.SubElement(connections, "connection", **{"from": _edge(k), "to": _edge(k + 1)},
                          fromLane="0", toLane="0")  # fmt: skip
    for name, root in (("i24.nod.xml", nodes), ("i24.edg.xml", edges),
                       ("i24.con.xml", connections)):  # fmt: skip
        ET.ElementTree(root).write(folder / name, encoding="utf-8", xml_declaration=True)
    _call(
        [
            str(_tool("netconvert")),
            "--node-files", str(folder / "i24.nod.xml"),
            "--edge-files", str(folder / "i24.edg.xml"),
            "--connection-files", str(folder / "i24.con.xml"),
            "--output-file", str(folder / "i24.net.xml"),
            "--offset.disable-normalization", "true",
            "--no-turnarounds", "true",
            "--no-warnings", "true",
        ],
        "netconvert",
    )  # fmt: skip


# -- the demand -------------------------------------------------------------------------------


def _routes(config: SynthConfig, pieces: list[_Piece], folder: Path,
            sumo_drivers: SumoDrivers | None, depart_speed: str) -> pd.DataFrame:  # fmt: skip
    """Vehicle types, one flow per lane and the ramp's (random arrivals: exponential
    headways); returns the types' table. Each I-24 class is a type with its size, and
    with the preset's desired speeds (their spread clipped at 2 sd, as the synthesiser
    draws them), time headways (Krauss's ``tau``) and standstill gaps; each lane's
    class mix is the preset's (heavy vehicles out of the HOV lane, scaled by its
    ``heavy_factor`` elsewhere; the ramp's as lane -4's); how they accelerate, brake,
    dawdle (``sigma``) and change lanes is SUMO's default for their SUMO class, so the
    road's capacity is SUMO's drivers', not the preset's. With ``sumo_drivers`` every
    type takes their models and parameters instead (their time headway, standstill
    gap and speed spread in place of the preset's)."""
    frame = vehicle_classes().frame
    drivers = config.drivers
    routes = ET.Element("routes")
    rows = []
    for hov in (False, True):
        for c in frame.index:
            row = frame.loc[c]
            if hov and not row["hov_allowed"]:
                continue
            name = f"{row['name']}{'_hov' if hov else ''}"
            factor = row["desired_speed_mps"] * drivers.desired_speed_scale / SPEED_LIMIT
            spread = row["desired_speed_sd_mps"] * drivers.desired_speed_scale / SPEED_LIMIT
            headway = row["time_headway_s"] * drivers.time_headway_scale
            if sumo_drivers is not None:
                spread = sumo_drivers.speed_dev
            low, high = factor - 2.0 * spread, factor + 2.0 * spread  # the synthesiser's clip
            draw = f"normc({factor:.4f},{spread:.4f},{low:.4f},{high:.4f})"
            sumo_class = "hov" if hov else SUMO_CLASSES[int(c)]
            if sumo_drivers is None:
                behaviour = {"carFollowModel": "Krauss", "tau": f"{headway:.3f}",
                             "minGap": f"{drivers.min_gap:.3f}"}  # fmt: skip
            else:
                behaviour = sumo_drivers.attributes(sumo_class)
            ET.SubElement(routes, "vType", id=name, vClass=sumo_class,
                          length=f"{row['length_m']:.3f}", width=f"{row['width_m']:.3f}",
                          height=f"{row['height_m']:.3f}", **behaviour,
                          speedFactor=draw)  # fmt: skip
            rows.append((name, int(c), row["length_m"], row["width_m"], row["height_m"]))
    types = pd.DataFrame(rows, columns=["type", "vehicle_class", "length", "width", "height"])
    types = types.set_index("type")
    for lane in i24.LANES:  # each lane's mix, as the synthesiser draws it
        dist = ET.SubElement(routes, "vTypeDistribution", id=f"mix{lane}")
        hov = lane == i24.HOV_LANE
        for c, weight in enumerate(class_weights(frame, config.heavy_factor, lane)):
            if weight > 0:
                name = f"{frame.loc[c, 'name']}{'_hov' if hov else ''}"
                ET.SubElement(dist, "vType", refId=name, probability=f"{weight:.6f}")
    last = len(pieces) - 1
    first_general = 1 if pieces[0].ramp else 0  # the rightmost lane at the start
    end = config.warmup + 60.0 * config.minutes
    for k, lane in enumerate(i24.LANES):  # -1 .. -4
        flow = config.flow[k]
        if flow <= 0:
            continue
        index = pieces[0].lanes - 1 - k
        if index < first_general:
            continue
        ET.SubElement(routes, "flow", id=f"lane{lane}", type=f"mix{lane}",
                      begin="0", end=f"{end:.1f}", period=f"exp({flow / 3600.0:.6f})",
                      departLane=str(index), departSpeed=depart_speed, departPos="base",
                      **{"from": _edge(0), "to": _edge(last)})  # fmt: skip
    ramp = config.on_ramp
    if ramp is not None and ramp.flow > 0:
        start = next(k for k, p in enumerate(pieces) if p.ramp)
        ET.SubElement(routes, "flow", id="ramp", type=f"mix{-i24.N_LANES}", begin="0",
                      end=f"{end:.1f}", period=f"exp({ramp.flow / 3600.0:.6f})", departLane="0",
                      departSpeed=f"{min(ramp.speed, SPEED_LIMIT):.2f}", departPos="base",
                      **{"from": _edge(start), "to": _edge(last)})  # fmt: skip
    ET.ElementTree(routes).write(folder / "i24.rou.xml", encoding="utf-8", xml_declaration=True)
    return types


# -- the run ----------------------------------------------------------------------------------


def _run(config: SynthConfig, folder: Path, lane_change_duration: float,
         drivers: SumoDrivers | None) -> dict:  # fmt: skip
    """Run SUMO; returns its counts (lane changes, collisions, departed, waiting)."""
    end = config.warmup + 60.0 * config.minutes
    if drivers is not None and drivers.sublane:
        lateral = ["--lateral-resolution", f"{drivers.lateral_resolution}"]
    else:
        lateral = ["--lanechange.duration", f"{lane_change_duration}"]
    _call(
        [
            str(_tool("sumo")),
            "--net-file", str(folder / "i24.net.xml"),
            "--route-files", str(folder / "i24.rou.xml"),
            "--begin", "0", "--end", f"{end:.1f}",
            "--step-length", f"{STEP}",
            "--seed", str(int(config.seed) % (2**31)),
            *lateral,
            "--time-to-teleport", "-1",
            "--collision.action", "warn",
            "--collision.check-junctions", "true",
            "--fcd-output", str(folder / "fcd.parquet"),
            "--fcd-output.attributes", "x,y,angle,type",
            "--device.fcd.begin", f"{max(config.warmup - 1.0, 0.0):.1f}",
            "--lanechange-output", str(folder / "lanechanges.xml"),
            "--statistic-output", str(folder / "statistics.xml"),
            "--no-step-log", "true",
            "--no-warnings", "true",
            "--duration-log.disable", "true",
        ],
        "sumo",
    )  # fmt: skip
    stats = ET.parse(folder / "statistics.xml").getroot()
    vehicles = stats.find("vehicles")
    safety = stats.find("safety")
    changes = sum(1 for _ in ET.iterparse(folder / "lanechanges.xml") if _[1].tag == "change")
    return {
        "lane_changes": changes,
        "collisions": int(safety.get("collisions", 0)) if safety is not None else 0,
        "departed": int(vehicles.get("inserted", 0)) if vehicles is not None else 0,
        "waiting": int(vehicles.get("waiting", 0)) if vehicles is not None else 0,
    }


# -- the recording ----------------------------------------------------------------------------


def _record(config: SynthConfig, pieces: list[_Piece], folder: Path, types: pd.DataFrame):
    """SUMO's floating-car data as recorded tracks: back centre in the road frame,
    inside the recorded range and times, at the camera rate with the preset's tracking
    noise and a per-vehicle phase."""
    try:
        fcd = pd.read_parquet(folder / "fcd.parquet", columns=None)
    except (OSError, ValueError) as error:  # pyarrow's ArrowInvalid is a ValueError
        raise SumoDayError(
            f"SUMO's floating-car data is not Parquet ({error}): SUMO writes Parquet from "
            "1.24 on; python3 -m pip install -U eclipse-sumo"
        ) from None
    fcd = fcd.rename(columns=lambda c: c.removeprefix("vehicle_").removeprefix("timestep_"))
    if "id" not in fcd or fcd.empty:
        raise SumoDayError("SUMO's vehicles never entered the road")
    ids = fcd["id"].astype(str).to_numpy()
    kinds = fcd["type"].astype(str).to_numpy()
    length = types.loc[kinds, "length"].to_numpy(float)
    angle = np.radians(fcd["angle"].to_numpy(float))  # SUMO's: clockwise from north
    # SUMO gives the front bumper; the recording the back centre. SUMO's y grows to the
    # left of travel from the left edge of the HOV lane; the road frame's y to the right,
    # the HOV lane's centre 1.5 lane widths from its origin.
    x = fcd["x"].to_numpy(float) - length * np.sin(angle) + pieces[0].x0
    y = -(fcd["y"].to_numpy(float) - length * np.cos(angle)) + i24.LANE_WIDTH
    t = config.start - config.warmup + fcd["time"].to_numpy(float)
    lo, hi = config.x_record
    seen = (x >= lo) & (x <= hi) & (t >= config.start - STEP)
    frame = pd.DataFrame({"id": ids[seen], "type": kinds[seen], "t": t[seen], "x": x[seen],
                          "y": y[seen]})  # fmt: skip
    frame = frame.sort_values(["id", "t"], kind="stable")
    rng = np.random.default_rng(config.seed)
    vid, tracks, classes, dims = [], [], [], []
    names = sorted(frame["id"].unique(), key=_departure_order)
    groups = dict(tuple(frame.groupby("id", sort=False)))
    for n, name in enumerate(names):
        rows = groups[name]
        track = camera_track(config, rng, rows["t"].to_numpy(), rows["x"].to_numpy(),
                             rows["y"].to_numpy())  # fmt: skip
        if track is None:
            continue
        kind = types.loc[rows["type"].iloc[0]]
        vid.append(n)
        tracks.append(track)
        classes.append(int(kind["vehicle_class"]))
        dims.append((kind["length"], kind["width"], kind["height"]))
    return np.array(vid, np.int64), tracks, np.array(classes, np.int64), np.array(dims, float)


def _departure_order(name: str) -> tuple[str, int]:
    flow, _, number = name.rpartition(".")
    return (flow, int(number)) if number.isdigit() else (name, 0)


# -- helpers ----------------------------------------------------------------------------------


def _tool(name: str) -> Path:
    try:
        return sumo_tool(name)
    except SumoMissing as error:
        raise SumoDayError(str(error)) from None


def _call(command: list[str], what: str) -> None:
    env = {**os.environ, "SUMO_HOME": str(sumo_home())}  # SUMO validates its inputs then
    done = subprocess.run(command, capture_output=True, text=True, check=False, env=env)
    if done.returncode != 0:
        message = (done.stderr or done.stdout).strip().splitlines()[-5:]
        raise SumoDayError(f"{what} failed (exit {done.returncode}): " + " / ".join(message))
