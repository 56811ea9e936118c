import pytest

from twin.core.i24 import SCENARIO_TIME, Road
from twin.cosim.config import (
    PRESETS,
    SCENARIO_A,
    SCENARIO_B,
    ConfigError,
    CosimConfig,
    from_toml,
    load_config,
    override,
    parse_assignments,
    switch_world,
    to_toml,
)


def test_presets_are_the_papers_scenarios():
    assert (SCENARIO_A.road, SCENARIO_A.lane, SCENARIO_A.x) == (Road.EASTBOUND, -2, 300.0)
    assert (SCENARIO_B.road, SCENARIO_B.lane, SCENARIO_B.x) == (Road.WESTBOUND, -1, 700.0)
    for preset in PRESETS.values():
        assert preset.time == SCENARIO_TIME == 1669812350.0
        assert (preset.t_max, preset.dt, preset.w_visible, preset.w_ghost) == (30, 0.01, 150, 50)
        assert preset.ghost_smoothing == 0.0  # the paper's behaviour is the baseline
    assert SCENARIO_B.steps == 3000


@pytest.mark.parametrize("preset", ["A", "B"])
def test_toml_round_trip(preset):
    config = override(
        PRESETS[preset],
        {
            "bev_time": 12.5,
            "traffic": {"hov_openings": [[100.0, 200.0]], "mobil": {"politeness": 0.5}},
        },
    )
    text = to_toml(config)
    assert from_toml(text) == config
    assert to_toml(from_toml(text)) == text


def test_a_file_overrides_its_preset_and_flags_override_the_file(tmp_path):
    path = tmp_path / "run.toml"
    path.write_text('scenario = "A"\nx = 420\n[traffic]\nhov_share = 0.3\n')
    config = load_config(path)
    assert config.road == Road.EASTBOUND and config.x == 420.0 and isinstance(config.x, float)
    assert config.traffic.hov_share == 0.3
    config = override(config, parse_assignments(["traffic.hov_share=0.1", "lane=-3"]))
    assert config.traffic.hov_share == 0.1 and config.lane == -3
    assert load_config(path, base=SCENARIO_B).road == Road.WESTBOUND  # --scenario wins


def test_the_traffic_manager_runs_at_the_runs_step_and_seed():
    config = CosimConfig(dt=0.005, seed=7)
    assert config.traffic.dt == 0.005 and config.traffic.seed == 7


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("lane = 0", "lane must be one of"),
        ("dt = 0.05", "dt must be in"),
        ("t_max = -1.0", "t_max must be > 0"),
        ("x = nan", "x must be finite"),
        ("ghost_log_rate = 7.0", "must divide the step rate"),
        ("bev_time = 40.0", "bev_time must be in"),
        ('road = "northbound"', "unknown road"),
        ("speed = 3", "unknown setting 'speed'"),
        ("[traffic]\nhov_share = 2.0", "hov_share must be in 0..1"),
        ("[traffic]\nfoo = 1", "unknown setting 'traffic.foo'"),
        ('lane = "left"', "lane must be an integer"),
        ("seed = 1.5", "seed must be an integer"),
        ('ego_controller = "nocolon"', "module:function"),
        ("x = [", "not valid TOML"),
        ('world = "mujoco"', "world must be one of physics, kinematic"),
        ('world = "kinematic"\ndt = 0.5', r"kinematic world's dt must be in \(0, 0.1\]"),
        ('world = "kinematic"\n[camera]\nenabled = true', "cameras need the physics world"),
    ],
)
def test_bad_configurations_name_the_problem(text, message):
    with pytest.raises(ConfigError, match=message):
        from_toml(text, source="test.toml")


def test_an_unreadable_file_is_a_config_error(tmp_path):
    with pytest.raises(ConfigError, match="cannot read configuration"):
        load_config(tmp_path / "missing.toml")
    with pytest.raises(ConfigError, match="expected KEY=VALUE"):
        parse_assignments(["hov_share"])


def test_switching_the_world_carries_its_step_unless_one_was_set():
    assert (SCENARIO_B.world, SCENARIO_B.dt) == ("physics", 0.01)
    kinematic = switch_world(SCENARIO_B, "kinematic")
    assert (kinematic.world, kinematic.dt, kinematic.traffic.dt) == ("kinematic", 0.1, 0.1)
    assert kinematic.steps == 300 and kinematic.ghost_log_every == 1
    assert switch_world(kinematic, "physics").dt == 0.01
    # a step set by hand stays; TOML and --set switch the same way
    assert switch_world(override(SCENARIO_B, {"dt": 0.005}), "kinematic").dt == 0.005
    assert from_toml('world = "kinematic"').dt == 0.1
    assert from_toml('world = "kinematic"\ndt = 0.05').dt == 0.05
    assert override(SCENARIO_B, parse_assignments(["world=kinematic"])).dt == 0.1
    # the resolved configuration loads back to itself
    assert from_toml(to_toml(kinematic)) == kinematic
