"""The ghost-cell boundary's jumps (twin.metrics.handover) on a hand-made log."""

import numpy as np
import pandas as pd
import pytest

from twin.core.i24 import Road
from twin.metrics.handover import handover_section

T0, DT = 1000.0, 0.1


class Recording:
    """Recorded states by (tid, step); absent elsewhere."""

    def __init__(self, states):
        self.states = states

    def recorded_states(self, road, tids, times):
        steps = np.round((np.asarray(times) - T0) / DT).astype(int)
        rows = [self.states.get((int(tid), int(k))) for tid, k in zip(tids, steps, strict=True)]
        present = np.array([row is not None for row in rows])
        x = np.array([row[0] if row else 0.0 for row in rows])
        speed = np.array([row[1] if row else 0.0 for row in rows])
        return present, x, np.zeros(len(rows)), speed


def _log(rows, accel=None):
    vehicles = pd.DataFrame(rows, columns=["step", "id", "tid", "role", "x", "speed"])
    vehicles["time"] = vehicles.pop("step") * DT
    vehicles["accel"] = np.nan if accel is None else accel
    windows = pd.DataFrame({"time": np.arange(5) * DT, "g0": 0.0, "x0": 100.0, "x1": 300.0,
                            "g1": 400.0})  # fmt: skip
    return vehicles, windows


@pytest.fixture
def section():
    rows = [(k, 0, 1, 0, 200.0 + 3 * k, 30.0) for k in range(5)]  # the ego: not counted
    rows += [(k, 1, 7, 1, 290.0 + 3 * k, 30.0) for k in range(3)]  # removed at step 3
    rows += [(k, 2, 8, 1, 150.0, 10.0) for k in range(2)]  # removed, recording absent
    rows += [(k, 3, 9, 1, 110.0, 10.0) for k in range(2)]  # removed, recording visible
    rows += [(k, 4, 10, 1, 105.0, 10.0) for k in range(2)]  # removed, recording behind
    rows += [(k, 5, 11, 1, 95.0 + 2 * (k - 2), 20.0) for k in range(2, 5)]  # spawned
    rows += [(k, 6, 12, 1, 250.0, 0.0) for k in range(5)]  # stays to the end
    rows += [(k, 13, 13, 1, 310.0 + 3 * k, 30.0 - 0.5 * k) for k in range(5)]  # relaxing
    rows += [(k, 14, 14, 1, 995.0 + 3 * k, 30.0) for k in range(3)]  # drives off the road
    rows += [(k, 15, 15, 1, 290.0 + 7 * k, 20.0) for k in range(5)]  # out of the window at 2
    recording = Recording({
        (7, 3): (310.0, 29.0),  # in the front ghost cell: 11 m ahead of 296 + 3
        (9, 2): (200.0, 10.0),  # inside the visible window: 89 m ahead of 110 + 1
        (10, 2): (90.0, 12.0),  # in the rear ghost cell: 16 m behind 105 + 1
        (11, 1): (92.9, 20.0),  # a ghost the step before its spawn: 92.9 + 2 = 94.9
        **{(13, k): (312.0 + 3 * k - 0.5 * k, 30.0) for k in range(5)},  # 13 is 2 m behind
        (14, 3): (500.0, 30.0),  # still in the windows, but 14 left the road
    })  # fmt: skip
    accel = [np.nan] * len(rows)
    accel[-13:-8] = [np.nan, -5.0, -3.5, 1.5, -0.5]  # vehicle 13's measured acceleration
    accel[-5:] = [np.nan, 0.5, 3.0, 1.0, 1.0]  # 15's: the 3.0 commanded inside the window
    vehicles, windows = _log(rows, accel)
    return handover_section(vehicles, windows, recording, Road.WESTBOUND, T0, DT, (0.0, 1000.0))


def test_a_vehicle_handed_back_jumps_to_its_recording_and_the_jump_is_measured(section):
    out = section["visible_to_ghost"]
    assert out["count"] == 2  # 7 and 10: their recordings are in the ghost cells
    assert out["into_visible_window"] == 1  # 9: its recording is visible, not drawn
    assert out["left_windows"] == 1  # 8: its recording is absent
    assert out["left_road"] == 1  # 14: beyond the road's end, whatever its recording
    assert out["backwards"] == 1  # 10
    assert out["position_jump_m"]["max"] == pytest.approx(16.0)
    assert out["position_jump_m"]["median"] == pytest.approx(13.5)  # 11 and 16 m
    assert out["speed_jump_mps"]["max"] == pytest.approx(2.0)


def test_the_vehicles_outside_the_visible_window_are_relaxing_and_measured(section):
    out = section["relaxing"]
    assert out["vehicles"] == 4  # 13, 14 and 15 ahead of the visible window, 5 behind it
    assert out["accel_min_mps2"] == -5.0 and out["accel_max_mps2"] == 1.5
    assert out["speed_min_mps"] == pytest.approx(20.0)  # 5
    distance = out["distance_m"]  # 13 against its recording (5 has none then)
    assert distance["median"] == pytest.approx(1.0) and distance["max"] == pytest.approx(2.0)


def test_a_spawn_from_the_ghost_cells_is_measured_against_its_ghost(section):
    out = section["ghost_to_visible"]
    assert out["count"] == 1
    assert out["position_jump_m"]["max"] == pytest.approx(0.1)
    assert out["speed_jump_mps"]["max"] == pytest.approx(0.0)
    assert out["backwards"] == 0


def test_no_hand_over_gives_counts_of_zero_and_no_figures():
    vehicles, windows = _log([(k, 0, 1, 0, 200.0, 30.0) for k in range(5)])
    out = handover_section(vehicles, windows, Recording({}), Road.WESTBOUND, T0, DT)
    assert out["visible_to_ghost"]["count"] == 0
    assert out["visible_to_ghost"]["position_jump_m"] == {"median": None, "p90": None,
                                                          "max": None}  # fmt: skip
    assert out["ghost_to_visible"]["count"] == 0


def test_a_log_without_windows_has_no_hand_over():
    vehicles, windows = _log([(0, 0, 1, 0, 200.0, 30.0), (0, 3, 9, 1, 110.0, 10.0)])
    out = handover_section(vehicles, windows.iloc[:0], Recording({}), Road.WESTBOUND, T0, DT)
    assert out["visible_to_ghost"]["count"] == out["ghost_to_visible"]["count"] == 0
