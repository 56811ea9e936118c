"""The run's pictures draw what a reader of a paper needs: titles, axes with units, the
absolute time, legends for every kind of mark, and the bird's-eye view to scale
(matplotlib's artists, not pixels)."""

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
import pytest
from matplotlib.collections import PatchCollection

from twin.core import i24
from twin.core.i24 import Road
from twin.cosim import plots

T0 = 1669812350.0  # 2022-11-30 06:45:50 CST


@pytest.fixture
def episode():
    """Two simulated vehicles and the ego over 10 s; the ego starts in lane -2 and moves
    to lane -3 at 5 s."""
    time = np.round(np.arange(0.0, 10.0, 0.1), 6)
    rows = []
    for vid, role, x0, lanes in ((0, 0, 700.0, (-2, -3)), (1, 1, 720.0, (-1, -1)),
                                 (2, 1, 680.0, (-3, -3))):  # fmt: skip
        lane = np.where(time < 5.0, lanes[0], lanes[1])
        rows.append(pd.DataFrame({"time": time, "id": vid, "role": role, "x": x0 + 20.0 * time,
                                  "lane": lane, "speed": 20.0}))  # fmt: skip
    sim = pd.concat(rows, ignore_index=True)
    windows = pd.DataFrame({"time": time, "g0": 500.0 + 20 * time, "x0": 550.0 + 20 * time,
                            "x1": 850.0 + 20 * time, "g1": 900.0 + 20 * time})  # fmt: skip
    recorded = {"t": T0 + np.tile(time, 2), "x": np.r_[700 + 20 * time, 300 + 20 * time],
                "lane": np.r_[np.full(100, -2), np.full(100, -4)],
                "speed": np.full(200, 20.0)}  # fmt: skip
    recorded_ego = {"t": T0 + time, "x": 700 + 20 * time, "lane": np.full(100, -2)}
    return sim, windows, recorded, recorded_ego


def test_timespace_has_the_legend_the_clock_and_the_ego_lane(episode):
    sim, windows, recorded, recorded_ego = episode
    fig = plots.timespace_figure(recorded, sim, windows, recorded_ego, T0, "scenario B")
    try:
        axes = fig.axes[: 1 + len(i24.LANES)]
        legend = [t.get_text() for t in axes[0].get_legend().get_texts()]
        assert legend == ["visible window", "simulated vehicles", "recorded ego", "simulated ego"]
        assert axes[-1].get_xlabel() == "time [s] after 2022-11-30 06:45:50.0 CST"
        assert fig.get_suptitle() == "scenario B"
        assert all("x [m]" in ax.get_ylabel() for ax in axes)
        assert "(HOV)" in axes[1].get_ylabel()
        # the ego's first lane is named and framed; the other panels are not
        framed = [ax.spines["left"].get_linewidth() > 2 for ax in axes]
        assert framed == [False, False, True, False, False]
        assert "ego lane" in axes[2].get_ylabel() and "ego lane" not in axes[3].get_ylabel()
        assert fig.axes[-1].get_ylabel() == "recorded speed [m/s]"  # the colour bar
        # the simulated ego is drawn in lane -2 only while it is there
        ego_line = next(ln for ln in axes[2].get_lines() if ln.get_label() == "simulated ego")
        drawn = np.isfinite(ego_line.get_ydata())
        assert drawn[:50].all() and not drawn[50:].any()
    finally:
        plt.close(fig)


def _scene(sim: pd.DataFrame, at: float) -> plots.BevScene:
    rows = sim[np.isclose(sim["time"], at)].copy()
    rows["y"] = i24.lane_center(rows["lane"].to_numpy())
    rows["length"], rows["width"] = 4.5, 1.9
    ghosts = pd.DataFrame({"x": [520.0, 880.0], "y": i24.lane_center(np.array([-1, -4])),
                           "length": 4.5, "width": 1.9})  # fmt: skip
    window = pd.Series({"g0": 500.0, "x0": 550.0, "x1": 850.0, "g1": 900.0})
    return plots.BevScene(rows, ghosts, window, at)


def test_bev_is_to_scale_with_lanes_windows_and_a_legend(episode):
    sim = episode[0]
    figure = plots.BevFigure(Road.WESTBOUND, T0, "scenario B", span_m=400.0)
    try:
        figure.show(_scene(sim, 2.0))
        ax = figure.ax
        assert ax.get_xlabel() == "x along westbound travel [m] (travel to the right)"
        assert [t.get_text() for t in ax.get_yticklabels()] == ["-1 HOV", "-2", "-3", "-4"]
        legend = [t.get_text() for t in ax.get_legend().get_texts()]
        assert legend == ["visible window", "ghost cells", "ego", "simulated vehicle",
                          "ghost (recorded)"]  # fmt: skip
        assert ax.get_title() == "scenario B\nt = 2.0 s after t0, 2022-11-30 06:45:52.0 CST"
        # one metre is as long across the road as along it
        box = ax.get_position()
        width_in = box.width * figure.fig.get_figwidth()
        height_in = box.height * figure.fig.get_figheight()
        (x_lo, x_hi), (y_hi, y_lo) = ax.get_xlim(), ax.get_ylim()
        assert width_in / (x_hi - x_lo) == pytest.approx(height_in / (y_hi - y_lo), rel=1e-6)
        boxes = [c for c in ax.collections if isinstance(c, PatchCollection)]
        assert [len(c.get_paths()) for c in boxes] == [2, 2, 1]  # ghosts, simulated, ego
        # a later instant replaces the vehicles rather than adding to them
        figure.show(_scene(sim, 4.0))
        boxes = [c for c in ax.collections if isinstance(c, PatchCollection)]
        assert [len(c.get_paths()) for c in boxes] == [2, 2, 1]
        image = figure.image()
        assert image.dtype == np.uint8 and image.shape[2] == 3
    finally:
        figure.close()


def test_timespace_draws_the_recorded_ramp_vehicles_in_a_panel_of_their_own(episode):
    sim, windows, recorded, recorded_ego = episode
    time = np.round(np.arange(0.0, 10.0, 0.1), 6)
    ramp = {"t": T0 + time, "x": 600 + 15 * time, "lane": np.full(100, -5),
            "speed": np.full(100, 15.0)}  # fmt: skip
    with_ramp = {k: np.r_[recorded[k], ramp[k]] for k in recorded}
    fig = plots.timespace_figure(with_ramp, sim, windows, recorded_ego, T0, "on-ramp")
    try:
        panels = fig.axes[: 2 + len(i24.LANES)]
        assert "lane -5 (on-ramp)" in panels[-1].get_ylabel()
        assert len(panels[-1].collections[1].get_offsets()) == 100  # after the window
        # "all lanes" holds theirs too: every lane panel's points, the ramp's included
        counts = [len(ax.collections[1].get_offsets()) for ax in panels]
        assert counts[0] == sum(counts[1:])
    finally:
        plt.close(fig)
