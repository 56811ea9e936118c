"""How fast the recording's ramp vehicles drive on an acceleration lane with nothing
close ahead (calibration.json's ``ramp_speeds``)."""

from types import SimpleNamespace

import numpy as np
import pytest

from twin.calibration.following import CalibrationDataError
from twin.calibration.merge_positions import road_ramps
from twin.calibration.ramp_speeds import (
    MIN_FREE,
    describe_ramp_speeds,
    ramp_speed_section,
    ramp_speed_table,
)
from twin.core.ramps import RAMP_LANE

RAMP = road_ramps("westbound")[0]
STORE = SimpleNamespace(trajectory_arrays={"length": np.full(100, 4.5),
                                           "vehicle_class": np.zeros(100, np.int64)})  # fmt: skip


def samples(tracks):
    """A store's samples dict of ``tracks``: {tid: (t0 [s], x0 [m], speeds [m/s] at 10
    Hz, lane)}."""
    out = {name: [] for name in ("tid", "t", "x", "y", "speed", "lane")}
    for tid in sorted(tracks):
        t0, x0, speeds, lane = tracks[tid]
        speeds = np.asarray(speeds, np.float64)
        x = x0 + np.concatenate([[0.0], np.cumsum(speeds[:-1] * 0.1)])
        out["tid"].append(np.full(speeds.size, tid))
        out["t"].append(t0 + 0.1 * np.arange(speeds.size))
        out["x"].append(x)
        out["y"].append(np.full(speeds.size, 16.0))
        out["speed"].append(speeds)
        out["lane"].append(np.full(speeds.size, lane))
    return {name: np.concatenate(v) if v else np.zeros(0) for name, v in out.items()}


def cruising(k: int, speed: float) -> tuple:
    """Ramp vehicle ``k``: alone on the ramp's lane (20 s after the one before), 8 s at
    ``speed`` from the gore."""
    return (20.0 * k, RAMP.x_start, np.full(80, speed), RAMP_LANE)


def test_ramp_drivers_cruising_with_nothing_ahead_give_the_ramp_its_speed():
    tracks = {k: cruising(k, 16.0 + 0.2 * k) for k in range(MIN_FREE)}
    tracks[50] = (200.0, RAMP.x_start, np.linspace(12.0, 22.0, 80), RAMP_LANE)  # accelerating
    tracks[51] = (300.0, RAMP.x_start + 20.0, np.full(80, 16.0), RAMP_LANE)  # a leader ...
    tracks[52] = (300.0, RAMP.x_start, np.full(80, 16.0), RAMP_LANE)  # ... 15.5 m ahead
    tracks[53] = (400.0, RAMP.x_start, np.full(80, 30.0), -4)  # in lane -4: not the ramp's
    tracks[54] = (500.0, -5000.0, np.full(80, 30.0), RAMP_LANE)  # on no ramp of the road
    (section,) = ramp_speed_section(STORE, "westbound", samples(tracks), 0.0)
    assert section["ramp"] == RAMP.name
    assert section["end_m"] == pytest.approx(RAMP.x_end, abs=1e-3)
    # the five cruising alone, and the leader of 52 (nothing ahead of it)
    assert section["free"] == MIN_FREE + 1
    speed = section["free_speed"]
    assert speed["count"] == MIN_FREE + 1
    assert speed["p50"] == pytest.approx(16.3)  # of 16.0, 16.0, 16.2, ..., 16.8
    assert speed["mean"] == pytest.approx(16.333, abs=1e-3)
    table = ramp_speed_table([section])
    assert table.shape == (1, 3)
    assert table[0].tolist() == pytest.approx([RAMP.x_end, speed["mean"], speed["sd"]], abs=1e-3)
    assert "free on its lane at 16.3 m/s" in describe_ramp_speeds([section])[0]


def test_too_few_free_ramp_drivers_leave_the_ramp_their_own_speeds():
    tracks = {k: cruising(k, 16.0) for k in range(MIN_FREE - 1)}
    (section,) = ramp_speed_section(STORE, "westbound", samples(tracks), 0.0)
    assert section["free"] == MIN_FREE - 1 and section["free_speed"] is None
    assert ramp_speed_table([section]).shape == (0, 3)
    assert ramp_speed_table(None).shape == (0, 3)  # a calibration made before them
    assert "too few" in describe_ramp_speeds([section])[0]
    (empty,) = ramp_speed_section(STORE, "westbound", samples({}), 0.0)
    assert empty["free"] == 0 and empty["free_speed"] is None


@pytest.mark.parametrize(
    "section",
    [
        {"ramp": "wb"},  # not a list
        [{"ramp": "wb", "free": 9, "free_speed": {"mean": 16.0, "sd": 0.3}}],  # no end_m
        [{"ramp": "wb", "end_m": 100.0, "free": 9, "free_speed": 16.0}],
        [{"ramp": "wb", "end_m": 100.0, "free": 9, "free_speed": {"mean": None, "sd": 0.3}}],
        [{"ramp": "wb", "end_m": 100.0, "free": 9, "free_speed": {"mean": 16.0, "sd": -1.0}}],
        [{"ramp": "wb", "end_m": 100.0, "free": 9, "free_speed": {"mean": 0.0, "sd": 0.3}}],
        [{"ramp": "wb", "end_m": "far", "free": 9, "free_speed": {"mean": 16.0, "sd": 0.3}}],
        ["wb"],  # an entry not a dict
        [{"ramp": "wb", "end_m": "144.9", "free": 9, "free_speed": {"mean": 16.0, "sd": 0.3}}],
        [{"ramp": "wb", "end_m": 100.0, "free": 9, "free_speed": {"mean": 16.0, "sd": True}}],
        [{"ramp": "wb", "end_m": 100.0, "free": 9, "free_speed": {"mean": 99.0, "sd": 0.3}}],
    ],
)
def test_every_malformed_ramp_speeds_section_is_a_clear_error(section):
    with pytest.raises(CalibrationDataError, match=r"calibration\.json: .*ramp_speeds"):
        ramp_speed_table(section)
    assert all("on-ramp" in line for line in describe_ramp_speeds(section))  # no traceback
