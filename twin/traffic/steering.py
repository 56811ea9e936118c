"""Lateral control of the traffic manager: each vehicle's path in the road frame (its
lane centre, or during a lane change a cosine blend from where the change began to the
new lane's centre over a distance set by speed and manoeuvre time) and the Stanley
controller with curvature feedforward that tracks it.

(Pure pursuit was tried first: at 25 to 35 m/s the body's yaw lag made it overshoot a
0.8 m offset by 0.13 to 0.21 m; Stanley settles it with under 1 cm.)
"""

import numpy as np

from twin.traffic.scene import centre_y

MAX_STEER = 0.5  # [rad] front-wheel angle limit of the lateral controller
SETTLED = 0.1  # [m] from the new lane's centre, a lane change is over

SOFT_SPEED = 1.0  # [m/s] keeps the Stanley cross-track term finite at rest


def path_shape(
    x: np.ndarray, start_x: np.ndarray, start_y: np.ndarray, end_y: np.ndarray, distance
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The path at road-frame ``x``: a cosine blend from ``start_y`` at ``start_x`` to
    ``end_y`` at ``start_x + distance`` [m] (> 0), straight at ``end_y`` beyond it.

    Returns:
        y [m], slope dy/dx [-] and bend d2y/dx2 [1/m], each (n,). With
        ``start_y == end_y`` the path is the straight line ``y = end_y``.
    """
    progress = np.clip((x - start_x) / distance, 0.0, 1.0)
    inside = (progress > 0.0) & (progress < 1.0)
    rise = end_y - start_y
    phase = np.pi * progress
    y = start_y + rise * (0.5 - 0.5 * np.cos(phase))
    slope = np.where(inside, 0.5 * rise * (np.pi / distance) * np.sin(phase), 0.0)
    bend = np.where(inside, 0.5 * rise * (np.pi / distance) ** 2 * np.cos(phase), 0.0)
    return y, slope, bend


def stanley_steer(
    error: np.ndarray,
    heading_error: np.ndarray,
    speed: np.ndarray,
    curvature: np.ndarray,
    wheelbase: np.ndarray,
    gain: float,
    max_steer: np.ndarray,
) -> np.ndarray:
    """Front-wheel angle [rad] (positive left) of the Stanley controller (Hoffmann,
    Tomlin, Montemerlo, Thrun 2007) with the path's curvature as feedforward.

    Args:
        error: (n,) [m] vehicle y minus path y (road frame: positive is right of travel).
        heading_error: (n,) [rad] vehicle yaw minus path yaw (positive left).
        speed: (n,) [m/s].
        curvature: (n,) [1/m] the path's curvature, positive turning left.
        wheelbase: (n,) [m].
        gain: [1/s] cross-track gain: the error decays at about this rate.
        max_steer: (n,) [rad] limit of the result's magnitude.
    """
    steer = (
        np.arctan(wheelbase * curvature)
        - heading_error
        + np.arctan(gain * error / (np.maximum(speed, 0.0) + SOFT_SPEED))
    )
    return np.clip(steer, -max_steer, max_steer)


def finish_changes(drivers, centre_x: np.ndarray, y: np.ndarray) -> None:
    """End the lane changes whose path has ended with the vehicle centred in its new
    lane (within ``SETTLED``): ``lane_from`` becomes ``lane``.

    Args:
        drivers: the manager's :class:`~twin.traffic.driver_state.DriverState`.
        centre_x: (n,) [m] the vehicles' centres along the road; y: (n,) [m].
    """
    changing = drivers.lane_from != drivers.lane
    done = (
        changing
        & (centre_x >= drivers.start_x + drivers.path_length)
        & (np.abs(y - centre_y(drivers.lane)) < SETTLED)
    )
    drivers.lane_from[done] = drivers.lane[done]


def steer(drivers, states, speed, centre_x, road_heading, config) -> tuple[np.ndarray, np.ndarray]:
    """Front-wheel angles [rad] that track each vehicle's path, and the path's y [m].

    Stanley on the path's cross-track error, with the path's direction and curvature
    taken ``config.path_preview`` seconds ahead (at the current speed) to make up for
    the body's yaw lag.

    Args:
        drivers: the :class:`~twin.traffic.driver_state.DriverState` (n,).
        states: the bodies' states (``y``, ``heading``); speed: (n,) [m/s] >= 0.
        centre_x: (n,) [m] the vehicles' centres along the road.
        road_heading: (2,) [rad] world yaw of travel westbound and eastbound.
        config: the :class:`~twin.traffic.config.TrafficConfig`.

    Returns:
        steer (n,) [rad], path_y (n,) [m].
    """
    n = len(drivers)
    path = centre_y(drivers.lane)
    slope, bend = np.zeros(n), np.zeros(n)
    moving = np.flatnonzero(drivers.lane_from != drivers.lane)
    if moving.size:
        start_x, start_y = drivers.start_x[moving], drivers.start_y[moving]
        end_y, length = path[moving], drivers.path_length[moving]
        path[moving] = path_shape(centre_x[moving], start_x, start_y, end_y, length)[0]
        ahead = centre_x[moving] + config.path_preview * speed[moving]
        _, slope[moving], bend[moving] = path_shape(ahead, start_x, start_y, end_y, length)
    heading_error = wrap(states.heading - road_heading[(drivers.road > 0) * 1] + np.arctan(slope))
    max_steer = np.minimum(
        MAX_STEER,
        np.arctan(drivers.wheelbase * config.max_lateral_accel / np.maximum(speed, 1.0) ** 2),
    )
    angle = stanley_steer(
        states.y - path,
        heading_error,
        speed,
        -bend / (1.0 + slope**2) ** 1.5,
        drivers.wheelbase,
        config.lateral_gain,
        max_steer,
    )
    # Held for one step of dt, the angle turns the heading by about v dt tan(angle) / L;
    # never by more than the heading change Stanley asks for (about the angle itself),
    # else at 10 Hz a short vehicle (v dt / L near 2) swings from side to side. At
    # 100 Hz (v dt / L under 1) the limit never binds.
    step_limit = np.arctan(
        drivers.wheelbase * np.abs(angle) / (np.maximum(speed, SOFT_SPEED) * config.dt)
    )
    return np.clip(angle, -step_limit, step_limit), path


def wrap(angle: np.ndarray) -> np.ndarray:
    """Angles [rad] into [-pi, pi)."""
    return (angle + np.pi) % (2.0 * np.pi) - np.pi
