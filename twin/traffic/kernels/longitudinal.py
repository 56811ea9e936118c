"""Longitudinal decisions of the traffic manager, as compiled kernels: each driver's
car-following acceleration behind every leader it has (one per lane it occupies, and a
slower car on its left it may not pass on the right), the
deceleration it would need to stay clear of them (emergency braking), and the
cooperation of the drivers behind an urgent (strategic) lane change.

The acceleration itself is tracked by the vehicle model, which adds feedforward for
grade, rolling resistance and drag.

**Strategic lane changes** (the idea of SUMO's LC2013 strategic and cooperative
layers, Erdmann 2015, in the twin's own form): a driver who must leave its lane by a
place (a lane that ends, a merge or an exit beyond the window, as the recording's
flows say, or the change its own recording makes) has a target: a direction, the
place ``strategic_from`` where it starts to want the change and the place
``strategic_by`` by which it must have made it; its urgency grows from 0 at the one to
1 at the other (:func:`urgency`). From ``strategic_from`` it wants that change
whatever MOBIL's incentive, judges it at every decision step, makes no change the
other way, and takes a gap whose new follower must brake up to ``safe_decel (1 +
urgency)`` (at most ``emergency_decel``); past ``strategic_by`` it keeps trying until
GIVE_UP metres beyond (:mod:`twin.traffic.kernels.lane_change`). Once its urgency is at
least ``cooperate_from``, it settles behind the target lane's vehicle ahead of it (or
alongside it, when that one is more than half a length past its back), and the driver
behind that one drops back for it, once the urgency is also at least ``yield_from``,
if it is courteous (a share ``courtesy`` of the drivers, drawn once per driver), each
braking no harder than ``cooperative_decel``; where that one does not make room and
the gap is too short for the change (:func:`opening`, :func:`takes`), the urgent
driver drops back to the gap behind it if that is one to take, and otherwise drives on
along its lane to a gap further on or its lane's end, as LC2013's merging drivers
adapt their speed to a gap (:func:`cooperate`; the last three are
calibrated from how the recording's lane -4 yields to the on-ramps' merges,
:mod:`twin.calibration.yielding`). An urgent change takes a
shorter path than a discretionary one (``urgent_path``), so that a driver can get across
a crawling queue as real drivers do.

**Lanes that end** (``lane_ends``: an on-ramp's acceleration lane, lane -5, half an
urgent change's shortest path before its taper ends) are a standing obstacle to the
drivers in them: a driver who has not merged by then slows and waits there
(:func:`lane_end_gap`), as a real one does, and merges from there when lane -4 gives
it a gap, its change from a stop crossing into lane -4 (half-way along its path) before
the taper's end; a change out of such a lane at speed takes a path no longer than
twice the distance to that place (nor shorter than an urgent one), so that it too
crosses before the end (:mod:`twin.traffic.kernels.lane_change`).
"""

import math

import numpy as np

from twin.core.jit import kernel, uniform
from twin.traffic.kernels.models import follow_accel
from twin.traffic.kernels.neighbours import around, leader_entry

MIN_SPEED_PATH = 5.0  # [m/s] lane-change paths are at least this speed times their time
MIN_ROOM = 0.1  # [m] the gap a cooperating driver judges when it overlaps the urgent one
COURTESY_STREAM = np.int64(0x636F75)  # whether a driver is courteous: one draw per driver
MIN_LANE_CHANGE_GAP = 1.0  # [m] bumper to bumper, to each of a lane change's new neighbours
CLEARANCE_SPEED = 5.0  # [m/s] from this speed of the rear vehicle a spawn needs the full clearance
#: [s] a change in front of a recording leaves it also what it closes in this time (the
#: cosimulation's crowding test looks as far ahead: the recording is made a body in time)
ROOM_AHEAD = 1.0
#: [s] a change in front of a recording judges it at the speed it reaches this much later
#: where it speeds up (its recorded acceleration, ``Obstacles.accel``): half the longest
#: change, by when the changer is in the recording's lane and, braking behind its new
#: leader, slower than it may have been when it began
FORESEEN = 3.0


@kernel(inline=True)
def required_decel(gap, v, v_lead, lead_decel, margin, reaction):
    """[m/s^2] >= 0 a follower needs to stay ``margin`` [m] behind its leader ``gap`` [m]
    ahead if the leader keeps braking at ``lead_decel`` (>= 0) until it stops, after
    ``reaction`` [s] of travel; ``inf`` where the room is used up already, 0 for
    ``gap`` inf.

    After ``reaction`` of travel at the current speeds, the follower brakes at a
    constant deceleration. If it would close the gap before the leader stops, the
    relative motion decides (``lead_decel + closing^2 / (2 room)``); otherwise the final
    gap with both stopped does."""
    if not math.isfinite(gap):
        return 0.0
    closing = v - v_lead
    room = gap - margin - max(closing, 0.0) * reaction
    if lead_decel > 1e-6:
        lead_stop_time = v_lead / lead_decel
        lead_stop = 0.5 * v_lead * lead_stop_time
    else:
        lead_stop_time = math.inf
        lead_stop = math.inf
    stop_room = gap - margin - closing * reaction + lead_stop
    catches_up = closing > 0.0 and 2.0 * room < closing * lead_stop_time
    if catches_up:
        return lead_decel + closing * closing / (2.0 * room) if room > 0.0 else math.inf
    return v * v / (2.0 * stop_room) if stop_room > 0.0 else math.inf


@kernel(inline=True)
def cf(model, params, obstacle, b, n, owner, v, v_lead, gap):
    """The car-following acceleration of ``owner`` (a vehicle's slot, with its row of
    ``params``; or an obstacle, judged as the mean driver ``obstacle``) behind a
    leader."""
    if owner < n:
        return follow_accel(
            model, v, v_lead, gap, params[b, owner, 0], params[b, owner, 1],
            params[b, owner, 2], params[b, owner, 3], params[b, owner, 4], params[b, owner, 5],
        )  # fmt: skip
    p = obstacle
    return follow_accel(model, v, v_lead, gap, p[0], p[1], p[2], p[3], p[4], p[5])


@kernel
def follow(b, t):
    """Each vehicle's acceleration behind its most constraining leader (``cf_accel``),
    with a slower car on its left it may not pass (:func:`not_passing_right`, where
    ``no_pass_right_from`` is set), and the deceleration staying clear of its leaders
    needs (``need``)."""
    vehicles, drivers, sc, settings = t.vehicles, t.drivers, t.scratch, t.settings
    valid, body_lane = vehicles.valid, vehicles.lane
    lane_to, lane_from, params = drivers.lane, drivers.lane_from, drivers.cf
    owner_of, group, count = sc.entry_owner, sc.entry_group, sc.entry_count[b]
    sx, slength, sspeed, saccel = sc.sx, sc.slength, sc.sspeed, sc.saccel
    cf_accel, need_of = sc.cf_accel, sc.need
    model, obstacle = settings.model, settings.obstacle_cf
    margin, reaction = settings.emergency_margin, settings.reaction_time
    n = valid.shape[1]
    for i in range(vehicles.top[b]):
        cf_accel[b, i] = math.inf
        need_of[b, i] = 0.0
    for e in range(count):
        o = owner_of[b, e]
        if o >= n:
            continue
        speed = sspeed[b, o]
        lead_e = leader_entry(count, group, b, e)
        leader = owner_of[b, lead_e] if lead_e >= 0 else -1
        gap = math.inf
        if leader >= 0:
            gap = sx[b, leader] - sx[b, o] - slength[b, o]
        v_lead = sspeed[b, leader] if leader >= 0 else speed
        lead_decel = max(-saccel[b, leader], 0.0) if leader >= 0 else 0.0
        entry_lane = -group[b, e] - 1
        # the lane's end, nearer than its leader, is a standing obstacle to a driver in
        # it; no longer to one changing out of it (from a stop at the end, a driver
        # noses into the next lane past where the taper closes), nor to one whose
        # footprint only reaches into it
        if lane_from[b, o] == lane_to[b, o] and (
            entry_lane == lane_to[b, o] or entry_lane == body_lane[b, o]
        ):
            end = lane_end_gap(settings.lane_ends, entry_lane, sx[b, o], slength[b, o])
            if end < gap:
                gap, v_lead, lead_decel = end, 0.0, 0.0
        # a slow vehicle past the middle of its lane change no longer follows the
        # leader of the lane it leaves: it finishes the change rather than stopping
        # across the line behind a queue it is leaving
        if (
            entry_lane == lane_from[b, o]
            and lane_from[b, o] != lane_to[b, o]
            and body_lane[b, o] == lane_to[b, o]
            and speed < MIN_SPEED_PATH
        ):
            gap, v_lead, lead_decel = math.inf, speed, 0.0
        accel = cf(model, params, obstacle, b, n, o, speed, v_lead, gap)
        if accel < cf_accel[b, o]:
            cf_accel[b, o] = accel
        need = required_decel(gap, speed, v_lead, lead_decel, margin, reaction)
        if need > need_of[b, o]:
            need_of[b, o] = need
    if settings.no_pass_right_from < math.inf:
        for i in range(vehicles.top[b]):
            if valid[b, i] and lane_from[b, i] == lane_to[b, i]:
                cf_accel[b, i] = min(cf_accel[b, i], not_passing_right(t, b, n, i))


@kernel(inline=True)
def not_passing_right(t, b, n, i):
    """[m/s^2] the car-following acceleration of driver ``i`` behind the nearest vehicle
    (or recording) whose back is ahead of ``i``'s front in the lane to its left, where
    that one is slower and ``i`` drives at ``no_pass_right_from`` or faster (``i`` does
    not pass it on the right), braking no harder than ``cooperative_decel`` (it drops
    back as it would for a merging driver: one it cannot stay behind so gently, it
    passes); inf otherwise. A car already level with ``i`` is not judged, nor is the
    rule part of the emergency need: it is a driver's choice, not a collision to avoid.
    Only in lanes -4 and -3: the HOV lane behind its double line is not a lane the
    drivers of lane -2 could move into to pass, so they pass it as SUMO's drivers do
    (LC2013 applies the rule towards a lane the vehicle may change into)."""
    sc, settings = t.scratch, t.settings
    lane = t.drivers.lane[b, i]
    speed = sc.sspeed[b, i]
    if speed < settings.no_pass_right_from or not -4 <= lane <= -3:
        return math.inf
    front = sc.sx[b, i] + sc.slength[b, i]
    ahead, _ = around(sc.entry_key, sc.entry_group, sc.entry_owner, sc.entry_count[b], b,
                      lane + 1, front)  # fmt: skip
    if ahead < 0 or sc.sspeed[b, ahead] >= speed:
        return math.inf
    gap = max(sc.sx[b, ahead] - front, MIN_ROOM)
    behind_it = cf(settings.model, t.drivers.cf, settings.obstacle_cf, b, n, i, speed,
                   sc.sspeed[b, ahead], gap)  # fmt: skip
    return max(behind_it, -settings.cooperative_decel)


@kernel(inline=True)
def lane_end_gap(ends, lane, x, length):
    """[m] from the front of a vehicle of ``length`` at back ``x`` in ``lane`` to the
    nearest end of that lane not behind its back (rows (lane, x) of ``ends``:
    :class:`~twin.traffic.kernels.decide.TrafficSettings`' ``lane_ends``); inf where
    none."""
    gap = math.inf
    for k in range(ends.shape[0]):
        if ends[k, 0] == lane and ends[k, 1] >= x:
            gap = min(gap, ends[k, 1] - x - length)
    return gap


@kernel(inline=True)
def urgency(strategic, x_from, x_by, b, i, centre_x):
    """Vehicle ``i``'s strategic urgency at ``centre_x`` [m] (its ``strategic``
    direction, ``x_from`` and ``x_by``): -1 with no target or before ``x_from``; 0 to 1
    up to ``x_by``; 1 beyond."""
    start = x_from[b, i]
    if strategic[b, i] == 0 or not centre_x >= start:
        return -1.0
    u = (centre_x - start) / max(x_by[b, i] - start, 1.0)
    return min(max(u, 0.0), 1.0)


@kernel(inline=True)
def spawn_room(clearance, at_rest, decel, rear_speed, closing):
    """[m] bumper-to-bumper room a spawn needs to a body in its lane: the clearance,
    ``at_rest`` for a rear vehicle at rest growing to ``clearance`` at CLEARANCE_SPEED,
    plus the difference of braking distances at ``decel`` (``closing`` = v_rear^2 -
    v_front^2; :func:`twin.cosim.cosimulator.spawn_room`). The cosimulation's spawns and
    hand-overs use it (:mod:`twin.cosim.core.room`), and so does a lane change in front
    of an obstacle (:func:`room_behind`)."""
    share = min(max(rear_speed / CLEARANCE_SPEED, 0.0), 1.0)
    return at_rest + share * (clearance - at_rest) + max(closing, 0.0) / (2.0 * decel)


@kernel(inline=True)
def room_behind(t, b, n, back, speed):
    """[m] the gap a lane change must leave in front of its new follower ``back``, the
    changing vehicle to drive at ``speed`` [m/s] there (the lesser of its own and its
    new leader's: it slows to the leader's): :data:`MIN_LANE_CHANGE_GAP` to a driver,
    who brakes for it; to an obstacle (``back`` >= ``n``: a recording, which does not)
    the room it needs to be made a simulated vehicle that brakes behind it once it
    crowds the changing one: :func:`spawn_room` at the settings' ``obstacle_clearance``
    and ``obstacle_clearance_at_rest`` with the difference of braking distances at
    ``emergency_decel``, plus what it closes in :data:`ROOM_AHEAD`, the recording judged
    at the speed it will reach :data:`FORESEEN` seconds on where it speeds up. Ramp
    vehicles that started their change 1.4 and 2.0 m ahead of a recording, then slowed
    behind their new leader, were run through (SUMO's on-ramp morning); so was one that
    left a recording then at 9.9 m/s the 2.0 m its speed asked for, which went on
    speeding up to 11.2 m/s."""
    if back < n:
        return MIN_LANE_CHANGE_GAP
    s = t.settings
    rear = t.scratch.sspeed[b, back] + max(t.obstacles.accel[b, back - n], 0.0) * FORESEEN
    room = spawn_room(s.obstacle_clearance, s.obstacle_clearance_at_rest, s.emergency_decel,
                      rear, rear * rear - speed * speed)  # fmt: skip
    return max(room + ROOM_AHEAD * max(rear - speed, 0.0), MIN_LANE_CHANGE_GAP)


@kernel(inline=True)
def yields(seed, key, urge, yield_from, courtesy):
    """Whether the driver of ``key`` drops back for an urgent change of urgency
    ``urge``: from ``yield_from``, if it is courteous (a share ``courtesy``, one draw
    per driver)."""
    if urge < yield_from:
        return False
    return courtesy >= 1.0 or courtesy > uniform(seed, COURTESY_STREAM, key, 0)


@kernel(inline=True)
def accepted_decel(safe_decel, urge, emergency_decel):
    """[m/s^2] the braking a lane change may ask of its new follower: ``safe_decel``,
    raised by an urgent driver's urgency ``urge`` to ``safe_decel (1 + urge)``, never
    past emergency braking."""
    if urge > 0.0:
        return max(min(safe_decel * (1.0 + urge), emergency_decel), safe_decel)
    return safe_decel


@kernel(inline=True)
def takes(t, b, n, i, behind, urge, x, speed):
    """Whether urgent driver ``i`` at back ``x`` [m] and ``speed`` [m/s] could change in
    front of ``behind`` now as it is: the gap to it at least :func:`room_behind` and its
    braking behind ``i`` no harder than the lane
    change's test accepts at urgency ``urge`` (:mod:`twin.traffic.kernels.lane_change`)."""
    gap = x - t.scratch.sx[b, behind] - t.scratch.slength[b, behind]
    return gap >= room_behind(t, b, n, behind, speed) and accepts(
        t, b, n, i, behind, urge, speed, gap
    )


@kernel(inline=True)
def accepts(t, b, n, i, back, urge, speed, gap):
    """Whether ``back`` would brake no harder than urgent driver ``i``'s change may ask
    (:func:`accepted_decel` at urgency ``urge``) behind ``i`` at ``speed`` [m/s],
    ``gap`` [m] ahead of it."""
    settings = t.settings
    accepted = accepted_decel(t.drivers.safe_decel[b, i], urge, settings.emergency_decel)
    brake = cf(settings.model, t.drivers.cf, settings.obstacle_cf, b, n, back,
               t.scratch.sspeed[b, back], speed, gap)  # fmt: skip
    return brake >= -accepted


@kernel(inline=True)
def opening(t, b, n, i, front, back, urge, seed, yield_from, courtesy):
    """Whether urgent driver ``i`` could fall in between ``front`` and ``back`` (-1:
    none) of its target lane: room for its length and :data:`MIN_LANE_CHANGE_GAP` to
    each, and ``back`` either making room for it (:func:`yields`) or braking behind it
    there, at ``front``'s speed, no harder than the change's test accepts."""
    if back < 0:
        return True
    sc, settings = t.scratch, t.settings
    space = sc.sx[b, front] - sc.sx[b, back] - sc.slength[b, back]
    gap = space - sc.slength[b, i] - MIN_LANE_CHANGE_GAP
    if gap < MIN_LANE_CHANGE_GAP:
        return False
    # in the middle of it, at its front's speed: its own braking behind the front as the
    # change's test asks of it
    v = sc.sspeed[b, front]
    if 0.5 * gap < room_behind(t, b, n, back, v):
        return False
    own = cf(settings.model, t.drivers.cf, settings.obstacle_cf, b, n, i, v, v, 0.5 * gap)
    if own < -t.drivers.safe_decel[b, i]:
        return False
    if back < n and yields(seed, t.drivers.key[b, back], urge, yield_from, courtesy):
        return True
    return accepts(t, b, n, i, back, urge, v, 0.5 * gap)


@kernel
def cooperate(b, seed, t):
    """``cf_accel`` with the urgent drivers settling behind their target lane's vehicle
    and the one behind it dropping back where it is courteous (module doc; ``seed``: the
    run's, of the courtesy draws)."""
    vehicles, drivers, sc, settings = t.vehicles, t.drivers, t.scratch, t.settings
    valid = vehicles.valid
    lane_to, lane_from, params = drivers.lane, drivers.lane_from, drivers.cf
    strategic, x_from, x_by = drivers.strategic, drivers.strategic_from, drivers.strategic_by
    key, group, owner, count = sc.entry_key, sc.entry_group, sc.entry_owner, sc.entry_count[b]
    sx, slength, sspeed, cf_accel = sc.sx, sc.slength, sc.sspeed, sc.cf_accel
    model, obstacle = settings.model, settings.obstacle_cf
    start, most, courtesy = settings.cooperate_from, settings.cooperative_decel, settings.courtesy
    yield_from = settings.yield_from
    key_of = drivers.key
    n = valid.shape[1]
    for i in range(vehicles.top[b]):
        if not valid[b, i] or strategic[b, i] == 0 or lane_to[b, i] != lane_from[b, i]:
            continue
        x = sx[b, i]
        length = slength[b, i]
        urge = urgency(strategic, x_from, x_by, b, i, x + 0.5 * length)
        if urge < start:
            continue
        target = lane_to[b, i] + strategic[b, i]
        if not -4 <= target <= -1:
            continue
        ahead, behind = around(key, group, owner, count, b, target, x)
        gap = x - sx[b, behind] - slength[b, behind] if behind >= 0 else math.inf
        if gap < -0.5 * length:  # alongside: go behind it, and the one behind it helps
            ahead = behind
            _, behind = around(key, group, owner, count, b, target, sx[b, ahead])
        speed = sspeed[b, i]
        if (
            0 <= behind < n
            and not yields(seed, key_of[b, behind], urge, yield_from, courtesy)
            and not (
                opening(t, b, n, i, ahead, behind, urge, seed, yield_from, courtesy)
                if ahead >= 0
                else takes(t, b, n, i, behind, urge, x, speed)
            )
        ):
            # the one behind will not make room (not now, or never) and the gap is too
            # short: drop back to the gap behind it where that gap is one to take (the
            # speed adaptation of LC2013's merging drivers); otherwise drive on along
            # its own lane to a gap further on, or to the lane's end
            _, next_back = around(key, group, owner, count, b, target, sx[b, behind])
            if not opening(t, b, n, i, behind, next_back, urge, seed, yield_from, courtesy):
                continue
            ahead, behind = behind, next_back
        if ahead >= 0:
            room = sx[b, ahead] - x - length
            behind_it = cf(model, params, obstacle, b, n, i, speed, sspeed[b, ahead], room)
            cf_accel[b, i] = min(cf_accel[b, i], max(behind_it, -most))
        if behind < 0 or behind >= n or not yields(seed, key_of[b, behind], urge, yield_from,
                                                   courtesy):  # fmt: skip
            continue  # not (yet) courteous: keeps to its own leader
        gap = x - sx[b, behind] - slength[b, behind]
        if gap < -0.5 * length:
            continue
        room = max(gap, MIN_ROOM)
        drop_back = cf(model, params, obstacle, b, n, behind, sspeed[b, behind], speed, room)
        cf_accel[b, behind] = min(cf_accel[b, behind], max(drop_back, -most))
