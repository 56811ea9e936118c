"""Hand-built recordings for the cosimulator's loop tests: constant-speed westbound
vehicles placed in lanes at road-frame x, ingested into a store like real data."""

from tests.conftest import make_doc, write_day
from twin.core import i24
from twin.core.i24 import SCENARIO_TIME
from twin.data.ingest import ingest
from twin.data.store import TrajectoryStore

T0 = SCENARIO_TIME
EGO_X = 700.0  # [m] westbound


def vehicle(n: int, lane: int, x: float, speed: float, *, start=-5.0, seconds=45.0, **doc):
    """A westbound document: at T0 the back centre is at ``x`` [m] in ``lane``; constant
    ``speed`` [m/s] from T0 + ``start`` for ``seconds``."""
    x_start = x + speed * start
    return make_doc(
        f"{n:024x}",
        direction=-1,
        mm=i24.SEGMENT_END_MM - x_start / i24.MILE,
        y_ft=(-lane + 0.5) * i24.LANE_WIDTH_FT,
        speed=speed,
        t0=T0 + start,
        n=int(seconds * 25) + 1,
        **doc,
    )


def make_store(folder, docs) -> TrajectoryStore:
    folder.mkdir(parents=True, exist_ok=True)
    day = write_day(folder / "day.json", docs)
    ingest([day], folder / "store", progress=False)
    return TrajectoryStore(folder / "store")


def hold_speed(observation):
    """An ego controller that keeps the speed it has."""
    return 0.0


def rows_of(sim, tid: int):
    """The log rows of the simulated vehicle spawned from recorded vehicle ``tid``."""
    frame = sim.log.vehicles()
    return frame[frame["tid"] == tid]


def tid_of(sim, n: int) -> int:
    return sim.traffic.store.tid_of(f"{n:024x}")


def step_until(sim, predicate, limit=3000):
    for _ in range(limit):
        sim.step()
        if predicate():
            return
    raise AssertionError("condition never met")
