"""Anchored ghosts: a recorded vehicle whose simulated body ends is drawn where the body
was, not where its recording is, and closes the distance at a physical rate (issue 76,
``docs/cosim.md``, "The boundary without seams"). On with the run setting ``anchor``
(by default wherever vehicles relax: on the development days it leaves about as many
collisions as relaxation alone, and only it keeps every track continuous). With or
without it, a ghost that could not stop behind a body ahead of it is anchored where it
is and drawn braking for it (:func:`brake_ghosts`); without either, nothing is
anchored and every function here leaves the state as it is.

A body ends at the boundary in two ways: handed back once it is within 0.3 m of its
recording (:func:`twin.cosim.core.handover.hand_back`), or removed where it leaves the
simulated region (the ghost windows and :data:`twin.cosim.core.handover.REAR_MARGIN`
behind them) still metres from its recording (:func:`twin.cosim.core.handover.
despawn_outside`). Drawn at its recording at once, the vehicle jumped by that distance
(scenario B: a median 9 m, up to 34 m), in the log and in the cameras.

Here the body's recording becomes its ghost **anchored**: the tid table keeps its
offset from the recording (along and across the road, and their rates of change:
``TidTable.off_x``, ``off_v``, ``off_y``, ``off_vy``; ``rec_v``, the recorded speed
it was last drawn at), set to the body's state minus the recording's at the step it
ends, so the ghost's first state is the body's. Every
snapshot of the recording draws it at its recorded state plus the offset
(:func:`apply`): it keeps its recording's speed profile, shifted, so the traffic behind
it still sees the recorded wave, and everything that reads the snapshot (the ghost
set, the log, the cameras, a spawn into the visible window, a yield behind a body)
sees it where it is drawn. After each step the offset decays as a critically damped
spring of natural frequency :data:`OMEGA` (relaxation's), its acceleration within
:data:`ACCEL` along and :data:`ACCEL_Y` across, never so fast that the vehicle drawn
would back up (ahead of a standing recording it stands and waits), nor so fast that
it could not stop behind the body or ghost ahead of it (:func:`decay`);
once all four are below :data:`SETTLED` the anchor is dropped and the ghost is its
recording again. A
recorded vehicle simulated again (spawned into the visible window, or made a body
behind one it crowds) drops its anchor: the body starts where it was drawn.

``Episodes.anchors`` lists the anchored entries of the table (at most
:data:`~twin.cosim.core.layout.ANCHORS_KEPT`; one more is not anchored and is counted
in ``anchors_full``; ``anchored`` counts the bodies anchored, ``metrics.json``'s
``counts``); ``anchor_lo`` and ``anchor_hi`` [m] are the smallest and largest
offsets along the road, by which the snapshot reads the recording further
(:func:`twin.cosim.core.handover.snapshot`), so an anchored vehicle whose recording is
outside the windows is still drawn where it is.
"""

import math

import numpy as np

from twin.core.i24 import N_LANES
from twin.core.jit import kernel
from twin.core.ramps import lane_of_y as lane_of
from twin.cosim.core.layout import ANCHORED, SIMULATED, entry
from twin.cosim.core.relax import OMEGA, short_of
from twin.physics.kernels import keep_sorted
from twin.traffic.kernels.steering import centre_y

ACCEL = 2.0  # [m/s^2] the largest acceleration of the offset along the road
ACCEL_Y = 1.0  # [m/s^2] across it
SETTLED = 1e-3  # [m], [m/s] an offset this small in all four is dropped
FOLLOW_GAP = 2.0  # [m] an anchored vehicle keeps this far behind what is ahead of it
FOLLOW_DECEL = 4.0  # [m/s^2] and could stop there braking this hard
BRAKE = 8.0  # [m/s^2] the hardest its drawn speed falls for what is ahead
HEADWAY = 1.0  # [s] what is behind it closer than FOLLOW_GAP and this at its speed
BESIDE_GAP = 0.3  # [m] it moves across no closer than this to a body alongside
BESIDE_WATCH = 0.3  # [m] a ghost this much further from a body alongside is anchored


@kernel
def anchor(b, core, i, rec_x, rec_y, rec_speed):
    """Body slot ``i``, ending now, is drawn from now on as its recording (at back x,
    y [m] and ``rec_speed`` [m/s] now) offset to where the body is. Returns whether it
    was anchored (not where the list is full)."""
    bo, table, ep = core.bodies, core.table, core.episodes
    h = entry(table.key, table.flags, table.slot, b, core.slots.r[b, i], np.bool_(True))
    if h < 0:
        return False
    if table.flags[b, h] & ANCHORED == 0:
        n = ep.anchor_count[b]
        if n == ep.anchors.shape[1]:
            ep.anchors_full[b] += 1
            return False
        ep.anchors[b, n] = h
        ep.anchor_count[b] = n + 1
        table.flags[b, h] |= ANCHORED
    table.off_x[b, h] = bo.x[b, i] - rec_x
    table.off_v[b, h] = bo.speed[b, i] - rec_speed
    table.off_y[b, h] = bo.y[b, i] - rec_y
    table.off_vy[b, h] = bo.speed[b, i] * math.sin(bo.yaw[b, i])
    table.rec_x[b, h], table.rec_y[b, h], table.rec_v[b, h] = rec_x, rec_y, rec_speed
    ep.anchored[b] += 1
    _extent(b, core)
    return True


@kernel
def brake_ghosts(b, core, decel):
    """The ghosts (not anchored) that could not stop behind a body, or an anchored
    vehicle, ahead of them in a lane they occupy, braking at ``decel`` [m/s^2] (a
    yield's: they are those a yield refused, too close to be made a body there) to the
    clearance at rest, are anchored where they are (offset 0): from the next
    snapshot on they are drawn braking for it (:func:`decay`, :func:`_behind`), each
    counted in ``Episodes.ghosts_braked``. Before, a recording closing on a relaxing
    body faster than it could be made a body behind it (a yield needs room to stop at a
    yield's braking) drove on into it (9 of the 22 collisions on the SUMO test family,
    16 x 120 s per day, kinematic). So is a ghost beside a body whose footprint comes
    within :data:`BESIDE_GAP` plus :data:`BESIDE_WATCH` of the body's across the road:
    :func:`apply` then draws it holding its line (a sub-lane driver's recording drifting
    toward a body beside it ran into it: 4 of the 9 collisions left on that family).
    Ghosts do so wherever vehicles relax (not with the
    paper's hand-over, ``relax = false``), with or without the ``anchor`` setting;
    with it, ended bodies are anchored too (:func:`anchor`)."""
    gh, table, bo, ep, sl = core.ghosts, core.table, core.bodies, core.episodes, core.slots
    watch = BESIDE_GAP + BESIDE_WATCH
    # the bodies by back x (as the reload left them: a pass, no move)
    m = keep_sorted(b, bo, sl.by_back, sl.by_back_listed, np.bool_(False))
    order, longest = sl.by_back, 0.0
    for k in range(m):
        longest = max(longest, bo.length[b, order[b, k]])
    for g in range(gh.count[b]):
        h = entry(table.key, table.flags, table.slot, b, np.int64(gh.r[b, g]), np.bool_(False))
        if h < 0 or table.flags[b, h] & (ANCHORED | SIMULATED):
            continue
        x, y, lane, reach = gh.x[b, g], gh.y[b, g], gh.lane[b, g], gh.reach[b, g]
        length, half = gh.length[b, g], 0.5 * core.rec.width[gh.r[b, g]]
        # the nearest body ahead in a lane it occupies; whether one is beside it: from
        # the first body that could be alongside it, to the first beyond both
        ahead, ahead_v, beside = math.inf, 0.0, False
        lo, hi = 0, m
        while lo < hi:
            mid = (lo + hi) // 2
            if bo.x[b, order[b, mid]] < x - FOLLOW_GAP - longest:
                lo = mid + 1
            else:
                hi = mid
        for k in range(lo, m):
            i = order[b, k]
            bx = bo.x[b, i]
            if bx >= x + length + FOLLOW_GAP and bx >= ahead:
                break
            if (bo.lane[b, i] == lane or bo.lane[b, i] == reach) and x < bx < ahead:
                ahead, ahead_v = bx, bo.speed[b, i]
            clear = half + 0.5 * bo.width[b, i]
            if _along(x, length, bx, bo.length[b, i]) and _beside(b, core, i, y, clear, watch):
                beside = True
                break
        if beside:
            _hold(b, core, h, x, y, gh.speed[b, g])  # apply holds its line
            continue
        for a in range(ep.anchor_count[b]):  # or the nearest anchored vehicle ahead
            ha = ep.anchors[b, a]
            if table.flags[b, ha] & SIMULATED:
                continue
            xa = table.rec_x[b, ha] + table.off_x[b, ha]
            if x < xa < ahead:
                la = lane_of(table.rec_y[b, ha] + table.off_y[b, ha])
                if la == lane or la == reach:  # noqa: SIM109 (compiled: two compares)
                    ahead = xa
                    ahead_v = max(table.rec_v[b, ha] + table.off_v[b, ha], 0.0)
        if not math.isfinite(ahead):
            continue
        room = max(ahead - x - length - core.settings.clearance_at_rest, 0.0)
        if gh.speed[b, g] > math.sqrt(ahead_v * ahead_v + 2.0 * decel * room):
            _hold(b, core, h, x, y, gh.speed[b, g])


@kernel(inline=True)
def _hold(b, core, h, x, y, speed):
    """Table entry ``h``, a ghost drawn at back x, y [m] and ``speed`` [m/s] now,
    anchored there (offset 0) and counted in ``Episodes.ghosts_braked``."""
    table, ep = core.table, core.episodes
    n = ep.anchor_count[b]
    if n == ep.anchors.shape[1]:
        ep.anchors_full[b] += 1
        return
    ep.anchors[b, n] = h
    ep.anchor_count[b] = n + 1
    table.flags[b, h] |= ANCHORED
    table.off_x[b, h], table.off_v[b, h], table.off_y[b, h], table.off_vy[b, h] = 0, 0, 0, 0
    table.rec_x[b, h], table.rec_y[b, h], table.rec_v[b, h] = x, y, speed
    ep.ghosts_braked[b] += 1


@kernel(inline=True)
def _near_across(b, core, r, x, y, gap):
    """Whether recording ``r`` drawn at back x, y [m] has a body alongside it
    (:func:`_along`) whose footprint is clear of its own across the road but within
    ``gap`` [m] of it (one whose footprint overlaps it across is ahead or behind it, a
    matter for braking)."""
    bo = core.bodies
    length, half = core.rec.length[r], 0.5 * core.rec.width[r]
    for i in range(bo.top[b]):
        clear = half + 0.5 * bo.width[b, i]
        if (
            bo.valid[b, i]
            and _along(x, length, bo.x[b, i], bo.length[b, i])
            and _beside(b, core, i, y, clear, gap)
        ):
            return True
    return False


@kernel(inline=True)
def _beside(b, core, i, y, clear, gap):
    """Whether a vehicle centred at road-frame ``y`` [m], alongside body ``i``, is beside
    it: their footprints ``clear`` [m] apart at centre distance, clear of each other
    across but within ``gap`` [m]; or, where the body changes lanes, within ``gap`` of
    its footprint at the new lane's centre (:func:`_goes_to`)."""
    by = core.bodies.y[b, i]
    if clear <= abs(by - y) < clear + gap:
        return True
    going = _goes_to(b, core, i)
    return going != by and abs(going - y) < clear + gap


@kernel(inline=True)
def _goes_to(b, core, i):
    """[m] where body ``i`` goes across the road: the centre of its new lane while it
    changes lanes, else where it is (read only where the two differ: from where it is,
    a vehicle overlapping it across is ahead or behind it, not beside it). A relaxing
    car changing into lane -3 beside a recorded truck drifting toward it from lane -4
    (a sub-lane driver) was 2.6 m across from it, too far for the truck to hold its
    line, until they touched (SUMO test family, day 1002 episode 14)."""
    dr = core.traffic.drivers
    if dr.lane_from[b, i] != dr.lane[b, i] and -N_LANES <= dr.lane[b, i] <= -1:
        return centre_y(dr.lane[b, i])
    return core.bodies.y[b, i]


@kernel(inline=True)
def _along(x, length, bx, body_length):
    """Whether boxes from back ``x`` [m], ``length`` long, and from ``bx``,
    ``body_length`` long, overlap along the road, :data:`FOLLOW_GAP` apart."""
    return x - FOLLOW_GAP < bx + body_length and bx - FOLLOW_GAP < x + length


@kernel(inline=True)
def _held_line(b, core, r, x, y_was, y):
    """[m] where recording ``r``, drawn at road-frame ``y_was`` a step ago and at back
    ``x`` now, is drawn across the road now, its recording (plus its offset) asking for
    ``y``: no nearer than :data:`BESIDE_GAP` across to a body alongside it on the side
    it moves toward (a recording does not know of the body and would drive into it),
    nor pushed back from where it was (a body whose footprint overlapped its own across
    is ahead or behind it, not beside it)."""
    bo = core.bodies
    length, half = core.rec.length[r], 0.5 * core.rec.width[r]
    for i in range(bo.top[b]):
        if bo.valid[b, i] and _along(x, length, bo.x[b, i], bo.length[b, i]):
            clear = half + 0.5 * bo.width[b, i]
            if abs(bo.y[b, i] - y_was) >= clear:
                y = short_of(y_was, y, bo.y[b, i], clear + BESIDE_GAP)
            going = _goes_to(b, core, i)  # and from where it goes, changing lanes
            if going != bo.y[b, i] and abs(going - y_was) >= clear:
                y = short_of(y_was, y, going, clear + BESIDE_GAP)
    return y


@kernel
def apply(b, core):
    """The snapshot's anchored vehicles drawn at their recorded states plus their
    offsets (a speed never below 0; one drawn beyond the road's ends has left the map
    and is dropped), and the rows sorted by x again. Across the road an anchored vehicle
    comes no nearer than :data:`BESIDE_GAP` to a body alongside it (:func:`_held_line`:
    it holds its line while its recording drifts toward the body; its offset across
    shrinks first by as much as the recording then moves back, so it follows the
    recording again from where it held, without a jump or an overshoot)."""
    sn, table, cs = core.snap, core.table, core.settings
    flags = table.flags
    if core.episodes.anchor_count[b] == 0:
        return
    shifted, kept = False, 0
    for k in range(sn.count[b]):
        r, x, y, speed = sn.r[b, k], sn.x[b, k], sn.y[b, k], sn.speed[b, k]
        h = entry(table.key, flags, table.slot, b, np.int64(r), np.bool_(False))
        if h >= 0 and flags[b, h] & ANCHORED and not flags[b, h] & SIMULATED:
            # the recorded state it is drawn from: its offset's rate never drives it
            # backwards, nor into what is ahead of where it is drawn (decay)
            off_y = table.off_y[b, h]
            y_was = table.rec_y[b, h] + off_y
            moved = y - table.rec_y[b, h]  # its recording, across the road
            if off_y * moved > 0.0:  # toward where it is drawn: the offset shrinks by that
                off_y -= math.copysign(min(abs(off_y), abs(moved)), off_y)
            table.rec_x[b, h], table.rec_y[b, h], table.rec_v[b, h] = x, y, speed
            x += table.off_x[b, h]
            # across, no nearer a body alongside than BESIDE_GAP (it holds its line)
            held = _held_line(b, core, r, x, y_was, y + off_y)
            table.off_y[b, h] = held - y
            y = held
            speed = max(speed + table.off_v[b, h], 0.0)
            shifted = True
            if not cs.limit_lo <= x <= cs.limit_hi:
                continue  # drawn beyond the road's end: it has left the map
        sn.r[b, kept], sn.x[b, kept], sn.y[b, kept], sn.speed[b, kept] = r, x, y, speed
        kept += 1
    sn.count[b] = kept
    if shifted:
        _sort(b, sn)


@kernel(inline=True)
def _sort(b, sn):
    """Insertion sort of the snapshot's rows by x (they come nearly sorted)."""
    r, x, y, speed = sn.r, sn.x, sn.y, sn.speed
    for k in range(1, sn.count[b]):
        rk, xk, yk, vk = r[b, k], x[b, k], y[b, k], speed[b, k]
        j = k
        while j > 0 and x[b, j - 1] > xk:
            r[b, j], x[b, j] = r[b, j - 1], x[b, j - 1]
            y[b, j], speed[b, j] = y[b, j - 1], speed[b, j - 1]
            j -= 1
        r[b, j], x[b, j], y[b, j], speed[b, j] = rk, xk, yk, vk


@kernel
def decay(b, core):
    """One step of every anchor's offset toward zero (module doc); the settled and the
    simulated again dropped from the list."""
    table, ep, dt = core.table, core.episodes, core.settings.dt
    flags = table.flags
    kept = 0
    for a in range(ep.anchor_count[b]):
        h = ep.anchors[b, a]
        if flags[b, h] & ANCHORED == 0 or flags[b, h] & SIMULATED:
            flags[b, h] &= ~ANCHORED
            continue
        x, v = _step(table.off_x[b, h], table.off_v[b, h], ACCEL, dt, -table.rec_v[b, h])
        v = _behind(b, core, h, v, dt)
        x = table.off_x[b, h] + v * dt
        y, vy = _step(table.off_y[b, h], table.off_vy[b, h], ACCEL_Y, dt, -math.inf)
        if _body_beside(b, core, h, table.rec_y[b, h] + y):
            # a body beside where it would move across: it holds its line
            vy = 0.0
            y = table.off_y[b, h]
        table.off_x[b, h], table.off_v[b, h] = x, v
        table.off_y[b, h], table.off_vy[b, h] = y, vy
        r = table.key[b, h]
        if max(abs(x), abs(v), abs(y), abs(vy)) < SETTLED and not _near_across(
            b, core, r, table.rec_x[b, h] + x, table.rec_y[b, h] + y, BESIDE_GAP + BESIDE_WATCH
        ):  # settled, and no body beside it whose side it keeps
            flags[b, h] &= ~ANCHORED
            continue
        ep.anchors[b, kept] = h
        kept += 1
    ep.anchor_count[b] = kept
    _extent(b, core)


@kernel(inline=True)
def _step(x, v, limit, dt, floor):
    """(offset, rate) one step of ``dt`` [s] later: a critically damped spring toward 0
    of natural frequency OMEGA, its acceleration within ``limit`` (semi-implicit), its
    rate no lower than ``floor`` (along the road: minus the recorded speed, so that the
    vehicle drawn ahead of a slower recording waits for it rather than backs up)."""
    a = min(max(-2.0 * OMEGA * v - OMEGA * OMEGA * x, -limit), limit)
    v = max(v + a * dt, floor)
    return x + v * dt, v


@kernel(inline=True)
def _nearer(x, xi, vi, li, ahead, ahead_v, behind, behind_v, behind_end):
    """The nearest ahead of and behind back ``x`` [m] so far (back, speed; and the one
    behind's front), with a vehicle at back ``xi`` moving at ``vi``, ``li`` long."""
    if x < xi < ahead:
        ahead, ahead_v = xi, vi
    if behind < xi < x:
        behind, behind_v, behind_end = xi, vi, xi + li
    return ahead, ahead_v, behind, behind_v, behind_end


@kernel(inline=True)
def _behind(b, core, h, v, dt):
    """Table entry ``h``'s offset rate [m/s] ``v`` for the next step: no slower than the
    nearest body or ghost behind it in its lane where that is within :data:`FOLLOW_GAP`
    and :data:`HEADWAY` of it (raised no faster than :data:`ACCEL` allows: a recording
    behind does not know of the offset and would run into it); no faster than lets the
    vehicle drawn stop behind the nearest body or ghost ahead of it (braking at
    :data:`FOLLOW_DECEL` to :data:`FOLLOW_GAP` behind it), lowered no faster than
    :data:`BRAKE` allows (a vehicle drawn does not stop at once). What is ahead wins:
    an anchored vehicle closes in on its recording only as the traffic allows."""
    table, bo, gh = core.table, core.bodies, core.ghosts
    r = table.key[b, h]
    length = core.rec.length[r]
    x = table.rec_x[b, h] + table.off_x[b, h]
    lane = lane_of(table.rec_y[b, h] + table.off_y[b, h])
    if lane == 0:
        return v
    # the nearest body or ghost ahead of it and behind it in its lane (bodies first)
    ahead, ahead_v = math.inf, 0.0
    behind, behind_v, behind_end = -math.inf, 0.0, -math.inf
    for i in range(bo.top[b]):
        if bo.valid[b, i] and bo.lane[b, i] == lane:
            ahead, ahead_v, behind, behind_v, behind_end = _nearer(
                x, bo.x[b, i], bo.speed[b, i], bo.length[b, i],
                ahead, ahead_v, behind, behind_v, behind_end,
            )  # fmt: skip
    for g in range(gh.count[b]):
        if gh.r[b, g] != r and gh.lane[b, g] == lane:
            ahead, ahead_v, behind, behind_v, behind_end = _nearer(
                x, gh.x[b, g], gh.speed[b, g], gh.length[b, g],
                ahead, ahead_v, behind, behind_v, behind_end,
            )  # fmt: skip
    # and the other anchored vehicles, where they are drawn: those outside the ghost
    # windows are in no ghost set (a row of them behind the windows, each closing in on
    # its recording, drew level and came into the rear ghost cell on top of one another)
    ep, flags = core.episodes, table.flags
    for a in range(ep.anchor_count[b]):
        ha = ep.anchors[b, a]
        if ha == h or flags[b, ha] & (ANCHORED | SIMULATED) != ANCHORED:
            continue
        if lane_of(table.rec_y[b, ha] + table.off_y[b, ha]) == lane:
            ahead, ahead_v, behind, behind_v, behind_end = _nearer(
                x, table.rec_x[b, ha] + table.off_x[b, ha],
                max(table.rec_v[b, ha] + table.off_v[b, ha], 0.0),
                core.rec.length[table.key[b, ha]], ahead, ahead_v, behind, behind_v, behind_end,
            )  # fmt: skip
    if math.isfinite(behind) and x - behind_end < FOLLOW_GAP + behind_v * HEADWAY:
        # what is behind it closes in: it goes no slower than that, as it speeds up
        v = max(v, min(behind_v - table.rec_v[b, h], table.off_v[b, h] + ACCEL * dt))
    if not math.isfinite(ahead):
        return v
    room = max(ahead - x - length - FOLLOW_GAP, 0.0)
    allowed = math.sqrt(ahead_v * ahead_v + 2.0 * FOLLOW_DECEL * room) - table.rec_v[b, h]
    if v <= allowed:
        return v
    return max(allowed, table.off_v[b, h] - BRAKE * dt, -table.rec_v[b, h])


@kernel(inline=True)
def _body_beside(b, core, h, y):
    """Whether table entry ``h``'s vehicle drawn at road-frame ``y`` [m] (its x where it
    is drawn now) would come within :data:`BESIDE_GAP` across of a body alongside it
    (:func:`_along`): an anchored
    vehicle moving across toward its recording's lane does so only where the lane is
    clear, as a lane change would."""
    table, bo, rec = core.table, core.bodies, core.rec
    r = table.key[b, h]
    x = table.rec_x[b, h] + table.off_x[b, h]
    length, width = rec.length[r], rec.width[r]
    for i in range(bo.top[b]):
        across = abs(bo.y[b, i] - y) < 0.5 * (width + bo.width[b, i]) + BESIDE_GAP
        if bo.valid[b, i] and across and _along(x, length, bo.x[b, i], bo.length[b, i]):
            return True
    return False


@kernel(inline=True)
def _extent(b, core):
    """``anchor_lo``, ``anchor_hi`` [m]: the smallest and largest offsets along the
    road (0 without anchors)."""
    table, ep = core.table, core.episodes
    lo, hi = 0.0, 0.0
    for a in range(ep.anchor_count[b]):
        off = table.off_x[b, ep.anchors[b, a]]
        lo, hi = min(lo, off), max(hi, off)
    ep.anchor_lo[b], ep.anchor_hi[b] = lo, hi
