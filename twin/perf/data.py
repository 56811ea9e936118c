"""Benchmarks of the data layer and of the calibration fitted on it: snapshot
queries, the synthesiser, ingest, and ``twin calibrate``."""

import json
import math
import subprocess
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

from twin.core.i24 import SCENARIO_TIME
from twin.data import synth
from twin.data.empirical import EmpiricalTraffic
from twin.perf.common import median, seconds_per_call, store_or_default, timed

MB_PER_MINUTE = 10.5  # [MB] a little under what preset B writes a minute (about 10.9)


def query(store, *, repeats: int = 5, calls: int = 2000) -> dict:
    """Snapshot latency on a 400 m window in the densest traffic (scenario B's wave)."""
    traffic = EmpiricalTraffic(store)
    x_min, x_max = 500.0, 900.0
    times = SCENARIO_TIME + np.arange(calls) * 0.01
    arguments = [("westbound", float(t), x_min, x_max) for t in times]
    traffic.snapshot("westbound", SCENARIO_TIME, x_min, x_max)  # build the frame table once
    medians = [median(seconds_per_call(traffic.snapshot, arguments)) for _ in range(repeats)]
    vehicles = len(traffic.snapshot("westbound", SCENARIO_TIME, x_min, x_max))
    return {
        "snapshot_median_us": round(1e6 * median(medians), 2),
        "target_us": 200,
        "vehicles_in_window": vehicles,
        "window_m": x_max - x_min,
        "repeats": repeats,
        "calls_per_repeat": calls,
    }


def synth_bench(*, minutes: float = 10.0, repeats: int = 3) -> dict:
    """Time to simulate and write ``minutes`` of preset B (one direction) as I-24 JSON."""
    seconds, sizes = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(repeats):
            config = replace(synth.PRESET_B, minutes=minutes, seed=seed)
            path, elapsed = timed(_write_day, config, Path(tmp) / "day.json")
            seconds.append(elapsed)
            sizes.append(path.stat().st_size)
    return {
        "minutes": minutes,
        "median_s": round(median(seconds), 2),
        "target_s": 60,
        "file_mb": round(median(sizes) / 1e6, 1),
        "repeats": repeats,
    }


def ingest_bench(*, size_mb: float = 300.0, repeats: int = 3) -> dict:
    """Ingest throughput and peak memory on a synthetic day of at least ``size_mb``.

    Peak memory is the resident set of a fresh process running only the ingest; it is
    measured on the full file and on a quarter of it, to show it does not grow with
    file size.
    """
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        files = {}
        for label, mb in (("quarter", size_mb / 4), ("full", size_mb)):
            config = replace(synth.PRESET_B, minutes=math.ceil(mb / MB_PER_MINUTE))
            files[label] = _write_day(config, tmp / f"{label}.json")
        figures = {}
        for label, path in files.items():
            seconds, peaks = [], []
            for _ in range(repeats if label == "full" else 1):
                elapsed, peak = _ingest_in_child(path, tmp / f"store-{label}")
                seconds.append(elapsed)
                peaks.append(peak)
            mb = path.stat().st_size / 1e6
            figures[label] = {
                "file_mb": round(mb, 1),
                "median_s": round(median(seconds), 2),
                "throughput_mb_s": round(mb / median(seconds), 1),
                "peak_rss_mb": round(max(peaks), 1),
            }
    return {**figures["full"], "quarter_file": figures["quarter"], "repeats": repeats}


def calibrate_bench(store=None, *, road: str = "westbound", repeats: int = 3) -> dict:
    """Wall time of ``twin calibrate`` on ``road`` of ``store`` (default: the embedded
    data; nothing is written), median of the repeats, with what it fitted."""
    from twin.calibration.calibrate import calibrate

    store = store_or_default(store)
    walls = []
    for _ in range(repeats):
        (doc, _), wall = timed(calibrate, store, [road])
        walls.append(wall)
    section = doc["roads"][road]
    return {
        "road": road,
        "trajectories": section["trajectories"],
        "minutes": round((section["window"]["until"] - section["window"]["from"]) / 60.0, 2),
        "followers_fitted": section["car_following"]["fitted"],
        "repeats": repeats,
        "wall_s": round(median(walls), 2),
        "wall_s_runs": [round(w, 2) for w in walls],
    }


def _write_day(config: synth.SynthConfig, path: Path) -> Path:
    """Synthesise the day of ``config`` and write it to ``path`` as I-24 JSON."""
    return synth.write_i24_json(synth.synthesize(config), path)


def _ingest_in_child(path: Path, out: Path) -> tuple[float, float]:
    """Ingest in a fresh process; return its seconds and peak resident memory [MB].

    The peak is the child's VmHWM: ru_maxrss would include the parent's peak, which
    a forked child inherits on Linux.
    """
    code = (
        "import sys, time, json\n"
        "from twin.data.ingest import ingest\n"
        "start = time.perf_counter()\n"
        "ingest([sys.argv[1]], sys.argv[2], progress=False)\n"
        "elapsed = time.perf_counter() - start\n"
        "status = open('/proc/self/status').read().split('VmHWM:')[1].split()[0]\n"
        "print(json.dumps([elapsed, int(status) / 1024]))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code, str(path), str(out)],
        capture_output=True,
        text=True,
        check=True,
    )
    elapsed, peak = json.loads(done.stdout.strip().splitlines()[-1])
    return elapsed, peak
