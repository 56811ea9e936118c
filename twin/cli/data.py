"""``twin data``: I-24 MOTION data: ingest, inspect, synthesize, plot, waves."""

from dataclasses import replace
from pathlib import Path

from twin.cli.options import (
    UsageError,
    add_car_following,
    add_quiet,
    add_start,
    add_store,
    add_workers,
    at_least_one,
    check_seed,
    checked_road,
    open_store,
    unix_time,
)

WINDOW_START_HELP = "unix or ISO 8601 with offset (default: data start)"


def register(commands) -> None:
    """Add ``data`` and its commands to the subparsers ``commands``."""
    data = commands.add_parser("data", help="I-24 MOTION data: ingest, inspect, synthesize, plot")
    data_commands = data.add_subparsers(title="data commands")
    _register_ingest(data_commands)
    _register_info(data_commands)
    _register_synth(data_commands)
    _register_sumo(data_commands)
    _register_plot(data_commands)
    _register_waves(data_commands)


def _register_ingest(commands) -> None:
    p = commands.add_parser("ingest", help="ingest I-24 MOTION day files (JSON) into a store")
    p.add_argument(
        "files", nargs="+", type=Path, help="day files: JSON arrays of trajectory documents"
    )
    p.add_argument(
        "--out", required=True, type=Path, help="store folder to write (replaced atomically)"
    )
    p.add_argument(
        "--margin",
        type=float,
        default=None,
        help="kept beyond each end of the segment [m] (>= 400; default: all)",
    )
    p.add_argument("--bucket", type=float, default=60.0, help="time per Parquet row group [s]")
    add_quiet(p)
    p.set_defaults(handler=_ingest)


def _ingest(args) -> int:
    from twin.data.ingest import IngestOptions, ingest
    from twin.data.store import TrajectoryStore

    for path in args.files:
        if not path.is_file():
            raise UsageError(f"input file not found: {path}")
    try:
        options = IngestOptions(margin=args.margin, bucket=args.bucket)
    except ValueError as error:  # IngestOptions names the bad --margin or --bucket
        raise UsageError(str(error)) from None
    ingest(args.files, args.out, options, progress=not args.quiet)
    print(TrajectoryStore(args.out).describe())
    return 0


def _register_info(commands) -> None:
    p = commands.add_parser("info", help="what a store holds")
    add_store(p)
    p.set_defaults(handler=_info)


def _info(args) -> int:
    from twin.calibration.calibrate import describe_calibration, read_calibration
    from twin.data.embedded import EMBEDDED, EMBEDDED_PREFIX, embedded_folder
    from twin.data.store import is_store

    store = open_store(args.store)
    store.verify()
    print(store.describe())
    print(describe_calibration(read_calibration(store)))
    if args.store is None:
        print("embedded data (STORE or --data):")
        for name, (_, presets) in EMBEDDED.items():
            built = "built" if is_store(embedded_folder(name)) else "built on first use"
            print(
                f"  {EMBEDDED_PREFIX}{name}: synthetic preset{'s' * (len(presets) > 1)} "
                f"{', '.join(presets)} ({built})"
            )
    return 0


def _register_synth(commands) -> None:
    p = commands.add_parser("synth", help="write a synthetic I-24 MOTION day (JSON)")
    p.add_argument(
        "--preset",
        choices=["A", "B", "C", "S", "D", "E"],
        required=True,
        help="A: eastbound light traffic; B: westbound, a wave in the HOV lane; C: a "
        "westbound morning with waves like the real ones (twin data waves); S (test "
        "data): westbound, 20 minutes of stop-and-go in three lanes started by drivers "
        "braking, HOV lane closed; D (test data): C's morning with lanes -3 and -4 "
        "ending 300 m past the segment (drivers leave them inside it); E (test data): "
        "C's morning with the Old Hickory on-ramp merging into lane -4 by MM 61.51",
    )
    p.add_argument(
        "--drivers",
        choices=["default", "other"],
        default="default",
        help="other: drivers and lane changing unlike the twin's defaults (test data)",
    )
    add_car_following(
        p,
        "--car-following",
        "idm-textbook",
        "the drivers' model: %(choices)s (idm-textbook: IDM as published, the presets'; "
        "idm: the twin's drivers; gipps: one the twin's defaults do not drive with)",
    )
    for flag, unit in (
        ("--politeness", "-"),
        ("--change-threshold", "m/s^2"),
        ("--decision-interval", "s"),
    ):
        p.add_argument(
            flag,
            type=float,
            default=None,
            help=f"the drivers' MOBIL {flag[2:].replace('-', ' ')} [{unit}] (default: "
            "the preset's, or --drivers other's)",
        )
    p.add_argument("--out", required=True, type=Path, help="JSON file to write")
    p.add_argument(
        "--minutes", type=float, default=None,
        help="time recorded [min] (default: the preset's: 16 for A and B, 20 for S, 30 for C, D "
        "and E)",
    )  # fmt: skip
    add_start(
        p,
        "first recorded time, unix or ISO 8601 with offset (default: the preset's, CST "
        "2022-11-30 06:39:30 for A and B, 06:35:50 for the others)",
    )
    p.add_argument("--seed", type=int, default=0, help="random seed of the drivers and demand")
    add_quiet(p)
    p.set_defaults(handler=_synth)


def _synth(args) -> int:
    from twin.data import synth

    config = _synth_config(args)
    result = synth.synthesize(config, progress=not args.quiet)
    path = synth.write_i24_json(result, args.out, progress=not args.quiet)
    print(
        f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB): {len(result.vid):,} trajectories, "
        f"{result.lane_changes:,} lane changes, {config.road.value}"
    )
    return 0


def _synth_config(args):
    """The preset with the command line's changes.

    Raises:
        UsageError: a value the synthesiser cannot take (the message names it).
    """
    from twin.data import synth

    check_seed(args.seed)
    changes = {"seed": args.seed, "car_following": args.car_following}
    if args.drivers == "other":
        changes.update(drivers=synth.OTHER_DRIVERS, **synth.OTHER_LANE_CHANGES)
    for name in ("politeness", "change_threshold", "decision_interval"):
        if getattr(args, name) is not None:
            changes[name] = getattr(args, name)
    return _preset(args, changes)


def _preset(args, changes: dict):
    """``--preset`` with ``changes``, ``--minutes`` and ``--start``.

    Raises:
        UsageError: a value the synthesiser cannot take (the message names it).
    """
    from twin.data import synth

    if args.minutes is not None:
        changes["minutes"] = args.minutes
    if args.start is not None:
        changes["start"] = unix_time(args.start, "--start")
    try:
        return replace(synth.ALL_PRESETS[args.preset], **changes)
    except ValueError as error:  # SynthConfig names the value it cannot take
        raise UsageError(str(error)) from None


def _register_sumo(commands) -> None:
    p = commands.add_parser(
        "sumo",
        help="write I-24 MOTION days made by Eclipse SUMO's drivers (test data from another "
        "simulator): a preset's, or a family of held-out days",
        description="Drive a synthesiser preset's road (its lane drop, on-ramp, bottleneck) and "
        "demand with SUMO's own drivers (Krauss, LC2013) and write what the cameras see as an "
        "I-24 MOTION day file (--preset); or draw a family of N days whose SUMO drivers (Krauss, "
        "IDM or EIDM; LC2013 or SL2015; their parameters), demand and bottleneck vary within "
        "published ranges, each with its parameters beside it (--family). Needs Eclipse SUMO "
        "(pip install eclipse-sumo, in the test extra).",
    )
    which = p.add_mutually_exclusive_group(required=True)
    which.add_argument(
        "--preset",
        choices=["D", "E"],
        help="whose road and demand: D (lanes -3 and -4 ending 300 m past the segment), E "
        "(the Old Hickory on-ramp and C's bottleneck) (no default: this or --family)",
    )
    which.add_argument(
        "--family", type=at_least_one, metavar="N",
        help="draw N days, seeds --seed to --seed + N - 1 (development: 0 to 19; test: 1000 "
        "to 1019), into the folder --out; a rerun keeps the days already made (no default: "
        "this or --preset)",
    )  # fmt: skip
    p.add_argument(
        "--out", required=True, type=Path,
        help="JSON file to write (--preset), or the family's folder (--family)",
    )  # fmt: skip
    p.add_argument(
        "--minutes", type=float, default=None,
        help="time recorded [min] (default: the preset's, 30; a family's days: 12, 1 to 60)",
    )  # fmt: skip
    add_start(p, "first recorded time, unix or ISO 8601 with offset (default: the preset's)")
    p.add_argument(
        "--seed", type=int, default=0,
        help="SUMO's seed, and the tracking noise's; with --family, the first day's",
    )  # fmt: skip
    p.add_argument(
        "--lane-change-duration", type=float, default=None,
        help="how long SUMO's lane changes take [s] (default: 3; --preset only)",
    )  # fmt: skip
    p.add_argument(
        "--keep", type=Path, default=None,
        help="folder to keep SUMO's network, routes and outputs in (default: none kept; "
        "--preset only)",
    )  # fmt: skip
    add_workers(p, "days made at once, with --family (default: the cores available)")
    add_quiet(p)
    p.set_defaults(handler=_sumo)


def _sumo(args) -> int:
    if args.family is not None:
        return _sumo_family(args)
    from twin.data.sumo_day import sumo_day

    if args.workers is not None:
        raise UsageError("--workers is for --family: a preset is one day")
    check_seed(args.seed)
    config = _preset(args, {"seed": args.seed})
    duration = 3.0 if args.lane_change_duration is None else args.lane_change_duration
    if not duration > 0:
        raise UsageError(f"--lane-change-duration must be > 0 s, got {duration}")
    result = sumo_day(config, args.out, lane_change_duration=duration, keep=args.keep,
                      progress=not args.quiet)  # fmt: skip
    path = result.path
    print(
        f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB): {result.trajectories:,} "
        f"trajectories made by SUMO, {config.road.value}; SUMO: {result.departed:,} vehicles, "
        f"{result.lane_changes:,} lane changes, {result.collisions} collisions, "
        f"{result.waiting} still waiting to enter"
    )
    return 0


def _sumo_family(args) -> int:
    """``twin data sumo --family N``: one line per day as it is made, then a summary."""
    import time

    from twin.data import sumo_family

    for option, given in (("--start", args.start), ("--keep", args.keep),
                          ("--lane-change-duration", args.lane_change_duration)):  # fmt: skip
        if given is not None:
            raise UsageError(f"{option} is for --preset: a family's days set their own")
    check_seed(args.seed)
    minutes = sumo_family.MINUTES if args.minutes is None else args.minutes
    low, high = sumo_family.MINUTES_RANGE
    if not low <= minutes <= high:
        raise UsageError(f"--minutes must be {low:g} to {high:g} for a family, got {minutes:g}")
    if args.workers is not None and args.workers < 1:
        raise UsageError(f"--workers must be >= 1, got {args.workers}")
    if args.out.exists() and not args.out.is_dir():
        raise UsageError(f"--out {args.out} is a file: a family is written to a folder")
    days = []

    def show(day) -> None:
        days.append(day)
        params, sumo = day.record["params"], day.record["sumo"]
        drivers = params["drivers"]
        made = "kept (made before)" if day.seconds is None else f"{day.seconds:.0f} s"
        print(
            f"{day.path.name}: {params['geometry']}, {drivers['car_following']} + "
            f"{drivers['lane_changing']}, tau {drivers['tau']:.2f} s, load {params['load']:.2f}; "
            f"{sumo['trajectories']:,} trajectories, {sumo['lane_changes']:,} lane changes, "
            f"{sumo['collisions']} collisions, {sumo['waiting']:,} waiting ({made})",
            flush=True,
        )

    start = time.perf_counter()
    sumo_family.make_family(args.family, args.seed, args.out, minutes=minutes,
                            workers=args.workers, progress=not args.quiet,
                            on_day=show)  # fmt: skip
    kept = sum(day.seconds is None for day in days)
    print(
        f"wrote {args.family - kept} of {args.family} days (seeds {args.seed} to "
        f"{args.seed + args.family - 1}, {minutes:g} min each) to {args.out} in "
        f"{time.perf_counter() - start:.0f} s, {kept} kept from before: "
        f"{sumo_family.summary(days)}; {sumo_family.FAMILY_INDEX} indexes them"
    )
    return 0


def _register_plot(commands) -> None:
    p = commands.add_parser("plot", help="time-space diagram per lane, coloured by speed")
    add_store(p)
    p.add_argument("--road", default="westbound", help="eastbound or westbound")
    add_start(p, WINDOW_START_HELP)
    p.add_argument("--minutes", type=float, default=10.0, help="time span plotted [min]")
    p.add_argument("--out", type=Path, default=Path("timespace.png"), help="PNG file to write")
    p.set_defaults(handler=_plot)


def _plot(args) -> int:
    from twin.data.plot import time_space_plot

    road = checked_road(args.road)
    store = open_store(args.store)
    start = unix_time(args.start, "--start")
    if start is None:
        start = store.time_range(road)[0]
    out = time_space_plot(store, road, start, args.minutes, args.out)
    print(f"wrote {out}")
    return 0


def _register_waves(commands) -> None:
    p = commands.add_parser(
        "waves",
        help="stop-and-go waves per lane as the I-24 MOTION team measures them, against "
        "the real 2022-11-22 morning",
        description="The I-24 MOTION wave-analysis method (Ji et al. 2024): virtual "
        "trajectories through each lane's speed field, wave fronts and tails at 15 mph, "
        "chained into waves. Writes lane_N/wave_front_15.csv, wave_tail_15.csv, CC_15.csv "
        "(the real tables' columns and units), waves.json and waves.png, and prints each "
        "lane's figures beside the real westbound morning's.",
    )
    add_store(p)
    p.add_argument("--road", default="westbound", help="eastbound or westbound")
    add_start(p, WINDOW_START_HELP)
    p.add_argument(
        "--minutes", type=float, default=None, help="time span [min] (default: to the data's end)"
    )
    p.add_argument(
        "--out", type=Path, default=None,
        help="folder to write (replaced as a whole; no default: required unless --tables)",
    )  # fmt: skip
    p.add_argument(
        "--tables",
        type=Path,
        default=None,
        help="summarise a folder of lane_N tables instead (e.g. the I-24 MOTION team's "
        "published tables of the real 2022-11-22 morning; default: none, analyse STORE)",
    )
    p.add_argument(
        "--miles", type=float, default=None,
        help="miles the --tables cover (default: from their waves.json, else 3.85, the real ones')",
    )  # fmt: skip
    add_quiet(p)
    p.set_defaults(handler=_waves)


def _waves(args) -> int:
    from twin.data import wave_analysis as wa
    from twin.data import wave_tables as tables

    real = tables.reference()
    if args.tables is not None:
        lanes = tables.read_tables(args.tables, **({"miles": args.miles} if args.miles else {}))
        print(
            tables.format_comparison(tables.compare(tables.summary(lanes), real["lanes"]), "tables")
        )
        return 0
    if args.out is None:
        raise UsageError("twin data waves needs --out DIR (or --tables DIR to read tables)")
    road = checked_road(args.road)
    store = open_store(args.store)
    start = unix_time(args.start, "--start")
    lanes = wa.analyse_store(store, road, start, args.minutes, progress=not args.quiet)
    first = start if start is not None else store.time_range(road)[0]
    meta = {
        "store": str(store.path),
        "road": road,
        "start_unix": first,
        "minutes": args.minutes,
        "title": f"{args.store or 'the embedded data'}, {road}: waves at 15 mph",
    }
    out = tables.write_tables(lanes, args.out, meta)
    print(
        tables.format_comparison(
            tables.compare(tables.summary(lanes), real["lanes"]), store.path.name
        )
    )
    print(f"real: {real['source']}")
    print(f"wrote {out} (lane_N/*.csv, waves.json, waves.png)")
    return 0
