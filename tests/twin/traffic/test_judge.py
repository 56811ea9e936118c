"""MOBIL's options in still scenes (twin/traffic/judge.py) are the rule the traffic
drives by: on random scenes, every driver the traffic's own decision round moves goes
the way the judge's best safe gain above 0 points, and no other driver moves."""

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from twin.core.vehicle_classes import vehicle_classes
from twin.traffic.config import TrafficConfig
from twin.traffic.drivers import DriverDistribution
from twin.traffic.judge import Scenes, judge_scenes, scene_blocks
from twin.traffic.kernels import state
from twin.traffic.kernels.decide import decide_from_python
from twin.traffic.mobil import MOBILParams
from twin.traffic.models import car_following_model


def random_scenes(seed: int, model_name: str, scenes: int = 6) -> Scenes:
    """Scenes of 20 to 60 vehicles on 500 m of the four lanes, at any speed, drivers
    drawn from the class table."""
    rng = np.random.default_rng(seed)
    model = car_following_model(model_name)
    classes = vehicle_classes()
    parts = []
    for s in range(scenes):
        n = int(rng.integers(20, 60))
        vehicle_class = rng.integers(0, len(classes.frame), n)
        traits = DriverDistribution().draw(classes, vehicle_class, rng)
        params = model.from_traits(traits)
        cf = np.column_stack([np.broadcast_to(getattr(params, p), (n,)) for p in model.names])
        parts.append({
            "scene": np.full(n, s), "x": rng.uniform(0.0, 500.0, n),
            "speed": rng.uniform(0.0, 32.0, n), "lane": rng.integers(-4, 0, n),
            "length": classes.column("length_m")[vehicle_class], "cf": cf,
            "hov_eligible": rng.random(n) < 0.5,
        })  # fmt: skip
    return Scenes(**{k: np.concatenate([p[k] for p in parts]) for k in parts[0]})


def driven_choices(scenes: Scenes, config: TrafficConfig) -> np.ndarray:
    """(r,) the direction each driver of ``scenes`` starts a change to (+1 left, -1
    right, 0 none) in the traffic's decision round (the whole step of the kernels)."""
    out = np.zeros(scenes.scene.size, np.int64)
    for rows, traffic, scene, slot in scene_blocks(scenes, config):
        packed = state.pack(traffic)
        for b in range(traffic.vehicles.valid.shape[0]):
            decide_from_python(b, 0, 0.0, 7, packed)
        d = traffic.drivers
        out[rows] = (d.lane - d.lane_from)[scene, slot]
    return out


def judged_choices(gain: np.ndarray, possible: np.ndarray) -> np.ndarray:
    """The choice the judge's options imply: the safe one of the highest gain above 0,
    the left one where both are equal (the round tries left first)."""
    best = np.where(possible & (gain > 0.0), gain, 0.0)
    return np.where(best[:, 0] >= best[:, 1], np.where(best[:, 0] > 0, 1, 0),
                    np.where(best[:, 1] > 0, -1, 0))  # fmt: skip


@settings(max_examples=12, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), model=st.sampled_from(["idm", "gipps"]),
       threshold=st.floats(0.0, 1.0), politeness=st.floats(0.0, 1.0))  # fmt: skip
def test_the_judge_chooses_as_the_traffic_drives(seed, model, threshold, politeness):
    scenes = random_scenes(seed, model)
    mobil = MOBILParams(politeness=politeness, threshold=threshold, keep_right=0.1)
    config = TrafficConfig(car_following=model, mobil=mobil)
    gain, possible = judge_scenes(scenes, config)
    assert gain.shape == possible.shape == (scenes.scene.size, 2)
    np.testing.assert_array_equal(driven_choices(scenes, config), judged_choices(gain, possible))


def test_the_judge_sees_changes_and_no_moves_off_the_road_or_across_the_hov_line():
    scenes = random_scenes(3, "idm", scenes=8)
    config = TrafficConfig(car_following="idm", mobil=MOBILParams(threshold=0.0))
    gain, possible = judge_scenes(scenes, config)
    choices = driven_choices(scenes, config)
    assert 0 < np.count_nonzero(choices) < choices.size  # a test that can fail both ways
    assert not possible[scenes.lane == -4, 1].any() and not possible[scenes.lane == -2, 0].any()
    assert np.all(gain[scenes.lane == -1] == -np.inf)  # no opening in the HOV line: no move
    # a higher threshold lowers every gain by the difference, and moves fewer drivers
    higher = replace(config, mobil=MOBILParams(threshold=0.5))
    gain_high, possible_high = judge_scenes(scenes, higher)
    allowed = np.isfinite(gain)
    np.testing.assert_allclose(gain_high[allowed], gain[allowed] - 0.5)
    np.testing.assert_array_equal(possible_high, possible)
    assert np.count_nonzero(driven_choices(scenes, higher)) < np.count_nonzero(choices)


def test_scenes_name_what_is_wrong_with_them():
    good = random_scenes(0, "idm", scenes=1)
    with pytest.raises(ValueError, match=r"lanes must be -1\.\.-4"):
        replace(good, lane=np.zeros_like(good.lane))
    with pytest.raises(ValueError, match="non-finite"):
        replace(good, x=np.full_like(good.x, np.nan))
    with pytest.raises(ValueError, match="sorted by scene"):
        replace(good, scene=good.scene[::-1] - np.arange(good.scene.size))
    with pytest.raises(ValueError, match="car-following parameters"):
        judge_scenes(good, TrafficConfig(car_following="gipps"))
