"""The ``cosim`` fixture: a cosimulator over a hand-built recording (``scenes``)."""

import pytest

from tests.twin.cosim.scenes import EGO_X, T0, hold_speed, make_store
from twin.cosim.config import CosimConfig
from twin.cosim.cosimulator import Cosimulator
from twin.data.empirical import EmpiricalTraffic


@pytest.fixture
def cosim(built_map, tmp_path):
    """``cosim(docs, **config) -> Cosimulator`` (reset, ego held at its speed unless a
    controller is given); closed at the end of the test."""
    made = []

    def make(docs, controller=hold_speed, **settings):
        store = make_store(tmp_path / f"store{len(made)}", docs)
        config = CosimConfig(
            **{"road": "westbound", "lane": -2, "x": EGO_X, "time": T0, "vel_default": 30.0,
               **settings}
        )  # fmt: skip
        sim = Cosimulator(config, EmpiricalTraffic(store), built_map, controller=controller)
        made.append(sim)
        sim.reset()
        return sim

    yield make
    for sim in made:
        sim.close()
