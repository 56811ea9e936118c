"""Relaxing vehicles: the ghost-cell boundary without a seam, compiled, for one episode
of a batch (``docs/cosim.md``, "Relaxing vehicles").

In the paper a visible vehicle that leaves the visible window becomes its recording
again at once, wherever the recording is: simulated vehicles drift from their
recordings while they are in the window (a few metres to tens of metres), so the
vehicle jumped. Here it stays a simulated body in the ghost cell, **relaxing**, and
closes the distance to its recorded trajectory within physical limits:

* its acceleration is a critically damped tracking law toward its recording (the
  recording's own acceleration plus a correction of natural frequency :data:`OMEGA`),
  never more than its car following allows behind the vehicle or ghost ahead, within
  [:data:`ACCEL_LOW`, :data:`ACCEL_HIGH`]; braking harder is left to it where its car
  following needs it, behind a body or a ghost (a ghost is drawn: running into one is
  a crash a user sees); its speed never goes below zero (the world's brakes hold it);
  ahead of its recording it slows for it no further than :data:`EASE_SHARE` of the
  recording's speed, nor below the speed of the ghost just ahead of it in its lane less
  a tenth of the recording's (:func:`_eased_speed`), and where its car following has
  braked it below that (behind a queue it has since left) it speeds up to it again, by
  1 m/s^2 per m/s short (the tracking law's speed gain), within the limits above;
* across the road it keeps its recording's place in its lane, the traffic core's
  centre line aside (:func:`path_offset`), clear of a vehicle alongside;
* it changes lanes only toward its recording's lane where the HOV rule allows it,
  asked of the traffic manager, which starts the change when the gap is safe (no
  discretionary change, no strategic target but an on-ramp's merge, which it keeps;
  such a change is not counted among the visible traffic's lane changes or merges);
* it is handed to its recording (a ghost again) once it is within
  :data:`HAND_BACK_X` and :data:`HAND_BACK_SPEED` of it, in its lane and within
  :data:`HAND_BACK_Y` across, with the recording in a ghost cell, and its speed a step
  ago (the last one drawn of it) within :data:`HAND_BACK_SPEED` of its recording's now
  too: the step it becomes a ghost it moves by at most that much, and its speed
  changes by at most that much (not that plus the step's own change of speed); and
  only where its recording, the ghost it becomes, would not crowd a body ahead
  (:func:`twin.cosim.core.handover.hand_back`);
* without ``anchor`` it is removed once it is outside the windows, unless its
  recording is in a ghost cell (it would appear there, away from the vehicle); with
  ``anchor`` (the default) it ends where it leaves the simulated region (the windows and
  :data:`twin.cosim.core.handover.REAR_MARGIN` behind them) wherever its recording is,
  its recording drawn from then on where it was and closing in on the recording
  (:mod:`twin.cosim.core.anchor`); it is removed once its recording ends or leaves the
  lanes, and when it leaves the road; a vehicle whose recording is absent when it
  leaves the visible window is removed then, as in the paper;
* back inside the visible window it is a visible vehicle again: its driver decides
  (its next lane-change decision at once) and draws its strategic targets from where
  it is, as a vehicle spawned there does
  (:func:`end`), and goes back to its lane's centre as far as nothing alongside is in
  the way (:func:`ease_offset`).

A recorded vehicle in a ghost cell, or behind the rear one (as far as 50 m behind the
rearmost relaxing vehicle; with ``anchor``, as far as the simulated region reaches),
that crowds a body ahead of it becomes a relaxing vehicle too, spawned
at its recorded state (:func:`twin.cosim.core.handover.enter_and_reload`): the lag of a
relaxing vehicle travels upstream, as a queue does, instead of the recording driving
through it.

How far a relaxing vehicle strays from its recorded track, its acceleration and its
slowest speed are measured in every run (``twin.metrics.handover``).
"""

import math

from twin.core.i24 import LANE_WIDTH, N_LANES
from twin.core.jit import kernel
from twin.core.ramps import lane_of_y as lane_of
from twin.cosim.core import drivers as behaviour
from twin.cosim.core.room import (
    CROWD_AHEAD,
    CROWD_DECEL,
    follows_what_is_ahead,
    spawn_room,
    stopping_decel,
)
from twin.data.recording import replay
from twin.traffic.kernels import state as traffic
from twin.traffic.kernels.lane_change import LEFT, RIGHT, clear_target, hov_allows
from twin.traffic.kernels.neighbours import around
from twin.traffic.kernels.steering import centre_y

OMEGA = 0.5  # [1/s] natural frequency of the tracking law (critically damped)
ACCEL_LOW, ACCEL_HIGH = -4.0, 2.0  # [m/s^2] a relaxing vehicle's command, emergencies aside
HAND_BACK_X = 0.3  # [m] along its recording
HAND_BACK_SPEED = 0.3  # [m/s]
HAND_BACK_Y = 0.5  # [m] across
FREE_SPEED = 5.0  # [m/s] a relaxing driver's desired speed lies this far above its target's
#: a relaxing vehicle ahead of its recording eases off to let it catch up, to no less than
#: this share of its recording's speed: a driver lets the traffic behind close in, it does
#: not stop in a live lane (on SUMO's on-ramp morning one ran 160 m ahead of a recording
#: slowing in lane -3, braked to a stand at the window's front to wait for it and stopped
#: the visible traffic behind it)
EASE_SHARE = 0.9
BESIDE_GAP = 0.5  # [m] across: it keeps its recording's place in its lane no nearer a vehicle
BESIDE_AHEAD = 2.0  # [m] alongside it: overlapping it along the road, this far apart,
IN_LANE = 0.25  # [m] its footprint stays this far inside its lane's lines
BESIDE_HORIZON = 4.0  # [s] or as far as the one behind closes on the other in this time


@kernel
def begin(b, core, i):
    """Slot ``i`` leaves the visible window into a ghost cell (its :func:`target` read
    this step): it relaxes toward its recording from now on."""
    sl, dr = core.slots, core.traffic.drivers
    sl.relaxing[b, i] = True
    dr.next_decision[b, i] = math.inf  # no discretionary change while it relaxes
    if dr.lane[b, i] >= -N_LANES:  # on an on-ramp's lane it must still merge, urgently
        clear_target(dr.strategic, dr.strategic_from, dr.strategic_by, b, i)
    sl.tgt_on[b, i] = False


@kernel
def end(b, core, i, time):
    """Slot ``i`` is back inside the visible window at clock ``time`` [s]: its driver
    decides again (its next lane-change decision at once) and draws its strategic
    targets from where it is, as a spawn there does
    (:func:`twin.cosim.core.drivers.first_target`; its draws start again, so a driver
    that was visible before reads the same draws for the bins ahead of it).

    :func:`begin` cleared them. A recorded vehicle made a body in a ghost cell (a yield,
    :func:`twin.cosim.core.handover._yields`) enters the visible window relaxing where
    before it spawned from its ghost: in stop-and-go most vehicles entering at the rear
    do so, and without targets they left the recording's lane-change flows undriven
    (SUMO development day 3, 12 x 120 s calibrated: 178 lane changes against the
    recording's 297, 201 with the targets; twin data sumo --family). Its path offset
    goes back to its lane's centre as far as that is clear (:func:`ease_offset`)."""
    core.slots.relaxing[b, i] = False
    drivers = core.traffic.drivers
    drivers.next_decision[b, i] = time
    drivers.requested[b, i] = 0
    if drivers.ctrl[b, i] == traffic.DRIVER and core.settings.targets:
        behaviour.first_target(b, i, core, core.episodes.seed[b], core.bodies.x[b, i])


@kernel
def target(b, core, i, t):
    """Slot ``i``'s recording at unix ``t`` [s] (``rec_on`` where it is recorded then and
    on the lanes; its acceleration over the next step), and the lane change toward its
    lane asked where the lanes differ and the HOV rule allows it."""
    sl, dr, ts = core.slots, core.traffic.drivers, core.traffic.settings
    present, x, y, speed = replay(core.rec, sl.r[b, i], t)
    lane = lane_of(y) if present else 0
    sl.rec_on[b, i] = present and lane != 0
    sl.rec_x[b, i], sl.rec_y[b, i], sl.rec_speed[b, i] = x, y, speed
    dt = core.settings.dt
    later, _, _, speed_later = replay(core.rec, sl.r[b, i], t + dt)
    sl.rec_accel[b, i] = (speed_later - speed) / dt if later else 0.0
    ask = 0
    own = dr.lane[b, i]
    if sl.rec_on[b, i] and dr.lane_from[b, i] == own and lane != own:
        step = LEFT if lane > own else RIGHT
        if hov_allows(dr.hov_eligible[b, i], own, own + step, core.bodies.x[b, i], ts.hov_openings):
            ask = step
    dr.requested[b, i] = ask
    dr.offset[b, i] = path_offset(b, core, i)


@kernel
def path_offset(b, core, i):
    """[m] how far from its lane's centre relaxing slot ``i`` (its :func:`target` read
    this step) keeps across the road while it is not changing lanes (else 0, the
    centre): where its recording is, as far as its footprint stays :data:`IN_LANE`
    inside the lane's lines (a recording in another lane: that side of its own, from
    where the change it asks for toward it begins), but no nearer
    than :data:`BESIDE_GAP` across to a body or ghost alongside it on that side, or soon
    to be (:func:`_alongside`; it moves no further toward one, nor is pushed away from
    one it is already nearer).

    The traffic core keeps a body on its lane's centre; a recording of a sub-lane driver
    (SUMO's SL2015) drives up to 1.6 m off it, with another passing it inside the lane.
    A vehicle made a body at such a recorded place (a yield) steered back to the centre
    into the recording passing beside it (SUMO test family, day 1017 episode 15: a crash
    at 76.4 s, 1.4 s after the yield), and a relaxing vehicle on the centre was never
    within :data:`HAND_BACK_Y` of such a recording, so never handed back to it. Moving
    across toward a vehicle ahead in the next lane (its footprint now reaching into that
    lane, where the traffic core's car following, lane by lane, does not see it), a
    relaxing body ran into it from behind (day 1005 episode 1), hence the horizon; and
    straddling a line, a body is seen by the traffic core in one lane only (a motorcycle
    made a body in lane -4 beside one that straddled from lane -3 ran into it, day 1005
    episode 1), hence the footprint inside its lane. A motorcycle made a body 1.8 m off
    its lane's centre, its recording crossing into the next lane, steered back to the
    centre (0, as where the recording was in another lane) into a recording behind it
    (day 1005 episode 10)."""
    bo, sl, dr = core.bodies, core.slots, core.traffic.drivers
    own = dr.lane[b, i]
    if not sl.rec_on[b, i] or dr.lane_from[b, i] != own or not -N_LANES <= own <= -1:
        return 0.0
    centre = centre_y(own)
    inside = max(0.5 * LANE_WIDTH - 0.5 * bo.width[b, i] - IN_LANE, 0.0)
    want = min(max(sl.rec_y[b, i], centre - inside), centre + inside)
    return _clear_across(b, core, i, own, want) - centre


@kernel
def ease_offset(b, core, i):
    """Visible slot ``i``'s path offset (``Drivers.offset``, kept from when it relaxed,
    :func:`end`) back toward its lane's centre, as the visible traffic drives, as far as
    it is clear across of what is alongside it (:func:`_clear_across`); 0 once it
    changes lanes. A body made of a sub-lane driver's recording 1 m off its lane's
    centre, visible again, steered back to the centre at once into a recorded bus
    passing beside it inside the lane (SUMO test family, day 1013 episode 0)."""
    dr = core.traffic.drivers
    own = dr.lane[b, i]
    if dr.lane_from[b, i] != own or not -N_LANES <= own <= -1:
        dr.offset[b, i] = 0.0
        return
    centre = centre_y(own)
    dr.offset[b, i] = _clear_across(b, core, i, own, centre) - centre


@kernel(inline=True)
def _clear_across(b, core, i, own, want):
    """[m] where slot ``i`` in lane ``own`` moves across the road, asking for ``want``:
    no nearer than :data:`BESIDE_GAP` across to a body or ghost alongside it on that
    side, or soon to be (:func:`_alongside`; :func:`short_of`)."""
    bo, sl, gh = core.bodies, core.slots, core.ghosts
    x, length, v, half = bo.x[b, i], bo.length[b, i], bo.speed[b, i], 0.5 * bo.width[b, i]
    y = bo.y[b, i]
    for j in range(bo.top[b]):
        if j == i or not bo.valid[b, j]:
            continue
        apart = half + 0.5 * bo.width[b, j] + BESIDE_GAP
        if _in_the_way(y, want, bo.y[b, j], apart) and _alongside(
            x, length, v, bo.x[b, j], bo.length[b, j], bo.speed[b, j], lane_of(bo.y[b, j]) != own
        ):
            want = short_of(y, want, bo.y[b, j], apart)
    r = sl.r[b, i]
    for g in range(gh.count[b]):
        if gh.r[b, g] != r and _alongside(
            x, length, v, gh.x[b, g], gh.length[b, g], gh.speed[b, g], gh.lane[b, g] != own
        ):
            apart = half + 0.5 * core.rec.width[gh.r[b, g]] + BESIDE_GAP
            want = short_of(y, want, gh.y[b, g], apart)
    return want


@kernel(inline=True)
def _in_the_way(y, want, yj, apart):
    """Whether :func:`short_of` keeps a vehicle at ``y`` [m] that wants to go to
    ``want`` short of it for one at ``yj`` (read first for the bodies: across the road
    most are not in the way, and this is cheaper than their lanes)."""
    if want > y:
        return yj >= y and yj - apart < want
    if want < y:
        return yj <= y and yj + apart > want
    return False


@kernel(inline=True)
def _alongside(x, length, v, xj, length_j, vj, other_lane):
    """Whether a vehicle from back ``xj`` [m], ``length_j`` long, at ``vj`` [m/s] is
    alongside one from back ``x``, ``length`` long, at ``v``: their boxes along the road
    within :data:`BESIDE_AHEAD`; in the ``other_lane`` also where the one behind closes
    that in :data:`BESIDE_HORIZON` (a body moved across into the next lane's part is
    not seen there by the traffic core's car following, lane by lane; in its own lane
    it is)."""
    horizon = BESIDE_HORIZON if other_lane else 0.0
    ahead = BESIDE_AHEAD + horizon * max(v - vj, 0.0)  # xj ahead, closed on by x
    behind = BESIDE_AHEAD + horizon * max(vj - v, 0.0)
    return x - behind < xj + length_j and xj - ahead < x + length


@kernel(inline=True)
def short_of(y, want, yj, apart):
    """``want`` [m], where a vehicle at ``y`` wants to go across, kept ``apart`` [m] from
    one at ``yj`` on that side: no further toward it than that, nor back from ``y``."""
    if yj >= y and want > y:
        return min(want, max(yj - apart, y))
    if yj <= y and want < y:
        return max(want, min(yj + apart, y))
    return want


@kernel
def settled(b, core, i):
    """Whether relaxing slot ``i`` is back on its recording (module doc; its
    :func:`target` read this step): to be handed to it."""
    bo, sl, dr, ep = core.bodies, core.slots, core.traffic.drivers, core.episodes
    if not sl.rec_on[b, i]:
        return False
    xr = sl.rec_x[b, i]
    in_ghost_cell = ep.windows[b, 0] <= xr <= ep.windows[b, 3] and not (
        ep.windows[b, 1] <= xr <= ep.windows[b, 2]
    )
    return (
        in_ghost_cell
        and abs(bo.x[b, i] - xr) <= HAND_BACK_X
        and abs(bo.speed[b, i] - sl.rec_speed[b, i]) <= HAND_BACK_SPEED
        and abs(ep.speed_prev[b, i] - sl.rec_speed[b, i]) <= HAND_BACK_SPEED
        and abs(bo.y[b, i] - sl.rec_y[b, i]) <= HAND_BACK_Y
        and dr.lane_from[b, i] == dr.lane[b, i]
        and lane_of(sl.rec_y[b, i]) == dr.lane[b, i]
        and dr.lane[b, i] >= -N_LANES  # on an on-ramp's lane it merges first
    )


@kernel
def desired_speeds(b, core):
    """A relaxing driver's desired speed well above its target's (the tracking law,
    not the free road, sets how fast it goes; its car following still keeps it clear
    of what is ahead)."""
    bo, sl, params = core.bodies, core.slots, core.traffic.drivers.cf
    for i in range(bo.top[b]):
        if bo.valid[b, i] and sl.relaxing[b, i] and sl.rec_on[b, i]:
            fastest = max(bo.speed[b, i], sl.rec_speed[b, i])
            params[b, i, 0] = max(params[b, i, 0], 2.0 * fastest + FREE_SPEED)


@kernel
def note_changes(b, core):
    """Before the traffic manager's step: which relaxing vehicles are changing lanes
    (:func:`track` then takes the changes they start out of the manager's count, which
    counts the visible traffic's)."""
    bo, sl, dr = core.bodies, core.slots, core.traffic.drivers
    for i in range(bo.top[b]):
        sl.changing[b, i] = dr.lane_from[b, i] != dr.lane[b, i]


@kernel
def track(b, core):
    """Each relaxing vehicle's command (after the traffic manager's): the tracking law
    toward its recording, never above its car following's command, within
    [ACCEL_LOW, ACCEL_HIGH]; where its car following asks for harder braking, behind a
    body or a ghost (drawn, so a crash a user sees), it brakes that hard. Ahead of its
    recording it brakes toward it only above :func:`_eased_speed`, and below that speeds
    up to it. It does not brake toward its recording
    while a ghost behind it crowds it (a recording, which cannot brake for it): it
    keeps its speed, its car following aside."""
    bo, sl, dr = core.bodies, core.slots, core.traffic.drivers
    accel, lanes, lanes_from = dr.accel, dr.lane, dr.lane_from
    for i in range(bo.top[b]):
        if not (bo.valid[b, i] and sl.relaxing[b, i]):
            continue
        if lanes_from[b, i] != lanes[b, i] and not sl.changing[b, i]:
            # toward its recording's lane: not the visible traffic's
            if lanes_from[b, i] < -N_LANES:
                core.traffic.counters.merges[b] -= 1
            else:
                core.traffic.counters.lane_changes[b] -= 1
        if not sl.rec_on[b, i]:
            continue
        law = (
            sl.rec_accel[b, i]
            + OMEGA * OMEGA * (sl.rec_x[b, i] - bo.x[b, i])
            + 2.0 * OMEGA * (sl.rec_speed[b, i] - bo.speed[b, i])
        )
        if law < 0.0 and _crowded_by_ghost(b, core, i):
            law = 0.0  # a recording close behind it, which cannot brake: no slowing for its own
        if bo.x[b, i] > sl.rec_x[b, i]:
            # ahead of it: brakes for it at most down to the eased speed in one step, and
            # from below speeds up to it at the tracking law's gain
            short = _eased_speed(b, core, i) - bo.speed[b, i]
            law = max(law, min(short / core.settings.dt, 2.0 * OMEGA * short))
        following = accel[b, i]
        floor = min(following, ACCEL_LOW)  # behind a body or a ghost: as hard as needed
        if following < ACCEL_LOW and (
            core.traffic.scratch.emergency[b, i] or follows_what_is_ahead(b, core, i, following)
        ):
            # as hard as stopping short of it needs, not as hard as its car following (or
            # the traffic manager's emergency braking, whose 1 m margin a recording that
            # crowded a body is often inside when it becomes one: full braking from
            # 0.5 m/s, 0.96 m behind a standing body, where 0.2 m/s^2 would do) says;
            # inside its standstill gap IDM asks for far more than stopping takes
            need = stopping_decel(b, core, i, core.settings.clearance_at_rest)
            floor = min(max(following, -need), ACCEL_LOW)
        accel[b, i] = min(max(min(law, following), floor), ACCEL_HIGH)


@kernel
def _eased_speed(b, core, i):
    """[m/s] the speed relaxing slot ``i``, ahead of its recording, slows to no further
    for it: :data:`EASE_SHARE` of its recording's, or the speed of the ghost just ahead
    of it in its lane (the recorded traffic there, which its own recording, behind, has
    not reached) less a tenth of its recording's, where that is faster. Behind recorded
    traffic that drives as its recording does, it still closes in on it at a tenth of
    the recording's speed; behind faster recorded traffic it keeps up with it rather
    than hold the lane at its own recording's pace. On SUMO's on-ramp morning (seed 1,
    episode 1) two bodies that had raced ahead in lane -3 and braked behind its queue
    moved back into lane -4 and held 1.8 and 4.6 m/s there for half a minute, 180 m
    ahead of recordings speeding up to 9 m/s, with the recorded traffic ahead of them at
    18: lane -4 crawled behind them and the ego ended 800 m short of its recording."""
    bo, sl, sc = core.bodies, core.slots, core.traffic.scratch
    own = sl.rec_speed[b, i]
    eased = EASE_SHARE * own
    ahead, _ = around(sc.entry_key, sc.entry_group, sc.entry_owner, sc.entry_count[b], b,
                      core.traffic.drivers.lane[b, i], bo.x[b, i])  # fmt: skip
    if ahead >= bo.valid.shape[1]:  # owners from n on are ghosts
        eased = max(eased, sc.sspeed[b, ahead] - (1.0 - EASE_SHARE) * own)
    return eased


@kernel
def _crowded_by_ghost(b, core, i):
    """Whether the ghost just behind slot ``i`` in a lane it occupies is closer than
    :func:`twin.cosim.core.room.spawn_room` with the whole clearance at any speed and
    the braking distances at :data:`CROWD_DECEL`, plus what it closes in
    :data:`CROWD_AHEAD`."""
    bo, dr, sc = core.bodies, core.traffic.drivers, core.traffic.scratch
    n = bo.valid.shape[1]  # owners from n on are ghosts
    v = max(bo.speed[b, i], 0.0)
    for lane in (dr.lane[b, i], dr.lane_from[b, i]):
        _, behind = around(sc.entry_key, sc.entry_group, sc.entry_owner, sc.entry_count[b], b,
                           lane, bo.x[b, i])  # fmt: skip
        if behind < n:
            continue
        gap = bo.x[b, i] - sc.sx[b, behind] - sc.slength[b, behind]
        vg = max(sc.sspeed[b, behind], 0.0)
        clearance = core.settings.clearance  # the whole clearance, at rest too
        room = spawn_room(clearance, clearance, CROWD_DECEL, vg, vg * vg - v * v)
        if gap < room + CROWD_AHEAD * max(vg - v, 0.0):
            return True
    return False
