"""``twin run`` (one cosimulation episode) and ``twin render`` (one camera frame)."""

import argparse
from pathlib import Path

from twin.cli.options import (
    add_config,
    add_data,
    add_quiet,
    add_set,
    add_world,
    open_data,
    unix_time,
)


def register(commands) -> None:
    """Add ``run`` and ``render`` to the subparsers ``commands``."""
    _register_run(commands)
    _register_render(commands)


def _register_run(commands) -> None:
    p = commands.add_parser(
        "run",
        help="one cosimulation episode: ego in recorded traffic; writes a run folder",
        description="Run the paper's ghost-cell cosimulation around an ego and write a run "
        "folder (config.toml, trajectories.parquet, metrics.json, timespace.png, bev.png). "
        "Settings: preset (--scenario) < --config file < flags.",
    )
    p.add_argument("--scenario", choices=["A", "B"], default=None, help="paper preset (default B)")
    add_config(p)
    add_data(p)
    p.add_argument(
        "--road", default=None, help="eastbound or westbound (default: the preset's; B westbound)"
    )
    p.add_argument(
        "--lane", type=int, default=None,
        help="desired ego lane, -1 (HOV) .. -4 (default: the preset's; B -1)",
    )  # fmt: skip
    p.add_argument(
        "--x", type=float, default=None,
        help="desired ego x [m] along travel (default: the preset's; B 700)",
    )  # fmt: skip
    p.add_argument(
        "--time", default=None,
        help="desired ego time: unix or ISO 8601 with offset (default: the preset's; "
        "2022-11-30T06:45:50-06:00)",
    )  # fmt: skip
    p.add_argument(
        "--duration", type=float, default=None, help="episode length t_max [s] (default 30)"
    )
    p.add_argument(
        "--dt", type=float, default=None, help="step [s] (default 0.01 physics, 0.1 kinematic)"
    )
    add_world(p)
    p.add_argument(
        "--seed", type=int, default=None,
        help="seed of the visible drivers' draw (default: the preset's, 0)",
    )  # fmt: skip
    p.add_argument(
        "--vel-default", type=float, default=None,
        help="default desired speed [m/s] (default 31.29, the posted 70 mph)",
    )  # fmt: skip
    p.add_argument(
        "--behaviour",
        choices=["auto", "paper", "calibrated", "recorded"],
        default=None,
        help="how the visible vehicles drive (default auto: calibrated where the store has "
        "been calibrated with 'twin calibrate', else paper)",
    )
    p.add_argument(
        "--w-visible", type=float, default=None, help="visible window each side [m] (default 150)"
    )
    p.add_argument(
        "--w-ghost", type=float, default=None, help="ghost window beyond it [m] (default 50)"
    )
    p.add_argument(
        "--ghost-smoothing",
        type=float,
        default=None,
        help="lag on ghost speeds [s] (default 0: off)",
    )
    p.add_argument(
        "--relax",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="a vehicle leaving the visible window closes in on its recording in the ghost "
        "cell before it becomes a ghost (default); --no-relax: the paper's hand-over, a jump",
    )
    p.add_argument(
        "--ego-controller",
        default=None,
        help="module:function driving the ego, or a baseline: twin.controllers:human, "
        "follower_stopper, pi_saturation or acc (parameters: --set controller.NAME.KEY=V; "
        "default: none, the traffic manager drives the ego)",
    )
    p.add_argument(
        "--bev-time", type=float, default=None,
        help="time of bev.png [s after t0] (default: half the episode)",
    )  # fmt: skip
    p.add_argument("--bev-video", action="store_true", default=None, help="also write bev.mp4")
    add_set(p, "any other setting, e.g. --set traffic.hov_share=0.2 (repeatable)")
    p.add_argument(
        "--camera",
        action="store_true",
        default=None,
        help="render the ego's cameras into <out>/cameras (settings: --set camera.KEY=V)",
    )
    p.add_argument("--out", type=Path, default=None, help="run folder (default runs/<scenario>)")
    add_quiet(p)
    p.set_defaults(handler=_run)


def _run_config(args):
    """The episode's configuration: preset (--scenario) < --config file < --set < flags."""
    from twin.cosim.config import PRESETS, SCENARIO_B, load_config, override, parse_assignments

    base = PRESETS[args.scenario] if args.scenario else None
    config = base or SCENARIO_B
    if args.config is not None:
        config = load_config(args.config, base=base)
    flags = {
        "road": args.road,
        "lane": args.lane,
        "x": args.x,
        "time": unix_time(args.time, "--time"),
        "t_max": args.duration,
        "dt": args.dt,
        "world": args.world,
        "seed": args.seed,
        "vel_default": args.vel_default,
        "behaviour": args.behaviour,
        "w_visible": args.w_visible,
        "w_ghost": args.w_ghost,
        "ghost_smoothing": args.ghost_smoothing,
        "relax": args.relax,
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
    from mapgen.build import default_map
    from twin.runners import precompile
    from twin.runners.run import run_episode, summary

    config = _run_config(args)
    out = args.out if args.out is not None else Path("runs") / config.scenario
    compiling = precompile.start(config.world)
    if compiling is not None:
        print(f"compiling the traffic core's kernels in the background, once per machine "
              f"(cached in {compiling.cache})")  # fmt: skip
    try:
        store = open_data(args.data, progress=not args.quiet)
        bundle = default_map(progress=not args.quiet)
        if compiling is not None:
            seconds = compiling.wait()
            print(f"compiled the kernels in {seconds:.1f} s" if seconds is not None else
                  f"the second process could not compile the kernels ({compiling.error}): "
                  "this run compiles what it calls itself")  # fmt: skip
    finally:
        if compiling is not None:
            compiling.stop()
    result = run_episode(config, store, out, bundle=bundle, progress=not args.quiet)
    print(summary(result))
    return 0


def _register_render(commands) -> None:
    p = commands.add_parser(
        "render",
        help="one camera frame of a scenario at a time, for a quick look",
        description="Run the cosimulation (nothing written) to --t seconds after t0 and "
        "write one frame of the ego's camera as PNG: RGB, or with --labels RGB, depth, "
        "semantic and instance side by side.",
    )
    p.add_argument("--scenario", choices=["A", "B"], default="B", help="the paper's preset")
    add_config(p)
    add_data(p)
    p.add_argument("--t", type=float, default=0.0, help="time of the frame [s after t0]")
    p.add_argument(
        "--camera", default=None,
        help="camera mount: front, rear, left, right, dashcam or one of camera.mounts "
        "(default: the rig's first, front)",
    )  # fmt: skip
    p.add_argument(
        "--renderer", choices=["auto", "tiny", "egl"], default=None,
        help="pybullet's renderer: tiny (CPU), egl (GPU, headless) or auto (EGL where it "
        "works) (default: the camera settings', auto)",
    )  # fmt: skip
    p.add_argument("--labels", action="store_true", help="add depth and segmentation panels")
    add_set(p, "any setting, e.g. --set camera.hfov_deg=60 (repeatable)")
    p.add_argument("--out", type=Path, default=Path("frame.png"), help="PNG file to write")
    p.set_defaults(handler=_render)


def _render(args) -> int:
    from sensors.preview import frame_picture, frame_vehicles
    from twin.cosim.config import PRESETS, load_config, override, parse_assignments
    from twin.runners.run import render_at

    base = PRESETS[args.scenario]
    config = load_config(args.config, base=base) if args.config is not None else base
    values = parse_assignments(args.assignments)
    if args.renderer is not None:
        values.setdefault("camera", {})["renderer"] = args.renderer
    if args.camera is not None:  # any mount, unless --set gave the rig
        values.setdefault("camera", {}).setdefault("cameras", [args.camera])
    config = override(config, values, source="command line")
    frame = render_at(config, open_data(args.data), args.t, camera=args.camera)
    out = frame_picture(frame, args.out, labels=args.labels)
    print(
        f"wrote {out}: camera {frame.camera.name} ({frame.renderer}), "
        f"{frame.sim_time:.2f} s after t0, {len(frame_vehicles(frame))} vehicles in view"
    )
    return 0
