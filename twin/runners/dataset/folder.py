"""A dataset's folder: its identity, its episodes' folders and where they are drawn."""

from pathlib import Path

from twin import __version__
from twin.core.atomic import marked_as
from twin.core.errors import TwinError
from twin.data.store import TrajectoryStore
from twin.runners.dataset.config import (
    EPISODE,
    EPISODE_FORMAT,
    EPISODES,
    FORMAT,
    FORMAT_VERSION,
    IDENTITY,
    DatasetConfig,
    DatasetError,
)
from twin.runners.episodes import (
    SamplingError,
    check_roads,
    draw_episode,
)
from twin.runners.episodes import measure_cells as _measure_cells
from twin.runners.folders import claim


def draw_episodes(config: DatasetConfig, store: TrajectoryStore, bundle, n: int):
    """The first ``n`` episodes of the dataset ``config`` on ``store``.

    Raises:
        SamplingError: no cell of the data can hold an episode.
    """
    from twin.core.i24 import Road
    from twin.cosim.windows import road_limits
    from twin.data.empirical import EmpiricalTraffic

    check_roads(store, config.sampling)
    traffic = EmpiricalTraffic(store)
    roads = [Road.parse(r) for r in config.sampling.roads]
    try:
        limits = {r: road_limits(bundle, traffic, r) for r in roads}
    except TwinError as error:
        raise SamplingError(str(error)) from None
    cells = _measure_cells(store, config.sampling, limits, config.duration)
    return [draw_episode(cells, config.sampling, config.seed, i) for i in range(n)]


def episode_folder(out: Path, index: int) -> Path:
    return Path(out) / EPISODES / f"{index:06d}"


def is_episode(path: Path) -> bool:
    return marked_as(path, EPISODE, EPISODE_FORMAT)


def _identity(config: DatasetConfig, store: TrajectoryStore, bundle) -> dict:
    data = {k: v for k, v in store.metadata.items() if k in ("format", "version", "roads")}
    data["sources"] = [
        {k: s.get(k) for k in ("name", "bytes")} for s in store.metadata.get("sources", [])
    ]
    return {
        "format": FORMAT,
        "version": FORMAT_VERSION,
        "software": __version__,
        "config": config.to_toml(),
        "data": data,
        "map": bundle.key,
    }


def claim_folder(out: Path, config: DatasetConfig, store: TrajectoryStore, bundle) -> None:
    """Make ``out`` this dataset's folder, or check that it already is
    (:func:`twin.runners.folders.claim`; its ``config.toml`` loads back with --config)."""
    identity = _identity(config, store, bundle)
    claim(
        out, IDENTITY, identity, kind="i24-twin dataset", noun="dataset", error=DatasetError,
        files={"config.toml": identity["config"]}, toml=("config",),
        defaults={"config": DatasetConfig().to_toml()},
        hint=f" ({Path(out) / 'config.toml'} loads back with --config)",
    )  # fmt: skip
