"""Where the sun is: its elevation and azimuth over the I-24 segment at a time, and the
light the cameras' renderer gets from it.

The position follows NOAA's general solar position equations (the Spencer series for
the declination and the equation of time, as in NOAA's solar calculator's
documentation, "General Solar Position Calculations"): within about 0.3 degrees of
the sun's true position over 1950-2050, well inside a camera's needs; no refraction.
The segment's latitude and longitude are the mean of its mile posts
(``assets/i24_aux/mile_marker_layer.csv``, I-24 MOTION infrastructure data).
"""

import math
from dataclasses import dataclass
from functools import cache

import numpy as np

from twin.core.paths import asset

SUN_MODES = ("recorded", "noon", "random")


@dataclass(frozen=True)
class SunPosition:
    """The sun seen from the ground.

    Attributes:
        elevation_deg: above the horizon [deg] (negative: below it).
        azimuth_deg: clockwise from true north [deg], 0..360.
    """

    elevation_deg: float
    azimuth_deg: float

    def direction_enu(self) -> np.ndarray:
        """Unit vector toward the sun, (east, north, up)."""
        el, az = math.radians(self.elevation_deg), math.radians(self.azimuth_deg)
        return np.array([math.cos(el) * math.sin(az), math.cos(el) * math.cos(az), math.sin(el)])


def sun_position(unix_time: float, latitude: float, longitude: float) -> SunPosition:
    """The sun's elevation and azimuth at ``unix_time`` [s] seen from ``latitude``,
    ``longitude`` [deg, north and east positive].

    Raises:
        ValueError: a non-finite time or a position off the globe.
    """
    if not math.isfinite(unix_time):
        raise ValueError(f"time must be finite, got {unix_time!r}")
    if not (-90.0 <= latitude <= 90.0 and -180.0 <= longitude <= 180.0):
        raise ValueError(f"no place at latitude {latitude!r}, longitude {longitude!r}")
    days = unix_time / 86400.0
    day_start = math.floor(days)
    minutes = (days - day_start) * 1440.0  # UTC minutes into the day
    year_day, year_length = _day_of_year(day_start)
    g = 2.0 * math.pi / year_length * (year_day - 1 + (minutes / 60.0 - 12.0) / 24.0)
    equation_of_time = 229.18 * (
        0.000075
        + 0.001868 * math.cos(g)
        - 0.032077 * math.sin(g)
        - 0.014615 * math.cos(2 * g)
        - 0.040849 * math.sin(2 * g)
    )  # [min]
    declination = (
        0.006918
        - 0.399912 * math.cos(g)
        + 0.070257 * math.sin(g)
        - 0.006758 * math.cos(2 * g)
        + 0.000907 * math.sin(2 * g)
        - 0.002697 * math.cos(3 * g)
        + 0.00148 * math.sin(3 * g)
    )  # [rad]
    true_solar = minutes + equation_of_time + 4.0 * longitude  # [min]
    hour_angle = math.radians(true_solar / 4.0 - 180.0)
    lat = math.radians(latitude)
    sin_el = math.sin(lat) * math.sin(declination) + math.cos(lat) * math.cos(
        declination
    ) * math.cos(hour_angle)
    elevation = math.degrees(math.asin(max(-1.0, min(1.0, sin_el))))
    # azimuth from south, westward positive; then from north, clockwise
    from_south = math.atan2(
        math.sin(hour_angle),
        math.cos(hour_angle) * math.sin(lat) - math.tan(declination) * math.cos(lat),
    )
    azimuth = (math.degrees(from_south) + 180.0) % 360.0
    return SunPosition(elevation, azimuth)


def _day_of_year(day_number: int) -> tuple[int, int]:
    """(day of the year from 1, days in that year) of the UTC day ``day_number`` since
    1970-01-01."""
    date = np.datetime64("1970-01-01") + np.timedelta64(int(day_number), "D")
    year = date.astype("datetime64[Y]")
    first = year.astype("datetime64[D]")
    length = int(((year + 1).astype("datetime64[D]") - first).astype(int))
    return int((date - first).astype(int)) + 1, length


@cache
def segment_location() -> tuple[float, float]:
    """(latitude, longitude) [deg] of the segment: the mean of the mile posts 60.6 to
    61.6 (I-24 MOTION infrastructure data)."""
    import pandas as pd

    posts = pd.read_csv(asset("i24_aux/mile_marker_layer.csv"))
    inside = posts[(posts["MM"] >= 60.6 - 1e-9) & (posts["MM"] <= 61.6 + 1e-9)]
    return float(inside["Y_WGS84"].mean()), float(inside["X_WGS84"].mean())


#: Lowest sun the renderer is given [deg]: a sun on the horizon casts shadows longer
#: than the renderer's shadow map can hold (a 1.5 m car's would run 130 m at 0.65 deg).
MIN_LIGHT_ELEVATION = 4.0
DAWN_TOP = (86.0, 112.0, 160.0)  # RGB of the sky above at sunrise
DAWN_HORIZON = (236.0, 196.0, 160.0)  # ...and at the horizon, warm


def sun_light(sun: SunPosition, *, shadows: bool = True, intensity: float = 1.0):
    """The renderer's light for the sun at ``sun``: a warm, weaker light and a warm
    horizon near sunrise, the noon light from 20 degrees up; ``intensity`` scales the
    sun's and the sky's light (1: as modelled).

    Raises:
        ValueError: an intensity that is not positive.
    """
    from twin.physics.render import NOON, Light

    if not (math.isfinite(intensity) and intensity > 0):
        raise ValueError(f"intensity must be > 0, got {intensity!r}")
    day = min(max(sun.elevation_deg / 20.0, 0.0), 1.0)  # 0 at sunrise, 1 from 20 deg
    lit = SunPosition(max(sun.elevation_deg, MIN_LIGHT_ELEVATION), sun.azimuth_deg)

    def blend(a, b):
        return tuple(float(x + (y - x) * day) for x, y in zip(a, b, strict=True))

    return Light(
        direction=tuple(float(v) for v in lit.direction_enu()),
        color=blend((1.0, 0.82, 0.66), (1.0, 1.0, 1.0)),
        ambient=float(intensity * (0.4 + (NOON.ambient - 0.4) * day)),
        diffuse=float(intensity * (0.45 + (NOON.diffuse - 0.45) * day)),
        specular=NOON.specular,
        shadows=shadows,
        sky_top=tuple(min(255.0, v * intensity) for v in blend(DAWN_TOP, NOON.sky_top)),
        sky_horizon=tuple(min(255.0, v * intensity) for v in blend(DAWN_HORIZON, NOON.sky_horizon)),
    )


def episode_light(mode: str, unix_time: float, *, shadows: bool = True, rng=None):
    """The light of a picture taken at ``unix_time`` [s] on the segment, and what it
    was, for the labels: ``(Light, {"sun": mode, "elevation_deg", "azimuth_deg",
    "intensity"})``.

    Args:
        mode: ``recorded`` (the sun at that time over the segment), ``noon`` (the
            paper's high noon, no shadows) or ``random`` (a sun drawn from ``rng``:
            elevation 5 to 70 deg, any azimuth, intensity 0.8 to 1.2).
        rng: a ``numpy.random.Generator`` for ``random`` (seeded by the caller).

    Raises:
        ValueError: an unknown mode, or ``random`` without ``rng``.
    """
    from twin.physics.render import NOON

    if mode not in SUN_MODES:
        raise ValueError(f"sun must be one of {', '.join(SUN_MODES)}, got {mode!r}")
    if mode == "noon":
        return NOON, {"sun": mode, "elevation_deg": None, "azimuth_deg": None, "intensity": 1.0}
    if mode == "recorded":
        sun, intensity = sun_position(unix_time, *segment_location()), 1.0
    else:
        if rng is None:
            raise ValueError("sun = random needs a seeded random generator")
        sun = SunPosition(float(rng.uniform(5.0, 70.0)), float(rng.uniform(0.0, 360.0)))
        intensity = float(rng.uniform(0.8, 1.2))
    info = {
        "sun": mode,
        "elevation_deg": round(sun.elevation_deg, 3),
        "azimuth_deg": round(sun.azimuth_deg, 3),
        "intensity": round(intensity, 4),
    }
    return sun_light(sun, shadows=shadows, intensity=intensity), info
