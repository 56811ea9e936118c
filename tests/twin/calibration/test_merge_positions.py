"""Where the recording's ramp vehicles merge (calibration.json's ``merges``)."""

import numpy as np
import pytest

from twin.calibration.following import CalibrationDataError
from twin.calibration.merge_positions import (
    MIN_MERGES,
    QUANTILES,
    describe_merges,
    merge_section,
    merge_table,
    recorded_merges,
    road_ramps,
)
from twin.core.ramps import RAMP_LANE


def samples(tracks):
    """A store's samples dict of ``tracks``: {tid: [(x, lane), ...]} one second apart."""
    out = {"tid": [], "t": [], "x": [], "lane": []}
    for tid in sorted(tracks):
        for k, (x, lane) in enumerate(tracks[tid]):
            out["tid"].append(tid)
            out["t"].append(float(k))
            out["x"].append(x)
            out["lane"].append(lane)
    return {name: np.asarray(v) for name, v in out.items()}


def test_a_merge_is_the_lane_4_sample_after_the_ramp_the_last_time():
    s = samples({
        1: [(0.0, RAMP_LANE), (10.0, RAMP_LANE), (20.0, -4), (30.0, -4)],
        2: [(0.0, -4), (10.0, -3)],  # never on the ramp
        3: [(0.0, RAMP_LANE), (5.0, RAMP_LANE)],  # never merged
        4: [(0.0, RAMP_LANE), (8.0, -4), (16.0, RAMP_LANE), (24.0, -4)],  # wobbled: last
    })  # fmt: skip
    tid, x, t = recorded_merges(s)
    assert tid.tolist() == [1, 4]
    assert x.tolist() == [20.0, 24.0]
    assert t.tolist() == [2.0, 3.0]
    assert [len(a) for a in recorded_merges(samples({2: [(0.0, -4)]}))] == [0, 0, 0]


def test_each_ramp_gets_the_quantiles_of_its_merges():
    ramp = road_ramps("westbound")[0]
    places = np.linspace(ramp.x_end - 100.0, ramp.x_end - 10.0, MIN_MERGES)
    tracks = {k: [(p - 20.0, RAMP_LANE), (p, -4)] for k, p in enumerate(places)}
    tracks[99] = [(-5000.0, RAMP_LANE), (-4990.0, -4)]  # on no ramp: not counted
    (section,) = merge_section(samples(tracks), "westbound")
    assert section["ramp"] == ramp.name and section["merged"] == MIN_MERGES
    q = section["x_quantiles"]
    assert len(q) == QUANTILES
    assert q[0] == pytest.approx(places[0], abs=1e-3)
    assert q[-1] == pytest.approx(places[-1], abs=1e-3)
    assert q[QUANTILES // 2] == pytest.approx(np.median(places), abs=1e-3)
    table = merge_table([section])
    assert table.shape == (1, 1 + QUANTILES) and table[0, 0] == pytest.approx(ramp.x_end, abs=1e-3)
    assert "10 merges" in describe_merges([section])[0]


def test_too_few_merges_place_none():
    ramp = road_ramps("westbound")[0]
    tracks = {k: [(ramp.x_end - 60.0, RAMP_LANE), (ramp.x_end - 50.0, -4)] for k in range(3)}
    (section,) = merge_section(samples(tracks), "westbound")
    assert section["merged"] == 3 and section["x_quantiles"] is None
    assert merge_table([section]).shape == (0, 1 + QUANTILES)
    assert merge_table(None).shape == (0, 1 + QUANTILES)
    assert "too few" in describe_merges([section])[0]


def test_a_malformed_merges_entry_is_named():
    bad = {"ramp": "wb", "gore_m": 0.0, "end_m": 100.0, "merged": 20, "x_quantiles": [1.0, 2.0]}
    with pytest.raises(CalibrationDataError, match="x_quantiles"):
        merge_table([bad])
    bad["x_quantiles"] = [float("nan")] * QUANTILES
    with pytest.raises(CalibrationDataError, match="finite"):
        merge_table([bad])


@pytest.mark.parametrize(
    "section",
    [
        {"ramp": "wb"},  # not a list
        [{"ramp": "wb", "merged": 20, "x_quantiles": [1.0] * QUANTILES}],  # no end_m
        [{"ramp": "wb", "end_m": 100.0, "merged": 20, "x_quantiles": 5.0}],
        [{"ramp": "wb", "end_m": 100.0, "merged": 20, "x_quantiles": [None] * QUANTILES}],
        [{"ramp": "wb", "end_m": "far", "merged": 20, "x_quantiles": [1.0] * QUANTILES}],
        ["wb"],  # an entry not a dict
    ],
)
def test_every_malformed_merges_section_is_a_clear_error(section):
    with pytest.raises(CalibrationDataError, match=r"calibration\.json: .*merges"):
        merge_table(section)
    assert all("on-ramp" in line for line in describe_merges(section))  # no traceback
