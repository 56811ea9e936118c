"""Pictures of a run: the time-space diagram (the paper's Figure c) and the bird's-eye
view of the windows (its Figure a), as PNG and optionally MP4."""

from pathlib import Path

import cv2
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from twin.core import i24
from twin.core.atomic import atomic_file
from twin.data.plot import SPEED_RANGE, save_figure

BEV_WIDTH = 1600  # [px]
BEV_PX_PER_M_Y = 12.0  # [px/m] lateral; the longitudinal scale follows the window span
BEV_HEADER = 44  # [px]
BEV_MARGIN_M = 10.0  # [m] shown beyond the ghost windows
_BGR = {
    "road": (70, 70, 70),
    "line": (235, 235, 235),
    "visible": (60, 170, 60),
    "ghost_window": (40, 200, 230),
    "ego": (40, 40, 230),
    "visible_vehicle": (215, 140, 40),
    "ghost": (40, 200, 230),
    "text": (20, 20, 20),
}


def timespace_plot(
    recorded: dict,
    sim: pd.DataFrame,
    windows: pd.DataFrame,
    recorded_ego: dict,
    t0: float,
    title: str,
    out: Path,
) -> Path:
    """Recorded trajectories (points coloured by speed) with the simulated ego over them:
    one panel for all lanes, then one per lane with the simulated vehicles of that lane.

    Args:
        recorded: ``store.samples`` of the road over the episode.
        sim: the log's simulated rows (time, x, lane, speed, role).
        windows: the log's windows per step (time, x0, x1).
        recorded_ego: ``store.trajectory`` of the ego's recorded vehicle.
        t0: [s] unix start; times are drawn as seconds since t0.
    """
    t_end = float(windows["time"].iloc[-1])
    x_lo = float(windows["g0"].min()) - 50.0
    x_hi = float(windows["g1"].max()) + 50.0
    keep = (recorded["x"] >= x_lo) & (recorded["x"] <= x_hi)
    rec = {k: v[keep] for k, v in recorded.items()}
    rec_t = rec["t"] - t0
    ego = sim[sim["role"] == 0]
    ego_rec_t = recorded_ego["t"] - t0
    on = (ego_rec_t >= 0) & (ego_rec_t <= t_end)

    fig, axes = plt.subplots(
        1 + len(i24.LANES), 1, figsize=(11, 15), sharex=True, constrained_layout=True
    )
    panels = [("all lanes", np.ones(len(rec_t), bool), None)]
    panels += [(f"lane {lane}", rec["lane"] == lane, lane) for lane in i24.LANES]
    points = None
    for ax, (label, rows, lane) in zip(axes, panels, strict=True):
        ax.fill_between(
            windows["time"], windows["x0"], windows["x1"], color="0.85", alpha=0.5, lw=0,
            label="visible window",
        )  # fmt: skip
        points = ax.scatter(
            rec_t[rows], rec["x"][rows], c=rec["speed"][rows], s=0.5, cmap="RdYlGn",
            vmin=SPEED_RANGE[0], vmax=SPEED_RANGE[1], rasterized=True, linewidths=0,
        )  # fmt: skip
        if lane is not None:
            mine = sim[(sim["lane"] == lane) & (sim["role"] == 1)]
            ax.scatter(
                mine["time"], mine["x"], s=0.3, color="0.15", rasterized=True, linewidths=0,
                label="simulated vehicles",
            )  # fmt: skip
        ax.plot(
            ego_rec_t[on], recorded_ego["x"][on], color="magenta", lw=1.6, ls="--",
            label="recorded ego",
        )  # fmt: skip
        ax.plot(ego["time"], ego["x"], color="black", lw=1.8, label="simulated ego")
        ax.set_ylabel(f"{label}{' (HOV)' if lane == i24.HOV_LANE else ''}\nx [m]")
        ax.set_ylim(x_lo, x_hi)
        ax.grid(alpha=0.2)
    axes[0].legend(loc="upper left", fontsize=8, markerscale=8)
    axes[-1].set_xlabel("time since t0 [s]")
    axes[-1].set_xlim(0.0, t_end)
    fig.colorbar(points, ax=axes, label="recorded speed [m/s]", shrink=0.5)
    fig.suptitle(title)
    return save_figure(fig, out)


def bev_frame(
    sim: pd.DataFrame, ghosts: pd.DataFrame, window: pd.Series, time: float, title: str
) -> np.ndarray:
    """A bird's-eye image (BGR, uint8) of the road frame at ``time``: the visible window
    green, the ghost windows yellow, the ego red, visible vehicles blue, ghosts yellow.

    Args:
        sim: simulated rows at ``time`` (x, y, length, width, role, speed).
        ghosts: ghost rows at ``time`` (x, y, length, width).
        window: the windows row at ``time`` (g0, x0, x1, g1).
    """
    x_lo, x_hi = window["g0"] - BEV_MARGIN_M, window["g1"] + BEV_MARGIN_M
    y_lo, y_hi = 0.0, (i24.N_LANES + 2) * i24.LANE_WIDTH
    sx = BEV_WIDTH / (x_hi - x_lo)
    height = BEV_HEADER + round((y_hi - y_lo) * BEV_PX_PER_M_Y)
    image = np.full((height, BEV_WIDTH, 3), 255, np.uint8)

    def px(x):
        return np.round((np.asarray(x) - x_lo) * sx).astype(int)

    def py(y):  # travel to the right, the median at the top
        return np.round(BEV_HEADER + (np.asarray(y) - y_lo) * BEV_PX_PER_M_Y).astype(int)

    edge_in, edge_out = i24.LANE_WIDTH, (i24.N_LANES + 1) * i24.LANE_WIDTH
    cv2.rectangle(image, (0, int(py(edge_in))), (BEV_WIDTH, int(py(edge_out))), _BGR["road"], -1)
    overlay = image.copy()
    for (a, b), colour in (
        ((window["g0"], window["x0"]), _BGR["ghost_window"]),
        ((window["x0"], window["x1"]), _BGR["visible"]),
        ((window["x1"], window["g1"]), _BGR["ghost_window"]),
    ):
        cv2.rectangle(overlay, (int(px(a)), BEV_HEADER), (int(px(b)), height - 1), colour, -1)
    image = cv2.addWeighted(overlay, 0.25, image, 0.75, 0)
    for k in range(1, i24.N_LANES + 2):
        y = int(py(k * i24.LANE_WIDTH))
        cv2.line(image, (0, y), (BEV_WIDTH, y), _BGR["line"], 1)
    for frame, colour_of in ((ghosts, None), (sim, "role")):
        if frame.empty:
            continue
        x0, x1 = px(frame["x"]), px(frame["x"] + frame["length"])
        y0 = py(frame["y"] - 0.5 * frame["width"])
        y1 = py(frame["y"] + 0.5 * frame["width"])
        roles = frame[colour_of].to_numpy() if colour_of else np.full(len(frame), 2)
        for a, b, c, d, role in zip(x0, y0, x1, y1, roles, strict=True):
            colour = (_BGR["ego"], _BGR["visible_vehicle"], _BGR["ghost"])[int(role)]
            cv2.rectangle(image, (int(a), int(b)), (int(c), int(d)), colour, -1 if role < 2 else 2)
    cv2.putText(image, title, (8, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, _BGR["text"], 1, cv2.LINE_AA)
    legend = (
        f"t = {time:5.1f} s   x {x_lo:.0f}..{x_hi:.0f} m (travel to the right; lateral "
        f"scale x{BEV_PX_PER_M_Y / sx:.1f})   red ego, blue visible, yellow ghosts; green "
        "visible window, yellow ghost windows"
    )
    cv2.putText(
        image, legend, (8, 36), cv2.FONT_HERSHEY_SIMPLEX, 0.42, _BGR["text"], 1, cv2.LINE_AA
    )
    return image


def write_png(image: np.ndarray, out: Path) -> Path:
    """Write an image to a temporary name and rename it into place."""
    with atomic_file(out) as tmp:
        if not cv2.imwrite(str(tmp), image):
            raise OSError(f"OpenCV could not write {out}")
    return Path(out)


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
