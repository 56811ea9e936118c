"""The benchmarks page: made from twin bench's JSON lines, naming a line it cannot read,
and the page in docs/ made from the lines kept beside it."""

import json

import pytest

from twin.cli import main
from twin.core.paths import REPO_ROOT
from twin.perf.common import context
from twin.perf.report import (
    ReportError,
    document,
    figures,
    met,
    read_lines,
    replace_lines,
    unit_of,
)

MACHINE = {
    "cpu": "Test CPU",
    "cores": 8,
    "memory_gb": 31.4,
    "os": "Linux-6",
    "numpy": "2.0.0",
    "pybullet": "3.2.7",
}
QUERY = {
    "bench": "query",
    "snapshot_median_us": 21.3,
    "target_us": 200,
    "vehicles_in_window": 34,
    "window_m": 400.0,
    "repeats": 5,
    "options": {"--data": None, "--repeats": 5},
    "commit": "abc1234",
    "dirty": True,
    "date": "2026-11-24T05:40:01+00:00",
    "python": "3.11.7",
    "cpus": 2,
    "machine": MACHINE,
}
PHYSICS = {
    "bench": "physics",
    "vehicles_100": {"step_ms": 1.54, "real_time_factor": 6.5},
    "vehicles_200": {"step_ms": 2.65, "real_time_factor": 3.8},
    "targets": {"vehicles_100": ">= 10 x", "vehicles_200": ">= 5 x"},
    "dt": 0.01,
    "steps": 500,
    "repeats": 3,
    "wall_s_runs": [1.0, 2.0],
    "options": {"--steps": 500, "--repeats": 3},
    "commit": "def5678",
    "dirty": False,
    "date": "2026-11-24T06:00:00+00:00",
    "python": "3.11.7",
    "cpus": 2,
    "machine": MACHINE,
}


def test_every_figure_becomes_a_row_with_its_unit_target_and_run():
    page = document([QUERY, PHYSICS])
    assert "| query | `snapshot_median_us` | 21.3 | µs | <= 200 | yes | 1 |" in page
    assert "| query | `vehicles_in_window` | 34 | count | - | - | 1 |" in page
    # a group's target in another unit is shown, and judged only where its unit is the figure's
    assert "| physics | `vehicles_100.step_ms` | 1.54 | ms | >= 10 x | - | 2 |" in page
    assert (
        "| physics | `vehicles_200.real_time_factor` | 3.8 | x real time | >= 5 x | **no** | 2 |"
        in page
    )
    # settings, context and the single repeats are not figures
    names = [f.name for f in figures(PHYSICS, 2)]
    assert names == [
        "vehicles_100.step_ms",
        "vehicles_100.real_time_factor",
        "vehicles_200.step_ms",
        "vehicles_200.real_time_factor",
    ]


def test_runs_give_settings_date_commit_and_machine():
    page = document([QUERY, PHYSICS])
    assert "| 1 | query | `--repeats 5` | 2026-11-24 05:40 | abc1234 (modified) | A |" in page
    assert "| 2 | physics | `--steps 500` `--repeats 3` | 2026-11-24 06:00 | def5678 | A |" in page
    assert "| A | Test CPU | 8 (2) | 31.4 | Linux-6 | 3.11.7 | 2.0.0 | 3.2.7 |" in page
    assert "twin bench report --run query,physics --lines docs/benchmarks.jsonl" in page


def test_units_are_read_from_the_keys():
    assert unit_of("throughput_mb_s") == "MB/s"
    assert unit_of("env_steps_per_s") == "steps/s"
    assert unit_of("decision_p99_ms") == "ms"
    assert unit_of("vehicle_triangles_median") == "count"
    assert unit_of("ghost_reload_share") == "share"
    assert unit_of("relative_difference") == "-"


@pytest.mark.parametrize(
    "line, message",
    [
        ('{"bench": "query", "snapshot_median_us": 21.3', "not a JSON line of twin bench"),
        ("[1, 2, 3]", "expected a JSON object, got list"),
        ('{"snapshot_median_us": 21.3}', "no benchmark name"),
    ],
)
def test_a_malformed_line_is_named_by_file_and_line(tmp_path, line, message):
    path = tmp_path / "lines.jsonl"
    path.write_text(json.dumps(QUERY) + "\n\n" + line + "\n")
    with pytest.raises(ReportError, match=message) as error:
        read_lines([path])
    assert f"{path}:3" in str(error.value)


@pytest.mark.parametrize(
    ("target", "value", "unit", "expected"),
    [
        ("<= 200", 31.0, "µs", True),
        ("<= 0.3", 0.45, "ms", False),
        (">= 10 x (<= 1 ms)", 0.9, "ms", True),
        (">= 10 x (<= 1 ms)", 4.6, "x real time", False),
        (">= 5 x", 4.0, "ms", None),
        (None, 1.0, "ms", None),
    ],
)
def test_a_figure_is_judged_by_the_bound_in_its_unit(target, value, unit, expected):
    assert met(target, value, unit) is expected


def test_refreshing_some_benchmarks_keeps_the_others_in_their_places():
    old = [QUERY, PHYSICS, {**QUERY, "bench": "synth"}]
    new_physics, new_map = {**PHYSICS, "commit": "0000000"}, {**QUERY, "bench": "map"}
    merged = replace_lines(old, [new_map, new_physics])
    assert [(line["bench"], line["commit"]) for line in merged] == [
        ("query", "abc1234"), ("physics", "0000000"), ("synth", "abc1234"), ("map", "abc1234")
    ]  # fmt: skip


def test_twin_bench_report_writes_the_page_and_keeps_the_lines(tmp_path, capsys):
    given = tmp_path / "given.jsonl"
    given.write_text(json.dumps(QUERY) + "\n" + json.dumps(PHYSICS) + "\n")
    lines, page = tmp_path / "kept.jsonl", tmp_path / "benchmarks.md"
    assert main(["bench", "report", str(given), "--lines", str(lines), "--out", str(page)]) == 0
    assert read_lines([lines]) == [QUERY, PHYSICS]
    assert page.read_text() == document([QUERY, PHYSICS], lines_path=str(lines), page=str(page))
    assert main(["bench", "report", "--out", str(page)]) == 2
    assert main(["bench", "report", "--run", "nothing", "--out", str(page)]) == 2
    assert "--run: no benchmark nothing" in capsys.readouterr().err


def test_a_benchmark_line_carries_its_date_and_machine():
    line = context()
    assert {"commit", "dirty", "date", "python", "cpus", "machine"} <= set(line)
    assert line["date"].endswith("+00:00") and line["cpus"] >= 1
    assert line["machine"]["pybullet"] and line["machine"]["cores"] >= line["cpus"]


def test_the_benchmarks_page_is_made_from_the_lines_beside_it():
    lines = read_lines([REPO_ROOT / "docs" / "benchmarks.jsonl"])
    expected = document(lines, lines_path="docs/benchmarks.jsonl", page="docs/benchmarks.md")
    assert (REPO_ROOT / "docs" / "benchmarks.md").read_text() == expected, (
        "docs/benchmarks.md is out of date: run twin bench report docs/benchmarks.jsonl "
        "--out docs/benchmarks.md"
    )
