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


def ramp_lane_width(road_name: str, x: float) -> float:
    """[m] the acceleration lane's width at road-frame ``x``, from the landmark layer's
    mile markers and the geometry the map documents (a 30 m opening before the gore, a
    300 ft taper ending at the merge's end), worked out here in feet and mile markers."""
    table = pd.read_csv(asset("i24_aux/ramp_and_landmark_layer.csv")).set_index("Landmark name")
    stem = "eb_HH_on" if road_name == "eastbound" else "wb_OH_on"
    start, end = table.loc[f"{stem}_start", "MM"], table.loc[f"{stem}_end", "MM"]
    mm = 60.6 + x / 1609.344 if road_name == "eastbound" else 61.6 - x / 1609.344
    along = (mm - start) * 5280.0 if road_name == "eastbound" else (start - mm) * 5280.0  # [ft]
    to_end = abs(end - mm) * 5280.0 * (1 if (end - mm) * (end - start) > 0 else -1)  # [ft]
    if along < -30.0 / FT or to_end <= 0.0:
        return 0.0
    if along < 0.0:
        return 12.0 * FT * (1.0 + along / (30.0 / FT))
    return 12.0 * FT * min(1.0, to_end / 300.0)
