import gzip
import json
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from tests.conftest import SHARED, make_doc, make_merging_doc, write_day
from twin.core.errors import DataFormatError, StoreError
from twin.data.empirical import EmpiricalTraffic
from twin.data.ingest import IngestOptions, ingest, smoothed_speed
from twin.data.store import TrajectoryStore


def _store_bytes(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


def test_hand_built_documents_give_expected_metres_lanes_and_speeds(tmp_path):
    west = make_doc("a" * 24, direction=-1, mm=61.5, y_ft=18.0, speed=30.0)
    east = make_doc(
        "b" * 24, direction=1, mm=60.7, y_ft=-40.0, speed=20.0, vehicle_class=4, length_ft=65.0
    )
    day = write_day(tmp_path / "day.json", [west, east])
    report = ingest([day], tmp_path / "store", progress=False)
    assert report.documents_kept == 2 and not report.documents_rejected

    store = TrajectoryStore(tmp_path / "store")
    w = store.trajectory(store.tid_of("a" * 24))
    # Westbound x runs from MM 61.6: MM 61.5 is 0.1 mile = 160.9344 m in, then 30 m/s.
    expected_x = 0.1 * 1609.344 + 30.0 * (w["t"] - w["t"][0])
    assert np.allclose(w["x"], expected_x, atol=1e-6)
    assert np.allclose(w["y"], 18.0 * 0.3048)
    assert set(w["lane"]) == {-1}
    assert np.allclose(w["speed"], 30.0, atol=1e-3)

    e = store.trajectory(store.tid_of("b" * 24))
    assert np.allclose(e["x"], 0.1 * 1609.344 + 20.0 * (e["t"] - e["t"][0]), atol=1e-6)
    assert set(e["lane"]) == {-3}
    meta = store.trajectories.loc[store.tid_of("b" * 24)]
    assert meta["road"] == "eastbound" and meta["vehicle_class"] == 4
    assert meta["length"] == pytest.approx(65.0 * 0.3048, rel=1e-6)

    traffic = EmpiricalTraffic(store)
    t = float(w["t"][10])
    snap = traffic.snapshot("westbound", t, 0.0, 500.0)
    assert snap.id.tolist() == ["a" * 24]
    assert snap.x[0] == pytest.approx(w["x"][10], abs=1e-5)
    assert snap.speed[0] == pytest.approx(30.0, abs=1e-3)
    assert snap.lane[0] == -1


def test_the_shared_format_example_ingests(tmp_path):
    ingest([SHARED / "data" / "i24_format_example.json"], tmp_path / "s", progress=False)
    store = TrajectoryStore(tmp_path / "s")
    west = store.trajectory(store.tid_of("6386d89efb3ff533c12df001"))
    assert np.median(west["speed"]) == pytest.approx(21.8, abs=0.1)  # "about 21.8 m/s"
    assert set(west["lane"]) == {-1}


def test_every_kind_of_bad_document_is_counted_by_reason_and_valid_data_kept(tmp_path):
    good = make_doc("0" * 24)
    missing = make_doc("1" * 24)
    del missing["x_position"]
    wrong_type = make_doc("2" * 24)
    wrong_type["timestamp"][3] = "soon"
    bool_direction = make_doc("3" * 24)
    bool_direction["direction"] = True
    mismatch = make_doc("4" * 24)
    mismatch["y_position"] = mismatch["y_position"][:-1]
    unknown_direction = make_doc("5" * 24)
    unknown_direction["direction"] = 0
    bad_size = make_doc("6" * 24, length_ft=-3.0)
    noisy = make_doc("7" * 24)  # per-sample problems; the rest of it is kept
    noisy["x_position"][5] = float("nan")
    noisy["timestamp"][10] = noisy["timestamp"][9]
    noisy["y_position"][20] = 75.0  # outside the four lanes
    noisy["y_position"][21] = -18.0  # the eastbound side for a westbound vehicle
    noisy["timestamp"][30] = None
    noisy["x_position"][31] = float("inf")
    empty = make_doc("8" * 24)
    empty["timestamp"], empty["x_position"], empty["y_position"] = [], [], []
    duplicate = make_doc("0" * 24)
    docs = [
        good,
        missing,
        wrong_type,
        bool_direction,
        mismatch,
        unknown_direction,
        bad_size,
        noisy,
        empty,
        duplicate,
        42,
    ]
    day = tmp_path / "day.json"
    day.write_text(json.dumps(docs, allow_nan=True))
    report = ingest([day], tmp_path / "store", progress=False)

    assert report.documents_read == len(docs)
    assert report.documents_kept == 2
    assert dict(report.documents_rejected) == {
        "missing_field:x_position": 1,
        "wrong_type:timestamp": 1,
        "wrong_type:direction": 1,
        "array_length_mismatch": 1,
        "unknown_direction": 1,
        "invalid_value:length": 1,
        "empty_trajectory": 1,
        "duplicate_id": 1,
        "not_an_object": 1,
    }
    assert dict(report.samples_rejected) == {
        "non_finite": 3,
        "non_increasing_timestamp": 1,
        "outside_lane_bands": 1,
        "wrong_side_of_median": 1,
    }
    store = TrajectoryStore(tmp_path / "store")
    assert len(store.trajectory(store.tid_of("7" * 24))["t"]) == 50 - 6
    assert store.metadata["ingest"]["documents"]["rejected"]["duplicate_id"] == 1


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b'{"_id": 1}', "not an I-24 MOTION day file"),
        (b"", "empty file"),
        (b"not json at all", "not an I-24 MOTION day file"),
    ],
)
def test_a_file_that_is_not_an_i24_array_is_a_clear_error(tmp_path, content, message):
    bad = tmp_path / "bad.json"
    bad.write_bytes(content)
    with pytest.raises(DataFormatError, match=message) as error:
        ingest([bad], tmp_path / "store", progress=False)
    assert "bad.json" in str(error.value)
    assert not (tmp_path / "store").exists()
    assert not list(tmp_path.glob(".store.partial-*"))


def test_a_truncated_file_names_file_and_position_and_keeps_the_previous_store(tmp_path):
    docs = [make_doc(f"{i:024x}") for i in range(20)]
    day = write_day(tmp_path / "day.json", docs)
    ingest([day], tmp_path / "store", progress=False)
    before = _store_bytes(tmp_path / "store")

    truncated = tmp_path / "cut.json"
    truncated.write_bytes(day.read_bytes()[: len(day.read_bytes()) // 2])
    with pytest.raises(
        DataFormatError, match=r"cut\.json: malformed or truncated JSON after document \d+"
    ):
        ingest([truncated], tmp_path / "store", progress=False)
    assert _store_bytes(tmp_path / "store") == before
    assert not list(tmp_path.glob(".store.partial-*"))


def test_a_folder_that_is_not_a_store_is_never_overwritten(tmp_path):
    precious = tmp_path / "precious"
    precious.mkdir()
    (precious / "thesis.tex").write_text("years of work")
    day = write_day(tmp_path / "day.json", [make_doc()])
    with pytest.raises(StoreError, match="not an i24-twin store"):
        ingest([day], precious, progress=False)
    assert (precious / "thesis.tex").read_text() == "years of work"


def test_reingest_gives_the_same_bytes_and_spilling_does_not_change_them(tmp_path):
    docs = [
        make_doc(
            f"{i:024x}",
            mm=61.5 - 0.01 * i,
            t0=1669812350.0 + 7.3 * i,
            n=400,
            y_ft=18.0 + 12 * (i % 4),
        )
        for i in range(30)
    ]
    day = write_day(tmp_path / "day.json", docs)
    ingest([day], tmp_path / "a", IngestOptions(bucket=10.0), progress=False)
    first = _store_bytes(tmp_path / "a")
    ingest([day], tmp_path / "a", IngestOptions(bucket=10.0), progress=False)
    assert _store_bytes(tmp_path / "a") == first
    ingest([day], tmp_path / "b", IngestOptions(bucket=10.0, flush_rows=7), progress=False)
    assert _store_bytes(tmp_path / "b") == first
    groups = pq.ParquetFile(tmp_path / "a" / "samples_westbound.parquet").metadata.num_row_groups
    assert groups > 5  # one per 10 s bucket


def test_gzip_input_and_margin_clipping(tmp_path):
    inside = make_doc("a" * 24, mm=61.5)
    far = make_doc("b" * 24, mm=63.0)  # 1.4 miles upstream of the westbound entry
    raw = json.dumps([inside, far]).encode()
    day = tmp_path / "day.json.gz"
    day.write_bytes(gzip.compress(raw))
    report = ingest([day], tmp_path / "s", IngestOptions(margin=400.0), progress=False)
    assert report.documents_kept == 1 and report.documents_outside_margin == 1
    assert report.samples_outside_margin == 50
    with pytest.raises(ValueError, match="margin"):
        IngestOptions(margin=100.0)


def test_smoothed_speed_removes_tracking_noise():
    rng = np.random.default_rng(3)
    t = np.arange(500) / 25.0
    x = 25.0 * t + rng.normal(0.0, 0.1 * 0.3048, len(t))
    v = smoothed_speed(t, x, 0.5)
    assert np.mean(v) == pytest.approx(25.0, abs=0.05)
    assert np.max(np.abs(np.diff(v) / np.diff(t))[20:-20]) < 2.0  # m/s^2
    raw = np.diff(x) / np.diff(t)
    assert np.max(np.abs(np.diff(raw) / 0.04)) > 20.0  # what unsmoothed noise would give


def test_leftovers_of_a_killed_ingest_are_cleaned_and_an_interrupt_leaves_nothing(
    tmp_path, monkeypatch
):
    stale = tmp_path / ".store.partial-999999999"  # no such process: killed with -9
    stale.mkdir()
    (stale / "samples_westbound.parquet").write_bytes(b"half")
    day = write_day(tmp_path / "day.json", [make_doc()])
    ingest([day], tmp_path / "store", progress=False)
    assert not stale.exists()
    assert TrajectoryStore(tmp_path / "store").metadata["ingest"]["documents"]["kept"] == 1

    def interrupt(*_):
        raise KeyboardInterrupt

    monkeypatch.setattr("twin.data.ingest._write_samples", interrupt)
    with pytest.raises(KeyboardInterrupt):
        ingest([day], tmp_path / "other", progress=False)
    assert not (tmp_path / "other").exists()
    assert not list(tmp_path.glob(".other.partial-*"))


def test_samples_on_an_on_ramps_lane_are_ramp_traffic_and_the_shoulder_stays_out(tmp_path):
    """The westbound Old Hickory on-ramp's acceleration lane runs beside lane -4 to MM
    61.51: a vehicle recorded on it (|y| 60 to 72 ft) before it merges is kept as lane
    -5; the same band where no ramp runs is the shoulder, counted out; a vehicle seen on
    its ramp only is not a trajectory of the lanes."""
    merging = make_merging_doc("1" * 24)  # 50 samples on the ramp, then 50 in lane -4
    shoulder = make_doc("2" * 24, direction=1, mm=61.0, y_ft=-54.0, n=50)
    shoulder["y_position"] = [-66.0] * 5 + [-54.0] * 45  # no ramp at MM 61.0 eastbound
    ramp_only = make_doc("3" * 24, direction=-1, mm=61.72, y_ft=66.0, speed=20.0, n=50)
    report = ingest([write_day(tmp_path / "d.json", [merging, shoulder, ramp_only])],
                    tmp_path / "store", progress=False)  # fmt: skip

    assert dict(report.samples_rejected) == {"outside_lane_bands": 5, "too_few_valid_samples": 50}
    assert dict(report.documents_rejected) == {"too_few_valid_samples": 1}
    store = TrajectoryStore(tmp_path / "store")
    tid = store.tid_of("1" * 24)
    row = store.trajectories.iloc[tid]
    t = np.array(merging["timestamp"])
    # the trajectory table describes the vehicle in the lanes (from its merge on)
    assert row["t_first"] == t[50] and row["n_samples"] == 50
    assert row["lanes_seen"] == (1 << 3) | (1 << 4)  # lanes -4 and -5
    lanes = store.samples("westbound", t[0], t[-1])["lane"]
    assert set(lanes.tolist()) == {-4} and lanes.size == 50
    with_ramps = store.samples("westbound", t[0], t[-1], ramps=True)
    assert with_ramps["lane"].tolist() == [-5] * 50 + [-4] * 50
    assert store.metadata["roads"]["westbound"]["samples_per_lane"]["-5"] == 50
    store.verify()
    described = store.describe()
    assert "lane -5: 1 trajectories, 50 samples  (an on-ramp's acceleration lane)" in described


def test_the_lanes_speeds_are_smoothed_from_the_lanes_samples_alone(tmp_path):
    """A vehicle that speeds up as it merges: its speeds in lane -4 are those of its lane
    -4 samples alone, as before the ramps' samples were kept."""
    merging = make_merging_doc("1" * 24)
    t = np.array(merging["timestamp"])
    x_ft = np.array(merging["x_position"])
    x_ft[50:] -= np.cumsum(np.linspace(0.0, 0.4, 50))  # faster once in the lane
    merging["x_position"] = x_ft.tolist()
    ingest([write_day(tmp_path / "d.json", [merging])], tmp_path / "s", progress=False)
    s = TrajectoryStore(tmp_path / "s").samples("westbound", t[0], t[-1], ramps=True)
    x = (61.6 - x_ft / 5280.0) * 1609.344
    lane_only = smoothed_speed(t[50:], x[50:], IngestOptions().speed_smoothing)
    np.testing.assert_allclose(s["speed"][50:], lane_only, rtol=1e-6)
    assert not np.allclose(lane_only, smoothed_speed(t, x, 0.5)[50:], rtol=1e-3)


def test_a_margin_that_leaves_a_vehicle_only_its_ramp_samples_leaves_it_out_counted(tmp_path):
    """Eastbound, in lane -4 far before the segment, then on the Hickory Hollow on-ramp's
    acceleration lane inside the margin: no sample in the lanes within the margin, so the
    vehicle is left out, and every sample read is accounted for."""
    doc = make_doc("4" * 24, direction=1, mm=60.30, y_ft=-54.0, speed=30.0, n=350)
    doc["y_position"] = [-54.0] * 40 + [-66.0] * 310  # x < -435 m, then the ramp's band
    other = make_doc("5" * 24, direction=1, mm=60.5, y_ft=-30.0, n=50)
    report = ingest([write_day(tmp_path / "d.json", [doc, other])], tmp_path / "s",
                    options=IngestOptions(margin=400.0), progress=False)  # fmt: skip
    assert report.documents_outside_margin == 1 and report.documents_kept == 1
    rejected = sum(report.samples_rejected.values())
    assert report.samples_read == report.samples_kept + rejected + report.samples_outside_margin
