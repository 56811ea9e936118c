"""A relaxing vehicle near the windows' front end sees the recording ahead of it: the
recording is read and drawn (as ghosts) up to REAR_MARGIN beyond the frontmost
relaxing body's front, not only to the front ghost window's end."""

from tests.twin.cosim.scenes import EGO_X, T0, make_store, tid_of, vehicle
from twin.cosim.config import CosimConfig
from twin.cosim.core.handover import REAR_MARGIN
from twin.cosim.cosimulator import Cosimulator
from twin.data.empirical import EmpiricalTraffic


def test_a_queue_beyond_the_front_ghost_window_is_drawn_ahead_of_a_relaxing_body(
    built_map, tmp_path
):
    ego = vehicle(1, -1, EGO_X, 0.0, seconds=30.0)  # standing: the windows stay put
    runner = vehicle(2, -2, EGO_X + 140.0, 20.0, seconds=30.0)  # leaves the visible window
    standing = vehicle(3, -2, EGO_X + 215.0, 0.0, seconds=30.0)  # beyond the ghost window
    behind = vehicle(4, -4, EGO_X - 300.0, 0.0, seconds=30.0)  # the data's range
    store = make_store(tmp_path, [ego, runner, standing, behind])
    config = CosimConfig(road="westbound", lane=-1, x=EGO_X, time=T0, t_max=3.0,
                         world="kinematic")  # fmt: skip
    with Cosimulator(config, EmpiricalTraffic(store), built_map) as sim:
        sim.reset()
        sim.run()
        windows = sim.log.windows()
        ghosts = sim.log.ghosts()
        rows = sim.log.vehicles()
    g1 = windows["g1"].max()
    assert g1 + 5.0 < EGO_X + 215.0  # the standing vehicle lies beyond the windows
    runner_rows = rows[rows["tid"] == tid_of(sim, 2)]
    front = runner_rows["x"].max() + store.trajectory_arrays["length"][tid_of(sim, 2)]
    assert front > windows["x1"].max()  # the runner left the visible window, relaxing
    assert front + REAR_MARGIN > EGO_X + 215.0
    drawn = ghosts[ghosts["tid"] == tid_of(sim, 3)]
    assert len(drawn) > 0  # drawn ahead of it, where it could meet it
