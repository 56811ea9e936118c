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

Where an on-ramp's acceleration lane runs beside lane -4 (:mod:`twin.core.ramps`: the
eastbound Hickory Hollow Pkwy and westbound Old Hickory Blvd on-ramps), the road has
lane sections of their own, cut where its width changes slope (its opening, gore,
taper and end): there lane +-6 is that lane, type ``entry`` (OpenDRIVE's acceleration
lane, which netconvert imports with its default options and CARLA keeps), with a linear
width record (its opening from nothing and its taper to nothing), a solid white outer
edge line, lane +-5's outer line broken, and the shoulder is +-7. Lanes link to
themselves across sections (the shoulder from +-6 to +-7); the acceleration lane links
to nothing where it opens and where its taper ends.

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
from twin.core.i24 import LANE_WIDTH, Road

XODR = "i24.xodr"  # its name in a map folder (twin map build)
HOV_ID = 2  # [-] |OpenDRIVE lane id| of the HOV lane (the twin's lane -1)
RAMP_ID = 6  # [-] |OpenDRIVE lane id| of an on-ramp's acceleration lane (the twin's lane -5)
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
            "(HOV, double solid line), 3 and 4 lanes -2 and -3, 5 lane -4, 6 the shoulder; "
            "where an on-ramp's acceleration lane (the twin's lane -5) runs, 6 is that lane "
            "(type entry) and 7 the shoulder"
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
    cuts = _section_starts(road_model)
    for k, start in enumerate(cuts):
        end = cuts[k + 1] if k + 1 < len(cuts) else s1
        after = cuts[k + 2] if k + 2 < len(cuts) else s1
        neighbours = (cuts[k - 1] if k else None, after if k + 1 < len(cuts) else None)
        _lane_section(lanes, road_model, start, end, neighbours, s0)
    _objects(road, road_model, description, s0)
    tree = ET.ElementTree(root)
    ET.indent(tree)
    return tree


def _section_starts(road_model) -> list[float]:
    """[m] eastbound stations where a lane section starts: the map's first, and every
    point where an acceleration lane's width changes slope."""
    return [road_model.station_range[0], *(float(s) for s in road_model.ramp_stations())]


def _side(sign: int) -> Road:
    """The carriageway on OpenDRIVE's ``sign`` side: -1 right (eastbound), +1 left."""
    return Road.EASTBOUND if sign < 0 else Road.WESTBOUND


def _ramp_widths(road_model, sign: int, start: float, end: float) -> tuple[float, float]:
    """[m] the acceleration lane's width at a section's two ends on side ``sign``."""
    road = _side(sign)
    w = road_model.ramp_width(road, road_model.station(road, np.array([start, end])))
    w[w < 1e-9] = 0.0  # round-off at the ends of a taper is no lane
    return float(w[0]), float(w[1])


def _beside(road_model, sign: int, start: float, end: float) -> bool:
    """Whether a section lies between an acceleration lane's gore and its end on side
    ``sign`` (lane -4's line is broken there; not on the lane's opening)."""
    road = _side(sign)
    x = float(road_model.station(road, np.array([0.5 * (start + end)]))[0])
    return any(r.road is road and r.x_start <= x <= r.x_end for r in road_model.ramps)


def _lane_section(lanes, road_model, start: float, end: float, neighbours, s0: float) -> None:
    """One ``laneSection`` from eastbound station ``start`` to ``end``; ``neighbours``
    are where the section before it starts and the one after it ends (None at the
    road's ends)."""
    section = ET.SubElement(lanes, "laneSection", s=_f(start - s0))
    groups = {side: ET.SubElement(section, side) for side in ("left", "center", "right")}
    for side, sign in (("left", 1), ("right", -1)):  # the schema's order: left, center, right
        ramp = _ramp_widths(road_model, sign, start, end)
        first, last = neighbours
        before = None if first is None else _ramp_widths(road_model, sign, first, start)
        after = None if last is None else _ramp_widths(road_model, sign, end, last)
        rows = _lanes(ramp, _beside(road_model, sign, start, end))
        for number, kind, width, (mark, color), _ in rows if sign < 0 else rows[::-1]:
            lane = ET.SubElement(groups[side], "lane", id=str(sign * number), type=kind,
                                 level="false")  # fmt: skip
            _lane_links(lane, sign, number, kind, before, after)
            length = end - start
            ET.SubElement(lane, "width", sOffset="0", **_width(width, length))
            _road_mark(lane, mark, color)
            if kind in ("driving", "entry"):
                ET.SubElement(lane, "speed", sOffset="0", max="70", unit="mph")
            if number == HOV_ID:
                _hov_restriction(lane)
    middle = ET.SubElement(groups["center"], "lane", id="0", type="none", level="false")
    ET.SubElement(middle, "link")
    _road_mark(middle, "none", "standard")


def _lanes(ramp: tuple[float, float], beside: bool) -> list[tuple]:
    """The lanes of a side, outward, with an acceleration lane (``entry``) between lane
    -4 and the shoulder where ``ramp`` (its widths at the section's ends) is not nothing,
    and lane -4's outer line broken ``beside`` it; widths as (start, end) pairs."""
    rows = [(n, k, (w, w), m, name) for n, k, w, m, name in LANES]
    if max(ramp) > 0.0:
        if beside:
            n, kind, width, _, name = rows[-2]
            rows[-2] = (n, kind, width, ("broken", "white"), name)
        shoulder = rows[-1]
        rows[-1] = (RAMP_ID, "entry", ramp, ("solid", "white"), "the on-ramp's lane (-5)")
        rows.append((RAMP_ID + 1, *shoulder[1:]))
    return rows


def _width(width: tuple[float, float], length: float) -> dict:
    """A linear width record from ``width`` at the section's start to its end."""
    return {"a": _f(width[0]), "b": _f((width[1] - width[0]) / length), "c": "0", "d": "0"}


def _lane_links(lane, sign, number, kind, before, after) -> None:
    """Links to the same lane in the sections before and after (``before``/``after``:
    their acceleration lane's widths, None at the road's ends): the shoulder's id moves
    out by one where an acceleration lane runs; that lane links only to itself, where
    it begins (it opens from nothing) and ends (its taper) to nothing."""
    link = ET.SubElement(lane, "link")
    for tag, other in (("predecessor", before), ("successor", after)):
        if other is None or (kind == "entry" and max(other) == 0.0):
            continue
        their = number
        if kind == "shoulder":
            their = RAMP_ID + 1 if max(other) > 0.0 else RAMP_ID
        ET.SubElement(link, tag, id=str(sign * their))


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
