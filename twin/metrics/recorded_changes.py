"""The recording's lane changes, as every run and evaluation counts them: found over a
road's whole recording (:func:`twin.calibration.following.lane_changes`, so that a
change near an episode's start or end is found as it is anywhere else), once per
store, and kept beside the store's cached recording
(``STORE/.recording/ROAD-KEY.lane-changes-CODE.npz``, or in the twin's cache where
the store is read-only: :func:`twin.data.recording.cached_folder`). ``KEY`` is the
store's (a store written again has new files) and ``CODE`` a digest of the code that
finds the changes (a changed definition finds them again).

Finding them reads and resamples the whole road (about 2 s for the embedded morning);
the file makes that once per machine instead of once per process, so a ``twin run``
starts as fast as before and every worker of ``twin eval`` reads them at once. A file
that cannot be written (a full or read-only disk) only costs the time again; one that
cannot be read is found again and replaced. Two processes that find them at once (an
evaluation's first workers on a new store) both find the same arrays, and the last
rename wins.
"""

import hashlib
import inspect
import zipfile
from dataclasses import fields, replace
from functools import cache
from pathlib import Path

import numpy as np

from twin.calibration import following
from twin.calibration.following import SPEED_BINS, LaneChanges, lane_changes, load_grid
from twin.core import i24
from twin.core.atomic import atomic_file
from twin.core.i24 import Road
from twin.data.recording import CACHE_FOLDER, cached_folder, store_key
from twin.data.store import TrajectoryStore

VERSION = 1  # of the file's layout
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
            _write(changes, path, store.path / CACHE_FOLDER)
        _LOADED[key] = changes
    return _LOADED[key]


def changes_path(store: TrajectoryStore, road: Road | str) -> Path:
    """The file of ``road``'s lane changes, beside its cached recording."""
    folder = cached_folder(store, road)
    return folder.with_name(f"{folder.name}.lane-changes-{code_key()}.npz")


@cache
def code_key() -> str:
    """A digest of the file's layout and the code that finds the changes."""
    digest = hashlib.sha256(f"{VERSION}".encode())
    for module in (following, i24):
        digest.update(inspect.getsource(module).encode())
    return digest.hexdigest()[:12]


def _read(path: Path) -> LaneChanges | None:
    try:
        with np.load(path, allow_pickle=False) as data:
            changes = LaneChanges(**{f.name: data[f.name] for f in fields(LaneChanges)})
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
        return None  # absent or damaged: found again
    sizes = {getattr(changes, name).shape for name in PER_CHANGE}
    if len(sizes) != 1 or len(next(iter(sizes))) != 1:
        return None  # arrays of different lengths: damaged
    if changes.exposure_km.shape != (4, len(SPEED_BINS) - 1):
        return None
    return changes


def _write(changes: LaneChanges, path: Path, store_folder: Path) -> None:
    try:
        with atomic_file(path) as tmp, open(tmp, "wb") as file:
            np.savez(file, **{f.name: getattr(changes, f.name) for f in fields(changes)})
    except OSError:
        return  # nowhere to keep them: found again by the next process
    if path.parent != store_folder:
        return  # in the twin's cache, beside other stores' files
    road, _, rest = path.name.partition("-")
    mine = rest.partition(".")[0]  # the store's key
    for stale in path.parent.glob(f"{road}-*.lane-changes-*.npz"):
        if stale.name.partition("-")[2].partition(".")[0] != mine:
            stale.unlink(missing_ok=True)  # the road of the store as written before


def clear_loaded() -> None:
    """Forget the changes this process holds (tests)."""
    _LOADED.clear()
