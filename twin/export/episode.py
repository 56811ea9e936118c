"""A run folder as the exporters read it: its settings, its trajectory log and the
facts the log's Parquet metadata carries (t0, the road, which recorded vehicle the ego
is)."""

import json
from dataclasses import dataclass
from pathlib import Path

import pandas as pd
import pyarrow.parquet as pq

from twin.core.errors import TwinError
from twin.core.i24 import Road

#: the log's columns the exporters read (twin.cosim.log writes them all)
COLUMNS = ("time", "record_id", "role", "road", "lane", "x", "y", "speed", "heading", "grade",
           "vehicle_class", "length", "width", "height")  # fmt: skip


class ExportError(TwinError):
    """A run cannot be exported: not a run folder, a tool is missing, or bad options."""


@dataclass(frozen=True)
class Episode:
    """One run folder, read.

    Attributes:
        folder: the run folder.
        config: its resolved ``CosimConfig`` (``config.toml``).
        rows: ``trajectories.parquet`` (columns in :mod:`twin.cosim.log`).
        t0: [s] unix time of the run's time 0 (the ego's recorded time).
        road: the carriageway the run drove on.
        ego_record_id: the I-24 MOTION ``_id`` of the recorded vehicle the ego is.
        duration: [s] the last logged time.
    """

    folder: Path
    config: object
    rows: pd.DataFrame
    t0: float
    road: Road
    ego_record_id: str
    duration: float


def read_episode(run: Path) -> Episode:
    """Read run folder ``run``.

    Raises:
        ExportError: ``run`` is not a run folder (``twin run --out`` makes one), or its
            trajectory log lacks the twin's metadata or a column, or holds no row.
        StoreError: the log is not a readable Parquet file.
    """
    from twin.cosim.config import load_config
    from twin.data.store import damaged_file
    from twin.runners.run import is_run

    run = Path(run)
    if not is_run(run):
        raise ExportError(f"{run} is not a run folder (twin run --out makes one)")
    config = load_config(run / "config.toml")
    log = run / "trajectories.parquet"
    again = f"run it again: twin run --config {run / 'config.toml'} --out {run}"
    with damaged_file(log, f"the run is damaged; {again}"):
        metadata = (pq.read_schema(log).metadata or {}).get(b"i24_twin")
        rows = pd.read_parquet(log)
    try:
        facts = json.loads(metadata)
        t0, road, ego = float(facts["t0"]), Road.parse(facts["road"]), str(facts["ego_record_id"])
    except (TypeError, ValueError, KeyError):
        raise ExportError(
            f"{log} lacks the twin's metadata (t0, road, ego_record_id): not the trajectory "
            f"log of a twin run, or a damaged one; {again}"
        ) from None
    missing = [name for name in COLUMNS if name not in rows.columns]
    if missing:
        raise ExportError(f"{log} lacks the columns {', '.join(missing)}; {again}")
    if rows.empty:
        raise ExportError(f"{log} holds no rows: nothing to export")
    return Episode(run, config, rows, t0, road, ego, float(rows["time"].max()))
