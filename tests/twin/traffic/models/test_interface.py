"""Every registered car-following model keeps the interface's promises (so a new one
is one module and a line in the registry): free-road acceleration that vanishes at
the desired speed, braking behind a stopped leader, a stop where the desired speed
is 0, parameters for the class table's drivers, and a calibration box around its
start."""

from dataclasses import fields, replace

import numpy as np
import pytest

from twin.core.vehicle_classes import vehicle_classes
from twin.traffic.drivers import DriverDistribution
from twin.traffic.models import MODELS, car_following_model
from twin.traffic.models.base import REQUIRED, concatenate, take


def _drivers(model, n=6, seed=0):
    classes = vehicle_classes()
    traits = DriverDistribution().draw(classes, np.arange(n) % 7, np.random.default_rng(seed))
    return model.from_traits(traits)


@pytest.mark.parametrize("name", sorted(MODELS))
def test_a_free_road_driver_accelerates_below_and_settles_at_its_desired_speed(name):
    model = MODELS[name]
    drivers = _drivers(model)
    n = len(drivers.desired_speed)
    free = np.full(n, np.inf)
    slow = model.accel(0.5 * drivers.desired_speed, np.zeros(n), free, drivers)
    at = model.accel(np.asarray(drivers.desired_speed, float), np.zeros(n), free, drivers)
    assert np.all(slow > 0.05)
    assert np.all(np.abs(at) < 1e-9)


@pytest.mark.parametrize("name", sorted(MODELS))
def test_a_driver_closing_on_a_stopped_leader_brakes_and_a_zero_desired_speed_stops(name):
    model = MODELS[name]
    drivers = _drivers(model)
    n = len(drivers.desired_speed)
    braking = model.accel(np.full(n, 20.0), np.zeros(n), np.full(n, 15.0), drivers)
    assert np.all(braking < -1.0)
    stopped = model.make(**{p: getattr(drivers, p) for p in model.names if p != "desired_speed"},
                         desired_speed=np.zeros(n))  # fmt: skip
    stop = model.accel(np.full(n, 10.0), np.zeros(n), np.full(n, np.inf), stopped)
    assert np.all(np.isfinite(stop)) and np.all(stop < 0)
    rest = model.accel(np.zeros(n), np.zeros(n), np.full(n, np.inf), stopped)
    assert np.all(np.isfinite(rest)) and np.all(rest <= 0)


@pytest.mark.parametrize("name", sorted(MODELS))
def test_parameters_are_declared_bounded_and_sliced_as_struct_of_arrays(name):
    model = car_following_model(name)
    assert set(REQUIRED) <= set(model.names)
    for p in model.parameters:
        assert 0 < p.bounds[0] <= p.start <= p.bounds[1], p
    drivers = _drivers(model, n=5)
    two = take(drivers, np.array([1, 3]))
    assert all(np.shape(getattr(two, p)) == (2,) for p in model.names)
    both = concatenate(drivers, two)
    assert all(np.shape(getattr(both, p)) == (7,) for p in model.names)
    start = model.from_fitted(np.array([[p.start for p in model.fitted]]))
    assert all(np.ndim(getattr(start, p.name)) in (0, 1) for p in model.parameters)


@pytest.mark.parametrize("name", sorted(MODELS))
def test_one_driver_of_scalar_traits_is_the_same_as_in_an_array(name):
    """The traffic manager judges the ghosts as the class table's mean driver, given
    as scalar traits."""
    model = MODELS[name]
    traits = DriverDistribution().draw(
        vehicle_classes(), np.array([0, 4]), np.random.default_rng(3)
    )
    one = model.from_traits(replace(traits, **{f.name: float(getattr(traits, f.name)[1])
                                               for f in fields(traits)}))  # fmt: skip
    many = model.from_traits(traits)
    v, lead, gap = np.array([12.0]), np.array([10.0]), np.array([30.0])
    assert model.accel(v, lead, gap, one)[0] == model.accel(v, lead, gap, take(many, [1]))[0]


def test_a_model_must_fit_its_desired_speed():
    idm = MODELS["idm"]
    fixed = tuple(replace(p, fitted=False) if p.name == "desired_speed" else p
                  for p in idm.parameters)  # fmt: skip
    with pytest.raises(ValueError, match="desired_speed must be a fitted parameter"):
        replace(idm, name="broken", parameters=fixed)


def test_an_unknown_model_is_named_with_the_known_ones():
    with pytest.raises(ValueError, match=r"unknown car-following model 'ovm'.*idm"):
        car_following_model("ovm")
