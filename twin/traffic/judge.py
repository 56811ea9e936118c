"""MOBIL's options in still scenes, judged by the rule the traffic drives.

The calibration fits the drivers' lane-change threshold on the recorded scenes: at each
decision time, which of the recorded drivers would MOBIL have moved, with which gain.
A threshold means the same thing in the fit and on the road only if both apply the
same rule, so :func:`judge_scenes` packs the scenes into the traffic kernels' state
(:mod:`twin.traffic.kernels.state`), one scene per episode, and runs the kernels' own
decision (:func:`twin.traffic.kernels.lane_change.judge_scenes`: their neighbours,
their car following, :func:`~twin.traffic.kernels.lane_change.lane_option`), with
the settings a run drives by (:class:`~twin.traffic.config.TrafficConfig`). Nothing
of the rule is written twice.

A scene's vehicles are drivers in their lanes (not mid-change, the body on the lane's
centre line, no strategic target), without an acceleration of their own (the
emergency braking a leader's braking triggers does not enter MOBIL's gain); obstacles
are judged as the class table's mean driver, as in a run.
"""

from dataclasses import dataclass

import numpy as np

from twin.core.i24 import LANE_WIDTH
from twin.core.vehicle_classes import vehicle_classes
from twin.traffic.config import TrafficConfig
from twin.traffic.drivers import mean_driver_row
from twin.traffic.kernels import state
from twin.traffic.kernels.decide import settings as kernel_settings
from twin.traffic.kernels.lane_change import judge_scenes as _judge_kernel
from twin.traffic.kernels.models import N_PARAMS
from twin.traffic.models import car_following_model

#: scenes packed per kernel call (bounds the working arrays: a few MB per call)
SCENES_PER_CALL = 256


@dataclass(frozen=True)
class Scenes:
    """Vehicles in still scenes, one row each, sorted by ``scene``.

    Attributes:
        scene: (r,) int, which scene the vehicle is in (non-decreasing).
        x: (r,) [m] back centre, road frame. speed: (r,) [m/s]. lane: (r,) -1..-4.
        length: (r,) [m]. cf: (r, k) the driver's car-following parameters in the
            model's order (:attr:`~twin.traffic.models.base.CarFollowingModel.names`).
        hov_eligible: (r,) bool, may drive in the HOV lane.
    """

    scene: np.ndarray
    x: np.ndarray
    speed: np.ndarray
    lane: np.ndarray
    length: np.ndarray
    cf: np.ndarray
    hov_eligible: np.ndarray

    def __post_init__(self):
        r = self.scene.shape[0]
        for name in ("x", "speed", "lane", "length", "hov_eligible"):
            if getattr(self, name).shape != (r,):
                raise ValueError(f"scenes: {name} has shape {getattr(self, name).shape}, "
                                 f"not ({r},)")  # fmt: skip
        if self.cf.ndim != 2 or self.cf.shape[0] != r or self.cf.shape[1] > N_PARAMS:
            raise ValueError(f"scenes: cf has shape {self.cf.shape}, not ({r}, <= {N_PARAMS})")
        if r and np.any(np.diff(self.scene) < 0):
            raise ValueError("scenes: rows must be sorted by scene")
        bad = ~(np.isfinite(self.x) & np.isfinite(self.speed) & np.isfinite(self.length))
        if np.any(bad):
            raise ValueError(f"scenes: {int(bad.sum())} rows with a non-finite x, speed or "
                             "length")  # fmt: skip
        if np.any((self.lane > -1) | (self.lane < -4)):
            raise ValueError(f"scenes: lanes must be -1..-4, got {np.unique(self.lane)}")


def judge_scenes(scenes: Scenes, config: TrafficConfig) -> tuple[np.ndarray, np.ndarray]:
    """MOBIL's options of every vehicle of ``scenes``, as the traffic of ``config`` (its
    car-following model, MOBIL parameters, lane-change times, HOV openings, no passing
    on the right, ...) would judge them at a decision (module doc).

    Returns:
        gain: (r, 2) [m/s^2] MOBIL's gain less the driver's threshold (``config.mobil``'s)
            of a change to the left ([:, 0], toward lane -1) and to the right ([:, 1]);
            -inf where the rules do not allow the move (no lane, the HOV rule).
        possible: (r, 2) bool: allowed and safe.
    """
    model = car_following_model(config.car_following)
    if scenes.cf.shape[1] != len(model.names):
        raise ValueError(f"scenes: {scenes.cf.shape[1]} car-following parameters, "
                         f"{config.car_following} has {len(model.names)}")  # fmt: skip
    settings = kernel_settings(config, mean_driver_row(config.drivers, model, vehicle_classes()))
    r = scenes.scene.size
    gain = np.full((r, 2), -np.inf)
    possible = np.zeros((r, 2), dtype=bool)
    if r == 0:
        return gain, possible
    for rows, traffic, scene, slot in scene_blocks(scenes, config, settings):
        g = np.empty((*traffic.vehicles.valid.shape, 2))
        p = np.empty(g.shape, dtype=bool)
        _judge_kernel(state.pack(traffic), g, p)
        gain[rows], possible[rows] = g[scene, slot], p[scene, slot]
    return gain, possible


def scene_blocks(scenes: Scenes, config: TrafficConfig, settings=None):
    """The scenes as the kernels' traffic, :data:`SCENES_PER_CALL` at a time: yields
    (rows, traffic, scene, slot): the slice of ``scenes``' rows in the block, the
    block's :data:`~twin.traffic.kernels.state.Traffic` (one episode per scene, its
    drivers due to decide now), and each row's episode and slot in it."""
    if settings is None:
        model = car_following_model(config.car_following)
        settings = kernel_settings(config, mean_driver_row(config.drivers, model,
                                                           vehicle_classes()))  # fmt: skip
    r = scenes.scene.size
    starts = np.flatnonzero(np.r_[True, np.diff(scenes.scene) != 0]) if r else np.zeros(0, int)
    bounds = np.r_[starts, r]
    for first in range(0, starts.size, SCENES_PER_CALL):
        a, b = bounds[first], bounds[min(first + SCENES_PER_CALL, starts.size)]
        scene = np.searchsorted(starts, np.arange(a, b), side="right") - 1 - first
        slot = np.arange(a, b) - starts[first + scene]
        rows = slice(a, b)
        yield rows, _traffic(scenes, rows, scene, slot, config, settings), scene, slot


def _traffic(scenes, rows, scene, slot, config, settings) -> state.Traffic:
    """The kernels' traffic of the scenes of ``rows`` (``scene`` and ``slot`` of each
    row in the block)."""
    b, n = int(scene[-1]) + 1, int(slot.max()) + 1
    shape = (b, n)

    def place(values, dtype=float, fill=0.0):
        out = np.full(shape, fill, dtype=dtype)
        out[scene, slot] = values
        return out

    valid = place(True, bool, False)
    top = np.bincount(scene, minlength=b).astype(np.int64)
    lane = scenes.lane[rows].astype(np.int64)
    length = scenes.length[rows]
    vehicles = state.Vehicles(
        valid=valid, top=top, x=place(scenes.x[rows]), y=place((0.5 - lane) * LANE_WIDTH),
        yaw=np.zeros(shape), speed=place(scenes.speed[rows]), lane=place(lane, np.int64),
        length=place(length), width=place(np.full(lane.size, 2.0)), wheelbase=place(0.6 * length),
        mu=np.ones(shape),
    )  # fmt: skip
    obstacles = state.Obstacles(
        count=np.zeros(b, np.int64), lane=np.zeros((b, 1), np.int64), x=np.zeros((b, 1)),
        length=np.zeros((b, 1)), speed=np.zeros((b, 1)), accel=np.zeros((b, 1)),
        reach=np.zeros((b, 1), np.int64),
    )  # fmt: skip
    drivers = state.drivers(b, n)
    cf = scenes.cf[rows]
    drivers.cf[scene, slot, : cf.shape[1]] = cf
    drivers.key[scene, slot] = slot
    drivers.hov_eligible[scene, slot] = scenes.hov_eligible[rows]
    drivers.auto[scene, slot] = True
    drivers.lane[scene, slot] = lane
    drivers.lane_from[scene, slot] = lane
    mobil = config.mobil
    for name in ("politeness", "threshold", "safe_decel", "keep_right"):
        getattr(drivers, name)[scene, slot] = np.broadcast_to(
            np.asarray(getattr(mobil, name), dtype=float), lane.shape
        )
    traffic = state.Traffic(
        vehicles=vehicles, obstacles=obstacles, drivers=drivers, scratch=state.scratch(b, n, 1),
        settings=settings, counters=state.counters(b), actions=np.zeros(b),
    )  # fmt: skip
    return traffic
