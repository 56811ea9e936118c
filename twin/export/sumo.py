"""A twin run as Eclipse SUMO inputs: replay the same episode in SUMO next to the
twin's result.

``twin export RUN --format sumo --out DIR`` writes into ``DIR``:

- ``i24.xodr`` and ``i24.net.xml``: the segment (:mod:`mapgen.opendrive`) and SUMO's
  network of it (``netconvert``, coordinates kept: SUMO's x, y are the twin's world),
  with the HOV lane's double solid line as SUMO's lane-change permissions (only
  emergency vehicles cross; netconvert does not read OpenDRIVE's ``laneChange``);
- ``routes.rou.xml``: every recorded vehicle of the run (the ego, the visible
  vehicles and the ghosts) but one first seen in its last step, departing at the time,
  lane, position and speed the run first had it (without SUMO's insertion checks:
  recorded queues are tighter than its safe gaps), on its carriageway's edge, with a
  vehicle type of its own size;
- ``twin.fcd.xml``: the twin's trajectories in SUMO's floating-car-data format
  (every vehicle at 10 Hz: front bumper x, y, z, angle, speed, lane and position);
- ``i24.sumocfg``: SUMO's configuration of the episode (``sumo -c i24.sumocfg``).

netconvert cuts each carriageway into edges where its lanes change (an on-ramp's
acceleration lane, the twin's lane -5, is kept as a lane of the edges it runs beside):
a vehicle departs on the edge under its front bumper, and its route runs from there to
the carriageway's end. Times are seconds from the run's t0; SUMO lanes count from the
outside (0 the shoulder; on an edge of n lanes, index n - 2 is the twin's HOV lane -1,
n - 5 its lane -4 and n - 6 an acceleration lane).
"""

import math
import subprocess
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from mapgen.opendrive import write_opendrive
from twin.core.atomic import AtomicFolder
from twin.core.i24 import VEHICLE_CLASSES, Road
from twin.core.ramps import RAMP_LANE
from twin.core.sumo import SumoMissing
from twin.core.sumo import sumo_home as core_sumo_home
from twin.export.episode import ExportError, read_episode

FCD_PERIOD = 0.1  # [s]
SIDES = {Road.EASTBOUND: "-1", Road.WESTBOUND: "1"}  # netconvert's ids of the two sides
LANE_IDS = (-1, -2, -3, -4, RAMP_LANE)
HEAVY = {"semi", "truck"}


def sumo_home() -> Path:
    """SUMO's home (the ``eclipse-sumo`` package).

    Raises:
        ExportError: it is not installed.
    """
    try:
        return core_sumo_home()
    except SumoMissing as error:
        raise ExportError(f"exporting to SUMO: {error}") from None


@dataclass(frozen=True)
class Edge:
    """One of netconvert's edges of a carriageway: its id, lane count and the road-frame
    x its lanes span (along travel)."""

    id: str
    lanes: int
    x_start: float
    x_end: float


def sumo_lane(lane: int, lanes: int) -> int:
    """SUMO's lane index of the twin's lane -1..-5 on an edge of ``lanes`` lanes (SUMO
    counts from the outside, 0 the shoulder, ``lanes - 1`` the median strip)."""
    return lanes - 1 + int(lane)


def edges_of(net: Path, road_model) -> dict[Road, list[Edge]]:
    """Each carriageway's edges in SUMO's network ``net``, in travel order."""
    chains = {road: [] for road in SIDES}
    for edge in ET.parse(net).getroot().findall("edge"):
        if edge.get("function") is not None:
            continue
        road = next((r for r, prefix in SIDES.items() if edge.get("id").split("#")[0] == prefix),
                    None)  # fmt: skip
        if road is None:
            continue
        lanes = edge.findall("lane")
        shape = np.array([[float(v) for v in p.split(",")] for p in lanes[-2].get("shape").split()])
        x = road_model.to_road(shape).x
        chains[road].append(Edge(edge.get("id"), len(lanes), float(x.min()), float(x.max())))
    return {road: sorted(edges, key=lambda e: e.x_start) for road, edges in chains.items()}


def _edge_at(edges: list[Edge], x: np.ndarray) -> np.ndarray:
    """(n,) index into ``edges`` of the edge under road-frame ``x`` (the first or last
    beyond the ends)."""
    starts = np.array([e.x_start for e in edges])
    return np.clip(np.searchsorted(starts, x, side="right") - 1, 0, len(edges) - 1)


def export_run(run: Path, out: Path, bundle) -> dict:
    """Write the SUMO inputs of run folder ``run`` into ``out`` (atomically); returns
    what was written (counts and file names).

    Raises:
        ExportError: ``run`` is not a run folder, or SUMO is missing or fails.
    """
    out = Path(out)
    episode = read_episode(run)
    home = sumo_home()
    config, rows = episode.config, episode.rows
    road_model = bundle.road
    recognise = lambda p: (p / "i24.sumocfg").is_file()  # noqa: E731
    with AtomicFolder(out, recognise=recognise, kind="SUMO export", error=ExportError) as folder:
        xodr = write_opendrive(bundle, folder.tmp / "i24.xodr")
        done = subprocess.run(
            [str(home / "bin" / "netconvert"), "--opendrive-files", str(xodr),
             "--output-file", str(folder.tmp / "i24.net.xml"),
             "--offset.disable-normalization", "true", "--opendrive.import-all-lanes", "true",
             "--no-warnings", "true"],
            capture_output=True, text=True, env={"SUMO_HOME": str(home)},
        )  # fmt: skip
        if done.returncode != 0:
            raise ExportError(f"netconvert failed: {done.stderr.strip()[-500:]}")
        _hov_line(folder.tmp / "i24.net.xml")
        edges = edges_of(folder.tmp / "i24.net.xml", road_model)
        vehicles = _routes(rows, edges, folder.tmp / "routes.rou.xml", config.t_max)
        samples = _fcd(rows, road_model, edges, folder.tmp / "twin.fcd.xml")
        _config(config.t_max, folder.tmp / "i24.sumocfg")
    return {"folder": str(out), "vehicles": vehicles, "fcd_samples": samples,
            "duration_s": config.t_max}  # fmt: skip


def _hov_line(net: Path) -> None:
    """The HOV lane's double solid line in SUMO's network: netconvert (1.28) does not
    read OpenDRIVE's ``laneChange``, so no class but emergency vehicles may change
    between the HOV lane and lane -2, on every edge of both carriageways."""
    tree = ET.parse(net)
    for edge in tree.getroot().findall("edge"):
        if edge.get("function") is not None or edge.get("id").split("#")[0] not in SIDES.values():
            continue
        lanes = edge.findall("lane")
        for lane in lanes:
            index = int(lane.get("index"))
            if index == sumo_lane(-2, len(lanes)):
                lane.set("changeLeft", "emergency")
            elif index == sumo_lane(-1, len(lanes)):
                lane.set("changeRight", "emergency")
    tree.write(net, encoding="utf-8", xml_declaration=True)


def _routes(rows: pd.DataFrame, edges: dict[Road, list[Edge]], path: Path, duration: float) -> int:
    first = rows.sort_values(["time", "record_id"]).groupby("record_id", sort=False).head(1)
    # a vehicle first seen in the run's last step would depart as SUMO's run ends
    first = first[first["time"] < duration - 1e-6]
    first = first.sort_values(["time", "record_id"], kind="stable")
    root = ET.Element("routes")
    for chain in edges.values():  # from each edge to the carriageway's end
        for k in range(len(chain)):
            ET.SubElement(root, "route", id=f"r{chain[k].id}",
                          edges=" ".join(e.id for e in chain[k:]))  # fmt: skip
    kept = 0
    for row in first.itertuples(index=False):
        road = Road.parse(int(row.road))
        lane = int(row.lane)
        front = row.x + row.length
        edge = edges[road][int(_edge_at(edges[road], np.array([front]))[0])]
        if lane not in LANE_IDS or sumo_lane(lane, edge.lanes) < 1:
            continue  # between lanes at its first row, or beside a lane that is not here
        name = VEHICLE_CLASSES[int(row.vehicle_class)]
        ET.SubElement(  # a type of its own: its recorded size
            root, "vType", id=f"t{row.record_id}", vClass="truck" if name in HEAVY else
            "passenger", length=f"{row.length:.2f}", width=f"{row.width:.2f}",
            minGap="1.0",  # recorded queues stand 1 to 2 m apart (SUMO's default is 2.5)
        )  # fmt: skip
        ET.SubElement(
            root, "vehicle", id=str(row.record_id), type=f"t{row.record_id}",
            route=f"r{edge.id}", depart=f"{row.time:.2f}",
            departLane=str(sumo_lane(lane, edge.lanes)),
            departPos=f"{min(max(front - edge.x_start, 0.0), edge.x_end - edge.x_start):.2f}",
            departSpeed=f"{max(row.speed, 0.0):.2f}",
            # at its recorded place and speed even where SUMO's safe gap is larger (queues)
            insertionChecks="none",
        )  # fmt: skip
        kept += 1
    tree = ET.ElementTree(root)
    ET.indent(tree)
    tree.write(path, encoding="utf-8", xml_declaration=True)
    return kept


def _fcd(rows: pd.DataFrame, road_model, edges: dict[Road, list[Edge]], path: Path) -> int:
    tick = np.round(rows["time"].to_numpy() / FCD_PERIOD)
    sampled = rows[np.isclose(rows["time"].to_numpy(), tick * FCD_PERIOD, atol=1e-6)]
    sampled = sampled.sort_values(["time", "record_id"], kind="stable")
    direction = sampled["road"].to_numpy().astype(np.int64)
    front = sampled["x"].to_numpy() + sampled["length"].to_numpy()
    lo = np.where(direction > 0, road_model.x_range(1)[0], road_model.x_range(-1)[0])
    hi = np.where(direction > 0, road_model.x_range(1)[1], road_model.x_range(-1)[1])
    position, _, pitch = road_model.to_world(
        direction, np.clip(front, lo, hi), sampled["y"].to_numpy()
    )
    angle = (90.0 - np.degrees(sampled["heading"].to_numpy())) % 360.0
    on_edge = {
        road: _edge_at(chain, front[direction == road.direction]) for road, chain in edges.items()
    }
    edge_of = np.empty(len(sampled), dtype=object)
    for road, chain in edges.items():
        edge_of[direction == road.direction] = [chain[k] for k in on_edge[road]]
    with open(path, "w", encoding="utf-8") as f:
        f.write('<?xml version="1.0" encoding="UTF-8"?>\n<fcd-export>\n')
        current = None
        for i, row in enumerate(sampled.itertuples(index=False)):
            if row.time != current:
                if current is not None:
                    f.write("  </timestep>\n")
                current = row.time
                f.write(f'  <timestep time="{row.time:.2f}">\n')
            lane, edge = int(row.lane), edge_of[i]
            index = sumo_lane(lane, edge.lanes) if lane in LANE_IDS else 0
            lane_id = f"{edge.id}_{index}" if index >= 1 else ""
            x, y, z = position[i]
            f.write(
                f'    <vehicle id="{row.record_id}" x="{x:.2f}" y="{y:.2f}" z="{z:.2f}" '
                f'angle="{angle[i]:.2f}" type="{VEHICLE_CLASSES[int(row.vehicle_class)]}" '
                f'speed="{max(row.speed, 0.0):.2f}" pos="{front[i] - edge.x_start:.2f}" '
                f'lane="{lane_id}" slope="{math.degrees(pitch[i]):.2f}" '
                f'role="{row.role}"/>\n'
            )
        if current is not None:
            f.write("  </timestep>\n")
        f.write("</fcd-export>\n")
    return len(sampled)


def _config(duration: float, path: Path) -> None:
    root = ET.Element("configuration")
    inputs = ET.SubElement(root, "input")
    ET.SubElement(inputs, "net-file", value="i24.net.xml")
    ET.SubElement(inputs, "route-files", value="routes.rou.xml")
    time = ET.SubElement(root, "time")
    ET.SubElement(time, "begin", value="0")
    ET.SubElement(time, "end", value=f"{duration:g}")
    ET.SubElement(time, "step-length", value=f"{FCD_PERIOD:g}")
    tree = ET.ElementTree(root)
    ET.indent(tree)
    tree.write(path, encoding="utf-8", xml_declaration=True)
