"""``twin calibrate``: fit the drivers to a store's recording."""

from twin.cli.options import (
    UsageError,
    add_car_following,
    add_quiet,
    add_store,
    add_window,
    checked_road,
    open_store,
    unix_time,
)


def register(commands) -> None:
    """Add ``calibrate`` to the subparsers ``commands``."""
    p = commands.add_parser(
        "calibrate",
        help="fit the drivers to a store's recording (writes STORE/calibration.json)",
        description="Fit the visible traffic's behaviour to the recording: car following "
        "(IDM and Gipps, the one that replays the window best kept; or --model) per "
        "follower (replaying its recorded leader, fitted on spacing), "
        "its distribution per "
        "class group, desired speeds per lane from free flow, the lane-change rates, their "
        "flows by lane pair, position and time (discretionary, or strategic: one way and "
        "unexplained by MOBIL) and the MOBIL threshold that matches the discretionary ones. "
        "Writes calibration.json and "
        "calibration_fits.parquet into the store, with a picture of its lane-change flows "
        "(lane_flows_ROAD.png); the recorded data are not changed.",
    )
    add_store(p)
    p.add_argument(
        "--road",
        action="append",
        default=None,
        help="eastbound or westbound (repeatable; default: all)",
    )
    add_window(p, "start: unix or ISO 8601 with offset", "end: unix or ISO 8601 with offset")
    add_car_following(
        p,
        "--model",
        "auto",
        "the car-following model fitted: %(choices)s (default auto: each of idm and gipps is "
        "fitted, and the one whose drivers, drawn from its fits, follow the window's "
        "recorded leaders most like its followers did is kept; runs drive the model a "
        "store's calibration fitted)",
        extra=("auto",),
    )
    p.add_argument(
        "--threshold-drivers",
        choices=("median", "drawn"),
        default="drawn",
        help="who MOBIL's threshold is fitted with: drawn, one driver per recorded vehicle "
        "drawn from the calibrated distribution, as the twin draws its drivers (default); "
        "median, one median calibrated driver for every recorded vehicle (the drivers' "
        "spread changes their incentives: on SUMO's on-ramp morning median set the twin "
        "changing lanes 5.4 times as often as the recording, drawn 1.35 times; on a "
        "stop-and-go morning of other drivers median 1.24 times, drawn 0.62)",
    )
    p.add_argument(
        "--following-from",
        metavar="CALIBRATION_JSON",
        default=None,
        help="where this window has too few accepted car-following fits (no waves to fit "
        "them on), take the drivers' car following from this calibration (the same "
        "drivers on another morning, fitted with the same --model, or with the model auto "
        "chose); the lane changes, "
        "their flows, the threshold, desired speeds and merges are still fitted here "
        "(default: none, such a road is not calibrated)",
    )
    p.add_argument(
        "--lane-changes",
        choices=["scenes", "twin"],
        default="scenes",
        help="how MOBIL's threshold is fitted: scenes, on the recorded scenes judged still "
        "by the twin's rule; twin, then through the twin's own kinematic episodes of the "
        "window, to start as many lane changes as the recording makes in them (20 "
        "episodes, about 10 s a road; default scenes)",
    )
    p.add_argument(
        "--check-episodes",
        type=int,
        default=20,
        metavar="N",
        help="once calibrated, run N kinematic episodes of each road's window in the twin "
        "and report its lane changes against the recording's, out of each lane and by "
        "zone (before a drop, the weave, elsewhere), written as lane_change_check "
        "(0: no check; default 20, a few seconds a road)",
    )
    add_quiet(p)
    p.set_defaults(handler=_calibrate)


def _calibrate(args) -> int:
    from twin.calibration.calibrate import (
        calibrate,
        describe_calibration,
        draw_lane_flows,
        write_calibration,
    )

    if args.check_episodes < 0:
        raise UsageError(f"--check-episodes must be >= 0, got {args.check_episodes}")
    roads = [checked_road(road) for road in args.road] if args.road is not None else None
    store = open_store(args.store)
    t_from, t_until = unix_time(args.t_from, "--from"), unix_time(args.t_until, "--until")
    if t_from is not None and t_until is not None and not t_from < t_until:
        raise UsageError(f"--from ({args.t_from}) must be before --until ({args.t_until})")
    from twin.calibration.model_choice import AUTO
    from twin.traffic.models import car_following_model

    model = AUTO if args.model == AUTO else car_following_model(args.model)
    from twin.calibration.calibrate import CalibrationSettings

    settings = CalibrationSettings(threshold_drivers=args.threshold_drivers)
    following = None
    if args.following_from is not None:
        from twin.calibration.calibrate import read_calibration_file

        following = read_calibration_file(args.following_from)
    doc, fits = calibrate(
        store,
        roads,
        t_from,
        t_until,
        settings,
        model=model,
        progress=not args.quiet,
        following=following,
    )
    path = write_calibration(store, doc, fits)
    if args.lane_changes == "twin":
        from mapgen.build import default_map
        from twin.runners.lane_change_fit import refit_store

        doc = refit_store(open_store(args.store), default_map(), progress=not args.quiet)
    if args.check_episodes:
        from mapgen.build import default_map
        from twin.runners.lane_change_fit import check_store

        doc = check_store(open_store(args.store), default_map(), episodes=args.check_episodes,
                          progress=not args.quiet)  # fmt: skip
    pictures = draw_lane_flows(store, doc)
    print(describe_calibration(doc))
    print(f"written: {', '.join(map(str, [path, *pictures]))}")
    print(
        f"twin run on {store.path} now drives its visible vehicles calibrated (behaviour "
        f"auto), as {doc['car_following_model']} drivers; --behaviour paper drives as the "
        "paper does"
    )
    return 0
