"""Camera files as other tools read them: OpenCV for PNG and MP4, json for metadata;
``twin run --camera``, ``twin render`` and the EGL renderer."""

import json
import os
import subprocess
import sys
import textwrap

import cv2
import numpy as np
import pytest

from sensors.camera import CameraRig, CameraSpec
from sensors.writer import FrameWriter, decode_depth, encode_depth, encode_instance
from tests.sensors.test_camera import EGO_X, spawn
from tests.twin.cosim.scenes import EGO_X as SCENE_X
from tests.twin.cosim.scenes import make_store, vehicle
from twin.cli import main
from twin.physics.world import PhysicsWorld

SMALL = CameraSpec(width=160, height=120, rate_hz=10.0)


@pytest.fixture(scope="module")
def frames(built_map):
    with PhysicsWorld(built_map) as world:
        ego, _ = spawn(world, EGO_X, -2, 0)
        spawn(world, EGO_X + 20.0, -2, 1)
        rig = CameraRig(world, built_map, (SMALL,), "tiny")
        captured = []
        for k in range(3):
            for _ in range(10):
                world.step()
            captured += rig.capture(ego, time=100.0 + 0.1 * k, sim_time=0.1 * k)
        rig.close()
    return captured


def test_written_frames_read_back_losslessly(frames, tmp_path):
    with FrameWriter(tmp_path, (SMALL,)) as writer:
        for frame in frames:
            writer.write(frame)
    folder = tmp_path / "front"
    for frame in frames:
        stem = f"{frame.index:06d}.png"
        rgb = cv2.imread(str(folder / "rgb" / stem), cv2.IMREAD_UNCHANGED)
        assert np.array_equal(rgb[:, :, ::-1], frame.rgb)
        depth = cv2.imread(str(folder / "depth" / stem), cv2.IMREAD_UNCHANGED)
        assert depth.dtype == np.uint16
        back = decode_depth(depth)
        near = np.isfinite(frame.depth) & (frame.depth < 65.0)
        assert np.all(np.abs(back[near] - frame.depth[near]) <= 0.0005 + 1e-6)
        assert np.all(np.isinf(back[np.isinf(frame.depth)]))
        semantic = cv2.imread(str(folder / "semantic" / stem), cv2.IMREAD_UNCHANGED)
        assert np.array_equal(semantic, frame.semantic)
        instance = cv2.imread(str(folder / "instance" / stem), cv2.IMREAD_UNCHANGED)
        assert instance.dtype == np.uint16
        assert np.array_equal(instance.astype(np.int64) - 1, frame.instance)
        meta = json.loads((folder / "meta" / stem.replace(".png", ".json")).read_text())
        np.testing.assert_allclose(meta["K"], frame.K)
        np.testing.assert_allclose(meta["world_from_camera"], frame.world_from_camera)
        assert meta["time"] == frame.time and meta["ego_id"] == frame.ego_id
        assert [v["id"] for v in meta["vehicles"]] == [1]
        assert meta["vehicles"][0]["pixels"] == int((frame.instance == 1).sum())
    video = cv2.VideoCapture(str(folder / "rgb.mp4"))
    assert int(video.get(cv2.CAP_PROP_FRAME_COUNT)) == len(frames)
    ok, first = video.read()
    assert ok and first.shape == (120, 160, 3)
    rig = json.loads((tmp_path / "rig.json").read_text())
    assert rig["cameras"][0]["name"] == "front" and len(rig["classes"]) == 16


def test_depth_and_instance_encodings_name_their_limits():
    depth = np.array([[0.0004, 1.2345, 70.0, np.inf]], dtype=np.float32)
    assert encode_depth(depth).tolist() == [[0, 1234, 65535, 0]]
    with pytest.raises(ValueError, match="16-bit"):
        encode_instance(np.array([[65535]]))


def test_a_failing_write_is_raised_not_lost(frames, tmp_path):
    writer = FrameWriter(tmp_path, (SMALL,), video=False)
    (tmp_path / "front" / "rgb").rmdir()
    (tmp_path / "front" / "rgb").write_text("not a folder")
    writer.write(frames[0])
    with pytest.raises(OSError, match="could not be written"):
        writer.close()


@pytest.fixture(scope="module")
def scene_store(tmp_path_factory):
    docs = [vehicle(1, -2, SCENE_X, 20.0), vehicle(3, -1, SCENE_X + 40.0, 22.0)]
    return make_store(tmp_path_factory.mktemp("camera-scene"), docs)


def scene_args(store):
    return [
        "--data", str(store.path), "--set", "road=westbound", "--set", "lane=-2",
        "--set", f"x={SCENE_X}", "--set", "time=1669812350.0",
    ]  # fmt: skip


def test_twin_run_camera_writes_frames_at_the_camera_rate(scene_store, tmp_path, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    out = tmp_path / "run"
    args = ["run", *scene_args(scene_store), "--duration", "0.5", "--camera", "--quiet"]
    args += ["--set", "camera.width=160", "--set", "camera.height=120", "--out", str(out)]
    assert main(args) == 0
    folder = out / "cameras" / "front"
    assert sorted(p.name for p in (folder / "rgb").iterdir()) == [
        f"{k:06d}.png" for k in range(6)
    ]  # t = 0, 0.1, ..., 0.5 s
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["cameras"]["frames"] == 6 and metrics["cameras"]["renderer"] == "tiny"
    meta = json.loads((folder / "meta" / "000005.json").read_text())
    assert abs(meta["sim_time"] - 0.5) < 1e-9
    assert "camera" in (out / "config.toml").read_text()


def test_twin_render_writes_one_frame_and_a_label_panel(scene_store, tmp_path, capsys):
    out = tmp_path / "frame.png"
    args = ["render", *scene_args(scene_store), "--t", "0.2", "--out", str(out), "--labels"]
    assert main(args) == 0
    picture = cv2.imread(str(out))
    assert picture.shape[0] > 960 and picture.shape[1] > 1280  # 2 x 2 panels with labels
    assert "1 vehicles in view" in capsys.readouterr().out
    # any mount can be named, not only the rig's cameras
    rear = ["render", *scene_args(scene_store), "--camera", "rear", "--out", str(out)]
    assert main(rear) == 0
    assert "camera rear" in capsys.readouterr().out
    assert cv2.imread(str(out)).shape == (480, 640, 3)
    assert main([*rear[:-2], "--camera", "roof", "--out", str(out)]) == 2
    assert "unknown camera(s) ['roof']" in capsys.readouterr().err
    assert main(["render", *scene_args(scene_store), "--t", "99", "--out", str(out)]) == 2
    assert "--t must be in" in capsys.readouterr().err


EGL_SCRIPT = textwrap.dedent(
    """
    import sys, numpy as np
    from mapgen.build import load_map
    from sensors.camera import CameraRig, CameraSpec
    from tests.sensors.test_camera import spawn, EGO_X
    from twin.physics.world import PhysicsWorld
    bundle = load_map(sys.argv[1])
    out = {}
    for renderer in ("tiny", "egl"):
        with PhysicsWorld(bundle) as world:
            ego, _ = spawn(world, EGO_X, -2, 0)
            spawn(world, EGO_X + 20.0, -2, 1)
            world.step()
            rig = CameraRig(world, bundle, (CameraSpec(width=320, height=240),), renderer)
            frame = rig.capture(ego)[0]
            out[renderer + "_semantic"] = frame.semantic
            out[renderer + "_instance"] = frame.instance
            out[renderer + "_depth"] = frame.depth
            rig.close()
    np.savez(sys.argv[2], **out)
    """
)


def test_egl_renderer_gives_the_same_labels(built_map, tmp_path):
    """EGL (the GPU where one is, else Mesa's llvmpipe) in a child process: a broken EGL
    stack must not take the test session down with it."""
    result = subprocess.run(
        [sys.executable, "-c", EGL_SCRIPT, str(built_map.folder), str(tmp_path / "egl.npz")],
        capture_output=True,
        text=True,
        cwd=os.getcwd(),
        env={**os.environ, "PYTHONPATH": os.getcwd()},
        timeout=300,
    )
    if result.returncode != 0:
        if os.environ.get("CI"):
            pytest.fail(f"the EGL renderer failed:\n{result.stderr[-2000:]}")
        pytest.skip(f"no working EGL here: {result.stderr.strip().splitlines()[-1:]}")
    data = np.load(tmp_path / "egl.npz")
    # the same classes and ids; the two rasterisers place edges up to a pixel apart
    # (measured on llvmpipe: 98.1 % of semantic pixels agree, 98.7 % shifted by one), so
    # a sliver of a pixel or two (a distant pole's edge) may be drawn by one only
    for name in ("semantic", "instance"):
        tiny, egl = data["tiny_" + name], data["egl_" + name]
        assert _seen(tiny, 3) <= _seen(egl, 1) and _seen(egl, 3) <= _seen(tiny, 1), name
    assert np.mean(data["tiny_semantic"] == data["egl_semantic"]) > 0.97
    assert np.mean(data["tiny_instance"] == data["egl_instance"]) > 0.99
    both = np.isfinite(data["tiny_depth"]) & np.isfinite(data["egl_depth"])
    error = np.abs(data["egl_depth"][both] / data["tiny_depth"][both] - 1.0)
    assert np.median(error) < 0.02  # measured 0.7 %: the same one-pixel offset on the road


def _seen(labels: np.ndarray, pixels: int) -> set:
    """The labels covering at least ``pixels`` pixels."""
    values, counts = np.unique(labels, return_counts=True)
    return set(values[counts >= pixels].tolist())
