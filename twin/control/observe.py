"""What the wave-dampening environment returns each step, compiled over a batch of
episodes: the AV's observation, its reward, whether it collided, and the episode's
running figures (its metrics at the end), read from the batched core's state after
the step (:mod:`twin.cosim.core`).

The observation (:data:`twin.control.env.OBSERVATION`) is the AV's own speed and
measured acceleration; the gap (bumper to bumper) to and speed of its leader and its
follower in the lane it drives to (vehicles of the window occupying that lane, and the
ghosts of it; a gap of :data:`GAP_CAP` and its own speed where nobody is within it);
and the recorded mean speeds ahead of it per lane in three bins (the recording at the
same time, as a connected vehicle could be told; the run's ``vel_default`` where
nobody is recorded). The reward is minus the fuel [g] of the AV and its followers over
the step (weighted), minus a penalty when its time gap exceeds ``gap_max`` and one when
its time to collision is under ``ttc_min``.

The figures accumulate per control step in ``stats`` (B, :data:`STATS`): distances and
fuel of the AV and of the AV with its followers, the AV's speed error against its
recording, its least time to collision, its acceleration and jerk, the return.
"""

import math

import numpy as np

from twin.core.i24 import MILE, N_LANES
from twin.core.jit import kernel
from twin.core.ramps import lane_of_y
from twin.data.recording import replay, window
from twin.metrics.collisions import count_collisions
from twin.metrics.economy import GRAMS_PER_GALLON

GAP_CAP = 200.0  # [m] gaps are reported up to this
AHEAD_EDGES = (0.0, 200.0, 400.0, 600.0)  # [m] downstream of the AV, the bins' edges
N_BINS = 4 * (len(AHEAD_EDGES) - 1)  # the lanes' bins ahead: o[6:6 + N_BINS]
N_OBS = 6 + N_BINS
SNAPSHOT_ROWS = 4096  # recorded vehicles a query of the road ahead holds
#: The running figures' columns.
STATS = (
    "ego_distance_m", "speed_error_sq", "samples", "min_ttc_s", "accel_sq", "jerk_sq",
    "last_accel", "return", "last_x", "fuel_seen_g", "steps",
)  # fmt: skip
(EGO_DIST, SPEED_SQ, SAMPLES, MIN_TTC, ACCEL_SQ, JERK_SQ, LAST_ACCEL, RETURN, LAST_X,
 FUEL_SEEN, STEPS) = range(len(STATS))  # fmt: skip


@kernel(nrt=True)  # called from Python with the struct: counted
def observe_batch(core, done_before, obs, reward, collided, stats, weights, low, high,
                  control_dt, first, snap_r, snap_x, snap_y, snap_v, bins):  # fmt: skip
    """After a control step (``first``: after the reset): each running episode's
    observation (B, N_OBS), clipped to ``low``/``high``; its reward (B,) with
    ``weights`` (fuel [1/g], gap, gap_max [s], ttc, ttc_min [s]); whether its AV
    collided in the step (B,); its running ``stats`` (B, STATS). ``done_before`` (B,)
    the episodes that were over before the step (left as they are); ``snap_*`` working
    arrays of a recording query, ``bins`` (2 N_BINS,) of the speeds ahead."""
    ep = core.episodes
    for b in range(ep.done.size):
        if done_before[b] and not first[b]:
            continue
        _observe(b, core, obs, reward, collided, stats, weights, low, high, control_dt,
                 first[b], snap_r, snap_x, snap_y, snap_v, bins)  # fmt: skip


@kernel
def _observe(b, core, obs, reward, collided, stats, weights, low, high, control_dt, first,
             snap_r, snap_x, snap_y, snap_v, bins):  # fmt: skip
    bo, ep, cs = core.bodies, core.episodes, core.settings
    dr, gh = core.traffic.drivers, core.ghosts
    valid, x, lanes, speeds, length, ids = bo.valid, bo.x, bo.lane, bo.speed, bo.length, bo.id
    e = ep.ego[b]
    ego_x, ego_len = x[b, e], length[b, e]
    speed = max(speeds[b, e], 0.0)
    lane = dr.lane[b, e]
    st = stats[b]
    if first:
        for k in range(st.size):
            st[k] = 0.0
        st[MIN_TTC] = math.inf
        st[LAST_X] = ego_x
        accel = 0.0
    else:
        accel = (speeds[b, e] - ep.speed_prev_control[b]) / control_dt
    ep.speed_prev_control[b] = speeds[b, e]
    # the leader and the follower in the lane the AV drives to
    lead_gap, lead_speed, follow_gap, follow_speed = math.inf, speed, math.inf, speed
    for i in range(bo.top[b]):
        if not valid[b, i] or i == e:
            continue
        if not (dr.lane[b, i] == lane or dr.lane_from[b, i] == lane or lanes[b, i] == lane):
            continue
        if x[b, i] > ego_x:
            gap = x[b, i] - ego_x - ego_len
            if gap < lead_gap:
                lead_gap, lead_speed = gap, max(speeds[b, i], 0.0)
        elif x[b, i] < ego_x:
            gap = ego_x - x[b, i] - length[b, i]
            if gap < follow_gap:
                follow_gap, follow_speed = gap, max(speeds[b, i], 0.0)
    for g in range(gh.count[b]):
        if gh.lane[b, g] != lane:
            continue
        if gh.x[b, g] > ego_x:
            gap = gh.x[b, g] - ego_x - ego_len
            if gap < lead_gap:
                lead_gap, lead_speed = gap, gh.speed[b, g]
        elif gh.x[b, g] < ego_x:
            gap = ego_x - gh.x[b, g] - gh.length[b, g]
            if gap < follow_gap:
                follow_gap, follow_speed = gap, gh.speed[b, g]
    o = obs[b]
    o[0], o[1] = speed, accel
    o[2], o[3] = min(lead_gap, GAP_CAP), lead_speed
    o[4], o[5] = min(follow_gap, GAP_CAP), follow_speed
    _ahead(b, core, ego_x, o, snap_r, snap_x, snap_y, snap_v, bins)
    for k in range(N_OBS):
        o[k] = min(max(o[k], low[k]), high[k])
    # the figures and the reward of the step
    time = ep.t0[b] + ep.step[b] * cs.dt
    fuel = ep.fuel_sum[b] - st[FUEL_SEEN]
    st[FUEL_SEEN] = ep.fuel_sum[b]
    r = 0.0
    if not first:
        st[EGO_DIST] += ego_x - st[LAST_X]
        st[STEPS] += 1.0
        jerk = (accel - st[LAST_ACCEL]) / control_dt
        st[ACCEL_SQ] += accel * accel
        st[JERK_SQ] += jerk * jerk
        r = -weights[0] * fuel
        if math.isfinite(lead_gap) and speed > 1.0 and lead_gap / speed > weights[2]:
            r -= weights[1]
        closing = speed - lead_speed
        if math.isfinite(lead_gap) and closing > 0.0:
            ttc = lead_gap / closing
            st[MIN_TTC] = min(st[MIN_TTC], ttc)
            if ttc < weights[4]:
                r -= weights[3]
        st[RETURN] += r
    st[LAST_X] = ego_x
    st[LAST_ACCEL] = accel
    present, _, _, rec_v = replay(core.rec, ep.ego_r[b], time)
    if present:
        st[SPEED_SQ] += (speeds[b, e] - rec_v) ** 2
        st[SAMPLES] += 1.0
    reward[b] = r
    collided[b] = _ego_collided(b, core, ids[b, e])


@kernel(inline=True)
def _ahead(b, core, ego_x, o, snap_r, snap_x, snap_y, snap_v, bins):
    """The recorded mean speed per lane -1..-4 in each bin ahead (o[6:6 + N_BINS]); ``bins``
    (2 N_BINS,) holds the sums and counts."""
    t = core.episodes.t0[b] + core.episodes.step[b] * core.settings.dt
    n = window(core.rec, t, ego_x, ego_x + AHEAD_EDGES[3], snap_r, snap_x, snap_y, snap_v)
    sums, counts = bins[:N_BINS], bins[N_BINS:]
    for j in range(2 * N_BINS):
        bins[j] = 0.0
    for k in range(max(n, 0)):
        lane = lane_of_y(snap_y[k])
        if not -N_LANES <= lane <= -1:  # off the lanes, or on an on-ramp
            continue
        d = snap_x[k] - ego_x
        for j in range(3):
            if AHEAD_EDGES[j] <= d < AHEAD_EDGES[j + 1]:
                sums[3 * (-lane - 1) + j] += snap_v[k]
                counts[3 * (-lane - 1) + j] += 1.0
    for j in range(N_BINS):
        o[6 + j] = sums[j] / counts[j] if counts[j] > 0 else core.settings.vel_default


@kernel(inline=True)
def _ego_collided(b, core, ego_id):
    """Whether the AV is in a collision that began since the last call (the collisions
    kept; past COLLISIONS_KEPT, the pairs touching now)."""
    ep = core.episodes
    hit = False
    kept = ep.collision_log.shape[1]
    for k in range(ep.collisions_before[b], ep.collisions[b]):
        if k < kept:
            hit |= ep.collision_log[b, k, 1] == ego_id or ep.collision_log[b, k, 2] == ego_id
        else:
            for j in range(ep.touching_count[b]):
                hit |= ep.touching[b, j, 0] == ego_id or ep.touching[b, j, 1] == ego_id
    ep.collisions_before[b] = ep.collisions[b]
    return hit


def work_arrays() -> tuple:
    """The working arrays :func:`observe_batch` takes after ``first``: a recording
    query's (``snap_r``, ``snap_x``, ``snap_y``, ``snap_v``) and ``bins``."""
    query = (np.empty(SNAPSHOT_ROWS, t) for t in (np.int32, float, float, float))
    return (*query, np.empty(2 * N_BINS))


def collision_pairs(core_state, b: int) -> int:
    """Episode ``b``'s collisions: the pairs of bodies that touched, however often
    (:mod:`twin.metrics.collisions`); each contact past the first COLLISIONS_KEPT of a
    pair not among them counts as one."""
    ep = core_state.episodes
    kept = min(int(ep.collisions[b]), ep.collision_log.shape[1])
    return count_collisions(ep.collision_log[b, :kept], int(ep.collisions_unlisted[b]))


def metrics(stats: np.ndarray, core_state, b: int, dt: float) -> dict:
    """The figures of episode ``b`` so far (the env's ``info["metrics"]``): the names of
    :mod:`twin.metrics.table` where a figure is one of its metrics."""
    st = stats[b]
    ep, counters = core_state.episodes, core_state.counters
    group_fuel = float(ep.fuel_sum[b])
    group_distance = float(ep.group_distance[b])

    def mpg(distance, fuel):
        return round(distance / MILE / (fuel / GRAMS_PER_GALLON), 4) if fuel > 0 else None

    steps = max(float(st[STEPS]), 1.0)
    return {
        "simulated_s": round(float(ep.step[b]) * dt, 6),
        "ego_speed_rmse_mps": round(math.sqrt(st[SPEED_SQ] / st[SAMPLES]), 4)
        if st[SAMPLES] > 0
        else None,
        "ego_and_followers_mpg": mpg(group_distance, group_fuel),
        "ego_and_followers_fuel_g": round(group_fuel, 4),
        "ego_distance_m": round(float(st[EGO_DIST]), 3),
        "collisions": collision_pairs(core_state, b),
        "lane_changes_simulated": int(counters.lane_changes[b]),
        "min_ttc_s": round(float(st[MIN_TTC]), 4) if math.isfinite(st[MIN_TTC]) else None,
        "accel_rms_mps2": round(math.sqrt(st[ACCEL_SQ] / steps), 4),
        "jerk_rms_mps3": round(math.sqrt(st[JERK_SQ] / steps), 4),
        "safety_override_s": round(float(counters.safety_overrides[b]) * dt, 3),
        "ended_early": int(ep.ended[b] != 0),
        "return": round(float(st[RETURN]), 6),
    }
