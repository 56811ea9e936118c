"""The real I-24 infrastructure data the map is built from (``assets/i24_aux``).

These are the I-24 MOTION auxiliary files (Gloudemans et al. 2023; see
``assets/i24_aux/README_auxiliary_data.txt``), shipped with the twin so that a map
is built from the repository alone. Each reader checks its columns and values and
raises :class:`~twin.core.errors.MapError` naming the file and the problem.
"""

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from twin.core.errors import MapError
from twin.core.i24 import FT
from twin.core.paths import asset

AUX_DIR = "i24_aux"
MILE_MARKERS = "mile_marker_layer.csv"
GRADE = "grade_elevation.csv"
POLES = "pole_layer.csv"
LANDMARKS = "ramp_and_landmark_layer.csv"
SOURCE_FILES = (MILE_MARKERS, GRADE, POLES, LANDMARKS)
PROFILE_STEP_MI = 0.01  # [mi] spacing of grade_elevation.csv


@dataclass(frozen=True, eq=False)
class Sources:
    """The auxiliary layers, as arrays.

    Attributes:
        post_mm: (p,) float, mile marker of each mile-marker post, increasing.
        post_lat, post_lon: (p,) float [deg] WGS84 position of each post.
        profile_mm: (k,) float, mile markers of the elevation profile, every 0.01 mi.
        profile_elevation: (k,) float [m] road elevation there (the file gives feet).
        pole_id: (q,) int, camera pole numbers; pole_lat, pole_lon: (q,) [deg].
        landmarks: name -> (direction, mm, lat, lon).
    """

    post_mm: np.ndarray
    post_lat: np.ndarray
    post_lon: np.ndarray
    profile_mm: np.ndarray
    profile_elevation: np.ndarray
    pole_id: np.ndarray
    pole_lat: np.ndarray
    pole_lon: np.ndarray
    landmarks: dict[str, tuple[str, float, float, float]]


def source_paths(folder: Path | None = None) -> list[Path]:
    """The four CSV files read by :func:`load_sources`, in a fixed order."""
    base = Path(folder) if folder is not None else asset(AUX_DIR)
    return [base / name for name in SOURCE_FILES]


def load_sources(folder: Path | None = None) -> Sources:
    """Read and check the auxiliary layers from ``folder`` (default: ``assets/i24_aux``).

    Raises:
        MapError: a file is missing, lacks a column, holds a non-numeric or
            non-finite value, or is inconsistent (posts out of order, profile not on
            its 0.01 mi grid).
    """
    markers, grade, poles, landmarks = (_read(path) for path in source_paths(folder))
    _need(markers, MILE_MARKERS, ("MM", "X_WGS84", "Y_WGS84"))
    _need(grade, GRADE, ("MM", "elevation (ft)"))
    _need(poles, POLES, ("pole-number", "X_WGS84", "Y_WGS84"))
    _need(landmarks, LANDMARKS, ("Direction", "Landmark name", "MM", "X_WGS84", "Y_WGS84"))

    markers = markers.sort_values("MM")
    post_mm = _numbers(markers, MILE_MARKERS, "MM")
    if np.any(np.diff(post_mm) <= 0):
        raise MapError(f"{MILE_MARKERS}: mile markers repeat: {post_mm.tolist()}")

    grade = grade.sort_values("MM")
    profile_mm = _numbers(grade, GRADE, "MM")
    steps = np.round(profile_mm / PROFILE_STEP_MI)
    if np.any(np.abs(steps * PROFILE_STEP_MI - profile_mm) > 1e-6) or np.any(np.diff(steps) != 1):
        raise MapError(f"{GRADE}: mile markers are not a gapless 0.01 mi grid")

    return Sources(
        post_mm=post_mm,
        post_lat=_numbers(markers, MILE_MARKERS, "Y_WGS84"),
        post_lon=_numbers(markers, MILE_MARKERS, "X_WGS84"),
        profile_mm=steps * PROFILE_STEP_MI,
        profile_elevation=_numbers(grade, GRADE, "elevation (ft)") * FT,
        pole_id=_numbers(poles, POLES, "pole-number").astype(np.int64),
        pole_lat=_numbers(poles, POLES, "Y_WGS84"),
        pole_lon=_numbers(poles, POLES, "X_WGS84"),
        landmarks={
            str(name): (str(direction), float(mm), float(lat), float(lon))
            for name, direction, mm, lat, lon in zip(
                landmarks["Landmark name"],
                landmarks["Direction"],
                _numbers(landmarks, LANDMARKS, "MM"),
                _numbers(landmarks, LANDMARKS, "Y_WGS84"),
                _numbers(landmarks, LANDMARKS, "X_WGS84"),
                strict=True,
            )
        },
    )


def _read(path: Path) -> pd.DataFrame:
    if not path.is_file():
        raise MapError(f"map source {path} not found")
    try:
        return pd.read_csv(path)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as error:
        raise MapError(f"{path.name}: not a readable CSV ({error})") from error


def _need(frame: pd.DataFrame, name: str, columns: tuple[str, ...]) -> None:
    missing = [c for c in columns if c not in frame.columns]
    if missing:
        raise MapError(f"{name}: missing column(s) {missing}; has {list(frame.columns)}")
    if frame.empty:
        raise MapError(f"{name}: no rows")


def _numbers(frame: pd.DataFrame, name: str, column: str) -> np.ndarray:
    values = pd.to_numeric(frame[column], errors="coerce").to_numpy(dtype=np.float64)
    bad = ~np.isfinite(values)
    if bad.any():
        row = int(np.flatnonzero(bad)[0])
        raise MapError(
            f"{name}: column {column!r} has a non-numeric or non-finite value "
            f"{frame[column].iloc[row]!r} (data row {row + 1})"
        )
    return values
