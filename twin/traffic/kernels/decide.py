"""The traffic manager's step as a chain of compiled kernels, for one episode of a
batch: what every vehicle does next, decided from where everything is now.

::

    finish_changes   lane changes whose path has ended are over
    gather, sort     the lane entries of vehicles and obstacles, sorted (neighbours)
    follow           car following behind every leader (and a slower car on the left
                     not to pass, where asked), and the emergency need
    cooperate        drivers behind an urgent change make room
    emergency        braking as hard as staying clear needs, where that is much
    change_lanes     MOBIL, strategic targets, the HOV rule (on the decision grid)
    control          the controllers' commands (an action, a baseline's law)
    limit            within the drivers' (or the tyres') limits
    steer            Stanley along each vehicle's path

Vehicles a Python controller drives (``ctrl`` :data:`~twin.traffic.kernels.state.PYTHON`)
keep the driver's command here; the caller gives them theirs (one episode at a time,
:class:`twin.traffic.manager.TrafficManager`).

:class:`TrafficSettings` holds what is the same for every episode of a batch: the
car-following model, the :class:`~twin.traffic.config.TrafficConfig`'s settings and the
controllers' parameters (:func:`settings`).
"""

import math
from collections import namedtuple

import numpy as np

from twin.core.jit import kernel
from twin.physics.vehicle import GRAVITY
from twin.traffic.kernels import state
from twin.traffic.kernels.controllers import acc_accel, follower_stopper_speed, speed_loop
from twin.traffic.kernels.lane_change import change_lanes, expire
from twin.traffic.kernels.longitudinal import MIN_LANE_CHANGE_GAP, cooperate, follow
from twin.traffic.kernels.models import MAX_ACCEL_COLUMN, MODEL_IDS
from twin.traffic.kernels.neighbours import around, gather, sort_entries
from twin.traffic.kernels.steering import finish_changes, steer

TrafficSettings = namedtuple(
    "TrafficSettings",
    "model max_accel_column dt decision_interval decision_steps lane_change_low "
    "lane_change_high emergency_decel emergency_margin reaction_time brake_limit "
    "lateral_gain path_preview max_lateral_accel cooperate_from yield_from cooperative_decel "
    "courtesy no_pass_right_from "
    "urgent_path "
    "hov_openings keep_out lane_ends obstacle_cf obstacle_clearance obstacle_clearance_at_rest "
    "action_speed action_gain action_low action_high "
    "fs_desired fs_dx0 fs_decel fs_gain fs_max_accel fs_max_decel "
    "acc_desired acc_time_gap acc_min_gap acc_k1 acc_k2 acc_cruise_gain acc_max_accel "
    "acc_max_decel",
)


def settings(
    config, obstacle_cf, *, keep_out=(), lane_ends=(), controller=None, action="accel",
    action_range=(-3.0, 1.5), action_gain=1.0, obstacle_clearance=MIN_LANE_CHANGE_GAP,
    obstacle_clearance_at_rest=MIN_LANE_CHANGE_GAP,
) -> TrafficSettings:  # fmt: skip
    """The kernels' settings of a :class:`~twin.traffic.config.TrafficConfig`.

    Args:
        obstacle_cf: (N_PARAMS,) the mean driver's parameter row (obstacles are judged
            as if they drove like one).
        keep_out: (lane, x0, x1) zones with no discretionary change into the lane.
        lane_ends: (lane, x) [m]: the lane ends at road-frame x (an on-ramp's
            acceleration lane where its taper ends), a standing obstacle to its drivers.
        controller: the baselines' :class:`~twin.traffic.baselines.ControllerSettings`
            (default parameters where None).
        action: ``accel`` or ``speed``: what an ACTION vehicle's action is (a speed is
            tracked with ``action_gain`` [1/s] within ``action_range`` [m/s^2]).
        obstacle_clearance, obstacle_clearance_at_rest: [m] the room a lane change
            leaves in front of an obstacle (a recording, which does not brake for it) at
            speed and at rest (:func:`~twin.traffic.kernels.longitudinal.room_behind`;
            the cosimulation's spawn clearances, so that the recording can be made a
            simulated vehicle behind it); by default the gap any new neighbour gets.
    """
    from twin.traffic.baselines import ControllerSettings

    model = MODEL_IDS[config.car_following]
    c = controller or ControllerSettings()
    fs, acc = c.follower_stopper, c.acc
    zones = np.array([z[1:] if len(z) == 4 else z for z in keep_out], dtype=np.float64)
    return TrafficSettings(
        model=model,
        max_accel_column=MAX_ACCEL_COLUMN[model],
        dt=float(config.dt),
        decision_interval=float(config.decision_interval),
        decision_steps=round(config.decision_period / config.dt),
        lane_change_low=float(config.lane_change_time[0]),
        lane_change_high=float(config.lane_change_time[1]),
        emergency_decel=float(config.emergency_decel),
        emergency_margin=float(config.emergency_margin),
        reaction_time=float(config.reaction_time),
        brake_limit=float(config.brake_limit),
        lateral_gain=float(config.lateral_gain),
        path_preview=float(config.path_preview),
        max_lateral_accel=float(config.max_lateral_accel),
        cooperate_from=float(config.cooperate_from),
        yield_from=float(config.yield_from),
        cooperative_decel=float(config.cooperative_decel),
        courtesy=float(config.courtesy),
        no_pass_right_from=float(config.no_pass_right_from),
        urgent_path=float(config.urgent_path),
        hov_openings=np.array(config.hov_openings, dtype=np.float64).reshape(-1, 2),
        keep_out=zones.reshape(-1, 3),
        lane_ends=np.array(lane_ends, dtype=np.float64).reshape(-1, 2),
        obstacle_cf=np.asarray(obstacle_cf, dtype=np.float64),
        obstacle_clearance=float(obstacle_clearance),
        obstacle_clearance_at_rest=float(obstacle_clearance_at_rest),
        action_speed=action == "speed",
        action_gain=float(action_gain),
        action_low=float(action_range[0]),
        action_high=float(action_range[1]),
        fs_desired=math.nan if fs.desired_speed is None else float(fs.desired_speed),
        fs_dx0=np.array(fs.dx0, dtype=np.float64),
        fs_decel=np.array(fs.decel, dtype=np.float64),
        fs_gain=float(fs.loop.gain),
        fs_max_accel=float(fs.loop.max_accel),
        fs_max_decel=float(fs.loop.max_decel),
        acc_desired=math.nan if acc.desired_speed is None else float(acc.desired_speed),
        acc_time_gap=float(acc.time_gap),
        acc_min_gap=float(acc.min_gap),
        acc_k1=float(acc.k1),
        acc_k2=float(acc.k2),
        acc_cruise_gain=float(acc.cruise_gain),
        acc_max_accel=float(acc.max_accel),
        acc_max_decel=float(acc.max_decel),
    )


@kernel
def decide(b, step, time, seed, t):
    """The traffic manager's step for episode ``b`` of the packed traffic ``t``
    (:func:`twin.traffic.kernels.state.pack`; module doc): its ``step`` number and clock
    ``time`` [s], its ``seed``. Writes ``drivers.accel`` (the command), the scratch's
    ``steer`` and ``path_y``."""
    sc, settings, counters = t.scratch, t.settings, t.counters
    finish_changes(b, t)
    gather(b, t)
    sort_entries(b, t)
    follow(b, t)
    valid, strategic, top = t.vehicles.valid, t.drivers.strategic, t.vehicles.top[b]
    for i in range(top):
        if valid[b, i] and strategic[b, i] != 0:
            cooperate(b, seed, t)
            break
    _emergency(b, top, valid, sc.need, sc.cf_accel, sc.emergency, sc.command,
               settings.emergency_decel, counters.emergency_steps)  # fmt: skip
    if step % settings.decision_steps == 0:
        expire(b, t)
        counters.lane_changes[b] += change_lanes(b, time, seed, t)
    limit(b, t)
    steer(b, t)


@kernel(nrt=True)
def decide_from_python(b, step, time, seed, t):
    """:func:`decide` called from Python (with reference counting, so that the struct
    ``t`` passed in is released after the call; :func:`twin.core.jit.register_struct`)."""
    decide(b, step, time, seed, t)


@kernel(inline=True)
def _emergency(b, top, valid, need, cf_accel, emergency, command, threshold, steps):
    """Where staying clear needs more than ``threshold`` [m/s^2], the command brakes as
    hard as it needs (and the step counts)."""
    for i in range(top):
        if not valid[b, i]:
            continue
        urgent = need[b, i] > threshold
        emergency[b, i] = urgent
        command[b, i] = min(cf_accel[b, i], -need[b, i]) if urgent else cf_accel[b, i]
        if urgent:
            steps[b] += 1


@kernel(inline=True)
def driver_limit(command, emergency, tyre, brake_limit, max_accel):
    """[m/s^2] a driver's ``command`` as its vehicle applies it: braking within the
    driver's ``brake_limit`` share of the tyres' grip ``tyre`` [m/s^2] (all of it in an
    ``emergency``, where the command may be -inf: no room left), accelerating within
    ``max_accel``. Finite for any command but NaN."""
    low = -tyre if emergency else -brake_limit * tyre
    return min(max(command, low), max_accel)


@kernel
def limit(b, t):
    """Each vehicle's command [m/s^2] (``drivers.accel``): its controller's answer
    (emergency braking over it where the controller is guarded), within the tyres' grip
    for a controller, within the driver's brake limit (all the grip in an emergency)
    and its acceleration for a driver."""
    vehicles, drivers, sc, settings, counters = (
        t.vehicles,
        t.drivers,
        t.scratch,
        t.settings,
        t.counters,
    )
    valid, mu = vehicles.valid, vehicles.mu
    ctrl, params, accel_out = drivers.ctrl, drivers.cf, drivers.accel
    command, emergency, need = sc.command, sc.emergency, sc.need
    column, brake_limit = settings.max_accel_column, settings.brake_limit
    for i in range(vehicles.top[b]):
        if not valid[b, i]:
            continue
        kind = ctrl[b, i] % state.GUARDED
        tyre = mu[b, i] * GRAVITY
        if kind == state.DRIVER or kind == state.HUMAN:  # human: the driver's command
            # as its vehicle applies it, as a Python controller is shown it
            accel_out[b, i] = driver_limit(
                command[b, i], emergency[b, i], tyre, brake_limit, params[b, i, column]
            )
            continue
        if kind == state.PYTHON:  # its controller answers outside; the driver's for now
            accel_out[b, i] = min(max(command[b, i], -tyre), tyre)
            continue
        accel = controlled_accel(b, i, kind, t)
        if ctrl[b, i] >= state.GUARDED and emergency[b, i]:
            if -need[b, i] < accel:
                counters.safety_overrides[b] += 1
            accel = min(accel, -need[b, i])
        accel_out[b, i] = min(max(accel, -tyre), tyre)


@kernel
def controlled_accel(b, i, kind, t):
    """[m/s^2] what controller ``kind`` asks of vehicle ``i``."""
    vehicles, drivers, sc, settings, actions = (
        t.vehicles,
        t.drivers,
        t.scratch,
        t.settings,
        t.actions,
    )
    speed = max(vehicles.speed[b, i], 0.0)
    if kind == state.ACTION:
        if settings.action_speed:
            return min(
                max(settings.action_gain * (actions[b] - speed), settings.action_low),
                settings.action_high,
            )
        return actions[b]
    if kind == state.HUMAN:
        return sc.command[b, i]
    x, length = vehicles.x[b, i], vehicles.length[b, i]
    ahead, _ = around(sc.entry_key, sc.entry_group, sc.entry_owner, sc.entry_count[b], b,
                      drivers.lane[b, i], x)  # fmt: skip
    gap, leader_speed = math.inf, math.nan
    if ahead >= 0:
        gap, leader_speed = sc.sx[b, ahead] - x - length, sc.sspeed[b, ahead]
    own_desired = drivers.cf[b, i, 0]
    if kind == state.FOLLOWER_STOPPER:
        desired = settings.fs_desired if settings.fs_desired > 0.0 else own_desired
        v_cmd = follower_stopper_speed(
            gap, speed, leader_speed, desired, settings.fs_dx0, settings.fs_decel
        )
        return speed_loop(v_cmd, speed, settings.fs_gain, settings.fs_max_accel,
                          settings.fs_max_decel)  # fmt: skip
    if kind == state.ACC:
        desired = settings.acc_desired if settings.acc_desired > 0.0 else own_desired
        return acc_accel(
            gap, speed, leader_speed, desired, settings.acc_time_gap, settings.acc_min_gap,
            settings.acc_k1, settings.acc_k2, settings.acc_cruise_gain, settings.acc_max_accel,
            settings.acc_max_decel,
        )  # fmt: skip
    return sc.command[b, i]
