"""How lane -4 yields to the on-ramps' merging vehicles (calibration.json's ``yielding``)."""

import numpy as np
import pytest

from twin.calibration.following import CalibrationDataError, GridTraffic, _leaders
from twin.calibration.merge_positions import road_ramps
from twin.calibration.yielding import (
    MIN_MERGES,
    cooperation,
    describe_yielding,
    fit_yielding,
    judged_steps,
    yielding_section,
)
from twin.core.i24 import Road
from twin.core.ramps import RAMP_LANE
from twin.traffic.models import car_following_model

IDM = car_following_model("idm")
DRIVER = IDM.make(**{p.name: p.start for p in IDM.fitted})
DT = 0.1
LENGTH = 4.5


def scene(yields: float, merges: int = MIN_MERGES + 2, seed: int = 0):
    """``merges`` merges 40 s apart on the westbound on-ramp: a ramp vehicle at 15 m/s
    crosses into lane -4 20 m before the taper's end, 10 s after it appears; the lane
    -4 vehicle that ends up behind it starts 90 m behind it at 22 m/s with its own
    leader 80 m ahead at 22 m/s, and drives by the IDM driver behind the ramp vehicle
    (from 5 s before the merge: a share ``yields`` of the followers, every other one for
    0.5) or behind its own leader. Returns (grid, samples with the ramp's)."""
    rng = np.random.default_rng(seed)
    ramp = road_ramps("westbound")[0]
    rows = {name: [] for name in ("tid", "k", "x", "speed", "lane")}
    samples = {name: [] for name in ("tid", "t", "x", "speed", "lane")}

    def row(tid, k, x, v, lane):
        for name, value in zip(rows, (tid, k, x, v, lane), strict=True):
            rows[name].append(value)

    for m in range(merges):
        courteous = yields > 0 and m % round(1.0 / yields) == 0
        k0 = 400 * m
        x_merge = ramp.x_end - 20.0
        x_r0 = x_merge - 150.0  # 15 m/s for 10 s
        x_f, v_f = x_r0 - 90.0 - LENGTH + rng.normal(0.0, 1.0), 22.0
        x_l = x_f + 80.0
        tid_r, tid_f, tid_l = 3 * m + 1, 3 * m + 2, 3 * m + 3
        for j in range(150):  # 15 s: 10 before the merge, 5 after
            k, t = k0 + j, (k0 + j) * DT
            x_r = x_r0 + 15.0 * j * DT
            lane_r = RAMP_LANE if j < 100 else -4
            samples["tid"].append(tid_r)
            samples["t"].append(t)
            samples["x"].append(x_r)
            samples["speed"].append(15.0)
            samples["lane"].append(lane_r)
            if lane_r == -4:
                row(tid_r, k, x_r, 15.0, -4)
            row(tid_f, k, x_f, v_f, -4)
            row(tid_l, k, x_l + 22.0 * j * DT, 22.0, -4)
            own = IDM.accel(np.array([v_f]), np.array([22.0]),
                            np.array([x_l + 22.0 * j * DT - x_f - LENGTH]), DRIVER)[0]  # fmt: skip
            behind = IDM.accel(np.array([v_f]), np.array([15.0]),
                               np.array([max(x_r - x_f - LENGTH, 0.1)]), DRIVER)[0]  # fmt: skip
            a = min(own, max(behind, -3.0)) if courteous and j >= 50 else own
            v_f = max(v_f + a * DT, 0.0)
            x_f += v_f * DT
    tid = np.asarray(rows["tid"], np.int64)
    order = np.lexsort((np.asarray(rows["k"]), tid))
    cols = {name: np.asarray(v)[order] for name, v in rows.items()}
    length = np.full(order.size, LENGTH)
    leader, gap = _leaders(cols["k"], cols["lane"], cols["x"], length)
    grid = GridTraffic(
        road=Road.WESTBOUND, dt=DT, t0=0.0, tid=cols["tid"], k=cols["k"].astype(np.int64),
        x=cols["x"].astype(float), speed=cols["speed"].astype(float),
        y=np.zeros(order.size), lane=cols["lane"].astype(np.int8), length=length,
        vehicle_class=np.zeros(order.size, np.int64), leader=leader, gap=gap,
    )  # fmt: skip
    s_order = np.lexsort((np.asarray(samples["t"]), np.asarray(samples["tid"])))
    samples = {name: np.asarray(v)[s_order] for name, v in samples.items()}
    return grid, samples


def test_followers_who_drop_back_for_the_merging_vehicle_are_found_yielding():
    section = yielding_section(*scene(yields=1.0), IDM, DRIVER)
    assert section["identified"] and section["merges"] == MIN_MERGES + 2
    assert section["yield_from"] is not None
    # the followers start to yield 5 s (75 m) before the merge: urgency about 0.5
    assert 0.3 <= section["yield_from"] <= 0.7
    assert section["agreement"] > 0.8
    assert 0.3 <= section["cooperative_decel"] <= 3.0
    assert section["courtesy"] == 1.0
    assert "100% of lane -4's drivers, from urgency 0.55" in describe_yielding(section)[0]
    settings = cooperation(section)
    assert settings["yield_from"] == section["yield_from"]
    assert settings["cooperative_decel"] == section["cooperative_decel"]
    assert settings["courtesy"] == 1.0


def test_the_share_of_courteous_followers_is_found():
    section = yielding_section(*scene(yields=0.5, merges=2 * MIN_MERGES), IDM, DRIVER)
    assert section["courtesy"] == pytest.approx(0.5, abs=0.05)
    assert 0.3 <= section["yield_from"] <= 0.7
    assert "50% of lane -4's drivers" in describe_yielding(section)[0]


def test_followers_who_ignore_the_merging_vehicle_never_yield():
    section = yielding_section(*scene(yields=0.0), IDM, DRIVER)
    assert section["identified"] and section["steps"] > 0
    assert section["yield_from"] is None and section["cooperative_decel"] is None
    assert cooperation(section) == {"courtesy": 0.0}
    assert "does not make room" in describe_yielding(section)[0]


def test_the_steps_are_judged_only_where_the_follower_is_behind_the_merging_vehicle():
    grid, samples = scene(yields=1.0)
    steps = judged_steps(grid, samples, IDM, DRIVER)
    assert steps["merge"].size > 0
    assert np.all(steps["yield"] < steps["own"])
    assert np.all((steps["urgency"] == -1.0) | ((steps["urgency"] >= 0) & (steps["urgency"] <= 1)))


def test_too_few_merges_keep_the_defaults():
    section = yielding_section(*scene(yields=1.0, merges=3), IDM, DRIVER)
    assert not section["identified"] and section["merges"] == 3
    assert cooperation(section) == {}
    assert "not identified" in describe_yielding(section)[0]
    assert cooperation(None) == {}
    empty = fit_yielding({n: np.zeros(0) for n in ("merge", "urgency", "accel", "own", "yield")})
    assert empty["merges"] == 0 and not empty["identified"]


@pytest.mark.parametrize(
    "section",
    [
        {"identified": True},
        {"identified": True, "yield_from": -0.5, "cooperative_decel": None},
        {"identified": True, "yield_from": 0.5, "cooperative_decel": 0.0},
        {"identified": True, "yield_from": "soon", "cooperative_decel": 1.0},
        {"identified": True, "yield_from": float("nan"), "cooperative_decel": 1.0},
        {"identified": True, "yield_from": 0.5, "courtesy": 1.5, "cooperative_decel": 1.0},
        {"identified": True, "yield_from": 0.5, "cooperative_decel": 1.0},
        "yes",
    ],
)
def test_a_malformed_yielding_section_is_a_clear_error(section):
    with pytest.raises(CalibrationDataError, match="yielding"):
        cooperation(section)
    assert "malformed" in describe_yielding(section)[0]
