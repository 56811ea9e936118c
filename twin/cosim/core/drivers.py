"""Who drives a spawned vehicle, compiled: its driver's parameters (the paper's drivers
drawn from the class table, or the store's calibrated distributions, or its own fitted
parameters), its desired speed, its MOBIL settings, its eligibility for the HOV lane,
whether it is an AV, and its strategic targets (the recording's lane-change flows, or
its own recorded changes) as :mod:`twin.cosim.behaviour` and
:mod:`twin.cosim.strategic_targets` describe them.

Every draw is keyed by the run's seed and the vehicle's recorded trajectory (its
store ``tid``), so a vehicle gets the same driver whenever and in whatever slot it is
spawned, alone or in a batch (:mod:`twin.core.jit`); only its desired speed's floor,
the speed it is spawned at (in ``calibrated`` and ``recorded``, where the calibration
gives desired speeds), depends on the spawn.

:data:`BehaviourArrays` holds the behaviour as arrays (:func:`behaviour_arrays` makes
them from a :class:`~twin.cosim.behaviour.Behaviour`).

Over 500 lines: the spawn draws, the strategic targets and their packing as arrays;
issue 78 splits them.
"""

import math
from collections import namedtuple

import numpy as np

from twin.calibration.following import CELL, CalibrationDataError
from twin.calibration.merge_positions import MERGE_LEAD, merge_table
from twin.calibration.ramp_speeds import ramp_speed_table
from twin.core.i24 import HOV_LANE, LANE_WIDTH, N_LANES
from twin.core.jit import kernel, uniform
from twin.core.ramps import RAMP_LANE, SPAN_MARGIN
from twin.traffic.drivers import CLIP_SD
from twin.traffic.kernels.drivers import (
    clipped_normal,
    draw_driver,
    driver_table,
    first_decision,
    hov_lucky,
)
from twin.traffic.kernels.lane_change import (
    DURATION_STREAM,
    clear_target,
    path_length,
    shortest_urgent,
)
from twin.traffic.kernels.longitudinal import lane_end_gap
from twin.traffic.kernels.steering import centre_y

# The random streams of the draws made at a spawn (numpy integers: a kernel called with
# a Python int constant is compiled once per value)
BEHAVIOUR_STREAM = np.int64(0x42)
SPEED_STREAM = np.int64(0x53)
AV_STREAM = np.int64(0x41565F)
STRATEGIC_STREAM = np.int64(0x737472)
MERGE_STREAM = np.int64(0x6D7267)
RAMP_SPEED_STREAM = np.int64(0x726D73)
PAPER, CALIBRATED, RECORDED = 0, 1, 2
RECORDED_SPAN = 100.0  # [m] a recorded change's urgency grows over this distance
PLANNED_LATE = 100.0  # [m] a recorded change not started this far past its place is dropped
BIN_EVENTS = 65536  # events of one strategic draw: one per position bin
#: [m] the stretch of a lane whose mean speed is the traffic state a strategic target is
#: drawn in: the calibration's
STATE_CELL = CELL
#: [m] a vehicle spawned on an on-ramp's acceleration lane with its centre this far or
#: more inside the lane's centre line (toward lane -4), past the ramp's gore, is
#: crossing into lane -4 in its recording (a quarter of a lane: more than a driver
#: wanders inside its lane): it is spawned with that change under way (:func:`merging`)
MID_MERGE = 0.25 * LANE_WIDTH

BehaviourArrays = namedtuple(
    "BehaviourArrays",
    "mode class_v0 class_v0_sd class_time_headway class_max_accel class_hov class_group "
    "time_headway_sd_log min_gap min_gap_sd max_accel_sd_log decel decel_sd delta "
    "v0_scale time_headway_scale max_accel_scale hov_share decision_interval auto "
    "politeness threshold safe_decel keep_right dist_on dist_have dist_mean dist_matrix "
    "dist_low dist_high dist_columns desired_dim speed_source lane_speed_mean "
    "lane_speed_sd lane_speed_own fits fit_ok flows_on flow_edges flow_left flow_right "
    "flow_lanes flow_states "
    "plan_start plan_x plan_time plan_from plan_to hov_openings merge_q merge_x ramp_speeds",
)


# -- a spawned vehicle's driver -------------------------------------------------------------


@kernel
def init_driver(b, i, core, seed, key, r, vehicle_class, lane, time, speed):
    """Slot ``i``'s driver for recorded trajectory ``r`` (store tid ``key``) of
    ``vehicle_class``, spawned in ``lane`` at the manager's clock ``time`` moving at
    ``speed`` [m/s] (its recording's)."""
    beh, slots, drivers = core.beh, core.slots, core.traffic.drivers
    model, vel_default = core.traffic.settings.model, core.settings.vel_default
    c = vehicle_class
    draw_driver(beh, model, drivers.cf[b, i], seed, key, c)  # the class table's traits
    lucky = hov_lucky(beh, seed, key)
    drivers.hov_eligible[b, i] = lane == HOV_LANE or (beh.class_hov[c] and lucky)
    drivers.next_decision[b, i] = time + first_decision(beh, seed, key)
    drivers.politeness[b, i] = beh.politeness
    drivers.threshold[b, i] = beh.threshold
    drivers.safe_decel[b, i] = beh.safe_decel
    drivers.keep_right[b, i] = beh.keep_right
    drivers.auto[b, i] = beh.auto
    desired = vel_default
    if beh.mode != PAPER:
        desired = _behaviour_drivers(b, i, core, seed, key, r, c, lane)
        if lane != RAMP_LANE and beh.speed_source != 0:
            desired = max(desired, speed)  # no less than it was seen to drive
    slots.base_speed[b, i] = desired
    drivers.cf[b, i, 0] = desired
    drivers.key[b, i] = key
    drivers.lane[b, i] = lane
    drivers.lane_from[b, i] = lane
    drivers.start_x[b, i] = 0.0
    drivers.start_y[b, i] = (0.5 - lane) * LANE_WIDTH
    drivers.path_length[b, i] = 1.0
    drivers.decisions[b, i] = 0
    drivers.changes[b, i] = 0
    drivers.requested[b, i] = 0
    drivers.mandatory[b, i] = False
    drivers.offset[b, i] = 0.0
    clear_target(drivers.strategic, drivers.strategic_from, drivers.strategic_by, b, i)
    drivers.accel[b, i] = 0.0
    drivers.ctrl[b, i] = 0


@kernel(inline=True)
def _behaviour_drivers(b, i, core, seed, key, r, c, lane):
    """The calibrated (or recorded) parameters of slot ``i``'s driver; returns its own
    desired speed [m/s] (:meth:`twin.cosim.behaviour.Behaviour.drivers`)."""
    beh, drivers, vel_default = core.beh, core.traffic.drivers, core.settings.vel_default
    desired = vel_default
    own = beh.mode == RECORDED and beh.fit_ok[r]  # its own fit (recorded)
    if beh.dist_on:
        group = beh.class_group[c]
        if not beh.dist_have[group]:
            group = 0
        k = beh.dist_columns.size
        for d in range(k):
            if own:
                value = beh.fits[r, d]
            else:
                log = beh.dist_mean[group, d]
                for j in range(k):
                    log += beh.dist_matrix[group, d, j] * clipped_normal(
                        seed, BEHAVIOUR_STREAM, key, j
                    )
                log = min(max(log, beh.dist_low[group, d]), beh.dist_high[group, d])
                value = math.exp(log)
            if d == beh.desired_dim:
                if beh.speed_source == 2:
                    desired = value
            else:
                drivers.cf[b, i, beh.dist_columns[d]] = value
    k = min(-lane - 1, 3)  # an on-ramp's driver: lane -4's
    # free-flow speeds: every lane's, or, where desired speeds come from the fits, those
    # of a lane with free-flow speeds of its own (a drawn driver's, not a vehicle's own fit)
    drawn_fit = beh.speed_source == 2 and not own
    if beh.speed_source == 1 or (drawn_fit and beh.lane_speed_own[k]):
        z = clipped_normal(seed, SPEED_STREAM, key, np.int64(0))
        desired = max(beh.lane_speed_mean[k] + beh.lane_speed_sd[k] * z, 1.0)
    return desired


@kernel(inline=True)
def is_av(seed, key, share):
    """Whether recorded vehicle ``key`` is an AV at ``share`` (one draw per vehicle)."""
    return share > 0.0 and uniform(seed, AV_STREAM, key, np.int64(0)) < share


# -- strategic targets -----------------------------------------------------------------------


@kernel
def first_target(b, i, core, seed, x):
    """Slot ``i``'s first strategic target once spawned at back x [m]; its recorded
    changes are those of the episode's time span."""
    beh, slots, drivers, ep = core.beh, core.slots, core.traffic.drivers, core.episodes
    time_from = ep.t0[b]
    time_to = ep.t0[b] + ep.steps[b] * core.settings.dt
    slots.tgt_on[b, i] = True
    slots.tgt_draws[b, i] = 0
    slots.plan_next[b, i] = 0
    slots.plan_end[b, i] = 0
    if beh.mode == RECORDED:
        r = slots.r[b, i]
        a, e = beh.plan_start[r], beh.plan_start[r + 1]
        first = e
        for k in range(a, e):
            if beh.plan_x[k] > x - 0.5 * PLANNED_LATE and time_from <= beh.plan_time[k] <= time_to:
                first = k
                break
        slots.plan_next[b, i], slots.plan_end[b, i] = first, e
    next_target(b, i, core, seed, drivers.lane[b, i], x, time_from, time_to)


@kernel
def merge_target(b, i, core, seed, x):
    """Slot ``i``, spawned at back x [m] on an on-ramp's acceleration lane (lane -5),
    must merge left by its merge place: the recording's (``recorded``: its own, where
    its recording merges there; else a quantile of the ramp's recorded merges drawn for
    the vehicle, ``BehaviourArrays.merge_q``; without them, the taper's start), kept
    between the ramp's gore and its end; it wants the merge from MERGE_LEAD metres
    before (not before the gore; :mod:`twin.calibration.merge_positions`). Its lane
    ends at the taper's end (:func:`twin.traffic.kernels.longitudinal.lane_end_gap`);
    past every ramp's end (none is), it wants it at once. ``CoreSettings.merges`` rows:
    (opening, gore, taper start, end) [m]; places compare with its centre."""
    drivers, merges, beh, slots = core.traffic.drivers, core.settings.merges, core.beh, core.slots
    half = 0.5 * core.bodies.length[b, i]
    x_from, x_by = x + half, x + half
    for k in range(merges.shape[0]):
        if x > merges[k, 3]:
            continue
        gore, taper, end = merges[k, 1], merges[k, 2], merges[k, 3]
        place = taper
        own = beh.merge_x[slots.r[b, i]] if beh.mode == RECORDED else math.nan
        row = _merge_row(beh.merge_q, end)
        if gore - SPAN_MARGIN <= own <= end + SPAN_MARGIN:
            place = own + half
        elif row >= 0:
            u = uniform(seed, MERGE_STREAM, slots.tid[b, i], 0)
            place = _quantile(beh.merge_q, row, u) + half
        x_by = min(max(place, gore), end)
        x_from = max(x_by - MERGE_LEAD, gore)
        break
    drivers.strategic[b, i] = 1  # LEFT
    drivers.strategic_from[b, i] = x_from
    drivers.strategic_by[b, i] = x_by


@kernel(inline=True)
def ramp_speed(b, i, core, seed):
    """The speed [m/s] slot ``i``'s driver wants on the on-ramp's acceleration lane it is
    on, or NaN where it wants its own there: a draw per driver from the free-flow speeds
    the recording's drivers drove on that ramp's lane (``BehaviourArrays.ramp_speeds``,
    :mod:`twin.calibration.ramp_speeds`; normal, clipped as every trait is, at least 1
    m/s), for a driver of a calibrated or recorded behaviour (its own desired speed again
    once its merge has begun: the caller asks only on lane -5). The ramp is the one
    whose lane holds its back x, as the calibration placed the samples
    (``CoreSettings.merges`` rows: (opening, gore, taper start, end) [m]); the draw is
    the same at every step (the seed, its key, one event)."""
    beh, merges = core.beh, core.settings.merges
    table = beh.ramp_speeds
    if beh.mode == PAPER or table.shape[0] == 0:
        return math.nan
    x = core.bodies.x[b, i]
    for k in range(merges.shape[0]):
        if not merges[k, 0] - SPAN_MARGIN <= x <= merges[k, 3] + SPAN_MARGIN:
            continue
        row = _merge_row(table, merges[k, 3])
        if row < 0:
            return math.nan
        z = clipped_normal(seed, RAMP_SPEED_STREAM, core.traffic.drivers.key[b, i], np.int64(0))
        return max(table[row, 1] + table[row, 2] * z, 1.0)
    return math.nan


@kernel(inline=True)
def crossing(core, centre_x, y):
    """Whether a vehicle on an on-ramp's acceleration lane (lane -5) at centre x, y [m]
    is crossing into lane -4 in its recording: :data:`MID_MERGE` inside its lane's
    centre, between the ramp's gore and just past its end (``CoreSettings.merges``)."""
    if centre_y(np.int64(RAMP_LANE)) - y < MID_MERGE:
        return False
    merges = core.settings.merges
    for k in range(merges.shape[0]):
        if merges[k, 1] <= centre_x <= merges[k, 3] + SPAN_MARGIN:
            return True
    return False


@kernel
def merging(b, i, core, seed, x, y):
    """Slot ``i``, spawned at back x, y [m] on an on-ramp's acceleration lane where its
    recording crosses into lane -4 (:func:`crossing`), goes on with that change: a
    merge under way from where it is, not pulled back to its lane's centre first (near
    the taper's end that pull-back made it cross past the end). Its path is the share of
    an urgent merge's (:func:`twin.traffic.kernels.lane_change.path_length`, drawn as
    the traffic manager draws one, no longer than twice the distance to where its lane
    ends) that the crossing still has ahead; its merge target is met."""
    drivers, ts, bo = core.traffic.drivers, core.traffic.settings, core.bodies
    draw = uniform(seed, DURATION_STREAM, drivers.key[b, i], drivers.changes[b, i])
    drivers.changes[b, i] += 1
    duration = ts.lane_change_low + (ts.lane_change_high - ts.lane_change_low) * draw
    length = bo.length[b, i]
    whole = path_length(max(bo.speed[b, i], 0.0), duration, True, ts.urgent_path, length)
    end = lane_end_gap(ts.lane_ends, np.int64(RAMP_LANE), x, length)
    if math.isfinite(end):
        whole = min(whole, max(2.0 * end, shortest_urgent(ts.urgent_path, length)))
    target = np.int64(-N_LANES)
    ahead = min(max((y - centre_y(target)) / LANE_WIDTH, 0.0), 1.0)
    drivers.lane_from[b, i], drivers.lane[b, i] = RAMP_LANE, target
    drivers.start_x[b, i] = x + 0.5 * length
    drivers.start_y[b, i] = y
    drivers.path_length[b, i] = max(ahead * whole, 1.0)
    drivers.mandatory[b, i] = True
    drivers.requested[b, i] = 0
    clear_target(drivers.strategic, drivers.strategic_from, drivers.strategic_by, b, i)


@kernel(inline=True)
def _merge_row(table, end):
    """The row of ``table`` (``merge_q``, ``ramp_speeds``: a ramp's taper's end first)
    of the ramp whose taper ends at ``end`` [m], or -1."""
    for k in range(table.shape[0]):
        if abs(table[k, 0] - end) < 1.0:
            return k
    return -1


@kernel(inline=True)
def _quantile(table, row, u):
    """The place at quantile ``u`` in [0, 1) of ``merge_q`` row ``row`` (linear between
    its quantiles)."""
    q = table.shape[1] - 1
    pos = u * (q - 1)
    j = min(int(pos), q - 2)
    w = pos - j
    return (1.0 - w) * table[row, 1 + j] + w * table[row, 2 + j]


@kernel
def update_targets(b, core):
    """At a decision step: the next target of each vehicle whose target is done (its
    change started and finished) or given up."""
    beh, slots, drivers, ep = core.beh, core.slots, core.traffic.drivers, core.episodes
    valid, x = core.bodies.valid, core.bodies.x
    seed = ep.seed[b]
    time_from = ep.t0[b]
    time_to = ep.t0[b] + ep.steps[b] * core.settings.dt
    tgt_on, plan_next, plan_end, tgt_lane = (
        slots.tgt_on,
        slots.plan_next,
        slots.plan_end,
        slots.tgt_lane,
    )
    strategic, lanes, lane_from = drivers.strategic, drivers.lane, drivers.lane_from
    for i in range(core.bodies.top[b]):
        if not valid[b, i] or not tgt_on[b, i]:
            continue
        if strategic[b, i] != 0 or lane_from[b, i] != lanes[b, i]:
            continue
        lane = lanes[b, i]
        recorded = beh.mode == RECORDED
        due = plan_next[b, i] < plan_end[b, i] if recorded else lane != tgt_lane[b, i]
        if due:
            next_target(b, i, core, seed, lane, x[b, i], time_from, time_to)


@kernel
def next_target(b, i, core, seed, lane, x, time_from, time_to):
    """Draw (or read from the recording) slot ``i``'s next target from ``lane`` at back
    x [m], and set it where the rules allow the change."""
    beh, slots, drivers = core.beh, core.slots, core.traffic.drivers
    if lane < -4:  # on an on-ramp's lane its target is the merge (merge_target); the
        slots.tgt_lane[b, i] = lane  # next is drawn, or read, in lane -4
        return
    if beh.mode == RECORDED:
        direction, x_from, x_by = _recorded(b, i, core, lane, x, time_from, time_to)
    else:
        direction, x_from, x_by = _draw(b, i, core, seed, lane, x)
    slots.tgt_lane[b, i] = lane
    if direction == 0:
        return
    target = lane + direction
    if not -4 <= target <= -1:
        return
    if target == HOV_LANE and not drivers.hov_eligible[b, i]:
        return
    if (target == HOV_LANE or lane == HOV_LANE) and beh.hov_openings.shape[0] == 0:
        return
    drivers.strategic[b, i] = direction
    drivers.strategic_from[b, i] = x_from
    drivers.strategic_by[b, i] = x_by


@kernel(inline=True)
def _draw(b, i, core, seed, lane, x):
    """(direction, x_from, x_by) drawn from the flows for slot ``i`` in ``lane`` at back
    x, in the traffic state around it, or (0, nan, nan)."""
    beh, slots = core.beh, core.slots
    slots.tgt_draws[b, i] += 1
    if not beh.flows_on:
        return 0, math.nan, math.nan
    speed = lane_speed(b, core.traffic, lane, x) if beh.flow_states.size else math.inf
    return draw_target(seed, slots.tid[b, i], slots.tgt_draws[b, i], lane, x, speed,
                       beh.flow_edges, beh.flow_left, beh.flow_right, beh.flow_lanes,
                       beh.flow_states)  # fmt: skip


@kernel(inline=True)
def lane_speed(b, traffic, lane, x):
    """[m/s] the mean speed of ``lane`` within half a :data:`STATE_CELL` of back x [m],
    over the simulated vehicles and the recording's ghosts there (the traffic state a
    strategic target is drawn in; inf where the lane is empty, as free as it gets)."""
    vehicles, ghosts = traffic.vehicles, traffic.obstacles
    half = 0.5 * STATE_CELL
    total, n = 0.0, 0
    for j in range(vehicles.top[b]):
        here = vehicles.lane[b, j] == lane and abs(vehicles.x[b, j] - x) <= half
        if vehicles.valid[b, j] and here:
            total += vehicles.speed[b, j]
            n += 1
    for j in range(ghosts.count[b]):
        if ghosts.lane[b, j] == lane and abs(ghosts.x[b, j] - x) <= half:
            total += ghosts.speed[b, j]
            n += 1
    return total / n if n > 0 else math.inf


@kernel
def draw_target(seed, key, draws, lane, x, speed, edges, left, right, lanes, states):
    """A strategic target drawn from the recording's flows (the ``calibrated``
    behaviour): the vehicle of record ``key`` in ``lane`` at back x [m], whose lane
    moves at ``speed`` [m/s] around it, passes the position bins (``edges``) ahead of it
    and, in each, leaves its lane left or right with the flows' probabilities in that
    traffic state (``left``, ``right``: (states, 4, bins), per lane -1..-4; the state is
    the number of ``states`` speeds [m/s] at or below ``speed``; ``lanes`` (4,) bool
    where the lane has flows); its target is the first bin drawn, wanted from half a bin
    before it to the bin's end. ``draws``: how many targets it has drawn, this one
    included (a vehicle draws again in the lane it changed to).
    Returns (direction, x_from, x_by), or (0, nan, nan)."""
    k = -lane - 1
    if not 0 <= k < lanes.size or not lanes[k]:
        return 0, math.nan, math.nan
    s = 0
    while s < states.size and states[s] <= speed:
        s += 1
    bins = edges.size - 1
    first = 0  # the bins starting ahead of x
    while first <= bins and edges[first] <= x:
        first += 1
    half = 0.5 * (edges[1] - edges[0])
    for j in range(first, bins):
        u = uniform(seed, STRATEGIC_STREAM, key, draws * BIN_EVENTS + j)
        p_left, p_right = left[s, k, j], right[s, k, j]
        if u < p_left + p_right:
            return (1 if u < p_left else -1), edges[j] - half, edges[j + 1]
    return 0, math.nan, math.nan


def flow_arrays(flows: dict | None) -> tuple:
    """(edges, left, right, lanes, states) of the recording's strategic flows
    (``calibration.json``'s ``lane_flows``) for :func:`draw_target`: per traffic state
    where the calibration has them (``probability_by_state``), else one state."""
    if flows is None:
        return np.zeros(2), np.zeros((1, 4, 1)), np.zeros((1, 4, 1)), np.zeros(4, bool), np.zeros(0)
    edges = np.asarray(flows["x_edges"], dtype=np.float64)
    conditioned = "states" in flows and all(
        "probability_by_state" in s for s in flows["strategic"].values()
    )
    names = flows["states"]["names"] if conditioned else [None]
    states = np.asarray(flows["states"]["speeds"] if conditioned else [], dtype=np.float64)
    if states.size != len(names) - 1 or np.any(np.diff(states) <= 0):
        raise CalibrationDataError(
            "calibration: lane_flows.states needs one speed fewer than names, increasing; "
            f"got names {names}, speeds {states.tolist()}"
        )
    shape = (len(names), 4, edges.size - 1)
    left, right = np.zeros(shape), np.zeros(shape)
    lanes = np.zeros(4, bool)
    for s, name in enumerate(names):
        for lane, (pl, pr) in flow_probabilities(flows, edges.size - 1, name).items():
            left[s, -lane - 1], right[s, -lane - 1] = pl, pr
            lanes[-lane - 1] = True
    return edges, left, right, lanes, states


@kernel(inline=True)
def _recorded(b, i, core, lane, x, time_from, time_to):
    """Slot ``i``'s next recorded change that starts from ``lane`` and is not already
    far behind it, as (direction, x_from, x_by), or (0, nan, nan)."""
    beh, slots = core.beh, core.slots
    while slots.plan_next[b, i] < slots.plan_end[b, i]:
        k = slots.plan_next[b, i]
        slots.plan_next[b, i] += 1
        if not time_from <= beh.plan_time[k] <= time_to:
            continue
        if beh.plan_from[k] == lane and x <= beh.plan_x[k] + RECORDED_SPAN:
            direction = 1 if beh.plan_to[k] > beh.plan_from[k] else -1
            return direction, beh.plan_x[k], beh.plan_x[k] + RECORDED_SPAN
    return 0, math.nan, math.nan


# -- the arrays of a behaviour ---------------------------------------------------------------


def behaviour_arrays(behaviour, traffic_config, recording, plan=None) -> BehaviourArrays:
    """The arrays of ``behaviour`` (a :class:`~twin.cosim.behaviour.Behaviour`) for
    drivers of ``traffic_config`` (a :class:`~twin.traffic.config.TrafficConfig`) on
    ``recording`` (:class:`~twin.data.recording.RecordingArrays`); ``plan``: the
    recording's lane changes (:func:`twin.cosim.core.recorded_plan`), for ``recorded``."""
    from twin.calibration.distributions import CLASS_GROUPS
    from twin.core.vehicle_classes import vehicle_classes
    from twin.traffic.models import car_following_model

    classes = vehicle_classes()
    dist = traffic_config.drivers
    mobil = traffic_config.mobil
    model = car_following_model(traffic_config.car_following)
    mode = {"paper": PAPER, "calibrated": CALIBRATED, "recorded": RECORDED}[behaviour.name]
    group_of_class = np.zeros(len(classes.frame), np.int64)
    for g, name in enumerate(("car", "truck"), start=1):
        group_of_class[list(CLASS_GROUPS[name])] = g
    names = model.names
    fitted = tuple(p.name for p in model.fitted)
    k = len(fitted)
    mean, matrix = np.zeros((3, k)), np.zeros((3, k, k))
    low, high, have = np.zeros((3, k)), np.zeros((3, k)), np.zeros(3, bool)
    for g, name in enumerate(("all", "car", "truck")):
        d = behaviour.distributions.get(name)
        if d is None:
            continue
        order = [d.names.index(f) for f in fitted]
        cov = d.correlation * np.outer(d.sd_log, d.sd_log)
        w, vectors = np.linalg.eigh(cov)
        full = vectors * np.sqrt(np.maximum(w, 0.0))[None, :]
        mean[g] = d.mean_log[order]
        matrix[g] = full[order]
        low[g] = (d.mean_log - CLIP_SD * d.sd_log)[order]
        high[g] = (d.mean_log + CLIP_SD * d.sd_log)[order]
        have[g] = True
    source = {"paper": 0, "free_flow": 1, "car_following": 2}.get(behaviour.speed_source, 0)
    if mode == PAPER:
        source = 0
    speeds = behaviour.speeds or {}
    lane_mean, lane_sd, lane_own = np.zeros(4), np.zeros(4), np.zeros(4, bool)
    for j, lane in enumerate((-1, -2, -3, -4)):
        entry = speeds.get(str(lane)) or speeds.get("all")
        if entry:
            lane_mean[j], lane_sd[j] = entry["mean"], entry["sd"]
        lane_own[j] = str(lane) in speeds
    fits, fit_ok = np.zeros((recording.tid.size, k)), np.zeros(recording.tid.size, bool)
    if behaviour._fits is not None and len(behaviour._fits):
        table = behaviour._fits
        local = np.full(int(recording.tid.max(initial=-1)) + 1, -1, np.int64)
        local[np.asarray(recording.tid)] = np.arange(recording.tid.size)
        tids = table.index.to_numpy()
        inside = tids < local.size
        r = local[tids[inside]]
        ok = r >= 0
        fits[r[ok]] = table.loc[tids[inside][ok], list(fitted)].to_numpy()
        fit_ok[r[ok]] = True
    flows = behaviour.strategic_flows
    edges, left, right, lanes, states = flow_arrays(flows)
    plan = plan if plan is not None else empty_plan(recording.tid.size)
    # the draw's fields, as the traffic manager's (one builder)
    table = driver_table(dist, classes, traffic_config.hov_share, traffic_config.decision_interval)
    return BehaviourArrays(
        mode=mode,
        **table._asdict(),
        class_hov=classes.column("hov_allowed").astype(np.int64) == 1,
        class_group=group_of_class,
        auto=bool(traffic_config.auto_lane_change and behaviour.auto_lane_change),
        politeness=float(
            mobil.politeness if behaviour.politeness is None else behaviour.politeness
        ),
        threshold=float(mobil.threshold if behaviour.threshold is None else behaviour.threshold),
        safe_decel=float(mobil.safe_decel), keep_right=float(mobil.keep_right),
        dist_on=bool(behaviour.distributions), dist_have=have, dist_mean=mean,
        dist_matrix=matrix, dist_low=low, dist_high=high,
        dist_columns=np.array([names.index(f) for f in fitted], np.int64),
        desired_dim=fitted.index("desired_speed"), speed_source=source,
        lane_speed_mean=lane_mean, lane_speed_sd=lane_sd, lane_speed_own=lane_own, fits=fits,
        fit_ok=fit_ok,
        flows_on=flows is not None, flow_edges=edges, flow_left=left, flow_right=right,
        flow_lanes=lanes, flow_states=states, plan_start=plan["start"], plan_x=plan["x"],
        plan_time=plan["time"], plan_from=plan["lane_from"], plan_to=plan["lane_to"],
        hov_openings=np.array(traffic_config.hov_openings, np.float64).reshape(-1, 2),
        merge_q=merge_table(behaviour.merges), merge_x=plan["merge_x"],
        ramp_speeds=ramp_speed_table(behaviour.ramp_speeds),
    )  # fmt: skip


def empty_plan(trajectories: int) -> dict:
    """No recorded lane changes for ``trajectories`` trajectories."""
    return {
        "start": np.zeros(trajectories + 1, np.int64),
        "x": np.zeros(0),
        "time": np.zeros(0),
        "lane_from": np.zeros(0, np.int64),
        "lane_to": np.zeros(0, np.int64),
        "merge_x": np.full(trajectories, np.nan),
    }


def flow_probabilities(flows: dict, n_bins: int, state: str | None = None) -> dict:
    """{lane: (p_left, p_right)}, (bins,) each: the probability that a vehicle passing a
    bin in the lane leaves it that way for a strategic reason (in traffic ``state``, one
    of the flows' ``states`` names; None: pooled over the states)."""
    out = {}
    for name, s in flows["strategic"].items():
        a, b = (int(v) for v in name.split(">"))
        p = s["probability"] if state is None else s["probability_by_state"].get(state)
        if p is None:
            raise CalibrationDataError(
                f"calibration: lane_flows.strategic[{name!r}] has no probability for the "
                f"traffic state {state!r}"
            )
        p = np.asarray(p, dtype=np.float64)
        if p.shape != (n_bins,):
            raise CalibrationDataError(
                f"calibration: lane_flows.strategic[{name!r}] has {p.size} probabilities for "
                f"{n_bins} position bins"
            )
        left, right = out.setdefault(a, (np.zeros(n_bins), np.zeros(n_bins)))
        (left if b > a else right)[:] += p
    for left, right in out.values():  # never more than certainty between the two
        total = left + right
        scale = np.where(total > 1.0, 1.0 / np.maximum(total, 1e-12), 1.0)
        left *= scale
        right *= scale
    return out
