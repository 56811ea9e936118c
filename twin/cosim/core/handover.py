"""The paper's hand-overs, compiled: the windows around the ego, the visible vehicles
that leave the visible window (step 5), the recorded vehicles that enter it and are
spawned where they fit (step 6), and the ghost set reloaded from the recording (step
7), for one episode of a batch (``docs/cosim.md`` gives the rules).

Every recorded vehicle an episode meets has an entry in its tid table (an
open-addressing hash by recording index ``r``): simulated now, a ghost after the last
reload, seen in the windows before, waiting for room to spawn.

Over 500 lines: steps 5 to 7 and the room, crowding and spawn tests they share. Issue
78 splits it (the windows and despawn, the spawn checks, entering and cut-ins, the lead
speeds of step 3); until that lands it stays one module rather than be split twice.
"""

import math

import numpy as np

from twin.core.i24 import N_LANES
from twin.core.jit import kernel
from twin.core.ramps import RAMP_LANE
from twin.core.ramps import lane_of_y as lane_of
from twin.cosim.core import anchor, relax
from twin.cosim.core import drivers as behaviour
from twin.cosim.core.layout import (
    GHOST,
    GHOSTS_FULL,
    HELD,
    SEEN,
    SIMULATED,
    SNAPSHOT_FULL,
    TABLE_FULL,
    WAITING,
    entry,
)
from twin.cosim.core.room import CROWD_AHEAD, CROWD_DECEL, spawn_room
from twin.data.recording import mean_accel, replay, window
from twin.physics.kernels import keep_sorted, place
from twin.traffic.kernels import state as traffic
from twin.traffic.kernels.lane_change import clear_target
from twin.traffic.kernels.longitudinal import FORESEEN
from twin.traffic.kernels.neighbours import N_GROUPS, footprint_lanes, lanes_occupied
from twin.traffic.kernels.steering import centre_y

LATERAL_MARGIN = 0.5  # [m] two bodies closer than their half widths plus this share a lane
MAX_SPEED = 60.0  # [m/s] spawn speeds above this are refused
#: [m] behind the rear ghost window, and behind the rearmost relaxing body, the recording
#: is read too (``Episodes.lookback``): a recorded vehicle there that crowds a body
#: becomes a relaxing body before it would run into it; a relaxing body stays while its
#: recording is there, and any body this far behind the rear ghost window. With
#: ``anchor``, the simulated region ends this far behind the rear ghost window: a body
#: further behind ends there (its recording anchored to it, :mod:`twin.cosim.core.anchor`)
REAR_MARGIN = 50.0
#: [m/s^2] it becomes a body behind the one it crowds only where it can stop behind it
#: braking this hard, ``spawn_clearance_at_rest`` apart (else it stays a ghost: a contact
#: with a ghost if they touch, counted)
YIELD_DECEL = 6.0
#: [s], [m] a recording moving across its lane (its centre this far off the lane's)
#: that is in the next lane this long from now is changing into it: where it would be
#: too close to a body there, it becomes a body (:func:`_yields`) and its change is the
#: traffic's, not a recorded cut-in in front of a body that does not know of it (a
#: body at 23 m/s ran into a recording cutting in at 2 m/s, preset E)
ANNOUNCE_S = 2.0
ANNOUNCE_Y = 0.3
#: [m/s^2] a recording appears ahead of a body only where the body can stop behind it,
#: the clearance at rest apart, braking this hard (an emergency stop)
APPEAR_DECEL = 8.0


# -- the tid table ---------------------------------------------------------------------------


@kernel(inline=True)
def flags_of(keys, flags, slots, b, r):
    """The flags of ``r`` (0 where absent)."""
    h = entry(keys, flags, slots, b, r, np.bool_(False))
    return flags[b, h] if h >= 0 else 0


# -- the windows -----------------------------------------------------------------------------


@kernel
def set_windows(b, core, ego_x):
    """The windows around back x ``ego_x`` [m] (rear ghost start, visible start and end,
    front ghost end), clipped to the road limits (:class:`twin.cosim.windows.Windows`)."""
    cs, ep = core.settings, core.episodes
    lo, hi = cs.limit_lo, cs.limit_hi
    ep.windows[b, 0] = min(max(ego_x - cs.w_visible - cs.w_ghost, lo), hi)
    ep.windows[b, 1] = min(max(ego_x - cs.w_visible, lo), hi)
    ep.windows[b, 2] = min(max(ego_x + cs.w_visible, lo), hi)
    ep.windows[b, 3] = min(max(ego_x + cs.w_visible + cs.w_ghost, lo), hi)


@kernel
def despawn_outside(b, core):
    """Step 5: the visible vehicles now outside the visible window (not the ego) are
    removed, or, where the settings relax them, relax (:mod:`twin.cosim.core.relax`)
    from the ghost cells on until they are back on their recordings; a relaxing vehicle
    more than :data:`REAR_MARGIN` behind the windows or ahead of them is removed unless
    its recording is in a ghost cell or behind it as far as the recording is read (it
    would appear there, away from the vehicle); with ``anchor`` it ends there wherever
    its recording is, its recording anchored to where it was
    (:mod:`twin.cosim.core.anchor`: drawn on from there, no jump); one whose recording is
    absent or off the lanes, or one off the road, is removed; back inside the visible
    window it is
    visible again, with strategic targets drawn as a spawn's (:func:`relax.end`).
    Returns how many were removed."""
    valid, x, ep, sl, cs = (
        core.bodies.valid,
        core.bodies.x,
        core.episodes,
        core.slots,
        core.settings,
    )
    g0, v0, v1, g1 = ep.windows[b, 0], ep.windows[b, 1], ep.windows[b, 2], ep.windows[b, 3]
    rear = g0 - REAR_MARGIN
    lookback = min(ep.lookback[b], rear)
    ego = ep.ego[b]
    gone = 0
    for i in range(core.bodies.top[b]):
        if not valid[b, i] or i == ego:
            continue
        if v0 <= x[b, i] <= v1:
            if sl.relaxing[b, i]:
                relax.end(b, core, i, ep.step[b] * cs.dt)
            if core.traffic.drivers.offset[b, i] != 0.0:
                relax.ease_offset(b, core, i)
            continue
        t = ep.t0[b] + ep.step[b] * cs.dt
        if cs.relax:
            relax.target(b, core, i, t)  # its recording now
        xr = sl.rec_x[b, i]
        recorded_in_cell = sl.rec_on[b, i] and lookback <= xr <= g1 and not v0 <= xr <= v1
        # without anchors, a relaxing body stays while its recording is in a ghost cell
        # (it would appear there, away from the vehicle), however far that is
        held = not cs.anchor and sl.relaxing[b, i] and recorded_in_cell
        stays = sl.rec_on[b, i] and ((rear <= x[b, i] <= g1) or held)
        if cs.relax and stays and cs.limit_lo <= x[b, i] <= cs.limit_hi:
            if not sl.relaxing[b, i]:
                relax.begin(b, core, i)
            continue
        if not cs.relax:  # the paper's hand-over: its ghost appears at once, where it is
            _drawn_now(b, core, core.slots.r[b, i])
        elif (
            cs.anchor
            and sl.rec_on[b, i]
            and anchor.anchor(b, core, i, sl.rec_x[b, i], sl.rec_y[b, i], sl.rec_speed[b, i])
        ):
            _drawn_now(b, core, core.slots.r[b, i])  # its ghost goes on where it is
        remove(b, core, i)
        gone += 1
    ep.despawned[b] += gone
    return gone


@kernel(inline=True)
def _drawn_now(b, core, r):
    """Recorded vehicle ``r`` is drawn this step (``TidTable.drawn``): a ghost now, or a
    body handed to its recording, whose ghost appears at once where it was."""
    table = core.table
    h = entry(table.key, table.flags, table.slot, b, r, np.bool_(True))
    if h >= 0:
        table.drawn[b, h] = core.episodes.step[b]


@kernel
def hand_back(b, core):
    """Step 6 for the relaxing vehicles, after the recording was read: those back on
    their recordings (:func:`twin.cosim.core.relax.settled`, on the targets step 5 read
    at this same time) are handed to them; they are ghosts at the reload. Returns how
    many."""
    bo, sl, ep = core.bodies, core.slots, core.episodes
    t = ep.t0[b] + ep.step[b] * core.settings.dt
    back = 0
    for i in range(bo.top[b]):
        if not (bo.valid[b, i] and sl.relaxing[b, i] and relax.settled(b, core, i)):
            continue
        if not _crowds_as_ghost(b, core, i, t):
            _drawn_now(b, core, core.slots.r[b, i])
            if core.settings.anchor:
                anchor.anchor(b, core, i, sl.rec_x[b, i], sl.rec_y[b, i], sl.rec_speed[b, i])
            remove(b, core, i)
            back += 1
    ep.handed_back[b] += back
    ep.despawned[b] += back
    return back


@kernel
def _crowds_as_ghost(b, core, i, t):
    """Whether relaxing slot ``i``, a ghost at unix ``t`` [s], would crowd a body ahead
    of it or cut in too close to one, and be taken back at once (:func:`_yields`): the
    ghost it would be, at its recording's position and speed (:func:`relax.target`
    read this step), not the body's. A body just spawned from a recording crawling
    close behind another brakes hard in its first step; judged at its own speed it
    crowded no more, was handed back, and its recording, which does not brake, was
    taken back at the reload: a vehicle spawned and handed back every step for
    seconds, never holding back, until its recording was too close to yield and drove
    into the body ahead as a ghost (physics, preset D by other drivers, episode 3)."""
    sl = core.slots
    x, y, speed = sl.rec_x[b, i], sl.rec_y[b, i], sl.rec_speed[b, i]
    length, width = core.bodies.length[b, i], core.bodies.width[b, i]
    return crowds(b, core, x, y, speed, length, width, i) or _cuts_in(
        b, core, sl.r[b, i], t, x, y, speed, length, width, i
    )


@kernel
def remove(b, core, i):
    """Free slot ``i``: its vehicle is simulated no more."""
    table, dr = core.table, core.traffic.drivers
    h = entry(table.key, table.flags, table.slot, b, core.slots.r[b, i], np.bool_(False))
    if h >= 0:
        table.flags[b, h] &= ~SIMULATED
        table.slot[b, h] = -1
    bo = core.bodies
    bo.valid[b, i] = False
    core.slots.relaxing[b, i] = False
    while bo.top[b] > 0 and not bo.valid[b, bo.top[b] - 1]:
        bo.top[b] -= 1
    core.slots.tgt_on[b, i] = False
    clear_target(dr.strategic, dr.strategic_from, dr.strategic_by, b, i)


# -- spawning --------------------------------------------------------------------------------


@kernel(inline=True)
def _clear_of(clearance, at_rest, decel, horizon, x, y, speed, length, width, bx, by, bv,
              blength, bwidth):  # fmt: skip
    """Whether a spawn at (x, y) is clear of one body (its x, y, speed, size): the room
    of :func:`spawn_room`, and what the rear one closes in ``horizon`` [s] more."""
    if abs(by - y) >= 0.5 * (bwidth + width) + LATERAL_MARGIN:
        return True
    if bx >= x:
        gap = bx - (x + length)
        closing, rear = speed * speed - bv * bv, speed
    else:
        gap = x - (bx + blength)
        closing, rear = bv * bv - speed * speed, bv
    return gap >= spawn_room(clearance, at_rest, decel, rear, closing) + horizon * max(
        rear - (bv if bx >= x else speed), 0.0
    )


@kernel
def fits(b, core, x, y, speed, length, width):
    """Whether a recorded vehicle at back x, y [m] can be spawned among the bodies: no
    body within :func:`spawn_room` ahead or behind among those it overlaps laterally;
    a body changing lanes holds its new lane too."""
    cs = core.settings
    return not _near(b, core, x, y, speed, length, width, cs.clearance, cs.clearance_at_rest,
                     cs.spawn_decel, 0.0, np.int64(-1), np.bool_(False))  # fmt: skip


@kernel
def lane_room(b, core, r, x, y, speed, length, width, c, rest, decel, waits):
    """Whether a recorded vehicle ``r`` at back x, y [m] and ``speed`` [m/s] has a spawn's
    room (:func:`spawn_room` at clearances ``c``, ``rest`` [m] and ``decel`` [m/s^2])
    in the lanes the traffic core will see it in once simulated (its lane and those its
    footprint reaches into, :func:`twin.traffic.kernels.neighbours.lanes_occupied`): to
    every body ahead of it or beside it along the road in those lanes (a body in the
    lanes it occupies) and to every ghost ahead (in its recording's lane and the one it
    reaches into, carried on a step from the last reload), and, for a spawn that
    ``waits`` for room where there is none, from every body behind and to any ghost
    beside it. A yield (:func:`_yields`, which cannot wait: the recording would run into
    the body it crowds) is judged while the ghost set is reloaded, so against the
    recordings ahead of its back instead (:func:`_recorded_room`): two recorded at one
    place, both crowding a body that lags, were both refused where a ghost beside one
    counted, and ran into it as ghosts (12 collisions in one test-family episode,
    against 1). :func:`fits` asks the same of the footprints; but a lane holds vehicles
    side by side in a recording made with a sub-lane model (a motorcycle beside a car, a
    car beside a truck's tail, SUMO's SL2015 days), and a vehicle spawned half a metre
    behind one beside it in its lane got the traffic manager's emergency braking,
    harder than its tyres hold: its speed a step on was off its spawn's by up to 2.4 %
    (11 such spawns in the test family's 304 kinematic episodes, every one so)."""
    cs, bo, gh = core.settings, core.bodies, core.ghosts
    mine = _lanes_of(y, width)
    for j in range(bo.top[b]):
        if not bo.valid[b, j] or not lanes_occupied(bo, core.traffic.drivers, b, j) & mine:
            continue
        bx, bv, blength = bo.x[b, j], max(bo.speed[b, j], 0.0), bo.length[b, j]
        if bx + blength > x:  # ahead, or beside it along the road
            gap, rear, closing = bx - (x + length), speed, speed * speed - bv * bv
        elif waits:
            gap, rear, closing = x - (bx + blength), bv, bv * bv - speed * speed
        else:
            continue
        if gap < spawn_room(c, rest, decel, rear, closing):
            return False
    if not waits:
        return True
    for g in range(gh.count[b]):
        if not _lane_bits(gh.lane[b, g], gh.reach[b, g]) & mine or gh.r[b, g] == r:
            continue
        gv = max(gh.speed[b, g], 0.0)
        gx = gh.x[b, g] + gv * cs.dt
        if gx + gh.length[b, g] <= x:
            continue  # behind: a ghost that crowds a body is made one behind it (_yields)
        if gx - (x + length) < spawn_room(c, rest, decel, speed, speed * speed - gv * gv):
            return False
    return True


@kernel
def _recorded_room(b, core, k, x, y, speed, length, width, rest, decel):
    """:func:`lane_room`'s ghost test for a yield of snapshot row ``k``: the recorded
    vehicles ahead of its back in the snapshot (the reload's own rows, sorted by x), in
    the ghost cells and not simulated, in the lanes it will occupy, each at least the
    room of a stop at ``decel`` from the clearance ``rest`` [m] ahead."""
    sn, rec, ep = core.snap, core.rec, core.episodes
    keys, flags, tslot = core.table.key, core.table.flags, core.table.slot
    mine = _lanes_of(y, width)
    v0, v1 = ep.windows[b, 1], ep.windows[b, 2]
    reach = x + length + rest + speed * speed / (2.0 * decel)  # nothing beyond matters
    for k2 in range(k + 1, sn.count[b]):
        gx = sn.x[b, k2]
        if gx > reach:
            break
        if gx < ep.windows[b, 0] or v0 <= gx <= v1:
            continue  # in the rear margin or the visible window: not drawn, or a body
        r2 = sn.r[b, k2]
        if flags_of(keys, flags, tslot, b, r2) & SIMULATED:
            continue  # a body: judged as one
        lane2 = lane_of(sn.y[b, k2])
        if not _lane_bits(lane2, _reach(sn.y[b, k2], rec.width[r2], lane2)) & mine:
            continue
        gv = max(sn.speed[b, k2], 0.0)
        if gx - (x + length) < spawn_room(rest, rest, decel, speed, speed * speed - gv * gv):
            return False
    return True


@kernel(inline=True)
def _recorded_behind_on(b, core, k, x, y, width, rest):
    """Whether a recorded vehicle drawn behind snapshot row ``k`` (at back x, y [m],
    ``width`` wide), in the ghost cells and not simulated, reaches within ``rest`` [m] of
    its back, their footprints overlapping across the road: made a body there, it would
    be touching a vehicle that does not know of it (an anchored vehicle drawn over the
    recording, or recordings that overlap: 6 of the 7 collisions left on the SUMO test
    family with anchors, 16 x 120 s per day, were a body made so, 0.06 to 4.6 m into
    the one behind). Every row behind is read (no vehicle's length is assumed): this
    is asked only of a recording that crowds a body, rarely."""
    sn, rec, ep = core.snap, core.rec, core.episodes
    keys, flags, tslot = core.table.key, core.table.flags, core.table.slot
    v0, v1 = ep.windows[b, 1], ep.windows[b, 2]
    for k2 in range(k - 1, -1, -1):
        gx = sn.x[b, k2]
        if gx < ep.windows[b, 0] or v0 <= gx <= v1:
            continue  # in the rear margin or the visible window: not drawn, or a body
        r2 = sn.r[b, k2]
        if abs(sn.y[b, k2] - y) >= 0.5 * (width + rec.width[r2]):
            continue
        if gx + rec.length[r2] + rest > x and not flags_of(keys, flags, tslot, b, r2) & SIMULATED:
            return True
    return False


@kernel(inline=True)
def _lanes_of(y, width):
    """The lanes (bits 1 << (-lane - 1)) a vehicle at ``y`` [m], ``width`` [m] wide,
    will occupy once simulated: its own and those its footprint reaches into."""
    lane = lane_of(y)
    return footprint_lanes(y, 0.5 * width) | _lane_bits(lane, np.int64(0))


@kernel(inline=True)
def _lane_bits(lane, reach):
    """Bits of ``lane`` and of ``reach`` (0: none) among lanes -1..-N_GROUPS."""
    bits = 0
    if -N_GROUPS <= lane <= -1:
        bits |= 1 << (-lane - 1)
    if -N_GROUPS <= reach <= -1:
        bits |= 1 << (-reach - 1)
    return bits


@kernel
def may_appear(b, core, x, y, speed, length, width):
    """Whether a recorded vehicle not drawn a step ago may appear as a ghost at back x,
    y [m] moving at ``speed`` [m/s]: no body ahead of it within a spawn's room (a
    recording cannot brake for it), no body's footprint within the clearance at rest
    of its own, and no body behind it that could not stop behind it braking at
    APPEAR_DECEL. A body close behind it may be otherwise: that body brakes for it (a
    ghost held back there would leave the queue it stands in undrawn, and the body
    would drive on into it); one that cannot stop would run into it (a recording that
    reappeared half a metre ahead of a body 4 m/s faster, on SUMO's on-ramp morning)."""
    cs = core.settings
    return not (
        _near(b, core, x, y, speed, length, width, cs.clearance, cs.clearance_at_rest,
              cs.spawn_decel, 0.0, np.int64(-1), np.bool_(True))
        # on a body's footprint, or where one behind could not stop (the clearance at
        # rest apart, which alone is the footprint test)
        or _near(b, core, x, y, speed, length, width, cs.clearance_at_rest,
                 cs.clearance_at_rest, APPEAR_DECEL, 0.0, np.int64(-1), np.bool_(False))
    )  # fmt: skip


@kernel
def crowds(b, core, x, y, speed, length, width, skip):
    """Whether a vehicle at back x, y [m] moving at ``speed`` [m/s] is closer than
    :func:`spawn_room` at :data:`CROWD_DECEL`, plus what it closes on it in
    :data:`CROWD_AHEAD`, to a body ahead of it (not slot ``skip``) among those it
    overlaps laterally, as :func:`fits` asks: a recording so close behind a simulated
    body would soon run into it."""
    cs = core.settings
    return _near(b, core, x, y, speed, length, width, cs.clearance, cs.clearance_at_rest,
                 CROWD_DECEL, CROWD_AHEAD, skip, np.bool_(True))  # fmt: skip


@kernel
def _near(b, core, x, y, speed, length, width, c, rest, decel, horizon, skip, ahead_only):
    """Whether a body (not slot ``skip``; only those ahead of back ``x`` where
    ``ahead_only``) is closer than :func:`spawn_room` at clearances ``c``, ``rest`` [m]
    and deceleration ``decel`` [m/s^2], plus what the rear one closes in ``horizon``
    [s], to a vehicle at back x, y [m] and ``speed`` [m/s], among those it overlaps
    laterally; a body changing lanes holds its new lane too."""
    bo = core.bodies
    for j in range(bo.top[b]):
        if not bo.valid[b, j] or j == skip or (ahead_only and bo.x[b, j] < x):
            continue
        if _body_near(b, core, j, x, y, speed, length, width, c, rest, decel, horizon):
            return True
    return False


@kernel
def _sort_bodies(b, core):
    """The bodies by back x for :func:`_crowds_sorted`: ``slots.by_back[b]`` kept sorted
    (:func:`twin.physics.kernels.keep_sorted`) and ``slots.by_back_stop[b, k]`` the
    nearest point where the bodies from the k-th on could stop braking at
    :data:`CROWD_DECEL`. Returns how many bodies."""
    bo, sl = core.bodies, core.slots
    m = keep_sorted(b, bo, sl.by_back, sl.by_back_listed, np.bool_(False))
    nearest = np.inf
    for k in range(m - 1, -1, -1):
        j = sl.by_back[b, k]
        v = max(bo.speed[b, j], 0.0)
        nearest = min(nearest, bo.x[b, j] + v * v / (2.0 * CROWD_DECEL))
        sl.by_back_stop[b, k] = nearest
    return m


@kernel
def _crowds_sorted(b, core, m, x, y, speed, length, width):
    """:func:`crowds` (no slot skipped) over the ``m`` bodies sorted by
    :func:`_sort_bodies`, from the first at or ahead of back ``x`` (a binary search) to
    the last that could be too close: a body crowded by a vehicle there is closer than
    the larger clearance if it is faster, else its stopping point is closer than the
    vehicle's plus that clearance."""
    cs, bx, order, stop = core.settings, core.bodies.x, core.slots.by_back, core.slots.by_back_stop
    lo, hi = 0, m
    while lo < hi:
        mid = (lo + hi) // 2
        if bx[b, order[b, mid]] < x:
            lo = mid + 1
        else:
            hi = mid
    near = x + length + max(cs.clearance, cs.clearance_at_rest) + speed * CROWD_AHEAD + 1.0
    # (a metre for rounding)
    own_stop = near + speed * speed / (2.0 * CROWD_DECEL)
    for k in range(lo, m):
        j = order[b, k]
        if bx[b, j] >= near and stop[b, k] >= own_stop:
            break  # neither close nor stopping short, nor any body ahead of it
        if _body_near(b, core, j, x, y, speed, length, width, cs.clearance,
                      cs.clearance_at_rest, CROWD_DECEL, CROWD_AHEAD):  # fmt: skip
            return True
    return False


@kernel(inline=True)
def _body_near(b, core, j, x, y, speed, length, width, c, rest, decel, horizon):
    """Whether body ``j`` is closer than :func:`spawn_room` to a vehicle at back x, y
    (:func:`_near`), in its lane or, changing lanes, in its new one or, from an on-ramp's
    acceleration lane, in the one it leaves (which its drivers still follow it in). Its
    width is what its footprint covers across the road, turned by its yaw: a car yawed
    0.29 rad in a lane change reaches 0.6 m further to the side than straight (a
    recording appeared there as a ghost on its tail, SUMO's on-ramp morning)."""
    bo, dr = core.bodies, core.traffic.drivers
    bv = max(bo.speed[b, j], 0.0)
    bx, blength = bo.x[b, j], bo.length[b, j]
    yaw = bo.yaw[b, j]
    bwidth = blength * abs(math.sin(yaw)) + bo.width[b, j] * abs(math.cos(yaw))
    if not _clear_of(c, rest, decel, horizon, x, y, speed, length, width, bx, bo.y[b, j], bv,
                     blength, bwidth):  # fmt: skip
        return True
    if dr.lane_from[b, j] == dr.lane[b, j]:
        return False
    if not _clear_of(c, rest, decel, horizon, x, y, speed, length, width, bx,
                     centre_y(dr.lane[b, j]), bv, blength, bwidth):  # fmt: skip
        return True
    return dr.lane_from[b, j] == RAMP_LANE and not _clear_of(
        c, rest, decel, horizon, x, y, speed, length, width, bx, centre_y(dr.lane_from[b, j]),
        bv, blength, bwidth,
    )  # fmt: skip


@kernel
def spawn(b, core, r, x, y, speed, desired_speed, controller):
    """Spawn recorded trajectory ``r`` into the first free slot at back x, y [m] moving
    at ``speed`` [m/s], with its driver (``desired_speed`` the ego's), driven by
    ``controller`` (a ``ctrl`` kind; -1: the driver, or the AV controller where the
    draw makes it an AV). Returns the slot, or -1 where every slot is taken."""
    bo, sl, ep, cs, rec = core.bodies, core.slots, core.episodes, core.settings, core.rec
    dr = core.traffic.drivers
    i = -1
    for k in range(bo.valid.shape[1]):
        if not bo.valid[b, k]:
            i = k
            break
    if i < 0:
        return -1
    bo.top[b] = max(bo.top[b], i + 1)
    seed = ep.seed[b]
    tid = rec.tid[r]
    bo.valid[b, i] = True
    bo.id[b, i] = ep.next_id[b]
    ep.next_id[b] += 1
    bo.x[b, i], bo.y[b, i], bo.yaw[b, i] = x, y, 0.0
    bo.speed[b, i], bo.yaw_rate[b, i], bo.drive_power[b, i] = speed, 0.0, 0.0
    params = core.params
    for c in range(params.shape[1]):
        _set_param(b, i, c, bo, params[r, c])
    place(b, i, bo, cs.profile)
    sl.r[b, i], sl.tid[b, i] = r, tid
    sl.just_spawned[b, i] = True
    sl.born[b, i] = ep.step[b]
    sl.spawn_speed[b, i] = speed
    sl.off_road[b, i] = False
    sl.av[b, i] = False
    sl.tgt_on[b, i] = False
    sl.relaxing[b, i] = False
    sl.rec_on[b, i] = False
    lane = lane_of(y)
    behaviour.init_driver(
        b, i, core, seed, tid, r, rec.vehicle_class[r], lane, ep.step[b] * cs.dt, speed
    )
    if controller >= 0:
        if controller != traffic.DRIVER:
            dr.ctrl[b, i] = controller
        if desired_speed > 0.0:
            sl.base_speed[b, i] = desired_speed
            dr.cf[b, i, 0] = desired_speed
    elif lane != RAMP_LANE and behaviour.is_av(seed, tid, cs.av_share):
        dr.ctrl[b, i] = cs.av_controller
        sl.av[b, i] = True
    if dr.ctrl[b, i] == traffic.DRIVER and cs.targets:
        behaviour.first_target(b, i, core, seed, x)
    if dr.ctrl[b, i] == traffic.DRIVER and lane == RAMP_LANE:
        # crossing into lane -4 in its recording, with room there (the room that makes a
        # ramp ghost a body, :func:`_cuts_in`, so that one made a body for want of it
        # does not merge at once): the merge goes on
        if behaviour.crossing(core, x + 0.5 * bo.length[b, i], y) and not _near(
            b, core, x, centre_y(np.int64(-N_LANES)), speed, bo.length[b, i], bo.width[b, i],
            cs.clearance, cs.clearance, YIELD_DECEL, 0.0, np.int64(i), np.bool_(False),
        ):  # fmt: skip
            behaviour.merging(b, i, core, seed, x, y)
        else:
            behaviour.merge_target(b, i, core, seed, x)
    table = core.table
    h = entry(table.key, table.flags, table.slot, b, r, np.bool_(True))
    if h >= 0:
        table.flags[b, h] = (table.flags[b, h] | SIMULATED) & ~(WAITING | HELD)
        table.slot[b, h] = i
    return i


@kernel(inline=True)
def _set_param(b, i, c, bo, value):
    """Physical parameter ``c`` (:data:`twin.physics.kernels.PARAMETERS` order) of slot
    ``i``."""
    if c == 0:
        bo.vehicle_class[b, i] = int(value)
    elif c == 1:
        bo.length[b, i] = value
    elif c == 2:
        bo.width[b, i] = value
    elif c == 3:
        bo.height[b, i] = value
    elif c == 4:
        bo.mass[b, i] = value
    elif c == 5:
        bo.eff_mass[b, i] = value
    elif c == 6:
        bo.max_power[b, i] = value
    elif c == 7:
        bo.drag_area[b, i] = value
    elif c == 8:
        bo.rolling[b, i] = value
    elif c == 9:
        bo.mu[b, i] = value
    elif c == 10:
        bo.driven_share[b, i] = value
    elif c == 11:
        bo.wheelbase[b, i] = value
    elif c == 12:
        bo.cg_height[b, i] = value
    else:
        bo.wheel_radius[b, i] = value


@kernel
def spawn_recorded(b, core, k, retry):
    """Step 6 for snapshot row ``k``: spawn it where it fits; a refusal is counted once
    per vehicle and, where ``retry``, the vehicle waits to be tried again each step.
    Returns whether it was spawned."""
    sn, ep, table, rec, cs = core.snap, core.episodes, core.table, core.rec, core.settings
    r = sn.r[b, k]
    x, y, speed = sn.x[b, k], sn.y[b, k], sn.speed[b, k]
    lane = lane_of(y)
    if not (RAMP_LANE <= lane <= -1) or speed > MAX_SPEED:
        ep.skipped_invalid[b] += 1
        return False
    h = entry(table.key, table.flags, table.slot, b, r, np.bool_(True))
    if h < 0:
        ep.overflow[b] |= TABLE_FULL
        return False
    slot = -1
    if fits(b, core, x, y, speed, rec.length[r], rec.width[r]) and lane_room(
        b, core, np.int64(r), x, y, speed, rec.length[r], rec.width[r], cs.clearance,
        cs.clearance_at_rest, cs.spawn_decel, np.bool_(True),
    ):  # fmt: skip
        slot = spawn(b, core, np.int64(r), x, y, speed, 0.0, np.int64(-1))
        if slot < 0:
            ep.skipped_full[b] += 1
    if slot >= 0:
        return True
    if not table.flags[b, h] & WAITING:
        ep.skipped_overlap[b] += 1
    if retry:
        table.flags[b, h] |= WAITING
    return False


# -- the recording around the ego ------------------------------------------------------------


@kernel
def snapshot(b, core, t):
    """The recorded vehicles in the windows' span at unix ``t`` [s], sorted by x, and
    (where vehicles relax) :data:`REAR_MARGIN` behind it and behind the rearmost
    relaxing body (``Episodes.lookback``, the span's rear end), and ahead of the front
    ghost window as far as :data:`REAR_MARGIN` beyond the frontmost relaxing body's
    front: a relaxing body near the windows' front end sees the recording ahead of it
    (drawn as ghosts, :func:`enter_and_reload`) instead of a recorded queue appearing
    in front of it."""
    sn, ep, bo = core.snap, core.episodes, core.bodies
    rear, front = ep.windows[b, 0], ep.windows[b, 3]
    if core.settings.relax:  # and behind the rearmost relaxing body, ahead of the frontmost
        rear -= REAR_MARGIN
        for i in range(bo.top[b]):
            if bo.valid[b, i] and core.slots.relaxing[b, i]:
                rear = min(rear, bo.x[b, i] - REAR_MARGIN)
                front = max(front, bo.x[b, i] + bo.length[b, i] + REAR_MARGIN)
        # and as far as anchored ghosts are from their recordings (module anchor)
        rear -= max(ep.anchor_hi[b], 0.0)
        front += max(-ep.anchor_lo[b], 0.0)
    rear = max(rear, core.settings.limit_lo)  # no body is spawned beyond the map's end
    front = max(min(front, core.settings.limit_hi), ep.windows[b, 3])
    ep.lookback[b] = rear
    count = window(core.rec, t, rear, front, sn.r[b], sn.x[b], sn.y[b], sn.speed[b])
    if count < 0:
        ep.overflow[b] |= SNAPSHOT_FULL
        count = sn.r.shape[1]
    sn.count[b] = count


@kernel(inline=True)
def _bound(values, count, x, right):
    """The first index of sorted ``values[:count]`` above ``x`` (at or above where not
    ``right``)."""
    lo, hi = 0, count
    while lo < hi:
        mid = (lo + hi) // 2
        if values[mid] < x or (right and values[mid] == x):
            lo = mid + 1
        else:
            hi = mid
    return lo


@kernel
def enter_and_reload(b, core):
    """Steps 6 and 7 on the episode's snapshot: the ghosts now inside the visible window,
    the tracks first seen inside it and the vehicles waiting for room are spawned (at
    the reset, step 0: the visible set, the ego's own track left out), then the ghost
    set is reloaded, the recorded vehicles there or behind it that crowd a body ahead
    made relaxing bodies (:func:`_yields`). A recorded vehicle not drawn a step ago (a
    ghost at the last reload, or a body handed to it since: ``table.drawn``) appears as a
    ghost only where it would not be on a body nor run into one, nor have one that
    could not stop run into it there or in the lane it goes into (:func:`may_appear`,
    :func:`_cannot_stop_where_it_goes`): one
    that would, most often one that waited for room in the visible window while the
    simulated traffic took its place, is held back and waits as a spawn does
    (``Episodes.held`` counts each time a vehicle is held back). Returns how many were
    spawned into the visible window."""
    sn, ep, gh, rec = core.snap, core.episodes, core.ghosts, core.rec
    step = ep.step[b]
    initial = step == 0  # a value, not a literal argument: one compilation
    t = ep.t0[b] + step * core.settings.dt
    keys, flags, tslot = core.table.key, core.table.flags, core.table.slot
    sr, sx, sy, sspeed = sn.r, sn.x, sn.y, sn.speed
    n = sn.count[b]
    a = _bound(sx[b], n, ep.windows[b, 0], np.bool_(False))  # before a: the rear margin
    # with anchors, bodies are simulated as far as REAR_MARGIN behind the rear ghost
    # window: no yield behind that (a body there ends, its recording anchored to it)
    m0 = 0
    if core.settings.anchor:
        m0 = _bound(sx[b], n, ep.windows[b, 0] - REAR_MARGIN, np.bool_(False))
    v0 = _bound(sx[b], n, ep.windows[b, 1], np.bool_(False))
    v1 = _bound(sx[b], n, ep.windows[b, 2], np.bool_(True))
    g1 = _bound(sx[b], n, ep.windows[b, 3], np.bool_(True))  # up to the windows' end
    d = n  # to the front ghost window's end, or beyond it ahead of a relaxing body
    spawned = 0
    for k in range(v0, v1):
        r = sr[b, k]
        if initial:
            if r == ep.ego_r[b]:
                continue
            enter, retry = True, True
        else:
            f = flags_of(keys, flags, tslot, b, r)
            simulated = f & SIMULATED != 0
            first_seen = f & (SEEN | SIMULATED) == 0
            enter = f & GHOST != 0 or first_seen or (f & (WAITING | HELD) != 0 and not simulated)
            # a track beginning inside the window that finds a body in its way is not
            # tried again: in real data it is most often the next fragment of that vehicle
            retry = not first_seen
        if enter and spawn_recorded(b, core, k, retry):
            spawned += 1
    # 7. the ghost set: the recorded vehicles of the ghost windows not simulated
    gr, glane, gx, gy, gspeed, glength = gh.r, gh.lane, gh.x, gh.y, gh.speed, gh.length
    for g in range(gh.count[b]):
        h = entry(keys, flags, tslot, b, np.int64(gr[b, g]), np.bool_(False))
        if h >= 0:
            flags[b, h] &= ~GHOST
    overflow = False
    for k in range(a, n):
        h = entry(keys, flags, tslot, b, np.int64(sr[b, k]), np.bool_(True))
        if h >= 0:
            flags[b, h] |= SEEN
        else:
            overflow = True
    count = 0
    capacity = gr.shape[1]
    relaxing, m = core.settings.relax, 0
    if relaxing:  # the bodies by back x, for the crowding test
        m = _sort_bodies(b, core)
    for k in range(d):
        r = sr[b, k]
        h = entry(keys, flags, tslot, b, r, np.bool_(False))
        f = flags[b, h] if h >= 0 else 0
        if v0 <= k < v1:
            continue
        lane = lane_of(sy[b, k])
        if lane == 0 or f & SIMULATED:
            continue
        drawn = h >= 0 and core.table.drawn[b, h] >= step - 1
        if relaxing and m0 <= k < g1 and _yields(b, core, k, t, m, drawn):
            # simulated now, relaxing behind the body it would run into
            m = _sort_bodies(b, core)
            continue
        if k < a:
            continue  # in the rear margin, not a ghost
        length, width = rec.length[r], rec.width[r]
        x, y, speed = sx[b, k], sy[b, k], sspeed[b, k]
        if not drawn and (
            not may_appear(b, core, x, y, speed, length, width)
            or _cannot_stop_where_it_goes(b, core, r, t, x, y, speed, length, width)
        ):
            # not drawn a step ago: appearing now, it would appear on a body, run into
            # one or be run into; it waits for room as a spawn does (tried as a spawn
            # too, back in the visible window)
            if h >= 0 and not f & HELD:
                ep.held[b] += 1
                flags[b, h] |= HELD
            continue
        if count == capacity:
            ep.overflow[b] |= GHOSTS_FULL
            break
        gr[b, count], glane[b, count] = r, lane
        gx[b, count], gy[b, count] = sx[b, k], sy[b, k]
        gspeed[b, count], glength[b, count] = sspeed[b, k], length
        # what its recording does next, for a lane change in front of it to foresee
        gh.accel[b, count] = mean_accel(rec, r, t, FORESEEN)
        gh.reach[b, count] = _reach(sy[b, k], rec.width[r], lane)
        h = entry(keys, flags, tslot, b, r, np.bool_(True))
        if h >= 0:
            flags[b, h] = (flags[b, h] | GHOST) & ~HELD
            core.table.drawn[b, h] = step
        count += 1
    gh.count[b] = count
    if overflow:
        ep.overflow[b] |= TABLE_FULL
    return spawned


@kernel(inline=True)
def _reach(y, width, lane):
    """The lane other than ``lane`` a recorded footprint centred at ``y`` [m] and
    ``width`` [m] wide reaches into as a body's would make it occupy it (0: none)."""
    bits = footprint_lanes(y, 0.5 * width)
    for grp in range(N_GROUPS):
        other = -grp - 1
        if bits & (1 << grp) and other != lane:
            return other
    return 0


@kernel
def _yields(b, core, k, t, m, drawn):
    """Whether snapshot row ``k``, a recorded vehicle in a ghost cell at unix ``t`` [s],
    crowds a body ahead of it (:func:`crowds`: a simulated vehicle that lags its own
    recording, which the recording behind it does not know of) and so becomes a
    simulated vehicle there, relaxing (:mod:`twin.cosim.core.relax`): spawned at its
    recorded state where it can stop behind every body ahead of it braking at
    :data:`YIELD_DECEL` and is not on a body's footprint,
    it follows the body ahead and is handed back to its recording once on it with room
    ahead. Counted in ``Episodes.yielded``. ``m``: the bodies in ``slots.by_back[b]``.

    A recorded vehicle on an on-ramp's acceleration lane (lane -5) becomes one too where,
    in lane -4 beside it, it would be that close to a body: its merge is then the
    traffic core's (gap acceptance, lane -4 making room), not a recorded cut-in in front
    of a body that does not know of it; it is handed back once merged and on its
    recording (:func:`twin.cosim.core.relax.settled`). So does one changing into the
    next through lane (:func:`_changing_into`) where it would be that close to a body
    there: its change is the traffic's too.

    One not ``drawn`` a step ago (appearing now) is not made a body where a body behind
    it could not stop for it, in its lane or the one it goes into
    (:func:`_cannot_stop_for`): it is held back, as it would
    be as a ghost (a ramp recording whose track resumed after a gap, crossing into lane
    -4 half a metre ahead of a body 5.6 m/s faster, was made a body there and run into,
    SUMO's on-ramp morning)."""
    sn, rec = core.snap, core.rec
    r = sn.r[b, k]
    x, y, speed = sn.x[b, k], sn.y[b, k], sn.speed[b, k]
    length, width = rec.length[r], rec.width[r]
    if speed > MAX_SPEED:
        return False
    cs = core.settings
    crowds = _crowds_sorted(b, core, m, x, y, speed, length, width)
    if not crowds:
        crowds = _cuts_in(b, core, r, t, x, y, speed, length, width, np.int64(-1))
    if not crowds:
        return False
    # too close to stop behind a body ahead of it: it stays a ghost (a contact with a
    # ghost); the room is that of a stop at a harder braking than the crowding test's,
    # to the clearance at rest, so that a vehicle crowding a body is still far enough
    # back to yield (at the whole clearance at any speed, a crawling recording crowds a
    # standing body only once already too close to it; so did one drawn at the whole
    # clearance behind a body as fast as it, which then sped up: too close from its
    # first step of crowding, it stayed a ghost and ran into the body, SUMO's on-ramp
    # morning). A body behind it is no reason to stay a ghost (it did not see the ghost
    # either: a ramp recording already over the line beside a body closing fast on it
    # stayed a ghost and was run into, preset E), unless their footprints are within
    # the clearance at rest: a body is not spawned onto another.
    if _near(b, core, x, y, speed, length, width, cs.clearance_at_rest, cs.clearance_at_rest,
             YIELD_DECEL, 0.0, np.int64(-1), np.bool_(True)) or _near(
        b, core, x, y, speed, length, width, cs.clearance_at_rest, cs.clearance_at_rest,
        math.inf, 0.0, np.int64(-1), np.bool_(False),
    ) or _recorded_behind_on(b, core, k, x, y, width, cs.clearance_at_rest):  # fmt: skip
        return False
    # nor where, in its lanes as the traffic core sees them, it could not stop so behind
    # a body or recorded vehicle ahead (a recording beside another in one lane,
    # :func:`lane_room`): its first command would be an emergency stop, its spawn inexact
    rest = cs.clearance_at_rest
    if not lane_room(b, core, np.int64(r), x, y, speed, length, width, rest, rest,
                     YIELD_DECEL, np.bool_(False)) or not _recorded_room(
        b, core, k, x, y, speed, length, width, rest, YIELD_DECEL
    ):  # fmt: skip
        return False
    if not drawn and (
        _cannot_stop_for(b, core, x, y, speed, length, width)
        or _cannot_stop_where_it_goes(b, core, r, t, x, y, speed, length, width)
    ):
        return False
    slot = spawn(b, core, np.int64(r), x, y, speed, 0.0, np.int64(-1))
    if slot < 0:
        core.episodes.skipped_full[b] += 1
        return False
    relax.begin(b, core, slot)
    relax.target(b, core, slot, t)
    core.episodes.yielded[b] += 1
    return True


@kernel(inline=True)
def _cannot_stop_for(b, core, x, y, speed, length, width):
    """Whether a body behind a recording appearing at back x, y [m] and ``speed`` [m/s]
    could not stop for it braking at APPEAR_DECEL, the clearance at rest apart
    (:func:`may_appear`'s test for a body behind; pass the centre of the lane it goes
    into as ``y`` to judge it there). Bodies ahead of it are not this test's: it could
    brake for them once a body."""
    rest = core.settings.clearance_at_rest
    bo = core.bodies
    for j in range(bo.top[b]):
        if (
            bo.valid[b, j]
            and bo.x[b, j] < x
            and _body_near(b, core, j, x, y, speed, length, width, rest, rest, APPEAR_DECEL, 0.0)
        ):
            return True
    return False


@kernel(inline=True)
def _cannot_stop_where_it_goes(b, core, r, t, x, y, speed, length, width):
    """:func:`_cannot_stop_for` in the lane recording ``r`` at ``y`` [m] at unix ``t``
    [s] goes into (:func:`_going_into`); False where it goes into none."""
    into = _going_into(core, r, t, y)
    return into != 0 and _cannot_stop_for(b, core, x, centre_y(into), speed, length, width)


@kernel
def _cuts_in(b, core, r, t, x, y, speed, length, width, skip):
    """Whether recording ``r`` at back x, y [m] and ``speed`` [m/s] at unix ``t`` [s],
    on an on-ramp's acceleration lane or changing into the next through lane
    (:func:`_changing_into`), would be too close to a body (not slot ``skip``) in the
    lane it goes to, were it there now: the room at YIELD_DECEL with the whole
    clearance at any speed."""
    into = _going_into(core, r, t, y)
    if into == 0:
        return False
    cs = core.settings
    return _near(b, core, x, centre_y(into), speed, length, width, cs.clearance,
                 cs.clearance, YIELD_DECEL, 0.0, skip, np.bool_(False))  # fmt: skip


@kernel(inline=True)
def _going_into(core, r, t, y):
    """The lane recording ``r`` at ``y`` [m] at unix ``t`` [s] goes into: lane -4 from an
    on-ramp's acceleration lane, else the next through lane it is changing into
    (:func:`_changing_into`); 0 where none."""
    lane = lane_of(y)
    return np.int64(-N_LANES) if lane == RAMP_LANE else _changing_into(core, r, t, y, lane)


@kernel(inline=True)
def _changing_into(core, r, t, y, lane):
    """The through lane recording ``r``, at ``y`` [m] in ``lane`` at unix ``t`` [s] and
    moving across it (ANNOUNCE_Y off its centre), is in ANNOUNCE_S from now where that
    is the next lane over; 0 otherwise."""
    if not -N_LANES <= lane <= -1 or abs(y - centre_y(lane)) < ANNOUNCE_Y:
        return np.int64(0)
    present, _, y_later, _ = replay(core.rec, np.int64(r), t + ANNOUNCE_S)
    later = lane_of(y_later) if present else 0
    if -N_LANES <= later <= -1 and abs(later - lane) == 1:
        return np.int64(later)
    return np.int64(0)


@kernel
def lead_speeds(b, core):
    """Step 3: every vehicle wants its own desired speed, but the lead visible vehicle
    of each lane ahead of the ego (relaxing vehicles are not visible), which takes the
    speed of the ghost ahead of it (its own if none; the larger of the two where the
    lead chases its ghost), through the optional first-order lag (the paper's rule;
    ``docs/cosim.md``), and a driver on an on-ramp's acceleration lane, who wants the
    ramp's speed where the calibration knows it (:func:`drivers.ramp_speed`)."""
    bo, sl, ep, gh, cs = core.bodies, core.slots, core.episodes, core.ghosts, core.settings
    dr = core.traffic.drivers
    valid, x, ids, lanes = bo.valid, bo.x, bo.id, dr.lane
    params, base = dr.cf, sl.base_speed
    glane, gx, gspeed = gh.lane, gh.x, gh.speed
    ego = ep.ego[b]
    ego_x = x[b, ego]
    leads = ep.leads
    for k in range(N_LANES):
        leads[b, k] = -1
    for i in range(bo.top[b]):
        if not valid[b, i]:
            continue
        params[b, i, 0] = base[b, i]
        # on an on-ramp's lane a driver wants the ramp's speed, where the calibration
        # knows it, and has the lane's end ahead, not a ghost
        if lanes[b, i] < -N_LANES:
            if dr.ctrl[b, i] == traffic.DRIVER:
                ramp = behaviour.ramp_speed(b, i, core, ep.seed[b])
                if not math.isnan(ramp):
                    params[b, i, 0] = ramp
            continue
        if i == ego or x[b, i] <= ego_x or sl.relaxing[b, i]:
            continue
        k = -lanes[b, i] - 1
        lead = leads[b, k]
        if lead < 0 or x[b, i] > x[b, lead] or (x[b, i] == x[b, lead] and ids[b, i] < ids[b, lead]):
            leads[b, k] = i
    for k in range(N_LANES):
        lead = leads[b, k]
        if lead < 0:
            ep.lead_speed[b, k] = math.nan
            continue
        lane = -k - 1
        target = base[b, lead]
        best = -1
        for g in range(gh.count[b]):
            ahead = glane[b, g] == lane and gx[b, g] > x[b, lead]
            if ahead and (best < 0 or gx[b, g] < gx[b, best]):
                best = g
        if best >= 0:
            target = gspeed[b, best]
        if cs.lead_chases_ghost:
            target = max(target, base[b, lead])
        previous = ep.lead_speed[b, k]
        if cs.ghost_smoothing > 0.0 and math.isfinite(previous):
            target = previous + min(1.0, cs.dt / cs.ghost_smoothing) * (target - previous)
        ep.lead_speed[b, k] = target
        params[b, lead, 0] = target
