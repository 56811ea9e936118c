"""``twin export``: a run for other simulators (SUMO)."""

from pathlib import Path


def register(commands) -> None:
    """Add ``export`` to the subparsers ``commands``."""
    p = commands.add_parser(
        "export",
        help="a run for other simulators: SUMO (network, routes of its recorded vehicles, "
        "the twin's trajectories as FCD, a sumocfg)",
    )
    p.add_argument("run", type=Path, help="a run folder (twin run --out)")
    p.add_argument(
        "--format", choices=["sumo"], default="sumo",
        help="sumo: a network, routes, FCD trajectories and a sumocfg for Eclipse SUMO",
    )  # fmt: skip
    p.add_argument("--out", type=Path, required=True, help="folder to write")
    p.set_defaults(handler=_export)


def _export(args) -> int:
    from mapgen.build import default_map
    from twin.export.sumo import export_run

    done = export_run(args.run, args.out, default_map(progress=False))
    print(
        f"wrote {done['folder']}: {done['vehicles']} vehicles in routes.rou.xml, "
        f"{done['fcd_samples']:,} FCD samples, {done['duration_s']:g} s "
        f"(run it: sumo -c {Path(done['folder']) / 'i24.sumocfg'})"
    )
    return 0
