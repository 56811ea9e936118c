"""What a dataset is made of (its TOML): the episodes' sampling, the label filters, the
cosimulation and cameras of every episode; the names of its files."""

import math
from dataclasses import dataclass, field, replace

import numpy as np

from sensors.camera import CameraSettings
from sensors.labels import VehicleLabels
from twin.core.errors import TwinError
from twin.cosim.config import ConfigError, CosimConfig, to_toml
from twin.runners.episodes import (
    EpisodeSampling,
    EpisodeSpec,
    SamplingError,
    episode_config,
)

FORMAT = "i24-twin-dataset"
FORMAT_VERSION = 1
EPISODE_FORMAT = "i24-twin-dataset-episode"
IDENTITY = "dataset.json"
MANIFEST = "manifest.json"
EPISODE = "episode.json"
COCO = "coco.json"
EPISODES = "episodes"
SPLIT = "training"
# sub-folder -> file suffix of each sample's files
KINDS = {
    "image_2": ".png",
    "label_2": ".txt",
    "calib": ".txt",
    "depth_2": ".png",
    "semantic_2": ".png",
    "instance_2": ".png",
    "labels": ".json",
}


class DatasetError(TwinError):
    """A dataset cannot be made as asked, or its folder holds something else."""


@dataclass(frozen=True)
class LabelFilters:
    """Which labelled vehicles a dataset keeps (``[filters]``); the others become
    KITTI ``DontCare`` regions and are left out of COCO.

    Attributes:
        min_height_px: [px] least height of the visible 2D box.
        max_occlusion: highest KITTI occlusion level kept (0, 1 or 2).
        max_distance_m: [m] farthest distance from the camera to the box centre.
    """

    min_height_px: float = 10.0
    max_occlusion: int = 2
    max_distance_m: float = 150.0

    def __post_init__(self):
        if not (math.isfinite(self.min_height_px) and self.min_height_px >= 0):
            raise DatasetError(f"min_height_px must be >= 0, got {self.min_height_px!r}")
        if self.max_occlusion not in (0, 1, 2) or isinstance(self.max_occlusion, bool):
            raise DatasetError(f"max_occlusion must be 0, 1 or 2, got {self.max_occlusion!r}")
        if not self.max_distance_m > 0:
            raise DatasetError(f"max_distance_m must be > 0, got {self.max_distance_m!r}")

    def keep(self, labels: VehicleLabels) -> np.ndarray:
        """(n,) bool: the vehicles that pass every filter."""
        return (
            (labels.height_px >= self.min_height_px)
            & (labels.occlusion_level <= self.max_occlusion)
            & (labels.distance <= self.max_distance_m)
        )


def _dataset_cosim() -> CosimConfig:
    return CosimConfig(
        scenario="dataset", camera=CameraSettings(enabled=True, rate_hz=5.0, video=False)
    )


@dataclass(frozen=True)
class DatasetConfig:
    """What a dataset is made of (a dataset's TOML).

    Attributes:
        seed: the dataset's seed: episode ``i`` is drawn and simulated from
            ``(seed, i)`` alone.
        frames_per_episode: frames each camera takes per episode (at the camera rate).
        warmup_s: [s] simulated before the first frame.
        sampling: where episodes start (``[sampling]``).
        filters: which vehicles are kept (``[filters]``).
        cosim: the cosimulation of every episode (``[cosim]``, ``[cosim.camera]``, ...);
            its road, lane, x, time, seed and t_max are set per episode.
    """

    seed: int = 0
    frames_per_episode: int = 20
    warmup_s: float = 0.5
    sampling: EpisodeSampling = field(default_factory=EpisodeSampling)
    filters: LabelFilters = field(default_factory=LabelFilters)
    cosim: CosimConfig = field(default_factory=_dataset_cosim)

    def __post_init__(self):
        if not isinstance(self.seed, int) or isinstance(self.seed, bool) or self.seed < 0:
            raise DatasetError(f"seed must be a non-negative integer, got {self.seed!r}")
        k = self.frames_per_episode
        if not isinstance(k, int) or isinstance(k, bool) or k < 1:
            raise DatasetError(f"frames_per_episode must be an integer >= 1, got {k!r}")
        if not (math.isfinite(self.warmup_s) and self.warmup_s >= 0):
            raise DatasetError(f"warmup_s must be >= 0, got {self.warmup_s!r}")
        object.__setattr__(
            self, "cosim", replace(self.cosim, camera=replace(self.cosim.camera, enabled=True))
        )

    @property
    def warmup_steps(self) -> int:
        return round(self.warmup_s / self.cosim.dt)

    @property
    def frame_every(self) -> int:
        """Steps between two frames."""
        return self.cosim.camera_every

    @property
    def last_step(self) -> int:
        """The step of the last frame."""
        return self.warmup_steps + (self.frames_per_episode - 1) * self.frame_every

    @property
    def duration(self) -> float:
        """[s] simulated per episode."""
        return self.last_step * self.cosim.dt

    def episode_config(self, spec: EpisodeSpec) -> CosimConfig:
        """The cosimulation of episode ``spec``."""
        return episode_config(
            self.cosim,
            spec,
            scenario=f"dataset-{spec.index:06d}",
            t_max=max(self.duration, self.cosim.dt),
            bev_time=None,
        )

    def to_toml(self) -> str:
        return to_toml(self, header="dataset")


def resolved_renderer(config: DatasetConfig) -> DatasetConfig:
    """``config`` with its renderer named: ``auto`` is decided once, here, so every
    episode of a dataset (on any worker or node) is drawn by the same renderer."""
    from twin.physics.render import resolve_renderer

    camera = config.cosim.camera
    if camera.renderer != "auto":
        return config
    named = replace(camera, renderer=resolve_renderer("auto").value)
    return replace(config, cosim=replace(config.cosim, camera=named))


def load_dataset_config(
    text: str, *, source: str = "dataset configuration", base: DatasetConfig | None = None
) -> DatasetConfig:
    """Parse a dataset's TOML over ``base`` (default: the defaults).

    Raises:
        ConfigError: malformed TOML, an unknown key or an impossible value.
    """
    import tomllib

    from twin.cosim.config import override

    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise ConfigError(f"{source} is not valid TOML: {error}") from None
    try:
        return override(base or DatasetConfig(), data, source=source)
    except (DatasetError, SamplingError) as error:
        raise ConfigError(f"{source}: {error}") from None
