"""The ``twin`` command line."""

import argparse
import json
import os
import sys
from dataclasses import replace
from pathlib import Path

from twin import __version__
from twin.core.errors import TwinError

DATA_HELP = "store folder, I-24 JSON or embedded:morning (default: the embedded data)"


def main(argv: list[str] | None = None) -> int:
    parser = _parser()
    args = parser.parse_args(argv)
    if not hasattr(args, "handler"):
        parser.print_help()
        return 2
    try:
        return args.handler(args) or 0
    except (TwinError, ValueError, FileNotFoundError, KeyError) as error:
        message = error.args[0] if isinstance(error, KeyError) and error.args else error
        print(f"twin: error: {message}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("twin: interrupted; nothing partial was left behind", file=sys.stderr)
        return 130


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="twin", description="i24-twin: a physics-based digital twin of I-24 (MM 60.6-61.6)."
    )
    parser.add_argument("--version", action="version", version=f"i24-twin {__version__}")
    commands = parser.add_subparsers(title="commands")

    p = commands.add_parser(
        "run",
        help="one cosimulation episode: ego in recorded traffic; writes a run folder",
        description="Run the paper's ghost-cell cosimulation around an ego and write a run "
        "folder (config.toml, trajectories.parquet, metrics.json, timespace.png, bev.png). "
        "Settings: preset (--scenario) < --config file < flags.",
    )
    p.add_argument("--scenario", choices=["A", "B"], default=None, help="paper preset (default B)")
    p.add_argument("--config", type=Path, default=None, help="TOML configuration file")
    p.add_argument("--data", type=Path, default=None, help=DATA_HELP)
    p.add_argument("--road", default=None, help="eastbound or westbound")
    p.add_argument("--lane", type=int, default=None, help="desired ego lane, -1 (HOV) .. -4")
    p.add_argument("--x", type=float, default=None, help="desired ego x [m] along travel")
    p.add_argument("--time", default=None, help="desired ego time: unix or ISO 8601 with offset")
    p.add_argument("--duration", type=float, default=None, help="episode length t_max [s]")
    p.add_argument("--dt", type=float, default=None, help="step [s] (default 0.01)")
    p.add_argument("--seed", type=int, default=None)
    p.add_argument("--vel-default", type=float, default=None, help="default desired speed [m/s]")
    p.add_argument(
        "--behaviour",
        choices=["auto", "paper", "calibrated", "recorded"],
        default=None,
        help="how the visible vehicles drive (default auto: calibrated where the store has "
        "been calibrated with 'twin calibrate', else paper)",
    )
    p.add_argument("--w-visible", type=float, default=None, help="visible window each side [m]")
    p.add_argument("--w-ghost", type=float, default=None, help="ghost window beyond it [m]")
    p.add_argument(
        "--ghost-smoothing", type=float, default=None, help="lag on ghost speeds [s] (0: off)"
    )
    p.add_argument(
        "--ego-controller",
        default=None,
        help="module:function driving the ego, or a baseline: twin.controllers:human, "
        "follower_stopper, pi_saturation or acc (parameters: --set controller.NAME.KEY=V)",
    )
    p.add_argument("--bev-time", type=float, default=None, help="time of bev.png [s after t0]")
    p.add_argument("--bev-video", action="store_true", default=None, help="also write bev.mp4")
    _add_set(p, "any other setting, e.g. --set traffic.hov_share=0.2 (repeatable)")
    p.add_argument(
        "--camera",
        action="store_true",
        default=None,
        help="render the ego's cameras into <out>/cameras (settings: --set camera.KEY=V)",
    )
    p.add_argument("--out", type=Path, default=None, help="run folder (default runs/<scenario>)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(handler=_run)

    p = commands.add_parser(
        "render",
        help="one camera frame of a scenario at a time, for a quick look",
        description="Run the cosimulation (nothing written) to --t seconds after t0 and "
        "write one frame of the ego's camera as PNG: RGB, or with --labels RGB, depth, "
        "semantic and instance side by side.",
    )
    p.add_argument("--scenario", choices=["A", "B"], default="B", help="paper preset")
    p.add_argument("--config", type=Path, default=None, help="TOML configuration file")
    p.add_argument("--data", type=Path, default=None, help=DATA_HELP)
    p.add_argument("--t", type=float, default=0.0, help="time of the frame [s after t0]")
    p.add_argument("--camera", default=None, help="camera name (default: the rig's first)")
    p.add_argument("--renderer", choices=["auto", "tiny", "egl"], default=None)
    p.add_argument("--labels", action="store_true", help="add depth and segmentation panels")
    _add_set(p, "any setting, e.g. --set camera.hfov_deg=60 (repeatable)")
    p.add_argument("--out", type=Path, default=Path("frame.png"), help="PNG file")
    p.set_defaults(handler=_render)

    data = commands.add_parser("data", help="I-24 MOTION data: ingest, inspect, synthesize, plot")
    data_commands = data.add_subparsers(title="data commands")

    p = data_commands.add_parser("ingest", help="ingest I-24 MOTION day files (JSON) into a store")
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
        help="metres kept beyond each end of the segment (>= 400; default: all)",
    )
    p.add_argument("--bucket", type=float, default=60.0, help="seconds per Parquet row group")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(handler=_ingest)

    p = data_commands.add_parser("info", help="what a store holds")
    p.add_argument("store", nargs="?", type=Path, help="store folder (default: the embedded data)")
    p.set_defaults(handler=_info)

    p = data_commands.add_parser("synth", help="write a synthetic I-24 MOTION day (JSON)")
    p.add_argument(
        "--preset",
        choices=["A", "B", "C", "S"],
        required=True,
        help="A: eastbound light traffic; B: westbound, a wave in the HOV lane; C: a "
        "westbound morning with waves like the real ones (twin data waves); S (test "
        "data): westbound, 20 minutes of stop-and-go in three lanes started by drivers "
        "braking, HOV lane closed",
    )
    p.add_argument(
        "--drivers",
        choices=["default", "other"],
        default="default",
        help="other: drivers and lane changing unlike the twin's defaults (test data)",
    )
    p.add_argument(
        "--car-following",
        choices=["idm", "gipps"],
        default="idm",
        help="the drivers' model (gipps: one the twin does not drive with)",
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
    p.add_argument("--minutes", type=float, default=None, help="recorded minutes (default 16)")
    p.add_argument(
        "--start", default=None, help="first recorded time (unix or ISO 8601 with offset)"
    )
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(handler=_synth)

    p = data_commands.add_parser("plot", help="time-space diagram per lane, coloured by speed")
    p.add_argument("store", nargs="?", type=Path, help="store folder (default: the embedded data)")
    p.add_argument("--road", default="westbound")
    p.add_argument(
        "--start", default=None, help="unix or ISO 8601 with offset (default: data start)"
    )
    p.add_argument("--minutes", type=float, default=10.0)
    p.add_argument("--out", type=Path, default=Path("timespace.png"))
    p.set_defaults(handler=_plot)

    p = data_commands.add_parser(
        "waves",
        help="stop-and-go waves per lane as the I-24 MOTION team measures them, against "
        "the real 2022-11-22 morning",
        description="The I-24 MOTION wave-analysis method (Ji et al. 2024): virtual "
        "trajectories through each lane's speed field, wave fronts and tails at 15 mph, "
        "chained into waves. Writes lane_N/wave_front_15.csv, wave_tail_15.csv, CC_15.csv "
        "(the real tables' columns and units), waves.json and waves.png, and prints each "
        "lane's figures beside the real westbound morning's.",
    )
    p.add_argument("store", nargs="?", type=Path, help="store folder (default: the embedded data)")
    p.add_argument("--road", default="westbound")
    p.add_argument(
        "--start", default=None, help="unix or ISO 8601 with offset (default: data start)"
    )
    p.add_argument("--minutes", type=float, default=None, help="span (default: to the data's end)")
    p.add_argument("--out", type=Path, default=None, help="folder to write (replaced as a whole)")
    p.add_argument(
        "--tables",
        type=Path,
        default=None,
        help="summarise a folder of lane_N tables instead (e.g. the real ones in "
        "../shared/data/i24_waves/2022-11-22)",
    )
    p.add_argument(
        "--miles", type=float, default=None,
        help="miles the --tables cover (default: from their waves.json, else 3.85, the real ones')",
    )  # fmt: skip
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(handler=_waves)

    maps = commands.add_parser("map", help="the road map: build it, look at it")
    map_commands = maps.add_subparsers(title="map commands")
    p = map_commands.add_parser(
        "build", help="build the map (GLB, OBJ, road.json); default: into the cache"
    )
    p.add_argument(
        "--out", type=Path, default=None, help="map folder to write (default: the cache)"
    )
    p.add_argument("--seed", type=int, default=0, help="terrain seed")
    p.set_defaults(handler=_map_build)
    p = map_commands.add_parser(
        "export",
        help="the map for other tools: OpenDRIVE 1.6 (CARLA, esmini, SUMO's netconvert)",
    )
    p.add_argument("--format", choices=["opendrive"], default="opendrive")
    p.add_argument("--out", type=Path, required=True, help="file to write, e.g. i24.xodr")
    p.add_argument("--map", type=Path, default=None, help="map folder (default: the cached map)")
    p.add_argument("--seed", type=int, default=0, help="terrain seed of the cached map")
    p.set_defaults(handler=_map_export)
    p = map_commands.add_parser("preview", help="render a top view and a driver's-eye view")
    p.add_argument("--out", type=Path, default=Path("map.png"))
    p.add_argument("--map", type=Path, default=None, help="map folder (default: the cached map)")
    p.add_argument("--seed", type=int, default=0, help="terrain seed of the cached map")
    p.set_defaults(handler=_map_preview)

    p = commands.add_parser(
        "export",
        help="a run for other simulators: SUMO (network, routes of its recorded vehicles, "
        "the twin's trajectories as FCD, a sumocfg)",
    )
    p.add_argument("run", type=Path, help="a run folder (twin run --out)")
    p.add_argument("--format", choices=["sumo"], default="sumo")
    p.add_argument("--out", type=Path, required=True, help="folder to write")
    p.set_defaults(handler=_export)

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
    p.add_argument("--data", type=Path, default=None, help=DATA_HELP)
    p.add_argument("--seed", type=int, default=None, help="dataset seed (default 0)")
    p.add_argument(
        "--camera", default=None, help="cameras of the rig, comma-separated (default: front)"
    )
    p.add_argument(
        "--frames-per-episode", type=int, default=None, help="frames per camera (default 20)"
    )
    p.add_argument(
        "--workers",
        type=int,
        default=None,
        help="processes (local) or CPUs (Ray) to use (default: the cores available)",
    )
    p.add_argument("--engine", choices=["local", "ray"], default="local")
    p.add_argument("--ray-address", default=None, help="Ray cluster to join (--engine ray)")
    p.add_argument("--config", type=Path, default=None, help="dataset TOML configuration")
    _add_set(p, "any other setting, e.g. --set filters.min_height_px=25 (repeatable)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(handler=_dataset)

    p = commands.add_parser(
        "calibrate",
        help="fit the drivers to a store's recording (writes STORE/calibration.json)",
        description="Fit the visible traffic's behaviour to the recording: IDM car following "
        "per follower (replaying its recorded leader, fitted on spacing), its distribution per "
        "class group, desired speeds per lane from free flow, the lane-change rates and the "
        "MOBIL threshold that matches them. Writes calibration.json and "
        "calibration_fits.parquet into the store; the recorded data are not changed.",
    )
    p.add_argument("store", nargs="?", type=Path, help="store folder (default: the embedded data)")
    p.add_argument(
        "--road",
        action="append",
        default=None,
        help="eastbound or westbound (repeatable; default: all)",
    )
    p.add_argument(
        "--from", dest="t_from", default=None, help="start: unix or ISO 8601 with offset"
    )
    p.add_argument(
        "--until", dest="t_until", default=None, help="end: unix or ISO 8601 with offset"
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(handler=_calibrate)

    p = commands.add_parser(
        "eval",
        help="fidelity over many episodes, each behaviour on the same episodes",
        description="Draw episodes from the recorded traffic (congested and free cells), run "
        "each with every behaviour asked for, measure each run as 'twin run' does, and write "
        "episodes.parquet, summary.json, summary.md and fidelity.png. Finished episodes are "
        "kept: rerun the same command to resume.",
    )
    p.add_argument("--data", type=Path, default=None, help=DATA_HELP)
    p.add_argument("--road", default="westbound", help="eastbound or westbound")
    p.add_argument("--episodes", type=int, required=True, help="episodes to draw")
    p.add_argument("--duration", type=float, default=120.0, help="episode length [s]")
    p.add_argument("--from", dest="t_from", default=None, help="episodes start at or after")
    p.add_argument("--until", dest="t_until", default=None, help="episodes end at or before")
    p.add_argument(
        "--congested-share", type=float, default=1.0, help="share drawn from congested cells"
    )
    p.add_argument(
        "--behaviour",
        default=None,
        help="behaviours, comma-separated (default: paper, and calibrated and recorded when "
        "the store is calibrated)",
    )
    p.add_argument(
        "--controller",
        default=None,
        help="ego controllers run on every episode, comma-separated: human, follower_stopper, "
        "pi_saturation, acc or module:function (the benchmark: paired against human; "
        "default behaviour then: calibrated where the store is calibrated, else paper)",
    )
    _add_set(
        p,
        "any run setting for every episode, e.g. --set "
        "controller.follower_stopper.desired_speed=25 or --set controller.policy.model=ppo.zip "
        "(repeatable)",
    )
    p.add_argument(
        "--av-share",
        type=float,
        default=0.0,
        help="share of the visible vehicles driven by the controller as well as the ego "
        "(needs --controller; default 0: the ego alone)",
    )
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--workers", type=int, default=None, help="processes (default: the cores)")
    p.add_argument("--engine", choices=["local", "ray"], default="local")
    p.add_argument("--ray-address", default=None, help="Ray cluster to join (--engine ray)")
    p.add_argument("--out", type=Path, required=True, help="evaluation folder")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(handler=_eval)

    bench = commands.add_parser("bench", help="benchmarks; each prints one JSON line")
    bench_commands = bench.add_subparsers(title="benchmarks")
    p = bench_commands.add_parser("query", help="snapshot latency of EmpiricalTraffic")
    p.add_argument("--data", type=Path, default=None, help="store (default: the embedded data)")
    p.add_argument("--repeats", type=int, default=5)
    p.set_defaults(handler=_bench_query)
    p = bench_commands.add_parser("synth", help="time to synthesize 10 minutes of one direction")
    p.add_argument("--minutes", type=float, default=10.0)
    p.add_argument("--repeats", type=int, default=3)
    p.set_defaults(handler=_bench_synth)
    p = bench_commands.add_parser("map", help="full map build time and triangle counts")
    p.add_argument("--repeats", type=int, default=5)
    p.set_defaults(handler=_bench_map)
    p = bench_commands.add_parser("physics", help="physics step time with 100 and 200 vehicles")
    p.add_argument("--steps", type=int, default=500)
    p.add_argument("--repeats", type=int, default=3)
    p.set_defaults(handler=_bench_physics)
    p = bench_commands.add_parser(
        "traffic", help="traffic manager decision step and closed loop, 100 vehicles"
    )
    p.add_argument("--vehicles", type=int, default=100)
    p.add_argument("--steps", type=int, default=3000)
    p.add_argument("--repeats", type=int, default=3)
    p.set_defaults(handler=_bench_traffic)
    p = bench_commands.add_parser(
        "run", help="the whole cosimulation loop of scenario B (no outputs written)"
    )
    p.add_argument("--scenario", choices=["A", "B"], default="B")
    p.add_argument("--data", type=Path, default=None, help="store (default: the embedded data)")
    p.add_argument("--repeats", type=int, default=3)
    p.set_defaults(handler=_bench_run)
    p = bench_commands.add_parser(
        "camera", help="camera frames per second, 640x480, 100 vehicles, with and without files"
    )
    p.add_argument("--renderer", choices=["tiny", "egl"], default="tiny")
    p.add_argument("--frames", type=int, default=30)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument(
        "--data",
        type=Path,
        default=None,
        help="recording drawn around the scene (default: the embedded data)",
    )
    p.add_argument(
        "--no-replay", action="store_true", help="without the recorded traffic around the scene"
    )
    p.set_defaults(handler=_bench_camera)
    p = bench_commands.add_parser(
        "dataset", help="labelled 640x480 frames per second of twin dataset, by workers"
    )
    p.add_argument("--data", type=Path, default=None, help="store (default: the embedded data)")
    p.add_argument("--episodes", type=int, default=16)
    p.add_argument("--frames", type=int, default=20, help="frames per episode")
    p.add_argument(
        "--workers", default=None, help="worker counts, comma-separated (default: 1 to cores)"
    )
    p.add_argument("--repeats", type=int, default=3)
    p.set_defaults(handler=_bench_dataset)
    p = bench_commands.add_parser(
        "env", help="env steps per second of i24twin/WaveDampening-v0, one env and a vector env"
    )
    p.add_argument("--data", default=None, help="store (default: the embedded morning)")
    p.add_argument("--steps", type=int, default=200, help="steps timed per env")
    p.add_argument("--workers", type=int, default=None, help="vector env size (default: cores)")
    p.add_argument("--repeats", type=int, default=3)
    p.set_defaults(handler=_bench_env)
    p = bench_commands.add_parser("eval", help="wall time of twin eval, by workers")
    p.add_argument("--data", type=Path, default=None, help="store (default: the embedded data)")
    p.add_argument("--episodes", type=int, default=4)
    p.add_argument("--duration", type=float, default=60.0, help="episode length [s]")
    p.add_argument("--behaviour", default="paper", help="behaviours, comma-separated")
    p.add_argument(
        "--workers", default=None, help="worker counts, comma-separated (default: 1 to cores)"
    )
    p.add_argument("--repeats", type=int, default=1)
    p.set_defaults(handler=_bench_eval)
    p = bench_commands.add_parser("calibrate", help="wall time of twin calibrate on one road")
    p.add_argument("--data", type=Path, default=None, help="store (default: the embedded data)")
    p.add_argument("--road", default="westbound")
    p.add_argument("--repeats", type=int, default=3)
    p.set_defaults(handler=_bench_calibrate)
    p = bench_commands.add_parser("ingest", help="ingest throughput and peak memory")
    p.add_argument("--size-mb", type=float, default=300.0)
    p.add_argument("--repeats", type=int, default=3)
    p.set_defaults(handler=_bench_ingest)
    return parser


def _add_set(parser: argparse.ArgumentParser, help: str) -> None:
    parser.add_argument(
        "--set", dest="assignments", action="append", default=[], metavar="KEY=VALUE", help=help
    )


def _run_config(args):
    from twin.core.timeutil import parse_time
    from twin.cosim.config import PRESETS, SCENARIO_B, load_config, override, parse_assignments

    base = PRESETS[args.scenario] if args.scenario else None
    config = base or SCENARIO_B
    if args.config is not None:
        config = load_config(args.config, base=base)
    flags = {
        "road": args.road,
        "lane": args.lane,
        "x": args.x,
        "time": parse_time(args.time) if args.time is not None else None,
        "t_max": args.duration,
        "dt": args.dt,
        "seed": args.seed,
        "vel_default": args.vel_default,
        "behaviour": args.behaviour,
        "w_visible": args.w_visible,
        "w_ghost": args.w_ghost,
        "ghost_smoothing": args.ghost_smoothing,
        "ego_controller": args.ego_controller,
        "bev_time": args.bev_time,
        "bev_video": args.bev_video,
    }
    values = parse_assignments(args.assignments)
    values.update({k: v for k, v in flags.items() if v is not None})
    if args.camera:
        values.setdefault("camera", {})["enabled"] = True
    return override(config, values, source="command line")


def _run(args) -> int:
    from twin.runners.run import open_data, run_episode, summary

    config = _run_config(args)
    store = open_data(args.data, progress=not args.quiet)
    out = args.out if args.out is not None else Path("runs") / config.scenario
    result = run_episode(config, store, out, progress=not args.quiet)
    print(summary(result))
    return 0


def _render(args) -> int:
    from sensors.preview import frame_picture, frame_vehicles
    from twin.cosim.config import PRESETS, load_config, override, parse_assignments
    from twin.runners.run import open_data, render_at

    base = PRESETS[args.scenario]
    config = load_config(args.config, base=base) if args.config is not None else base
    values = parse_assignments(args.assignments)
    if args.renderer is not None:
        values.setdefault("camera", {})["renderer"] = args.renderer
    config = override(config, values, source="command line")
    frame = render_at(config, open_data(args.data), args.t, camera=args.camera)
    out = frame_picture(frame, args.out, labels=args.labels)
    print(
        f"wrote {out}: camera {frame.camera.name} ({frame.renderer}), "
        f"{frame.sim_time:.2f} s after t0, {len(frame_vehicles(frame))} vehicles in view"
    )
    return 0


def _dataset(args) -> int:
    from twin.cosim.config import ConfigError, override, parse_assignments
    from twin.runners.dataset import DatasetConfig, load_dataset_config
    from twin.runners.dataset_runner import generate, summary
    from twin.runners.run import open_data

    config = DatasetConfig()
    if args.config is not None:
        try:
            text = args.config.read_text()
        except OSError as error:
            raise ConfigError(f"cannot read {args.config}: {error.strerror}") from None
        config = load_dataset_config(text, source=str(args.config))
    flags = {"seed": args.seed, "frames_per_episode": args.frames_per_episode}
    values = {k: v for k, v in flags.items() if v is not None}
    if args.camera is not None:
        names = [name.strip() for name in args.camera.split(",") if name.strip()]
        values["cosim"] = {"camera": {"cameras": names}}
    config = override(config, values, source="command line")
    config = override(config, parse_assignments(args.assignments), source="--set")
    if args.ray_address is not None and args.engine != "ray":
        raise ConfigError("--ray-address needs --engine ray")
    workers = args.workers if args.workers is not None else len(os.sched_getaffinity(0))
    store = open_data(args.data, progress=not args.quiet)
    result = generate(
        config,
        store,
        args.out,
        args.episodes,
        workers=workers,
        engine=args.engine,
        ray_address=args.ray_address,
        progress=not args.quiet,
    )
    print(summary(result))
    return 0


def _store(path: Path | None):
    """A STORE argument: the embedded default (None), ``embedded:NAME`` or a store folder."""
    from twin.data.embedded import default_store, embedded_name, embedded_store
    from twin.data.store import TrajectoryStore

    if path is None:
        return default_store()
    if (name := embedded_name(path)) is not None:
        return embedded_store(name)
    return TrajectoryStore(path)


def _ingest(args) -> int:
    from twin.data.ingest import IngestOptions, ingest
    from twin.data.store import TrajectoryStore

    report = ingest(
        args.files,
        args.out,
        IngestOptions(margin=args.margin, bucket=args.bucket),
        progress=not args.quiet,
    )
    print(TrajectoryStore(args.out).describe())
    if report.documents_kept == 0:
        print("twin: warning: no document was kept", file=sys.stderr)
    return 0


def _info(args) -> int:
    from twin.calibration.calibrate import describe_calibration, read_calibration
    from twin.data.embedded import EMBEDDED, EMBEDDED_PREFIX, embedded_folder
    from twin.data.store import is_store

    store = _store(args.store)
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


def _eval(args) -> int:
    from twin.calibration.calibrate import read_calibration
    from twin.core.timeutil import parse_time
    from twin.cosim.config import SCENARIO_B, override, parse_assignments
    from twin.runners.evaluation import EvalConfig, evaluate, summary_lines
    from twin.runners.run import open_data

    cosim = override(SCENARIO_B, parse_assignments(args.assignments), source="--set")

    store = open_data(args.data, progress=not args.quiet)
    controllers = _listed(args.controller)
    calibrated = read_calibration(store) is not None
    if args.behaviour is not None:
        behaviours = _listed(args.behaviour)
    elif controllers:
        behaviours = ("calibrated",) if calibrated else ("paper",)
    elif calibrated:
        behaviours = ("paper", "calibrated", "recorded")
    else:
        behaviours = ("paper",)
    config = EvalConfig(
        road=args.road,
        episodes=args.episodes,
        duration=args.duration,
        behaviours=behaviours,
        congested_share=args.congested_share,
        t_from=parse_time(args.t_from) if args.t_from is not None else None,
        t_until=parse_time(args.t_until) if args.t_until is not None else None,
        seed=args.seed,
        controllers=controllers,
        av_share=args.av_share,
        cosim=cosim,
    )
    workers = args.workers if args.workers is not None else len(os.sched_getaffinity(0))
    result = evaluate(
        store,
        args.out,
        config,
        workers=workers,
        engine=args.engine,
        ray_address=args.ray_address,
        progress=not args.quiet,
    )
    print(summary_lines(result))
    return 0


def _listed(text: str | None) -> tuple[str, ...]:
    """A comma-separated option as a tuple (empty for None)."""
    return tuple(t.strip() for t in (text or "").split(",") if t.strip())


def _calibrate(args) -> int:
    from twin.calibration.calibrate import calibrate, describe_calibration, write_calibration
    from twin.core.timeutil import parse_time

    store = _store(args.store)
    t_from = parse_time(args.t_from) if args.t_from is not None else None
    t_until = parse_time(args.t_until) if args.t_until is not None else None
    if t_from is not None and t_until is not None and not t_from < t_until:
        raise TwinError(f"--from ({args.t_from}) must be before --until ({args.t_until})")
    doc, fits = calibrate(store, args.road, t_from, t_until, progress=not args.quiet)
    path = write_calibration(store, doc, fits)
    print(describe_calibration(doc))
    print(f"written: {path}")
    return 0


def _synth(args) -> int:
    from twin.core.timeutil import parse_time
    from twin.data import synth

    config = synth.ALL_PRESETS[args.preset]
    changes = {"seed": args.seed, "car_following": args.car_following}
    if args.drivers == "other":
        changes.update(drivers=synth.OTHER_DRIVERS, **synth.OTHER_LANE_CHANGES)
    for name in ("politeness", "change_threshold", "decision_interval"):
        if getattr(args, name) is not None:
            changes[name] = getattr(args, name)
    if args.minutes is not None:
        changes["minutes"] = args.minutes
    if args.start is not None:
        changes["start"] = parse_time(args.start)
    config = replace(config, **changes)
    result = synth.synthesize(config, progress=not args.quiet)
    path = synth.write_i24_json(result, args.out, progress=not args.quiet)
    print(
        f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB): {len(result.vid):,} trajectories, "
        f"{result.lane_changes:,} lane changes, {config.road.value}"
    )
    return 0


def _plot(args) -> int:
    from twin.core.timeutil import parse_time
    from twin.data.plot import time_space_plot

    store = _store(args.store)
    start = parse_time(args.start) if args.start is not None else store.time_range(args.road)[0]
    out = time_space_plot(store, args.road, start, args.minutes, args.out)
    print(f"wrote {out}")
    return 0


def _waves(args) -> int:
    from twin.core.timeutil import parse_time
    from twin.data import wave_analysis as wa

    real = wa.reference()
    if args.tables is not None:
        lanes = wa.read_tables(args.tables, **({"miles": args.miles} if args.miles else {}))
        print(wa.format_comparison(wa.compare(wa.summary(lanes), real["lanes"]), "tables"))
        return 0
    if args.out is None:
        raise TwinError("twin data waves needs --out DIR (or --tables DIR to read tables)")
    store = _store(args.store)
    start = parse_time(args.start) if args.start is not None else None
    lanes = wa.analyse_store(store, args.road, start, args.minutes, progress=not args.quiet)
    first = start if start is not None else store.time_range(args.road)[0]
    meta = {
        "store": str(store.path),
        "road": args.road,
        "start_unix": first,
        "minutes": args.minutes,
        "title": f"{store.path.name}, {args.road}: waves at 15 mph",
    }
    out = wa.write_tables(lanes, args.out, meta)
    print(wa.format_comparison(wa.compare(wa.summary(lanes), real["lanes"]), store.path.name))
    print(f"real: {real['source']}")
    print(f"wrote {out} (lane_N/*.csv, waves.json, waves.png)")
    return 0


def _map(folder: Path | None, seed: int):
    from mapgen.build import default_map, load_map

    return load_map(folder) if folder is not None else default_map(seed, progress=True)


def _map_build(args) -> int:
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
    from mapgen.build import default_map
    from twin.export.sumo import export_run

    done = export_run(args.run, args.out, default_map(progress=False))
    print(
        f"wrote {done['folder']}: {done['vehicles']} vehicles in routes.rou.xml, "
        f"{done['fcd_samples']:,} FCD samples, {done['duration_s']:g} s "
        f"(run it: sumo -c {Path(done['folder']) / 'i24.sumocfg'})"
    )
    return 0


def _map_export(args) -> int:
    from mapgen.opendrive import write_opendrive

    out = write_opendrive(_map(args.map, args.seed), args.out)
    print(f"wrote {out} (OpenDRIVE 1.6)")
    return 0


def _map_preview(args) -> int:
    from sensors.map_preview import render_preview

    print(f"wrote {render_preview(_map(args.map, args.seed), args.out)}")
    return 0


def _emit(name: str, figures: dict) -> int:
    from twin.perf.bench import context

    print(json.dumps({"bench": name, **figures, **context()}))
    return 0


def _bench_query(args) -> int:
    from twin.perf.bench import query

    return _emit("query", query(_store(args.data), repeats=args.repeats))


def _bench_synth(args) -> int:
    from twin.perf.bench import synth_bench

    return _emit("synth", synth_bench(minutes=args.minutes, repeats=args.repeats))


def _bench_map(args) -> int:
    from twin.perf.bench import map_bench

    return _emit("map", map_bench(repeats=args.repeats))


def _bench_physics(args) -> int:
    from twin.perf.bench import physics_bench

    return _emit("physics", physics_bench(steps=args.steps, repeats=args.repeats))


def _bench_traffic(args) -> int:
    from twin.perf.bench import traffic_bench

    return _emit(
        "traffic",
        traffic_bench(vehicles=args.vehicles, steps=args.steps, repeats=args.repeats),
    )


def _bench_run(args) -> int:
    from twin.perf.bench import run_bench

    store = _store(args.data)
    return _emit("run", run_bench(store, scenario=args.scenario, repeats=args.repeats))


def _bench_camera(args) -> int:
    from twin.perf.bench import camera_bench

    return _emit(
        "camera",
        camera_bench(
            None if args.no_replay else _store(args.data),
            renderer=args.renderer,
            frames=args.frames,
            repeats=args.repeats,
            replay=not args.no_replay,
        ),
    )


def _worker_counts(text: str | None):
    if text is None:
        return None
    try:
        return tuple(int(w) for w in text.split(","))
    except ValueError:
        raise ValueError(f"--workers must be integers like 1,2, got {text!r}") from None


def _bench_env(args) -> int:
    from twin.perf.bench import env_bench

    if args.steps < 1 or args.repeats < 1 or (args.workers is not None and args.workers < 1):
        raise ValueError("--steps, --repeats and --workers must be >= 1")
    return _emit(
        "env",
        env_bench(args.data, steps=args.steps, workers=args.workers, repeats=args.repeats),
    )


def _bench_eval(args) -> int:
    from twin.perf.bench import eval_bench

    return _emit(
        "eval",
        eval_bench(
            _store(args.data) if args.data is not None else None,
            episodes=args.episodes,
            duration=args.duration,
            behaviours=tuple(b.strip() for b in args.behaviour.split(",") if b.strip()),
            workers=_worker_counts(args.workers),
            repeats=args.repeats,
        ),
    )


def _bench_calibrate(args) -> int:
    from twin.perf.bench import calibrate_bench

    return _emit(
        "calibrate",
        calibrate_bench(
            _store(args.data) if args.data is not None else None,
            road=args.road,
            repeats=args.repeats,
        ),
    )


def _bench_dataset(args) -> int:
    from twin.perf.bench import dataset_bench

    workers = _worker_counts(args.workers)
    return _emit(
        "dataset",
        dataset_bench(
            _store(args.data) if args.data is not None else None,
            episodes=args.episodes,
            frames=args.frames,
            workers=workers,
            repeats=args.repeats,
        ),
    )


def _bench_ingest(args) -> int:
    from twin.perf.bench import ingest_bench

    return _emit("ingest", ingest_bench(size_mb=args.size_mb, repeats=args.repeats))
