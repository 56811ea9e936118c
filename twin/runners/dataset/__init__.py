"""``twin dataset``: labelled camera datasets from many cosimulation episodes.

Episodes are drawn from the recorded traffic (:mod:`twin.runners.episodes`); each is a
cosimulation whose ego cameras take ``frames_per_episode`` frames at the camera
rate after ``warmup_s``. Every frame of every camera is one sample, labelled by
:mod:`sensors.labels` and written in KITTI's object layout and as COCO instances;
:mod:`twin.runners.dataset.run` runs the episodes (a process pool or Ray) and assembles them.

The dataset folder::

    DIR/
      dataset.json            what the dataset is made of: configuration, data, version
                              (a rerun with other settings is refused)
      config.toml             the resolved configuration (loads back with --config)
      manifest.json           episodes, samples, statistics; written last
      coco.json               COCO instances of the kept vehicles (images are
                              training/image_2/NNNNNN.png)
      training/               KITTI object layout, samples numbered 000000, 000001, ...
        image_2/NNNNNN.png    8-bit RGB
        label_2/NNNNNN.txt    KITTI labels (sensors.kitti)
        calib/NNNNNN.txt      KITTI calibration
        depth_2/NNNNNN.png    KITTI depth map: uint16, metres x 256, 0: none
        semantic_2/NNNNNN.png 8-bit semantic class ids (assets/semantic_classes.csv)
        instance_2/NNNNNN.png 16-bit vehicle instance id + 1, 0: no vehicle
        labels/NNNNNN.json    every visible vehicle with all its labels (sensors.labels)
      episodes/EEEEEE/        one folder per episode, written under a temporary name
                              and renamed when complete: episode.json and the same
                              sub-folders, samples numbered within the episode

The ``training/`` files are hard links to the episodes' files (copies where the
file system has no links), numbered in episode order; ``training/``, ``coco.json``
and ``manifest.json`` are rebuilt from the complete episodes at the end of a run.
A rerun of the same command skips the complete episodes, so an interrupted run
resumes where it stopped and ends with the same dataset as an uninterrupted one.
"""

from twin.runners.dataset.config import (
    EPISODES,
    DatasetConfig,
    DatasetError,
    LabelFilters,
    load_dataset_config,
)
from twin.runners.dataset.episode import render_episode
from twin.runners.dataset.folder import draw_episodes, is_episode
from twin.runners.dataset.run import DatasetResult, generate, summary

__all__ = [
    "EPISODES", "DatasetConfig", "DatasetError", "DatasetResult", "LabelFilters",
    "draw_episodes", "generate", "is_episode", "load_dataset_config", "render_episode", "summary",
]  # fmt: skip
