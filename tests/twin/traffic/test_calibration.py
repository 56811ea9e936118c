"""The car-following calibration against oracles: synthetic days made with known drivers
unlike the twin's defaults, whose parameters it must recover."""

from dataclasses import replace

import numpy as np
import pytest

from twin.calibration import fitting as calibration
from twin.calibration import following
from twin.calibration.fitting import PARAMS, FitSettings, ParameterDistribution
from twin.data import synth
from twin.data.ingest import ingest
from twin.data.store import TrajectoryStore


@pytest.fixture(scope="module")
def known(tmp_path_factory):
    """Six minutes of the westbound wave driven by synth.OTHER_DRIVERS, ingested; the runs,
    the fits and each fitted follower's true parameters."""
    folder = tmp_path_factory.mktemp("oracle")
    config = replace(synth.PRESET_B, minutes=6.0, seed=3, drivers=synth.OTHER_DRIVERS)
    result = synth.synthesize(config)
    day = synth.write_i24_json(result, folder / "day.json")
    ingest([day], folder / "store", progress=False)
    store = TrajectoryStore(folder / "store")
    runs = following.following_runs(following.load_grid(store, "westbound"))
    fits = calibration.fit_followers(runs)
    vid = np.array([int(oid[10:], 16) for oid in store.trajectory_arrays["id"][fits.tid]])
    at = np.searchsorted(result.vid, vid)
    truth = np.stack([getattr(result.drivers, name)[at] for name in PARAMS], axis=1)
    return runs, fits, truth


def test_calibration_recovers_known_drivers(known):
    _, fits, truth = known
    assert len(fits) >= 50
    assert fits.accepted.mean() >= 0.8
    error = dict(
        zip(
            PARAMS,
            calibration.median_relative_error(fits.params[fits.accepted], truth[fits.accepted]),
            strict=True,
        )
    )
    assert error["time_headway"] <= 0.10
    assert error["min_gap"] <= 0.10
    assert error["max_accel"] <= 0.10
    assert error["comfortable_decel"] <= 0.25
    # and they are not the defaults the fit starts from
    assert np.median(truth[:, PARAMS.index("min_gap")]) > 2.5


def test_a_recording_replayed_through_its_own_fitted_drivers_reproduces_itself(known):
    runs, fits, truth = known
    rows = np.flatnonzero(np.isin(runs.tid, fits.tid[fits.accepted]))
    sub = runs.take(rows)
    at = np.searchsorted(fits.tid, sub.tid)
    valid = sub.valid
    mean_gap = np.nanmean(np.where(valid, sub.gap, np.nan), axis=1)

    def nrmse(params):
        error = np.where(valid, calibration.replay(sub, params) - sub.gap, 0.0)
        return np.sqrt((error**2).sum(axis=1) / valid.sum(axis=1)) / mean_gap

    fitted, true = nrmse(fits.params[at]), nrmse(truth[at])
    assert np.median(fitted) < 0.02
    assert np.quantile(fitted, 0.9) < 0.05
    # the model fitted is the model that made the data: its true parameters fit too
    assert np.median(true) < 0.05
    # and the defaults do not
    default = np.array([calibration.START[name] for name in PARAMS])
    assert np.median(nrmse(np.tile(default, (len(sub), 1)))) > 3 * np.median(fitted)


def test_followers_of_a_wrong_leader_are_rejected_as_poor(known):
    runs, fits, _ = known
    rows = np.flatnonzero(np.isin(runs.tid, fits.tid[fits.accepted]))[:40]
    sub = runs.take(rows)
    # every follower is given the leader of another run, shifted to its starting gap
    other = np.roll(np.arange(len(sub)), 7)
    shift = sub.x_lead[:, :1] - sub.x_lead[other, :1]
    width = min(sub.x.shape[1], int(sub.steps[other].min()))
    wrong = replace(
        sub,
        steps=np.minimum(sub.steps, width),
        x=sub.x[:, :width],
        speed=sub.speed[:, :width],
        x_lead=sub.x_lead[other, :width] + shift,
        speed_lead=sub.speed_lead[other, :width],
    )
    bad = calibration.fit_followers(wrong, FitSettings(stop_speed=1e3, moving_speed=0.0))
    assert len(bad) == len(np.unique(sub.tid))
    assert bad.accepted.mean() < 0.3
    assert (bad.poor | bad.at_bound[:, 1:].any(axis=1))[~bad.accepted].all()


def test_followers_that_never_crossed_a_wave_are_not_fitted(known):
    runs, _, _ = known
    steady = runs.take(np.flatnonzero(np.nanmin(runs.speed, axis=1) > 15.0))
    assert len(steady) > 0
    fits = calibration.fit_followers(steady)
    assert len(fits) == 0
    assert fits.uninformative == np.unique(steady.tid).size


def test_parameter_distribution_draws_what_it_describes_and_round_trips():
    rng = np.random.default_rng(0)
    mean = np.log([30.0, 1.4, 2.5, 1.5, 2.0])
    sd = np.array([0.05, 0.2, 0.15, 0.2, 0.1])
    corr = np.eye(5)
    corr[1, 3] = corr[3, 1] = -0.6
    cov = corr * np.outer(sd, sd)
    params = np.exp(rng.multivariate_normal(mean, cov, size=4000))
    dist = ParameterDistribution.of(params)
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


def test_the_mobil_threshold_matches_the_recorded_count_and_stops_above_resisted_gains():
    # two drivers, five decisions each, one way: driver 1's incentive rises to 2.0 m/s^2
    gains = np.array([0.1, 0.5, 2.0, 0.5, 0.1, 0.2, 0.9, 0.2, 1.5, 0.2])
    incentives = calibration.Incentives(
        tid=np.repeat([1, 2], 5),
        decision=np.tile(np.arange(5), 2),
        direction=np.ones(10, dtype=np.int8),
        gain=gains,
        possible=np.ones(10, dtype=bool),
    )
    assert incentives.changes(0.3) == 3  # onsets: 1 at 0.5, 2 at 0.9 and again at 1.5
    fit = calibration.fit_threshold(incentives, 1)
    assert fit["predicted"] == 1 and 1.5 <= fit["threshold"] < 2.0 + 1e-6
    # none recorded: just above the largest incentive resisted, not the top of the range
    none = calibration.fit_threshold(incentives, 0)
    assert none["predicted"] == 0 and none["threshold"] == pytest.approx(2.0, abs=1e-3)
