"""The room a vehicle needs to a body in its lane, shared by the hand-overs
(:mod:`twin.cosim.core.handover`: spawns, recordings that appear or crowd a body) and
the relaxing vehicles (:mod:`twin.cosim.core.relax`: a ghost crowding one from behind)."""

from twin.core.jit import kernel

CLEARANCE_SPEED = 5.0  # [m/s] from this speed of the rear vehicle a spawn needs the full clearance
#: [m/s^2] a recorded vehicle crowds a body ahead of it when closer than a spawn's room
#: with the braking distances at this deceleration (it would have to brake harder)
CROWD_DECEL = 2.0
#: [s] and closer than that plus what it closes on the body in this time: at a crawl the
#: room at CROWD_DECEL is hardly more than the clearance at rest, which a recording
#: creeping at 0.5 m/s into a standing body crossed in a step, from crowding it to too
#: close to stop behind it (a contact: preset E, recorded)
CROWD_AHEAD = 1.0


@kernel(inline=True)
def spawn_room(clearance, at_rest, decel, rear_speed, closing):
    """[m] bumper-to-bumper room a spawn needs to a body in its lane: the clearance,
    ``at_rest`` for a rear vehicle at rest growing to ``clearance`` at CLEARANCE_SPEED,
    plus the difference of braking distances at ``decel`` (``closing`` = v_rear^2 -
    v_front^2; :func:`twin.cosim.cosimulator.spawn_room`)."""
    share = min(max(rear_speed / CLEARANCE_SPEED, 0.0), 1.0)
    return at_rest + share * (clearance - at_rest) + max(closing, 0.0) / (2.0 * decel)
