"""The synthetic days the twin ships and tests with: presets A and B (the paper's
scenarios), C (a westbound morning like the real one), S (test data for the
calibration), D and E (test data with lane changes made for reasons beyond the
segment: a lane drop, an on-ramp), and drivers unlike the class table's."""

from dataclasses import replace

from twin.core import i24
from twin.core.i24 import SCENARIO_TIME, Road
from twin.data.synth.config import Bottleneck, LaneDrop, OnRamp, Slowdown, SynthConfig
from twin.traffic.drivers import DriverDistribution

#: Scenario A of the paper: eastbound, light free-flowing traffic (I-24 eastbound is
#: free-flowing in the morning, 59 to 80 mph).
PRESET_A = SynthConfig(
    road=Road.EASTBOUND,
    anchor=SCENARIO_TIME,
    start=SCENARIO_TIME - 380.0,
    flow=(450.0, 900.0, 850.0, 650.0),
)

#: Scenario B of the paper: westbound (inbound), a stop-and-go wave arriving in the HOV
#: lane: the vehicle at x = 700 m in lane -1 at 06:45:50 is at cruise speed, meets the
#: wave's front a few seconds later and is stopped within the 30 s episode, while lanes
#: -3 and -4 are only mildly disturbed.
PRESET_B = SynthConfig(
    road=Road.WESTBOUND,
    anchor=SCENARIO_TIME,
    start=SCENARIO_TIME - 380.0,
    flow=(2300.0, 2100.0, 1600.0, 1300.0),
    slowdowns=(
        Slowdown(t=-560.0, x=2500.0, lanes=(-1, -2), speed=3.0, duration=15.0),
        Slowdown(t=-285.0, x=2450.0, lanes=(-1,), speed=0.0, duration=20.0),
        Slowdown(t=-285.0, x=2450.0, lanes=(-2,), speed=6.0, duration=10.0),
        Slowdown(t=-285.0, x=2450.0, lanes=(-3, -4), speed=22.0, duration=8.0),
        Slowdown(t=0.0, x=2500.0, lanes=(-1, -2), speed=2.0, duration=15.0),
        Slowdown(t=200.0, x=2450.0, lanes=(-1,), speed=4.0, duration=12.0),
    ),
)

PRESETS = {"A": PRESET_A, "B": PRESET_B}  # the embedded default data

#: Test data unlike the default data, for calibration and fidelity (issue 17; preset
#: "S", for its slowdowns): twenty minutes westbound, the HOV lane closed, stop-and-go in
#: the three other lanes (a driver brakes nearly to a stop downstream every 150 s).
PRESET_S = SynthConfig(
    road=Road.WESTBOUND,
    anchor=SCENARIO_TIME,
    start=SCENARIO_TIME - 600.0,
    minutes=20.0,
    flow=(0.0, 2000.0, 1900.0, 1700.0),
    slowdowns=tuple(
        Slowdown(t=-700.0 + 150.0 * k, x=2450.0, lanes=(-2, -3, -4), speed=2.0, duration=12.0)
        for k in range(13)
    ),
)

#: Drivers unlike the class table's: longer headways, harder acceleration, larger
#: standstill gaps, firmer and varied braking.
OTHER_DRIVERS = DriverDistribution(
    min_gap=3.0,
    min_gap_sd=0.5,
    comfortable_decel=2.5,
    comfortable_decel_sd=0.4,
    time_headway_scale=1.4,
    max_accel_scale=1.5,
)

#: Lane changing unlike the default data's: more polite, a higher threshold, decisions
#: half as often.
OTHER_LANE_CHANGES = {"politeness": 0.5, "change_threshold": 0.6, "decision_interval": 4.0}

#: The drivers of preset C: the other drivers with time gaps x 1.35 (not 1.4): longer
#: than the class table's, firmer acceleration (x 1.5), larger standstill gaps (3 +- 0.5
#: m) and varied braking (2.5 +- 0.4 m/s^2). With them the queue behind the
#: bottleneck carries its waves upstream at 4.5 to 5 m/s, the corridor's measured front
#: speeds.
MORNING_DRIVERS = replace(OTHER_DRIVERS, time_headway_scale=1.35)

#: Preset C, a westbound morning whose waves are like the real 2022-11-22 morning's
#: (issue 18; ``twin data waves`` compares them): 30 minutes from 06:35:50, traffic in
#: every lane near what its drivers can carry, and 1.2 km downstream of the recorded
#: range a 200 m stretch (a merge) that drivers take at their own speed (26 +- 2 m/s),
#: a few of them (1 in 200, spread evenly) hesitantly at 4.5 m/s. Each hesitant driver
#: holds up its lane; the queue behind it leaves as a stop-and-go wave that travels
#: upstream through the recorded range. No driver is made to brake: the waves come from
#: the drivers. Heavy vehicles are a third of the class table's whole-day share in lanes
#: -2 to -4 (a commuter peak; with the table's share, their slow starts break lanes -3
#: and -4 into short shallow waves: front to tail 14 to 18 s against the real 29 to
#: 32 s). Lane changes are rarer than in the other presets (threshold 1.5 m/s^2,
#: decisions every 4 s) and gentler (into gaps the new follower takes braking at most
#: 1 m/s^2), and the HOV lane is closed by its double line, as everywhere.
PRESET_C = SynthConfig(
    road=Road.WESTBOUND,
    anchor=SCENARIO_TIME,
    start=SCENARIO_TIME - 600.0,
    minutes=30.0,
    flow=(1900.0, 1900.0, 1850.0, 1800.0),
    warmup=900.0,
    downstream=2500.0,
    bottleneck=Bottleneck(
        x=i24.SEGMENT_LENGTH + 600.0 + 1200.0,
        length=200.0,
        speed=26.0,
        speed_sd=2.0,
        slow_share=0.005,
        slow_speed=4.5,
    ),
    heavy_factor=(0.3, 0.3, 0.3),
    drivers=MORNING_DRIVERS,
    change_threshold=1.5,
    decision_interval=4.0,
    safe_decel=1.0,
)

#: Preset D, test data with strategic lane changes (issue 30): preset C's morning without
#: its bottleneck, but with lanes -3 and -4 ending 300 m past the segment's downstream
#: end (MM 60.6 westbound), inside the recorded range: four lanes become two (the HOV
#: lane and lane -2). Signed well ahead, their drivers start to leave them 400 to 1200 m
#: before the end per lane to cross, inside the segment; those of lane -4 twice. Lane -2
#: takes more than it discharges through the merge (its drivers make room for the
#: mergers), so a queue grows upstream of the drop in lanes -2 to -4 and the HOV lane
#: flows.
PRESET_D = replace(
    PRESET_C,
    flow=(1700.0, 850.0, 550.0, 400.0),
    bottleneck=None,
    lane_drop=LaneDrop(x=i24.SEGMENT_LENGTH + 300.0, lanes=(-3, -4)),
    merge_lookahead=(400.0, 1200.0),
)

#: Preset E, test data with strategic lane changes (issue 30): preset C's morning with
#: the westbound Old Hickory Blvd on-ramp, whose acceleration lane beside lane -4 ends
#: at MM 61.51 (145 m into the segment) and carries 600 veh/h. The ramp's vehicles are
#: recorded on the acceleration lane until they are in lane -4 (``twin data ingest``
#: keeps those samples as lane -5, where they lie within the map's lane there).
PRESET_E = replace(
    PRESET_C,
    on_ramp=OnRamp(
        x_start=-250.0,
        x_end=(i24.SEGMENT_END_MM - 61.51) * i24.MILE,
        flow=600.0,
    ),
)

#: Every preset ``twin data synth`` offers.
ALL_PRESETS = {**PRESETS, "C": PRESET_C, "S": PRESET_S, "D": PRESET_D, "E": PRESET_E}
