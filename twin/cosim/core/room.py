"""The room a vehicle needs to a body in its lane, shared by the hand-overs
(:mod:`twin.cosim.core.handover`: spawns, recordings that appear or crowd a body) and
the relaxing vehicles (:mod:`twin.cosim.core.relax`: a ghost crowding one from behind);
and the braking a body needs to stop short of what is ahead of it, which bounds the
braking of relaxing and of newly spawned bodies (:mod:`twin.cosim.core.settle`)."""

import math

from twin.core.jit import kernel
from twin.traffic.kernels.longitudinal import (  # noqa: F401 (spawn_room, CLEARANCE_SPEED: shared here)
    CLEARANCE_SPEED,
    cf,
    lane_end_gap,
    required_decel,
    spawn_room,
)
from twin.traffic.kernels.neighbours import around

#: [m/s^2] a recorded vehicle crowds a body ahead of it when closer than a spawn's room
#: with the braking distances at this deceleration (it would have to brake harder)
CROWD_DECEL = 2.0
#: [s] and closer than that plus what it closes on the body in this time: at a crawl the
#: room at CROWD_DECEL is hardly more than the clearance at rest, which a recording
#: creeping at 0.5 m/s into a standing body crossed in a step, from crowding it to too
#: close to stop behind it (a contact: preset E, recorded)
CROWD_AHEAD = 1.0


@kernel
def stopping_decel(b, core, i, margin):
    """[m/s^2] >= 0 slot ``i`` needs to stop ``margin`` [m] short of what is ahead of it
    in the lanes it occupies (a leader braking as it brakes now, or its lane's end), a
    step's travel first (:func:`required_decel`); inf where that room is used up."""
    bo, dr, sc, ts = core.bodies, core.traffic.drivers, core.traffic.scratch, core.traffic.settings
    v, x, length = max(bo.speed[b, i], 0.0), bo.x[b, i], bo.length[b, i]
    dt = core.settings.dt
    need = 0.0
    for lane in (dr.lane[b, i], dr.lane_from[b, i]):
        ahead, _ = around(sc.entry_key, sc.entry_group, sc.entry_owner, sc.entry_count[b], b,
                          lane, x)  # fmt: skip
        if ahead >= 0:
            gap = sc.sx[b, ahead] - x - length
            lead_decel = max(-sc.saccel[b, ahead], 0.0)
            need = max(need, required_decel(gap, v, max(sc.sspeed[b, ahead], 0.0), lead_decel,
                                            margin, dt))  # fmt: skip
    if dr.lane_from[b, i] == dr.lane[b, i]:
        end = lane_end_gap(ts.lane_ends, dr.lane[b, i], x, length)
        need = max(need, required_decel(end, v, 0.0, 0.0, margin, dt))
    return need


@kernel
def follows_what_is_ahead(b, core, i, accel):
    """Whether ``accel`` [m/s^2], slot ``i``'s command, asks no more braking than its car
    following behind what is ahead of it in the lanes it occupies (the vehicles and
    ghosts there, its lane's end): not a cooperating driver's dropping back for a
    merge, nor a controller's own braking, which :func:`stopping_decel` does not see."""
    bo, dr, sc, ts = core.bodies, core.traffic.drivers, core.traffic.scratch, core.traffic.settings
    v, x, length = max(bo.speed[b, i], 0.0), bo.x[b, i], bo.length[b, i]
    n = bo.valid.shape[1]
    lowest = math.inf
    for lane in (dr.lane[b, i], dr.lane_from[b, i]):
        ahead, _ = around(sc.entry_key, sc.entry_group, sc.entry_owner, sc.entry_count[b], b,
                          lane, x)  # fmt: skip
        gap, v_lead = math.inf, v
        if ahead >= 0:
            gap, v_lead = sc.sx[b, ahead] - x - length, sc.sspeed[b, ahead]
        if dr.lane_from[b, i] == dr.lane[b, i]:
            end = lane_end_gap(ts.lane_ends, lane, x, length)
            if end < gap:
                gap, v_lead = end, 0.0
        lowest = min(lowest, cf(ts.model, dr.cf, ts.obstacle_cf, b, n, i, v, v_lead, gap))
    return accel >= lowest - 1e-6
