"""``twin data``: a store made from day files on the command line, and described."""

from tests.conftest import make_doc, write_day
from twin.cli import main


def test_ingest_then_info_describes_the_store_per_lane(tmp_path, capsys):
    day = write_day(tmp_path / "day.json", [make_doc("a" * 24), make_doc("b" * 24, y_ft=30.0)])
    assert main(["data", "ingest", str(day), "--out", str(tmp_path / "s"), "--quiet"]) == 0
    assert main(["data", "info", str(tmp_path / "s")]) == 0
    out = capsys.readouterr().out
    assert "westbound 2 trajectories, 100 samples" in out
    assert "lane -1: 1 trajectories, 50 samples  (HOV)" in out
    assert "lane -2: 1 trajectories, 50 samples" in out


def test_a_plot_window_outside_the_data_is_a_named_error(tmp_path, capsys):
    day = write_day(tmp_path / "day.json", [make_doc()])
    assert main(["data", "ingest", str(day), "--out", str(tmp_path / "s"), "--quiet"]) == 0
    capsys.readouterr()
    out = tmp_path / "ts.png"
    argv = ["data", "plot", str(tmp_path / "s"), "--out", str(out)]
    assert main([*argv, "--start", "2031-01-01T08:00:00-06:00"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("twin: error: no westbound samples between 2031-01-01 08:00:00")
    assert "the store covers 2022-11-30 06:45:50 to 2022-11-30 06:45:51 CST" in err
    assert main([*argv, "--minutes", "-1"]) == 2
    assert "no westbound samples" in capsys.readouterr().err
    assert not out.exists()
    assert main(argv) == 0 and out.is_file()


def test_synth_command_writes_a_day(tmp_path, capsys):
    out = tmp_path / "day.json"
    assert (
        main(
            [
                "data",
                "synth",
                "--preset",
                "A",
                "--out",
                str(out),
                "--minutes",
                "0.5",
                "--start",
                "2022-11-30T06:45:50-06:00",
                "--quiet",
            ]
        )
        == 0
    )
    assert out.read_bytes().startswith(b"[") and "trajectories" in capsys.readouterr().out
    assert main(["data", "synth", "--preset", "A", "--out", str(out), "--start", "06:45"]) == 2
    assert "ISO 8601" in capsys.readouterr().err
