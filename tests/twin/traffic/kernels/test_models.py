"""The compiled car-following models are the registered models: every name of
``MODELS`` has a kernel, and the kernel's acceleration is the vectorised model's."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from twin.traffic.kernels.models import MAX_ACCEL_COLUMN, MODEL_IDS, N_PARAMS, follow_accel
from twin.traffic.models import MODELS


def test_every_registered_model_has_a_kernel():
    assert set(MODEL_IDS) == set(MODELS)
    for name, model in MODELS.items():
        assert len(model.names) <= N_PARAMS
        assert model.names[MAX_ACCEL_COLUMN[MODEL_IDS[name]]] == "max_accel"


@pytest.mark.parametrize("name", sorted(MODELS))
def test_kernel_acceleration_is_the_models(name):
    model = MODELS[name]
    rng = np.random.default_rng(7)
    n = 400
    values = {}
    for p in model.parameters:
        low, high = p.bounds
        values[p.name] = rng.uniform(low, high, n)
    values["desired_speed"][:20] = 0.0  # a stop order
    params = model.make(**values)
    v = rng.uniform(0.0, 35.0, n)
    v_lead = rng.uniform(0.0, 35.0, n)
    gap = rng.uniform(0.5, 120.0, n)
    gap[::7] = np.inf  # free roads
    expected = model.accel(v, v_lead, gap, params)
    row = np.zeros((n, N_PARAMS))
    for column, p in enumerate(model.names):
        row[:, column] = values[p]
    got = np.array(
        [follow_accel(MODEL_IDS[name], v[i], v_lead[i], gap[i], *row[i]) for i in range(n)]
    )
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-9)


@pytest.mark.parametrize("name", sorted(MODELS))
def test_kernel_parameters_from_traits_are_the_models(name):
    """The batched core's drivers get their parameters from the kernels' from_traits:
    the same row as the model's own from_traits gives the traffic manager."""
    from twin.traffic.drivers import DriverTraits
    from twin.traffic.kernels.models import from_traits

    model = MODELS[name]
    rng = np.random.default_rng(11)
    n = 50
    traits = DriverTraits(rng.uniform(0.0, 40.0, n), rng.uniform(0.5, 3.0, n),
                          rng.uniform(0.5, 5.0, n), rng.uniform(0.3, 3.0, n),
                          rng.uniform(0.5, 4.0, n), rng.uniform(1.0, 8.0, n))  # fmt: skip
    params = model.from_traits(traits)
    expected = np.zeros((n, N_PARAMS))
    for column, p in enumerate(model.names):
        expected[:, column] = getattr(params, p)
    got = np.zeros((n, N_PARAMS))
    for i in range(n):
        from_traits(MODEL_IDS[name], got[i], traits.desired_speed[i], traits.time_headway[i],
                    traits.min_gap[i], traits.max_accel[i], traits.comfortable_decel[i],
                    traits.delta[i])  # fmt: skip
    np.testing.assert_array_equal(got, expected)


@settings(max_examples=200, deadline=None)
@given(
    name=st.sampled_from(sorted(MODELS)),
    draws=st.lists(st.floats(0.0, 1.0), min_size=N_PARAMS, max_size=N_PARAMS),
    v=st.floats(0.0, 40.0),
    v_lead=st.floats(0.0, 40.0),
    gap=st.one_of(st.floats(0.01, 300.0), st.just(np.inf)),
)
def test_kernel_acceleration_is_the_models_for_any_state(name, draws, v, v_lead, gap):
    # the numpy models are the calibration's reference (their fits evaluate them on the
    # recorded followers), the kernels what the traffic drives: one law, found so by
    # hypothesis over the parameters' bounds and any speeds and gaps
    model = MODELS[name]
    values = {
        p.name: np.array([p.bounds[0] + u * (p.bounds[1] - p.bounds[0])])
        for p, u in zip(model.parameters, draws, strict=False)
    }
    expected = model.accel(np.array([v]), np.array([v_lead]), np.array([gap]),
                           model.make(**values))  # fmt: skip
    row = np.zeros(N_PARAMS)
    for column, p in enumerate(model.names):
        row[column] = values[p][0]
    got = follow_accel(MODEL_IDS[name], v, v_lead, gap, *row)
    np.testing.assert_allclose(got, expected[0], rtol=1e-12, atol=1e-9)
