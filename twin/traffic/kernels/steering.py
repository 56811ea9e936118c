"""Lateral control of the traffic manager: each vehicle's path in the road frame (its
lane centre, or as far from it as its driver's ``offset``, or during a lane change a
cosine blend from where the change began to the new lane's centre over a distance set
by speed and manoeuvre time) and the Stanley
controller (Hoffmann, Tomlin, Montemerlo, Thrun 2007) with curvature feedforward that
tracks it, as compiled kernels.

(Pure pursuit was tried first: at 25 to 35 m/s the body's yaw lag made it overshoot a
0.8 m offset by 0.13 to 0.21 m; Stanley settles it with under 1 cm.)
"""

import math

from twin.core.i24 import LANE_WIDTH
from twin.core.jit import kernel

MAX_STEER = 0.5  # [rad] front-wheel angle limit of the lateral controller
SETTLED = 0.1  # [m] from the new lane's centre, a lane change is over
SOFT_SPEED = 1.0  # [m/s] keeps the Stanley cross-track term finite at rest


@kernel(inline=True)
def centre_y(lane):
    """Road-frame y [m] of lane ``lane``'s centre line."""
    return (0.5 - lane) * LANE_WIDTH


@kernel(inline=True)
def path_shape(x, start_x, start_y, end_y, distance):
    """(y [m], slope [-], bend [1/m]) at road-frame ``x`` of the cosine blend from
    ``start_y`` at ``start_x`` to ``end_y`` ``distance`` [m] later (straight beyond)."""
    progress = min(max((x - start_x) / distance, 0.0), 1.0)
    rise = end_y - start_y
    phase = math.pi * progress
    y = start_y + rise * (0.5 - 0.5 * math.cos(phase))
    if progress <= 0.0 or progress >= 1.0:
        return y, 0.0, 0.0
    k = math.pi / distance
    return y, 0.5 * rise * k * math.sin(phase), 0.5 * rise * k * k * math.cos(phase)


@kernel(inline=True)
def stanley(error, heading_error, speed, curvature, wheelbase, gain, max_steer):
    """Front-wheel angle [rad] (positive left) of the Stanley controller with the path's
    curvature as feedforward: ``error`` [m] the vehicle's y minus the path's (positive
    right of travel), ``heading_error`` [rad] its yaw minus the path's (positive left),
    ``speed`` [m/s], ``curvature`` [1/m] (positive turning left), ``wheelbase`` [m],
    ``gain`` [1/s] (the cross-track error decays at about this rate). The steer toward
    the path (feedforward and cross-track terms) stays within +/- ``max_steer`` [rad]
    (the lateral-acceleration limit); the heading term turns a yawed body back beyond
    it, up to :data:`MAX_STEER` (clamped with the rest, a body that yawed under hard
    braking at 48 m/s could not be turned back and spun off the road)."""
    feedforward = math.atan(wheelbase * curvature) if curvature != 0.0 else 0.0
    toward = feedforward + math.atan(gain * error / (max(speed, 0.0) + SOFT_SPEED))
    angle = min(max(toward, -max_steer), max_steer) - heading_error
    return min(max(angle, -MAX_STEER), MAX_STEER)


@kernel(inline=True)
def wrap(angle):
    """``angle`` [rad] into [-pi, pi)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


@kernel
def finish_changes(b, t):
    """End the lane changes whose path has ended with the vehicle centred in its new
    lane (within SETTLED)."""
    vehicles, drivers = t.vehicles, t.drivers
    valid, x, y, length = vehicles.valid, vehicles.x, vehicles.y, vehicles.length
    lane, lane_from = drivers.lane, drivers.lane_from
    start_x, path_length = drivers.start_x, drivers.path_length
    for i in range(vehicles.top[b]):
        if not valid[b, i] or lane_from[b, i] == lane[b, i]:
            continue
        centre = x[b, i] + 0.5 * length[b, i]
        if (
            centre >= start_x[b, i] + path_length[b, i]
            and abs(y[b, i] - centre_y(lane[b, i])) < SETTLED
        ):
            lane_from[b, i] = lane[b, i]


@kernel
def steer(b, t):
    """The front-wheel angle [rad] (``steer``) that tracks each vehicle's path, and the
    path's y now (``path_y``): Stanley on the cross-track error with the path's
    direction and curvature taken ``path_preview`` seconds ahead."""
    vehicles, drivers, sc, settings = t.vehicles, t.drivers, t.scratch, t.settings
    valid, x, y, yaw, speeds = vehicles.valid, vehicles.x, vehicles.y, vehicles.yaw, vehicles.speed
    length, wheelbases = vehicles.length, vehicles.wheelbase
    lane, lane_from, offsets = drivers.lane, drivers.lane_from, drivers.offset
    start_xs, start_ys, path_lengths = drivers.start_x, drivers.start_y, drivers.path_length
    out_steer, out_path = sc.steer, sc.path_y
    preview, gain, dt = settings.path_preview, settings.lateral_gain, settings.dt
    max_lateral = settings.max_lateral_accel
    for i in range(vehicles.top[b]):
        if not valid[b, i]:
            continue
        speed = max(speeds[b, i], 0.0)
        wheelbase = wheelbases[b, i]
        centre = x[b, i] + 0.5 * length[b, i]
        path = centre_y(lane[b, i])
        slope, bend = 0.0, 0.0
        if lane_from[b, i] == lane[b, i]:
            path += offsets[b, i]
        else:
            start_x, start_y, distance = start_xs[b, i], start_ys[b, i], path_lengths[b, i]
            end_y = path
            path = path_shape(centre, start_x, start_y, end_y, distance)[0]
            _, slope, bend = path_shape(centre + preview * speed, start_x, start_y, end_y,
                                        distance)  # fmt: skip
        heading_error = wrap(yaw[b, i] + math.atan(slope)) if slope != 0.0 else wrap(yaw[b, i])
        max_steer = min(MAX_STEER, math.atan(wheelbase * max_lateral / max(speed, 1.0) ** 2))
        rise = 1.0 + slope * slope
        curvature = -bend / (rise * math.sqrt(rise))
        angle = stanley(y[b, i] - path, heading_error, speed, curvature, wheelbase, gain,
                        max_steer)  # fmt: skip
        # never turn the heading over one step by more than the angle asks (a short
        # vehicle at 10 Hz would swing from side to side)
        limit = math.atan(wheelbase * abs(angle) / (max(speed, SOFT_SPEED) * dt))
        out_steer[b, i] = min(max(angle, -limit), limit)
        out_path[b, i] = path
