"""Map outputs: files other tools open, determinism, the cache, and safe writing."""

import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
import trimesh

from mapgen import build
from mapgen.build import build_map, default_map, load_map, map_key
from twin.cli import main
from twin.core.errors import MapError

VALIDATOR_SCRIPT = """
const validator = require(process.argv[2]);
const bytes = new Uint8Array(require('fs').readFileSync(process.argv[3]));
validator.validateBytes(bytes).then(
  (report) => console.log(JSON.stringify(report.issues)),
  (error) => { console.error(error); process.exit(1); });
"""


def _validator() -> Path | None:
    """The npm package gltf-validator: $GLTF_VALIDATOR_DIR, else the CI cache folder."""
    folders = [os.environ.get("GLTF_VALIDATOR_DIR"), Path.home() / ".cache" / "i24-twin-npm"]
    for folder in filter(None, folders):
        module = Path(folder) / "node_modules" / "gltf-validator"
        if module.is_dir() and shutil.which("node"):
            return module
    return None


def test_glb_passes_the_khronos_validator(built_map, tmp_path):
    module = _validator()
    if module is None:
        if os.environ.get("CI"):
            pytest.fail("gltf-validator is not installed; .ci/run installs it with npm")
        pytest.skip(
            "npm package gltf-validator not installed (see docs/getting-started.md, The tests)"
        )
    script = tmp_path / "validate.js"
    script.write_text(VALIDATOR_SCRIPT)
    result = subprocess.run(
        ["node", str(script), str(module), str(built_map.folder / "scene.glb")],
        capture_output=True,
        text=True,
        check=True,
        timeout=120,
    )
    issues = json.loads(result.stdout)
    assert issues["numErrors"] == 0, issues["messages"][:5]
    assert issues["numWarnings"] == 0, issues["messages"][:5]


def test_glb_holds_every_part_with_its_class_and_is_y_up(built_map):
    scene = trimesh.load(built_map.folder / "scene.glb")
    assert set(scene.geometry) == {part.name for part in built_map.parts}
    for part in built_map.parts:
        geometry = scene.geometry[part.name]
        assert geometry.metadata["semantic_class"] == part.semantic_class
        assert len(geometry.faces) == part.triangles
    terrain = trimesh.load(built_map.folder / "visual" / "terrain.obj")
    glb_terrain = scene.geometry["terrain"]
    # glTF +Y up: the GLB's y is the world's z and its z is minus the world's north
    np.testing.assert_allclose(glb_terrain.bounds[:, 1], terrain.bounds[:, 2], atol=1e-4)
    np.testing.assert_allclose(glb_terrain.bounds[:, 2], -terrain.bounds[::-1, 1], atol=1e-4)


def test_road_json_describes_the_geometry(built_map):
    description = json.loads((built_map.folder / "road.json").read_text())
    assert description["format"] == "i24-twin-map"
    assert description["cross_section"]["lane_width_m"] == pytest.approx(3.6576)
    assert description["road"]["origin"]["lat_deg"] == pytest.approx(36.03399726)
    assert "Gloudemans" in description["sources"]["citation"]
    assert set(description["sources"]["files"]) >= {"mile_marker_layer.csv", "map.toml"}
    reloaded = load_map(built_map.folder)
    assert reloaded.road.bearing == built_map.road.bearing


def test_same_seed_same_bytes(built_map, tmp_path):
    a = built_map  # the session's, of seed 0
    b = build_map(tmp_path / "b", seed=0)
    files = sorted(p.relative_to(a.folder) for p in a.folder.rglob("*") if p.is_file())
    assert len(files) >= 12
    for name in files:
        assert (a.folder / name).read_bytes() == (b.folder / name).read_bytes(), name


def test_default_map_is_cached_by_input_hash(tmp_path, monkeypatch):
    monkeypatch.setenv("I24_TWIN_CACHE", str(tmp_path))
    first = default_map(seed=0)
    stamp = (first.folder / "road.json").stat().st_mtime_ns
    again = default_map(seed=0)
    assert again.folder == first.folder
    assert (again.folder / "road.json").stat().st_mtime_ns == stamp  # not rebuilt
    assert map_key(0) != map_key(1)
    assert first.folder.name == f"map-{map_key(0)}"


def test_build_never_overwrites_a_folder_that_is_not_a_map(tmp_path):
    precious = tmp_path / "precious"
    precious.mkdir()
    (precious / "thesis.tex").write_text("years of work")
    with pytest.raises(MapError, match="not an i24-twin map"):
        build_map(precious)
    assert (precious / "thesis.tex").read_text() == "years of work"


def test_failed_build_leaves_the_previous_map_intact(tmp_path, monkeypatch):
    out = build_map(tmp_path / "map", seed=0).folder
    before = (out / "road.json").read_bytes()

    def broken(*args, **kwargs):
        raise RuntimeError("disk full")

    monkeypatch.setattr(build, "_glb", broken)
    with pytest.raises(RuntimeError, match="disk full"):
        build_map(out, seed=1)
    assert (out / "road.json").read_bytes() == before
    assert not list(tmp_path.glob(".map.partial-*"))


def test_loading_something_else_is_a_clear_error(tmp_path):
    with pytest.raises(MapError, match="not an i24-twin map folder"):
        load_map(tmp_path)
    out = build_map(tmp_path / "map").folder
    (out / "visual" / "terrain.obj").unlink()
    with pytest.raises(MapError, match=r"lacks visual/terrain\.obj"):
        load_map(out)


def test_cli_build_and_preview(tmp_path, capsys):
    assert main(["map", "build", "--out", str(tmp_path / "m"), "--seed", "2"]) == 0
    assert "visual" in capsys.readouterr().out
    png = tmp_path / "map.png"
    assert main(["map", "preview", "--map", str(tmp_path / "m"), "--out", str(png)]) == 0
    import cv2

    image = cv2.imread(str(png))
    assert image is not None and image.shape[1] == 1600 and image.shape[0] > 1000
    # the driver's-eye panel (bottom) shows pavement below and sky above
    bottom = image[-50:, 700:900].reshape(-1, 3).mean(axis=0)
    assert np.ptp(bottom) < 20 and bottom.mean() < 120  # grey asphalt
    assert main(["map", "preview", "--map", str(tmp_path / "nothing"), "--out", str(png)]) == 2
    assert "not an i24-twin map folder" in capsys.readouterr().err
