"""The batched core's state: B episodes of N vehicle slots each, as struct-of-arrays
with a leading episode axis (Waymax's layout: one array per field, fixed slots with a
validity mask), made once and reused.

* ``bodies`` (:data:`twin.physics.kernels.Bodies`) and ``drivers``
  (:data:`twin.traffic.kernels.state.Drivers`): each slot's vehicle and its driver;
* ``slots`` (:data:`Slots`, B x N): what the cosimulation keeps of each vehicle: the
  recorded trajectory it stands for (``r``, an index of the recording, and the
  store's ``tid``), its own desired speed, whether it is an AV, its strategic target's
  bookkeeping, the checks of its spawn, and whether it relaxes toward its recording
  in a ghost cell with the recording's state now (:mod:`twin.cosim.core.relax`);
* ``episodes`` (:data:`Episodes`, B): each episode's seed, clock, ego, windows,
  counters, and the contacts it had (``collisions`` counts new contacts, of two bodies
  or of a body and a ghost, and ``collision_log`` keeps the first with what each vehicle
  was doing, :data:`CONTACT_COLUMNS`; a collision is a pair,
  :mod:`twin.metrics.collisions`);
* ``table`` (:data:`TidTable`, B x H): per episode, every recorded vehicle it has met,
  in an open-addressing hash by recording index: simulated now, a ghost after the
  last reload, seen in the windows before, waiting for room to spawn, anchored (drawn
  off its recording where its body was, the offset decaying:
  :mod:`twin.cosim.core.anchor`, whose entries ``Episodes.anchors`` lists);
* ``ghosts`` (:data:`Ghosts`, B x G): the ghost set, the traffic's obstacles;
* ``snap`` (:data:`Snapshot`, B x S): the recorded vehicles in the windows now;
* ``log`` (:data:`Log`): every slot every step, the windows, the ghosts at the log
  rate (empty where the batch keeps no log: training);
* the traffic kernels' scratch and counters, and their views of the bodies and the
  ghosts (``vehicles``, ``obstacles``: the same arrays).

Sizes are capacities: a batch refuses (and counts) a spawn when its slots are full,
and says so where a snapshot or the hash table would overflow (:mod:`twin.cosim.core.
batch` raises naming the episode and the setting to raise).
"""

from collections import namedtuple

import numpy as np
from numba.core.extending import overload
from numba.experimental import structref

from twin.core.jit import StructType, kernel, packing, register_struct
from twin.physics import kernels as physics
from twin.traffic.kernels import state as traffic

Slots = namedtuple(
    "Slots",
    "r tid base_speed av just_spawned spawn_speed off_road tgt_lane tgt_draws plan_next "
    "plan_end tgt_on order listed by_back by_back_listed by_back_stop relaxing rec_on rec_x "
    "rec_y rec_speed rec_accel changing born",
)
Episodes = namedtuple(
    "Episodes",
    "seed t0 step steps done ended ended_x ego ego_id ego_r next_id windows lead_speed leads "
    "spawned spawned_initially despawned handed_back yielded held lookback skipped_overlap "
    "skipped_invalid skipped_full collisions collision_log off_road spawn_errors "
    "spawn_error_count touching touching_count ghost_touching ghost_touching_count pair_count "
    "fuel fuel_sum group_distance speed_prev speed_prev_control collisions_before followers "
    "follower_count overflow anchors anchor_count anchor_lo anchor_hi anchored anchors_full "
    "collisions_unlisted ghosts_braked",
)
TidTable = namedtuple("TidTable", "key flags slot drawn off_x off_v off_y off_vy rec_x rec_y rec_v")
Ghosts = namedtuple("Ghosts", "count r lane x y speed length accel reach")
Snapshot = namedtuple("Snapshot", "count r x y speed")
Log = namedtuple(
    "Log",
    "on id r lane x y z speed accel_cmd yaw drive_power windows ghost_every ghost_count "
    "ghost_r ghost_lane ghost_x ghost_y ghost_speed",
)
State = namedtuple(
    "State",
    "bodies drivers slots episodes table ghosts snap log scratch counters pairs vehicles "
    "obstacles actions",
)
#: What the kernels take: the state's groups, the traffic's packed struct, and what the
#: batch shares (its :data:`~twin.cosim.core.step.CoreSettings`, the recording, the
#: bodies' parameters by trajectory, the behaviour's arrays), packed by :func:`pack`.
Core = namedtuple(
    "Core", "traffic bodies slots episodes table ghosts snap log pairs settings rec params beh"
)

#: flags of the tid table: simulated, a ghost, read before, waiting for room, held back
#: from appearing as a ghost on a body until it appears
#: (:func:`twin.cosim.core.handover.enter_and_reload`), anchored (drawn at an offset
#: from its recording, :mod:`twin.cosim.core.anchor`); the table's ``drawn`` keeps the
#: last step a vehicle was drawn (a ghost, or a body until its removal)
SIMULATED, GHOST, SEEN, WAITING, HELD, ANCHORED = 1, 2, 4, 8, 16, 32
ANCHORS_KEPT = 256  # anchored recorded vehicles per episode (more are not anchored: counted)
#: ``Episodes.ended``
RUNNING, EGO_LEFT = 0, 1
#: ``Episodes.overflow``: what ran out (the batch's facade names it)
SNAPSHOT_FULL, TABLE_FULL, PAIRS_FULL, GHOSTS_FULL = 1, 2, 4, 8
COLLISIONS_KEPT = 64  # the first new contacts of an episode are kept (CONTACT_COLUMNS)
#: a kept contact's columns: its time [s], the two vehicles (ids, the smaller first; a
#: ghost's is GHOST_ID_BASE - its store tid, second), what each was doing (the CONTACT_*
#: flags), and the second's lane and speed [m/s] where it is a ghost (else 0 and NaN)
CONTACT_COLUMNS = ("time", "a", "b", "flags_a", "flags_b", "ghost_lane", "ghost_speed")
#: contact flags: what a vehicle was at its contact
CONTACT_EGO, CONTACT_RELAXING, CONTACT_CHANGING, CONTACT_MANDATORY, CONTACT_GHOST = 1, 2, 4, 8, 16
NEVER = -2  # ``TidTable.drawn`` of a vehicle not drawn this episode
GHOST_ID_BASE = -1  # a ghost's id in a contact: GHOST_ID_BASE - tid (below every body's)
SPAWN_ERRORS_KEPT = 4096  # spawn speed errors kept per episode
TOUCHING_KEPT = 256  # vehicle pairs in contact at once, per episode
FOLLOWERS = 5  # the AV's followers whose fuel counts with its own


@kernel(inline=True)
def entry(keys, flags, slots, b, r, insert):  # the tid table's probe
    """The table's index of recording index ``r`` in episode ``b`` (inserted where
    ``insert``), or -1 (absent, or the table is full)."""
    size = keys.shape[1]
    h = (r * 2654435761) & (size - 1)
    for _ in range(size):
        k = keys[b, h]
        if k == r:
            return h
        if k < 0:
            if not insert:
                return -1
            keys[b, h] = r
            flags[b, h] = 0
            slots[b, h] = -1
            return h
        h = (h + 1) & (size - 1)
    return -1


def make_state(b: int, n: int, g: int, s: int, h: int, log_steps: int, ghost_every: int) -> State:
    """A state of ``b`` episodes: ``n`` vehicle slots, ``g`` ghosts, ``s`` snapshot rows,
    a tid table of ``h`` (a power of two), and a log of ``log_steps`` steps (0: none;
    ghosts every ``ghost_every`` steps)."""
    if h & (h - 1):
        raise ValueError(f"the tid table's size must be a power of two, got {h}")

    def per_slot(dtype=float, fill=0):
        return np.full((b, n), fill, dtype=dtype)

    slots = Slots(
        r=per_slot(np.int64, -1), tid=per_slot(np.int64, -1), base_speed=per_slot(),
        av=per_slot(bool), just_spawned=per_slot(bool), spawn_speed=per_slot(),
        off_road=per_slot(bool), tgt_lane=per_slot(np.int64), tgt_draws=per_slot(np.int64),
        plan_next=per_slot(np.int64), plan_end=per_slot(np.int64), tgt_on=per_slot(bool),
        order=per_slot(np.int64, -1), listed=per_slot(bool), by_back=per_slot(np.int64, -1),
        by_back_listed=per_slot(bool), by_back_stop=per_slot(), relaxing=per_slot(bool),
        rec_on=per_slot(bool), rec_x=per_slot(), rec_y=per_slot(), rec_speed=per_slot(),
        rec_accel=per_slot(), changing=per_slot(bool), born=per_slot(np.int64),
    )  # fmt: skip
    zeros = np.zeros(b, np.int64)
    episodes = Episodes(
        seed=zeros.copy(), t0=np.zeros(b), step=zeros.copy(), steps=zeros.copy(),
        done=np.ones(b, bool), ended=zeros.copy(), ended_x=np.zeros(b), ego=zeros.copy(),
        ego_id=zeros.copy(), ego_r=zeros.copy(), next_id=zeros.copy(),
        windows=np.zeros((b, 4)), lead_speed=np.full((b, 4), np.nan),
        leads=np.full((b, 4), -1, np.int64), spawned=zeros.copy(),
        spawned_initially=zeros.copy(), despawned=zeros.copy(), handed_back=zeros.copy(),
        yielded=zeros.copy(), held=zeros.copy(), lookback=np.full(b, -np.inf),
        skipped_overlap=zeros.copy(),
        skipped_invalid=zeros.copy(), skipped_full=zeros.copy(), collisions=zeros.copy(),
        collisions_unlisted=zeros.copy(),
        collision_log=np.zeros((b, COLLISIONS_KEPT, len(CONTACT_COLUMNS))), off_road=zeros.copy(),
        spawn_errors=np.zeros((b, SPAWN_ERRORS_KEPT)), spawn_error_count=zeros.copy(),
        touching=np.zeros((b, TOUCHING_KEPT, 2), np.int64), touching_count=zeros.copy(),
        ghost_touching=np.zeros((b, TOUCHING_KEPT, 2), np.int64),
        ghost_touching_count=zeros.copy(),
        pair_count=zeros.copy(), fuel=np.zeros(b), fuel_sum=np.zeros(b),
        group_distance=np.zeros(b), speed_prev=np.zeros((b, n)), speed_prev_control=np.zeros(b),
        collisions_before=zeros.copy(),
        followers=np.full((b, FOLLOWERS), -1, np.int64), follower_count=zeros.copy(),
        overflow=zeros.copy(), anchors=np.full((b, ANCHORS_KEPT), -1, np.int64),
        anchor_count=zeros.copy(), anchor_lo=np.zeros(b), anchor_hi=np.zeros(b),
        anchored=zeros.copy(), anchors_full=zeros.copy(), ghosts_braked=zeros.copy(),
    )  # fmt: skip
    table = TidTable(
        key=np.full((b, h), -1, np.int64), flags=np.zeros((b, h), np.int64),
        slot=np.full((b, h), -1, np.int64), drawn=np.full((b, h), NEVER, np.int64),
        off_x=np.zeros((b, h)), off_v=np.zeros((b, h)), off_y=np.zeros((b, h)),
        off_vy=np.zeros((b, h)), rec_x=np.zeros((b, h)), rec_y=np.zeros((b, h)),
        rec_v=np.zeros((b, h)),
    )  # fmt: skip
    ghosts = Ghosts(
        count=zeros.copy(), r=np.zeros((b, g), np.int64), lane=np.zeros((b, g), np.int64),
        x=np.zeros((b, g)), y=np.zeros((b, g)), speed=np.zeros((b, g)), length=np.zeros((b, g)),
        accel=np.zeros((b, g)), reach=np.zeros((b, g), np.int64),
    )  # fmt: skip
    snap = Snapshot(
        count=zeros.copy(), r=np.zeros((b, s), np.int32), x=np.zeros((b, s)),
        y=np.zeros((b, s)), speed=np.zeros((b, s)),
    )  # fmt: skip
    t = log_steps + 1 if log_steps else 0
    tg = log_steps // ghost_every + 1 if log_steps else 0
    log = Log(
        on=log_steps > 0, id=np.full((b, t, n), -1, np.int64), r=np.zeros((b, t, n), np.int64),
        lane=np.zeros((b, t, n), np.int8), x=np.zeros((b, t, n)), y=np.zeros((b, t, n)),
        z=np.zeros((b, t, n)), speed=np.zeros((b, t, n)), accel_cmd=np.zeros((b, t, n)),
        yaw=np.zeros((b, t, n)), drive_power=np.zeros((b, t, n)), windows=np.zeros((b, t, 4)),
        ghost_every=max(int(ghost_every), 1), ghost_count=np.zeros((b, tg), np.int64),
        ghost_r=np.zeros((b, tg, g), np.int64), ghost_lane=np.zeros((b, tg, g), np.int8),
        ghost_x=np.zeros((b, tg, g)), ghost_y=np.zeros((b, tg, g)),
        ghost_speed=np.zeros((b, tg, g)),
    )  # fmt: skip
    bodies = physics.bodies(b, n)
    return State(
        bodies=bodies, drivers=traffic.drivers(b, n), slots=slots, episodes=episodes,
        table=table, ghosts=ghosts, snap=snap, log=log, scratch=traffic.scratch(b, n, g),
        counters=traffic.counters(b), pairs=np.zeros((b, TOUCHING_KEPT, 2), np.int64),
        vehicles=vehicles(bodies), obstacles=obstacles(ghosts), actions=np.zeros(b),
    )  # fmt: skip


def vehicles(bo) -> traffic.Vehicles:
    """The traffic kernels' view of the bodies (the same arrays)."""
    return traffic.Vehicles(
        valid=bo.valid, top=bo.top, x=bo.x, y=bo.y, yaw=bo.yaw, speed=bo.speed, lane=bo.lane,
        length=bo.length, width=bo.width, wheelbase=bo.wheelbase, mu=bo.mu,
    )  # fmt: skip


def obstacles(g: Ghosts) -> traffic.Obstacles:
    """The traffic kernels' view of the ghosts (the same arrays)."""
    return traffic.Obstacles(
        count=g.count, lane=g.lane, x=g.x, length=g.length, speed=g.speed, accel=g.accel,
        reach=g.reach,
    )  # fmt: skip


def pack(state: State, settings, traffic_settings, rec, params, beh) -> "CoreStruct":
    """The kernels' struct of ``state`` and what the batch shares (arrays shared)."""
    t = traffic.pack(
        traffic.Traffic(
            vehicles=state.vehicles, obstacles=state.obstacles, drivers=state.drivers,
            scratch=state.scratch, settings=traffic_settings, counters=state.counters,
            actions=state.actions,
        )
    )  # fmt: skip
    return _pack_kernel(
        Core(
            traffic=t, bodies=state.bodies, slots=state.slots, episodes=state.episodes,
            table=state.table, ghosts=state.ghosts, snap=state.snap, log=state.log,
            pairs=state.pairs, settings=settings, rec=rec, params=params, beh=beh,
        )
    )  # fmt: skip


class CoreType(StructType):
    """The kernels' type of a packed :data:`Core`."""


class CoreStruct(structref.StructRefProxy):
    """A packed :data:`Core` as Python holds it."""


register_struct(CoreType, CoreStruct)


def _pack(group):
    raise NotImplementedError  # compiled only


@overload(_pack)
def _pack_overload(group):
    return packing(CoreType, group)


@kernel(nrt=True)
def _pack_kernel(group):
    return _pack(group)
