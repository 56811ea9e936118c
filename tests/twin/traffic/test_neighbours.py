"""Who is ahead of whom in each lane (twin/traffic/kernels/neighbours.py): an obstacle
is entered in its lane and in the lane its footprint reaches into."""

import numpy as np

from twin.core.i24 import LANE_WIDTH
from twin.cosim.core.handover import _reach
from twin.traffic.kernels.neighbours import FOOTPRINT_REACH, _merge, around, group_of


def test_an_obstacle_reaching_into_the_next_lane_is_ahead_in_both():
    # obstacle 0 in lane -3 reaching into lane -4 at x 50 m, obstacle 1 in lane -4 at
    # 80 m; no vehicle entries (m = 0), n = 4 slots
    n, count = 4, 2
    lane = np.array([[-3, -4]], np.int64)
    reach = np.array([[-4, 0]], np.int64)
    x = np.array([[50.0, 80.0]])
    size = 5 * n + 2 * count
    owner, group = np.zeros((1, size), np.int64), np.zeros((1, size), np.int64)
    key, entries = np.zeros((1, size)), np.zeros(1, np.int64)
    empty = np.zeros((1, 5 * n), np.int64)
    _merge(0, 0, n, count, lane, reach, x, empty, empty, key, owner, group, entries)
    assert entries[0] == 3
    ahead_in_4, _ = around(key, group, owner, entries[0], 0, -4, 20.0)
    ahead_in_3, _ = around(key, group, owner, entries[0], 0, -3, 20.0)
    assert ahead_in_4 == n + 0 and ahead_in_3 == n + 0  # the same obstacle in both
    assert around(key, group, owner, entries[0], 0, -4, 60.0)[0] == n + 1
    assert group_of(-4) == 3


def test_a_footprint_reaches_the_next_lane_as_a_body_would_occupy_it():
    line = 4 * LANE_WIDTH  # between lanes -3 and -4 (lane -k: k to k + 1 lane widths)
    width = 1.83
    # its side 0.1 m past the reach: it occupies lane -4 too; 0.1 m short: it does not
    assert _reach(line + FOOTPRINT_REACH + 0.1 - 0.5 * width, width, -3) == -4
    assert _reach(line + FOOTPRINT_REACH - 0.1 - 0.5 * width, width, -3) == 0
    assert _reach(line - FOOTPRINT_REACH - 0.1 + 0.5 * width, width, -4) == -3
