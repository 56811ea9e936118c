import numpy as np
import pytest

from twin.traffic.models.idm import IDMParams, equilibrium_gap, idm_acceleration

PARAMS = IDMParams(
    desired_speed=33.0, time_headway=1.2, min_gap=2.0, max_accel=1.0, comfortable_decel=1.5
)


def test_free_road_reaches_the_desired_speed_and_not_beyond():
    assert idm_acceleration(np.array([0.0]), np.array([0.0]), np.array([np.inf]), PARAMS)[0] == 1.0
    assert idm_acceleration(np.array([33.0]), np.array([0.0]), np.array([np.inf]), PARAMS)[0] == 0.0
    assert idm_acceleration(np.array([35.0]), np.array([0.0]), np.array([np.inf]), PARAMS)[0] < 0


def test_equilibrium_gap_is_a_steady_state():
    v = np.linspace(1.0, 30.0, 30)
    gap = equilibrium_gap(v, PARAMS)
    assert np.allclose(idm_acceleration(v, v, gap, PARAMS), 0.0, atol=1e-12)
    assert equilibrium_gap(np.array([20.0]), PARAMS)[0] == pytest.approx(
        (2.0 + 20.0 * 1.2) / np.sqrt(1 - (20 / 33) ** 4)
    )


def test_standing_at_the_minimum_gap_is_at_rest_and_closer_brakes():
    assert idm_acceleration(np.array([0.0]), np.array([0.0]), np.array([2.0]), PARAMS)[0] == 0.0
    assert idm_acceleration(np.array([0.0]), np.array([0.0]), np.array([1.0]), PARAMS)[0] < 0
