"""``twin export``: a run for other simulators (SUMO, OpenSCENARIO players)."""

from pathlib import Path

from twin.cli.options import DATA_HELP, add_data, positive_float

FORMATS = ("sumo", "openscenario")


def register(commands) -> None:
    """Add ``export`` to the subparsers ``commands``."""
    p = commands.add_parser(
        "export",
        help="a run for other simulators: SUMO (network, routes, the twin's trajectories as "
        "FCD, a sumocfg) or ASAM OpenSCENARIO 1.0 (CARLA ScenarioRunner, esmini)",
    )
    p.add_argument("run", type=Path, help="a run folder (twin run --out)")
    p.add_argument(
        "--format", choices=FORMATS, default="sumo",
        help="sumo: a network, routes, FCD trajectories and a sumocfg for Eclipse SUMO; "
        "openscenario: i24.xosc (every vehicle following its timed trajectory) and i24.xodr",
    )  # fmt: skip
    p.add_argument("--out", type=Path, required=True, help="folder to write")
    scenario = p.add_argument_group("openscenario only")
    scenario.add_argument(
        "--trajectories", choices=["simulated", "recorded"], default=None,
        help="simulated: the run's (the twin's for the ego and visible vehicles, the "
        "recording for ghosts); recorded: every vehicle as I-24 MOTION recorded it "
        "(default: simulated)",
    )  # fmt: skip
    scenario.add_argument(
        "--ego", choices=["trajectory", "external"], default=None,
        help="trajectory: the ego follows its trajectory; external: it starts as the run's "
        "ego did and is left to your controller (default: trajectory)",
    )  # fmt: skip
    scenario.add_argument(
        "--late-vehicles", choices=["add", "omit"], default=None,
        help="add: vehicles that enter the map after time 0 are added when they appear "
        "(esmini); omit: only the vehicles on the map at time 0, which CARLA ScenarioRunner "
        "can load (default: add)",
    )  # fmt: skip
    scenario.add_argument(
        "--rate", type=positive_float, default=None, metavar="HZ",
        help="trajectory vertices per second [Hz], each a row of the source (default: 10)",
    )  # fmt: skip
    scenario.add_argument(
        "--osc-version", choices=["1.0", "1.1", "1.2", "1.3"], default=None,
        help="the OpenSCENARIO version to write; CARLA ScenarioRunner reads only 1.0 "
        "(default: 1.0)",
    )  # fmt: skip
    add_data(scenario, help=f"with --trajectories recorded, the data the run was made from: "
             f"{DATA_HELP}")  # fmt: skip
    p.set_defaults(handler=_export)


def _export(args) -> int:
    from mapgen.build import default_map
    from twin.export.episode import ExportError

    scenario_only = {"--trajectories": args.trajectories, "--ego": args.ego,
                     "--rate": args.rate, "--osc-version": args.osc_version,
                     "--late-vehicles": args.late_vehicles,
                     "--data": args.data}  # fmt: skip
    if args.format == "sumo":
        given = [name for name, value in scenario_only.items() if value is not None]
        if given:
            raise ExportError(f"{', '.join(given)}: only for --format openscenario")
        from twin.export.sumo import export_run

        done = export_run(args.run, args.out, default_map(progress=False))
        print(
            f"wrote {done['folder']}: {done['vehicles']} vehicles in routes.rou.xml, "
            f"{done['fcd_samples']:,} FCD samples, {done['duration_s']:g} s "
            f"(run it: sumo -c {Path(done['folder']) / 'i24.sumocfg'})"
        )
        return 0
    from twin.export import openscenario

    if args.data is not None and args.trajectories != "recorded":
        raise ExportError("--data: only read with --trajectories recorded")
    done = openscenario.export_openscenario(
        args.run, args.out, default_map(progress=False),
        trajectories=args.trajectories or "simulated", ego=args.ego or "trajectory",
        rate=args.rate or openscenario.DEFAULT_RATE, data=args.data,
        minor=int((args.osc_version or "1.0").split(".")[1]),
        late=args.late_vehicles or "add",
    )  # fmt: skip
    folder = Path(done["folder"])
    print(
        f"wrote {folder}: {done['vehicles']} of the run's {done['of_vehicles']} vehicles, "
        f"{done['vertices']:,} trajectory vertices "
        f"({done['trajectories']}), {done['duration_s']:g} s, the ego "
        f"{'left to an external controller' if done['ego'] == 'external' else 'on its trajectory'}"
        f"\n  {folder / openscenario.SCENARIO}  the episode (OpenSCENARIO 1.{done['minor']})"
        f"\n  {folder / openscenario.NETWORK}  the road it names (OpenDRIVE 1.6)"
        f"\n(play it: esmini --window 60 60 800 400 --osc {folder / openscenario.SCENARIO})"
    )
    return 0
