"""Newly spawned bodies settle in: the ghost-cell boundary without a braking seam,
compiled, for one episode of a batch (``docs/cosim.md``, "Spawned vehicles settle in").

A recorded vehicle becomes a body in the state its recording is in: its speed, its gap.
Its simulated driver would seldom have got itself into that state: a recording that
catches up with a slower vehicle 45 m ahead at 3.5 m/s, a normal approach, is far
inside the calibrated IDM's desired gap at 30 m/s (about 80 m), and IDM answers with
its full braking, -7.9 m/s^2, in the first step; so does the body behind a recording
spawned 6 m ahead of it in a queue. On SUMO's on-ramp morning 60 % of the bodies
spawned after the reset braked harder than 4 m/s^2 within 3 s of their spawn, where
their recordings braked gently; one such stop was run into by the recording behind it.

For :data:`SETTLE_S` after its spawn, and while the body ahead of it is that new, a
driven body (its driver's command: the traffic manager's, or a ``human`` controller's)
brakes beyond its driver's comfortable deceleration only as hard as stopping its
standstill gap short of what is ahead needs (:func:`twin.cosim.core.room.stopping_decel`),
where that braking is its car following's behind what is ahead; an emergency (the
traffic manager's emergency braking), a cooperating driver's dropping back for a merge
(stopped short of a gap the merging driver could take, it held a ramp vehicle and the
queue behind both for 100 s on SUMO's on-ramp morning) and a controller's command (an
AV's) are left as they are.
"""

from twin.core.jit import kernel
from twin.cosim.core.room import follows_what_is_ahead, stopping_decel
from twin.traffic.kernels import state as traffic
from twin.traffic.kernels.models import GIPPS
from twin.traffic.kernels.neighbours import around

SETTLE_S = 3.0  # [s] how long a spawned body, and the one behind it, settles in


@kernel(inline=True)
def _comfortable_decel(model, params, b, i):
    """[m/s^2] > 0 driver ``i``'s comfortable deceleration (IDM's ``b``, Gipps' ``decel``)."""
    return params[b, i, 2] if model == GIPPS else params[b, i, 4]


@kernel(inline=True)
def _min_gap(model, params, b, i):
    """[m] driver ``i``'s gap at a standstill (IDM's ``s0``, Gipps' ``min_gap``)."""
    return params[b, i, 4] if model == GIPPS else params[b, i, 2]


@kernel
def _new(b, core, i, steps):
    """Whether slot ``i`` was spawned fewer than ``steps`` steps ago, or the body just
    ahead of it in a lane it occupies was."""
    bo, sl, dr, sc = core.bodies, core.slots, core.traffic.drivers, core.traffic.scratch
    step = core.episodes.step[b]
    if step - sl.born[b, i] < steps:
        return True
    n = bo.valid.shape[1]  # owners from n on are ghosts
    for lane in (dr.lane[b, i], dr.lane_from[b, i]):
        ahead, _ = around(sc.entry_key, sc.entry_group, sc.entry_owner, sc.entry_count[b], b,
                          lane, bo.x[b, i])  # fmt: skip
        if 0 <= ahead < n and step - sl.born[b, ahead] < steps:
            return True
    return False


@kernel
def settle(b, core):
    """After the traffic manager's commands (and the relaxing vehicles'): each driven
    body that is settling in (module doc) brakes no harder than its comfortable
    deceleration, or than stopping short needs where that is more."""
    bo, sl, dr, sc = core.bodies, core.slots, core.traffic.drivers, core.traffic.scratch
    steps = round(SETTLE_S / core.settings.dt)
    accel, params, model = dr.accel, dr.cf, core.traffic.settings.model
    for i in range(bo.top[b]):
        if not bo.valid[b, i] or sl.relaxing[b, i] or sc.emergency[b, i]:
            continue
        kind = dr.ctrl[b, i] % traffic.GUARDED
        if kind != traffic.DRIVER and kind != traffic.HUMAN:
            continue
        comfortable = _comfortable_decel(model, params, b, i)
        if accel[b, i] >= -comfortable or not _new(b, core, i, steps):
            continue
        if not follows_what_is_ahead(b, core, i, accel[b, i]):
            continue  # dropping back for a merge: as its cooperation says
        need = stopping_decel(b, core, i, _min_gap(model, params, b, i))
        accel[b, i] = max(accel[b, i], -max(comfortable, need))
