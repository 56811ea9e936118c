"""``twin dataset`` read back by independent readers (pycocotools for COCO, a KITTI
reader written from the devkit's readme), resumed after kill -9, and made by Ray."""

import contextlib
import json
import math
import os
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest
from pycocotools import mask as coco_mask
from pycocotools.coco import COCO
from pycocotools.cocoeval import COCOeval

from sensors.kitti import decode_depth
from tests.sensors import kitti_devkit
from twin.core.i24 import Road
from twin.cosim.config import override
from twin.cosim.windows import road_limits
from twin.data.empirical import EmpiricalTraffic
from twin.runners.dataset import (
    EPISODES,
    DatasetConfig,
    DatasetError,
    LabelFilters,
    draw_episodes,
    generate,
    is_episode,
    render_episode,
)
from twin.runners.episodes import EpisodeSampling, measure_cells

EPISODE_COUNT, FRAMES = 3, 3
SETTINGS = {"frames_per_episode": FRAMES, "sampling": {"roads": ["westbound"]}}
CLI_SETTINGS = ["--frames-per-episode", str(FRAMES), "--set", 'sampling.roads=["westbound"]']


def config() -> DatasetConfig:
    return override(DatasetConfig(), SETTINGS)


def files_of(folder: Path) -> dict[str, bytes]:
    return {
        str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()
    }


@pytest.fixture(scope="module")
def dataset(tmp_path_factory, wave_store, built_map):
    """A small dataset of the wave recording, made in this process."""
    out = tmp_path_factory.mktemp("dataset") / "ds"
    result = generate(
        config(), wave_store, out, EPISODE_COUNT, workers=1, bundle=built_map, progress=False
    )
    return result


def test_the_dataset_has_every_sample_and_its_manifest(dataset):
    out, manifest = dataset.folder, dataset.manifest
    episodes = manifest["episodes"]
    assert [e["index"] for e in episodes] == list(range(EPISODE_COUNT))
    assert len({e["seed"] for e in episodes}) == EPISODE_COUNT  # a seed of its own each
    samples = sum(e["samples"] for e in episodes)
    assert samples == len(manifest["samples"]) == manifest["statistics"]["samples"]
    assert samples == EPISODE_COUNT * FRAMES  # no episode was skipped or cut short here
    for kind in ("image_2", "label_2", "calib", "depth_2", "semantic_2", "instance_2", "labels"):
        assert len(list((out / "training" / kind).iterdir())) == samples
    assert manifest["software"] and "frames_per_episode = 3" in manifest["config"]
    stats = manifest["statistics"]
    assert stats["vehicles_kept"] + stats["vehicles_dont_care"] == stats["vehicles_visible"]
    assert stats["vehicles_kept"] > 0
    # the statistics the perception user reads: distance bands, truncation, per sample
    assert sum(stats["distance_bands"].values()) == stats["vehicles_kept"]
    assert list(stats["distance_bands"]) == ["0-30", "30-60", "60-100", "100-200", "200+"]
    assert sum(stats["truncation_levels"].values()) == stats["vehicles_kept"]
    assert stats["truncation_levels"]["none"] == stats["vehicles_kept"] - stats["truncated"]
    per_sample = stats["kept_per_sample_quantiles"]
    assert per_sample["min"] <= stats["kept_per_sample"] <= per_sample["max"]
    # the motion check followed the labelled vehicles from frame to frame
    motion = stats["motion"]
    assert motion["pairs"] > 0 and 0 <= motion["violations"] <= motion["pairs"]
    # the light of each episode (the sun over the segment at its time, by default) is in
    # the manifest and in every label file
    assert all(e["light"]["sun"] == "recorded" for e in episodes)
    label = json.loads((out / "training" / "labels" / "000000.json").read_text())
    assert label["light"]["sun"] == "recorded" and label["light"]["elevation_deg"] is not None


def test_kitti_files_read_by_a_devkit_reader(dataset):
    split = dataset.folder / "training"
    objects = 0
    for index in range(len(dataset.manifest["samples"])):
        stem = f"{index:06d}"
        image = cv2.imread(str(split / "image_2" / f"{stem}.png"), cv2.IMREAD_UNCHANGED)
        assert image.shape == (480, 640, 3) and image.dtype == np.uint8
        calib = kitti_devkit.read_calibration(split / "calib" / f"{stem}.txt")
        labels = kitti_devkit.read_label(split / "label_2" / f"{stem}.txt")
        record = json.loads((split / "labels" / f"{stem}.json").read_text())
        kept = [v for v in record["vehicles"] if v["kept"]]
        dont_care = [v for v in record["vehicles"] if not v["kept"]]
        assert [o.type for o in labels] == [v["kitti_type"] for v in kept] + ["DontCare"] * len(
            dont_care
        )
        np.testing.assert_allclose(calib["P2"][:, :3], record["K"], atol=1e-9)
        depth = decode_depth(
            cv2.imread(str(split / "depth_2" / f"{stem}.png"), cv2.IMREAD_UNCHANGED)
        )
        instance = cv2.imread(str(split / "instance_2" / f"{stem}.png"), cv2.IMREAD_UNCHANGED)
        for obj, vehicle in zip(labels, kept, strict=False):
            objects += 1
            # the box is the projected 3D box, clipped to the image
            corners = kitti_devkit.box_corners(obj)
            if corners[:, 2].min() > 1.0:
                uv = kitti_devkit.project(calib["P2"], corners)
                box = np.r_[np.clip(uv.min(0), 0, [639, 479]), np.clip(uv.max(0), 0, [639, 479])]
                np.testing.assert_allclose(obj.bbox, box, atol=1.5)
            # alpha is the observation angle of the box seen from the camera
            x, _, z = obj.location
            expected = (obj.rotation_y - math.atan2(x, z) + math.pi) % (2 * math.pi) - math.pi
            assert abs(math.remainder(obj.alpha - expected, 2 * math.pi)) < 0.02
            # the depth map sees the vehicle where its mask is, about where its box is
            mine = instance == vehicle["id"] + 1
            nearest = float(np.min(depth[mine]))
            assert obj.location[2] - 0.5 * obj.dimensions[2] - 1.0 < nearest < obj.location[2] + 1
    assert objects > 0


def test_coco_loads_and_evaluates_in_pycocotools(dataset):
    out = dataset.folder
    coco = COCO(str(out / "coco.json"))
    assert len(coco.getImgIds()) == len(dataset.manifest["samples"])
    assert len(coco.getAnnIds()) == dataset.manifest["statistics"]["vehicles_kept"]
    for ann in coco.loadAnns(coco.getAnnIds()):
        image = coco.loadImgs(ann["image_id"])[0]
        instance = cv2.imread(
            str(out / image["file_name"].replace("image_2", "instance_2")), cv2.IMREAD_UNCHANGED
        )
        expected = instance.astype(np.int64) - 1 == ann["track_id"]
        assert np.array_equal(coco.annToMask(ann).astype(bool), expected)
        rle = coco.annToRLE(ann)
        assert coco_mask.area(rle) == ann["area"] == expected.sum()
        np.testing.assert_allclose(coco_mask.toBbox(rle), ann["bbox"])
    # the ground truth scored against itself is perfect for boxes and masks
    detections = [{**ann, "score": 1.0} for ann in coco.loadAnns(coco.getAnnIds())]
    results = coco.loadRes(detections)
    for kind in ("bbox", "segm"):
        evaluation = COCOeval(coco, results, kind)
        evaluation.evaluate()
        evaluation.accumulate()
        evaluation.summarize()
        assert evaluation.stats[0] == pytest.approx(1.0)  # AP at IoU .50:.95


def test_filters_decide_what_is_kept(dataset):
    filters = config().filters
    records = [
        json.loads(p.read_text()) for p in sorted((dataset.folder / "training/labels").iterdir())
    ]
    vehicles = [v for r in records for v in r["vehicles"]]
    for v in vehicles:
        height = v["visible_box"][3] - v["visible_box"][1] + 1
        expected = (
            height >= filters.min_height_px
            and v["occlusion_level"] <= filters.max_occlusion
            and v["distance_m"] <= filters.max_distance_m
        )
        assert v["kept"] == expected
    assert any(not v["kept"] for v in vehicles) and any(v["kept"] for v in vehicles)


def test_episodes_are_drawn_from_congested_and_free_cells(wave_store, built_map):
    traffic = EmpiricalTraffic(wave_store)
    limits = {Road.WESTBOUND: road_limits(built_map, traffic, Road.WESTBOUND)}
    for share in (0.0, 0.5, 1.0):
        sampling = EpisodeSampling(roads=("westbound",), congested_share=share)
        cells = measure_cells(wave_store, sampling, limits, 2.0)
        assert (cells.speed < sampling.congested_below_mps).any()  # the recording's wave
        drawn = [draw_episode_of(cells, sampling, 7, i) for i in range(300)]
        congested = np.mean([e.congested for e in drawn])
        assert congested == pytest.approx(share, abs=0.08)
        t0, t1 = wave_store.time_range(Road.WESTBOUND)
        lo, hi = limits[Road.WESTBOUND]
        assert all(t0 <= e.time <= t1 - 2.0 and lo <= e.x <= hi for e in drawn)
        assert all(e.congested == (e.cell_speed < 13.4) for e in drawn)


def draw_episode_of(cells, sampling, seed, index):
    from twin.runners.episodes import draw_episode

    return draw_episode(cells, sampling, seed, index)


def test_an_episode_depends_on_the_seed_and_its_index_only(wave_store, built_map):
    few = draw_episodes(config(), wave_store, built_map, 2)
    many = draw_episodes(config(), wave_store, built_map, 6)
    assert many[:2] == few
    other = draw_episodes(override(config(), {"seed": 1}), wave_store, built_map, 2)
    assert other != few


@pytest.mark.slow  # a dataset made twice by new processes, one killed (about 12 s)
def test_a_killed_run_resumes_to_the_same_dataset(dataset, wave_store, tmp_path):
    """kill -9 of the whole run in the middle; the rerun skips the complete episodes
    and ends with a dataset identical, file by file, to the uninterrupted one."""
    out = tmp_path / "ds"
    command = [
        sys.executable, "-m", "twin", "dataset", "--episodes", str(EPISODE_COUNT),
        "--out", str(out), "--data", str(wave_store.path), "--workers", "2", "--quiet",
        *CLI_SETTINGS,
    ]  # fmt: skip
    log = tmp_path / "killed.stderr"  # a file, not a pipe nobody reads while it runs
    with open(log, "w") as stderr:
        run = subprocess.Popen(
            command, start_new_session=True, stdout=subprocess.DEVNULL, stderr=stderr
        )

    def finished() -> list[Path]:
        folder = out / EPISODES
        if not folder.is_dir():
            return []
        # an episode being written lies in a hidden .partial folder until it is renamed
        return sorted(p for p in folder.iterdir() if not p.name.startswith(".") and is_episode(p))

    deadline = time.monotonic() + 300
    # killed as soon as any episode is complete (the workers' episodes end in any order;
    # waiting for episode 0 could let the others finish first and the run end)
    try:
        while not finished():
            assert run.poll() is None, log.read_text()
            assert time.monotonic() < deadline, "no episode was finished in 5 minutes"
            time.sleep(0.02)
    finally:  # also when the run failed: no process of it is left behind
        with contextlib.suppress(ProcessLookupError):  # a run that ended by itself
            os.killpg(run.pid, signal.SIGKILL)
        run.wait()
    assert not (out / "manifest.json").exists()  # killed before the end
    done = finished()
    assert 1 <= len(done) < EPISODE_COUNT
    first = done[0]
    stamp = (first / "episode.json").stat().st_mtime_ns

    rerun = subprocess.run(command, capture_output=True, text=True, timeout=600)
    assert rerun.returncode == 0, rerun.stderr
    assert (first / "episode.json").stat().st_mtime_ns == stamp  # skipped, not redone
    assert not list(out.rglob(".*partial*"))  # the killed run's leftovers are gone
    assert files_of(out) == files_of(dataset.folder)


@pytest.mark.slow  # a local Ray cluster started and stopped (about 10 s)
def test_ray_makes_the_same_dataset(dataset, wave_store, built_map, tmp_path):
    try:
        import ray  # noqa: F401
    except ImportError:
        if os.environ.get("CI"):
            raise
        pytest.skip("Ray is not installed (pip install -e '.[ray]')")
    result = generate(
        config(),
        wave_store,
        tmp_path / "ds",
        EPISODE_COUNT,
        workers=2,
        engine="ray",
        bundle=built_map,
        progress=False,
    )
    assert result.episodes_rendered == EPISODE_COUNT
    assert files_of(result.folder) == files_of(dataset.folder)


def test_an_episode_whose_ego_cannot_be_placed_is_kept_empty(wave_store, built_map, tmp_path):
    spec = draw_episodes(config(), wave_store, built_map, 1)[0]
    late = replace(spec, time=wave_store.time_range(Road.WESTBOUND)[1] - 1.0)
    description = render_episode(config(), late, wave_store, built_map, tmp_path)
    assert "data on westbound end at" in description["skipped"]
    assert description["samples"] == [] and description["ego"] is None
    assert json.loads((tmp_path / "episode.json").read_text()) == description


def test_a_folder_of_something_else_or_other_settings_is_refused(dataset, wave_store, tmp_path):
    (tmp_path / "mine.txt").write_text("precious")
    with pytest.raises(DatasetError, match="not an i24-twin dataset"):
        generate(config(), wave_store, tmp_path, 1, progress=False)
    assert (tmp_path / "mine.txt").read_text() == "precious"
    other = override(config(), {"filters": {"min_height_px": 25.0}})
    with pytest.raises(DatasetError, match=r"filters.min_height_px: dataset has 10.0, asked 25.0"):
        generate(other, wave_store, dataset.folder, EPISODE_COUNT, progress=False)


@pytest.mark.parametrize(
    ("settings", "message"),
    [
        ({"frames_per_episode": 0}, "frames_per_episode"),
        ({"filters": {"max_occlusion": 3}}, "max_occlusion"),
        ({"sampling": {"congested_share": 1.5}}, "congested_share"),
        ({"sampling": {"roads": ["north"]}}, "unknown road"),
        ({"cosim": {"camera": {"rate_hz": 3.0}}}, "must divide"),
    ],
)
def test_impossible_settings_are_named(settings, message):
    from twin.cosim.config import ConfigError

    with pytest.raises(ConfigError, match=message):
        override(DatasetConfig(), settings)


def test_a_road_without_data_is_named(wave_store, built_map, tmp_path):
    from twin.runners.episodes import SamplingError

    with pytest.raises(SamplingError, match=r"no eastbound traffic \(roads: \['westbound'\]\)"):
        generate(DatasetConfig(), wave_store, tmp_path / "ds", 1, bundle=built_map)
    assert not (tmp_path / "ds").exists()  # nothing was claimed


def test_filters_reject_impossible_values():
    with pytest.raises(DatasetError, match="min_height_px"):
        LabelFilters(min_height_px=float("nan"))
