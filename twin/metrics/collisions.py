"""Every collision explained: who touched whom, what each was doing, and why, read from
an episode's contacts and its trajectory log (the ``physics`` section of
``metrics.json``).

A contact is a pair of vehicles that begins to touch: two bodies (the world's contact,
or the kinematic world's footprints), or a body and a ghost (footprints: a ghost has no
body, but it is drawn and labelled, so a body on it is a crash the cameras see). The
core records each with its time, the two ids and what each was doing then
(:data:`~twin.cosim.core.layout.CONTACT_COLUMNS`). A **collision** is a pair that
touched at least once, however often it touched again (two bodies pushed together in a
queue touch and part many times). Each collision is listed with both vehicles at its
first contact:

* ``role``: ``ego``, ``visible``, ``relaxing`` (a simulated vehicle in a ghost cell on
  its way back to its recording, :mod:`twin.cosim.core.relax`) or ``ghost`` (``id``
  null, ``tid`` its store trajectory);
* ``lane``, ``speed_mps``;
* ``doing``: ``just_spawned`` (its first row less than :data:`JUST_SPAWNED_S` before),
  ``merging`` (in a lane change it must make, or seeking one inside its strategic
  target's zone: a lane ending, a merge), ``changing_lanes`` (its lane in the log
  changes within :data:`CHANGE_BEFORE_S` before or :data:`CHANGE_AFTER_S` after, or
  the core saw it changing), ``stalled`` (slower than :data:`STALLED_SPEED` for the
  :data:`STALLED_S` before), else ``following``; a ghost is ``recorded``.

and a ``cause``, the first that holds: ``ghost`` (one of them is a ghost), ``spawn``
(either just spawned), ``lane_change`` (either changing lanes or merging),
``rear_end`` (the same lane), else ``other``; a contact past those the core keeps
(:data:`~twin.cosim.core.layout.COLLISIONS_KEPT` an episode) of a pair not among them
counts as a collision of cause ``unknown`` (one of a pair kept is that pair's again).
"""

import numpy as np

from twin.cosim.core.layout import (
    CONTACT_CHANGING,
    CONTACT_EGO,
    CONTACT_GHOST,
    CONTACT_MANDATORY,
    CONTACT_RELAXING,
    GHOST_ID_BASE,
)

JUST_SPAWNED_S = 1.0  # [s]
CHANGE_BEFORE_S = 3.0  # [s]
CHANGE_AFTER_S = 1.0  # [s]
STALLED_SPEED = 0.5  # [m/s]
STALLED_S = 10.0  # [s]
CAUSES = ("ghost", "spawn", "lane_change", "rear_end", "other")
UNKNOWN = "unknown"  # the cause of a contact past those the core keeps
#: every cause, in the order of twin eval's columns
COLUMNS = ("rear_end", "lane_change", "spawn", "ghost", "other", UNKNOWN)
LISTED = 20  # the first collisions are listed


def count_collisions(contacts, unlisted: int = 0) -> int:
    """How many collisions the contacts make, of which ``contacts`` (rows of time, id,
    id, ...) are the first kept: the pairs among those kept, and each of the
    ``unlisted`` contacts past them whose pair is not among them as one of its own (its
    pair is not known)."""
    pairs = {(min(int(row[1]), int(row[2])), max(int(row[1]), int(row[2]))) for row in contacts}
    return len(pairs) + int(unlisted)


def collision_section(contacts, vehicles, total: int | None = None, unlisted: int = 0) -> dict:
    """The collisions of an episode (module doc).

    Args:
        contacts: the new contacts, in time order (the core keeps the first
            COLLISIONS_KEPT of an episode): rows of CONTACT_COLUMNS (time [s], id, id,
            then optionally both vehicles' flags and a ghost's lane and speed).
        vehicles: the log's vehicle rows, a DataFrame (``time`` [s], ``id``, ``role``, ``lane``,
            ``speed``).
        total: how many new contacts there were (default: as many as listed).
        unlisted: of those past the listed ones, how many were of pairs not listed
            (the core's ``collisions_unlisted``): each counts as a collision of its
            own, cause ``unknown``.

    Returns:
        ``contacts`` (count), ``collisions`` (pairs), ``collisions_by_cause`` and
        ``collision_list`` (the first :data:`LISTED`).
    """
    first: dict[tuple[int, int], list] = {}
    for row in contacts:
        time, a, b = float(row[0]), int(row[1]), int(row[2])
        flags = (int(row[3]), int(row[4])) if len(row) > 4 else (0, 0)
        ghost = (int(row[5]), float(row[6])) if len(row) > 6 else (0, float("nan"))
        if a > b:
            a, b, flags = b, a, flags[::-1]
        pair = (a, b)
        if pair in first:
            first[pair][1] += 1
        else:
            first[pair] = [time, 1, flags, ghost]
    tracks = {int(i): rows for i, rows in vehicles.groupby("id", sort=False)} if first else {}
    listed, by_cause = [], dict.fromkeys(CAUSES, 0)
    for pair, (time, touches, flags, ghost) in sorted(first.items(), key=lambda item: item[1][0]):
        states = [
            _ghost(i, ghost) if f & CONTACT_GHOST else _state(tracks.get(i), i, time, f)
            for i, f in zip(pair, flags, strict=True)
        ]
        cause = _cause(states)
        by_cause[cause] += 1
        if len(listed) < LISTED:
            listed.append({"time_s": round(time, 3), "ids": list(pair), "contacts": touches,
                           "cause": cause, "vehicles": states})  # fmt: skip
    by_cause[UNKNOWN] = int(unlisted)
    return {
        "contacts": len(contacts) if total is None else int(total),
        "collisions": count_collisions(contacts, unlisted),
        "collisions_by_cause": by_cause,
        "collision_list": listed,
    }


def _ghost(key: int, ghost: tuple) -> dict:
    """A ghost in a contact (its id there ``GHOST_ID_BASE - tid``; its lane and speed)."""
    lane, speed = ghost
    return {
        "id": None,
        "tid": GHOST_ID_BASE - key,
        "role": "ghost",
        "lane": lane,
        "speed_mps": round(speed, 3),
        "doing": "recorded",
    }


def _state(rows, vehicle_id: int, time: float, flags: int = 0) -> dict:
    """What vehicle ``vehicle_id`` was at ``time`` (its last log row at or before it;
    ``flags``, the core's CONTACT_* flags of it then)."""
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
    elif flags & CONTACT_MANDATORY:
        doing = "merging"
    elif flags & CONTACT_CHANGING or np.any(lanes[around] != lane):
        doing = "changing_lanes"
    elif times[0] <= time - STALLED_S and np.all(speeds[before] < STALLED_SPEED):
        doing = "stalled"
    else:
        doing = "following"
    return {
        "id": vehicle_id,
        "role": _role(int(rows["role"].to_numpy()[k]), flags),
        "lane": lane,
        "speed_mps": round(float(speeds[k]), 3),
        "doing": doing,
    }


def _role(logged: int, flags: int) -> str:
    """The role of a body (its log role, ``flags`` the core's at the contact)."""
    if logged == 0 or flags & CONTACT_EGO:
        return "ego"
    return "relaxing" if flags & CONTACT_RELAXING else "visible"


def _cause(states: list[dict]) -> str:
    if any(s["role"] == "ghost" for s in states):
        return "ghost"
    doings = {s["doing"] for s in states}
    if "just_spawned" in doings:
        return "spawn"
    if doings & {"changing_lanes", "merging"}:
        return "lane_change"
    lanes = {s["lane"] for s in states}
    if len(lanes) == 1 and None not in lanes:
        return "rear_end"
    return "other"
