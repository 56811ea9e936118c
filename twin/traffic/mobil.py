"""MOBIL lane-change decisions (Kesting, Treiber, Helbing 2007), vectorised.

"Minimizing Overall Braking Induced by Lane changes": a driver changes lane when the
change is safe for the new follower and the driver's own gain in acceleration, less
a politeness share of what the followers lose, beats a threshold. A keep-right bias
favours moves to the right (toward lane -4).

:class:`MOBILParams` are the parameters every driver of the twin starts with. The
functions here are the synthesiser's MOBIL (:mod:`twin.data.synth`), kept apart on
purpose: test data made by a model that is not the twin's own. The twin's traffic
decides by its kernels (:mod:`twin.traffic.kernels.lane_change`: room to reach the
middle of a change, an urgency-scaled accepted deceleration, room behind), and the
calibration fits its threshold with that same rule (:mod:`twin.traffic.judge`), not
with these.
"""

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class MOBILParams:
    """MOBIL parameters, each (n,) float64 or a scalar.

    Attributes:
        politeness: [-] p, weight of the followers' acceleration changes.
        threshold: [m/s^2] gain a change must beat.
        safe_decel: [m/s^2] positive; the new follower must not have to brake harder.
        keep_right: [m/s^2] bias added to moves to the right, taken from moves left.
    """

    politeness: np.ndarray | float = 0.3
    threshold: np.ndarray | float = 0.2
    safe_decel: np.ndarray | float = 4.0
    keep_right: np.ndarray | float = 0.1


def mobil_incentive(
    own_now: np.ndarray,
    own_after: np.ndarray,
    new_follower_now: np.ndarray,
    new_follower_after: np.ndarray,
    old_follower_now: np.ndarray,
    old_follower_after: np.ndarray,
    to_right: np.ndarray,
    params: MOBILParams,
) -> np.ndarray:
    """Incentive [m/s^2] of a lane change less its threshold; change where > 0.

    Accelerations [m/s^2] (k,) of the driver and of its followers in the target lane
    (new) and in its own lane (old), now and after the change; 0 for a missing
    follower. ``to_right`` (k,) bool: the move is to the right.
    """
    own = own_after - own_now
    others = (new_follower_after - new_follower_now) + (old_follower_after - old_follower_now)
    bias = np.where(to_right, params.keep_right, -np.asarray(params.keep_right))
    return own + params.politeness * others + bias - params.threshold


def mobil_safe(new_follower_after: np.ndarray, params: MOBILParams) -> np.ndarray:
    """(k,) bool: the new follower would not have to brake harder than ``safe_decel``."""
    return new_follower_after >= -np.asarray(params.safe_decel)
