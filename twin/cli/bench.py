"""``twin bench``: the performance benchmarks of :mod:`twin.perf.bench`, each printing
one JSON line of figures with the commit and machine they were taken on."""

import json
from pathlib import Path

from twin.cli.evaluate import add_eval_options
from twin.cli.options import (
    UsageError,
    add_data,
    add_repeats,
    add_worker_counts,
    add_workers,
    add_world,
    checked_data,
    checked_road,
    listed,
    open_data,
    open_store,
    worker_counts,
    workers_or_cores,
)

STORE_HELP = "store (default: the embedded data)"


def register(commands) -> None:
    """Add ``bench`` and its benchmarks to the subparsers ``commands``."""
    bench = commands.add_parser("bench", help="benchmarks; each prints one JSON line")
    benchmarks = bench.add_subparsers(title="benchmarks")
    _register_parts(benchmarks)
    _register_commands(benchmarks)


def _register_parts(benchmarks) -> None:
    """The twin's parts and its loop: query, synth, map, physics, traffic, run, camera."""
    p = benchmarks.add_parser("query", help="snapshot latency of EmpiricalTraffic")
    add_data(p, STORE_HELP)
    add_repeats(p, 5)
    p.set_defaults(handler=_query)
    p = benchmarks.add_parser("synth", help="time to synthesize 10 minutes of one direction")
    p.add_argument("--minutes", type=float, default=10.0)
    add_repeats(p, 3)
    p.set_defaults(handler=_synth)
    p = benchmarks.add_parser("map", help="full map build time and triangle counts")
    add_repeats(p, 5)
    p.set_defaults(handler=_map)
    p = benchmarks.add_parser("physics", help="physics step time with 100 and 200 vehicles")
    p.add_argument("--steps", type=int, default=500)
    add_repeats(p, 3)
    p.set_defaults(handler=_physics)
    p = benchmarks.add_parser(
        "traffic", help="traffic manager decision step and closed loop, 100 vehicles"
    )
    p.add_argument("--vehicles", type=int, default=100)
    p.add_argument("--steps", type=int, default=3000)
    add_repeats(p, 3)
    p.set_defaults(handler=_traffic)
    p = benchmarks.add_parser(
        "run", help="the whole cosimulation loop of scenario B (no outputs written)"
    )
    p.add_argument("--scenario", choices=["A", "B"], default="B")
    add_data(p, STORE_HELP)
    add_repeats(p, 3)
    p.set_defaults(handler=_run)
    p = benchmarks.add_parser(
        "camera", help="camera frames per second, 640x480, 100 vehicles, with and without files"
    )
    p.add_argument("--renderer", choices=["tiny", "egl"], default="tiny")
    p.add_argument("--frames", type=int, default=30)
    add_repeats(p, 3)
    add_data(p, "recording drawn around the scene (default: the embedded data)")
    p.add_argument(
        "--no-replay", action="store_true", help="without the recorded traffic around the scene"
    )
    p.set_defaults(handler=_camera)


def _register_commands(benchmarks) -> None:
    """The commands run at scale: dataset, env, eval, calibrate, ingest."""
    p = benchmarks.add_parser(
        "dataset", help="labelled 640x480 frames per second of twin dataset, by workers"
    )
    add_data(p, STORE_HELP)
    p.add_argument("--episodes", type=int, default=16)
    p.add_argument("--frames", type=int, default=20, help="frames per episode")
    add_worker_counts(p)
    add_repeats(p, 3)
    p.set_defaults(handler=_dataset)
    p = benchmarks.add_parser(
        "env", help="env steps per second of i24twin/WaveDampening-v0, one env and a vector env"
    )
    add_data(p, "store (default: the embedded morning)", type=str)
    p.add_argument("--steps", type=int, default=200, help="steps timed per env")
    add_workers(p, "vector env size (default: cores)")
    add_world(p)
    add_repeats(p, 3)
    p.set_defaults(handler=_env)
    p = benchmarks.add_parser(
        "worlds",
        help="the kinematic world against the physics world: twin eval in both, compared",
        description="Run the same evaluation (with --controller: the paired benchmark) in "
        "the physics and the kinematic world, on the same episodes and seeds, into "
        "OUT/physics and OUT/kinematic, and compare them in OUT/worlds.json and worlds.md: "
        "the ego's speed between worlds, each fidelity figure, the controllers' signs and "
        "ranking. Rerun the same command to resume.",
    )
    add_eval_options(p)
    p.add_argument("--out", type=Path, required=True, help="comparison folder")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(handler=_worlds)
    p = benchmarks.add_parser("eval", help="wall time of twin eval, by workers")
    add_data(p, STORE_HELP)
    p.add_argument("--episodes", type=int, default=4)
    p.add_argument("--duration", type=float, default=60.0, help="episode length [s]")
    p.add_argument("--behaviour", default="paper", help="behaviours, comma-separated")
    add_worker_counts(p)
    add_repeats(p, 1)
    p.set_defaults(handler=_eval)
    p = benchmarks.add_parser("calibrate", help="wall time of twin calibrate on one road")
    add_data(p, STORE_HELP)
    p.add_argument("--road", default="westbound")
    add_repeats(p, 3)
    p.set_defaults(handler=_calibrate)
    p = benchmarks.add_parser("ingest", help="ingest throughput and peak memory")
    p.add_argument("--size-mb", type=float, default=300.0)
    add_repeats(p, 3)
    p.set_defaults(handler=_ingest)


def _emit(name: str, figures: dict) -> int:
    """Print the figures of benchmark ``name`` as one JSON line, with their context."""
    from twin.perf.bench import context

    print(json.dumps({"bench": name, **figures, **context()}))
    return 0


def _store_or_none(data):
    """The store of ``--data``, or None for the benchmark's own default."""
    return open_store(data) if data is not None else None


def _check_positive(**values: float) -> None:
    """Raise :class:`UsageError` naming the first option whose value is not > 0."""
    for name, value in values.items():
        if not value > 0:
            raise UsageError(f"--{name.replace('_', '-')} must be > 0, got {value!r}")


def _query(args) -> int:
    from twin.perf.bench import query

    return _emit("query", query(open_store(args.data), repeats=args.repeats))


def _synth(args) -> int:
    from twin.perf.bench import synth_bench

    _check_positive(minutes=args.minutes)
    return _emit("synth", synth_bench(minutes=args.minutes, repeats=args.repeats))


def _map(args) -> int:
    from twin.perf.bench import map_bench

    return _emit("map", map_bench(repeats=args.repeats))


def _physics(args) -> int:
    from twin.perf.bench import physics_bench

    return _emit("physics", physics_bench(steps=args.steps, repeats=args.repeats))


def _traffic(args) -> int:
    from twin.perf.bench import traffic_bench

    _check_positive(vehicles=args.vehicles, steps=args.steps)
    return _emit(
        "traffic",
        traffic_bench(vehicles=args.vehicles, steps=args.steps, repeats=args.repeats),
    )


def _run(args) -> int:
    from twin.perf.bench import run_bench

    store = open_store(args.data)
    return _emit("run", run_bench(store, scenario=args.scenario, repeats=args.repeats))


def _camera(args) -> int:
    from twin.perf.bench import camera_bench

    _check_positive(frames=args.frames)
    return _emit(
        "camera",
        camera_bench(
            None if args.no_replay else open_store(args.data),
            renderer=args.renderer,
            frames=args.frames,
            repeats=args.repeats,
            replay=not args.no_replay,
        ),
    )


def _dataset(args) -> int:
    from twin.perf.bench import dataset_bench

    workers = worker_counts(args.workers)
    return _emit(
        "dataset",
        dataset_bench(
            _store_or_none(args.data),
            episodes=args.episodes,
            frames=args.frames,
            workers=workers,
            repeats=args.repeats,
        ),
    )


def _env(args) -> int:
    from twin.perf.bench import env_bench

    if args.steps < 1 or args.repeats < 1 or (args.workers is not None and args.workers < 1):
        raise UsageError("--steps, --repeats and --workers must be >= 1")
    data = checked_data(args.data)
    return _emit(
        "env",
        env_bench(
            data,
            steps=args.steps,
            workers=args.workers,
            repeats=args.repeats,
            world=args.world or "physics",
        ),
    )


def _worlds(args) -> int:
    from twin.cli.evaluate import eval_config
    from twin.perf.worlds import worlds_bench

    store = open_data(args.data, progress=not args.quiet)
    figures = worlds_bench(
        store,
        args.out,
        eval_config(args, store),
        workers=workers_or_cores(args.workers),
        progress=not args.quiet,
    )
    return _emit("worlds", figures)


def _eval(args) -> int:
    from twin.perf.bench import eval_bench

    return _emit(
        "eval",
        eval_bench(
            _store_or_none(args.data),
            episodes=args.episodes,
            duration=args.duration,
            behaviours=listed(args.behaviour),
            workers=worker_counts(args.workers),
            repeats=args.repeats,
        ),
    )


def _calibrate(args) -> int:
    from twin.perf.bench import calibrate_bench

    road = checked_road(args.road)
    return _emit(
        "calibrate", calibrate_bench(_store_or_none(args.data), road=road, repeats=args.repeats)
    )


def _ingest(args) -> int:
    from twin.perf.bench import ingest_bench

    _check_positive(size_mb=args.size_mb)
    return _emit("ingest", ingest_bench(size_mb=args.size_mb, repeats=args.repeats))
