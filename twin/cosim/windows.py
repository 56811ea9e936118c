"""The paper's windows around the ego: the visible window, whose recorded vehicles are
simulated, and the ghost windows beyond it, whose recorded vehicles are the boundary
condition (the ghost set, reloaded from the data every step), clipped to where the
map and the data exist."""

from dataclasses import dataclass

import numpy as np

from mapgen.build import MapBundle
from twin.core.errors import TwinError
from twin.data.empirical import EmpiricalTraffic, Snapshot

MAP_MARGIN = 30.0  # [m] windows stay this far inside the map's ends (a body must fit)


class ScenarioError(TwinError):
    """The scenario cannot run on these data and this map (e.g. the data end too soon)."""


@dataclass(frozen=True)
class Windows:
    """Road-frame x ranges [m] of the back centres in each window, clipped to where
    the map and the data exist: ``ghost_back`` < ``visible`` < ``ghost_front``."""

    ghost_back: tuple[float, float]
    visible: tuple[float, float]
    ghost_front: tuple[float, float]

    @classmethod
    def around(
        cls, x: float, w_visible: float, w_ghost: float, limits: tuple[float, float]
    ) -> "Windows":
        lo, hi = limits

        def clip(a, b):
            return (min(max(a, lo), hi), min(max(b, lo), hi))

        return cls(
            ghost_back=clip(x - w_visible - w_ghost, x - w_visible),
            visible=clip(x - w_visible, x + w_visible),
            ghost_front=clip(x + w_visible, x + w_visible + w_ghost),
        )

    @property
    def span(self) -> tuple[float, float]:
        return self.ghost_back[0], self.ghost_front[1]

    def in_visible(self, x: np.ndarray) -> np.ndarray:
        return (x >= self.visible[0]) & (x <= self.visible[1])

    def bounds(self, x: np.ndarray) -> tuple[int, int, int, int]:
        """For ``x`` sorted: (a, b, c, d) such that ``x[a:b]`` is in the rear ghost
        window, ``x[b:c]`` in the visible window and ``x[c:d]`` in the front one."""
        a, b = x.searchsorted((self.ghost_back[0], self.visible[0]))
        c, d = x.searchsorted((self.visible[1], self.ghost_front[1]), side="right")
        return int(a), int(b), int(c), int(d)


@dataclass(frozen=True, eq=False)
class Ghosts:
    """The ghost set: recorded vehicles in the ghost windows, (k,) arrays sorted by x
    (``tid`` store index, ``lane``, ``x`` [m] back centre, ``y`` [m], ``speed`` [m/s],
    ``length`` [m])."""

    tid: np.ndarray
    lane: np.ndarray
    x: np.ndarray
    y: np.ndarray
    speed: np.ndarray
    length: np.ndarray

    @classmethod
    def take(cls, snap: Snapshot, rows: np.ndarray) -> "Ghosts":
        return cls(
            snap.tid[rows], snap.lane[rows], snap.x[rows], snap.y[rows], snap.speed[rows],
            snap.length[rows],
        )  # fmt: skip

    def __len__(self) -> int:
        return self.tid.size


def no_ghosts() -> Ghosts:
    """An empty ghost set."""
    empty = np.empty(0)
    return Ghosts(empty.astype(np.int32), empty.astype(np.int8), empty, empty, empty, empty)


def road_limits(bundle: MapBundle, traffic: EmpiricalTraffic, road) -> tuple[float, float]:
    """[m] the x range where the map has road and the data have vehicles on ``road``."""
    m0, m1 = bundle.road.x_range(road)
    table = traffic.store.trajectories
    table = table[table["road"] == road.value]
    if table.empty:
        raise ScenarioError(f"the data hold no trajectories on {road.value}")
    d0 = float(np.minimum(table["x_first"], table["x_last"]).min())
    d1 = float(np.maximum(table["x_first"], table["x_last"]).max())
    lo, hi = max(m0 + MAP_MARGIN, d0), min(m1 - MAP_MARGIN, d1)
    if not lo < hi:
        raise ScenarioError(f"the map ({m0:.0f} to {m1:.0f} m) and data do not overlap")
    return lo, hi
