"""Gipps' model, the second driver model of the test data: its free acceleration, its
safe speed, and a synthetic day driven by it."""

from dataclasses import replace

import numpy as np
import pytest

from twin.data import synth
from twin.traffic.models.gipps import GippsParams, gipps_acceleration

DRIVER = GippsParams(desired_speed=30.0, max_accel=1.5, decel=3.0, reaction_time=0.8, min_gap=2.0)


def test_free_road_acceleration_is_gipps_and_vanishes_at_the_desired_speed():
    v = np.array([0.0, 10.0, 30.0])
    acc = gipps_acceleration(v, np.zeros(3), np.full(3, np.inf), DRIVER)
    ratio = v / 30.0
    expected = 2.5 * 1.5 * (1 - ratio) * np.sqrt(0.025 + ratio)
    assert np.allclose(acc, expected)
    assert acc[2] == pytest.approx(0.0)


def test_safe_speed_stops_behind_a_standing_leader_and_holds_at_the_minimum_gap():
    # at the minimum gap behind a standing leader: stay stopped
    assert gipps_acceleration([0.0], [0.0], [2.0], DRIVER)[0] == pytest.approx(0.0)
    # closing fast on a standing leader 20 m ahead: brake
    assert gipps_acceleration([20.0], [0.0], [20.0], DRIVER)[0] < -3.0
    # steady following: some gap where the safe speed equals the speed
    gaps = np.linspace(3.0, 80.0, 400)
    acc = gipps_acceleration(np.full(400, 20.0), np.full(400, 20.0), gaps, DRIVER)
    assert acc[0] < 0 and acc[-1] > 0
    equilibrium = gaps[np.argmin(np.abs(acc))]
    # about 1.5 reaction times at 20 m/s, plus the minimum gap, for equal braking beliefs
    assert equilibrium == pytest.approx(2.0 + 20.0 * 0.8 * 1.5, rel=0.25)


def test_a_day_driven_by_gipps_drivers_differs_from_idm_and_has_no_collision():
    config = replace(synth.PRESET_S, minutes=1.0, warmup=120.0, drivers=synth.OTHER_DRIVERS)
    gipps = synth.synthesize(replace(config, car_following="gipps"))
    idm = synth.synthesize(config)
    assert gipps.collisions == 0 and len(gipps.vid) > 100
    assert not np.array_equal(gipps.tracks[0][1], idm.tracks[0][1])
    with pytest.raises(ValueError, match="car_following"):
        replace(config, car_following="ovm")
