"""The road model: the segment's alignment, elevation profile and cross-section, and the
vectorised transforms between the road frame and the world frame.

World frame (``docs/design.md``): local east-north-up metres, origin on the median centre line
at MM 60.6, z = 0 at the road elevation there. The alignment is the straight line
through the mile-marker posts (bearing about 138 degrees), stationed by nominal mile
length: eastbound station ``s = (MM - 60.6) * 1609.344`` is the horizontal distance
from the origin along the bearing, so that I-24 MOTION x maps exactly (the posts
themselves are closer together than a mile; :meth:`RoadModel.to_geodetic` accounts
for that when it places a world point on the globe).

Road frame per carriageway (``docs/design.md``): ``x`` along travel from the segment entry,
``y`` from the median centre line outward, lanes -1 (inner, HOV) to -4 and, where an
on-ramp's acceleration lane runs beside lane -4, lane -5 (:mod:`twin.core.ramps`: its
pavement widens the road there, and the shoulder lies beyond it). Eastbound
lies to the right of the eastbound direction, westbound to the left, so the world
point of ``(road, x, y)`` is ``O + s * d + direction * y * r`` with ``d`` the unit
vector along the bearing and ``r`` the unit vector to its right.

The pavement is laterally level (no cross-slope is modelled): its height depends on
the station only, linear between the 0.01 mi points of ``grade_elevation.csv``.
"""

import math
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from mapgen import geodesy
from mapgen.params import MapParams
from mapgen.sources import PROFILE_STEP_MI, Sources
from twin.core import ramps as ramp_lanes
from twin.core.errors import MapError
from twin.core.i24 import (
    LANE_WIDTH,
    MILE,
    N_LANES,
    SEGMENT_LENGTH,
    SEGMENT_START_MM,
    Road,
    lane_center,
    mile_marker,
)

EARTH_RADIUS = 6_371_000.0  # [m] mean radius, for the curvature drop of a tangent plane
STATION_TOLERANCE = 1e-6  # [m] beyond the map's ends still accepted as on the map


def station_of(mm: np.ndarray) -> np.ndarray:
    """Eastbound station [m] of mile markers: ``(MM - 60.6) * 1609.344``."""
    return (np.asarray(mm, dtype=np.float64) - SEGMENT_START_MM) * MILE


def mile_marker_of(station: np.ndarray) -> np.ndarray:
    """Mile markers of eastbound stations [m] (the inverse of :func:`station_of`)."""
    return mile_marker(station, Road.EASTBOUND)


class RoadCoordinates(NamedTuple):
    """Road-frame coordinates of world points (arrays of shape (n,)).

    ``road`` is the direction of the carriageway (+1 eastbound, -1 westbound; see
    :meth:`twin.core.i24.Road.parse`), ``lane`` is -1..-4, -5 on an acceleration lane
    (:func:`twin.core.ramps.lane_at`) or 0 off the lanes, and
    ``height`` [m] is above the pavement (NaN off the map's ends).
    """

    road: np.ndarray
    x: np.ndarray
    y: np.ndarray
    lane: np.ndarray
    height: np.ndarray


@dataclass(frozen=True, eq=False)
class RoadModel:
    """Alignment, profile and cross-section of the mapped segment.

    Attributes:
        origin: (lat [deg], lon [deg], elevation [m]) of the world origin.
        bearing: [deg] clockwise from north of eastbound travel.
        profile_s: (k,) float [m] eastbound stations of the profile points, increasing.
        profile_z: (k,) float [m] pavement height there (world z).
        post_mm: (p,) float, mile markers of the posts; post_along: (p,) [m] their
            geographic distance from the origin along the bearing.
        outer_edge: [m] road-frame y of the outer edge of the paved shoulder beside
            lane -4 (:meth:`outer_edge_at` adds an acceleration lane where there is one).
        ramps: the on-ramps' acceleration lanes (:class:`twin.core.ramps.Ramp`).
    """

    origin: tuple[float, float, float]
    bearing: float
    profile_s: np.ndarray
    profile_z: np.ndarray
    post_mm: np.ndarray
    post_along: np.ndarray
    outer_edge: float
    ramps: tuple[ramp_lanes.Ramp, ...] = ()
    _d: np.ndarray = field(init=False, repr=False)
    _r: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        b = math.radians(self.bearing)
        object.__setattr__(self, "_d", np.array([math.sin(b), math.cos(b)]))
        object.__setattr__(self, "_r", np.array([math.cos(b), -math.sin(b)]))
        if len(self.profile_s) < 2 or np.any(np.diff(self.profile_s) <= 0):
            raise MapError("road profile stations must increase")
        if self.outer_edge <= (N_LANES + 1) * LANE_WIDTH:
            raise MapError(f"outer edge {self.outer_edge} m lies inside the lanes")

    # -- construction ---------------------------------------------------------------

    @classmethod
    def from_sources(cls, sources: Sources, params: MapParams) -> "RoadModel":
        """Fit the alignment to the posts and cut the profile to the map's extent.

        Raises:
            MapError: the post at MM 60.6 is missing, fewer than two posts lie in the
                fit range, or the profile does not cover the map's extent.
        """
        at_origin = np.flatnonzero(np.isclose(sources.post_mm, SEGMENT_START_MM))
        if at_origin.size != 1:
            raise MapError(f"no mile-marker post at MM {SEGMENT_START_MM}")
        have = np.round(sources.profile_mm / PROFILE_STEP_MI).astype(np.int64)
        k0 = round(SEGMENT_START_MM / PROFILE_STEP_MI)
        if k0 not in have:
            raise MapError(f"the elevation profile has no row at MM {SEGMENT_START_MM}")
        z0 = float(sources.profile_elevation[np.searchsorted(have, k0)])
        origin = (float(sources.post_lat[at_origin[0]]), float(sources.post_lon[at_origin[0]]), z0)
        # Posts at the road's height at the origin, where from_geodetic puts points by
        # default, so that both measure distances at the same height.
        enu = geodesy.to_enu(
            sources.post_lat, sources.post_lon, np.full(sources.post_mm.size, z0), origin
        )[:, :2]
        lo, hi = params.alignment.fit_mm
        fit = (sources.post_mm >= lo - 1e-9) & (sources.post_mm <= hi + 1e-9)
        if np.count_nonzero(fit & (np.arange(fit.size) != at_origin[0])) < 1:
            raise MapError(f"no mile-marker post besides the origin in MM {lo}..{hi}")
        # The line through the origin closest to the posts: the principal axis of
        # their second moments about the origin.
        pts = enu[fit]
        _, vectors = np.linalg.eigh(pts.T @ pts)
        d = vectors[:, -1]
        if np.dot(pts[np.argmax(sources.post_mm[fit])], d) < 0:
            d = -d
        bearing = math.degrees(math.atan2(d[0], d[1])) % 360.0

        step = PROFILE_STEP_MI * MILE
        n_margin = math.ceil(params.extent.margin / step - 1e-9)
        n_segment = round(SEGMENT_LENGTH / step)
        wanted = np.arange(k0 - n_margin, k0 + n_segment + n_margin + 1)
        if wanted[0] < have[0] or wanted[-1] > have[-1]:
            raise MapError(
                f"the elevation profile covers MM {have[0] / 100:.2f}..{have[-1] / 100:.2f}, "
                f"the map needs {wanted[0] / 100:.2f}..{wanted[-1] / 100:.2f}"
            )
        elevation = sources.profile_elevation[np.searchsorted(have, wanted)]
        try:
            ramps = ramp_lanes.ramps_from_landmarks(
                {name: (d, mm) for name, (d, mm, _, _) in sources.landmarks.items()}
            )
        except ValueError as error:
            raise MapError(f"the landmark layer's on-ramps: {error}") from None
        return cls(
            origin=origin,
            bearing=bearing,
            profile_s=(wanted - k0) * step,
            profile_z=elevation - z0,
            post_mm=sources.post_mm.copy(),
            post_along=enu @ d,
            outer_edge=(N_LANES + 1) * LANE_WIDTH + params.cross_section.outer_shoulder,
            ramps=ramps,
        )

    def to_dict(self) -> dict:
        """A JSON-ready description (``road.json``'s ``road`` entry)."""
        return {
            "origin": {
                "lat_deg": self.origin[0],
                "lon_deg": self.origin[1],
                "elevation_m": self.origin[2],
            },
            "bearing_deg": self.bearing,
            "profile": {"station_m": self.profile_s.tolist(), "z_m": self.profile_z.tolist()},
            "posts": {"mm": self.post_mm.tolist(), "along_m": self.post_along.tolist()},
            "outer_edge_m": self.outer_edge,
            "ramps": [
                {"road": r.road.value, "name": r.name, "x_start_m": r.x_start, "x_end_m": r.x_end}
                for r in self.ramps
            ],
        }

    @classmethod
    def from_dict(cls, data: dict) -> "RoadModel":
        """Inverse of :meth:`to_dict`.

        Raises:
            MapError: naming a missing or malformed entry.
        """
        try:
            origin = data["origin"]
            return cls(
                origin=(
                    float(origin["lat_deg"]),
                    float(origin["lon_deg"]),
                    float(origin["elevation_m"]),
                ),
                bearing=float(data["bearing_deg"]),
                profile_s=np.asarray(data["profile"]["station_m"], dtype=np.float64),
                profile_z=np.asarray(data["profile"]["z_m"], dtype=np.float64),
                post_mm=np.asarray(data["posts"]["mm"], dtype=np.float64),
                post_along=np.asarray(data["posts"]["along_m"], dtype=np.float64),
                outer_edge=float(data["outer_edge_m"]),
                ramps=tuple(
                    ramp_lanes.Ramp(
                        Road.parse(r["road"]),
                        str(r["name"]),
                        float(r["x_start_m"]),
                        float(r["x_end_m"]),
                    )
                    for r in data["ramps"]
                ),
            )
        except (KeyError, TypeError, ValueError) as error:
            raise MapError(f"road description malformed: {error!r}") from None

    # -- frame geometry ---------------------------------------------------------------

    @property
    def direction_vector(self) -> np.ndarray:
        """(2,) unit east-north vector of eastbound travel."""
        return self._d.copy()

    @property
    def right_vector(self) -> np.ndarray:
        """(2,) unit east-north vector to the right of eastbound travel (toward eastbound)."""
        return self._r.copy()

    @property
    def station_range(self) -> tuple[float, float]:
        """[m] eastbound stations of the map's two ends."""
        return float(self.profile_s[0]), float(self.profile_s[-1])

    def x_range(self, road: Road | str | int) -> tuple[float, float]:
        """[m] road-frame x of the map's two ends on ``road``, increasing."""
        s0, s1 = self.station_range
        if Road.parse(road) is Road.EASTBOUND:
            return s0, s1
        return SEGMENT_LENGTH - s1, SEGMENT_LENGTH - s0

    def heading(self, road: Road | str | int) -> float:
        """[rad] world yaw (counter-clockwise from east) of travel on ``road``."""
        yaw = math.atan2(self._d[1], self._d[0])
        if Road.parse(road) is Road.WESTBOUND:
            yaw = math.atan2(-self._d[1], -self._d[0])
        return yaw

    def ramp_width(self, road, x: np.ndarray) -> np.ndarray:
        """[m] width of the acceleration lane (lane -5) at road-frame ``x`` on ``road``
        (a Road or (n,) directions), 0 where there is none."""
        return ramp_lanes.ramp_width(road, x, self.ramps)

    def outer_edge_at(self, road, x: np.ndarray) -> np.ndarray:
        """[m] road-frame y of the paved shoulder's outer edge at ``x`` on ``road``: beyond
        the acceleration lane where there is one."""
        return self.outer_edge + self.ramp_width(road, x)

    def ramp_stations(self) -> np.ndarray:
        """(k,) [m] eastbound stations on the map where an acceleration lane's width
        changes slope (its opening, gore, taper and end), increasing."""
        if not self.ramps:
            return np.empty(0)
        stations = np.concatenate([self.station(r.road, r.breakpoints) for r in self.ramps])
        s0, s1 = self.station_range
        return np.unique(stations[(stations > s0) & (stations < s1)])

    def surface_z(self, station: np.ndarray) -> np.ndarray:
        """[m] pavement height at eastbound stations (anywhere across the carriageways)."""
        return np.interp(station, self.profile_s, self.profile_z)

    def station(self, road, x: np.ndarray) -> np.ndarray:
        """Eastbound station [m] of road-frame x on ``road`` (a Road or (n,) directions)."""
        direction = _directions(road, np.shape(x))
        x = np.asarray(x, dtype=np.float64)
        return np.where(direction > 0, x, SEGMENT_LENGTH - x)

    # -- transforms -------------------------------------------------------------------

    def to_world(
        self, road, x: np.ndarray, y: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """World pose of road-frame points on the pavement.

        Args:
            road: a :class:`~twin.core.i24.Road` (or its name, or +1/-1) for all
                points, or (n,) int directions, one per point.
            x: (n,) [m] along travel from the segment entry.
            y: (n,) [m] from the median centre line outward.

        Returns:
            positions (n, 3) [m] on the pavement, heading (n,) [rad] world yaw of
            travel, pitch (n,) [rad] nose-up along travel (the grade ahead).

        Raises:
            ValueError: a coordinate is not finite, or x lies beyond the map's ends.
        """
        x, y = np.broadcast_arrays(np.asarray(x, np.float64), np.asarray(y, np.float64))
        x, y = np.atleast_1d(x), np.atleast_1d(y)
        if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
            raise ValueError("road-frame x and y must be finite")
        direction = _directions(road, x.shape)
        s = np.where(direction > 0, x, SEGMENT_LENGTH - x)
        s0, s1 = self.station_range
        outside = (s < s0 - STATION_TOLERANCE) | (s > s1 + STATION_TOLERANCE)
        if outside.any():
            i = int(np.flatnonzero(outside)[0])
            raise ValueError(
                f"x = {x[i]:.3f} m on {Road.parse(int(direction[i])).value} lies beyond the "
                f"map, which covers x in {self.x_range(int(direction[i]))} m there"
            )
        lateral = direction * y
        positions = np.empty((x.size, 3))
        positions[:, :2] = s[:, None] * self._d + lateral[:, None] * self._r
        positions[:, 2] = self.surface_z(s)
        yaw_eb = math.atan2(self._d[1], self._d[0])
        heading = np.where(direction > 0, yaw_eb, math.atan2(-self._d[1], -self._d[0]))
        return positions, heading, np.arctan(direction * self._slope_ahead(s, direction))

    def to_road(self, positions: np.ndarray) -> RoadCoordinates:
        """Road-frame coordinates of (n, 3) world points (the inverse of :meth:`to_world`).

        A point on the median centre line belongs to the eastbound carriageway.

        Raises:
            ValueError: ``positions`` is not (n, 3) or not finite.
        """
        positions = np.asarray(positions, dtype=np.float64)
        if positions.ndim == 1:
            positions = positions[None]
        if positions.ndim != 2 or positions.shape[1] != 3:
            raise ValueError(f"positions must be (n, 3), got shape {positions.shape}")
        if not np.all(np.isfinite(positions)):
            raise ValueError("positions must be finite")
        s = positions[:, :2] @ self._d
        lateral = positions[:, :2] @ self._r
        direction = np.where(lateral >= 0.0, 1, -1).astype(np.int8)
        y = np.abs(lateral)
        s0, s1 = self.station_range
        on_map = (s >= s0 - STATION_TOLERANCE) & (s <= s1 + STATION_TOLERANCE)
        height = np.where(on_map, positions[:, 2] - self.surface_z(s), np.nan)
        x = np.where(direction > 0, s, SEGMENT_LENGTH - s)
        return RoadCoordinates(
            road=direction,
            x=x,
            y=y,
            lane=ramp_lanes.lane_at(direction, x, y, self.ramps),
            height=height,
        )

    def lane_center_line(self, road, lane: int, x: np.ndarray) -> np.ndarray:
        """(n, 3) [m] world points of lane ``lane``'s centre line at road-frame ``x``."""
        x = np.atleast_1d(np.asarray(x, dtype=np.float64))
        return self.to_world(road, x, np.full(x.shape, float(lane_center(lane))))[0]

    def _slope_ahead(self, s: np.ndarray, direction: np.ndarray) -> np.ndarray:
        """dz/ds of the profile piece the traveller is about to drive on."""
        # At a profile point, eastbound drives onto the piece after it, westbound onto
        # the piece before it.
        after = np.searchsorted(self.profile_s, s, side="right") - 1
        before = np.searchsorted(self.profile_s, s, side="left") - 1
        piece = np.clip(np.where(direction > 0, after, before), 0, len(self.profile_s) - 2)
        return np.diff(self.profile_z)[piece] / np.diff(self.profile_s)[piece]

    # -- geo-reference ----------------------------------------------------------------

    def to_geodetic(self, positions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """WGS84 (lat [deg], lon [deg]) and elevation [m] of (n, 3) world points.

        The station is turned into a mile marker and placed along the bearing where the
        posts put that mile marker (piecewise linear between posts); the lateral offset
        is kept. Elevation is the profile's datum (``grade_elevation.csv``) plus z.

        Raises:
            ValueError: a point lies beyond the posts.
        """
        positions = np.atleast_2d(np.asarray(positions, dtype=np.float64))
        mm = mile_marker_of(positions[:, :2] @ self._d)
        if np.any((mm < self.post_mm[0]) | (mm > self.post_mm[-1])):
            raise ValueError(f"points beyond the posts (MM {self.post_mm[0]}..{self.post_mm[-1]})")
        along = np.interp(mm, self.post_mm, self.post_along)
        lateral = positions[:, :2] @ self._r
        enu = np.empty_like(positions)
        enu[:, :2] = along[:, None] * self._d + lateral[:, None] * self._r
        enu[:, 2] = positions[:, 2] - (enu[:, 0] ** 2 + enu[:, 1] ** 2) / (2.0 * EARTH_RADIUS)
        return geodesy.from_enu(enu, self.origin)

    def from_geodetic(
        self, lat_deg: np.ndarray, lon_deg: np.ndarray, elevation: np.ndarray | None = None
    ) -> np.ndarray:
        """(n, 3) world points of WGS84 positions (inverse of :meth:`to_geodetic`).

        With no ``elevation`` the points are put on the pavement's height.

        Raises:
            ValueError: a point lies beyond the posts.
        """
        lat = np.atleast_1d(np.asarray(lat_deg, dtype=np.float64))
        lon = np.atleast_1d(np.asarray(lon_deg, dtype=np.float64))
        h = np.full(lat.shape, self.origin[2]) if elevation is None else np.asarray(elevation)
        enu = geodesy.to_enu(lat, lon, h, self.origin)
        along = enu[:, :2] @ self._d
        if np.any((along < self.post_along.min()) | (along > self.post_along.max())):
            raise ValueError("points beyond the posts")
        order = np.argsort(self.post_along)
        mm = np.interp(along, self.post_along[order], self.post_mm[order])
        s = station_of(mm)
        lateral = enu[:, :2] @ self._r
        out = np.empty((lat.size, 3))
        out[:, :2] = s[:, None] * self._d + lateral[:, None] * self._r
        out[:, 2] = self.surface_z(s) if elevation is None else h - self.origin[2]
        return out


def _directions(road, shape: tuple[int, ...]) -> np.ndarray:
    """(n,) int directions from one road for all points or one direction per point."""
    if isinstance(road, (Road, str, int, np.integer)):
        return np.full(shape, Road.parse(road).direction, dtype=np.int8)
    direction = np.asarray(road)
    # (== rather than np.isin: this runs every physics step on a few dozen values)
    if direction.shape != tuple(shape) or not np.all((direction == 1) | (direction == -1)):
        raise ValueError(f"road must be a Road or an array of +1/-1 of shape {shape}")
    return direction.astype(np.int8)
