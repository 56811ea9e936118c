"""Strategic targets drawn from a recording's flows, or its own changes
(twin.cosim.strategic_targets)."""

from types import SimpleNamespace

import numpy as np

from twin.cosim.strategic_targets import RECORDED_SPAN, StrategicTargets

EDGES = [0.0, 100.0, 200.0, 300.0, 400.0, 500.0, 600.0, 700.0, 800.0]


class FakeManager:
    """What the targets ask of the traffic manager, recorded."""

    def __init__(self):
        self.targets = {}
        self.lane = {}
        self.ids = set()

    def set_strategic(self, ids, direction, x_from, x_by):
        for i in ids:
            self.targets[int(i)] = (direction, x_from, x_by) if direction else None

    def strategic(self, ids):
        return np.array([(self.targets.get(int(i)) or (0,))[0] for i in ids])

    def changing(self, ids):
        return np.zeros(len(ids), dtype=bool)

    def lanes(self, ids):
        return np.array([self.lane[int(i)] for i in ids])


def _flows(p_left_at_600=0.5, p_right_at_200=0.0):
    left, right = [0.0] * 8, [0.0] * 8
    left[6], right[2] = p_left_at_600, p_right_at_200
    strategic = {"-3>-2": {"probability": left}}
    if p_right_at_200:
        strategic["-3>-4"] = {"probability": right}
    return {"x_edges": EDGES, "strategic": strategic}


def _targets(flows, seed=0, name="calibrated"):
    behaviour = SimpleNamespace(name=name, strategic_flows=flows, changes_of=lambda t, x: [])
    manager = FakeManager()
    return StrategicTargets(behaviour, manager, seed), manager


def test_vehicles_leave_a_lane_where_and_as_often_as_the_flows_say():
    targets, manager = _targets(_flows(0.5, 0.2))
    n = 4000
    targets.added(np.arange(n), np.arange(n) + 1000, np.full(n, -3), np.full(n, 50.0))
    drawn = [t for t in manager.targets.values() if t is not None]
    left = [t for t in drawn if t[0] == 1]
    right = [t for t in drawn if t[0] == -1]
    # right first (bin 200-300, p 0.2), then left of those remaining (bin 600-700, p 0.5)
    assert abs(len(right) / n - 0.2) < 0.02
    assert abs(len(left) / n - 0.8 * 0.5) < 0.025
    assert {t[1:] for t in right} == {(150.0, 300.0)}  # from half a bin before to its end
    assert {t[1:] for t in left} == {(550.0, 700.0)}
    # a vehicle already past a bin is not drawn for it; lane -2 has no flow
    targets.added([n], [99], [-3], [650.0])
    targets.added([n + 1], [98], [-2], [50.0])
    assert manager.targets.get(n) is None and manager.targets.get(n + 1) is None


def test_draws_depend_on_the_seed_and_the_record_not_the_order_of_spawns():
    a, ma = _targets(_flows())
    b, mb = _targets(_flows())
    ids, tids = np.arange(200), np.arange(200) + 7
    a.added(ids, tids, np.full(200, -3), np.zeros(200))
    b.added(ids[::-1], tids[::-1], np.full(200, -3), np.zeros(200))
    assert ma.targets == mb.targets
    c, mc = _targets(_flows(), seed=1)
    c.added(ids, tids, np.full(200, -3), np.zeros(200))
    assert mc.targets != ma.targets


def test_a_vehicle_draws_again_in_the_lane_it_changed_to():
    flows = _flows(1.0)
    flows["strategic"]["-2>-1"] = {"probability": [0.0] * 7 + [1.0]}
    targets, manager = _targets(flows)
    manager.ids = {0}
    targets.added([0], [5], [-3], [0.0])
    assert manager.targets[0] == (1, 550.0, 700.0)
    manager.targets[0] = None  # the manager started the change: target cleared
    manager.lane[0] = -2
    targets.update(SimpleNamespace(id=np.array([0]), x=np.array([640.0])))
    assert manager.targets[0] == (1, 650.0, 800.0)


def test_recorded_changes_become_targets_one_after_the_other():
    plan = [(300.0, -3, -2), (600.0, -2, -1)]
    behaviour = SimpleNamespace(
        name="recorded", strategic_flows=None, changes_of=lambda tid, x: list(plan)
    )
    manager = FakeManager()
    targets = StrategicTargets(behaviour, manager, 0)
    targets.added([0], [5], [-3], [100.0])
    assert manager.targets[0] == (1, 300.0, 300.0 + RECORDED_SPAN)
    manager.targets[0], manager.lane[0] = None, -2
    targets.update(SimpleNamespace(id=np.array([0]), x=np.array([350.0])))
    assert manager.targets[0] == (1, 600.0, 600.0 + RECORDED_SPAN)


def test_paper_and_stores_without_strategic_flows_give_no_targets():
    targets, manager = _targets(None)
    targets.added([0], [5], [-3], [0.0])
    assert not targets.on and manager.targets == {}


def test_a_target_the_manager_refuses_is_skipped_and_removal_clears_targets():
    class Refusing(FakeManager):
        def set_strategic(self, ids, direction, x_from, x_by):
            if direction == 1:
                raise ValueError("the HOV line cannot be crossed")
            super().set_strategic(ids, direction, x_from, x_by)

    flows = {"x_edges": EDGES, "strategic": {"-2>-1": {"probability": [1.0] * 8}}}
    behaviour = SimpleNamespace(name="calibrated", strategic_flows=flows, changes_of=None)
    manager = Refusing()
    targets = StrategicTargets(behaviour, manager, 0)
    targets.added([0], [5], [-2], [0.0])  # its draw is refused: no target, no error
    assert manager.targets == {}
    plain, fake = _targets(_flows(1.0))
    fake.ids = {3}
    plain.added([3], [9], [-3], [0.0])
    assert fake.targets[3] is not None
    plain.removed([3])  # a despawned vehicle, or one given a controller
    assert fake.targets[3] is None and 3 not in plain._tid
