"""Synthetic I-24 MOTION days: a multi-lane microsimulation with real stop-and-go waves.

The real I-24 MOTION files cannot be downloaded on the twin's machines, so the twin
ships a stand-in in exactly their JSON layout. Heterogeneous IDM drivers
(:mod:`twin.traffic.models.idm`, parameters per vehicle class from ``assets/``) with
acceleration noise drive four lanes of a road longer than the recorded range;
MOBIL-style lane changes take several seconds; the HOV lane (-1) is entered by
nobody and left by nobody (the double line of this corridor). Lanes may end (a lane
drop, an on-ramp's acceleration lane): their drivers leave them by a merging model of
the synthesiser's own (:mod:`twin.data.synth.lane_ends`). Waves are started
the way they start on a freeway, by a driver braking hard downstream
(:class:`Slowdown`); in dense traffic the braking propagates upstream as a
stop-and-go wave at the congested wave speed of the drivers, about
(s0 + length) / T, i.e. 4.5 to 5.5 m/s as measured on I-24.

Vehicle positions are recorded at the simulation step and resampled to the
camera rate (25 Hz) with a per-vehicle phase and small tracking noise.
"""

from twin.data.synth.config import (
    COMFORT_DECEL,
    Bottleneck,
    LaneDrop,
    OnRamp,
    Slowdown,
    SynthConfig,
)
from twin.data.synth.presets import (
    ALL_PRESETS,
    OTHER_DRIVERS,
    OTHER_LANE_CHANGES,
    PRESET_A,
    PRESET_B,
    PRESET_C,
    PRESET_D,
    PRESET_E,
    PRESET_S,
)
from twin.data.synth.recording import SynthResult, synthesize, write_i24_json
from twin.data.synth.simulation import Simulation

__all__ = [
    "ALL_PRESETS", "COMFORT_DECEL", "OTHER_DRIVERS", "OTHER_LANE_CHANGES", "PRESET_A",
    "PRESET_B", "PRESET_C", "PRESET_D", "PRESET_E", "PRESET_S", "Bottleneck", "LaneDrop",
    "OnRamp", "Simulation", "Slowdown", "SynthConfig", "SynthResult", "synthesize",
    "write_i24_json",
]  # fmt: skip
