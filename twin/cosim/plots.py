"""Pictures of a run: the time-space diagram (the paper's Figure c) and the bird's-eye
view of the windows (its Figure a), as PNG and optionally MP4.

Colours are the Okabe-Ito palette and every colour that carries meaning is doubled by a
fill, a hatch or a line style, so the figures read in greyscale and to a colour-blind
reader; speeds use ``cividis``, whose lightness grows with speed."""

from dataclasses import dataclass
from pathlib import Path

import cv2
import matplotlib

matplotlib.use("Agg")
import matplotlib.patheffects as pe
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from matplotlib.collections import LineCollection, PatchCollection
from matplotlib.patches import Patch, Rectangle

from mapgen.params import load_params
from twin.core import i24
from twin.core.atomic import atomic_file
from twin.data.plot import SPEED_CMAP, SPEED_RANGE, clock, lane_name, panel_lanes, save_figure

#: Okabe-Ito colours (distinct to colour-blind readers), each doubled by a fill or a style.
COLOURS = {
    "ego": "#D55E00",  # vermillion, filled, thick black edge
    "simulated": "#0072B2",  # blue, filled
    "ghost": "#000000",  # hollow, dashed edge
    "visible_window": "#009E73",  # bluish green, plain
    "ghost_cells": "#F0E442",  # yellow, hatched
    "recorded_ego": "#CC79A7",  # reddish purple, dashed
}
BEV_MARGIN_M = 10.0  # [m] shown beyond the ghost windows
BEV_WIDTH = 14.0  # [in] of the figure; its height follows from the road drawn to scale
BEV_MARGINS = (0.8, 0.7, 0.6, 0.95)  # [in] left, right, top (title), bottom (axis, legend)
BEV_DPI = 150  # [1/in] of bev.png
BEV_VIDEO_DPI = 100  # [1/in] of bev.mp4's frames
_HALO = [pe.withStroke(linewidth=2.6, foreground="white")]


def timespace_figure(
    recorded: dict,
    sim: pd.DataFrame,
    windows: pd.DataFrame,
    recorded_ego: dict,
    t0: float,
    title: str,
):
    """The time-space diagram of a run (a matplotlib figure): recorded trajectories as
    points coloured by speed, one panel for all lanes, then one per lane with the
    simulated vehicles of that lane over them; the ego (simulated and recorded) drawn in
    the lanes it drove, its starting lane's panel framed and named.

    Args:
        recorded: ``store.samples`` of the road over the episode (t, x, lane, speed),
            an on-ramp's acceleration lane's too (lane -5: a panel of its own).
        sim: the log's simulated rows (time [s since t0], id, x, lane, speed, role).
        windows: the log's windows per step (time, g0, x0, x1, g1).
        recorded_ego: ``store.trajectory`` of the ego's recorded vehicle (t, x, lane).
        t0: [s] unix start; times are drawn as seconds since t0, labelled with the clock.
    """
    t_end = float(windows["time"].iloc[-1])
    x_lo = float(windows["g0"].min()) - 50.0
    x_hi = float(windows["g1"].max()) + 50.0
    keep = (recorded["x"] >= x_lo) & (recorded["x"] <= x_hi)
    rec = {k: v[keep] for k, v in recorded.items()}
    rec_t = rec["t"] - t0
    ego = sim[sim["role"] == 0]
    ego_lane = int(ego["lane"].iloc[0]) if len(ego) else None
    ego_rec_t = recorded_ego["t"] - t0
    on = (ego_rec_t >= 0) & (ego_rec_t <= t_end)
    ego_rec = {"t": ego_rec_t[on], "x": recorded_ego["x"][on], "lane": recorded_ego["lane"][on]}

    lanes = panel_lanes(rec["lane"])
    fig, axes = plt.subplots(
        1 + len(lanes), 1, figsize=(11, 3 * (1 + len(lanes))), sharex=True,
        constrained_layout=True,
    )  # fmt: skip
    panels = [("all lanes", np.ones(len(rec_t), bool), None)]
    panels += [(lane_name(lane), rec["lane"] == lane, lane) for lane in lanes]
    points = None
    for ax, (label, rows, lane) in zip(axes, panels, strict=True):
        ax.fill_between(
            windows["time"], windows["x0"], windows["x1"], color=COLOURS["visible_window"],
            alpha=0.15, lw=0, label="visible window",
        )  # fmt: skip
        points = ax.scatter(
            rec_t[rows], rec["x"][rows], c=rec["speed"][rows], s=1.5, cmap=SPEED_CMAP,
            vmin=SPEED_RANGE[0], vmax=SPEED_RANGE[1], rasterized=True, linewidths=0,
        )  # fmt: skip
        others = sim[sim["role"] == 1]
        if lane is not None:
            others = others[others["lane"] == lane]
        _trajectory_lines(ax, others, label="simulated vehicles")
        _ego_line(ax, ego_rec["t"], ego_rec["x"], ego_rec["lane"], lane, recorded=True)
        _ego_line(ax, ego["time"], ego["x"], ego["lane"], lane, recorded=False)
        mine = lane is not None and lane == ego_lane
        ax.set_ylabel(f"{label}{chr(10)}{'ego lane, ' if mine else ''}x [m]")
        if mine:
            for spine in ax.spines.values():
                spine.set_linewidth(2.2)
        ax.set_ylim(x_lo, x_hi)
        ax.grid(alpha=0.2)
    handles, labels = axes[0].get_legend_handles_labels()
    axes[0].legend(handles, labels, loc="upper left", fontsize=8, framealpha=0.9)
    axes[-1].set_xlabel(f"time [s] after {clock(t0)}")
    axes[-1].set_xlim(0.0, t_end)
    fig.colorbar(points, ax=axes, label="recorded speed [m/s]", shrink=0.5)
    fig.suptitle(title)
    return fig


def timespace_plot(recorded, sim, windows, recorded_ego, t0: float, title: str, out: Path):
    """Write :func:`timespace_figure` as a PNG (a temporary name, then renamed)."""
    return save_figure(timespace_figure(recorded, sim, windows, recorded_ego, t0, title), out)


BOUNDARY_MARGIN_M = 30.0  # [m] shown inside the visible window and past the ghost cells


def boundary_figure(sim: pd.DataFrame, ghosts: pd.DataFrame, windows: pd.DataFrame,
                    t0: float, title: str):  # fmt: skip
    """The seams of the ghost-cell boundary, zoomed (a matplotlib figure): one panel per
    edge of the visible window (front, then rear), each in the moving frame of that edge
    (distance past it [m] against time). Each vehicle that was simulated and then became
    a ghost is drawn in a colour of its own: its simulated track as a line (thick where
    it was outside the visible window, relaxing), its ghost as dots of the same colour;
    a jump at the hand-over is the gap between the end of the line and the first dot.
    The other ghosts are faint grey dots, the ghost cells hatched.

    Args:
        sim: the log's simulated rows (time [s since t0], id, tid, x, role).
        ghosts: the log's ghost rows (time, tid, x).
        windows: the log's windows per step (time, g0, x0, x1, g1).
    """
    edges = windows.set_index("time")
    t = edges.index.to_numpy()
    fig, axes = plt.subplots(2, 1, figsize=(11, 8), sharex=True, constrained_layout=True)
    others = sim[sim["role"] != 0]
    lives = others.groupby("id").agg(tid=("tid", "first"), first=("time", "min"),
                                     last=("time", "max"))  # fmt: skip
    lives = lives.sort_values("first", kind="stable")
    # each life's ghost: its recording's dots after it, until the recording is simulated again
    lives["until"] = lives.groupby("tid")["first"].shift(-1).fillna(np.inf)
    ghost_of = {}
    for vid, life in lives.iterrows():
        dots = ghosts[(ghosts["tid"] == life["tid"]) & (ghosts["time"] > life["last"])
                      & (ghosts["time"] < life["until"])]  # fmt: skip
        if len(dots):
            ghost_of[vid] = dots
    handed_tids = lives.loc[list(ghost_of), "tid"].unique() if ghost_of else []
    palette = plt.get_cmap("tab10").colors
    sides = (("front", "x1", "g1", 1.0), ("rear", "x0", "g0", -1.0))
    for ax, (name, edge, outer, sign) in zip(axes, sides, strict=True):
        cell = sign * (edges[outer] - edges[edge]).to_numpy()
        ax.fill_between(t, 0.0, cell, facecolor="none", edgecolor=COLOURS["ghost_cells"],
                        hatch="//", lw=0, label="ghost cell")  # fmt: skip
        ax.axhline(0.0, color=COLOURS["visible_window"], lw=1.5,
                   label="edge of the visible window")  # fmt: skip

        def moved(rows, edge=edge, sign=sign):
            return sign * (rows["x"].to_numpy() - edges[edge].reindex(rows["time"]).to_numpy())

        plain = ~ghosts["tid"].isin(handed_tids)
        ax.scatter(ghosts["time"][plain], moved(ghosts[plain]), s=2, color="0.75",
                   linewidths=0, label="ghosts", rasterized=True)  # fmt: skip
        side = 0
        for vid, ghost in ghost_of.items():
            track = others[others["id"] == vid]
            d, g = moved(track), moved(ghost)
            if not (d[-1] > 0.0 or g[0] > 0.0):
                continue  # handed over at the other edge
            colour = palette[side % len(palette)]
            side += 1
            ax.plot(track["time"], d, color=colour, lw=0.8)
            ax.plot(track["time"], np.where(d > 0.0, d, np.nan), color=colour, lw=2.2)
            ax.scatter(ghost["time"], g, s=6, color=colour, linewidths=0)
        ax.plot([], [], color="0.3", lw=0.8, label="a vehicle simulated (thick: relaxing)")
        ax.scatter([], [], s=6, color="0.3", label="... then its ghost")
        ax.set_ylim(-BOUNDARY_MARGIN_M, float(np.nanmax(cell, initial=0.0)) + BOUNDARY_MARGIN_M)
        ax.set_ylabel(f"{name}: metres past the{chr(10)}visible window's {name} edge")
        ax.grid(alpha=0.2)
        ax.legend(loc="upper left", fontsize=8, framealpha=0.9)
    axes[-1].set_xlabel(f"time [s] after {clock(t0)}")
    axes[-1].set_xlim(0.0, float(t[-1]))
    fig.suptitle(title)
    return fig


def boundary_plot(sim, ghosts, windows, t0: float, title: str, out: Path):
    """Write :func:`boundary_figure` as a PNG (a temporary name, then renamed)."""
    return save_figure(boundary_figure(sim, ghosts, windows, t0, title), out)


def _trajectory_lines(ax, rows: pd.DataFrame, label: str, color: str = "black",
                      width: float = 0.45) -> None:  # fmt: skip
    """One thin black line per vehicle, over the recorded speeds' colours."""
    segments = []
    for _, track in rows.groupby("id", sort=True):
        t, x = track["time"].to_numpy(), track["x"].to_numpy()
        breaks = np.flatnonzero(np.diff(t) > 0.5) + 1  # left the lane and came back
        pieces = zip(np.split(t, breaks), np.split(x, breaks), strict=True)
        segments += [np.column_stack(piece) for piece in pieces]
    lines = LineCollection(segments, colors=color, linewidths=width, alpha=0.85, label=label)
    lines.set_rasterized(True)
    ax.add_collection(lines)


def _ego_line(ax, t, x, lanes, lane, *, recorded: bool) -> None:
    """The ego where it was in ``lane`` (every lane when ``lane`` is None)."""
    t, x = np.asarray(t, float), np.asarray(x, float)
    if lane is not None:
        x = np.where(np.asarray(lanes) == lane, x, np.nan)
    style = (
        {"color": COLOURS["recorded_ego"], "ls": "--", "lw": 1.6, "label": "recorded ego"}
        if recorded
        else {"color": "black", "ls": "-", "lw": 2.0, "label": "simulated ego"}
    )
    ax.plot(t, x, path_effects=_HALO, **style)


@dataclass
class BevScene:
    """One instant of a run from above, in the road frame.

    Attributes:
        sim: simulated rows (x back centre [m], y [m], length [m], width [m], role: 0 ego,
            1 other simulated vehicle).
        ghosts: ghost rows (x, y, length, width).
        window: the windows [m] (g0, x0, x1, g1): ghost cells g0..x0 and x1..g1, the
            visible window x0..x1.
        time: [s] since t0.
    """

    sim: pd.DataFrame
    ghosts: pd.DataFrame
    window: pd.Series
    time: float


class BevFigure:
    """The paper's bird's-eye figure (Figure a), drawn to scale: the carriageway with its
    lanes and markings, the visible window and the ghost cells, the ego, the simulated
    vehicles and the ghosts. :meth:`show` redraws it for another instant (the video)."""

    def __init__(self, road: i24.Road, t0: float, title: str, span_m: float, *, dpi: int = BEV_DPI):
        """
        Args:
            road: the carriageway.
            t0: [s] unix time of the run's start.
            title: the figure's first title line.
            span_m: [m] along the road shown (the windows); sets the figure's height.
        """
        self.t0, self.title = t0, title
        self.half_view = 0.5 * span_m + BEV_MARGIN_M  # [m]
        self._dynamic: list = []
        shoulder = load_params().cross_section.outer_shoulder
        self.y_edges = (0.0, i24.LANE_WIDTH, (i24.N_LANES + 1) * i24.LANE_WIDTH)
        self.y_max = self.y_edges[-1] + shoulder
        left, right, top, bottom = BEV_MARGINS
        width = BEV_WIDTH - left - right
        height = width * (self.y_max + 2.0) / (span_m + 2 * BEV_MARGIN_M)  # to scale
        size = (BEV_WIDTH, height + top + bottom)
        self.fig = plt.figure(figsize=size, dpi=dpi)
        self.ax = self.fig.add_axes((left / size[0], bottom / size[1], width / size[0],
                                     height / size[1]))  # fmt: skip
        ax = self.ax
        ax.set_ylim(self.y_max + 1.0, -1.0)  # the median at the top, travel to the right
        ax.set_facecolor("#b8b8b8")  # paved median and shoulder
        ax.set_xlabel(f"x along {road.value} travel [m] (travel to the right)")
        centres = i24.lane_center(np.array(i24.LANES))
        ax.set_yticks(centres, [f"{lane} HOV" if lane == i24.HOV_LANE else str(lane)
                                for lane in i24.LANES])  # fmt: skip
        ax.tick_params(axis="y", labelsize=8)
        ax.set_ylabel("lane")
        ax.secondary_yaxis("right").set_ylabel("y from the median [m]")
        ax.legend(
            handles=[
                Patch(facecolor=COLOURS["visible_window"], alpha=0.3, label="visible window"),
                Patch(facecolor=COLOURS["ghost_cells"], alpha=0.5, hatch="///",
                      label="ghost cells"),
                Patch(facecolor=COLOURS["ego"], edgecolor="black", lw=1.2, label="ego"),
                Patch(facecolor=COLOURS["simulated"], label="simulated vehicle"),
                Patch(facecolor="white", edgecolor=COLOURS["ghost"], ls="--",
                      label="ghost (recorded)"),
            ],
            loc="upper center", bbox_to_anchor=(0.5, -0.5 / height), ncol=5, fontsize=9,
            frameon=False,
        )  # fmt: skip

    def show(self, scene: BevScene) -> None:
        """Draw ``scene`` (replacing the previous instant's vehicles and windows)."""
        for artist in self._dynamic:
            artist.remove()
        ax, w = self.ax, scene.window
        centre = 0.5 * float(w["g0"] + w["g1"])
        x_lo, x_hi = centre - self.half_view, centre + self.half_view  # the same scale always
        ax.set_xlim(x_lo, x_hi)
        lanes = ax.add_patch(Rectangle((x_lo, self.y_edges[1]), x_hi - x_lo,
                                       self.y_edges[2] - self.y_edges[1], color="#4a4a4a",
                                       zorder=0))  # fmt: skip
        spans = [
            ax.axvspan(w["g0"], w["x0"], color=COLOURS["ghost_cells"], alpha=0.5, hatch="///",
                       lw=0, zorder=1),
            ax.axvspan(w["x1"], w["g1"], color=COLOURS["ghost_cells"], alpha=0.5, hatch="///",
                       lw=0, zorder=1),
            ax.axvspan(w["x0"], w["x1"], color=COLOURS["visible_window"], alpha=0.3, lw=0,
                       zorder=1),
        ]  # fmt: skip
        self._dynamic = [lanes, *spans, *self._markings(x_lo, x_hi), *self._vehicles(scene)]
        ax.set_title(f"{self.title}{chr(10)}t = {scene.time:.1f} s after t0, "
                     f"{clock(self.t0 + scene.time)}", fontsize=10)  # fmt: skip

    def _markings(self, x_lo: float, x_hi: float) -> list:
        """Yellow median edge, the HOV lane's double white line, broken white lines between
        the general lanes, the white outer edge (US style, 10 ft dashes, 30 ft gaps)."""
        ax, width = self.ax, i24.LANE_WIDTH
        lines = [
            ax.axhline(width, color="#E6C200", lw=1.0, zorder=2),
            ax.axhline(2 * width - 0.12, color="white", lw=0.8, zorder=2),
            ax.axhline(2 * width + 0.12, color="white", lw=0.8, zorder=2),
            ax.axhline(self.y_edges[2], color="white", lw=1.0, zorder=2),
        ]
        period, dash = 40.0 * i24.FT, 10.0 * i24.FT  # [m]
        starts = np.arange(np.floor(x_lo / period) * period, x_hi, period)
        segments = [[(s, k * width), (s + dash, k * width)]
                    for k in range(3, i24.N_LANES + 1) for s in starts]  # fmt: skip
        lines.append(ax.add_collection(LineCollection(segments, colors="white", lw=0.8,
                                                      zorder=2)))  # fmt: skip
        return lines

    def _vehicles(self, scene: BevScene) -> list:
        def boxes(frame):
            return [Rectangle((x, y - 0.5 * wd), ln, wd) for x, y, ln, wd in zip(
                frame["x"], frame["y"], frame["length"], frame["width"], strict=True)]  # fmt: skip

        sim = scene.sim
        ego, others = sim[sim["role"] == 0], sim[sim["role"] != 0]
        collections = [
            PatchCollection(boxes(scene.ghosts), facecolor="white", edgecolor=COLOURS["ghost"],
                            linestyle="--", linewidth=0.8, zorder=3),
            PatchCollection(boxes(others), facecolor=COLOURS["simulated"], edgecolor="black",
                            linewidth=0.3, zorder=3),
            PatchCollection(boxes(ego), facecolor=COLOURS["ego"], edgecolor="black",
                            linewidth=1.4, zorder=4),
        ]  # fmt: skip
        return [self.ax.add_collection(c) for c in collections]

    def image(self) -> np.ndarray:
        """The figure as a BGR uint8 image (for the video)."""
        self.fig.canvas.draw()
        rgba = np.asarray(self.fig.canvas.buffer_rgba())
        return cv2.cvtColor(rgba, cv2.COLOR_RGBA2BGR)

    def close(self) -> None:
        plt.close(self.fig)


def bev_plot(scene: BevScene, road: i24.Road, t0: float, title: str, out: Path) -> Path:
    """Write the bird's-eye figure of ``scene`` as a PNG."""
    figure = BevFigure(road, t0, title, _span(scene))
    figure.show(scene)
    return save_figure(figure.fig, out, dpi=BEV_DPI)


def bev_video(scenes, road: i24.Road, t0: float, title: str, out: Path, fps: float) -> Path:
    """Write the bird's-eye figure of each of ``scenes`` (an iterable) as an MP4."""
    figure = None

    def frames():
        nonlocal figure
        for scene in scenes:
            if figure is None:
                figure = BevFigure(road, t0, title, _span(scene), dpi=BEV_VIDEO_DPI)
            figure.show(scene)
            image = figure.image()
            yield image[: image.shape[0] // 2 * 2, : image.shape[1] // 2 * 2]

    try:
        return write_mp4(frames(), out, fps)
    finally:
        if figure is not None:
            figure.close()


def _span(scene: BevScene) -> float:
    """[m] from the upstream ghost cell's start to the downstream one's end."""
    return float(scene.window["g1"] - scene.window["g0"])


def write_mp4(frames, out: Path, fps: float) -> Path:
    """Write BGR frames (an iterable of equal-size images) as an MP4 (mp4v)."""
    with atomic_file(out) as tmp:
        writer = None
        try:
            for frame in frames:
                if writer is None:
                    size = (frame.shape[1], frame.shape[0])
                    fourcc = cv2.VideoWriter_fourcc(*"mp4v")
                    writer = cv2.VideoWriter(str(tmp), fourcc, fps, size)
                    if not writer.isOpened():
                        raise OSError(f"OpenCV cannot write MP4 video to {out}")
                writer.write(frame)
        finally:
            if writer is not None:
                writer.release()
        if writer is None:
            raise ValueError(f"no frames to write to {out}")
    return Path(out)
