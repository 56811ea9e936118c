"""The MOBIL threshold fitted to a recording's lane-change count."""

import numpy as np
import pytest

from twin.calibration.lane_changes import Incentives, fit_threshold


def test_the_mobil_threshold_matches_the_recorded_count_and_stops_above_resisted_gains():
    # two drivers, five decisions each, one way: driver 1's incentive rises to 2.0 m/s^2
    gains = np.array([0.1, 0.5, 2.0, 0.5, 0.1, 0.2, 0.9, 0.2, 1.5, 0.2])
    incentives = Incentives(
        tid=np.repeat([1, 2], 5),
        decision=np.tile(np.arange(5), 2),
        direction=np.ones(10, dtype=np.int8),
        gain=gains,
        possible=np.ones(10, dtype=bool),
        x=np.tile(np.arange(5) * 100.0, 2),
        lane=np.full(10, -3),
    )
    assert incentives.changes(0.3) == 3  # onsets: 1 at 0.5, 2 at 0.9 and again at 1.5
    fit = fit_threshold(incentives, 1)
    assert fit["predicted"] == 1 and 1.5 <= fit["threshold"] < 2.0 + 1e-6
    # none recorded: just above the largest incentive resisted, not the top of the range
    none = fit_threshold(incentives, 0)
    assert none["predicted"] == 0 and none["threshold"] == pytest.approx(2.0, abs=1e-3)
    # judged only short of 200 m (where 2.0 and 1.5 are resisted no more): 0.5 and 0.9
    where = incentives.x < 200.0
    assert incentives.changes(0.3, where) == 2
    assert fit_threshold(incentives, 0, where=where)["threshold"] == pytest.approx(0.9, abs=1e-3)


def test_drawn_drivers_judge_the_recorded_scenes_each_as_its_own(calibrated_wave_store):
    from twin.calibration import following
    from twin.calibration.calibrate import (
        CalibrationSettings,
        _median_driver,
        read_calibration,
    )
    from twin.calibration.distributions import ParameterDistribution
    from twin.calibration.lane_changes import drawn_drivers, recorded_incentives
    from twin.traffic.mobil import MOBILParams
    from twin.traffic.models import car_following_model

    model = car_following_model("idm")
    doc = read_calibration(calibrated_wave_store)
    dist = ParameterDistribution.from_dict(
        doc["roads"]["westbound"]["car_following"]["distributions"]["all"]
    )
    grid = following.load_grid(calibrated_wave_store, "westbound")
    tids, drawn = drawn_drivers(grid.tid, dist, model)
    assert np.array_equal(tids, np.unique(grid.tid))
    again = drawn_drivers(grid.tid[::-1], dist, model)[1]  # one fixed draw per vehicle
    assert all(np.array_equal(getattr(drawn, p.name), getattr(again, p.name)) for p in model.fitted)
    assert np.std(drawn.time_headway) > 0.0
    # every vehicle given the median driver: the same incentives as one shared driver
    median = _median_driver(model, dist)
    same = model.make(**{p.name: np.full(tids.size, getattr(median, p.name)) for p in model.fitted})
    one = recorded_incentives(grid, model, median, MOBILParams(), every=2.0)
    each = recorded_incentives(grid, model, median, MOBILParams(), every=2.0, drivers=(tids, same))
    assert np.allclose(one.gain, each.gain) and np.array_equal(one.possible, each.possible)
    # drawn drivers judge differently
    spread = recorded_incentives(
        grid, model, median, MOBILParams(), every=2.0, drivers=(tids, drawn)
    )
    assert not np.allclose(one.gain, spread.gain)
    with pytest.raises(ValueError, match="threshold_drivers"):
        CalibrationSettings(threshold_drivers="mean")
