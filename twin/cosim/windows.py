"""The paper's windows around the ego: the visible window, whose recorded vehicles are
simulated, and the ghost windows beyond it, whose recorded vehicles are the boundary
condition (the ghost set, reloaded from the data every step), clipped to where the
map and the data exist."""

from dataclasses import dataclass

import numpy as np

from mapgen.build import MapBundle
from twin.core.errors import TwinError
from twin.data.empirical import EmpiricalTraffic

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

    @property
    def span(self) -> tuple[float, float]:
        return self.ghost_back[0], self.ghost_front[1]


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

    def __len__(self) -> int:
        return self.tid.size


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
