"""Behaviour modes: the paper's drivers, drivers drawn from a store's calibration, and
each vehicle driving as fitted to its own recording with its recorded lane changes."""

import json
import shutil
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from twin.calibration.calibrate import read_fits
from twin.cosim.behaviour import Behaviour, BehaviourError, resolve
from twin.cosim.config import SCENARIO_B, ConfigError
from twin.cosim.cosimulator import Cosimulator
from twin.data.empirical import EmpiricalTraffic
from twin.data.store import TrajectoryStore
from twin.metrics import fidelity as metrics
from twin.traffic.models import IDM


@pytest.fixture
def calibrated_store(calibrated_wave_store) -> TrajectoryStore:
    return calibrated_wave_store


PARAMS = tuple(p.name for p in IDM.fitted)


def _episode(store, built_map, behaviour, seconds=3.0):
    config = replace(SCENARIO_B, behaviour=behaviour, t_max=seconds)
    sim = Cosimulator(config, EmpiricalTraffic(store), built_map)
    sim.reset()
    while not sim.done:
        sim.step()
    return sim


def test_an_unknown_behaviour_or_an_uncalibrated_store_is_named(wave_store, built_map):
    with pytest.raises(ConfigError, match="behaviour must be one of paper, calibrated"):
        replace(SCENARIO_B, behaviour="wild")
    with pytest.raises(BehaviourError, match="twin calibrate"):
        Behaviour("calibrated", wave_store, "westbound", 0)
    # the paper's behaviour needs no calibration
    assert (
        Behaviour("paper", wave_store, "westbound", 0).drivers(
            np.arange(3), np.zeros(3, int), np.full(3, -2)
        )
        == {}
    )


def test_calibrated_drivers_are_drawn_from_the_calibration(calibrated_store, built_map):
    sim = _episode(calibrated_store, built_map, "calibrated")
    try:
        ids = sim.manager.ids
        params = sim.manager.params(ids)
        doc_threshold = sim.behaviour.threshold
        assert np.all(params["threshold"] == doc_threshold)
        # drawn per vehicle (not the paper's single decel), within 2 sd of the fit
        dist = sim.behaviour.distributions["all"]
        decel = np.log(params["comfortable_decel"])
        j = PARAMS.index("comfortable_decel")
        assert np.unique(params["comfortable_decel"]).size > 1
        assert np.all(np.abs(decel - dist.mean_log[j]) <= 2 * dist.sd_log[j] + 1e-9)
        # every vehicle keeps its own desired speed (not vel_default)
        assert np.unique(np.round(sim.base_speeds(ids), 6)).size > 1
    finally:
        sim.close()
    again = _episode(calibrated_store, built_map, "calibrated")
    try:
        assert np.array_equal(again.manager.params(ids)["time_headway"], params["time_headway"])
    finally:
        again.close()


def test_recorded_drivers_get_their_own_fits_and_no_mobil(calibrated_store, built_map):
    sim = _episode(calibrated_store, built_map, "recorded")
    try:
        fits = read_fits(calibrated_store)
        fits = fits[fits["accepted"]].set_index("tid")
        ids = sim.manager.ids
        tids = sim.tids
        own = np.isin(tids, fits.index.to_numpy())
        assert own.sum() >= 3
        params = sim.manager.params(ids[own])
        for name in PARAMS[1:]:
            assert np.allclose(params[name], fits.loc[tids[own], name].to_numpy())
        assert not sim.manager.auto_lane_change(ids).any()
    finally:
        sim.close()


def test_slow_spells_are_paired_and_timed():
    t = np.arange(0.0, 60.0, 0.1)
    recorded = {"t": 1000.0 + t, "x": 20.0 * t, "speed": np.where((t > 10) & (t < 30), 2.0, 20.0)}
    sim_speed = np.where((t > 12) & (t < 35), 2.0, 20.0)
    rows = pd.DataFrame({"time": t, "x": 20.0 * t, "speed": sim_speed})
    timing = metrics.slow_spell_timing(rows, recorded, 1000.0)
    (spell,) = timing["spells"]
    assert spell["begin_difference_s"] == pytest.approx(2.0, abs=0.11)
    assert spell["end_difference_s"] == pytest.approx(5.0, abs=0.11)
    errors = metrics.ego_position_errors(rows.assign(x=20.0 * t + 3.0), recorded, 1000.0)
    assert errors["30s"] == pytest.approx(3.0) and errors["end"] == pytest.approx(3.0)
    assert errors["60s"] is None or errors["60s"] == pytest.approx(3.0)


def test_a_vehicle_straddling_a_line_at_a_standstill_is_counted_as_stalled():
    t = np.arange(0.0, 10.0, 0.1)
    line = 2 * 3.6576  # between lanes -1 and -2
    rows = pd.DataFrame(
        {
            "id": np.r_[np.zeros(t.size), np.ones(t.size)],
            "y": np.r_[np.full(t.size, line), np.full(t.size, 1.5 * 3.6576)],
            "speed": np.zeros(2 * t.size),
        }
    )
    assert metrics.stalled_across_lines(rows, 0.1) == 1
    rows.loc[rows["id"] == 0, "speed"] = 5.0  # moving across: a lane change, not a stall
    assert metrics.stalled_across_lines(rows, 0.1) == 0


class _StandingRecording:
    """Recording ``tid`` stands across the line between lanes -1 and -2 until ``until``
    [s]; recording 2 drives lane -2's centre."""

    def __init__(self, until):
        self.until = until

    def recorded_states(self, road, tids, times):
        tids, times = np.asarray(tids), np.asarray(times)
        y = np.where(tids == 1, 2 * 3.6576, 1.5 * 3.6576)
        speed = np.where((tids == 1) & (times - 1000.0 < self.until), 0.0, 5.0)
        return np.ones(tids.size, bool), np.zeros(tids.size), y, speed


def test_a_stall_is_as_recorded_only_where_the_recording_stood_across_the_line_as_long():
    # on SUMO's days sub-lane drivers jam across the lines for minutes (test family day
    # 1001: three recordings stand across one for all 120 s); a vehicle spawned at its
    # recorded place stands there with its recording, which the twin did not cause
    t = np.arange(0.0, 10.0, 0.1)
    line = 2 * 3.6576
    rows = pd.DataFrame(
        {
            "time": np.r_[t, t],
            "id": np.r_[np.zeros(t.size), np.ones(t.size)],
            "tid": np.r_[np.ones(t.size), np.full(t.size, 2)],
            "y": np.full(2 * t.size, line),
            "speed": np.zeros(2 * t.size),
        }
    )
    assert metrics.stalled_across_lines(rows, 0.1) == 2
    # vehicle 0's recording stands there as long; vehicle 1's drives its lane's centre
    assert metrics.stalled_as_recorded(rows, 0.1, _StandingRecording(10.0), 1000.0, "w") == 1
    # vehicle 0's recording moves on after 3 s: a 7 s stall the twin made
    assert metrics.stalled_as_recorded(rows, 0.1, _StandingRecording(3.0), 1000.0, "w") == 0
    # a vehicle with no recording (tid -1) is never stalled as recorded
    assert metrics.stalled_as_recorded(rows.assign(tid=-1), 0.1, _StandingRecording(10.0),
                                       1000.0, "w") == 0  # fmt: skip


def test_auto_is_calibrated_where_the_store_is_calibrated_else_paper(wave_store, calibrated_store):
    from twin.cosim.behaviour import AUTO_CHOICE, resolve

    assert resolve("auto", wave_store, "westbound") == "paper"
    assert resolve("auto", calibrated_store, "westbound") == AUTO_CHOICE
    assert resolve("auto", calibrated_store, "eastbound") == "paper"  # not calibrated there
    assert resolve("recorded", wave_store, "westbound") == "recorded"
    with pytest.raises(BehaviourError, match="unknown behaviour"):
        resolve("wild", wave_store, "westbound")


@pytest.fixture(scope="module")
def gipps_calibrated_store(wave_store, tmp_path_factory) -> TrajectoryStore:
    """A copy of ``wave_store`` calibrated with Gipps drivers (``--model gipps``)."""
    import shutil

    from twin.calibration.calibrate import calibrate, write_calibration
    from twin.traffic.models import GIPPS

    folder = tmp_path_factory.mktemp("gipps") / "store"
    shutil.copytree(wave_store.path, folder)
    store = TrajectoryStore(folder)
    doc, fits = calibrate(store, ["westbound"], model=GIPPS)
    write_calibration(store, doc, fits)
    return store


def test_a_gipps_calibration_drives_gipps_drivers_and_names_the_model_it_needs(
    gipps_calibrated_store, built_map
):
    store = gipps_calibrated_store
    assert read_fits(store).columns.tolist()[5:10] == [
        "desired_speed", "max_accel", "decel", "reaction_time", "min_gap",
    ]  # fmt: skip
    with pytest.raises(BehaviourError, match=r"traffic\.car_following=gipps"):
        Behaviour("calibrated", store, "westbound", 0)  # the run drives IDM
    # auto: the calibration where it is of the run's model, else the paper's drivers
    assert resolve("auto", store, "westbound") == "paper"
    assert resolve("auto", store, "westbound", "gipps") == "calibrated"
    config = replace(
        SCENARIO_B, behaviour="calibrated", t_max=3.0,
        traffic=replace(SCENARIO_B.traffic, car_following="gipps"),
    )  # fmt: skip
    sim = Cosimulator(config, EmpiricalTraffic(store), built_map)
    try:
        sim.reset()
        while not sim.done:
            sim.step()
        assert sim.manager.model.name == "gipps"
        params = sim.manager.params(sim.manager.ids)
        dist = sim.behaviour.distributions["all"]
        assert dist.names == ("desired_speed", "max_accel", "decel", "reaction_time", "min_gap")
        # every driver's reaction time drawn from the Gipps fit, within 2 sd of it
        j = dist.names.index("reaction_time")
        tau = np.log(params["reaction_time"])
        assert np.all(np.abs(tau - dist.mean_log[j]) <= 2 * dist.sd_log[j] + 1e-9)
        assert len(sim.counters.collisions) == 0
    finally:
        sim.close()


def _free_speeds(mean: float) -> dict:
    """A lane's free-flow speeds in the calibration's layout: ``mean`` +/- 0.1 m/s."""
    return {"count": 12, "mean": mean, "sd": 0.1, "p10": mean - 0.1, "p50": mean,
            "p90": mean + 0.1}  # fmt: skip


def _with_desired_speeds(store, tmp_path, speeds: dict, identified: int) -> TrajectoryStore:
    """A copy of ``store`` whose westbound calibration has the free-flow ``speeds`` and
    ``identified`` desired speeds from the car-following fits."""
    folder = tmp_path / "store"
    shutil.copytree(store.path, folder)
    path = folder / "calibration.json"
    doc = json.loads(path.read_text())
    road = doc["roads"]["westbound"]
    road["car_following"]["desired_speed_identified"] = identified
    road["desired_speed"] = speeds
    path.write_text(json.dumps(doc))
    return TrajectoryStore(folder)


def test_a_lane_with_free_flow_speeds_of_its_own_drives_them(calibrated_store, built_map, tmp_path):
    # the fits identify more desired speeds than free flow does (a congested morning),
    # but lane -2's free drivers were seen at 48 m/s: its drivers want that, the other
    # lanes' the fitted speeds (on SUMO's on-ramp morning the fits said 40.8 m/s where
    # the HOV lane's free drivers drove 29.3, and its speed field was 4.9 m/s off)
    free = _free_speeds(48.0)
    store = _with_desired_speeds(calibrated_store, tmp_path, {"all": free, "-2": free}, 1000)
    sim = _episode(store, built_map, "calibrated", seconds=0.1)
    try:
        assert sim.behaviour.speed_source == "car_following"
        ids = sim.manager.ids
        base = sim.base_speeds(ids)
        lanes, changing = sim.manager.lanes(ids), sim.manager.changing(ids)
        in_2, others = (lanes == -2) & ~changing, (lanes != -2) & ~changing  # as spawned
        assert in_2.any() and others.any()
        assert np.all(sim.spawn_speeds(ids) < 47.8)  # each wants its draw (the next test)
        assert np.all(np.abs(base[in_2] - 48.0) <= 0.2 + 1e-9)  # within 2 sd
        assert np.all(np.abs(base[others] - 48.0) > 0.2)  # the fits' (calibrated at 25+)
        # the reference draw says the same
        drawn = sim.behaviour.drivers(np.arange(4), np.zeros(4, int), np.array([-2, -2, -3, -1]))
        assert np.all(np.abs(drawn["desired_speed"][:2] - 48.0) <= 0.2 + 1e-9)
        assert np.all(np.abs(drawn["desired_speed"][2:] - 48.0) > 0.2)
        # an on-ramp's driver (lane -5) takes lane -4's, as the compiled draw does
        from twin.calibration.distributions import draw_desired

        speeds = {"all": free, "-4": free}
        lanes = np.array([-4, -5, -3])
        rng = np.random.default_rng(0)
        ramp = draw_desired(speeds, "car_following", np.full(3, 40.0), lanes, rng)
        assert np.all(np.abs(ramp[:2] - 48.0) <= 0.2 + 1e-9) and ramp[2] == 40.0
    finally:
        sim.close()


@pytest.mark.parametrize("behaviour", ["calibrated", "recorded"])
def test_a_driver_wants_no_less_than_its_recording_drove_where_it_was_spawned(
    calibrated_store, built_map, tmp_path, behaviour
):
    # every lane's free drivers were seen at 26 m/s (the window's vehicles are spawned
    # at 23 to 29): those spawned faster keep their own speed as their desired speed,
    # slower ones the draw (SUMO's lane drop: fast drivers in its emptied right lanes,
    # drawn 29 m/s, fell 3 m/s behind)
    store = _with_desired_speeds(calibrated_store, tmp_path, {"all": _free_speeds(26.0)}, 0)
    sim = _episode(store, built_map, behaviour, seconds=0.1)
    try:
        assert sim.behaviour.speed_source == "free_flow"
        ids = sim.manager.ids
        ego = ids == sim.ego_id
        assert ego.sum() == 1 and sim.base_speeds(ids[ego])[0] == sim.config.vel_default
        ids = ids[~ego]  # the ego wants vel_default whatever it drove
        base, spawned = sim.base_speeds(ids), sim.spawn_speeds(ids)
        faster, slower = spawned > 26.2, spawned < 25.8
        assert faster.sum() >= 3 and slower.sum() >= 3
        assert np.array_equal(base[faster], spawned[faster])
        assert np.all(np.abs(base[slower] - 26.0) <= 0.2 + 1e-9)
        # the reference draw says the same
        lanes = np.array([-2, -2, -3, -5])
        drawn = sim.behaviour.drivers(
            np.arange(4), np.zeros(4, int), lanes, speed=np.array([30.0, 5.0, 33.0, 30.0])
        )["desired_speed"]
        assert drawn[0] == 30.0 and drawn[2] == 33.0 and abs(drawn[1] - 26.0) <= 0.2 + 1e-9
        assert abs(drawn[3] - 26.0) <= 0.2 + 1e-9  # an on-ramp's driver: its draw alone
    finally:
        sim.close()
    paper = _episode(store, built_map, "paper", seconds=0.1)
    try:  # the paper's drivers want vel_default whatever they drove
        assert np.allclose(paper.base_speeds(paper.manager.ids), paper.config.vel_default)
    finally:
        paper.close()
