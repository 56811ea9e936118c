"""The sun and its light: positions against an independent ephemeris (astral), the
projected shadows against their geometry, and lighting that changes the RGB picture
only."""

import datetime as dt
import math

import numpy as np
import pytest

from sensors.camera import CameraError, CameraSettings
from sensors.shadows import GROUND_CLASSES, Casters, darken, shadow_mask, shadow_polygons
from sensors.sun import SunPosition, episode_light, segment_location, sun_position
from twin.core.i24 import SCENARIO_TIME
from twin.cosim.config import SCENARIO_B, override
from twin.physics.render import NOON


@pytest.mark.parametrize(
    ("when", "lat", "lon"),
    [
        ("2022-11-30T12:45:50", 36.03, -86.64),  # the scenarios: 06:45:50 CST on I-24
        ("2022-11-22T17:00:00", 36.03, -86.64),  # the real waves' morning, 11:00 CST
        ("2023-06-21T18:00:00", 36.03, -86.64),  # midsummer, near noon
        ("2024-03-20T09:00:00", 0.0, 0.0),  # (at noon the azimuth is ill-posed: overhead)
        ("2021-12-01T03:30:00", -33.87, 151.21),  # Sydney, afternoon
        ("2022-09-10T20:15:00", 64.15, -21.94),  # Reykjavik
    ],
)
def test_the_sun_agrees_with_astral_within_half_a_degree(when, lat, lon):
    astral_sun = pytest.importorskip("astral.sun")
    from astral import Observer

    moment = dt.datetime.fromisoformat(when).replace(tzinfo=dt.UTC)
    mine = sun_position(moment.timestamp(), lat, lon)
    observer = Observer(latitude=lat, longitude=lon)
    elevation = astral_sun.elevation(observer, moment, with_refraction=False)
    azimuth = astral_sun.azimuth(observer, moment)
    assert mine.elevation_deg == pytest.approx(elevation, abs=0.5)
    assert (mine.azimuth_deg - azimuth + 180.0) % 360.0 - 180.0 == pytest.approx(0.0, abs=0.5)


def test_the_scenarios_morning_sun_is_rising_in_the_south_east():
    lat, lon = segment_location()
    assert 36.0 < lat < 36.1 and -86.7 < lon < -86.6  # between the mile posts 60.6 and 61.6
    sun = sun_position(SCENARIO_TIME, lat, lon)  # 2022-11-30 06:45:50 CST
    assert 0.0 < sun.elevation_deg < 2.0 and 110.0 < sun.azimuth_deg < 125.0
    light, record = episode_light("recorded", SCENARIO_TIME)
    assert record["sun"] == "recorded" and light.shadows
    assert light.color[2] < light.color[0]  # warm near sunrise
    east, north, up = np.asarray(light.direction)
    assert east > 0 and north < 0 and up > 0  # toward the south-east, above the horizon


def test_noon_is_the_papers_light_and_random_is_seeded():
    assert episode_light("noon", SCENARIO_TIME)[0] == NOON
    a = episode_light("random", 0.0, rng=np.random.default_rng(4))
    b = episode_light("random", 0.0, rng=np.random.default_rng(4))
    c = episode_light("random", 0.0, rng=np.random.default_rng(5))
    assert a == b and a[1] != c[1]
    assert 5.0 <= a[1]["elevation_deg"] <= 70.0 and 0.8 <= a[1]["intensity"] <= 1.2
    with pytest.raises(ValueError, match="needs a seeded random generator"):
        episode_light("random", 0.0)
    with pytest.raises(ValueError, match="sun must be one of"):
        episode_light("dusk", 0.0)
    with pytest.raises(CameraError, match="sun must be one of recorded, noon, random"):
        CameraSettings(sun="dusk")
    with pytest.raises(ValueError, match="no place"):
        sun_position(0.0, 91.0, 0.0)


def test_a_shadow_is_as_long_as_the_sun_is_low():
    """A 2 m cube on the ground, the sun 30 degrees up in the east: its shadow reaches
    2 / tan(30 deg) = 3.46 m west of its west face."""
    box = Casters.on_ground([[0.0, 0.0, 5.0]], np.eye(3)[None], np.array([[2.0, 2.0, 2.0]]))
    sun = SunPosition(30.0, 90.0).direction_enu()
    points = shadow_polygons(box, sun)
    assert np.allclose(points[:, :, 2], 5.0)  # on the box's ground
    assert points[0, :, 0].min() == pytest.approx(-1.0 - 2.0 / math.tan(math.radians(30.0)))
    assert points[0, :, 0].max() == pytest.approx(1.0)
    assert np.allclose(sorted(set(np.round(points[0, :, 1], 9))), [-1.0, 1.0])


def test_the_shadow_mask_covers_the_shadows_pixels():
    """Seen from 20 m straight above: the shadow of the cube fills its (2 + 3.46) x 2 m
    footprint, within a pixel's rounding along the edges."""
    box = Casters.on_ground([[0.0, 0.0, 0.0]], np.eye(3)[None], np.array([[2.0, 2.0, 2.0]]))
    sun = SunPosition(30.0, 90.0).direction_enu()
    f, size = 400.0, 400  # 20 m from the ground: 20 px per m
    K = np.array([[f, 0.0, size / 2], [0.0, f, size / 2], [0.0, 0.0, 1.0]])
    camera_from_world = np.eye(4)  # looking down: camera x east, y south, z down
    camera_from_world[:3, :3] = [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]]
    camera_from_world[2, 3] = 20.0
    mask = shadow_mask(box, sun, K, camera_from_world, size, size, 0.1)
    area = (2.0 + 2.0 / math.tan(math.radians(30.0))) * 2.0 * 20.0**2
    perimeter = 2.0 * (5.46 + 2.0) * 20.0
    assert abs(mask.sum() - area) < perimeter  # about a pixel along the edges
    columns = np.flatnonzero(mask.any(axis=0))
    assert (columns.min() - size / 2) / 20.0 == pytest.approx(-3.46 - 1.0, abs=0.1)  # west
    assert (columns.max() + 1 - size / 2) / 20.0 == pytest.approx(1.0, abs=0.1)
    # no sun, no shadow
    assert not shadow_mask(box, np.array([1.0, 0.0, 0.0]), K, camera_from_world, 8, 8, 0.1).any()


def test_only_the_ground_is_darkened():
    rgb = np.full((2, 3, 3), 200, np.uint8)
    semantic = np.array([[GROUND_CLASSES[0], 9, 0], [GROUND_CLASSES[-1], 4, 1]], np.uint8)
    mask = np.ones((2, 3), bool)
    out = darken(rgb, semantic, mask, 0.5)
    assert out[0, 0, 0] == 100 and out[1, 0, 0] == 100  # road, terrain
    assert out[0, 1, 0] == 200 and out[1, 1, 0] == 200 and out[0, 2, 0] == 200  # car, barrier, sky


def test_lighting_changes_the_rgb_picture_only(wave_store, built_map):
    """Scenario B's front camera at 12 s under three suns: depth, semantic and instance
    images are the same, the RGB picture is not."""
    from twin.runners.run import render_at

    frames = {}
    for sun, seed in (("noon", 0), ("recorded", 0), ("random", 0)):
        config = override(SCENARIO_B, {"seed": seed, "camera": {"sun": sun}})
        frames[sun] = render_at(config, wave_store, 12.0, bundle=built_map)
    noon = frames["noon"]
    for sun in ("recorded", "random"):
        frame = frames[sun]
        assert np.array_equal(frame.depth, noon.depth)
        assert np.array_equal(frame.semantic, noon.semantic)
        assert np.array_equal(frame.instance, noon.instance)
        assert np.abs(frame.rgb.astype(int) - noon.rgb).mean() > 5.0
        assert frame.light["sun"] == sun


def test_a_random_sun_is_drawn_once_per_episode_from_its_seed(built_map):
    from sensors.camera import CameraRig
    from twin.physics.world import PhysicsWorld

    with PhysicsWorld(built_map) as world:
        lights = []
        for seed in (1, 1, 2):
            rig = CameraRig(world, built_map, renderer="tiny", sun="random", seed=seed)
            lights.append((rig.light_at(0.0), rig.light_at(600.0)))
            rig.close()
    assert lights[0][0] == lights[0][1]  # the same all episode long
    assert lights[0] == lights[1] and lights[0] != lights[2]  # by the seed
