"""Lane-change decisions of the traffic manager, compiled: MOBIL (Kesting, Treiber,
Helbing 2007, :mod:`twin.traffic.mobil`) for the drivers due to decide, the changes
asked for (by a controller), the strategic targets (a lane to leave by a place:
:mod:`twin.traffic.kernels.longitudinal`'s doc) and the HOV rule.

A driver decides on a grid of ``decision_period`` at random intervals around
``decision_interval``; a change it starts lasts a drawn manoeuvre time, along a path
the lateral controller tracks (:mod:`twin.traffic.kernels.steering`). Accelerations are
the drivers' car-following model's; obstacles (the ghosts) are judged as the class
table's mean driver.

The drivers deciding in a round are judged against the scene as it was when the round
began (the entries are not re-sorted between them), so the order they are taken in
changes nothing. Their random draws (the next decision time, a manoeuvre's duration)
come from counters: the run's seed, the driver's key and its count of such draws.
"""

import math

import numpy as np

from twin.core.i24 import HOV_LANE, N_LANES
from twin.core.jit import kernel, uniform
from twin.traffic.kernels.longitudinal import (
    MIN_LANE_CHANGE_GAP,
    MIN_SPEED_PATH,
    accepted_decel,
    cf,
    follow,
    lane_end_gap,
    room_behind,
    urgency,
)
from twin.traffic.kernels.neighbours import around, around_other, gather, sort_entries

LEFT, RIGHT = 1, -1  # toward lane -1, toward lane -4
# An urgent path is at least this many of the vehicle's lengths: along a shorter one the
# yawed front of a long vehicle sweeps past the target lane's far line (a 20.5 m truck
# following a 15 m path exactly would reach 1.7 m into the lane beyond; at 2.5 lengths
# its front corner stays 0.2 m inside, as a 4.5 m car's does 0.75 m inside at 15 m)
URGENT_PATH_LENGTHS = 2.5
GIVE_UP = 150.0  # [m] past strategic_by a strategic change is no longer tried
# The random streams of the next decision and the manoeuvre time (numpy integers: a
# kernel called with a Python int constant is compiled once per value)
DECISION_STREAM = np.int64(0x44)
DURATION_STREAM = np.int64(0x4D)
FIRST_DECISION_STREAM = np.int64(0x46)


@kernel(inline=True)
def shortest_urgent(urgent_path, length):
    """[m] the shortest path of an urgent change of a vehicle ``length`` [m] long:
    ``urgent_path``, and at least URGENT_PATH_LENGTHS of its own length."""
    return max(urgent_path, URGENT_PATH_LENGTHS * length)


@kernel(inline=True)
def path_length(speed, duration, urgent, urgent_path, length):
    """[m] a lane-change path at ``speed`` [m/s] lasting ``duration`` [s] of a vehicle
    ``length`` [m] long: made for at least MIN_SPEED_PATH, or, ``urgent``, at least
    :func:`shortest_urgent` long."""
    if urgent:
        return max(speed * duration, shortest_urgent(urgent_path, length))
    return max(speed, MIN_SPEED_PATH) * duration


@kernel(inline=True)
def hov_allows(eligible, lane, target, x, openings):
    """Whether a move from ``lane`` to ``target`` at back x [m] keeps the HOV rule (into
    the HOV lane only when ``eligible``; across its line only inside an opening, rows
    (x0, x1) of ``openings``)."""
    if target == HOV_LANE and not eligible:
        return False
    if lane != HOV_LANE and target != HOV_LANE:
        return True
    for k in range(openings.shape[0]):  # noqa: SIM110 (a generator does not compile)
        if openings[k, 0] <= x <= openings[k, 1]:
            return True
    return False


@kernel(inline=True)
def kept_out(zones, lane, x):
    """Whether ``lane`` at ``x`` [m] lies in a keep-out zone, rows (lane, x0, x1) of
    ``zones`` (half-open in x)."""
    for k in range(zones.shape[0]):
        if lane == zones[k, 0] and zones[k, 1] <= x < zones[k, 2]:
            return True
    return False


@kernel
def expire(b, t):
    """Clear the strategic targets of drivers more than GIVE_UP past their
    ``strategic_by``; not an on-ramp driver's merge (its lane ends: it waits at the end
    until it has merged, however far before the end its merge was due)."""
    valid, x, length = t.vehicles.valid, t.vehicles.x, t.vehicles.length
    strategic, x_from, x_by = t.drivers.strategic, t.drivers.strategic_from, t.drivers.strategic_by
    lane = t.drivers.lane
    for i in range(t.vehicles.top[b]):
        if (
            valid[b, i]
            and strategic[b, i] != 0
            and lane[b, i] >= -N_LANES
            and x[b, i] + 0.5 * length[b, i] > x_by[b, i] + (GIVE_UP)
        ):
            clear_target(strategic, x_from, x_by, b, i)


@kernel(inline=True)
def clear_target(strategic, x_from, x_by, b, i):
    """No strategic target for driver ``i`` (its ``strategic``, ``x_from``, ``x_by``)."""
    strategic[b, i] = 0
    x_from[b, i] = math.nan
    x_by[b, i] = math.nan


@kernel
def change_lanes(b, time, seed, t):
    """One decision round of episode ``b`` at its clock ``time`` [s]: start the changes
    MOBIL chooses for the drivers due and the changes asked for where safe. Returns how
    many started between the through lanes; a merge from an on-ramp's acceleration lane
    (lane -5 to -4) is counted in ``counters.merges`` instead, as the recording's lane
    changes leave merges out."""
    vehicles, drivers, sc, settings = t.vehicles, t.drivers, t.scratch, t.settings
    valid, y = vehicles.valid, vehicles.y
    lane_to, lane_from, ctrl = drivers.lane, drivers.lane_from, drivers.ctrl
    strategic, x_from, x_by = drivers.strategic, drivers.strategic_from, drivers.strategic_by
    next_decision, auto, requested = drivers.next_decision, drivers.auto, drivers.requested
    keys, decisions = drivers.key, drivers.decisions
    sx, slength = sc.sx, sc.slength
    n = valid.shape[1]
    started = 0
    for i in range(vehicles.top[b]):
        if not valid[b, i] or lane_from[b, i] != lane_to[b, i]:
            continue
        driven = ctrl[b, i] == 0  # a controller decides its own changes
        x = sx[b, i]
        centre = x + 0.5 * slength[b, i]
        wants = driven and strategic[b, i] != 0 and centre >= x_from[b, i]
        timed = next_decision[b, i] <= time
        if not ((timed and auto[b, i] and driven) or requested[b, i] != 0 or wants):
            continue
        urge = urgency(strategic, x_from, x_by, b, i, centre)
        if timed:
            draw = uniform(seed, DECISION_STREAM, keys[b, i], decisions[b, i])
            decisions[b, i] += 1
            next_decision[b, i] = time + settings.decision_interval * (0.5 + draw)
        choice = _choose(b, i, x, urge, t, n)
        if choice == 0:
            continue
        _start(b, seed, t, i, choice, centre, y[b, i], urge >= 0.0)
        if choice == strategic[b, i]:
            clear_target(strategic, x_from, x_by, b, i)
        if drivers.lane_from[b, i] < -N_LANES:
            t.counters.merges[b] += 1
        else:
            started += 1
    return started


@kernel
def _choose(b, i, x, urge, t, n):
    """The direction driver ``i`` at back ``x`` [m] with urgency ``urge`` changes to
    (LEFT, RIGHT), or 0: the safe option of the highest gain above 0
    (:func:`lane_option`)."""
    room, old_now, old_after, accepted, asked = _situation(b, i, x, urge, t, n)
    best, choice = 0.0, 0
    for step in (LEFT, RIGHT):
        allowed, gain, safe = lane_option(b, i, x, urge, step, room, old_now, old_after,
                                          accepted, asked, t, n)  # fmt: skip
        if allowed and safe and gain > best:
            best, choice = gain, step
    return choice


@kernel(inline=True)
def _situation(b, i, x, urge, t, n):
    """What driver ``i`` at back ``x`` [m] with urgency ``urge`` weighs both ways by:
    whether it has room to reach the middle of a change behind the leader it still
    follows, its old lane's follower's acceleration now and once it has left [m/s^2],
    the deceleration it accepts of a new follower [m/s^2] and the direction it is asked
    to change to (0: none)."""
    drivers, sc, settings = t.drivers, t.scratch, t.settings
    key, group, owner, count = sc.entry_key, sc.entry_group, sc.entry_owner, sc.entry_count[b]
    sx, slength, sspeed, cf_accel = sc.sx, sc.slength, sc.sspeed, sc.cf_accel
    params, model, obstacle = drivers.cf, settings.model, settings.obstacle_cf
    lane = drivers.lane[b, i]
    speed = sspeed[b, i]
    length = slength[b, i]
    urgent = urge >= 0.0
    ahead, behind = around(key, group, owner, count, b, lane, x)
    # room to reach the middle of the change behind the leader it still follows
    high = settings.lane_change_high
    gap_now = sx[b, ahead] - x - length if ahead >= 0 else math.inf
    lead_now = sspeed[b, ahead] if ahead >= 0 else 0.0
    room = gap_now + lead_now * 0.5 * high >= 0.5 * path_length(
        speed, high, urgent, settings.urgent_path, length
    ) + (MIN_LANE_CHANGE_GAP)
    # its old lane's follower now (this step's car following; an obstacle's 0) and
    # once it has left
    old_now, old_after = 0.0, 0.0
    if behind >= 0:
        old_gap, lead_speed = math.inf, speed
        if ahead >= 0:
            old_gap = sx[b, ahead] - sx[b, behind] - slength[b, behind]
            lead_speed = sspeed[b, ahead]
        old_now = cf_accel[b, behind] if behind < n else 0.0
        old_after = cf(model, params, obstacle, b, n, behind, sspeed[b, behind], lead_speed,
                       old_gap)  # fmt: skip
    asked = drivers.requested[b, i]
    if asked == 0 and urgent:
        asked = drivers.strategic[b, i]
    # an urgent driver takes a harder gap, never past emergency braking
    accepted = accepted_decel(drivers.safe_decel[b, i], urge, settings.emergency_decel)
    return room, old_now, old_after, accepted, asked


@kernel(inline=True)
def lane_option(b, i, x, urge, step, room, old_now, old_after, accepted, asked, t, n):
    """Driver ``i``'s option of a change one lane ``step`` (LEFT, RIGHT) in its
    :func:`_situation`: whether the rules allow it at all (the road, the HOV rule, what
    it is asked, its strategic target, the keep-out zones), MOBIL's gain [m/s^2] (its
    own, less its threshold, plus its politeness share of its followers', plus the
    keep-right bias; infinite where asked) and whether it is safe (room, the new
    follower's braking within ``accepted``, its own within its ``safe_decel``, the gaps).
    The one rule both the traffic (:func:`change_lanes`) and the calibration
    (:func:`judge_scenes`) apply."""
    drivers, sc, settings = t.drivers, t.scratch, t.settings
    key, group, owner, count = sc.entry_key, sc.entry_group, sc.entry_owner, sc.entry_count[b]
    sx, slength, sspeed, cf_accel = sc.sx, sc.slength, sc.sspeed, sc.cf_accel
    params, model, obstacle = drivers.cf, settings.model, settings.obstacle_cf
    strategic = drivers.strategic[b, i]
    lane = drivers.lane[b, i]
    speed = sspeed[b, i]
    length = slength[b, i]
    urgent = urge >= 0.0
    target = lane + step
    if not -N_LANES <= target <= -1:
        return False, 0.0, False
    if not hov_allows(drivers.hov_eligible[b, i], lane, target, x, settings.hov_openings):
        return False, 0.0, False
    if asked != 0 and asked != step:
        return False, 0.0, False
    if urgent and strategic == -step:  # never away from its target
        return False, 0.0, False
    if asked != step and kept_out(settings.keep_out, target, x):
        return False, 0.0, False
    safe_decel = drivers.safe_decel[b, i]
    # MOBIL in the target lane: its new leader and follower
    # (one level with it there is ahead of it: a vehicle is never beside itself)
    t_ahead, t_behind = around_other(key, group, owner, count, b, target, x, i)
    gap_ahead = sx[b, t_ahead] - x - length if t_ahead >= 0 else math.inf
    gap_behind = x - sx[b, t_behind] - slength[b, t_behind] if t_behind >= 0 else math.inf
    v_ahead = sspeed[b, t_ahead] if t_ahead >= 0 else speed
    own_after = cf(model, params, obstacle, b, n, i, speed, v_ahead, gap_ahead)
    new_now, new_after = 0.0, 0.0
    if t_behind >= 0:
        new_now = cf_accel[b, t_behind] if t_behind < n else 0.0
        new_after = cf(model, params, obstacle, b, n, t_behind, sspeed[b, t_behind], speed,
                       gap_behind)  # fmt: skip
    safe = (
        room
        and new_after >= -accepted
        and own_after >= -safe_decel
        and gap_ahead >= MIN_LANE_CHANGE_GAP
        and gap_behind >= room_behind(t, b, n, t_behind, min(speed, v_ahead))
    )
    bias = drivers.keep_right[b, i] if step == RIGHT else -drivers.keep_right[b, i]
    others = (new_after - new_now) + (old_after - old_now)
    gain = (
        own_after - cf_accel[b, i] + drivers.politeness[b, i] * others + bias
        - drivers.threshold[b, i]
    )  # fmt: skip
    if asked == step:
        gain = math.inf
    return True, gain, safe


@kernel(nrt=True)
def judge_scenes(t, gain, possible):
    """MOBIL's options in still scenes, by the rule the traffic drives
    (:func:`lane_option`): each episode of the packed traffic ``t`` is one scene (its
    vehicles where they are, none mid-change, no strategic target), each of its drivers
    is judged as at a decision, both ways. Writes ``gain`` (B, N, 2) [m/s^2] and
    ``possible`` (B, N, 2) bool (allowed and safe), [..., 0] to the left and [..., 1] to
    the right; a slot not valid gets gain -inf and not possible."""
    vehicles, drivers, sc = t.vehicles, t.drivers, t.scratch
    n = vehicles.valid.shape[1]
    for b in range(vehicles.valid.shape[0]):
        gather(b, t)
        sort_entries(b, t)
        follow(b, t)
        for i in range(n):
            for k in range(2):
                gain[b, i, k] = -math.inf
                possible[b, i, k] = False
            if i >= vehicles.top[b] or not vehicles.valid[b, i]:
                continue
            x = sc.sx[b, i]
            centre = x + 0.5 * sc.slength[b, i]
            urge = urgency(drivers.strategic, drivers.strategic_from, drivers.strategic_by,
                           b, i, centre)  # fmt: skip
            room, old_now, old_after, accepted, asked = _situation(b, i, x, urge, t, n)
            for k in range(2):
                step = LEFT if k == 0 else RIGHT
                allowed, g, safe = lane_option(b, i, x, urge, step, room, old_now, old_after,
                                               accepted, asked, t, n)  # fmt: skip
                if allowed:
                    gain[b, i, k] = g
                    possible[b, i, k] = safe


@kernel
def _start(b, seed, t, i, choice, centre, y, urgent):
    """Start driver ``i``'s change one lane ``choice`` from ``centre`` x, ``y`` [m]."""
    drivers, sc, settings = t.drivers, t.scratch, t.settings
    draw = uniform(seed, DURATION_STREAM, drivers.key[b, i], drivers.changes[b, i])
    drivers.changes[b, i] += 1
    low, high = settings.lane_change_low, settings.lane_change_high
    duration = low + (high - low) * draw
    drivers.mandatory[b, i] = urgent and choice == drivers.strategic[b, i]
    drivers.lane_from[b, i] = drivers.lane[b, i]
    drivers.lane[b, i] = drivers.lane[b, i] + choice
    drivers.start_x[b, i] = centre
    drivers.start_y[b, i] = y
    length = sc.slength[b, i]
    path = path_length(sc.sspeed[b, i], duration, urgent, settings.urgent_path, length)
    # out of a lane that ends (an on-ramp's): crossing the line (half-way) before its end
    end = lane_end_gap(settings.lane_ends, drivers.lane_from[b, i], centre - 0.5 * length,
                       length)  # fmt: skip
    if math.isfinite(end):
        path = min(path, max(2.0 * end, shortest_urgent(settings.urgent_path, length)))
    drivers.path_length[b, i] = path
    drivers.requested[b, i] = 0
