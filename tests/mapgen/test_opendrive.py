"""The OpenDRIVE export against the twin's road model, and read by an independent
reader: Eclipse SUMO's netconvert (``eclipse-sumo`` on PyPI)."""

import itertools
import subprocess
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from mapgen.opendrive import LANES, write_opendrive
from twin.core import i24, ramps
from twin.core.i24 import LANE_WIDTH, Road


@pytest.fixture(scope="module")
def xodr(built_map, tmp_path_factory):
    return write_opendrive(built_map, tmp_path_factory.mktemp("xodr") / "i24.xodr")


def _elevation(road, s: np.ndarray) -> np.ndarray:
    records = road.findall("elevationProfile/elevation")
    starts = np.array([float(e.get("s")) for e in records])
    k = np.searchsorted(starts, s, side="right") - 1
    ds = s - starts[k]
    coefficient = {c: np.array([float(records[i].get(c)) for i in k]) for c in "abcd"}
    a, b, c, d = (coefficient[n] for n in "abcd")
    return a + b * ds + c * ds**2 + d * ds**3


def test_the_file_describes_the_twins_road(xodr, built_map):
    root = ET.parse(xodr).getroot()
    header = root.find("header")
    assert (header.get("revMajor"), header.get("revMinor")) == ("1", "6")
    lat, _, _ = built_map.road.origin
    assert f"+lat_0={lat:.10f}" in header.find("geoReference").text
    (road,) = root.findall("road")
    s0, s1 = built_map.road.station_range
    assert float(road.get("length")) == pytest.approx(s1 - s0)
    # the reference line starts at the map's first station on the median centre line
    line = road.find("planView/geometry")
    start = s0 * built_map.road.direction_vector
    assert (float(line.get("x")), float(line.get("y"))) == pytest.approx(tuple(start))
    # the elevation profile is the map's
    s = np.linspace(0.0, s1 - s0, 97)
    assert np.allclose(_elevation(road, s), built_map.road.surface_z(s + s0), atol=1e-9)
    section = road.find("lanes/laneSection")
    for side, sign in (("right", -1), ("left", 1)):
        lanes = {int(lane.get("id")): lane for lane in section.findall(f"{side}/lane")}
        assert sorted(abs(i) for i in lanes) == [1, 2, 3, 4, 5, 6]
        for number, kind, width, (mark, color), _ in LANES:
            lane = lanes[sign * number]
            assert lane.get("type") == kind
            assert float(lane.find("width").get("a")) == pytest.approx(width)
            road_mark = lane.find("roadMark")
            assert (road_mark.get("type"), road_mark.get("color")) == (mark, color)
        hov = lanes[sign * 2].find("roadMark")
        assert hov.get("type") == "solid solid" and hov.get("laneChange") == "none"
        # the HOV lane is a driving lane whose restriction is kept where readers look
        hov_lane = lanes[sign * 2]
        assert hov_lane.get("type") == "driving"
        assert hov_lane.find("rule").get("value") == "car pool"
        access = hov_lane.find("access")
        assert (access.get("rule"), access.get("restriction")) == ("deny", "truck")
        assert "HOV" in hov_lane.find("userData").get("value")
    objects = road.find("objects")
    kinds = [o.get("type") for o in objects.findall("object")]
    assert kinds.count("barrier") == 1 and "overpass" in {o.get("subtype") for o in objects}
    assert kinds.count("pole") == len(built_map.description["objects"]["poles"]) + len(
        built_map.description["objects"]["posts"]
    )


def test_the_export_is_the_same_bit_for_bit(xodr, built_map, tmp_path):
    again = write_opendrive(built_map, tmp_path / "again.xodr")
    assert again.read_bytes() == xodr.read_bytes()


def _netconvert(xodr, net, *options):
    sumo = pytest.importorskip("sumo", reason="eclipse-sumo is not installed")
    from pathlib import Path

    done = subprocess.run(
        [str(Path(sumo.SUMO_HOME) / "bin" / "netconvert"), "--opendrive-files", str(xodr),
         "--output-file", str(net), *options],
        capture_output=True, text=True, env={"SUMO_HOME": sumo.SUMO_HOME},
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    edges = [e for e in ET.parse(net).getroot().findall("edge") if e.get("function") is None]
    sides = {Road.EASTBOUND: [], Road.WESTBOUND: []}
    for edge in edges:  # netconvert cuts a side into edges where its lanes change
        sides[Road.EASTBOUND if edge.get("id").startswith("-") else Road.WESTBOUND].append(edge)
    return sides


def _length(edge) -> float:
    return float(edge.find("lane").get("length"))


def test_netconvert_drives_the_lanes_and_the_on_ramps_lanes_with_its_default_options(
    xodr, built_map, tmp_path
):
    """netconvert imports only lanes it can drive unless told otherwise: the HOV lane and
    the on-ramps' acceleration lanes (OpenDRIVE ``entry`` lanes) are among them, so each
    carriageway has the twin's four lanes, and a fifth beside an on-ramp's lane."""
    sides = _netconvert(xodr, tmp_path / "default.net.xml")
    for road, edges in sides.items():
        assert sorted({len(edge.findall("lane")) for edge in edges}) == [4, 5]
        for edge in edges:  # the access record keeps trucks out of the HOV lane (the last)
            hov = edge.findall("lane")[-1].get("allow").split()
            assert "hov" in hov and "passenger" in hov and "truck" not in hov
        # the acceleration lane's edges span it: from its opening (or the map's start)
        # to its taper's end
        (ramp,) = [r for r in built_map.road.ramps if r.road is road]
        start = max(ramp.x_start - ramps.OPENING, built_map.road.x_range(road)[0])
        beside = sum(_length(e) for e in edges if len(e.findall("lane")) == 5)
        assert beside == pytest.approx(ramp.x_end - start, rel=0.05)


def test_netconvert_reads_it_as_the_twins_lanes(xodr, built_map, tmp_path):
    """SUMO's network from the file: each carriageway a chain of edges of six lanes,
    seven beside an on-ramp's lane, the twin's widths, end to end with no more than 10 m
    between edges (netconvert's junctions), and lane centres within 5 cm of
    ``RoadModel.to_world``, the on-ramp's lane's too."""
    sides = _netconvert(
        xodr, tmp_path / "i24.net.xml", "--offset.disable-normalization", "true",
        "--opendrive.import-all-lanes", "true",
    )  # fmt: skip
    road_model = built_map.road
    for road, edges in sides.items():
        x_all, spans = [], []
        for edge in edges:
            lanes = edge.findall("lane")
            assert len(lanes) in (6, 7)
            # SUMO counts lanes from the outside: 0 the shoulder .. the median strip
            widths = [float(lane.get("width")) for lane in lanes]
            assert widths[0] == pytest.approx(3.048, abs=0.006)
            assert widths[-5:] == pytest.approx([LANE_WIDTH] * 5, abs=0.006)
            n = len(lanes)
            pairs = [(n - 1 + k, k) for k in (-1, -2, -3, -4)]
            if n == 7 and widths[1] == pytest.approx(LANE_WIDTH, abs=0.006):
                pairs.append((1, ramps.RAMP_LANE))  # where the on-ramp's lane is full
            for index, twin_lane in pairs:
                shape = np.array(
                    [
                        [float(v) for v in point.split(",")]
                        for point in lanes[index].get("shape").split()
                    ]
                )
                coordinates = road_model.to_road(shape)
                assert np.all(coordinates.road == road.direction)
                assert np.abs(coordinates.y - (-twin_lane + 0.5) * LANE_WIDTH).max() < 0.05
                # on the twin's pavement (SUMO's 1 cm rounding puts an end a hair off the map)
                height = coordinates.height[np.isfinite(coordinates.height)]
                assert height.size >= len(shape) - 2 and np.abs(height).max() < 0.05
                x_all.append(coordinates.x)
                if twin_lane == -1:
                    spans.append((coordinates.x.min(), coordinates.x.max()))
        spans.sort()
        assert max(b[0] - a[1] for a, b in itertools.pairwise(spans)) < 10.0
        x = np.concatenate(x_all)
        assert x.min() < road_model.x_range(road)[0] + 1.0  # from end to end
        assert x.max() > road_model.x_range(road)[1] - 1.0


def test_the_on_ramps_lanes_are_entry_lanes_as_wide_as_the_maps(xodr, built_map):
    """Each on-ramp's acceleration lane is an ``entry`` lane (id -6 eastbound, 6
    westbound) beside lane -4 in the lane sections it runs through, as wide as the map's
    lane -5 along its opening, gore and taper, with a broken line between it and lane
    -4 and the shoulder beyond it."""
    road = ET.parse(xodr).getroot().find("road")
    s0 = built_map.road.station_range[0]
    sections = road.findall("lanes/laneSection")
    starts = [float(sec.get("s")) for sec in sections]
    ends = [*starts[1:], float(road.get("length"))]
    for side, sign, name in (("right", -1, Road.EASTBOUND), ("left", 1, Road.WESTBOUND)):
        seen = 0.0
        for section, start, end in zip(sections, starts, ends, strict=True):
            lanes = {int(lane.get("id")): lane for lane in section.findall(f"{side}/lane")}
            ds = np.linspace(0.0, end - start, 9)
            station = s0 + start + ds
            x = station if sign < 0 else i24.SEGMENT_LENGTH - station
            expected = built_map.road.ramp_width(name, x)
            entry = lanes.get(sign * 6)
            if entry is None or entry.get("type") != "entry":
                assert expected.max() < 1e-6
                assert lanes[sign * 6].get("type") == "shoulder"
                continue
            width = entry.find("width")
            a, b = float(width.get("a")), float(width.get("b"))
            np.testing.assert_allclose(a + b * ds, expected, atol=1e-6)
            middle = x[4]  # lane -4's line: broken from the gore to the end, solid before
            ramp = built_map.road.ramps[0 if sign < 0 else 1]
            beside = ramp.x_start <= middle <= ramp.x_end
            mark = lanes[sign * 5].find("roadMark").get("type")
            assert mark == ("broken" if beside else "solid")
            assert lanes[sign * 7].get("type") == "shoulder"
            seen += end - start
        ramp = built_map.road.ramps[0 if sign < 0 else 1]
        lo, hi = built_map.road.x_range(name)
        assert seen == pytest.approx(min(ramp.x_end, hi) - max(ramp.x_start - ramps.OPENING, lo))
