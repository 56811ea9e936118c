"""The recording's lane changes, as every run and evaluation counts them: found over a
road's whole recording (:func:`twin.calibration.following.lane_changes`, so that a
change near an episode's start or end is found as it is anywhere else), once per
store, and kept beside the store's cached recording
(``STORE/.recording/ROAD-KEY.lane-changes.npz``, or in the twin's cache where the
store is read-only: :func:`twin.data.recording.cached_folder`).

Finding them reads and resamples the whole road (about 2 s for the embedded morning);
the file makes that once per machine instead of once per process, so a ``twin run``
starts as fast as before and every worker of ``twin eval`` reads them at once. A file
that cannot be written (a full or read-only disk) only costs the time again; one that
cannot be read is found again and replaced.
"""

from dataclasses import fields, replace
from pathlib import Path

import numpy as np

from twin.calibration.following import LaneChanges, lane_changes, load_grid
from twin.core.atomic import atomic_file
from twin.core.i24 import Road
from twin.data.recording import CACHE_FOLDER, cached_folder, store_key
from twin.data.store import TrajectoryStore

VERSION = 1  # of the file and of how the changes are found: a new one is found again
SUFFIX = f".lane-changes-v{VERSION}.npz"
PER_CHANGE = ("tid", "time", "x", "lane_from", "lane_to", "speed_from", "speed_to")

_LOADED: dict[tuple[str, str], LaneChanges] = {}


def recorded_lane_changes(store: TrajectoryStore, road: Road | str, t0: float, t1: float):
    """The recording's lane changes on ``road`` between unix ``t0`` and ``t1`` [s]
    (their exposure is the whole recording's)."""
    changes = whole_recording(store, road)
    keep = (changes.time >= t0) & (changes.time <= t1)
    return replace(changes, **{name: getattr(changes, name)[keep] for name in PER_CHANGE})


def whole_recording(store: TrajectoryStore, road: Road | str) -> LaneChanges:
    """Every lane change of ``road``'s recording: from this process's memory, else
    the store's file (module doc), else found and written there."""
    road = Road.parse(road)
    key = (store_key(store), road.value)
    if key not in _LOADED:
        path = changes_path(store, road)
        changes = _read(path)
        if changes is None:
            first, last = store.time_range(road)
            changes = lane_changes(load_grid(store, road, first, last))
            _write(changes, path)
        _LOADED[key] = changes
    return _LOADED[key]


def changes_path(store: TrajectoryStore, road: Road | str) -> Path:
    """The file of ``road``'s lane changes, beside its cached recording."""
    folder = cached_folder(store, road)
    return folder.with_name(folder.name + SUFFIX)


def _read(path: Path) -> LaneChanges | None:
    try:
        with np.load(path, allow_pickle=False) as data:
            return LaneChanges(**{f.name: data[f.name] for f in fields(LaneChanges)})
    except (OSError, ValueError, KeyError, EOFError):
        return None  # absent or damaged: found again


def _write(changes: LaneChanges, path: Path) -> None:
    try:
        with atomic_file(path) as tmp, open(tmp, "wb") as file:
            np.savez(file, **{f.name: getattr(changes, f.name) for f in fields(changes)})
    except OSError:
        return  # nowhere to keep them: found again by the next process
    if path.parent.name != CACHE_FOLDER:
        return  # in the twin's cache, beside other stores' files
    road = path.name.split("-")[0]
    for stale in path.parent.glob(f"{road}-*.lane-changes-*.npz"):
        if stale != path:  # the road of the store written earlier, or an older version
            stale.unlink(missing_ok=True)


def clear_loaded() -> None:
    """Forget the changes this process holds (tests)."""
    _LOADED.clear()
