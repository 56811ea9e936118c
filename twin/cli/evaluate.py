"""``twin eval``: fidelity over many episodes, and the paired controller benchmark."""

from pathlib import Path

from twin.cli.options import (
    add_data,
    add_engine,
    add_quiet,
    add_set,
    add_window,
    add_workers,
    add_world,
    check_seed,
    listed,
    open_data,
    unix_time,
    workers_or_cores,
)


def register(commands) -> None:
    """Add ``eval`` to the subparsers ``commands``."""
    p = commands.add_parser(
        "eval",
        help="fidelity over many episodes, each behaviour on the same episodes",
        description="Draw episodes from the recorded traffic (congested and free cells), run "
        "each with every behaviour asked for, measure each run as 'twin run' does, and write "
        "episodes.parquet, summary.json, summary.md and fidelity.png. Finished episodes are "
        "kept: rerun the same command to resume. An episode that fails (a controller's "
        "non-finite command, a bug) is recorded as failed with its error and the 'twin run' "
        "that repeats it, the others run, and the exit status is 1; a rerun retries it.",
    )
    add_eval_options(p)
    add_world(p)
    add_engine(p)
    p.add_argument("--out", type=Path, required=True, help="evaluation folder")
    add_quiet(p)
    p.set_defaults(handler=_eval)


def add_eval_options(p) -> None:
    """The options that say what an evaluation runs (shared with ``twin bench worlds``)."""
    add_data(p)
    p.add_argument("--road", default="westbound", help="eastbound or westbound")
    p.add_argument("--episodes", type=int, required=True, help="episodes to draw")
    p.add_argument("--duration", type=float, default=120.0, help="episode length [s]")
    add_window(p, "episodes start at or after", "episodes end at or before")
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
        "default behaviour then: calibrated where the store is calibrated, else paper; "
        "default: none, the behaviours are compared)",
    )
    add_set(
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
    p.add_argument("--seed", type=int, default=0, help="seed of the episode draw and the runs")
    add_workers(p, "processes (default: the cores)")


def _eval(args) -> int:
    import sys

    from twin.runners.evaluation import evaluate, summary_lines
    from twin.runners.failures import failure_lines

    store = open_data(args.data, progress=not args.quiet)
    config = eval_config(args, store)
    if config.controllers:  # the wave-dampening benchmark: every controller paired with human
        from twin.control.benchmark import benchmark as evaluate
        from twin.control.benchmark import summary_lines
    result = evaluate(
        store,
        args.out,
        config,
        workers=workers_or_cores(args.workers),
        engine=args.engine,
        ray_address=args.ray_address,
        progress=not args.quiet,
    )
    print(summary_lines(result))
    failed = failure_lines(result.summary)
    if failed:
        print("\n".join(failed), file=sys.stderr)
        return 1
    return 0


def eval_config(args, store):
    """The :class:`~twin.runners.evaluation.EvalConfig` of the options of
    :func:`add_eval_options` over ``store``."""
    from twin.calibration.calibrate import read_calibration
    from twin.cosim.config import SCENARIO_B, override, parse_assignments
    from twin.runners.evaluation import EvalConfig

    values = parse_assignments(args.assignments)
    if getattr(args, "world", None) is not None:
        values["world"] = args.world
    cosim = override(SCENARIO_B, values, source="command line")
    check_seed(args.seed)
    controllers = listed(args.controller)
    return EvalConfig(
        road=args.road,
        episodes=args.episodes,
        duration=args.duration,
        behaviours=_behaviours(args.behaviour, controllers, read_calibration(store) is not None),
        congested_share=args.congested_share,
        t_from=unix_time(args.t_from, "--from"),
        t_until=unix_time(args.t_until, "--until"),
        seed=args.seed,
        controllers=controllers,
        av_share=args.av_share,
        cosim=cosim,
    )


def _behaviours(asked: str | None, controllers: tuple[str, ...], calibrated: bool):
    """The behaviours to run: those asked for; else with controllers the one they drive
    among (calibrated where the store is calibrated, else paper); else paper, and
    calibrated and recorded when the store is calibrated."""
    if asked is not None:
        return listed(asked)
    if controllers:
        return ("calibrated",) if calibrated else ("paper",)
    return ("paper", "calibrated", "recorded") if calibrated else ("paper",)
