"""String behaviour: a platoon of 10 behind a braking leader amplifies or damps the
disturbance as linear IDM theory says for its parameters, and follows exactly the
IDM integrated independently here."""

import numpy as np
import pytest

from tests.twin.traffic.conftest import PointMasses, point_mass_manager
from twin.core.i24 import lane_center
from twin.traffic.scene import Obstacles

DT = 0.01  # [s]
V_EQ = 12.0  # [m/s] platoon speed
LENGTH = 4.7  # [m] sedan (the class table's mean)
N = 10
STABLE = dict(
    desired_speed=30.0, time_headway=1.5, min_gap=2.0, max_accel=2.0, comfortable_decel=2.0
)
UNSTABLE = dict(
    desired_speed=30.0, time_headway=1.2, min_gap=2.0, max_accel=0.3, comfortable_decel=2.0
)


def idm(v, dv, s, p):
    """The IDM written out from Treiber, Hennecke and Helbing (2000)."""
    s_star = p["min_gap"] + np.maximum(
        0.0,
        v * p["time_headway"] + v * dv / (2.0 * np.sqrt(p["max_accel"] * p["comfortable_decel"])),
    )
    return p["max_accel"] * (1.0 - (v / p["desired_speed"]) ** 4 - (s_star / s) ** 2)


def equilibrium(v, p):
    return (p["min_gap"] + v * p["time_headway"]) / np.sqrt(1.0 - (v / p["desired_speed"]) ** 4)


def max_gain(p):
    """max over frequency of |V_follower / V_leader| for the IDM linearised at V_EQ:
    G(s) = (a_s - s a_dv) / (s^2 - s (a_v + a_dv) + a_s)."""
    s, h = equilibrium(V_EQ, p), 1e-5
    a_s = (idm(V_EQ, 0.0, s + h, p) - idm(V_EQ, 0.0, s - h, p)) / (2 * h)
    a_v = (idm(V_EQ + h, 0.0, s, p) - idm(V_EQ - h, 0.0, s, p)) / (2 * h)
    a_dv = (idm(V_EQ, h, s, p) - idm(V_EQ, -h, s, p)) / (2 * h)
    jw = 1j * np.linspace(1e-4, 3.0, 30000)
    return np.abs((a_s - jw * a_dv) / (jw**2 - jw * (a_v + a_dv) + a_s)).max()


def leader_speed(t):
    """12 m/s with one slow dip to 10 m/s between 5 and 55 s (a 50 s period, where
    the unstable set's linear gain peaks)."""
    phase = 2.0 * np.pi * np.clip((t - 5.0) / 50.0, 0.0, 1.0)
    return V_EQ - (1.0 - np.cos(phase))


def advance(x, v, a):
    v_new = np.maximum(v + a * DT, 0.0)
    return x + 0.5 * (v + v_new) * DT, v_new


def platoon(p, steps):
    """(steps, N) follower speeds: by the traffic manager, and by the IDM above."""
    manager, params = point_mass_manager(np.full(N, -2), 0, auto_lane_change=False)
    ids = np.arange(N)
    manager.add(ids, 1, -2, params, desired_speed=p["desired_speed"])
    manager.set_params(ids, **{k: v for k, v in p.items() if k != "desired_speed"})
    gap = equilibrium(V_EQ, p)
    x0 = -np.arange(1, N + 1) * (gap + LENGTH)
    speeds = []
    for drive in ("manager", "independent"):
        x, v = x0.copy(), np.full(N, V_EQ)
        lead_x, out = 0.0, np.empty((steps, N))
        for k in range(steps):
            t = k * DT
            v_lead = leader_speed(t)
            ahead_x = np.r_[lead_x, x[:-1]]
            ahead_v = np.r_[v_lead, v[:-1]]
            if drive == "manager":
                states = PointMasses(
                    ids, x, lane_center(np.full(N, -2)), np.full(N, -2), v, np.zeros(N)
                )
                a_lead = (leader_speed(t + DT) - v_lead) / DT
                ghost = Obstacles.make(1, -2, lead_x, LENGTH, v_lead, a_lead)
                a = manager.step(states, ghost).accel
            else:
                a = idm(v, v - ahead_v, ahead_x - x - LENGTH, p)
            lead_x += 0.5 * (v_lead + leader_speed(t + DT)) * DT
            x, v = advance(x, v, a)
            out[k] = v
        speeds.append(out)
    assert manager.emergency_steps == 0 and manager.lane_changes == 0
    return speeds


@pytest.mark.parametrize("p, amplifies", [(STABLE, False), (UNSTABLE, True)])
def test_platoon_amplifies_or_damps_as_linear_theory_says(p, amplifies):
    gain = max_gain(p)
    assert (gain > 1.0 + 1e-6) == amplifies  # the parameters are what the test claims
    by_manager, independent = platoon(p, steps=12000)
    assert np.abs(by_manager - independent).max() < 1e-6
    dip = V_EQ - by_manager.min(axis=0)  # each follower's speed drop
    ratio = dip[-1] / dip[0]
    if amplifies:
        assert 1.2 < ratio <= gain ** (N - 1)
        assert np.all(np.diff(dip) > 0)
    else:
        assert ratio < 1.0
        assert np.all(np.diff(dip) < 0)
