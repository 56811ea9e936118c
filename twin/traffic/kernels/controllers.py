"""The baseline controllers' laws as compiled scalar functions, for vehicles the core
drives with them (:mod:`twin.traffic.baselines` keeps the Python controllers, their
parameters and their sources: Stern et al. 2018 for FollowerStopper; a constant
time-gap ACC of the order Milanes and Shladover 2014 report). Each takes the gap [m]
to the leader (``inf`` where none), the speeds [m/s] and its parameters, and gives an
acceleration [m/s^2] or a commanded speed [m/s]; the equality with the Python
controllers is a test.
"""

import math

from twin.core.jit import kernel


@kernel(inline=True)
def speed_loop(v_cmd, speed, gain, max_accel, max_decel):
    """[m/s^2] the low-level loop toward ``v_cmd``: ``gain (v_cmd - v)`` within the
    limits."""
    return min(max(gain * (v_cmd - speed), -max_decel), max_accel)


@kernel(inline=True)
def follower_stopper_speed(gap, speed, leader_speed, desired, dx0, decel):
    """FollowerStopper's commanded speed [m/s] (:func:`twin.traffic.baselines.
    follower_stopper_speed`); ``dx0``, ``decel``: (3,) gaps [m] and decelerations."""
    if not math.isfinite(gap):
        return desired
    closing = min(leader_speed - speed, 0.0)
    dx1 = dx0[0] + closing * closing / (2.0 * decel[0])
    dx2 = dx0[1] + closing * closing / (2.0 * decel[1])
    dx3 = dx0[2] + closing * closing / (2.0 * decel[2])
    w = min(max(leader_speed, 0.0), desired)
    if gap <= dx1:
        return 0.0
    if gap <= dx2:
        return w * (gap - dx1) / (dx2 - dx1)
    if gap <= dx3:
        return w + (desired - w) * (gap - dx2) / (dx3 - dx2)
    return desired


@kernel(inline=True)
def acc_accel(gap, speed, leader_speed, desired, time_gap, min_gap, k1, k2, cruise_gain,
              max_accel, max_decel):  # fmt: skip
    """The constant time-gap ACC's acceleration [m/s^2] (:func:`twin.traffic.baselines.
    acc_accel`)."""
    accel = cruise_gain * (desired - speed)
    if math.isfinite(gap):
        follow = k1 * (gap - min_gap - time_gap * speed) + k2 * (leader_speed - speed)
        accel = min(accel, follow)
    return min(max(accel, -max_decel), max_accel)
