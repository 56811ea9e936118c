"""The OpenDRIVE export against the twin's road model, and read by an independent
reader: Eclipse SUMO's netconvert (``eclipse-sumo`` on PyPI)."""

import subprocess
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from mapgen.opendrive import LANES, write_opendrive
from twin.core.i24 import LANE_WIDTH, Road, lane_center


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


def test_netconvert_drives_four_lanes_each_way_with_its_default_options(xodr, tmp_path):
    """netconvert imports only lanes it can drive unless told otherwise: the HOV lane is
    one of them, so each carriageway has the twin's four lanes, lane -1 (HOV) included."""
    sumo = pytest.importorskip("sumo", reason="eclipse-sumo is not installed")
    from pathlib import Path

    net = tmp_path / "default.net.xml"
    done = subprocess.run(
        [str(Path(sumo.SUMO_HOME) / "bin" / "netconvert"), "--opendrive-files", str(xodr),
         "--output-file", str(net)],
        capture_output=True, text=True, env={"SUMO_HOME": sumo.SUMO_HOME},
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    edges = [e for e in ET.parse(net).getroot().findall("edge") if e.get("function") is None]
    assert [len(edge.findall("lane")) for edge in edges] == [4, 4]
    for edge in edges:  # the access record keeps trucks out of the HOV lane (index 3)
        hov = edge.findall("lane")[3].get("allow").split()
        assert "hov" in hov and "passenger" in hov and "truck" not in hov


def test_netconvert_reads_it_as_the_twins_lanes(xodr, built_map, tmp_path):
    """SUMO's network from the file: two edges of six lanes, the twin's widths, its
    length within 0.1 % and its lane centres within 5 cm of ``RoadModel.to_world``."""
    sumo = pytest.importorskip("sumo", reason="eclipse-sumo is not installed")
    from pathlib import Path

    netconvert = Path(sumo.SUMO_HOME) / "bin" / "netconvert"
    net = tmp_path / "i24.net.xml"
    done = subprocess.run(
        [str(netconvert), "--opendrive-files", str(xodr), "--output-file", str(net),
         "--offset.disable-normalization", "true", "--opendrive.import-all-lanes", "true"],
        capture_output=True, text=True, env={"SUMO_HOME": sumo.SUMO_HOME},
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    edges = [e for e in ET.parse(net).getroot().findall("edge") if e.get("function") is None]
    assert len(edges) == 2
    s0, s1 = built_map.road.station_range
    road_model = built_map.road
    for edge in edges:
        lanes = edge.findall("lane")
        assert len(lanes) == 6
        # SUMO counts lanes from the outside: 0 the shoulder .. 5 the median strip
        widths = [float(lane.get("width")) for lane in lanes]
        assert widths == pytest.approx([3.048] + [LANE_WIDTH] * 5, abs=0.006)
        for lane in lanes:
            assert float(lane.get("length")) == pytest.approx(s1 - s0, rel=1e-3)
        road = Road.EASTBOUND if edge.get("id").startswith("-") else Road.WESTBOUND
        for index, twin_lane in ((4, -1), (3, -2), (2, -3), (1, -4)):
            shape = np.array(
                [
                    [float(v) for v in point.split(",")]
                    for point in lanes[index].get("shape").split()
                ]
            )
            coordinates = road_model.to_road(shape)
            assert np.all(coordinates.road == road.direction)
            assert np.abs(coordinates.y - lane_center(twin_lane)).max() < 0.05
            # on the twin's pavement (SUMO's 1 cm rounding puts an end a hair off the map)
            height = coordinates.height[np.isfinite(coordinates.height)]
            assert height.size >= len(shape) - 2 and np.abs(height).max() < 0.05
            x = coordinates.x
            assert x.min() < road_model.x_range(road)[0] + 1.0  # from end to end
            assert x.max() > road_model.x_range(road)[1] - 1.0
