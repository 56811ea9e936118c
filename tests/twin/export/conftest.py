"""The run the exporters' tests export: scenario B for 8 s on the wave store, made once
for the package."""

import pytest

from twin.cli import main


@pytest.fixture(scope="package")
def run(wave_store, tmp_path_factory):
    out = tmp_path_factory.mktemp("run") / "b"
    args = ["run", "--scenario", "B", "--data", str(wave_store.path), "--duration", "8",
            "--out", str(out), "--quiet"]  # fmt: skip
    assert main(args) == 0
    return out
