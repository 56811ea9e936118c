"""``twin bench fidelity``: the twin's fidelity over many days, each calibrated on its
first half and evaluated on its second.

For every day file given (or every day file of a folder given, such as a family of
SUMO days made by ``twin data sumo --family``), in that order:

1. the day is ingested into a store (:func:`twin.data.ingest.ingest`);
2. its road is calibrated on the recording's first half (:func:`twin.calibration.
   calibrate.calibrate`, the default settings, timed); a day whose first half cannot be
   calibrated (no stop-and-go wave to fit the drivers on) is recorded as
   ``not calibrated`` with the reason, and the benchmark goes on;
3. the second half is evaluated (:func:`twin.runners.evaluation.evaluate`) with the
   behaviours of :data:`BEHAVIOURS`: ``episodes`` episodes in the kinematic world, and
   the first ``physics_episodes`` of the same episodes in the physics world, for their
   collisions and stalls;
4. each behaviour's figures are read from the evaluations
   (:mod:`twin.metrics.day_fidelity`) into the day's rows.

The benchmark's folder, resumable (the same command goes on where it stopped; a day
done is not done again; a rerun with other settings is refused)::

    OUT/
      bench.json            the settings
      days/NAME/store/      the day ingested, calibrated in calibration.json
      days/NAME/calibrate.json   the calibration's outcome: its wall time or the reason
      days/NAME/kinematic/  days/NAME/physics/   the evaluations (twin eval folders)
      days/NAME/day.json    the day's rows, written once the day is done
      days.parquet          one row per day and behaviour (``days.md``: the same)
      summary.json          over the days: each figure's median and worst, the targets
      fidelity.png          the figures' distributions over the days, with the targets

A day's name is its file's name less ``.json`` (or ``.json.gz``); where
``NAME.params.json`` lies beside it (the parameters ``twin data sumo --family``
drew for it), each of its values is a ``param_...`` column of the day's rows.
"""

import json
import math
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

from twin.core.atomic import atomic_file
from twin.core.errors import TwinError
from twin.core.i24 import Road
from twin.perf.fidelity_outputs import EVALUATED, NOT_CALIBRATED, NOT_EVALUATED, write_outputs

FORMAT = "i24-twin-fidelity-bench"
IDENTITY = "bench.json"
#: The behaviours evaluated on every day: the calibrated drivers, and the paper's.
BEHAVIOURS = ("calibrated", "paper")
DAY_SUFFIXES = (".json", ".json.gz")
PARAMS_SUFFIX = ".params.json"
FAMILY_FILE = "family.json"
DROP_X = "param_params_drop_x"  # a family day's lane drop [m], from its parameters file


class FidelityBenchError(TwinError):
    """The fidelity benchmark cannot run: bad settings or days, a folder holding
    something else."""


@dataclass(frozen=True)
class FidelitySettings:
    """What ``twin bench fidelity`` runs on every day.

    Attributes:
        episodes: kinematic episodes evaluated per day.
        physics_episodes: of those, how many are run in the physics world too (0: none).
        duration: [s] each episode's length.
        seed: the evaluations' seed (episode ``i`` of every day draws from ``(seed, i)``).
        road: the carriageway calibrated and evaluated.
        lane_changes: how the calibration fits MOBIL's threshold: ``scenes`` (on the
            recorded scenes) or ``twin`` (then through the twin's episodes,
            :mod:`twin.runners.lane_change_fit`; ``twin calibrate --lane-changes``).
    """

    episodes: int = 40
    physics_episodes: int = 2
    duration: float = 120.0
    seed: int = 0
    road: str = "westbound"
    lane_changes: str = "scenes"

    def __post_init__(self):
        for name in ("episodes", "physics_episodes", "seed"):
            value = getattr(self, name)
            least = 1 if name == "episodes" else 0
            if not isinstance(value, int) or isinstance(value, bool) or value < least:
                raise FidelityBenchError(
                    f"--{name.replace('_', '-')} must be an integer >= {least}, got {value!r}"
                )
        if self.physics_episodes > self.episodes:
            raise FidelityBenchError(
                f"--physics-episodes ({self.physics_episodes}) must be at most --episodes "
                f"({self.episodes}): they are the first of the same episodes"
            )
        if not (
            isinstance(self.duration, int | float)
            and math.isfinite(self.duration)
            and self.duration > 0
        ):
            raise FidelityBenchError(f"--duration must be > 0 s, got {self.duration!r}")
        try:
            object.__setattr__(self, "road", Road.parse(self.road).value)
        except ValueError as error:
            raise FidelityBenchError(f"--road: {error}") from None
        if self.lane_changes not in ("scenes", "twin"):
            raise FidelityBenchError(
                f"--lane-changes must be scenes or twin, got {self.lane_changes!r}"
            )


@dataclass(frozen=True)
class Day:
    """One day file of the benchmark: its name, its path and the parameters it was
    made with (``{}`` without a ``.params.json`` beside it)."""

    name: str
    path: Path
    params: dict


def find_days(paths) -> list[Day]:
    """The day files of ``paths``: each a day file, or a folder whose day files
    (``*.json`` and ``*.json.gz``, less ``*.params.json`` and ``family.json``) are
    taken in the order of their names.

    Raises:
        FidelityBenchError: a path is missing, a folder holds no day file, two days
            share a name, or a parameters file is not a JSON object.
    """
    days = []
    for given in map(Path, paths):
        if given.is_dir():
            found = sorted(p for p in given.iterdir() if p.is_file() and _is_day(p))
            if not found:
                raise FidelityBenchError(
                    f"--days {given}: the folder holds no day file (*.json, *.json.gz)"
                )
            days += found
        elif given.is_file():
            days.append(given)
        else:
            raise FidelityBenchError(f"--days {given}: no such file or folder")
    if not days:
        raise FidelityBenchError("--days: give at least one day file or folder of them")
    named: dict[str, Path] = {}
    for path in days:
        name = _day_name(path)
        if name in named:
            raise FidelityBenchError(
                f"two days are named {name}: {named[name]} and {path} (a day's results are "
                "kept by its file's name; rename one)"
            )
        named[name] = path
    return [
        Day(name, path, _params(path.with_name(name + PARAMS_SUFFIX)))
        for name, path in named.items()
    ]


def _is_day(path: Path) -> bool:
    name = path.name
    return name.endswith(DAY_SUFFIXES) and not name.endswith(PARAMS_SUFFIX) and name != FAMILY_FILE


def _day_name(path: Path) -> str:
    for suffix in DAY_SUFFIXES[::-1]:  # .json.gz before .json
        if path.name.endswith(suffix):
            return path.name.removesuffix(suffix)
    return path.stem


def _params(path: Path) -> dict:
    """The ``param_...`` columns of a day's parameters file (nested keys joined by
    ``_``; a list as its JSON text); ``{}`` where there is none."""
    if not path.is_file():
        return {}
    doc = _read_json(path, "a day's parameters")
    if not isinstance(doc, dict):
        raise FidelityBenchError(f"{path}: a day's parameters must be a JSON object")
    return _flat(doc, "param_")


def _flat(doc: dict, prefix: str) -> dict:
    out = {}
    for key, value in doc.items():
        if isinstance(value, dict):
            out.update(_flat(value, f"{prefix}{key}_"))
        else:
            out[f"{prefix}{key}"] = json.dumps(value) if isinstance(value, list) else value
    return out


def _read_json(path: Path, what: str):
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError) as error:
        raise FidelityBenchError(f"{path}: cannot read {what} ({error})") from None


def fidelity_bench(
    days,
    out,
    settings: FidelitySettings = FidelitySettings(),
    *,
    workers: int = 1,
    progress: bool = False,
) -> dict:
    """The twin's fidelity on held-out halves of days: each day of ``days`` (day files
    or folders of them) calibrated on its first half and evaluated on its second, the
    ego's speed RMSE and end error (median and p90 over a day's episodes), the speed
    field's RMSE per lane, the lane changes simulated over recorded, collisions and
    stalls in both worlds and the calibration's wall time, per day and behaviour, with
    their median and worst over the days against the issue's targets.

    Writes the folder ``out`` (module doc) and returns the benchmark's figures: the
    days, and per behaviour each main figure's median and worst over the days, with
    the targets they are judged by (``targets``: figure to bound).

    Raises:
        FidelityBenchError: bad days or settings, ``out`` holds something else, or a
            day cannot be ingested or evaluated (what the ingest or the evaluation
            raised, with the day's name; the days done before it are kept).
    """
    from twin.core.locks import output_lock
    from twin.runners.folders import claim

    days = find_days(days)
    out = Path(out)
    identity = {"format": FORMAT, "settings": asdict(settings)}
    claim(
        out,
        IDENTITY,
        identity,
        kind="i24-twin fidelity benchmark",
        noun="benchmark",
        error=FidelityBenchError,
    )
    with output_lock(out, "twin bench fidelity"):
        rows = []
        for day in days:
            try:
                rows += run_day(day, out / "days" / day.name, settings, workers, progress)
            except FidelityBenchError:
                raise
            except TwinError as error:  # which day, and that the others are kept
                raise FidelityBenchError(
                    f"{day.name} ({day.path}): {error} (the days done are kept: rerun to resume)"
                ) from error
        return write_outputs(out, rows, settings, _families(days))


def run_day(
    day: Day, folder: Path, settings: FidelitySettings, workers: int, progress: bool
) -> list[dict]:
    """The rows of ``day`` (one per behaviour), from ``folder/day.json`` where the day
    is done, else made (steps 1 to 4 of the module doc, each kept in ``folder``)."""
    from twin.data.store import open_store

    done = folder / "day.json"
    if done.is_file():
        return _read_json(done, "a finished day's rows (remove it to redo the day)")
    folder.mkdir(parents=True, exist_ok=True)
    store = open_store(_ingested(day, folder / "store"))
    road = Road.parse(settings.road)
    if road not in store.roads:
        raise FidelityBenchError(
            f"{day.name} ({day.path}) holds no {road.value} traffic (it holds "
            f"{', '.join(r.value for r in store.roads)}); choose its road with --road"
        )
    first, last = store.time_range(road)
    split = 0.5 * (first + last)
    calibration = _calibrated(store, folder / "calibrate.json", road, first, split,
                              settings.lane_changes)  # fmt: skip
    common = {
        "day": day.name,
        "file": str(day.path),
        "road": road.value,
        "calibrate_from": first,
        "split": split,
        "evaluate_until": last,
        **{k: v for k, v in calibration.items() if k != "calibrated"},
    }
    if not calibration["calibrated"]:
        rows = [{**common, "behaviour": b, "status": NOT_CALIBRATED} for b in BEHAVIOURS]
        _say(progress, f"{day.name}: not calibrated ({calibration['reason']})")
    else:
        rows = _evaluated(store, folder, common, settings, (split, last), workers, progress,
                          day.params.get(DROP_X))  # fmt: skip
    rows = [{**_finite_or_none(row), **day.params} for row in rows]
    with atomic_file(done) as tmp:
        tmp.write_text(json.dumps(rows, indent=1, allow_nan=False) + "\n")
    return rows


def _finite_or_none(row: dict) -> dict:
    """``row`` with each NaN (a figure not measured) as None, as JSON holds it."""
    return {k: None if isinstance(v, float) and math.isnan(v) else v for k, v in row.items()}


def _ingested(day: Day, store: Path) -> Path:
    """``store``, the day ingested there unless it already is."""
    from twin.data.ingest import ingest
    from twin.data.store import is_store

    if not is_store(store):
        ingest([day.path], store, progress=False)
    return store


def _calibrated(store, record: Path, road: Road, first: float, split: float,
                lane_changes: str = "scenes") -> dict:  # fmt: skip
    """The calibration of ``road`` on ``first`` to ``split`` (unix seconds), made and
    written into ``store`` unless ``record`` says it was: whether it is
    (``calibrated``), the reason where not, the model chosen and its wall time
    (:func:`twin.metrics.day_fidelity.calibration_figures`)."""
    from twin.calibration.calibrate import calibrate, write_calibration
    from twin.calibration.following import CalibrationDataError
    from twin.metrics.day_fidelity import calibration_figures

    if record.is_file():
        return _read_json(record, "a day's calibration record (remove it to calibrate again)")
    start = time.perf_counter()
    try:
        doc, fits = calibrate(store, [road], first, split)
    except CalibrationDataError as error:
        outcome = {
            "calibrated": False,
            "reason": str(error),
            "calibration_window_s": round(split - first, 1),
        }
    else:
        write_calibration(store, doc, fits)
        if lane_changes == "twin":  # the threshold fitted again, through the twin
            from mapgen.build import default_map
            from twin.data.store import open_store
            from twin.runners.lane_change_fit import refit_store

            doc = refit_store(open_store(store.path), default_map())
        outcome = {
            "calibrated": True,
            "reason": None,
            "car_following_model": doc["car_following_model"],
            **calibration_figures(time.perf_counter() - start, split - first),
        }
    with atomic_file(record) as tmp:
        tmp.write_text(json.dumps(_finite_or_none(outcome), indent=1) + "\n")
    return outcome


def _evaluated(
    store,
    folder: Path,
    common: dict,
    settings: FidelitySettings,
    window: tuple[float, float],
    workers: int,
    progress: bool,
    drop_x: float | None = None,
) -> list[dict]:
    """The day's rows from its evaluations in both worlds (the physics one skipped
    with ``physics_episodes`` 0); ``drop_x`` [m]: where its lanes end, if known."""
    from twin.cosim.config import SCENARIO_B, switch_world
    from twin.metrics.day_fidelity import day_figures, safety_figures
    from twin.metrics.lane_change_zones import store_zones
    from twin.runners.episodes import SamplingError
    from twin.runners.evaluation import EvalConfig, evaluate

    config = EvalConfig(
        road=settings.road,
        episodes=settings.episodes,
        duration=settings.duration,
        behaviours=BEHAVIOURS,
        t_from=window[0],
        t_until=window[1],
        seed=settings.seed,
    )
    # lane changes by zone: where the day's own parameters say its lanes end, else
    # where its recording shows them ending
    zones = store_zones(store, settings.road, drop_x=drop_x)
    summaries, seconds = {}, {}
    worlds = {"kinematic": settings.episodes, "physics": settings.physics_episodes}
    for world, episodes in worlds.items():
        if not episodes:
            continue
        world_config = replace(config, episodes=episodes, cosim=switch_world(SCENARIO_B, world))
        start = time.perf_counter()
        try:
            result = evaluate(
                store, folder / world, world_config, workers=workers, progress=progress,
                zones=zones,
            )  # fmt: skip
        except SamplingError as error:
            reason = f"no episode to evaluate in the second half: {error}"
            _say(progress, f"{common['day']}: not evaluated ({reason})")
            return [
                {**common, "behaviour": b, "status": NOT_EVALUATED, "reason": reason}
                for b in BEHAVIOURS
            ]
        seconds[world] = round(time.perf_counter() - start, 1)
        summaries[world] = result.summary["behaviours"]
    _say(
        progress,
        f"{common['day']}: calibrated in {common['calibrate_s']:g} s, evaluated in "
        + ", ".join(f"{s:g} s ({w})" for w, s in seconds.items()),
    )
    return [
        {
            **common,
            "behaviour": b,
            "status": EVALUATED,
            "reason": None,
            "eval_s": seconds["kinematic"],
            "physics_s": seconds.get("physics", math.nan),
            **day_figures(summaries["kinematic"][b]),
            **safety_figures(
                summaries["physics"][b] if "physics" in summaries else None, "physics_"
            ),
        }
        for b in BEHAVIOURS
    ]


def _families(days: list[Day]) -> dict:
    """``family.json`` of every folder the days lie in that has one, by folder."""
    folders = dict.fromkeys(day.path.parent for day in days)
    return {
        str(folder): _read_json(folder / FAMILY_FILE, "a family's description")
        for folder in folders
        if (folder / FAMILY_FILE).is_file()
    }


def _say(progress: bool, line: str) -> None:
    """A line on standard error for people watching, where ``progress`` is on."""
    if progress:
        import sys

        print(line, file=sys.stderr, flush=True)
