"""The folder of a resumable run: claimed once, recognised on a rerun, refused when it
holds something else, and resumable after the twin gained a setting."""

import json

import pytest

from twin.core.errors import TwinError
from twin.runners.folders import claim, differences

TOML = 'seed = 3\n\n[traffic]\nhov_share = 0.2\ncar_following = "idm"\n'
OLD_TOML = "seed = 3\n\n[traffic]\nhov_share = 0.2\n"  # before car_following existed


def _claim(out, config=TOML, **options):
    identity = {"format": "kind-x", "config": config}
    claim(out, "marker.json", identity, kind="x", noun="thing", error=TwinError,
          files={"config.toml": config}, toml=("config",), **options)  # fmt: skip


def test_a_new_folder_is_claimed_with_its_files_then_recognised(tmp_path):
    out = tmp_path / "run"
    _claim(out)
    assert (out / "config.toml").read_text() == TOML
    assert json.loads((out / "marker.json").read_text())["format"] == "kind-x"
    _claim(out)  # the same settings: resumed
    with pytest.raises(TwinError, match=r"traffic\.hov_share: thing has 0\.2, asked 0\.5"):
        _claim(out, TOML.replace("0.2", "0.5"))


def test_a_file_a_foreign_folder_and_a_damaged_marker_are_refused(tmp_path):
    (tmp_path / "file").write_text("x")
    with pytest.raises(TwinError, match="is a file"):
        _claim(tmp_path / "file")
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("mine")
    with pytest.raises(TwinError, match="not an x folder; refusing to write into it"):
        _claim(foreign)
    assert (foreign / "notes.txt").read_text() == "mine"
    damaged = tmp_path / "damaged"
    damaged.mkdir()
    (damaged / "marker.json").write_text("{not json")
    with pytest.raises(TwinError, match="is damaged"):
        _claim(damaged)


def test_a_folder_made_before_a_setting_existed_resumes_at_its_default(tmp_path):
    out = tmp_path / "old"
    _claim(out, OLD_TOML)
    defaults = {"config": TOML}
    _claim(out, TOML, defaults=defaults)  # car_following asked at its default: resumed
    with pytest.raises(TwinError, match="car_following: thing has None, asked 'gipps'"):
        _claim(out, TOML.replace('"idm"', '"gipps"'), defaults=defaults)
    # without the defaults the new setting is a difference
    assert differences({"config": OLD_TOML}, {"config": TOML}, "thing", ("config",)) == [
        "config.traffic.car_following: thing has None, asked 'idm'"
    ]
