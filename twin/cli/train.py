"""``twin train``: a wave-dampening policy trained in the kinematic world: a linear speed
policy by random search (:mod:`twin.control.train`, ``--algorithm ars``) or an MLP
speed policy by an evolution strategy on the batched vector env
(:mod:`twin.control.evolve`, ``--algorithm es``)."""

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
        help="train a wave-dampening policy in the kinematic world (ARS of a linear "
        "policy, or an evolution strategy of an MLP on the vector env)",
        description="--algorithm ars: Augmented Random Search of a linear speed policy on "
        "the benchmark's objective (the AV and its followers' economy against human, with "
        "penalties for collisions, time gaps over 4 s and a worse window economy). "
        "--algorithm es: OpenAI's evolution strategy of an MLP speed policy, every member "
        "of the population driving its own episodes of the batched vector env, on the AV "
        "and its followers' economy with penalties for collisions, short and long time "
        "gaps, short times to collision, jerk and the safety layer's time; a held-out "
        "score every few generations; resumes an interrupted training (the same command "
        "again). Both train on congested episodes before the recording's middle and write "
        "OUT/policy.json after every iteration, OUT/curve.csv and OUT/curve.png. Drive "
        "with it: --controller twin.rl:policy --set controller.policy.model=OUT/policy.json.",
    )
    p.add_argument(
        "--algorithm", choices=["ars", "es"], default="ars",
        help="ars: random search of the linear speed policy (default); es: evolution "
        "strategy of the MLP speed policy on the vector env",
    )  # fmt: skip
    add_data(p, "store (default: embedded:morning)")
    p.add_argument(
        "--also-data", action="append", default=[], metavar="STORE",
        help="es: another morning whose training split it trains on too (repeatable; a "
        "generation's episodes are dealt out over --data and these in turn; held-out scores "
        "stay on --data)",
    )  # fmt: skip
    p.add_argument("--iterations", type=int, default=30, help="ars: random-search iterations")
    p.add_argument("--directions", type=int, default=8, help="ars: perturbations per iteration")
    p.add_argument("--top", type=int, default=4, help="ars: best directions kept per iteration")
    p.add_argument(
        "--episodes", type=int, default=4,
        help="training episodes per iteration or generation (default 4)",
    )  # fmt: skip
    p.add_argument(
        "--duration", type=float, default=None,
        help="episode length [s] (default: 120 with ars, 60 with es)",
    )  # fmt: skip
    p.add_argument(
        "--step-size",
        type=float,
        default=0.3,
        help="ars: step size alpha (Mania et al. 2018)",
    )
    p.add_argument(
        "--noise",
        type=float,
        default=0.5,
        help="ars: exploration noise nu (times each feature's scale)",
    )
    p.add_argument("--generations", type=int, default=100, help="es: generations (default 100)")
    p.add_argument(
        "--population", type=int, default=32,
        help="es: antithetic pairs per generation (sub-envs: 2 x population x episodes)",
    )  # fmt: skip
    p.add_argument("--sigma", type=float, default=0.05, help="es: perturbation sd (0.05)")
    p.add_argument("--learning-rate", type=float, default=0.01, help="es: Adam's step (0.01)")
    p.add_argument(
        "--hidden", default="32,32", help="es: the MLP's hidden layers' units (default 32,32)"
    )
    p.add_argument(
        "--heldout-every", type=int, default=5, help="es: generations between held-out scores"
    )
    p.add_argument(
        "--heldout-episodes", type=int, default=16, help="es: held-out episodes (default 16)"
    )
    p.add_argument(
        "--obs-noise", type=float, default=0.0, help="es: the env's observation noise (sd)"
    )
    p.add_argument("--latency-steps", type=int, default=0, help="es: the env's observation latency")
    p.add_argument(
        "--smoothing", type=float, default=0.0,
        help="es: [s] the policy's smoothing of its observations (default 0: none)",
    )  # fmt: skip
    p.add_argument(
        "--jerk-from", choices=["measured", "command"], default="measured",
        help="es: what the policy's jerk limit counts from: its measured acceleration "
        "(default) or its own previous command",
    )  # fmt: skip
    p.add_argument(
        "--time-gap-p90-max", type=float, default=4.0,  # evolve.TIME_GAP_P90_MAX
        help="es: [s] the time gap p90 the score penalises a run over (default 4, the "
        "target; lower asks for a margin)",
    )  # fmt: skip
    p.add_argument(
        "--start", type=Path, default=None,
        help="es: a policy file whose weights the training starts from (default: none, drawn "
        "weights that follow the leader)",
    )  # fmt: skip
    p.add_argument(
        "--world",
        choices=["kinematic", "physics"],
        default="kinematic",
        help="the world the training episodes run in",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the perturbations and episodes")
    add_workers(p, "ars: processes (default: the cores)")
    p.add_argument("--out", type=Path, required=True, help="training folder")
    add_quiet(p)
    p.set_defaults(handler=_train)


def _train(args) -> int:
    from twin.control.train import TrainConfig, TrainingError, train

    check_seed(args.seed)
    if args.algorithm == "es":
        return _evolve(args)
    if args.also_data:
        raise TrainingError("--also-data trains the MLP: use it with --algorithm es")
    config = TrainConfig(
        iterations=args.iterations,
        directions=args.directions,
        top=args.top,
        episodes=args.episodes,
        duration=120.0 if args.duration is None else args.duration,
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


def _evolve(args) -> int:
    from twin.control.evolve import EvolveConfig, evolve
    from twin.control.train import TrainingError
    from twin.core.errors import DataFormatError, StoreError

    if args.world != "kinematic":
        raise TrainingError("--algorithm es trains on the vector env: the kinematic world")
    for store in args.also_data:  # a bad store is named before any training
        try:
            open_data(store, progress=False)
        except (StoreError, DataFormatError) as error:
            message = str(error).removeprefix(f"--data {Path(store)}").lstrip(": ")
            raise TrainingError(f"--also-data {store}: {message}") from None
    try:
        hidden = tuple(int(h) for h in str(args.hidden).split(","))
    except ValueError:
        raise TrainingError(f"--hidden must be units joined by commas: {args.hidden!r}") from None
    config = EvolveConfig(
        generations=args.generations, population=args.population, episodes=args.episodes,
        duration=60.0 if args.duration is None else args.duration, sigma=args.sigma,
        learning_rate=args.learning_rate, hidden=hidden, heldout_every=args.heldout_every,
        heldout_episodes=args.heldout_episodes, obs_noise=args.obs_noise,
        latency_steps=args.latency_steps, smoothing=args.smoothing, jerk_from=args.jerk_from,
        start=args.start, data=str(args.data or "embedded:morning"),
        also=tuple(args.also_data), seed=args.seed, time_gap_p90_max=args.time_gap_p90_max,
    )  # fmt: skip
    policy = evolve(args.out, config, progress=not args.quiet)
    print(
        f"policy: {args.out / 'policy.json'} (an MLP {'x'.join(map(str, policy.hidden))}, "
        f"{policy.about['env_steps']:,} env steps in {policy.about['wall_s']:.0f} s)"
    )
    return 0
