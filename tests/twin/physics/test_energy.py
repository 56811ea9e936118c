"""Energy: the RAV4 fuel model against its source's check values, and the tractive
energy of the twin's powertrain against the physics of a known manoeuvre."""

import numpy as np
import pytest

from twin.core.i24 import LANE_WIDTH, MILE
from twin.metrics import economy
from twin.physics import energy
from twin.physics.states import SpawnStates
from twin.physics.vehicle import AIR_DENSITY, GRAVITY
from twin.physics.world import PhysicsWorld

RAV4 = energy.RAV4_2019


def test_the_rav4_model_gives_the_check_values_of_control_md():
    cruise = RAV4.rate(30.0, 0.0, 0.0)
    assert cruise == pytest.approx(1.2524, abs=5e-4)  # g/s
    assert cruise * economy.GALLONS_PER_HOUR_PER_GRAM_PER_S == pytest.approx(1.59, abs=5e-3)
    hour = economy.economy(30.0 * 3600.0, float(cruise) * 3600.0)
    assert hour["mpg"] == pytest.approx(42.3, abs=0.1)  # 67.1 mph on 1.59 gal/h
    l_per_100km_times_mpg = 100.0 * economy.LITRES_PER_GALLON / (MILE / 1000.0)  # 235.2
    assert hour["l_per_100km"] == pytest.approx(l_per_100km_times_mpg / hour["mpg"], rel=1e-9)
    # a 1.1 % grade adds 0.436 g/s: m g sin(theta) v = 5.6 kW at about 28 % efficiency
    climb = RAV4.rate(30.0, 0.0, 0.011) - cruise
    assert climb == pytest.approx(0.436, abs=5e-4)
    work = RAV4.mass * GRAVITY * 0.011 * 30.0  # [W]
    assert work / (climb * 42_360.0) == pytest.approx(0.28, abs=0.03)  # 30 % here


def test_fuel_is_floored_at_idle_and_never_negative():
    # at or below 5.98 m/s the idle floor; above it braking cuts the fuel, to 0 at most
    slow = RAV4.rate([0.0, 3.0, 5.98], [-4.0, -2.0, -2.0], 0.0)
    np.testing.assert_allclose(slow, RAV4.beta0)
    braking = RAV4.rate([10.0, 20.0, 30.0], -2.0, 0.0)
    np.testing.assert_array_equal(braking, 0.0)
    assert 0.0 < RAV4.rate(6.5, -0.53, 0.0) < RAV4.beta0  # slightly below the floor, kept


def test_infeasible_accelerations_are_flagged_not_clipped():
    assert RAV4.max_accel(30.0) == pytest.approx(1.720, abs=1e-3)
    assert RAV4.feasible(30.0, 1.5) and not RAV4.feasible(30.0, 2.0)
    # the rate extrapolates the polynomial there, as the source does
    assert RAV4.rate(30.0, 2.0, 0.0) > RAV4.rate(30.0, 1.5, 0.0)


@pytest.mark.parametrize(
    ("speed", "accel", "grade", "name"),
    [(np.nan, 0.0, 0.0, "speed"), (20.0, np.inf, 0.0, "accel"), (20.0, 0.0, np.nan, "grade")],
)
def test_bad_inputs_are_named(speed, accel, grade, name):
    with pytest.raises(ValueError, match=name):
        RAV4.rate(speed, accel, grade)
    with pytest.raises(ValueError, match="speeds must be >= 0"):
        RAV4.rate(-1.0, 0.0, 0.0)


def test_tractive_energy_is_the_work_of_a_known_manoeuvre(built_map):
    """A sedan accelerating at 1 m/s^2 from 15 to 20 m/s: what its powertrain delivered at
    the wheels is its kinetic energy gained (wheels' inertia included), the work
    against drag and rolling resistance and the climb, plus what the tyres' slip takes
    (the drive force over the slip stiffness, about 2.4 % of slip on the driven front
    wheels here): more than the body's work, by less than 7 %."""
    dt = 0.01
    with PhysicsWorld(built_map) as world:
        state = SpawnStates.make("eastbound", [0.0], 2.5 * LANE_WIDTH, 15.0, 0, 4.7, 1.83, 1.45)
        (vid,) = world.spawn(state)
        world.step()
        params = world.params
        start = world.states()
        world.set_controls([vid], accel=[1.0])
        work = resist = 0.0
        for _ in range(500):
            world.step()
            now = world.states()
            work += float(now.drive_power[0]) * dt
            v = float(now.speed[0])
            drag = 0.5 * AIR_DENSITY * float(params.drag_area[0]) * v**3
            rolling = float(params.rolling[0] * params.mass[0]) * GRAVITY * v
            resist += (drag + rolling) * dt
    v0, v1 = float(start.speed[0]), float(now.speed[0])
    assert v1 == pytest.approx(20.0, abs=0.2)
    kinetic = 0.5 * float(params.effective_mass[0]) * (v1**2 - v0**2)
    climb = float(params.mass[0]) * GRAVITY * float(now.position[0, 2] - start.position[0, 2])
    assert 1.0 < work / (kinetic + resist + climb) < 1.07
