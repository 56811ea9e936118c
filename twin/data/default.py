"""The embedded default data: a store built from the synthetic presets, cached on first use.

The real I-24 MOTION days cannot be downloaded on the twin's machines, so ``twin run``
and the ``twin data`` commands with no store use this one: preset A (eastbound) and
preset B (westbound) of :mod:`twin.data.synth`, written as I-24 JSON and ingested
like real data. It is built once (about a minute) and cached under
:func:`twin.paths.cache_dir`, keyed by a hash of everything it is made from.
"""

import hashlib
import inspect
from dataclasses import replace
from pathlib import Path

from twin.data import ingest as ingest_module
from twin.data import synth
from twin.data.ingest import IngestOptions, ingest
from twin.data.store import TrajectoryStore, is_store
from twin.paths import asset, cache_dir
from twin.traffic import drivers, idm, lanes

DEFAULT_SEED = 0


def default_key(seed: int = DEFAULT_SEED) -> str:
    """Hash of the generator's code (with the driver models it uses), presets, class
    table, ingest code and seed."""
    digest = hashlib.sha256()
    for module in (synth, ingest_module, idm, drivers, lanes):
        digest.update(inspect.getsource(module).encode())
    digest.update(asset("vehicle_classes.csv").read_bytes())
    digest.update(str(seed).encode())
    return digest.hexdigest()[:16]


def default_store(*, seed: int = DEFAULT_SEED, progress: bool = True) -> TrajectoryStore:
    """The default store, built (and cached) on first use."""
    folder = cache_dir() / f"default-store-{default_key(seed)}"
    if not is_store(folder):
        build_default_store(folder, seed=seed, progress=progress)
    return TrajectoryStore(folder)


def build_default_store(out: Path, *, seed: int = DEFAULT_SEED, progress: bool = True) -> Path:
    """Synthesize presets A and B, write them as I-24 JSON days, and ingest both into ``out``."""
    out = Path(out)
    work = out.parent / f".{out.name}.json"
    work.mkdir(parents=True, exist_ok=True)
    days = []
    for name, preset in sorted(synth.PRESETS.items()):
        if progress:
            print(f"building the default data: synthetic preset {name} ({preset.road.value})")
        config = replace(preset, seed=seed)
        result = synth.synthesize(config, progress=progress)
        days.append(
            synth.write_i24_json(result, work / f"synthetic_{name}.json", progress=progress)
        )
    ingest(days, out, IngestOptions(), progress=progress)
    for day in days:
        day.unlink()
    work.rmdir()
    return out
