"""``twin train``: a wave-dampening policy trained in the kinematic world
(:mod:`twin.control.train`)."""

from pathlib import Path

from twin.cli.options import (
    add_data,
    add_quiet,
    add_workers,
    check_seed,
    open_data,
    workers_or_cores,
)


def register(commands) -> None:
    """Add ``train`` to the subparsers ``commands``."""
    p = commands.add_parser(
        "train",
        help="train a wave-dampening policy (ARS, linear speed policy) in the kinematic world",
        description="Augmented Random Search of a linear speed policy on the benchmark's "
        "objective (the AV and its followers' economy against human, with penalties for "
        "collisions, time gaps over 4 s and a worse window economy), on congested episodes "
        "before the recording's middle. Writes OUT/policy.json after every iteration, "
        "OUT/curve.csv and OUT/curve.png. Drive with it: --controller twin.rl:policy --set "
        "controller.policy.model=OUT/policy.json.",
    )
    add_data(p, "store (default: embedded:morning)")
    p.add_argument("--iterations", type=int, default=30, help="random-search iterations")
    p.add_argument("--directions", type=int, default=8, help="perturbations per iteration")
    p.add_argument("--top", type=int, default=4, help="best directions kept per iteration")
    p.add_argument("--episodes", type=int, default=4, help="training episodes per iteration")
    p.add_argument("--duration", type=float, default=120.0, help="episode length [s]")
    p.add_argument(
        "--step-size",
        type=float,
        default=0.3,
        help="ARS step size alpha (Mania et al. 2018)",
    )
    p.add_argument(
        "--noise",
        type=float,
        default=0.5,
        help="ARS exploration noise nu (times each feature's scale)",
    )
    p.add_argument(
        "--world",
        choices=["kinematic", "physics"],
        default="kinematic",
        help="the world the training episodes run in",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the perturbations and episodes")
    add_workers(p, "processes (default: the cores)")
    p.add_argument("--out", type=Path, required=True, help="training folder")
    add_quiet(p)
    p.set_defaults(handler=_train)


def _train(args) -> int:
    from twin.control.train import TrainConfig, train

    check_seed(args.seed)
    config = TrainConfig(
        iterations=args.iterations,
        directions=args.directions,
        top=args.top,
        episodes=args.episodes,
        duration=args.duration,
        step_size=args.step_size,
        noise=args.noise,
        world=args.world,
        seed=args.seed,
    )
    store = open_data(args.data or "embedded:morning", progress=not args.quiet)
    policy = train(
        store, args.out, config, workers=workers_or_cores(args.workers), progress=not args.quiet
    )
    weights = ", ".join(f"{w:.3f}" for w in policy.weights)
    print(f"policy: {args.out / 'policy.json'} (weights {weights})")
    return 0
