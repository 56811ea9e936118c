"""Independent oracles for the map tests, computed from the source CSVs directly."""

import math

import numpy as np
import pandas as pd

from twin.core.paths import asset

FT = 0.3048
MILE = 1609.344
EARTH_RADIUS = 6_371_008.8  # [m] mean radius (IUGG)


def grade_table() -> pd.DataFrame:
    return pd.read_csv(asset("i24_aux/grade_elevation.csv"))


def profile_height(mm: np.ndarray) -> np.ndarray:
    """[m] road height above its height at MM 60.6, linear in the CSV's 0.01 mi rows."""
    table = grade_table()
    feet = np.interp(mm, table["MM"], table["elevation (ft)"])
    return (feet - np.interp(60.6, table["MM"], table["elevation (ft)"])) * FT


def posts() -> pd.DataFrame:
    return pd.read_csv(asset("i24_aux/mile_marker_layer.csv")).sort_values("MM")


def azimuth(lat1, lon1, lat2, lon2) -> float:
    """[deg] azimuth between two close points on the WGS84 ellipsoid, from the radii of
    curvature in the meridian (M) and the prime vertical (N) at their mean latitude."""
    a, f = 6378137.0, 1 / 298.257223563
    e2 = f * (2 - f)
    phi = math.radians((lat1 + lat2) / 2)
    w = 1 - e2 * math.sin(phi) ** 2
    m = a * (1 - e2) / w**1.5
    n = a / math.sqrt(w)
    east = math.radians(lon2 - lon1) * n * math.cos(phi)
    north = math.radians(lat2 - lat1) * m
    return math.degrees(math.atan2(east, north)) % 360.0


def haversine(lat1, lon1, lat2, lon2) -> float:
    """[m] great-circle distance (spherical Earth, within 0.5 % of the ellipsoid)."""
    p1, p2 = math.radians(lat1), math.radians(lat2)
    a = (
        math.sin((p2 - p1) / 2) ** 2
        + math.cos(p1) * math.cos(p2) * math.sin(math.radians(lon2 - lon1) / 2) ** 2
    )
    return 2 * EARTH_RADIUS * math.asin(math.sqrt(a))
