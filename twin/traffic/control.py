"""The controllers between the traffic manager's decisions and the vehicle bodies.

* Lateral: the Stanley controller with curvature feedforward, tracking a path in the
  road frame: the lane centre, or during a lane change a cosine blend from where the
  change began to the new lane centre over a distance set by speed and manoeuvre time.
  (Pure pursuit was tried first: at 25 to 35 m/s the body's yaw lag made it overshoot
  a 0.8 m offset by 0.13 to 0.21 m; Stanley settles it with under 1 cm.)
* Longitudinal safety: the deceleration a follower needs to stay clear of its leader
  if the leader keeps braking as it does now; the traffic manager enforces it when it
  exceeds what the driver model would brake (emergency braking).

The acceleration itself is tracked by the vehicle model (``Controls.accel``), which
adds feedforward for grade, rolling resistance and drag.
"""

import numpy as np

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


def required_decel(
    gap: np.ndarray,
    v: np.ndarray,
    v_lead: np.ndarray,
    lead_decel: np.ndarray,
    margin: float,
    reaction: float,
) -> np.ndarray:
    """Deceleration [m/s^2] (>= 0) a follower needs to stay ``margin`` behind its leader
    if the leader keeps decelerating at ``lead_decel`` (>= 0) until it stops.

    After ``reaction`` [s] of travel at the current speeds, the follower brakes at a
    constant deceleration. If it would close the gap before the leader stops, the
    relative motion decides (``lead_decel + closing^2 / (2 room)``); otherwise the
    final gap with both stopped does. Where the room is used up already, the result
    is ``inf``. Shapes (n,); ``gap`` inf gives 0.
    """
    closing = v - v_lead
    room = gap - margin - np.maximum(closing, 0.0) * reaction
    with np.errstate(divide="ignore", invalid="ignore"):
        lead_stop_time = np.where(lead_decel > 1e-6, v_lead / lead_decel, np.inf)
        lead_stop = np.where(lead_decel > 1e-6, 0.5 * v_lead * lead_stop_time, np.inf)
        stop_room = gap - margin - closing * reaction + lead_stop
        both_stop = np.where(stop_room > 0, v**2 / (2.0 * stop_room), np.inf)
        # the relative motion's closest approach comes at 2 room / closing
        catches_up = (closing > 0) & (2.0 * room < closing * lead_stop_time)
        relative = np.where(room > 0, lead_decel + closing**2 / (2.0 * room), np.inf)
    need = np.where(catches_up, relative, both_stop)
    return np.where(np.isfinite(gap), need, 0.0)
