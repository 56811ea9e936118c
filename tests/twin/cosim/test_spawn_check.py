"""The spawn check (twin/cosim/core/step.py ``_checks``): one step after its impulse a
spawned vehicle's speed is what its driver commanded, up to what its powertrain gives:
a driver wanting more than the engine has at speed is no inexact spawn, braking harder
than the tyres hold is."""

import numpy as np
import pytest

from tests.twin.cosim.scenes import EGO_X, rows_of, tid_of, vehicle
from twin.core import i24
from twin.cosim.core.step import _checks
from twin.physics import kernels

DT = 0.1


def _car(speed: float):
    bo = kernels.bodies(1, 1)
    bo.valid[0, 0], bo.top[0] = True, 1
    bo.mass[0, 0], bo.eff_mass[0, 0], bo.max_power[0, 0] = 1500.0, 1550.0, 100e3
    bo.mu[0, 0], bo.driven_share[0, 0] = 0.9, 0.5
    bo.drag_area[0, 0], bo.rolling[0, 0], bo.lane[0, 0] = 0.7, 0.01, -2
    bo.speed[0, 0] = speed
    return bo


def _error(speed: float, command: float, achieved: float) -> float:
    bo = _car(speed + achieved * DT)
    just, spawn_speed = np.ones((1, 1), bool), np.full((1, 1), speed)
    errors, count = np.zeros((1, 4)), np.zeros(1, np.int64)
    _checks(0, bo, just, spawn_speed, np.zeros((1, 1), bool), np.full((1, 1), command),
            errors, count, np.zeros(1, np.int64), DT, np.zeros((0, 4)))  # fmt: skip
    assert count[0] == 1 and not just[0, 0]
    return errors[0, 0]


def test_the_powertrains_limit_is_no_spawn_error():
    limit = kernels.drive_limit(0, 0, _car(30.0), 30.0)
    assert 0.0 < limit < 2.5  # 100 kW at 30 m/s
    assert _error(30.0, 2.5, limit) == pytest.approx(0.0, abs=1e-12)
    assert _error(30.0, 1.0, 1.0) == pytest.approx(0.0, abs=1e-12)  # within it: as commanded


def test_braking_harder_than_the_tyres_hold_is_a_spawn_error():
    grip = 0.9 * kernels.GRAVITY
    assert _error(30.0, -15.0, -grip) == pytest.approx((15.0 - grip) * DT / 30.0)
    assert _error(30.0, -15.0, -grip) > 0.005


def test_the_limit_is_what_the_kinematic_world_gives_at_full_throttle():
    bo = _car(30.0)
    limit = kernels.drive_limit(0, 0, bo, 30.0)
    accel = np.full((1, 1), 5.0)
    zeros = np.zeros((1, 1))
    profile = kernels.Profile(1, np.array([-1e4, 1e4]), np.zeros(2), np.zeros(2), 2e4)
    kernels.integrate(0, bo, accel, zeros, zeros, zeros, profile, DT)
    assert bo.speed[0, 0] == pytest.approx(30.0 + limit * DT, rel=1e-12)


def test_lane_5s_band_off_an_on_ramp_is_the_shoulder_off_the_road():
    spans = np.array([[-100.0, -70.0, 50.0, 145.0]])  # opening, gore, taper, end
    for x, lane, off in ((100.0, -5, 0), (400.0, 0, 1)):
        bo = _car(20.0)
        bo.lane[0, 0], bo.x[0, 0] = -5, x
        off_road, off_count = np.zeros((1, 1), bool), np.zeros(1, np.int64)
        _checks(0, bo, np.zeros((1, 1), bool), np.zeros((1, 1)), off_road, np.zeros((1, 1)),
                np.zeros((1, 4)), np.zeros(1, np.int64), off_count, DT, spans)  # fmt: skip
        assert (bo.lane[0, 0], off_count[0]) == (lane, off)


def _beside(n: int, lane: int, y: float, x: float, speed: float):
    """A constant-speed document ``y`` [m] across the road, in ``lane`` nonetheless."""
    doc = vehicle(n, lane, x, speed)
    doc["y_position"] = [y / i24.FT] * len(doc["y_position"])
    return doc


def test_a_recording_beside_another_in_its_lane_waits_for_room_not_an_emergency_stop(cosim):
    # two recorded vehicles side by side in lane -3 (footprints 2.6 m apart across, clear
    # of each other, as a sub-lane model drives them), the rear one's front 3 m past the
    # other's back, at 15 m/s, reached by the visible window's front edge: the traffic
    # core sees them one behind the other in the lane, so the rear one spawned there
    # would brake as an emergency, harder than its tyres hold (a spawn 2.4 % off on a
    # SUMO SL2015 day; here, in the kinematic world at 100 Hz, it ran into the other); it
    # waits for room instead, counted, and every spawn is exact
    ahead = _beside(2, -3, 11.4, EGO_X + 165.0, 15.0)
    rear = _beside(3, -3, 14.0, EGO_X + 163.5, 15.0)
    sim = cosim([vehicle(1, -2, EGO_X, 20.0), ahead, rear], world="kinematic", t_max=6.0)
    sim.run()
    assert sim.counters.skipped_overlap == 1  # the rear one, refused once and waiting
    first = rows_of(sim, tid_of(sim, 3)).iloc[0]  # spawned once the other drove on
    other = rows_of(sim, tid_of(sim, 2)).set_index("time").loc[first["time"]]
    assert other["x"] - (first["x"] + 15 * i24.FT) >= 0.3  # 15 ft long, as the documents
    errors = sim.counters.spawn_speed_error  # the ego's, at the reset, and the two
    assert len(errors) == 3 and max(errors) <= 0.005
    assert sim.counters.contacts == 0  # spawned at once, it ran into the other
