"""Benchmarks behind ``twin bench``: each returns a dict of figures (medians of repeats).

The command line prints each as one JSON line with the commit (:func:`context`), so
results can be compared between commits. Targets live here, not in timed unit tests.
This module is the one the command line imports; the benchmarks live by what they
measure: :mod:`twin.perf.data` (queries, synthesiser, ingest, calibration),
:mod:`twin.perf.simulation` (map, physics, traffic, cosimulation),
:mod:`twin.perf.camera`, :mod:`twin.perf.runners` (datasets and evaluations by
workers), :mod:`twin.perf.env_steps` (the env) and :mod:`twin.perf.first_run` (a new
user's first ``twin run``), on :mod:`twin.perf.common`; :mod:`twin.perf.fidelity` (the
twin's fidelity over many days against the issue's targets) writes a folder of results
beside its line.
"""

from twin.perf.camera import camera_bench
from twin.perf.common import context
from twin.perf.data import calibrate_bench, ingest_bench, query, synth_bench
from twin.perf.env_steps import env_bench
from twin.perf.fidelity import fidelity_bench
from twin.perf.first_run import first_run_bench
from twin.perf.runners import dataset_bench, eval_bench
from twin.perf.simulation import map_bench, physics_bench, run_bench, traffic_bench

__all__ = [
    "calibrate_bench",
    "camera_bench",
    "context",
    "dataset_bench",
    "env_bench",
    "eval_bench",
    "fidelity_bench",
    "first_run_bench",
    "ingest_bench",
    "map_bench",
    "physics_bench",
    "query",
    "run_bench",
    "synth_bench",
    "traffic_bench",
]
