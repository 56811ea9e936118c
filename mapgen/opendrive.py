"""The mapped segment as ASAM OpenDRIVE 1.6, for CARLA, esmini, SUMO (netconvert),
CommonRoad and the other tools that read road networks.

One road carries both carriageways. Its reference line is the median centre line,
straight along the alignment's bearing in the direction of eastbound travel, from
the map's first station to its last, in the twin's world frame (x east, y north, z
up, metres); so OpenDRIVE's right-hand lanes (negative ids) are the eastbound
carriageway and the left-hand ones (positive ids) the westbound one, and a point at
(s, t) is the twin's world point ``(s0 + s) d - t r`` (d the direction, r the unit
vector to the right of eastbound travel). The lanes, outward from the median on each
side:

==========  ============================  =========  =================================
OpenDRIVE   twin                          type       outer road mark
==========  ============================  =========  =================================
+-1         the paved median strip        median     solid yellow
+-2         lane -1, the HOV lane         driving    solid solid white (no crossing)
+-3, +-4    lanes -2, -3                  driving    broken white, 10 ft on 30 ft off
+-5         lane -4                       driving    solid white (the edge line)
+-6         the outer paved shoulder      shoulder   none
==========  ============================  =========  =================================

The HOV lane is a ``driving`` lane, so that every reader drives it (netconvert's
default import, CARLA, whose road model has no HOV type), with its restriction where
readers look for it: a lane ``rule`` ``car pool`` (OpenDRIVE 1.6's value for it), an
``access`` record that denies trucks (Tennessee keeps heavy trucks out of the leftmost
lane; the twin's class table does too) and ``userData`` naming it the HOV lane.

Lane widths are 12 ft (3.6576 m); the shoulder 10 ft. The elevation profile is the
map's (``grade_elevation.csv`` through the map build), one linear ``elevation``
record per profile segment; the cross slope is zero as in the map. The median
barrier, the Old Franklin Rd overpass, the I-24 MOTION camera poles and the
0.1-mile posts are objects. The header's ``geoReference`` is a transverse Mercator
PROJ string centred on the world origin (the median centre line at MM 60.6): the
twin's local east-north-up frame to well under a millimetre over the segment.
"""

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from mapgen.params import load_params
from twin.core.atomic import atomic_file
from twin.core.i24 import LANE_WIDTH

XODR = "i24.xodr"  # its name in a map folder (twin map build)
HOV_ID = 2  # [-] |OpenDRIVE lane id| of the HOV lane (the twin's lane -1)
SHOULDER_WIDTH = 3.048  # [m] 10 ft
MARK_WIDTH = 0.1524  # [m] 6 in
DASH, GAP = 3.048, 9.144  # [m] 10 ft painted, 30 ft gap
BARRIER = {"width": 0.6096, "height": 1.0668}  # [m] the concrete median barrier
LANES = (  # (OpenDRIVE |id|, type, width, outer mark, twin name)
    (1, "median", LANE_WIDTH, ("solid", "yellow"), "the paved median strip"),
    (2, "driving", LANE_WIDTH, ("solid solid", "white"), "lane -1 (HOV)"),
    (3, "driving", LANE_WIDTH, ("broken", "white"), "lane -2"),
    (4, "driving", LANE_WIDTH, ("broken", "white"), "lane -3"),
    (5, "driving", LANE_WIDTH, ("solid", "white"), "lane -4"),
    (6, "shoulder", SHOULDER_WIDTH, ("none", "standard"), "the outer shoulder"),
)


def proj_string(latitude: float, longitude: float) -> str:
    """A PROJ string of the world frame: transverse Mercator on the origin."""
    return (
        f"+proj=tmerc +lat_0={latitude:.10f} +lon_0={longitude:.10f} +k=1 +x_0=0 +y_0=0 "
        "+ellps=WGS84 +units=m +no_defs"
    )


def opendrive(bundle) -> ET.ElementTree:
    """The OpenDRIVE document of a built map (``mapgen.build.MapBundle``)."""
    road_model, description = bundle.road, bundle.description
    s0, s1 = road_model.station_range
    length = s1 - s0
    d = road_model.direction_vector
    start = s0 * d
    heading = math.atan2(d[1], d[0])
    lat, lon, _ = road_model.origin

    root = ET.Element("OpenDRIVE")
    header = ET.SubElement(
        root,
        "header",
        revMajor="1",
        revMinor="6",
        name="I-24 westbound and eastbound, MM 60.6 to 61.6 (i24-twin)",
        version=str(description.get("key", "")),
        vendor="i24-twin",
    )
    ET.SubElement(header, "geoReference").text = proj_string(lat, lon)
    ET.SubElement(
        header,
        "userData",
        code="i24twin:lanes",
        value=(
            "right lanes (negative ids) carry eastbound traffic, left lanes (positive ids) "
            "westbound; on each side, outward: 1 paved median strip, 2 the twin's lane -1 "
            "(HOV, double solid line), 3 and 4 lanes -2 and -3, 5 lane -4, 6 the shoulder"
        ),
    )

    road = ET.SubElement(
        root, "road", name="I-24", length=_f(length), id="1", junction="-1", rule="RHT"
    )
    kind = ET.SubElement(road, "type", s="0", type="motorway")
    ET.SubElement(kind, "speed", max="70", unit="mph")
    plan = ET.SubElement(road, "planView")
    geometry = ET.SubElement(
        plan, "geometry", s="0", x=_f(start[0]), y=_f(start[1]), hdg=_f(heading),
        length=_f(length),
    )  # fmt: skip
    ET.SubElement(geometry, "line")
    profile = ET.SubElement(road, "elevationProfile")
    ss, zz = road_model.profile_s, road_model.profile_z
    for k in range(len(ss) - 1):
        slope = (zz[k + 1] - zz[k]) / (ss[k + 1] - ss[k])
        ET.SubElement(
            profile, "elevation", s=_f(ss[k] - s0), a=_f(zz[k]), b=_f(slope), c="0", d="0"
        )
    lateral = ET.SubElement(road, "lateralProfile")
    ET.SubElement(lateral, "superelevation", s="0", a="0", b="0", c="0", d="0")

    lanes = ET.SubElement(road, "lanes")
    section = ET.SubElement(lanes, "laneSection", s="0")
    groups = {side: ET.SubElement(section, side) for side in ("left", "center", "right")}
    for side, sign in (("left", 1), ("right", -1)):  # the schema's order: left, center, right
        group = groups[side]
        ordered = LANES if sign < 0 else tuple(reversed(LANES))
        for number, kind, width, (mark, color), _ in ordered:
            lane = ET.SubElement(group, "lane", id=str(sign * number), type=kind, level="false")
            ET.SubElement(lane, "link")
            ET.SubElement(lane, "width", sOffset="0", a=_f(width), b="0", c="0", d="0")
            _road_mark(lane, mark, color)
            if kind == "driving":
                ET.SubElement(lane, "speed", sOffset="0", max="70", unit="mph")
            if number == HOV_ID:
                _hov_restriction(lane)
    middle = ET.SubElement(groups["center"], "lane", id="0", type="none", level="false")
    ET.SubElement(middle, "link")
    _road_mark(middle, "none", "standard")

    _objects(road, road_model, description, s0)
    tree = ET.ElementTree(root)
    ET.indent(tree)
    return tree


def write_opendrive(bundle, path: str | Path) -> Path:
    """Write :func:`opendrive` of ``bundle`` to ``path`` (atomically)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_file(path) as tmp:
        opendrive(bundle).write(tmp, encoding="utf-8", xml_declaration=True)
    return path


def _hov_restriction(lane) -> None:
    """The HOV lane's rule in the forms readers know: OpenDRIVE 1.6's lane rule value
    ``car pool``, an access record denying trucks, and the twin's own ``userData``."""
    ET.SubElement(lane, "access", sOffset="0", rule="deny", restriction="truck")
    ET.SubElement(lane, "rule", sOffset="0", value="car pool")
    ET.SubElement(lane, "userData", code="i24-twin:restriction",
                  value="HOV: high-occupancy vehicles only; no heavy trucks")  # fmt: skip


def _road_mark(lane, mark: str, color: str) -> None:
    attributes = {
        "sOffset": "0",
        "type": mark,
        "color": color,
        "material": "standard",
        "width": _f(MARK_WIDTH if mark != "none" else 0.0),
        "laneChange": "none" if mark in ("solid", "solid solid") else "both",
    }
    element = ET.SubElement(lane, "roadMark", attributes)
    if mark == "broken":
        pattern = ET.SubElement(element, "type", name="broken 10/30 ft", width=_f(MARK_WIDTH))
        ET.SubElement(pattern, "line", length=_f(DASH), space=_f(GAP), tOffset="0",
                      sOffset="0", rule="caution", width=_f(MARK_WIDTH))  # fmt: skip
    if mark == "solid solid":
        pattern = ET.SubElement(element, "type", name="double solid", width=_f(3 * MARK_WIDTH))
        for offset in (-MARK_WIDTH, MARK_WIDTH):
            ET.SubElement(pattern, "line", length=_f(0.0), space=_f(0.0), tOffset=_f(offset),
                          sOffset="0", rule="no passing", width=_f(MARK_WIDTH))  # fmt: skip


def _objects(road, road_model, description, s0: float) -> None:
    objects = ET.SubElement(road, "objects")
    s_end = road_model.station_range[1] - s0
    ET.SubElement(
        objects, "object", type="barrier", name="concrete median barrier", id="barrier",
        s="0", t="0", zOffset="0", length=_f(s_end), width=_f(BARRIER["width"]),
        height=_f(BARRIER["height"]), hdg="0", pitch="0", roll="0", orientation="none",
    )  # fmt: skip
    found = description.get("objects", {})
    deck = found.get("overpass")
    if deck:
        a, b = deck["deck_stations_m"]
        outer = description["cross_section"]["outer_edge_y_m"]
        z = deck["deck_bottom_z_m"] - float(road_model.surface_z((a + b) / 2))
        shape = load_params().overpass
        ET.SubElement(
            objects, "object", type="none", subtype="overpass", name=deck["name"],
            id="overpass", s=_f((a + b) / 2 - s0), t="0", zOffset=_f(z), length=_f(b - a),
            width=_f(2 * (outer + shape.abutment_offset)),
            height=_f(shape.deck_depth + shape.parapet_height), hdg="0", pitch="0", roll="0",
            orientation="none",
        )  # fmt: skip
    for pole in found.get("poles", []):
        ET.SubElement(
            objects, "object", type="pole", subtype="I-24 MOTION camera pole",
            name=f"pole {pole['pole']}", id=f"pole{pole['pole']}",
            s=_f(pole["station_m"] - s0), t=_f(-pole["lateral_m"]), zOffset="0",
            height=_f(pole["height_m"]), radius=_f(load_params().poles.base_radius), hdg="0",
            pitch="0", roll="0",
            orientation="none",
        )  # fmt: skip
    for k, post in enumerate(found.get("posts", [])):
        ET.SubElement(
            objects, "object", type="pole", subtype="mile post",
            name=f"MM {post['mm']:.1f} {post['road']}", id=f"post{k}",
            s=_f(post["station_m"] - s0), t=_f(-post["lateral_m"]), zOffset="0",
            height="1.5", radius="0.05", hdg="0", pitch="0", roll="0",
            orientation="-" if post["road"] == "westbound" else "+",
        )  # fmt: skip


def _f(value) -> str:
    """A number as OpenDRIVE text: round-trip exact, no exponent noise for zeros."""
    value = float(np.asarray(value))
    return "0" if value == 0.0 else repr(value)
