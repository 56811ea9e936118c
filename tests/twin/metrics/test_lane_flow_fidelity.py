"""Lane changes by lane pair and the net lane flow by position, simulated against
recorded (twin.metrics.lane_flow_fidelity), and their place in ``fidelity.png``."""

from types import SimpleNamespace

import matplotlib
import numpy as np
import pandas as pd
import pytest

from twin.metrics import lane_flow_fidelity as lff

matplotlib.use("Agg")

DT = 0.1


def _log(*vehicles):
    """A run's log: each vehicle (id, x0, speed, lanes by step)."""
    frames = []
    for vid, x0, speed, lanes in vehicles:
        n = len(lanes)
        t = np.arange(n) * DT
        frames.append(pd.DataFrame({"id": vid, "time": t, "x": x0 + speed * t, "lane": lanes}))
    return pd.concat(frames, ignore_index=True).sample(frac=1.0, random_state=0)  # any order


def test_simulated_changes_are_held_ones_at_the_place_of_the_new_lane():
    log = _log(
        (1, 100.0, 10.0, [-2] * 20 + [-3] * 20),  # a change at step 20: x = 120 m
        (2, 300.0, 10.0, [-2] * 20 + [-3] * 3 + [-2] * 20),  # flicker on a line: none
        (3, 500.0, 10.0, [-4] * 15 + [-3] * 15 + [-2] * 15),  # two changes
        (4, 700.0, 10.0, [-5] * 20 + [-4] * 20),  # a merge from an on-ramp: none
    )
    changes = lff.simulated_changes(log, DT)
    assert changes[["lane_from", "lane_to"]].values.tolist() == [[-2, -3], [-4, -3], [-3, -2]]
    assert changes["x"].tolist() == pytest.approx([120.0, 515.0, 530.0])
    assert changes["time"].tolist() == pytest.approx([2.0, 1.5, 3.0])


def test_recorded_changes_count_inside_the_moving_window_only():
    windows = pd.DataFrame(
        {"time": [0.0, 1.0, 2.0], "x0": [0.0, 10.0, 20.0], "x1": [100.0, 110.0, 120.0]}
    )
    changes = SimpleNamespace(
        time=np.array([1000.5, 1001.0, 1001.0, 1005.0]),
        x=np.array(
            [50.0, 5.0, 50.0, 50.0]
        ),  # 5 m: behind the window at 1 s; 5 s: after the episode
        lane_from=np.array([-2, -2, -3, -3], np.int8),
        lane_to=np.array([-3, -3, -4, -4], np.int8),
    )
    inside = lff.recorded_changes_in_window(changes, windows, t0=1000.0)
    assert inside["x"].tolist() == [50.0, 50.0]
    assert inside["time"].tolist() == [0.5, 1.0]


def test_episode_section_counts_pairs_and_the_net_flow_by_bin_on_the_road_grid():
    windows = pd.DataFrame({"time": [0.0, 10.0], "x0": [150.0, 250.0], "x1": [450.0, 550.0]})
    sim = pd.DataFrame({"time": [1.0, 2.0, 3.0], "x": [210.0, 220.0, 450.0],
                        "lane_from": [-4, -4, -3], "lane_to": [-3, -3, -4]})  # fmt: skip
    rec = pd.DataFrame({"time": [1.0], "x": [390.0], "lane_from": [-4], "lane_to": [-3]})
    section = lff.episode_section(sim, rec, windows)
    assert section["x_edges"] == [0.0, 200.0, 400.0, 600.0]  # multiples of 200 m
    assert section["pairs"]["-4>-3"] == [2, 1]
    assert section["pairs"]["-3>-4"] == [1, 0]
    assert section["net_out"]["-4"]["simulated"] == [0, 2, -1]
    assert section["net_out"]["-3"]["simulated"] == [0, -2, 1]
    assert section["net_out"]["-4"]["recorded"] == [0, 1, 0]
    assert section["net_out"]["-1"]["recorded"] == [0, 0, 0]
    assert section["changes"] == {"simulated_x": [210.0, 220.0, 450.0], "recorded_x": [390.0]}


def _section(edges, net_sim, net_rec, pair=(0, 0)):
    zeros = [0] * (len(edges) - 1)
    net = {str(k): {"simulated": zeros, "recorded": zeros} for k in (-1, -2, -3, -4)}
    net["-4"] = {"simulated": net_sim, "recorded": net_rec}
    pairs = {lff.pair_key(a, b): [0, 0] for a, b in lff.PAIRS}
    pairs["-4>-3"] = list(pair)
    return {"bin_m": 200.0, "x_edges": edges, "pairs": pairs, "net_out": net}


def test_episodes_add_up_bin_by_bin_and_the_errors_follow():
    a = _section([0.0, 200.0, 400.0], [10, 2], [12, 0], pair=(12, 12))
    b = _section([200.0, 400.0, 600.0], [3, 20], [2, 10], pair=(23, 12))
    total = lff.sum_episodes([a, None, b])
    assert total["x_edges"] == [0.0, 200.0, 400.0, 600.0]
    assert total["net_out"]["-4"]["simulated"] == [10, 5, 20]
    assert total["net_out"]["-4"]["recorded"] == [12, 2, 10]
    assert total["pairs"]["-4>-3"] == {"simulated": 35, "recorded": 24}
    assert total["changes_ratio"] == pytest.approx(35 / 24, abs=1e-4)
    assert total["net_flow_error"] == pytest.approx((2 + 3 + 10) / 24, abs=1e-4)
    # judged: bins with |recorded| >= 10 (12 and 10); within 30 %: 10 of 12, not 20 of 10
    assert (total["bins_judged"], total["bins_within"]) == (2, 1)
    assert total["episodes_summed"] == 2
    assert total["changes"] == {"simulated_x": [], "recorded_x": []}  # none kept then
    a["changes"] = {"simulated_x": [30.0, 310.0], "recorded_x": [5.0]}
    b["changes"] = {"simulated_x": [250.0], "recorded_x": []}
    assert lff.sum_episodes([a, b])["changes"] == {
        "simulated_x": [30.0, 250.0, 310.0], "recorded_x": [5.0]
    }  # fmt: skip
    assert lff.sum_episodes([None, {}]) is None


def test_episodes_far_apart_add_up_on_one_contiguous_grid():
    a = _section([0.0, 200.0, 400.0], [1, 2], [1, 2])
    b = _section([800.0, 1000.0], [5], [4])
    total = lff.sum_episodes([a, b])
    assert total["x_edges"] == [0.0, 200.0, 400.0, 600.0, 800.0, 1000.0]
    assert total["net_out"]["-4"]["simulated"] == [1, 2, 0, 0, 5]  # nothing measured: 0


def test_the_pictures_are_titled_labelled_and_have_legends():
    import matplotlib.pyplot as plt

    total = lff.sum_episodes([_section([0.0, 200.0, 400.0], [10, 2], [12, 0], pair=(3, 4))])
    fig, axes = plt.subplots(1, 5)
    lff.draw(axes[0], axes[1:], {"paper": total, "recorded": total})
    for ax in axes:
        assert ax.get_title() and ax.get_ylabel()
        assert ax.get_legend() is not None
        labels = [t.get_text() for t in ax.get_legend().get_texts()]
        # the recording is told apart from the behaviour named recorded
        assert labels == ["the recording", "paper", "recorded"]
    assert axes[1].get_title() == "net flow out of lane -1 (HOV)"
    plt.close(fig)
    text = lff.markdown({"paper": total, "calibrated": None})
    assert "| -4 to -3 | 3 / 4 |" in text
