"""Whether the recording's drivers pass on the right (calibration.json's ``passing_right``)."""

import numpy as np
import pytest

from twin.calibration.following import CalibrationDataError, GridTraffic, _leaders
from twin.calibration.passing import (
    FROM_SPEED,
    MIN_STEPS,
    MIN_VEHICLES,
    describe_passing,
    left_leaders,
    no_pass_right,
    passing_section,
)
from twin.core.i24 import Road

DT = 0.1
LENGTH = 4.5


def grid_of(tid, k, x, speed, lane, length=None) -> GridTraffic:
    length = np.full(len(tid), LENGTH) if length is None else length
    tid, k, x, speed, lane, length = (np.asarray(a) for a in (tid, k, x, speed, lane, length))
    order = np.lexsort((k, tid))
    tid, k, x, speed = tid[order], k[order], x[order], speed[order]
    lane, length = lane[order], length[order].astype(float)
    leader, gap = _leaders(k, lane, x, length)
    return GridTraffic(
        road=Road.WESTBOUND, dt=DT, t0=0.0, tid=tid.astype(np.int64), k=k.astype(np.int64),
        x=x.astype(float), speed=speed.astype(float), y=np.zeros(tid.size),
        lane=lane.astype(np.int8), length=length, vehicle_class=np.zeros(tid.size, np.int64),
        leader=leader, gap=gap,
    )  # fmt: skip


def scene(
    speed_beside: float, steps: int = MIN_STEPS + 100, free_speed: float = 30.0, *,
    left_speed: float = 25.0, own_leader: float | None = None, vehicles: int = 30,
):  # fmt: skip
    """At every step: a car in lane -3 at ``speed_beside`` [m/s] (one of ``vehicles``,
    in turn) with a car at ``left_speed`` in lane -2 20 m ahead of its front (its own
    lane open, or with a leader ``own_leader`` [m] ahead), and a car in lane -4 far from
    anyone at ``free_speed``."""
    rows = []
    for k in range(steps):
        rows += [
            (100 + k % vehicles, k, 100.0, speed_beside, -3),
            (1, k, 100.0 + LENGTH + 20.0, left_speed, -2),
            (2, k, 900.0, free_speed, -4),
        ]
        if own_leader is not None:
            rows.append((3, k, 100.0 + LENGTH + own_leader, speed_beside, -3))
    return grid_of(*zip(*rows, strict=True))


def test_drivers_who_keep_to_the_slower_car_on_their_left_do_not_pass_on_the_right():
    section = passing_section(scene(speed_beside=25.0))
    assert section["identified"] and section["judged"] == section["free"] == MIN_STEPS + 100
    assert section["passing"] == 0.0 and section["expected"] == 1.0
    assert section["no_pass_right_from"] == pytest.approx(FROM_SPEED, abs=1e-3)
    assert no_pass_right(section) == {"no_pass_right_from": section["no_pass_right_from"]}
    assert "drivers do not, from 16.7 m/s" in describe_passing(section)[0]


def test_drivers_faster_than_the_car_on_their_left_pass_on_the_right():
    section = passing_section(scene(speed_beside=30.0))
    assert section["identified"] and section["ratio"] == 1.0
    assert section["no_pass_right_from"] is None
    assert no_pass_right(section) == {}
    assert "drivers pass (100% faster" in describe_passing(section)[0]


def test_too_few_steps_or_congested_traffic_tell_nothing():
    few = passing_section(scene(speed_beside=25.0, steps=MIN_STEPS - 1))
    assert not few["identified"] and few["ratio"] is None and no_pass_right(few) == {}
    assert "not identified" in describe_passing(few)[0]
    # below FROM_SPEED drivers may pass as they like: no step is judged
    slow = passing_section(scene(speed_beside=14.0, free_speed=14.0))
    assert slow["judged"] == 0 and not slow["identified"]
    # left leaders never slower than the free speeds: nothing to tell
    fast = passing_section(scene(speed_beside=25.0, free_speed=20.0))
    assert fast["expected"] == 0.0 and not fast["identified"]
    # a few vehicles do not make a road's rule
    one = passing_section(scene(speed_beside=25.0, vehicles=MIN_VEHICLES - 1))
    assert one["vehicles"] == MIN_VEHICLES - 1 and not one["identified"]


def test_only_a_driver_whose_own_lane_is_open_beside_a_moving_left_lane_is_judged():
    # kept back by its own leader, it says nothing of passing
    assert passing_section(scene(speed_beside=25.0, own_leader=30.0))["judged"] == 0
    # a left lane crawling below FROM_SPEED is passed by anyone at speed
    assert passing_section(scene(speed_beside=25.0, left_speed=10.0))["judged"] == 0


def test_left_leaders_are_the_nearest_vehicle_ahead_of_the_front_in_the_lane_to_the_left():
    rng = np.random.default_rng(0)
    n = 400
    grid = grid_of(
        rng.permutation(n), rng.integers(0, 5, n), rng.uniform(0.0, 300.0, n),
        rng.uniform(0.0, 30.0, n), rng.choice([0, -1, -2, -3, -4], n), rng.uniform(3.0, 20.0, n),
    )  # fmt: skip
    row, gap = left_leaders(grid)
    for i in range(n):
        ahead = np.flatnonzero(
            (grid.k == grid.k[i]) & (grid.lane == grid.lane[i] + 1)
            & (grid.x > grid.x[i] + grid.length[i])
        )  # fmt: skip
        if grid.lane[i] in (0, -1) or ahead.size == 0:
            assert row[i] == -1 and gap[i] == np.inf
            continue
        nearest = ahead[np.argmin(grid.x[ahead])]
        assert row[i] == nearest
        assert gap[i] == pytest.approx(grid.x[nearest] - grid.x[i] - grid.length[i])


@pytest.mark.parametrize(
    "section",
    [{}, {"identified": True}, {"identified": True, "no_pass_right_from": -1.0},
     {"identified": True, "no_pass_right_from": "fast"}, "passing",
     {"identified": "false", "no_pass_right_from": None},
     {"identified": False, "no_pass_right_from": 16.7}],
)  # fmt: skip
def test_a_malformed_section_is_named(section):
    with pytest.raises(CalibrationDataError, match="passing_right"):
        no_pass_right(section)
