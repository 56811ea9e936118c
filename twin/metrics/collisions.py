"""Every collision explained: who touched whom, what each was doing, and why, read from
an episode's contacts and its trajectory log (the ``physics`` section of
``metrics.json``).

A contact is a pair of bodies that begins to touch (the core records each with its
time and the two ids); a **collision** is a pair that touched at least once, however
often it touched again (two bodies pushed together in a queue touch and part many
times). Each collision is listed with both vehicles at its first contact:

* ``role``: ``ego`` or ``visible`` (ghosts have no body and cannot touch);
* ``lane``, ``speed_mps``;
* ``doing``: ``just_spawned`` (its first row less than :data:`JUST_SPAWNED_S` before),
  ``changing_lanes`` (its lane in the log changes within :data:`CHANGE_BEFORE_S`
  before or :data:`CHANGE_AFTER_S` after), ``stalled`` (slower than
  :data:`STALLED_SPEED` for the :data:`STALLED_S` before), else ``following``.

and a ``cause``, the first that holds: ``spawn`` (either just spawned), ``lane_change``
(either changing lanes), ``rear_end`` (the same lane), else ``other``; a contact past
those the core keeps (:data:`~twin.cosim.core.layout.COLLISIONS_KEPT` an episode) counts as a
collision of cause ``unknown``.
"""

import numpy as np

JUST_SPAWNED_S = 1.0  # [s]
CHANGE_BEFORE_S = 3.0  # [s]
CHANGE_AFTER_S = 1.0  # [s]
STALLED_SPEED = 0.5  # [m/s]
STALLED_S = 10.0  # [s]
CAUSES = ("spawn", "lane_change", "rear_end", "other")
UNKNOWN = "unknown"  # the cause of a contact past those the core keeps
#: every cause, in the order of twin eval's columns
COLUMNS = ("rear_end", "lane_change", "spawn", "other", UNKNOWN)
LISTED = 20  # the first collisions are listed


def count_collisions(contacts, total: int) -> int:
    """How many collisions ``total`` new contacts make, of which ``contacts`` (time, id,
    id) are the first kept: the pairs among those kept, and each contact past them as
    one of its own (its pair is not known)."""
    pairs = {(min(int(a), int(b)), max(int(a), int(b))) for _, a, b in contacts}
    return len(pairs) + max(int(total) - len(contacts), 0)


def collision_section(contacts, vehicles, total: int | None = None) -> dict:
    """The collisions of an episode (module doc).

    Args:
        contacts: (time [s], id, id) of the new contacts, in time order (the core keeps
            first COLLISIONS_KEPT of an episode).
        vehicles: the log's vehicle rows, a DataFrame (``time`` [s], ``id``, ``role``, ``lane``,
            ``speed``).
        total: how many new contacts there were (default: as many as listed); each
            one past those listed counts as a collision of its own, cause
            ``unknown``.

    Returns:
        ``contacts`` (count), ``collisions`` (pairs), ``collisions_by_cause`` and
        ``collision_list`` (the first :data:`LISTED`).
    """
    first: dict[tuple[int, int], list] = {}
    for time, a, b in contacts:
        pair = (min(int(a), int(b)), max(int(a), int(b)))
        if pair in first:
            first[pair][1] += 1
        else:
            first[pair] = [float(time), 1]
    tracks = {int(i): rows for i, rows in vehicles.groupby("id", sort=False)} if first else {}
    listed, by_cause = [], dict.fromkeys(CAUSES, 0)
    for pair, (time, touches) in sorted(first.items(), key=lambda item: item[1][0]):
        states = [_state(tracks.get(i), i, time) for i in pair]
        cause = _cause(states)
        by_cause[cause] += 1
        if len(listed) < LISTED:
            listed.append({"time_s": round(time, 3), "ids": list(pair), "contacts": touches,
                           "cause": cause, "vehicles": states})  # fmt: skip
    unlisted = max((len(contacts) if total is None else int(total)) - len(contacts), 0)
    by_cause[UNKNOWN] = unlisted
    return {
        "contacts": len(contacts) + unlisted,
        "collisions": count_collisions(contacts, len(contacts) + unlisted),
        "collisions_by_cause": by_cause,
        "collision_list": listed,
    }


def _state(rows, vehicle_id: int, time: float) -> dict:
    """What vehicle ``vehicle_id`` was at ``time`` (its last log row at or before it)."""
    if rows is None or rows.empty:
        return {"id": vehicle_id, "role": None, "lane": None, "speed_mps": None, "doing": None}
    times = rows["time"].to_numpy()
    k = max(int(np.searchsorted(times, time + 1e-9, side="right")) - 1, 0)
    lanes, speeds = rows["lane"].to_numpy(), rows["speed"].to_numpy()
    lane = int(lanes[k])
    around = (times >= time - CHANGE_BEFORE_S) & (times <= time + CHANGE_AFTER_S)
    before = (times >= time - STALLED_S) & (times <= time)
    if time - times[0] < JUST_SPAWNED_S:
        doing = "just_spawned"
    elif np.any(lanes[around] != lane):
        doing = "changing_lanes"
    elif times[0] <= time - STALLED_S and np.all(speeds[before] < STALLED_SPEED):
        doing = "stalled"
    else:
        doing = "following"
    return {
        "id": vehicle_id,
        "role": "ego" if int(rows["role"].to_numpy()[k]) == 0 else "visible",
        "lane": lane,
        "speed_mps": round(float(speeds[k]), 3),
        "doing": doing,
    }


def _cause(states: list[dict]) -> str:
    doings = {s["doing"] for s in states}
    if "just_spawned" in doings:
        return "spawn"
    if "changing_lanes" in doings:
        return "lane_change"
    lanes = {s["lane"] for s in states}
    if len(lanes) == 1 and None not in lanes:
        return "rear_end"
    return "other"
