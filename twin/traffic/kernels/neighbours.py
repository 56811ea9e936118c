"""Who is ahead of whom in each lane: one sort per step of an episode's lane entries,
keyed (lane, x), and binary searches in it. Lane -5 (an on-ramp's acceleration
lane, :mod:`twin.core.ramps`) is a lane as the others are.

A vehicle occupies every lane it is in: the lane it drives to, during a lane change
the lane it leaves, the lane its body is in, and any lane its footprint reaches more
than :data:`FOOTPRINT_REACH` into (a body standing yawed across a line, as one that
gave up a change at a lane's end does: the drivers of that lane see it ahead of them);
an obstacle its lane and the one its footprint reaches into so (``reach``: a recorded
vehicle standing off its lane's centre by the line, as a sub-lane model drives them,
was run into by a wide truck driving the next lane's centre, which did not see it).
Each occupied lane is an entry; entries are sorted by ``group * LANE_KEY + x`` with
``group`` 0..4 for lanes -1..-5, and the leader of an entry is the next entry of its
group.

Owners number the vehicles' slots ``0..N-1`` and the obstacles ``N + g``; the step's
values of both (x, length, speed, last command) are gathered in the scratch's ``sx``,
``slength``, ``sspeed`` and ``saccel``, indexed by owner.

The vehicles' entries keep last step's order and are put right by an insertion sort
(a few neighbours overtake per step, so it costs about one pass); the obstacles, which
come sorted by x, are merged in.
"""

import math

from twin.core.i24 import LANE_WIDTH
from twin.core.jit import kernel

LANE_KEY = 1.0e6  # [m] spacing of the lanes in the sort key, beyond any road-frame x
N_GROUPS = 5  # lanes -1..-4 and an on-ramp's acceleration lane, -5
# [m] how far past a lane's line a footprint reaches before the body occupies that lane
# too: short of the 0.53 m a 2.6 m wide truck keeps to each line of a 3.66 m lane, so
# that a body reaching that far is ahead of the drivers of that lane before it touches
# one; longer than a body driving along its lane off its centre reaches
FOOTPRINT_REACH = 0.4


@kernel(inline=True)
def group_of(lane):
    """The entry group (0..4) of lane -1..-5; -1 for anything else."""
    if -N_GROUPS <= lane <= -1:
        return -lane - 1
    return -1


@kernel(inline=True)
def lanes_occupied(vehicles, drivers, b, o):
    """The lanes vehicle ``o`` occupies (module doc), as bits ``1 << (-lane - 1)``: its
    driver's lane and the lane it leaves, its body's lane, and the lanes its footprint
    (length and width about the centre, turned by its yaw) reaches more than
    :data:`FOOTPRINT_REACH` into."""
    bits = 0
    for which in range(3):
        if which == 0:
            lane = drivers.lane[b, o]
        elif which == 1:
            lane = drivers.lane_from[b, o]
        else:
            lane = vehicles.lane[b, o]
        if group_of(lane) >= 0:
            bits |= 1 << (-lane - 1)
    yaw = vehicles.yaw[b, o]
    half = 0.5 * (vehicles.length[b, o] * abs(math.sin(yaw))
                  + vehicles.width[b, o] * abs(math.cos(yaw)))  # fmt: skip
    return bits | footprint_lanes(vehicles.y[b, o], half)


@kernel(inline=True)
def footprint_lanes(y, half):
    """The lanes (bits as :func:`lanes_occupied`) a footprint centred at ``y`` [m] and
    ``half`` [m] wide each side reaches more than :data:`FOOTPRINT_REACH` into."""
    bits = 0
    # lane -k lies between y = k and k + 1 lane widths: the footprint, less the reach
    # at each side, must cross into it
    low = (y - half + FOOTPRINT_REACH) / LANE_WIDTH
    high = (y + half - FOOTPRINT_REACH) / LANE_WIDTH
    if not (math.isfinite(low) and math.isfinite(high)):
        return bits
    for k in range(max(math.floor(low), 1), min(math.ceil(high) - 1, N_GROUPS) + 1):
        bits |= 1 << (k - 1)
    return bits


@kernel
def gather(b, t):
    """The step's owner values (module doc): vehicles' back x, length, speed (>= 0) and
    last command; obstacles' x, length, speed and no acceleration (``t`` a packed
    :data:`~twin.traffic.kernels.state.Traffic`)."""
    vehicles, obstacles, drivers, sc = t.vehicles, t.obstacles, t.drivers, t.scratch
    valid, x, length, speed = vehicles.valid, vehicles.x, vehicles.length, vehicles.speed
    accel = drivers.accel
    sx, slength, sspeed, saccel = sc.sx, sc.slength, sc.sspeed, sc.saccel
    n = valid.shape[1]
    for i in range(vehicles.top[b]):
        if valid[b, i]:
            sx[b, i] = x[b, i]
            slength[b, i] = length[b, i]
            sspeed[b, i] = max(speed[b, i], 0.0)
            saccel[b, i] = accel[b, i]
    ox, olength, ospeed = obstacles.x, obstacles.length, obstacles.speed
    for g in range(obstacles.count[b]):
        sx[b, n + g] = ox[b, g]
        slength[b, n + g] = olength[b, g]
        sspeed[b, n + g] = ospeed[b, g]
        saccel[b, n + g] = 0.0


@kernel
def sort_entries(b, t):
    """Rebuild episode ``b``'s sorted entries (module doc) from the vehicles' lanes and
    the obstacles; :func:`gather` first."""
    vehicles, obstacles, drivers, sc = t.vehicles, t.obstacles, t.drivers, t.scratch
    valid = vehicles.valid
    marks, order_owner, order_lane = sc.marks, sc.order_owner, sc.order_lane
    key, sx = sc.entry_key, sc.sx
    n = valid.shape[1]
    top = vehicles.top[b]
    # the lanes each vehicle occupies in the high bits, those already entered in the low
    for i in range(top):
        marks[b, i] = lanes_occupied(vehicles, drivers, b, i) << N_GROUPS if valid[b, i] else 0
    # last step's vehicle entries that still hold, in their order
    m = 0
    for k in range(sc.order_count[b]):
        o, lane = order_owner[b, k], order_lane[b, k]
        bit = 1 << (-lane - 1)
        if o >= top or not valid[b, o] or marks[b, o] & bit:
            continue
        if (marks[b, o] >> N_GROUPS) & bit:
            order_owner[b, m], order_lane[b, m] = o, lane
            marks[b, o] |= bit
            m += 1
    # and the new ones, in slot order
    for o in range(top):
        if not valid[b, o]:
            continue
        for grp in range(N_GROUPS):
            bit = 1 << grp
            if marks[b, o] & bit or not (marks[b, o] >> N_GROUPS) & bit:
                continue
            order_owner[b, m], order_lane[b, m] = o, -grp - 1
            marks[b, o] |= bit
            m += 1
    sc.order_count[b] = m
    # insertion sort by key (the order is last step's: nearly sorted)
    for k in range(m):
        key[b, k] = (-order_lane[b, k] - 1) * LANE_KEY + sx[b, order_owner[b, k]]
    for k in range(1, m):
        kk, o, lane = key[b, k], order_owner[b, k], order_lane[b, k]
        j = k - 1
        while j >= 0 and key[b, j] > kk:
            key[b, j + 1] = key[b, j]
            order_owner[b, j + 1] = order_owner[b, j]
            order_lane[b, j + 1] = order_lane[b, j]
            j -= 1
        key[b, j + 1], order_owner[b, j + 1], order_lane[b, j + 1] = kk, o, lane
    _merge(b, m, n, obstacles.count[b], obstacles.lane, obstacles.reach, obstacles.x,
           order_owner, order_lane, key, sc.entry_owner, sc.entry_group,
           sc.entry_count)  # fmt: skip


@kernel(inline=True)
def _merge(b, m, n, count, ob_lane, ob_reach, ob_x, order_owner, order_lane, key, owner,
           group, entries):  # fmt: skip
    """The vehicles' ``m`` sorted entries (their keys in ``key``) merged with the
    obstacles (an entry in their lane and one in the lane they reach into), each lane's
    in x order (they come sorted by x), into the entries."""
    out = m + count
    for g in range(count):
        if group_of(ob_reach[b, g]) >= 0:
            out += 1
    v = m - 1
    w = out - 1
    for grp in range(N_GROUPS - 1, -1, -1):
        for g in range(count - 1, -1, -1):
            if group_of(ob_lane[b, g]) != grp and group_of(ob_reach[b, g]) != grp:
                continue
            kk = grp * LANE_KEY + ob_x[b, g]
            while v >= 0 and key[b, v] > kk:
                owner[b, w], group[b, w] = order_owner[b, v], -order_lane[b, v] - 1
                key[b, w] = key[b, v]
                v -= 1
                w -= 1
            owner[b, w], group[b, w], key[b, w] = n + g, grp, kk
            w -= 1
    while v >= 0:
        owner[b, w], group[b, w] = order_owner[b, v], -order_lane[b, v] - 1
        key[b, w] = key[b, v]
        v -= 1
        w -= 1
    # obstacles off the lanes took no place: close the hole at the front
    shift = w + 1
    if shift > 0:
        for k in range(shift, out):
            owner[b, k - shift] = owner[b, k]
            group[b, k - shift] = group[b, k]
            key[b, k - shift] = key[b, k]
    entries[b] = out - shift


@kernel(inline=True)
def leader_entry(count, group, b, e):
    """The entry ahead of entry ``e`` in its lane, -1 where none (``count`` the
    episode's entries, ``group`` the entries' groups)."""
    if e + 1 < count and group[b, e + 1] == group[b, e]:
        return e + 1
    return -1


@kernel(inline=True)
def around(key, group, owner, count, b, lane, x):
    """(ahead, behind): the owners just ahead of and just behind road-frame ``x`` [m] in
    ``lane`` among the ``count`` sorted entries (``key``, ``group``, ``owner``), -1
    where the lane is empty that way; an entry exactly at ``x`` (the asking vehicle)
    is neither."""
    return _around(key, group, owner, count, b, lane, x, -1, True)


@kernel(inline=True)
def around_other(key, group, owner, count, b, lane, x, me):
    """(ahead, behind) of owner ``me`` at road-frame ``x`` [m] in ``lane``, as
    :func:`around`, except that an entry exactly at ``x`` is ``me``'s own only if ``me``
    owns it: another's (a vehicle or an obstacle level with it in a lane it moves to)
    is ahead, overlapping it, not invisible."""
    return _around(key, group, owner, count, b, lane, x, me, False)


@kernel(inline=True)
def _around(key, group, owner, count, b, lane, x, me, any_level):
    """:func:`around` (``any_level``: every entry exactly at ``x`` is skipped) and
    :func:`around_other` (only ``me``'s is)."""
    grp = group_of(lane)
    if grp < 0:
        return -1, -1
    query = grp * LANE_KEY + x
    lo = _first_not_before(key, count, b, query)
    before = lo - 1
    after = lo
    while after < count and key[b, after] == query and (any_level or owner[b, after] == me):
        after += 1
    ahead = owner[b, after] if after < count and group[b, after] == grp else -1
    behind = owner[b, before] if before >= 0 and group[b, before] == grp else -1
    return ahead, behind


@kernel(inline=True)
def _first_not_before(key, count, b, query):
    """The first of the ``count`` sorted entries of episode ``b`` whose key is at least
    ``query`` (``count`` where none is): a binary search."""
    lo, hi = 0, count
    while lo < hi:
        mid = (lo + hi) // 2
        if key[b, mid] < query:
            lo = mid + 1
        else:
            hi = mid
    return lo
