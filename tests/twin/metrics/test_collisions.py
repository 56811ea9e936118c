"""Collisions explained (twin.metrics.collisions) on a hand-made log."""

import numpy as np
import pandas as pd

from twin.cosim.core.layout import (
    CONTACT_CHANGING,
    CONTACT_GHOST,
    CONTACT_MANDATORY,
    CONTACT_RELAXING,
    GHOST_ID_BASE,
)
from twin.metrics.collisions import CAUSES, COLUMNS, UNKNOWN, collision_section, count_collisions

DT = 0.5


def _rows(vehicle_id, role, lanes, speeds, start=0):
    return [
        (start + k * DT, vehicle_id, role, lane, speed)
        for k, (lane, speed) in enumerate(zip(lanes, speeds, strict=True))
    ]


def _log():
    n = 40  # 20 s
    rows = _rows(0, 0, [-2] * n, [10.0] * n)  # the ego, following in lane -2
    rows += _rows(1, 1, [-2] * n, [0.0] * n)  # stopped in lane -2 all along: stalled
    rows += _rows(2, 1, [-3] * 30 + [-2] * 10, [12.0] * n)  # into lane -2 at 15 s
    rows += _rows(3, 1, [-4] * 4, [20.0] * 4, start=17.0)  # spawned at 17 s
    rows += _rows(4, 1, [-4] * n, [22.0] * n)
    return pd.DataFrame(rows, columns=["time", "id", "role", "lane", "speed"])


def test_each_pair_is_one_collision_with_both_vehicles_and_a_cause():
    contacts = [
        (12.0, 1, 0),  # the ego runs into the stalled vehicle: rear-end
        (12.5, 0, 1),  # the same pair again: one collision, two contacts
        (15.5, 2, 0),  # vehicle 2 changing into the ego's lane
        (17.2, 3, 4),  # vehicle 3 spawned just before
    ]
    out = collision_section(contacts, _log())
    assert out["contacts"] == 4 and out["collisions"] == 3
    assert out["collisions_by_cause"] == {"ghost": 0, "spawn": 1, "lane_change": 1,
                                          "rear_end": 1, "other": 0, "unknown": 0}  # fmt: skip
    first, change, spawn = out["collision_list"]
    assert first["ids"] == [0, 1] and first["contacts"] == 2 and first["cause"] == "rear_end"
    ego, stalled = first["vehicles"]
    assert ego == {"id": 0, "role": "ego", "lane": -2, "speed_mps": 10.0, "doing": "following"}
    assert stalled["role"] == "visible" and stalled["doing"] == "stalled"
    assert change["cause"] == "lane_change" and change["vehicles"][1]["doing"] == "changing_lanes"
    assert spawn["cause"] == "spawn" and spawn["vehicles"][0]["doing"] == "just_spawned"


def test_contacts_past_those_listed_are_counted_as_collisions_of_unknown_cause():
    out = collision_section([(12.0, 0, 1)], _log(), total=3, unlisted=2)
    assert out["contacts"] == 3 and out["collisions"] == 3
    assert out["collisions_by_cause"]["unknown"] == 2
    # past the list, contacts of a listed pair are that pair's: no collision more
    out = collision_section([(12.0, 0, 1)], _log(), total=80, unlisted=0)
    assert out["contacts"] == 80 and out["collisions"] == 1


def test_no_contact_gives_no_collision():
    out = collision_section([], _log())
    assert out["contacts"] == 0 and out["collisions"] == 0 and out["collision_list"] == []
    assert not any(np.asarray(list(out["collisions_by_cause"].values())))


def test_twin_evals_columns_are_every_cause_once():
    assert sorted(COLUMNS) == sorted({*CAUSES, UNKNOWN}) and len(COLUMNS) == len(CAUSES) + 1
    assert list(collision_section([], _log())["collisions_by_cause"]) == [*CAUSES, UNKNOWN]


def test_collisions_count_pairs_and_each_contact_past_those_kept():
    kept = [(1.0, 3, 5), (2.0, 5, 3), (3.0, 3, 6)]
    assert count_collisions(kept) == 2 and count_collisions(kept, 4) == 6
    assert count_collisions([], 0) == 0


def test_the_cores_flags_name_relaxing_vehicles_merging_and_ghosts():
    nan = float("nan")
    ghost = GHOST_ID_BASE - 77  # store trajectory 77
    contacts = [
        # vehicle 4 relaxing in a ghost cell, a ghost (lane -4, 21 m/s) runs onto it
        (5.0, 4, ghost, CONTACT_RELAXING, CONTACT_GHOST, -4, 21.0),
        # vehicle 2 in a change it must make (a lane ending) into the stalled vehicle 1
        (6.0, 1, 2, 0, CONTACT_CHANGING | CONTACT_MANDATORY, 0, nan),
        # the ego and vehicle 4 (the core saw 4 changing lanes; the log's rows do not)
        (8.0, 4, 0, CONTACT_CHANGING, 0, 0, nan),
    ]
    out = collision_section(contacts, _log())
    assert out["collisions"] == 3
    assert out["collisions_by_cause"]["ghost"] == 1
    assert out["collisions_by_cause"]["lane_change"] == 2
    on_ghost, merge, change = out["collision_list"]
    assert on_ghost["ids"] == [ghost, 4] and on_ghost["cause"] == "ghost"
    ghost_state, relaxing = on_ghost["vehicles"]
    assert ghost_state == {"id": None, "tid": 77, "role": "ghost", "lane": -4,
                           "speed_mps": 21.0, "doing": "recorded"}  # fmt: skip
    assert relaxing["role"] == "relaxing" and relaxing["id"] == 4
    assert merge["vehicles"][1]["doing"] == "merging"
    assert change["ids"] == [0, 4] and change["vehicles"][1]["doing"] == "changing_lanes"
