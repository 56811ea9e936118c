"""The cosimulation step of a batch of episodes as a chain of compiled kernels (the
paper's loop, ``docs/cosim.md``), one pure pass per episode::

    lead_speeds      3. desired speeds: lane leads ahead of the ego take their ghost's
    update_targets      strategic targets (on the decision grid)
    decide              the traffic manager: car following, lane changes, controllers
    integrate        4. the kinematic world moves the bodies (or pybullet, outside)
    after_world         contacts, the spawns' speed check, the ego's range
    despawn_outside  5. visible vehicles leaving the visible window relax (or are removed)
    snapshot         6. the recording in the windows now; relaxing vehicles back on
    hand_back           their recordings handed to them; entering vehicles spawned
    enter_and_reload 7. and the ghost set reloaded
    record              the log row, the AV's fuel

The kinematic world's step is these as named phases (:data:`PHASES`: desired speeds,
decisions, move, contacts, leave, read windows, enter, close); :func:`phase_batch`
runs one phase over every episode, so that ``twin bench env --profile`` times them
apart (the same bytes as :func:`step_batch`, since episodes are independent).

Every kernel takes the packed core (:data:`twin.cosim.core.layout.Core`). Episodes
never read each other's slots, and every draw is keyed by the episode's seed and the
vehicle's record, so an episode's rows are the same alone or at any place in a batch
of any size.

:data:`CoreSettings` holds what every episode of a batch shares (the windows, the
spawn clearances, the road, the controllers).

Over 500 lines: besides the phases it holds the contacts, fuel and log kernels the
step calls; issue 78 moves those out so that the step reads top to bottom.
"""

import math
from collections import namedtuple

from twin.core.jit import kernel
from twin.core.ramps import RAMP_LANE, on_ramp
from twin.cosim.core import anchor, relax, settle
from twin.cosim.core.drivers import update_targets
from twin.cosim.core.handover import (
    YIELD_DECEL,
    despawn_outside,
    enter_and_reload,
    hand_back,
    lead_speeds,
    set_windows,
    snapshot,
    spawn,
)
from twin.cosim.core.layout import (
    COLLISIONS_KEPT,
    CONTACT_CHANGING,
    CONTACT_EGO,
    CONTACT_GHOST,
    CONTACT_MANDATORY,
    CONTACT_RELAXING,
    EGO_LEFT,
    FOLLOWERS,
    GHOST_ID_BASE,
    NEVER,
    PAIRS_FULL,
)
from twin.physics.kernels import drive_limit, footprints_overlap, fuel_rate, integrate, overlaps
from twin.physics.vehicle import HOLD_SPEED
from twin.traffic.kernels.decide import decide

CoreSettings = namedtuple(
    "CoreSettings",
    "dt limit_lo limit_hi w_visible w_ghost vel_default ghost_smoothing clearance "
    "clearance_at_rest spawn_decel av_share av_controller ego_controller lead_chases_ghost "
    "targets kinematic profile fuel relax anchor merges",
)


@kernel(nrt=True)  # called from Python with the struct: counted
def reset_episode(b, core, seed, t0, steps, ego_r, ego_x, ego_y, ego_speed):
    """Steps 1 and 2 for episode ``b``: the ego (recorded trajectory ``ego_r`` at back
    x, y [m] and speed [m/s] at unix ``t0``) and the recorded vehicles of the visible
    window spawned at their recorded speeds, the ghosts loaded, the first log row."""
    bo, sl, ep, cs = core.bodies, core.slots, core.episodes, core.settings
    t = core.traffic
    valid, order, listed, ctrl = bo.valid, sl.order, sl.listed, t.drivers.ctrl
    for i in range(valid.shape[1]):
        valid[b, i] = False
        order[b, i] = -1
        listed[b, i] = False
        sl.by_back[b, i] = -1
        sl.by_back_listed[b, i] = False
        ctrl[b, i] = 0
    bo.top[b] = 0
    if core.log.on:
        ids = core.log.id
        for k in range(ids.shape[1]):
            for i in range(ids.shape[2]):
                ids[b, k, i] = -1
    keys = core.table.key
    for h in range(keys.shape[1]):
        keys[b, h] = -1
        core.table.drawn[b, h] = NEVER
    t.scratch.order_count[b] = 0
    core.ghosts.count[b] = 0
    ep.seed[b], ep.t0[b], ep.step[b], ep.steps[b] = seed, t0, 0, steps
    ep.ended[b], ep.ended_x[b], ep.next_id[b], ep.ego_r[b] = 0, 0.0, 0, ego_r
    ep.spawned[b], ep.spawned_initially[b], ep.despawned[b] = 0, 0, 0
    ep.handed_back[b], ep.yielded[b], ep.held[b], ep.lookback[b] = 0, 0, 0, -math.inf
    ep.skipped_overlap[b], ep.skipped_invalid[b], ep.skipped_full[b] = 0, 0, 0
    ep.collisions[b], ep.off_road[b], ep.spawn_error_count[b] = 0, 0, 0
    ep.collisions_unlisted[b] = 0
    ep.touching_count[b], ep.pair_count[b], ep.fuel[b], ep.overflow[b] = 0, 0, 0.0, 0
    ep.ghost_touching_count[b] = 0
    ep.anchor_count[b], ep.anchor_lo[b], ep.anchor_hi[b], ep.anchors_full[b] = 0, 0.0, 0.0, 0
    ep.anchored[b], ep.ghosts_braked[b] = 0, 0
    ep.fuel_sum[b], ep.group_distance[b], ep.collisions_before[b] = 0.0, 0.0, 0
    for k in range(4):
        ep.lead_speed[b, k] = math.nan
    c = t.counters
    c.lane_changes[b], c.emergency_steps[b] = 0, 0
    c.safety_overrides[b], c.refused_requests[b], c.merges[b] = 0, 0, 0
    ego = spawn(b, core, ego_r, ego_x, ego_y, ego_speed, cs.vel_default, cs.ego_controller)
    ep.ego[b] = ego
    ep.ego_id[b] = bo.id[b, ego]
    set_windows(b, core, ego_x)
    snapshot(b, core, t0)
    ep.spawned_initially[b] = enter_and_reload(b, core)
    _followers(b, core)
    record(b, core, ep.step[b])  # 0 (a variable: a literal 0 compiles record twice)
    ep.done[b] = steps <= 0


@kernel
def _followers(b, core):
    """The AV's FOLLOWERS nearest followers in its lane at the start, nearest first
    (their fuel counts with its own)."""
    bo, ep = core.bodies, core.episodes
    valid, lane, x, ids, followers = bo.valid, bo.lane, bo.x, bo.id, ep.followers
    ego = ep.ego[b]
    count = 0
    for _ in range(FOLLOWERS):
        best = -1
        for i in range(bo.top[b]):
            if not valid[b, i] or i == ego or lane[b, i] != lane[b, ego] or x[b, i] >= x[b, ego]:
                continue
            taken = False
            for k in range(count):
                if followers[b, k] == ids[b, i]:
                    taken = True
            if not taken and (best < 0 or x[b, i] > x[b, best]):
                best = i
        if best < 0:
            break
        followers[b, count] = ids[b, best]
        count += 1
    ep.follower_count[b] = count


@kernel(nrt=True)  # called from Python with the struct: counted
def before_world(b, core):
    """Step 3 (desired speeds, strategic targets) and the traffic manager's decisions
    of episode ``b``: each body's commanded acceleration (``drivers.accel``) and front
    wheels' angle (the traffic scratch's ``steer``)."""
    desired_speeds(b, core)
    decisions(b, core)


@kernel(nrt=True)  # called from Python with the struct: counted
def after_world(b, core):
    """After the world's step of episode ``b``: the clock, the contacts (the kinematic
    world's footprints, else the pairs the world gave), the spawns' speed check, the
    vehicles off the road, the ego's range, then steps 5 to 7 and the log row."""
    contacts(b, core)
    leave(b, core)
    read_windows(b, core)
    enter(b, core)
    close_step(b, core)


# The step's phases, in order (step_batch runs them episode by episode; since episodes
# never read each other's slots, running each phase over every episode in turn gives
# the same bytes, which is how twin bench env --profile times them).


@kernel
def desired_speeds(b, core):
    """Step 3: the lane leads ahead of the ego take their ghost's speed; strategic
    targets on the decision grid."""
    lead_speeds(b, core)
    relax.desired_speeds(b, core)
    if core.settings.targets and core.episodes.step[b] % core.traffic.settings.decision_steps == 0:
        update_targets(b, core)


@kernel
def decisions(b, core):
    """The traffic manager: every body's commanded acceleration and steering."""
    ep, cs = core.episodes, core.settings
    step = ep.step[b]
    relax.note_changes(b, core)
    decide(b, step, step * cs.dt, ep.seed[b], core.traffic)
    relax.track(b, core)
    settle.settle(b, core)
    speed, before = core.bodies.speed, ep.speed_prev
    for i in range(core.bodies.top[b]):
        before[b, i] = speed[b, i]


@kernel
def move(b, core):
    """Step 4 in the kinematic world: the bodies integrated over the step."""
    integrate(
        b,
        core.bodies,
        core.traffic.drivers.accel,
        core.traffic.scratch.steer,
        core.traffic.drivers.accel,
        core.traffic.drivers.accel,
        core.settings.profile,
        core.settings.dt,
    )  # fmt: skip  (never raw drive and brake)


@kernel
def contacts(b, core):
    """The clock, the spawns' speed check and the vehicles off the road, the contacts
    (the kinematic world's footprints, else the pairs the world gave), the ego's
    range."""
    bo, sl, ep, cs = core.bodies, core.slots, core.episodes, core.settings
    ep.step[b] += 1
    step = ep.step[b]
    _checks(b, bo, sl.just_spawned, sl.spawn_speed, sl.off_road, core.traffic.drivers.accel,
            ep.spawn_errors, ep.spawn_error_count, ep.off_road, cs.dt,
            cs.merges)  # fmt: skip
    if cs.kinematic:
        count = overlaps(b, bo, sl.order, sl.listed, core.pairs)
        if count < 0:
            ep.overflow[b] |= PAIRS_FULL
            count = core.pairs.shape[1]
        ep.pair_count[b] = count
    _contacts(b, core, step * cs.dt)
    ego_x = bo.x[b, ep.ego[b]]
    if not cs.limit_lo <= ego_x <= cs.limit_hi and ep.ended[b] == 0:
        ep.ended[b] = EGO_LEFT
        ep.ended_x[b] = ego_x


@kernel
def leave(b, core):
    """Step 5: the windows follow the ego; visible vehicles outside are removed."""
    set_windows(b, core, core.bodies.x[b, core.episodes.ego[b]])
    despawn_outside(b, core)


@kernel
def read_windows(b, core):
    """Step 6: the recording in the windows now; relaxing vehicles back on their
    recordings handed to them."""
    ep = core.episodes
    snapshot(b, core, ep.t0[b] + ep.step[b] * core.settings.dt)
    hand_back(b, core)
    anchor.apply(b, core)


@kernel
def enter(b, core):
    """Step 7: entering vehicles spawned where there is room, the ghost set reloaded."""
    ep = core.episodes
    ep.spawned[b] += enter_and_reload(b, core)
    if core.settings.relax:  # the paper's hand-over (relax = false) keeps its ghosts
        anchor.brake_ghosts(b, core, YIELD_DECEL)
    ghost_contacts(b, core, ep.step[b] * core.settings.dt)


@kernel
def close_step(b, core):
    """The AV group's fuel, the log row, and whether the episode is over."""
    ep = core.episodes
    fuel, distance = _fuel(b, core)
    ep.fuel[b] = fuel
    ep.fuel_sum[b] += fuel
    ep.group_distance[b] += distance
    record(b, core, ep.step[b])
    anchor.decay(b, core)
    ep.done[b] = ep.step[b] >= ep.steps[b] or ep.ended[b] != 0


#: The kinematic world's step, phase by phase (names for twin bench env --profile).
PHASES = ("desired_speeds", "decisions", "move", "contacts", "leave", "read_windows",
          "enter", "close_step")  # fmt: skip


@kernel
def _checks(b, bo, just_spawned, spawn_speed, off_road, accel, errors, error_count, off_count,
            dt, spans):  # fmt: skip
    """The speed error of the vehicles spawned before the step, one step after their
    impulse (|v - max(v_spawn + a dt, 0)| / max(v_spawn, 1 m/s), ``a`` the driver's
    command up to what the powertrain gives at the spawn speed: a driver wanting more
    on a free road than the engine has is no inexact spawn, while braking harder than
    the tyres hold is; a braking vehicle slower than HOLD_SPEED may also be held at
    rest, as the physics world's static friction holds it); the vehicles off the lanes,
    each counted once: lane 0, or in lane -5's band off the on-ramps' ``spans``
    (``CoreSettings.merges``: the shoulder, whose lane is then 0)."""
    valid, speed, lane = bo.valid, bo.speed, bo.lane
    for i in range(bo.top[b]):
        if not valid[b, i]:
            continue
        if just_spawned[b, i]:
            v0 = spawn_speed[b, i]
            wanted = min(accel[b, i], drive_limit(b, i, bo, v0))
            expected = max(v0 + wanted * dt, 0.0)  # brakes hold at 0
            error = abs(speed[b, i] - expected)
            if accel[b, i] <= 0.0 and expected < HOLD_SPEED:  # or static friction holds it
                error = min(error, abs(speed[b, i]))
            k = error_count[b]
            if k < errors.shape[1]:
                errors[b, k] = error / max(v0, 1.0)
            error_count[b] = k + 1
            just_spawned[b, i] = False
        if lane[b, i] == RAMP_LANE and not on_ramp(spans, bo.x[b, i] + 0.5 * bo.length[b, i]):
            lane[b, i] = 0
        if lane[b, i] == 0 and not off_road[b, i]:
            off_road[b, i] = True
            off_count[b] += 1


@kernel
def _contacts(b, core, time):
    """The pairs now touching (``core.pairs``, slots) that were not touching at the
    last step are new contacts, counted in ``collisions`` and kept in ``collision_log``
    as (time [s], id, id) with the smaller id first, in id order."""
    ep, ids, pairs = core.episodes, core.bodies.id, core.pairs
    touching = ep.touching
    count = ep.pair_count[b]
    for k in range(count):  # as ids, smaller first
        a, c = ids[b, pairs[b, k, 0]], ids[b, pairs[b, k, 1]]
        pairs[b, k, 0], pairs[b, k, 1] = min(a, c), max(a, c)
    for k in range(1, count):  # in id order
        a, c = pairs[b, k, 0], pairs[b, k, 1]
        j = k - 1
        while j >= 0 and (pairs[b, j, 0] > a or (pairs[b, j, 0] == a and pairs[b, j, 1] > c)):
            pairs[b, j + 1, 0] = pairs[b, j, 0]
            pairs[b, j + 1, 1] = pairs[b, j, 1]
            j -= 1
        pairs[b, j + 1, 0], pairs[b, j + 1, 1] = a, c
    for k in range(count):
        a, c = pairs[b, k, 0], pairs[b, k, 1]
        if not _touched(touching, b, ep.touching_count[b], a, c):
            _new_contact(ep, b, time, a, c, _doing(b, core, _slot_of(b, core.bodies, a)),
                         _doing(b, core, _slot_of(b, core.bodies, c)), 0, math.nan)  # fmt: skip
    keep = min(count, touching.shape[1])
    for k in range(keep):
        touching[b, k, 0], touching[b, k, 1] = pairs[b, k, 0], pairs[b, k, 1]
    ep.touching_count[b] = keep


@kernel
def ghost_contacts(b, core, time):
    """The bodies whose footprints overlap a ghost's (its recorded box, along the road,
    the ghost set just reloaded: both at the step's time) that did not at the last step
    are new contacts, counted and kept as :func:`_contacts` does, the ghost second
    (GHOST_ID_BASE - its tid). Ghosts have no body: only this test sees them touch."""
    ep, bo, gh, rec = core.episodes, core.bodies, core.ghosts, core.rec
    valid, x, y, yaw, length, width, ids = (
        bo.valid, bo.x, bo.y, bo.yaw, bo.length, bo.width, bo.id
    )  # fmt: skip
    gr, gx, gy = gh.r, gh.x, gh.y
    touching = ep.ghost_touching
    n_ghosts = gh.count[b]
    if n_ghosts == 0:
        ep.ghost_touching_count[b] = 0
        return
    reach = 0.0  # the longest footprint's half diagonal, of bodies and ghosts
    for g in range(n_ghosts):
        reach = max(reach, 0.5 * (rec.length[gr[b, g]] + rec.width[gr[b, g]]))
    for i in range(bo.top[b]):
        if valid[b, i]:
            reach = max(reach, 0.5 * (length[b, i] + width[b, i]))
    before = ep.ghost_touching_count[b]
    count = 0
    for i in range(bo.top[b]):
        if not valid[b, i]:
            continue
        xi = x[b, i] + 0.5 * length[b, i]
        # ghosts sorted by back x: a ghost that may touch has its centre within two
        # reaches of xi, so its back within three
        g = _first_at(gx[b], n_ghosts, xi - 3.0 * reach)
        while g < n_ghosts and gx[b, g] <= xi + 2.0 * reach:
            r = gr[b, g]
            xg = gx[b, g] + 0.5 * rec.length[r]
            reach_ig = 0.5 * (length[b, i] + width[b, i] + rec.length[r] + rec.width[r])
            near = abs(xg - xi) <= reach_ig and abs(gy[b, g] - y[b, i]) <= reach_ig
            if near and footprints_overlap(
                xi, y[b, i], yaw[b, i], 0.5 * length[b, i], 0.5 * width[b, i],
                xg, gy[b, g], 0.0, 0.5 * rec.length[r], 0.5 * rec.width[r],
            ):  # fmt: skip
                a, c = ids[b, i], GHOST_ID_BASE - rec.tid[r]
                if not _touched(touching, b, before, a, c):
                    _new_contact(ep, b, time, a, c, _doing(b, core, i), CONTACT_GHOST,
                                 gh.lane[b, g], gh.speed[b, g])  # fmt: skip
                # this step's pairs after last step's, which are still being read
                if before + count < touching.shape[1]:
                    touching[b, before + count, 0], touching[b, before + count, 1] = a, c
                    count += 1
            g += 1
    for k in range(count):  # this step's pairs replace last step's
        touching[b, k, 0] = touching[b, before + k, 0]
        touching[b, k, 1] = touching[b, before + k, 1]
    ep.ghost_touching_count[b] = count


@kernel(inline=True)
def _touched(touching, b, count, a, c):
    """Whether pair (a, c) is among the first ``count`` of ``touching[b]``."""
    for j in range(count):  # noqa: SIM110 (a generator does not compile)
        if touching[b, j, 0] == a and touching[b, j, 1] == c:
            return True
    return False


@kernel(inline=True)
def _new_contact(ep, b, time, a, c, flags_a, flags_c, ghost_lane, ghost_speed):
    """Count a new contact of (a, c) at ``time`` [s] and keep it while the log has room
    (:data:`~twin.cosim.core.layout.CONTACT_COLUMNS`); past that, one of a pair the log
    does not hold is counted in ``collisions_unlisted`` (a pair that touches again and
    again, a body beside a ghost that straddles the line, made 81 contacts of two
    pairs, each past the log once counted as a collision of its own: 19)."""
    m = ep.collisions[b]
    log = ep.collision_log
    if m < COLLISIONS_KEPT:
        log[b, m, 0], log[b, m, 1], log[b, m, 2] = time, a, c
        log[b, m, 3], log[b, m, 4] = flags_a, flags_c
        log[b, m, 5], log[b, m, 6] = ghost_lane, ghost_speed
    elif not _listed(log, b, a, c):
        ep.collisions_unlisted[b] += 1
    ep.collisions[b] = m + 1


@kernel(inline=True)
def _listed(log, b, a, c):
    """Whether pair (a, c), smaller id first, is among the contacts the log keeps."""
    for k in range(log.shape[1]):  # noqa: SIM110 (a generator does not compile)
        if log[b, k, 1] == a and log[b, k, 2] == c:
            return True
    return False


@kernel(inline=True)
def _first_at(values, count, x):
    """The first index of sorted ``values[:count]`` at or above ``x``."""
    lo, hi = 0, count
    while lo < hi:
        mid = (lo + hi) // 2
        if values[mid] < x:
            lo = mid + 1
        else:
            hi = mid
    return lo


@kernel(inline=True)
def _slot_of(b, bo, vehicle_id):
    """The slot of body ``vehicle_id`` (-1 where none holds it)."""
    for i in range(bo.top[b]):
        if bo.valid[b, i] and bo.id[b, i] == vehicle_id:
            return i
    return -1


@kernel
def _doing(b, core, i):
    """What slot ``i`` was doing (the CONTACT_* flags; 0 for no slot): the ego, relaxing,
    changing lanes, and a change it must make (started, or sought inside its strategic
    target's zone: merging)."""
    if i < 0:
        return 0
    dr = core.traffic.drivers
    flags = 0
    if i == core.episodes.ego[b]:
        flags |= CONTACT_EGO
    if core.slots.relaxing[b, i]:
        flags |= CONTACT_RELAXING
    if dr.lane_from[b, i] != dr.lane[b, i]:
        flags |= CONTACT_CHANGING
        if dr.mandatory[b, i]:
            flags |= CONTACT_MANDATORY
    elif dr.strategic[b, i] != 0:
        centre = core.bodies.x[b, i] + 0.5 * core.bodies.length[b, i]
        if centre >= dr.strategic_from[b, i]:
            flags |= CONTACT_MANDATORY
    return flags


@kernel
def _fuel(b, core):
    """([g], [m]) the fuel of the AV and its followers over the step (the RAV4 model at
    each one's speed, measured acceleration and grade; a vehicle new in the step has no
    acceleration yet) and the distance they drove (at the mean of the speeds before and
    after)."""
    bo, ep, cs = core.bodies, core.episodes, core.settings
    valid, ids, speeds, grade = bo.valid, bo.id, bo.speed, bo.grade
    just_spawned, before, followers = core.slots.just_spawned, ep.speed_prev, ep.followers
    coefficients, dt = cs.fuel, cs.dt
    total, distance = 0.0, 0.0
    for i in range(bo.top[b]):
        if not valid[b, i]:
            continue
        mine = i == ep.ego[b]
        for k in range(ep.follower_count[b]):
            if followers[b, k] == ids[b, i]:
                mine = True
        if not mine:
            continue
        speed = max(speeds[b, i], 0.0)
        accel = 0.0 if just_spawned[b, i] else (speeds[b, i] - before[b, i]) / dt
        total += fuel_rate(coefficients, speed, accel, grade[b, i])
        if not just_spawned[b, i]:
            distance += 0.5 * (speed + max(before[b, i], 0.0)) * dt
    return total * dt, distance


@kernel
def record(b, core, step):
    """The log row of step ``step`` (when the batch keeps a log)."""
    log = core.log
    if not log.on:
        return
    bo, sl, dr = core.bodies, core.slots, core.traffic.drivers
    valid, ids, lane, x, y, z = bo.valid, bo.id, bo.lane, bo.x, bo.y, bo.z
    speed, yaw, power, r, new, accel = (
        bo.speed,
        bo.yaw,
        bo.drive_power,
        sl.r,
        sl.just_spawned,
        dr.accel,
    )
    lid, lr, llane, lx, ly, lz = log.id, log.r, log.lane, log.x, log.y, log.z
    lspeed, laccel, lyaw, lpower = log.speed, log.accel_cmd, log.yaw, log.drive_power
    for i in range(bo.top[b]):
        if not valid[b, i]:
            lid[b, step, i] = -1
            continue
        lid[b, step, i] = ids[b, i]
        lr[b, step, i] = r[b, i]
        llane[b, step, i] = lane[b, i]
        lx[b, step, i] = x[b, i]
        ly[b, step, i] = y[b, i]
        lz[b, step, i] = z[b, i]
        lspeed[b, step, i] = speed[b, i]
        laccel[b, step, i] = 0.0 if new[b, i] else accel[b, i]
        lyaw[b, step, i] = yaw[b, i]
        lpower[b, step, i] = power[b, i]
    windows = core.episodes.windows
    for k in range(4):
        log.windows[b, step, k] = windows[b, k]
    if step % log.ghost_every == 0:
        row = step // log.ghost_every
        gh = core.ghosts
        gr, glane, gx, gy, gspeed = gh.r, gh.lane, gh.x, gh.y, gh.speed
        log.ghost_count[b, row] = gh.count[b]
        for g in range(gh.count[b]):
            log.ghost_r[b, row, g] = gr[b, g]
            log.ghost_lane[b, row, g] = glane[b, g]
            log.ghost_x[b, row, g] = gx[b, g]
            log.ghost_y[b, row, g] = gy[b, g]
            log.ghost_speed[b, row, g] = gspeed[b, g]


@kernel(nrt=True)  # called from Python with the struct: counted
def step_batch(core):
    """One step of every running episode of the batch (the kinematic world)."""
    done = core.episodes.done
    for b in range(done.size):
        if done[b]:
            continue
        before_world(b, core)
        move(b, core)
        after_world(b, core)


@kernel(nrt=True)  # called from Python with the struct: counted
def phase_batch(core, phase):
    """Phase ``phase`` (an index of :data:`PHASES`) of every running episode: the
    phases in turn are one :func:`step_batch` (for timing them apart)."""
    done = core.episodes.done
    for b in range(done.size):
        if done[b]:
            continue
        if phase == 0:
            desired_speeds(b, core)
        elif phase == 1:
            decisions(b, core)
        elif phase == 2:
            move(b, core)
        elif phase == 3:
            contacts(b, core)
        elif phase == 4:
            leave(b, core)
        elif phase == 5:
            read_windows(b, core)
        elif phase == 6:
            enter(b, core)
        else:
            close_step(b, core)
