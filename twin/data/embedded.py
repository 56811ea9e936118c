"""The embedded data: stores built from the synthetic presets, cached on first use.

The real I-24 MOTION days cannot be downloaded on the twin's machines, so ``twin run``
and the ``twin data`` commands with no store use the default one: preset A
(eastbound) and preset B (westbound) of :mod:`twin.data.synth`, written as I-24 JSON
and ingested like real data. ``embedded:morning`` (``--data embedded:morning``) is
preset C, a realistic westbound morning; it is built only when first asked for, so
that the first ``twin run`` stays short. Each is built once and cached under
:func:`twin.core.paths.cache_dir`, keyed by a hash of everything it is made from.
"""

import hashlib
import inspect
from dataclasses import replace
from pathlib import Path

from twin.core import ramps
from twin.core.errors import StoreError
from twin.core.locks import build_lock
from twin.core.paths import asset, cache_dir
from twin.data import day_files, synth
from twin.data import ingest as ingest_module
from twin.data.ingest import IngestOptions, ingest
from twin.data.store import TrajectoryStore, is_store, open_store
from twin.data.synth import config, presets, recording, simulation
from twin.traffic import drivers, lanes, mobil
from twin.traffic.models import base, gipps, idm

#: The code the embedded data are made with: a change to any of it rebuilds them.
GENERATOR = (
    synth, config, presets, simulation, recording, ingest_module, day_files,
    base, idm, gipps, drivers, lanes, mobil, ramps,
)  # fmt: skip

DEFAULT_SEED = 0


#: The embedded stores: name -> (folder prefix, presets).
EMBEDDED = {"default": ("default-store", ("A", "B")), "morning": ("morning-store", ("C",))}
EMBEDDED_PREFIX = "embedded:"


def default_key(seed: int = DEFAULT_SEED) -> str:
    """Hash of the generator's code (with the driver models it uses), presets, class
    table, ingest code and seed."""
    digest = hashlib.sha256()
    for module in GENERATOR:
        digest.update(inspect.getsource(module).encode())
    digest.update(asset("vehicle_classes.csv").read_bytes())
    digest.update(str(seed).encode())
    return digest.hexdigest()[:16]


def embedded_name(data) -> str | None:
    """The embedded store ``data`` names (``embedded:NAME``, where no file or folder of
    that name exists), else None."""
    text = str(data)
    if text.startswith(EMBEDDED_PREFIX) and not Path(text).exists():
        return text[len(EMBEDDED_PREFIX) :]
    return None


def default_store(*, seed: int = DEFAULT_SEED, progress: bool = True) -> TrajectoryStore:
    """The default store, built (and cached) on first use."""
    return embedded_store("default", seed=seed, progress=progress)


def embedded_folder(name: str, seed: int = DEFAULT_SEED) -> Path:
    """Where the embedded store ``name`` is cached (built or not)."""
    prefix, _ = EMBEDDED[name]
    return cache_dir() / f"{prefix}-{default_key(seed)}"


def embedded_store(
    name: str, *, seed: int = DEFAULT_SEED, progress: bool = True
) -> TrajectoryStore:
    """The embedded store ``name`` (see ``EMBEDDED``), built (and cached) on first use.

    Raises:
        StoreError: no embedded store of that name (the message lists them).
    """
    if name not in EMBEDDED:
        raise StoreError(
            f"no embedded data {name!r}: choose one of "
            + ", ".join(EMBEDDED_PREFIX + n for n in EMBEDDED)
        )
    folder = embedded_folder(name, seed)
    if not is_store(folder):
        with build_lock(folder):  # another process may be building it
            if not is_store(folder):
                build_default_store(folder, seed=seed, progress=progress, presets=EMBEDDED[name][1])
    return open_store(folder)


def build_default_store(
    out: Path,
    *,
    seed: int = DEFAULT_SEED,
    progress: bool = True,
    presets: tuple[str, ...] = ("A", "B"),
) -> Path:
    """Synthesize ``presets``, write them as I-24 JSON days, and ingest them into ``out``."""
    out = Path(out)
    work = out.parent / f".{out.name}.json"
    work.mkdir(parents=True, exist_ok=True)
    days = []
    for name in sorted(presets):
        preset = synth.ALL_PRESETS[name]
        if progress:
            print(f"building the embedded data: synthetic preset {name} ({preset.road.value})")
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
