"""Every recorded vehicle's track, whatever it is drawn as (twin.metrics.continuity): on
hand-made logs, and on scenario B's run, where it finds the jumps issue 76 reported."""

import numpy as np
import pandas as pd
import pytest

from tests.twin.metrics.test_handover import DT, T0, Recording
from twin.core.i24 import LANE_WIDTH
from twin.metrics.continuity import continuity_section

STEPS = 20
ON_LANE_Y = 1.5 * LANE_WIDTH  # [m] lane -2's centre


class OnLanes(Recording):
    """The hand-made recording, on lane -2 where present (``off`` (tid, step) keys off
    the lanes)."""

    def __init__(self, states, off=()):
        super().__init__(states)
        self.off = set(off)

    def recorded_states(self, road, tids, times):
        present, x, _, speed = super().recorded_states(road, tids, times)
        steps = np.round((np.asarray(times) - T0) / DT).astype(int)
        y = np.array([0.0 if (int(t), int(k)) in self.off else ON_LANE_Y
                      for t, k in zip(tids, steps, strict=True)])  # fmt: skip
        return present, x, y, speed


EDGES = {"g0": 0.0, "x0": 100.0, "x1": 300.0, "g1": 400.0}


def _section(bodies, ghosts, recording=None, ghost_period=DT, record_ids=None, off=()):
    """The section of a log of ``bodies`` (step, tid, role, x, speed) and ``ghosts``
    (step, tid, x, speed) over STEPS steps of windows EDGES; recordings present
    wherever ``recording`` (tid -> steps) says, everywhere by default."""
    vehicles = pd.DataFrame(bodies, columns=["step", "tid", "role", "x", "speed"])
    vehicles["time"] = vehicles.pop("step") * DT
    drawn = pd.DataFrame(ghosts, columns=["step", "tid", "x", "speed"])
    drawn["time"] = drawn.pop("step") * DT
    windows = pd.DataFrame({"time": np.arange(STEPS) * DT, **EDGES})
    tids = set(vehicles["tid"]) | set(drawn["tid"])
    steps = recording or {tid: range(-5, STEPS + 5) for tid in tids}
    states = {(tid, k): (0.0, 0.0) for tid, ks in steps.items() for k in ks}
    return continuity_section(vehicles, drawn, windows, OnLanes(states, off), "westbound", T0, DT,
                              ghost_period, (-1000.0, 3000.0), record_ids)  # fmt: skip


def _moving(tid, role, x0, speed, steps):
    return [(k, tid, role, x0 + speed * DT * k, speed) for k in steps]


def test_a_body_handed_to_a_ghost_that_is_elsewhere_is_a_jump_named_with_its_record():
    # tid 3 drives at 20 m/s in the front ghost cell (relaxing) until step 9, and its
    # recording appears 12 m ahead of where it would be at step 10
    bodies = _moving(3, 1, 320.0, 20.0, range(10))
    ghosts = [(k, 3, 332.0 + 2.0 * k, 20.0) for k in range(10, STEPS)]
    ids = np.array(["a", "b", "c", "rec-3"])
    s = _section(bodies, ghosts, record_ids=ids)
    assert s["discontinuous"] == 1
    assert s["position_jump_m"]["max"] == pytest.approx(12.0)
    seam = s["by_roles"]["relaxing>ghost"]
    assert (seam["pairs"], seam["position_jump_max_m"], seam["discontinuous"]) == (1, 12.0, 1)
    assert s["by_roles"]["ghost>ghost"]["discontinuous"] == 0
    assert s["worst"]["record_id"] == "rec-3" and s["worst"]["roles"] == "relaxing>ghost"
    assert s["worst"]["time"] == pytest.approx(1.0) and s["tracks"]["count"] == 1


def test_a_hand_over_on_the_recording_and_hard_braking_are_continuous():
    # tid 4 brakes at 8 m/s^2 (below 1 g) inside the window, then is handed to its
    # recording exactly where it is carried on
    bodies = [(k, 4, 1, 150.0 + 20.0 * DT * k - 4.0 * (DT * k) ** 2, 20.0 - 8.0 * DT * k)
              for k in range(10)]  # fmt: skip
    x9, v9 = bodies[-1][3], bodies[-1][4]
    ghosts = [(10, 4, x9 + v9 * DT, v9), (11, 4, x9 + 2 * v9 * DT, v9)]
    s = _section(bodies, ghosts)
    assert s["discontinuous"] == 0 and s["position_jump_m"]["max"] < 1e-6
    assert s["speed_jump_mps"]["max"] == 0.0


def test_a_speed_jump_beyond_one_g_is_counted():
    bodies = _moving(5, 1, 150.0, 20.0, range(5))
    bodies += [(5, 5, 1, 150.0 + 20.0 * DT * 5, 18.0)]  # -2 m/s in 0.1 s (20 m/s^2)
    s = _section(bodies, [])
    assert s["speed_jump_mps"]["max"] == pytest.approx(2.0 - 9.81 * DT)
    assert s["discontinuous"] == 1


def test_tracks_begin_and_end_at_the_region_edge_or_are_seams():
    bodies = _moving(6, 1, 180.0, 10.0, range(3, 8))  # begins and ends in the window
    bodies += _moving(7, 0, 200.0, 10.0, range(STEPS))  # the ego: the whole episode
    ghosts = [(k, 8, 399.0 + 0.1 * k, 1.0) for k in range(0, 4)]  # leaves at the front edge
    ghosts += [(k, 9, 50.0, 0.0) for k in range(5, 9)]  # ends where its recording ends
    recording = {6: range(-5, 30), 7: range(-5, 30), 8: range(-5, 30), 9: range(5, 9)}
    s = _section(bodies, ghosts, recording)
    assert s["tracks"]["count"] == 4
    assert s["tracks"]["begin"] == {"episode": 2, "edge": 0, "road": 0, "recording": 1,
                                    "inside": 1}  # fmt: skip
    assert s["tracks"]["end"] == {"episode": 1, "edge": 1, "road": 0, "recording": 1,
                                  "inside": 1}  # fmt: skip


def test_a_gap_in_a_record_splits_its_track_and_a_record_drawn_twice_is_counted():
    bodies = _moving(10, 1, 150.0, 10.0, range(0, 4)) + _moving(10, 1, 150.0, 10.0, range(8, 12))
    # its ghost drawn at its body's time, 100 m off: judged by the body, counted once
    ghosts = [(11, 10, 250.0 + 10.0 * DT * 11, 10.0)]
    s = _section(bodies, ghosts)
    assert s["tracks"]["count"] == 2 and s["doubled"] == 1
    assert s["discontinuous"] == 0 and s["position_jump_m"]["max"] < 1e-9
    assert sum(s["tracks"]["end"].values()) == sum(s["tracks"]["begin"].values()) == 2


def test_ghosts_logged_at_a_low_rate_are_one_track():
    # ghosts logged at 2 Hz: rows 0.5 s apart are one track, judged pair by pair
    ghosts = [(k, 14, 150.0 + 10.0 * DT * k, 10.0) for k in range(0, STEPS, 5)]
    s = _section([], ghosts, ghost_period=0.5)
    assert s["tracks"]["count"] == 1 and s["pairs"] == 3 and s["discontinuous"] == 0
    assert s["tracks"]["begin"]["inside"] == 0 and s["tracks"]["end"]["inside"] == 0


def test_a_body_removed_where_its_recording_leaves_the_lanes_ends_at_the_recording():
    bodies = _moving(15, 1, 150.0, 10.0, range(0, 6))
    s = _section(bodies, [], off=[(15, k) for k in range(6, STEPS + 5)])
    assert s["tracks"]["end"]["recording"] == 1 and s["tracks"]["end"]["inside"] == 0


def test_bodies_far_beyond_the_ghost_windows_are_counted():
    bodies = _moving(12, 1, -80.0, 0.0, range(STEPS))  # 80 m behind the rear ghost window
    bodies += _moving(13, 1, 430.0, 0.0, range(STEPS))  # 30 m ahead of the front one
    s = _section(bodies, [])
    assert s["beyond_region"] == {"margin_m": 50.0, "vehicles": 1, "farthest_m": 80.0}


def test_an_empty_log_has_an_empty_section():
    s = _section([], [])
    assert s["pairs"] == 0 and s["worst"] is None and s["tracks"]["count"] == 0
