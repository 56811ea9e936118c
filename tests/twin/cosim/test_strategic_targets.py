"""Strategic targets drawn from a recording's flows (twin.cosim.core.drivers)."""

import numpy as np

from twin.cosim.core.drivers import draw_target, flow_arrays

EDGES = [0.0, 100.0, 200.0, 300.0, 400.0, 500.0, 600.0, 700.0, 800.0]


def _flows(p_left_at_600=0.5, p_right_at_200=0.0):
    left, right = [0.0] * 8, [0.0] * 8
    left[6], right[2] = p_left_at_600, p_right_at_200
    strategic = {"-3>-2": {"probability": left}}
    if p_right_at_200:
        strategic["-3>-4"] = {"probability": right}
    return {"x_edges": EDGES, "strategic": strategic}


def _draw(flows, key, lane=-3, x=50.0, seed=0, draws=1):
    """(direction, x_from, x_by) of a draw, (0, -1, -1) for none (comparable)."""
    direction, x_from, x_by = draw_target(seed, key, draws, lane, x, *flow_arrays(flows))
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
    direction, x_from, x_by = draw_target(0, 5, 1, -3, 50.0, *flow_arrays(None))
    assert direction == 0 and np.isnan(x_from) and np.isnan(x_by)
