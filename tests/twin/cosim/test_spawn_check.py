"""The spawn check (twin/cosim/core/step.py ``_checks``): one step after its impulse a
spawned vehicle's speed is what its driver commanded, up to what its powertrain gives:
a driver wanting more than the engine has at speed is no inexact spawn, braking harder
than the tyres hold is."""

import numpy as np
import pytest

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
