"""The recorded traffic the cameras see beyond the simulated vehicles: the ghosts, the
recorded vehicles past the ghost windows up to the far plane, and the other
carriageway's traffic, each replayed kinematically from the data (never a physics
body) at its recorded position, with its heading from its recorded path (so lane
changes show) and its recorded size and class.
"""

from dataclasses import dataclass, replace

import numpy as np

from twin.core.i24 import Road

HEADING_LEAD = 0.2  # [s] the heading is the recorded path's direction over this time
STILL = 0.05  # [m] moving less than this over HEADING_LEAD: the road's heading


@dataclass(frozen=True, eq=False)
class Replayed:
    """Recorded vehicles posed for one picture, (n,) or (n, ...) arrays.

    Attributes:
        tid: store trajectory index. record_id: I-24 MOTION ``_id``.
        road: +1 eastbound, -1 westbound. vehicle_class: index into the classes.
        size: (n, 3) [m] length, width, height.
        position: (n, 3) [m] world, the centre of the box's bottom face.
        rotation: (n, 3, 3) box-to-world (columns: forward, left, up).
        speed: [m/s] recorded.
    """

    tid: np.ndarray
    record_id: np.ndarray
    road: np.ndarray
    vehicle_class: np.ndarray
    size: np.ndarray
    position: np.ndarray
    rotation: np.ndarray
    speed: np.ndarray

    def __len__(self) -> int:
        return int(self.tid.size)

    def take(self, index) -> "Replayed":
        """The vehicles at ``index`` (indices or a boolean mask)."""
        return Replayed(*(getattr(self, f)[index] for f in _FIELDS))


class RecordedView:
    """What of the recording a camera on a simulated ego can see, replayed.

    Args:
        traffic: the recorded traffic (``EmpiricalTraffic``).
        road_model: the map's road model (road frame to world).
        radius: [m] along the road from the camera (the far plane).
    """

    def __init__(self, traffic, road_model, radius: float):
        self.traffic, self.road_model, self.radius = traffic, road_model, float(radius)
        self._preloaded: set = set()

    def preload(self, t_start: float, t_end: float) -> None:
        """Read both roads' samples of ``[t_start, t_end]`` once, for fast queries."""
        for road in (Road.EASTBOUND, Road.WESTBOUND):
            if road not in self._preloaded and road.value in self._roads():
                self.traffic.preload(road, t_start, t_end)
                self._preloaded.add(road)

    def _roads(self) -> list:
        return list(self.traffic.store.metadata.get("roads", {}) or ["eastbound", "westbound"])

    def around(
        self, t: float, station: float, simulated: np.ndarray, drawn=None, drawn_road=None
    ) -> Replayed:
        """The recorded vehicles at unix time ``t`` within ``radius`` of ``station``
        [m, along the map's reference direction] on both roads, but those simulated
        (``simulated``: (trajectories,) bool by store index). ``drawn``
        (:class:`twin.cosim.core.drawn.Drawn`), on road ``drawn_road``: the
        cosimulation's own drawing of its road's recording, which the replay follows
        (anchored vehicles where they are drawn, those held undrawn left out)."""
        parts = []
        for road in (Road.EASTBOUND, Road.WESTBOUND):
            if road.value not in self._roads():
                continue
            lo, hi = self.road_model.x_range(road)
            snap = self.traffic.snapshot(road, t, lo, hi)
            if len(snap.tid) == 0:
                continue
            shift = drawn if drawn is not None and road == drawn_road else None
            if shift is not None:
                snap = _shifted(snap, shift)
            centre = snap.x + 0.5 * snap.length
            near = np.abs(self.road_model.station(road, centre) - station) <= self.radius
            keep = near & ~simulated[snap.tid]
            if shift is not None:
                # held undrawn by the cosimulation, or drawn (anchored) past the road's
                # ends, which the cosimulation drops
                keep &= ~shift.hidden[snap.tid] & (snap.x >= lo) & (snap.x <= hi)
            if keep.any():
                parts.append(self._posed(road, t, snap, np.flatnonzero(keep), shift))
        if not parts:
            return _empty()
        return Replayed(*(np.concatenate([getattr(p, f) for p in parts]) for f in _FIELDS))

    def _posed(self, road: Road, t: float, snap, rows: np.ndarray, shift=None) -> Replayed:
        tid = snap.tid[rows]
        length, width = snap.length[rows], snap.width[rows]
        height = snap.height[rows]
        x, y = snap.x[rows] + 0.5 * length, snap.y[rows]
        lo, hi = self.road_model.x_range(road)
        position, heading, pitch = self.road_model.to_world(road, np.clip(x, lo, hi), y)
        # the heading from the recorded path a moment later (lane changes show)
        later = self.traffic.snapshot(road, t + HEADING_LEAD, lo, hi)
        if shift is not None and later.tid.size:
            later = _shifted(later, shift)
        forward = np.column_stack([np.cos(heading), np.sin(heading), np.tan(pitch)])
        found = np.zeros(tid.size, bool)
        if later.tid.size:
            order = np.argsort(later.tid, kind="stable")
            at = order[np.minimum(np.searchsorted(later.tid[order], tid), order.size - 1)]
            found = later.tid[at] == tid
        if found.any():
            rows_later = at[found]
            x2 = later.x[rows_later] + 0.5 * later.length[rows_later]
            p2, _, _ = self.road_model.to_world(road, np.clip(x2, lo, hi), later.y[rows_later])
            step = p2 - position[found]
            moving = np.hypot(step[:, 0], step[:, 1]) > STILL
            forward[np.flatnonzero(found)[moving]] = step[moving]
        forward /= np.linalg.norm(forward, axis=1, keepdims=True)
        left = np.cross([0.0, 0.0, 1.0], forward)
        left /= np.linalg.norm(left, axis=1, keepdims=True)
        up = np.cross(forward, left)
        return Replayed(
            tid=tid.astype(np.int64),
            record_id=np.asarray(snap.id[rows], dtype=object),
            road=np.full(tid.size, road.direction, np.int64),
            vehicle_class=snap.vehicle_class[rows].astype(np.int64),
            size=np.column_stack([length, width, height]),
            position=position,
            rotation=np.stack([forward, left, up], axis=2),
            speed=snap.speed[rows].astype(np.float64),
        )


def _shifted(snap, drawn):
    """A snapshot with its anchored vehicles where the cosimulation draws them."""
    tid = snap.tid
    return replace(
        snap,
        x=snap.x + drawn.off_x[tid],
        y=snap.y + drawn.off_y[tid],
        speed=np.maximum(snap.speed + drawn.off_v[tid], 0.0),
    )


_FIELDS = ("tid", "record_id", "road", "vehicle_class", "size", "position", "rotation", "speed")


def _empty() -> Replayed:
    return Replayed(
        np.empty(0, np.int64), np.empty(0, object), np.empty(0, np.int64),
        np.empty(0, np.int64), np.empty((0, 3)), np.empty((0, 3)), np.empty((0, 3, 3)),
        np.empty(0),
    )  # fmt: skip


class FrameTraffic:
    """The recorded traffic of a cosimulation's camera frames: what to replay at the
    current step and the records of the simulated vehicles (for
    :meth:`sensors.camera.CameraRig.capture`).

    Args:
        sim: the cosimulator (after ``reset``).
        road_model: the map's road model.
        radius: [m] along the road from the ego (the cameras' far plane).
    """

    def __init__(self, sim, road_model, radius: float):
        self.sim, self.road_model = sim, road_model
        self.view = RecordedView(sim.traffic, road_model, radius)
        self.view.preload(sim.t0, sim.t0 + sim.config.t_max + HEADING_LEAD)

    def tids_of(self, ids):
        """The store trajectory indices of simulated vehicles ``ids`` (-1: none; every
        vehicle of a cosimulation has one)."""
        return self.sim.tids_of(np.asarray(ids, np.int64))

    def replayed(self) -> Replayed:
        """The recorded vehicles to draw now."""
        sim = self.sim
        states = sim.world.states()
        ego = states.id == sim.ego_id
        centre = states.x[ego] + 0.5 * sim.world.params.length[ego]
        station = float(self.road_model.station(sim.road, centre)[0])
        return self.view.around(sim.t, station, sim.simulated, sim.drawn, sim.road)

    def record_of(self, ids):
        """(record ids, roads) of simulated vehicles ``ids``."""
        ids = np.asarray(ids, np.int64)
        return self.sim.records_of(ids), np.full(ids.size, self.sim.direction, np.int64)
