"""The first run's kernels compiled in the background (twin.runners.precompile): what
says they are cached, what a part compiles, and clear refusals."""

import pytest

from twin.runners import precompile


def test_a_run_starts_no_compilation_where_the_marker_says_the_kernels_are_cached(
    tmp_path, monkeypatch
):
    monkeypatch.setattr(precompile, "marker", lambda world: tmp_path / f"compiled-{world}")
    (tmp_path / "compiled-kinematic").write_text("1\n")
    assert precompile.compiled("kinematic") and precompile.start("kinematic") is None
    assert not precompile.compiled("physics")


def test_the_step_part_compiles_the_step_of_the_state_a_run_packs(tmp_path):
    """The ``step`` part compiles the step kernel for the cosimulator's packed state (a
    load, where the session compiled it already), says it is done, and leaves the
    marker to the ``episode`` part."""
    from twin.cosim.core import step

    before = precompile.marker("kinematic").is_file()
    done = tmp_path / "steps-done"
    assert precompile.main(["kinematic", "step", str(done)]) == 0
    assert step.step_batch.signatures
    assert done.is_file()  # what the episode part waits for
    assert precompile.marker("kinematic").is_file() == before


@pytest.mark.parametrize("argv", [["air", "step", "d"], ["physics", "all", "d"], ["kinematic"]])
def test_an_unknown_world_or_part_is_a_usage_error(argv, capsys):
    assert precompile.main(argv) == 2
    assert "usage: python -m twin.runners.precompile" in capsys.readouterr().err
    with pytest.raises(ValueError, match="world must be one of"):
        precompile.Compilation("air")
