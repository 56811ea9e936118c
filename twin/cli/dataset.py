"""``twin dataset``: labelled camera datasets (KITTI, COCO) from many episodes."""

from pathlib import Path

from twin.cli.options import (
    add_config,
    add_data,
    add_engine,
    add_quiet,
    add_set,
    add_workers,
    open_data,
    workers_or_cores,
)


def register(commands) -> None:
    """Add ``dataset`` to the subparsers ``commands``."""
    p = commands.add_parser(
        "dataset",
        help="labelled camera datasets (KITTI, COCO) from many episodes of recorded traffic",
        description="Draw episodes from the recorded traffic (congested and free flow), run "
        "each as a cosimulation with the ego's cameras, and write every frame with its labels "
        "in KITTI's object layout and as COCO instances. Complete episodes are kept: rerun the "
        "same command to resume an interrupted run. Settings: defaults < --config file < flags "
        "< --set.",
    )
    p.add_argument("--episodes", type=int, required=True, help="episodes in the dataset")
    p.add_argument("--out", type=Path, required=True, help="dataset folder")
    add_data(p)
    p.add_argument("--seed", type=int, default=None, help="dataset seed (default 0)")
    p.add_argument(
        "--camera", default=None, help="cameras of the rig, comma-separated (default: front)"
    )
    p.add_argument(
        "--frames-per-episode", type=int, default=None, help="frames per camera (default 20)"
    )
    add_workers(p, "processes (local) or CPUs (Ray) to use (default: the cores available)")
    add_engine(p)
    add_config(p, "dataset TOML configuration (default: none, the default settings)")
    add_set(p, "any other setting, e.g. --set filters.min_height_px=25 (repeatable)")
    add_quiet(p)
    p.set_defaults(handler=_dataset)


def _dataset(args) -> int:
    from twin.cosim.config import ConfigError
    from twin.runners.dataset import generate, summary

    config = _dataset_config(args)
    if args.ray_address is not None and args.engine != "ray":
        raise ConfigError("--ray-address needs --engine ray")
    store = open_data(args.data, progress=not args.quiet)
    result = generate(
        config,
        store,
        args.out,
        args.episodes,
        workers=workers_or_cores(args.workers),
        engine=args.engine,
        ray_address=args.ray_address,
        progress=not args.quiet,
    )
    print(summary(result))
    return 0


def _dataset_config(args):
    """The dataset's settings: defaults < --config file < flags < --set."""
    from twin.cosim.config import ConfigError, override, parse_assignments
    from twin.runners.dataset import DatasetConfig, load_dataset_config

    config = DatasetConfig()
    if args.config is not None:
        try:
            text = args.config.read_text()
        except OSError as error:
            raise ConfigError(f"cannot read {args.config}: {error.strerror}") from None
        except UnicodeDecodeError as error:
            raise ConfigError(
                f"{args.config} is not a TOML text file (not UTF-8: {error.reason})"
            ) from None
        config = load_dataset_config(text, source=str(args.config))
    flags = {"seed": args.seed, "frames_per_episode": args.frames_per_episode}
    values = {k: v for k, v in flags.items() if v is not None}
    if args.camera is not None:
        names = [name.strip() for name in args.camera.split(",") if name.strip()]
        values["cosim"] = {"camera": {"cameras": names}}
    config = override(config, values, source="command line")
    return override(config, parse_assignments(args.assignments), source="--set")
