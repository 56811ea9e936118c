from dataclasses import replace

import numpy as np
import pytest

from twin.core import i24
from twin.core.i24 import SCENARIO_TIME
from twin.data.empirical import EmpiricalTraffic
from twin.data.speed_field import speed_field, wave_front_speed
from twin.data.synth import PRESET_B, PRESET_C, Simulation, synthesize

MPH15 = 15 * 0.44704  # [m/s]


def _lane_samples(store, lane, t0, t1):
    s = store.samples("westbound", t0, t1)
    rows = s["lane"] == lane
    return {k: v[rows] for k, v in s.items()}


def test_wave_travels_upstream_at_the_corridors_measured_speed(wave_store):
    s = _lane_samples(wave_store, -1, SCENARIO_TIME - 240, SCENARIO_TIME + 180)
    field = speed_field(
        s["t"],
        s["x"],
        s["speed"].astype(float),
        np.arange(SCENARIO_TIME - 240, SCENARIO_TIME + 180, 2.0),
        np.arange(0.0, 1609.4, 50.0),
    )
    fit = wave_front_speed(field, MPH15, SCENARIO_TIME - 240)
    assert -5.5 <= fit.speed <= -4.5  # m/s: 10 to 12 mph upstream (I24_DATA.md)
    assert fit.r2 > 0.95
    assert len(fit.x) >= 25  # seen across the whole segment


def test_scenario_b_wave_arrives_at_the_hov_ego_within_the_episode_and_spares_lanes_3_and_4(
    wave_store,
):
    """DESIGN.md: in scenario B a stop-and-go wave arrives in the HOV lane; the paper's
    simulated ego should nearly stop when it does."""
    ego = EmpiricalTraffic(wave_store).closest("westbound", -1, 700.0, SCENARIO_TIME)
    assert abs(ego.x - 700.0) < 20.0 and ego.speed > 20.0  # cruising when the episode starts
    tr = wave_store.trajectory(ego.tid)
    episode = (tr["t"] >= ego.t) & (tr["t"] <= ego.t + 30.0)
    stopped = tr["t"][episode][tr["speed"][episode] < 0.5]
    assert stopped.size and 5.0 < stopped[0] - ego.t < 25.0  # the wave reaches it mid-episode
    s = wave_store.samples("westbound", ego.t, ego.t + 30.0)
    near = (s["x"] > ego.x - 100.0) & (s["x"] < ego.x + 400.0)
    for lane in (-3, -4):
        rows = near & (s["lane"] == lane)
        assert np.mean(s["speed"][rows]) > 20.0


def test_vehicles_spend_tens_of_seconds_below_15_mph_in_the_wave(wave_store):
    table = wave_store.trajectories
    complete = table.index[
        (table["x_first"] < -550) & (table["x_last"] > 2150) & (table["lanes_seen"] == 1)
    ]  # whole HOV-lane trips on record
    durations = []
    for tid in complete:
        tr = wave_store.trajectory(int(tid))
        durations.append(np.sum(np.diff(tr["t"])[tr["speed"][:-1] < MPH15]))
    durations = np.array(durations)
    slowed = durations[durations > 0]
    assert len(slowed) > 20
    assert 10.0 <= np.median(slowed) <= 120.0  # corridor median is about 30 s


def test_free_flow_in_preset_a(light_result):
    speeds = np.concatenate([np.diff(x) / np.diff(t) for t, x, _ in light_result.tracks])
    assert 28.0 <= np.median(speeds) <= 36.0  # 63 to 80 mph
    assert light_result.collisions == 0


@pytest.mark.parametrize("preset", [PRESET_B, PRESET_C], ids=["B", "C"])
def test_synthesis_is_deterministic_by_seed(preset):
    config = replace(preset, start=SCENARIO_TIME, minutes=0.5, warmup=30.0)
    a, b = synthesize(config), synthesize(config)
    c = synthesize(replace(config, seed=1))
    assert np.array_equal(a.vid, b.vid)
    for (ta, xa, ya), (tb, xb, yb) in zip(a.tracks, b.tracks, strict=True):
        assert np.array_equal(ta, tb) and np.array_equal(xa, xb) and np.array_equal(ya, yb)
    assert len(a.tracks) != len(c.tracks) or not np.array_equal(a.tracks[0][1], c.tracks[0][1])


def test_the_synthetic_day_is_valid_i24_data_with_a_realistic_class_mix(wave_store):
    ingest = wave_store.metadata["ingest"]
    assert ingest["documents"]["rejected"] == {} and ingest["samples"]["rejected"] == {}
    table = wave_store.trajectories
    shares = table["vehicle_class"].value_counts(normalize=True)
    assert 0.25 <= shares[0] <= 0.55  # sedans
    assert shares.get(4, 0) > 0.02  # semis
    hov = (table["lanes_seen"] & 1) > 0
    assert not table.loc[hov, "vehicle_class"].isin([4, 5]).any()  # no heavy trucks in HOV
    semis = table[table["vehicle_class"] == 4]
    assert semis["length"].between(16, 25).all()
    dt = np.diff(wave_store.trajectory(int(table.index[0]))["t"])
    assert np.allclose(dt, 0.04, atol=1e-3)  # 25 Hz


def test_lane_changes_are_manoeuvres_of_several_seconds(wave_store):
    table = wave_store.trajectories
    # Exactly two adjacent lanes seen, neither HOV: lane changes between them on record.
    one_change = table.index[table["lanes_seen"].isin([0b0110, 0b1100])]
    assert len(one_change) > 10
    durations = []
    for tid in one_change[:60]:
        tr = wave_store.trajectory(int(tid))
        lanes = np.unique(tr["lane"])
        if lanes.size != 2:
            continue
        # +1 / -1 near either lane centre, 0 between: each manoeuvre is the time from
        # the last sample near one centre to the first sample near the other
        near = np.zeros(len(tr["y"]), dtype=int)
        for sign, lane in ((-1, lanes[0]), (1, lanes[1])):
            near[np.abs(tr["y"] - i24.lane_center(int(lane))) < 0.3] = sign
        at = np.flatnonzero(near)
        switch = np.flatnonzero(near[at][1:] != near[at][:-1])
        durations += list(tr["t"][at[switch + 1]] - tr["t"][at[switch]])
    assert len(durations) > 10
    assert np.min(durations) > 1.5  # s: no teleports
    assert 2.0 <= np.median(durations) <= 6.0  # configured manoeuvres last 3 to 6 s


def test_invalid_config_is_named():
    with pytest.raises(ValueError, match="flow"):
        replace(PRESET_B, flow=(1.0, 2.0))
    with pytest.raises(ValueError, match="decision_interval"):
        replace(PRESET_B, decision_interval=0.0)
    with pytest.raises(ValueError, match="heavy_factor"):
        replace(PRESET_B, heavy_factor=(0.3, -1.0, 1.6))
    # a bottleneck must lie downstream of the recorded range, inside the simulated road
    with pytest.raises(ValueError, match="bottleneck"):
        replace(PRESET_C, bottleneck=replace(PRESET_C.bottleneck, x=100.0))
    with pytest.raises(ValueError, match="bottleneck"):
        replace(PRESET_C, bottleneck=replace(PRESET_C.bottleneck, slow_share=1.5))


def test_hesitant_drivers_at_the_bottleneck_queue_the_lane_behind_them():
    """Preset C's mechanism: no driver is made to brake; drivers who take the bottleneck
    slowly hold up their lane, upstream of the bottleneck too. Every driver hesitant
    (share 1): the 200 m before it are slowed after 5 minutes; none (share 0): they
    flow at the drivers' speed."""
    base = replace(PRESET_C, flow=(0.0, 1900.0, 0.0, 0.0))
    speeds = {}
    for share in (0.0, 1.0):
        config = replace(base, bottleneck=replace(base.bottleneck, slow_share=share))
        sim = Simulation(config, np.random.default_rng(0))
        sim.populate()
        for _ in range(3000):
            sim.step()
        v, b = sim.vehicles, config.bottleneck
        before = (v.x > b.x - 200.0) & (v.x < b.x)
        speeds[share] = float(np.median(v.v[before]))
    assert speeds[0.0] > 25.0
    assert speeds[1.0] < speeds[0.0] - 10.0


def test_hesitant_drivers_are_spread_evenly_over_each_lane():
    """1 in 200 drivers of each lane, never closer than 100 nor further apart than 300
    drivers: a 30-minute day is not left with one wave in a lane, or ten, by chance."""
    sim = Simulation(PRESET_C, np.random.default_rng(0))
    lanes = np.tile(np.array(i24.LANES), 20_000)
    hesitant = sim._bottleneck_speeds(lanes) == PRESET_C.bottleneck.slow_speed
    for lane in i24.LANES:
        at = np.flatnonzero(hesitant[lanes == lane])
        assert 88 <= at.size <= 112  # of 20,000 drivers (the count's sd is about 3)
        gaps = np.diff(at)
        assert gaps.min() >= 100 and gaps.max() <= 300
        assert 180 <= np.mean(gaps) <= 220
