"""Newly spawned bodies settle in (twin/cosim/core/settle.py): a recording that becomes
a body where its driver would brake hard (inside IDM's desired gap, with room to slow
gently) brakes no harder than its comfortable deceleration."""

from tests.twin.cosim.scenes import EGO_X, rows_of, tid_of, vehicle
from twin.cosim.core import settle


def _catching_up(cosim):
    # a body 115 m behind the ego at 27 m/s and, in the rear ghost cell, a recording at
    # 30.5 m/s that enters the visible window about 25 m behind it: 3.5 m/s closing,
    # which 0.25 m/s^2 would take away, far inside IDM's desired gap at 30 m/s (73 m)
    sim = cosim(
        [vehicle(1, -2, EGO_X, 27.0), vehicle(2, -2, EGO_X - 115.0, 27.0),
         vehicle(3, -2, EGO_X - 115.0 - 25.0 - 4.7 - 4.0, 30.5)],
        world="kinematic", t_max=6.0,
    )  # fmt: skip
    sim.run()
    return sim


def test_a_recording_spawned_inside_its_drivers_desired_gap_brakes_gently(cosim):
    sim = _catching_up(cosim)
    rows = rows_of(sim, tid_of(sim, 3))
    assert len(rows), "the recording never became a body"
    first = rows["time"].min()
    early = rows[rows["time"] <= first + settle.SETTLE_S]
    comfortable = sim.config.traffic.drivers.comfortable_decel
    # without settling in, IDM braked at up to 7.6 m/s^2
    assert early["accel_cmd"].min() >= -comfortable - 1e-9
    assert sim.counters.contacts == 0
