"""The MOBIL threshold fitted through the twin itself: episodes of the calibration's
window run in the batched core, the threshold moved until the visible traffic starts
as many lane changes as the recording makes there.

The calibration's own threshold (:func:`twin.calibration.lane_changes.fit_threshold`)
is fitted on the recorded scenes: the drivers of the recording, judged still, once a
second, by the rule the twin drives. A scene judged still is not the twin's traffic:
the twin's drivers keep their own gaps, and once one has changed lanes its gain is
gone. On SUMO's on-ramp morning the scenes' threshold (2.89 m/s^2) left the calibrated
twin making 14 lane changes where the recording made 72 (0.19 of them). So
:func:`fit_in_twin` takes the scenes' threshold as its start and fits it through the
twin's own episodes in the kinematic world (the same episodes at every threshold:
common random numbers, so the count falls with the threshold without noise between
trials): the lowest threshold at which the episodes' simulated lane changes are no
more than the recorded ones inside their moving visible windows (what ``twin eval``
compares: ``lane_changes_simulated`` against ``lane_changes_recorded``).

Only the calibration's window is run (its episodes start and end inside it), so a
held-out window stays held out. Where the window has no recorded lane change, or too
few episodes can be placed, the scenes' threshold is kept and the reason written.
"""

from dataclasses import replace

from twin.core.errors import TwinError
from twin.core.progress import progress_bar

#: Threshold bounds [m/s^2] the fit searches between (the scenes' fit's range)
LOW, HIGH = 0.0, 8.0
#: Bisection rounds: 8.0 / 2^9 = 0.016 m/s^2 at the end
ROUNDS = 9
#: Fewer recorded lane changes than this in the episodes' windows: too few to fit on
MIN_RECORDED = 5


def fit_in_twin(
    store, bundle, road, window: tuple[float, float], *, episodes: int = 20,
    duration: float = 120.0, seed: int = 0, progress: bool = False,
) -> dict:  # fmt: skip
    """The calibrated behaviour's MOBIL threshold [m/s^2] at which ``episodes``
    kinematic episodes of ``duration`` [s] inside ``window`` (unix [s]) of ``store``'s
    ``road`` (its calibration's other settings as they are) start as many lane changes
    as the recording makes in their visible windows (module doc).

    Returns:
        ``{"threshold", "scenes_threshold", "recorded", "simulated", "episodes",
        "trials": [[threshold, simulated], ...]}``, or, where it cannot fit,
        ``{"threshold": the scenes', "note": why}``.
    """
    shared, cosims = _episodes(store, bundle, road, window, episodes, duration, seed)
    start = shared.behaviour.threshold
    if start is None:
        raise TwinError(f"{road}: the calibration has no MOBIL threshold to start from")

    def run(threshold: float, measured: bool):
        """(simulated lane changes, recorded ones or None) of the episodes."""
        simulated, recorded, placed, _ = _run(shared, cosims, store, threshold, measured)
        return simulated, recorded, placed

    bar = progress_bar(total=ROUNDS + 1, desc=f"lane changes through the twin ({road})",
                       unit="trial", progress=progress)  # fmt: skip
    with bar:
        simulated, recorded, placed = run(start, measured=True)
        bar.update(1)
        trials = [[round(start, 4), simulated]]
        if recorded < MIN_RECORDED or placed < max(2, episodes // 2):
            return {
                "threshold": start,
                "note": f"kept the scenes' threshold: {recorded} recorded lane changes in "
                f"{placed} episodes placed of {len(cosims)} (need {MIN_RECORDED} and half "
                "the episodes)",
            }
        lo, hi = LOW, HIGH  # simulated(lo) > recorded >= simulated(hi), found by bisection
        counts = {start: simulated}
        if simulated > recorded:
            lo = start
        else:
            hi = start
        for _ in range(ROUNDS):
            mid = 0.5 * (lo + hi)
            counts[mid] = run(mid, measured=False)[0]
            trials.append([round(mid, 4), counts[mid]])
            bar.update(1)
            if counts[mid] > recorded:
                lo = mid
            else:
                hi = mid
    # the nearer of the bracket's ends to the recorded count
    if hi not in counts:
        counts[hi] = run(hi, measured=False)[0]
        trials.append([round(hi, 4), counts[hi]])
    best = min((k for k in (lo, hi) if k in counts), key=lambda k: abs(counts[k] - recorded))
    return {
        "threshold": round(best, 4),
        "scenes_threshold": round(start, 4),
        "recorded": recorded,
        "simulated": counts[best],
        "episodes": placed,
        "trials": trials,
        "criterion": "the threshold whose kinematic episodes of the window start the "
        "number of lane changes nearest the recorded ones in their visible windows "
        f"(bisection between {LOW} and {HIGH} m/s^2, {ROUNDS} rounds)",
    }


def refit_store(store, bundle, *, episodes: int = 20, duration: float = 120.0, seed: int = 0,
                progress: bool = False) -> dict:  # fmt: skip
    """Fit every calibrated road's MOBIL threshold of ``store``'s calibration through
    the twin (:func:`fit_in_twin`, on each road's calibration window) and write it into
    its ``calibration.json`` (atomically): the road's ``mobil.threshold`` becomes the
    fitted one, ``mobil.scenes_threshold`` keeps the scenes' and ``mobil.twin_fit`` the
    fit's trials. Returns the document written.

    Raises:
        TwinError: the store has no calibration.
    """
    import json

    from twin.calibration.calibrate import CALIBRATION, read_calibration
    from twin.core.atomic import atomic_file

    doc = read_calibration(store)
    if doc is None:
        raise TwinError(f"{store.path} has no calibration to refit (run 'twin calibrate')")
    for road, section in doc["roads"].items():
        mobil = section.get("mobil")
        if not mobil or "not_calibrated" in section.get("car_following", {}):
            continue
        window = (section["window"]["from"], section["window"]["until"])
        fit = fit_in_twin(store, bundle, road, window, episodes=episodes, duration=duration,
                          seed=seed, progress=progress)  # fmt: skip
        mobil["scenes_threshold"] = mobil.get("scenes_threshold", mobil["threshold"])
        mobil["threshold"] = fit.pop("threshold")
        mobil["twin_fit"] = fit
    with atomic_file(store.path / CALIBRATION) as tmp:
        tmp.write_text(json.dumps(doc, indent=1, allow_nan=False) + "\n")
    return doc


def _episodes(store, bundle, road, window, episodes, duration, seed):
    """The calibrated behaviour's shared setting and ``episodes`` kinematic episodes'
    cosimulations of ``duration`` [s] inside ``window`` of ``road``."""
    from twin.cosim.config import SCENARIO_B, switch_world
    from twin.cosim.core.batch import Shared
    from twin.data.empirical import EmpiricalTraffic
    from twin.runners.evaluation import EvalConfig, draw_specs, episode_cosim

    config = EvalConfig(
        road=road, episodes=episodes, duration=duration, behaviours=("calibrated",),
        t_from=window[0], t_until=window[1], seed=seed,
        cosim=switch_world(SCENARIO_B, "kinematic"),
    )  # fmt: skip
    cosims = [
        episode_cosim(config, spec, "calibrated") for spec in draw_specs(config, store, bundle)
    ]
    shared = Shared.make(store, bundle, cosims[0], traffic=EmpiricalTraffic(store))
    return shared, cosims


def _run(shared, cosims, store, threshold, measured: bool):
    """Run the episodes with MOBIL's ``threshold`` in one batch: (lane changes the
    simulated vehicles started, the recorded ones in the visible windows or None, the
    episodes placed, their ``lane_flows`` summed or None); the recorded ones and the
    flows only where ``measured``."""
    from twin.cosim.core.batch import Batch
    from twin.cosim.core.step import step_batch
    from twin.cosim.cosimulator import Finished, StepTimes
    from twin.metrics import lane_flow_fidelity
    from twin.metrics.measure import measure
    from twin.runners.episodes import PLACEMENT_ERRORS

    arrays = shared.behaviour_arrays._replace(threshold=float(threshold))
    batch = Batch(replace(shared, behaviour_arrays=arrays), len(cosims), log=measured)
    placed = []
    for b, cosim in enumerate(cosims):
        try:
            batch.reset(b, lane=cosim.lane, x=cosim.x, time=cosim.time, seed=cosim.seed)
            placed.append(b)
        except PLACEMENT_ERRORS:
            continue
    while not batch.done.all():
        step_batch(batch.core)
    batch.check_all()
    simulated = sum(int(batch.state.counters.lane_changes[b]) for b in placed)
    if not measured:
        return simulated, None, len(placed), None
    recorded, sections = 0, []
    for b in placed:
        times = StepTimes(steps=int(batch.state.episodes.step[b]), total=0.0, physics=0.0)
        figures, _ = measure(Finished(shared, batch, b, cosims[b], times), store, 0.0, 0.0)
        recorded += int(figures["counts"]["lane_changes_recorded_in_window"])
        sections.append(figures.get("lane_flows"))
    return simulated, recorded, len(placed), lane_flow_fidelity.sum_episodes(sections)


def check_in_twin(
    store, bundle, road, window: tuple[float, float], *, episodes: int = 20,
    duration: float = 120.0, seed: int = 0,
) -> dict:  # fmt: skip
    """The calibrated twin's lane changes against the recording's on its own
    calibration window: ``episodes`` kinematic episodes of ``duration`` [s] inside
    ``window`` (unix [s]) of ``store``'s ``road``, run as calibrated, their lane changes
    (held ones, :mod:`twin.metrics.lane_flow_fidelity`) counted simulated and recorded
    in their visible windows, out of each lane and in each zone
    (:mod:`twin.metrics.lane_change_zones`).

    Returns:
        ``{"episodes", "simulated", "recorded", "by_lane": {lane: {"simulated",
        "recorded"}}, "by_zone": {zone: {"simulated", "recorded", "ratio"}}, "zones"}``,
        or ``{"note": why}`` where no episode could be placed.
    """
    from twin.metrics.day_fidelity import lane_changes_by_lane
    from twin.metrics.lane_change_zones import by_zone, store_zones
    from twin.metrics.lane_flow_fidelity import LANES
    from twin.runners.episodes import SamplingError

    try:
        shared, cosims = _episodes(store, bundle, road, window, episodes, duration, seed)
    except SamplingError as error:
        return {"note": f"no episode to check in the window: {error}"}
    if shared.behaviour.threshold is None:
        raise TwinError(f"{road}: the calibration has no MOBIL threshold to check")
    _, _, placed, flows = _run(shared, cosims, store, shared.behaviour.threshold, True)
    if not placed or flows is None:
        return {"note": f"no episode could be placed of {len(cosims)} drawn"}
    lanes = lane_changes_by_lane(flows)
    zones = store_zones(store, road)
    return {
        "episodes": placed,
        "simulated": flows["changes_simulated"],
        "recorded": flows["changes_recorded"],
        "by_lane": {
            str(lane): {
                "simulated": int(lanes[f"lane_changes_out_of_lane_{lane}_simulated"]),
                "recorded": int(lanes[f"lane_changes_out_of_lane_{lane}_recorded"]),
            }
            for lane in LANES
        },
        "by_zone": by_zone(flows["changes"], zones),
        "zones": zones.to_dict(),
    }


def check_store(store, bundle, *, episodes: int = 20, duration: float = 120.0, seed: int = 0,
                progress: bool = False) -> dict:  # fmt: skip
    """:func:`check_in_twin` on every calibrated road of ``store``'s calibration, its
    own window; each road's result written into its ``calibration.json`` section as
    ``lane_change_check`` (atomically). Returns the document written.

    Raises:
        TwinError: the store has no calibration.
    """
    import json

    from twin.calibration.calibrate import CALIBRATION, read_calibration
    from twin.core.atomic import atomic_file

    doc = read_calibration(store)
    if doc is None:
        raise TwinError(f"{store.path} has no calibration to check (run 'twin calibrate')")
    roads = [
        (road, section)
        for road, section in doc["roads"].items()
        if section.get("mobil") and "not_calibrated" not in section.get("car_following", {})
    ]
    bar = progress_bar(total=len(roads), desc="lane changes checked in the twin", unit="road",
                       progress=progress)  # fmt: skip
    with bar:
        for road, section in roads:
            window = (section["window"]["from"], section["window"]["until"])
            section["lane_change_check"] = check_in_twin(
                store, bundle, road, window, episodes=episodes, duration=duration, seed=seed
            )
            bar.update(1)
    with atomic_file(store.path / CALIBRATION) as tmp:
        tmp.write_text(json.dumps(doc, indent=1, allow_nan=False) + "\n")
    return doc
