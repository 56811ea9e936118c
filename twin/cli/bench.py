"""``twin bench``: the performance benchmarks of :mod:`twin.perf.bench`, each printing
one JSON line of figures with the options, commit, date and machine they were taken
with; ``twin bench report`` makes the benchmarks page of such lines
(:mod:`twin.perf.report`)."""

import argparse
import json
import math
from pathlib import Path

from twin.cli.evaluate import add_eval_options
from twin.cli.options import (
    UsageError,
    add_data,
    add_worker_counts,
    add_workers,
    add_world,
    at_least_one,
    check_seed,
    checked_data,
    checked_road,
    listed,
    open_data,
    open_store,
    worker_counts,
    workers_or_cores,
)

STORE_HELP = "store folder or embedded:NAME (default: the embedded data)"
#: ``args`` attributes that are not options of a benchmark.
NOT_OPTIONS = frozenset({"handler"})
#: Options whose attribute is not their flag's name (the others: ``--`` + dashed name).
FLAGS = {"t_from": "--from", "t_until": "--until", "assignments": "--set"}


def register(commands) -> None:
    """Add ``bench`` and its benchmarks to the subparsers ``commands``."""
    bench = commands.add_parser(
        "bench",
        help="benchmarks; each prints one JSON line",
        description="Performance benchmarks. Each prints one JSON line: its figures "
        "(medians of --repeats repeats), the options it ran with, the date, the commit "
        "and the machine. 'twin bench report' makes docs/benchmarks.md of such lines.",
    )
    benchmarks = bench.add_subparsers(title="benchmarks")
    _register_parts(benchmarks)
    _register_commands(benchmarks)
    _register_report(benchmarks)


def _repeats(parser, default: int) -> None:
    """``--repeats``: how often a benchmark is timed (its figures are the medians)."""
    parser.add_argument(
        "--repeats",
        type=at_least_one,
        default=default,
        help="times the measurement is repeated; figures are medians",
    )


def _register_parts(benchmarks) -> None:
    """The twin's parts and its loop: query, synth, map, physics, traffic, run, camera."""
    p = benchmarks.add_parser(
        "query", help="snapshot latency of EmpiricalTraffic on a 400 m window of scenario B"
    )
    add_data(p, STORE_HELP)
    _repeats(p, 5)
    p.set_defaults(handler=_query)
    p = benchmarks.add_parser(
        "synth", help="time to synthesise preset B (one direction) and write it as I-24 JSON"
    )
    p.add_argument(
        "--minutes",
        type=float,
        default=10.0,
        help="length of the synthetic recording [min]",
    )
    _repeats(p, 3)
    p.set_defaults(handler=_synth)
    p = benchmarks.add_parser("map", help="full map build time and triangle counts")
    _repeats(p, 5)
    p.set_defaults(handler=_map)
    p = benchmarks.add_parser("physics", help="physics step time with 100 and 200 vehicles")
    p.add_argument(
        "--steps",
        type=int,
        default=500,
        help="physics steps of 0.01 s timed per repeat",
    )
    _repeats(p, 3)
    p.set_defaults(handler=_physics)
    p = benchmarks.add_parser(
        "traffic", help="traffic manager decision step and closed loop, 100 vehicles"
    )
    p.add_argument(
        "--vehicles",
        type=int,
        default=100,
        help="vehicles in the circuit",
    )
    p.add_argument(
        "--steps",
        type=int,
        default=3000,
        help="steps of 0.01 s timed per repeat",
    )
    _repeats(p, 3)
    p.set_defaults(handler=_traffic)
    p = benchmarks.add_parser(
        "run", help="the whole cosimulation loop of a scenario (no outputs written)"
    )
    p.add_argument(
        "--scenario",
        choices=["A", "B"],
        default="B",
        help="the paper's scenario timed",
    )
    add_data(p, STORE_HELP)
    add_world(p)
    p.add_argument(
        "--duration",
        type=float,
        default=None,
        help="the episode [s] (default: the scenario's)",
    )
    p.add_argument(
        "--sumo",
        action="store_true",
        help="also run SUMO (eclipse-sumo) on the same episode exported (twin export "
        "--format sumo) and time it beside the twin's loop, start-up included",
    )
    _repeats(p, 3)
    p.set_defaults(handler=_run)
    p = benchmarks.add_parser(
        "camera", help="camera frames per second, 640x480, 100 vehicles, with and without files"
    )
    p.add_argument(
        "--renderer",
        choices=["tiny", "egl"],
        default="tiny",
        help="tiny: TinyRenderer on the CPU; egl: the EGL plugin",
    )
    p.add_argument(
        "--frames",
        type=int,
        default=30,
        help="frames timed per repeat",
    )
    _repeats(p, 3)
    add_data(p, "recording replayed around the scene (default: the embedded data)")
    p.add_argument(
        "--no-replay",
        action="store_true",
        help="without the recorded traffic around the scene (default: with it)",
    )
    p.set_defaults(handler=_camera)


def _register_commands(benchmarks) -> None:
    """The commands run at scale: dataset, env, worlds, eval, calibrate, ingest."""
    p = benchmarks.add_parser(
        "dataset", help="labelled 640x480 frames per second of twin dataset, by workers"
    )
    add_data(p, STORE_HELP)
    p.add_argument("--episodes", type=int, default=16, help="episodes per dataset")
    p.add_argument("--frames", type=int, default=20, help="frames per episode")
    add_worker_counts(p)
    _repeats(p, 3)
    p.set_defaults(handler=_dataset)
    p = benchmarks.add_parser(
        "env",
        help="env steps per second of i24twin/WaveDampening-v0, one env and a vector env; "
        "its reset; the kernels' cold compile and warm start",
    )
    add_data(p, "store folder or embedded:NAME (default: the embedded morning)", type=str)
    p.add_argument(
        "--steps",
        type=int,
        default=200,
        help="env steps of 0.1 s timed per env and repeat",
    )
    add_workers(p, "envs of the physics world's AsyncVectorEnv (default: the cores)")
    p.add_argument(
        "--num-envs",
        type=at_least_one,
        default=256,
        help="episodes of the kinematic world's batched vector env",
    )
    p.add_argument(
        "--resets",
        type=at_least_one,
        help="resets timed per repeat (default 50; a reset of the physics world builds "
        "its bodies anew, about a second on 2 cores)",
    )
    p.add_argument(
        "--profile",
        action="store_true",
        help="kinematic: also time the batched core's step phase by phase and the "
        "observation [us per episode step]",
    )
    p.add_argument(
        "--compile-times",
        action=argparse.BooleanOptionalAction,
        default=False,
        help="also time the cold compile and the warm start, each in a new process (the "
        "cold one compiles every kernel, about a minute; default: not timed)",
    )
    add_world(p)
    _repeats(p, 3)
    p.set_defaults(handler=_env)
    p = benchmarks.add_parser(
        "first-run",
        help="a new user's first twin run on a fresh cache (data, map, kernels) and a second",
        description="Time `twin run` twice in a new process with an empty cache folder, as "
        "on a fresh machine after pip install: the first builds the embedded data and the "
        "map and compiles the kernels, the second finds them cached (about a minute a "
        "repeat).",
    )
    add_world(p)
    _repeats(p, 3)
    p.set_defaults(handler=_first_run)
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
    p.add_argument("--out", type=Path, required=True, help="comparison folder (required)")
    p.add_argument("--quiet", action="store_true", help="no progress bar (default: shown)")
    p.set_defaults(handler=_worlds)
    p = benchmarks.add_parser("eval", help="wall time of twin eval, by workers")
    add_data(p, STORE_HELP)
    p.add_argument("--episodes", type=int, default=4, help="episodes evaluated")
    p.add_argument(
        "--duration",
        type=float,
        default=60.0,
        help="episode length [s]",
    )
    p.add_argument(
        "--behaviour",
        default="paper",
        help="behaviours, comma-separated",
    )
    add_worker_counts(p)
    _repeats(p, 1)
    p.set_defaults(handler=_eval)
    _register_fidelity(benchmarks)
    p = benchmarks.add_parser("calibrate", help="wall time of twin calibrate on one road")
    add_data(p, STORE_HELP)
    p.add_argument("--road", default="westbound", help="eastbound or westbound")
    _repeats(p, 3)
    p.set_defaults(handler=_calibrate)
    p = benchmarks.add_parser("ingest", help="ingest throughput and peak memory")
    p.add_argument(
        "--size-mb",
        type=float,
        default=300.0,
        help="size of the synthetic day file ingested [MB]",
    )
    _repeats(p, 3)
    p.set_defaults(handler=_ingest)


def _register_fidelity(benchmarks) -> None:
    """``twin bench fidelity``: calibrate and evaluate many days, against the targets."""
    p = benchmarks.add_parser(
        "fidelity",
        help="the twin's fidelity over many days: each calibrated on its first half and "
        "evaluated on its second, against the fidelity targets",
        description="For each day file (or folder of day files, such as a family of SUMO "
        "days made by twin data sumo --family): ingest it, calibrate its road on the "
        "recording's first half (a day "
        "that cannot be calibrated is recorded as 'not calibrated' with the reason) and "
        "evaluate the second half with the calibrated and the paper's behaviours, in the "
        "kinematic world and on the first episodes in the physics world. Writes "
        "OUT/days.parquet and days.md (one row per day and behaviour), OUT/summary.json (each "
        "figure's median and worst over the days, the targets met or not) and OUT/fidelity.png."
        " Rerun the same command to resume: a day done is not done again.",
    )
    p.add_argument(
        "--days",
        nargs="+",
        required=True,
        metavar="DAY_OR_DIR",
        help="I-24 MOTION day files (.json, .json.gz), or folders of them (their *.json "
        "less *.params.json and family.json; a day's NAME.params.json beside it is copied "
        "into its rows)",
    )
    p.add_argument(
        "--episodes", type=at_least_one, default=40, help="kinematic episodes per day (default 40)"
    )
    p.add_argument(
        "--physics-episodes",
        type=int,
        default=2,
        help="of those, how many also run in the physics world, for its collisions and "
        "stalls (default 2; 0: none)",
    )
    p.add_argument("--duration", type=float, default=120.0, help="episode length [s] (default 120)")
    p.add_argument("--road", default="westbound", help="the carriageway (default westbound)")
    p.add_argument(
        "--seed", type=int, default=0, help="seed of every day's episode draw and runs (default 0)"
    )
    p.add_argument(
        "--lane-changes",
        choices=["scenes", "twin"],
        default="scenes",
        help="how each day's calibration fits MOBIL's threshold (twin calibrate "
        "--lane-changes; default scenes)",
    )
    add_workers(p, "processes of each evaluation (default: the cores)")
    p.add_argument(
        "--out", type=Path, required=True, help="the benchmark's folder (required; resumable)"
    )
    p.add_argument("--quiet", action="store_true", help="no progress (default: shown)")
    p.set_defaults(handler=_fidelity)


def _register_report(benchmarks) -> None:
    """``twin bench report``: the benchmarks page from JSON lines."""
    from twin.perf.report import PAGE, QUICK

    names = tuple(benchmarks.choices)
    p = benchmarks.add_parser(
        "report",
        help="write docs/benchmarks.md from benchmark JSON lines (or run them first)",
        description="Make the benchmarks page (a table of every figure with its unit, the "
        "runs with their options, date and commit, and the machines) from JSON lines of "
        "twin bench. With --run, first run the named benchmarks one at a time with their "
        "default options. All lines reported are also written to --lines.",
    )
    p.add_argument(
        "files",
        nargs="*",
        metavar="JSONL",
        help="files of twin bench lines, one JSON object a line; '-' reads standard input",
    )
    p.add_argument(
        "--run",
        nargs="?",
        const=",".join(QUICK),
        default=None,
        metavar="NAMES",
        help="run these benchmarks first, comma-separated, after reading JSONL (without "
        f"NAMES: {','.join(QUICK)}; default: run none)",
    )
    p.add_argument(
        "--lines",
        dest="lines_out",
        metavar="FILE",
        type=Path,
        default=Path("docs/benchmarks.jsonl"),
        help="JSON Lines file of every line reported (default: docs/benchmarks.jsonl)",
    )
    p.add_argument(
        "--out", type=Path, default=Path(PAGE), help=f"the page written (default: {PAGE})"
    )
    p.set_defaults(handler=_report, benchmarks=names)


def _emit(name: str, figures: dict, args) -> int:
    """Print the figures of benchmark ``name`` as one JSON line, with the options of
    ``args`` it ran with and the context (commit, date, machine)."""
    from twin.perf.bench import context

    options = {
        FLAGS.get(key, "--" + key.replace("_", "-")): value
        for key, value in vars(args).items()
        if key not in NOT_OPTIONS
    }
    line = {"bench": name, **figures, "options": options, **context()}
    print(json.dumps(line, default=str))
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

    return _emit("query", query(open_store(args.data), repeats=args.repeats), args)


def _synth(args) -> int:
    from twin.perf.bench import synth_bench

    _check_positive(minutes=args.minutes)
    return _emit("synth", synth_bench(minutes=args.minutes, repeats=args.repeats), args)


def _map(args) -> int:
    from twin.perf.bench import map_bench

    return _emit("map", map_bench(repeats=args.repeats), args)


def _physics(args) -> int:
    from twin.perf.bench import physics_bench

    return _emit("physics", physics_bench(steps=args.steps, repeats=args.repeats), args)


def _traffic(args) -> int:
    from twin.perf.bench import traffic_bench

    _check_positive(vehicles=args.vehicles, steps=args.steps)
    return _emit(
        "traffic",
        traffic_bench(vehicles=args.vehicles, steps=args.steps, repeats=args.repeats),
        args,
    )


def _run(args) -> int:
    from twin.perf.bench import run_bench

    if args.duration is not None and not (math.isfinite(args.duration) and args.duration > 0):
        raise UsageError(f"--duration must be > 0 s, got {args.duration}")
    store = open_store(args.data)
    figures = run_bench(
        store, scenario=args.scenario, repeats=args.repeats, world=args.world or "physics",
        duration=args.duration, sumo=args.sumo,
    )  # fmt: skip
    return _emit("run", figures, args)


def _first_run(args) -> int:
    from twin.perf.bench import first_run_bench

    figures = first_run_bench(world=args.world or "physics", repeats=args.repeats)
    return _emit("first-run", figures, args)


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
        args,
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
        args,
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
            num_envs=args.num_envs,
            resets=args.resets,
            compile_times=args.compile_times,
            profile=args.profile,
        ),
        args,
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
    return _emit("worlds", figures, args)


def _fidelity(args) -> int:
    from twin.perf.bench import fidelity_bench
    from twin.perf.fidelity import FidelitySettings

    check_seed(args.seed)
    settings = FidelitySettings(
        episodes=args.episodes,
        physics_episodes=args.physics_episodes,
        duration=args.duration,
        seed=args.seed,
        road=args.road,
        lane_changes=args.lane_changes,
    )
    figures = fidelity_bench(
        args.days,
        args.out,
        settings,
        workers=workers_or_cores(args.workers),
        progress=not args.quiet,
    )
    return _emit("fidelity", figures, args)


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
        args,
    )


def _calibrate(args) -> int:
    from twin.perf.bench import calibrate_bench

    road = checked_road(args.road)
    return _emit(
        "calibrate",
        calibrate_bench(_store_or_none(args.data), road=road, repeats=args.repeats),
        args,
    )


def _ingest(args) -> int:
    from twin.perf.bench import ingest_bench

    _check_positive(size_mb=args.size_mb)
    return _emit("ingest", ingest_bench(size_mb=args.size_mb, repeats=args.repeats), args)


def _report(args) -> int:
    from twin.perf.report import (
        read_lines,
        replace_lines,
        run_benchmarks,
        write_lines,
        write_page,
    )

    names = listed(args.run)
    if not args.files and not names:
        raise UsageError("give JSONL files of twin bench lines, or --run to run benchmarks")
    unknown = [name for name in names if name not in args.benchmarks]
    if unknown:
        raise UsageError(
            f"--run: no benchmark {', '.join(unknown)}; choose from {', '.join(args.benchmarks)}"
        )
    if args.files:
        lines = read_lines(args.files)
    else:  # refresh some benchmarks of the kept lines, keeping the others
        lines = read_lines([args.lines_out]) if Path(args.lines_out).is_file() else []
    lines = replace_lines(lines, run_benchmarks(names))
    write_lines(lines, args.lines_out)
    write_page(lines, args.out, lines_path=str(args.lines_out))
    print(f"{args.out}: {len(lines)} benchmark lines (kept in {args.lines_out})")
    return 0
