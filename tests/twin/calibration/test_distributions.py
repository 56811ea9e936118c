"""The calibrated drivers' distributions: correlated log-normal draws, clipped, read back."""

import numpy as np
import pytest

from twin.calibration.distributions import ParameterDistribution


def test_parameter_distribution_draws_what_it_describes_and_round_trips():
    rng = np.random.default_rng(0)
    mean = np.log([30.0, 1.4, 2.5, 1.5, 2.0])
    sd = np.array([0.05, 0.2, 0.15, 0.2, 0.1])
    corr = np.eye(5)
    corr[1, 3] = corr[3, 1] = -0.6
    cov = corr * np.outer(sd, sd)
    params = np.exp(rng.multivariate_normal(mean, cov, size=4000))
    dist = ParameterDistribution.of(("v0", "T", "s0", "a", "b"), params)
    assert np.allclose(dist.mean_log, mean, atol=0.01)
    assert np.allclose(dist.sd_log, sd, rtol=0.05)
    drawn = dist.draw(20000, np.random.default_rng(1))
    logs = np.log(drawn)
    assert np.allclose(logs.mean(axis=0), mean, atol=0.01)
    assert np.corrcoef(logs.T)[1, 3] == pytest.approx(-0.6, abs=0.05)
    # clipped at 2 sd: nothing absurd
    assert np.all(np.abs(logs - dist.mean_log) <= 2 * dist.sd_log + 1e-9)
    again = ParameterDistribution.from_dict(dist.to_dict())
    assert np.allclose(again.mean_log, dist.mean_log, atol=1e-4)
    assert np.allclose(again.correlation, dist.correlation, atol=1e-4)
    # the same seed draws the same drivers
    assert np.array_equal(
        dist.draw(10, np.random.default_rng(5)), dist.draw(10, np.random.default_rng(5))
    )
