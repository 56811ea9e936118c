"""The table of metrics: every metric found where it says in a run's metrics.json, the
documentation generated from it up to date."""

import json

from twin.core.paths import REPO_ROOT
from twin.metrics.table import EVERY_RUN, METRICS, PAIRED, SUMMARISED, document, flatten


def test_every_metric_of_every_run_is_where_the_table_says(tmp_path):
    from tests.twin.cosim.scenes import EGO_X, make_store, vehicle
    from twin.cli import main

    docs = [vehicle(1, -2, EGO_X, 20.0), vehicle(2, -2, EGO_X - 40.0, 22.0)]
    store = make_store(tmp_path / "scene", docs)
    out = tmp_path / "run"
    assert main([
        "run", "--data", str(store.path), "--road", "westbound", "--lane", "-2", "--x",
        str(EGO_X), "--time", "2022-11-30T06:45:50-06:00", "--duration", "2", "--quiet",
        "--out", str(out),
    ]) == 0  # fmt: skip
    figures = json.loads((out / "metrics.json").read_text())
    for metric in METRICS:
        if metric.produced_by != EVERY_RUN:
            continue
        value = figures
        for key in metric.source:
            assert key in value if isinstance(value, dict) else key < len(value), (
                f"{metric.name}: no {key!r} on the way to {metric.source} in metrics.json"
            )
            value = value[key]
    row = flatten(figures)
    assert list(row) == [m.name for m in METRICS]
    assert row["collisions"] == figures["physics"]["collisions"]
    assert row["ended_early"] in (0, 1) and row["followers"] == len(
        figures["energy"]["followers"]["ids"]
    )


def test_the_summaries_and_the_pairing_come_from_the_table():
    assert set(SUMMARISED) == {m.name for m in METRICS if m.summary != "none"}
    assert PAIRED["ego_and_followers_mpg"] is True and PAIRED["jerk_rms_mps3"] is False
    assert len({m.name for m in METRICS}) == len(METRICS)


def test_the_documentation_is_the_table():
    assert (REPO_ROOT / "docs" / "metrics.md").read_text() == document(), (
        "docs/metrics.md is out of date: run python -m twin.metrics.table"
    )
