"""Calibrating a store: the fits of :mod:`twin.calibration.car_following`,
:mod:`~twin.calibration.distributions` and :mod:`~twin.calibration.lane_changes`, run
over a store's recording and kept beside it.

``twin calibrate STORE`` writes these files into the store folder and changes nothing
else in it (the recorded data are never touched)::

    STORE/
      calibration.json            the car-following model fitted; per road: the window
                                  used, its distributions per class group with fit counts and
                                  errors, desired speeds per lane, lane-change rates,
                                  the lane-change flows by lane pair, position and time
                                  (discretionary and strategic) and the fitted MOBIL
                                  threshold, where each on-ramp's vehicles merge and
                                  how lane -4 yields to them
      calibration_fits.parquet    one row per fitted follower: its parameters, errors,
                                  at-bound flags and whether the fit was accepted
      lane_flows_ROAD.png         the lane-change flows by position and lane pair
                                  (``twin calibrate`` draws it; :func:`draw_lane_flows`)

Each is written to a temporary file and renamed; the JSON last, so a reader never
sees a calibration whose fits are missing.

Over 500 lines: the fits' orchestration and the file format in one module; issue 78
separates the format, so that reading a calibration no longer imports the fitting.
"""

import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from twin import __version__
from twin.calibration import following
from twin.calibration.car_following import FitSettings, fit_followers
from twin.calibration.distributions import (
    ParameterDistribution,
    desired_speeds,
    group_distributions,
)
from twin.calibration.following import CalibrationDataError
from twin.calibration.lane_changes import (
    drawn_drivers,
    fit_threshold,
    lane_change_rates,
    recorded_incentives,
)
from twin.calibration.lane_flows import (
    describe_flows,
    explained_by_mobil,
    grid_edges,
    in_keep_out,
    keep_out,
    lane_change_flows,
    traffic_states,
)
from twin.calibration.merge_positions import describe_merges, merge_section
from twin.calibration.model_choice import (
    AUTO,
    CANDIDATES,
    choose,
    describe_model_choice,
    replay_score,
    score,
)
from twin.calibration.model_choice import summary as replay_summary
from twin.calibration.passing import describe_passing, passing_section
from twin.calibration.ramp_speeds import describe_ramp_speeds, ramp_speed_section
from twin.calibration.yielding import describe_yielding, yielding_section
from twin.core.atomic import atomic_file
from twin.core.errors import StoreError
from twin.core.i24 import Road
from twin.core.timeutil import format_local
from twin.data.store import TrajectoryStore, damaged_file
from twin.traffic.mobil import MOBILParams
from twin.traffic.models import car_following_model
from twin.traffic.models.base import CarFollowingModel

CALIBRATION = "calibration.json"
#: the threshold is refitted away from the strategic flows only where at least this
#: share of MOBIL's decisions lies away from them (fewer cannot pin it down)
MIN_AWAY_SHARE = 0.1
FLOW_ROUNDS = 5  # refits of the MOBIL threshold against the strategic changes, at most
FITS = "calibration_fits.parquet"
FORMAT = "i24-twin-calibration"
VERSION = 2  # 2 names the car-following model fitted (car_following_model)
READS = (1, 2)  # version 1 calibrations are of IDM


@dataclass(frozen=True)
class CalibrationSettings:
    """How a store is calibrated.

    Attributes:
        min_run, max_run: [s] following runs shorter are not used; longer are cut.
        fit: the car-following fit's settings.
        min_fits: accepted fits a road needs for its car following to be calibrated.
        mobil: the MOBIL parameters kept (politeness, safe deceleration, keep-right
            bias); the threshold is fitted.
        decision_every: [s] how often the recorded scenes are judged by MOBIL (the
            traffic manager's mean decision interval).
        threshold_drivers: who MOBIL's threshold is fitted with: ``drawn`` (the
            default), one driver per vehicle drawn from the calibrated distribution, as
            the twin draws its own (:func:`~twin.calibration.lane_changes.drawn_drivers`;
            a road whose car following was not calibrated keeps ``median``);
            ``median``, one median calibrated driver for every recorded vehicle.
    """

    min_run: float = 20.0
    max_run: float = 120.0
    fit: FitSettings = field(default_factory=FitSettings)
    min_fits: int = 10
    mobil: MOBILParams = field(default_factory=MOBILParams)
    decision_every: float = 1.0
    threshold_drivers: str = "drawn"

    def __post_init__(self):
        if self.threshold_drivers not in THRESHOLD_DRIVERS:
            raise ValueError(
                f"threshold_drivers must be one of {THRESHOLD_DRIVERS}, got "
                f"{self.threshold_drivers!r}"
            )


THRESHOLD_DRIVERS = ("median", "drawn")


def calibrate(
    store: TrajectoryStore,
    roads: list[Road] | None = None,
    t_from: float | None = None,
    t_until: float | None = None,
    settings: CalibrationSettings = CalibrationSettings(),
    *,
    model: CarFollowingModel | str = AUTO,
    progress: bool = False,
    following: dict | None = None,
) -> tuple[dict, dict]:
    """Calibrate ``roads`` (default: all the store's) on the recording between
    ``t_from`` and ``t_until`` (unix seconds; default: all of it), the drivers'
    car following as ``model``.

    ``model`` ``"auto"`` (:data:`~twin.calibration.model_choice.AUTO`, the default): each of
    :data:`~twin.calibration.model_choice.CANDIDATES` is fitted, and the one whose
    drawn drivers replay the window's followers best drives
    (:mod:`twin.calibration.model_choice`; the scores are kept as ``model_choice``).

    ``following``: another calibration document (of ``model``, or of one candidate)
    whose drivers' car following a road takes where its own window has too few
    accepted fits (a window with no waves to fit them on: the same drivers on another
    morning). The lane changes, their flows, the threshold (with those drivers),
    desired speeds and merges are still fitted on this window; the road's
    ``car_following`` says ``taken_from``.

    Returns:
        (the calibration document, {road: FollowerFits}).

    Raises:
        CalibrationDataError: a road named in ``roads`` has too few accepted fits (and
            ``following`` none for it), or (when ``roads`` is None) no road has enough;
            the window holds no data; ``following`` is of another model.
        StoreError: the store lacks a road named.
    """
    named = roads is not None
    roads = [Road.parse(r) for r in (roads if named else store.roads)]
    if not roads:
        raise CalibrationDataError(
            f"{store.path}: the store holds no trajectories, so there is no following to "
            "calibrate the drivers on (was every document of its day files rejected? "
            "twin data info says)"
        )
    auto = isinstance(model, str)
    if auto and model != AUTO:
        raise ValueError(f"model must be a car-following model or {AUTO!r}, got {model!r}")
    candidates = [car_following_model(n) for n in CANDIDATES] if auto else [model]
    offered = _offered_models(following)
    if following is not None and not offered & {m.name for m in candidates}:
        raise CalibrationDataError(
            f"the calibration to take car following from fitted {' and '.join(sorted(offered))}"
            f", this one {' or '.join(m.name for m in candidates)} (--model "
            f"{sorted(offered)[0]}, or calibrate that morning with --model auto)"
        )
    prepared = {road: _road_data(store, road, (t_from, t_until), settings) for road in roads}
    fitted = {}  # model name -> {road: (car section, fits, distributions)}
    for candidate in candidates:
        fitted[candidate.name] = {
            road.value: _car_following(
                road, prepared[road], settings, candidate, progress,
                _taken_following(following, road, candidate.name),
                label=candidate.name if auto else "",
            )
            for road in roads
        }  # fmt: skip
    choice = _choose_model(prepared, fitted, candidates, _model_of(following)) if auto else None
    model = car_following_model(choice["chosen"]) if auto else model
    doc = {
        "format": FORMAT,
        "version": VERSION,
        "created_by": f"i24-twin {__version__}",
        "created": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "car_following_model": model.name,
        "settings": _settings_dict(settings),
        "roads": {},
    }
    if choice is not None:
        doc["model_choice"] = choice
    all_fits, problems = {}, []
    for road in roads:
        car, fits, distributions = fitted[model.name][road.value]
        section = _road_section(store, road, prepared[road], settings, model, car, distributions)
        if auto:  # the others' drivers, for a morning that takes them (--following-from)
            section["car_following_candidates"] = {
                name: roads_fitted[road.value][0]
                for name, roads_fitted in fitted.items()
                if name != model.name
            }
        doc["roads"][road.value] = section
        all_fits[road.value] = fits
        reason = car.get("not_calibrated")
        if reason:
            problems.append(f"{road.value}: {reason}")
            if progress:
                print(f"{road.value}: car following not calibrated: {reason}")
    calibrated = [
        r for r, s in doc["roads"].items() if not s["car_following"].get("not_calibrated")
    ]
    if (named and problems) or not calibrated:
        raise CalibrationDataError(
            "not enough following to calibrate the drivers: " + "; ".join(problems)
        )
    return doc, all_fits


def _model_of(following: dict | None) -> str | None:
    """The car-following model a calibration document fitted (None for no document)."""
    return None if following is None else following.get("car_following_model", "idm")


def _offered_models(following: dict | None) -> set[str]:
    """The car-following models a calibration document offers drivers of: the one it
    fitted, and the candidates ``--model auto`` kept beside it."""
    if following is None:
        return set()
    offered = {_model_of(following)}
    for section in following.get("roads", {}).values():
        if isinstance(section, dict):
            offered |= set(section.get("car_following_candidates") or {})
    return offered


def _taken_following(following: dict | None, road: Road, model: str) -> dict | None:
    """``following``'s calibrated car following of ``road`` for the model named
    ``model`` (the one it fitted, or a candidate ``--model auto`` kept), or None."""
    if following is None:
        return None
    road_section = following.get("roads", {}).get(road.value, {})
    if following.get("car_following_model", "idm") == model:
        section = road_section.get("car_following")
    else:
        section = (road_section.get("car_following_candidates") or {}).get(model)
    if not isinstance(section, dict) or section.get("not_calibrated"):
        return None
    if not isinstance(section.get("distributions"), dict) or "all" not in section["distributions"]:
        raise CalibrationDataError(
            f"the calibration to take car following from has no {model} distributions of "
            f"{road.value}"
        )
    return {**section, "window": road_section.get("window")}


@dataclass(frozen=True)
class _RoadData:
    """What a road's calibration reads from the recording, once for every model."""

    grid: following.GridTraffic
    runs: following.FollowingRuns
    speeds: dict  # the desired_speed section (free flow)


def _road_data(store, road, window, settings) -> _RoadData:
    grid = following.load_grid(store, road, *window)
    runs = following.following_runs(
        grid, min_duration=settings.min_run, max_duration=settings.max_run
    )
    return _RoadData(grid, runs, desired_speeds(following.free_flow_speeds(grid)))


def _car_following(road, data, settings, model, progress, taken=None, label=""):
    """(the road's car_following section, its FollowerFits, {group: distribution}) of
    ``model`` fitted to ``data``'s runs (``taken``: another calibration's, where too few
    fits are accepted here)."""
    runs = data.runs
    bar = None
    if progress:
        from twin.core.progress import progress_bar

        what = f"fit {road.value}" + (f" ({label})" if label else "")
        bar = progress_bar(total=max(np.unique(runs.tid).size, 1), desc=what, unit="veh")

    def advance(done, total):
        if bar is not None:
            bar.total = total
            bar.n = done
            bar.refresh()

    fits = fit_followers(runs, settings.fit, model=model, progress=advance)
    if bar is not None:
        bar.close()
    distributions = group_distributions(fits)
    accepted = int(fits.accepted.sum())
    car = {
        "followers": int(np.unique(runs.tid).size),
        "runs": len(runs),
        "uninformative": fits.uninformative,
        "fitted": len(fits),
        "accepted": accepted,
        "rejected_poor": int(fits.poor.sum()),
        "rejected_at_bound": int((~fits.accepted & fits.other_at_bound).sum()),
        "desired_speed_identified": int((fits.accepted & fits.desired_speed_identified()).sum()),
        "nrmse": _quantiles(fits.nrmse[fits.accepted]),
        "rmse_m": _quantiles(fits.rmse[fits.accepted]),
        "distributions": {name: d.to_dict() for name, d in distributions.items()},
    }
    if accepted < settings.min_fits:
        reason = (
            f"{accepted} accepted fits (need {settings.min_fits}): {car['followers']} "
            f"followers, {fits.uninformative} of them never crossed a wave (stopped and "
            f"moved), {car['rejected_poor']} poor fits, {car['rejected_at_bound']} at a bound"
        )
        if taken is None:
            car["not_calibrated"] = reason
        else:  # another calibration's drivers (calibrate's ``following``)
            car["distributions"] = taken["distributions"]
            car["taken_from"] = {
                "why": reason,
                "window": taken.get("window"),
                "accepted": taken.get("accepted"),
            }
            try:
                distributions = {
                    name: ParameterDistribution.from_dict(d)
                    for name, d in taken["distributions"].items()
                }
            except (KeyError, TypeError, ValueError) as error:
                raise CalibrationDataError(
                    f"the calibration to take car following from has malformed "
                    f"distributions of {road.value}: {error!r}"
                ) from None
    return car, fits, distributions


def _choose_model(prepared: dict, fitted: dict, candidates: list, fallback: str | None) -> dict:
    """``model_choice`` of the document: each candidate's replay of every road's
    following runs (:mod:`~twin.calibration.model_choice`) and the one chosen. A
    candidate is scored only where it drives every road some candidate calibrated;
    where none could be scored (no following run to replay), ``fallback`` (the model
    of the calibration taken from) or the first candidate is kept, and a note says
    so."""
    usable = {
        name: {road for road, (car, *_) in roads.items() if not car.get("not_calibrated")}
        for name, roads in fitted.items()
    }
    wanted = set().union(*usable.values())
    scored = {}
    for m in candidates:
        missing = sorted(wanted - usable[m.name])
        if missing or not wanted:
            reasons = [
                f"{road}: {car['not_calibrated']}"
                for road, (car, *_) in fitted[m.name].items()
                if car.get("not_calibrated")
            ]
            scored[m.name] = {"not_calibrated": "; ".join(reasons)}
            continue
        scores = {}
        for road, data in prepared.items():
            if road.value in wanted:
                car, _, distributions = fitted[m.name][road.value]
                scores[road.value] = replay_score(data.runs, m, distributions, data.speeds, car)
        scored[m.name] = replay_summary(scores)
    eligible = {n: c for n, c in scored.items() if score(c) is not None}
    names = [m.name for m in candidates]
    note = None
    if eligible:
        chosen = choose(eligible)
    else:
        chosen = fallback if fallback in names else names[0]
        note = f"no candidate could be scored on this window: {chosen} kept"
    out = {
        "criterion": "median over the window's following runs of the spacing RMSE of "
        "drivers drawn from each model's distributions, each replayed behind its "
        "recorded leader",
        "candidates": scored,
        "chosen": chosen,
    }
    if note:
        out["note"] = note
    return out


def _road_section(store, road, data, settings, model, car, distributions) -> dict:
    """The road's calibration with its car following ``car`` of ``model``: the desired
    speeds, lane changes, their flows, MOBIL's threshold, merges, yielding and passing
    on the right."""
    grid = data.grid
    driver = _median_driver(model, distributions.get("all"))
    changes = following.lane_changes(grid)
    # threshold_drivers "drawn": the threshold is fitted with drivers drawn as the
    # calibrated twin draws them (lane_changes.drawn_drivers); a road whose car following
    # was not calibrated keeps the paper's drivers in the twin, and one driver here
    drawn = None
    wanted = settings.threshold_drivers == "drawn"
    if wanted and "not_calibrated" not in car and "all" in distributions:
        drawn = drawn_drivers(grid.tid, distributions["all"], model)
    incentives = recorded_incentives(
        grid, model, driver, settings.mobil, every=settings.decision_every, drivers=drawn
    )
    mobil, flows = _lane_change_flows(grid, changes, incentives, settings)
    mobil.update(
        politeness=settings.mobil.politeness,
        safe_decel=settings.mobil.safe_decel,
        keep_right=settings.mobil.keep_right,
    )
    t0, t1 = float(grid.time.min()), float(grid.time.max())
    with_ramps = store.samples(road, t0, t1, ramps=True)
    section = {
        "window": {
            "from": t0,
            "until": t1,
            "from_local": format_local(t0),
            "until_local": format_local(t1),
        },
        "trajectories": int(np.unique(grid.tid).size),
        "car_following": car,
        "desired_speed": data.speeds,
        "lane_changes": lane_change_rates(changes),
        "lane_flows": flows,
        "mobil": mobil,
        "merges": merge_section(with_ramps, road),
        "ramp_speeds": ramp_speed_section(store, road, with_ramps, grid.t0),
        "yielding": yielding_section(grid, with_ramps, model, driver),
        "passing_right": passing_section(grid),
    }
    return section


def describe_check(check: dict | None) -> list[str]:
    """The report's lines of a road's ``lane_change_check``
    (:func:`twin.runners.lane_change_fit.check_in_twin`): the calibrated twin's lane
    changes against the recording's on the window, out of each lane and by zone."""
    if not check:
        return []
    if "note" in check:
        return [f"      checked in the twin: {check['note']}"]

    def counts(by: dict, sep: str) -> str:
        return sep.join(
            f"{key.replace('_', ' ')} {c['simulated']} / {c['recorded']}" for key, c in by.items()
        )

    return [
        f"      checked in the twin ({check['episodes']} kinematic episodes of the window): "
        f"{check['simulated']} lane changes simulated / {check['recorded']} recorded",
        f"        out of lanes: {counts(check['by_lane'], ', ')}",
        f"        by zone: {counts(check['by_zone'], '; ')}",
    ]


def _lane_change_flows(grid, changes, incentives, settings) -> tuple[dict, dict]:
    """The MOBIL threshold and the lane-change flows (:mod:`lane_flows`). The threshold
    is fitted to every recorded change, then, where the flows show strategic changes,
    again away from them: MOBIL models the discretionary changes only, so it is fitted
    without the position bins that hold a strategic flow and without the moves into a
    lane kept out of (:func:`~twin.calibration.lane_flows.keep_out`), MOBIL's decisions
    and the recorded changes alike (where a lane ends, drivers resist incentives into it
    and leave it whatever MOBIL says: counting either there would bend the threshold)."""
    every = max(1, round(settings.decision_every / grid.dt)) * grid.dt
    mobil = fit_threshold(incentives, len(changes))
    explained = explained_by_mobil(changes, incentives, mobil["threshold"], grid.t0, every)
    # the traffic states of the passages and the changes: once, no refit moves them
    states = traffic_states(grid, changes, grid_edges(grid))
    flows = lane_change_flows(changes, grid, explained, states=states)
    excluded, previous = 0, None
    # the strategic bins depend on what MOBIL explains: refit until they are stable
    for _ in range(FLOW_ROUNDS):
        if not flows["identified"]:
            break
        away_changes, away_decisions = _away_from_strategic(flows, changes, incentives)
        if previous is not None and np.array_equal(away_decisions, previous):
            break
        previous = away_decisions
        if np.count_nonzero(away_decisions) < MIN_AWAY_SHARE * away_decisions.size:
            mobil["note"] = (
                f"not refitted (further): under {MIN_AWAY_SHARE:.0%} of MOBIL's decisions lie "
                "away from the strategic flows, too few to fit it on the discretionary ones"
            )
            break
        excluded = int(np.count_nonzero(~away_changes))
        mobil = fit_threshold(incentives, int(np.count_nonzero(away_changes)), where=away_decisions)
        explained = explained_by_mobil(changes, incentives, mobil["threshold"], grid.t0, every)
        flows = lane_change_flows(changes, grid, explained, states=states)
    if excluded > 0:
        mobil["strategic_bins_changes"] = excluded
        mobil["strategic_final"] = flows["strategic_count"]
    flows["keep_out"] = keep_out(flows) if flows["identified"] else []
    return mobil, flows


def _away_from_strategic(flows: dict, changes, incentives) -> tuple[np.ndarray, np.ndarray]:
    """(c,), (e,) bool: the recorded changes and MOBIL's decisions outside the position
    bins where the flows show a strategic flow and not into a lane kept out of there."""
    edges = np.asarray(flows["x_edges"])
    strategic = np.zeros(edges.size - 1, dtype=bool)
    for pair in flows["strategic"].values():
        strategic |= np.asarray(pair["by_position"]) > 0
    zones = keep_out(flows)

    def away(x, into):
        at = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, edges.size - 2)
        return ~strategic[at] & ~in_keep_out(zones, into, x)

    into = incentives.lane.astype(np.int64) + incentives.direction
    return away(changes.x, changes.lane_to), away(incentives.x, into)


def _median_driver(model: CarFollowingModel, distribution):
    """The model's median calibrated driver (the fit's start, a typical car, without
    one), as scalar parameters."""
    fitted = model.fitted
    values = distribution.median if distribution is not None else [p.start for p in fitted]
    return model.make(**{p.name: float(v) for p, v in zip(fitted, values, strict=True)})


def _quantiles(values: np.ndarray) -> dict:
    if values.size == 0:
        return {"median": None, "p90": None}
    return {
        "median": round(float(np.median(values)), 4),
        "p90": round(float(np.quantile(values, 0.9)), 4),
    }


def _settings_dict(settings: CalibrationSettings) -> dict:
    out = asdict(settings)
    out["mobil"] = {k: float(v) for k, v in out["mobil"].items()}
    return out


def write_calibration(store: TrajectoryStore, doc: dict, fits: dict) -> Path:
    """Write ``doc`` and the per-follower ``fits`` into the store folder (atomically;
    the recorded data are not touched). Returns the JSON's path."""
    table = _fits_table(fits)
    with atomic_file(store.path / FITS) as tmp:
        pq.write_table(table, tmp)
    with atomic_file(store.path / CALIBRATION) as tmp:
        tmp.write_text(json.dumps(doc, indent=1, allow_nan=False) + "\n")
    return store.path / CALIBRATION


def draw_lane_flows(store: TrajectoryStore, doc: dict) -> list[Path]:
    """Draw each road's lane-change flows beside the calibration
    (``STORE/lane_flows_ROAD.png``); returns the pictures' paths."""
    from twin.calibration.flow_plot import plot_lane_flows

    paths = []
    for road, section in doc["roads"].items():
        flows, window = section.get("lane_flows"), section["window"]
        if not flows:
            continue
        title = (
            f"Lane-change flows recorded on {road}, {window['from_local']} to "
            f"{window['until_local'][11:]}"
        )
        paths.append(plot_lane_flows(flows, store.path / f"lane_flows_{road}.png", title=title))
    return paths


def _fits_table(fits: dict) -> pa.Table:
    names = next(iter(fits.values())).names if fits else ()
    columns = {name: [] for name in ("road", "tid", "vehicle_class", "runs", "seconds")}
    columns.update({name: [] for name in names})
    columns.update({"rmse": [], "nrmse": [], "accepted": []})
    columns.update({f"{name}_at_bound": [] for name in names})
    for road, f in fits.items():
        columns["road"].append(np.full(len(f), road, dtype=object))
        columns["tid"].append(f.tid.astype(np.int32))
        columns["vehicle_class"].append(f.vehicle_class.astype(np.int8))
        columns["runs"].append(f.runs.astype(np.int32))
        columns["seconds"].append(f.seconds)
        for j, name in enumerate(names):
            columns[name].append(f.params[:, j])
            columns[f"{name}_at_bound"].append(f.at_bound[:, j])
        columns["rmse"].append(f.rmse)
        columns["nrmse"].append(f.nrmse)
        columns["accepted"].append(f.accepted)
    return pa.table(
        {name: np.concatenate(parts) if parts else [] for name, parts in columns.items()}
    )


def read_calibration(store: TrajectoryStore) -> dict | None:
    """The store's calibration document, or None when it has none.

    Raises:
        StoreError: the file is not valid JSON, of another format or version.
    """
    path = store.path / CALIBRATION
    if not path.is_file():
        return None
    return read_calibration_file(path)


def read_calibration_file(path: Path) -> dict:
    """The calibration document at ``path``.

    Raises:
        StoreError: the file is missing, not valid JSON, of another format or version.
    """
    path = Path(path)
    if not path.is_file():
        raise StoreError(f"{path}: no such calibration file")
    try:
        doc = json.loads(path.read_text())
    except ValueError as error:
        raise StoreError(f"{path} is not valid JSON: {error}; run 'twin calibrate' again") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise StoreError(f"{path} is not an i24-twin calibration")
    if doc.get("version") not in READS:
        raise StoreError(
            f"{path} has calibration version {doc.get('version')}, this twin reads "
            f"{' and '.join(map(str, READS))}: run 'twin calibrate' again"
        )
    return doc


def calibration_model(doc: dict) -> CarFollowingModel:
    """The car-following model a calibration document fitted (IDM for those written
    before models could be chosen).

    Raises:
        StoreError: the document names a model this twin does not know.
    """
    try:
        return car_following_model(doc.get("car_following_model", "idm"))
    except ValueError as error:
        raise StoreError(f"calibration: {error}") from None


def read_fits(store: TrajectoryStore):
    """The per-follower fits as a pandas DataFrame (empty when there are none)."""
    path = store.path / FITS
    if not path.is_file():
        import pandas as pd

        return pd.DataFrame()
    with damaged_file(path, "the calibration is damaged: run twin calibrate again"):
        return pq.read_table(path).to_pandas()


def describe_calibration(doc: dict | None) -> str:
    """Lines for ``twin data info``: what each road's calibration found."""
    if doc is None:
        return "calibration  none (run 'twin calibrate STORE')"
    model = calibration_model(doc)
    lines = [f"calibration  {doc['created']} by {doc['created_by']}, drivers {model.name}"]
    lines += describe_model_choice(doc.get("model_choice"))
    for road, section in doc["roads"].items():
        window = section["window"]
        car = section["car_following"]
        lines.append(
            f"  {road}: {window['from_local']} to {window['until_local'][11:]}, "
            f"{section['trajectories']:,} trajectories"
        )
        taken = car.get("taken_from")
        if car.get("not_calibrated"):
            lines.append(f"    car following: not calibrated ({car['not_calibrated']})")
        elif taken:
            other = taken.get("window") or {}
            lines.append(
                f"    car following: taken from another calibration ({other.get('from_local')} "
                f"to {str(other.get('until_local'))[11:]}, {taken.get('accepted')} accepted "
                f"fits) because this window has {taken['why']}"
            )
        else:
            lines.append(
                f"    car following: {car['accepted']} accepted of {car['fitted']} fitted "
                f"({car['rejected_poor']} poor, {car['rejected_at_bound']} at a bound, "
                f"{car['uninformative']} followers never crossed a wave); spacing NRMSE "
                f"median {car['nrmse']['median']:.3f}"
            )
        if not car.get("not_calibrated"):
            for group, d in car["distributions"].items():
                median = ", ".join(
                    f"{p.symbol} {d['median'][p.name]:.2f} {p.unit}" for p in model.fitted
                )
                lines.append(f"      {group:<5} n={d['count']:<4} {median}")
        speeds = section["desired_speed"]
        if speeds:
            per_lane = ", ".join(
                f"lane {lane} {s['mean']:.1f}" for lane, s in speeds.items() if lane != "all"
            )
            pooled = speeds["all"]
            lines.append(
                f"    desired speed: {pooled['mean']:.1f} m/s (sd {pooled['sd']:.1f}, "
                f"{pooled['count']} free vehicles){'; ' + per_lane if per_lane else ''}"
            )
        else:
            lines.append("    desired speed: too few free-flowing vehicles")
        changes, mobil = section["lane_changes"], section["mobil"]
        rate = changes["per_km"]
        lines.append(
            f"    lane changes: {changes['count']} in {changes['vehicle_km']:.0f} vehicle-km"
            f" ({rate if rate is not None else 0:.3f} per km); MOBIL threshold "
            f"{mobil['threshold']:.2f} m/s^2"
        )
        if mobil.get("note"):
            lines.append(f"      MOBIL threshold {mobil['note']}")
        fit = mobil.get("twin_fit")
        if fit and "note" in fit:
            lines.append(f"      through the twin: {fit['note']}")
        elif fit:
            lines.append(
                f"      through the twin: {fit['simulated']} lane changes simulated against "
                f"{fit['recorded']} recorded in {fit['episodes']} kinematic episodes (the "
                f"scenes' threshold {mobil['scenes_threshold']:.2f} m/s^2 made "
                f"{fit['trials'][0][1]})"
            )
        lines += describe_check(section.get("lane_change_check"))
        lines += describe_flows(section.get("lane_flows", {}))
        lines += describe_merges(section.get("merges", []))
        lines += describe_ramp_speeds(section.get("ramp_speeds"))
        lines += describe_yielding(section.get("yielding"))
        lines += describe_passing(section.get("passing_right"))
    return "\n".join(lines)
