"""WGS84 geodetic coordinates to a local east-north-up frame and back (vectorised)."""

import numpy as np

WGS84_A = 6378137.0  # [m] semi-major axis
WGS84_F = 1.0 / 298.257223563  # flattening
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)  # first eccentricity squared


def to_ecef(lat_deg: np.ndarray, lon_deg: np.ndarray, height: np.ndarray) -> np.ndarray:
    """(n, 3) [m] Earth-centred Earth-fixed position of geodetic points (ellipsoidal height)."""
    lat = np.radians(np.asarray(lat_deg, dtype=np.float64))
    lon = np.radians(np.asarray(lon_deg, dtype=np.float64))
    h = np.asarray(height, dtype=np.float64)
    n = WGS84_A / np.sqrt(1.0 - WGS84_E2 * np.sin(lat) ** 2)
    return np.stack(
        [
            (n + h) * np.cos(lat) * np.cos(lon),
            (n + h) * np.cos(lat) * np.sin(lon),
            (n * (1.0 - WGS84_E2) + h) * np.sin(lat),
        ],
        axis=-1,
    )


def from_ecef(ecef: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Geodetic (lat [deg], lon [deg], height [m]) of (n, 3) ECEF points.

    Fixed-point iteration on the latitude; five rounds reach well under a millimetre
    for points near the Earth's surface.
    """
    x, y, z = np.moveaxis(np.asarray(ecef, dtype=np.float64), -1, 0)
    lon = np.arctan2(y, x)
    p = np.hypot(x, y)
    lat = np.arctan2(z, p * (1.0 - WGS84_E2))
    for _ in range(5):
        n = WGS84_A / np.sqrt(1.0 - WGS84_E2 * np.sin(lat) ** 2)
        h = p / np.cos(lat) - n
        lat = np.arctan2(z, p * (1.0 - WGS84_E2 * n / (n + h)))
    n = WGS84_A / np.sqrt(1.0 - WGS84_E2 * np.sin(lat) ** 2)
    h = p / np.cos(lat) - n
    return np.degrees(lat), np.degrees(lon), h


def _rotation(lat0_deg: float, lon0_deg: float) -> np.ndarray:
    """(3, 3) rotation whose rows are the east, north and up axes in ECEF."""
    lat, lon = np.radians(lat0_deg), np.radians(lon0_deg)
    return np.array(
        [
            [-np.sin(lon), np.cos(lon), 0.0],
            [-np.sin(lat) * np.cos(lon), -np.sin(lat) * np.sin(lon), np.cos(lat)],
            [np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)],
        ]
    )


def to_enu(
    lat_deg: np.ndarray,
    lon_deg: np.ndarray,
    height: np.ndarray,
    origin: tuple[float, float, float],
) -> np.ndarray:
    """(n, 3) [m] east, north, up of geodetic points relative to ``origin`` (lat, lon, h)."""
    lat0, lon0, h0 = origin
    offset = to_ecef(lat_deg, lon_deg, height) - to_ecef(lat0, lon0, h0)
    return offset @ _rotation(lat0, lon0).T


def from_enu(
    enu: np.ndarray, origin: tuple[float, float, float]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Inverse of :func:`to_enu`: geodetic (lat, lon, height) of (n, 3) ENU points."""
    lat0, lon0, h0 = origin
    ecef = np.asarray(enu, dtype=np.float64) @ _rotation(lat0, lon0) + to_ecef(lat0, lon0, h0)
    return from_ecef(ecef)
