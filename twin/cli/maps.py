"""``twin map``: the road map: build it, export it, look at it."""

from pathlib import Path

from twin.cli.options import add_map


def register(commands) -> None:
    """Add ``map`` and its commands to the subparsers ``commands``."""
    maps = commands.add_parser("map", help="the road map: build it, look at it")
    map_commands = maps.add_subparsers(title="map commands")
    p = map_commands.add_parser(
        "build", help="build the map (GLB, OBJ, road.json); default: into the cache"
    )
    p.add_argument(
        "--out", type=Path, default=None, help="map folder to write (default: the cache)"
    )
    p.add_argument("--seed", type=int, default=0, help="terrain seed (the map's random parts)")
    p.set_defaults(handler=_build)
    p = map_commands.add_parser(
        "export",
        help="the map for other tools: OpenDRIVE 1.6 (CARLA, esmini, SUMO's netconvert)",
    )
    p.add_argument(
        "--format",
        choices=["opendrive"],
        default="opendrive",
        help="file format: ASAM OpenDRIVE 1.6",
    )
    p.add_argument("--out", type=Path, required=True, help="file to write, e.g. i24.xodr")
    add_map(p)
    p.set_defaults(handler=_export)
    p = map_commands.add_parser("preview", help="render a top view and a driver's-eye view")
    p.add_argument("--out", type=Path, default=Path("map.png"), help="PNG file to write")
    add_map(p)
    p.set_defaults(handler=_preview)


def _map(folder: Path | None, seed: int):
    """The map of ``--map`` and ``--seed``: a built folder, else the cached map."""
    from mapgen.build import default_map, load_map

    return load_map(folder) if folder is not None else default_map(seed, progress=True)


def _build(args) -> int:
    from mapgen.build import build_map, default_map
    from mapgen.opendrive import XODR, write_opendrive

    bundle = build_map(args.out, seed=args.seed) if args.out else default_map(args.seed)
    triangles = bundle.description["triangles"]
    xodr = write_opendrive(bundle, bundle.folder / XODR)
    print(
        f"map {bundle.key} (seed {args.seed}) in {bundle.folder}: "
        f"{triangles['visual']:,} visual and {triangles['collision']:,} collision triangles; "
        f"OpenDRIVE {xodr.name}"
    )
    return 0


def _export(args) -> int:
    from mapgen.opendrive import write_opendrive

    out = write_opendrive(_map(args.map, args.seed), args.out)
    print(f"wrote {out} (OpenDRIVE 1.6)")
    return 0


def _preview(args) -> int:
    from sensors.map_preview import render_preview

    print(f"wrote {render_preview(_map(args.map, args.seed), args.out)}")
    return 0
