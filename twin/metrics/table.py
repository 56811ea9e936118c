"""Every metric of a run, declared once: its name, unit, definition, where
``metrics.json`` holds it, which runs produce it, how ``twin eval`` summarises it, and
whether the paired benchmark compares it with ``human``.

``metrics.json`` (:mod:`twin.metrics.measure`) is the nested document a run writes;
this table is the flat view of it that ``twin eval``'s ``episodes.parquet`` and
summaries, the paired benchmark (:mod:`twin.control.benchmark`), the env's
``info["metrics"]`` and the documentation read. Adding a metric is its computation
(in the section of ``metrics.json`` it belongs to) and one :class:`Metric` here;
``python -m twin.metrics.table`` then writes ``docs/metrics.md`` anew (a test fails
while it is out of date).
"""

from collections.abc import Callable
from dataclasses import dataclass

from twin.metrics.collisions import COLUMNS

EVERY_RUN = "every run"
WITH_CONTROLLER = "runs with an ego controller"
WITH_AV_SHARE = "runs with --av-share"
WITH_RECORDING = "runs whose ego's recording has a slow spell"
WITH_LANE_TRAFFIC = "runs with recorded traffic in the lane"
WITH_HANDOVER = "runs with a hand-over to the recording"
WITH_GHOST_SPAWN = "runs with a spawn from the ghost cells"
WITH_SPAWN = "runs with a spawn"
WITH_RELAXING = "runs with a vehicle relaxing in the ghost cells"
WITH_RAMP = "runs on a road with an on-ramp"
WITH_PAIRS = "runs that log a recorded vehicle at two times in a row"


@dataclass(frozen=True)
class Metric:
    """One metric of a run.

    Attributes:
        name: its column in ``episodes.parquet`` and key in the summaries.
        unit: e.g. ``m/s``; ``-`` for a ratio, ``count`` for a count.
        definition: what it measures, in one sentence.
        source: the keys (and list indices) leading to it in ``metrics.json``.
        summary: how ``twin eval`` summarises it over episodes: ``stats`` (median, p90,
            mean), ``sum``, or ``none`` (kept in the rows only).
        paired: compared with ``human`` by the paired benchmark: ``higher`` or
            ``lower`` is better; ``None``: not compared.
        produced_by: which runs have a value (the others hold null).
        convert: applied to the value read (e.g. ``len`` of a list).
    """

    name: str
    unit: str
    definition: str
    source: tuple[str | int, ...]
    summary: str = "stats"
    paired: str | None = None
    produced_by: str = EVERY_RUN
    convert: Callable | None = None

    def __post_init__(self):
        if self.summary not in ("stats", "sum", "none"):
            raise ValueError(f"metric {self.name}: summary must be stats, sum or none")
        if self.paired not in (None, "higher", "lower"):
            raise ValueError(f"metric {self.name}: paired must be higher, lower or None")

    def read(self, figures: dict):
        """The value in a run's ``metrics.json`` document (None where it is missing)."""
        value = figures
        for key in self.source:
            try:
                value = value[key]
            except (KeyError, IndexError, TypeError):
                return None
        return self.convert(value) if self.convert is not None else value


def _ego(*keys):
    return ("ego", *keys)


def _energy(*keys):
    return ("energy", *keys)


def _control(*keys):
    return ("control", *keys)


METRICS: tuple[Metric, ...] = (
    Metric("ego_record_id", "-", "the recorded vehicle the ego is (its I-24 MOTION _id)",
           _ego("record_id"), summary="none"),
    Metric("simulated_s", "s", "time simulated", ("simulated_s",), summary="none"),
    Metric("ego_speed_rmse_mps", "m/s", "RMS of the simulated ego's speed minus its "
           "recording's, over the episode", _ego("speed_rmse_mps")),
    Metric("ego_position_rmse_m", "m", "RMS of the simulated ego's position along the road "
           "minus its recording's", _ego("position_rmse_m")),
    *(
        Metric(f"ego_position_error_{at}_m", "m", f"the ego's position minus its recording's "
               f"{'at the end' if at == 'end' else f'{at[:-1]} s after the start'}",
               _ego("position_error_m", at))
        for at in ("30s", "60s", "120s", "end")
    ),
    Metric("slow_spells_recorded", "count", "spells below 15 mph in the ego's recording",
           _ego("slow_spells", "recorded_spells"), summary="none"),
    Metric("slow_spell_begin_difference_s", "s", "when the ego's first slow spell begins "
           "minus when its recording's does", _ego("slow_spells", "spells", 0,
           "begin_difference_s"), produced_by=WITH_RECORDING),
    Metric("slow_spell_end_difference_s", "s", "when the ego's first slow spell ends minus "
           "when its recording's does", _ego("slow_spells", "spells", 0, "end_difference_s"),
           produced_by=WITH_RECORDING),
    Metric("speed_field_rmse_mps", "m/s", "RMS over Edie cells of the windows of the "
           "simulated speed field minus the recorded one, all lanes",
           ("traffic", "speed_field", "all_lanes", "rmse_mps")),
    Metric("lane_changes_simulated", "count", "lane changes the simulated vehicles made",
           ("counts", "lane_changes"), summary="sum"),
    Metric("lane_changes_recorded", "count", "lane changes the recording makes in the same "
           "moving window", ("counts", "lane_changes_recorded_in_window"), summary="sum"),
    Metric("handovers_to_ghost", "count", "simulated vehicles handed back to their recordings "
           "in the ghost cells", ("handover", "visible_to_ghost", "count"), summary="sum"),
    Metric("handover_to_ghost_jump_p90_m", "m", "p90 over the episode's hand-overs to the "
           "recording of the one-step position jump (the recording one step later against "
           "the simulated vehicle carried on at its speed)",
           ("handover", "visible_to_ghost", "position_jump_m", "p90"), produced_by=WITH_HANDOVER),
    Metric("handover_to_ghost_jump_max_m", "m", "the largest of those jumps",
           ("handover", "visible_to_ghost", "position_jump_m", "max"), produced_by=WITH_HANDOVER),
    Metric("handover_to_ghost_speed_jump_max_mps", "m/s", "the largest speed jump of a "
           "hand-over to the recording",
           ("handover", "visible_to_ghost", "speed_jump_mps", "max"), produced_by=WITH_HANDOVER),
    Metric("handovers_backwards", "count", "hand-overs to the recording that moved the vehicle "
           "more than 0.5 m against travel", ("handover", "visible_to_ghost", "backwards"),
           summary="sum"),
    Metric("handovers_left_windows", "count", "simulated vehicles removed that drove out of the "
           "windows, or whose recordings are outside them or absent then",
           ("handover", "visible_to_ghost", "left_windows"), summary="sum"),
    Metric("handovers_into_visible_window", "count", "simulated vehicles removed inside the "
           "windows whose recordings lie in the visible window, where nothing is drawn (they "
           "vanish)", ("handover", "visible_to_ghost", "into_visible_window"), summary="sum"),
    Metric("relaxing_vehicles", "count", "vehicles that relaxed toward their recordings in the "
           "ghost cells (twin/cosim/core/relax.py)", ("handover", "relaxing", "vehicles"),
           summary="sum"),
    Metric("relaxing_accel_min_mps2", "m/s^2", "the lowest measured acceleration of a relaxing "
           "vehicle", ("handover", "relaxing", "accel_min_mps2"), produced_by=WITH_RELAXING),
    Metric("relaxing_accel_max_mps2", "m/s^2", "the highest measured acceleration of a relaxing "
           "vehicle", ("handover", "relaxing", "accel_max_mps2"), produced_by=WITH_RELAXING),
    Metric("relaxing_speed_min_mps", "m/s", "the lowest speed of a relaxing vehicle (below 0: "
           "it moved backwards)", ("handover", "relaxing", "speed_min_mps"),
           produced_by=WITH_RELAXING),
    Metric("relaxing_distance_p90_m", "m", "p90 over a relaxing vehicle's steps of its distance "
           "along the road from its recording", ("handover", "relaxing", "distance_m", "p90"),
           produced_by=WITH_RELAXING),
    Metric("relaxing_distance_max_m", "m", "the largest distance of a relaxing vehicle from its "
           "recording", ("handover", "relaxing", "distance_m", "max"),
           produced_by=WITH_RELAXING),
    Metric("handover_from_ghost_jump_max_m", "m", "the largest one-step position jump of a "
           "spawn from the ghost cells (the spawn against its ghost carried on at its speed)",
           ("handover", "ghost_to_visible", "position_jump_m", "max"),
           produced_by=WITH_GHOST_SPAWN),
    Metric("continuity_jump_p90_m", "m", "p90 over every pair of consecutive logged states "
           "of one recorded vehicle, whatever it is drawn as (ego, body, ghost), of the "
           "second's distance from the first carried on at their mean speed "
           "(twin/metrics/continuity.py)", ("continuity", "position_jump_m", "p90"),
           produced_by=WITH_PAIRS),
    Metric("continuity_jump_max_m", "m", "the largest of those position jumps",
           ("continuity", "position_jump_m", "max"), produced_by=WITH_PAIRS),
    Metric("continuity_speed_jump_max_mps", "m/s", "the largest change of speed between two "
           "consecutive logged states of one recorded vehicle beyond what 1 g allows in "
           "their time", ("continuity", "speed_jump_mps", "max"), produced_by=WITH_PAIRS),
    Metric("continuity_discontinuous", "count", "pairs of consecutive states of one recorded "
           "vehicle more than 0.5 m or 0.5 m/s apart beyond their motion",
           ("continuity", "discontinuous"), summary="sum"),
    Metric("tracks_ending_inside", "count", "tracks of a recorded vehicle that end inside the "
           "drawn region (not at its edge, the road's end, the episode's end or the "
           "recording's)", ("continuity", "tracks", "end", "inside"), summary="sum"),
    Metric("tracks_beginning_inside", "count", "tracks of a recorded vehicle that begin inside "
           "the drawn region", ("continuity", "tracks", "begin", "inside"), summary="sum"),
    Metric("bodies_beyond_region", "count", "simulated vehicles ever more than 50 m beyond the "
           "ghost windows' outer ends", ("continuity", "beyond_region", "vehicles"),
           summary="sum"),
    Metric("collisions", "count", "pairs of vehicles that touched (however often): two "
           "bodies, or a body on a ghost's recorded box",
           ("physics", "collisions"), summary="sum"),
    Metric("contacts", "count", "new contacts between vehicles, bodies or a body and a "
           "ghost (a pair that touches again counts again)", ("physics", "contacts"),
           summary="sum"),
    *(
        Metric(f"collisions_{cause}", "count", f"collisions of cause {cause.replace('_', ' ')} "
               "(twin/metrics/collisions.py)", ("physics", "collisions_by_cause", cause),
               summary="sum")
        for cause in COLUMNS
    ),
    Metric("spawns_inexact", "count", "impulse spawns whose speed one step later missed "
           "the recorded speed (carried on at the driver's command) by more than 0.5 %",
           ("physics", "spawns_above_0.5_percent"), summary="sum"),
    Metric("spawn_speed_error_max", "-", "the largest relative spawn speed error of the run",
           ("physics", "spawn_speed_error_max"), produced_by=WITH_SPAWN),
    Metric("spawns_waiting", "count", "vehicles refused a spawn for want of room (each once), "
           "tried again while in the visible window", ("counts", "spawns_skipped_overlap"),
           summary="sum"),
    Metric("ghosts_yielded", "count", "recorded vehicles made relaxing bodies behind a body "
           "they crowded (twin/cosim/core/handover.py)", ("counts", "ghosts_yielded"),
           summary="sum"),
    Metric("ghosts_held", "count", "recorded vehicles held back from appearing as ghosts "
           "where a spawn would not fit, each time (twin/cosim/core/handover.py)",
           ("counts", "ghosts_held"), summary="sum"),
    Metric("ghosts_braked", "count", "ghosts drawn braking for a body or anchored vehicle "
           "ahead they could not stop behind (twin/cosim/core/anchor.py)",
           ("counts", "ghosts_braked"), summary="sum"),
    Metric("stalled_across_lines", "count", "vehicles stopped across a lane line",
           ("counts", "stalled_across_lines"), summary="sum"),
    Metric("stalled_as_recorded", "count", "of those, the ones whose recording stood across "
           "the line with them as long (twin/metrics/fidelity.py)",
           ("counts", "stalled_as_recorded"), summary="sum"),
    Metric("ramp_vehicles", "count", "simulated vehicles seen on an on-ramp's acceleration "
           "lane (lane -5) in the visible window", ("merges", "ramp_vehicles"), summary="sum",
           produced_by=WITH_RAMP),
    Metric("merges", "count", "of those, the ones that merged into lane -4",
           ("merges", "merged"), summary="sum", produced_by=WITH_RAMP),
    Metric("merges_before_taper_end", "count", "merges done with the vehicle's front short "
           "of the end of the acceleration lane's taper", ("merges", "before_taper_end"),
           summary="sum", produced_by=WITH_RAMP),
    Metric("merges_waiting", "count", "ramp vehicles that never merged and stood on the "
           "acceleration lane at their last row, waiting for a gap", ("merges", "waiting"),
           summary="sum", produced_by=WITH_RAMP),
    Metric("merges_waiting_at_end", "count", "of those, the ones standing first in the "
           "ramp lane with their front within 20 m of the taper's end (where a driver waits: "
           "7.5 m and its standstill gap short of it): they reached their lane's end without "
           "merging",
           ("merges", "waiting_at_end"), summary="sum", produced_by=WITH_RAMP),
    Metric("merges_entered_past_end", "count", "ramp vehicles that merged, spawned on the "
           "acceleration lane with their front already past its taper's end (their "
           "recording merged that late): not in merges nor the shares",
           ("merges", "entered_past_end"), summary="sum", produced_by=WITH_RAMP),
    Metric("vehicles_off_road", "count", "vehicles that left the road",
           ("physics", "vehicles_off_road"), summary="sum"),
    Metric("ended_early", "count", "1 where the episode ended before its length (the ego "
           "left the map or data)", ("ended_early",), summary="sum",
           convert=lambda value: int(bool(value))),
    Metric("loop_s", "s", "wall time of the cosimulation loop", ("timing", "loop_s")),
    Metric("ego_mpg", "mpg", "fuel economy of the AV (the ego): total distance over total "
           "fuel, RAV4 model, miles per US gallon", _energy("ego", "mpg"), paired="higher"),
    Metric("followers_mpg", "mpg", "the same of its K = 5 followers (nearest behind it in "
           "its lane at the start)", _energy("followers", "mpg")),
    Metric("ego_and_followers_mpg", "mpg", "the same of the AV and its followers together",
           _energy("ego_and_followers", "mpg"), paired="higher"),
    Metric("window_mpg", "mpg", "the same of every simulated vehicle of the window",
           _energy("window", "mpg"), paired="higher"),
    Metric("avs_mpg", "mpg", "the same of the ego and the other vehicles with its controller",
           _energy("avs", "mpg"), produced_by=WITH_AV_SHARE),
    Metric("avs", "count", "vehicles with the ego's controller, the ego included",
           _energy("avs", "ids"), summary="none", convert=len),
    Metric("ego_and_followers_l_per_100km", "L/100 km", "the economy of the AV and its "
           "followers the other way up", _energy("ego_and_followers", "l_per_100km")),
    Metric("followers", "count", "followers counted", _energy("followers", "ids"),
           summary="none", convert=len),
    Metric("speed_std_behind_mps", "m/s", "standard deviation of each follower's speed over "
           "the episode (10 Hz), averaged over the followers",
           _control("speed_std_behind_mps"), paired="lower"),
    Metric("speed_std_window_mps", "m/s", "standard deviation of each simulated vehicle's "
           "speed over its time in the window (10 Hz), averaged over the vehicles weighted "
           "by their time: the window's oscillation, which a fleet of AVs is to lower",
           _control("speed_std_window_mps"), paired="lower"),
    Metric("wave_amplitude_behind_mps", "m/s", "max - min speed of each follower, averaged",
           _control("wave_amplitude_behind_mps"), paired="lower"),
    Metric("throughput_veh_per_h", "veh/h", "simulated vehicles passing the ego's starting "
           "point, per hour of episode", _control("throughput_veh_per_h"), paired="higher"),
    Metric("min_ttc_s", "s", "least time to collision of the AV (gap over closing speed "
           "while closing on its leader, 10 Hz)", _control("min_ttc_s"), paired="higher"),
    Metric("ttc_under_4s_share", "-", "share of the AV's samples with a time to collision "
           "under 4 s", _control("ttc_under_4s_share")),
    Metric("time_gap_median_s", "s", "median of the AV's gap over its speed (while faster "
           "than 1 m/s)", _control("time_gap_s", "median")),
    Metric("time_gap_p10_s", "s", "10th percentile of the same", _control("time_gap_s", "p10")),
    Metric("time_gap_p90_s", "s", "90th percentile of the same (large gaps invite cut-ins)",
           _control("time_gap_s", "p90")),
    Metric("accel_rms_mps2", "m/s^2", "RMS of the AV's acceleration (from its speed at 10 Hz)",
           _control("accel_rms_mps2"), paired="lower"),
    Metric("jerk_rms_mps3", "m/s^3", "RMS of the AV's jerk", _control("jerk_rms_mps3"),
           paired="lower"),
    Metric("infeasible_s", "s", "time the AV's acceleration was beyond the RAV4 "
           "powertrain's", _energy("ego", "infeasible_s"), summary="sum"),
    Metric("safety_override_s", "s", "time the baselines' safety layer (emergency braking) "
           "overrode the AV's controller", _control("safety_override_s"), summary="sum",
           produced_by=WITH_CONTROLLER),
    *(
        Metric(f"speed_field_rmse_lane_{lane}_mps", "m/s", f"the speed-field RMS error of "
               f"lane {lane}{' (HOV)' if lane == -1 else ''}",
               ("traffic", "speed_field", f"lane_{lane}", "rmse_mps"),
               produced_by=WITH_LANE_TRAFFIC)
        for lane in (-1, -2, -3, -4)
    ),
)  # fmt: skip

#: How ``twin eval`` summarises each metric it summarises: ``stats`` or ``sum``.
SUMMARISED = {m.name: m.summary for m in METRICS if m.summary != "none"}
#: The metrics the paired benchmark compares with ``human``: whether more is better.
PAIRED = {m.name: m.paired == "higher" for m in METRICS if m.paired is not None}


def flatten(figures: dict) -> dict:
    """A run's ``metrics.json`` document as one flat row of :data:`METRICS`."""
    return {metric.name: metric.read(figures) for metric in METRICS}


def document() -> str:
    """``docs/metrics.md``: the table of metrics, for people."""
    return (
        "# Metrics\n\n"
        "Every metric of a run, as `twin eval` writes it to `episodes.parquet` and summarises\n"
        "it, the paired benchmark compares it and the Gymnasium env reports it in\n"
        '`info["metrics"]`. The path in brackets is where the run\'s `metrics.json` holds it.\n'
        "Generated from `twin/metrics/table.py` by `python -m twin.metrics.table`; do not edit.\n\n"
        "Beside these, `metrics.json` holds a nested `lane_flows` section: the lane changes\n"
        "by lane pair, the net flow out of each lane by 200 m bin and where each change\n"
        "was made, simulated and recorded in the same moving window\n"
        "(`twin/metrics/lane_flow_fidelity.py`); `twin eval` sums it over the episodes\n"
        "into `summary.json`, `summary.md` and `fidelity.png`, and counts the changes by\n"
        "zone of the road (`twin/metrics/lane_change_zones.py`).\n\n"
        "It also holds a `continuity` section (`twin/metrics/continuity.py`): every\n"
        "recorded vehicle's rows in the log, whatever it is drawn as (the ego, a body\n"
        "inside or outside the visible window, a ghost), judged pair by pair: how far each\n"
        "state lies from the one before carried on at their mean speed, how much the speed\n"
        "changed beyond 1 g, by kind of pair (`visible>ghost`, `relaxing>ghost`, ...), the\n"
        "worst pair with its `record_id`, where each track begins and ends (the episode's\n"
        "start or end, the drawn region's edge, the road's end, the recording's own start\n"
        "or end, or `inside`: a seam), records drawn twice at once, and the bodies that\n"
        "were ever more than 50 m beyond the ghost windows.\n\n" + markdown_table()
    )


def section_head(title: str, first: str, columns) -> list[str]:
    """The lines that open a Markdown section of ``summary.md``: a blank line, the
    ``title`` as a heading, and a table's header with ``first`` then ``columns``."""
    return [
        "",
        f"## {title}",
        "",
        f"| {first} | " + " | ".join(columns) + " |",
        "|---|" + "---|" * len(columns),
    ]


def markdown_table() -> str:
    """The table of metrics as Markdown."""
    lines = [
        "| metric | unit | definition | produced by | in twin eval | paired vs human |",
        "|---|---|---|---|---|---|",
    ]
    for m in METRICS:
        summary = {"stats": "median, p90, mean", "sum": "sum", "none": "rows only"}[m.summary]
        paired = f"{m.paired} is better" if m.paired else "-"
        where = ".".join(str(k) for k in m.source)
        lines.append(
            f"| `{m.name}` | {m.unit} | {m.definition} (`{where}`) | {m.produced_by} | "
            f"{summary} | {paired} |"
        )
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    from twin.core.paths import REPO_ROOT

    (REPO_ROOT / "docs" / "metrics.md").write_text(document())
