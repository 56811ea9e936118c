"""I-24 MOTION days made by Eclipse SUMO's drivers (twin/data/sumo_day.py): the road's
lane drop and on-ramp as SUMO drives them, recorded in the real layout, read back by
the ingest, deterministic by seed."""

import json
import xml.etree.ElementTree as ET
from dataclasses import replace

import numpy as np
import pytest

from twin.core import i24
from twin.core.errors import TwinError
from twin.data import synth
from twin.data.ingest import ingest
from twin.data.sumo_day import SumoDayError, sumo_day

pytest.importorskip("sumo", reason="SUMO-made test data needs eclipse-sumo (the test extra)")

#: short days: a minute recorded after a minute of warm-up
SHORT = {"minutes": 1.0, "warmup": 60.0, "upstream": 400.0, "downstream": 600.0}


def _documents(path):
    return json.loads(path.read_text())


@pytest.fixture(scope="module")
def lane_drop(tmp_path_factory):
    folder = tmp_path_factory.mktemp("sumo_d")
    config = replace(synth.ALL_PRESETS["D"], **SHORT)
    return config, sumo_day(config, folder / "d.json", keep=folder / "work")


@pytest.fixture(scope="module")
def on_ramp(tmp_path_factory):
    folder = tmp_path_factory.mktemp("sumo_e")
    config = replace(synth.ALL_PRESETS["E"], **SHORT, bottleneck=None)
    return config, sumo_day(config, folder / "e.json", keep=folder / "work")


def lane_of_samples(tracks):
    return i24.lane_of(np.concatenate([y for _, _, y in tracks]))


def _tracks(path, road):
    """Per document: t [s], road-frame x [m], y [m]."""
    out = []
    for doc in _documents(path):
        x = i24.road_x(np.array(doc["x_position"]), road)
        y = i24.road_y(np.array(doc["y_position"]))
        out.append((np.array(doc["timestamp"]), x, y))
    return out


def test_a_lane_drop_morning_is_recorded_in_the_real_layout(lane_drop, tmp_path):
    config, result = lane_drop
    assert result.trajectories > 50 and result.departed > result.trajectories
    assert result.lane_changes > 0 and result.collisions == 0
    docs = _documents(result.path)
    assert all(doc["flags"] == ["sumo"] for doc in docs)
    tracks = _tracks(result.path, config.road)
    for t, x, _ in tracks:
        assert np.allclose(np.diff(t), 1.0 / config.sample_rate, atol=2e-3)  # 25 Hz
        assert config.start <= t[0] and t[-1] <= config.end
        assert np.all((x >= config.x_record[0] - 1) & (x <= config.x_record[1] + 1))
        assert x[-1] > x[0]  # along travel
    # lanes -3 and -4 end at the drop: nobody is in them beyond it
    x = np.concatenate([x for _, x, _ in tracks])
    lane = i24.lane_of(np.concatenate([y for _, _, y in tracks]))
    beyond = x > config.lane_drop.x + 1.0
    assert beyond.any() and not np.isin(lane[beyond], config.lane_drop.lanes).any()
    # the ingest reads it all, every lane with traffic
    report = ingest([result.path], tmp_path / "store", progress=False)
    assert report.documents_kept == len(docs) and not report.documents_rejected
    assert report.samples_kept == report.samples_read
    for lane in i24.LANES:
        assert (lane == lane_of_samples(tracks)).any()


def _changes(work):
    """SUMO's lane changes (from lane, to lane) and each edge's lane count."""
    lanes = {}
    for edge in ET.parse(work / "i24.net.xml").getroot().iter("edge"):
        if edge.get("function") != "internal":
            lanes[edge.get("id")] = len(edge.findall("lane"))
    changes = [(e.get("from"), e.get("to"))
               for e in ET.parse(work / "lanechanges.xml").getroot().iter("change")]  # fmt: skip
    return changes, lanes


def _lane_start(work, edge):
    """SUMO's x of the start of lane 0 of ``edge``."""
    for lane in ET.parse(work / "i24.net.xml").getroot().iter("lane"):
        if lane.get("id") == f"{edge}_0":
            return float(lane.get("shape").split()[0].split(",")[0])
    raise AssertionError(f"no lane {edge}_0")


def test_nobody_crosses_the_hov_lanes_double_line(lane_drop):
    _, result = lane_drop
    changes, lanes = _changes(result.path.parent / "work")
    assert changes
    for a, b in changes:
        for lane in (a, b):
            edge, _, index = lane.rpartition("_")
            assert int(index) != lanes[edge] - 1, (a, b)  # the HOV lane is SUMO's leftmost


def test_the_same_seed_writes_the_same_bytes_and_another_seed_other_traffic(lane_drop, tmp_path):
    config, result = lane_drop
    again = sumo_day(config, tmp_path / "again.json")
    assert again.path.read_bytes() == result.path.read_bytes()
    other = sumo_day(replace(config, seed=1), tmp_path / "other.json")
    assert other.path.read_bytes() != result.path.read_bytes()


def test_ramp_vehicles_merge_from_the_acceleration_lane_before_its_end(on_ramp):
    config, result = on_ramp
    ramp = config.on_ramp
    tracks = _tracks(result.path, config.road)
    outside = 0
    for _, x, y in tracks:
        on_ramp_lane = y > i24.lane_center(-4) + 0.5 * i24.LANE_WIDTH  # right of lane -4
        outside += on_ramp_lane.sum()
        assert not (on_ramp_lane & (x > ramp.x_end + 1.0)).any()  # merged by its end
    assert outside > 0  # the ramp's vehicles are seen on it, outside the lane bands
    # they join lane -4 by changing lanes off the acceleration lane (SUMO's lane 0)
    changes, lanes = _changes(result.path.parent / "work")
    ramp_edges = {edge for edge, n in lanes.items() if n == i24.N_LANES + 1}
    assert ramp_edges
    assert any(a.rpartition("_")[0] in ramp_edges and a.endswith("_0") for a, _ in changes)
    # recorded at the back: one that departs while recorded appears where the ramp lane
    # begins (SUMO inserts it with its back there; its junction shifts the lane's start
    # a few metres past the node), not a length further on
    lane_start = _lane_start(result.path.parent / "work", min(ramp_edges)) + (
        config.x_record[0] - config.upstream
    )
    side = i24.lane_center(-4) + 0.5 * i24.LANE_WIDTH
    firsts = [x[0] - lane_start for t, x, y in tracks if t[0] > config.start + 0.5 and y[0] > side]
    assert len(firsts) >= 3
    assert min(firsts) > -0.3 and np.median(firsts) < 1.5


def test_missing_sumo_and_a_road_without_demand_are_named(monkeypatch, tmp_path):
    config = replace(synth.ALL_PRESETS["D"], **SHORT)
    with pytest.raises(SumoDayError, match="no demand"):
        sumo_day(replace(config, flow=(0.0, 0.0, 0.0, 0.0)), tmp_path / "x.json")
    import twin.data.sumo_day as module
    from twin.core.sumo import SumoMissing

    def missing(name):
        raise SumoMissing("this needs Eclipse SUMO: python3 -m pip install eclipse-sumo")

    monkeypatch.setattr(module, "sumo_tool", missing)
    with pytest.raises(TwinError, match="eclipse-sumo"):
        sumo_day(config, tmp_path / "y.json")
    assert not (tmp_path / "y.json").exists()
