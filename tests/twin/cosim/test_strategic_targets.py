"""Strategic targets drawn from a recording's flows (twin.cosim.core.drivers)."""

import numpy as np
import pytest

from twin.calibration.following import CalibrationDataError
from twin.cosim.core.drivers import draw_target, flow_arrays

EDGES = [0.0, 100.0, 200.0, 300.0, 400.0, 500.0, 600.0, 700.0, 800.0]


def _flows(p_left_at_600=0.5, p_right_at_200=0.0):
    left, right = [0.0] * 8, [0.0] * 8
    left[6], right[2] = p_left_at_600, p_right_at_200
    strategic = {"-3>-2": {"probability": left}}
    if p_right_at_200:
        strategic["-3>-4"] = {"probability": right}
    return {"x_edges": EDGES, "strategic": strategic}


def _draw(flows, key, lane=-3, x=50.0, seed=0, draws=1, speed=20.0):
    """(direction, x_from, x_by) of a draw, (0, -1, -1) for none (comparable)."""
    direction, x_from, x_by = draw_target(seed, key, draws, lane, x, speed, *flow_arrays(flows))
    return (0, -1.0, -1.0) if direction == 0 else (direction, x_from, x_by)


def test_vehicles_leave_a_lane_where_and_as_often_as_the_flows_say():
    flows = _flows(0.5, 0.2)
    n = 4000
    drawn = [_draw(flows, key) for key in range(1000, 1000 + n)]
    left = [t for t in drawn if t[0] == 1]
    right = [t for t in drawn if t[0] == -1]
    # right first (bin 200-300, p 0.2), then left of those remaining (bin 600-700, p 0.5)
    assert abs(len(right) / n - 0.2) < 0.02
    assert abs(len(left) / n - 0.8 * 0.5) < 0.025
    assert {t[1:] for t in right} == {(150.0, 300.0)}  # from half a bin before to its end
    assert {t[1:] for t in left} == {(550.0, 700.0)}
    # a vehicle already past a bin is not drawn for it; lane -2 has no flow
    assert all(_draw(flows, key, x=650.0)[0] != -1 for key in range(200))
    assert _draw(_flows(1.0), 98, lane=-2)[0] == 0


def test_draws_depend_on_the_seed_the_record_and_the_draw_not_the_order():
    flows = _flows()
    a = [_draw(flows, key) for key in range(7, 207)]
    b = [_draw(flows, key) for key in reversed(range(7, 207))][::-1]
    assert a == b
    assert [_draw(flows, key, seed=1) for key in range(7, 207)] != a
    assert [_draw(flows, key, draws=2) for key in range(7, 207)] != a


def test_a_vehicle_draws_again_in_the_lane_it_changed_to():
    flows = _flows(1.0)
    flows["strategic"]["-2>-1"] = {"probability": [0.0] * 7 + [1.0]}
    assert _draw(flows, 5) == (1, 550.0, 700.0)
    assert _draw(flows, 5, lane=-2, x=640.0, draws=2) == (1, 650.0, 800.0)


def test_paper_and_stores_without_strategic_flows_give_no_targets():
    direction, x_from, x_by = draw_target(0, 5, 1, -3, 50.0, 20.0, *flow_arrays(None))
    assert direction == 0 and np.isnan(x_from) and np.isnan(x_by)


def _by_state(queue, congested, free):
    """Flows whose lane -3 vehicles leave left in bin 600-700 m with these probabilities
    by traffic state (pooled 0.5)."""
    flows = _flows(0.5)
    by_state = {}
    for name, p in (("queue", queue), ("congested", congested), ("free", free)):
        by_state[name] = [0.0] * 8
        by_state[name][6] = p
    flows["strategic"]["-3>-2"]["probability_by_state"] = by_state
    flows["states"] = {"names": ["queue", "congested", "free"], "speeds": [5.0, 15.0]}
    return flows


def test_targets_follow_the_traffic_state_the_vehicle_is_in():
    flows = _by_state(1.0, 0.25, 0.0)
    n = 2000
    for speed, share in ((2.0, 1.0), (5.0, 0.25), (10.0, 0.25), (15.0, 0.0), (30.0, 0.0)):
        left = sum(_draw(flows, key, speed=speed)[0] == 1 for key in range(n)) / n
        assert abs(left - share) < 0.03, (speed, left)
    # an empty lane (inf) is free flow
    assert _draw(flows, 3, speed=np.inf)[0] == 0
    # the same random stream: a vehicle drawn in congestion is drawn in the queue too
    congested = {k for k in range(n) if _draw(flows, k, speed=10.0)[0] == 1}
    queue = {k for k in range(n) if _draw(flows, k, speed=1.0)[0] == 1}
    assert congested < queue


def test_flows_without_states_draw_as_before_whatever_the_speed():
    flows = _flows(0.5, 0.2)
    a = [_draw(flows, key, speed=1.0) for key in range(300)]
    assert a == [_draw(flows, key, speed=30.0) for key in range(300)]
    _, left, _, _, states = flow_arrays(flows)
    assert left.shape == (1, 4, 8) and states.size == 0


def test_malformed_state_flows_are_named():
    flows = _by_state(1.0, 0.5, 0.0)
    flows["states"]["speeds"] = [15.0, 5.0]
    with pytest.raises(CalibrationDataError, match=r"lane_flows\.states"):
        flow_arrays(flows)
    flows = _by_state(1.0, 0.5, 0.0)
    flows["strategic"]["-3>-2"]["probability_by_state"]["free"] = [0.0] * 3
    with pytest.raises(CalibrationDataError, match="3 probabilities for 8 position bins"):
        flow_arrays(flows)


def test_the_state_is_the_mean_speed_of_the_lane_around_the_vehicle_ghosts_included():
    from collections import namedtuple

    from twin.cosim.core.drivers import STATE_CELL, lane_speed
    from twin.traffic.kernels.state import Obstacles, Vehicles

    def vehicles(x, lane, speed, valid):
        n = len(x)
        return Vehicles(
            valid=np.array([valid]), top=np.array([n]), x=np.array([x], float),
            y=np.zeros((1, n)), yaw=np.zeros((1, n)), speed=np.array([speed], float),
            lane=np.array([lane], np.int64), length=np.full((1, n), 4.5),
            width=np.full((1, n), 1.8), wheelbase=np.full((1, n), 2.8), mu=np.ones((1, n)),
        )  # fmt: skip

    traffic = namedtuple("Traffic", "vehicles obstacles")
    half = 0.5 * STATE_CELL
    bodies = vehicles(
        [100.0, 100.0 + half, 100.0 - half - 1.0, 120.0, 90.0],
        [-3, -3, -3, -2, -3],
        [2.0, 4.0, 30.0, 30.0, 30.0],
        [True, True, True, True, False],  # the last slot is free
    )
    ghosts = Obstacles(
        count=np.array([2]), lane=np.array([[-3, -3, -3]], np.int64),
        x=np.array([[60.0, 140.0, 100.0]]), length=np.full((1, 3), 4.5),
        speed=np.array([[6.0, 8.0, 99.0]]), accel=np.zeros((1, 3)),
        reach=np.zeros((1, 3), np.int64),
    )  # fmt: skip
    # the bodies and the ghosts within half a cell of x = 100 m in lane -3 (the third
    # ghost is past the count, the third body beyond the cell, the fourth in lane -2)
    assert lane_speed(0, traffic(bodies, ghosts), -3, 100.0) == pytest.approx(5.0)
    assert lane_speed(0, traffic(bodies, ghosts), -1, 100.0) == np.inf
