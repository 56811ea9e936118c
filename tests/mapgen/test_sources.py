"""The map's inputs: shipped copies of the I-24 data, and clear errors on bad files."""

import shutil

import pytest

from mapgen.params import load_params
from mapgen.sources import SOURCE_FILES, load_sources
from tests.conftest import SHARED
from twin.core.errors import MapError
from twin.core.paths import asset


@pytest.mark.parametrize("name", SOURCE_FILES)
def test_shipped_sources_are_the_shared_i24_files(name):
    shared = SHARED / "data" / "i24_aux" / name
    if not shared.exists():
        pytest.skip("../shared is not beside the checkout")
    assert asset(f"i24_aux/{name}").read_bytes() == shared.read_bytes()


@pytest.fixture
def aux(tmp_path):
    folder = tmp_path / "aux"
    shutil.copytree(asset("i24_aux"), folder)
    return folder


def test_sources_load(aux):
    sources = load_sources(aux)
    assert 60.6 in sources.post_mm
    assert sources.profile_mm.size == 401  # MM 58.90 to 62.90
    assert "eb_OF_overpass" in sources.landmarks


@pytest.mark.parametrize(
    ("file", "edit", "message"),
    [
        ("mile_marker_layer.csv", lambda t: t.replace("X_WGS84", "lon"), "missing column"),
        ("mile_marker_layer.csv", lambda t: t.replace("-86.64237969", "nan"), "non-finite"),
        ("pole_layer.csv", lambda t: t.replace("-86.66833967", "east"), "non-numeric"),
        ("grade_elevation.csv", lambda t: t.replace("60.5,", "60.55,"), "0.01 mi grid"),
        ("grade_elevation.csv", lambda t: t.split("\n")[0], "no rows"),
        ("mile_marker_layer.csv", lambda t: "", "not a readable CSV"),
    ],
)
def test_malformed_sources_name_the_file_and_problem(aux, file, edit, message):
    path = aux / file
    path.write_text(edit(path.read_text()))
    with pytest.raises(MapError, match=message) as error:
        load_sources(aux)
    assert file in str(error.value)


def test_missing_source_file(aux):
    (aux / "pole_layer.csv").unlink()
    with pytest.raises(MapError, match=r"pole_layer.csv not found"):
        load_sources(aux)


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        ("clearance = 5.1", "clearance = 4.0", "clearance must be >= 4.9"),
        ("margin = 402.336", "margin = 100.0", "margin must be >= 400"),
        ("lift = 0.01", 'lift = "high"', "expected a number"),
        ("octaves = 3", "octaves = 2.5", "expected an integer"),
        ("[posts]", "[postz]", "missing table \\[posts\\]"),
        ("outer_shoulder = 3.048", "outer_shoulder = 3.048\nwidth = 1", "unknown \\['width'\\]"),
        ("fit_mm = [60.4, 61.8]", "fit_mm = [60.4]", "2 items"),
        ("[extent]", "[extent", "not valid TOML"),
    ],
)
def test_malformed_params_name_the_problem(tmp_path, old, new, message):
    text = asset("map.toml").read_text()
    assert old in text
    path = tmp_path / "map.toml"
    path.write_text(text.replace(old, new, 1))
    with pytest.raises(MapError, match=message) as error:
        load_params(path)
    assert str(path) in str(error.value)
