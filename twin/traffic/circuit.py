"""A circuit on the straight map: traffic that leaves the map's far end comes back at
its near end, so the traffic manager and the physics can be run for minutes with a
fixed number of vehicles (closed-loop tests and ``twin bench traffic``).

A vehicle that reaches the exit is despawned and re-spawned at the entry of its lane,
at the speed of the last vehicle there, once that vehicle has left room for it.
"""

from dataclasses import dataclass

import numpy as np

from twin.core.i24 import LANES, lane_center
from twin.core.vehicle_classes import vehicle_classes
from twin.physics.states import SpawnStates
from twin.physics.world import PhysicsWorld
from twin.traffic.manager import TrafficManager

ENTRY_MARGIN = 20.0  # [m] from the map's ends to the entry and the exit
ENTRY_GAP = 12.0  # [m] room (back to back) a re-entering vehicle needs ahead of it
ENTRY_HEADWAY = 1.5  # [s] and this much time at the speed of the vehicle ahead


@dataclass(frozen=True)
class CircuitSpec:
    """Traffic on one road of the map.

    Attributes:
        road: +1 eastbound or -1 westbound.
        vehicles: how many, spread evenly over the four lanes.
        speed: [m/s] initial speed; desired speeds are drawn per class.
        seed: seed of the classes, sizes and positions.
    """

    road: int = 1
    vehicles: int = 100
    speed: float = 25.0
    seed: int = 0


class Circuit:
    """Spawn ``spec.vehicles`` on the map and keep them there (see the module doc)."""

    def __init__(self, world: PhysicsWorld, manager: TrafficManager, spec: CircuitSpec):
        self.world, self.manager, self.spec = world, manager, spec
        self.rng = np.random.default_rng(spec.seed)
        self.classes = vehicle_classes()
        x0, x1 = world.road.x_range(spec.road)
        self.entry, self.exit = x0 + ENTRY_MARGIN, x1 - ENTRY_MARGIN
        self.recycled = 0
        self.waiting = dict.fromkeys(LANES, 0)  # vehicles waiting to re-enter, per lane
        n = spec.vehicles
        lanes = np.array(LANES)[np.arange(n) % len(LANES)]
        per_lane = -(-n // len(LANES))
        spacing = (self.exit - self.entry - 50.0) / per_lane
        slot = np.arange(n) // len(LANES)
        x = self.entry + slot * spacing + self.rng.uniform(0.0, 0.2 * spacing, n)
        self._spawn(lanes, x, np.full(n, spec.speed), self._draw_classes(lanes))

    def _draw_classes(self, lanes: np.ndarray) -> np.ndarray:
        share = self.classes.column("share")
        vehicle_class = self.rng.choice(len(share), size=lanes.size, p=share)
        heavy = self.classes.column("hov_allowed")[vehicle_class] == 0
        return np.where((lanes == -1) & heavy, 0, vehicle_class)

    def _spawn(self, lanes, x, speed, vehicle_class) -> np.ndarray:
        sizes = self.classes.sample_dimensions(vehicle_class, self.rng).T
        ids = self.world.spawn(
            SpawnStates.make(self.spec.road, x, lane_center(lanes), speed, vehicle_class, *sizes)
        )
        self.manager.add(
            ids,
            np.full(ids.size, self.spec.road),
            lanes,
            self.world.params_of(ids),
        )
        return ids

    def recycle(self, states) -> None:
        """Take vehicles past the exit off the road; bring waiting ones back at the
        entry, one per lane and step, where the lane has room."""
        out = states.x > self.exit
        if out.any():
            gone = states.id[out]
            for lane in self.manager.lanes(gone):
                self.waiting[int(lane)] += 1
            self.world.despawn(gone)
            self.manager.remove(gone)
        lanes, speeds = [], []
        for lane, count in self.waiting.items():
            if count == 0:
                continue
            in_lane = np.flatnonzero(~out & (states.lane == lane))
            speed = self.spec.speed
            if in_lane.size:
                tail = in_lane[np.argmin(states.x[in_lane])]
                speed = max(float(states.speed[tail]), 0.0)
                if states.x[tail] - self.entry < ENTRY_GAP + ENTRY_HEADWAY * speed:
                    continue
            lanes.append(lane)
            speeds.append(speed)
            self.waiting[lane] -= 1
        if lanes:
            lanes = np.array(lanes)
            self._spawn(
                lanes, np.full(lanes.size, self.entry), np.array(speeds), self._draw_classes(lanes)
            )
            self.recycled += lanes.size
