"""Shared fixtures: hand-built I-24 documents and small synthetic stores."""

import json
import os
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from twin.core import i24, jit
from twin.core.i24 import SCENARIO_TIME
from twin.core.locks import build_lock
from twin.data.ingest import ingest
from twin.data.store import TrajectoryStore
from twin.data.synth import PRESET_A, PRESET_B, synthesize, write_i24_json

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
#: The session's compiled kernels, for a command run in a subprocess with a cache folder
#: of its own (``$I24_TWIN_CACHE``): it loads them instead of compiling every kernel
#: again (a minute of a core). Only tests/test_first_run.py compiles afresh, as a new
#: user's first run does.
KERNEL_CACHE = {"NUMBA_CACHE_DIR": os.path.dirname(jit.numba.config.CACHE_DIR)}


def pytest_configure(config):
    """With workers (pytest-xdist), the kernels of both worlds are compiled before they
    start, where this version of them is not cached yet (a clean clone, a changed kernel):
    by the first run's two processes (twin.runners.precompile), instead of every worker
    compiling the same kernels at once."""
    if hasattr(config, "workerinput") or not getattr(config.option, "numprocesses", None):
        return
    if config.option.collectonly:
        return
    from twin.runners import precompile

    for world in precompile.WORLDS:  # a failure shows in the tests that call the kernel
        compiling = precompile.start(world)
        if compiling is not None:
            compiling.wait()


def make_doc(
    oid="6386d89efb3ff533c12d0001",
    *,
    direction=-1,
    mm=61.5,
    y_ft=18.0,
    speed=30.0,
    t0=SCENARIO_TIME,
    n=50,
    rate=25.0,
    vehicle_class=0,
    length_ft=15.0,
    width_ft=6.0,
    height_ft=5.0,
):
    """A valid I-24 MOTION document: constant speed [m/s] from mile marker ``mm``."""
    t = t0 + np.arange(n) / rate
    x_ft = mm * 5280.0 + direction * (speed / i24.FT) * (t - t0)
    return {
        "_id": {"$oid": oid},
        "timestamp": t.tolist(),
        "x_position": x_ft.tolist(),
        "y_position": np.full(n, y_ft).tolist(),
        "first_timestamp": float(t[0]),
        "last_timestamp": float(t[-1]),
        "starting_x": float(x_ft[0]),
        "ending_x": float(x_ft[-1]),
        "length": length_ft,
        "width": width_ft,
        "height": height_ft,
        "coarse_vehicle_class": vehicle_class,
        "fine_vehicle_class": vehicle_class,
        "direction": direction,
        "merged_ids": [],
        "flags": [],
    }


def make_merging_doc(oid: str, *, on_ramp: int = 50, in_lane: int = 50, speed: float = 20.0):
    """A westbound vehicle recorded ``on_ramp`` samples on the Old Hickory Blvd on-ramp's
    acceleration lane (|y| 66 ft, from MM 61.72) and then ``in_lane`` samples in lane -4
    (54 ft), at a constant ``speed`` [m/s]."""
    doc = make_doc(oid, direction=-1, mm=61.72, y_ft=66.0, speed=speed, n=on_ramp + in_lane)
    doc["y_position"] = [66.0] * on_ramp + [54.0] * in_lane
    return doc


def write_day(path: Path, docs) -> Path:
    path.write_text(json.dumps(docs))
    return path


@pytest.fixture
def doc():
    return make_doc


@pytest.fixture(scope="session")
def wave_config():
    """Preset B from 4 min before to 3 min after 06:45:50: the wave crosses the segment."""
    return replace(PRESET_B, start=SCENARIO_TIME - 240.0, minutes=7.0)


def built_once(tmp_path_factory, name: str, build) -> Path:
    """The folder ``name`` that ``build(folder)`` fills, built once for the whole test
    run: by the first of the run's workers (pytest-xdist) to ask, while any other waits
    for it, and then read by all. Nothing of it may be written by a test."""
    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):  # the workers' folders share a parent
        root = root.parent
    folder = root / name
    with build_lock(folder):
        if not (folder / ".built").is_file():
            shutil.rmtree(folder, ignore_errors=True)
            folder.mkdir(parents=True)
            build(folder)
            (folder / ".built").write_text("")
    return folder


@pytest.fixture(scope="session")
def wave_store(tmp_path_factory, wave_config) -> TrajectoryStore:
    def build(folder):
        day = write_i24_json(synthesize(wave_config), folder / "wave.json")
        ingest([day], folder / "store", progress=False)

    return TrajectoryStore(built_once(tmp_path_factory, "wave", build) / "store")


@pytest.fixture
def private_wave_store(wave_store, tmp_path) -> TrajectoryStore:
    """A private copy of ``wave_store`` without its cached recording (for tests that
    write into the store or its caches)."""
    shutil.copytree(
        wave_store.path, tmp_path / "store", ignore=shutil.ignore_patterns(".recording")
    )
    return TrajectoryStore(tmp_path / "store")


def store_written_again(store: TrajectoryStore) -> TrajectoryStore:
    """``store`` as after it was written again (its samples' time moved on): a new
    store object, whose caches have a new key."""
    parquet = store.path / "samples_westbound.parquet"
    os.utime(parquet, ns=(parquet.stat().st_atime_ns, parquet.stat().st_mtime_ns + 10**9))
    return TrajectoryStore(store.path)


def read_only_store(store: TrajectoryStore, monkeypatch, cache: Path) -> None:
    """Make ``store``'s folder read as not writable (``os.access``) for the rest of the
    test, and the twin's cache folder ``cache``: what a store on a read-only disk sees."""
    monkeypatch.setenv("I24_TWIN_CACHE", str(cache))
    writable = os.access
    monkeypatch.setattr(
        os, "access", lambda p, m: False if str(p) == str(store.path) else writable(p, m)
    )


@pytest.fixture(scope="session")
def light_result():
    """Preset A, two minutes around 06:45:50."""
    return synthesize(replace(PRESET_A, start=SCENARIO_TIME - 60.0, minutes=2.0))


@pytest.fixture(scope="session")
def built_map(tmp_path_factory):
    """The map with the default seed, built once for the session."""
    from mapgen.build import build_map

    return build_map(tmp_path_factory.mktemp("map") / "map", seed=0)


@pytest.fixture(scope="session")
def calibrated_wave_store(tmp_path_factory, wave_store) -> TrajectoryStore:
    """A copy of ``wave_store`` calibrated on its westbound road (``twin calibrate``)."""
    from twin.calibration.calibrate import calibrate, write_calibration

    def build(folder):
        shutil.copytree(wave_store.path, folder / "store")
        store = TrajectoryStore(folder / "store")
        doc, fits = calibrate(store, ["westbound"])
        write_calibration(store, doc, fits)

    return TrajectoryStore(built_once(tmp_path_factory, "calibrated", build) / "store")
