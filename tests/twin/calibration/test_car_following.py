"""The car-following calibration against oracles: synthetic days made with known drivers
unlike the twin's defaults, whose parameters it must recover, for every model."""

from dataclasses import replace

import numpy as np
import pytest

from twin.calibration import car_following as calibration
from twin.calibration import following
from twin.calibration.car_following import Box, FitSettings
from twin.data import synth
from twin.data.ingest import ingest
from twin.data.store import TrajectoryStore
from twin.traffic.models import GIPPS, IDM

PARAMS = tuple(p.name for p in IDM.fitted)


def _oracle(folder, car_following: str, model):
    """Six minutes of the westbound wave driven by synth.OTHER_DRIVERS with
    ``car_following``, ingested; the runs, ``model``'s fits and each fitted follower's
    true parameters."""
    config = replace(
        synth.PRESET_B, minutes=6.0, seed=3, drivers=synth.OTHER_DRIVERS,
        car_following=car_following,
    )  # fmt: skip
    result = synth.synthesize(config)
    day = synth.write_i24_json(result, folder / "day.json")
    ingest([day], folder / "store", progress=False)
    store = TrajectoryStore(folder / "store")
    runs = following.following_runs(following.load_grid(store, "westbound"))
    fits = calibration.fit_followers(runs, model=model)
    vid = np.array([int(oid[10:], 16) for oid in store.trajectory_arrays["id"][fits.tid]])
    at = np.searchsorted(result.vid, vid)
    drivers = model.from_traits(result.drivers)
    truth = np.stack([getattr(drivers, p.name)[at] for p in model.fitted], axis=1)
    return runs, fits, truth


@pytest.fixture(scope="module")
def known(tmp_path_factory):
    """IDM drivers (as published) fitted as the twin's IDM."""
    return _oracle(tmp_path_factory.mktemp("oracle"), "idm-textbook", IDM)


@pytest.fixture(scope="module")
def known_gipps(tmp_path_factory):
    """Gipps drivers fitted as Gipps."""
    return _oracle(tmp_path_factory.mktemp("oracle-gipps"), "gipps", GIPPS)


def _errors(fits, truth) -> dict:
    error = calibration.median_relative_error(fits.params[fits.accepted], truth[fits.accepted])
    return dict(zip(fits.names, error, strict=True))


def test_calibration_recovers_known_drivers(known):
    _, fits, truth = known
    assert len(fits) >= 50
    assert fits.accepted.mean() >= 0.8
    error = _errors(fits, truth)
    assert error["time_headway"] <= 0.10
    assert error["min_gap"] <= 0.10
    assert error["max_accel"] <= 0.10
    assert error["comfortable_decel"] <= 0.25
    # and they are not the defaults the fit starts from
    assert np.median(truth[:, PARAMS.index("min_gap")]) > 2.5


def test_calibration_recovers_known_gipps_drivers(known_gipps):
    """The same oracle for a second model: Gipps' reaction time plays IDM's time
    headway, its most severe braking the comfortable deceleration.

    Gipps' maximum acceleration and desired speed act only through its free speed,
    which a follower reaches only when its leader pulls away: on following runs
    (this oracle's 54 followers) the fitted pairs replay the spacing as well as the
    true ones but are not the true ones (max_accel 1.0 against 1.7 m/s^2 by median),
    so they are not asserted; the calibrated behaviour takes the desired speed from
    free flow."""
    runs, fits, truth = known_gipps
    assert fits.names == tuple(p.name for p in GIPPS.fitted)
    assert len(fits) >= 50
    assert fits.accepted.mean() >= 0.8
    error = _errors(fits, truth)
    assert error["reaction_time"] <= 0.10
    assert error["min_gap"] <= 0.10
    assert error["decel"] <= 0.25
    assert np.median(truth[:, fits.names.index("min_gap")]) > 2.5
    # the fitted Gipps drivers replay their recordings, as the true ones do
    rows = np.flatnonzero(np.isin(runs.tid, fits.tid[fits.accepted]))
    sub = runs.take(rows)
    at = np.searchsorted(fits.tid, sub.tid)
    valid = sub.valid
    mean_gap = np.nanmean(np.where(valid, sub.gap, np.nan), axis=1)
    error = np.where(valid, calibration.replay(sub, fits.params[at], GIPPS) - sub.gap, 0.0)
    nrmse = np.sqrt((error**2).sum(axis=1) / valid.sum(axis=1)) / mean_gap
    assert np.median(nrmse) < 0.02


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
    default = Box.of(IDM).start
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
